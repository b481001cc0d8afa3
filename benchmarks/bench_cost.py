"""Cost of scoring candidate cars on the built-in 10-run dataset.

Compares, in the same run:

* rideid's compiled kernel (a population of 64 at once);
* a plain SciPy user: ``scipy.signal.lsim`` per candidate and run, (a) at the
  data rate with its first-order hold (inaccurate: the envelope is not linear
  between samples) and (b) on an input grid fine enough for 1e-4 relative
  RMS accuracy, the accuracy rideid delivers;
* ``scipy.integrate.solve_ivp`` (RK45, rtol 1e-6) per candidate and run.

Also: candidate-samples per second, the share of the machine's
floating-point peak, scaling with population size and run length.

Run: ``make bench`` (or ``python benchmarks/bench_cost.py``).
"""

from __future__ import annotations

import os
import sys
import time
import warnings

import numpy as np
import scipy.integrate
import scipy.signal

import rideid
from rideid.model.contact import envelope
from rideid.estimate.problem.cost import CostFunction
from rideid.model.batch import BatchSimulator, single_threaded_blas
from rideid.model.equations import state_space, static_state
from rideid.data.scenario import run_times
from rideid.synth.scenario import simulate_manifest, write_dataset
from rideid.model.simulate import corner_positions, prepare_run, simulate_lsim


def timeit(f, repeat=3, number=1):
    f()
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(number):
            f()
        best = min(best, (time.perf_counter() - t) / number)
    return best


def cpu_peak_gflops():
    """2 cores x clock x double-precision flops per cycle (AVX-512 or AVX2 FMA, 2 pipes)."""
    mhz = 0.0
    flags = ""
    try:
        with open("/proc/cpuinfo") as f:
            for ln in f:
                if ln.startswith("cpu MHz"):
                    mhz = max(mhz, float(ln.split(":")[1]))
                if ln.startswith("flags"):
                    flags = ln
    except OSError:
        pass
    width = 8 if "avx512f" in flags else (4 if "avx2" in flags else 2)
    per_cycle = width * 2 * 2  # FMA = 2 flops, 2 FMA pipes
    return os.cpu_count() * mhz / 1e3 * per_cycle, mhz, width


def lsim_run(P, geom, track, speed, t, upsample):
    return simulate_lsim(P, geom, track, speed, t, upsample=upsample, exact_envelope=False)


def solve_ivp_run(P, geom, track, speed, t):
    A, B, Cy, Dy = state_space(np.atleast_2d(P), geom)
    A, B, Cy, Dy = A[0], B[0], Cy[0], Dy[0]
    tf = np.linspace(t[0], t[-1], (t.size - 1) * 20 + 1)
    xs = corner_positions(geom, speed * tf)
    u = np.stack([envelope(track.path(y).h, xs[:, i], geom.tire_radius) for i, y in enumerate(geom.corner_y)], -1)

    def rhs(tt, x):
        ui = np.array([np.interp(tt, tf, u[:, i]) for i in range(4)])
        return A @ x + B @ ui

    sol = scipy.integrate.solve_ivp(rhs, (t[0], t[-1]), static_state(A[None], B[None], u[0])[0], t_eval=t,
                                    method="RK45", rtol=1e-6, atol=1e-9)
    return sol.y.T @ Cy.T


#: an SUV-like set of extensions (bar rates at the wheel, tire damping)
EXTENSIONS = {"k_arf": 15600.0, "k_arr": 6000.0, "c_tf": 180.0, "c_tr": 200.0}


def extended_cost_ratio(cf, X, repeat=5):
    """Seconds per candidate of the simulation-and-error kernel, base (12) vs extended (16) rows."""
    from rideid.model.params import EXT_NAMES, full_rows

    P12 = cf.space.full(X)[:, :12]
    P16 = full_rows(P12)
    P16[:, 12:] = [EXTENSIONS[n] for n in EXT_NAMES]
    with single_threaded_blas():
        tb = timeit(lambda: cf.sim.errors(P12, cf.Y, cf.W), repeat=repeat)
        te = timeit(lambda: cf.sim.errors(P16, cf.Y, cf.W), repeat=repeat)
    n = X.shape[0]
    return {"base": tb / n, "ext": te / n, "ratio": te / tb}


def main(out=sys.stdout):
    def say(*a):
        print(*a, file=out, flush=True)

    sc = rideid.default_scenario()
    geom = sc.geometry
    P0 = np.array([sc.truth[n] for n in rideid.NAMES])
    runs = [(r, sc.tracks[r.track], run_times(r)) for r in sc.runs]
    n_samples = sum(t.size for _, _, t in runs)
    say(f"## Cost per candidate: built-in dataset, {len(runs)} runs, {n_samples} samples\n")

    # rideid kernel, population of 64
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data, _ = simulate_manifest(sc, noise=0.0)
        write_dataset(sc, data, d)
        ds = rideid.load_dataset(d)
        t0 = time.perf_counter()
        cf = CostFunction(ds)
        prep = time.perf_counter() - t0
    rng = np.random.default_rng(1)
    X = np.array([[sc.truth[n] for n in cf.names]]) * np.exp(rng.normal(0, 0.05, (64, len(cf.names))))
    with single_threaded_blas():
        t_pop = timeit(lambda: cf.run_errors(X), repeat=5)
    per_cand = t_pop / 64
    say(f"dataset preparation (envelopes, input moments): {prep:.2f} s, once per dataset")
    say(f"rideid kernel: {t_pop * 1e3:.1f} ms per population of 64 -> {per_cand * 1e3:.3f} ms per candidate, "
        f"{64 * n_samples / t_pop / 1e6:.1f} M candidate-samples/s")

    # flops: (210 + 28 N) multiply-adds per candidate-sample (see rideid.model.kernel)
    N = 10
    flops = 2 * (210 + 28 * N) * 64 * n_samples / t_pop
    peak, mhz, width = cpu_peak_gflops()
    if peak > 0:
        say(f"arithmetic: {flops / 1e9:.1f} GFLOP/s = {100 * flops / 1e9 / peak:.0f} % of the {peak:.0f} GFLOP/s peak "
            f"({os.cpu_count()} cores x {mhz:.0f} MHz x {width}-wide FMA x 2 pipes)")

    # the extended model (SPEC §6: anti-roll bars and tire damping) on the same data
    ext = extended_cost_ratio(cf, X)
    say(f"extended model (bars + tire damping, 16 parameters): {ext['ext'] * 1e3:.3f} ms per candidate vs "
        f"{ext['base'] * 1e3:.3f} ms base (simulation only): {ext['ratio']:.2f}x (target <= 1.3x)")

    # accuracy of lsim at the data rate and upsampled, against a 200x reference
    r0, tr0, t0_ = runs[6]  # H_HL: herringbone, the hardest input
    ref = simulate_lsim(P0, geom, tr0, r0.speed, t0_, upsample=200)
    y_k = cf.simulate(P0)[r0.id]

    def err(y):
        return float(np.max(np.sqrt(np.mean((y - ref) ** 2, 0)) / np.sqrt(np.mean(ref ** 2, 0))))

    acc = {1: err(lsim_run(P0, geom, tr0, r0.speed, t0_, 1))}
    up = 1
    while acc[up] > 1e-4 and up < 64:
        up *= 2
        acc[up] = err(lsim_run(P0, geom, tr0, r0.speed, t0_, up))
    say(f"\naccuracy on {r0.id} (max over channels of relative RMS error vs a 200x lsim reference):")
    say(f"  rideid: {err(y_k):.1e};  lsim: " + ", ".join(f"{k}x input grid {v:.1e}" for k, v in acc.items()))

    def lsim_all(factor):
        for r, tr, t in runs:
            lsim_run(P0, geom, tr, r.speed, t, factor)

    t_lsim1 = timeit(lambda: lsim_all(1), repeat=2)
    t_lsim_eq = timeit(lambda: lsim_all(up), repeat=1)
    # solve_ivp on one run, extrapolated per sample
    t_ivp_run = timeit(lambda: solve_ivp_run(P0, geom, tr0, r0.speed, t0_), repeat=1)
    t_ivp = t_ivp_run * n_samples / t0_.size
    say("\n| method (per candidate, all 10 runs) | time | rideid is faster by |")
    say("|---|---|---|")
    say(f"| rideid kernel (population of 64) | {per_cand * 1e3:.3f} ms | 1 |")
    say(f"| lsim at the data rate (inaccurate, {acc[1]:.0e}) | {t_lsim1 * 1e3:.1f} ms | {t_lsim1 / per_cand:.0f}x |")
    say(f"| lsim, {up}x input grid (equal accuracy) | {t_lsim_eq * 1e3:.1f} ms | {t_lsim_eq / per_cand:.0f}x |")
    say(f"| solve_ivp RK45 rtol 1e-6 (extrapolated from {r0.id}) | {t_ivp * 1e3:.0f} ms | {t_ivp / per_cand:.0f}x |")
    say(f"\nlsim per simulated sample: {t_lsim1 / n_samples * 1e6:.1f} us at the data rate")

    # scaling with population size
    say("\n## Scaling with population size (all 10 runs)\n")
    say("| population | ms per call | us per candidate |")
    say("|---|---|---|")
    with single_threaded_blas():
        for n in (1, 8, 32, 64, 128, 256, 512):
            Xn = np.resize(X, (n, X.shape[1]))
            t = timeit(lambda Xn=Xn: cf.run_errors(Xn), repeat=3)
            say(f"| {n} | {t * 1e3:.1f} | {t / n * 1e6:.0f} |")

    # scaling with run length
    say("\n## Scaling with run length (washboard, population 64)\n")
    say("| samples | ms per call | ns per candidate-sample |")
    say("|---|---|---|")
    wb = sc.tracks["washboard"]
    Pp = cf.space.full(X)
    with single_threaded_blas():
        for dur in (1.0, 4.0, 16.0, 64.0):
            t = np.arange(int(dur * 200) + 1) / 200
            sim = BatchSimulator(geom, [prepare_run(wb, geom, 10.0, t)])
            Y = np.zeros((t.size, 10))
            W = np.ones((1, 10))
            tt = timeit(lambda sim=sim, Y=Y, W=W: sim.errors(Pp, Y, W), repeat=3)
            say(f"| {t.size} | {tt * 1e3:.1f} | {tt / 64 / t.size * 1e9:.1f} |")


if __name__ == "__main__":
    main()
