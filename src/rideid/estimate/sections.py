"""The result's sections as typed records: ``model``, ``adequacy``, ``polish``, ``uncertainty``, ``correlation``.

Each is a frozen dataclass whose fields are the keys result.json's section may hold (docs/formats.md "result.json"),
each field documented where it is declared. A section records which of its keys it holds, in the order they were
given (:attr:`Section.keys`): a key the fit did not write is absent, as it is from the file, and its attribute is
None. A section reads as the dict it is written as (``section["extensions"]``, ``section.get("note")``,
``"advice" in section``, ``dict(section)``), so that code and notebooks that read result.json read the result the
same way; ``section.extensions`` is the typed read.

The stages of the fit still build a section as a dict where they accrete it; :meth:`Section.of` turns it into the
record when it reaches an :class:`~rideid.estimate.result.IdentificationResult`, and refuses a key the record does
not declare (a section's keys are this module's, not whatever a stage wrote). A result.json read back keeps the
keys its section declares (a file of the same schema version has no others).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
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
        """A copy with ``changes`` (keys of the section) set: held from now on."""
        bad = [k for k in changes if k not in self.declared_keys()]
        if bad:
            raise TypeError(f"result section {self.name!r}: undeclared key(s) {', '.join(map(repr, bad))}")
        return replace(self, **changes, held=self.held + tuple(k for k in changes if k not in self.held))

    def to_dict(self) -> dict:
        """The section as result.json holds it: the keys held, in their order (values as they are)."""
        return {k: getattr(self, k) for k in self.held}

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


#: result attribute -> its section's record
SECTIONS = {cls.name: cls for cls in (ModelSection, AdequacySection, PolishSection, UncertaintySection,
                                      CorrelationSection)}

__all__ = ["Section", "ModelSection", "AdequacySection", "PolishSection", "UncertaintySection",
           "CorrelationSection", "SECTIONS"]
