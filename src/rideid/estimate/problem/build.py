"""The problem a single-model fit solves, built once, up front, from the dataset and the options.

:func:`build_problem` reads the dataset (its ``[known]``, ``[bounds]``, ``[model]``, the runs whose start is
estimated) and the fit's options (the model, a given start, the search and polish settings) and returns a
frozen :class:`Problem`: the cost function of the model fitted (its parameter space: free parameters, bounds,
groups), the cost function the search runs on (the linear model of a damper-curve or bump-stop model: the
exact linear kernel, ~100x cheaper per candidate), where the nonlinear groups start from (:func:`curve_start`),
the runs' blocks and the settings in force. The fit pipeline (:func:`rideid.estimate.fit.identify.identify`:
search -> polish -> error bars -> assessments) reads it and decides nothing the problem already says;
:meth:`Problem.plan` is the plan result.json records (:class:`rideid.estimate.records.Plan`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import OptimizeResult

from ...data.dataset import Dataset
from ...data.schema import NONLINEAR_GROUPS
from ...errors import ArgumentError
from ...model.nonlinear import BUMP_STOP_NAMES
from ...model.params import SUSPENSION_GROUPS
from ...model.simulator import Simulator
from ...settings import defaults
from ..records import Block, Plan
from .blocks import speed_runs
from .bumps import frozen_values, reach, scan_start
from .cost import IDENTIFIABLE_GROUPS, CostFunction, ParameterSpace, checked_groups, refuse_unsupported_groups
from .dampers import knot_excitation
from .weighting import TrackWeighting

#: ``--model`` choices handled here (SPEC §6)
MODELS = ("base", "full", "auto")

#: ``model`` strings that name one fitted model: its extension groups
NAMED_MODELS = {"base": (), "full": tuple(SUSPENSION_GROUPS)}


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
        if model in NAMED_MODELS:
            return NAMED_MODELS[model]
        if model in MODELS:
            raise ArgumentError(f"model {model!r} is not one fitted model")
        model = parse_model_arg(model)
    return checked_groups(model)


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


def linear_cost(ds, cf: CostFunction) -> CostFunction:
    """The linear model of a damper-curve or bump-stop cost function: the same groups less the curves and
    the stops (``c_sf``, ``c_sr`` free, the linear kernel), the same data and bounds."""
    sp = cf.space
    space = ParameterSpace({k: v for k, v in sp.known.items() if k not in BUMP_STOP_NAMES}, sp.geometry,
                           {k: v for k, v in sp._bounds_arg.items()
                            if not k.startswith("F_") and k not in BUMP_STOP_NAMES},
                           extensions=[g for g in sp.extensions if g not in NONLINEAR_GROUPS])
    return CostFunction(cf.ds, space=space, counter=cf.counter, simulator=cf.simulator)  # one count


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


def linear_start(cf: CostFunction, cf_search: CostFunction, x):
    """A linear model starts where the search (or the given row) left it: ``(cf, x, None, None)``."""
    return cf, x, None, None


def curve_start(cf: CostFunction, cf_search: CostFunction, x):
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


@dataclass(frozen=True)
class FitSettings:
    """The options of one fit, checked when built (:func:`build_problem`)."""

    population: int
    generations: int
    #: the search's early stop (every free parameter's coefficient of variation below it; 0 disables it)
    spread_tol: float
    weighting: TrackWeighting
    polish: bool
    assess: bool


@dataclass(frozen=True)
class Problem:
    """What a single-model fit solves, built up front (:func:`build_problem`); frozen.

    ``cost`` is the model fitted (its space: free parameters, bounds, fixed and derived ones, groups);
    ``search`` the cost the search runs on (``cost`` itself for a linear model, the linear model of damper
    curves and bump stops); ``start`` a given free row that skips the search (None: search), a row of
    ``start_cost``'s space; ``begin`` maps the search's best row to the polish's start (:func:`linear_start`,
    or :func:`curve_start`: the curves as ``F = c v``, the knots not excited frozen, the stops scanned);
    ``start_runs`` the runs whose start the polish estimates with the car, ``speed_runs`` those whose speed it
    does (a nonlinear car's runs at a declared constant speed: :func:`rideid.estimate.problem.blocks.speed_runs`).
    """

    cost: CostFunction
    search: CostFunction
    start_cost: CostFunction
    settings: FitSettings
    begin: Callable = linear_start
    start: np.ndarray | None = None
    start_runs: tuple = ()
    speed_runs: tuple = ()
    known: tuple = ()
    run_ids: tuple = ()

    @property
    def nonlinear(self) -> bool:
        """Damper curves or bump stops: the search on the linear model, the polish on the nonlinear car."""
        return self.begin is curve_start

    @property
    def search_generations(self) -> int:
        """The search's generation limit: none from a given start (the first population is still scored)."""
        return self.settings.generations if self.start is None else 0

    def started(self, search: OptimizeResult) -> OptimizeResult:
        """The search's result as the polish starts from it: from a given start, that row and stop ``"start"``."""
        if self.start is None:
            return search
        return OptimizeResult(dict(search, x=self.start, stop="start"))

    def plan(self) -> Plan:
        """The problem's blocks (result.json ``plan``): the car's free and fixed parameters, each run whose
        speed or start the polish estimates."""
        space = self.cost.space
        fixed = [n for n in space.reported_names if n in space.fixed]
        fixed += [n for n in self.known if n not in fixed]  # total_mass: a known that is no parameter
        runs = [Block(f"run {rid}", "run", unknowns=["speed"] * (rid in self.speed_runs)
                      + ["start"] * (rid in self.start_runs), runs=[rid])
                for rid in self.run_ids if rid in self.speed_runs or rid in self.start_runs]
        return Plan([Block("car", "car", unknowns=list(space.names), fixed=fixed, runs=list(self.run_ids))] + runs)


def fit_settings(*, population, generations, weights, polish, spread_tol, assess) -> FitSettings:
    """The fit's options checked: ``spread_tol`` None takes setting ``identify.spread_tol`` with the polish
    (it only needs the right basin), ``identify.spread_tol_no_polish`` without."""
    if spread_tol is None:
        spread_tol = defaults["identify.spread_tol"] if polish else defaults["identify.spread_tol_no_polish"]
    if not isinstance(generations, (int, np.integer)) or generations < 1:
        raise ArgumentError(f"generations must be a positive integer, got {generations!r}")
    return FitSettings(population, generations, spread_tol, TrackWeighting.create(weights), bool(polish), assess)


def build_problem(ds: Dataset, settings: FitSettings, *, model=None, cost: CostFunction | None = None,
                  simulator: Simulator | None = None, start=None) -> Problem:
    """The problem of fitting ``model`` (:func:`model_extensions`) to ``ds``, or ``cost``'s model (copied, never
    changed) when given; ``start``: a free row to polish from (the linear model's, whose curves ``F = c v``
    start the polish, or the nonlinear model's own with its knot forces as given)."""
    if isinstance(model, str) and model == "auto" and cost is None:
        raise ArgumentError("model='auto' is the model choice of rideid.identify "
                            "(rideid.estimate.choice.model_choice.identify); this function fits one given model")
    cf = (cost if cost is not None else CostFunction(ds, extensions=model_extensions(ds, model),
                                                     simulator=simulator)).copy()
    nonlinear = cf.space.layout is not None
    search = linear_cost(ds, cf) if nonlinear else cf
    x0 = None if start is None else np.asarray(start, dtype=float)
    # a start of the nonlinear model's own width: its knot forces as given (not a linear car's F = c v)
    own = x0 is not None and nonlinear and len(x0) == len(cf.names) != len(search.names)
    fitted = knee_cost(cf) if finds_knees(cf.space) and not own else cf  # no [model] damper_knots: the knee grid
    return Problem(cost=fitted, search=search, start_cost=cf if own else search, settings=settings,
                   begin=curve_start if nonlinear else linear_start, start=x0,
                   start_runs=tuple(ds.auto_start_runs) if settings.polish else (),
                   speed_runs=tuple(r.id for r in speed_runs(ds, cf.space.extensions)) if settings.polish else (),
                   known=tuple(ds.known), run_ids=tuple(r.id for r in ds.runs))


__all__ = ["MODELS", "model_extensions", "parse_model_arg", "linear_cost", "finds_knees", "knee_cost",
           "linear_start", "curve_start", "FitSettings", "Problem", "fit_settings", "build_problem"]
