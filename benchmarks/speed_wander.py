"""Speed as driven (SPEC §11): the lags behind the refusal of a run whose speed wanders, on the cases it must
refuse and the ones it must not.

For every constant-speed run of each case, the load-time check's lags of the data against the nominal car's
response at the declared speed (rideid.conditioning.speed), summarised as the speed's relative deviation between
neighbouring windows (low, high), the straight line's slope (mean) and the largest departure from it (wander):

* ``wander3``, ``wander1``: the SUV's five runs (tests/driven_speed.py, independent SciPy car, exact drawings,
  1 % noise) with a driver wandering +-3 % / +-1 %, written without the speed column
* ``held``: the same, the speed held exactly (no wander)
* ``asbuilt``: the SUV on tracks 4 % off their drawing with 1.5 mm RMS unevenness (tests/asbuilt_tracks.py)
* ``builtin``: the built-in car's ten runs simulated by ``rideid simulate builtin`` with 2 % noise
* ``off2``: the ``held`` runs declared 2 % slower than driven (a constant but wrong speed)

    PYTHONPATH=src .venv/bin/python benchmarks/speed_wander.py [--seeds 1 2 3] [--cases wander3 held ...]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import tomllib
import warnings
from pathlib import Path

import tomli_w

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
import rideid.conditioning.checks as checks  # noqa: E402
import rideid.conditioning.speed as speed  # noqa: E402
from asbuilt_tracks import write_dataset as write_asbuilt  # noqa: E402
from driven_speed import write_case  # noqa: E402


def _builtin(folder, seed):
    subprocess.run([sys.executable, "-m", "rideid", "simulate", "builtin", "--out", str(folder), "--noise", "0.02",
                    "--seed", str(seed), "--quiet"], check=True)


def _off(folder, seed, factor=0.98):
    write_case(folder, seed=seed, speed_channel=False, speed_column=False, wander=0.0)
    doc = tomllib.loads((folder / "dataset.toml").read_text())
    for r in doc["runs"]:
        r["speed"] = round(r["speed"] * factor, 6)
    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))


CASES = {
    "wander3": lambda f, s: write_case(f, seed=s, speed_channel=False, speed_column=False),
    "wander1": lambda f, s: write_case(f, seed=s, speed_channel=False, speed_column=False, wander=0.005),
    "held": lambda f, s: write_case(f, seed=s, speed_channel=False, speed_column=False, wander=0.0),
    "asbuilt": lambda f, s: write_asbuilt(f, seed=s),
    "builtin": _builtin,
    "off2": _off,
}


def measure(folder) -> dict:
    """Run id -> the speed summary (and the lags) of every constant-speed run, the refusal switched off."""
    got = {}
    real = checks.speed_held

    def spy(ds, rid, Y, Yhat):
        w = checks.speed_lags(ds, rid, Y, Yhat)
        s = None if w is None else speed.speed_summary(w)
        if s is not None:
            got[rid] = dict(s, lag_ms=[round(1e3 * float(x), 2) for x in w["lag"]],
                            correlation=[round(float(x), 2) for x in w["correlation"]])
        return None

    checks.speed_held = spy
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rideid.load_dataset(folder)
    finally:
        checks.speed_held = real
    return got


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    args = ap.parse_args(argv)
    print("| case | seed | run | low % | high % | mean % | wander % | lags ms | correlation |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases:
            for seed in args.seeds:
                folder = Path(tmp) / f"{case}{seed}"
                CASES[case](folder, seed)
                for rid, s in measure(folder).items():
                    print(f"| {case} | {seed} | {rid} | {100 * s['low']:+.2f} | {100 * s['high']:+.2f} | "
                          f"{100 * s['mean']:+.2f} | {100 * s['wander']:.2f} | {s['lag_ms']} | {s['correlation']} |",
                          flush=True)


if __name__ == "__main__":
    main()
