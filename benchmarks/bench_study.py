"""Throughput of ``rideid study``: tasks per minute on a 2-worker local cluster vs serial loops.

The same Monte Carlo tasks (built-in car, 1 % noise, one noise seed per
task, JADE population 16 with the polish) are run three ways in one run:

* serial, one core: the study's own task function in a plain loop in this
  process (Numba and BLAS limited to one thread, as in a worker);
* serial, Numba's threads: the same identifications in a loop with the
  compiled kernel free to use every core (what a shell loop of
  ``rideid identify`` gets);
* ``rideid.study`` on a local cluster of 2 single-threaded worker
  processes, timed from the call to the written summary (cluster start-up,
  the workers' kernel loading and the output files included).

The study's table must equal the serial results bit for bit. On 2 idle
cores the expected ratio against the one-core loop is >= 1.7 (two tasks at
a time, less the start-up); against Numba's threads it is smaller, since
the kernel already uses both cores for part of each task. Run:
``python benchmarks/bench_study.py [--tasks 12]`` or ``make bench``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from pathlib import Path


def main(argv=None, out=sys.stdout):
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", type=int, default=12)
    ap.add_argument("--generations", type=int, default=40)
    a = ap.parse_args(argv)

    def say(*x):
        print(*x, file=out, flush=True)

    import rideid
    from rideid.studies.engine import machine_cores
    from rideid.studies.task import _identify, run_task

    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        (d / "mc.toml").write_text(
            f"[data]\nscenario = 'builtin'\nnoise = 0.01\nnoise_seeds = {{ first = 1, count = {a.tasks} }}\n"
            f"[identify]\npopulation = 16\ngenerations = {a.generations}\n")
        st = rideid.load_study(d / "mc.toml")
        sc = rideid.default_scenario()
        run_task(st.tasks[0].options, scenario=sc)  # kernels loaded, caches warm

        t = time.perf_counter()
        serial = [run_task(task.options, scenario=sc) for task in st.tasks]
        t_one = time.perf_counter() - t
        assert all(r["status"] == "done" for r in serial), [r["error"] for r in serial]

        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for task in st.tasks:
                with tempfile.TemporaryDirectory() as tmp:
                    _identify(task.options, None, sc, Path(tmp))
        t_threads = time.perf_counter() - t

        finished = []
        t = time.perf_counter()
        res = rideid.study(st, d / "out", n_workers=2,
                           progress=lambda info: finished.append(time.perf_counter()) if info["done"] else None)
        t_study = time.perf_counter() - t
        # steady state: after the first wave (one task per worker, which also pays the workers' start-up)
        steady = (len(finished) - 2) / (finished[-1] - finished[1]) if len(finished) > 2 else float("nan")
        rows = res.table().to_pylist()
        same = all(rows[i][n] == serial[i]["row"][n] for i in range(len(rows)) for n in rideid.NAMES)

    n = a.tasks
    say(f"## `rideid study` throughput: {n} Monte Carlo tasks (built-in car, population 16, "
        f"{a.generations} generations + polish), {machine_cores()} cores\n")
    say("| how | wall time | tasks per minute | ratio |")
    say("|---|---|---|---|")
    say(f"| serial loop, one core | {t_one:.1f} s | {60 * n / t_one:.1f} | 1.00 |")
    say(f"| serial loop, Numba's threads | {t_threads:.1f} s | {60 * n / t_threads:.1f} | {t_one / t_threads:.2f} |")
    say(f"| rideid.study, local cluster 2 workers x 1 thread | {t_study:.1f} s | {60 * n / t_study:.1f} | "
        f"{t_one / t_study:.2f} |")
    say(f"| rideid.study, steady state (after each worker's first task) | | {60 * steady:.1f} | "
        f"{steady * t_one / n:.2f} |")
    say(f"\nstudy table equals the serial results bit for bit: {same}")
    say("(ratio = serial one-core wall time / wall time; the study's time includes starting the cluster and "
        "writing results.parquet and the summary)")
    return t_one / t_study


if __name__ == "__main__":
    main()
