"""Damper knees found by the data (issue 38): the price in time, and the knee grid against the alternatives.

The built-in car with smooth digressive dampers bending at 0.13 m/s, rebound 2:1 (``tests/knee_cars.py``,
car ``sedan``: not piecewise linear on any knots rideid fits), simulated with 1 % noise (seed 3), identified
by ``rideid identify --model damper_curves --seed 1`` three ways on the same data:

* ``found``: no ``[model] damper_knots`` (the knee grid, knees read off the fitted curves);
* ``given``: ``damper_knots = [0.025, 0.05, 0.13, 0.2, 0.4]``, a user who knew where the damper bends;
* ``default``: ``damper_knots`` = the default knots ``[0.025, 0.05, 0.1, 0.2, 0.4]`` (rideid before the grid).

Printed per way: wall time (best of ``--repeats`` interleaved, the machine may be shared), the largest
parameter error, the largest curve error at the excited knots, how many parameters ±2 std_robust covers,
the adequacy verdict and the knees; then the ratio found / given (goal <= 2).
Run: ``python benchmarks/bench_knees.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
import time
from pathlib import Path

import tomli_w

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from knee_cars import curve_error, scenario_doc  # noqa: E402

from rideid.cli import main  # noqa: E402
from rideid.data.schema import read_toml  # noqa: E402

WAYS = {"found": None, "given": [0.025, 0.05, 0.13, 0.2, 0.4], "default": [0.025, 0.05, 0.1, 0.2, 0.4]}


def _identify(ds: Path, knots, out: Path) -> tuple[float, dict]:
    doc = read_toml(ds / "dataset.toml")
    doc.pop("model", None)
    if knots is not None:
        doc["model"] = {"damper_knots": knots}
    (ds / "dataset.toml").write_text(tomli_w.dumps(doc))
    t = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        rc = main(["identify", str(ds), "--out", str(out), "--model", "damper_curves", "--seed", "1", "--quiet",
                   "--no-report"])
    wall = time.perf_counter() - t
    assert rc == 0, rc
    return wall, json.loads((out / "result.json").read_text())


def _summary(res: dict, truth: dict) -> dict:
    errs, cov, n = {}, 0, 0
    for k, v in truth.items():
        e = res["parameters"][k]
        if e["fixed"]:
            continue
        errs[k] = e["value"] / v - 1
        if e.get("std_robust"):
            n += 1
            cov += abs(e["value"] - v) <= 2 * e["std_robust"]
    worst = max(errs, key=lambda k: abs(errs[k]))
    knees = {a: [(res["dampers"]["knees"][a][s]["velocity"]) for s in ("compression", "rebound")]
             for a in ("front", "rear")}
    curve = 100 * curve_error("sedan", res["dampers"])
    return {"worst": f"{worst} {100 * errs[worst]:+.3f} %", "curve": f"{curve:.2f} %",
            "covered": f"{cov}/{n}", "adequate": res["adequacy"]["adequate"], "knees": knees}


def main_bench(repeats: int = 1) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "sc.toml").write_text(tomli_w.dumps(scenario_doc("sedan")))
        ds = tmp / "ds"
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["simulate", str(tmp / "sc.toml"), "--out", str(ds), "--noise", "0.01", "--seed", "3",
                         "--quiet"]) == 0
        truth = read_toml(ds / "truth.toml")["truth"]
        best, rows = {}, {}
        for r in range(repeats):
            for way, knots in WAYS.items():
                wall, res = _identify(ds, knots, tmp / f"fit-{way}-{r}")
                best[way] = min(best.get(way, float("inf")), wall)
                rows[way] = _summary(res, truth)
    for way in WAYS:
        print(f"{way:8s} {best[way]:7.1f} s  worst {rows[way]['worst']:>18s}  curves {rows[way]['curve']:>7s}  "
              f"covered {rows[way]['covered']}  adequate {rows[way]['adequate']}  knees {rows[way]['knees']}")
    ratio = best["found"] / best["given"]
    print(f"found / given knots: {ratio:.2f} x (goal <= 2)")
    return {"seconds": best, "ratio_found_given": ratio, "rows": rows}


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=1)
    main_bench(ap.parse_args().repeats)
