"""Speed as driven (SPEC §11): a driver holding +-3 %, a 10 Hz GPS speed channel, on the independent MuJoCo car.

The SUV of tests/logger_case.py (anti-roll bars, five runs, 200 Hz, 1 % sensor noise) is driven by the MuJoCo
car (rideid.verify.hifi) along a speed that wanders +-3 % (two sines of 2-6 s), written as MDF4 logger files
with a 10 Hz speed channel in km/h: exact, or with 0.03 m/s of white noise. rideid identifies each with its
defaults but the model (anti-roll bars) and prints every parameter's error, its |error| / std_robust, the
distance corrections and the verdict.

    .venv/bin/python benchmarks/speed_as_driven.py [--seeds 0 1] [--noise 0.0 0.03]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
from logger_case import suv_scenario  # noqa: E402
from logger_files import G0, LOGGER, channel_map, write_mdf  # noqa: E402
from rideid.data.schema import DatasetManifest, RunSpec, write_toml  # noqa: E402
from rideid.model.equations import CHANNELS  # noqa: E402
from rideid.model.params import as_vector  # noqa: E402
from rideid.verify.hifi import simulate_mujoco  # noqa: E402

#: file time of the start (front axle at x = 0); the car is already moving then
OFFSET = 2.0


def write_case(out: Path, seed: int, gps_noise: float):
    sc = suv_scenario(out / "scenario", fs=200.0)
    P = as_vector(sc.truth)
    rng = np.random.default_rng(seed)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    runs = []
    for run in sc.runs:
        v0 = run.speed
        periods, phases = rng.uniform(2.0, 6.0, 2), rng.uniform(0, 2 * np.pi, 2)

        def vel(t, v0=v0, periods=periods, phases=phases):
            return v0 * (1 + 0.015 * (np.sin(2 * np.pi * t / periods[0] + phases[0])
                                      + np.sin(2 * np.pi * t / periods[1] + phases[1])))
        tg = np.arange(-OFFSET - 0.01, run.duration + 0.02, 1e-4)
        xg = np.concatenate([[0.0], np.cumsum(0.5 * (vel(tg[1:]) + vel(tg[:-1])) * 1e-4)])
        x0 = np.interp(0.0, tg, xg)
        t = -OFFSET + np.arange(int(round((run.duration + OFFSET) * 200)) + 1) / 200.0
        Y = simulate_mujoco(P, sc.geometry, sc.tracks[run.track], None, t,
                            distance=lambda tt, tg=tg, xg=xg, x0=x0: np.interp(tt, tg, xg) - x0)
        Y = Y + rng.normal(0, 1, Y.shape) * 0.01 * np.sqrt(np.mean(Y ** 2, axis=0))
        ft = t + OFFSET
        chans = {}
        for i, c in enumerate(CHANNELS):
            name, unit, sign = LOGGER[c]
            v = np.degrees(Y[:, i]) if c.endswith("rate") else (Y[:, i] + G0) / (G0 if unit == "g" else 1.0)
            chans[name] = (ft, sign * v, unit)
        t10 = ft[::20]
        chans["Speed"] = (t10, (vel(t10 - OFFSET) + rng.normal(0, gps_noise, t10.size)) * 3.6, "km/h")
        write_mdf(out / "runs" / f"{run.id}.mf4", chans)
        runs.append(RunSpec(run.id, run.track, None, file=f"runs/{run.id}.mf4"))
    doc = DatasetManifest(**{**sc.shared(), "runs": runs, "extensions": None}).to_dataset_doc()
    cmap = channel_map()
    cmap["speed"] = {"name": "Speed", "unit": "km/h"}
    doc["channels"] = cmap
    doc["preprocess"] = {"gravity_included": True}
    write_toml(out / "dataset.toml", doc)
    return sc


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.03], help="GPS speed noise, m/s")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for noise in args.noise:
                folder = Path(tmp) / f"s{seed}n{noise}"
                sc = write_case(folder, seed, noise)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    res = rideid.identify(rideid.load_dataset(folder), seed=1, model="anti_roll_bars")
                    wall = time.perf_counter() - t0
                truth = sc.truth
                err = {n: (res.parameters[n] - truth[n]) / truth[n] for n in truth if n in res.details}
                z = {n: abs(res.parameters[n] - truth[n]) / res.details[n]["std_robust"] for n in err
                     if res.details[n].get("std_robust")}
                corr = [st.get("distance_correction", {}).get("rms_m") for st in res.starts.values()]
                row = {"seed": seed, "gps_noise": noise, "largest_error_pct": 100 * max(abs(e) for e in err.values()),
                       "covered_2std_robust": sum(v <= 2 for v in z.values()), "estimated": len(z),
                       "adequate": res.adequacy["adequate"], "wall_s": wall,
                       "distance_correction_rms_mm": [None if c is None else 1e3 * c for c in corr]}
                rows.append(row)
                print(json.dumps(row), flush=True)
    print("\n| seed | GPS noise m/s | largest error % | ±2 std_robust | adequate | identify s |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']} | {r['gps_noise']} | {r['largest_error_pct']:.2f} | {r['covered_2std_robust']}/"
              f"{r['estimated']} | {'yes' if r['adequate'] else 'no'} | {r['wall_s']:.0f} |")


if __name__ == "__main__":
    main()
