"""The residual blocks of a fit with roads (SPEC §9, §11, §13): each block owns its nuisance unknowns.

A fit with unknown roads or tracks as built (:mod:`rideid.estimate.fit.anyroad`) is one least-squares problem
over the car's parameters whose residual is a list of blocks of three kinds, with one interface:

- :class:`DrawnTracks`: the runs on tracks taken as drawn, in the time domain
  (:class:`rideid.estimate.problem.cost.CostFunction`, the runs weighed alike);
- :class:`RoadBlock`: a run on an unknown road, the road projected out frequency by frequency
  (:mod:`rideid.estimate.problem.roadfit`; the state at the first sample and the road its nuisances);
- :class:`TrackBlock`: a run on a track as built (:mod:`rideid.estimate.problem.asbuilt`; the track's amplitude
  factor and unevenness its nuisances) and where the car was on it, the run's constant speed and start, each
  under its prior (SPEC §13; :class:`rideid.estimate.problem.asbuilt.MotionPrior`).

Each block gives its residuals at a car (:meth:`residuals`), whether the fit divides it by its own RMS
(``reweighted``: a track as built is whitened bin by bin already), its share of the sandwich's meat
(:meth:`meat`), its thread-scheduling key (``order``: the longest first) and its line of the polish's
``method``. A track block's motion is solved with the car: :meth:`TrackBlock.moved` places the drawing,
:meth:`TrackBlock.prior_rows` weighs the set-up's priors, :meth:`TrackBlock.motion_jacobian` gives the error
bars' columns. The placement before the solve (:meth:`TrackBlock.aligned`, Nelder-Mead) minimises the same
block's cost, the same moved drawing and prior rows, over its motion alone, the car held: where the car was on
the track is one block's unknowns, placed and then solved with the car."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from ...data.schema import NONLINEAR_GROUPS
from ...errors import ArgumentError, DataError
from ...model.equations import CHANNELS
from ...settings import defaults
from ...profiling import stage
from . import asbuilt, roadfit
from .cost import CostFunction
from .scores import andrews_bandwidth, long_run_covariance, run_scores


def road_meat(J, e, m_per_bin: int) -> np.ndarray:
    """Sum over DFT bins of ``(J_k^T e_k)(J_k^T e_k)^T`` (each bin's rows one cluster)."""
    g = (J * e[:, None]).reshape(-1, m_per_bin, J.shape[1]).sum(axis=1)
    return g.T @ g


def track_meat(J, e, cf) -> np.ndarray:
    """The HAC long-run covariance of the gradient of the runs on tracks as drawn (``cf``), run by run."""
    blocks = [(int(e_ - s), int(np.count_nonzero(cf.W[ri] > 0)))
              for ri, (s, e_) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))]
    S = np.zeros((J.shape[1], J.shape[1]))
    for G in run_scores(J, e, blocks):
        S += long_run_covariance(G, andrews_bandwidth(G))
    return S


@dataclass(frozen=True)
class DrawnTracks:
    """The runs on tracks taken as drawn: the time-domain residuals of ``cf``, every run weighed alike."""

    cf: object
    reweighted = True
    rank = 2
    method = "runs on tracks as drawn in the time domain"

    @property
    def order(self) -> float:
        return -np.inf

    def residuals(self, x, P, geom) -> np.ndarray:
        return self.residual_rows(x[None])[0]

    def residual_rows(self, X) -> np.ndarray:
        """The residuals (n, m) of the free parameters' rows ``X`` (n, d) at once: the simulator's population."""
        n = len(self.cf.run_ids)
        return self.cf.residuals(X, np.full(n, 1.0 / n))

    def meat(self, J, e, s2) -> np.ndarray:
        return track_meat(J, e, self.cf)


class _OneRun:
    """What a block that owns one run's road-fitted channels (``rr``) says of itself: the run, and its order in
    the threads (the longest first)."""

    @property
    def run_id(self) -> str:
        return self.rr.run_id

    @property
    def order(self) -> float:
        return -self.rr.fit.size

    @property
    def motion_steps(self) -> tuple:
        """The joint solve's difference steps of the block's ``n_motion`` unknowns (setting
        ``asbuilt.motion_jacobian_steps``: the speed's, the start's)."""
        return tuple(defaults["asbuilt.motion_jacobian_steps"][:self.n_motion])

    @property
    def motion_bound(self) -> float:
        """How far (setting ``asbuilt.motion_scale`` units, either way) the joint solve may move the motion: setting
        ``anyroad.joint_motion_bound``."""
        return float(defaults["anyroad.joint_motion_bound"])

    def motion_cost(self, P, geom, ds, weight: float):
        """``cost(p)``: the block's squared residual at the car ``P`` with its motion moved by ``p`` (:meth:`moved`),
        plus its set-up priors' rows weighed at ``weight`` (:meth:`prior_rows`): what a placement minimises."""
        def cost(p):
            return (float(np.sum(self.moved(ds, p).residuals(None, P, geom) ** 2))
                    + float(np.sum(self.prior_rows(p, weight) ** 2)))
        return cost

    def motion_jacobian(self, P, geom, ds) -> np.ndarray:
        """The Jacobian (m, ``n_motion``) of the block's residuals in its motion (the speed relative, the start s),
        by central differences of :meth:`moved` at :attr:`motion_steps`: the columns that put the motion's
        uncertainty into the error bars (rideid.estimate.fit.anyroad's sandwich)."""
        cols = []
        for j, h in enumerate(self.motion_steps):
            p = np.zeros(self.n_motion)
            p[j] = h
            d = self.moved(ds, p).residuals(None, P, geom) - self.moved(ds, -p).residuals(None, P, geom)
            cols.append(d / (2 * h * defaults["asbuilt.motion_scale"][j]))
        return np.stack(cols, axis=1)

    @property
    def speed(self) -> float:
        """The run's speed as the block is placed (m/s)."""
        return float(self.rr.speed)

    def prior_jacobian(self, weight: float) -> np.ndarray:
        """(rows, ``n_motion``): the set-up priors' rows' derivatives in the motion (none without a prior)."""
        if self.prior is None:
            return np.zeros((0, self.n_motion))
        return self.prior.jacobian(self.speed, weight)[:, :self.n_motion]

    def scan_speed(self, P, geom, ds):
        """The block at the speed that minimises its cost at the car ``P`` with its declared speed's row (weighed
        at its own residual level, as the joint solve weighs it): a scan over the joint solve's range
        (:attr:`motion_bound`) at setting ``anyroad.road_speed_scan`` steps, then a bounded Brent search between
        the best point's neighbours (:meth:`RoadBlock.aligned` says why a scan first)."""
        motion = self.motion_cost(P, geom, ds, self.level(P, geom))

        def cost(p):
            return motion([p])

        bound, step = self.motion_bound, defaults["anyroad.road_speed_scan"]
        grid = np.arange(-bound, bound + 0.5 * step, step)
        costs = [cost(p) for p in grid]
        j = int(np.argmin(costs))
        sol = minimize_scalar(cost, bounds=(grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]), method="bounded",
                              options={"xatol": defaults["asbuilt.motion_xtol"]})
        best = sol.x if sol.fun < costs[j] else grid[j]
        return self.moved(ds, [best]).settled(ds)

    def prior_bound(self) -> float:
        """How far the speed may move (setting ``asbuilt.motion_scale`` units, either way): setting
        ``anyroad.joint_motion_bound``, or four prior std where the declared speed is wider (a speedometer's
        ``speed = { value = 11.0, std = 0.4 }``)."""
        if self.prior is None or self.prior.speed is None:
            return float(defaults["anyroad.joint_motion_bound"])
        return asbuilt.speed_move_bound(*self.prior.speed[:2])


@dataclass(frozen=True)
class RoadBlock(_OneRun):
    """A run on an unknown road (or moving at its first sample): ``rr`` its
    :class:`rideid.estimate.problem.roadfit.RoadRun`; the meat the gradient's spread over DFT bins.

    Its motion unknown is its speed (SPEC §13: a declared speed is a prior, ``prior`` its
    :class:`rideid.estimate.problem.asbuilt.MotionPrior` with the speed alone, none along a speed channel), which
    sets the rear wheels' delay ``wheelbase / speed``: a road run has no start to place. Measured on a van on three
    ISO roads (../shared/cases/van-roads-dampers with linear dampers, 2 % noise), one run's speed typed 1 % high
    and taken as exact: m_uf -0.42 % (4 std_total), the tires -0.33 %, "not adequate" without a word on the speed;
    estimated with the car (docs/any-road.md). ``record``: the speed as solved (``speed_m_s``)."""

    rr: roadfit.RoadRun
    prior: asbuilt.MotionPrior | None = None
    record: dict = field(default_factory=dict)
    reweighted, rank = True, 0
    method = "road runs by frequency-domain variable projection (rideid.estimate.problem.roadfit)"
    #: the motion unknowns: the speed's relative change (setting ``asbuilt.motion_scale`` units)
    n_motion = 1

    @classmethod
    def of(cls, rr: roadfit.RoadRun, prior: asbuilt.MotionPrior | None, geom) -> RoadBlock:
        """The block of ``rr`` with its rear lead-in unknowns held at the count the slowest speed the joint solve
        may try needs (:attr:`motion_bound`), so its cost is smooth in the speed."""
        b = cls(rr, prior, {"speed_m_s": float(rr.speed)})
        slowest = rr.speed * (1.0 - min(b.motion_bound * defaults["asbuilt.motion_scale"][0], 0.5))
        lead = int(np.floor(geom.wheelbase / slowest * rr.fs)) + defaults["roadfit.delay_order"] + 2
        return replace(b, rr=replace(rr, lead=max(lead, rr.lead_in)))

    @property
    def motion_bound(self) -> float:
        return self.prior_bound()

    def residuals(self, x, P, geom) -> np.ndarray:
        return roadfit.residuals(P, geom, self.rr)

    @property
    def affine_in_knots(self) -> bool:
        """Whether the residuals are affine in the damper curves' knot forces: with curves they enter as a known
        input of the linear car (:class:`rideid.estimate.problem.roadfit.Departure`), its projection the same
        (the error bars' Hessian takes their entries exactly: rideid.estimate.problem.joint.JointProblem.hessian)."""
        return self.rr.dep is not None and self.rr.dep.c_ref is not None

    def meat(self, J, e, s2) -> np.ndarray:
        return road_meat(J, e, 2 * len(self.rr.cols))

    @stage("road speed alignment")
    def aligned(self, P, geom, ds, mode: str = "prior") -> RoadBlock:
        """The block at the speed that minimises its cost at the car ``P`` with its declared speed's row (weighed
        at its own residual level, as the joint solve weighs it): a scan over the joint solve's range
        (:attr:`motion_bound`) at setting ``anyroad.road_speed_scan`` steps, then a bounded Brent
        search between the best point's neighbours. The cost is a narrow valley in the speed (the delay's phase
        over the fit band): on the van's 50 km/h run typed 1 % fast, at the car fitted with it, the cost is 2.2e6
        at the declared speed, 2.5e4 at the true one and 5.8e5 half-way, and the joint solve's trust region
        started at the declared speed shrank to nothing (the speed kept). In the track blocks' first ``mode``
        ("amplitude": their drawing alone) the block stays where it is: it has no drawing to place."""
        return self if mode == "amplitude" else self.scan_speed(P, geom, ds)

    def with_prior(self, P, geom) -> RoadBlock:
        """The block as it is (a road run's levels are its block weight's: :meth:`level`)."""
        return self

    def moved(self, ds, p) -> RoadBlock:
        """The block at its speed moved by ``p[0]`` (setting ``asbuilt.motion_scale`` units): the delay at it."""
        v = self.rr.speed * (1.0 + p[0] * defaults["asbuilt.motion_scale"][0])
        return replace(self, rr=replace(self.rr, speed=v, tau=ds.geometry.wheelbase / v))

    def settled(self, ds) -> RoadBlock:
        """The block with its record at its speed."""
        return replace(self, record=dict(self.record, speed_m_s=float(self.rr.speed)))

    def level(self, P, geom) -> float:
        """The RMS of the block's residual at the car ``P`` (unscaled: the problem weighs it by its scale)."""
        return float(np.sqrt(np.mean(roadfit.residuals(P, geom, self.rr) ** 2)))

    def prior_rows(self, p, weight: float) -> np.ndarray:
        """The declared speed's row at the motion ``p`` (none along a speed channel)."""
        return np.zeros(0) if self.prior is None else self.prior.rows(self.rr.speed, 0.0, p, weight)


@dataclass(frozen=True)
class DrawnRun(_OneRun, DrawnTracks):
    """One run on a track taken as drawn at a declared constant speed, its speed estimated with the car (SPEC §13:
    a declared speed is a prior, ``prior`` its :class:`rideid.estimate.problem.asbuilt.MotionPrior` with the speed
    alone): the time-domain residuals of ``cf`` (that run alone, read at the block's speed), as
    :class:`DrawnTracks`. A run fitted on a nonlinear car (damper curves, bump stops) cannot be taken as built,
    and a speed held where the data put it at load (a grid step of 0.25 %) is not exact enough for it: measured on
    the van of ../shared/cases/van-roads-dampers with its twist run typed 3.03 m/s (driven at 3.0), the damper
    curves with that run held at 3.0019 m/s (the linear fit's speed as built) gave k_tf -4.7 %, k_tr -4.1 %, not
    adequate; declared 3.0, adequate (docs/any-road.md). ``record``: the speed as solved (``speed_m_s``)."""

    run: object = None
    prior: asbuilt.MotionPrior | None = None
    record: dict = field(default_factory=dict)
    #: the motion unknowns: the speed's relative change (setting ``asbuilt.motion_scale`` units)
    n_motion = 1
    method = "runs on tracks as drawn in the time domain, each speed estimated with the car"

    @classmethod
    def of(cls, ds, run, space, simulator) -> DrawnRun:
        """The block of ``run`` of ``ds`` at its speed there (the declared one, or where the data put it at load)."""
        cf = CostFunction(ds.subset([run]), space=space, simulator=simulator)
        return cls(cf, run, asbuilt.MotionPrior(speed=run.speed_prior(), start=None),
                   {"speed_m_s": float(run.speed)})

    @property
    def run_id(self) -> str:
        return self.run.id

    @property
    def order(self) -> float:
        return -np.inf

    @property
    def speed(self) -> float:
        return float(self.record["speed_m_s"])

    @property
    def motion_bound(self) -> float:
        return self.prior_bound()

    def residuals(self, x, P, geom) -> np.ndarray:
        """The run's residuals at the free row ``x``, or (``x`` None) at the car ``P``."""
        if x is None:
            space = self.cf.space
            x = np.array([P[space.col[n]] for n in space.names])
        return self.residual_rows(np.asarray(x, dtype=float)[None])[0]

    def aligned(self, P, geom, ds, mode: str = "prior") -> DrawnRun:
        """The block at the speed its cost at the car ``P`` is least (:meth:`scan_speed`); in the track blocks'
        first ``mode`` ("amplitude") where it is."""
        return self if mode == "amplitude" else self.scan_speed(P, geom, ds)

    def with_prior(self, P, geom) -> DrawnRun:
        return self

    def moved(self, ds, p) -> DrawnRun:
        """The block with the run read at its speed moved by ``p[0]`` (setting ``asbuilt.motion_scale`` units)."""
        v = self.speed * (1.0 + p[0] * defaults["asbuilt.motion_scale"][0])
        cf = self.cf.with_data(ds.subset([self.run]).with_speeds({self.run.id: v}))
        return replace(self, cf=cf, record=dict(self.record, speed_m_s=float(v)))

    def settled(self, ds) -> DrawnRun:
        return self

    def level(self, P, geom) -> float:
        """The RMS of the run's residual at the car ``P``: the weight its prior's row takes."""
        return float(np.sqrt(np.mean(self.residuals(None, P, geom) ** 2)))

    def prior_rows(self, p, weight: float) -> np.ndarray:
        """The declared speed's row at the motion ``p``."""
        return self.prior.rows(self.speed, 0.0, p, weight)


@dataclass(frozen=True)
class TrackBlock(_OneRun):
    """A run on a track as built, ``tr`` (:class:`rideid.estimate.problem.asbuilt.TrackRun`), with where the car
    was on it: ``run`` (the manifest's run), ``prior`` (:class:`rideid.estimate.problem.asbuilt.MotionPrior`) and
    ``record`` (the motion as last placed or solved: ``speed_m_s``, ``start_shift_s``, ...; the result's
    ``motion``). The meat is the white one (:func:`rideid.estimate.problem.asbuilt.meat` says why)."""

    tr: asbuilt.TrackRun
    run: object
    prior: asbuilt.MotionPrior
    record: dict = field(default_factory=dict)
    reweighted = False
    rank = 1
    #: the motion unknowns: the speed's relative change and the start's shift (setting ``asbuilt.motion_scale``)
    n_motion = 2
    method = "runs on tracks as built (rideid.estimate.problem.asbuilt)"

    @property
    def rr(self) -> roadfit.RoadRun:
        """The run's channels as an unknown-road run (the road fit's view of it)."""
        return self.tr.rr

    def residuals(self, x, P, geom) -> np.ndarray:
        return asbuilt.residuals(P, geom, self.tr)

    def meat(self, J, e, s2) -> np.ndarray:
        return asbuilt.meat(J, e, self.tr, s2)

    def with_prior(self, P, geom) -> TrackBlock:
        """The block with its noise and unevenness levels estimated at the car ``P``
        (:func:`rideid.estimate.problem.asbuilt.estimate_prior`)."""
        return replace(self, tr=replace(self.tr, prior=asbuilt.estimate_prior(P, geom, self.tr)))

    @stage("motion alignment")
    def aligned(self, P, geom, ds, mode: str = "prior") -> TrackBlock:
        """The block placed at the car ``P`` by its motion alone: the speed and the start that minimise its cost in
        ``mode`` (:data:`rideid.estimate.problem.asbuilt.MODES`; the prior as the block has it) with its set-up
        priors' rows (:meth:`prior_rows`, weighed at its own residual level: the same rows and the same moved
        drawing, :meth:`moved`, that the joint solve of the car and the motion takes, rideid.estimate.fit.anyroad),
        from where it is (Nelder-Mead: the cost is flat to a few per cent over millimetres, and a gradient solver
        stopped on its tolerance where it began). The drawing at ``x = v (t - shift)``, the rear wheels' delay at
        ``v``; the tabulated inputs renewed; the record ``{"speed_m_s", "start_shift_s", "speed_channel_mean_m_s"}``
        (``start_shift_s`` from the start as read).

        Two passes place a drawing (rideid.estimate.fit.anyroad's polish): "amplitude" first (the drawing alone:
        sharp, but the unevenness, weighed as if it were sensor noise, pulls it: H_HH's speed +0.5 to +1.1 % off at
        the true car of the all-realities case, seeds 1-3), the prior estimated again there, then "prior" from that
        placement. The prior alone cannot start: a drawing placed by the channel's speed is off at its own lines,
        the prior takes them up as unevenness, and the cost no longer sees where the drawing lies (flat to 1e-5 over
        ±9 ms on an exact washboard).

        A GPS channel's mean speed is 0.05-0.1 % off over a few seconds, centimetres of the drawing at a run's end;
        the distance the fit on the tracks as drawn corrected it to was 15-29 mm off (the drawing's error is in it;
        the all-realities case of tests/realities_case.py): the drawing as built needs the track's own features to
        place it."""
        base = replace(self, tr=replace(self.tr, mode=mode))
        # SPEC §13: the declared speed and start weigh in at the run's own level
        cost = base.motion_cost(P, geom, ds, base.level(P, geom))
        c0 = cost(np.zeros(2))
        steps = defaults["asbuilt.motion_steps"]
        sol = minimize(cost, np.zeros(2), method="Nelder-Mead",
                       options={"initial_simplex": np.array([[0.0, 0.0], [steps[0], 0.0], [0.0, steps[1]]]),
                                "xatol": defaults["asbuilt.motion_xtol"], "fatol": 1e-9 * c0,
                                "maxfev": defaults["asbuilt.motion_maxfev"]})
        out = self.moved(ds, sol.x if sol.fun < c0 else np.zeros(2)).settled(ds)
        return replace(out, record={"speed_m_s": float(out.tr.rr.speed), "start_shift_s": float(out.tr.shift),
                                    "speed_channel_mean_m_s": asbuilt.held_speed(ds, self.run)})

    def moved(self, ds, p) -> TrackBlock:
        """The block with its drawing moved by ``p`` (the speed's relative change, the start's shift; setting
        ``asbuilt.motion_scale`` units), the tabulated inputs as they were."""
        return replace(self, tr=asbuilt.moved(self.tr, ds, self.run, p))

    def settled(self, ds) -> TrackBlock:
        """The block with its inputs tabulated at its speed and start, its record theirs."""
        tr = replace(self.tr, inputs=asbuilt.nominal_inputs(ds, self.run, self.tr.rr.speed, self.tr.shift))
        return replace(self, tr=tr, record=dict(self.record, speed_m_s=float(tr.rr.speed),
                                                start_shift_s=float(tr.shift)))

    def level(self, P, geom) -> float:
        """The RMS of the block's residual at the car ``P``: the weight its priors' rows take."""
        return float(np.sqrt(np.mean(asbuilt.residuals(P, geom, self.tr) ** 2)))

    def prior_rows(self, p, weight: float) -> np.ndarray:
        """The set-up priors' rows at the motion ``p`` moved from the block as it is placed."""
        return self.prior.rows(self.tr.rr.speed, self.tr.shift, p, weight)


# -- which block each run gets ---------------------------------------------------------------------------------

#: ``tracks``: each declared track fitted as built (the default: the drawing is the nominal shape, SPEC §11) or
#: taken exactly as drawn
TRACK_OPTIONS = ("as-built", "as-drawn")


def unknown_road_runs(ds, extensions=()) -> list:
    """The runs of ``ds`` fitted with their road projected out: those on unknown roads (SPEC §9), and, when the
    model (its ``extensions``) is linear, those on known tracks that begin moving (``moving = true``: the road
    fit estimates the state at the first sample, and the road, without using the track's profile). With
    damper curves or bump stops, which the projection cannot take, a moving run on a known track is fitted on
    its track, simulated from rest a lead-in before its first sample (:func:`rideid.data.dataset.run_lead_in`,
    docs/any-road.md)."""
    nonlinear = any(g in NONLINEAR_GROUPS for g in extensions)
    return [r for r in ds.runs
            if not getattr(r, "road_known", True) or (getattr(r, "moving", False) and not nonlinear)]


def run_speed(ds, run) -> float:
    """The constant speed (m/s) of an unknown-road run: the manifest's, or its speed/distance channel's
    mean when it varies by at most setting ``anyroad.speed_tolerance`` (else one clear error)."""
    rd = ds.data[run.id]
    dist = getattr(rd, "distance", None)
    if dist is None:
        return float(run.speed)
    x = np.asarray(dist(rd.time), dtype=float)
    v = np.gradient(x, rd.time)
    vm = float(np.mean(v))
    spread = float((np.max(v) - np.min(v)) / vm) if vm > 0 else np.inf
    if not np.isfinite(spread) or spread > 2 * defaults["anyroad.speed_tolerance"]:
        raise DataError(f"run '{run.id}': an unknown-road run needs a constant speed (the rear wheels' delay "
                        f"wheelbase/speed is taken as constant), but its speed channel goes from {np.min(v):.2f} to "
                        f"{np.max(v):.2f} m/s ({100 * spread:.0f} % of its mean; at most "
                        f"{200 * defaults['anyroad.speed_tolerance']:.0f} %); cut the run to a stretch of steady speed")
    return vm


def prepare_road_runs(ds, extensions=(), knots=None) -> list:
    """:class:`rideid.estimate.problem.roadfit.RoadRun` of each run fitted with its road projected out
    (:func:`unknown_road_runs` of the model's ``extensions``); with damper curves on ``knots`` each with its
    measured suspension velocities (:func:`rideid.estimate.problem.roadfit.departure_of`)."""
    out = []
    for r in unknown_road_runs(ds, extensions):
        rd = ds.data[r.id]
        rr = roadfit.prepare_road_run(r.id, rd.matrix(), rd.fs, run_speed(ds, r), ds.geometry,
                                      clipped=ds.clipped(r.id))
        if knots is not None:
            rr = replace(rr, dep=roadfit.departure_of(rd.matrix(), rd.fs, knots))
        out.append(roadfit.with_sensors(rr, ds.sensor_filters(r.id)))  # the channels as wired (SPEC §11)
    return out


def speed_wander(ds, run) -> float | None:
    """The relative RMS wander (about its mean) of the speed of ``run`` over its window, from its speed or distance
    channel (None without one): the channel's speed between its samples, its variance less what the channel's
    white noise (``preprocessing.<run>.speed.noise_std``, a GPS's) puts into a trapezoid's mean of two samples
    (``sigma^2 / 2``) and twice that estimate's own standard error (``sigma^2 / 2 sqrt(2 / (N - 1))``: a slow
    run's GPS noise is a per cent of its speed), floored at 0, over the mean speed. Measured on
    tests/driven_speed.py's five runs, seeds 1-2: a held speed 0-0.35 %, a +-3 % driver 0.7-2.2 %."""
    mr = ds.measured.get(run.id)
    dist = getattr(mr, "distance", None) if mr is not None else None
    if dist is None:
        return None
    if mr.window is not None and mr.start is not None:
        lo, hi = mr.times[mr.window[0]], mr.times[mr.window[1] - 1]
    else:
        lo, hi = mr.t_first, mr.t_last
    t = np.asarray(dist.t, dtype=float)
    k = np.nonzero((t >= lo) & (t <= hi))[0]
    if k.size < 4:
        k = np.arange(t.size)
    v = np.diff(np.asarray(dist.d, dtype=float)[k]) / np.diff(t[k])
    vm = float(np.mean(v))
    if not vm > 0:
        return float("inf")
    noise = float(mr.record.get("speed", {}).get("noise_std") or 0.0)
    excess = float(np.var(v)) - 0.5 * noise ** 2 * (1.0 + 2.0 * np.sqrt(2.0 / max(v.size - 1, 1)))
    return float(np.sqrt(max(excess, 0.0)) / vm)


#: why a run on a declared track is taken as drawn, in order: (the test on the run, the dataset, the run's data and
#: the model's nonlinear groups; the line that says why)
_AS_DRAWN = (
    (lambda ds, r, rd, bad: getattr(r, "posts", False),
     lambda ds, r, rd, bad: "a four-post rig run (SPEC §13): no track, its posts measured"),
    (lambda ds, r, rd, bad: bool(bad),
     lambda ds, r, rd, bad: f"as drawn: the model has {', '.join(bad)} (the as-built road is fitted on a linear car)"),
    (lambda ds, r, rd, bad: any(c not in rd.channels for c in CHANNELS[:8]),
     lambda ds, r, rd, bad: f"as drawn: no {', '.join(c for c in CHANNELS[:8] if c not in rd.channels)} (the "
                            "as-built road needs all eight accelerometers)"),
    (lambda ds, r, rd, bad: getattr(rd, "distance", None) is not None
     and (speed_wander(ds, r) or 0.0) > defaults["anyroad.held_speed"],
     lambda ds, r, rd, bad: f"as drawn: its speed wanders {100 * (speed_wander(ds, r) or 0.0):.1f} % RMS about its "
                            "mean (the speed channel less its noise; the as-built road needs the speed held within "
                            f"{100 * defaults['anyroad.held_speed']:.1f} %: the rear wheels' delay is taken as "
                            "constant)"),
    (lambda ds, r, rd, bad: "roll_rate" not in rd.channels,
     lambda ds, r, rd, bad: "as drawn: no roll_rate (without the roll gyro the road's slow left-right difference "
                            "cannot be told from the body's roll, and the as-built road is not determined)"),
)


def as_built_runs(ds, ext, tracks: str = "as-built") -> tuple[list, dict]:
    """The runs on declared tracks fitted as built (SPEC §11, :mod:`rideid.estimate.problem.asbuilt`), and those taken
    as drawn with why: run id -> one line. As built needs a linear car (``ext`` without damper curves or bump
    stops), the eight accelerometers, the roll rate and a speed held (a declared constant speed, or a speed or
    distance channel that wanders by at most setting ``anyroad.held_speed``, :func:`speed_wander`);
    ``tracks="as-drawn"`` takes every track as drawn (:data:`_AS_DRAWN`, in order).

    The roll rate: without it a slow road difference between the wheel paths and the body's roll (a free
    state at the first sample) trade off, and the road the prior is estimated from is not determined. Measured
    on the SUV's five runs on tracks as built (4 % off, 1.5 mm RMS) with the roll_rate column removed: the
    boundary unknowns of the free-road fit 4-79 (0.03-0.1 with it), "unevenness" of 0.2-3.6 m RMS, and the
    tracks as built rejected as implausible; the pitch rate removed instead changes nothing. A roll rate that is
    present but carries no signal (a symmetric track in simulated data) has the same trade-off; such runs stay as
    built, and the plausibility of what the tracks needed (setting ``anyroad.plausible_rms``) judges them, as before."""
    if tracks not in TRACK_OPTIONS:
        raise ArgumentError(f"tracks: expected one of {', '.join(TRACK_OPTIONS)}, got {tracks!r}")
    road_ids = {r.id for r in unknown_road_runs(ds, ext)}
    runs = [r for r in ds.runs if r.id not in road_ids]
    if tracks == "as-drawn":
        return [], {r.id: "as drawn (tracks = as-drawn)" for r in runs}
    bad = [g for g in ext if g in NONLINEAR_GROUPS]
    why = {r.id: next((say(ds, r, ds.data[r.id], bad) for test, say in _AS_DRAWN if test(ds, r, ds.data[r.id], bad)),
                      None) for r in runs}
    return [r for r in runs if why[r.id] is None], {rid: w for rid, w in why.items() if w is not None}


def speed_runs(ds, ext) -> tuple:
    """The runs on known tracks a model with damper curves or bump stops (``ext``) takes as drawn, driven at a
    declared constant speed: their speed is estimated with the car on the track as drawn (SPEC §13;
    :class:`DrawnRun`), as the polish on tracks alone estimates it (rideid.estimate.fit.polish.paced_runs). None
    for a linear model (its runs on tracks as built have their speed and start fitted with the car)."""
    if not any(g in NONLINEAR_GROUPS for g in ext):
        return ()
    roads = {r.id for r in unknown_road_runs(ds, ext)}
    return tuple(r for r in ds.runs if r.id not in roads and getattr(r, "track", None) is not None
                 and asbuilt.motion_prior(ds, r).speed is not None)


def align_motion(P, geom, tr: asbuilt.TrackRun, ds, run, mode: str = "prior",
                 prior: asbuilt.MotionPrior | None = None) -> tuple[asbuilt.TrackRun, dict]:
    """``tr`` of ``run`` placed at the car ``P`` (16,) by its speed and start alone (:meth:`TrackBlock.aligned`;
    ``prior``: the run's set-up priors, none by default), and the placement's record."""
    b = TrackBlock(tr, run, prior or asbuilt.MotionPrior(speed=None, start=None)).aligned(P, geom, ds, mode)
    return b.tr, b.record


def motion_jacobian(P, geom, tr: asbuilt.TrackRun, ds, run) -> np.ndarray:
    """:meth:`TrackBlock.motion_jacobian` of ``tr`` of ``run`` (placed by :func:`align_motion`) at the car ``P``."""
    return TrackBlock(tr, run, asbuilt.MotionPrior(speed=None, start=None)).motion_jacobian(P, geom, ds)


def method(blocks) -> str:
    """The polish's ``method``: the kinds of ``blocks``, unknown roads, tracks as built, tracks as drawn."""
    return "joint: " + ", ".join(m for _, m in sorted({(b.rank, b.method) for b in blocks}))


__all__ = ["DrawnTracks", "DrawnRun", "RoadBlock", "TrackBlock", "road_meat", "track_meat", "method", "align_motion",
           "speed_runs", "motion_jacobian", "TRACK_OPTIONS", "unknown_road_runs", "run_speed", "prepare_road_runs",
           "speed_wander", "as_built_runs"]
