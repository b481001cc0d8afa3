"""``rideid.plan``: which candidate runs to drive, and the precision they buy (SPEC §7).

See ``docs/planning.md`` for the method, the choices and the validation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..data.scenario import load_scenario
from ..data.schema import Scenario
from ..errors import ArgumentError, DataError
from ..estimate.fit.budget import LENGTHS
from ..estimate.problem.cost import ParameterSpace
from ..model.batch import single_threaded_blas
from ..model.nonlinear import PinnedSimulator
from ..model.simulator import Simulator
from ..estimate.problem.sensitivity import compute_maps
from ..model.equations import CHANNELS
from ..model.nonlinear import curve_names
from ..model.params import (ALL_NAMES, EXT_NAMES, GROUPS, NAMES, POWERTRAIN_NAMES, SCALE_FREE, SIGNED)
from ..report.plan_files import pct as _pct, plan_markdown, write_plan
from . import powertrain as pt_info
from . import roadinfo
from .colour import load_noise_psd
from .curves import (AXLES, CURVES, Excitation, mask_information, nominal_forces, not_excited_names, plan_knots,
                     run_counts)
from .fisher import (STEP, NoiseModel, Precision, RunInformation, messages, precision, run_information, simulator,
                     subset_precision)
from .select import Selector

CRITERIA = ("D", "A", "target")
#: default noise when neither a fraction nor a density is given: the demo's 1 %
DEFAULT_NOISE = 0.01
#: without a budget, select the fewest runs whose CRLB is within this factor of all runs' on every parameter
DEFAULT_WITHIN = 1.5
#: robust plans: free parameters without a scenario [bounds] entry vary by +-this fraction of nominal
DEFAULT_ROBUST_SPREAD = 0.2


@dataclass
class PlanResult:
    """What :func:`plan` returns; :meth:`save` writes plan.json, tables and the figure."""

    scenario: str
    names: list
    nominal: dict
    derived: str | None
    known: dict
    extensions: list
    noise: dict
    criterion: str
    budget: dict
    targets: dict
    robust: dict
    sensitivity: dict
    candidates: list
    all_runs: Precision
    selected_runs: list
    selected: Precision
    path: list                      # [(run id, Precision)] along the greedy path over all candidates
    messages_all: list
    messages_selected: list
    notes: list = field(default_factory=list)
    derived_grad: np.ndarray | None = None
    robust_worst: np.ndarray | None = None   # (d,) worst relative spread over the sampled cars, selected runs
    comparison: dict = field(default_factory=dict)
    noise_text: str = ""
    dampers: dict | None = None    # with damper curves: knots, excitation, CRLB per knot
    #: SPEC §12: the scenario's declared uncertainties (key -> std) and the anchor's relative std added to every
    #: scale parameter's predicted std in quadrature (:func:`declared_relative`)
    declared: dict = field(default_factory=dict)
    #: SPEC §11: with a free powertrain, where its information comes from (:func:`rideid.design.powertrain.
    #: powertrain_block`: the whole car's modes, per run the shares, leave-one-out losses, input frequency)
    powertrain: dict | None = None

    def declared_relative(self, name: str) -> float:
        """The declared inputs' relative contribution to parameter ``name`` (0 when none is declared): the
        scale anchor's relative std for every mass, inertia, stiffness and damping (SPEC §1: they scale with
        it), 0 for the lengths, frequencies and damping ratios (``a``, the powertrain's ``x_p``, ``f_pb``,
        ``zeta_pb``, ``f_pp``, ``zeta_pp``); other declared inputs are not predicted (plan.json says so)."""
        rel = (self.declared.get("anchor") or {}).get("relative", 0.0)
        return 0.0 if name in LENGTHS or name in SCALE_FREE else rel

    # -- dictionaries ---------------------------------------------------------
    def _crlb(self, p: Precision, which="crlb") -> dict:
        rel = p.rel_crlb if which == "crlb" else p.rel_identify
        out = {}
        for j, n in enumerate(self.names):
            ok = np.isfinite(rel[j])
            out[n] = {"std": float(rel[j] * abs(p.x0[j])) if ok else None,
                      "relative": float(rel[j]) if ok else None}
            if which != "crlb" and self.declared.get("anchor"):
                tot = float(np.hypot(rel[j], self.declared_relative(n))) if ok else None
                out[n]["relative_total"] = tot
                out[n]["std_total"] = None if tot is None else tot * abs(float(p.x0[j]))
            if which == "crlb":
                out[n]["identifiable"] = bool(ok)
        return out

    def _derived(self, p: Precision) -> dict:
        if self.derived is None:
            return {}
        if not p.identifiable[self.derived_grad != 0].all():
            return {self.derived: {"std": None, "relative": None, "std_identify": None}}
        a, b = p.derived_std(self.derived_grad)
        v = self.nominal[self.derived]
        return {self.derived: {"std": a, "relative": a / v, "std_identify": b, "relative_identify": b / v,
                               "from": f"[known] {'total_mass' if 'total_mass' in self.known else ''}".strip()}}

    def _block(self, p: Precision, msgs) -> dict:
        C = p.correlation()
        return {"crlb": self._crlb(p), "identify_std": self._crlb(p, "identify"), "derived": self._derived(p),
                "rank": p.rank, "parameters": len(self.names),
                "condition": p.condition if np.isfinite(p.condition) else None,
                "correlation": {"names": self.names,
                                "matrix": [[None if not np.isfinite(v) else round(float(v), 6) for v in row]
                                           for row in C]},
                "messages": list(msgs)}

    def to_dict(self) -> dict:
        cand = {c["id"]: c for c in self.candidates}
        sel = self._block(self.selected, self.messages_selected)
        sel = {"runs": list(self.selected_runs), **sel,
               "runs_count": len(self.selected_runs),
               "track_time_s": float(sum(cand[r]["time_cost_s"] for r in self.selected_runs))}
        if self.robust_worst is not None:
            sel["robust_worst_relative"] = {n: (float(v) if np.isfinite(v) else None)
                                            for n, v in zip(self.names, self.robust_worst)}
        if self.targets:
            sel["targets"] = {n: {"target": t,
                                  "expected_identify": (float(self.selected.rel_identify[self.names.index(n)])
                                                        if self.selected.identifiable[self.names.index(n)]
                                                        else None)}
                              for n, t in self.targets.items()}
            for _n, v in sel["targets"].items():
                v["met"] = v["expected_identify"] is not None and v["expected_identify"] <= v["target"] * (1 + 1e-9)
        return {
            "scenario": self.scenario,
            "free": self.names,
            "nominal": self.nominal,
            "known": self.known,
            "derived": self.derived,
            "model": {"extensions": self.extensions},
            "noise": self.noise,
            "criterion": self.criterion,
            "budget": self.budget,
            "targets": self.targets,
            "robust": self.robust,
            "sensitivities": self.sensitivity,
            "declared": self.declared,
            "precision_definitions": {
                "crlb": "Cramér-Rao lower bound (J^T Sigma^-1 J)^-1 at the nominal car for the Gaussian noise "
                        "of the noise model (coloured noise: the whitened problem, the best any unbiased "
                        "estimator can do); relative = std / nominal value",
                "identify_std": "expected spread of rideid identify's estimate: its equal-run-weight, "
                                "energy-normalised least squares (rideid.cost, not whitened) has the sandwich "
                                "covariance A^-1 B A^-1 with B = sum W^2 J^T Sigma J (Sigma the noise covariance, "
                                "coloured or white), never below the CRLB; a Monte Carlo of identify should match this",
            },
            "candidates": self.candidates,
            "all_runs": self._block(self.all_runs, self.messages_all),
            "selected": sel,
            "greedy_path": [{"n_runs": k + 1, "added": rid,
                             "relative": {n: (float(v) if np.isfinite(v) else None)
                                          for n, v in zip(self.names, p.rel_crlb)},
                             "relative_identify": {n: (float(v) if np.isfinite(v) else None)
                                                   for n, v in zip(self.names, p.rel_identify)}}
                            for k, (rid, p) in enumerate(self.path)],
            "sensitivity_map_comparison": self.comparison,
            "notes": self.notes,
        } | ({"dampers": self.dampers} if self.dampers is not None else {}) | (
            {"powertrain": self.powertrain} if self.powertrain is not None else {})

    def label(self, rid: str) -> str:
        """A run id, with ``(road B)`` for a run on an unknown road of ISO 8608 class B."""
        c = next((c for c in self.candidates if c["id"] == rid), None)
        return f"{rid} (road {c['road']['road_class']})" if c is not None and c.get("road") else rid

    # -- output files ---------------------------------------------------------
    def summary(self) -> str:
        """Terminal text: the chosen runs and the precision they buy."""
        cand = {c["id"]: c for c in self.candidates}
        t = sum(cand[r]["time_cost_s"] for r in self.selected_runs)
        lines = [f"plan ({self.criterion}-optimal"
                 f"{', robust over ' + str(self.robust['cars']) + ' cars' if self.robust['cars'] > 1 else ''}): "
                 f"drive {len(self.selected_runs)} of {len(self.candidates)} runs, {t:.0f} s of track time: "
                 + ", ".join(self.label(r) for r in self.selected_runs),
                 f"noise: {self.noise_text}",
                 f"{'parameter':10s} {'nominal':>12s} {'selected ±':>12s} {'(identify)':>10s} {'all runs ±':>10s}"]
        off_sel = set(self.dampers["selected"]["not_excited"]) if self.dampers else set()
        off_all = set(self.dampers["all_runs"]["not_excited"]) if self.dampers else set()

        def cell(v, n, off, width):
            return f"{'not excited' if n in off else _pct(v):>{width}s}"

        anchor = self.declared.get("anchor")
        if anchor:
            lines[-1] += f" {'+ declared':>10s}"
        for j, n in enumerate(self.names):
            total = np.hypot(self.selected.rel_identify[j], self.declared_relative(n))
            lines.append(f"{n:10s} {self.nominal[n]:12.6g} {cell(self.selected.rel_crlb[j], n, off_sel, 12)} "
                         f"{cell(self.selected.rel_identify[j], n, off_sel, 10)} "
                         f"{cell(self.all_runs.rel_crlb[j], n, off_all, 10)}"
                         + (f" {cell(total, n, off_sel, 10)}" if anchor else ""))
        if anchor:
            lines.append(f"+ declared: identify's expected spread with {anchor['key']}'s declared std "
                         f"({100 * anchor['relative']:.3g} %) added in quadrature to every scale parameter")
        if self.declared.get("not_predicted"):
            lines.append("declared but not in the prediction: " + ", ".join(self.declared["not_predicted"]))
        if self.dampers:
            for c in self.candidates:
                ne = c["dampers"]["not_excited"]
                lines.append(f"damper knots run {c['id']}: "
                             + (f"not excited {', '.join(ne)}" if ne else "all excited"))
        lines += pt_info.summary_lines(self.powertrain, self.selected_runs)
        lines += self.messages_selected + self.notes
        return "\n".join(lines)

    def markdown(self) -> str:
        """plan.md: the candidates, the precision per parameter, identifiability, the greedy path
        (:func:`rideid.report.plan_files.plan_markdown`)."""
        return plan_markdown(self)

    def save(self, out_dir) -> Path:
        """Write plan.json, plan.md, crlb.csv, path.csv, correlation.csv and precision_path.png into ``out_dir``
        (:func:`rideid.report.plan_files.write_plan`)."""
        return write_plan(self, out_dir)


def parse_target(text: str) -> tuple[str, float]:
    """``"k_sr=0.5%"`` or ``"k_sr=0.005"`` -> ``("k_sr", 0.005)``."""
    if "=" not in text:
        raise ArgumentError(f"--target {text!r}: expected NAME=PRECISION, e.g. k_sr=0.5%")
    name, val = (s.strip() for s in text.split("=", 1))
    pct = val.endswith("%")
    try:
        v = float(val[:-1] if pct else val) / (100 if pct else 1)
    except ValueError:
        raise ArgumentError(f"--target {text!r}: {val!r} is not a number (e.g. 0.5% or 0.005)") from None
    if not (math.isfinite(v) and v > 0):
        raise ArgumentError(f"--target {text!r}: the precision must be positive")
    return name, v


@dataclass(frozen=True)
class PlanProblem:
    """What a plan is made for: the scenario's candidate runs, the free parameters and the nominal car.

    Attributes
    ----------
    sc : Scenario
    space : ParameterSpace
        The free parameters (``extensions`` free, damper-curve knots with curves).
    names : list of str
        ``space.names``.
    x0 : ndarray, shape (d,)
        Nominal value of each free parameter ([truth]; knot forces from the curves).
    P0 : ndarray, shape (n_param,)
        The nominal car's full parameter row.
    curves : bool
        Whether damper curves are planned (SPEC §8).
    knots_from : str or None
        Where the knot velocities come from (curves only).
    run_ids, road_ids : list of str
        Every candidate run; those on unknown roads (SPEC §9).
    """

    sc: Scenario
    space: ParameterSpace
    names: list
    x0: np.ndarray
    P0: np.ndarray
    curves: bool
    knots_from: str | None
    run_ids: list
    road_ids: list

    @property
    def knot_names(self) -> list:
        """The free damper-knot forces (empty without curves)."""
        return [n for n in self.names if n.startswith("F_")] if self.curves else []

    @classmethod
    def build(cls, scenario, extensions=None) -> "PlanProblem":
        """Load ``scenario`` (path or :class:`Scenario`) and check it describes a nominal car to plan for."""
        sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        road_ids = [r.id for r in sc.runs if not r.road_known]
        if sc.truth is None:
            raise DataError(f"{sc.path}: a plan needs a scenario with a [truth] table (the nominal car)")
        extensions = _extensions(sc, extensions)
        curves = CURVES in extensions
        if curves and road_ids:
            raise ArgumentError(f"runs on unknown roads ({', '.join(road_ids)}) cannot be planned with damper "
                                "curves: the road fit projects the road out of a linear car (docs/any-road.md); plan "
                                "the curves on known tracks, or the linear model with --model")
        knots, knots_from = plan_knots(sc) if curves else (None, None)
        space = ParameterSpace(sc.known, sc.geometry, sc.bounds, extensions=extensions,
                               damper_knots=knots)  # refuses a missing anchor
        names = list(space.names)
        x0 = _nominal_free(sc, space, names, curves)
        P0 = space.full(x0[None])[0]
        _check_truth(sc, space, P0)
        run_ids = [r.id for r in sc.runs]
        if not run_ids:
            raise DataError(f"{sc.path}: no [[runs]]: nothing to plan")
        return cls(sc, space, names, x0, P0, curves, knots_from, run_ids, road_ids)


def _extensions(sc, extensions) -> tuple:
    """The groups to plan: ``extensions``, else the scenario's [model], else the groups the nominal car has;
    damper curves added when the car has real dampers."""
    if extensions is None:
        extensions = (sc.extensions if sc.extensions is not None else
                      tuple(g for g, ns in GROUPS.items() if any(sc.truth.get(n, 0.0) > 0 for n in ns)))
    extensions = tuple(extensions)
    if sc.dampers is not None and CURVES not in extensions:  # the car has real dampers: plan their curves
        extensions += (CURVES,)
    return extensions


def _nominal_free(sc, space, names, curves) -> np.ndarray:
    """(d,) nominal value of each free parameter; refuses one without a positive [truth] value."""
    knot_names = [n for n in names if n.startswith("F_")] if curves else []
    x0 = np.array([float(sc.truth.get(n, 0.0)) for n in names])
    if curves:
        Fk = nominal_forces(sc, space.layout)
        all_knots = curve_names(space.layout.n_knots)
        x0[[names.index(n) for n in knot_names]] = [Fk[all_knots.index(n)] for n in knot_names]
    zero = [n for n, v in zip(names, x0) if n in SIGNED and v == 0]
    if zero:  # a signed length (the powertrain's position, behind the CG negative) may be negative, not 0
        raise DataError(f"{sc.path}: [truth] {', '.join(zero)} = 0: precision is planned relative to the nominal "
                        f"value, which must not be 0; give the position to the nearest centimetre (e.g. 0.01, "
                        "behind the CG negative)")
    bad = [n for n, v in zip(names, x0) if (v == 0 if n in knot_names else v <= 0) and n not in SIGNED]
    if bad:
        raise DataError(f"{sc.path}: [truth] has no positive value for {', '.join(bad)}, a free parameter of the "
                        "model; precision is planned relative to the nominal value, so give one")
    return x0


@dataclass(frozen=True)
class PlanOptions:
    """How to plan, checked when built (:meth:`build`): noise, criterion, budget, targets, robustness.

    The fields are :func:`plan`'s keywords after checking; ``noise`` is the :class:`NoiseModel`,
    ``criterion`` never None, ``time_cost`` (s, shape (R,)) each candidate run's duration plus ``overhead``.
    """

    noise: NoiseModel
    criterion: str
    targets: dict
    budget_runs: int | None
    budget_time: float | None
    overhead: float
    robust: int
    robust_spread: float
    seed: int
    within: float
    step: float
    time_cost: np.ndarray

    @property
    def budgeted(self) -> bool:
        """A budget or targets decide the selection (else the fewest runs ``within`` all runs' CRLB)."""
        return self.criterion == "target" or self.budget_runs is not None or self.budget_time is not None

    @classmethod
    def build(cls, pb: PlanProblem, *, noise=None, accel_density=0.0, gyro_density=0.0, bandwidth=None,
              noise_ar1=0.0, noise_psd=None, budget_runs=None, budget_time=None, overhead=0.0, criterion=None,
              targets=None, robust=1, robust_spread=DEFAULT_ROBUST_SPREAD, seed=0, within=DEFAULT_WITHIN,
              step=STEP) -> "PlanOptions":
        """:func:`plan`'s options checked against the problem ``pb``; :class:`ArgumentError` naming the option."""
        nm = _noise_model(pb.sc, noise, accel_density, gyro_density, bandwidth, noise_ar1, noise_psd)
        targets = dict(targets or {})
        if criterion is None:
            criterion = "target" if targets else "D"
        if criterion not in CRITERIA:
            raise ArgumentError(f"--criterion {criterion!r}: expected one of {', '.join(CRITERIA)}")
        _check_targets(pb, targets)
        if criterion == "target" and not targets:
            raise ArgumentError("--criterion target needs at least one --target NAME=PRECISION (e.g. k_sr=0.5%)")
        _check_budget(budget_runs, budget_time, overhead, robust, within)
        tcost = np.array([r.duration + overhead for r in pb.sc.runs])
        if budget_time is not None and tcost.min() > budget_time:
            j = int(np.argmin(tcost))
            raise ArgumentError(f"--budget-time {budget_time:g} s: no candidate run fits (the shortest, "
                                f"{pb.run_ids[j]}, takes {pb.sc.runs[j].duration:g} s + {overhead:g} s overhead)")
        return cls(nm, criterion, targets, budget_runs, budget_time, overhead, robust, robust_spread, seed, within,
                   step, tcost)


def _noise_model(sc, noise, accel_density, gyro_density, bandwidth, noise_ar1, noise_psd) -> NoiseModel:
    """The plan's :class:`NoiseModel` (SPEC ``--noise``, densities, AR(1) or a spectrum file)."""
    if isinstance(noise_psd, (str, Path)):
        noise_psd = load_noise_psd(noise_psd)
    if noise is None:
        noise = 0.0 if (accel_density or gyro_density or noise_psd is not None) else DEFAULT_NOISE
    nm = noise if isinstance(noise, NoiseModel) else NoiseModel(float(noise), float(accel_density),
                                                                  float(gyro_density), bandwidth,
                                                                  float(noise_ar1), noise_psd)
    if nm.psd is not None:
        for r in sc.runs:
            nm.psd.check_covers(r.fs, f"run {r.id} (fs {r.fs:g} Hz)")
    return nm


def _check_targets(pb: PlanProblem, targets: dict) -> None:
    """Targets name free parameters and ask for a positive relative precision."""
    for n, v in targets.items():
        if n not in pb.names:
            why = (f"{n} is {'derived from the anchor' if n == pb.space.derived else 'fixed in [known]'}"
                   if n in pb.sc.truth else f"unknown parameter {n!r}")
            raise ArgumentError(f"--target {n}: {why}; targets apply to the free parameters: {', '.join(pb.names)}")
        if not (np.isfinite(v) and v > 0):
            raise ArgumentError(f"--target {n}: the relative precision must be positive, got {v!r}")


def _check_budget(budget_runs, budget_time, overhead, robust, within) -> None:
    """The budget, overhead, robust and within options' ranges."""
    if budget_runs is not None and (int(budget_runs) != budget_runs or budget_runs < 1):
        raise ArgumentError(f"--budget-runs must be a positive integer, got {budget_runs!r}")
    if budget_time is not None and not (np.isfinite(budget_time) and budget_time > 0):
        raise ArgumentError(f"--budget-time must be a positive number of seconds, got {budget_time!r}")
    if not (np.isfinite(overhead) and overhead >= 0):
        raise ArgumentError(f"--overhead must be a non-negative number of seconds, got {overhead!r}")
    if not (isinstance(robust, int) and robust >= 1):
        raise ArgumentError(f"--robust must be a positive integer (number of cars), got {robust!r}")
    if not (np.isfinite(within) and within >= 1):
        raise ArgumentError(f"--within must be at least 1, got {within!r}")


@single_threaded_blas()  # many small matrices: a plan of two road runs 9.1 s with OpenBLAS on two threads, 5.1 s
def plan(scenario, *, noise=None, accel_density: float = 0.0, gyro_density: float = 0.0,
         bandwidth: float | None = None, noise_ar1: float = 0.0, noise_psd=None, budget_runs: int | None = None,
         budget_time: float | None = None,
         overhead: float = 0.0, criterion: str | None = None, targets: dict | None = None, robust: int = 1,
         robust_spread: float = DEFAULT_ROBUST_SPREAD, seed: int = 0, within: float = DEFAULT_WITHIN,
         step: float = STEP, extensions=None) -> PlanResult:
    """Plan a test: the precision of every candidate run, and the best subset under a budget.

    Parameters
    ----------
    scenario : path or Scenario
        A scenario (SPEC §3): ``[truth]`` is the nominal car, ``[[runs]]`` the
        candidate runs (``fs``, ``duration``), ``[known]`` the scale anchor. A
        run with ``road_class`` instead of a track is a drive on an unknown
        road (SPEC §9): its precision is predicted from the road fit on
        generated roads of the class (:mod:`rideid.design.roadinfo`).
    noise : float, optional
        SPEC ``--noise``: noise sd as a fraction of each channel's RMS, per run.
        Default 0.01 unless a density is given (then 0).
    accel_density, gyro_density : float
        Absolute sensor noise densities, (m/s²)/√Hz and (rad/s)/√Hz.
    bandwidth : float, optional
        Logger bandwidth for the densities, Hz (default each run's fs/2).
    noise_ar1 : float
        Coloured noise, AR(1) in time with this coefficient per sample and the
        same standard deviation (as ``simulate --noise-ar1``); 0: white.
    noise_psd : path or NoiseSpectrum, optional
        Coloured noise with a measured spectrum (CSV, ``docs/planning.md``).
        With ``noise`` or a density only its shape counts (scaled to their
        standard deviation per run and channel); alone it is absolute, and
        ``noise`` defaults to 0.
    budget_runs : int, optional
        At most this many runs.
    budget_time : float, optional
        At most this much track time, s: each run costs its duration plus ``overhead``.
    overhead : float
        Per-run overhead (turning, waiting, re-positioning), s.
    criterion : {"D", "A", "target"}, optional
        Default ``"target"`` when ``targets`` are given, else ``"D"``.
    targets : dict name -> relative std, optional
        E.g. ``{"k_sr": 0.005}``: reach ±0.5 % (identify's expected spread) at
        the lowest cost.
    robust : int
        Number of cars the criterion must hold for (1: the nominal car only;
        N > 1: the nominal car and N-1 cars sampled uniformly in the
        scenario's ``[bounds]``, or ±``robust_spread`` around nominal for
        parameters without bounds; the worst car counts).
    seed : int
        Seed of the ``numpy.random.Generator`` that samples the robust cars, and
        of the unknown-road candidates' generated roads.
    within : float
        Without a budget (D, A): the fewest runs whose CRLB is within this
        factor of all candidates' on every parameter.
    step : float
        Relative finite-difference step of the sensitivities.
    extensions : sequence of str, optional
        SPEC §6 groups whose parameters are free (as identify ``--model``);
        default the scenario's ``[model]``, else every group with a positive
        value in ``[truth]`` (the car has it, so identify must fit it).

    Returns
    -------
    PlanResult
    """
    pb = PlanProblem.build(scenario, extensions)
    opts = PlanOptions.build(pb, noise=noise, accel_density=accel_density, gyro_density=gyro_density,
                             bandwidth=bandwidth, noise_ar1=noise_ar1, noise_psd=noise_psd, budget_runs=budget_runs,
                             budget_time=budget_time, overhead=overhead, criterion=criterion, targets=targets,
                             robust=robust, robust_spread=robust_spread, seed=seed, within=within, step=step)
    inf = gather_information(pb, opts)
    chosen = select_runs(pb, opts, inf)
    return assemble(pb, opts, inf, chosen)


@dataclass
class PlanInformation:
    """The Fisher and identify information of every candidate run (:func:`gather_information`).

    ``infos``: one :class:`RunInformation` per car (the nominal car first), knots no run excites masked out;
    ``road_info``: the unknown-road runs' information by run id; ``sim``: the simulator the
    information came from (the curves' with damper curves), ``lin_sim`` the linear car's;
    ``exc``: the damper knots' :class:`Excitation` (None without curves); ``cars``: (d,) rows;
    ``notes``: what the plan says about how it was made.
    """

    infos: list
    road_info: dict
    sim: object
    lin_sim: object
    exc: Excitation | None
    cars: list
    notes: list

    @property
    def info(self) -> RunInformation:
        """The nominal car's information."""
        return self.infos[0]

    def precision(self, S) -> Precision:
        """Precision of runs ``S``; with curves the knots they do not excite excluded."""
        if self.exc is None:
            return subset_precision(self.info, S)
        idx = list(S)
        k = self.exc.mask(idx)
        return precision(*(mask_information(M[idx].sum(0), k) for M in (self.info.F, self.info.A, self.info.B)),
                         self.info.names, self.info.x0)


#: the plan's note for a scenario with bump stops: its model has none (the information of the stops' rate and
#: clearance is not planned; ``rideid identify --model bump_stops`` fits them)
BUMP_STOP_NOTE = ("bump stops are not in the plan's model (it plans the linear groups and the damper curves; "
                  "`rideid identify --model bump_stops` fits the stops): planned without them")


def gather_information(pb: PlanProblem, opts: PlanOptions) -> PlanInformation:
    """Information of every candidate run for the nominal car and the robust cars."""
    sc, notes = pb.sc, []
    sim = (simulator(replace(sc, runs=tuple(r for r in sc.runs if r.road_known)))
           if len(pb.road_ids) < len(pb.run_ids) else None)
    lin_sim, exc = sim, None
    if pb.curves:
        curve_sim = Simulator(pb.space.layout).bind(sc.geometry, sim.runs)
        # one integrator for every row of the differences
        sim = PinnedSimulator(curve_sim, curve_sim.pin_at(pb.P0[None], margin=1.0))
        exc = Excitation(pb.space.layout.knots, run_counts(pb.space, sim, pb.P0), pb.names)
        if sc.dampers is not None and pb.knots_from == "default knots (SPEC §8)":
            notes.append("the [dampers] velocities are not symmetric: the plan's car is the truth curve sampled at "
                         "the default knots (set [model] damper_knots to plan other knots)")
        if sc.bump_stops:
            notes.append(BUMP_STOP_NOTE)
    cars = [pb.x0] + _sample_cars(pb.space, pb.x0, sc.bounds, opts.robust - 1, opts.robust_spread, opts.seed)
    infos, road_info = _information(sc, sim, pb.space, cars, opts.noise, opts.seed, opts.step)
    if road_info:
        notes.append(f"runs on unknown roads ({', '.join(road_info)}): precision predicted from the road fit of "
                     f"identify (estimate.problem.roadfit) on {roadinfo.ROADS} generated roads of their ISO 8608 "
                     "class per run (seeded by --seed; one with a road_seed), information averaged (docs/planning.md)")
    if exc is not None:  # a knot no candidate excites is not in any Fisher matrix
        keep = exc.mask(range(len(pb.run_ids)))
        for i in infos:
            i.F, i.A, i.B = (mask_information(M, keep) for M in (i.F, i.A, i.B))
    return PlanInformation(infos, road_info, sim, lin_sim, exc, cars, notes)


@dataclass(frozen=True)
class Selection:
    """What :func:`select_runs` chose: ``S`` (sorted candidate indices), the greedy ``order`` over all
    candidates, its ``path`` [(run id, Precision)], the selector and the selection's notes."""

    S: list
    order: list
    path: list
    selector: Selector
    notes: list


def select_runs(pb: PlanProblem, opts: PlanOptions, inf: PlanInformation) -> Selection:
    """The runs to drive: the best subset under the budget or for the targets, else the fewest runs
    ``within`` all candidates' CRLB; and the greedy path over every candidate (for the figure)."""
    R = len(pb.run_ids)
    F, A, B = (np.stack([getattr(i, m) for i in inf.infos]) for m in "FAB")
    # track time is the cost when it is budgeted, and for targets (reach them in the least time)
    use_time = opts.budget_time is not None or opts.criterion == "target"
    cost = opts.time_cost if use_time else np.ones(R)
    ti = [pb.names.index(n) for n in opts.targets]
    sel = Selector(F, A, B, cost, opts.criterion, ti, [opts.targets[n] for n in opts.targets])
    # greedy path over all candidates (no budget), for the figure
    order = (sel.greedy(lambda S: True, stop_when_met=False) if opts.criterion != "target" else
             Selector(F, A, B, np.ones(R), opts.criterion, ti, sel.tr).greedy(lambda S: True, stop_when_met=False))
    path = [(pb.run_ids[j], inf.precision(order[:k + 1])) for k, j in enumerate(order)]
    S, notes = (_budgeted_subset if opts.budgeted else _fewest_within)(pb, opts, inf, sel)
    return Selection(sorted(S), order, path, sel, notes)


def _fits(opts: PlanOptions, S, limit_runs) -> bool:
    """Whether runs ``S`` fit at most ``limit_runs`` runs and the time budget."""
    if limit_runs is not None and len(S) > limit_runs:
        return False
    return opts.budget_time is None or opts.time_cost[list(S)].sum() <= opts.budget_time * (1 + 1e-12)


def _budgeted_subset(pb, opts, inf, sel) -> tuple[list, list]:
    """The best subset within the budget (targets: at the least cost); a note when targets are missed."""
    S = sel.best(lambda S: _fits(opts, S, opts.budget_runs))
    notes = []
    if opts.criterion == "target" and not sel.met(S):
        ti = [pb.names.index(n) for n in opts.targets]
        worst = sel.rel_std(S)[:, ti].max(0)
        miss = [f"{n} ±{100 * w:.3g} % (target {100 * opts.targets[n]:.3g} %)"
                for n, w in zip(opts.targets, worst) if w > opts.targets[n] * (1 + 1e-9)]
        where = "within the budget" if (opts.budget_runs or opts.budget_time) else "even with every candidate run"
        notes.append(f"targets not reached {where}: best reachable " + ", ".join(miss))
    return S, notes


def _fewest_within(pb, opts, inf, sel) -> tuple[list, list]:
    """Without a budget: the fewest runs whose CRLB is within ``opts.within`` of all candidates' on every
    parameter."""
    R = len(pb.run_ids)
    all_p = inf.precision(range(R))
    S = None
    for k in range(1, R + 1):
        T = sel.best(lambda S, k=k: _fits(opts, S, k))
        if np.all(inf.precision(T).rel_crlb <= opts.within * all_p.rel_crlb):
            S = T
            break
    S = S if S is not None else list(range(R))
    return S, [f"no budget given: the fewest runs whose CRLB is within {opts.within:g}x of all "
               f"{R} candidates' on every parameter (--within; set --budget-runs or --budget-time)"]


def assemble(pb: PlanProblem, opts: PlanOptions, inf: PlanInformation, chosen: Selection) -> PlanResult:
    """The :class:`PlanResult` of the selection: precisions, candidates, messages, notes, comparison."""
    R, S, names, space = len(pb.run_ids), chosen.S, pb.names, pb.space
    all_p, sel_p = inf.precision(range(R)), inf.precision(chosen.S)
    notes = inf.notes + chosen.notes + _identify_note(sel_p, names, opts.noise)
    res = PlanResult(
        scenario=str(pb.sc.path), names=names, nominal=_nominal(pb),
        derived=space.derived, known=dict(pb.sc.known), extensions=list(space.extensions),
        noise=opts.noise.to_dict(), noise_text=opts.noise.describe(), criterion=opts.criterion,
        budget={"runs": opts.budget_runs, "time_s": opts.budget_time, "overhead_s": opts.overhead,
                "within": None if (opts.budget_runs or opts.budget_time or opts.criterion == "target")
                else opts.within},
        targets=opts.targets,
        robust={"cars": opts.robust,
                "rule": "maximin: the criterion of the worst car" if opts.robust > 1 else "nominal car",
                "seed": opts.seed, "spread": opts.robust_spread if opts.robust > 1 else None,
                "cars_free": [dict(zip(names, map(float, c))) for c in inf.cars[1:]]},
        sensitivity=_sensitivity_method(pb, opts, inf),
        candidates=_candidates(pb, opts, inf), all_runs=all_p, selected_runs=[pb.run_ids[j] for j in S],
        selected=sel_p, path=chosen.path,
        messages_all=_messages(inf.info, inf.exc, range(R), None, all_p),
        messages_selected=_messages(inf.info, inf.exc, S, [pb.run_ids[j] for j in S], sel_p), notes=notes,
        derived_grad=None if space.derived is None else space.derived_gradient() * pb.x0,  # d(derived)/du, u = x/x0
        robust_worst=chosen.selector.rel_std(S).max(0) if opts.robust > 1 else None,
        declared=_declared_block(pb.sc, space))
    if any(n in POWERTRAIN_NAMES for n in names):
        res.powertrain = _powertrain_block(pb, inf, S)
        res.notes += pt_info.selection_note(res.powertrain, res.selected_runs)
    if inf.exc is not None:
        res.dampers = _dampers_block(inf.exc, space, pb.x0, names, all_p, sel_p, S, R, pb.knots_from)
    tk = [k for k, r in enumerate(pb.sc.runs) if r.road_known]
    if tk:  # the paper's map covers track runs only
        width = len(ALL_NAMES) if any(n in EXT_NAMES for n in names) else len(NAMES)
        res.comparison = _compare_maps(inf.lin_sim, replace(pb.sc, runs=tuple(pb.sc.runs[k] for k in tk)),
                                       pb.P0[:width] if pb.curves else pb.P0, [pb.run_ids[k] for k in tk],
                                       replace(inf.info, F=inf.info.F[tk]), names,
                                       [pb.run_ids[j] for j in chosen.order], opts.criterion)
    return res


def _powertrain_block(pb: PlanProblem, inf: PlanInformation, S) -> dict:
    """plan.json ``"powertrain"`` (:func:`rideid.design.powertrain.powertrain_block`) of the nominal car."""
    tk = [k for k, r in enumerate(pb.sc.runs) if r.road_known]
    runs = [None] * len(pb.run_ids)
    for i, k in enumerate(tk):
        runs[k] = inf.lin_sim.runs[i]
    tracks = [pb.sc.tracks[r.track] if r.track is not None else None for r in pb.sc.runs]
    return pt_info.powertrain_block(pb.names, pb.P0, pb.sc.geometry, inf.info.F, runs, tracks,
                                    [r.speed for r in pb.sc.runs], pb.run_ids, S)


def _declared_block(sc, space) -> dict:
    """plan.json's ``declared`` (SPEC §12): the scenario's declared stds, the anchor's relative one (added in
    quadrature to the identify spread of every scale parameter), and the inputs the plan does not predict."""
    declared = dict(getattr(sc, "declared", {}) or {})
    if not declared:
        return {}
    out = {"stds": declared, "method": "the scale anchor's relative std added in quadrature to the expected "
                                       "identify spread of every mass, inertia, stiffness and damping (exact by the "
                                       "scale invariance of SPEC §1); 0 for a"}
    anchor = space.anchor
    if declared.get(anchor, 0) > 0:
        out["anchor"] = {"key": anchor, "std": declared[anchor],
                         "relative": declared[anchor] / abs(sc.known[anchor])}
    out["not_predicted"] = [k for k, v in declared.items() if v > 0 and k != anchor]
    return out


def _identify_note(sel_p: Precision, names, nm: NoiseModel) -> list:
    """A note when identify's expected spread exceeds the CRLB by more than 10 % on some parameter."""
    with np.errstate(invalid="ignore"):
        ratio = sel_p.rel_identify / sel_p.rel_crlb
    fin = np.isfinite(ratio)
    if not (fin.any() and ratio[fin].max() > 1.1):
        return []
    j = int(np.nanargmax(np.where(fin, ratio, np.nan)))
    what = "neither noise-weighted nor whitened (the noise is coloured)" if nm.coloured else "not noise-weighted"
    return [f"identify's cost is {what}: its expected spread exceeds the CRLB by up to "
            f"{100 * (ratio[fin].max() - 1):.0f} % ({names[j]}); promises use identify's spread"]


def _nominal(pb: PlanProblem) -> dict:
    """plan.json ``"nominal"``: [truth], and the knot forces with curves."""
    nominal = {n: float(v) for n, v in pb.sc.truth.items()}
    nominal.update({n: float(v) for n, v in zip(pb.names, pb.x0) if n in pb.knot_names})
    return nominal


def _sensitivity_method(pb: PlanProblem, opts: PlanOptions, inf: PlanInformation) -> dict:
    """plan.json ``"sensitivities"``: how the derivatives were taken."""
    sens = {"method": "central finite differences through the compiled kernel", "relative_step": opts.step}
    if any(n in POWERTRAIN_NAMES for n in pb.names):
        sens["method"] = ("central finite differences through the compiled kernel's 12-state specialisation (a car "
                          "with a powertrain on mounts, SPEC §11)")
    if pb.curves:
        sens["method"] = ("central finite differences through the compiled nonlinear car (damper curves, RK4 with "
                          "its sub-step count pinned at the nominal car's for every row of the differences)")
        sens["substeps"] = {rid: int(m) for rid, m in zip(pb.run_ids, inf.sim.pin.substeps)}
    return sens


def _candidates(pb: PlanProblem, opts: PlanOptions, inf: PlanInformation) -> list:
    """plan.json ``"candidates"``: each run's road, rate, duration, cost, channels (and knots excited)."""
    cand = [{"id": r.id, "kind": "rig" if r.posts else "track" if r.road_known else "road", "track": r.track,
             "speed": r.speed,
             "fs": r.fs, "duration_s": r.duration, "time_cost_s": float(opts.time_cost[k]),
             "channels_used": [c for c, u in zip(CHANNELS, inf.info.used[k]) if u]}
            for k, r in enumerate(pb.sc.runs)]
    for c, r in zip(cand, pb.sc.runs):
        if not r.road_known:
            c["road"] = {"road_class": r.road.road_class, "coherence": r.road.coherence,
                         "road_seeds": inf.road_info[r.id].seeds,
                         "method": "an unknown road (SPEC §9): precision of identify's road fit on generated roads "
                                   "of this ISO 8608 class, information averaged over the roads"}
    if inf.exc is not None:
        for k, c in enumerate(cand):
            c["dampers"] = inf.exc.run_entry(k)
    return cand


def _information(sc, sim, space, cars, nm, seed, step):
    """:class:`RunInformation` of every candidate run (scenario order) for each car, and the unknown-road
    candidates' :class:`rideid.design.roadinfo.RoadRunInformation` by run id.

    Track runs: :func:`run_information`. Runs on unknown roads: :func:`rideid.design.roadinfo.road_run_information`;
    their Fisher information adds as it is, their identify matrices ``A``, ``B`` times the track runs' noise
    level ``c = tr(B) / tr(A)`` and ``c^2`` (the joint fit weights each block by its own residual level;
    module docstring of :mod:`rideid.design.roadinfo`)."""
    tk = [k for k, r in enumerate(sc.runs) if r.road_known]
    rk = [k for k, r in enumerate(sc.runs) if not r.road_known]
    road = {sc.runs[k].id: roadinfo.road_run_information(sc, space, cars, sc.runs[k], k, nm, seed)
            for k in rk}
    fs = [sc.runs[k].fs for k in tk]
    out = []
    for i, x in enumerate(cars):
        R, d = len(sc.runs), len(space.names)
        F, A, B = np.zeros((R, d, d)), np.zeros((R, d, d)), np.zeros((R, d, d))
        sig, rms, used = np.zeros((R, 10)), np.zeros((R, 10)), np.zeros((R, 10), bool)
        c = 1.0
        if tk:
            t = run_information(sim, space, x, nm, fs, step=step)
            F[tk], A[tk], B[tk], sig[tk], rms[tk], used[tk] = t.F, t.A, t.B, t.sigma, t.rms, t.used
            c = float(np.trace(t.B.sum(0)) / np.trace(t.A.sum(0)))
        for k in rk:
            ri = road[sc.runs[k].id]
            F[k], A[k], B[k] = ri.F[i], c * ri.A[i], c * c * ri.B[i]
            sig[k], rms[k], used[k] = ri.sigma, ri.rms, ri.used
        out.append(RunInformation(F, A, B, sig, rms, used, names=list(space.names), x0=np.asarray(x, float),
                                  P0=space.full(np.asarray(x)[None])[0]))
    return out, road


def _messages(info, exc, runs, run_ids, p) -> list:
    """:func:`messages` of precision ``p`` of ``runs``; with curves those of the knots the runs excite (the
    Fisher matrix without the others), and the knots not excited named."""
    off = exc.not_excited(runs) if exc is not None else []
    if not off:
        return messages(p, run_ids)
    idx, keep = list(runs), np.nonzero(exc.mask(runs))[0]
    sub = precision(*(M[idx].sum(0)[np.ix_(keep, keep)] for M in (info.F, info.A, info.B)),
                    [info.names[i] for i in keep], info.x0[keep])
    out = messages(sub, run_ids)
    where = f" by {', '.join(run_ids)}" if run_ids is not None else " by any candidate run"
    return [f"damper knots not excited{where}: {', '.join(off)} (no run reaches them; excluded from the Fisher "
            "matrix, identify would continue the last excited segment's slope)"] + out


def _dampers_block(exc, space, x0, names, all_p, sel_p, S, n_runs, knots_from) -> dict:
    """plan.json ``"dampers"``: knots, nominal forces, and per axle the CRLB per knot (all runs, selected)."""
    K = space.layout.n_knots
    kn = curve_names(K)

    def block(p, runs):
        e = exc.of(runs)
        out = {"not_excited": not_excited_names(exc.knots, e)}
        for a, axle in enumerate(AXLES):
            rows = []
            for j, n in enumerate(kn[a * K:(a + 1) * K]):
                i = names.index(n) if n in names else None
                ok = i is not None and bool(e[a, j]) and np.isfinite(p.rel_crlb[i])
                rows.append((n, ok, i))
            out[axle] = {"names": [n for n, _, _ in rows], "excited": [bool(e[a, j]) for j in range(K)],
                         "samples_beyond_previous_knot": exc.counts[list(runs)][:, a].sum(0).tolist(),
                         "crlb_std": [float(p.std[i]) if ok else None for _, ok, i in rows],
                         "crlb_relative": [float(p.rel_crlb[i]) if ok else None for _, ok, i in rows],
                         "identify_std": [float(p.std_identify[i]) if ok and np.isfinite(p.std_identify[i]) else None
                                          for _, ok, i in rows]}
        return out

    force = {n: float(v) for n, v in zip(names, x0) if n in kn}
    return {"velocity": list(space.layout.knots), "knots_from": knots_from, "unit": {"velocity": "m/s", "force": "N"},
            "nominal": {axle: [force.get(n) for n in kn[a * K:(a + 1) * K]] for a, axle in enumerate(AXLES)},
            "excitation_rule": exc.rule(),
            "all_runs": block(all_p, range(n_runs)), "selected": block(sel_p, S)}


def _check_truth(sc, space, P0):
    """The anchor must describe the nominal car: fixed and derived values equal to [truth]."""
    # a nonlinear row is the car's 16 (23 with a powertrain) columns, then the curves' and stops'
    names = space.layout.names[:space.layout.n_car] if space.layout is not None else ALL_NAMES
    for k, n in enumerate(names[:P0.size]):
        if space.curves and n in ("c_sf", "c_sr"):  # the curves' mean slopes, not parameters of the plan
            continue
        if abs(P0[k] - sc.truth.get(n, 0.0)) > 1e-6 * max(abs(sc.truth.get(n, 0.0)), 1e-12):
            src = "derived from [known] total_mass" if n == space.derived else "[known]"
            raise DataError(f"{sc.path}: {n} = {P0[k]:.6g} ({src}) disagrees with [truth] {n} = "
                            f"{sc.truth.get(n, 0.0):.6g}; "
                            "the plan is made for the [truth] car, so [known] must match it")


def _sample_cars(space, x0, bounds, n, spread, seed) -> list:
    """``n`` cars uniform in the scenario's [bounds] (or ±spread around nominal), physically valid."""
    if n <= 0:
        return []
    rng = np.random.default_rng(seed)
    lo = np.array([bounds[k][0] if k in bounds else x * (1 - spread) for k, x in zip(space.names, x0)])
    hi = np.array([bounds[k][1] if k in bounds else x * (1 + spread) for k, x in zip(space.names, x0)])
    out = []
    # damper curves without [bounds] for their knots: each axle's curve scaled as a whole (independent knots
    # would make non-monotone curves, which ParameterSpace.full flattens and the differences could not see)
    axles = [[j for j, k in enumerate(space.names) if k.startswith(p) and k not in bounds] for p in ("F_f", "F_r")]
    for _ in range(1000 * n):
        x = lo + (hi - lo) * rng.random(lo.size)
        for js in axles:
            if js:
                x[js] = x0[js] * (1 + spread * (2 * rng.random() - 1))
        if space.valid(space.full(x[None]))[0]:
            out.append(x)
            if len(out) == n:
                return out
    raise ArgumentError("--robust: could not sample physically valid cars in the bounds (derived mass negative?)")


def _compare_maps(sim, sc, P0, run_ids, info, names, greedy_order, criterion) -> dict:
    """Where the paper's sensitivity map (rideid sensitivity) and the Fisher information agree."""
    from scipy.stats import spearmanr  # slow to import, needed by this comparison only
    maps = compute_maps(sim, sc.geometry, P0, run_ids)
    names = [n for n in names if n in maps.params]  # parameters the map covers
    M = maps.submap(names)  # (d, R), rows sum to 1
    diag = np.stack([np.diag(F) for F in info.F], axis=1)  # (d, R): information about p alone, per run
    diag = diag[[info.names.index(n) for n in names]]
    share = diag / np.maximum(diag.sum(1, keepdims=True), 1e-300)
    out = {}
    for j, n in enumerate(names):
        rho = spearmanr(M[j], share[j]).statistic if np.ptp(M[j]) > 0 and np.ptp(share[j]) > 0 else float("nan")
        out[n] = {"top_map": run_ids[int(np.argmax(M[j]))], "top_fisher": run_ids[int(np.argmax(share[j]))],
                  "spearman": float(rho) if np.isfinite(rho) else 0.0,
                  "map_share": [float(v) for v in M[j]], "fisher_share": [float(v) for v in share[j]]}
    total = M.sum(0)
    return {"method": "Per parameter: the map's share of each run (paper's parameter→track map, +25 % peak "
                      "changes weighted by run RMS) against the run's share of the diagonal Fisher information "
                      "(information about that parameter with all others known); Spearman rank correlation over "
                      "the runs. The map ignores noise, run length and correlations between parameters.",
            "parameters": out, "map_order": [run_ids[k] for k in np.argsort(-total)], "greedy_order": greedy_order,
            "runs": run_ids}
