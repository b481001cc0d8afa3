"""Where a real test's time goes: each case identified by ``rideid identify --profile``, stage by stage.

    python benchmarks/bench_realtest.py [--cases builtin,realities,...] [--out bench-out/realtest]

The cases (each written first, by the tests' independent simulators or the shared cases' scripts, then
identified with the defaults and seed 1, as a user would):

* ``builtin``: the built-in car's ten runs, 1 % noise (``rideid simulate builtin``): the clean baseline;
* ``realities``: the SUV with every reality of SPEC §11 at once, five runs (tests/realities_case.py);
* ``realities-ten``: the same realities on the built-in car and its ten runs (a proving-ground day's ten-run real
  test: an engine on mounts, tracks as built, AC-coupled hubs, a clipping hub, a GPS speed channel, unstated
  starts; tests/realities_case.py, ``car="builtin"``);
* ``gps``: the SUV along a GPS speed channel, five runs (tests/driven_speed.py);
* ``knees``: the knee car with the knots found (tests/knee_cars.py, car ``bars``), 1 % noise;
* ``van-csv`` / ``van-logger``: the shared damper van as SPEC CSV and as logger files
  (../shared/cases/damper-van-logger, when that folder is beside the repository);
* ``roads``: the built-in car with tire damping on two unknown 12 s ISO roads, 2 % noise (the case of
  tests/test_road_model_choice.py);
* ``van-roads``: the shared van with digressive dampers on three unknown roads and one twist run, 2 % noise
  (../shared/cases/van-roads-dampers, when beside the repository); ``van-roads-slip``: the same with the twist
  run's speed typed 3.03 m/s (driven at 3.0).

Each case's table: the stages of ``profile.csv`` (wall and CPU seconds, CPU counting every thread), its
whole wall time, and, for scale, the same wall time in units of a plain SciPy baseline measured in the same
run (``scipy.signal.lsim`` of the built-in car's linear state space over its ten runs: one cost evaluation as
a SciPy user would write it). The summary table is written to ``OUT/realtest.md``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"
SHARED = ROOT.parent / "shared" / "cases"
CASES = ("builtin", "realities", "realities-ten", "gps", "knees", "van-csv", "van-logger", "roads", "van-roads",
         "van-roads-slip")


def _rideid(*args, cwd=None) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("rideid")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "rideid"]
    return subprocess.run(cmd + [str(a) for a in args], cwd=cwd, capture_output=True, text=True)


def scipy_baseline() -> float:
    """Seconds of one plain-SciPy cost evaluation: ``lsim`` of the built-in car's state space over the ten
    runs' road inputs (median of three)."""
    from scipy import signal

    import rideid
    from rideid.model.equations import state_space
    from rideid.model.params import as_vector

    sc = rideid.default_scenario()
    A, B, C, D = (m[0] for m in state_space(as_vector(sc.truth), sc.geometry))
    sys_ = signal.StateSpace(A, B, C, D)
    rng = np.random.default_rng(1)
    inputs = [(rng.standard_normal((int(r.duration * r.fs), B.shape[1])) * 1e-3, r.fs) for r in sc.runs]
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        for u, fs in inputs:
            signal.lsim(sys_, u, np.arange(u.shape[0]) / fs)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def write_case(case: str, folder: Path) -> Path:
    """Write case ``case``'s dataset under ``folder``; returns the dataset folder."""
    sys.path.insert(0, str(TESTS))
    data = folder / "data"
    if data.exists():
        shutil.rmtree(data)
    if case == "builtin":
        _check(_rideid("simulate", "builtin", "--out", data, "--noise", "0.01", "--seed", "1", "--quiet"))
    elif case in ("realities", "realities-ten"):
        import realities_case
        realities_case.write_dataset(data, car="suv" if case == "realities" else "builtin", seed=1)
    elif case == "gps":
        import driven_speed
        driven_speed.write_case(data, seed=1)
    elif case == "knees":
        import knee_cars
        import tomli_w
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "scenario.toml").write_text(tomli_w.dumps(knee_cars.scenario_doc("bars")))
        _check(_rideid("simulate", folder / "scenario.toml", "--out", data, "--noise", "0.01", "--seed", "1",
                       "--quiet"))
    elif case in ("van-csv", "van-logger"):
        van = SHARED / "damper-van-logger"
        if not van.is_dir():
            raise FileNotFoundError(f"{van}: the shared van case is not beside the repository")
        sim = folder / "sim"
        if not sim.exists():
            _check(_rideid("simulate", van / "scenario.toml", "--out", sim, "--noise", "0.01", "--seed", "1",
                           "--quiet"))
        if case == "van-csv":
            shutil.copytree(sim, data)
        else:
            subprocess.run([sys.executable, str(van / "make_logger.py"), str(sim), str(data), "2.5"], check=True)
            shutil.copy(van / "logger.toml", data / "dataset.toml")
    elif case == "roads":
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "scenario.toml").write_text(_roads_scenario())
        _check(_rideid("simulate", folder / "scenario.toml", "--out", data, "--noise", "0.02", "--seed", "3",
                       "--quiet"))
    elif case in ("van-roads", "van-roads-slip"):
        van = SHARED / "van-roads-dampers"
        if not van.is_dir():
            raise FileNotFoundError(f"{van}: the shared case is not beside the repository")
        _check(_rideid("simulate", van / "scenario.toml", "--out", data, "--noise", "0.02", "--seed", "1",
                       "--quiet"))
        if case == "van-roads-slip":  # the twist run's speed typed 1 % high (driven at 3.0 m/s)
            manifest = data / "dataset.toml"
            manifest.write_text(manifest.read_text().replace('speed = 3.0, file = "runs/T_HL.csv"',
                                                             'speed = 3.03, file = "runs/T_HL.csv"'))
    else:
        raise ValueError(f"unknown case {case!r}; the cases: {', '.join(CASES)}")
    return data


def _roads_scenario() -> str:
    """The scenario of ``roads``: the built-in car, tire damping 400 N s/m, no bars (declared), two roads."""
    import tomli_w

    import rideid
    from rideid.model.params import total_mass

    sc = rideid.default_scenario()
    g = sc.geometry
    truth = dict(sc.truth, c_tf=400.0, c_tr=400.0)
    runs = [{"id": "B40", "road_class": "B", "speed": 11.0, "fs": 200.0, "duration": 12.0},
            {"id": "C25", "road_class": "C", "speed": 7.0, "fs": 200.0, "duration": 12.0}]
    return tomli_w.dumps({"name": "roads", "vehicle": {k: getattr(g, k) for k in g.KEYS},
                          "known": {"total_mass": float(total_mass(dict(sc.truth))), "k_arf": 0.0, "k_arr": 0.0},
                          "truth": truth, "runs": runs})


def _check(p: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    if p.returncode != 0:
        raise RuntimeError(f"rideid failed ({p.returncode}): {p.stderr.strip() or p.stdout.strip()}")
    return p


def run_case(case: str, out: Path) -> dict:
    """Write and identify one case; its profile rows, wall time and the identify command's last lines."""
    folder = out / case
    data = write_case(case, folder)
    fit = folder / "fit"
    t0 = time.perf_counter()
    _check(_rideid("identify", data, "--out", fit, "--seed", "1", "--quiet", "--no-report", "--profile"))
    wall = time.perf_counter() - t0
    with open(fit / "profile.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {"case": case, "wall_s": wall, "rows": rows, "verdict": verdict_of(fit / "result.json")}


def verdict_of(path: Path) -> str:
    """The model kept and the verdict of a result.json, in a few words."""
    res = json.loads(Path(path).read_text())
    ok = (res.get("adequacy") or {}).get("adequate")
    model = " + ".join(res.get("model", {}).get("extensions") or []) or "base"
    return f"{model}; {'adequate' if ok else 'NOT adequate' if ok is False else 'not assessed'}"


def main(argv=None, out=sys.stdout):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma-separated: " + ", ".join(CASES))
    ap.add_argument("--out", default="bench-out/realtest", help="folder for the cases and realtest.md")
    args = ap.parse_args(argv)
    dest = Path(args.out)
    dest.mkdir(parents=True, exist_ok=True)
    base = scipy_baseline()
    lines = [f"# Real tests, stage by stage ({os.cpu_count()} cores)", "",
             f"SciPy baseline (lsim of the built-in car over its ten runs): {base * 1e3:.1f} ms", ""]
    summary = ["| case | wall s | CPU s | x SciPy baseline | largest stage | verdict |", "|---|---|---|---|---|---|"]
    for case in args.cases.split(","):
        r = run_case(case.strip(), dest)
        total = next(x for x in r["rows"] if x["stage"] == "total")
        top = [x for x in r["rows"] if x["stage"] != "total"]
        deepest = max((x for x in top if int(x["depth"]) > 0), key=lambda x: float(x["self_wall_s"]),
                      default=max(top, key=lambda x: float(x["wall_s"])))
        summary.append(f"| {case} | {r['wall_s']:.1f} | {float(total['cpu_s']):.1f} | {r['wall_s'] / base:.0f} | "
                       f"{deepest['stage']} ({float(deepest['self_wall_s']):.1f} s self) | {r['verdict'][:60]} |")
        lines += [f"## {case}", "", "| stage | calls | wall s | CPU s | self s |", "|---|---|---|---|---|"]
        lines += [f"| {'&nbsp;' * 2 * int(x['depth'])}{x['stage'].rsplit('/', 1)[-1]} | {x['calls']} | "
                  f"{float(x['wall_s']):.2f} | {float(x['cpu_s']):.2f} | {float(x['self_wall_s']):.2f} |"
                  for x in r["rows"]]
        lines.append("")
        print(f"{case}: {r['wall_s']:.1f} s", file=out, flush=True)
    text = "\n".join(lines[:4] + summary + [""] + lines[4:]) + "\n"
    (dest / "realtest.md").write_text(text)
    out.write(text)


if __name__ == "__main__":
    main()
