"""Loading a dataset: read it (the data layer), then align every measured run and check it against a nominal car.

:func:`load_dataset` is the orchestrator behind :func:`rideid.load_dataset`:
:func:`rideid.data.dataset.read_dataset` reads and conditions the files (no
simulation), :func:`align_starts` fixes the start of every measured run
(:mod:`rideid.conditioning.starts`) and runs the physics checks
(:func:`rideid.conditioning.checks.check_dataset`).
"""

from __future__ import annotations

import math
from dataclasses import replace

from ..profiling import stage
from ..data.checks import WARNING, enforce
from ..settings import using
from ..data.dataset import Dataset, check_rig_run, read_dataset
from .checks import check_reach, check_steps
from .nominal import gather, run_steps
from .starts import speed_channel_std, start_steps


@stage("load dataset")
def load_dataset(path, starts: dict[str, float | dict] | None = None, simulator=None) -> Dataset:
    """Load and validate a dataset folder (or its ``dataset.toml``), ready to identify.

    Two steps, each available on its own, top-down: :func:`rideid.data.dataset.read_dataset` (formats and
    conditioning: SPEC §3 CSVs taken as they are, logger files through
    :mod:`rideid.data.measured`), then :func:`align_starts` (the start of every
    measured run whose start is not given, estimated with the nominal car
    :func:`rideid.model.params.nominal_car`, which the checks compare the
    data with too). The starts and the checks are one step
    (:mod:`rideid.conditioning.nominal`): they analyse, and ask for the
    nominal car's responses, simulated a round at a time for every run in one
    batch.
    ``Dataset.preprocessing()`` says what was done.

    Parameters
    ----------
    path : str or Path
        The dataset folder, or its ``dataset.toml``.
    starts : dict, optional
        Run id -> start (file time, s) to use instead of estimating it, e.g.
        the starts a previous identification settled on (``result.json``;
        :meth:`rideid.IdentificationResult.start_values`). A value may also be a
        record ``{"value": start, "model_time": [first, last]}``
        (:meth:`rideid.IdentificationResult.start_records`): the run then has
        the samples that identification fitted, from ``start + first`` to
        ``start + last`` of file time, rather than a window chosen anew at
        ``start`` (which may take one sample more or fewer).
    simulator : rideid.model.simulator.Simulator, optional
        How the nominal car is simulated (backend, integration settings;
        default ``Simulator()``, the linear car as ``RIDEID_KERNEL`` says).

    The dataset's ``[settings]`` (:mod:`rideid.settings`) are in force while its runs are aligned and checked
    (:func:`align_starts` runs under the settings in force: called on its own, ``rideid.settings.using`` puts a
    dataset's in force around it).

    Returns
    -------
    Dataset

    Raises
    ------
    DataError
        Naming the file, key or column at fault.
    """
    ds = read_dataset(path)
    with using(dict(getattr(ds.manifest, "settings", None) or {})):  # the dataset's [settings] (rideid.settings)
        return align_starts(ds, starts, simulator=simulator)


def align_starts(ds: Dataset, starts: dict[str, float | dict] | None = None, car=None, simulator=None) -> Dataset:
    """The estimation step of loading: fix the start of every measured run.

    A start given in ``starts`` or in the run's ``[preprocess] start`` is
    taken; otherwise it is estimated by correlating the run with the response
    of the nominal car (:func:`rideid.model.params.nominal_car`; the record
    keeps the estimate and its correlation). Returns a new dataset; ``ds``
    is not changed.

    Parameters
    ----------
    ds : Dataset
        As read (:func:`rideid.data.dataset.read_dataset`).
    starts : dict, optional
        Run id -> start (file time, s) or start record, as in :func:`load_dataset`.
    car : (12,) array, optional
        The nominal car's parameter vector (default
        ``nominal_car(ds.geometry)``): the car the starts are estimated with
        and the checks compare the data with.
    simulator : rideid.model.simulator.Simulator, optional
        How it is simulated (default ``Simulator()``: the linear car). The nominal car is linear: the model to
        fit is not chosen yet, and a start and a wiring check need only the car's main response.

    Runs under the settings in force (:func:`load_dataset` puts the dataset's ``[settings]`` in force around it).
    """
    # the starts, then the checks, as one step: the nominal car is simulated a round at a time, every run's
    # requests of a round in one batch (rideid.conditioning.nominal)
    step = _aligned(ds, starts)
    ds, findings = run_steps(step, ds.geometry, car, None if simulator is None else simulator.linear())
    findings = where_to_fix(findings, [r.id for r in ds.runs if getattr(r, "road_known", True)])
    enforce(findings, f"{ds.manifest.path}: ")
    return replace(_seen_speeds(ds, findings), findings=findings)


def where_to_fix(findings: list, checked: list) -> list:
    """The wiring findings with their fix placed where it belongs (:attr:`rideid.data.checks.MapFix.where`): the
    dataset's ``[channels]`` when every checked run (``checked``: run ids) needs the same re-wiring, else the run's
    own ``channels`` (a cable swapped on one run: the dataset-wide fix would break the others). Other findings,
    and a dataset of one run, unchanged."""
    wired = [f for f in findings if f.check == "wiring" and f.fix and f.remedy is not None]
    if len(checked) < 2 or not wired:
        return findings
    fixes, entries = {}, {}
    for f in wired:  # a run's findings each fix one channel (a unit) or several (a swap): the run's whole fix
        fixes.setdefault(f.run, {}).update(f.fix)
        entries.setdefault(f.run, {}).update(dict.fromkeys(f.remedy.entries))
    first = fixes[wired[0].run]
    if not (set(checked) <= set(fixes) and all(fx == first for fx in fixes.values())):
        # each run's own map; the runs that need the same fix are named (the rest may be wired as mapped, or be
        # runs the check cannot read: a symmetric run's roll)
        shared = {rid: tuple(r for r in fixes if fixes[r] == fixes[rid]) for rid in fixes}
        return [replace(f, remedy=replace(f.remedy, where="run", shared=shared[f.run], checked=len(checked)))
                if f in wired else f for f in findings]
    # every run wired the same way: each message names the whole [channels] fix, not its own channel's entry
    return [replace(f, remedy=replace(f.remedy, where="channels", entries=tuple(entries[f.run])))
            if f in wired else f for f in findings]


def _seen_speeds(ds: Dataset, findings) -> Dataset:
    """SPEC §13: each run whose data put its speed beyond the declared value's prior (a ``speed`` warning with
    the speed the data show, :func:`rideid.conditioning.checks.speed_prior_finding`) is fitted from that speed;
    the declared one stays its prior (``RunSpec.declared_speed``). A speed within the prior (a note) is not moved:
    the lags are read against the nominal linear car, and a car with damper curves or bump stops lags the road
    otherwise (measured: 0.7 % and 0.56 % on the built-in car with stops at 30 mm, tests/test_bump_stops.py),
    which moved the stops' rate 22 % when the fit started from those speeds."""
    # a logger file's run: its starts are estimated again with the car at this speed (the polish)
    return ds.with_speeds({f.run: f.fix["speed"] for f in findings
                           if f.check == "speed" and f.severity == WARNING and f.fix and "speed" in f.fix})


def _aligned(ds: Dataset, starts: dict[str, float | dict] | None):
    """The step of :func:`align_starts`: returns ``(dataset aligned, findings of the checks)``."""
    man = ds.manifest
    found = yield from gather(_start_of(ds, rid, starts) for rid in ds.measured)
    data, measured = dict(ds.data), {}
    for (rid, mr0), (s, record) in zip(ds.measured.items(), found):
        mr = replace(mr0, record=dict(mr0.record), window=None, start=None)
        mr.record["start"] = record
        given = (starts or {}).get(rid)
        if not (isinstance(given, dict) and given.get("model_time") is not None
                and mr.keep_window(s, given["model_time"])):
            mr.make_grid(s)
        mr.start = float(s)
        measured[rid] = mr
        data[rid] = mr.run_data(s)
        if man.run(rid).posts:  # SPEC §13: post amplitudes that no rig makes (a column in mm mapped as m)
            check_rig_run(man.run(rid), data[rid], f"{mr.path} (as mapped in {man.path})")
    ds = Dataset(man, {r.id: data[r.id] for r in man.runs}, measured)
    # the one hook for the physics checks (rideid.conditioning.checks): every run conditioned and aligned
    findings = yield from check_steps(ds)
    return ds, findings


def _start_of(ds: Dataset, rid: str, starts: dict[str, float | dict] | None):
    """The step (:mod:`rideid.conditioning.nominal`) giving the start of the measured run ``rid`` and how it
    was found: ``(start, record)``."""
    man = ds.manifest
    mr = ds.measured[rid]
    run = man.run(rid)
    if starts and rid in starts:
        given = starts[rid]
        return (float(given["value"] if isinstance(given, dict) else given),
                {"source": "given (from a previous identification)"})
    if not mr.auto_start:
        return mr.options["start"], {"source": "given"}
    if run.posts:  # SPEC §13: no track to align with; the rig's time 0 is the first sample (of the window)
        return (max(mr.t_first, mr.options.get("window", (-math.inf, math.inf))[0]),
                {"source": "four-post rig run (SPEC §13): time 0 at the first sample"})
    if not run.road_known:
        # no road to align with: x = 0 is where the front axle is at the first sample (of the window)
        return (max(mr.t_first, mr.options.get("window", (-math.inf, math.inf))[0]),
                {"source": "unknown road (SPEC §9): x = 0 at the first sample"})
    track = man.tracks[run.track]
    longest = (mr.speed * (mr.t_last - mr.t_first) if mr.distance is None
               else float(mr.distance.d[-1] - mr.distance.d[0]))
    reach = check_reach(rid, track, man.geometry, longest)
    enforce(reach, f"{man.path}: ")
    # the run as read, unaligned (window and start dropped), as the estimate sees it
    s, rho = yield from start_steps(replace(mr, window=None, start=None), man.geometry, track)
    s_speed = speed_channel_std(mr, track, man.geometry)
    return s, {"source": "estimated (nominal car)", "nominal_estimate": s, "correlation": rho,
               **({} if s_speed is None else {"std_speed_channel": s_speed})}


__all__ = ["align_starts", "load_dataset"]
