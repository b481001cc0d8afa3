"""AC-coupled hub sensors (SPEC §11 "sensors as wired") on the two paths that fit the road in the frequency
domain, for the tests. In both the four hub accelerometers pass an analog Butterworth high-pass by ``scipy.signal.lsim``
on a fine grid (:func:`sensor_case.analog_highpass`), then are sampled at 200 Hz: not rideid's first-order hold.

* **Tracks as built** (:func:`write_tracks_dataset`): the SUV of tests/cars.py on the as-built tracks of
  :mod:`asbuilt_tracks` (the drawing times ``amplitude`` plus band-limited unevenness, SciPy ``lsim`` of the
  7-DOF car written from SPEC §1 on a 2 kHz grid; nothing of rideid's equations, tracks or contact), the filter at
  rest with the car at t = 0; white noise of ``noise`` times each channel's RMS added by the logger. The record
  begins as the front axle reaches x = 0 (``start = 0``), as the as-built tests' SPEC CSVs do.
* **Unknown roads** (:func:`write_roads_dataset`): the built-in car on ISO 8608 roads by ``rideid simulate`` at
  1 kHz with 2 % sensor noise (the car moving at the first sample), the noise passing the coupling as in an IEPE
  sensor, the filter at rest at the first sample while the car is not: its state there is what the fit must
  estimate.

Each dataset declares, with ``declare``, the coupling in ``[channels]``.
"""

from __future__ import annotations

import numpy as np
import tomli_w
from scipy.signal import lsim

from asbuilt_tracks import CHANNELS, FS, RUNS, TRACKS, UPSAMPLE, state_space, wheel_inputs
from cars import SUV_TOTAL_MASS, SUV_TRUTH, SUV_VEHICLE
from sensor_case import analog_highpass

HUBS = ("axle_az_fl", "axle_az_fr", "axle_az_rl", "axle_az_rr")


def simulate_run(tracks, run, *, highpass_hz, order=1, amplitude=1.04, rms=1.5e-3, rng=None):
    """The ten channels (n, 10) at ``FS`` of one run, the hubs through the analog high-pass (None: no coupling)."""
    A, B, C, D = state_space(SUV_TRUTH, SUV_VEHICLE)
    t, u, _ = wheel_inputs(tracks, run, SUV_VEHICLE, amplitude, rms, rng)
    x0 = -np.linalg.solve(A, B @ u[0])   # at rest in static equilibrium on the road under the wheels
    _, y, _ = lsim((A, B, C, D), u, t, X0=x0, interp=True)
    if highpass_hz is not None:
        for c in HUBS:
            i = CHANNELS.index(c)
            y[:, i] = analog_highpass(t, y[:, i], highpass_hz, order)
    return t[::UPSAMPLE], y[::UPSAMPLE]


def write_tracks_dataset(folder, *, highpass_hz=0.5, order=1, declare=True, amplitude=1.04, rms=1.5e-3, noise=0.01,
                  seed=1, runs=RUNS, tracks=TRACKS):
    """Write the runs as a rideid dataset with a ``[channels]`` map (declaring the coupling with ``declare``)."""
    rng = np.random.default_rng(seed)
    (folder / "runs").mkdir(parents=True, exist_ok=True)
    by_id = {tr["id"]: tr for tr in tracks}
    used = sorted({r[1] for r in runs})
    cmap = {"time": {"name": "time", "unit": "s"}}
    for c in CHANNELS:
        cmap[c] = {"name": c, "unit": "rad/s" if c.endswith("rate") else "m/s^2"}
        if declare and highpass_hz is not None and c in HUBS:
            cmap[c]["highpass"] = highpass_hz if order == 1 else {"hz": highpass_hz, "order": order}
    doc = {"name": "suv-as-built-coupled", "vehicle": dict(SUV_VEHICLE), "known": {"total_mass": SUV_TOTAL_MASS},
           "channels": cmap, "preprocess": {"fs": FS, "pre_roll": 0.0},
           "tracks": [by_id[t] for t in used], "runs": []}
    for run in runs:
        t, y = simulate_run(by_id, run, highpass_hz=highpass_hz, order=order, amplitude=amplitude, rms=rms, rng=rng)
        y = y + rng.standard_normal(y.shape) * noise * np.sqrt(np.mean(y ** 2, axis=0))
        lines = ["time," + ",".join(CHANNELS)] + [
            f"{ti:.6f}," + ",".join(f"{v:.9e}" for v in row) for ti, row in zip(t, y)]
        (folder / "runs" / f"{run[0]}.csv").write_text("\n".join(lines) + "\n")
        doc["runs"].append({"id": run[0], "track": run[1], "speed": run[2], "file": f"runs/{run[0]}.csv",
                            "start": 0.0})
    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
    return folder


#: two unknown-road runs of the built-in car (as tests/test_anyroad.py's), simulated at 1 kHz
ROAD_RUNS = [{"id": "B40", "road_class": "B", "speed": 11.0, "fs": 1000.0, "duration": 20.0},
             {"id": "C25", "road_class": "C", "speed": 7.0, "fs": 1000.0, "duration": 20.0}]


def write_roads_dataset(folder, *, highpass_hz=0.5, declare=True, noise=0.02, seed=3, runs=ROAD_RUNS):
    """The built-in car on unknown roads through coupled hubs (module docstring): ``folder/ds`` with
    ``truth.toml`` beside its ``dataset.toml``, and ``folder/sim`` the 1 kHz simulation it came from."""
    import shutil
    import tomllib

    from rideid.cli import main
    from rideid.data.scenario import default_scenario
    from rideid.model.params import total_mass
    sc = default_scenario()
    g = sc.geometry
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"name": "roads", "vehicle": {k: getattr(g, k) for k in g.KEYS},
           "known": {"total_mass": float(total_mass(dict(sc.truth)))}, "truth": dict(sc.truth), "runs": runs}
    (folder / "sc.toml").write_text(tomli_w.dumps(doc))
    sim = folder / "sim"
    assert main(["simulate", str(folder / "sc.toml"), "--out", str(sim), "--noise", str(noise), "--seed", str(seed),
                 "--quiet"]) == 0
    out = folder / "ds"
    (out / "runs").mkdir(parents=True, exist_ok=True)
    doc = tomllib.loads((sim / "dataset.toml").read_text())
    for r in doc["runs"]:
        d = np.loadtxt(sim / r["file"], delimiter=",", skiprows=1)
        t, Y = d[:, 0], d[:, 1:]
        for c in HUBS:
            i = CHANNELS.index(c)
            Y[:, i] = analog_highpass(t, Y[:, i], highpass_hz)
        step = int(round(1.0 / (FS * (t[1] - t[0]))))
        lines = ["time," + ",".join(CHANNELS)] + [
            f"{ti:.6f}," + ",".join(f"{v:.9g}" for v in row) for ti, row in zip(t[::step], Y[::step])]
        (out / r["file"]).write_text("\n".join(lines) + "\n")
    doc["channels"] = {"time": {"name": "time", "unit": "s"}}
    for c in CHANNELS:
        doc["channels"][c] = {"name": c, "unit": "rad/s" if c.endswith("rate") else "m/s^2"}
        if declare and c in HUBS:
            doc["channels"][c]["highpass"] = highpass_hz
    doc["preprocess"] = {"fs": FS}
    (out / "dataset.toml").write_text(tomli_w.dumps(doc))
    shutil.copy(sim / "truth.toml", out / "truth.toml")
    return out
