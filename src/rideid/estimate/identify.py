"""Identification: JADE with adaptive track weights, then a least-squares polish.

1. The free parameters and bounds come from the dataset (``[known]``,
   ``[bounds]``, defaults in :data:`rideid.params.DEFAULT_BOUNDS`).
2. The parameter -> track map ``M`` (:mod:`rideid.sensitivity`) is computed
   around a nominal car (the built-in car scaled to the anchor).
3. JADE evolves the population on ``J = sum_r w_r E_r``. After every
   generation (``weights="adaptive"``) the normalised spread of each free
   parameter (eq. 12) gives new weights ``w ∝ spread @ M`` (eq. 13) and the
   population is re-scored with them before the next generation (no new
   simulation: the per-run errors of every individual are kept).
4. JADE stops after ``generations``, or earlier once every free parameter's
   coefficient of variation in the population is below ``spread_tol``.
5. The polish (SciPy ``least_squares``, trust-region reflective, in
   bound-normalised coordinates, forward-difference Jacobian evaluated as
   one batch) minimises the **equal-weight** cost from the best individual.
   The adaptive weights steer the search; the estimate is defined by the
   equal-weight objective so that adaptive and fixed runs are comparable.
6. Runs whose start was estimated (:mod:`rideid.measured`, ``start =
   "auto"``) were aligned with a nominal car; after the polish their starts
   become unknowns of the polish beside the parameters (the data are re-read
   at each start; ``ds.data`` is updated in place, the estimates and their
   standard errors go to ``result.json``). Runs with a speed channel, whose
   wheel inputs depend on the start, are re-simulated and polished again
   until no start moves by more than 1e-3 of a sample interval (at most 5
   rounds). Without the polish the nominal alignment stands.
7. Standard errors: ``cov = s^2 (J^T J)^-1`` at the optimum with
   ``s^2 = RSS / (m - d)``, assuming white residuals (an optimistic lower
   bound when residuals are correlated or the model is wrong).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from .cost import CostFunction
from ..data.dataset import Dataset
from ..model.batch import single_threaded_blas
from ..errors import ArgumentError
from .jade import JadeSolver
from ..model.equations import modal_summary
from ..model.params import GROUPS, INDEX, UNITS
from .sensitivity import SensitivityMaps, adaptive_weights, coefficient_of_variation, compute_maps, normalised_spread

DEFAULT_POPULATION = 64
DEFAULT_GENERATIONS = 400
DEFAULT_SPREAD_TOL = 2e-2
#: Without a polish JADE itself must converge: a much tighter stop.
DEFAULT_SPREAD_TOL_NO_POLISH = 1e-5


@dataclass
class IdentificationResult:
    """What :func:`identify` returns.

    ``parameters`` maps all twelve names to values (and the four extensions
    of SPEC §6 when the model has them or one is known); ``model`` holds the
    model's extension groups; ``details`` adds unit,
    bounds, fixed/derived flags and standard error; ``history`` has one dict
    per generation.
    """

    parameters: dict[str, float]
    details: dict[str, dict]
    known: dict[str, float]
    cost: float
    generations: int
    evaluations: int
    wall_time_s: float
    seed: int | None
    track_weights: dict[str, float]
    weights_mode: str
    polish: dict | None
    stop: str
    history: list[dict] = field(default_factory=list)
    preprocessing: dict = field(default_factory=dict)
    modal: dict | None = None
    dataset: str = ""
    maps: SensitivityMaps | None = None
    model: dict = field(default_factory=lambda: {"extensions": []})

    def to_dict(self) -> dict:
        return {
            "parameters": self.details,
            "model": self.model,
            "known": self.known,
            "cost": self.cost,
            "cost_definition": "equal-weight sum over runs of the per-channel energy-normalised squared error "
                               "(see rideid.cost)",
            "generations": self.generations,
            "evaluations": self.evaluations,
            "wall_time_s": self.wall_time_s,
            "seed": self.seed,
            "track_weights": self.track_weights,
            "weights": self.weights_mode,
            "stop": self.stop,
            "polish": self.polish,
            "modal": self.modal,
            "preprocessing": self.preprocessing,
            "dataset": str(Path(self.dataset).resolve()) if self.dataset else "",
            "history_file": "history.csv",
        }

    def save(self, out_dir):
        out_dir = Path(out_dir)
        (out_dir / "result.json").write_text(json.dumps(self.to_dict(), indent=2) + "\n")
        write_history(self.history, out_dir / "history.csv")


def write_history(history, path):
    if not history:
        Path(path).write_text("")
        return
    keys = list(history[0].keys())
    lines = [",".join(keys)]
    for h in history:
        lines.append(",".join(f"{h[k]:.10g}" if isinstance(h[k], float) else str(h[k]) for k in keys))
    Path(path).write_text("\n".join(lines) + "\n")


#: ``--model`` choices handled here (SPEC §6)
MODELS = ("base", "full")


def model_extensions(ds: Dataset, model=None) -> tuple[str, ...]:
    """Extension groups of the model to fit.

    ``model``: ``None`` (the dataset's ``[model] extensions``, else the
    twelve), ``"base"`` (the twelve), ``"full"`` (every group), or a sequence
    of group names.
    """
    if model is None:
        return tuple(ds.manifest.extensions or ())
    if isinstance(model, str):
        if model == "base":
            return ()
        if model == "full":
            return tuple(GROUPS)
        raise ArgumentError(f"--model must be one of {', '.join(MODELS)}, got {model!r}")
    groups = tuple(model)
    for g in groups:
        if g not in GROUPS:
            raise ArgumentError(f"unknown extension group '{g}'; groups are: {', '.join(GROUPS)}")
    return tuple(g for g in GROUPS if g in groups)


def identify(ds: Dataset, *, seed: int | None = None, population: int = DEFAULT_POPULATION,
             generations: int = DEFAULT_GENERATIONS, weights: str = "adaptive", polish: bool = True,
             spread_tol: float | None = None, progress=None, cost: CostFunction | None = None,
             maps: SensitivityMaps | None = None, model=None) -> IdentificationResult:
    """Estimate the ride parameters of a dataset.

    Parameters
    ----------
    ds : Dataset
    seed : int, optional
        Seed of the ``numpy.random.Generator`` (same seed, same result).
    population, generations : int
        JADE's NP and generation limit.
    weights : {"adaptive", "fixed"}
        Adaptive track weights (paper eq. 12-13) or equal weights.
    polish : bool
        Refine with ``scipy.optimize.least_squares`` after JADE.
    spread_tol : float, optional
        Stop JADE once every free parameter's coefficient of variation in the
        population is below this (0 disables the early stop). Default 2e-2
        with the polish (it only needs the right basin), 1e-5 without.
    progress : callable, optional
        ``progress(info)`` each generation with a dict (generation, best,
        spread, evaluations, elapsed).
    cost : CostFunction, optional
        Reuse an existing cost function of ``ds`` (its weights are reset).
    maps : SensitivityMaps, optional
        Reuse parameter -> track maps (default: computed around the nominal car).
    model : {None, "base", "full"} or sequence of group names
        The model (SPEC §6): the twelve (``"base"``), with every extension
        group (``"full"``), or the given groups; ``None``: the dataset's
        ``[model]``, else the twelve. Ignored when ``cost`` is given (its
        parameter space decides). Known extension values are held fixed and
        used whatever the model.

    Returns
    -------
    IdentificationResult
    """
    with single_threaded_blas():
        return _identify(ds, seed=seed, population=population, generations=generations, weights=weights,
                         polish=polish, spread_tol=spread_tol, progress=progress, cost=cost, maps=maps,
                         model=model)


def _identify(ds, *, seed, population, generations, weights, polish, spread_tol, progress, cost, maps, model):
    if spread_tol is None:
        spread_tol = DEFAULT_SPREAD_TOL if polish else DEFAULT_SPREAD_TOL_NO_POLISH
    if weights not in ("adaptive", "fixed"):
        raise ArgumentError(f"weights must be 'adaptive' or 'fixed', got {weights!r}")
    if not isinstance(generations, int) or generations < 1:
        raise ArgumentError(f"generations must be a positive integer, got {generations!r}")
    t0 = time.perf_counter()
    cf = cost or CostFunction(ds, extensions=model_extensions(ds, model))
    cf.set_weights(np.ones(len(cf.run_ids)))
    space = cf.space
    if maps is None:
        mask = cf.W > 0
        maps = compute_maps(cf.sim, ds.geometry, space.nominal(), cf.run_ids, mask)
    M_free = maps.submap(cf.names)
    rng = np.random.default_rng(seed)
    solver = JadeSolver(cf.bounds, population, rng)
    n_runs = len(cf.run_ids)
    w = np.full(n_runs, 1.0 / n_runs)
    history: list[dict] = []

    X = solver.ask()
    E = cf.run_errors(X)
    solver.tell(cf.combine(E, w))
    E_pop = E
    stop = "generations"
    for g in range(1, generations + 1):
        X = solver.ask()
        E_trial = cf.run_errors(X)
        better = solver.tell(cf.combine(E_trial, w))
        E_pop = np.where(better[None, :], E_trial, E_pop)
        spread = normalised_spread(solver.pop)
        if weights == "adaptive":
            w = adaptive_weights(M_free, spread)
            solver.rescore(cf.combine(E_pop, w))
        cv = coefficient_of_variation(solver.pop)
        finite = np.isfinite(solver.costs)
        rec = {"generation": g, "evaluations": solver.nfev, "best_cost": float(solver.fun),
               "mean_cost": float(np.mean(solver.costs[finite])) if finite.any() else float("inf"),
               "best_cost_equal": float(np.mean(E_pop[:, solver.best_index])),
               "mu_f": solver.mu_f, "mu_cr": solver.mu_cr}
        mean = solver.pop.mean(axis=0)
        xb = solver.x
        for j, n in enumerate(cf.names):
            rec[f"best_{n}"] = float(xb[j])
        for j, n in enumerate(cf.names):
            rec[f"mean_{n}"] = float(mean[j])
        for j, n in enumerate(cf.names):
            rec[f"spread_{n}"] = float(spread[j])
        for j, n in enumerate(cf.names):
            rec[f"cv_{n}"] = float(cv[j])
        for r, rid in enumerate(cf.run_ids):
            rec[f"weight_{rid}"] = float(w[r])
        history.append(rec)
        if progress is not None:
            progress({"generation": g, "generations": generations, "best": float(solver.fun),
                      "spread": float(cv.max()), "evaluations": solver.nfev,
                      "elapsed": time.perf_counter() - t0})
        if spread_tol > 0 and cv.max() < spread_tol:
            stop = "spread"
            break

    x_best = solver.x
    equal = np.full(n_runs, 1.0 / n_runs)
    polish_info = None
    std = np.full(len(cf.names), np.nan)
    if polish and ds.auto_start_runs():
        x_best, polish_info, std, cf = _polish_aligned(ds, cf, x_best, equal)
    elif polish:
        x_best, polish_info, std = _polish(cf, x_best, equal)
    final_E = cf.run_errors(x_best[None])[:, 0]
    P = space.full(x_best[None])[0]
    wall = time.perf_counter() - t0

    details = {}
    for n in space.reported_names:
        d = {"value": float(P[INDEX[n]]), "unit": UNITS[n], "fixed": n in space.fixed,
             "derived": n == space.derived}
        if n in cf.names:
            j = cf.names.index(n)
            d["lower"], d["upper"] = float(cf.bounds[j, 0]), float(cf.bounds[j, 1])
            d["std"] = None if not np.isfinite(std[j]) else float(std[j])
        elif n == space.derived:
            d["std"] = _derived_std(space, polish_info)
            d["lower"] = d["upper"] = None  # follows from the anchor: never searched
        else:
            d["std"] = 0.0
        details[n] = d
    return IdentificationResult(
        parameters={n: float(P[INDEX[n]]) for n in space.reported_names}, details=details, known=dict(ds.known),
        cost=float(equal @ final_E), generations=solver.nit, evaluations=cf.nfev, wall_time_s=wall,
        seed=seed, track_weights={rid: float(w[r]) for r, rid in enumerate(cf.run_ids)},
        weights_mode=weights, polish=polish_info, stop=stop, history=history,
        modal=modal_summary(P, ds.geometry), dataset=str(ds.path), maps=maps,
        preprocessing=ds.preprocessing(), model={"extensions": list(space.extensions)})


def _polish(cf: CostFunction, x0, weights, align=None):
    """Least squares from ``x0``; ``align`` = [(run index, MeasuredRun, start)] adds those starts as unknowns.

    A start enters through the measured data, re-read at ``start + t`` (its
    Jacobian column is minus the data's time derivative); the model's wheel
    inputs stay put (exact for constant speed; with a speed channel the
    outer loop in :func:`_polish_aligned` accounts for the rest).
    """
    lo, hi = cf.bounds[:, 0], cf.bounds[:, 1]
    span = hi - lo
    d = len(cf.names)
    align = align or []

    def to_x(z):
        return lo + span * z

    def start_of(v, k):
        ri, mr, s0 = align[k]
        return s0 + v[d + k] / mr.fs

    def measured(v):
        if not align:
            return None
        Y = cf.Y.copy()
        for k, (ri, mr, _) in enumerate(align):
            a, b = cf.sim.run_start[ri], cf.sim.run_start[ri + 1]
            Y[a:b] = np.nan_to_num(mr.measured_at(start_of(v, k)), nan=0.0)
        return Y

    def fun(v):
        return cf.residuals(to_x(v[:d])[None], weights, Y=measured(v))[0]

    def jac(v):
        h = 1e-7
        z = v[:d]
        Z = np.tile(z, (d + 1, 1))
        steps = np.where(z + h <= 1, h, -h)
        Z[1:][np.arange(d), np.arange(d)] += steps
        R = cf.residuals(to_x(Z), weights, Y=measured(v))
        J = np.zeros((R.shape[1], v.size))
        J[:, :d] = ((R[1:] - R[0]) / steps[:, None]).T
        offsets = np.cumsum([0] + [(e - s) * cf.residual_scale(ri, weights)[0].size
                                   for ri, (s, e) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))])
        for k, (ri, mr, _) in enumerate(align):
            cols, sc = cf.residual_scale(ri, weights)
            dY = np.nan_to_num(mr.measured_at(start_of(v, k), nu=1), nan=0.0)[:, cols]
            J[offsets[ri]:offsets[ri + 1], d + k] = (-dY * sc / mr.fs).ravel()
        return J

    z0 = np.clip((x0 - lo) / span, 0, 1)
    v0 = np.concatenate([z0, np.zeros(len(align))])
    blo = np.concatenate([np.zeros(d), np.full(len(align), -5.0)])
    bhi = np.concatenate([np.ones(d), np.full(len(align), 5.0)])
    sol = least_squares(fun, v0, jac=jac, bounds=(blo, bhi), method="trf", x_scale="jac",
                        ftol=1e-15, xtol=1e-12, gtol=1e-15, max_nfev=100)
    J = sol.jac
    m, n = J.shape
    rss = float(sol.fun @ sol.fun)
    s2 = rss / max(m - n, 1)
    scale = np.concatenate([span, [1.0 / mr.fs for _, mr, _ in align]])
    try:
        cov_all = s2 * np.linalg.inv(J.T @ J) * np.outer(scale, scale)
        std_all = np.sqrt(np.clip(np.diag(cov_all), 0, None))
    except np.linalg.LinAlgError:
        cov_all = np.full((n, n), np.nan)
        std_all = np.full(n, np.nan)
    x = to_x(sol.x[:d])
    info = {"success": bool(sol.success), "message": sol.message, "nfev": int(sol.nfev),
            "cost_before": float(np.sum(fun(v0) ** 2)), "cost_after": 2 * float(sol.cost),
            "covariance": cov_all[:d, :d].tolist(), "names": list(cf.names)}
    if align:
        info["starts"] = {mr.run_id: {"value": start_of(sol.x, k), "std": float(std_all[d + k])}
                          for k, (_, mr, _) in enumerate(align)}
    return x, info, std_all[:d]


#: re-estimate the starts until none moves by more than this fraction of a sample interval
REALIGN_TOL = 1e-3
REALIGN_MAX = 5


def _polish_aligned(ds, cf, x_best, equal):
    """Polish parameters and the estimated starts together; with speed channels, re-simulate and repeat."""
    rounds = []
    for _ in range(REALIGN_MAX):
        align = [(cf.run_ids.index(rid), ds.measured[rid], ds.measured[rid].start) for rid in ds.auto_start_runs()]
        x_best, info, std = _polish(cf, x_best, equal, align)
        changes = {}
        for rid, st in info["starts"].items():
            mr = ds.measured[rid]
            changes[rid] = st["value"] - mr.start
            ds.data[rid] = mr.run_data(st["value"])
            mr.record["start"].update({"source": "estimated with the parameters (least squares)",
                                       "std": st["std"]})
        worst = max(abs(v) * ds.measured[rid].fs for rid, v in changes.items())
        rounds.append({"max_change_samples": worst})
        varying = [rid for rid in changes if ds.measured[rid].distance is not None]
        slipped = _cycle_check(ds, cf.space.full(x_best[None])[0])
        if slipped:
            rounds[-1]["cycle_slips"] = slipped
        elif not varying or worst < REALIGN_TOL:
            break
        # the wheel inputs of speed-channel runs depend on the start: rebuild them and polish again
        nfev = cf.nfev
        cf = CostFunction(ds, space=cf.space)
        cf.nfev = nfev
    info["alignment_rounds"] = rounds
    return x_best, info, std, cf


def _cycle_check(ds, P) -> dict:
    """Constant-speed auto runs: redo the all-lags correlation with the identified car.

    On a periodic track the nominal car may have picked a neighbouring cycle
    (the polish only moves a start by a few samples). Where the identified
    car's correlation peaks more than two samples away, take its start.
    """
    from ..data.measured import _coarse

    slipped = {}
    for rid in ds.auto_start_runs():
        mr = ds.measured[rid]
        if mr.distance is not None:
            continue
        s = _coarse(mr, P, ds.geometry, ds.manifest.tracks[ds.manifest.run(rid).track])
        if abs(s - mr.start) > 2.0 / mr.fs:
            slipped[rid] = s - mr.start
            ds.data[rid] = mr.run_data(s)
    return slipped


def _derived_std(space, polish_info):
    if polish_info is None or space.derived is None:
        return None
    cov = np.array(polish_info["covariance"])
    if not np.all(np.isfinite(cov)):
        return None
    g = space.derived_gradient()
    return float(np.sqrt(max(g @ cov @ g, 0.0)))
