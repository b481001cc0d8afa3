"""The identification result: one object, its JSON/CSV formats, ``save`` and ``load``.

Shaped like SciPy's :class:`scipy.optimize.OptimizeResult`: ``x`` (the free
parameters, in ``names`` order), ``std`` and ``covariance`` of ``x``,
``fun``, ``success``, ``message``, ``nit``, ``nfev``; besides them
``parameters`` (all names -> value, SPEC §5), ``details`` (per parameter:
value, unit, fixed, derived, std, bounds; std_robust where computed), the estimated
``starts`` of measured runs, ``history`` (a :class:`History` table, one row
per JADE generation) and what the report renders (``modal``, ``maps``,
``preprocessing``).

Files (docs/formats.md): ``result.json`` and ``history.csv`` in one folder.
This module is the only place that writes or reads them; the checks of a
result.json read back are :func:`rideid.data.schema.result.read_result_json`.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..data.schema.result import SCHEMA_VERSION, read_result_json
from ..errors import DataError
from .problem.sensitivity import SensitivityMaps
from .problem.bumps import format_bump_stops
from .assess.frequency import frequency_response as _frequency_response
from ..model.equations import CHANNELS
from .records import Assessment, Plan, assessments_from_json, assessments_of
from .sections import (SECTIONS, TABLES, AdequacySection, BumpStopsSection, CorrelationSection, DampersSection,
                       DataQualitySection, ModeRecord, ModelSection, ParameterRecord, PolishSection,
                       PreprocessingRecord, RoadRecord, Section, StartRecord, TrackRecord, UncertaintySection,
                       VehicleSection, FindingRecord, list_of, table_of)

COST_DEFINITION = ("equal-weight sum over runs of the per-channel energy-normalised squared error "
                   "(see rideid.cost)")


class History:
    """Per-generation records as a table.

    ``h[i]`` is row ``i`` as a dict, ``h["best_cost"]`` column ``best_cost``
    as an ndarray; iterating gives the rows; :meth:`to_pandas` a DataFrame.
    """

    def __init__(self, rows=None):
        self._rows = [dict(r) for r in (rows or [])]

    @property
    def columns(self) -> list[str]:
        return list(self._rows[0]) if self._rows else []

    def append(self, row: dict):
        self._rows.append(dict(row))

    def __len__(self):
        return len(self._rows)

    def __iter__(self):
        return iter(self._rows)

    def __bool__(self):
        return bool(self._rows)

    def __getitem__(self, key):
        if isinstance(key, str):
            if key not in self.columns:
                raise KeyError(f"history has no column {key!r}; columns: {', '.join(self.columns)}")
            return np.array([r[key] for r in self._rows], dtype=float)
        return self._rows[key]

    def __eq__(self, other):
        return isinstance(other, History) and self._rows == other._rows

    def __repr__(self):
        return f"History({len(self)} generations x {len(self.columns)} columns)"

    def to_pandas(self):
        """The table as a ``pandas.DataFrame`` (needs pandas)."""
        import pandas as pd
        return pd.DataFrame(self._rows)

    def write_csv(self, path):
        """``history.csv``: a header of column names, one line per generation."""
        if not self._rows:
            Path(path).write_text("")
            return
        keys = self.columns
        lines = [",".join(keys)]
        for h in self._rows:
            lines.append(",".join(f"{h[k]:.10g}" if isinstance(h[k], float) else str(h[k]) for k in keys))
        Path(path).write_text("\n".join(lines) + "\n")

    @classmethod
    def read_csv(cls, path) -> "History":
        path = Path(path)
        if not path.is_file() or path.stat().st_size == 0:
            return cls()
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        try:
            return cls([{k: float(v) for k, v in r.items()} for r in rows])
        except (TypeError, ValueError) as e:
            raise DataError(f"{path}: not a history table of numbers: {e}") from None


def jsonable(v):
    """NaN/inf -> None, NumPy scalars/arrays -> Python, recursively (strict JSON); a result section
    (:mod:`rideid.estimate.sections`) as its dict."""
    if isinstance(v, Section):
        v = v.to_dict()
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    if isinstance(v, np.generic):  # np.bool_ and other NumPy scalars
        return v.item()
    return v


def _maps_to_json(m: SensitivityMaps | None):
    if m is None:
        return None
    return {"params": m.params, "channels": m.channels, "runs": m.runs, "S": m.S, "S_bar": m.S_bar,
            "R": m.R, "M": m.M, "baseline": m.baseline}


def _maps_from_json(d, where):
    if d is None:
        return None
    try:  # None (JSON null) becomes NaN
        arr = {k: np.array(d[k], dtype=float) for k in ("S", "S_bar", "R", "M", "baseline")}
        return SensitivityMaps(list(d["params"]), list(d["channels"]), list(d["runs"]), **arr)
    except (KeyError, TypeError, ValueError) as e:
        raise DataError(f"{where}: sensitivity: malformed ({e})") from None


@dataclass(repr=False, frozen=True)
class IdentificationResult:
    """What :func:`rideid.identify` returns (see the module docstring).

    Frozen: built once by the fit; a changed result is a new one
    (``dataclasses.replace``), as the model choice builds its own.

    Attributes
    ----------
    x : ndarray, shape (d,)
        The free parameters, in ``names`` order (SI units).
    names : list of str
        The free parameter names.
    std, covariance : ndarray, shape (d,), (d, d)
        Standard errors and covariance of ``x`` from the polish's Jacobian
        (white residuals assumed: an optimistic lower bound when residuals
        are correlated); NaN without the polish.
    fun : float
        Equal-weight cost at ``x`` (also ``cost``).
    success, message, stop
        Whether the result is usable, why the search stopped, and which
        criterion fired (``"generations"``, ``"spread"``, ``"callback"``).
    nit, nfev : int
        JADE generations (also ``generations``) and cost evaluations
        (also ``evaluations``).
    parameters : dict
        Every parameter name -> value (fixed and derived ones included).
    details : dict of ParameterRecord
        Name -> ``value, unit, fixed, derived, std, lower, upper`` (and
        ``std_robust``, SPEC §6, where the robust standard error is computed; ``std_total``, SPEC §12).
    starts : dict of StartRecord
        Run id -> ``value, std, source, ...``: the start of each
        measured run with an estimated start, as the identification settled it.
    roads, tracks, preprocessing, modal : dict of RoadRecord, TrackRecord, PreprocessingRecord, ModeRecord
        The tables keyed by run, track or mode; each entry a typed record (:mod:`rideid.estimate.sections`) read
        as the dict result.json holds.
    history : History
    model, adequacy, polish, uncertainty, correlation, dampers, bump_stops, data_quality, vehicle : Section or None
        result.json's sections as typed records (:mod:`rideid.estimate.sections`: each field declared and
        documented, read as the mapping result.json holds): which model was fitted, the residual verdict, the
        least-squares polish, the uncertainty budget (SPEC §12), the estimates' correlation, the damper curves and
        bump stops (SPEC §8), the data's quality, the vehicle's geometry. A dict given for one becomes its record;
        a key it does not declare is a TypeError.
    plan, settings, assessments
        SPEC §13: the problem's blocks and their unknowns (:class:`~rideid.estimate.records.Plan`), every tuning
        value in force during the fit (:mod:`rideid.settings`), one typed record per assessment
        (:mod:`rideid.estimate.records`; ``verdict`` and ``reason`` each).
    """

    x: np.ndarray
    names: list
    std: np.ndarray
    covariance: np.ndarray
    fun: float
    success: bool
    message: str
    stop: str
    nit: int
    nfev: int
    parameters: dict
    details: dict
    known: dict  #: the dataset's ``[known]`` values, name -> value (SI units)
    wall_time_s: float  #: how long the identification took, s (wall clock)
    seed: int | None  #: the integer seed; None when a ``numpy.random.Generator`` was given
    track_weights: dict  #: run id -> the run's final weight in the cost; empty when they weigh equally
    weights_mode: str  #: ``"adaptive"`` or ``"fixed"`` run weights in the search; ``"equal"`` in the any-road fit
    polish: PolishSection | None  #: the least-squares polish (docs/formats.md ``polish``); None without it
    history: History = field(default_factory=History)
    starts: dict = field(default_factory=dict)
    preprocessing: dict = field(default_factory=dict)  #: per run, how its data were read, resampled and filtered
    modal: dict | None = None  #: mode -> frequency (Hz), damping ratio (:func:`rideid.model.equations.modal_summary`)
    dataset: str = ""  #: the dataset's folder (:attr:`rideid.Dataset.path`)
    maps: SensitivityMaps | None = None  #: the three sensitivity maps (result.json ``sensitivity``); None: not computed
    rng_state: dict | None = None  #: the generator's starting state (``bit_generator.state``), to repeat the search
    model: ModelSection | None = None
    adequacy: AdequacySection | None = None
    #: correlation matrix of the estimates (robust covariance): ``names``, ``matrix``, ``basis``
    correlation: CorrelationSection | None = None
    #: the identified car's channels per run on the final data (in memory only, for the report)
    response: dict | None = None
    #: with damper curves: run id -> (front, rear) suspension velocities of the identified car (in memory
    #: only, the report's histograms; rideid.estimate.assess.responses)
    velocities: dict | None = None
    #: findings of the data checks, the bound check and the motion check (rideid.data.checks), as typed records
    #: (:class:`rideid.estimate.sections.FindingRecord`)
    checks: list = field(default_factory=list)
    #: SPEC §8 damper curves when the model has them: {"velocity", "front": {"force", "std", "std_robust",
    #: "excited", ...}, "rear": {...}} (rideid.estimate.problem.dampers.dampers_block); None otherwise
    dampers: DampersSection | None = None
    #: SPEC §8 bump stops when the model has them: per axle {"reached", "clearance", "rate", "std",
    #: "std_robust", ...} (rideid.estimate.problem.bumps.bump_block); None otherwise
    bump_stops: BumpStopsSection | None = None
    #: SPEC §9 runs on unknown roads: run id -> {"file", "iso8608_class", "gd_n0", ...}; None without such runs
    roads: dict | None = None
    #: the estimated roads (in memory; written as road/<run>.csv): run id -> (x (n,), z (n, 2) left, right)
    road_profiles: dict | None = field(default=None, repr=False)
    #: SPEC §11 tracks as built: track id -> what was learnt about it ("amplitude_factor", "unevenness_rms_m",
    #: per run, ...; rideid.estimate.problem.asbuilt); None when every track was taken as drawn
    tracks: dict | None = None
    #: the dataset's ``[vehicle]`` table (m: wheelbase, tracks, tire_radius, cg_height when given), so that the
    #: identified car can leave without its dataset (rideid export, SPEC §10); None in results written before
    vehicle: VehicleSection | None = None
    #: SPEC §12: what was declared uncertain and how it was propagated: {"declared", "anchor", "anchor_exact",
    #: "method", "not_propagated", "notes"} (rideid.estimate.fit.budget.with_budget); None in results written before
    uncertainty: UncertaintySection | None = None
    #: per channel over the runs: clipped share, gaps bridged, noise level, sensor chain
    #: (:func:`rideid.data.quality.data_quality`); None in results written before
    data_quality: DataQualitySection | None = None
    # -- SPEC §13: the typed records (rideid.estimate.records), built at the end of rideid.identify
    #: the problem's blocks and their unknowns (the single-model fit's: the problem built up front,
    #: rideid.estimate.problem.build.Problem.plan; rideid.identify's: read from the result it returns, with the
    #: tracks and roads); None where the result was built by neither
    plan: Plan | None = None
    #: every tuning value in force during the fit, name -> value (:mod:`rideid.settings`); None in results
    #: written before schema version 2
    settings: dict | None = None
    #: one record per assessment kind (:data:`rideid.estimate.records.ASSESSMENTS`), each with ``verdict`` and
    #: ``reason``; read from the old keys for results written before schema version 2
    assessments: list[Assessment] = field(default_factory=list)

    def __post_init__(self):
        """The sections and the tables' entries given as dicts become their typed records
        (:mod:`rideid.estimate.sections`); a key a record does not declare is a TypeError."""
        for attr, cls in SECTIONS.items():
            object.__setattr__(self, attr, cls.of(getattr(self, attr)))
        for attr, cls in TABLES.items():
            object.__setattr__(self, attr, table_of(cls, getattr(self, attr)))
        object.__setattr__(self, "checks", list_of(FindingRecord, self.checks))

    # SciPy/SPEC §4 names for the same numbers
    @property
    def cost(self) -> float:
        return self.fun

    @property
    def generations(self) -> int:
        return self.nit

    @property
    def evaluations(self) -> int:
        return self.nfev

    def __repr__(self):
        """Short: the search's outcome, the model and its adequacy verdict, each parameter ± ``std_total``
        (SPEC §12: ``std_robust`` with every declared uncertainty; ``std_robust`` in results without it).

        ``std`` assumes white residuals (``details`` has every standard error and each ``budget``).
        """
        ext = (self.model or {}).get("extensions")
        model = "" if ext is None else f" model={' + '.join(ext) or 'base'!r},"
        adequate = (self.adequacy or {}).get("adequate")
        lines = [f"IdentificationResult(success={self.success}, stop={self.stop!r}, fun={self.fun:.4g}, "
                 f"nit={self.nit}, nfev={self.nfev},", f" {model} adequate={adequate},"]
        for n, d in self.details.items():
            if n.startswith("F_") and self.dampers:
                continue  # the curves' table below
            total = "std_total" in d
            std = d.get("std_total") if total else d.get("std_robust")
            note = " (known)" if d.get("fixed") else (" (derived)" if d.get("derived") else "")
            if d.get("reached") is False and not d.get("fixed"):
                note = " (not reached — not a number to trust)"
            err = f" ± {std:.3g} ({'total' if total else 'robust'})" if std not in (None, 0.0) else ""
            lines.append(f"  {n}={d['value']:.6g}{err} {d['unit']}{note}")
        for note in (self.uncertainty or {}).get("notes", []):  # the first clause; the whole in .uncertainty
            lines.append(f"  {note.split(':')[0]} (result.uncertainty['notes'])")
        if self.dampers:  # one line: the table is format_dampers(result.dampers), the forces to_frame()
            v = [x for x in self.dampers["velocity"] if x > 0]
            lines.append(f"  damper curves: {len(self.dampers['velocity'])} knots per axle up to "
                         f"{max(v, default=0):g} m/s (forces: result.to_frame(), result.dampers)")
        if self.bump_stops:
            lines += ["  " + ln for ln in format_bump_stops(self.bump_stops).splitlines()]
        if adequate is False:
            lines.append("  not adequate: the residuals carry structure the model misses (adequacy)")
        return "\n".join(lines) + ")"

    # -- a notebook's view ----------------------------------------------------
    def to_frame(self):
        """Every parameter as a ``pandas.DataFrame`` (needs pandas), indexed by ``parameter``.

        Columns ``value``, ``unit``, ``std_total`` (SPEC §12: ``std_robust`` with every declared uncertainty),
        ``std``, ``std_robust`` (NaN where none was computed), ``fixed``
        (a known value), ``derived`` (computed from the others, e.g. ``m_s`` from ``total_mass``).
        With damper curves the knot forces ``F_f1 ..`` are rows too (N).
        """
        import pandas as pd
        rows = [{"parameter": n, "value": float(d["value"]), "unit": d.get("unit", ""),
                 "std_total": np.nan if d.get("std_total", d.get("std_robust")) is None
                 else float(d.get("std_total", d.get("std_robust"))),
                 "std": np.nan if d.get("std") is None else float(d["std"]),
                 "std_robust": np.nan if d.get("std_robust") is None else float(d["std_robust"]),
                 "fixed": bool(d.get("fixed", False)), "derived": bool(d.get("derived", False))}
                for n, d in self.details.items()]
        return pd.DataFrame(rows).set_index("parameter")

    def start_values(self) -> dict[str, float]:
        """Run id -> start (file time, s) of every run the identification settled,
        from ``starts`` (results written before it existed: from ``preprocessing``)."""
        out = {rid: rec["start"]["value"] for rid, rec in self.preprocessing.items()
               if isinstance(rec, Mapping) and isinstance(rec.get("start"), Mapping)
               and rec["start"].get("value") is not None}
        out.update({rid: st["value"] for rid, st in self.starts.items()})
        return out

    def speed_values(self) -> dict[str, float]:
        """Run id -> the speed (m/s) the identification estimated with the car for a run on a track as drawn
        (``preprocessing.<run>.motion`` naming its ``track``: a car with damper curves or bump stops, SPEC §13)."""
        out = {}
        for rid, rec in self.preprocessing.items():
            m = rec.get("motion") if isinstance(rec, Mapping) else None
            if isinstance(m, Mapping) and m.get("track") and m.get("speed_m_s") is not None:
                out[rid] = float(m["speed_m_s"])
        return out

    def fitted_data(self, ds):
        """``ds`` with its runs read as the identification last read them: at the speeds it estimated
        (:meth:`speed_values`) and the starts it settled (``starts``)."""
        ds = ds.with_speeds({rid: v for rid, v in self.speed_values().items() if rid in {r.id for r in ds.runs}})
        return ds.with_starts({rid: st for rid, st in (self.starts or {}).items() if rid in ds.measured})

    def start_records(self) -> dict[str, dict]:
        """Run id -> ``{"value": start, "model_time": [first, last]}``: :meth:`start_values` with the span of
        model time of the samples the identification fitted (``preprocessing``), for
        :func:`rideid.load_dataset` to read the runs as the identification read them (no ``model_time``
        where the record has none)."""
        out = {}
        for rid, s in self.start_values().items():
            rec = self.preprocessing.get(rid)
            span = rec.get("model_time") if isinstance(rec, Mapping) else None
            out[rid] = {"value": s, **({"model_time": list(span)} if span is not None else {})}
        return out

    def assessment(self, kind: str) -> Assessment:
        """The typed record of one assessment (SPEC §13): ``kind`` one of ``adequacy``, ``materiality``,
        ``small_angles``, ``sensor_hints``, ``level``, ``drawing``, ``roads``, ``bounds``; the record as kept, or
        built from the result's blocks (a result read from schema version 1)."""
        found = [a for a in (self.assessments or assessments_of(self)) if a.kind == kind]
        if not found:
            kinds = sorted({a.kind for a in assessments_of(self)})
            raise KeyError(f"no assessment {kind!r} (one of {', '.join(kinds)})")
        return found[0]

    def frequency_response(self, freq=None):
        """The identified car's frequency responses with the std of ``|H|`` from ``std_total`` (SPEC §13).

        Parameters
        ----------
        freq : array_like, optional
            Hz (default: 240 log-spaced from 0.2 to 30 Hz).

        Returns
        -------
        FrequencyResponse
            ``freq``, ``inputs`` (``r_fl .. r_rr``), ``outputs`` (the ten channels, ``heave``, ``pitch``,
            ``roll``), ``H`` (complex, n_freq x n_out x n_in, per metre of road), ``std_abs``
            (:func:`rideid.estimate.assess.frequency.frequency_response`; docs/frequency-response.md).
        """
        return _frequency_response(self, freq)

    # -- formats -------------------------------------------------------------
    def to_dict(self) -> dict:
        """``result.json`` as a dict (docs/formats.md; schema version :data:`SCHEMA_VERSION`)."""
        return jsonable({
            "schema_version": SCHEMA_VERSION,
            "parameters": self.details,
            "known": self.known,
            "cost": self.fun,
            "cost_definition": COST_DEFINITION,
            "generations": self.nit,
            "evaluations": self.nfev,
            "wall_time_s": self.wall_time_s,
            "seed": self.seed,
            "rng_state": self.rng_state,
            "track_weights": self.track_weights,
            "weights": self.weights_mode,
            "stop": self.stop,
            "success": self.success,
            "message": self.message,
            "names": list(self.names),
            "covariance": self.covariance,
            "polish": self.polish,
            "starts": self.starts,
            "modal": self.modal,
            "model": self.model,
            "adequacy": self.adequacy,
            "correlation": self.correlation,
            "preprocessing": self.preprocessing,
            "checks": self.checks,
            **({"dampers": self.dampers} if self.dampers else {}),
            **({"bump_stops": self.bump_stops} if self.bump_stops else {}),
            **({"roads": self.roads} if self.roads else {}),
            **({"tracks": self.tracks} if self.tracks else {}),
            **({"vehicle": self.vehicle} if self.vehicle else {}),
            **({"uncertainty": self.uncertainty} if self.uncertainty else {}),
            **({"data_quality": self.data_quality} if self.data_quality else {}),
            "dataset": str(Path(self.dataset).resolve()) if self.dataset else "",
            "sensitivity": _maps_to_json(self.maps),
            "history_file": "history.csv",
            # SPEC §13 (schema version 2): the records typed; the keys above stay, with their meaning
            "plan": None if self.plan is None else self.plan.to_dict(),
            "settings": self.settings,
            "assessments": [a.to_dict() for a in (self.assessments or assessments_of(self))],
        })

    def save(self, out_dir):
        """Write ``result.json`` and ``history.csv`` into ``out_dir`` (created if it does not exist)."""
        out_dir = Path(out_dir)
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise DataError(f"{out_dir}: cannot create the result folder: {e}") from None
        (out_dir / "result.json").write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")
        self.history.write_csv(out_dir / "history.csv")
        for rid, (x, z) in (self.road_profiles or {}).items():
            (out_dir / "road").mkdir(exist_ok=True)
            np.savetxt(out_dir / "road" / f"{rid}.csv", np.column_stack([x, z]), delimiter=",", fmt="%.9g",
                       header="x,z_left,z_right", comments="")
        # the fitted response of the runs whose road was estimated (unknown roads, tracks as built): the car
        # driven over that road cannot be simulated again from result.json alone, and `rideid report` draws it
        for rid in self.estimated_road_runs():
            Y = (self.response or {}).get(rid)
            if Y is None:
                continue
            (out_dir / "road").mkdir(exist_ok=True)
            np.savetxt(out_dir / "road" / f"{rid}.response.csv", np.asarray(Y, dtype=float), delimiter=",",
                       fmt="%.9g", header=",".join(CHANNELS), comments="")

    def estimated_road_runs(self) -> list:
        """The runs fitted at an estimated road: on unknown roads (``roads``) and on tracks as built (``tracks``,
        not rejected)."""
        ids = list(self.roads or {})
        for rec in (self.tracks or {}).values():
            if not rec.get("rejected"):
                ids += [rid for rid in (rec.get("runs") or {}) if rid not in ids]
        return ids


def load(path) -> IdentificationResult:
    """Read an identification folder (or its ``result.json``) back into a result.

    Results written before ``names``/``covariance`` were stored take them
    from ``polish`` (or from the parameters that are neither fixed nor derived).
    """
    doc = read_result_json(path)
    rpath = Path(path) if Path(path).suffix == ".json" else Path(path) / "result.json"
    details = table_of(ParameterRecord, doc["parameters"], strict=False)
    polish = doc.get("polish")
    names = doc.get("names") or (polish or {}).get("names") or [
        n for n, d in details.items() if not d.get("fixed") and not d.get("derived")]
    cov = doc.get("covariance", (polish or {}).get("covariance"))
    d = len(names)
    cov = np.full((d, d), np.nan) if cov is None else np.array(cov, dtype=float)  # null -> NaN
    std = np.array([details[n].get("std") for n in names], dtype=float)
    stop = doc.get("stop", "")
    res = IdentificationResult(
        x=np.array([details[n]["value"] for n in names], dtype=float), names=list(names), std=std, covariance=cov,
        fun=float(doc.get("cost", np.nan)), success=bool(doc.get("success", True)),
        message=doc.get("message", stop), stop=stop, nit=int(doc.get("generations", 0)),
        nfev=int(doc.get("evaluations", 0)), parameters={n: float(v["value"]) for n, v in details.items()},
        details=details, known=dict(doc.get("known") or {}), wall_time_s=float(doc.get("wall_time_s", 0.0)),
        seed=doc.get("seed"), track_weights=dict(doc.get("track_weights") or {}),
        weights_mode=doc.get("weights", "adaptive"),
        history=History.read_csv(rpath.parent / doc.get("history_file", "history.csv")),
        starts=table_of(StartRecord, doc.get("starts") or {}, strict=False),
        preprocessing=table_of(PreprocessingRecord, doc.get("preprocessing") or {}, strict=False),
        modal=table_of(ModeRecord, doc.get("modal"), strict=False), dataset=doc.get("dataset", ""),
        maps=_maps_from_json(doc.get("sensitivity"), rpath), rng_state=doc.get("rng_state"),
        checks=list_of(FindingRecord, doc.get("checks") or [], strict=False),
        roads=table_of(RoadRecord, doc.get("roads"), strict=False),
        road_profiles=_read_roads(doc.get("roads"), rpath.parent),
        tracks=table_of(TrackRecord, doc.get("tracks"), strict=False), response=_read_responses(doc, rpath.parent),
        # each section as written, the keys this version declares (a later one's file is refused by its version)
        **{attr: cls.of(doc.get(attr), strict=False) for attr, cls in SECTIONS.items()})
    # SPEC §13: the typed records as written, or (schema version 1) the assessments read from the old keys
    return replace(res, plan=Plan.from_dict(doc.get("plan")), settings=doc.get("settings"),
                   assessments=assessments_from_json(doc["assessments"]) if "assessments" in doc
                   else assessments_of(res))


def _read_responses(doc, folder):
    """The fitted responses written beside result.json for the runs at an estimated road
    (road/<run>.response.csv, :meth:`IdentificationResult.save`), those that are there; None without any."""
    ids = list(doc.get("roads") or {})
    for rec in (doc.get("tracks") or {}).values():
        if not rec.get("rejected"):
            ids += [rid for rid in (rec.get("runs") or {}) if rid not in ids]
    out = {}
    for rid in ids:
        f = folder / "road" / f"{rid}.response.csv"
        if f.is_file():
            out[rid] = np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2)
    return out or None


def _read_roads(roads, folder):
    """The estimated roads written beside result.json (road/<run>.csv), those that are there."""
    out = {}
    for rid, rec in (roads or {}).items():
        f = folder / rec.get("file", f"road/{rid}.csv")
        if f.is_file():
            a = np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2)
            out[rid] = (a[:, 0], a[:, 1:3])
    return out or None


__all__ = ["IdentificationResult", "History", "load", "read_result_json", "SCHEMA_VERSION"]
