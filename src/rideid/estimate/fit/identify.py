"""Identification: JADE with adaptive track weights, then a least-squares polish.

1. The free parameters and bounds come from the dataset (``[known]``,
   ``[bounds]``, defaults in :data:`rideid.params.DEFAULT_BOUNDS`).
2. The parameter -> track map ``M`` (:mod:`rideid.estimate.problem.sensitivity`) is
   computed around a nominal car (the built-in car scaled to the anchor).
3. JADE evolves the population on ``J = sum_r w_r E_r``. After every
   generation the track weighting (:mod:`rideid.estimate.problem.weighting`;
   ``weights="adaptive"``) takes the normalised spread of each free
   parameter (eq. 12) to new weights ``w ∝ spread @ M`` (eq. 13) and the
   population is re-scored with them before the next generation (no new
   simulation: the per-run errors of every individual are kept).
4. JADE stops after ``generations``, or earlier once every free parameter's
   coefficient of variation in the population is below ``spread_tol``.
5. The polish (SciPy ``least_squares``: dogbox, continued by trust-region
   reflective where dogbox stops beside a bound, :meth:`_Polish.solve`; in
   bound-normalised coordinates, forward-difference Jacobian evaluated as
   one batch) minimises the **equal-weight** cost from the best individual.
   The adaptive weights steer the search; the estimate is defined by the
   equal-weight objective so that adaptive and fixed runs are comparable.
6. Runs whose start was estimated (:mod:`rideid.measured`, ``start =
   "auto"``) were aligned with a nominal car; in the polish their starts
   become unknowns beside the parameters. The model moves, the data never
   do: a start sets the model's time axis against the run's fixed samples
   (and, with a speed channel, its distance profile); the response is
   linearised in each start, and the polish is repeated on the model's new
   time axes until no start moves by more than 1e-3 of a sample interval
   (at most 8 rounds). The caller's dataset is never changed; the starts
   and their standard errors come back in ``result.starts``. Without the
   polish the nominal alignment stands.
7. Standard errors: ``std`` from ``cov = s^2 (J^T J)^+`` (through the SVD of ``J``:
   :func:`rideid.estimate.fit.uncertainty.normal_inverse`) at the optimum with
   ``s^2 = RSS / (m - d)``, assuming white residuals (an optimistic lower
   bound when residuals are correlated or the model is wrong), and
   ``std_robust`` from the HAC sandwich of :mod:`rideid.estimate.fit.uncertainty`
   (residuals correlated in time and across channels, runs independent).
8. Adequacy (:mod:`rideid.estimate.assess.adequacy`): per run and channel, the
   residual level against the quiet lead-in, a whiteness test and the
   decisive test: does the road input explain the prewhitened residual?
9. Damper curves (SPEC §8, group ``damper_curves``): the global search runs
   on the linear model (``c_sf``, ``c_sr`` free; the exact linear kernel,
   ~100x cheaper per candidate than the RK4 nonlinear car, whose cost also
   grows with the stiffest segment of every random candidate); its best car
   starts the curves as ``F = c v``. The knots no run excites with that car
   are frozen (:mod:`rideid.estimate.problem.dampers`), and the polish fits the
   curves with the other parameters on the nonlinear car, its RK4 sub-steps
   pinned at its start (so every differenced residual uses one integrator).
   ``c_sf``, ``c_sr`` and frozen knots are derived; their standard errors
   follow by the delta method (they are linear in the knot forces).
   Without ``[model] damper_knots`` the curves' knots are those of
   setting ``dampers.knee_grid`` (:func:`knee_cost`), and where
   each curve bends is reported with its error bar
   (:func:`rideid.estimate.problem.dampers.knees`).
10. Bump stops (SPEC §8, group ``bump_stops``): the search on the linear
    model as in 9; a scan of clearance and rate per axle from its car
    (:mod:`rideid.estimate.problem.bumps`) starts the polish on the nonlinear car;
    a stop no run reaches is held (not free, reported ``reached: false``
    without standard errors), also when the polished car no longer reaches
    it (the polish is then repeated).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import OptimizeResult

from ...profiling import stage, timing
from ...settings import defaults, legacy_names
from ...data.dataset import Dataset
from ...data.quality import data_quality
from ...errors import DataWarning
from ...model.batch import single_threaded_blas
from ...model.equations import modal_summary
from ...model.params import ALL_NAMES
from ...model.simulator import Simulator
from ..assess.adequacy import advise, assess_fit
from ..assess.details import details_of, mark_bounds, parameter_detail, preprocessing_record
from ..assess.motion import motion_findings, paced_motion
from ..assess.responses import suspension_velocities
from ..assess.sensor_check import sensor_notes
from ..assess.shape import with_shape
from ..problem.build import Problem, build_problem, fit_settings, model_extensions
from ..problem.bumps import bump_block
from ..problem.cost import CostFunction
from ..problem.dampers import add_grid_std, dampers_block
from ..problem.sensitivity import SensitivityMaps, cost_maps
from ..problem.weighting import coefficient_of_variation
from ..result import History, IdentificationResult
from .jade import JadeSolver, make_rng, stop_requested
from .polish import POLISH, mode_restart, restart_record
from .uncertainty import estimate_covariance

#: JADE's population and its early stop before the polish (every free parameter's spread below 20 %: the setting
#: ``identify.spread_tol``).
#: The polish only needs the optimum's basin: on five problems (the built-in car noise-free and at 2 %,
#: an SUV with AR(1) noise, the SUV with bars and tire damping fitted with the full model, a van), two
#: seeds each, every setting from (64, 0.02) to (24, 0.3) ends within 1e-5 standard errors of the same
#: estimate; (32, 0.2) takes 0.3 of the evaluations of the former (64, 0.1) and 0.16 of (64, 0.02)
#: (benchmarks/bench_search.py). 32 is about three times the number of free parameters.
DEFAULT_POPULATION = 32
DEFAULT_GENERATIONS = 400
MESSAGES = {"generations": "Maximum number of generations reached.",
            "spread": "Every free parameter's spread in the population fell below spread_tol.",
            "callback": "Stopped by callback.",
            "start": "No search: polished from the given start."}



@stage("fit")
def identify(ds: Dataset, *, rng=None, seed=None, population: int = DEFAULT_POPULATION,
             generations: int = DEFAULT_GENERATIONS, weights: str = "adaptive", polish: bool = True,
             spread_tol: float | None = None, callback=None, cost: CostFunction | None = None,
             maps: SensitivityMaps | None = None, model=None, start=None,
             assess: bool = True, simulator: Simulator | None = None) -> IdentificationResult:
    """Estimate the ride parameters of a dataset.

    The problem built up front (:func:`rideid.estimate.problem.build.build_problem`) -> global search (JADE
    with track weighting) -> the nonlinear groups' start (:attr:`~rideid.estimate.problem.build.Problem.begin`)
    -> polish (least squares, with the estimated starts of measured runs: :mod:`rideid.estimate.fit.polish`)
    -> error bars -> the result's blocks (:data:`RESULT_BLOCKS`). Neither ``ds`` nor ``cost`` is changed.

    Parameters
    ----------
    ds : Dataset
    rng : int, numpy.random.Generator or None
        Seed or generator of all randomness (same seed, same result). The
        seed, or the generator's starting state, is recorded in the result.
    seed : int, optional
        The older name of ``rng`` (SPEC §5).
    population, generations : int
        JADE's NP and generation limit.
    weights : {"adaptive", "fixed"}
        Adaptive track weights (paper eq. 12-13) or equal weights
        (:class:`rideid.estimate.problem.sensitivity.TrackWeighting`).
    polish : bool
        Refine with ``scipy.optimize.least_squares`` after JADE.
    spread_tol : float, optional
        Stop JADE once every free parameter's coefficient of variation in the
        population is below this (0 disables the early stop). Default 0.2
        with the polish (it only needs the right basin), 1e-5 without.
    callback : callable, optional
        ``callback(state)`` after each generation with an ``OptimizeResult``
        (``x, fun, nit, nfev, generations, spread, elapsed, track_weights``);
        returning True or raising ``StopIteration`` stops the search (the
        polish still runs), as for :func:`rideid.jade`.
    cost : CostFunction, optional
        An existing cost function of ``ds`` to reuse (saves preparing the
        runs); it is copied, never modified.
    maps : SensitivityMaps, optional
        Parameter -> track maps (default: computed around the nominal car).
    model : {None, "base", "full"} or sequence of group names
        The model (SPEC §6): the twelve (``"base"``), with every extension group (``"full"``), or the given
        groups (:func:`~rideid.estimate.problem.build.model_extensions`); ``None``: the dataset's ``[model]``,
        else the twelve (``"auto"``, the model choice, is :func:`rideid.estimate.choice.model_choice.identify`).
        Ignored when ``cost`` is given (its parameter space decides). Known extension values are held fixed
        and used whatever the model.
    start : array_like, shape (d,), optional
        Free-parameter row (the cost's ``names`` order) to polish from,
        skipping the search (used to fit nested models from a larger one).
        With damper curves: the row of the same model with linear dampers
        (``c_sf``, ``c_sr`` free), whose curves ``F = c v`` start the polish,
        or a row of the curve model itself (its knot forces as given).
    assess : bool
        Compute the adequacy verdict (:mod:`rideid.estimate.assess.adequacy`; a few
        seconds); ``False`` leaves ``adequacy`` None.
    simulator : Simulator, optional
        How the car is simulated (backend, integration settings:
        :class:`rideid.model.simulator.Simulator`; default ``Simulator()``),
        for every stage of the fit. Ignored when ``cost`` is given (its own).

    Returns
    -------
    IdentificationResult
    """
    settings = fit_settings(population=population, generations=generations, weights=weights, polish=polish,
                            spread_tol=spread_tol, assess=assess)
    gen, rng_record = make_rng(rng, seed)
    with single_threaded_blas():
        t0 = time.perf_counter()
        problem = build_problem(ds, settings, model=model, cost=cost, simulator=simulator, start=start)
        maps = cost_maps(problem.search) if maps is None else maps
        search = global_search(problem.search, settings.weighting, maps, gen, population=population,
                               generations=problem.search_generations, spread_tol=settings.spread_tol,
                               callback=callback, t0=t0)
        search = problem.started(search)
        cf, x0, excitation, bumps = problem.begin(problem.cost, problem.start_cost, search.x)
        fit, bumps = POLISH[settings.polish](ds, cf, x0, bumps)
        return _result(ds, problem, search, fit, maps, rng_record, t0, excitation, bumps)


@stage("search")
def global_search(cf: CostFunction, weighting, maps: SensitivityMaps, rng, *, population, generations,
                  spread_tol, callback=None, t0=None) -> OptimizeResult:
    """JADE on the weighted cost, the weights updated by ``weighting`` after every generation.

    Returns
    -------
    OptimizeResult
        ``x`` (best individual), ``nit``, ``stop``, ``history`` (list of
        dicts), ``track_weights`` (final, per run).
    """
    t0 = time.perf_counter() if t0 is None else t0
    M_free = maps.submap(cf.names)
    solver = JadeSolver(cf.bounds, population, rng)
    w = weighting.initial(len(cf.run_ids))
    history = []
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
        spread, w_new = weighting.update(M_free, solver.pop, w)
        if w_new is not w:
            w = w_new
            solver.rescore(cf.combine(E_pop, w))
        cv = relative_spread(solver.pop, cf.bounds)
        history.append(_generation_record(g, solver, E_pop, cf, spread, cv, w))
        state = OptimizeResult(x=solver.x, fun=float(solver.fun), nit=g, nfev=solver.nfev, generations=generations,
                               spread=float(cv.max()), elapsed=time.perf_counter() - t0,
                               track_weights=dict(zip(cf.run_ids, w.tolist())))
        if stop_requested(callback, state):
            stop = "callback"
            break
        if spread_tol > 0 and cv.max() < spread_tol:
            stop = "spread"
            break
    return OptimizeResult(x=solver.x, nit=solver.nit, stop=stop, history=history,
                          track_weights={rid: float(w[r]) for r, rid in enumerate(cf.run_ids)})


def relative_spread(pop, bounds) -> np.ndarray:
    """Coefficient of variation of each column; for columns bounded below by 0, std over
    ``max(|mean|, ZERO_SCALE * upper)`` (the early stop of step 4 for a model with extensions)."""
    cv = coefficient_of_variation(pop)
    zero = bounds[:, 0] == 0
    if zero.any():
        P = np.asarray(pop, dtype=float)[:, zero]
        cv[zero] = P.std(axis=0) / np.maximum(np.abs(P.mean(axis=0)), defaults["identify.zero_scale"] * bounds[zero, 1])
    return cv


def _generation_record(g, solver, E_pop, cf, spread, cv, w) -> dict:
    """One row of ``history.csv`` (column names in docs/formats.md)."""
    finite = np.isfinite(solver.costs)
    rec = {"generation": g, "evaluations": solver.nfev, "best_cost": float(solver.fun),
           "mean_cost": float(np.mean(solver.costs[finite])) if finite.any() else float("inf"),
           "best_cost_equal": float(np.mean(E_pop[:, solver.best_index])),
           "mu_f": solver.mu_f, "mu_cr": solver.mu_cr}
    mean = solver.pop.mean(axis=0)
    xb = solver.x
    for prefix, values in (("best", xb), ("mean", mean), ("spread", spread), ("cv", cv)):
        for j, n in enumerate(cf.names):
            rec[f"{prefix}_{n}"] = float(values[j])
    for r, rid in enumerate(cf.run_ids):
        rec[f"weight_{rid}"] = float(w[r])
    return rec


@dataclass(frozen=True)
class _Fitted:
    """What the result's blocks are made from: the problem, the fit, the identified car's full row ``P`` and
    channels ``response``, its error bars ``robust``, the parameters' ``details`` (the damper block adds the knee
    grid's share to them), the knots' ``excitation`` and the stops' ``bumps`` records."""

    ds: Dataset
    problem: Problem
    cf: CostFunction
    P: np.ndarray
    response: dict
    robust: object
    details: dict
    excitation: dict | None
    bumps: dict | None

    @property
    def space(self):
        return self.cf.space

    @property
    def model(self) -> dict:
        return {"extensions": list(self.space.extensions)}


def _adequacy(f: _Fitted) -> dict | None:
    """The adequacy verdict (:mod:`rideid.estimate.assess.adequacy`) with the sensor hints and advice."""
    return sensor_notes(f.ds, f.cf, f.response, advise(assess_fit(f.cf, f.P, f.response), f.model))


def _dampers(f: _Fitted) -> dict:
    """SPEC §8's damper curves; knots found on the knee grid add its approximation error to ``details``."""
    r = f.robust
    block = dampers_block(f.space, f.P, r.white, r.robust, r.names, f.excitation)
    if block.get("knots_from", "").startswith("found"):
        add_grid_std(f.details, block, f.space, f.P)  # the grid's approximation error, in std_robust
    return block


def _velocities(f: _Fitted) -> dict:
    return suspension_velocities(f.cf, f.P)


def _stops(f: _Fitted) -> dict:
    r = f.robust
    return bump_block(f.space, f.P, r.white, r.robust, r.names, f.bumps)


def _modal(f: _Fitted) -> dict:
    """The identified car's modes (its twelve, or the nonlinear layout's car columns)."""
    space = f.space
    return modal_summary(f.P[:len(ALL_NAMES) if space.layout is None else space.layout.n_car], f.ds.geometry)


#: the result's blocks beside the estimate, in the order they are made: ``(field, whether the fit has it, how it
#: is made)``; a block the fit does not have is None (``adequacy`` with ``assess=False``, the damper curves'
#: blocks without curves, ``bump_stops`` without stops)
RESULT_BLOCKS = (
    ("adequacy", lambda f: f.problem.settings.assess, _adequacy),
    ("dampers", lambda f: f.space.curves, _dampers),
    ("velocities", lambda f: f.space.curves, _velocities),
    ("bump_stops", lambda f: f.space.bump, _stops),
    ("modal", lambda f: True, _modal),
)


def _result(ds, problem: Problem, search, fit, maps, rng_record, t0, excitation=None,
            bumps=None) -> IdentificationResult:
    """The result, built once: the estimate, its uncertainty, details and the blocks of :data:`RESULT_BLOCKS`,
    each a function of the fit; ``wall_time_s`` from ``t0`` (``time.perf_counter``) to the end."""
    cf, x = fit.cost, fit.x
    space = cf.space
    final_E = cf.run_errors(x[None])[:, 0]
    P = space.full(x[None])[0]
    robust = estimate_covariance(fit.info, space, x)
    details, findings = details_of(ds, space, P, fit.std, fit.covariance, robust, bumps)
    success = bool(np.all(np.isfinite(x)) and np.isfinite(final_E).all()) and fit.success
    response = cf.simulate(P)
    nfev = int(cf.nfev)  # the fit's evaluations (the adequacy's simulations are not the fit's)
    with timing("error bars' shape"):  # rideid.estimate.assess.shape
        polish = with_shape(cf, x, fit.info)
    fitted = _Fitted(ds, problem, cf, P, response, robust, details, excitation, bumps)
    blocks = {name: make(fitted) if has(fitted) else None for name, has, make in RESULT_BLOCKS}
    # SPEC §13: the speeds the polish estimated with the car (a nonlinear car's runs whose declared speed load moved)
    motion = paced_motion(ds, (fit.info or {}).get("speeds") or {})
    preprocessing = preprocessing_record(ds, fit.starts)
    for rid, m in motion.items():
        preprocessing[rid]["motion"] = m
    return IdentificationResult(
        x=np.asarray(x, dtype=float), names=list(cf.names), std=np.asarray(fit.std, dtype=float),
        covariance=fit.covariance, fun=float(np.full(final_E.size, 1.0 / final_E.size) @ final_E), success=success,
        message=MESSAGES[search.stop] + fit.message, stop=search.stop,
        nit=int(search.nit), nfev=nfev, parameters={n: float(P[space.col[n]]) for n in space.reported_names},
        details=details, known=dict(ds.known), seed=rng_record["seed"],
        rng_state=rng_record["rng_state"], track_weights=search.track_weights,
        weights_mode=problem.settings.weighting.name, polish=polish, history=History(search.history),
        starts=fit.starts, preprocessing=preprocessing, dataset=str(ds.path), maps=maps,
        model=fitted.model, response=response, correlation=robust.correlation_dict(),
        checks=[f.to_dict() for f in findings] + motion_findings(motion), data_quality=data_quality(cf.ds),
        plan=problem.plan(),
        wall_time_s=time.perf_counter() - t0, **blocks)


def warn_bounds(res: IdentificationResult, stacklevel: int = 3) -> None:
    """A :class:`rideid.DataWarning` for each estimate of ``res`` that ended at a search bound, and for each
    run whose speed or start the data moved beyond its prior (SPEC §13, check ``"motion"``).

    :func:`rideid.identify` calls it once for the result it returns (under
    ``model="auto"``: the kept model only); the fits themselves only mark
    ``at_bound`` in ``details`` and list the finding in ``checks``.
    """
    for f in res.checks:
        if f.get("check") == "bounds" or (f.get("check") == "motion" and f.get("severity") == "warning"):
            warnings.warn(f["message"], DataWarning, stacklevel=stacklevel)



__all__ = ["DEFAULT_POPULATION", "DEFAULT_GENERATIONS", "MESSAGES", "identify", "global_search", "relative_spread",
           "warn_bounds", "RESULT_BLOCKS",
           # what the orchestrators (fit/anyroad.py, choice/model_choice.py) import from here, now in their modules
           "model_extensions", "mode_restart", "restart_record", "sensor_notes", "mark_bounds", "parameter_detail"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "DEFAULT_SPREAD_TOL": "identify.spread_tol", "DEFAULT_SPREAD_TOL_NO_POLISH":
    "identify.spread_tol_no_polish", "ZERO_SCALE": "identify.zero_scale", "RESTART_AT_BOUND":
    "identify.restart_at_bound", "REPAIR_RESTARTS": "identify.repair_restarts", "POLISH_MAX_NFEV":
    "identify.polish_max_nfev", "DOGBOX_MAX_NFEV": "identify.dogbox_max_nfev", "BOUND_SNAP":
    "identify.bound_snap", "WARP_BOUND": "identify.warp_bound", "STALL_OPTIMALITY": "identify.stall_optimality",
    "REALIGN_TOL": "identify.realign_tol", "REALIGN_MAX": "identify.realign_max"})
