"""A van with real dampers logged at 300, 500 or 1000 Hz, as its logger records it (tests and benchmarks).

The 2.4 t van of the project's damper-van case: digressive, asymmetric
dampers that bend at 0.05, 0.15 and 0.3 m/s, bump stops (the rear wheels
lift off on the washboard), a CG 0.45 m high, on a chassis twist, a
herringbone and a washboard (five runs). :func:`write_van_logger` simulates
it at the logger's rate ``fs_file`` (``rideid simulate`` with 1 % white
noise: instantaneous values at the samples, nothing low-passed), then
rewrites every run the way the logger writes it: accelerations in g with
gravity and a bias, gyros in deg/s with a bias (pitch nose-up positive),
the logger's own column names, a standing lead-in of ``lead`` seconds, no
start given (rideid estimates it), and no ``[preprocess] fs``: the rate is
rideid's default. The true start of every run is ``lead`` s of file time.

    python tests/rate_case.py OUT 500      # OUT/sim (SPEC CSV, truth.toml), OUT/logger (the logger's files)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

G0 = 9.80665
#: file channel names of the van's logger
NAMES = {"body_az_fl": "Acc_Body_VL", "body_az_fr": "Acc_Body_VR", "body_az_rl": "Acc_Body_HL",
         "body_az_rr": "Acc_Body_HR", "axle_az_fl": "Acc_Rad_VL", "axle_az_fr": "Acc_Rad_VR",
         "axle_az_rl": "Acc_Rad_HL", "axle_az_rr": "Acc_Rad_HR", "pitch_rate": "Gyro_Nick",
         "roll_rate": "Gyro_Wank"}

VAN = """
name = "van-dampers"
[vehicle]
wheelbase = 3.20
track_front = 1.72
track_rear = 1.70
tire_radius = 0.34
cg_height = 0.45
[known]
total_mass = 2400.0
[truth]
m_s = 2180.0
I_xx = 950.0
I_yy = 4300.0
a = 1.40
m_uf = 52.0
m_ur = 58.0
k_sf = 46000.0
k_sr = 62000.0
bs_clear_f = 0.06
bs_rate_f = 80e3
bs_clear_r = 0.06
bs_rate_r = 80e3
k_tf = 290000.0
k_tr = 310000.0
[dampers]
velocity = [-0.6, -0.3, -0.15, -0.05, 0.05, 0.15, 0.3, 0.6]
front    = [-1500.0, -1000.0, -700.0, -260.0, 120.0, 330.0, 480.0, 750.0]
rear     = [-1750.0, -1150.0, -800.0, -300.0, 140.0, 380.0, 560.0, 880.0]
[[tracks]]
id = "twist"
kind = "chassis_twist"
start = 4.0
height = 0.06
bump_length = 1.8
spacing = 4.5
bumps = 3
first = "left"
[[tracks]]
id = "hb"
kind = "herringbone"
start = 4.0
amplitude = 0.007
wavelength = 0.6
cycles = 16
angle = 30.0
[[tracks]]
id = "wb"
kind = "washboard"
start = 4.0
amplitude = 0.008
wavelength = 0.9
cycles = 12
"""
#: id, track, speed (m/s), duration (s)
VAN_RUNS = [("TW3", "twist", 3.0, 9.0), ("TW5", "twist", 5.0, 6.0), ("HB6", "hb", 6.0, 4.5),
            ("HB10", "hb", 10.0, 3.2), ("WB7", "wb", 7.0, 4.2)]


def van_scenario(folder: Path, fs_file: float, runs=None):
    """Write the van's scenario with its runs at ``fs_file`` Hz to ``folder/scenario.toml`` and load it.
    ``runs``: the ids to keep (default all five)."""
    import rideid
    text = VAN
    for rid, track, v, dur in VAN_RUNS:
        if runs is None or rid in runs:
            text += f'[[runs]]\nid = "{rid}"\ntrack = "{track}"\nspeed = {v}\nfs = {float(fs_file)}\nduration = {dur}\n'
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "scenario.toml").write_text(text)
    return rideid.load_scenario(folder / "scenario.toml")


def write_van_logger(out: Path, fs_file: float, *, lead: float = 2.5, noise: float = 0.01, seed: int = 1,
                     runs=None, preprocess: dict | None = None) -> Path:
    """Simulate the van at ``fs_file`` Hz into ``out/sim`` (SPEC CSV and ``truth.toml``) and write its logger's
    files to ``out/logger``; returns ``out/logger``. ``preprocess``: added to its ``[preprocess]`` table."""
    import rideid
    from rideid.data.schema import write_toml
    from rideid.synth.scenario import write_dataset

    out = Path(out)
    sc = van_scenario(out, fs_file, runs)
    data, _ = rideid.simulate_manifest(sc, noise=noise, seed=seed)
    write_dataset(sc, data, out / "sim")
    rng = np.random.default_rng(42)
    dst = out / "logger"
    (dst / "runs").mkdir(parents=True, exist_ok=True)
    doc_runs = []
    for run in sc.runs:
        d = np.genfromtxt(out / "sim" / "runs" / f"{run.id}.csv", delimiter=",", names=True)
        t = d["time"]
        dt = t[1] - t[0]
        n0 = int(round(lead / dt))
        cols = {"Zeit": np.concatenate([np.arange(n0) * dt, t + n0 * dt])}
        for k, nm in NAMES.items():
            x = d[k]
            x = np.concatenate([rng.normal(0, np.std(x[:50]) + 1e-12, n0), x])
            if k.startswith(("body", "axle")):
                x = x / G0 + 1.0 + rng.normal(0, 0.01)  # g, gravity in, a bias
            else:
                x = np.degrees(x) + rng.normal(0, 0.3)  # deg/s with a bias
                x = -x if k == "pitch_rate" else x  # the logger's pitch is nose-up positive
            cols[nm] = x
        arr = np.column_stack(list(cols.values()))
        np.savetxt(dst / "runs" / f"{run.id}.csv", arr, delimiter=",", header=",".join(cols), comments="",
                   fmt="%.7g")
        doc_runs.append({"id": run.id, "track": run.track, "speed": run.speed, "file": f"runs/{run.id}.csv"})
    doc = rideid.DatasetManifest(**{**sc.shared(), "runs": []}).to_dataset_doc()
    doc.pop("runs", None)
    doc["channels"] = {"time": {"name": "Zeit", "unit": "s"},
                       **{c: {"name": nm, "unit": "deg/s" if c.endswith("rate") else "g",
                              **({"sign": -1} if c == "pitch_rate" else {})} for c, nm in NAMES.items()}}
    doc["preprocess"] = {"gravity_included": True, "remove_bias": True, "lead_in": [0.0, 2.0], **(preprocess or {})}
    doc["runs"] = doc_runs
    write_toml(dst / "dataset.toml", doc)
    return dst


if __name__ == "__main__":
    print(write_van_logger(Path(sys.argv[1]), float(sys.argv[2])))
