"""Frequency responses (SPEC §13) measured: do the ±2 std bands cover the true car, how close is the measured H1?

    PYTHONPATH=src python benchmarks/study_frf.py [--seeds 3] [--runs all|small] [--search] [--noise 0.01]

The car of SPEC §1 written out independently (tests/frf_car.py: its own matrices from the SPEC, SciPy's ``lsim`` at
ten times the sample rate) drives the built-in tracks; white noise of ``--noise`` x each channel's RMS is added
(seeded); rideid identifies it (model base: the polish from the truth, the identification's last step, or with
``--search`` the whole identification, JADE and polish). Printed per seed:

- **coverage**: the share of (frequency, output, input) over 120 log-spaced frequencies from 0.5 to 25 Hz, 13
  outputs x 4 inputs, where the true |H| lies within ±2 std_abs of the identified car's, and the same for the
  heave, pitch and roll views; the median and largest std_abs / |H|;
- **measured H1** (every run on a known track, one record per run): points with partial coherence > 0.9 over
  0.5-25 Hz, their median relative error of |H| against the true car, the share within their own ±2 std;
- **the weighbridge**: the largest change of std_abs when total_mass is declared with a std of 1 %.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
from rideid.estimate.problem.cost import CostFunction  # noqa: E402
from rideid.estimate.assess.frequency import measured_response  # noqa: E402

from frf_car import TRUTH, coverage, h1_accuracy, independent_dataset  # noqa: E402

SMALL = ("T_LL", "T_HH", "H_LL", "H_HH", "W_L", "W_H")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--runs", choices=("all", "small"), default="all")
    ap.add_argument("--search", action="store_true", help="the whole identification (JADE and polish)")
    ap.add_argument("--noise", type=float, default=0.01)
    args = ap.parse_args(argv)
    runs = SMALL if args.runs == "small" else tuple(r.id for r in rideid.default_scenario().runs)
    print(f"runs {', '.join(runs)}; noise {args.noise:g}; {'search + polish' if args.search else 'polish'}")
    print("seed  coverage  views  median_rel_std  max_rel_std  h1_points  h1_median_err  h1_within_2std  "
          "anchor_change  seconds")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, args.seeds + 1):
            t0 = time.time()
            ds = independent_dataset(Path(tmp) / f"s{seed}", runs, args.noise, seed=seed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if args.search:
                    res = rideid.identify(ds, seed=seed, model="base")
                else:
                    cf = CostFunction(ds, extensions=())
                    res = rideid.identify(ds, model="base", start=[TRUTH[n] for n in cf.names], assess=False)
            share, views, fr = coverage(res)
            rel = fr.std_abs / np.abs(fr.H)
            points, err, within = h1_accuracy(measured_response(ds, res))
            unc = dict(res.uncertainty or {})
            tm = res.known["total_mass"]
            unc["declared"] = {"total_mass": {"kind": "known", "key": "total_mass", "value": tm, "std": 0.01 * tm}}
            fr1 = replace(res, uncertainty=unc).frequency_response(fr.freq)
            anchor = float(np.max(np.abs(fr1.std_abs - fr.std_abs) / np.maximum(fr.std_abs, 1e-300)))
            print(f"{seed:4d}  {share:8.3f}  {views:5.3f}  {np.median(rel):14.2e}  {rel.max():11.2e}  {points:9d}  "
                  f"{err:13.3f}  {within:14.2f}  {anchor:13.1e}  {time.time() - t0:7.1f}")


if __name__ == "__main__":
    main()
