"""Wall time and peak memory of ``rideid identify`` on the built-in dataset.

Runs the real command line in a subprocess (numba cache warm), noise-free
data: the twelve-parameter model (``--model base``) and the default model
choice (``--model auto``: a full-model search and three polishes), with and
without the report, and reports the largest parameter error. Targets
(base): 3 s without the report, 5 s with it; the default (auto, report) 3 s. Run: ``make bench``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: the command line as the ``rideid`` command runs it (rideid.cli.console: no interpreter teardown for
#: these commands), reporting the main process's peak memory
RUSAGE = ("import os, resource, sys; from rideid.cli import FAST_EXIT, main; rc = main(sys.argv[1:]); "
          "print('MAXRSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr); "
          "sys.stdout.flush(); sys.stderr.flush(); os._exit(rc) if sys.argv[1] in FAST_EXIT else sys.exit(rc)")


def cli(args, repeat=1):
    """Best wall time of ``repeat`` runs of the command line, its CPU time (user + system, the
    process and its children: steadier than wall time on a shared machine) and peak memory."""
    import resource
    best = None
    for _ in range(repeat):
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        r = subprocess.run([sys.executable, "-c", RUSAGE] + [str(a) for a in args], capture_output=True, text=True)
        wall = time.perf_counter() - t
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if r.returncode != 0:
            raise RuntimeError(r.stderr)
        cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)
        rss = [ln for ln in r.stderr.splitlines() if ln.startswith("MAXRSS")]
        mem = int(rss[0].split()[1]) / 1024 if rss else float("nan")
        if best is None or wall < best[0]:
            best = (wall, cpu, mem)
    return best


#: the same rows on the same machine before the package restructure (stop 32: lazy imports, the report's
#: figures on their own canvases, dogbox polish), best of 3; the goal for the default row is 3 s
BEFORE = {"--model base (report)": "2.8 s", "--model base --no-report": "1.7 s",
          "default: --model auto (report)": "4.3 s", "--model auto --no-report": "3.3 s",
          "--model base --no-polish --no-report": "3.1 s", "--help": "0.59 s"}


def _wall(cmd) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t


def main(out=sys.stdout):
    def say(*a):
        print(*a, file=out, flush=True)

    import rideid
    truth = rideid.default_scenario().truth
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        cli(["simulate", rideid.default_scenario_path(), "--out", d / "ds", "--quiet"])
        cli(["identify", d / "ds", "--out", d / "warm", "--seed", "1", "--quiet", "--generations", "2"])
        say("## `rideid identify` on the built-in dataset (noise-free)\n")
        say("best of 3 runs; CPU = user + system time of all the process's threads and figure workers\n")
        say("| variant | wall time | before the restructure | CPU time | peak memory | generations | largest error |")
        say("|---|---|---|---|---|---|---|")
        for label, extra in (("--model base (report)", ["--model", "base"]),
                             ("--model base --no-report", ["--model", "base", "--no-report"]),
                             ("default: --model auto (report)", []),
                             ("--model auto --no-report", ["--no-report"]),
                             ("--model base --no-polish --no-report",
                             ["--model", "base", "--no-polish", "--no-report"])):
            o = d / "".join(ch if ch.isalnum() else "_" for ch in label)
            wall, cpu, rss = cli(["identify", d / "ds", "--out", o, "--seed", "1", "--quiet"] + extra, repeat=3)
            res = json.loads((o / "result.json").read_text())
            worst = max(abs(res["parameters"][n]["value"] / truth[n] - 1) for n in truth)
            say(f"| {label} | {wall:.1f} s (identify {res['wall_time_s']:.1f} s) | {BEFORE[label]} | {cpu:.1f} s | "
                f"{rss:.0f} MiB | {res['generations']} | {100 * worst:.2g} % |")
        # the command line's start: --help imports neither NumPy nor the kernels
        t_help = min(_wall([sys.executable, "-m", "rideid", "--help"]) for _ in range(5))
        say(f"\n`rideid --help`: {t_help:.2f} s (before the restructure: {BEFORE['--help']}; goal 0.3 s)")
        # the first call after installing compiles the kernels; later processes load Numba's cache
        import os
        env = dict(os.environ, NUMBA_CACHE_DIR=str(d / "cold-cache"))
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "from rideid.model.backend import compile_kernels; compile_kernels()"],
                       env=env, check=True)
        cold = time.perf_counter() - t
        t = time.perf_counter()
        subprocess.run([sys.executable, "-c", "from rideid.model.backend import compile_kernels; compile_kernels()"],
                       env=env, check=True)
        warm = time.perf_counter() - t
        say(f"\nkernel compilation, first run after install: {cold:.1f} s; later runs (cache): {warm:.1f} s "
            "(both including Python start-up and imports)")


if __name__ == "__main__":
    main()
