"""Damper curves on unknown roads (docs/any-road.md, "Damper curves on unknown roads").

The road fit (:mod:`rideid.estimate.fit.anyroad`) keeps a linear car and moves the curves into the data: each road
run's departure of the damper force from the linear car's ``c v`` at the suspension velocities the accelerometers
measure (:class:`rideid.estimate.problem.roadfit.Departure`). This module owns what that takes: which models the
roads can take (:func:`refuse`), the knots and the ones the measured velocities excite (:func:`knots`,
:func:`excited`), where the curves start (:func:`start`), the linear car held through the fit (:func:`held`), and
the result's blocks (:func:`dampers`, :func:`velocities`) with the velocities' noise as an error term
(:func:`velocity_std`).

The velocities' error
---------------------
On an unknown road the curves' force enters the fit at the suspension velocities read off each corner's body and
axle accelerometers (:func:`rideid.estimate.problem.roadfit.suspension_velocities`); those velocities carry the
sensors' noise, integrated. The sandwich of ``std_robust`` holds them as they are, so it leaves out what that noise
does to the knot forces: errors in variables, a bias where a curve bends (the noise blurs the kink at 0 of a damper
stiffer in rebound) and a spread. Measured here by simulation (SIMEX, Cook and Stefanski, 1994): the velocities with
as much noise again (each channel's level from the road fit's residual, :func:`rideid.estimate.problem.roadfit.
channel_noise`, white), every parameter solved again (one Newton step on the fit's own true Hessian), setting
``roadfit.velocity_draws`` draws. A bias that grows with the noise's variance grows by as much again, so the
draws' mean shift stands for the bias the noise already present caused, and their spread for its spread:
With them a third term, the drift's model: the estimates' shift when the velocities are taken with the drift's
spline knots twice as far apart (near a record's ends the spline cannot tell the drift from the suspension's
slowest motion; on short runs that is most of the velocities' error, measured in docs/any-road.md).
``std_velocity`` is the root of the sum of the three squares, combined in quadrature into ``std_robust`` of every
parameter (as the knee grid's ``std_grid`` of the knot forces). The runs on known tracks hold their simulated
velocities.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...data.schema import NONLINEAR_GROUPS
from ...errors import ArgumentError
from ...profiling import timing
from ...settings import defaults
from ..assess.adequacy import setup_slips
from ..assess.responses import suspension_velocities
from ..problem import roadfit
from ..problem.blocks import DrawnTracks, RoadBlock, speed_runs, unknown_road_runs
from ..problem.cost import CURVES
from ..problem.dampers import add_grid_std, add_std_term, dampers_block, excitation_of


def refusal(ds, ext) -> str | None:
    """Why the model ``ext`` cannot be fitted on the unknown roads of ``ds`` (one line), or None: bump stops cannot
    (the projection needs a car linear in its states); damper curves need each road run's body and axle
    accelerometers at all four corners (the suspension velocities)."""
    road_ids = [r.id for r in unknown_road_runs(ds, ext)]
    bad = [g for g in ext if g in NONLINEAR_GROUPS and g != CURVES]
    if bad and road_ids:
        return (f"{', '.join(bad)}: a model with bump stops cannot be fitted with runs on unknown roads "
                f"({', '.join(road_ids)}): the road is projected out of a car linear in its states "
                f"(docs/any-road.md); fit it without {' and '.join(bad)}, or on known tracks only")
    lacking = {rid: roadfit.missing_corners(ds.data[rid].matrix()) for rid in road_ids if CURVES in ext}
    rid = next((r for r, lack in lacking.items() if lack), None)
    if rid is None:
        return None
    return (f"damper_curves: run '{rid}' on an unknown road lacks {', '.join(lacking[rid])}: the damper curves are "
            "read there from each corner's body and axle accelerometers (docs/any-road.md); fit the linear "
            "dampers, or leave the run out")


def refuse(ds, ext) -> None:
    """One clear error when the model ``ext`` cannot be fitted on the unknown roads of ``ds`` (:func:`refusal`)."""
    why = refusal(ds, ext)
    if why:
        raise ArgumentError(why)


def knots(ds, ext, road_ids):
    """The parameter space's ``damper_knots``: with damper curves and road runs the dataset's, else the knee grid
    (setting ``dampers.knee_grid``: the knees read off it, as on tracks); else the dataset's."""
    if CURVES in ext and road_ids:
        return ds.manifest.damper_knots or defaults["dampers.knee_grid"]
    return ds.manifest.damper_knots


def layout_knots(space, road_ids):
    """The signed knots the road runs' departures are built on (None: no curves on roads)."""
    return space.layout.knots if space.curves and road_ids else None


def excited(space, rruns) -> tuple:
    """``(space, excitation)``: with damper curves on the roads ``rruns`` the knots their measured suspension
    velocities do not reach frozen, and the excitation record (:func:`rideid.estimate.problem.dampers.excitation_of`);
    else ``(space, None)``."""
    v = [rr.dep.v for rr in rruns if rr.dep is not None]
    if not v:
        return space, None
    rec = excitation_of(space, (np.concatenate([t[:, :2].ravel() for t in v]),
                                np.concatenate([t[:, 2:].ravel() for t in v])),
                        by="the suspension velocities measured on the unknown roads")
    return space.with_frozen(rec["frozen"]), rec


def candidates(ds, parent, key) -> list:
    """The damper-curve candidates of the road model choice on top of ``parent`` (the model ``key`` kept): none
    when its verdict is adequate (or not given), when it names a set-up slip the curves' fit would hold (a sensor's
    coupling or gain, or a declared speed the data moved of a run whose speed that fit does not estimate: curves
    would take up what no model extension mends, and the advice says to mend the set-up first), when the dataset
    knows the dampers' rates, or when the roads cannot take curves (:func:`refusal`); else the one model with the
    curves (its groups, in no order). A speed slip of a road run or of a run the curves take as drawn with its speed
    estimated (:func:`rideid.estimate.problem.blocks.speed_runs`) is mended with the curves as with the linear car:
    measured on ../shared/cases/van-roads-dampers with its twist run typed 3.03 m/s (docs/any-road.md)."""
    with_curves = tuple(key) + (CURVES,)
    adequacy = parent.adequacy or {}
    if (adequacy.get("adequate", True) or held_slips(ds, parent, with_curves) or adequacy.get("sensor_hints")
            or {"c_sf", "c_sr"} & set(ds.known) or refusal(ds, with_curves)):
        return []
    return [with_curves]


def held_slips(ds, parent, ext) -> list:
    """The set-up slips ``parent`` names (:func:`rideid.estimate.assess.adequacy.setup_slips`) of runs whose speed a
    fit of the model ``ext`` on unknown roads holds: not a road run's, nor a run's as drawn with its speed
    estimated (:func:`rideid.estimate.problem.blocks.speed_runs`)."""
    estimated = {r.id for r in unknown_road_runs(ds, ext)} | {r.id for r in speed_runs(ds, ext)}
    return [s for s in setup_slips(parent.checks) if s["run"] not in estimated or s["declared"] is None]


def road_note(rr) -> str:
    """What a road run's record adds with damper curves (``roads.<run>.note``)."""
    if rr.dep is None:
        return ""
    return ("; with damper curves the first and last 2 s are less certain still (the suspension velocities read off "
            "the accelerometers ring there: docs/any-road.md)")


def linear_groups(ext) -> list:
    """The model ``ext`` without its damper curves."""
    return [g for g in ext if g != CURVES]


def start(plan, given, start_result, parent, linear):
    """Where damper curves on unknown roads start: ``given`` when given (or a start result), else a linear fit's
    dampers as curves ``F = c v`` (as on tracks, where the search runs on the linear car): ``parent``'s
    parameters, else ``linear()``'s (the linear model's first joint solve)."""
    if not (plan.space.curves and plan.roads) or given is not None or start_result is not None:
        return given
    vals = dict(parent or linear())
    space = plan.space
    vals.update({n: vals[f"c_s{n[2]}"] * v for n, v in zip(space.knot_names, space.knot_velocities())})
    return np.clip([vals[n] for n in space.names], space.bounds[:, 0], space.bounds[:, 1])


def held(space, roads, x0) -> list:
    """The road blocks ``roads`` with their linear car held at the start ``x0``'s damper rates (the curves' mean
    slopes, :class:`rideid.estimate.problem.roadfit.Departure` ``c_ref``): a knot force then moves the curves'
    known input alone, and a car's projection serves every knot force (docs/any-road.md: the error bars' second
    differences 274 s -> 83 s on the shared van)."""
    if not (space.curves and roads):
        return roads
    P0 = space.full(np.asarray(x0, dtype=float)[None])[0]
    c_ref = (float(P0[space.col["c_sf"]]), float(P0[space.col["c_sr"]]))
    return [replace(b, rr=replace(b.rr, dep=replace(b.rr.dep, c_ref=c_ref))) for b in roads]


def dampers(space, out, excitation) -> dict | None:
    """SPEC §8's damper curves of a fit on unknown roads (``out``: ``anyroad._Outcome``) with the knots the
    measured velocities excite; on the knee grid its approximation error, and with error bars the velocities'
    noise (:func:`velocity_std`), both in ``std_robust`` of ``out.details`` too. None without curves."""
    if not space.curves:
        return None
    r = out.robust
    block = dampers_block(space, out.P, r.white, r.robust, r.names, excitation)
    if block.get("knots_from", "").startswith("found"):
        add_grid_std(out.details, block, space, out.P)
    f = out.fitted
    if f.hessian is None:
        return block
    with timing("curves' velocity error"):
        term = velocity_std(f.prob, f.z, f.hessian, f.jacobian)
    add_std_term(out.details, block, space, term, "std_velocity")
    return dict(block, velocity_note=VELOCITY_NOTE)


def velocities(space, prob, P) -> dict | None:
    """With damper curves, result.json's ``velocities`` (run id -> front and rear suspension velocities, the report's
    histograms): on each unknown road of ``prob`` the measured ones, on the tracks those of the car ``P``."""
    if not space.curves:
        return None
    vel = {b.run_id: (b.rr.dep.v[:, :2].ravel(), b.rr.dep.v[:, 2:].ravel())
           for b in (prob.parts[k] for k in prob.of(RoadBlock))}
    for k in prob.of(DrawnTracks):
        vel.update(suspension_velocities(prob.parts[k].cf, P))
    return vel


#: result.json ``dampers.velocity_note`` of curves fitted on unknown roads
VELOCITY_NOTE = ("on unknown roads the curves' force is taken at the suspension velocities read off the body and axle "
                 "accelerometers: their noise's effect on the estimates (a bias where a curve bends, and a spread) "
                 "is std_velocity, estimated by simulation and included in std_robust (docs/any-road.md)")


def velocity_std(prob, z, H, J) -> dict:
    """Name -> ``std_velocity`` of each reported parameter at the fit ``z`` of the problem ``prob``
    (:class:`rideid.estimate.problem.joint.JointProblem`; ``H`` its true half Hessian and ``J`` its residuals'
    Jacobian there, in its ``v`` units): module docstring. Each draw's shift is the Newton step ``-H^+ J^T de`` of
    the residuals' change ``de`` (the road runs' at the noisier velocities; the gradient is 0 at the fit)."""
    space = prob.space
    roads = prob.of(RoadBlock)
    if not roads or not space.curves:
        return {}
    x = prob.x(z)
    P = space.full(x[None])[0]
    offs = np.concatenate([[0], np.cumsum(prob.sizes)])
    base = {k: roadfit.residuals(P, prob.geom, prob.parts[k].rr) for k in roads}
    sigma = {k: roadfit.channel_noise(roadfit.solve(P, prob.geom, prob.parts[k].rr)) for k in roads}
    Hinv = np.linalg.pinv(H, rcond=1e-12, hermitian=True)

    def shifted(dv) -> np.ndarray:  # the car's full row after one Newton step with the velocities moved by dv
        de = np.zeros(offs[-1])
        for k in roads:
            rr = prob.parts[k].rr
            dep = roadfit.departure_at(rr.dep.v + dv[k], rr.dep.knots, rr.dep.c_ref)
            de[offs[k]:offs[k + 1]] = prob.scale[k] * (roadfit.residuals(P, prob.geom, replace(rr, dep=dep))
                                                       - base[k])
        return space.full((x + prob.dxdv(z) * (-Hinv @ (J.T @ de)))[None])[0]

    rng = np.random.default_rng(defaults["roadfit.velocity_seed"])
    rows = [shifted({k: roadfit.suspension_velocities(_noise(prob.parts[k].rr, sigma[k], rng), prob.parts[k].rr.fs)
                     for k in roads}) for _ in range(defaults["roadfit.velocity_draws"])]
    # the drift's model: the velocities with the spline's knots twice as far apart
    drift = shifted({k: roadfit.suspension_velocities(_accelerations(prob, k), prob.parts[k].rr.fs,
                                                      2 * defaults["roadfit.velocity_drift"]) - prob.parts[k].rr.dep.v
                     for k in roads})
    D = np.array(rows) - P
    names = [n for n in space.reported_names if n not in space.fixed and n not in set(space.frozen)]
    cols = [space.col[n] for n in names]
    s = np.sqrt(D[:, cols].mean(axis=0) ** 2 + D[:, cols].std(axis=0, ddof=1) ** 2 + (drift - P)[cols] ** 2)
    return {n: float(v) for n, v in zip(names, s)}


def _noise(rr, sigma, rng) -> np.ndarray:
    """White noise (n, 10) of each used accelerometer's level ``sigma`` (``rr.cols`` order), 0 elsewhere."""
    noise = np.zeros((rr.n, 10))
    for j, ch in enumerate(rr.cols):
        if ch < 8:
            noise[:, ch] = sigma[j] * rng.standard_normal(rr.n)
    return noise


def _accelerations(prob, k) -> np.ndarray:
    """The channels (n, 10) road block ``k`` of ``prob`` read its suspension velocities from."""
    return prob.parts[k].rr.dep.y
