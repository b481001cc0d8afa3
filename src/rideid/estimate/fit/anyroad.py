"""Identification of a dataset with runs on unknown roads (SPEC §9).

The road under an unknown-road run is projected out frequency by frequency
(:mod:`rideid.estimate.problem.roadfit`); runs on known tracks keep their
time-domain residuals (:class:`rideid.estimate.problem.cost.CostFunction`). The
steps:

1. *Start.* With track runs: the usual identification of the track runs
   alone (search and polish, :func:`rideid.estimate.fit.identify.identify`).
   Without: JADE on the road runs' search cost
   (:func:`rideid.estimate.problem.roadfit.search_costs`, a Hann-windowed
   approximation a few per cent from the exact cost), stopped by the same
   population-spread rule as the track search.
2. *Polish.* Least squares on the exact residuals of every run together:
   each run's residuals (the track runs' as one block) divided by their own
   standard deviation at the start, again at the first solution (the blocks
   are different kinds of numbers: time samples of normalised channels, DFT
   bins of weighted channels; weighting each by its own noise level is the
   maximum-likelihood combination). Then Newton steps on the cost's true
   Hessian (finite differences): the projected residual's Gauss-Newton
   ``J^T J`` over-states the curvature along the wheels' common scale, so the
   least-squares solver stops short there.
3. *Uncertainty.* Sandwiches ``H^+ B H^+`` with ``H`` that true Hessian (the
   pseudo-inverse by SVD): ``std`` with ``B = s^2 J^T J`` (one variance),
   ``std_robust`` with ``B`` the gradient's spread over clusters, each road
   run's DFT bin one cluster and the track runs' HAC long-run covariance
   (:mod:`rideid.estimate.fit.uncertainty`).
   A channel without signal on a run (RMS below setting ``roadfit.signal_floor`` of its kind's
   largest: a roll rate on a washboard, a dead sensor) is left out of that run's fit and named in
   ``roads.<run>.channels_left_out``: the fit weights each channel by 1 / its RMS, and rounding must not
   become the heaviest channel.
4. *Road.* Each road run's road under both wheel paths
   (:func:`rideid.estimate.problem.roadfit.road`), written as ``road/<run>.csv``,
   and its ISO 8608 class (:func:`rideid.model.roads.iso8608_class`).

Declared sensor filters (SPEC §11 ``highpass``, ``lowpass``) pass into the projection: each filtered channel
times its filter's response, the filters' states at the first sample estimated with the car's
(:func:`rideid.estimate.problem.roadfit.with_sensors`; module docstring there). A coupling that is not declared gets
no hint on an unknown road (:func:`rideid.estimate.assess.sensor_check.coupling_hints` compares a simulation in the
time domain); on tracks as built the hints of the fit on the tracks as drawn are kept, with a note.

The problem is built up front (:class:`_Plan`): one block per unknown road, one per run on a track as built (with
where the car was on it, its speed and start under their priors), one for the runs on tracks as drawn
(:mod:`rideid.estimate.problem.blocks`, one interface: residuals, weight, meat, record). Each stage takes the
problem and returns the next one (:func:`_start`, :func:`_polish`, :func:`_error_bars`, then the records and the
verdict); a new nuisance is a new block, not a new stage.

The model: linear (the twelve, anti-roll bars, tire damping, CG height).
Damper curves and bump stops are nonlinear and the projection needs a linear
car: such a model with an unknown-road run is refused. ``auto`` fits the
twelve plus the dataset's ``[model]`` groups (model choice is not run on
unknown roads) and says so in ``result.json`` (``model.note``). The
adequacy verdict covers the track runs only; road runs are listed as not
assessed. The result's cost is the one of :mod:`rideid.estimate.problem.cost` on every run, equal weights: on a
road run each used channel's squared error at the estimated road over its measured energy
(:func:`road_run_error`).
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from ...profiling import stage, timing
from ...settings import defaults, legacy_names
from ...errors import ArgumentError
from ...model.batch import single_threaded_blas, thread_map, thread_map_rows
from ...model.equations import CHANNELS, modal_summary
from ...model.params import ALL_NAMES
from ...model.roads import iso8608_class
from ..problem import asbuilt
from ..problem import roadfit
from ..problem.joint import JointProblem
from ..problem.blocks import DrawnRun, DrawnTracks, RoadBlock, TrackBlock, method as blocks_method
# which block each run gets (the problem's, re-exported: the model choice and the tests read them here)
from ..problem.blocks import (TRACK_OPTIONS, as_built_runs, prepare_road_runs, run_speed, speed_runs,  # noqa: F401
                              speed_wander, unknown_road_runs)
from ..assess.adequacy import ADVICE, advise, assess as assess_runs
from ..problem.cost import CostFunction, ParameterSpace, channel_weights, refuse_unsupported_groups
from . import road_curves
from .identify import (DEFAULT_GENERATIONS, DEFAULT_POPULATION, identify as identify_model, mark_bounds,
                       mode_restart, model_extensions, parameter_detail, relative_spread, restart_record)
from .jade import JadeSolver, make_rng, stop_requested
from ..result import History, IdentificationResult
from ..assess.sensor_check import road_coupling_hints
from ..assess.roads import judge as judge_road_runs
from ..assess.details import not_determined
from ..assess.shape import check as shape_check
from ..assess.motion import (ROAD_MOTION_NOTE, drawn_motion_record, left_out, motion_findings, motion_record,
                             road_motion_record, tracks_block)
from .uncertainty import along_record, estimate_covariance, remeasured

def road_run_error(rr, y, fitted) -> float:
    """``E_r`` of :mod:`rideid.estimate.problem.cost` for an unknown-road run: each used channel's squared error at
    the estimated road (:func:`rideid.estimate.problem.roadfit.fitted_channels`) over its measured energy (floored as
    there), averaged over the channels the fit used; so the result's cost has the one meaning on every run
    (the polish's own objective, each block weighted by its noise, is about 1 by construction)."""
    ym = np.full(np.shape(y), np.nan)
    ym[:, rr.cols] = np.asarray(y, dtype=float)[:, rr.cols]
    W = channel_weights(ym)
    d = np.where(np.isnan(ym), 0.0, np.asarray(fitted, dtype=float) - ym)
    return float(W @ np.sum(d * d, axis=0))


def _pinv(H):
    """SVD pseudo-inverse of a symmetric positive semi-definite matrix (never squares a condition number
    beyond the Jacobian's own)."""
    return np.linalg.pinv(H, rcond=1e-12, hermitian=True)


def _newton(prob, v, H, steps: int = 3):
    """Newton steps on the cost with the true (half) Hessian ``H``: where the Gauss-Newton solver stops
    short along the wheels' common scale (its ``J^T J`` over-states the curvature there, so its steps
    fall short and its tolerances are met early). Returns ``v``, the residuals and their Jacobian there."""
    Hinv = _pinv(H)
    e = prob(v)
    J = prob.jacobian(v)
    for _ in range(steps):
        dv = -Hinv @ (J.T @ e)
        t = 1.0
        while t > 1e-3:
            vn = np.clip(v + t * dv, *prob.vbounds)
            en = prob(vn)
            if en @ en < e @ e:
                break
            t *= 0.5
        else:
            break
        v, e = vn, en
        J = prob.jacobian(v)
        if np.max(np.abs(t * dv)) < 1e-7:
            break
    return v, e, J


def _motion_block(prob, w, d: int):
    """Where each moving block's motion unknowns sit in the joint vector ``w`` (the car's ``d`` first): block
    index -> ``w``'s slice of its unknowns (a track as built: speed, start; an unknown road: speed)."""
    return {k: w[a:b] for k, (a, b) in _motion_slices(prob, d).items()}


def _motion_slices(prob, d: int) -> dict:
    """Block index -> ``(first, end)`` of its motion unknowns in the joint vector (the car's ``d`` first)."""
    out, a = {}, d
    for k in prob.moving():
        out[k] = (a, a + prob.parts[k].n_motion)
        a += prob.parts[k].n_motion
    return out


def _side_by_side(fn, points) -> list:
    """``[fn(p) for p in points]`` on the kernels' threads: the workers of a least squares' difference Jacobian, one
    column an evaluation (each evaluation's blocks one after the other). The same numbers as one after the other,
    to the last bit; the van on three roads and a twist run (../shared/cases/van-roads-dampers: 52 columns, the
    blocks of unequal size) keeps both cores busier so than with each evaluation's blocks side by side: its joint
    solves 24.5-32.1 -> 21.8-22.5 s, interleaved (docs/performance.md)."""
    return thread_map(fn, points, "rideid-columns")


@stage("joint solve of car and motion")
def _joint_solve(prob, z, ds, max_nfev: int):
    """Least squares of the car ``z`` (v units) together with the speed and the start of each run on a track as
    built (each :class:`rideid.estimate.problem.blocks.TrackBlock` of ``prob``: the drawing moved by
    :meth:`~rideid.estimate.problem.blocks.TrackBlock.moved`, its unevenness prior as it is) and the speed of each
    run on an unknown road (:class:`rideid.estimate.problem.blocks.RoadBlock`: the rear wheels' delay), each set-up
    value's prior (SPEC §13) a residual block of the same solve, weighted by its std against the run's own residual
    level in the problem (the block's weight times its RMS).

    Placed by :meth:`rideid.estimate.problem.blocks.TrackBlock.aligned` at one car and then held, a run's speed
    follows that car, and the car the speed: on the all-realities case without an engine (seed 5, model base) the speeds
    ended 0.03-0.07 % low (4-8 of their standard errors) and the unsprung masses +3.5-4.2 % (4 std_robust);
    with the speed declared instead, +0.8 %. Solved together, both go to their joint minimum (measured:
    docs/tracks-as-built.md). Returns the solution (``x``: the car) and the problem on the moved blocks (their
    ``inputs`` tabulated at the new speed and start, their records the solved speed and shift)."""
    d = z.size
    keys = prob.moving()
    P0 = prob.car(z)
    weights = {k: prob.scale[k] * prob.parts[k].level(P0, prob.geom) for k in keys}

    # (block, its motion) -> the moved block, one object for every car at that motion: a road run's projection of
    # one car is cached by its run (rideid.estimate.problem.roadfit._context), so the damper curves' knot-force
    # columns of the Jacobian reuse it (a new run object per call missed it: the van of
    # ../shared/cases/van-roads-dampers, joint solves 110 -> 55 s)
    @functools.lru_cache(maxsize=4 * max(len(keys), 1))
    def moved(k: int, p: bytes):
        return prob.parts[k].moved(ds, np.frombuffer(p, dtype=float))

    def placed(w):
        parts = list(prob.parts)
        for k, p in _motion_block(prob, w, d).items():
            parts[k] = moved(k, np.asarray(p, dtype=float).tobytes())
        return prob.with_blocks(parts)

    def fun(w):  # the blocks one after the other: the difference Jacobian's columns run side by side (workers)
        rows = [prob.parts[k].prior_rows(p, weights[k]) for k, p in _motion_block(prob, w, d).items()]
        return np.concatenate([placed(w).residual(w[:d])] + rows)

    q = sum(prob.parts[k].n_motion for k in keys)
    reach = np.concatenate([np.full(prob.parts[k].n_motion, prob.parts[k].motion_bound) for k in keys] or [[]])
    lo, hi = np.concatenate([prob.vbounds[0], -reach]), np.concatenate([prob.vbounds[1], reach])
    steps = np.concatenate([np.full(d, 1e-5)] + [np.asarray(prob.parts[k].motion_steps, dtype=float) for k in keys])
    sol = least_squares(fun, np.concatenate([z, np.zeros(q)]), bounds=(lo, hi), method="trf", diff_step=steps,
                        max_nfev=max_nfev, workers=_side_by_side)
    parts = list(placed(sol.x).parts)
    for k in keys:
        parts[k] = parts[k].settled(ds)
    return OptimizeResult(dict(sol, x=sol.x[:d], motion=sol.x[d:])), prob.with_blocks(parts)


@stage("error bars with motion")
def _with_motion(prob, z, H, Ja, S, s2, ds, res):
    """The error bars with the speed and the start of each run on a track as built (placed by
    :meth:`rideid.estimate.problem.blocks.TrackBlock.aligned`, solved with the car by :func:`_joint_solve`, then
    held for the Newton steps and the Hessian) as nuisance parameters of the same sandwich: their residual columns
    (:meth:`rideid.estimate.problem.blocks.TrackBlock.motion_jacobian`) join the car's, the bread
    ``[[H, Ja^T Jm], [Jm^T Ja, Jm^T Jm + Jp^T Jp]]`` (the car's block the true Hessian, the rest Gauss-Newton: the
    drawing's inputs are not projected, so ``J^T J`` is their curvature; ``Jp`` the set-up priors' rows, SPEC §13),
    the meat the runs' white meat over both (the priors' rows as independent observations of the same level); the
    car's block of the inverse is the car's covariance with the motion marginalised.

    The speed of each run on an unknown road (:class:`rideid.estimate.problem.blocks.RoadBlock`) joins the same
    way, one column (its residuals are weighted by the block's scale, as the problem's).

    The bread's inverse is taken on the car's resolved directions (``res``,
    :class:`rideid.estimate.fit.uncertainty.Resolution`), on every direction of the motion's.

    Returns the white and robust covariances (car's parameters, x units) and per moving block index
    ``{"speed_std_m_s"}`` and, on a track as built, ``"start_shift_std_s"``."""
    n = Ja.shape[1]
    offs = np.concatenate([[0], np.cumsum(prob.sizes)])
    P = prob.car(z)
    where = {k: (a - n, b - n) for k, (a, b) in _motion_slices(prob, n).items()}
    q = sum(b - a for a, b in where.values())
    Jm = np.zeros((Ja.shape[0], q))
    Jp = np.zeros((0, q))
    for k, (a, b) in where.items():
        Jm[offs[k]:offs[k + 1], a:b] = prob.scale[k] * prob.parts[k].motion_jacobian(P, prob.geom, ds)
        pj = prob.parts[k].prior_jacobian(float(np.sqrt(s2)))
        rows = np.zeros((pj.shape[0], q))
        rows[:, a:b] = pj
        Jp = np.vstack([Jp, rows])
    cross = Ja.T @ Jm
    prior_info = Jp.T @ Jp
    Hf = np.block([[H, cross], [cross.T, Jm.T @ Jm + prior_info]])
    Sf = np.block([[S, s2 * cross], [s2 * cross.T, s2 * (Jm.T @ Jm + prior_info)]])  # white meat of the blocks
    Hinv = res.pinv(Hf)
    D = np.diag(np.concatenate([prob.dxdv(z), np.ones(q)]))
    Jf = np.concatenate([Ja, Jm], axis=1)
    m = Ja.shape[0]
    cov = (D @ Hinv @ (s2 * (Jf.T @ Jf + np.block([[np.zeros((n, n)), np.zeros((n, q))],
                                                     [np.zeros((q, n)), prior_info]]))) @ Hinv @ D)
    rob = D @ Hinv @ Sf @ Hinv @ D * (m / max(m - n - q, 1))
    out = {}
    for k, (a, b) in where.items():
        sd = np.sqrt(np.clip(np.diag(rob)[n + a:n + b], 0.0, None))
        out[k] = {"speed_std_m_s": float(prob.parts[k].speed * sd[0])}
        if b - a > 1:
            out[k]["start_shift_std_s"] = float(sd[1])
    return cov[:n, :n], rob[:n, :n], out


@stage("road search")
def _search(space, geom, rruns, gen, population, generations, callback, t0):
    """JADE on the road runs' search cost, stopped by the population spread (setting ``anyroad.spread_tol``)."""
    def fun(X):
        P = space.full(X)
        out = np.full(P.shape[0], np.inf)
        ok = space.valid(P)
        if ok.any():  # each row's cost is its own: slices of the population on parallel threads
            out[ok] = thread_map_rows(lambda Q: roadfit.search_costs(Q, geom, rruns), P[ok], "rideid-search")
        return out

    solver = JadeSolver(space.bounds, population, gen)
    X = solver.ask()
    solver.tell(fun(X))
    history, stop, g = [], "generations", 0
    for g in range(1, generations + 1):
        X = solver.ask()
        solver.tell(fun(X))
        cv = relative_spread(solver.pop, space.bounds)
        finite = np.isfinite(solver.costs)
        rec = {"generation": g, "evaluations": solver.nfev, "best_cost": float(solver.fun),
               "mean_cost": float(np.mean(solver.costs[finite])) if finite.any() else float("inf"),
               "best_cost_equal": float(solver.fun), "mu_f": solver.mu_f, "mu_cr": solver.mu_cr}
        mean = solver.pop.mean(axis=0)
        for prefix, values in (("best", solver.x), ("mean", mean), ("cv", cv)):
            for j, nme in enumerate(space.names):
                rec[f"{prefix}_{nme}"] = float(values[j])
        for rr in rruns:  # the road runs weigh alike in the search
            rec[f"weight_{rr.run_id}"] = 1.0 / len(rruns)
        history.append(rec)
        state = OptimizeResult(x=solver.x, fun=float(solver.fun), nit=g, nfev=solver.nfev, generations=generations,
                               spread=float(cv.max()), elapsed=time.perf_counter() - t0, track_weights={})
        if stop_requested(callback, state):
            stop = "callback"
            break
        if cv.max() < defaults["anyroad.spread_tol"]:
            stop = "spread"
            break
    return solver.x, g, solver.nfev, stop, history


def identify_any_road(ds, **kw) -> IdentificationResult:
    """Identify ``ds``, which has at least one unknown-road run or one run on a track fitted as built (module
    docstring); BLAS on one thread (its small products are many, and threads only contend)."""
    with single_threaded_blas():
        return _identify_any_road(ds, **kw)


def _carry_sensor_hints(adequacy, start_result):
    """``adequacy`` of the as-built stage with the hints of an undeclared AC coupling that the fit on the tracks as
    drawn gave (:func:`rideid.estimate.fit.identify.sensor_notes`: a time-domain comparison of the car's channel,
    high-passed, with the data), said to be from there, and, when not adequate, first in the advice. They are
    not computed again at the estimated road: there the model's channels are the data less the fit band's
    residual, and high-passing them says nothing about the sensor. Runs on unknown roads get the road fit's own
    (:func:`_road_sensor_hints`)."""
    hints = (getattr(start_result, "adequacy", None) or {}).get("sensor_hints")
    if adequacy is None or hints is None:
        return adequacy
    out = dict(adequacy, sensor_hints=list(hints),
               sensor_hints_note="from the fit on the tracks as drawn (time domain), before the tracks as built")
    if hints and not out.get("adequate", True):
        out["advice"] = " ".join(h["message"] + "." for h in hints[:4]) + " " + (out.get("advice") or "")
    return out


#: where the road fit's coupling hints come from (adequacy.sensor_hints_note)
ROAD_HINTS_NOTE = "from the road fit of the runs on tracks as built: the road free, a trial high-pass on the channels"
FREE_ROAD_HINTS_NOTE = "from the road fit of the runs on unknown roads: a trial high-pass on the channels"


def _with_hints(adequacy, hints, note=ROAD_HINTS_NOTE):
    """``adequacy`` with coupling ``hints`` from the road fit: not adequate (the sensor model is wrong; the
    weighing of structure cannot clear it, ``sensors_suspect``), the hints first in the reasons and the advice."""
    first = ("the data look AC-coupled on " + ", ".join(h["channel"] for h in hints) + f" ({note})")
    return dict(adequacy, sensor_hints=list(hints), sensor_hints_note=note, adequate=False, sensors_suspect=True,
                reasons=[first] + list(adequacy.get("reasons", [])),
                advice=" ".join(dict.fromkeys(h["message"] + "." for h in hints)) + " "
                + (adequacy.get("advice") or ""))


def _road_sensor_hints(P, geom, rruns, ds, threshold=None):
    """The coupling hints of the road fit
    (:func:`~rideid.estimate.assess.sensor_check.road_coupling_hints`) on road-fitted runs ``rruns``
    (:class:`rideid.estimate.problem.roadfit.RoadRun`). On tracks as built they are asked when the fit on the tracks
    as drawn gave none: there an undeclared coupling is taken up by the road and the springs (the
    SUV's hubs coupled at 0.5 Hz, not declared: k_sf +21 %, 37 std_total, which the residual test at the estimated
    road did not see). On unknown roads (no as-drawn fit, no time-domain hint) the road takes up part of a
    coupling's signature, so a smaller cut names it (``threshold`` =
    setting ``sensor_check.free_road_hint_reduction``; the hubs of the built-in car coupled at 0.5 Hz,
    not declared: k_sr +18 % at the fit, the trial cut the residual 35 %)."""
    threshold = defaults["sensor_check.hint_reduction"] if threshold is None else threshold
    return road_coupling_hints(P, geom, rruns, {rr.run_id: ds.sensor_filters(rr.run_id) for rr in rruns},
                               threshold=threshold)


@dataclass(frozen=True)
class _Plan:
    """The problem a dataset poses, built up front: the model's groups (``ext``; ``model``: result.json's record of
    them), the parameter space, the blocks (:mod:`rideid.estimate.problem.blocks`: each unknown road, each track as
    built with its run's motion, the runs on tracks as drawn) and the runs taken as drawn with why (``skipped``)."""

    ext: tuple
    model: dict
    space: ParameterSpace
    roads: list
    tracks: list
    drawn: list
    track_runs: list
    skipped: dict
    excitation: dict | None = None
    #: the runs as drawn whose speed is estimated with the car (:class:`rideid.estimate.problem.blocks.DrawnRun`):
    #: on a car with damper curves or bump stops, each at a declared constant speed
    speed_runs: tuple = ()

    def problem(self, ds, geom, simulator) -> JointProblem:
        """The joint problem: the runs as drawn (one block; each run of :attr:`speed_runs` its own), then the
        unknown roads, then the tracks as built."""
        held = [r for r in self.drawn if r.id not in {s.id for s in self.speed_runs}]
        cf = [DrawnTracks(CostFunction(ds.subset(held), space=self.space, simulator=simulator))] if held else []
        cf += [DrawnRun.of(ds, r, self.space, simulator) for r in self.speed_runs]
        blocks = cf + self.roads + self.tracks
        return JointProblem(self.space, geom, blocks, np.ones(len(blocks)))


def _extensions(ds, model, start_result) -> tuple[tuple, dict]:
    """The model's groups and result.json's ``model``: the start's; else for ``auto`` the dataset's ``[model]``
    groups, with the note that the model choice was not run; else ``model``'s."""
    if start_result is not None:
        ext = tuple((start_result.model or {}).get("extensions", ()))
        return ext, dict(start_result.model or {"extensions": list(ext), "selection": "given"})
    if not (isinstance(model, str) and model == "auto"):
        ext = tuple(model_extensions(ds, model))
        return ext, {"extensions": list(ext), "selection": "given"}
    ext = tuple(ds.manifest.extensions or ())
    return ext, {"extensions": list(ext), "selection": "auto (not run: unknown roads)",
                 "note": ("model choice (auto) is not run on unknown roads: fitted the twelve"
                          + (f" plus the dataset's [model] groups ({', '.join(ext)})" if ext else "")
                          + "; give --model to fit anti_roll_bars or tire_damping")}


def _plan(ds, model, start_result, tracks: str, polish: bool, as_built_mode: str) -> _Plan:
    """The :class:`_Plan` of ``ds``; a model the roads cannot take is refused
    (:func:`rideid.estimate.fit.road_curves.refusal`)."""
    ext, model_block = _extensions(ds, model, start_result)
    road_curves.refuse(ds, ext)
    refuse_unsupported_groups(ext, "model")
    road_ids = [r.id for r in unknown_road_runs(ds, ext)]
    # with damper curves on the roads: their knots (rideid.estimate.fit.road_curves), the knots they excite frozen
    space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=ext,
                           damper_knots=road_curves.knots(ds, ext, road_ids))
    # SPEC §13: each road run's speed estimated with the car, the declared one its prior (none along a speed channel)
    rruns = prepare_road_runs(ds, ext, road_curves.layout_knots(space, road_ids))
    space, excitation = road_curves.excited(space, rruns)
    roads = [RoadBlock.of(rr, _road_prior(ds, rr.run_id), ds.geometry) for rr in rruns]
    ab_list, skipped = as_built_runs(ds, ext, tracks if polish else "as-drawn")
    # every run on a track as built: its constant speed and its start fitted with the car (SPEC §13: a declared
    # speed and a given start are priors of them; along a speed channel the channel's mean starts the speed)
    blocks = [TrackBlock(asbuilt.prepare_track_run(ds, r, as_built_mode), r, asbuilt.motion_prior(ds, r))
              for r in ab_list]
    track_runs = [r for r in ds.runs if r.id not in road_ids]
    ab_ids = {r.id for r in ab_list}
    return _Plan(ext, model_block, space, roads, blocks, [r for r in track_runs if r.id not in ab_ids], track_runs,
                 skipped, excitation, speed_runs(ds, ext) if polish else ())


def _road_prior(ds, run_id: str):
    """The :class:`rideid.estimate.problem.asbuilt.MotionPrior` of an unknown-road run: a track run's speed prior
    (:func:`rideid.estimate.problem.asbuilt.motion_prior`), no start (a road run has none to place)."""
    return replace(asbuilt.motion_prior(ds, next(r for r in ds.runs if r.id == run_id)), start=None)


def _start(ds, plan, gen, population, generations, polish, callback, simulator, start_result, t0, start=None):
    """Where the polish starts, and the search's record: ``(x0, nit, nfev, stop, history)``. A given row of the
    free parameters (``start``: a candidate of the model choice from its parent's fit); else from the given
    result; else the usual identification of every track run, each track taken as drawn; else (unknown roads
    alone) JADE on the road runs' search cost (:func:`_search`)."""
    if start is not None:
        x0 = np.asarray(start, dtype=float)
        if x0.shape != (len(plan.space.names),):
            raise ArgumentError(f"start: expected {len(plan.space.names)} values ({', '.join(plan.space.names)}), "
                                f"got {x0.size}")
        return x0, 0, 0, "start given", []
    if start_result is None and plan.track_runs:
        start_result = identify_model(ds.subset(plan.track_runs), rng=gen, population=population,
                                      generations=generations, model=list(plan.ext), polish=polish, callback=callback,
                                      assess=False, simulator=simulator)
    if start_result is None:
        return _search(plan.space, ds.geometry, [b.rr for b in plan.roads], gen, population, generations, callback,
                       t0)
    return (np.array([start_result.parameters[n] for n in plan.space.names]), start_result.nit, start_result.nfev,
            start_result.stop, list(start_result.history))


def _replaced(prob, fn, roads: bool = True) -> JointProblem:
    """``prob`` with each moving block ``b`` (a track as built, and with ``roads`` an unknown road) replaced by
    ``fn(b)`` (on parallel threads)."""
    keys = [k for k in prob.moving() if roads or not isinstance(prob.parts[k], RoadBlock)]
    parts = list(prob.parts)
    for k, b in zip(keys, thread_map(lambda k: fn(prob.parts[k]), keys, "rideid-priors")):
        parts[k] = b
    return prob.with_blocks(parts)


def _realigned(prob, P, ds, mode: str, roads: bool = True) -> JointProblem:
    """Each track block placed at the car ``P`` in ``mode`` and its levels estimated there; with ``roads`` each
    unknown road's speed scanned there (:meth:`rideid.estimate.problem.blocks.RoadBlock.aligned`)."""
    return _replaced(prob, lambda b: b.aligned(P, prob.geom, ds, mode).with_prior(P, prob.geom), roads)


def _placed(prob, z, ds) -> JointProblem:
    """The track blocks' noise and unevenness levels at the car ``z``, each run's drawing placed there on the
    drawing alone and then with the prior estimated there (:meth:`rideid.estimate.problem.blocks.TrackBlock.aligned`
    says why), the levels again at each placement."""
    P = prob.car(z)
    prob = _replaced(prob, lambda b: b.with_prior(P, prob.geom))
    for mode in ("amplitude", "prior"):
        prob = _realigned(prob, P, ds, mode)
    return prob


def _refined(prob, z, ds):
    """The placements, priors and block weights at the car ``z``, then a short joint solve from it (the roads'
    speeds, solved with the car already, from where they are)."""
    return _joint_solve(_realigned(prob, prob.car(z), ds, "prior", roads=False).reweighted(z), z, ds, 50)


def _first_solve(prob, z0, ds):
    """The polish's first solve: the blocks placed at ``z0``, weighted there (and their priors), one solve (with
    unknown roads the joint one). Returns the solution, the problem at it and the cost before."""
    prob = _placed(prob, z0, ds).reweighted(z0)
    cost_before = float(np.sum(prob(z0) ** 2))
    if prob.of(RoadBlock):  # the roads' speeds with the car from the start: they trade off with the wheels
        sol, prob = _joint_solve(prob, z0, ds, 100)
    else:
        sol = least_squares(prob, z0, bounds=prob.vbounds, method="trf", diff_step=1e-5, max_nfev=100)
    return sol, prob, cost_before


def _polish(prob, z0, ds):
    """The polish from ``z0``: one solve at the start's block weights (and priors), both again at its solution, a
    short joint solve; a powertrain mode left at a search bound polished again from typical values. Returns the
    solution, the problem at it, the cost before and the restart's record."""
    sol, prob, cost_before = _first_solve(prob, z0, ds)
    sol, prob = _refined(prob, sol.x, ds)
    restart = mode_restart(prob.space, prob.x(sol.x))
    if restart is None:
        return sol, prob, cost_before, None
    alt = least_squares(prob, prob.v(restart[0]), bounds=prob.vbounds, method="trf", diff_step=1e-5, max_nfev=100)
    c_first, c_alt = float(np.sum(prob(sol.x) ** 2)), float(np.sum(prob(alt.x) ** 2))  # the same priors
    restarted = restart_record(restart[1], c_first, c_alt, prob.space, prob.x(sol.x), prob.x(alt.x))
    if c_alt < c_first:
        sol, prob = _refined(prob, alt.x, ds)
    return sol, prob, cost_before, restarted


@dataclass(frozen=True)
class _Fitted:
    """The fit at its solution: ``z`` (v units), the problem there (the track blocks' records final), the polish's
    ``info`` (None unpolished), the white error bars ``std`` and covariance ``cov`` (x units), the function
    evaluations spent."""

    z: np.ndarray
    prob: JointProblem
    info: dict | None
    std: np.ndarray
    cov: np.ndarray
    nfev: int = 0
    hessian: np.ndarray | None = None
    jacobian: np.ndarray | None = None


def _with_records(prob, motion_std: dict, ds) -> JointProblem:
    """The moving blocks with their motion's std (``motion_std``: block index -> stds) and their result.json
    records (:func:`rideid.estimate.assess.motion.motion_record`,
    :func:`~rideid.estimate.assess.motion.road_motion_record`)."""
    parts = list(prob.parts)
    for k, sd in motion_std.items():
        b = parts[k]
        if isinstance(b, (RoadBlock, DrawnRun)):  # a speed alone
            parts[k] = replace(b, record=road_motion_record(dict(b.record, **sd), b.prior, b.run_id))
            continue
        read = float(getattr(ds.measured.get(b.run_id), "start", 0.0) or 0.0)
        parts[k] = replace(b, record=motion_record(dict(b.record, **sd, start_read_s=read), b.prior, b.tr))
    return prob.with_blocks(parts)


def _remeasured_record(r: dict, names) -> dict:
    """result.json ``polish.remeasured``: a direction measured again at the larger step (the parameters along it
    with their share: :func:`rideid.estimate.fit.uncertainty.along_record`; its curvature at the Hessian's step and
    at the larger one)."""
    return {"along": along_record(r["direction"], names), **{k: r[k] for k in ("curvature", "curvature_at_step",
                                                                                 "step")}}


@stage("error bars")
def _error_bars(prob, sol, ds, cost_before: float, restarted) -> _Fitted:
    """The true Hessian; Newton steps on it to the minimum (module docstring); the sandwich: bread the Hessian,
    meat each block's (:meth:`rideid.estimate.problem.blocks.TrackBlock.meat` and its kin); with tracks as built the
    runs' speeds and starts as nuisances of the same sandwich (:func:`_with_motion`)."""
    h = defaults["anyroad.hessian_step"]
    H = prob.hessian(sol.x, h)
    z, e, Ja = _newton(prob, sol.x, H)          # in v units
    m, n = Ja.shape
    s2 = float(e @ e) / max(m - n, 1)
    # the directions the cost's rounding hides at h measured again at a larger step, those still hidden out of the
    # bread (uncertainty.remeasured, uncertainty.Resolution)
    delta = prob.rounding(sol.x, h)
    H, res, again = remeasured(H, delta, h, defaults["uncertainty.direction_step"],
                               functools.partial(prob.along, sol.x, step=h))
    Hinv = res.pinv(H)
    D = np.diag(prob.dxdv(z))
    cov = D @ Hinv @ (s2 * Ja.T @ Ja) @ Hinv @ D
    S = np.zeros((n, n))
    offs = np.concatenate([[0], np.cumsum(prob.sizes)])
    for k, b in enumerate(prob.parts):
        S += b.meat(Ja[offs[k]:offs[k + 1]], e[offs[k]:offs[k + 1]], s2)
    cov_rob = D @ Hinv @ S @ Hinv @ D * (m / max(m - n, 1))
    cov_fixed = None
    if prob.moving():  # the speed (and start) of each run: nuisances of the same sandwich
        cov_fixed = cov_rob  # the motion held: for the budget's share
        cov, cov_rob, motion_std = _with_motion(prob, z, H, Ja, S, s2, ds, res)
        prob = _with_records(prob, motion_std, ds)
    with timing("error bars' shape"):  # the car's cost along each parameter's profile line, the motion held
        sigma = np.where(res.not_determined, np.nan, np.sqrt(np.clip(np.diag(cov_rob), 0, None)) / prob.dxdv(z))
        with np.errstate(divide="ignore"):
            shape = shape_check(prob.costs, z, Hinv, sigma, prob.vbounds, list(prob.space.names), to_x=prob.x,
                                exact=True, scale=np.ones(z.size))
    unresolved = res.record(list(prob.space.names))
    info = {"success": bool(sol.success), "message": sol.message, "nfev": int(sol.nfev), "shape": shape,
            **({} if restarted is None else {"mode_restart": restarted}),
            "cost_before": cost_before, "cost_after": float(e @ e), "covariance": cov.tolist(),
            "names": list(prob.space.names), "covariance_robust": (0.5 * (cov_rob + cov_rob.T)).tolist(),
            **({} if cov_fixed is None else {"covariance_robust_motion_fixed": cov_fixed.tolist()}),
            **({} if unresolved is None else {"unresolved": unresolved}),
            **({} if not again else {"remeasured": [_remeasured_record(r, prob.space.names) for r in again]}),
            "method": blocks_method(prob.parts)}
    return _Fitted(z, prob, info, np.sqrt(np.clip(np.diag(cov), 0, None)), cov, int(sol.nfev) * (n + 1), H, Ja)


def _details(space, x, P, fitted) -> tuple[dict, object]:
    """Each reported parameter's record (:func:`rideid.estimate.fit.identify.parameter_detail`), with the speeds' and
    starts' share of ``std_robust`` (``std_motion``: the budget's "speed and start",
    :mod:`rideid.estimate.fit.budget`) with tracks as built; and the robust covariance."""
    info = fitted.info
    robust = estimate_covariance(info, space, x)
    details = {nme: parameter_detail(space, P, nme, fitted.std, fitted.cov, robust) for nme in space.reported_names}
    not_determined(details, space, x, (info or {}).get("unresolved"))
    if "covariance_robust_motion_fixed" not in (info or {}):
        return details, robust
    fixed = estimate_covariance(dict(info, covariance_robust=info["covariance_robust_motion_fixed"]), space, x)
    for nme, d in details.items():
        a, b = d.get("std_robust"), (None if nme in space.fixed else fixed.std_robust(nme))
        if a is not None and b is not None and not d.get("fixed"):
            d["std_motion"] = float(np.sqrt(max(a * a - b * b, 0.0)))
    return details, robust


def _road_records(ds, P, geom, roads) -> tuple[dict, dict, dict, list]:
    """Each unknown road's record (result.json ``roads``: its file, ISO 8608 class, fit band), its profile, the
    fitted channels and its error (:func:`road_run_error`)."""
    out, profiles, response = {}, {}, {}
    lam, band = defaults["roadfit.road_wavelengths"], defaults["roadfit.band"]
    for b in roads:
        rr = b.rr
        sol_r = roadfit.solve(P, geom, rr)
        xr, zr = roadfit.road(P, geom, rr, sol_r)
        cls, gd = iso8608_class(xr, zr, n_band=(1 / lam[1], 1 / lam[0]))
        out[rr.run_id] = {
            "file": f"road/{rr.run_id}.csv", "iso8608_class": cls, "gd_n0": float(gd),
            "gd_n0_unit": "m^3", "speed": rr.speed, "fit_band_hz": [float(band[0]), float(min(band[1], 0.45 * rr.fs))],
            **({"motion": dict(b.record, note=ROAD_MOTION_NOTE)} if "speed" in b.record else {}),
            "wavelengths_m": list(defaults["roadfit.road_wavelengths"]),
            "note": (f"the road's content at wavelengths {lam[0]}-{lam[1]} m; the first and last {lam[1]:.0f} m carry "
                     "the record's ends and are less certain; adequacy not assessed on this run"
                     + road_curves.road_note(rr))}
        run = next(r for r in ds.runs if r.id == rr.run_id)
        if getattr(run, "road_known", False):
            out[rr.run_id]["note"] = (f"moving at its first sample on the known track '{run.track}': fitted as a "
                                      "road run (its state at the first sample and its road estimated; the "
                                      "track's profile not used); " + out[rr.run_id]["note"])
        out[rr.run_id].update(left_out(rr))
        profiles[rr.run_id] = (xr, zr)
        response[rr.run_id] = roadfit.fitted_channels(P, geom, rr, ds.data[rr.run_id].matrix(), sol_r)
    errors = [road_run_error(rr, ds.data[rr.run_id].matrix(), response[rr.run_id]) for rr in (b.rr for b in roads)]
    return out, profiles, response, errors


def _checked(ds, P, geom, x, prob) -> tuple[dict, list, dict]:
    """The fitted channels, the errors and, for the verdict, run id -> (residual, measured, inputs) of the runs on
    known tracks: each track as built at its estimated road, the runs as drawn simulated."""
    response, errors, checked = {}, [], {}
    for b in (prob.parts[k] for k in prob.of(TrackBlock)):
        y = ds.data[b.run_id].matrix()
        response[b.run_id] = asbuilt.fitted_channels(P, geom, b.tr, y)
        errors.append(road_run_error(b.tr.rr, y, response[b.run_id]))
        ri = b.tr.inputs  # the drawing's, tabulated when the run was prepared (asbuilt.prepare_track_run)
        checked[b.run_id] = (y - response[b.run_id], y, np.concatenate([ri.u, ri.rate], axis=1))
    for cf in (prob.parts[k].cf for k in prob.of(DrawnTracks)):
        errors += list(cf.run_errors(x[None])[:, 0])
        resp_t = cf.simulate(P)
        response.update(resp_t)
        for ri_, rid in enumerate(cf.run_ids):
            s_, e_ = cf.sim.run_start[ri_], cf.sim.run_start[ri_ + 1]
            Y = cf.Y[s_:e_].copy()
            Y[:, cf.W[ri_] <= 0] = np.nan
            run_in = cf.sim.runs[ri_]
            checked[rid] = (Y - resp_t[rid], Y, np.concatenate([run_in.u, run_in.rate], axis=1))
    return response, errors, checked


def _implausible(tracks_block: dict) -> list[str]:
    """The tracks whose as-built fit needed more than a track carries (a road can explain what the car lacks: a
    missing anti-roll bar, as unevenness left and right), one line each."""
    return [f"{tid}: factor {rec['amplitude_factor']:.3f} ± {rec['amplitude_factor_std']:.3f}, unevenness "
            f"{1e3 * rec['unevenness_rms_surface_m']:.1f} mm RMS"
            for tid, rec in tracks_block.items() if "amplitude_factor" in rec
            and (abs(rec["amplitude_factor"] - 1)
                 > defaults["anyroad.plausible_factor"] + 2 * rec["amplitude_factor_std"]
                 or rec["unevenness_rms_surface_m"] > defaults["anyroad.plausible_rms"])]


def _verdict(checked, ext, road_ids: list, ab_ids: list, tracks_block: dict) -> tuple[dict, list]:
    """The adequacy of the runs on known tracks (runs on unknown roads, ``road_ids``, listed as not assessed; runs
    on tracks as built, ``ab_ids``, judged at their estimated road), not adequate when the tracks as built needed
    more than a track carries; and those tracks' lines."""
    adequacy = advise(assess_runs(checked, CHANNELS), {"extensions": list(ext)})
    lo, hi = defaults["roadfit.band"]
    notes = ((road_ids, {"not_assessed": list(road_ids), "note": "the verdict covers the runs on known tracks; runs "
                         "on unknown roads are not assessed"}),
             (ab_ids, {"as_built": sorted(ab_ids), "as_built_note": "runs on tracks as built: the residual at the "
                       f"estimated road, over the fit band {lo}-{hi} Hz"}))
    for note in (note for ids, note in notes if ids):
        adequacy = dict(adequacy, **note)
    odd = _implausible(tracks_block)
    if odd:
        adequacy = dict(adequacy, adequate=False, advice=adequacy.get("advice") or ADVICE,
                        reasons=[f"the tracks as built needed more than a track carries ({'; '.join(odd)}; at most "
                                 f"±{100 * defaults['anyroad.plausible_factor']:.0f} % beyond twice the "
                                 f"factor's error, and {1e3 * defaults['anyroad.plausible_rms']:.1f} mm RMS at "
                                 f"waves up to {defaults['anyroad.plausible_wavelength']:g} m): "
                                 "the road is explaining what the model misses"] + list(adequacy["reasons"]))
    return adequacy, odd


def _road_hints(ds, P, geom, prob, adequacy, assess: bool, polish: bool) -> tuple[list, str]:
    """The coupling hints of the road fit (:func:`_road_sensor_hints`) and where they come from, from the first
    source that gives any (:data:`_HINT_SOURCES`); none when the adequacy has hints already (the fit on the tracks
    as drawn gave them)."""
    asked = {"verdict": adequacy is not None and not adequacy.get("sensor_hints"),
             "polish": assess and polish and not (adequacy or {}).get("sensor_hints")}
    for kind, when, note, threshold in _HINT_SOURCES:
        runs = [prob.parts[k].rr for k in prob.of(kind) if asked[when]]
        hints = _road_sensor_hints(P, geom, runs, ds, defaults[threshold]) if runs else []
        if hints:
            return hints, note
    return [], ROAD_HINTS_NOTE


#: where the road fit's coupling hints are asked, in order: (the blocks, asked after a verdict or after a polish,
#: the note, the setting of the residual's reduction that names a coupling)
_HINT_SOURCES = ((TrackBlock, "verdict", ROAD_HINTS_NOTE, "sensor_check.hint_reduction"),
                 (RoadBlock, "polish", FREE_ROAD_HINTS_NOTE, "sensor_check.free_road_hint_reduction"))


@dataclass
class _Outcome:
    """What the fit gives, for the result: the estimate (``x``, ``P``), its error bars and records, the
    fitted channels, the verdict and the road fit's coupling hints, the roads' and tracks' records, the
    search's record (``search``: ``(x0, nit, nfev, stop, history)``)."""

    x: np.ndarray
    P: np.ndarray
    fitted: _Fitted
    details: dict
    robust: object
    errors: list
    response: dict
    adequacy: dict | None
    hints: tuple
    tracks: dict | None
    motion: dict
    roads: dict
    profiles: dict
    search: tuple
    rng_record: dict
    wall: float

    @property
    def hinted(self) -> dict | None:
        """The verdict with the road fit's coupling hints (:func:`_with_hints`), when it has any."""
        return _with_hints(self.adequacy, *self.hints) if self.hints[0] else self.adequacy


def _drawn_runs(prob) -> list:
    """The problem's runs as drawn whose speed was estimated with the car (:class:`DrawnRun`)."""
    return [prob.parts[k] for k in prob.of(DrawnRun)]


def _preprocessing(pre: dict, prob) -> dict:
    """result.json ``preprocessing`` with the ``motion`` of each run as drawn whose speed was estimated with the car
    (:class:`DrawnRun`: ``speed`` as a road run's, the track, and how; not the speed held at load)."""
    pre = {rid: dict(rec) for rid, rec in pre.items()}
    for b in _drawn_runs(prob):
        if "speed" in b.record and b.run_id in pre:
            pre[b.run_id]["motion"] = drawn_motion_record(b.record, b.run)
    return pre


def _as_drawn_stands(ds, plan, start_result, out: _Outcome):
    """The tracks as built rejected (the road is not the explanation): the as-drawn result with its verdict and
    what the tracks as built needed; the speeds and starts the as-built fit found are the data's all the same
    (SPEC §13: named, not dropped)."""
    why = out.adequacy["reasons"][0]
    ad = dict(start_result.adequacy or {})
    if ad:
        ad["reasons"] = [f"tracks as built rejected: {why}"] + list(ad.get("reasons", []))
        if out.hints[0] and not ad.get("sensor_hints"):  # what the road fit saw of the sensors
            ad = _with_hints(ad, *out.hints)
    for rec in out.tracks.values():
        rec["rejected"] = why
    checks = [c for c in (start_result.checks or []) if c.get("check") != "motion"] + motion_findings(out.motion)
    return replace(start_result, adequacy=ad or start_result.adequacy, tracks=out.tracks, checks=checks,
                   wall_time_s=start_result.wall_time_s + out.wall)


def _on_start(ds, plan, start_result, out: _Outcome):
    """The as-drawn identification's search, weights, maps and starts stand; the estimate is the as-built fit's,
    and so are the estimates at a search bound (the as-drawn fit's bound findings replaced)."""
    info, space = out.fitted.info, plan.space
    checks = [c for c in (start_result.checks or []) if c.get("check") not in ("bounds", "motion")]
    checks += [f.to_dict() for f in mark_bounds(out.details)] + motion_findings(out.motion)
    return replace(start_result, checks=checks, x=np.asarray(out.x, dtype=float), names=list(space.names),
                   std=out.fitted.std, covariance=out.fitted.cov, fun=float(np.mean(out.errors)),
                   success=bool(start_result.success and info["success"]),
                   message=f"{start_result.message}; tracks as built: polish {info['message']}",
                   nfev=int(start_result.nfev + out.fitted.nfev),
                   parameters={nme: float(out.P[space.col[nme]]) for nme in space.reported_names},
                   details=out.details, wall_time_s=start_result.wall_time_s + out.wall,
                   polish=dict(info, as_drawn=start_result.polish),
                   modal=modal_summary(out.P[:len(ALL_NAMES)], ds.geometry), model=dict(plan.model),
                   response=out.response, correlation=out.robust.correlation_dict(), adequacy=out.hinted,
                   tracks=out.tracks, preprocessing=_preprocessing(start_result.preprocessing or {}, out.fitted.prob))


def _fresh(ds, plan, start_result, out: _Outcome):
    """The result of a fit from its own start."""
    info, space = out.fitted.info, plan.space
    _, nit, nfev, stop, history = out.search
    return IdentificationResult(
        x=np.asarray(out.x, dtype=float), names=list(space.names), std=out.fitted.std, covariance=out.fitted.cov,
        fun=float(np.mean(out.errors)),
        success=bool(info is None or info["success"]), message="unknown-road identification" +
        ("" if info is None else f"; polish: {info['message']}"), stop=stop, nit=int(nit),
        nfev=int(nfev + out.fitted.nfev),
        parameters={nme: float(out.P[space.col[nme]]) for nme in space.reported_names}, details=out.details,
        known=dict(ds.known), wall_time_s=out.wall, seed=out.rng_record["seed"],
        rng_state=out.rng_record["rng_state"], track_weights={}, weights_mode="equal", polish=info,
        history=History(history), starts={}, preprocessing=_preprocessing(ds.preprocessing(), out.fitted.prob),
        dataset=str(ds.path), maps=None,
        modal=modal_summary(out.P[:len(ALL_NAMES) if space.layout is None else space.layout.n_car], ds.geometry),
        model=dict(plan.model), response=out.response, correlation=out.robust.correlation_dict(),
        adequacy=out.hinted, checks=[f.to_dict() for f in getattr(ds, "findings", [])] + motion_findings(out.motion),
        roads=out.roads or None, road_profiles=out.profiles or None, tracks=out.tracks,
        dampers=road_curves.dampers(plan.space, out, plan.excitation),
        velocities=road_curves.velocities(plan.space, out.fitted.prob, out.P))


#: the result by (a start's result given, the tracks as built rejected)
_RESULTS = {(True, True): _as_drawn_stands, (True, False): _on_start, (False, True): _fresh, (False, False): _fresh}


def _fit(prob, z0, ds, polish: bool, probe: bool = False) -> _Fitted:
    """The polish and the error bars from ``z0``; unpolished, the start as it is. A ``probe`` (a candidate of the
    model choice whose cost alone is wanted first): the first joint solve from the placements at the start, no
    refinement, no error bars (their true Hessian is most of a road fit's time); its cost is then at or above the
    candidate's least, so a gain it shows is one the candidate has (:func:`_first_solve`)."""
    nan = np.full(len(prob.space.names), np.nan)
    if not polish:
        return _Fitted(z0, prob, None, nan, np.full((nan.size,) * 2, np.nan))
    if probe:
        sol, prob, _ = _first_solve(prob, z0, ds)
        return _Fitted(sol.x, prob, None, nan, np.full((nan.size,) * 2, np.nan), int(sol.nfev) * (nan.size + 1))
    sol, prob, cost_before, restarted = _polish(prob, z0, ds)
    return _error_bars(prob, sol, ds, cost_before, restarted)


@stage("roads and tracks as built")
def _identify_any_road(ds, *, rng=None, seed=None, population=None, generations=None, model=None,
                       polish: bool = True, callback=None, assess: bool = True, simulator=None,
                       tracks: str = "as-built", start_result=None, as_built_mode: str = "prior", start=None,
                       probe: bool = False, parent: dict | None = None, **_ignored) -> IdentificationResult:
    """The pipeline on the problem of ``ds`` (:class:`_Plan`): start, polish, error bars, records, verdict. With
    damper curves on unknown roads, ``parent`` (a linear fit's parameters) starts them
    (:func:`rideid.estimate.fit.road_curves.start`)."""
    t0 = time.perf_counter()
    gen, rng_record = make_rng(rng, seed)
    geom = ds.geometry
    plan = _plan(ds, model, start_result, tracks, polish, as_built_mode)

    def linear(kw):  # the linear model's first joint solve: where damper curves named without a start begin
        return _identify_any_road(ds, model=road_curves.linear_groups(plan.ext), probe=True, assess=False, **kw)
    start = road_curves.start(plan, start, start_result, parent, lambda: linear(
        dict(rng=gen, population=population, generations=generations, callback=callback, simulator=simulator,
             tracks=tracks)).parameters)
    search = _start(ds, plan, gen, population or DEFAULT_POPULATION, generations or DEFAULT_GENERATIONS, polish,
                    callback, simulator, start_result, t0, start)
    plan = replace(plan, roads=road_curves.held(plan.space, plan.roads, search[0]))
    prob = plan.problem(ds, geom, simulator)
    fitted = _fit(prob, prob.v(search[0]), ds, polish, probe)
    x = fitted.prob.x(fitted.z)
    P = plan.space.full(x[None])[0]
    details, robust = _details(plan.space, x, P, fitted)
    road_blocks = [fitted.prob.parts[k] for k in fitted.prob.of(RoadBlock)]  # each at its estimated speed
    roads, profiles, response, errors = _road_records(ds, P, geom, road_blocks)
    response_t, errors_t, checked = _checked(ds, P, geom, x, fitted.prob)
    blocks = [fitted.prob.parts[k] for k in fitted.prob.of(TrackBlock)]
    tracks, motion = tracks_block(ds, blocks, plan.skipped, P, geom) if blocks else (None, {})
    drawn = {b.run_id: drawn_motion_record(b.record, b.run) for b in _drawn_runs(fitted.prob) if "speed" in b.record}
    motion = {**{b.run_id: b.record for b in road_blocks if "speed" in b.record}, **motion, **drawn}
    adequacy, odd = (_verdict(checked, plan.ext, list(roads), [b.run_id for b in blocks], tracks or {})
                     if assess and checked else (None, []))
    if assess and polish:  # every run assessed: the road runs by their residual at their own road estimate
        adequacy = judge_road_runs(adequacy, roads, [b.rr for b in road_blocks],
                                   {b.rr.run_id: ds.data[b.rr.run_id].matrix() for b in road_blocks}, response)
    adequacy = _carry_sensor_hints(adequacy, start_result)
    road_hints, hints_note = _road_hints(ds, P, geom, fitted.prob, adequacy, assess, polish)
    if road_hints and adequacy is None:  # unknown roads alone: no residual verdict, but the sensors' is one
        adequacy = {"adequate": False, "not_assessed": list(roads), "reasons": [], "advice": None,
                    "note": "runs on unknown roads alone: the residuals are not assessed; the sensor check of the "
                            "road fit is"}
    out = _Outcome(x, P, fitted, details, robust, errors + errors_t, dict(response, **response_t), adequacy,
                   (road_hints, hints_note), tracks, motion, roads, profiles, search, rng_record,
                   time.perf_counter() - t0)
    return _RESULTS[(start_result is not None, bool(odd))](ds, plan, start_result, out)


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "SPEED_TOLERANCE": "anyroad.speed_tolerance", "HELD_SPEED": "anyroad.held_speed", "PLAUSIBLE_FACTOR":
    "anyroad.plausible_factor", "PLAUSIBLE_RMS": "anyroad.plausible_rms", "PLAUSIBLE_WAVELENGTH":
    "anyroad.plausible_wavelength", "SPREAD_TOL": "anyroad.spread_tol", "JOINT_MOTION_BOUND":
    "anyroad.joint_motion_bound", "MOTION_NAMED": "anyroad.motion_named"})
