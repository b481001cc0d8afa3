"""Cost of the nonlinear car (damper curves, SPEC §8) against the linear kernel and against SciPy.

On the built-in scenario's runs (``rideid.data.scenario.default_scenario()``),
a population of 64 cars near the built-in one, each with digressive,
asymmetric damper curves (rebound 2:1, knee 0.1 m/s, 0.4 of the slope above
it) at the ten default knots:

* cost per candidate-sample of ``NonlinearSimulator.errors`` against
  ``BatchSimulator.errors`` (the linear exact-discretisation kernel) on the
  same runs in the same process, one thread and every core, as a ratio
  (goal <= 3x, issue 37), with the current kernel (four candidates per
  ``<4 x double>``, :mod:`rideid.model.kernel_nl_ir`) and the one before it
  (one candidate at a time, ``kernel_nl_before.py``), both with the default
  integration (RK4 sub-steps split at the kinks, ``RHO_MAX``); for comparison
  plain RK4 sub-steps of the same accuracy (``rho = 0.03``);
* the same ratio for the compiled kernels alone (no coefficient, sub-step or
  discretisation work in Python), one thread;
* against SciPy ``solve_ivp`` (DOP853, rtol 1e-8) on the same equations, per
  candidate: one run, scaled to all runs by their samples;
* the states of one car over every run (``NonlinearSimulator.states``: what
  the bump stops' reach, the knots' excitation and the report's velocity
  histograms read) against the NumPy backend;
* the kernel's compile time in a fresh process with an empty Numba cache.

Timings are the best of interleaved repeats (the machine may be shared).
Run: ``make bench`` (or ``python benchmarks/bench_nonlinear.py``; ``--quick``
leaves out SciPy, the NumPy states and the compile time).
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from rideid.data.scenario import default_scenario, run_times
from rideid.model import kernel, kernel_nl
from rideid.model import nonlinear as nl
from rideid.model.batch import BatchSimulator
from rideid.model.nonlinear import DEFAULT_KNOTS, NonlinearLayout, NonlinearSimulator
from rideid.verify.hifi import hifi_curve
from rideid.model.params import ALL_NAMES, SUSPENSION_NAMES, as_vector
from rideid.model.simulate import prepare_run

sys.path.insert(0, str(Path(__file__).parent))
import kernel_nl_before  # noqa: E402

N_POP = 64


def best(f, repeat=3):
    f()
    b = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        b = min(b, time.perf_counter() - t)
    return b


def interleaved(fs: dict, repeat=5, clock=time.perf_counter):
    """Best time of each function of ``fs``, their repeats taken in turn (a shared machine's load then
    weighs on all alike); ``clock``: wall time, or ``time.process_time`` (this process's CPU time: on one
    thread, the cost itself, whatever else the machine runs)."""
    for f in fs.values():
        f()
    b = {k: np.inf for k in fs}
    for _ in range(repeat):
        for k, f in fs.items():
            t = clock()
            f()
            b[k] = min(b[k], clock() - t)
    return b


@contextlib.contextmanager
def kernel_before():
    """The nonlinear simulators use the scalar kernel of before (``kernel_nl_before.py``) meanwhile."""
    module = nl.backend.module
    nl.backend.module = lambda name: kernel_nl_before if name == "nonlinear" else module(name)
    try:
        yield
    finally:
        nl.backend.module = module


COLD = ("import time, json; t = time.perf_counter(); from rideid.model import kernel_nl; "
        "kernel_nl.compile_kernel(); print(json.dumps({'seconds': time.perf_counter() - t}))")


def cold_compile():
    """Seconds (wall, and the process's CPU time: on a shared machine the wall time waits for the others) to
    import and compile the nonlinear kernel in a fresh process with an empty Numba cache."""
    import resource
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        r = subprocess.run([sys.executable, "-c", COLD], env=env, capture_output=True, text=True, check=True)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return json.loads(r.stdout.strip().splitlines()[-1])["seconds"], cpu


def kernel_args(sim, P, Y, W):
    """The arguments of :func:`rideid.model.kernel_nl.run` for population ``P`` (as the simulator makes them)."""
    P = sim.layout.rows(P)
    ms = sim.substeps(P)
    co, xk, Fk, Sk = nl.coefficients(P, sim.geom, sim.layout)
    X0 = np.stack([nl.shifted(co, nl.initial_state(P, sim.geom, sim.layout, r.u[0]), r.u[0]) for r in sim.runs])
    return ((co, xk, Fk, Sk, True, X0, sim.run_start, np.array([r.h for r in sim.runs]), np.array(ms),
             [sim.fine(i, m) for i, m in enumerate(ms)], Y, W, 0), {"kinks": sim.kinks(P)})


def setup():
    sc = default_scenario()
    runs = [prepare_run(sc.tracks[r.track], sc.geometry, r.speed, run_times(r)) for r in sc.runs]
    P16 = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)[:len(SUSPENSION_NAMES)]
    rng = np.random.default_rng(1)
    P = P16 * rng.uniform(0.95, 1.05, (N_POP, P16.size))
    layout = NonlinearLayout(knots=DEFAULT_KNOTS)
    Ff = np.stack([hifi_curve(c, DEFAULT_KNOTS, 2.0, 0.1, 0.4) for c in P[:, 8]])
    Fr = np.stack([hifi_curve(c, DEFAULT_KNOTS, 2.0, 0.1, 0.4) for c in P[:, 9]])
    return sc, runs, P, np.concatenate([P, Ff, Fr], axis=1), layout


def scipy_per_candidate(geom, run, Pn, layout, rtol=1e-8):
    from scipy.integrate import solve_ivp

    co, xk, Fk, Sk = nl.coefficients(Pn[:1], geom, layout)
    X0 = nl.shifted(co, nl.initial_state(Pn[:1], geom, layout, run.u[0]), run.u[0])[0]

    def rhs(t, X):
        u, ud = run.inputs_at(np.array([t]))
        dX, _ = nl.accelerations(co, xk, Fk, Sk, True, X[None], u[0], ud[0])
        return dX[0]

    t = time.perf_counter()
    sol = solve_ivp(rhs, (0, run.t[-1]), X0, method="DOP853", t_eval=run.t, rtol=rtol, atol=1e-12,
                    max_step=run.h)
    return time.perf_counter() - t, sol.nfev


def main(out=sys.stdout, quick=None):
    quick = ("--quick" in sys.argv[1:]) if quick is None else quick
    sc, runs, P, Pn, layout = setup()
    geom = sc.geometry
    n_samples = sum(r.n for r in runs)
    cs = N_POP * n_samples  # candidate-samples per call
    lin = BatchSimulator(geom, runs)
    Y = np.concatenate([o[0] for o in lin.outputs(P[:1])])
    W = np.ones((len(runs), 10))
    split = NonlinearSimulator(geom, runs, layout)
    plain = NonlinearSimulator(geom, runs, layout, rho=0.03, split=False)

    def before():
        with kernel_before():
            split.errors(Pn, Y, W)

    out.write(f"# Nonlinear car (damper curves) vs the linear kernel\n\n{len(runs)} runs of the built-in "
              f"scenario, {n_samples} samples, {N_POP} candidates with digressive curves; ns per candidate-sample, "
              f"best of interleaved repeats (one thread: CPU time; every core: wall time)\n\n")
    out.write("| threads | linear | curves (split, RHO_MAX) | ratio | before: scalar kernel | ratio | "
              "plain RK4, rho=0.03 | ratio |\n|---|---|---|---|---|---|---|---|\n")
    all_threads = numba.get_num_threads()
    res = {}
    for th in sorted({1, all_threads}):
        numba.set_num_threads(th)
        b = interleaved({"linear": lambda: lin.errors(P, Y, W), "split": lambda: split.errors(Pn, Y, W),
                         "before": before, "plain": lambda: plain.errors(Pn, Y, W)}, repeat=5 if th == 1 else 3,
                        clock=time.process_time if th == 1 else time.perf_counter)
        ns = {k: v / cs * 1e9 for k, v in b.items()}
        res[th] = {k: ns[k] / ns["linear"] for k in ns}
        out.write(f"| {th} | {ns['linear']:.0f} | {ns['split']:.0f} (m = {sorted(set(split.substeps(Pn)))}) | "
                  f"**{res[th]['split']:.1f}x** | {ns['before']:.0f} | {res[th]['before']:.1f}x | {ns['plain']:.0f} "
                  f"(m = {sorted(set(plain.substeps(Pn)))}) | {res[th]['plain']:.1f}x |\n")
    numba.set_num_threads(all_threads)
    out.write("\ndamper-curve cost per candidate-sample / the linear kernel's, same runs, same process: "
              + ", ".join(f"{th} thread{'s' if th > 1 else ''} {r['split']:.1f}x (before {r['before']:.1f}x)"
                          for th, r in res.items()) + " (goal <= 3x)\n")

    # the compiled kernels alone, one thread
    numba.set_num_threads(1)
    fn = kernel.compiled_kernel()
    CO, nt, X0 = lin._pack(P)
    n_chunks = N_POP // kernel.LANES

    def linear_kernel():
        fn(0, n_chunks, CO, n_chunks, nt, geom.corner_y[0], geom.corner_y[2], X0, lin.run_start, lin.run_group,
           lin.UD, lin.RD, lin.MU, Y, W, 0, np.zeros((len(runs), N_POP)), np.zeros((1, 10, 1)))

    args, kw = kernel_args(split, Pn, Y, W)
    b = interleaved({"linear": linear_kernel, "curves": lambda: kernel_nl.run(*args, **kw),
                     "before": lambda: kernel_nl_before.run(*args, **kw)}, repeat=5, clock=time.process_time)
    ns = {k: v / cs * 1e9 for k, v in b.items()}
    res["kernels"] = {k: ns[k] / ns["linear"] for k in ns}
    numba.set_num_threads(all_threads)
    out.write(f"compiled kernels alone, one thread: linear {ns['linear']:.0f}, curves {ns['curves']:.0f} "
              f"({res['kernels']['curves']:.1f}x), before {ns['before']:.0f} ({res['kernels']['before']:.1f}x) ns "
              f"per candidate-sample\n")
    if quick:
        return res
    # SciPy on the shortest run, scaled by samples
    ri = int(np.argmin([r.n for r in runs]))
    ts, nfev = scipy_per_candidate(geom, runs[ri], Pn, layout)
    ts_all = ts * n_samples / runs[ri].n
    numba.set_num_threads(1)
    tn1 = best(lambda: split.errors(Pn, Y, W)) / N_POP
    numba.set_num_threads(all_threads)
    res["scipy"] = ts_all / tn1
    out.write(f"\nSciPy solve_ivp (DOP853, rtol 1e-8) on run {runs[ri].t.size} samples: {ts:.2f} s "
              f"({nfev} evaluations), {ts_all:.1f} s per candidate for all runs; compiled kernel on one thread "
              f"{tn1 * 1e3:.2f} ms per candidate: {ts_all / tn1:.0f}x faster\n")
    # the states of one car over every run (the bump stops' reach, the knots' excitation, the report's
    # suspension velocities): the compiled kernel against the NumPy backend
    ts_np = best(lambda: split.states_reference(Pn[:1]), repeat=1)
    ts_c = best(lambda: split.states(Pn[:1]))
    res["states"] = ts_np / ts_c
    out.write(f"\nstates of one car over all runs (channels and states): NumPy backend {ts_np:.2f} s, compiled "
              f"kernel {ts_c * 1e3:.1f} ms: {ts_np / ts_c:.0f}x faster\n")
    wall, cpu = res["compile"] = cold_compile()
    out.write(f"\nkernel compile time, fresh process and empty Numba cache (import included): {wall:.1f} s wall, "
              f"{cpu:.1f} s CPU (target <= 20 s; from the cache: well under a second)\n")
    return res


if __name__ == "__main__":
    main()
