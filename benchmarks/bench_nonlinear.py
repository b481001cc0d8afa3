"""Cost of the nonlinear car (damper curves, SPEC §8) against the linear kernel and against SciPy.

On the built-in scenario's runs (``rideid.data.scenario.default_scenario()``),
a population of 64 cars near the built-in one, each with digressive,
asymmetric damper curves (rebound 2:1, knee 0.1 m/s, 0.4 of the slope above
it) at the ten default knots:

* cost per candidate of ``NonlinearSimulator.errors`` against
  ``BatchSimulator.errors`` (the linear exact-discretisation kernel) on the
  same runs, one thread and every core, as a ratio (goal <= 3x), with the
  default integration (RK4 sub-steps split at the kinks, ``RHO_MAX``: the
  accuracy the tests prove on severe runs) and, for comparison, with the
  previous one of the same accuracy (plain RK4 sub-steps, ``rho = 0.03``);
* against SciPy ``solve_ivp`` (DOP853, rtol 1e-8) on the same equations, per
  candidate (goal >= 100x faster): one run, scaled to all runs by their samples;
* the states of one car over every run (``NonlinearSimulator.states``: what
  the bump stops' reach, the knots' excitation and the report's velocity
  histograms read) against the NumPy backend that gave them before.

Run: ``make bench`` (or ``python benchmarks/bench_nonlinear.py``).
"""

from __future__ import annotations

import sys
import time

import numba
import numpy as np

from rideid.data.scenario import default_scenario, run_times
from rideid.model import nonlinear as nl
from rideid.model.batch import BatchSimulator
from rideid.model.nonlinear import DEFAULT_KNOTS, NonlinearLayout, NonlinearSimulator
from rideid.verify.hifi import hifi_curve
from rideid.model.params import ALL_NAMES, as_vector
from rideid.model.simulate import prepare_run

N_POP = 64


def best(f, repeat=3):
    f()
    b = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        b = min(b, time.perf_counter() - t)
    return b


def setup():
    sc = default_scenario()
    runs = [prepare_run(sc.tracks[r.track], sc.geometry, r.speed, run_times(r)) for r in sc.runs]
    P16 = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)
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


def main(out=sys.stdout):
    sc, runs, P, Pn, layout = setup()
    geom = sc.geometry
    n_samples = sum(r.n for r in runs)
    lin = BatchSimulator(geom, runs)
    Y = np.concatenate([o[0] for o in lin.outputs(P[:1])])
    W = np.ones((len(runs), 10))
    sims = {f"split, RHO_MAX={nl.RHO_MAX}": NonlinearSimulator(geom, runs, layout),
            "plain RK4, rho=0.03": NonlinearSimulator(geom, runs, layout, rho=0.03, split=False)}
    out.write(f"# Nonlinear car (damper curves) vs the linear kernel\n\n{len(runs)} runs of the built-in "
              f"scenario, {n_samples} samples, {N_POP} candidates\n\n")
    out.write("| threads | linear us/cand | nonlinear | us/cand | sub-steps | ratio |\n|---|---|---|---|---|---|\n")
    all_threads = numba.get_num_threads()
    res = {}
    for th in sorted({1, all_threads}):
        numba.set_num_threads(th)
        tl = best(lambda: lin.errors(P, Y, W)) / N_POP
        for name, sim in sims.items():
            tn = best(lambda sim=sim: sim.errors(Pn, Y, W)) / N_POP
            res[(th, name)] = tn / tl
            out.write(f"| {th} | {tl * 1e6:.0f} | {name} | {tn * 1e6:.0f} | {sorted(set(sim.substeps(Pn)))} "
                      f"| {tn / tl:.1f}x |\n")
    numba.set_num_threads(all_threads)
    # SciPy on the shortest run, scaled by samples
    ri = int(np.argmin([r.n for r in runs]))
    ts, nfev = scipy_per_candidate(geom, runs[ri], Pn, layout)
    ts_all = ts * n_samples / runs[ri].n
    numba.set_num_threads(1)
    tn1 = best(lambda: sims[f"split, RHO_MAX={nl.RHO_MAX}"].errors(Pn, Y, W)) / N_POP
    numba.set_num_threads(all_threads)
    out.write(f"\nSciPy solve_ivp (DOP853, rtol 1e-8) on run {runs[ri].t.size} samples: {ts:.2f} s "
              f"({nfev} evaluations), {ts_all:.1f} s per candidate for all runs; compiled kernel on one thread "
              f"{tn1 * 1e3:.2f} ms per candidate: {ts_all / tn1:.0f}x faster\n")
    # the states of one car over every run (the bump stops' reach, the knots' excitation, the report's
    # suspension velocities): the compiled kernel against the NumPy backend it replaced there
    sim = NonlinearSimulator(geom, runs, layout)
    ts_np = best(lambda: sim.states_reference(Pn[:1]), repeat=1)
    ts_c = best(lambda: sim.states(Pn[:1]))
    res["states"] = ts_np / ts_c
    out.write(f"\nstates of one car over all runs (channels and states): NumPy backend {ts_np:.2f} s, compiled "
              f"kernel {ts_c * 1e3:.1f} ms: {ts_np / ts_c:.0f}x faster\n")
    return res


if __name__ == "__main__":
    main()
