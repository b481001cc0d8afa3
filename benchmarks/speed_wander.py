"""Speed as driven (SPEC §11): the lags behind the refusal of a run whose speed wanders, on the cases it must
refuse and the ones it must not.

For every constant-speed run of each case, the load-time check's lags of the data against the nominal car's
response at the declared speed (rideid.conditioning.speed), summarised as the speed's relative deviation between
neighbouring windows with its uncertainty, the largest deviation beyond Z_MIN times its uncertainty (the one the
check compares with WANDER_MAX) and the straight line's slope (mean):

* ``wander3``, ``wander1``: the SUV's five runs (tests/driven_speed.py, independent SciPy car, exact drawings,
  1 % noise) with a driver wandering +-3 % / +-1 %, written without the speed column
* ``held``: the same, the speed held exactly (no wander)
* ``asbuilt``: the SUV on tracks 4 % off their drawing with 1.5 mm RMS unevenness (tests/asbuilt_tracks.py)
* ``builtin``: the built-in car's ten runs simulated by ``rideid simulate builtin`` with 2 % noise
* ``van``: the 2.45 t van of tests/conftest.py (a car far from the nominal one) on the same ten runs, 2 % noise
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

import numpy as np
import tomli_w

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
import rideid.conditioning.checks as checks  # noqa: E402
import rideid.conditioning.speed as speed  # noqa: E402
from asbuilt_tracks import write_dataset as write_asbuilt  # noqa: E402
from driven_speed import write_case  # noqa: E402


def _builtin(folder, seed):
    subprocess.run([sys.executable, "-m", "rideid", "simulate", "builtin", "--out", str(folder), "--noise", "0.02",
                    "--seed", str(seed), "--quiet"], check=True, stdout=subprocess.DEVNULL)


def _van(folder, seed):
    from conftest import van_scenario
    from rideid.synth.scenario import simulate_manifest, write_dataset
    folder.mkdir(parents=True, exist_ok=True)
    sc = van_scenario(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data, _ = simulate_manifest(sc, noise=0.02, seed=seed)
    write_dataset(sc, data, folder / "ds")
    return folder / "ds"


def _off(folder, seed, factor=0.98):
    write_case(folder, seed=seed, speed_channel=False, speed_column=False, wander=0.0)
    doc = tomllib.loads((folder / "dataset.toml").read_text())
    for r in doc["runs"]:
        r["speed"] = round(r["speed"] * factor, 6)
    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))


def _written(make):
    """A case writer that returns the dataset folder."""
    def write(folder, seed):
        make(folder, seed)
        return folder
    return write


CASES = {
    "wander3": _written(lambda f, s: write_case(f, seed=s, speed_channel=False, speed_column=False)),
    "wander1": _written(lambda f, s: write_case(f, seed=s, speed_channel=False, speed_column=False, wander=0.005)),
    "held": _written(lambda f, s: write_case(f, seed=s, speed_channel=False, speed_column=False, wander=0.0)),
    "asbuilt": _written(lambda f, s: write_asbuilt(f, seed=s)),
    "builtin": _written(_builtin),
    "van": _van,
    "off2": _written(_off),
}


def measure(folder) -> dict:
    """Run id -> the speed summary (and the lags) of every constant-speed run, the refusal switched off."""
    got = {}
    real = checks.speed_held

    def spy(ds, rid, Y, Yhat, **_options):  # the check's options (steady_ok) do not change the lags
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
    print("| case | seed | run | deviations % | +- % | seen beyond 1x % | mean % | lags ms | correlation |")
    print("|---|---|---|---|---|---|---|---|---|")
    summary = {}
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases:
            for seed in args.seeds:
                got = measure(CASES[case](Path(tmp) / f"{case}{seed}", seed))
                for rid, s in got.items():
                    print(f"| {case} | {seed} | {rid} | {[round(100 * float(x), 2) for x in s['deviation']]} | "
                          f"{[round(100 * float(x), 2) for x in s['std']]} | {100 * s['beyond']:.2f} | "
                          f"{100 * s['mean']:+.2f} | {s['lag_ms']} | {s['correlation']} |", flush=True)
                worst = max((max(-s["low"], s["high"]) for s in got.values()), default=0.0)
                z = max((float(np.max(np.abs(s["deviation"]) / s["std"])) for s in got.values()), default=0.0)
                seen = max((s["beyond"] for s in got.values()), default=0.0)
                refused = sum(s["beyond"] > speed.WANDER_MAX for s in got.values())
                summary.setdefault(case, []).append((seed, worst, z, seen, refused, len(got)))
    print(f"\n| case | seed | largest deviation % | largest deviation / its uncertainty | largest seen (beyond "
          f"{speed.Z_MIN:g}x) % | runs refused | runs checked |")
    print("|---|---|---|---|---|---|---|")
    for case, rows in summary.items():
        for seed, worst, z, seen, refused, n in rows:
            print(f"| {case} | {seed} | {100 * worst:.2f} | {z:.2f} | {100 * seen:.2f} | {refused} | {n} |")


if __name__ == "__main__":
    main()
