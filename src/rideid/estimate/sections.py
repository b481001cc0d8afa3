"""The result's sections and the entries of its tables as typed records (result.json, docs/formats.md).

Sections: ``model``, ``adequacy``, ``polish``, ``uncertainty``, ``correlation``, ``dampers``, ``bump_stops``,
``data_quality``, ``vehicle`` (:data:`SECTIONS`). Tables, name -> one record per entry (:data:`TABLES`): ``details``
(result.json ``parameters``, :class:`ParameterRecord`), ``starts``, ``roads``, ``tracks``, ``preprocessing``,
``modal``; and ``checks``, a list of :class:`FindingRecord`.

Each record is a frozen dataclass whose fields are the keys its part of result.json may hold, each field documented
where it is declared. A record knows which of its keys it holds, in the order they were given (:attr:`Section.held`):
a key the fit did not write is absent, as it is from the file, and its attribute is None. A record reads as the dict
it is written as (``section["extensions"]``, ``section.get("note")``, ``"advice" in section``, ``dict(section)``),
so that code and notebooks that read result.json read the result the same way; ``section.extensions`` is the typed
read.

The stages of the fit still build a part as a dict where they accrete it; :meth:`Section.of` turns it into its
record when it reaches an :class:`~rideid.estimate.result.IdentificationResult`, and refuses a key the record does
not declare (the keys are this module's, not whatever a stage wrote). A result.json read back keeps the keys its
records declare (a file of the same schema version has no others).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import ClassVar


@dataclass(frozen=True, eq=False)
class Section(Mapping):
    """A section of the result: declared fields, the keys held (:attr:`held`), read as a mapping of those keys."""

    #: result.json's key of the section
    name: ClassVar[str] = ""
    #: the keys this section holds, in the order given (the fields not among them are None: not written)
    held: tuple = field(default=(), repr=False)

    @classmethod
    def declared_keys(cls) -> tuple:
        """The keys the section may hold (its fields, in declaration order)."""
        return tuple(f.name for f in fields(cls) if f.name != "held")

    @classmethod
    def of(cls, value, strict: bool = True):
        """``value`` as this section: None stays None, a section of this kind is itself, a mapping becomes the record
        holding its keys. ``strict``: a key the section does not declare is a :class:`TypeError` (a stage wrote a key
        nobody declared); else it is left out (a file read back)."""
        if value is None or isinstance(value, cls):
            return value
        if not isinstance(value, Mapping):
            raise TypeError(f"result section {cls.name!r}: a mapping expected, got {type(value).__name__}")
        known = set(cls.declared_keys())
        unknown = [k for k in value if k not in known]
        if unknown and strict:
            raise TypeError(f"result section {cls.name!r}: undeclared key(s) {', '.join(map(repr, unknown))} "
                            f"(declare them in rideid.estimate.sections.{cls.__name__})")
        given = {k: v for k, v in value.items() if k in known}
        return cls(**given, held=tuple(given))

    def but(self, **changes) -> "Section":
        """A copy with ``changes`` (keys of the section) set: held from now on (a new key after the others)."""
        return self.of({**self, **changes})

    def to_dict(self) -> dict:
        """The section as result.json holds it: the keys held, in their order; a record nested in it as its dict
        too (other values as they are: NumPy arrays stay arrays)."""
        return {k: _plain(getattr(self, k)) for k in self.held}

    # -- read as the mapping of the keys held -----------------------------------------------------------------
    def __getitem__(self, key):
        if key in self.held:
            return getattr(self, key)
        raise KeyError(key)

    def __iter__(self):
        return iter(self.held)

    def __len__(self):
        return len(self.held)

    def __repr__(self):
        return f"{type(self).__name__}({', '.join(f'{k}={getattr(self, k)!r}' for k in self.held)})"


def _plain(v):
    """``v`` with every record in it as its dict (:meth:`Section.to_dict`), through dicts and lists."""
    if isinstance(v, Section):
        return v.to_dict()
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return type(v)(_plain(x) for x in v)
    return v


@dataclass(frozen=True, eq=False)
class ModelSection(Section):
    """Which model was fitted and, with ``auto``, how it was chosen (docs/model-choice.md)."""

    name: ClassVar[str] = "model"
    extensions: list | None = None  #: the extension groups fitted (SPEC §6), empty for the twelve alone
    selection: str | None = None  #: ``"given"``, ``"auto"``, or ``auto`` with why it stopped early
    criterion: str | None = None  #: the criterion weighing candidates, in words
    extension_criterion: str | None = None  #: the criterion weighing an extension against its parent, in words
    candidates: list | None = None  #: per candidate fitted: ``extensions, cost, criterion, wald, adequate, ...``
    fits_better_rule: str | None = None  #: the gate of the candidates' ``fits_better``, in words
    screens: list | None = None  #: per rival screened before any fit: the score test's figures and ``passes``
    steps: int | None = None  #: the extensions kept on top of the linear step
    skipped: list | None = None  #: the rivals the screen skipped
    first_fit: dict | None = None  #: when the first fit missed grossly: what mended it (null when it did not)
    curves: str | None = None  #: why damper curves were not tried (the linear model adequate)
    note: str | None = None  #: what ``auto`` did not try, or why the kept model differs from the as-drawn choice
    #: the groups ``auto`` kept on the tracks as drawn, when the fit on the tracks as built dropped one
    as_drawn_choice: list | None = None


@dataclass(frozen=True, eq=False)
class AdequacySection(Section):
    """The residual verdict and what qualifies it (docs/model-choice.md; the typed verdicts are
    :mod:`rideid.estimate.records`' assessments, read from this section)."""

    name: ClassVar[str] = "adequacy"
    adequate: bool | None = None  #: no road-driven structure that matters and no suspect sensor; None: no verdict
    reasons: list | None = None  #: why, one sentence each, the verdict's first
    advice: str | None = None  #: what to try next; null when adequate
    method: str | None = None  #: the test, in words
    alpha: float | None = None  #: the family-wise rate of the test
    min_explained: float | None = None  #: the least share of a whitened residual's variance the road must explain
    structure: bool | None = None  #: some pair holds road-driven structure (true; absent without)
    runs: dict | None = None  #: run -> channel -> the pair's figures (``rms, level, input_f, structure, ...``)
    materiality: dict | None = None  #: the weighing of the structure found (``material``, ``largest_shift``, ...)
    sensor_hints: list | None = None  #: channels that look AC-coupled without a declared ``highpass``
    sensor_hints_note: str | None = None  #: which road fit the hints come from
    sensors_suspect: bool | None = None  #: the road fit's hints made the verdict not adequate
    small_angle: dict | None = None  #: how far the body turned against the small-angle model (SPEC §1)
    tracks_caveat: str | None = None  #: adequate only with the tracks as drawn and structure weighed immaterial
    level_caveat: str | None = None  #: adequate, yet the residual well above the lead-in's noise floor
    setup_caveat: str | None = None  #: adequate, but the data contradicted a declared set-up value at load
    shape_caveat: str | None = None  #: adequate, but some error bars are optimistic (the cost's shape)
    not_assessed: list | None = None  #: the runs the verdict does not cover (unknown roads, ...)
    screens: list | None = None  #: a first fit that missed grossly: the model choice's screens at it
    gross_misfit: dict | None = None  #: the first fit missed grossly: ``run_errors``, ``at_bound`` and their thresholds
    roads: dict | None = None  #: the runs on unknown roads judged at their own road estimate (``verdict``, ``runs``)
    note: str | None = None  #: what the verdict covers, when not every run (runs on unknown roads not assessed)
    as_built: list | None = None  #: the runs judged at their track's estimated road (tracks as built, SPEC §11)
    as_built_note: str | None = None  #: how those runs were judged


@dataclass(frozen=True, eq=False)
class PolishSection(Section):
    """The least-squares polish: its outcome, covariances, the starts estimated with it, the error bars' shape."""

    name: ClassVar[str] = "polish"
    success: bool | None = None  #: the least squares ended on a criterion, not on a budget
    message: str | None = None  #: why it ended
    nfev: int | None = None  #: residual evaluations
    cost_before: float | None = None  #: sum of squared weighted residuals at the start
    cost_after: float | None = None  #: and at the end
    covariance: list | None = None  #: of the free parameters (white residuals)
    names: list | None = None  #: the free parameters, in ``covariance``'s order
    covariance_robust: list | None = None  #: HAC (correlated residuals)
    covariance_jackknife: list | None = None  #: leave-one-run-out; null with fewer than three runs
    jackknife_runs: int | None = None  #: the runs the jackknife left out in turn
    hac_bandwidths: dict | None = None  #: run -> the HAC kernel's bandwidth, samples
    starts: dict | None = None  #: run -> the start estimated with the parameters (``value, std, std_robust``)
    alignment_rounds: list | None = None  #: per round of the starts' re-estimation, how far they moved
    #: run -> the speed estimated with the parameters (a nonlinear car's run whose declared speed load moved: ``value,
    #: std, std_robust, declared, prior_std``, m/s)
    speeds: dict | None = None
    shape: dict | None = None  #: the error bars' shape out to ±2 std_robust (docs/uncertainty.md)
    unresolved: dict | None = None  #: a road fit's directions its Hessian does not fix above its rounding
    remeasured: list | None = None  #: those directions measured again at a larger step
    mode_restart: dict | None = None  #: a powertrain mode polished again from typical values, and what it gave
    method: str | None = None  #: a road fit's blocks, in words
    covariance_robust_motion_fixed: list | None = None  #: a road fit's, with the runs' speeds and starts held
    as_drawn: Mapping | None = None  #: a fit on the tracks as built: the polish on the tracks as drawn it began from


@dataclass(frozen=True, eq=False)
class UncertaintySection(Section):
    """SPEC §12: what was declared uncertain and how it was propagated (docs/uncertainty.md "The budget")."""

    name: ClassVar[str] = "uncertainty"
    declared: dict | None = None  #: name -> ``kind, key, value, std, unit`` of every declared uncertainty
    anchor: str | None = None  #: the scale anchor's key (normally ``total_mass``)
    anchor_exact: bool | None = None  #: the anchor is a plain number (taken as exact: said in ``notes``)
    method: str | None = None  #: how the declared uncertainties were propagated
    not_propagated: list | None = None  #: declared inputs this fit could not propagate (named in ``notes``)
    rigid_body: dict | None = None  #: the body sensors' relative gains from rigid-body redundancy
    notes: list | None = None  #: one sentence each, what a reader of the error bars must know


@dataclass(frozen=True, eq=False)
class CorrelationSection(Section):
    """The correlation matrix of the estimates from the robust covariance (docs/uncertainty.md)."""

    name: ClassVar[str] = "correlation"
    names: list | None = None  #: the free parameters, then the derived mass
    matrix: object = None  #: ``len(names)`` square, correlations
    basis: str | None = None  #: which covariance it is of


@dataclass(frozen=True, eq=False)
class DampersSection(Section):
    """SPEC §8 damper curves, with ``damper_curves`` (docs/dampers.md)."""

    name: ClassVar[str] = "dampers"
    velocity: list | None = None  #: the knots' velocities, m/s (compression +), both axles
    unit: dict | None = None  #: the units of ``velocity`` and ``force``
    front: dict | None = None  #: per knot ``force, std, std_robust, std_total, excited, ...`` (N)
    rear: dict | None = None  #: the same for the rear axle
    excitation_rule: str | None = None  #: when a knot counts as excited, in words
    mean_slope_velocity: float | None = None  #: the velocity (m/s) out to which the curves' mean slope is c_sf, c_sr
    knots_from: str | None = None  #: where the knots came from (SPEC §8 defaults, [model] damper_knots, a grid)
    grid_note: str | None = None  #: the knots were found on a grid: what that means for the error bars
    knees: dict | None = None  #: per axle and side, the velocity where the curve bends most, and its std
    knee_rule: str | None = None  #: how a knee is found, in words
    velocity_note: str | None = None  #: on unknown roads: the suspension velocities read off the accelerometers


@dataclass(frozen=True, eq=False)
class BumpStopsSection(Section):
    """SPEC §8 bump stops, with ``bump_stops`` (docs/dampers.md)."""

    name: ClassVar[str] = "bump_stops"
    front: dict | None = None  #: ``reached, clearance, rate, std, std_robust, known, ...`` of the front stops
    rear: dict | None = None  #: the same for the rear
    unit: dict | None = None  #: the units of ``clearance`` and ``rate``
    rule: str | None = None  #: when a stop counts as reached, in words


@dataclass(frozen=True, eq=False)
class DataQualitySection(Section):
    """Per channel over the runs: clipped share, gaps bridged, noise level, sensor chain
    (:func:`rideid.data.quality.data_quality`)."""

    name: ClassVar[str] = "data_quality"
    channels: dict | None = None  #: SPEC channel -> ``runs, clipped_share, clipped_runs, gaps, noise, unit, ...``
    runs: int | None = None  #: the dataset's run count


@dataclass(frozen=True, eq=False)
class VehicleSection(Section):
    """The dataset's ``[vehicle]`` table (m), so that the identified car can leave without its dataset (SPEC §10)."""

    name: ClassVar[str] = "vehicle"
    wheelbase: float | None = None  #: front to rear axle
    track_front: float | None = None  #: between the front wheels' centres
    track_rear: float | None = None  #: between the rear wheels' centres
    tire_radius: float | None = None  #: loaded
    cg_height: float | None = None  #: the sprung mass's CG above the ground, when given


# -- the records of the result's tables: one per parameter, run, road, track or mode -----------------------------

@dataclass(frozen=True, eq=False)
class ParameterRecord(Section):
    """One parameter of result.json ``parameters`` (SPEC §5, §6, §12; docs/uncertainty.md)."""

    name: ClassVar[str] = "parameters"
    value: float | None = None  #: the estimate (a known value, or one derived from the others), SI units
    unit: str | None = None  #: its unit
    fixed: bool | None = None  #: a ``[known]`` value, not estimated
    derived: bool | None = None  #: computed from the others (``m_s`` from ``total_mass``, a curve's mean slope)
    std: float | None = None  #: standard error, white residuals assumed (optimistic when they are correlated)
    std_robust: float | None = None  #: HAC standard error (correlated residuals), the larger of the robust ones
    std_total: float | None = None  #: ``std_robust`` with every declared uncertainty propagated (SPEC §12)
    budget: dict | None = None  #: each declared input's share of ``std_total``
    lower: float | None = None  #: the search's lower bound
    upper: float | None = None  #: and its upper bound
    at_bound: bool | None = None  #: ended within 1 % of the search range of a bound: the bound's value
    reached: bool | None = None  #: a bump stop's parameter: whether the stop was reached
    note: str | None = None  #: what a reader must know of this estimate, in words
    excited: bool | None = None  #: a damper-curve knot: excited by the runs (else held)
    std_grid: float | None = None  #: a knot found on a grid: the grid's share of the error bar
    std_hac: float | None = None  #: the HAC standard error itself
    std_jackknife: float | None = None  #: leave one run out
    std_between_runs: float | None = None  #: the runs' disagreement with each other
    std_motion: float | None = None  #: the runs' speeds and starts' share (tracks as built, unknown roads)
    std_velocity: float | None = None  #: on unknown roads with damper curves: the velocities' noise's share
    determined: bool | None = None  #: false where the cost's rounding hides the estimate (``polish.unresolved``)
    conditional_on: list | None = None  #: the parameters at a search bound its error bar holds only with


@dataclass(frozen=True, eq=False)
class StartRecord(Section):
    """A run's start estimated with the parameters (result.json ``starts``; SPEC §3, §13)."""

    name: ClassVar[str] = "starts"
    value: float | None = None  #: the start, s of the run's file time
    std: float | None = None  #: its standard error (with a speed channel combined with the channel's drift)
    std_fit: float | None = None  #: the fit's alone
    std_robust: float | None = None  #: the fit's HAC error
    std_speed_channel: float | None = None  #: a noisy speed channel's drift to the road's features
    source: str | None = None  #: how it was estimated
    distance_correction: dict | None = None  #: a noisy speed channel's distance correction, estimated with it


@dataclass(frozen=True, eq=False)
class RoadRecord(Section):
    """A run on an unknown road (result.json ``roads``; SPEC §9, docs/any-road.md)."""

    name: ClassVar[str] = "roads"
    file: str | None = None  #: the estimated road's file beside result.json (``road/<run>.csv``)
    iso8608_class: str | None = None  #: the road's ISO 8608 class
    gd_n0: float | None = None  #: its displacement PSD at the reference wavenumber
    gd_n0_unit: str | None = None  #: the unit of ``gd_n0``
    speed: float | None = None  #: the run's speed as estimated, m/s
    fit_band_hz: list | None = None  #: the band the road was fitted in, Hz
    wavelengths_m: list | None = None  #: the road wavelengths that band covers at that speed, m
    note: str | None = None  #: what the road estimate is and is not
    motion: dict | None = None  #: the speed estimated with the car, against its declared prior (SPEC §13)
    residual: dict | None = None  #: channel -> the run's residual at its own road estimate
    channels_left_out: dict | None = None  #: channel -> why it was left out of the run's fit (no signal, clipped)


@dataclass(frozen=True, eq=False)
class TrackRecord(Section):
    """A track fitted as built (result.json ``tracks``; SPEC §11, docs/tracks-as-built.md)."""

    name: ClassVar[str] = "tracks"
    amplitude_factor: float | None = None  #: the track's size over its drawing's
    amplitude_factor_std: float | None = None  #: its standard error
    unevenness_rms_m: float | None = None  #: the road the drawing lacks, RMS over one wheel path, m
    unevenness_rms_surface_m: float | None = None  #: the same over the surface
    method: str | None = None  #: how the track was fitted
    note: str | None = None  #: what a reader must know of it
    runs: dict | None = None  #: run -> what each run says of the track, with its ``motion``
    rejected: str | None = None  #: why the as-built fit was rejected (the track then taken as drawn)


@dataclass(frozen=True, eq=False)
class PreprocessingRecord(Section):
    """How one run was read, resampled and filtered (result.json ``preprocessing``; docs/real-data.md)."""

    name: ClassVar[str] = "preprocessing"
    file: str | None = None  #: the run's file
    format: str | None = None  #: its format (SPEC CSV, MDF4, TDMS, Parquet, a logger CSV)
    csv: dict | None = None  #: a logger CSV's options as read
    channels: dict | None = None  #: SPEC channel -> its source, unit, sign, scale as mapped
    start: dict | None = None  #: the run's start and where it came from
    speed: dict | None = None  #: the run's speed and where it came from
    fs: float | None = None  #: the rate the model runs at, Hz
    resampling: dict | None = None  #: how the file's rates were brought to ``fs``
    samples: int | None = None  #: the model samples fitted
    model_time: list | None = None  #: the span of model time fitted, s
    lead_in: dict | None = None  #: the quiet lead-in the noise floor is read on
    recording: dict | None = None  #: the file's own time span and rate
    motion: dict | None = None  #: the run's speed and start as estimated with the car
    moving_start: dict | None = None  #: a run that begins moving, fitted on its track: its lead-in (SPEC §9)
    warnings: list | None = None  #: what reading the file warned of


@dataclass(frozen=True, eq=False)
class ModeRecord(Section):
    """One of the seven modes of the identified car (result.json ``modal``)."""

    name: ClassVar[str] = "modal"
    frequency_hz: float | None = None  #: the natural frequency ``|lambda| / 2 pi`` of the mode's eigenvalue pair, Hz
    damping_ratio: float | None = None  #: ``-Re(lambda) / |lambda|``
    undamped_frequency_hz: float | None = None  #: the undamped natural frequency, Hz


@dataclass(frozen=True, eq=False)
class FindingRecord(Section):
    """A finding of the data checks, the bound check or the motion check (result.json ``checks``;
    :class:`rideid.data.checks.Finding`, docs/common-mistakes.md)."""

    name: ClassVar[str] = "checks"
    severity: str | None = None  #: ``"error"``, ``"warning"`` or ``"note"`` (recorded, not warned of)
    check: str | None = None  #: which check: ``coverage``, ``wiring``, ``track``, ``speed``, ``bounds``, ``motion``
    message: str | None = None  #: what it found and what to do, in one line
    run: str | None = None  #: the run it is about, if one
    channel: str | None = None  #: the channel, key or parameter it names, if one
    fix: dict | None = None  #: what rideid did or proposes (a channel map entry, a speed, a start)


def list_of(cls, value, strict: bool = True):
    """A list of records, each ``cls.of`` its item; None stays None."""
    return None if value is None else [cls.of(v, strict) for v in value]


#: result attribute -> the record of each entry of its table (parameter, run, road, track or mode -> record)
TABLES = {"details": ParameterRecord, "starts": StartRecord, "roads": RoadRecord, "tracks": TrackRecord,
          "preprocessing": PreprocessingRecord, "modal": ModeRecord}


def table_of(cls, value, strict: bool = True):
    """A table (a mapping of names to records) with each entry ``cls.of`` its value; None stays None."""
    if value is None:
        return None
    return {k: cls.of(v, strict) for k, v in value.items()}


#: result attribute -> its section's record
SECTIONS = {cls.name: cls for cls in (ModelSection, AdequacySection, PolishSection, UncertaintySection,
                                      CorrelationSection, DampersSection, BumpStopsSection, DataQualitySection,
                                      VehicleSection)}

__all__ = ["Section", "ModelSection", "AdequacySection", "PolishSection", "UncertaintySection",
           "CorrelationSection", "DampersSection", "BumpStopsSection", "DataQualitySection", "VehicleSection",
           "SECTIONS", "ParameterRecord", "StartRecord", "RoadRecord", "TrackRecord", "PreprocessingRecord",
           "ModeRecord", "TABLES", "table_of", "FindingRecord", "list_of"]
