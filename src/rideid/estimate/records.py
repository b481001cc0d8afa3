"""Typed records of a result: the problem's plan and one assessment per kind (SPEC §13).

The identification computes its verdicts where it always did (the adequacy
test, the materiality weighing, the small-angle check, the sensor hints, the
level and drawing caveats, the bound check) and keeps them in the result's
``adequacy``, ``details`` and ``tracks`` blocks. This module reads those
blocks once, at the end of :func:`rideid.identify`, into typed records:

* :class:`Plan`: the problem's blocks and their unknowns (the car's free
  parameters, each run's start and speed where estimated, each track's
  amplitude factor and unevenness where fitted as built, the roads of runs
  on unknown roads);
* :data:`ASSESSMENTS`: the declared list of assessment kinds, each a frozen
  dataclass with ``verdict`` and ``reason`` and its own fields, built by its
  ``from_result``.

Every assessment's ``verdict`` is one of :data:`VERDICTS`:

``"pass"``
    checked, and nothing found that bears on the estimates;
``"warn"``
    the estimates stand, but some of them or their error bars are to be read
    with the caveat in ``reason``;
``"fail"``
    the estimates are not to be trusted as they are (``reason`` says why);
``"not assessed"``
    the check did not run (``reason`` says why: ``assess=False``, runs on
    unknown roads only, no fitted response, ...).

The records are built from what the result holds, so a result written
before them (schema version 1) gets the same records when it is read back
(:func:`assessments_of`); docs/formats.md has one table per record.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import ClassVar

from .assess.adequacy import caveats, setup_caveat, setup_slips
from .assess.details import unresolved_sentence
from .assess.shape import caveat as shape_caveat

#: the four verdicts, mildest first
VERDICTS = ("pass", "warn", "fail", "not assessed")


def _not_assessed(why: str) -> dict:
    return {"verdict": "not assessed", "reason": why}


def _pairs(adequacy: dict, key: str = "structure") -> list[str]:
    """``run/channel`` of every pair of the adequacy test whose figure ``key`` is true."""
    return [f"{rid}/{ch}" for rid, rec in (adequacy.get("runs") or {}).items() for ch, f in rec.items()
            if isinstance(f, dict) and f.get(key)]


@dataclass(frozen=True)
class Assessment:
    """What every assessment record has: its ``kind`` (class attribute), ``verdict`` and ``reason``."""

    kind: ClassVar[str] = ""
    #: the ``adequacy`` key whose caveat this record's ``warn`` writes on an adequate verdict (:func:`with_caveats`),
    #: or None: a record that only reads the result
    caveat: ClassVar[str | None] = None
    verdict: str
    reason: str

    def __post_init__(self):
        if self.verdict not in VERDICTS:
            raise ValueError(f"{self.kind}: verdict {self.verdict!r} is not one of {', '.join(VERDICTS)}")

    def to_dict(self) -> dict:
        """The record in result.json ``assessments``: ``kind`` first, then the fields."""
        return {"kind": self.kind, **asdict(self)}

    @classmethod
    def from_dict(cls, d: dict) -> "Assessment":
        """The record read back (unknown keys, from a later version, are left out)."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


@dataclass(frozen=True)
class AdequacyAssessment(Assessment):
    """Does the model explain the road-driven part of the residuals (docs/model-choice.md)?

    ``fail`` when not adequate (road-driven structure that matters, or the sensors suspect).
    """

    kind: ClassVar[str] = "adequacy"
    adequate: bool | None = None  #: the verdict: no structure that matters, no suspect sensor; None: no verdict
    pairs: int = 0  #: the run/channel pairs tested
    pairs_with_structure: list = field(default_factory=list)  #: ``"run/channel"`` of each pair with structure
    alpha: float | None = None  #: the test's family-wise rate (setting ``adequacy.alpha``), split over the pairs
    min_explained: float | None = None  #: the least share of a whitened residual's variance the road must explain
    sensors_suspect: bool = False  #: the road fit's sensor hints made the verdict not adequate (docs/real-data.md)
    advice: str | None = None  #: what to try next; None when adequate

    @classmethod
    def from_result(cls, res) -> "AdequacyAssessment":
        ad = res.adequacy
        if not ad:
            return cls(**_not_assessed("no adequacy test was run (assess=False, or runs on unknown roads only)"))
        adequate = ad.get("adequate")
        pairs = sum(len(rec) for rec in (ad.get("runs") or {}).values())
        verdict = "not assessed" if adequate is None else ("pass" if adequate else "fail")
        reasons = ad.get("reasons") or []
        reason = reasons[0] if reasons else ad.get("note", "")
        held = caveats(ad)
        if held:  # adequate on what was tested, but not a clean verdict: unassessed runs, a loud residual
            verdict, reason = "warn", reason + "; but " + "; ".join(held)
        return cls(verdict=verdict, reason=reason, adequate=adequate,
                   pairs=pairs, pairs_with_structure=_pairs(ad), alpha=ad.get("alpha"),
                   min_explained=ad.get("min_explained"), sensors_suspect=bool(ad.get("sensors_suspect")),
                   advice=ad.get("advice"))


@dataclass(frozen=True)
class MaterialityAssessment(Assessment):
    """Does the structure the adequacy test found move the estimates by more than their error bars
    (:mod:`rideid.estimate.assess.materiality`)? ``fail`` when it does."""

    kind: ClassVar[str] = "materiality"
    material: bool | None = None  #: the structure matters: an estimate moves beyond ``threshold`` without its pairs
    threshold: float | None = None  #: the move that is material, std_total (setting ``materiality.material_shift``)
    largest_parameter: str | None = None  #: the estimate that moved most; None when none could be compared
    largest_shift: float | None = None  #: how far it moved, in std_total
    pairs_left_out: list = field(default_factory=list)  #: ``"run/channel"`` of the pairs with structure, left out

    @classmethod
    def from_result(cls, res) -> "MaterialityAssessment":
        rec = (res.adequacy or {}).get("materiality")
        if not rec:
            why = ("no structure to weigh" if res.adequacy and not _pairs(res.adequacy)
                   else "not weighed (no adequacy test, runs on unknown roads, or structure everywhere)")
            return cls(**_not_assessed(why))
        largest = rec.get("largest_shift") or {}
        material = rec.get("material")
        return cls(verdict="fail" if material else "pass", reason=rec.get("reason", ""), material=material,
                   threshold=rec.get("threshold"), largest_parameter=largest.get("parameter"),
                   largest_shift=largest.get("in_std_total"), pairs_left_out=list(rec.get("pairs_left_out") or []))


@dataclass(frozen=True)
class SmallAngleAssessment(Assessment):
    """How far the body turned, against the small-angle model of SPEC §1 (:mod:`rideid.estimate.assess.small_angle`).
    ``warn`` when the bias to expect exceeds some error bars (``optimistic``)."""

    kind: ClassVar[str] = "small_angles"
    largest_roll_deg: float | None = None  #: the fitted body's largest roll over the runs, deg (its gyro integrated)
    roll_run: str | None = None  #: the run it rolls that far in
    largest_pitch_deg: float | None = None  #: the fitted body's largest pitch over the runs, deg
    pitch_run: str | None = None  #: the run it pitches that far in
    expected_bias: float | None = None  #: relative bias to expect: ``small_angle.bias_per_degree`` x the larger angle
    threshold_deg: float | None = None  #: the angle above which it is weighed, deg (``small_angle.threshold_deg``)
    optimistic: list = field(default_factory=list)  #: the parameters whose ±2 std_total is narrower than that bias

    @classmethod
    def from_result(cls, res) -> "SmallAngleAssessment":
        sa = (res.adequacy or {}).get("small_angle")
        if not sa:
            return cls(**_not_assessed("no fitted response to integrate the gyros of (or no adequacy test)"))
        largest = max(sa.get("largest_roll_deg") or 0.0, sa.get("largest_pitch_deg") or 0.0)
        optimistic = list(sa.get("optimistic") or [])
        verdict = "warn" if optimistic else "pass"
        reason = sa.get("note") or (f"the body turned at most {largest:.2g} deg, below "
                                    f"{sa.get('threshold_deg')} deg: the small-angle bias is below the error bars")
        return cls(verdict=verdict, reason=reason, **{k: sa.get(k) for k in (
            "largest_roll_deg", "roll_run", "largest_pitch_deg", "pitch_run", "expected_bias", "threshold_deg")},
            optimistic=optimistic)


@dataclass(frozen=True)
class SensorHintsAssessment(Assessment):
    """Channels that look AC-coupled without a declared ``highpass`` (:mod:`rideid.estimate.assess.sensor_check`).
    ``warn`` when any is named."""

    kind: ClassVar[str] = "sensor_hints"
    channels: list = field(default_factory=list)  #: the channels that look AC-coupled (SPEC channel names)
    highpass_hz: list = field(default_factory=list)  #: per channel, the trial high-pass corner that fits best, Hz
    note: str | None = None  #: which road fit the hints come from (``adequacy.sensor_hints_note``); None: the car's fit

    @classmethod
    def from_result(cls, res) -> "SensorHintsAssessment":
        ad = res.adequacy
        if not ad:
            return cls(**_not_assessed("no adequacy test, so no sensor check"))
        hints = [h for h in (ad.get("sensor_hints") or []) if isinstance(h, dict)]
        if not hints:
            return cls(verdict="pass", reason="no channel looks AC-coupled beyond its declaration")
        chans = [str(h.get("channel")) for h in hints]
        return cls(verdict="warn", reason=str(hints[0].get("message") or f"{', '.join(chans)} look AC-coupled"),
                   channels=chans, highpass_hz=[h.get("highpass_hz") for h in hints],
                   note=ad.get("sensor_hints_note"))


@dataclass(frozen=True)
class LevelAssessment(Assessment):
    """An adequate verdict whose residual is well above the lead-in's noise floor in many pairs
    (:func:`rideid.estimate.assess.adequacy.level_caveat`): ``warn``."""

    kind: ClassVar[str] = "level"
    loud_pairs: int = 0  #: the run/channel pairs whose residual is above 3x their noise floor
    pairs_with_floor: int = 0  #: the pairs with a quiet lead-in to measure the floor on

    @classmethod
    def from_result(cls, res) -> "LevelAssessment":
        ad = res.adequacy
        if not ad or not ad.get("adequate"):
            return cls(**_not_assessed("the level caveat qualifies an adequate verdict only"))
        levels = [f["level"] for rec in (ad.get("runs") or {}).values() for f in rec.values()
                  if isinstance(f, dict) and f.get("level") is not None]
        loud = sum(1 for lv in levels if lv > 3)
        caveat = ad.get("level_caveat")
        if not levels:
            return cls(**_not_assessed("no run has a quiet lead-in to measure the noise floor on"))
        return cls(verdict="warn" if caveat else "pass",
                   reason=caveat or f"the residual is above 3x the noise floor in {loud} of {len(levels)} pairs",
                   loud_pairs=loud, pairs_with_floor=len(levels))


@dataclass(frozen=True)
class DrawingAssessment(Assessment):
    """An adequate verdict on tracks taken as drawn while the residuals hold road-driven structure in several
    runs (:func:`rideid.estimate.choice.model_choice._drawing_caveat`): ``warn``."""

    kind: ClassVar[str] = "drawing"
    tracks_as_built: list = field(default_factory=list)  #: the tracks fitted as built (SPEC §11), sorted
    tracks_rejected: list = field(default_factory=list)  #: the tracks whose as-built fit was rejected (taken as drawn)

    @classmethod
    def from_result(cls, res) -> "DrawingAssessment":
        tracks = res.tracks or {}
        built = sorted(t for t, rec in tracks.items() if not rec.get("rejected")
                       and any("amplitude_factor" in r for r in (rec.get("runs") or {}).values()))
        rejected = sorted(t for t, rec in tracks.items() if rec.get("rejected"))
        ad = res.adequacy
        if not ad:
            return cls(**_not_assessed("no adequacy test"), tracks_as_built=built, tracks_rejected=rejected)
        caveat = ad.get("tracks_caveat")
        if caveat:
            return cls(verdict="warn", reason=caveat, tracks_as_built=built, tracks_rejected=rejected)
        reason = (f"tracks fitted as built: {', '.join(built)}" if built else
                  "the tracks as drawn leave no road-driven structure that the weighing could not judge")
        return cls(verdict="pass", reason=reason, tracks_as_built=built, tracks_rejected=rejected)


@dataclass(frozen=True)
class BoundsAssessment(Assessment):
    """Free parameters that ended at a search bound (:func:`rideid.data.checks.bound_findings`): the bound's
    value, not the data's. ``fail`` when any."""

    kind: ClassVar[str] = "bounds"
    at_bound: list = field(default_factory=list)  #: the free parameters within 1 % of the search range of a bound

    @classmethod
    def from_result(cls, res) -> "BoundsAssessment":
        at = [n for n, d in (res.details or {}).items() if d.get("at_bound") and not d.get("fixed")]
        if at:
            return cls(verdict="fail", reason=f"{', '.join(at)} ended at a search bound: the bound's value, not the "
                       "data's (widen [bounds] in dataset.toml, or check the data)", at_bound=at)
        return cls(verdict="pass", reason="no free parameter ended at a search bound")


@dataclass(frozen=True)
class RoadsAssessment(Assessment):
    """Do the runs on unknown roads leave only the sensor noise at their own road estimate
    (:mod:`rideid.estimate.assess.roads`)? ``fail`` when a run leaves more; ``runs``: run -> channel -> figures
    (``rms``, ``signal_rms``, ``share``, ``off``); ``failed``: the runs that fail."""

    kind: ClassVar[str] = "roads"
    runs: dict = field(default_factory=dict)
    failed: list = field(default_factory=list)

    @classmethod
    def from_result(cls, res) -> "RoadsAssessment":
        ad = res.adequacy or {}
        if isinstance(ad.get("roads"), dict):
            return cls.from_dict(ad["roads"])
        roads = getattr(res, "roads", None) or {}
        if not roads:
            return cls(**_not_assessed("no run on an unknown road"))
        runs = {rid: r["residual"] for rid, r in roads.items() if isinstance(r, Mapping) and "residual" in r}
        if not runs:
            return cls(**_not_assessed("the road runs' residuals were not judged (assess=False, no polish, or a "
                                       "result written before the test)"))
        # judged, and no adequacy block kept: the road runs passed (rideid.estimate.assess.roads.judge)
        return cls(verdict="pass", reason="every run on an unknown road is explained to the sensor noise at its own "
                   "road estimate", runs=runs)


@dataclass(frozen=True)
class SetupAssessment(Assessment):
    """Did the data contradict a declared set-up value at load (SPEC §13: a declared speed more than 3 of its prior's
    std from the speed the lags show, a warning of the ``speed`` check in ``checks``)? ``warn`` when they did: the
    fit took the data's value, so the numbers may be right, but an adequate verdict is then not a clean one (its
    caveat ``adequacy.setup_caveat``, :func:`rideid.estimate.assess.adequacy.setup_caveat`). ``runs``: one
    ``{"run", "declared", "speed"}`` (m/s) per such run."""

    kind: ClassVar[str] = "setup"
    caveat: ClassVar[str | None] = "setup_caveat"
    runs: list = field(default_factory=list)

    @classmethod
    def from_result(cls, res) -> "SetupAssessment":
        checks = getattr(res, "checks", None) or []
        slips = setup_slips(checks)
        if slips:
            return cls(verdict="warn", reason=setup_caveat(checks), runs=slips)
        return cls(verdict="pass", reason="the data contradicted no declared set-up value at load")


@dataclass(frozen=True)
class ShapeAssessment(Assessment):
    """Is the cost as curved out to ±2 std_robust along each free parameter's profile line as its curvature at the
    minimum says (:mod:`rideid.estimate.assess.shape`)? ``warn`` naming the parameters where it rises less than
    setting ``shape.flat_ratio`` of that (their error bars are optimistic: a flat valley), and the parameters the
    cost's rounding leaves not determined (``polish.unresolved``, a road fit's Hessian:
    :class:`rideid.estimate.fit.uncertainty.Resolution`); written as the adequate verdict's caveat
    ``adequacy.shape_caveat``."""

    kind: ClassVar[str] = "error_bar_shape"
    caveat: ClassVar[str | None] = "shape_caveat"
    optimistic: list = field(default_factory=list)  #: the parameters whose error bar is optimistic
    ratio: dict = field(default_factory=dict)  #: parameter -> [minus, plus]: the cost's rise over the quadratic's
    error_bars: float | None = None  #: how far out, in std_robust (setting ``shape.error_bars``)
    flat_ratio: float | None = None  #: the share below which an error bar is optimistic (``shape.flat_ratio``)
    not_determined: list = field(default_factory=list)  #: the parameters without an error bar (``polish.unresolved``)

    @classmethod
    def from_result(cls, res) -> "ShapeAssessment":
        polish = getattr(res, "polish", None) or {}
        shape, unresolved = polish.get("shape"), polish.get("unresolved") or {}
        if not shape:
            return cls(**_not_assessed("no polish, or a result written before the check"))
        fields_ = {k: shape.get(k) for k in ("error_bars", "flat_ratio")}
        optimistic = list(shape.get("optimistic") or [])
        nd = list(unresolved.get("not_determined") or [])
        if optimistic or nd:
            return cls(verdict="warn", reason=error_bar_warning(polish), optimistic=optimistic, ratio=shape["ratio"],
                       not_determined=nd, **fields_)
        judged = sum(1 for r in shape["ratio"].values() if any(v is not None for v in r))
        if not judged:
            return cls(**_not_assessed("no error bar could be judged (each at the rounding of its value: a noise-free "
                                       "fit; or every step beyond a bound)"), ratio=shape["ratio"], **fields_)
        return cls(verdict="pass", reason=f"the cost is as curved as the error bars say out to "
                   f"±{shape['error_bars']:g} of them on the {judged} parameter(s) judged", ratio=shape["ratio"],
                   **fields_)


def error_bar_warning(polish: dict | None) -> str | None:
    """What the error bars do not bear, in one sentence (None when nothing): the parameters a road fit's Hessian
    leaves not determined (``polish.unresolved``), then those whose error bar the cost's shape calls optimistic
    (``polish.shape``, :func:`rideid.estimate.assess.shape.caveat`). The terminal, the report and
    :class:`ShapeAssessment` say it so."""
    polish = polish or {}
    unresolved = polish.get("unresolved") or {}
    nd = list(unresolved.get("not_determined") or [])
    flat = shape_caveat(polish.get("shape"))
    said = ([f"{', '.join(nd)} {unresolved_sentence(unresolved)}"] if nd else []) + ([flat] if flat else [])
    return "; ".join(said) or None


#: the declared list of assessments, in the order result.json lists them
ASSESSMENTS: tuple[type[Assessment], ...] = (AdequacyAssessment, MaterialityAssessment, SmallAngleAssessment,
                                             SensorHintsAssessment, LevelAssessment, DrawingAssessment,
                                             RoadsAssessment, BoundsAssessment, SetupAssessment, ShapeAssessment)
_BY_KIND = {a.kind: a for a in ASSESSMENTS}


def with_caveats(res):
    """``res`` with the caveat of each declared assessment that qualifies an adequate verdict (``caveat``: its
    ``adequacy`` key) written into ``adequacy`` where the record warns, so that :func:`caveats` (the terminal, the
    report, the adequacy record) says it; ``res`` itself when the verdict is not adequate or nothing warns."""
    ad = getattr(res, "adequacy", None)
    if not ad or not ad.get("adequate"):
        return res
    held = {a.caveat: r.reason for a in ASSESSMENTS if a.caveat for r in [a.from_result(res)] if r.verdict == "warn"}
    return replace(res, adequacy={**ad, **held}) if held else res


def assessments_of(res) -> list[Assessment]:
    """Every assessment of the result ``res``, built from its ``adequacy``, ``details``, ``tracks`` and ``checks``."""
    return [a.from_result(res) for a in ASSESSMENTS]


def assessments_from_json(items) -> list[Assessment]:
    """result.json ``assessments`` read back (records of an unknown kind are left out)."""
    return [_BY_KIND[d["kind"]].from_dict(d) for d in items or [] if isinstance(d, dict) and d.get("kind") in _BY_KIND]


@dataclass(frozen=True)
class Block:
    """One block of the problem: a named group of unknowns.

    ``kind``: ``"car"``, ``"run"`` (a run's start and speed), ``"track"`` (a track fitted as built) or
    ``"road"`` (a run on an unknown road, its road projected out); ``unknowns``: what the fit estimates in it;
    ``fixed``: what it holds at a known value; ``runs``: the runs whose data determine it (all, for the car).
    """

    name: str
    kind: str
    unknowns: list = field(default_factory=list)
    fixed: list = field(default_factory=list)
    runs: list = field(default_factory=list)


@dataclass(frozen=True)
class Plan:
    """The problem's blocks and their unknowns (result.json ``plan``)."""

    blocks: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"blocks": [asdict(b) for b in self.blocks]}

    @classmethod
    def from_dict(cls, d: dict | None) -> "Plan | None":
        if not isinstance(d, dict):
            return None
        names = {f.name for f in fields(Block)}
        return cls([Block(**{k: v for k, v in b.items() if k in names}) for b in d.get("blocks") or []])


def motion_line(rid: str, m: dict) -> str:
    """One run's motion as fitted, in one line (SPEC §13: the estimate, its std, the declared value): its speed, and
    on a track as built its start's move; ``m`` the run's ``motion`` record (result.json
    ``tracks.<track>.runs.<run>.motion``, ``roads.<run>.motion``). The terminal and the report both say it so."""
    # the stds to two significant digits: a small one is not printed as zero
    sd = m.get("speed_std_m_s")
    sd = ("" if sd is None else f" ± {sd:.2g}" if sd > 0
          else " (its std not determined: the fit's curvature there is nil)")
    st = "" if m.get("start_shift_std_s") is None else f" ± {1e3 * m['start_shift_std_s']:.2g}"
    sp = m.get("speed") or {}
    if sp.get("declared") is not None:
        was = f"declared {sp['declared']:.4g} ± {sp['prior_std']:.2g}"
    else:
        was = f"the speed channel's mean {m.get('speed_channel_mean_m_s') or float('nan'):.4f}"
    if "start_shift_s" not in m:  # a run on an unknown road: its speed alone
        return f"{rid}: speed {m['speed_m_s']:.4f}{sd} m/s ({was})"
    return (f"{rid}: speed {m['speed_m_s']:.4f}{sd} m/s ({was}), start moved "
            f"{1e3 * m['start_shift_s']:+.2f}{st} ms")


def drawn_motions(res) -> dict:
    """Run id -> the ``motion`` record of each run on a track as drawn whose speed a fit with unknown roads
    estimated with the car (result.json ``preprocessing.<run>.motion`` naming its ``track``; SPEC §13)."""
    return {rid: rec["motion"] for rid, rec in (getattr(res, "preprocessing", None) or {}).items()
            if (rec.get("motion") or {}).get("track") and "speed_m_s" in rec["motion"]}


def drawn_motion_line(rid: str, m: dict) -> str:
    """:func:`motion_line` of a run on a track as drawn (:func:`drawn_motions`), naming the track."""
    return f"{motion_line(rid, m)}, on track '{m['track']}' as drawn"


def drawn_speeds_line(res) -> str | None:
    """The runs' speeds estimated with the car on the tracks as drawn (:func:`drawn_motions`), in one line: each
    speed, the largest departure from its declared value, and the runs named beyond their prior; None without."""
    motions = drawn_motions(res)
    if not motions:
        return None
    speeds = ", ".join(f"{rid} {m['speed_m_s']:.4f}" for rid, m in motions.items())
    off = max(abs(m["speed"]["estimate"] / m["speed"]["declared"] - 1.0) for m in motions.values())
    named = [rid for rid, m in motions.items() if m.get("named")]
    return (f"speeds estimated with the car on the tracks as drawn (SPEC §13): {speeds} m/s; the largest "
            f"{100 * off:.2g} % from its declared value" + (f"; beyond its prior: {', '.join(named)}" if named else ""))


def candidate_label(c: dict) -> str:
    """A ``model.candidates`` entry's name: its extensions (``base`` for none) and, where it records them, the
    tracks it was fitted on (a gross first fit's candidates: the same extension as drawn and as built)."""
    name = " + ".join(c.get("extensions") or ()) or "base"
    return f"{name} ({c['tracks']})" if c.get("tracks") else name


def candidate_estimates(res) -> dict:
    """A ``model.candidates`` entry's estimates of the fit ``res``: ``parameters`` (name -> value) and
    ``std_robust`` (each free parameter's), which the report's candidate table reads for every candidate."""
    return {"parameters": dict(res.parameters),
            "std_robust": {n: d.get("std_robust") for n, d in res.details.items() if not d.get("fixed")}}


def kept_candidate(model: dict) -> int | None:
    """The index in ``model.candidates`` of the candidate kept (its extensions ``model.extensions`` and, after a
    gross first fit, its tracks ``model.first_fit.tracks``); None when none is."""
    ext, tracks = list(model.get("extensions") or ()), (model.get("first_fit") or {}).get("tracks")
    hits = [i for i, c in enumerate(model.get("candidates") or ())
            if list(c.get("extensions") or ()) == ext and (tracks is None or c.get("tracks") in (None, tracks))]
    return hits[-1] if hits else None


def first_fit_sentence(first: dict) -> str:
    """What mended a first fit that missed grossly (result.json ``model.first_fit``), in one sentence: the runs'
    unexplained shares, the extension the data called for most and its screen, the tracks it mended it on. The
    terminal and the report both say it so."""
    gm = first["gross_misfit"]
    bad = sorted(((e, r) for r, e in gm["run_errors"].items() if e > gm["threshold"]), reverse=True)
    runs = ", ".join(f"{100 * e:.0f} % of run {r}'s signal" for e, r in bad) or "parameters at their bounds"
    s = next((s for s in first["screens"] if s["extensions"] == first["mended_by"]), None)
    score = f" (screened at {s['score']:.4g} against {s['threshold']:.3g})" if s else ""
    where = "with the tracks as built" if first["tracks"] == "as built" else "on the tracks as drawn"
    return (f"first fit: missed grossly ({runs} unexplained); the model choice went on because "
            f"{' + '.join(first['extension'])}, the extension the data called for most{score}, mends it {where}")


def plan_of(res, run_ids=()) -> Plan:
    """The plan of result ``res`` (its free ``names``, ``details``, ``starts``, ``tracks``, ``roads``, the runs as
    drawn whose speed it estimated);
    ``run_ids``: the dataset's runs, in order."""
    fixed = [n for n, d in (res.details or {}).items() if d.get("fixed")]
    fixed += [n for n in (res.known or {}) if n not in fixed]  # total_mass: a known that is no parameter
    blocks = [Block("car", "car", unknowns=list(res.names), fixed=fixed, runs=list(run_ids))]
    motion = {}
    for rec in (res.tracks or {}).values():
        if rec.get("rejected"):
            continue
        for rid, r in (rec.get("runs") or {}).items():
            if "motion" in r:
                motion[rid] = r["motion"]
    roads = res.roads or {}
    drawn = drawn_motions(res)  # a nonlinear car's runs as drawn, their speed estimated with it
    for rid in list(run_ids) or sorted(set(res.starts) | set(motion) | set(drawn)):
        unknowns = []
        if rid in motion:
            unknowns += ["speed", "start"]
        else:
            unknowns += ["speed"] * (rid in drawn) + ["start"] * (rid in res.starts)
        if rid in roads:
            continue
        if unknowns:
            blocks.append(Block(f"run {rid}", "run", unknowns=unknowns, runs=[rid]))
    for tid, rec in sorted((res.tracks or {}).items()):
        runs = [rid for rid, r in (rec.get("runs") or {}).items() if "amplitude_factor" in r]
        if rec.get("rejected") or not runs:
            continue
        method = rec.get("method", "")  # the as-built mode, in words (rideid.estimate.assess.motion.tracks_block)
        unknowns = (["road"] if "projected out" in method else
                    ["amplitude_factor", "unevenness"] if "unevenness" in method else ["amplitude_factor"])
        blocks.append(Block(f"track {tid}", "track", unknowns=unknowns, fixed=["drawing"], runs=runs))
    for rid, r in roads.items():  # the road, and the run's speed (the rear wheels' delay) where it was estimated
        blocks.append(Block(f"road {rid}", "road", unknowns=["road"] + (["speed"] if "motion" in r else []),
                            runs=[rid]))
    return Plan(blocks)


__all__ = ["VERDICTS", "Assessment", "AdequacyAssessment", "MaterialityAssessment", "SmallAngleAssessment",
           "SensorHintsAssessment", "LevelAssessment", "DrawingAssessment", "RoadsAssessment",
           "BoundsAssessment", "SetupAssessment", "ShapeAssessment", "ASSESSMENTS", "with_caveats",
           "assessments_of", "assessments_from_json", "Block", "Plan", "plan_of"]
