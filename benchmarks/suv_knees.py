"""The SUV with anti-roll bars, tire damping and dampers bending at 0.12 m/s (issue 50's done-when), defaults.

The case of ``tests/suv_knees_case.py`` (an independent simulator's runs, 1 % white noise) written as SPEC CSV
and as logger files with estimated starts; ``rideid identify DATASET --seed 1`` on each, with the defaults
(``--model auto``). Printed per path: the wall time, the groups kept, the model choice's steps and skipped rivals,
each parameter's error (the twelve less the dampers' slopes, the bars, the tire damping), the curves' largest
error at the excited knots, the logger path's largest start error, the verdict. Goal: the parameters within 1 %,
the curves within 3 %, adequate.

Run: ``PYTHONPATH=src python benchmarks/suv_knees.py OUT [--small] [--seed N] [--paths spec logger]``
(``--small``: the three runs of the default test, ``SMALL``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import suv_knees_case as case  # noqa: E402

from rideid.cli import main as cli  # noqa: E402


def identify(ds: Path, out: Path) -> tuple[float, dict]:
    """``rideid identify ds --out out --seed 1`` with the defaults: (wall s, result.json)."""
    t = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        rc = cli(["identify", str(ds), "--out", str(out), "--seed", "1", "--quiet", "--no-report"])
    wall = time.perf_counter() - t
    assert rc == 0, rc
    return wall, json.loads((out / "result.json").read_text())


def describe(res: dict, wall: float, logger: bool = False, out=sys.stdout) -> dict:
    """Print one fit's line-up (module docstring); returns the errors of :func:`suv_knees_case.errors`."""
    err = case.errors(res, logger)
    model = res["model"]
    print(f"  wall {wall:.0f} s; kept {model['extensions']}; adequate {res['adequacy']['adequate']}; "
          f"steps on top {model.get('steps')}", file=out)
    for c in model.get("candidates", []):
        print(f"    candidate {c['extensions']}: cost {c['cost']:.5g}, criterion {c['criterion']}, "
              f"wald {c['wald']:.4g}, fits better {c['fits_better']}", file=out)
    for s in model.get("screens", []):
        print(f"    screen {s['extensions']}: score {s['score']:.4g} (threshold {s['threshold']:.3g}), predicted gain "
              f"{s['predicted_gain']:.3g}, passes {s['passes']}", file=out)
    knees = (res.get("dampers") or {}).get("knees") or {}
    if knees:
        print("    knees (m/s, true " + f"{case.KNEE}): " + ", ".join(
            f"{axle} {side} {abs(k['velocity']):.3f}" for axle, sides in knees.items() for side, k in sides.items()),
            file=out)
    cells = [f"{n} {100 * e:+.2f} %" for n, e in err.items() if n in case.TRUTH and not math.isnan(e)]
    for i in range(0, len(cells), 6):
        print("  " + ", ".join(cells[i:i + 6]), file=out)
    missing = [n for n in case.TRUTH if math.isnan(err[n])]
    worst = max(abs(e) for n, e in err.items() if n in case.TRUTH and not math.isnan(e))
    print(f"  largest parameter error {100 * worst:.2f} %{'; not estimated: ' + ', '.join(missing) if missing else ''}"
          f"; curves {100 * err['curves']:.2f} %; starts {1e3 * err['start']:.1f} ms", file=out)
    return err


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--small", action="store_true", help="the default test's three runs")
    ap.add_argument("--seed", type=int, default=1, help="the noise's seed")
    ap.add_argument("--paths", nargs="+", default=["spec", "logger"], choices=["spec", "logger"])
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    folders = dict(zip(("spec", "logger"), case.write(a.out / "data", runs=case.SMALL if a.small else None,
                                                          seed=a.seed)))
    for path in a.paths:
        print(f"{path} ({'small' if a.small else 'full'}, seed {a.seed}):")
        wall, res = identify(folders[path], a.out / f"fit-{path}")
        describe(res, wall, path == "logger")
    return 0


if __name__ == "__main__":
    sys.exit(main())
