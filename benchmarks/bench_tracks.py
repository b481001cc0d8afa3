"""Tracks as built (SPEC §11): the methods compared on the same recordings.

The SUV of tests/cars.py on five runs of the built-in tracks (T_HL, T_HH, H_HL, H_HH, W_H; 200 Hz, 1 % white
noise, total mass known), simulated by the independent simulator of tests/asbuilt_tracks.py on the tracks as
built: the drawing times 1.04 plus 1.5 mm RMS of band-limited unevenness per wheel path; and on the exact
drawing, for the price. The dataset declares the drawing. Methods (rideid.estimate.problem.asbuilt):

* ``as-drawn``  the drawing taken as exact: rideid identify --tracks as-drawn (JADE and the time-domain polish)
* ``prior``     the default: from the as-drawn car, the drawing times a fitted amplitude factor plus unevenness
                with a spectrum estimated from the data, integrated out bin by bin
* ``amplitude`` the same without unevenness: the drawing times a fitted amplitude factor
* ``free``      the road projected out (the runs as unknown roads; the drawing unused)

Each as-built method starts from the same as-drawn fit (as rideid identify does), so its time is that fit's
plus its own stage. Per method: the largest error of the eleven free parameters, how many of the twelve
(m_s derived) ±2 std_robust covers, the adequacy verdict, and CPU time (process time: the cores are shared).

    PYTHONPATH=src .venv/bin/python benchmarks/bench_tracks.py --seeds 1 2 3 --out bench-out/tracks
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import rideid  # noqa: E402
from rideid.estimate.fit.anyroad import identify_any_road  # noqa: E402
from asbuilt_tracks import write_dataset  # noqa: E402
from cars import SUV_TRUTH  # noqa: E402

METHODS = ("prior", "amplitude", "free")


def score(res) -> dict:
    errs, cov = {}, 0
    for n, true in SUV_TRUTH.items():
        d = res.details[n]
        errs[n] = 100 * (d["value"] / true - 1)
        s = d.get("std_robust") or 0.0
        cov += abs(d["value"] - true) <= 2 * s
    free = [n for n in res.names]
    worst = max(free, key=lambda n: abs(errs[n]))
    return {"worst": worst, "worst_pct": errs[worst], "covered": int(cov), "errors_pct": errs,
            "adequate": (res.adequacy or {}).get("adequate")}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--out", default="bench-out/tracks")
    ap.add_argument("--exact", action="store_true", help="also the exact drawing (the price of the default)")
    a = ap.parse_args(argv)
    out = Path(a.out)
    rows = []
    cases = [("as built", 1.04, 1.5e-3)] + ([("exact", 1.0, 0.0)] if a.exact else [])
    for seed in a.seeds:
        for case, amp, rms in cases:
            folder = out / f"{case.replace(' ', '_')}_{seed}"
            write_dataset(folder, amplitude=amp, rms=rms, seed=seed)
            ds = rideid.load_dataset(folder)
            c0 = time.process_time()
            base = rideid.identify(ds, rng=seed, tracks="as-drawn")
            t_base = time.process_time() - c0
            rows.append({"case": case, "seed": seed, "method": "as-drawn", "cpu_s": t_base, **score(base)})
            for m in METHODS if case == "as built" else ("prior",):
                c0 = time.process_time()
                res = identify_any_road(ds, start_result=base, as_built_mode=m)
                t = time.process_time() - c0
                row = {"case": case, "seed": seed, "method": m, "cpu_s": t_base + t, **score(res)}
                row["tracks"] = {k: {kk: v.get(kk) for kk in ("amplitude_factor", "unevenness_rms_m")}
                                 for k, v in (res.tracks or {}).items()}
                rows.append(row)
            for r in rows[-(1 + (len(METHODS) if case == "as built" else 1)):]:
                print(f"{r['case']:<9} seed {r['seed']:<3} {r['method']:<10} worst {r['worst']:<5} "
                      f"{r['worst_pct']:+7.2f} %  covered {r['covered']:>2}/12  adequate {str(r['adequate']):<5} "
                      f"cpu {r['cpu_s']:6.1f} s", flush=True)
    (out / "bench_tracks.json").write_text(json.dumps(rows, indent=1))
    print("\nsummary (over seeds): method, case, largest |error| %, coverage, adequate, mean CPU s")
    for case, _, _ in cases:
        for m in ("as-drawn",) + METHODS:
            sel = [r for r in rows if r["case"] == case and r["method"] == m]
            if not sel:
                continue
            print(f"{case:<9} {m:<10} {max(abs(r['worst_pct']) for r in sel):6.2f} %  "
                  f"{sum(r['covered'] for r in sel)}/{12 * len(sel)}  "
                  f"{sum(bool(r['adequate']) for r in sel)}/{len(sel)} adequate  "
                  f"{np.mean([r['cpu_s'] for r in sel]):6.1f} s")


if __name__ == "__main__":
    main()
