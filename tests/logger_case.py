"""Logger files of a simulated car, as a test engineer's logger writes them (tests only).

A scenario is simulated by :func:`rideid.simulate_manifest` (white or AR(1)
sensor noise), then every run is rewritten the way loggers record it:
accelerations in g with gravity and a bias, gyros in deg/s with a bias,
pitch nose-up positive, the logger's own column names, a standing lead-in
of ``LEAD`` seconds (sensor noise at the run's level) before the first
sample, and a dataset.toml whose runs give no start, so rideid estimates it.
The true start of every run is ``LEAD`` s of file time.

``suv_scenario`` is a 2.1 t SUV with anti-roll bars on a chassis twist, a
herringbone and a washboard (five runs; the car of a user's report), or the
same SUV without bars.
"""

from __future__ import annotations

import numpy as np

import rideid
from rideid.data.noise import sensor_noise
from rideid.data.schema import write_toml
from rideid.model.equations import CHANNELS

G0 = 9.80665
LEAD = 2.0
NAMES = {"body_az_fl": "AccBodyFL", "body_az_fr": "AccBodyFR", "body_az_rl": "AccBodyRL",
         "body_az_rr": "AccBodyRR", "axle_az_fl": "AccHubFL", "axle_az_fr": "AccHubFR",
         "axle_az_rl": "AccHubRL", "axle_az_rr": "AccHubRR", "pitch_rate": "GyroPitch",
         "roll_rate": "GyroRoll"}

SUV = """
name = "suv-2025"
[vehicle]
wheelbase = 2.85
track_front = 1.64
track_rear = 1.65
tire_radius = 0.37
[known]
total_mass = 2100.0
[model]
extensions = ["anti_roll_bars"]
[truth]
m_s = 1900.0
I_xx = 750.0
I_yy = 3400.0
a = 1.35
m_uf = 48.0
m_ur = 52.0
k_sf = 36000.0
k_sr = 40000.0
c_sf = 2600.0
c_sr = 2500.0
k_tf = 280000.0
k_tr = 280000.0
k_arf = 18000.0
k_arr = 8000.0
[[tracks]]
id = "twist"
kind = "chassis_twist"
start = 4.0
height = 0.06
bump_length = 1.8
spacing = 4.0
bumps = 3
[[tracks]]
id = "herring"
kind = "herringbone"
start = 4.0
amplitude = 0.006
wavelength = 0.6
cycles = 15
angle = 30.0
[[tracks]]
id = "wash"
kind = "washboard"
start = 4.0
amplitude = 0.006
wavelength = 1.0
cycles = 10
"""
SUV_RUNS = [("TW3", "twist", 3.0, 8.0), ("TW5", "twist", 5.0, 5.5), ("HB6", "herring", 6.0, 4.5),
            ("HB10", "herring", 10.0, 3.2), ("WB8", "wash", 8.0, 3.8)]


def suv_scenario(folder, fs=200.0, extensions=("anti_roll_bars",), bars=True):
    """Write the SUV scenario (runs at ``fs``) to ``folder/scenario.toml`` and load it.

    ``extensions``: its ``[model]`` table; None leaves the table out (the model is then chosen).
    ``bars``: False gives the truth no anti-roll bars (every extension truly 0).
    """
    model = "" if extensions is None else \
        "[model]\nextensions = [" + ", ".join(f'"{e}"' for e in extensions) + "]\n"
    text = SUV.replace('[model]\nextensions = ["anti_roll_bars"]\n', model)
    if not bars:
        text = text.replace("k_arf = 18000.0\nk_arr = 8000.0\n", "")
    for rid, track, v, dur in SUV_RUNS:
        text += f'[[runs]]\nid = "{rid}"\ntrack = "{track}"\nspeed = {v}\nfs = {fs}\nduration = {dur}\n'
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "scenario.toml").write_text(text)
    return rideid.load_scenario(folder / "scenario.toml")


def write_logger(sc, folder, *, noise=0.02, ar1=0.0, seed=0, model_fs=None, data=None):
    """Simulate ``sc`` and write it as logger files in ``folder``; returns the folder.

    ``model_fs``: ``[preprocess] fs`` (resample to it), default the runs' own rate. ``data``: the runs already
    simulated, noise included (``{run id: (t, Y)}`` from t = 0 at rest, another simulator's), written instead.
    """
    if data is None:
        data, _ = rideid.simulate_manifest(sc, noise=noise, seed=seed, noise_ar1=ar1)
    rng = np.random.default_rng([seed, 42])
    (folder / "runs").mkdir(parents=True, exist_ok=True)
    runs = []
    for run in sc.runs:
        t, Y = data[run.id]
        dt = t[1] - t[0]
        nlead = int(round(LEAD / dt))
        # the standing lead-in carries the run's own sensor noise (its level on the flat road before the track)
        sd = np.std(Y[: int(0.25 / dt)], axis=0)
        lead = sensor_noise(rng, (nlead, len(CHANNELS)), ar1) * sd
        Yl = np.concatenate([lead, Y])
        cols = {"Time_s": np.concatenate([np.arange(nlead) * dt, t + LEAD])}
        for i, c in enumerate(CHANNELS):
            y = Yl[:, i]
            if c.endswith("rate"):
                y = np.degrees(y) + rng.normal(0, 0.2)           # deg/s with a bias
                y = -y if c == "pitch_rate" else y               # nose-up positive
            else:
                y = (y + G0) / G0 + rng.normal(0, 0.01)          # g, gravity, bias
            cols[NAMES[c]] = y
        lines = [",".join(cols)] + [",".join(f"{v:.9g}" for v in row) for row in zip(*cols.values())]
        (folder / "runs" / f"{run.id}_log.csv").write_text("\n".join(lines) + "\n")
        runs.append({"id": run.id, "track": run.track, "speed": run.speed, "file": f"runs/{run.id}_log.csv"})
    doc = _shared_doc(sc)
    doc["channels"] = {"time": {"name": "Time_s", "unit": "s"},
                       **{c: {"name": NAMES[c], "unit": "deg/s" if c.endswith("rate") else "g",
                              **({"sign": -1} if c == "pitch_rate" else {})} for c in CHANNELS}}
    doc["preprocess"] = {"gravity_included": True, "remove_bias": True, "lead_in": [0.0, 1.5],
                         **({"fs": float(model_fs)} if model_fs else {})}
    doc["runs"] = runs
    write_toml(folder / "dataset.toml", doc)
    return folder


def _shared_doc(sc) -> dict:
    """The scenario's dataset.toml tables (vehicle, known, bounds, model, tracks) as a dict."""
    man = rideid.DatasetManifest(**{**sc.shared(), "runs": []})
    doc = man.to_dataset_doc()
    doc.pop("runs", None)
    return doc
