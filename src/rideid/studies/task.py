"""One study task, as a Dask worker runs it: data in, one record out.

The function is pure in the sense that matters here: its record depends only
on the task's options and data (same seeds, same bits), not on the worker,
the number of worker threads or what ran before on that process. It uses one
core: Numba's parallel kernel is limited to one thread and BLAS to one
thread for the duration of the task, so a cluster with one worker thread per
core is never oversubscribed (docs/studies.md).
"""

from __future__ import annotations

import contextlib
import tempfile
import time
import warnings
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from ..conditioning.load import load_dataset
from ..data.schema import load_truth
from ..errors import RideidError
from ..model.backend import one_thread
from ..estimate.choice.model_choice import identify
from ..estimate.result import jsonable
from ..synth.scenario import simulate_manifest, write_dataset

try:
    __version__ = version("rideid")
except PackageNotFoundError:  # pragma: no cover
    __version__ = "0+unknown"


#: columns of a record that differ between two runs of the same task (excluded when tables are compared)
TIMING_COLUMNS = ("identify_wall_s", "task_wall_s")


@contextlib.contextmanager
def one_core():
    """The kernels and BLAS limited to one thread (restored afterwards)."""
    from threadpoolctl import threadpool_limits

    with one_thread(), threadpool_limits(limits=1):
        yield


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


def run_task(options: dict, dataset_path: str | None = None, scenario=None) -> dict:
    """Run one identification of a study and return its record.

    Parameters
    ----------
    options : dict
        :attr:`rideid.studies.spec.Task.options`.
    dataset_path : str, optional
        Absolute dataset folder (dataset tasks; read by the worker, so it
        must be on a filesystem the workers share).
    scenario : rideid.Scenario, optional
        The parsed scenario (scenario tasks; sent with the task).

    Returns
    -------
    dict
        ``status`` ("done" or "failed"), ``final`` (False when retrying may
        help: anything but bad input), ``error`` (one line or None),
        ``warnings`` (list of str), ``row`` (flat estimates: values, std,
        std_robust when identify gives it, truth and relative errors when
        known, cost, generations, wall times) and ``result`` (the
        identification's result.json content).
    """
    t0 = time.perf_counter()
    rec = {"status": "failed", "final": True, "error": None, "warnings": [], "row": {}, "result": None,
           "rideid_version": __version__}
    with warnings.catch_warnings(record=True) as caught, one_core(), tempfile.TemporaryDirectory() as tmp:
        warnings.simplefilter("always")
        try:
            res, truth = _identify(options, dataset_path, scenario, Path(tmp))
            rec["row"] = result_row(res.to_dict(), truth)
            rec["result"] = jsonable(res.to_dict())
            rec["status"] = "done"
        except RideidError as e:
            rec["error"] = _one_line(e)
        except Exception as e:  # a bug or a resource problem: recorded, retried when the study is resumed
            rec["error"] = f"internal error: {type(e).__name__}: {_one_line(e)}"
            rec["final"] = False
    msgs = []
    for w in caught:
        m = _one_line(w.message) if isinstance(w.message, BaseException) else " ".join(str(w.message).split())
        if m not in msgs:
            msgs.append(m)
    rec["warnings"] = msgs
    rec["row"]["task_wall_s"] = time.perf_counter() - t0
    return rec


def _identify(options, dataset_path, scenario, tmp: Path):
    data = options["data"]
    if "scenario" in data:
        if scenario is None:
            raise ValueError("scenario task without its scenario")
        # through the files, exactly as `rideid simulate --noise N --seed S` then `rideid identify`
        sim, _ = simulate_manifest(scenario, noise=data["noise"], seed=data["noise_seed"])
        write_dataset(scenario, sim, tmp / "dataset")
        ds = load_dataset(tmp / "dataset")
    else:
        ds = load_dataset(dataset_path)
    if options["runs"] is not None:
        # the runs named (a DataError naming the subset for one the dataset lacks), with their load findings
        ds = ds.with_runs(options["runs"], f"subset '{options['subset']}'")
    if "scenario" in data:
        truth = dict(scenario.truth)
    else:
        tp = Path(dataset_path) / "truth.toml"
        truth = load_truth(tp, ds.geometry) if tp.is_file() else None
    return identify(ds, **options["identify"]), truth


def result_row(result: dict, truth: dict | None) -> dict:
    """Flatten a result.json dict (and the truth, if known) into one table row.

    Per parameter ``p``: ``p`` (estimate), ``p_std``, ``p_std_robust`` (when
    the result has it), ``p_truth`` and ``p_error`` (estimate / truth - 1)
    when the truth is known. ``estimated`` lists the free parameters.
    """
    row = {}
    pars = result["parameters"]
    est = []
    for n, d in pars.items():
        row[n] = float(d["value"])
        row[f"{n}_std"] = None if d.get("std") is None else float(d["std"])
        if "std_robust" in d:
            row[f"{n}_std_robust"] = None if d["std_robust"] is None else float(d["std_robust"])
        if truth is not None and n in truth:
            row[f"{n}_truth"] = float(truth[n])
            row[f"{n}_error"] = float(d["value"]) / float(truth[n]) - 1.0
        if not d.get("fixed"):
            est.append(n)
    row["estimated"] = ",".join(est)
    if truth is not None:
        row["max_abs_error"] = max((abs(row[f"{n}_error"]) for n in est if f"{n}_error" in row), default=None)
    row["cost"] = float(result["cost"])
    row["generations_run"] = int(result["generations"])
    row["evaluations"] = int(result["evaluations"])
    row["stop"] = str(result.get("stop", ""))
    model = result.get("model")
    if isinstance(model, dict) and "extensions" in model:
        row["model_extensions"] = ",".join(model["extensions"]) or "base"
    adequacy = result.get("adequacy")
    if isinstance(adequacy, dict) and "adequate" in adequacy:
        row["adequate"] = bool(adequacy["adequate"])
    row["identify_wall_s"] = float(result["wall_time_s"])
    return row
