"""Wall time until rideid says what went wrong, for each slip of a test day (issue 51's table).

Each case is made first (not timed) on an independent simulator where the tests have one:

* a run's speed typed 1 % high on the herringbone (10.1 for 10 m/s) and on the washboard (10.1 for 10 m/s): the
  SUV of tests/asbuilt_tracks.py (SciPy lsim) on the exact drawings, 1 % noise, three runs (T_HH, H_HH, W_H), as
  tests/test_priors.py writes them;
* every acceleration of that SPEC CSV written in g;
* a logger at 500 Hz read with the default rate: the van with real dampers of tests/rate_case.py (its logger's
  files, no ``[preprocess] fs``).

Then the clock runs from ``rideid.load_dataset`` to the line that names the slip (a warning, a refusal, or the
rate the load chose and why), and the table prints: slip, the diagnosis line (cut to 150 characters), wall s.

    python benchmarks/slip_times.py [OUT]       # OUT: where the cases are written (default: a temporary folder)
"""

from __future__ import annotations

import sys
import tempfile
import time
import warnings
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
from rideid.errors import DataError  # noqa: E402
from asbuilt_tracks import in_g, write_exact  # noqa: E402



def suv(folder: Path, speeds: dict | None = None) -> Path:
    """The SUV on the exact drawings (tests/asbuilt_tracks.py's ``write_exact``): T_HH, H_HH, W_H; ``speeds``
    declared."""
    return write_exact(folder, ["T_HH", "H_HH", "W_H"], speeds)


def diagnose(folder: Path, named) -> tuple[str, float]:
    """Load ``folder``; the first warning or error for which ``named(text)`` holds, and the seconds it took."""
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        try:
            ds = rideid.load_dataset(folder)
        except DataError as exc:
            return str(exc), time.perf_counter() - t0
    wall = time.perf_counter() - t0
    for w in rec:
        if named(str(w.message)):
            return str(w.message), wall
    rules = {ds.measured[r.id].record["resampling"].get("rule", "") for r in ds.runs if r.id in ds.measured}
    hit = [r for r in rules if named(r)]
    return (hit[0] if hit else "NOT NAMED at load"), wall


def main(out: Path) -> list[tuple[str, str, float]]:
    rows = []
    herring = suv(out / "herringbone", {"H_HH": 10.1})
    rows.append(("speed 1 % high, herringbone (10.1 for 10)",
                 *diagnose(herring, lambda m: "run 'H_HH'" in m and "declared speed" in m)))
    wash = suv(out / "washboard", {"W_H": 10.1})
    rows.append(("speed 1 % high, washboard (10.1 for 10)",
                 *diagnose(wash, lambda m: "run 'W_H'" in m and "declared speed" in m)))
    g = in_g(suv(out / "exact"), out / "in_g")
    rows.append(("every acceleration in g", *diagnose(g, lambda m: "look written in g" in m)))
    from rate_case import write_van_logger
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        logger = write_van_logger(out / "van500", 500.0)
    rows.append(("logger at 500 Hz, default rate", *diagnose(logger, lambda m: "500 Hz" in m)))
    return rows


if __name__ == "__main__":
    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp(prefix="slip_times_"))
    folder.mkdir(parents=True, exist_ok=True)
    table = main(folder)
    print(f"{'slip':<44} {'wall s':>7}  diagnosis")
    for slip, line, wall in table:
        print(f"{slip:<44} {wall:>7.2f}  {' '.join(line.split())[:150]}")
