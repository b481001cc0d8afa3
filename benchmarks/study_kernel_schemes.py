"""How far the damper kernel's cheaper integration settings would move the estimates, in the fit's std.

On the built-in scenario's ten runs (9470 samples at 200 Hz), three cars with
digressive, asymmetric damper curves at the ten default knots (rebound 2:1,
knee 0.1 m/s, 0.4 of the slope above it, as ``bench_nonlinear.py``): the
built-in car ("sedan"), the same with anti-roll bars ("bars", free
``k_arf, k_arr``) and with bump stops at 30 mm, 50 kN/m ("stops", known).
The free parameters: the twelve less ``c_sf, c_sr`` (the curves replace them),
the bars where the car has them, and the twenty knot forces.

Each integration scheme ``S`` (RK4 sub-steps ``m`` per sample, split at the
kinks or plain) simulates the channels ``y_S`` at the true car. Today's
estimates are the polish's, whose scheme is the default's sub-steps times
1.5 (:meth:`rideid.model.nonlinear.NonlinearSimulator.pin_at`: m = 3, every
interior knot split). The estimate a scheme would move to, to first order, is
the Gauss-Newton step of the reference's whitened Jacobian ``J`` (forward
differences, relative step 1e-6) on ``y_S - y_ref``; the fit's std is
``sqrt(diag((J^T J)^-1))`` with noise of 1 % of each channel's RMS in each run
(``rideid simulate --noise 0.01``). Printed: each scheme's largest move over
the parameters in std, the parameter, and the scheme's output error
(largest over runs and channels, relative to the channel's RMS).

Run: ``python benchmarks/study_kernel_schemes.py [car ...]`` (one thread; measured 9 s of CPU for the three cars,
import included).
"""

from __future__ import annotations

import sys

import numba
import numpy as np

from rideid.data.scenario import default_scenario, run_times
from rideid.model.nonlinear import DEFAULT_KNOTS, NonlinearLayout, NonlinearSimulator, Pin, curve_names
from rideid.model.params import SUSPENSION_NAMES, as_vector
from rideid.model.simulate import prepare_run
from rideid.verify.hifi import hifi_curve

#: (m, split) of each scheme; the reference (today's polish) first
SCHEMES = {"polish today: split m=3": (3, True), "search today: split m=2": (2, True),
           "split m=1": (1, True), "plain m=2": (2, False), "plain m=1": (1, False),
           "fine: split m=24": (24, True)}
CARS = {"sedan": ({}, False), "bars": ({"k_arf": 9000.0, "k_arr": 4000.0}, False), "stops": ({}, True)}
NOISE = 0.01
STOPS = [0.03, 0.03, 50e3, 50e3]


def car(name, sc):
    extra, stops = CARS[name]
    layout = NonlinearLayout(knots=DEFAULT_KNOTS, bump_stops=stops)
    truth = {n: sc.truth.get(n, 0.0) for n in SUSPENSION_NAMES}
    truth.update(extra)
    P16 = as_vector(truth, extended=True)[:len(SUSPENSION_NAMES)]
    Ff = hifi_curve(truth["c_sf"], DEFAULT_KNOTS, 2.0, 0.1, 0.4)
    Fr = hifi_curve(truth["c_sr"], DEFAULT_KNOTS, 2.0, 0.1, 0.4)
    row = np.concatenate([P16, STOPS if stops else [], Ff, Fr])
    names = list(SUSPENSION_NAMES[:12]) + list(extra) + list(curve_names(len(DEFAULT_KNOTS)))
    names = [n for n in names if n not in ("c_sf", "c_sr")]
    return layout, row, [layout.names.index(n) for n in names], names


def study(name, sc, runs, out=sys.stdout):
    layout, row, free, names = car(name, sc)
    sim = NonlinearSimulator(sc.geometry, runs, layout, rho=1e9)  # the pin sets the sub-steps
    mask = sim.kinks(row[None])
    mask[:, 1:-1] = 1
    n_runs = len(runs)

    def outputs(P, m, split):
        s = sim if split else NonlinearSimulator(sc.geometry, runs, layout, rho=1e9, split=False)
        return np.concatenate(s.outputs(P, Pin((m,) * n_runs, mask)), axis=1)  # (n, T, 10)

    m0, split0 = next(iter(SCHEMES.values()))
    y0 = outputs(row[None], m0, split0)[0]
    # noise: 1 % of each channel's RMS in each run
    sig = np.concatenate([np.broadcast_to(NOISE * np.sqrt(np.mean(y0[a:b] ** 2, axis=0)), (b - a, 10))
                          for a, b in zip(sim.run_start[:-1], sim.run_start[1:])])
    rms = sig / NOISE
    # a channel that stays still in a run (a symmetric run's roll) carries no weight
    ok = rms > 1e-9 * rms.max(axis=0)
    inv = np.where(ok, 1.0 / np.where(ok, sig, 1.0), 0.0)
    dx = 1e-6 * np.maximum(np.abs(row[free]), 1.0)
    Pj = np.repeat(row[None], len(free), axis=0)
    Pj[np.arange(len(free)), free] += dx
    J = ((outputs(Pj, m0, split0) - y0) / dx[:, None, None] * inv).reshape(len(free), -1).T
    _, sv, Vt = np.linalg.svd(J, full_matrices=False)
    cov = (Vt.T / sv ** 2) @ Vt
    std = np.sqrt(np.diag(cov))
    out.write(f"\n## {name}: {len(free)} free parameters, cond(J) {sv[0] / sv[-1]:.1e}\n\n"
              "| scheme | output error (of RMS) | largest move (std) | parameter | moves > 0.1 std |\n"
              "|---|---|---|---|---|\n")
    res = {}
    for label, (m, split) in SCHEMES.items():
        y = outputs(row[None], m, split)[0]
        err = max(float(np.max(np.sqrt(np.mean((y[a:b] - y0[a:b]) ** 2, axis=0)) * inv[a] * NOISE))
                  for a, b in zip(sim.run_start[:-1], sim.run_start[1:]))
        r = ((y - y0) * inv).reshape(-1)
        move = cov @ (J.T @ r) / std
        k = int(np.argmax(np.abs(move)))
        res[label] = (err, float(np.abs(move).max()))
        out.write(f"| {label} | {err:.1e} | {abs(move[k]):.3f} | {names[k]} | {int(np.sum(np.abs(move) > 0.1))} |\n")
    return res


def main(out=sys.stdout, cars=None):
    numba.set_num_threads(1)
    sc = default_scenario()
    runs = [prepare_run(sc.tracks[r.track], sc.geometry, r.speed, run_times(r)) for r in sc.runs]
    return {c: study(c, sc, runs, out) for c in (cars or CARS)}


if __name__ == "__main__":
    main(cars=sys.argv[1:] or None)
