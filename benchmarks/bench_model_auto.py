"""Cost of ``rideid identify --model auto`` against ``--model base`` and ``--model full``.

The built-in car and tracks, 2 % noise, seed 1, ``--no-report``, each in its
own process (numba cache warm). Issue 15 asks auto <= 3x base. Wall time is
shown with the CPU time of the process, which is the fairer ratio on a
shared machine. Run: ``python benchmarks/bench_model_auto.py`` (or ``make bench``).
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def cli(args):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "rideid"] + [str(a) for a in args], capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(r.stderr)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(out=sys.stdout):
    def say(*a):
        print(*a, file=out, flush=True)

    import rideid
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        cli(["simulate", rideid.default_scenario_path(), "--out", d / "ds", "--quiet", "--noise", "0.02",
             "--seed", "1"])
        cli(["identify", d / "ds", "--out", d / "warm", "--seed", "1", "--quiet", "--generations", "2",
             "--model", "base", "--no-report"])
        say("## `rideid identify --model base|full|auto` on the built-in dataset (2 % noise)\n")
        say("| model | wall time | CPU time | generations | kept | ratio to base (wall / CPU) |")
        say("|---|---|---|---|---|---|")
        base = None
        for model in ("base", "full", "auto"):
            o = d / model
            wall, cpu = cli(["identify", d / "ds", "--out", o, "--seed", "1", "--quiet", "--no-report",
                             "--model", model])
            res = json.loads((o / "result.json").read_text())
            base = base or (wall, cpu)
            kept = " + ".join(res["model"]["extensions"]) or "base"
            say(f"| {model} | {wall:.1f} s | {cpu:.1f} s | {res['generations']} | {kept} | "
                f"{wall / base[0]:.2f} / {cpu / base[1]:.2f} |")


if __name__ == "__main__":
    main()
