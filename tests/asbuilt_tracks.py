"""Tracks as built (SPEC §11): an independent simulator of the SUV of tests/cars.py driving over tracks that are
not their drawing, for the tests and benchmarks/bench_tracks.py.

Nothing here uses rideid's equations, tracks or contact model: the 7-DOF car is written from SPEC §1 as a
continuous state-space model and simulated by SciPy's ``lsim`` (exact discretisation of a first-order hold) on
a 2 kHz grid, the track shapes from SPEC §2, the rigid-disc envelope by a brute-force maximum over the disc's
arc on a 1 mm grid. The as-built road under each wheel path is the drawing times ``amplitude`` plus its own
band-limited unevenness (flat spectrum over 0.1-2 cycles/m, i.e. 0.5-10 m waves, scaled to ``unevenness`` m
RMS over the stretch driven), the rear wheel on the front wheel's path. The car starts at rest in static
equilibrium on the road under its wheels at t = 0 (SPEC §2).
"""

from __future__ import annotations

import csv
import math
import shutil
import tomllib

import numpy as np
import tomli_w
from scipy.signal import lsim

from cars import SUV_TOTAL_MASS, SUV_TRUTH, SUV_VEHICLE

CHANNELS = ("body_az_fl", "body_az_fr", "body_az_rl", "body_az_rr", "axle_az_fl", "axle_az_fr", "axle_az_rl",
            "axle_az_rr", "pitch_rate", "roll_rate")

#: the built-in track set's high-severity tracks (src/rideid/data/default_scenario.toml)
TRACKS = [
    {"id": "twist_high", "kind": "chassis_twist", "start": 3.0, "height": 0.08, "bump_length": 1.6,
     "spacing": 4.0, "bumps": 3, "first": "left"},
    {"id": "herringbone_high", "kind": "herringbone", "start": 3.0, "amplitude": 0.008, "wavelength": 0.5,
     "cycles": 16, "angle": 30.0},
    {"id": "washboard", "kind": "washboard", "start": 3.0, "amplitude": 0.008, "wavelength": 0.8, "cycles": 12},
]
#: five runs: (id, track, speed m/s, duration s), as the built-in T_HL, T_HH, H_HL, H_HH, W_H
RUNS = [("T_HL", "twist_high", 3.0, 7.5), ("T_HH", "twist_high", 5.0, 5.0), ("H_HL", "herringbone_high", 5.0, 4.5),
        ("H_HH", "herringbone_high", 10.0, 3.0), ("W_H", "washboard", 10.0, 3.1)]
FS = 200.0
#: the simulation grid: this many steps per sample
UPSAMPLE = 10
#: the road grid (m) of the envelope
DX = 1e-3


def drawn(track: dict, s, y: float):
    """SPEC §2's height (m) of ``track`` at distances ``s`` (m) on the wheel path at lateral offset ``y`` (m)."""
    s = np.asarray(s, dtype=float)
    kind = track["kind"]
    if kind in ("washboard", "herringbone"):
        shift = y * math.tan(math.radians(track["angle"])) if kind == "herringbone" else 0.0
        u = s - track["start"] + shift
        inside = (u >= 0) & (u <= track["cycles"] * track["wavelength"])
        return np.where(inside, track["amplitude"] * np.sin(2 * np.pi * u / track["wavelength"]), 0.0)
    if kind == "chassis_twist":
        left_first = track.get("first", "left") == "left"
        mine = 0.0 if (y > 0) == left_first else 0.5
        h = np.zeros_like(s)
        for k in range(track["bumps"]):
            xc = track["start"] + (k + mine) * track["spacing"]
            d = s - xc
            h += np.where(np.abs(d) <= track["bump_length"] / 2,
                          track["height"] / 2 * (1 + np.cos(2 * np.pi * d / track["bump_length"])), 0.0)
        return h
    raise ValueError(kind)


def unevenness(rng, s, rms: float, band=(0.1, 2.0)):
    """Band-limited random heights (m) at the uniform distances ``s``: flat spectrum over ``band`` cycles/m,
    scaled to ``rms``."""
    n = s.size
    spec = np.zeros(n // 2 + 1, dtype=complex)
    f = np.fft.rfftfreq(n, s[1] - s[0])
    on = (f >= band[0]) & (f <= band[1])
    spec[on] = np.exp(2j * np.pi * rng.random(on.sum()))
    z = np.fft.irfft(spec, n=n)
    return z * (rms / np.sqrt(np.mean(z ** 2)))


def envelope(h, R: float, dx: float = DX):
    """Rigid-disc envelope ``max_{|d| <= R} h(s + d) + sqrt(R^2 - d^2) - R`` on the grid of ``h`` (edges: the
    end values continued)."""
    m = int(R / dx)
    pad = np.concatenate([np.full(m, h[0]), h, np.full(m, h[-1])])
    out = np.full(h.size, -np.inf)
    for j in range(-m, m + 1):
        d = j * dx
        out = np.maximum(out, pad[m + j:m + j + h.size] + math.sqrt(max(R * R - d * d, 0.0)))
    return out - R


def state_space(truth: dict, vehicle: dict):
    """The 7-DOF car of SPEC §1: ``(A, B, C, D)`` with state ``[q, q']``, q = (z, theta, phi, z_fl, z_fr, z_rl,
    z_rr), input the four road heights fl, fr, rl, rr, outputs :data:`CHANNELS`."""
    p = truth
    a = p["a"]
    b = vehicle["wheelbase"] - a
    xs = np.array([a, a, -b, -b])
    ys = np.array([vehicle["track_front"], -vehicle["track_front"], vehicle["track_rear"],
                   -vehicle["track_rear"]]) / 2
    ks = np.array([p["k_sf"], p["k_sf"], p["k_sr"], p["k_sr"]])
    cs = np.array([p["c_sf"], p["c_sf"], p["c_sr"], p["c_sr"]])
    kt = np.array([p["k_tf"], p["k_tf"], p["k_tr"], p["k_tr"]])
    mu = np.array([p["m_uf"], p["m_uf"], p["m_ur"], p["m_ur"]])
    # deflection d_i = z_i - z_bi = L q, L (4, 7); the suspension forces F = K L q + C L q' act on the body
    # through G^T (G_i = (1, -x_i, y_i) with the pitch and roll signs of SPEC §1) and on the wheels with -1
    G = np.stack([np.ones(4), -xs, ys], axis=1)
    L = np.concatenate([-G, np.eye(4)], axis=1)
    Tq = np.concatenate([np.stack([np.ones(4), -xs, ys]), -np.eye(4)], axis=0)  # (7, 4): F_i's generalised force
    # body: m z'' = sum F, I_yy theta'' = -sum x F, I_xx phi'' = sum y F -> rows (1, -x, y) = G^T, as Tq's top
    Mq = np.diag([p["m_s"], p["I_yy"], p["I_xx"], *mu])
    Kq = -Tq @ np.diag(ks) @ L
    Cq = -Tq @ np.diag(cs) @ L
    Kq[3:, 3:] += np.diag(kt)
    Bq = np.zeros((7, 4))
    Bq[3:, :] = np.diag(kt)
    Mi = np.linalg.inv(Mq)
    A = np.block([[np.zeros((7, 7)), np.eye(7)], [-Mi @ Kq, -Mi @ Cq]])
    B = np.concatenate([np.zeros((7, 4)), Mi @ Bq])
    acc_q = A[7:]                 # q'' = acc_q x + accB u
    accB = B[7:]
    Cb = np.concatenate([G, np.zeros((4, 4))], axis=1)        # body corner displacement from q
    C = np.concatenate([Cb @ acc_q, acc_q[3:], np.zeros((2, 14))])
    D = np.concatenate([Cb @ accB, accB[3:], np.zeros((2, 4))])
    C[8, 8] = 1.0    # pitch rate = theta'
    C[9, 9] = 1.0    # roll rate = phi'
    return A, B, C, D


def wheel_inputs(tracks: dict, run, vehicle: dict, amplitude: float, rms: float, rng, distance=None):
    """The four as-built wheel inputs (n_fine, 4) of ``run`` = (id, track, speed, duration) on the fine time
    grid, and that grid; and the unevenness under each path over the stretch driven (for the checks).

    The front wheels are at ``x(t) = speed * t``, or at ``distance(t)`` (m, a function of the time grid: a
    speed as driven, x = its integral, may be negative before the start), the rear wheels at ``x - wheelbase``.
    """
    rid, tid, speed, duration = run
    n = int(round(duration * FS))
    t = np.arange(n * UPSAMPLE + 1) / (FS * UPSAMPLE)
    R = vehicle["tire_radius"]
    wb = vehicle["wheelbase"]
    x = speed * t if distance is None else np.asarray(distance(t), dtype=float)
    end = speed * duration if distance is None else float(x.max())
    s = np.arange(min(0.0, float(x.min())) - wb - 2 * R - 0.5, end + 2 * R + 0.5, DX)
    tr = tracks[tid]
    u = np.empty((t.size, 4))
    bumps = {}
    for side, y in (("left", vehicle["track_front"] / 2), ("right", -vehicle["track_front"] / 2)):
        e = unevenness(rng, s, rms)
        bumps[side] = (s, e)
        r = envelope(amplitude * drawn(tr, s, y) + e, R)
        col = 0 if side == "left" else 1
        u[:, col] = np.interp(x, s, r)
        u[:, col + 2] = np.interp(x - wb, s, r)
    return t, u, bumps


def simulate_run(tracks, run, truth=SUV_TRUTH, vehicle=SUV_VEHICLE, amplitude=1.04, rms=1.5e-3, rng=None,
                 distance=None):
    """Noise-free channels (n, 10) at ``FS`` of one run, and the unevenness under each wheel path (``distance``:
    the front axle's x(t), see :func:`wheel_inputs`; default ``speed * t``)."""
    A, B, C, D = state_space(truth, vehicle)
    t, u, bumps = wheel_inputs(tracks, run, vehicle, amplitude, rms, rng, distance)
    x0 = -np.linalg.solve(A, B @ u[0])   # at rest in static equilibrium on the road under the wheels
    _, y, _ = lsim((A, B, C, D), u, t, X0=x0, interp=True)
    return t[::UPSAMPLE], y[::UPSAMPLE], bumps


def write_dataset(folder, *, amplitude=1.04, rms=1.5e-3, noise=0.01, seed=1, runs=RUNS, tracks=TRACKS):
    """Simulate the runs on the as-built tracks, add white noise of ``noise`` x each channel's RMS, and write a
    rideid dataset declaring the drawn tracks (SPEC §3). Returns the unevenness RMS (m) of each track as driven
    (mean over its runs and paths, over the stretch each run drove)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "runs").mkdir(exist_ok=True)
    by_id = {tr["id"]: tr for tr in tracks}
    used = sorted({r[1] for r in runs})
    doc = {"name": "suv-as-built", "vehicle": dict(SUV_VEHICLE), "known": {"total_mass": SUV_TOTAL_MASS},
           "tracks": [by_id[t] for t in used], "runs": []}
    for run in runs:
        t, y, _ = simulate_run(by_id, run, amplitude=amplitude, rms=rms, rng=rng)
        y = y + rng.standard_normal(y.shape) * noise * np.sqrt(np.mean(y ** 2, axis=0))
        with open(folder / "runs" / f"{run[0]}.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(("time",) + CHANNELS)
            for k in range(t.size):
                w.writerow([f"{t[k]:.6f}"] + [f"{v:.9e}" for v in y[k]])
        doc["runs"].append({"id": run[0], "track": run[1], "speed": run[2], "file": f"runs/{run[0]}.csv"})
    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
    return folder


#: the eight accelerometers (SPEC §2)
ACCELS = [f"{p}_az_{c}" for p in ("body", "axle") for c in ("fl", "fr", "rl", "rr")]


def write_exact(folder, run_ids, speeds=None):
    """The SUV on the exact drawings (amplitude 1, no unevenness), 1 % noise, seed 1, the runs ``run_ids``;
    ``speeds``: run id -> the speed declared in dataset.toml (a slip), else the speed driven."""
    by_id = {r[0]: r for r in RUNS}
    write_dataset(folder, amplitude=1.0, rms=0.0, noise=0.01, seed=1, runs=[by_id[r] for r in run_ids])
    doc = tomllib.loads((folder / "dataset.toml").read_text())
    for r in doc["runs"]:
        if speeds and r["id"] in speeds:
            r["speed"] = speeds[r["id"]]
    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
    return folder


def in_g(src, dst):
    """``src`` copied to ``dst`` with every acceleration column divided by g (a SPEC CSV whose accelerations were
    written in g)."""
    shutil.copytree(src, dst)
    for f in (dst / "runs").glob("*.csv"):
        rows = list(csv.reader(f.open()))
        head = rows[0]
        out = [head] + [[row[0]] + [f"{float(v) / 9.80665:.9e}" if head[i] in ACCELS else v
                                    for i, v in enumerate(row[1:], start=1)] for row in rows[1:]]
        with f.open("w", newline="") as fh:
            csv.writer(fh).writerows(out)
    return dst
