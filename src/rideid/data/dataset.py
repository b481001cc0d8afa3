"""Datasets: a validated manifest plus its measured runs."""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from . import checks
from ..errors import DataError, DataWarning, ScaleError
from .schema import DatasetManifest, ReadOnlyDict, RunData, load_manifest, read_run_csv
from .schema.manifest import vehicle_table
from ..model.params import (CORNERS, EXT_NAMES, EXTRA_KNOWN, MASS_COUNT, NAMES, SCALE_FREE, Geometry, nominal_car,
                            total_mass)
from ..model.posts import POST_CHANNELS, prepare_posts
from ..model.simulate import prepare_run
from .measured import load_measured_run
from .quality import resampled_runs
from .scenario import flat_before, settle_time


@dataclass(frozen=True, repr=False)
class Dataset:
    """A dataset (SPEC §3): manifest and the data of every run. Immutable: the steps that
    change a dataset (:func:`rideid.conditioning.load.align_starts`, :meth:`with_starts`, :meth:`with_data`)
    return a new one.

    Attributes
    ----------
    manifest : DatasetManifest
        The parsed ``dataset.toml`` (frozen).
    data : dict run id -> RunData
        Model-ready data: uniform time relative to the run's start (the
        front axle at x = 0), SI channels.
    measured : dict run id -> MeasuredRun
        Runs read through :mod:`rideid.measured` (logger files, channel maps,
        preprocessing); SPEC §3 CSVs taken as they are have no entry.
    """

    manifest: DatasetManifest
    data: dict[str, RunData]
    measured: dict = field(default_factory=dict)
    #: what the data checks found (:mod:`rideid.data.checks`); errors never get this far
    findings: tuple = ()

    def __post_init__(self):
        # read-only tables: a dataset handed to identify or a report cannot be changed under them
        object.__setattr__(self, "data", ReadOnlyDict(self.data))
        object.__setattr__(self, "measured", ReadOnlyDict(self.measured))
        object.__setattr__(self, "findings", tuple(self.findings))

    #: run ids shown by :meth:`__repr__` before it counts the rest
    REPR_RUNS = 10

    def __repr__(self):
        """One short line: name, folder, runs, tracks, known values and model (never the data arrays)."""
        ids = [r.id for r in self.runs]
        shown = ", ".join(ids[:self.REPR_RUNS]) + (f", ... {len(ids) - self.REPR_RUNS} more"
                                                     if len(ids) > self.REPR_RUNS else "")
        ext = self.manifest.extensions
        model = "none ([model] absent: identify chooses auto)" if ext is None else " + ".join(ext) or "base"
        unknown = len(self.unknown_road_runs)
        roads = f" ({unknown} on unknown roads)" if unknown else ""
        parts = [f"runs={len(ids)}{roads} [{shown}]", f"tracks=[{', '.join(self.manifest.tracks)}]",
                 f"known={dict(self.known)}", f"model={model}"]
        import textwrap  # a few lines of at most 100 columns (the path may be longer: it is shown whole)
        body = textwrap.wrap(", ".join(parts) + ")", 98, initial_indent="  ", subsequent_indent="  ",
                             break_on_hyphens=False)
        return "\n".join([f"Dataset(name={self.name!r},", f"  path='{self.path}',", *body])

    @property
    def geometry(self) -> Geometry:
        return self.manifest.geometry

    @property
    def runs(self):
        return self.manifest.runs

    @property
    def known(self):
        return self.manifest.known

    @property
    def name(self):
        return self.manifest.name

    @property
    def path(self) -> Path:
        return self.manifest.base_dir

    @cached_property
    def anchor(self) -> str | None:
        """The known value that fixes the absolute scale (:func:`scale_anchor` of its ``[known]``), None when
        none does; worked out once, on first asking (the manifest is frozen)."""
        try:
            return scale_anchor(self.known)
        except DataError:  # no anchor, or one that contradicts the fixed masses: none to name
            return None

    @cached_property
    def vehicle(self) -> ReadOnlyDict:
        """The ``[vehicle]`` table of its geometry (:func:`rideid.data.schema.manifest.vehicle_table`, the
        declared stds left out), as a result carries it so the geometry travels with the car (``rideid
        export``); worked out once, on first asking."""
        return ReadOnlyDict(vehicle_table(self.geometry))

    def preprocessing(self) -> dict:
        """What was done to each run's file (for ``result.json`` and the report)."""
        out = {}
        for r in self.runs:
            mr = self.measured.get(r.id)
            if mr is None:
                rd = self.data[r.id]
                start = ("SPEC §13: a four-post rig run, time 0 at its first sample, the car at rest" if r.posts
                         else "SPEC: time 0 is the front axle at x = 0")
                out[r.id] = {"file": str(r.file), "format": "CSV (SPEC channels, SI units, taken as it is)",
                             "fs": rd.fs, "samples": int(rd.time.size), "start": {"value": 0.0, "source": start}}
            else:
                rec = dict(mr.record)
                rec["samples"] = int(mr.grid.size)
                rec["model_time"] = [float(mr.grid[0]), float(mr.grid[-1])]
                rec["start"] = dict(mr.record.get("start", {}), value=mr.start)
                rec["warnings"] = list(mr.warnings)
                out[r.id] = rec
        return out

    @cached_property
    def leads(self) -> tuple:
        """:func:`lead_ins` of every run, in order (a moving start's lead-in, SPEC §9); worked out once, on first
        asking (the data are frozen), for every cost function built on this dataset."""
        return tuple(lead_ins(self))

    @cached_property
    def preprocessed(self) -> ReadOnlyDict:
        """The preprocessing record (:meth:`preprocessing`) as a fit on this dataset reports it (SPEC §13): a run
        that begins moving on its track with its lead-in (``moving_start``, :func:`run_lead_in`), a run at a held
        constant speed with the ``motion`` the fit holds (:func:`held_motion`); worked out once, on first asking.
        Read-only: a result copies it (:func:`rideid.estimate.assess.details.preprocessing_record`)."""
        pre = self.preprocessing()
        for r, lead in zip(self.runs, self.leads):
            if getattr(r, "moving", False) and r.road_known:
                fs = float(self.data[r.id].fs)
                pre[r.id]["moving_start"] = {"lead_in_s": lead.samples / fs, "left_out_s": lead.settle / fs,
                                             "method": MOVING_START_METHOD}
            held = held_motion(self, r)
            if held is not None:
                pre[r.id]["motion"] = held
        return ReadOnlyDict(pre)

    @cached_property
    def resampled(self) -> ReadOnlyDict:
        """The runs rideid low-passed or interpolated to the model's rate, what and from which rates
        (:func:`rideid.data.quality.resampled_runs`); worked out once, on first asking."""
        return ReadOnlyDict(resampled_runs(self.measured))

    def sensor_filters(self, run_id: str) -> tuple:
        """Per SPEC channel (CHANNELS order) the analog filters of its sensor chain in run ``run_id``
        (SPEC §11 ``highpass``, ``lowpass``; empty tuples for a SPEC CSV taken as it is)."""
        mr = self.measured.get(run_id)
        return mr.chain_filters() if mr is not None else ((),) * 10

    def clipped(self, run_id: str):
        """``(n, 10)`` bool over run ``run_id``'s model samples: where a channel sat at its range (SPEC §11),
        left out of the fit; None when no sample of the run is."""
        mr = self.measured.get(run_id)
        if mr is None or mr.window is None or not mr.clipped.any():
            return None
        M = mr.window_clipped()
        rd = self.data.get(run_id)
        if rd is None or rd.time.size != M.shape[0]:  # data not read from the measured run's window
            return None
        return M if M.any() else None

    def subset(self, runs) -> "Dataset":
        """This dataset with only ``runs`` (run specs of it; the manifest otherwise the same)."""
        ids = {r.id for r in runs}
        man = replace(self.manifest, runs=tuple(r for r in self.runs if r.id in ids))
        return Dataset(man, {k: v for k, v in self.data.items() if k in ids},
                       {k: v for k, v in self.measured.items() if k in ids}, self.findings)

    def with_runs(self, run_ids, what: str) -> "Dataset":
        """:meth:`subset` to the runs named ``run_ids`` (manifest order kept) with the findings of those runs (and
        the dataset's own); :class:`DataError` naming ``what`` (who asked) and the first id that is no run of it."""
        have = [r.id for r in self.runs]
        bad = [r for r in run_ids if r not in have]
        if bad:
            raise DataError(f"{what}: run '{bad[0]}' is not in dataset {self.path} (its runs: {', '.join(have)})")
        keep = set(run_ids)
        sub = self.subset([r for r in self.runs if r.id in keep])
        return replace(sub, findings=tuple(f for f in self.findings if getattr(f, "run", None) in keep | {None}))

    def with_speeds(self, speeds: dict) -> "Dataset":
        """A new dataset with the runs of ``speeds`` (run id -> m/s) driven at those constant speeds, each declared
        value kept as the run's prior (``RunSpec.declared_speed``, SPEC §13): the speed the data show, or the one a
        fit estimated with the car. A measured run's start is estimated again at that speed by the fit."""
        if not speeds:
            return self
        man = self.manifest
        runs = tuple(replace(r, speed=float(speeds[r.id]), declared_speed=r.speed if r.declared_speed is None
                             else r.declared_speed) if r.id in speeds else r for r in man.runs)
        measured = {rid: replace(mr, speed=float(speeds[rid])) if rid in speeds and mr.speed is not None else mr
                    for rid, mr in self.measured.items()}
        return replace(self, manifest=replace(man, runs=runs), measured=measured)

    def with_data(self, data: dict) -> "Dataset":
        """A new dataset with other run data (same manifest and measured runs)."""
        return replace(self, data={r.id: data[r.id] for r in self.runs})  # the findings kept

    def with_starts(self, starts: dict) -> "Dataset":
        """A new dataset with measured runs re-read at other starts.

        ``starts``: run id -> start (file time, s) or a start record
        ``{"value", ...}`` such as :attr:`rideid.IdentificationResult.starts`;
        the record's other keys (source, std) join the run's preprocessing record; its
        ``distance_correction`` (a noisy speed channel's, :attr:`rideid.IdentificationResult.starts`) drives the
        run along the corrected distance.
        """
        measured, data = dict(self.measured), dict(self.data)
        for rid, st in starts.items():
            if rid not in self.measured:
                raise DataError(f"start given for run '{rid}', which is not a measured run of {self.name}")
            rec = st if isinstance(st, Mapping) else {"value": st}
            s = float(rec["value"])
            mr = self.measured[rid]
            record = dict(mr.record, start={**mr.record.get("start", {}),
                                            **{k: v for k, v in rec.items() if k != "value"}})
            dc = rec.get("distance_correction")
            if dc is not None and mr.distance is not None:  # a noisy speed channel's, estimated with the start
                mr = mr.with_distance_correction(dc["knots_s"], dc["values_m"])
            measured[rid] = replace(mr, start=s, record=record)
            data[rid] = measured[rid].run_data(s)
        return replace(self, data=data, measured=measured)  # the findings kept: what load found stays the data's

    @property
    def auto_start_runs(self) -> list[str]:
        """The measured runs on known tracks whose start is estimated (SPEC §3: ``start`` not given)."""
        return [rid for rid, mr in self.measured.items()
                if mr.auto_start and self.manifest.run(rid).track is not None]

    def road_known(self, run_id: str) -> bool:
        """Whether run ``run_id`` drives a known track (False: a road nobody measured, SPEC §9)."""
        return self.manifest.run(run_id).road_known

    def moving(self, run_id: str) -> bool:
        """Whether run ``run_id`` begins with the car moving (SPEC §9 ``moving = true``), not at rest."""
        return self.manifest.run(run_id).moving

    @property
    def unknown_road_runs(self) -> list[str]:
        """Ids of the runs on roads nobody measured (SPEC §9), in manifest order."""
        return [r.id for r in self.runs if not r.road_known]


def read_dataset(path) -> Dataset:
    """Read and condition every run of a dataset; no simulation.

    Measured runs come back without a start (``Dataset.data`` lacks them)
    until :func:`rideid.conditioning.load.align_starts` fixes one.
    """
    man = load_manifest(path)
    checks.enforce(checks.check_numbers(man))
    data, measured = {}, {}
    for run in man.runs:
        if man.is_measured(run):
            mr = measured[run.id] = load_measured_run(run, man)
            if not run.road_known:
                w0, w1 = mr.options.get("window", (-math.inf, math.inf))
                span = min(mr.t_last, w1) - max(mr.t_first, w0)
                check_unknown_road_run(man, run, mr.channels, span, int(math.floor(span * mr.fs + 1e-9)) + 1)
            continue
        f = Path(run.file)
        if not f.is_absolute():
            f = man.base_dir / f
        rd = data[run.id] = read_run_csv(f, posts=run.posts)
        if run.posts:
            check_rig_run(run, rd, f)
        if not run.road_known:
            check_unknown_road_run(man, run, rd.channels, float(rd.time[-1] - rd.time[0]), rd.time.size)
    return Dataset(man, data, measured)


#: the shortest run on an unknown road (SPEC §9) worth identifying: its road is unknown too, so it must hold
#: several periods of the slowest body mode (about 1 Hz) and the rear wheels' pass over the road the front
#: wheels saw (wheelbase / speed later)
MIN_ROAD_RUN_S = 5.0
#: ... and at least this many samples
MIN_ROAD_RUN_SAMPLES = 500
#: the channels a run on an unknown road must have (SPEC §9)
ROAD_RUN_CHANNELS = tuple(f"{g}_az_{c}" for g in ("body", "axle") for c in CORNERS)


def check_unknown_road_run(man, run, channels, duration: float, samples: int) -> None:
    """A run on an unknown road (SPEC §9) needs all four body and all four axle channels, and
    at least :data:`MIN_ROAD_RUN_S` s and :data:`MIN_ROAD_RUN_SAMPLES` samples; :class:`DataError` otherwise."""
    missing = [c for c in ROAD_RUN_CHANNELS if c not in channels]
    if missing:
        raise DataError(f"{man.path}: run '{run.id}' is on an unknown road (no track), which needs all four body "
                        f"and all four axle acceleration channels (SPEC §9); missing: {', '.join(missing)}")
    if duration < MIN_ROAD_RUN_S or samples < MIN_ROAD_RUN_SAMPLES:
        raise DataError(f"{man.path}: run '{run.id}' is on an unknown road and holds {duration:.3g} s "
                        f"({samples} samples): too short to identify anything; a run on an unknown road needs at "
                        f"least {MIN_ROAD_RUN_S:g} s and {MIN_ROAD_RUN_SAMPLES} samples")


#: a moving run on a known track (SPEC §9) is simulated from rest this many of the nominal car's settle times
#: (:func:`rideid.data.scenario.settle_time`, its slowest mode down to 1e-3) before its first sample, where the
#: track's road reaches that far back: the start transient then decays to 1e-9 of its size before the first
#: sample (more than the 1e-3 the nominal settle time gives: the car's own damping may be lighter)
LEAD_IN_SETTLES = 3.0

#: ... and where the road before x = 0 is known for less than that, what its lead-in lacks of this many nominal
#: settle times is left out of the comparison at the run's start
LEFT_OUT_SETTLES = 1.0


@dataclass(frozen=True)
class LeadIn:
    """How a run's simulation begins (SPEC §9): ``samples`` simulated before its first sample, the car at rest at
    the first of them, and ``settle`` recorded samples at the run's start simulated but not compared (the road
    known before x = 0 too short for the start transient to decay). Both 0 for a run that starts at rest."""

    samples: int = 0
    settle: int = 0


def known_road_before(track, geom) -> float:
    """How far back (m, <= 0) the road of ``track`` is known, as an x of the front axle: -inf for the analytic
    kinds (flat outside their features, SPEC §2), a ``profile``'s first x less the tire radius (before it
    nobody measured the road a moving car came over; its disc reaches R ahead)."""
    if track.kind != "profile":
        return -math.inf
    lo = min(track.path(y).extent[0] for y in geom.corner_y)
    return lo - geom.tire_radius


def run_lead_in(ds: Dataset, run) -> LeadIn:
    """The :class:`LeadIn` of ``run`` of ``ds`` (module docs: docs/any-road.md, "Moving starts on a known track").

    A run at rest at its first sample (SPEC §2): none. A moving run on a known track (``moving = true``) is
    simulated from rest ``T`` before its first sample on the track's road before x = 0, ``T`` the shorter of
    :data:`LEAD_IN_SETTLES` nominal settle times and, on an analytic track, the time back to where every
    wheel's road is flat (the car then was exactly at rest, nothing is approximated), on a ``profile`` the time
    back to where the profile begins (:func:`known_road_before`). When that profile gives less than one settle
    time before x = 0, the rest of that settle time is left out of the comparison at the run's start
    (``settle``). A moving run with a speed or distance channel: no lead-in (the channel does not reach before
    the first sample), one settle time left out.
    """
    if not getattr(run, "moving", False) or not run.road_known:
        return LeadIn()
    rd = ds.data[run.id]
    geom = ds.geometry
    settle = settle_time(nominal_car(geom), geom)
    if rd.distance is not None:
        return LeadIn(0, min(int(math.ceil(settle * rd.fs)), rd.time.size))
    track = ds.manifest.tracks[run.track]
    speed = float(run.speed)
    x_known = known_road_before(track, geom)
    if math.isfinite(x_known):  # a profile: known from its first x on, what came before unknown
        T = min(max(0.0, -x_known / speed), LEAD_IN_SETTLES * settle)
        short = max(0.0, LEFT_OUT_SETTLES * settle - T)
    else:  # flat outside the features: from rest where every wheel's road is still flat, exactly
        T = min(flat_before(track, geom, speed), LEAD_IN_SETTLES * settle)
        short = 0.0
    return LeadIn(int(math.ceil(T * rd.fs - 1e-9)), min(int(math.ceil(short * rd.fs - 1e-9)), rd.time.size))


#: ``preprocessing.<run>.moving_start.method`` of a run that begins moving, fitted on its track (SPEC §9)
MOVING_START_METHOD = ("simulated from rest lead_in_s before the first sample on the track's road before x = 0, "
                       "compared from the first sample on; the first left_out_s s of the run not compared (the "
                       "profile known less than a settling time before x = 0); docs/any-road.md")


def held_motion(ds, run) -> dict | None:
    """SPEC §13: the ``motion`` record of a run at a constant declared speed on a known track as the fit on the
    tracks as drawn holds it (never silently): ``speed`` with the value the fit used, its std where the lags at
    load measured it (:func:`rideid.conditioning.checks.speed_seen`), the declared value and its prior's std, and
    ``estimated``: how. The runs fitted as built replace it with their own (``tracks.<track>.runs.<run>.motion``,
    solved with the car). None for other runs."""
    if not getattr(run, "road_known", False) or getattr(run, "speed_prior", None) is None:
        return None
    prior = run.speed_prior()
    if prior is None or getattr(ds.data.get(run.id), "distance", None) is not None:
        return None
    seen = next((f for f in getattr(ds, "findings", ()) if f.check == "speed" and f.run == run.id and f.fix
                 and "speed" in f.fix), None)
    speed = {"estimate": float(run.speed), "std": None if seen is None else float(seen.fix["std"]), "unit": "m/s",
             "declared": prior[0], "prior_std": prior[1], "prior": "declared" if prior[2] else "default"}
    how = ("at load, from the lags of the data against a nominal car on the track (the fit on the tracks as drawn "
           "holds it there)" if seen is not None else
           "not moved: the lags at load agree with the declared value within their error (the fit on the tracks as "
           "drawn holds it)")
    return {"speed": speed, "estimated": how}


def lead_ins(ds: Dataset) -> list:
    """:func:`run_lead_in` of every run of ``ds``, in order."""
    return [run_lead_in(ds, r) for r in ds.runs]


def prepare_inputs(ds: Dataset, leads=None) -> list:
    """:class:`rideid.simulate.RunInput` of every run (wheel inputs and their moments), a moving run's from
    the start of its lead-in (``leads``: :func:`lead_ins`, computed here when not given).

    Every run must be on a known track: a run on an unknown road (SPEC §9)
    has no wheel inputs to tabulate (:class:`DataError`).
    """
    refuse_unknown_roads(ds, "rideid.CostFunction (the known-road fit of rideid identify)")
    leads = lead_ins(ds) if leads is None else leads
    out = []
    for r, lead in zip(ds.runs, leads):
        rd = ds.data[r.id]
        if r.posts:  # SPEC §13: the measured posts are the wheel inputs (no track, speed or envelope)
            out.append(prepare_posts(rd.time, rd.posts, rd.post_vel))
            continue
        t = rd.time
        if lead.samples:
            h = float(t[1] - t[0])
            t = np.concatenate([t[0] + h * np.arange(-lead.samples, 0), t])
        out.append(prepare_run(ds.manifest.tracks[r.track], ds.geometry, r.speed, t, distance=rd.distance))
    return out


#: the largest post stroke (m, peak to peak) a four-post rig run may show: servo-hydraulic ride rigs stroke
#: +-75 to +-125 mm; more is a column in mm read as m (SPEC §13 posts are in m)
MAX_POST_STROKE = 0.3
#: below the wheel hop the wheel follows its post: the axle's acceleration and the post's (the displacement's
#: second derivative) agree within a small factor in :data:`FOLLOW_BAND`; when they differ by more than this
#: factor the posts are in another unit than declared (mm read as m: 1000)
POST_UNIT_FACTOR = 20.0
#: the band (Hz) of that comparison: above the body modes' transmissibility peaks, below every wheel hop
FOLLOW_BAND = (3.0, 6.0)
#: a rig run starts at rest (the model starts in static equilibrium on the posts' first position): its posts
#: over the first :data:`STILL_S` s may move by at most this share of their RMS about that position over the run
STILL_SHARE, STILL_S = 0.25, 0.2


def check_rig_run(run, rd, path) -> None:
    """A four-post rig run (SPEC §13) whose posts cannot be in m: a stroke beyond :data:`MAX_POST_STROKE`, or,
    with axle accelerometers, post accelerations :data:`POST_UNIT_FACTOR` times above or below the axles' in
    :data:`FOLLOW_BAND`, where a wheel follows its post. One line naming the file, column and the unit that
    fits (:class:`DataError`)."""
    z = np.asarray(rd.posts, dtype=float)
    stroke = np.ptp(z, axis=0)
    k = int(np.argmax(stroke))
    if stroke[k] > MAX_POST_STROKE:
        raise DataError(f"{path}: column '{POST_CHANNELS[k]}' moves {stroke[k]:.4g} m peak to peak, beyond any ride "
                        f"rig's stroke ({MAX_POST_STROKE:g} m): post displacements are in m (SPEC §13); is the "
                        "column in mm? convert it, or map it in [channels] with unit = \"mm\"")
    n0 = max(3, int(round(STILL_S * rd.fs)))
    dz = z - z[0]
    rms = np.sqrt(np.mean(dz ** 2, axis=0))
    lead = np.sqrt(np.mean(dz[:n0] ** 2, axis=0))
    if rd.time.size > 4 * n0 and np.any(lead > STILL_SHARE * rms):
        k = int(np.argmax(lead / np.where(rms > 0, rms, np.inf)))
        warnings.warn(f"{path}: column '{POST_CHANNELS[k]}' already moves in the first {STILL_S:g} s "
                      f"({lead[k] / rms[k]:.0%} of its RMS over the run): a rig run is simulated from rest on the "
                      "posts' first position, so the start transient will not fit; start the run (a window, "
                      "[preprocess] start) where the car stands still", DataWarning, stacklevel=3)
    ratio = post_axle_ratio(rd)
    if ratio is not None and not 1 / POST_UNIT_FACTOR < ratio[1] < POST_UNIT_FACTOR:
        c, r = ratio
        unit = " (in mm?)" if 300 < r < 3000 else " (in cm?)" if 30 < r < 300 else ""
        raise DataError(f"{path}: column '{c}': the post's acceleration between {FOLLOW_BAND[0]:g} and "
                        f"{FOLLOW_BAND[1]:g} Hz is {r:.3g} times its axle's, where a wheel follows its post (about 1): "
                        f"the posts are not in m as SPEC §13 says{unit}; convert the post columns to m or map them "
                        "in [channels] with their unit")


def post_axle_ratio(rd):
    """``(post channel, ratio)``: for the corner whose axle accelerometer the band :data:`FOLLOW_BAND` excites
    most, the RMS of its post's acceleration over its axle's in that band; None without an axle channel, or
    with a band the run does not excite (the RMS of each below 1e-6 of the whole signal's)."""
    t = rd.time
    if t.size < 16:
        return None
    f = np.fft.rfftfreq(t.size, float(t[1] - t[0]))
    band = (f >= FOLLOW_BAND[0]) & (f <= FOLLOW_BAND[1])
    if not band.any():
        return None
    best = None
    for i, c in enumerate(CORNERS):
        a = rd.channels.get(f"axle_az_{c}")
        if a is None:
            continue
        A = np.fft.rfft(a - np.mean(a))
        z = rd.posts[:, i] - np.polyval(np.polyfit(t - t[0], rd.posts[:, i], 1), t - t[0])  # no drift leaks in
        Z = np.fft.rfft(z) * (2 * np.pi * f) ** 2
        ea, ez = float(np.sqrt(np.sum(np.abs(A[band]) ** 2))), float(np.sqrt(np.sum(np.abs(Z[band]) ** 2)))
        if ea <= 1e-6 * float(np.sqrt(np.sum(np.abs(A) ** 2))) or ez == 0.0:
            continue
        if best is None or ea > best[0]:
            best = (ea, POST_CHANNELS[i], ez / ea)
    return None if best is None else best[1:]


def refuse_unknown_roads(source, what: str) -> None:
    """:class:`DataError` naming the first run on an unknown road (SPEC §9) of a dataset or scenario,
    for code that needs every road known; ``what`` names that code."""
    for r in source.runs:
        if not r.road_known:
            kind = "a generated (road_class)" if r.road is not None else "an unknown"
            raise DataError(f"{source.path}: run '{r.id}': unknown-road runs (SPEC §9: this one is on {kind} "
                            f"road) are not supported by {what} yet; leave the run out or give its track")


def scale_anchor(known: dict[str, float], where: str = "[known]") -> str:
    """The known value that fixes the absolute scale, or raise :class:`ScaleError`."""
    for k in ("total_mass",) + tuple(n for n in NAMES + EXT_NAMES if n not in SCALE_FREE):
        if known.get(k, 0.0) > 0:  # a known zero extension (none fitted) fixes no scale
            return k
    raise ScaleError(
        f"{where}: no scale anchor. Accelerations driven by a known road do not change when every mass, "
        "inertia, stiffness and damping is multiplied by the same factor, so the data fix only ratios. "
        "Give one absolute value in [known], normally total_mass (kg) from a weighbridge "
        f"(any of {', '.join(list(EXTRA_KNOWN) + [n for n in NAMES if n != 'a'])} works).")


def check_known_consistent(known: dict[str, float]):
    if "total_mass" in known:
        fixed_mass = sum(known.get(n, 0.0) * c for n, c in MASS_COUNT.items())
        if fixed_mass >= known["total_mass"]:
            raise DataError(f"[known]: total_mass = {known['total_mass']} is not more than the fixed masses "
                            f"(m_s + 2 m_uf + 2 m_ur = {fixed_mass})")
        if all(n in known for n in MASS_COUNT):
            tm = total_mass(known)
            if abs(tm - known["total_mass"]) > 1e-6 * tm:
                raise DataError(f"[known]: total_mass = {known['total_mass']} disagrees with m_s + 2 m_uf + "
                                f"2 m_ur = {tm}")


__all__ = ["Dataset", "LEAD_IN_SETTLES", "LeadIn", "read_dataset", "scale_anchor", "check_unknown_road_run",
           "lead_ins", "prepare_inputs", "run_lead_in",
           "refuse_unknown_roads", "MIN_ROAD_RUN_S", "MIN_ROAD_RUN_SAMPLES", "check_rig_run", "post_axle_ratio"]
