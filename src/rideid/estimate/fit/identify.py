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

import math
import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from ...profiling import stage
from ...settings import defaults, legacy_names
from ...data.checks import bound_findings
from ...data.dataset import Dataset, lead_ins
from ...data.quality import data_quality, rate_advice
from ...conditioning.starts import cycle_slips, distance_warp, linearise_starts, warped
from ...errors import ArgumentError, DataWarning
from ...model.batch import single_threaded_blas
from ...model.equations import modal_summary
from ...data.schema import NONLINEAR_GROUPS
from ...model.nonlinear import BUMP_STOP_NAMES
from ...model.params import ALL_NAMES, INDEX, NOMINAL_EXTENSIONS, SUSPENSION_GROUPS, UNITS
from ...model.simulator import Simulator
from ..problem.bumps import bump_block, frozen_values, reach, scan_start
from ..problem.dampers import add_grid_std, dampers_block, knot_excitation
from ..assess.responses import suspension_velocities
from ..problem.cost import BUMP_UNITS, IDENTIFIABLE_GROUPS, CostFunction, ParameterSpace, refuse_unsupported_groups
from .jade import JadeSolver, make_rng, stop_requested
from ..assess.adequacy import advise, assess_fit
from ..assess.sensor_check import clipping_advice, coupling_hints
from ..result import History, IdentificationResult
from .uncertainty import jackknife_runs, estimate_covariance, hac_covariance, white_covariance
from ..problem.sensitivity import SensitivityMaps, cost_maps
from ..problem.weighting import TrackWeighting, coefficient_of_variation

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


#: ``--model`` choices handled here (SPEC §6)
MODELS = ("base", "full", "auto")


def model_extensions(ds: Dataset, model=None) -> tuple[str, ...]:
    """Extension groups of the model to fit.

    ``model``: ``None`` (the dataset's ``[model] extensions``, else the
    twelve), ``"base"`` (the twelve), ``"full"`` (SPEC §6's groups:
    anti-roll bars and tire damping), or a sequence of group names.
    """
    if model is None:
        refuse_unsupported_groups(ds.manifest.extensions or (), f"{ds.manifest.path}: [model] extensions")
        return tuple(ds.manifest.extensions or ())
    if isinstance(model, str):
        if model == "base":
            return ()
        if model == "full":
            return tuple(SUSPENSION_GROUPS)
        if model in MODELS:
            raise ArgumentError(f"model {model!r} is not one fitted model")
        model = parse_model_arg(model)
    groups = tuple(model)
    refuse_unsupported_groups(groups)
    for g in groups:
        if g not in IDENTIFIABLE_GROUPS:
            raise ArgumentError(f"unknown extension group '{g}'; groups are: {', '.join(IDENTIFIABLE_GROUPS)}")
    return tuple(g for g in IDENTIFIABLE_GROUPS if g in groups)


def parse_model_arg(model: str):
    """``--model``: ``base``, ``full``, ``auto``, or groups joined by ``,`` or ``+``
    (``damper_curves``, ``damper_curves,anti_roll_bars``) -> the string or a tuple of groups."""
    if model in MODELS:
        return model
    groups = tuple(g.strip() for g in model.replace("+", ",").split(",") if g.strip())
    bad = [g for g in groups if g not in IDENTIFIABLE_GROUPS]
    if not groups or bad:
        refuse_unsupported_groups(bad)
        raise ArgumentError(f"--model must be one of {', '.join(MODELS)}, got {model!r} (or model groups joined "
                            f"by ',': {', '.join(IDENTIFIABLE_GROUPS)})")
    return groups


@stage("fit")
def identify(ds: Dataset, *, rng=None, seed=None, population: int = DEFAULT_POPULATION,
             generations: int = DEFAULT_GENERATIONS, weights: str = "adaptive", polish: bool = True,
             spread_tol: float | None = None, callback=None, cost: CostFunction | None = None,
             maps: SensitivityMaps | None = None, model=None, start=None,
             assess: bool = True, simulator: Simulator | None = None) -> IdentificationResult:
    """Estimate the ride parameters of a dataset.

    Parameter space -> global search (JADE with track weighting) -> polish
    (least squares, with the estimated starts of measured runs) -> result.
    Neither ``ds`` nor ``cost`` is changed.

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
    model : {None, "base", "full", "auto"} or sequence of group names
        The model (SPEC §6): the twelve (``"base"``), with every extension
        group (``"full"``), or the given groups; ``"auto"``: fit the
        candidates and keep the model the data support
        (:func:`rideid.estimate.choice.model_choice.identify_auto`). ``None``: the
        dataset's ``[model]``, else ``"auto"``, as ``rideid identify`` does
        (SPEC §5 amended; :func:`rideid.estimate.choice.model_choice.default_model`;
        the single-model fit :func:`rideid.estimate.fit.identify.identify` takes
        the dataset's ``[model]``, else the twelve). Ignored when ``cost`` is given (its parameter space
        decides). Known extension values are held fixed and used whatever
        the model.
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
    if isinstance(model, str) and model == "auto" and cost is None:
        raise ArgumentError("model='auto' is the model choice of rideid.identify "
                            "(rideid.estimate.choice.model_choice.identify); this function fits one given model")
    if spread_tol is None:
        spread_tol = defaults["identify.spread_tol"] if polish else defaults["identify.spread_tol_no_polish"]
    if not isinstance(generations, (int, np.integer)) or generations < 1:
        raise ArgumentError(f"generations must be a positive integer, got {generations!r}")
    weighting = TrackWeighting.create(weights)
    gen, rng_record = make_rng(rng, seed)
    with single_threaded_blas():
        t0 = time.perf_counter()
        cf = (cost if cost is not None else CostFunction(ds, extensions=model_extensions(ds, model),
                                                         simulator=simulator)).copy()
        # damper curves, bump stops: the search on the linear model (steps 9, 10 of the module docstring)
        # (a start is then the linear model's row: the curves start as its F = c v)
        nonlinear = cf.space.layout is not None
        cf_search = linear_cost(ds, cf) if nonlinear else cf
        if maps is None:
            maps = cost_maps(cf_search)
        search = global_search(cf_search, weighting, maps, gen, population=population,
                               generations=generations if start is None else 0,
                               spread_tol=spread_tol, callback=callback, t0=t0)
        # a start of the curve model's own width: its knot forces as given (not a linear car's F = c v)
        own = start is not None and nonlinear and len(start) == len(cf.names) != len(cf_search.names)
        if finds_knees(cf.space) and not own:  # no [model] damper_knots: the curves on the knee grid
            cf = knee_cost(cf)
        x0 = search.x if start is None else np.asarray(start, dtype=float)
        excitation = bumps = None
        if nonlinear:
            cf, x0, excitation, bumps = nonlinear_start(cf, cf if own else cf_search, x0)
        search = OptimizeResult(dict(search, x=x0, stop=search.stop if start is None else "start"))
        fit = polish_fit(ds, cf, x0) if polish else None
        if fit is not None and cf.space.bump:
            fit, bumps = _bump_recheck(ds, fit, bumps)
        if fit is not None and nonlinear:  # the result's cost function evaluates as any other
            fit.cost = fit.cost.with_pin(None)
        return _result(ds, cf if fit is None else fit.cost, search, fit, weighting, maps, rng_record, t0, assess,
                       excitation, bumps)


def linear_cost(ds, cf: CostFunction) -> CostFunction:
    """The linear model of a damper-curve or bump-stop cost function: the same groups less the curves and
    the stops (``c_sf``, ``c_sr`` free, the linear kernel), the same data and bounds."""
    sp = cf.space
    space = ParameterSpace({k: v for k, v in sp.known.items() if k not in BUMP_STOP_NAMES}, sp.geometry,
                           {k: v for k, v in sp._bounds_arg.items()
                            if not k.startswith("F_") and k not in BUMP_STOP_NAMES},
                           extensions=[g for g in sp.extensions if g not in NONLINEAR_GROUPS])
    return CostFunction(cf.ds, space=space, counter=cf.counter, simulator=cf.simulator)  # one count


def nonlinear_start(cf: CostFunction, cf_search: CostFunction, x):
    """The nonlinear model's start from the search's best car: ``x`` mapped into the nonlinear space (a
    linear car's curves ``F = c v``), its knots' excitation, the space with the knots not excited frozen;
    with bump stops the scan of :func:`rideid.estimate.problem.bumps.scan_start` and the stops not reached held.

    Returns ``(cost function on that space with its sub-steps pinned, start row, excitation, bump record)``.
    """

    space = cf.space
    if cf_search is not cf:
        P_lin = cf_search.space.full(np.asarray(x, dtype=float)[None])[0]
        vals = {n: P_lin[cf_search.space.col[n]] for n in cf_search.space.param_names}
        if space.curves:
            v = space.knot_velocities()
            K = space.layout.n_knots
            for j, n in enumerate(space.knot_names):
                vals[n] = (vals["c_sf"] if j < K else vals["c_sr"]) * v[j]
        for n in BUMP_STOP_NAMES:  # no stop yet: the scan sets the start
            vals.setdefault(n, 0.0 if n.startswith("bs_rate") else 0.15)
        x = np.array([vals[n] for n in space.names])
        x = np.clip(x, space.bounds[:, 0], space.bounds[:, 1])
    excitation = bumps = None
    if space.curves:
        P = space.full(np.asarray(x, dtype=float)[None])[0]
        excitation = knot_excitation(cf, P)
        new = space.with_frozen(excitation["frozen"])
        x = space.reduce(x, new)
        cf, space = cf.with_space(new, counter=cf.counter), new
    if space.bump:
        rates = [x[space.names.index(n)] for n in ("bs_rate_f", "bs_rate_r") if n in space.names]
        if cf_search is not cf or (rates and not any(rates)):  # a linear car's start, or a start without stops
            x, bump_frozen, bumps = scan_start(cf, x)
        else:  # a given start: its stops, held where they are not reached
            bumps, bump_frozen = reach(cf, space.full(np.asarray(x, dtype=float)[None])[0]), {}
            for axle, a in (("front", "f"), ("rear", "r")):
                if not bumps[axle]["reached"]:
                    bump_frozen.update(frozen_values(space, a, bumps[axle]["max_compression"]))
        new = space.with_bump_frozen(bump_frozen)
        x = space.reduce(x, new)
        cf, space = cf.with_space(new, counter=cf.counter), new
    cf2 = cf.with_space(space, counter=cf.counter).pinned_at(space.full(np.asarray(x, dtype=float)[None]))
    return cf2, x, excitation, bumps


def finds_knees(space: ParameterSpace) -> bool:
    """Whether the curves of ``space`` are fitted again on setting ``dampers.knee_grid``: damper
    curves at the default knots (no ``[model] damper_knots``) and no ``[bounds]`` of a knot force (a user's
    knots, or bounds set on the default knots' forces, win)."""
    return space.curves and space.damper_knots is None and not any(k.startswith("F_") for k in space._bounds_arg)


def knee_cost(cf: CostFunction) -> CostFunction:
    """``cf`` on the same model with its curves' knots on setting ``dampers.knee_grid``
    (the same data, simulator settings and evaluation count)."""
    old = cf.space
    space = ParameterSpace(old.known, old.geometry, old._bounds_arg, old.extensions,
                           damper_knots=defaults["dampers.knee_grid"],
                           bump_frozen=old.bump_frozen)
    return CostFunction(cf.ds, space=space, counter=cf.counter, simulator=cf.simulator, use_kernel=cf.use_kernel)


def _bump_recheck(ds, fit, bumps):
    """After the polish: a stop the polished car no longer reaches (fewer than ``MIN_SAMPLES`` samples beyond
    its clearance) is held as not reached and the polish repeated (at most twice).

    Returns the fit and a new bump record (``bumps`` is not changed)."""

    for _ in range(2):
        cf = fit.cost
        space = cf.space
        P = space.full(fit.x[None])[0]
        r = reach(cf, P)
        add = {}
        bumps = dict(bumps)
        for axle, a in (("front", "f"), ("rear", "r")):
            free = any(f"bs_{k}_{a}" in space.names for k in ("clear", "rate"))
            held = (free and not r[axle]["reached"]) or f"bs_clear_{a}" in space.bump_frozen
            bumps[axle] = {**bumps.get(axle, {}), **r[axle], **({"reached": False} if held else {})}
            if free and not r[axle]["reached"]:
                add.update(frozen_values(space, a, r[axle]["max_compression"]))
        if not add:
            break
        new = space.with_bump_frozen({**space.bump_frozen, **add})
        x = space.reduce(fit.x, new)
        cf2 = cf.with_space(new, counter=cf.counter).with_pin(None).pinned_at(new.full(x[None]))
        fit = polish_fit(ds, cf2, x)
    return fit, bumps


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


@stage("polish")
def polish_fit(ds: Dataset, cf: CostFunction, x0) -> OptimizeResult:
    """Least squares on the equal-weight cost from ``x0``; estimated starts join as unknowns. A mode of the
    powertrain that ends at a search bound is polished again from typical values (:func:`mode_restart`), and
    the lower cost kept (``info["mode_restart"]`` says what was tried and what it gave).

    Returns
    -------
    OptimizeResult
        ``x``, ``std``, ``info`` (the ``polish`` block of result.json),
        ``cost`` (the cost function on the final data), ``starts`` (run id ->
        start record, for runs whose start was estimated).
    """
    equal = np.full(len(cf.run_ids), 1.0 / len(cf.run_ids))

    def once(x_start):
        if ds.auto_start_runs:
            x, info, std, cf_, starts = _polish_aligned(ds, cf, x_start, equal)
        else:
            (x, info, std), cf_, starts = _polish(cf, x_start, equal), cf, {}
        return OptimizeResult(x=x, std=std, info=info, cost=cf_, starts=starts)

    fit = once(x0)
    restart = mode_restart(cf.space, fit.x)
    if restart is not None:
        other = once(restart[0])
        record = restart_record(restart[1], fit.info["cost_after"], other.info["cost_after"],
                                cf.space, fit.x, other.x)
        fit = other if other.info["cost_after"] < fit.info["cost_after"] else fit
        fit.info["mode_restart"] = record
    return fit


#: the powertrain's modes a polish may leave switched off at a search bound (a local minimum: the mode's
#: inertia or frequency at its bound, its effect on the body nil, the unsprung masses taking up what it leaves),
#: and the typical values (:data:`rideid.model.params.NOMINAL_EXTENSIONS`) a second polish starts them from
RESTART_MODES = {"the engine's pitch mode": ("I_p", "f_pp", "zeta_pp"),
                 "the engine's bounce mode": ("f_pb", "zeta_pb")}


def mode_restart(space: ParameterSpace, x) -> tuple[np.ndarray, list] | None:
    """A second start for a polish that left a powertrain mode at a search bound, or None.

    Measured on the all-realities case (tests/realities_case.py, seed 3, three runs): the search ends with the
    engine's pitch mode at its bounds (I_p 1 kg m^2, f_pp 5 Hz, zeta_pp 0.02), the polish moves it to 5.6 Hz
    with I_p still at 1, and the unsprung masses carry what the mode leaves (+2.4 / +2.8 %). Polished again from
    the typical mode (13 Hz, damping 0.1, I_p at the nominal radius of gyration: 9 and 18 Hz gave the same end),
    the pitch mode lands at 13.0 Hz (the truth), at a lower cost on both stages (the tracks as drawn and as
    built), and the unsprung masses within 0.7 %. Returns ``(x, modes)``: the free row with each such mode's
    free parameters at typical values, and the modes' names; None when no mode is at a bound, the powertrain's
    mass is, or the typical row is not a physical car."""
    names = list(space.names)
    x = np.asarray(x, dtype=float)
    lo, hi = space.bounds[:, 0], space.bounds[:, 1]
    rel = (x - lo) / np.where(hi > lo, hi - lo, 1.0)
    at = {n for j, n in enumerate(names) if min(rel[j], 1.0 - rel[j]) < defaults["identify.restart_at_bound"]}
    if not at or "m_p" in at:
        return None
    P = space.full(x[None])[0]
    alt, modes = x.copy(), []
    for mode, members in RESTART_MODES.items():
        if not at & set(members):
            continue
        modes.append(mode)
        for n in members:
            if n in names:
                v = NOMINAL_EXTENSIONS[n]
                if n == "I_p":  # the nominal radius of gyration at this engine's mass
                    v *= P[INDEX["m_p"]] / NOMINAL_EXTENSIONS["m_p"]
                j = names.index(n)
                alt[j] = min(max(v, lo[j]), hi[j])
    if not modes or not space.valid(space.full(alt[None]))[0]:
        return None
    return alt, modes


def restart_record(modes, cost, cost_restart, space, x, x_restart) -> dict:
    """``polish.mode_restart`` of result.json: the modes started again, both costs, which was kept, and the
    parameters of both ends (the mode's and the twelve)."""
    names = list(space.names)
    return {"modes": list(modes), "cost": float(cost), "cost_restart": float(cost_restart),
            "kept": "restart" if cost_restart < cost else "first",
            "first": {n: float(v) for n, v in zip(names, x)},
            "restart": {n: float(v) for n, v in zip(names, x_restart)},
            "note": "a powertrain mode at a search bound (switched off) was polished again from typical values "
                    "(rideid.estimate.fit.identify.mode_restart); the lower cost is kept"}


def _result(ds, cf, search, fit, weighting, maps, rng_record, t0, assess=True,
            excitation=None, bumps=None) -> IdentificationResult:
    """The result, built once: the estimate, its uncertainty, details, adequacy and modes, each a function
    of the fit; ``wall_time_s`` from ``t0`` (``time.perf_counter``) to the end."""
    space = cf.space
    x = search.x if fit is None else fit.x
    d = len(cf.names)
    std = np.full(d, np.nan) if fit is None else fit.std
    info = None if fit is None else fit.info
    cov = np.full((d, d), np.nan) if info is None else np.array(info["covariance"], dtype=float)
    final_E = cf.run_errors(x[None])[:, 0]
    P = space.full(x[None])[0]
    robust = estimate_covariance(info, space, x)
    details, findings = _details(ds, space, P, std, cov, robust, bumps)
    starts = {} if fit is None else fit.starts
    finite = bool(np.all(np.isfinite(x)) and np.isfinite(final_E).all())
    success = finite and (info is None or bool(info["success"]))
    message = MESSAGES[search.stop] + ("" if info is None else f" Polish: {info['message']}")
    response = cf.simulate(P)
    nfev = int(cf.nfev)  # the fit's evaluations (the adequacy's simulations are not the fit's)
    model = {"extensions": list(space.extensions)}
    adequacy = advise(assess_fit(cf, P, response), model) if assess else None
    if adequacy is not None:
        adequacy = sensor_notes(ds, cf, response, adequacy)
    dampers = None if not space.curves else dampers_block(space, P, robust.white, robust.robust, robust.names,
                                                          excitation)
    if dampers is not None and dampers.get("knots_from", "").startswith("found"):
        add_grid_std(details, dampers, space, P)  # the grid's approximation error, in std_robust
    velocities = suspension_velocities(cf, P) if space.curves else None
    stops = None if not space.bump else bump_block(space, P, robust.white, robust.robust, robust.names, bumps)
    correlation, history = robust.correlation_dict(), History(search.history)
    # what the data were and what the car's modes are: records beside the fit
    preprocessing = _preprocessing(ds, starts)
    modal = modal_summary(P[:len(ALL_NAMES) if space.layout is None else space.layout.n_car], ds.geometry)
    return IdentificationResult(
        x=np.asarray(x, dtype=float), names=list(cf.names), std=np.asarray(std, dtype=float), covariance=cov,
        fun=float(np.full(final_E.size, 1.0 / final_E.size) @ final_E), success=success, message=message,
        stop=search.stop,
        nit=int(search.nit), nfev=nfev, parameters={n: float(P[space.col[n]]) for n in space.reported_names},
        details=details, known=dict(ds.known), seed=rng_record["seed"],
        rng_state=rng_record["rng_state"], track_weights=search.track_weights, weights_mode=weighting.name,
        polish=info, history=history, starts=starts, preprocessing=preprocessing,
        modal=modal, dataset=str(ds.path), maps=maps,
        model=model, response=response, velocities=velocities, correlation=correlation, adequacy=adequacy,
        checks=[f.to_dict() for f in findings], dampers=dampers, bump_stops=stops,
        data_quality=data_quality(cf.ds), wall_time_s=time.perf_counter() - t0)


def sensor_notes(ds, cf, response, adequacy: dict | None) -> dict | None:
    """``adequacy`` with ``sensor_hints`` (channels that look AC-coupled without a declared ``highpass``,
    :func:`rideid.estimate.assess.sensor_check.coupling_hints`) and, when not adequate, advice that names them and
    the clipped channels among the flagged pairs first (:func:`rideid.estimate.assess.sensor_check.clipping_advice`);
    None when the adequacy was not assessed. ``cf`` and ``response``: the fit's cost function at its final starts
    and the identified car's channels."""
    if adequacy is None:
        return None
    hints = coupling_hints(cf, response)
    out = {**adequacy, "sensor_hints": hints}
    if not adequacy.get("adequate", True):
        first = [h["message"] + "." for h in hints[:4]]
        clip = clipping_advice(ds, adequacy)
        if clip:
            first.append(clip)
        rate = rate_advice(ds, adequacy)  # a rate the file's is no whole multiple of: its filter, roughly modelled
        if rate:
            first.append(rate)
        if first:
            out["advice"] = " ".join(first) + " " + (adequacy.get("advice") or "")
    return out


def _details(ds, space, P, std, cov, robust, bumps):
    """``details`` (name -> :func:`parameter_detail`, with the knots not excited, the stops not reached and
    the estimates at a bound marked) and the findings of the data and bound checks."""
    details = {}
    for n in space.reported_names:
        e = parameter_detail(space, P, n, std, cov, robust)
        if n in space.frozen:  # a knot no run excites: continued, not measured
            e["std"] = e["std_robust"] = None
            e["excited"] = False
            e["note"] = "not excited"
        elif n.startswith("F_"):
            e["excited"] = True
        if n in BUMP_STOP_NAMES:  # a stop no run reaches: held, not measured
            e["reached"] = n not in space.bump_frozen and bool(
                ((bumps or {}).get("front" if n.endswith("_f") else "rear") or {}).get("reached", True))
            if not e["reached"] and not e["fixed"]:
                e["std"] = e["std_robust"] = None
                e["note"] = "not reached"
        details[n] = e
    # an estimate the bound stopped, not the data (rideid.data.checks); warned of by rideid.identify, once,
    # for the model it returns (warn_bounds), not for every candidate fitted on the way
    return details, list(getattr(ds, "findings", [])) + mark_bounds(details)


def mark_bounds(details: dict) -> list:
    """The findings of the estimates in ``details`` that ended at a search bound
    (:func:`rideid.data.checks.bound_findings`), each such entry marked ``at_bound``."""
    found = bound_findings(details)
    for f in found:
        details[f.channel]["at_bound"] = True
    return found


#: ``preprocessing.<run>.moving_start.method`` of a run that begins moving, fitted on its track (SPEC §9)
MOVING_START_METHOD = ("simulated from rest lead_in_s before the first sample on the track's road before x = 0, "
                       "compared from the first sample on; the first left_out_s s of the run not compared (the "
                       "profile known less than a settling time before x = 0); docs/any-road.md")


def _preprocessing(ds, starts) -> dict:
    """The dataset's preprocessing record with the starts the fit settled; ``model_time``, the samples' span of
    model time, at those starts (the samples stay those read at the first start, their model times move); a run
    that begins moving on its track with its lead-in (``moving_start``, :func:`rideid.data.dataset.run_lead_in`)."""
    pre = ds.preprocessing()
    for r, lead in zip(ds.runs, lead_ins(ds)):
        if getattr(r, "moving", False) and r.road_known:
            fs = float(ds.data[r.id].fs)
            pre[r.id]["moving_start"] = {"lead_in_s": lead.samples / fs, "left_out_s": lead.settle / fs,
                                         "method": MOVING_START_METHOD}
    for r in ds.runs:
        held = held_motion(ds, r)
        if held is not None:
            pre[r.id]["motion"] = held
    for rid, st in starts.items():
        before = pre[rid].get("start", {}).get("value")
        pre[rid]["start"] = dict(pre[rid].get("start", {}), **st)
        if pre[rid].get("model_time") is not None and before is not None and st.get("value") is not None:
            pre[rid]["model_time"] = [t + before - st["value"] for t in pre[rid]["model_time"]]
    return pre


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


#: the note of a free parameter the polish's Jacobian does not determine (rideid.estimate.fit.uncertainty)
NOT_IDENTIFIED = ("not identified: the data determine it only in combination with other parameters, or not at "
                  "all (a singular value of the Jacobian below RANK_RTOL of the largest); no standard error")


def parameter_detail(space, P, n: str, std, cov, robust) -> dict:
    """Parameter ``n``'s ``result.json`` entry: value, unit, fixed/derived, search bounds, ``std`` (white)
    and ``std_robust``, from the full row ``P``, the free parameters' ``std`` and white covariance ``cov``
    and the :class:`~rideid.estimate.fit.uncertainty.EstimateCovariance` ``robust``."""
    e = {"value": float(P[space.col[n]]), "unit": UNITS.get(n, BUMP_UNITS.get(n, "N")), "fixed": n in space.fixed,
         "derived": n in space.derived_names()}
    if n in space.names:
        j = space.names.index(n)
        e["lower"], e["upper"] = float(space.bounds[j, 0]), float(space.bounds[j, 1])
        e["std"] = None if not np.isfinite(std[j]) else float(std[j])
        if np.isinf(std[j]):
            e["note"] = NOT_IDENTIFIED
    elif n == space.derived:
        e["std"] = _derived_std(space, cov)
        e["lower"] = e["upper"] = None  # follows from the anchor: never searched
    elif e["derived"]:
        e["std"] = robust.std_white(n)
        e["lower"] = e["upper"] = None
    else:
        e["std"] = 0.0
    e["std_robust"] = robust.std_robust(n) if n not in space.fixed else 0.0
    if n not in space.fixed and robust.jackknife is not None:
        # the runs' disagreement beyond their noise (docs/uncertainty.md "Between runs") is part of the robust
        # standard error: the HAC sandwich's share is std_hac
        e["std_jackknife"] = robust.std_jackknife(n)
        e["std_between_runs"] = between = robust.std_between_runs(n)
        if between and e["std_robust"] is not None:
            e["std_hac"] = e["std_robust"]
            e["std_robust"] = float(math.hypot(e["std_robust"], between))
    return e


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


def _polish(cf: CostFunction, x0, weights, align=None):
    """Least squares from ``x0``; ``align`` = [:class:`_Shift`] adds those runs' starts as unknowns.

    The model moves, the data never do: a start changed by ``delta`` moves the
    model's time axis, ``y(t - delta)``, linearised as ``y + delta D`` with
    ``D = dy/d(start)`` from :func:`rideid.conditioning.starts.linearise_starts` (its Jacobian column).
    The linearisation is centred again by :func:`_polish_aligned` until the
    starts settle, so at the end it is exact.

    With damper curves a solve that ends on a row the monotone repair changes (a knot force below its
    inner neighbour: :meth:`ParameterSpace.full` hides it, so its gradient is 0 and the solver stops
    there) is solved again from the physical row, the forces the simulator saw (setting ``identify.repair_restarts``).

    Returns ``(x, info, std)``: the free parameters, the ``polish`` block of result.json and the
    parameters' white standard errors (:class:`_Polish`).
    """
    prob = _Polish(cf, np.asarray(weights, dtype=float), tuple(align or ()))
    if prob.has_warps:
        # the prior rows weigh a knot's increment against the data at the data's residual level
        v0 = np.concatenate([np.clip((x0 - prob.lo) / prob.span, 0, 1), np.zeros(prob.n_unknowns - prob.d)])
        r0 = cf.residuals(x0[None], prob.weights, Y=prob.measured(v0))[0]
        prob = replace(prob, prior_scale=float(np.sqrt(np.mean(r0 ** 2))))
    sol = prob.solve(x0)
    for _ in range(defaults["identify.repair_restarts"] if cf.space.curves else 0):
        x = prob.to_x(sol.x[:prob.d])
        physical = cf.space.reduce(x, cf.space)
        if np.array_equal(physical, x):
            break
        sol = prob.solve(physical, sol.x[prob.d:])
    info, std = prob.info(sol, x0)
    return prob.to_x(sol.x[:prob.d]), info, std


@stage("polish")
def polish_fixed_starts(cf: CostFunction, x0, weights):
    """The least-squares polish from ``x0`` with the runs as ``cf`` reads them (no start among the unknowns):
    ``(x, info, std)`` as :func:`_polish` returns them (the materiality refits, rideid.estimate.assess.materiality)."""
    return _polish(cf, x0, weights)


@dataclass(frozen=True)
class _Polish:
    """The polish's least-squares problem in bound-normalised coordinates ``v = (z, start shifts)``.

    ``z`` in ``[0, 1]`` per free parameter (``x = lo + span z``), then one shift per run of ``align``
    (samples, ``[-5, 5]``). The residuals are the cost function's at ``weights``; the measured data of an
    aligned run move by ``delta D`` (the start's linearisation, :func:`_polish`).
    """

    cf: CostFunction
    weights: np.ndarray
    align: tuple = ()
    #: the residual noise level the distance corrections' prior rows are scaled to (:meth:`prior_rows`)
    prior_scale: float = 1.0
    #: the residuals of the last :meth:`residuals` call: least_squares asks for the Jacobian where it just
    #: evaluated (a memo, not state of the problem)
    _last: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def d(self) -> int:
        return len(self.cf.names)

    @property
    def lo(self) -> np.ndarray:
        return self.cf.bounds[:, 0]

    @property
    def span(self) -> np.ndarray:
        return self.cf.bounds[:, 1] - self.cf.bounds[:, 0]

    def to_x(self, z) -> np.ndarray:
        """Bound-normalised ``z`` -> parameters ``x``."""
        return self.lo + self.span * z

    def start_of(self, v, k) -> float:
        """The start (file time, s) of ``align[k]`` at ``v``."""
        return self.align[k].start + v[self.d + k] / self.align[k].fs

    @property
    def warp_slices(self) -> list:
        """Per run of ``align``: the slice of ``v`` holding its distance correction's free knots (or None)."""
        out, i = [], self.d + len(self.align)
        for sh in self.align:
            if sh.warp is None:
                out.append(None)
            else:
                n = sh.warp.free.size
                out.append(slice(i, i + n))
                i += n
        return out

    @property
    def n_unknowns(self) -> int:
        return self.d + len(self.align) + sum(sh.warp.free.size for sh in self.align if sh.warp is not None)

    def prior_rows(self, v):
        """The distance corrections' prior residuals ``s A (w + dw) / sigma`` (the random walk's increments,
        :meth:`rideid.conditioning.starts.DistanceWarp.prior`, scaled to the data's residual level ``s``) and
        their Jacobian ``(rows, v.size)``."""
        rows, jac = [], []
        for sh, sl in zip(self.align, self.warp_slices):
            if sl is None:
                continue
            A, sigma = sh.warp.prior()
            M = self.prior_scale * A / sigma[:, None]
            rows.append(M @ (sh.warp.values[sh.warp.free] + v[sl]))
            Jp = np.zeros((A.shape[0], v.size))
            Jp[:, sl] = M
            jac.append(Jp)
        if not rows:
            return np.zeros(0), np.zeros((0, v.size))
        return np.concatenate(rows), np.vstack(jac)

    def measured(self, v):
        """The measured data with each aligned run moved by its shift's linearisation (None: no shift)."""
        if not self.align:
            return None
        cf, d = self.cf, self.d
        Y = cf.Y.copy()
        for k, (sh, sl) in enumerate(zip(self.align, self.warp_slices)):
            a, b = cf.sim.run_start[sh.run_index], cf.sim.run_start[sh.run_index + 1]
            Y[a:b] -= (v[d + k] / sh.fs) * sh.D  # y_model + delta D - y  ==  y_model - (y - delta D)
            if sl is not None:
                Y[a:b] -= np.tensordot(v[sl], sh.Dw, axes=1)
        return Y

    def residuals(self, v) -> np.ndarray:
        """Stacked weighted residuals ``(m,)`` at ``v``, the distance corrections' prior rows last."""
        r = self.cf.residuals(self.to_x(v[:self.d])[None], self.weights, Y=self.measured(v))[0]
        self._last["v"], self._last["r"] = v.copy(), r
        return np.concatenate([r, self.prior_rows(v)[0]]) if self.has_warps else r

    @property
    def has_warps(self) -> bool:
        return any(sh.warp is not None for sh in self.align)

    def jacobian(self, v) -> np.ndarray:
        """``(m, d + len(align))``: forward differences (step 1e-7 in ``z``) as one batch, the shifts' columns
        from their ``D``."""
        d, cf = self.d, self.cf
        D = self._differences(v)
        J = np.zeros((D.shape[0], v.size))
        J[:, :d] = D
        offsets = self._run_offsets()
        for k, (sh, sl) in enumerate(zip(self.align, self.warp_slices)):
            cols, sc = cf.residual_scale(sh.run_index, self.weights)
            rows = slice(offsets[sh.run_index], offsets[sh.run_index + 1])
            J[rows, d + k] = (sh.D[:, cols] * sc / sh.fs).ravel()
            if sl is not None:
                J[rows, sl] = (sh.Dw[:, :, cols] * sc).reshape(sh.Dw.shape[0], -1).T
        return np.vstack([J, self.prior_rows(v)[1]]) if self.has_warps else J

    def _differences(self, v) -> np.ndarray:
        """The parameters' forward-difference columns ``(m, d)`` at ``v`` (the last residuals reused)."""
        h = 1e-7
        z = v[:self.d]
        steps = np.where(z + h <= 1, h, -h)
        Z = np.tile(z, (self.d, 1))
        Z[np.arange(self.d), np.arange(self.d)] += steps
        Yv = self.measured(v)
        R = self.cf.residuals(self.to_x(Z), self.weights, Y=Yv)
        last = self._last
        r0 = last["r"] if "v" in last and np.array_equal(last["v"], v) else self.cf.residuals(
            self.to_x(z[None]), self.weights, Y=Yv)[0]
        return ((R - r0) / steps[:, None]).T

    def _run_offsets(self) -> np.ndarray:
        """Row where each run's residuals start in the stacked vector (and the end)."""
        cf = self.cf
        return np.cumsum([0] + [(e - s) * cf.residual_scale(ri, self.weights)[0].size
                                for ri, (s, e) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))])

    def solve(self, x0, shifts=None) -> OptimizeResult:
        """Bounded least squares from ``x0`` (shifts from ``shifts``, samples, else 0): dogbox, finished by trf
        where dogbox stalls.

        dogbox, not trf: an extension whose true value is its bound (an anti-roll bar or tire damping of 0)
        is held on the bound in one step, where trf's reflective scaling only halves the distance to it each
        iteration (28 iterations instead of 8 on the built-in car, the same answer to 1e-13). But dogbox
        holds a variable on its bound only when it lies exactly there, and it stops short beside a bound in
        two ways. A variable a rounding error inside its bound (a Gauss-Newton step that lands an extension
        on 0 leaves it at 1e-15) cuts every later step to that distance: dogbox ends on ``xtol`` after one
        step, far from the optimum, its gradient still large (setting ``identify.stall_optimality``). A variable on its
        bound whose gradient points inward while the Gauss-Newton step points outward is released, and
        every step is cut where it meets the bound again: a crawl to ``max_nfev``, each step taking a few
        parts in 1e5 off the cost. So: a start that close to a bound is put on it (setting ``identify.bound_snap``);
        dogbox gets setting ``identify.dogbox_max_nfev`` evaluations; a dogbox that ran out of them, or ended that close
        to a bound without being on it and short of the optimum, is continued by trf from where it stopped,
        within the polish's setting ``identify.polish_max_nfev`` in all (the lower cost of the two is the result).
        """
        d, n_al = self.d, len(self.align)
        n_w = self.n_unknowns - d - n_al
        z0 = np.clip((x0 - self.lo) / self.span, 0, 1)
        v0 = np.concatenate([z0, np.zeros(n_al + n_w) if shifts is None else np.asarray(shifts, dtype=float)])
        blo = np.concatenate([np.zeros(d), np.full(n_al, -5.0), np.full(n_w, -defaults["identify.warp_bound"])])
        bhi = np.concatenate([np.ones(d), np.full(n_al, 5.0), np.full(n_w, defaults["identify.warp_bound"])])
        near = defaults["identify.bound_snap"] * (bhi - blo)
        v0 = np.where(v0 - blo < near, blo, np.where(bhi - v0 < near, bhi, v0))
        sol = self._least_squares(v0, (blo, bhi), "dogbox", defaults["identify.dogbox_max_nfev"])
        beside = ((sol.x - blo < near) & (sol.x != blo)) | ((bhi - sol.x < near) & (sol.x != bhi))
        if sol.status == 0 or (beside.any() and sol.optimality > defaults["identify.stall_optimality"]):
            more = self._least_squares(sol.x, (blo, bhi), "trf", defaults["identify.polish_max_nfev"] - sol.nfev)
            more.nfev += sol.nfev
            if more.cost <= sol.cost:
                return more
            sol.nfev = more.nfev
        return sol

    def _least_squares(self, v0, bounds, method, max_nfev) -> OptimizeResult:
        return least_squares(self.residuals, v0, jac=self.jacobian, bounds=bounds, method=method,
                             x_scale="jac", ftol=1e-15, xtol=1e-12, gtol=1e-15, max_nfev=max_nfev)

    def scale(self) -> np.ndarray:
        """``dx/dv`` of every unknown: the bounds' spans, one sample interval per shift, 1 per knot (m)."""
        return np.concatenate([self.span, [1.0 / sh.fs for sh in self.align],
                               np.ones(self.n_unknowns - self.d - len(self.align))])

    def covariance(self, sol):
        """White covariance ``s^2 (J^T J)^+`` of every unknown in its own units, and its standard errors
        (:func:`rideid.estimate.fit.uncertainty.white_covariance`: SVD, unidentified directions inf/NaN)."""
        sc = self.scale()
        cov = white_covariance(sol.jac, sol.fun) * np.outer(sc, sc)
        with np.errstate(invalid="ignore"):
            return cov, np.sqrt(np.clip(np.diag(cov), 0, None))

    def robust(self, sol):
        """HAC covariance of every unknown in its own units (runs as independent blocks of samples, see
        :mod:`rideid.estimate.fit.uncertainty`) and the runs' bandwidths."""
        cf = self.cf
        blocks = self.run_blocks()
        n_prior = sol.fun.size - sum(t * c for t, c in blocks)
        if n_prior:  # the distance corrections' prior rows: independent pseudo-observations, one block
            blocks.append((n_prior, 1))
        hac = hac_covariance(sol.jac, sol.fun, blocks)
        return hac.cov * np.outer(self.scale(), self.scale()), hac.bandwidths[:len(cf.run_ids)]

    def run_blocks(self) -> list:
        """``(n_time, n_channel)`` of each run's residuals, in their order (the prior rows not among them)."""
        cf = self.cf
        return [(int(e - s), int(np.count_nonzero(cf.W[ri] > 0)))
                for ri, (s, e) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))]

    def jackknife(self, sol):
        """The delete-one-run jackknife covariance of every unknown in its own units and its number of runs
        (:func:`rideid.estimate.fit.uncertainty.jackknife_runs`; None with fewer than 3 runs to leave out)."""
        cov, k = jackknife_runs(sol.jac, sol.fun, self.run_blocks(), n_checked=self.d)
        return (None if cov is None else cov * np.outer(self.scale(), self.scale())), k

    def info(self, sol, x0):
        """The ``polish`` block of result.json (the starts of ``align`` under ``starts``) and the free
        parameters' white standard errors ``(d,)``."""
        d, cf = self.d, self.cf
        v0 = np.concatenate([np.clip((x0 - self.lo) / self.span, 0, 1), np.zeros(self.n_unknowns - self.d)])
        cov_all, std_all = self.covariance(sol)
        cov_rob, bandwidths = self.robust(sol)
        cov_jack, k_jack = self.jackknife(sol)
        with np.errstate(invalid="ignore"):
            std_rob = np.sqrt(np.clip(np.diag(cov_rob), 0, None))
        info = {"success": bool(sol.success), "message": sol.message, "nfev": int(sol.nfev),
                "cost_before": float(np.sum(self.residuals(v0) ** 2)), "cost_after": 2 * float(sol.cost),
                "covariance": cov_all[:d, :d].tolist(), "names": list(cf.names),
                "covariance_robust": cov_rob[:d, :d].tolist(),
                "covariance_jackknife": None if cov_jack is None else cov_jack[:d, :d].tolist(),
                "jackknife_runs": k_jack,
                "hac_bandwidths": {rid: float(b) for rid, b in zip(cf.run_ids, bandwidths)}}
        if self.align:
            info["starts"] = {sh.run_id: {"value": self.start_of(sol.x, k), "std": float(std_all[d + k]),
                                          "std_robust": float(std_rob[d + k])}
                              for k, sh in enumerate(self.align)}
            for sh, sl in zip(self.align, self.warp_slices):
                if sl is not None:
                    w = sh.warp.with_free(sh.warp.values[sh.warp.free] + sol.x[sl])
                    info["starts"][sh.run_id]["distance_correction"] = w.record(std_all[sl])
        return info, std_all[:d]


@dataclass(frozen=True)
class _Shift:
    """A run whose start joins the polish: its index in the cost, id, rate, start and ``D = dy/d(start)``."""

    run_index: int
    run_id: str
    fs: float
    start: float
    D: np.ndarray
    #: a noisy speed channel's distance correction (:class:`rideid.conditioning.starts.DistanceWarp`, as the
    #: runs are read now) and the response's derivative with respect to its free knots ``(K, n, 10)``
    warp: object = None
    Dw: np.ndarray | None = None


@stage("polish with starts")
def _polish_aligned(ds, cf, x_best, equal):
    """Polish the parameters and the estimated starts together, centring the starts' linearisation
    again (new model time axes, the same samples) until no start moves by more than
    ``REALIGN_TOL`` of a sample interval; a constant-speed run whose correlation with the polished car
    peaks a cycle away (:func:`rideid.conditioning.starts.cycle_slips`) is moved there.

    Each round reads the runs at the current starts with the derivative of the car's response there
    (:func:`rideid.conditioning.starts.linearise_starts`) and polishes; once the starts settle, the runs
    are read at the settled starts (no derivative) and the cost function on them is returned.
    Works on its own copy of the run data: ``ds`` is not changed.
    """
    starts = {rid: ds.measured[rid].start for rid in ds.auto_start_runs}
    warps = {rid: w for rid in starts if (w := distance_warp(ds.measured[rid], starts[rid])) is not None}
    rounds, settled = [], False
    for _ in range(defaults["identify.realign_max"] + 1):
        P = cf.space.full(x_best[None])[0]
        last = settled or len(rounds) == defaults["identify.realign_max"]
        ds_now, D, Dw = linearise_starts(warped(ds, warps), P, starts, cf.simulator, derivative=not last,
                                         warps=warps)
        # the model's time axes moved with the starts: the cost function (space, simulator, pin) on them
        cf = cf.with_data(ds_now)
        if last:
            break
        shifts = [_Shift(cf.run_ids.index(rid), rid, ds.measured[rid].fs, s, D[rid], warps.get(rid), Dw.get(rid))
                  for rid, s in starts.items()]
        x_best, info, std = _polish(cf, x_best, equal, shifts)
        fitted = {rid: st["value"] for rid, st in info["starts"].items()}
        worst = max(abs(v - starts[rid]) * ds.measured[rid].fs for rid, v in fitted.items())
        # a distance correction's largest change, in sample intervals at the run's mean speed
        for rid, w in warps.items():
            new = np.asarray(info["starts"][rid]["distance_correction"]["values_m"])
            v_mean = max(float(ds.measured[rid].record.get("speed", {}).get("mean") or 1.0), 1e-3)
            worst = max(worst, float(np.max(np.abs(new - w.values))) * ds.measured[rid].fs / v_mean)
            warps[rid] = replace(w, values=new)
        moved = cycle_slips(ds, cf.space.full(x_best[None])[0], fitted, cf.simulator)
        slipped = {rid: s - fitted[rid] for rid, s in moved.items()}
        starts = {**fitted, **moved}
        rounds.append({"max_change_samples": worst, **({"cycle_slips": slipped} if slipped else {})})
        settled = not slipped and worst < defaults["identify.realign_tol"]
    out = {rid: {"value": float(starts[rid]), "source": "estimated with the parameters (least squares)",
                 **_start_std(info["starts"][rid], ds.measured[rid].record.get("start", {}), rid in warps)}
           for rid in starts}
    for rid in warps:
        out[rid]["distance_correction"] = info["starts"][rid]["distance_correction"]
    return x_best, dict(info, alignment_rounds=rounds), std, cf, out


def _start_std(fitted: dict, record: dict, warped_run: bool = False) -> dict:
    """A start's standard errors: the fit's (``fitted``: the polish's ``std``, ``std_robust``) and, where the
    start's load ``record`` has one, a noisy speed channel's (:func:`rideid.conditioning.starts.speed_channel_std`)
    added in quadrature (not for a ``warped_run``: its distance correction was estimated with it, so the
    fit's standard error holds the channel's noise already)."""
    std_fit = fitted["std"]
    out = {"std": std_fit, "std_fit": std_fit}
    s_speed = record.get("std_speed_channel")
    if s_speed is not None and not warped_run:
        out["std_speed_channel"] = s_speed
        if std_fit is not None and np.isfinite(std_fit):
            out["std"] = float(math.hypot(std_fit, s_speed))
    return {**out, "std_robust": fitted["std_robust"]}


def _derived_std(space, cov):
    if space.derived is None or not np.all(np.isfinite(cov)):
        return None
    g = space.derived_gradient()
    return float(np.sqrt(max(g @ cov @ g, 0.0)))


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "DEFAULT_SPREAD_TOL": "identify.spread_tol", "DEFAULT_SPREAD_TOL_NO_POLISH":
    "identify.spread_tol_no_polish", "ZERO_SCALE": "identify.zero_scale", "RESTART_AT_BOUND":
    "identify.restart_at_bound", "REPAIR_RESTARTS": "identify.repair_restarts", "POLISH_MAX_NFEV":
    "identify.polish_max_nfev", "DOGBOX_MAX_NFEV": "identify.dogbox_max_nfev", "BOUND_SNAP":
    "identify.bound_snap", "WARP_BOUND": "identify.warp_bound", "STALL_OPTIMALITY": "identify.stall_optimality",
    "REALIGN_TOL": "identify.realign_tol", "REALIGN_MAX": "identify.realign_max"})
