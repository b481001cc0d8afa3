"""Speed as driven (SPEC §11) on the independent simulator of tests/asbuilt_tracks.py.

The SUV drives the five runs of :data:`asbuilt_tracks.RUNS` over the exact drawings (amplitude 1, no
unevenness) while the driver wanders +-3 % around each run's nominal speed: two sines of 1.5 % each, periods
2-6 s and phases drawn from a seeded Generator. The front wheels are at x(t) = the closed-form integral of
that speed, the rear ones a wheelbase behind (SciPy ``lsim`` of the 7-DOF car written from SPEC §1, rigid-disc
envelope), so the 7-DOF model is exact apart from the speed. Each run file is a CSV at 200 Hz whose first
:data:`OFFSET` s roll on the flat road before the front axle reaches x = 0 (the start, left for rideid to
estimate), with 1 % white sensor noise and a ``speed`` column logged at 10 Hz (every 20th row; the empty cells
between are "not sampled", docs/real-data.md), exact or with white noise as a GPS gives.
"""

from __future__ import annotations

import csv
import math

import numpy as np
import tomli_w

from asbuilt_tracks import CHANNELS, FS, RUNS, TRACKS, simulate_run
from cars import SUV_TOTAL_MASS, SUV_TRUTH, SUV_VEHICLE

#: file time (s) at which the front axle reaches x = 0; the car rolls on the flat road before it
OFFSET = 1.0
#: the speed channel's rate (Hz)
SPEED_FS = 10.0
#: each of the two sines' share of the nominal speed (together +-3 %)
WANDER = 0.015


def speed_profile(rng, v0: float, wander: float = WANDER):
    """A driver's speed ``v(T)`` (m/s) around ``v0`` at file time ``T`` (two sines of ``wander`` x ``v0``
    each) and the front axle's distance ``x(T)`` (its exact integral, 0 at ``T = OFFSET``)."""
    periods, phases = rng.uniform(2.0, 6.0, 2), rng.uniform(0.0, 2 * np.pi, 2)

    def v(T):
        T = np.asarray(T, dtype=float)
        return v0 * (1 + wander * sum(np.sin(2 * np.pi * T / p + f) for p, f in zip(periods, phases)))

    def integral(T):
        T = np.asarray(T, dtype=float)
        return v0 * (T - wander * sum(p / (2 * np.pi) * np.cos(2 * np.pi * T / p + f)
                                      for p, f in zip(periods, phases)))

    x0 = float(integral(OFFSET))
    return v, (lambda T: integral(T) - x0)


def write_case(folder, *, seed=1, gps_noise=0.03, noise=0.01, speed_channel=True, speed_column=True,
               wander=WANDER, runs=RUNS, tracks=TRACKS):
    """Write the case as a rideid dataset in ``folder``: each run's CSV carries the ``speed`` column (10 Hz,
    white noise of ``gps_noise`` m/s; left out when not ``speed_column``), mapped in ``[channels]`` when
    ``speed_channel``; otherwise each run declares its constant nominal ``speed`` (the wander ignored). The
    driver wanders by two sines of ``wander`` each (0: the speed held). The same ``seed`` gives the same wander
    and sensor noise whatever ``gps_noise``, ``speed_channel`` and ``speed_column`` are. Returns ``{run id:
    (v, x)}``, the speed and distance as driven (functions of file time)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "runs").mkdir(exist_ok=True)
    by_id = {tr["id"]: tr for tr in tracks}
    used = sorted({r[1] for r in runs})
    doc = {"name": "suv-speed-as-driven", "vehicle": dict(SUV_VEHICLE), "known": {"total_mass": SUV_TOTAL_MASS},
           "channels": ({"speed": {"name": "speed", "unit": "m/s"}} if speed_channel
                        else {"time": {"name": "time", "unit": "s"}}),
           "tracks": [by_id[t] for t in used], "runs": []}
    driven = {}
    every = int(round(FS / SPEED_FS))
    for rid, tid, v0, duration in runs:
        v, x = speed_profile(rng, v0, wander)
        driven[rid] = (v, x)
        t, y, _ = simulate_run(by_id, (rid, tid, v0, OFFSET + duration), amplitude=1.0, rms=0.0, rng=rng,
                               distance=x)
        y = y + rng.standard_normal(y.shape) * noise * np.sqrt(np.mean(y ** 2, axis=0))
        k10 = np.arange(0, t.size, every)
        gps = v(t[k10]) + gps_noise * rng.standard_normal(k10.size)
        with open(folder / "runs" / f"{rid}.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(("time",) + CHANNELS + (("speed",) if speed_column else ()))
            j = 0
            for k in range(t.size):
                cell = ""
                if j < k10.size and k10[j] == k:
                    cell, j = f"{gps[j]:.6f}", j + 1
                w.writerow([f"{t[k]:.6f}"] + [f"{val:.9e}" for val in y[k]] + ([cell] if speed_column else []))
        entry = {"id": rid, "track": tid, "file": f"runs/{rid}.csv"}
        if not speed_channel:
            entry["speed"] = v0
        doc["runs"].append(entry)
    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
    return driven


def scores(res, truth=SUV_TRUTH):
    """The twelve's relative errors, and how many of the estimated ones +-2 ``std_robust`` and +-2 ``std_total``
    cover: ``(errors, covered_robust, covered_total, estimated)``."""
    err = {n: (res.parameters[n] - truth[n]) / truth[n] for n in truth}
    est = [n for n in truth if res.details.get(n, {}).get("std_robust")]
    cov_r = sum(abs(res.parameters[n] - truth[n]) <= 2 * res.details[n]["std_robust"] for n in est)
    cov_t = sum(abs(res.parameters[n] - truth[n]) <= 2 * res.details[n].get("std_total", math.inf) for n in est)
    return err, cov_r, cov_t, len(est)
