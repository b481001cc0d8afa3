"""Every reality of SPEC §11 at once, for the tests: the SUV with an engine on mounts, driven over tracks as
built, logged through real sensor chains, with a noisy GPS speed channel and an unstated start.

Composed of the independent simulators of the tests, none of rideid's equations:

* the road: :mod:`asbuilt_tracks` (the drawing times ``AMPLITUDE`` plus ``UNEVENNESS`` m RMS of band-limited
  unevenness under each side's wheel path, rigid-disc envelope on a 1 mm grid, each wheel at its own lateral
  offset: SPEC §2), flat before x = 0 so that the car rolls in steady state on flat road during the lead-in;
* the car: :mod:`powertrain_car` (Newton-Euler, with the issue's 180 kg engine on 10.5/13 Hz mounts),
  ``scipy.signal.lsim`` on a 4 kHz grid, sampled at 1 kHz: the built-in car on the built-in track set's ten
  runs (``car="builtin"``, the default), or the SUV of tests/cars.py on the five high-severity runs of
  :mod:`asbuilt_tracks` (``car="suv"``);
* the sensors: 1 % white noise, the four hub accelerometers AC-coupled at 0.5 Hz (the analog Butterworth by
  ``lsim`` at 1 kHz, :func:`sensor_case.analog_highpass`), ``axle_az_fl`` clipping at ±5 g (``numpy.clip``),
  then every channel decimated to the 200 Hz file rate;
* the speed: a GPS channel at 10 Hz with ``GPS_NOISE`` m/s of white noise (the car holds its speed);
* the start: the recording begins ``OFFSET`` s before the front axle reaches x = 0, not stated.

The dataset declares the drawn tracks, the coupling and the range (as a test engineer who knows the chain
would), the speed channel and no run speed.
"""

from __future__ import annotations

import tomllib
import types

import numpy as np

from asbuilt_tracks import TRACKS, drawn, envelope, unevenness
from cars import SUV_TRUTH, SUV_VEHICLE
from logger_files import write_csv
from powertrain_car import ENGINE, simulate
from sensor_case import analog_highpass

import rideid
from rideid.data.schema import write_toml
from rideid.model.equations import CHANNELS

G0 = 9.80665
OFFSET = 2.3
AMPLITUDE = 1.04
UNEVENNESS = 1.5e-3
HIGHPASS_HZ = 0.5
CLIP_G = 5.0
GPS_NOISE = 0.03
FILE_FS = 200.0
#: the five runs of tests/asbuilt_tracks.py: (id, track, speed m/s, duration after the start, s)
SUV_RUNS = [("T_HL", "twist_high", 3.0, 7.5), ("T_HH", "twist_high", 5.0, 5.0),
            ("H_HL", "herringbone_high", 5.0, 4.5), ("H_HH", "herringbone_high", 10.0, 3.0),
            ("W_H", "washboard", 10.0, 3.1)]


def setup(car: str = "builtin"):
    """``(vehicle, truth of the twelve, tracks, runs)`` of the case: the built-in scenario's, or the SUV's."""
    if car == "suv":
        return dict(SUV_VEHICLE), dict(SUV_TRUTH), list(TRACKS), list(SUV_RUNS)
    doc = tomllib.loads(rideid.default_scenario_path().read_text())
    runs = [(r["id"], r["track"], float(r["speed"]), float(r["duration"])) for r in doc["runs"]]
    return dict(doc["vehicle"]), dict(doc["truth"]), list(doc["tracks"]), runs


def _road(vehicle: dict, track: dict, speed: float, duration: float, rng):
    """The as-built heights under the wheel paths: (s grid, (4, n) envelopes fl, fr, rl, rr). Each wheel rolls on
    its own lateral offset (SPEC §2: a herringbone's phase depends on it, and the built-in car's rear track is
    23 mm narrower than its front), the unevenness the same under a side's front and rear wheels (it varies over
    metres, not the 11.5 mm between them)."""
    R, wb = vehicle["tire_radius"], vehicle["wheelbase"]
    s = np.arange(-wb - speed * OFFSET - 2 * R - 1.0, speed * duration + 2 * R + 1.0, 1e-3)
    ramp = np.clip(s / 1.0, 0.0, 1.0)
    ramp = 0.5 - 0.5 * np.cos(np.pi * ramp)  # flat road before x = 0, the unevenness faded in over 1 m
    bumps = [ramp * unevenness(rng, s, UNEVENNESS) for _ in range(2)]
    paths = []
    for axle in ("track_front", "track_rear"):
        for side, y in enumerate((vehicle[axle] / 2, -vehicle[axle] / 2)):
            paths.append(envelope(AMPLITUDE * drawn(track, s, y) + bumps[side], R))
    return s, np.array(paths)


def simulate_run(vehicle: dict, truth: dict, track: dict, speed: float, duration: float, rng, engine=ENGINE):
    """File time (1 kHz) and the ten channels (SI) of one run, before the sensors."""
    wb = vehicle["wheelbase"]
    s, paths = _road(vehicle, track, speed, duration, rng)

    def road(tt):
        x = speed * (tt - OFFSET)
        return np.column_stack([np.interp(x, s, paths[0]), np.interp(x, s, paths[1]),
                                np.interp(x - wb, s, paths[2]), np.interp(x - wb, s, paths[3])])

    t = np.arange(int(round((OFFSET + duration) * 1000.0)) + 1) / 1000.0
    geom = types.SimpleNamespace(**vehicle)
    car = {**truth, **(engine or {**ENGINE, "m_p": 1e-6, "I_p": 1e-6})}
    return t, simulate(car, geom, t, road, upsample=4)


def write_dataset(folder, *, car="builtin", seed=7, runs=None, engine=ENGINE, noise=0.01):
    """Write the all-realities dataset (module docstring) to ``folder``; ``runs``: the run ids to keep.

    Returns the share of ``axle_az_fl``'s file samples at its range, per run.
    """
    vehicle, twelve, tracks, all_runs = setup(car)
    runs = [r for r in all_runs if runs is None or r[0] in runs]
    total = twelve["m_s"] + 2 * twelve["m_uf"] + 2 * twelve["m_ur"]
    rng = np.random.default_rng(seed)
    (folder / "runs").mkdir(parents=True, exist_ok=True)
    by_id = {tr["id"]: tr for tr in tracks}
    step = int(round(1000.0 / FILE_FS))
    clipped = {}
    out_runs = []
    for rid, tid, speed, duration in runs:
        t, Y = simulate_run(vehicle, twelve, by_id[tid], speed, duration, rng, engine)
        rms = np.sqrt(np.mean(Y[t > OFFSET] ** 2, axis=0))
        Y = Y + noise * rms * rng.standard_normal(Y.shape)
        for c in ("axle_az_fl", "axle_az_fr", "axle_az_rl", "axle_az_rr"):
            i = CHANNELS.index(c)
            Y[:, i] = analog_highpass(t, Y[:, i], HIGHPASS_HZ)
        i = CHANNELS.index("axle_az_fl")
        Y[:, i] = np.clip(Y[:, i], -CLIP_G * G0, CLIP_G * G0)
        tf, Yf = t[::step], Y[::step]
        clipped[rid] = float(np.mean(np.abs(Yf[:, i]) >= CLIP_G * G0))
        chans = {c: (tf, Yf[:, k], "rad/s" if c.endswith("rate") else "m/s^2") for k, c in enumerate(CHANNELS)}
        tg = tf[::int(round(FILE_FS / 10.0))]
        chans["gps_speed"] = (tg, speed + GPS_NOISE * rng.standard_normal(tg.size), "m/s")
        write_csv(folder / "runs" / f"{rid}.csv", chans, delimiter=",", decimal=".")
        out_runs.append({"id": rid, "track": tid, "file": f"runs/{rid}.csv"})
    cmap = {"time": {"name": "Time", "unit": "s"}, "speed": {"name": "gps_speed", "unit": "m/s"}}
    for c in CHANNELS:
        cmap[c] = {"name": c, "unit": "rad/s" if c.endswith("rate") else "m/s^2"}
        if c.startswith("axle"):
            cmap[c]["highpass"] = HIGHPASS_HZ
    cmap["axle_az_fl"]["range"] = CLIP_G * G0
    used = sorted({r[1] for r in runs})
    doc = {"name": f"{car}-all-realities", "vehicle": vehicle, "known": {"total_mass": total},
           "channels": cmap, "preprocess": {"fs": FILE_FS},
           "tracks": [by_id[t] for t in used], "runs": out_runs}
    write_toml(folder / "dataset.toml", doc)
    return clipped


def truth(car="builtin", engine=ENGINE) -> dict:
    """The twelve (the whole sprung mass, the engine as if rigidly mounted) and the engine's values."""
    return {**setup(car)[1], **(engine or {})}
