"""Run a study on Dask: a local cluster by default, an existing one by address; resumable.

Data flow
---------
* The client (this process) validates the study file, hashes every task's
  data and writes nothing until that succeeded.
* Scenario studies: the parsed scenario (a few kB) is sent inside every
  task, and each task simulates its noisy dataset in the worker (no files
  needed on the workers, except profile tracks' CSVs). It is not scattered:
  scattered data die with the worker that holds them and Dask cannot
  recompute them, while a task's own arguments survive any worker's death. Dataset studies: tasks carry the
  dataset's absolute path and the worker reads it, so on a remote cluster
  the datasets must be on a filesystem every worker sees at the same path.
* Workers return each task's record to the client, which writes it to
  ``DIR/tasks/<key>.json`` atomically (a temporary file, then
  ``os.replace``): the output folder need only be visible to the client.
* A restarted study skips every task whose record exists (and is final),
  so a study killed at any moment loses at most the tasks in flight. Dask
  itself reruns a task whose worker died (up to
  ``distributed.scheduler.allowed-failures`` times).
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from ..data.scenario import default_scenario, load_scenario
from ..errors import ArgumentError, DataError
from .spec import BUILTIN, Study, load_study
from .summary import write_summary
from ..data.schema.common import write_atomic
from .task import run_task


@dataclass
class StudyResult:
    """What :func:`rideid.study` returns.

    Attributes
    ----------
    tasks : int
        Tasks in the study.
    done, failed : int
        Tasks finished / failed (including those found from an earlier run).
    computed : int
        Tasks computed by this call (the others were resumed from ``DIR/tasks``).
    results : Path
        ``DIR/results.parquet``.
    summary : Path
        ``DIR/summary.html``.
    """

    tasks: int
    done: int
    failed: int
    computed: int
    results: Path
    summary: Path
    wall_time_s: float

    def table(self):
        """``results.parquet`` as a :class:`pyarrow.Table`."""
        import pyarrow.parquet as pq
        return pq.read_table(self.results)


def machine_cores() -> int:
    """Cores this process may use (affinity-aware)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


#: environment of local workers: one thread everywhere (a task uses one core; workers = cores)
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
              "MKL_NUM_THREADS": "1"}


def local_cluster(n_workers: int | None = None):
    """A :class:`distributed.LocalCluster` sized to the machine: ``n_workers`` processes x 1 thread."""
    import logging

    import signal
    import threading

    from distributed import LocalCluster
    n = n_workers or machine_cores()
    # Ctrl-C on a terminal reaches the whole process group: the workers are started with SIGINT ignored
    # (inherited, and kept by Python), so that only the client handles it and closes the cluster cleanly
    old = (signal.signal(signal.SIGINT, signal.SIG_IGN) if threading.current_thread() is threading.main_thread()
           else None)
    # The one-thread settings must be in the environment the worker processes start with (they
    # inherit this process's, set here for the spawn only): LocalCluster's ``env`` argument is applied
    # after the worker has imported Numba (whose thread count is read at import), and then every
    # worker ran 2 OpenMP threads whose spinning between parallel regions took the other worker's
    # core (measured: 10 s per task against 4.5 s in a plain process pool).
    saved = {k: os.environ.get(k) for k in WORKER_ENV}
    os.environ.update(WORKER_ENV)
    try:
        # ":0": the scheduler always serves HTTP (dashboard or not); a free port, not 8787 taken by another cluster
        import dask
        # Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers, which freezes glibc's mmap threshold
        # at 128 kB: every large NumPy temporary is then a fresh mmap, page-faulted in and unmapped
        # (a task took 8 s in a worker, 4.8 s in a plain process); rideid's workers keep glibc's default
        spawn_env = {k: v for k, v in dask.config.get("distributed.nanny.pre-spawn-environ").items()
                     if k != "MALLOC_TRIM_THRESHOLD_"}
        # and Dask's statistical profiler (it samples the task thread's stack every 10 ms) is off: the
        # nanny hands the workers this process's configuration
        with dask.config.set({"distributed.worker.profile.enabled": False,
                              "distributed.nanny.pre-spawn-environ": spawn_env}):
            return LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                silence_logs=logging.ERROR)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        if old is not None:
            signal.signal(signal.SIGINT, old)


def read_record(path: Path) -> dict | None:
    try:
        rec = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) and rec.get("status") in ("done", "failed") else None


def study(study_file_or_spec, out_dir, *, scheduler: str | None = None, progress=None,
          n_workers: int | None = None) -> StudyResult:
    """Run (or resume) a study of many identifications.

    Parameters
    ----------
    study_file_or_spec : str, Path or rideid.studies.Study
        A study TOML file (``docs/studies.md``) or a parsed study.
    out_dir : str or Path
        Output folder: ``tasks/<key>.json`` per task, ``results.parquet``,
        ``summary.md``, ``summary.csv``, ``summary.html`` and its figures.
        Tasks already recorded there are not recomputed.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``). Default:
        a local cluster with one single-threaded worker process per core.
    progress : callable, optional
        ``progress(info)`` after every finished task, with a dict: total,
        done, failed, resumed (found from an earlier run), running, elapsed
        (s), eta (s or None).
    n_workers : int, optional
        Worker processes of the local cluster (default: the cores).

    Returns
    -------
    StudyResult
    """
    t0 = time.perf_counter()
    spec = study_file_or_spec if isinstance(study_file_or_spec, Study) else load_study(study_file_or_spec)
    if scheduler is not None and not isinstance(scheduler, str):
        raise ArgumentError(f"scheduler must be an address such as 'tcp://127.0.0.1:8786', got {scheduler!r}")
    if n_workers is not None and (isinstance(n_workers, bool) or not isinstance(n_workers, int) or n_workers < 1):
        raise ArgumentError(f"n_workers must be a positive integer, got {n_workers!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DataError(f"{out}: exists and is not a folder")
    tasks_dir = out / "tasks"
    records = {}
    for t in spec.tasks:
        rec = read_record(tasks_dir / f"{t.key}.json")
        if rec is not None and (rec["status"] == "done" or rec.get("final")):
            records[t.key] = rec
    todo = [t for t in spec.tasks if t.key not in records]
    state = {"total": len(spec.tasks), "done": sum(r["status"] == "done" for r in records.values()),
             "failed": sum(r["status"] == "failed" for r in records.values()), "resumed": len(records),
             "running": len(todo), "elapsed": 0.0, "eta": None}
    # connect first: a wrong --scheduler leaves nothing behind
    client, cluster = _connect(scheduler, n_workers) if todo else (None, None)
    try:
        try:
            tasks_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise DataError(f"{out}: cannot create output folder: {e}") from None
        write_atomic(out / "study.json", json.dumps(
            {"name": spec.name, "file": str(spec.path) if spec.path else None, "study": spec.doc,
             "tasks": [{"index": t.index, "key": t.key, "options": t.options} for t in spec.tasks]},
            indent=1, default=str) + "\n")
        if progress is not None:
            progress(dict(state))
        if todo:
            _compute(client, spec, todo, tasks_dir, records, state, progress, t0)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()

    ordered = [(t, records.get(t.key)) for t in spec.tasks]
    html = write_summary(spec, ordered, out)
    done = sum(1 for _, r in ordered if r is not None and r["status"] == "done")
    failed = sum(1 for _, r in ordered if r is not None and r["status"] == "failed")
    return StudyResult(len(spec.tasks), done, failed, len(todo), out / "results.parquet", html,
                       time.perf_counter() - t0)


#: how long to wait for an existing scheduler to answer
CONNECT_TIMEOUT = "20s"


def _connect(scheduler, n_workers):
    from distributed import Client

    if scheduler is None:
        cluster = local_cluster(n_workers)
        return Client(cluster), cluster
    try:
        return Client(scheduler, timeout=CONNECT_TIMEOUT), None
    except (OSError, TimeoutError, ValueError) as e:
        raise ArgumentError(f"--scheduler {scheduler}: no Dask scheduler reachable there ({e})") from None


def _compute(client, spec, todo, tasks_dir, records, state, progress, t0):
    from distributed import as_completed

    sc = None
    if spec.scenario is not None:
        # a few kB: it travels inside every task. Scattered data would be lost with the worker holding
        # it (Dask cannot recompute it), while a task's own arguments survive any worker's death.
        sc = default_scenario() if spec.scenario == BUILTIN else load_scenario(spec.scenario)
    futures = {}
    for t in todo:
        f = client.submit(run_task, t.options, t.dataset_path, sc, key=f"rideid-study-{t.key}", retries=0)
        futures[f] = t
    first = time.perf_counter()
    computed = 0
    with _interrupt_flag() as stop:
        for fut in _completions(as_completed(futures), stop):
            t = futures.pop(fut)
            computed = _record(fut, t, tasks_dir, records, state, progress, t0, computed, first, len(futures))


#: how often (s) the client looks for a Ctrl-C while no task finishes
POLL_S = 0.1


@contextlib.contextmanager
def _interrupt_flag():
    """A :class:`threading.Event` set by Ctrl-C (SIGINT) while the study waits for its tasks.

    A KeyboardInterrupt raised by Python's default handler lands wherever the main thread happens to be,
    and inside a finaliser (a finished future released, Dask's own bookkeeping) it is printed and dropped:
    the study then ran to its end and exited 0 (seen once in about thirty runs on loaded cores). Our own
    handler only sets the flag; the loop over completions raises KeyboardInterrupt itself, between two
    tasks, at most :data:`POLL_S` later. Off the main thread (no signal handler can be set there) the flag
    is never set and Python's default handling stays."""
    import signal
    import threading

    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    old = signal.signal(signal.SIGINT, lambda signum, frame: stop.set())
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, old)


def _completions(ac, stop):
    """The futures of ``ac`` (a :class:`distributed.as_completed`) as they finish; KeyboardInterrupt as soon as
    ``stop`` is set (:func:`_interrupt_flag`)."""
    while True:
        if stop.is_set():
            raise KeyboardInterrupt
        if ac.has_ready():
            yield next(ac)
        elif ac.is_empty():
            return
        else:
            stop.wait(POLL_S)


def _record(fut, t, tasks_dir, records, state, progress, t0, computed, first, running):
    """Write the finished task ``t``'s record and report progress; the number computed so far."""
    try:
        rec = fut.result()
    except Exception as e:  # the task never returned (workers died repeatedly, cancelled, ...)
        rec = {"status": "failed", "final": False, "warnings": [], "row": {}, "result": None,
               "error": f"not computed: {type(e).__name__}: {' '.join(str(e).split())}"}
    write_atomic(tasks_dir / f"{t.key}.json", json.dumps(rec, default=str) + "\n")
    records[t.key] = rec
    computed += 1
    state["done" if rec["status"] == "done" else "failed"] += 1
    state["running"] = running
    state["elapsed"] = time.perf_counter() - t0
    rate = computed / (time.perf_counter() - first)
    state["eta"] = running / rate if rate > 0 else None
    if progress is not None:
        progress(dict(state))
    return computed
