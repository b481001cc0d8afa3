"""Speed as driven (SPEC §11) on a car the 7-DOF model describes exactly: only the speed is not held.

The SUV of tests/cars.py on the five runs of tests/asbuilt_tracks.py (exact drawings, 200 Hz, 1 % white sensor
noise, total mass known), simulated by that file's independent SciPy ``lsim`` car while the driver wanders
+-3 % around each run's nominal speed (tests/driven_speed.py). Each case is identified by ``rideid.identify``
with its defaults:

* ``exact``     the 10 Hz speed channel exact
* ``gps``       the same channel with 0.03 m/s of white noise, as a GPS gives
* ``constant``  no speed channel: each run's nominal constant speed (the wander ignored). Loading refuses such
                a dataset (docs/real-data.md, "A speed that wanders"); the case relaxes that with
                ``[checks] track = "warn"`` to measure what the fit would give

Per case: the largest error of the twelve, how many of the twelve +-2 std_robust and +-2 std_total cover, the
verdict, the distance corrections' RMS and the wall time.

    PYTHONPATH=src .venv/bin/python benchmarks/speed_as_driven_exact.py [--seeds 1 2 3] [--cases exact gps constant]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import tomllib
import warnings
from pathlib import Path

import tomli_w

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
from driven_speed import scores, write_case  # noqa: E402

CASES = {"exact": dict(gps_noise=0.0), "gps": dict(gps_noise=0.03), "constant": dict(speed_channel=False)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            for case in args.cases:
                folder = Path(tmp) / f"s{seed}{case}"
                write_case(folder, seed=seed, **CASES[case])
                if case == "constant":  # refused when loaded: relaxed to measure the fit it would give
                    doc = tomllib.loads((folder / "dataset.toml").read_text())
                    doc["checks"] = {"track": "warn"}
                    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    res = rideid.identify(rideid.load_dataset(folder), seed=1)
                    wall = time.perf_counter() - t0
                err, cov_r, cov_t, est = scores(res)
                worst = max(err, key=lambda n: abs(err[n]))
                corr = {rid: st.get("distance_correction", {}).get("rms_m") for rid, st in res.starts.items()}
                row = {"seed": seed, "case": case, "largest_error_pct": 100 * abs(err[worst]), "worst": worst,
                       "errors_pct": {n: round(100 * e, 3) for n, e in err.items()},
                       "covered_std_robust": cov_r, "covered_std_total": cov_t, "estimated": est,
                       "adequate": res.adequacy["adequate"], "wall_s": round(wall),
                       "distance_correction_rms_mm": {k: None if v is None else round(1e3 * v, 2)
                                                      for k, v in corr.items()}}
                rows.append(row)
                print(json.dumps(row), flush=True)
    print("\n| seed | case | largest error % | ±2 std_robust | ±2 std_total | adequate | identify s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['seed']} | {r['case']} | {r['largest_error_pct']:.2f} ({r['worst']}) | {r['covered_std_robust']}/"
              f"{r['estimated']} | {r['covered_std_total']}/{r['estimated']} | {'yes' if r['adequate'] else 'no'} | "
              f"{r['wall_s']} |")


if __name__ == "__main__":
    main()
