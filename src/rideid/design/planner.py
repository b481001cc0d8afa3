"""``rideid.plan``: which candidate runs to drive, and the precision they buy (SPEC §7).

See ``docs/planning.md`` for the method, the choices and the validation.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..estimate.cost import ParameterSpace
from ..model.params import GROUPS
from ..errors import ArgumentError, DataError
from ..data.scenario import load_scenario
from ..data.schema import Scenario
from .colour import load_noise_psd
from ..model.nonlinear import curve_names
from ..model.params import ALL_NAMES, EXT_NAMES, NAMES
from .curves import AXLES, CURVES, Excitation, mask_information, nominal_forces, not_excited_names, plan_knots, run_counts
from . import roadinfo
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

    # -- dictionaries ---------------------------------------------------------
    def _crlb(self, p: Precision, which="crlb") -> dict:
        rel = p.rel_crlb if which == "crlb" else p.rel_identify
        out = {}
        for j, n in enumerate(self.names):
            ok = np.isfinite(rel[j])
            out[n] = {"std": float(rel[j] * abs(p.x0[j])) if ok else None,
                      "relative": float(rel[j]) if ok else None}
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
            sel["targets"] = {n: {"target": t, "expected_identify": (float(self.selected.rel_identify[self.names.index(n)])
                                                                      if self.selected.identifiable[self.names.index(n)]
                                                                      else None)}
                              for n, t in self.targets.items()}
            for n, v in sel["targets"].items():
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
        } | ({"dampers": self.dampers} if self.dampers is not None else {})

    def label(self, rid: str) -> str:
        """A run id, with ``(road B)`` for a run on an unknown road of ISO 8608 class B."""
        c = next((c for c in self.candidates if c["id"] == rid), None)
        return f"{rid} (road {c['road']['road_class']})" if c is not None and c.get("road") else rid

    # -- output files ---------------------------------------------------------
    def summary(self) -> str:
        """Terminal text: the chosen runs and the precision they buy."""
        cand = {c["id"]: c for c in self.candidates}
        t = sum(cand[r]["time_cost_s"] for r in self.selected_runs)
        lines = [f"plan ({self.criterion}-optimal{', robust over ' + str(self.robust['cars']) + ' cars' if self.robust['cars'] > 1 else ''}): "
                 f"drive {len(self.selected_runs)} of {len(self.candidates)} runs, {t:.0f} s of track time: "
                 + ", ".join(self.label(r) for r in self.selected_runs),
                 f"noise: {self.noise_text}",
                 f"{'parameter':10s} {'nominal':>12s} {'selected ±':>12s} {'(identify)':>10s} {'all runs ±':>10s}"]
        off_sel = set(self.dampers["selected"]["not_excited"]) if self.dampers else set()
        off_all = set(self.dampers["all_runs"]["not_excited"]) if self.dampers else set()

        def cell(v, n, off, width):
            return f"{'not excited' if n in off else _pct(v):>{width}s}"

        for j, n in enumerate(self.names):
            lines.append(f"{n:10s} {self.nominal[n]:12.6g} {cell(self.selected.rel_crlb[j], n, off_sel, 12)} "
                         f"{cell(self.selected.rel_identify[j], n, off_sel, 10)} "
                         f"{cell(self.all_runs.rel_crlb[j], n, off_all, 10)}")
        if self.dampers:
            for c in self.candidates:
                ne = c["dampers"]["not_excited"]
                lines.append(f"damper knots run {c['id']}: " + (f"not excited {', '.join(ne)}" if ne else "all excited"))
        lines += self.messages_selected + self.notes
        return "\n".join(lines)

    def markdown(self) -> str:
        d = self.to_dict()
        out = [f"# Test plan: {Path(self.scenario).name}\n",
               f"Criterion **{self.criterion}**, noise {self.noise_text}; budget: {_budget_text(self.budget)}; robust over {self.robust['cars']} car(s) "
               f"({self.robust['rule']}).\n",
               f"**Selected runs** ({len(self.selected_runs)}, {d['selected']['track_time_s']:.0f} s of track time): "
               + ", ".join(self.label(r) for r in self.selected_runs) + "\n",
               "| candidate run | road | speed (m/s) | fs (Hz) | duration (s) | selected |",
               "|---|---|---|---|---|---|"]
        for c in self.candidates:
            road = (f"unknown road, ISO 8608 class {c['road']['road_class']}" if c.get("road")
                    else f"track {c['track']}")
            out.append(f"| {c['id']} | {road} | {c['speed']:g} | {c['fs']:g} | {c['duration_s']:g} | "
                       f"{'yes' if c['id'] in self.selected_runs else ''} |")
        out += ["",
               "| parameter | nominal | unit | selected CRLB ± | selected identify ± | all runs CRLB ± | all runs identify ± |",
               "|---|---|---|---|---|---|---|"]
        from ..model.params import UNITS
        for j, n in enumerate(self.names):
            out.append(f"| {n} | {self.nominal[n]:.6g} | {UNITS.get(n, '')} | {_pct(self.selected.rel_crlb[j])} | "
                       f"{_pct(self.selected.rel_identify[j])} | {_pct(self.all_runs.rel_crlb[j])} | "
                       f"{_pct(self.all_runs.rel_identify[j])} |")
        out.append("\n± are one relative standard deviation. CRLB: the best any unbiased estimator can do with "
                   "this noise; identify: the expected spread of `rideid identify` (its cost is not noise-weighted).\n")
        for title, msgs in (("Selected runs", self.messages_selected), ("All candidate runs", self.messages_all)):
            out.append(f"## Identifiability: {title.lower()}\n")
            out += [f"- {m}" for m in msgs] or ["- every parameter identifiable, no pair with |correlation| > 0.9"]
            out.append("")
        out.append("## Greedy path (relative CRLB, % — precision after adding each run)\n")
        out.append("| # | added run | " + " | ".join(self.names) + " |")
        out.append("|---" * (len(self.names) + 2) + "|")
        for k, (rid, p) in enumerate(self.path):
            out.append(f"| {k + 1} | {self.label(rid)} | " + " | ".join(_pct(v, sign=False) for v in p.rel_crlb) + " |")
        if self.comparison:
            c = self.comparison
            out.append("\n## Fisher information vs the paper's sensitivity map\n")
            out.append(c["method"] + "\n")
            out.append("| parameter | top run (map) | top run (Fisher) | rank correlation |")
            out.append("|---|---|---|---|")
            for n, v in c["parameters"].items():
                out.append(f"| {n} | {v['top_map']} | {v['top_fisher']} | {v['spearman']:+.2f} |")
            out.append(f"\nRuns ordered by the map's total share: {', '.join(c['map_order'])}  ")
            out.append(f"Runs in greedy {self.criterion} order: {', '.join(c['greedy_order'])}\n")
        if self.dampers:
            dm = self.dampers
            out.append("\n## Damper curves: knots excited and their CRLB (selected runs)\n")
            out.append(dm["excitation_rule"] + ".\n")
            out.append("| v (m/s) | front F (N) | front CRLB ± | rear F (N) | rear CRLB ± |")
            out.append("|---|---|---|---|---|")
            sel = dm["selected"]

            def c(ax, j):
                r = sel[ax]["crlb_relative"][j]
                return "not excited" if not sel[ax]["excited"][j] else ("—" if r is None else f"±{100 * r:.3g} %")
            for j, v in enumerate(dm["velocity"]):
                out.append(f"| {v:g} | {dm['nominal']['front'][j]:.6g} | {c('front', j)} | "
                           f"{dm['nominal']['rear'][j]:.6g} | {c('rear', j)} |")
            out.append("\n| run | knots not excited |\n|---|---|")
            for cd in self.candidates:
                out.append(f"| {cd['id']} | {', '.join(cd['dampers']['not_excited']) or 'none'} |")
            out.append("")
        if self.notes:
            out.append("## Notes\n")
            out += [f"- {m}" for m in self.notes]
        return "\n".join(out) + "\n"

    def save(self, out_dir) -> Path:
        """Write plan.json, plan.md, crlb.csv, path.csv, correlation.csv and precision_path.png into ``out_dir``."""
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "plan.json").write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")
        (out_dir / "plan.md").write_text(self.markdown())
        with open(out_dir / "crlb.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["parameter", "nominal", "selected_std", "selected_relative", "selected_identify_std",
                        "all_std", "all_relative", "all_identify_std"])
            for j, n in enumerate(self.names):
                s, a = self.selected, self.all_runs
                w.writerow([n, f"{self.nominal[n]:.10g}", _num(s.std[j]), _num(s.rel_crlb[j]), _num(s.std_identify[j]),
                            _num(a.std[j]), _num(a.rel_crlb[j]), _num(a.std_identify[j])])
        with open(out_dir / "path.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["n_runs", "added"] + [f"rel_{n}" for n in self.names])
            for k, (rid, p) in enumerate(self.path):
                w.writerow([k + 1, rid] + [_num(v) for v in p.rel_crlb])
        with open(out_dir / "correlation.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["selected"] + self.names)
            for n, row in zip(self.names, self.selected.correlation()):
                w.writerow([n] + [_num(v) for v in row])
        self.figure(out_dir / "precision_path.png")
        return out_dir

    def figure(self, path):
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        k = np.arange(1, len(self.path) + 1)
        R = np.array([p.rel_crlb for _, p in self.path]) * 100
        fig, ax = plt.subplots(figsize=(8, 5))
        cmap = matplotlib.colormaps["tab20"]
        for j, n in enumerate(self.names):
            y = np.where(np.isfinite(R[:, j]), R[:, j], np.nan)
            ax.semilogy(k, y, "o-", ms=3, color=cmap(j % 20), label=n)
        ns = len(self.selected_runs)
        ax.axvline(ns, color="k", ls=":", lw=1)
        ax.text(ns, ax.get_ylim()[1], f" selected size {ns}", va="top", fontsize=8)
        ax.set_xticks(k)
        ax.set_xticklabels([f"{i}\n{rid}" for i, (rid, _) in zip(k, self.path)], fontsize=6)
        ax.set_xlabel(f"runs along the greedy {self.criterion} path (run added)")
        ax.set_ylabel("relative CRLB, % (1 sd)")
        ax.set_title("Precision per parameter vs number of runs (missing points: not identifiable)", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)


def _budget_text(b) -> str:
    parts = []
    if b.get("runs") is not None:
        parts.append(f"at most {b['runs']} runs")
    if b.get("time_s") is not None:
        parts.append(f"at most {b['time_s']:g} s of track time")
    if b.get("within") is not None:
        parts.append(f"none (fewest runs within {b['within']:g}x of all candidates' CRLB)")
    parts.append(f"{b.get('overhead_s', 0):g} s overhead per run")
    return ", ".join(parts) if parts else "none"


def _pct(v, sign=True) -> str:
    if not np.isfinite(v):
        return "not identifiable" if sign else "—"
    s = f"{100 * v:.3g} %"
    return ("±" + s) if sign else f"{100 * v:.3g}"


def _num(v) -> str:
    return f"{v:.8g}" if np.isfinite(v) else ""


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


def plan(scenario, *, noise=None, accel_density: float = 0.0, gyro_density: float = 0.0,
         bandwidth: float | None = None, noise_ar1: float = 0.0, noise_psd=None, budget_runs: int | None = None, budget_time: float | None = None,
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
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    road_ids = [r.id for r in sc.runs if not r.road_known]
    if sc.truth is None:
        raise DataError(f"{sc.path}: a plan needs a scenario with a [truth] table (the nominal car)")
    if extensions is None:  # the scenario's [model], else the groups the nominal car has
        extensions = sc.extensions if sc.extensions is not None else \
            tuple(g for g, ns in GROUPS.items() if any(sc.truth.get(n, 0.0) > 0 for n in ns))
    extensions = tuple(extensions)
    if sc.dampers is not None and CURVES not in extensions:  # the car has real dampers: plan their curves
        extensions += (CURVES,)
    curves = CURVES in extensions
    if curves and road_ids:
        raise ArgumentError(f"runs on unknown roads ({', '.join(road_ids)}) cannot be planned with damper curves: "
                            "the road fit projects the road out of a linear car (docs/any-road.md); plan the curves "
                            "on known tracks, or the linear model with --model")
    knots, knots_from = plan_knots(sc) if curves else (None, None)
    space = ParameterSpace(sc.known, sc.geometry, sc.bounds, extensions=extensions,
                           damper_knots=knots)  # refuses a missing anchor
    names = list(space.names)
    knot_names = [n for n in names if n.startswith("F_")] if curves else []
    x0 = np.array([float(sc.truth.get(n, 0.0)) for n in names])
    if curves:
        Fk = nominal_forces(sc, space.layout)
        all_knots = curve_names(space.layout.n_knots)
        x0[[names.index(n) for n in knot_names]] = [Fk[all_knots.index(n)] for n in knot_names]
    bad = [n for n, v in zip(names, x0) if (v == 0 if n in knot_names else v <= 0)]
    if bad:
        raise DataError(f"{sc.path}: [truth] has no positive value for {', '.join(bad)}, a free parameter of the "
                        "model; precision is planned relative to the nominal value, so give one")
    P0 = space.full(x0[None])[0]
    _check_truth(sc, space, P0)
    run_ids = [r.id for r in sc.runs]
    if not run_ids:
        raise DataError(f"{sc.path}: no [[runs]]: nothing to plan")

    # -- options -------------------------------------------------------------
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
    targets = dict(targets or {})
    if criterion is None:
        criterion = "target" if targets else "D"
    if criterion not in CRITERIA:
        raise ArgumentError(f"--criterion {criterion!r}: expected one of {', '.join(CRITERIA)}")
    for n, v in targets.items():
        if n not in names:
            why = (f"{n} is {'derived from the anchor' if n == space.derived else 'fixed in [known]'}"
                   if n in sc.truth else f"unknown parameter {n!r}")
            raise ArgumentError(f"--target {n}: {why}; targets apply to the free parameters: {', '.join(names)}")
        if not (np.isfinite(v) and v > 0):
            raise ArgumentError(f"--target {n}: the relative precision must be positive, got {v!r}")
    if criterion == "target" and not targets:
        raise ArgumentError("--criterion target needs at least one --target NAME=PRECISION (e.g. k_sr=0.5%)")
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
    tcost = np.array([r.duration + overhead for r in sc.runs])
    if budget_time is not None and tcost.min() > budget_time:
        j = int(np.argmin(tcost))
        raise ArgumentError(f"--budget-time {budget_time:g} s: no candidate run fits (the shortest, {run_ids[j]}, "
                            f"takes {sc.runs[j].duration:g} s + {overhead:g} s overhead)")

    # -- information -----------------------------------------------------------
    notes = []
    sim = simulator(replace(sc, runs=tuple(r for r in sc.runs if r.road_known))) if len(road_ids) < len(run_ids) \
        else None
    lin_sim = sim
    exc = None
    if curves:
        from ..estimate.cost import CurveSimulator
        sim = CurveSimulator(sc.geometry, sim.runs, space.layout)
        sim.pin_at(P0[None], margin=1.0)  # one integrator for every row of the differences
        exc = Excitation(space.layout.knots, run_counts(space, sim, P0), names)
        if sc.dampers is not None and knots_from == "default knots (SPEC §8)":
            notes.append("the [dampers] velocities are not symmetric: the plan's car is the truth curve sampled at "
                         "the default knots (set [model] damper_knots to plan other knots)")
        if sc.bump_stops:
            notes.append("bump stops are not in the plan's model (identify cannot fit them): planned without them")
    cars = [x0] + _sample_cars(space, x0, sc.bounds, robust - 1, robust_spread, seed)
    infos, road_info = _information(sc, sim, space, cars, nm, seed, step)
    if road_info:
        notes.append(f"runs on unknown roads ({', '.join(road_info)}): precision predicted from the road fit of "
                     f"identify (rideid.estimate.roadfit) on {roadinfo.ROADS} generated roads of their ISO 8608 "
                     "class per run (seeded by --seed; one with a road_seed), information averaged (docs/planning.md)")
    if exc is not None:  # a knot no candidate excites is not in any Fisher matrix
        keep = exc.mask(range(len(run_ids)))
        for i in infos:
            i.F, i.A, i.B = (mask_information(M, keep) for M in (i.F, i.A, i.B))
    info = infos[0]

    def prec(S):
        """Precision of runs ``S``; with curves the knots they do not excite excluded."""
        if exc is None:
            return subset_precision(info, S)
        idx = list(S)
        k = exc.mask(idx)
        return precision(*(mask_information(M[idx].sum(0), k) for M in (info.F, info.A, info.B)), info.names, info.x0)
    F = np.stack([i.F for i in infos])
    A = np.stack([i.A for i in infos])
    B = np.stack([i.B for i in infos])
    # track time is the cost when it is budgeted, and for targets (reach them in the least time)
    use_time = budget_time is not None or criterion == "target"
    cost = tcost if use_time else np.ones(len(run_ids))
    ti = [names.index(n) for n in targets]
    sel = Selector(F, A, B, cost, criterion, ti, [targets[n] for n in targets])

    def fits(S, limit_runs=budget_runs):
        if limit_runs is not None and len(S) > limit_runs:
            return False
        return budget_time is None or tcost[list(S)].sum() <= budget_time * (1 + 1e-12)

    all_p = prec(range(len(run_ids)))
    # greedy path over all candidates (no budget), for the figure
    order = sel.greedy(lambda S: True, stop_when_met=False) if criterion != "target" else \
        Selector(F, A, B, np.ones(len(run_ids)), criterion, ti, sel.tr).greedy(lambda S: True, stop_when_met=False)
    path = [(run_ids[j], prec(order[:k + 1])) for k, j in enumerate(order)]

    if criterion == "target" or budget_runs is not None or budget_time is not None:
        S = sel.best(fits)
        if criterion == "target" and not sel.met(S):
            worst = sel.rel_std(S)[:, ti].max(0)
            miss = [f"{n} ±{100 * w:.3g} % (target {100 * targets[n]:.3g} %)"
                    for n, w in zip(targets, worst) if w > targets[n] * (1 + 1e-9)]
            where = "within the budget" if (budget_runs or budget_time) else "even with every candidate run"
            notes.append(f"targets not reached {where}: best reachable " + ", ".join(miss))
    else:
        S = None
        for k in range(1, len(run_ids) + 1):
            T = sel.best(lambda S, k=k: fits(S, k))
            p = prec(T)
            if np.all(p.rel_crlb <= within * all_p.rel_crlb):
                S = T
                break
        S = S if S is not None else list(range(len(run_ids)))
        notes.append(f"no budget given: the fewest runs whose CRLB is within {within:g}x of all "
                     f"{len(run_ids)} candidates' on every parameter (--within; set --budget-runs or --budget-time)")
    S = sorted(S)
    sel_p = prec(S)
    chosen = [run_ids[j] for j in S]
    worst = None
    if robust > 1:
        worst = sel.rel_std(S).max(0)

    grad = None
    if space.derived is not None:
        grad = space.derived_gradient() * x0  # d(derived)/du, u = x / x0

    cand = [{"id": r.id, "kind": "track" if r.road_known else "road", "track": r.track, "speed": r.speed,
             "fs": r.fs, "duration_s": r.duration, "time_cost_s": float(tcost[k]),
             "channels_used": [c for c, u in zip(_channels(), info.used[k]) if u]}
            for k, r in enumerate(sc.runs)]
    for c, r in zip(cand, sc.runs):
        if not r.road_known:
            c["road"] = {"road_class": r.road.road_class, "coherence": r.road.coherence,
                         "road_seeds": road_info[r.id].seeds,
                         "method": "an unknown road (SPEC §9): precision of identify's road fit on generated roads "
                                   "of this ISO 8608 class, information averaged over the roads"}
    if exc is not None:
        for k, c in enumerate(cand):
            c["dampers"] = exc.run_entry(k)
    with np.errstate(invalid="ignore"):
        ratio = sel_p.rel_identify / sel_p.rel_crlb
    fin = np.isfinite(ratio)
    if fin.any() and ratio[fin].max() > 1.1:
        j = int(np.nanargmax(np.where(fin, ratio, np.nan)))
        what = ("neither noise-weighted nor whitened (the noise is coloured)" if nm.coloured
                else "not noise-weighted")
        notes.append(f"identify's cost is {what}: its expected spread exceeds the CRLB by up to "
                     f"{100 * (ratio[fin].max() - 1):.0f} % ({names[j]}); promises use identify's spread")
    nominal = {n: float(v) for n, v in sc.truth.items()}
    nominal.update({n: float(v) for n, v in zip(names, x0) if n in knot_names})
    sens = {"method": "central finite differences through the compiled kernel", "relative_step": step}
    if curves:
        sens["method"] = ("central finite differences through the compiled nonlinear car (damper curves, RK4 with "
                          "its sub-step count pinned at the nominal car's for every row of the differences)")
        sens["substeps"] = {rid: int(m) for rid, m in zip(run_ids, sim.pin)}
    res = PlanResult(
        scenario=str(sc.path), names=names,
        nominal=nominal,
        derived=space.derived, known=dict(sc.known), extensions=list(space.extensions), noise=nm.to_dict(), noise_text=nm.describe(),
        criterion=criterion,
        budget={"runs": budget_runs, "time_s": budget_time, "overhead_s": overhead,
                "within": None if (budget_runs or budget_time or criterion == "target") else within},
        targets=targets,
        robust={"cars": robust, "rule": "maximin: the criterion of the worst car" if robust > 1 else "nominal car",
                "seed": seed, "spread": robust_spread if robust > 1 else None,
                "cars_free": [dict(zip(names, map(float, c))) for c in cars[1:]]},
        sensitivity=sens,
        candidates=cand, all_runs=all_p, selected_runs=chosen, selected=sel_p, path=path,
        messages_all=_messages(info, exc, range(len(run_ids)), None, all_p),
        messages_selected=_messages(info, exc, S, chosen, sel_p), notes=notes,
        derived_grad=grad, robust_worst=worst)
    if exc is not None:
        res.dampers = _dampers_block(exc, space, x0, names, all_p, sel_p, S, len(run_ids), knots_from)
    width = len(ALL_NAMES) if any(n in EXT_NAMES for n in names) else len(NAMES)
    tk = [k for k, r in enumerate(sc.runs) if r.road_known]
    if tk:  # the paper's map covers track runs only
        sub = replace(info, F=info.F[tk])
        res.comparison = _compare_maps(lin_sim, replace(sc, runs=tuple(sc.runs[k] for k in tk)),
                                       P0[:width] if curves else P0, [run_ids[k] for k in tk], sub, names,
                                       [run_ids[j] for j in order], criterion)
    return res


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
        out.append(RunInformation(list(space.names), np.asarray(x, float), space.full(np.asarray(x)[None])[0],
                                  F, A, B, sig, rms, used))
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


def _channels():
    from ..model.equations import CHANNELS
    return CHANNELS


def _check_truth(sc, space, P0):
    """The anchor must describe the nominal car: fixed and derived values equal to [truth]."""
    from ..model.params import ALL_NAMES
    for k, n in enumerate(ALL_NAMES[:P0.size]):
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
    from scipy.stats import spearmanr

    from ..estimate.sensitivity import compute_maps
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
