"""Two methods for identifying the car on roads nobody measured (issue 26), on the same data.

* method 1 (default): frequency-domain variable projection, :mod:`rideid.estimate.problem.roadfit`;
* method 2: time-domain staged fit, :mod:`rideid.estimate.problem.roadstaged`.

Data: the built-in car driven over random ISO 8608 roads (class A, B, C;
displacement PSD ``Gd(n) = Gd(n0) (n / 0.1)^-2``, FFT synthesis on a 1 cm grid,
0.01-3 cycles/m, left and right partially coherent), written as a ``profile``
track and simulated with rideid's exact simulator at 30, 70 and 100 km/h,
200 Hz, 40 s recorded after a 5 s lead-in from rest, white noise 2 % of each
channel's RMS (``--noise floor``: a fixed sensor floor instead). One fit per
method and (class, seed) uses the three runs; both start from the same car
(truth x U(0.95, 1.05), seeded).

Run (one core, about 2 minutes)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/road_methods.py [--classes ABC] [--seeds 3] [--methods 12]

Prints one line per fit, then the table of docs/road-methods.md.
"""

from __future__ import annotations

import argparse


import os
import tempfile
import time
from dataclasses import replace

for _v in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402
import scipy.optimize  # noqa: E402

from rideid.data.scenario import default_scenario  # noqa: E402
from rideid.estimate.problem import roadstaged  # noqa: E402
from rideid.estimate.problem import roadfit  # noqa: E402
from rideid.model.params import ALL_NAMES, INDEX, NAMES, as_vector  # noqa: E402
from rideid.model.simulate import prepare_run, simulate_reference  # noqa: E402
from rideid.model.tracks import Track  # noqa: E402


#: ISO 8608 Gd(n0) at n0 = 0.1 cycles/m, m^3
ISO_GD = {"A": 16e-6, "B": 64e-6, "C": 256e-6}
SPEEDS_KMH = (30.0, 70.0, 100.0)
FS, DURATION, PRE, NOISE = 200.0, 40.0, 5.0, 0.02
#: the "floor" noise model: accelerometers (m/s^2) and gyros (rad/s), the same on every road
FLOOR = (0.05, 5e-4)
#: left/right correlation of the road at wavenumber n (cycles/m): exp(-n / COHERENCE_N)
COHERENCE_N = 0.2


def iso_road(gd: float, length: float, rng, dx: float = 0.01, band=(0.01, 3.0)):
    """Heights ``z_left``, ``z_right`` (m) on the grid ``x = k dx`` of a random ISO 8608 road.

    Each side has the one-sided displacement PSD ``gd (n/0.1)^-2`` in ``band`` (cycles/m);
    left and right share a common part with correlation ``exp(-n / COHERENCE_N)`` at
    wavenumber ``n`` (equal at long wavelengths, independent at short ones).
    """
    n = int(np.ceil(length / dx)) + 1
    nfft = 1 << int(np.ceil(np.log2(n)))
    f = np.fft.rfftfreq(nfft, dx)
    G = np.where((f >= band[0]) & (f <= band[1]), gd * (np.maximum(f, 1e-12) / 0.1) ** -2, 0.0)
    amp = np.sqrt(G * nfft / (2 * dx))          # one-sided PSD -> |rfft| (random phases: power G df per bin)

    def part():
        return amp * np.exp(2j * np.pi * rng.uniform(size=f.size))

    rho = np.exp(-f / COHERENCE_N)
    c, lf, r = part(), part(), part()
    zl = np.fft.irfft(np.sqrt(rho) * c + np.sqrt(1 - rho) * lf, nfft)[:n]
    zr = np.fft.irfft(np.sqrt(rho) * c + np.sqrt(1 - rho) * r, nfft)[:n]
    return np.arange(n) * dx, zl, zr


def make_run(road_class: str, speed_kmh: float, rng, workdir: str, name: str, noise_model: str = "rms"):
    """One noisy run (n, 10) of the built-in car on a fresh random road, recorded while moving, its
    speed (m/s) and the noise standard deviation of each channel (10,).

    ``noise_model``: ``"rms"``, white noise of :data:`NOISE` times each channel's RMS (rideid's
    ``--noise``); ``"floor"``, a sensor floor independent of the road: :data:`FLOOR` (m/s^2 for the
    accelerometers, rad/s for the gyros)."""
    sc = default_scenario()
    geom = sc.geometry
    v = speed_kmh / 3.6
    length = v * (PRE + DURATION) + geom.wheelbase + 5.0
    x, zl, zr = iso_road(ISO_GD[road_class], length, rng)
    # the rear axle starts (at rest, t = 0 of the simulation) 2 m into the profile
    x = x - (geom.wheelbase + 2.0)
    path = os.path.join(workdir, f"{name}.csv")
    np.savetxt(path, np.c_[x, zl, zr], delimiter=",", header="x,z_left,z_right", comments="", fmt="%.6f,%.9e,%.9e")
    track = Track.from_table({"id": name, "kind": "profile", "file": path}, "road_methods")
    t = np.arange(int(round((PRE + DURATION) * FS)) + 1) / FS
    run = prepare_run(track, geom, v, t)
    P = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    y = simulate_reference(P[None], geom, run)[0][int(round(PRE * FS)):]
    sd = NOISE * y.std(axis=0) if noise_model == "rms" else np.array([FLOOR[0]] * 8 + [FLOOR[1]] * 2)
    return y + sd * rng.standard_normal(y.shape), v, sd


def truth_and_geometry():
    sc = default_scenario()
    P = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    M = sum(c * P[INDEX[n]] for n, c in (("m_s", 1), ("m_uf", 2), ("m_ur", 2)))
    return P, sc.geometry, M


def start_car(P, seed):
    """The common start: truth x U(0.95, 1.05) for every one of the twelve, seeded."""
    u = np.random.default_rng(10_000 + seed).uniform(0.95, 1.05, len(NAMES))
    P0 = P.copy()
    P0[:len(NAMES)] *= u
    return P0


def method1(rf, ys, speeds, geom, M, P0, max_nfev=30, diff_step=1e-5):
    """Frequency-domain variable projection (roadfit), polished as the default pipeline polishes it
    (each run's residuals divided by their RMS at the start; trust-region least squares over
    log-parameters, Jacobian-scaled steps, m_s from the known total mass). Uncertainty as the default
    reports it: the sandwich with the fitted channels' (noise-free) Jacobian as bread and each DFT bin
    of each run as a cluster."""
    t0 = time.perf_counter()
    rrs = [rf.prepare_road_run(f"r{i}", y, FS, v, geom) for i, (y, v) in enumerate(zip(ys, speeds))]
    free = [n for n in NAMES if n != "m_s"]
    cols = [INDEX[n] for n in free]

    def full(lth):
        P = P0.copy()
        P[cols] = np.exp(lth)
        P[INDEX["m_s"]] = M - 2 * P[INDEX["m_uf"]] - 2 * P[INDEX["m_ur"]]
        return P

    lth0 = np.log(P0[cols])
    scale = [1.0 / np.sqrt(np.mean(rf.residuals(full(lth0), geom, rr) ** 2)) for rr in rrs]

    def res(lth, runs=rrs):
        P = full(lth)
        return np.concatenate([s * rf.residuals(P, geom, rr) for s, rr in zip(scale, runs)])

    sol = scipy.optimize.least_squares(res, lth0, method="trf", x_scale="jac", diff_step=diff_step,
                                       ftol=1e-12, xtol=1e-10, gtol=1e-12, max_nfev=max_nfev)
    lth = sol.x
    P = full(lth)
    # bread: the Jacobian of the fitted channels (data minus residual), noise-free to first order
    fitted = []
    for rr in rrs:
        Yh = rr.Y.copy()
        Yh[rr.fit] -= rf.solve(P, geom, rr).residual
        fitted.append(replace(rr, Y=Yh))
    Js = np.empty((sol.fun.size, lth.size))
    for j in range(lth.size):
        d = np.zeros(lth.size)
        d[j] = diff_step
        Js[:, j] = (res(lth + d, fitted) - res(lth - d, fitted)) / (2 * diff_step)
    J, e = sol.jac, sol.fun
    m, n = J.shape
    Hi = np.linalg.pinv(Js.T @ Js, rcond=1e-12, hermitian=True)
    S = np.zeros((n, n))
    off = 0
    for rr in rrs:
        sz = rr.fit.size * 2 * len(rr.cols)
        g = (J[off:off + sz] * e[off:off + sz, None]).reshape(-1, 2 * len(rr.cols), n).sum(1)
        S += g.T @ g
        off += sz
    cov = Hi @ S @ Hi * (m / (m - n))
    # delta method to the twelve (m_s derived)
    Gm = np.zeros((len(NAMES), n))
    for j, nm in enumerate(free):
        Gm[NAMES.index(nm), j] = P[INDEX[nm]]
    Gm[NAMES.index("m_s")] = [-2 * P[INDEX[nm]] if nm in ("m_uf", "m_ur") else 0.0 for nm in free]
    sd = np.sqrt(np.diag(Gm @ cov @ Gm.T))
    return {nm: P[INDEX[nm]] for nm in NAMES}, dict(zip(NAMES, sd)), time.perf_counter() - t0, sol.nfev


def method2(ys, speeds, geom, M, P0, noise=None, lowpass=roadstaged.LOWPASS_HZ):
    """Time-domain staged fit (roadstaged); ``noise``: per run, the channels' noise levels (default:
    proportional to each channel's RMS); ``lowpass``: the two stages' low-pass frequencies (Hz)."""
    t0 = time.perf_counter()
    noise = noise or [None] * len(ys)
    runs = [roadstaged.prepare_staged_run(f"r{i}", y, FS, v, geom, noise=sd, lowpass_hz=lowpass[0])
            for i, (y, v, sd) in enumerate(zip(ys, speeds, noise))]
    r = roadstaged.fit(runs, geom, M, P0, lowpass2_hz=lowpass[1])
    return r.parameters, r.std_robust, time.perf_counter() - t0, r.nfev


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--classes", default="ABC", help="ISO 8608 classes, e.g. ABC or B")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per class (1..N)")
    ap.add_argument("--methods", default="12",
                    help="methods to run: 1, 2, and k (method 2 told the sensors' true noise levels)")
    ap.add_argument("--m1-diff-step", type=float, default=1e-5,
                    help="method 1's finite-difference step (log-parameters; docs/road-methods.md: 1e-7 fails)")
    ap.add_argument("--m2-lowpass", default=",".join(f"{f:g}" for f in roadstaged.LOWPASS_HZ),
                    help="method 2's low-pass frequencies (Hz) of stage 1 and stage 2, e.g. 30,15")
    ap.add_argument("--noise", default="rms", choices=("rms", "floor"),
                    help="rms: 2 %% of each channel's RMS (default); floor: a fixed sensor floor, FLOOR")
    args = ap.parse_args(argv)
    P, geom, M = truth_and_geometry()
    rf = roadfit if "1" in args.methods else None
    rows = []   # (class, seed, method, errors %, std %, wall s)
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        for cls in args.classes:
            for seed in range(1, args.seeds + 1):
                rng = np.random.default_rng(1000 * "ABC".index(cls) + seed)
                tg = time.perf_counter()
                data = [make_run(cls, s, rng, work, f"{cls}{seed}_{int(s)}", args.noise) for s in SPEEDS_KMH]
                ys, speeds, sds = [d[0] for d in data], [d[1] for d in data], [d[2] for d in data]
                tg = time.perf_counter() - tg
                P0 = start_car(P, seed)
                for m in args.methods:
                    if m == "1":
                        est, sd, wall, nfev = method1(rf, ys, speeds, geom, M, P0, diff_step=args.m1_diff_step)
                    else:
                        est, sd, wall, nfev = method2(ys, speeds, geom, M, P0, sds if m == "k" else None,
                                                      tuple(float(f) for f in args.m2_lowpass.split(",")))
                    err = {n: 100 * (est[n] / P[INDEX[n]] - 1) for n in NAMES}
                    rel = {n: 100 * sd[n] / P[INDEX[n]] for n in NAMES}
                    rows.append((cls, seed, m, err, rel, wall))
                    print(f"{cls} seed {seed} method {m}: {wall:6.1f} s ({nfev} evals; data {tg:.1f} s)  "
                          + " ".join(f"{n}:{err[n]:+.2f}({err[n] / rel[n]:+.1f})" for n in NAMES), flush=True)
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s\n")
    print_table(rows, args)
    return rows


def print_table(rows, args):
    methods = [m for m in "12k" if m in args.methods]
    classes = list(args.classes)
    label = {"1": "M1", "2": "M2", "k": "M2k"}
    head = "| parameter |" + "".join(f" {c} {label[m]} err | {c} {label[m]} std |" for c in classes for m in methods)
    print("Error: RMS over seeds of (estimate / truth - 1), %; std: mean robust standard error, %.")
    print(f"In brackets: mean signed error, %. Noise model: {args.noise}.\n")
    print(head)
    print("|---|" + "---:|" * (2 * len(classes) * len(methods)))
    for n in NAMES:
        line = f"| {n} |"
        for c in classes:
            for m in methods:
                sel = [r for r in rows if r[0] == c and r[2] == m]
                e = np.array([r[3][n] for r in sel])
                s = np.array([r[4][n] for r in sel])
                line += f" {np.sqrt(np.mean(e ** 2)):.2f} ({np.mean(e):+.2f}) | {np.mean(s):.2f} |"
        print(line)
    line = "| wall time per fit, s |"
    for c in classes:
        for m in methods:
            sel = [r for r in rows if r[0] == c and r[2] == m]
            line += f" {np.mean([r[5] for r in sel]):.0f} | |"
    print(line)
    # honesty: share of |error| <= 2 std over all parameters and fits
    for m in methods:
        z = np.array([[r[3][n] / r[4][n] for n in NAMES] for r in rows if r[2] == m])
        print(f"\n{label[m]}: |error| <= 2 std_robust for {100 * np.mean(np.abs(z) <= 2):.0f} % of "
              f"{z.size} estimates; RMS of error/std {np.sqrt(np.mean(z ** 2)):.2f}")


if __name__ == "__main__":
    main()
