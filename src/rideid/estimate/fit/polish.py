"""The polish: bounded least squares on the equal-weight cost from the search's best car (step 5-7 of
:mod:`rideid.estimate.fit.identify`).

:func:`polish_fit` is the stage the fit pipeline runs: the problem :class:`_Polish` in bound-normalised
coordinates (the free parameters, then the estimated starts and their distance corrections), solved by
:meth:`_Polish.solve` (dogbox, continued by trf where it stalls beside a bound), the starts' linearisation
centred again by :func:`_polish_aligned` until they settle, a powertrain mode left at a search bound polished
again from typical values (:func:`mode_restart`), and a bump stop the polished car no longer reaches held and
the polish repeated (:func:`bump_recheck`). Its settings keep their ``identify.`` names (rideid.settings).
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from ...profiling import stage, timing
from ...settings import defaults
from ...conditioning.starts import cycle_slips, distance_warp, linearise_starts, warped
from ...data.dataset import Dataset
from ...model.params import INDEX, NOMINAL_EXTENSIONS
from ..problem.asbuilt import speed_move_bound
from ..problem.blocks import speed_runs
from ..problem.bumps import frozen_values, reach
from ..problem.cost import CostFunction, ParameterSpace, time_derivative
from .tall import reduced, tall_r, tall_steps
from .uncertainty import jackknife_runs, hac_covariance, white_covariance


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
        if ds.auto_start_runs or paced_runs(ds, cf):
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
    """A second start for a polish that left a powertrain mode at a search bound (switched off: its inertia or
    frequency at either bound, or its damping at the upper one), or None.

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
    near = defaults["identify.restart_at_bound"]
    # a damping ratio at its lower bound is a lightly damped mode, one that is on: no second start (measured on the
    # all-realities case, seed 1: zeta_pp at 0.02 with f_pp 12.7 Hz on the tracks as drawn, and each of the three
    # powertrain candidates polished a second time to the same cost, 45 of 190 s)
    at = {n for j, n in enumerate(names)
          if rel[j] > 1.0 - near or (rel[j] < near and not n.startswith("zeta_"))}
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


def run_blocks(cf: CostFunction) -> list:
    """``(n_time, n_channel)`` of each run's residuals in ``cf.residuals``'s layout, in their order: the blocks of
    the HAC covariance (:func:`rideid.estimate.fit.uncertainty.hac_covariance`)."""
    return [(int(e - s), int(np.count_nonzero(cf.W[ri] > 0)))
            for ri, (s, e) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))]


def bump_recheck(ds, fit, bumps):
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



def _polish(cf: CostFunction, x0, weights, align=None, at=None, paced=()):
    """Least squares from ``x0``; ``align`` = [:class:`_Shift`] adds those runs' starts as unknowns.

    The model moves, the data never do: a start changed by ``delta`` moves the
    model's time axis, ``y(t - delta)``, modelled as ``y + delta D + delta^2 D2 / 2`` with
    ``D = dy/d(start)``, ``D2`` its derivative, from :func:`rideid.conditioning.starts.linearise_starts`.
    The linearisation is centred again by :func:`_polish_aligned` until the
    starts settle, so at the end it is exact.

    With damper curves a solve that ends on a row the monotone repair changes (a knot force below its
    inner neighbour: :meth:`ParameterSpace.full` hides it, so its gradient is 0 and the solver stops
    there) is solved again from the physical row, the forces the simulator saw (setting ``identify.repair_restarts``).
    A solve that lands on such a row is stopped there (:class:`Progress`, ``"repaired"``; at most setting
    ``identify.repair_early_stops`` times, not counted among the restarts): on the knee car the first curves
    solve sat on one from its first step and took 15 Jacobians to converge around the hidden knot, then 18 more
    from the physical row; stopped at once, 3 and 9 (the same end, 4e-10). Counted among the restarts, two early
    stops used them up and the engine-and-curves case's last solve ended on a hidden knot (a Wald statistic of
    NaN: the curves refused, the stops kept).

    ``paced`` = [:class:`_Pace`] adds those runs' speeds as unknowns (read exactly at each, with ``at``), each
    under its declared speed's prior.

    Returns ``(x, info, std)``: the free parameters, the ``polish`` block of result.json and the
    parameters' white standard errors (:class:`_Polish`).
    """
    prob = _Polish(cf, np.asarray(weights, dtype=float), tuple(align or ()), at=at, paced=tuple(paced))
    if prob.has_priors:
        # the prior rows weigh a knot's increment against the data at the data's residual level
        v0 = np.concatenate([np.clip((x0 - prob.lo) / prob.span, 0, 1), np.zeros(prob.n_unknowns - prob.d)])
        r0 = cf.residuals(x0[None], prob.weights, Y=prob.measured(v0))[0]
        prob = replace(prob, prior_scale=float(np.sqrt(np.mean(r0 ** 2))))
    restarts = defaults["identify.repair_restarts"] if cf.space.curves else 0
    early = defaults["identify.repair_early_stops"] if cf.space.curves else 0
    sol = prob.solve(x0, repair_stop=early > 0)
    while True:
        x = prob.to_x(sol.x[:prob.d])
        physical = cf.space.reduce(x, cf.space)
        if np.array_equal(physical, x):
            break
        if sol.get("progress") == "repaired":  # stopped where it landed on one: not a solve's end
            early -= 1
        elif restarts == 0:
            break
        else:
            restarts -= 1
        sol = prob.solve(physical, sol.x[prob.d:], repair_stop=early > 0)
    info, std = prob.info(sol, x0)
    return prob.to_x(sol.x[:prob.d]), info, std


@stage("polish")
def polish_fixed_starts(cf: CostFunction, x0, weights):
    """The least-squares polish from ``x0`` with the runs as ``cf`` reads them (no start among the unknowns):
    ``(x, info, std)`` as :func:`_polish` returns them (the materiality refits, rideid.estimate.assess.materiality)."""
    return _polish(cf, x0, weights)


#: whether this SciPy's ``least_squares`` takes a ``callback`` (1.16 on); without it the polish runs to SciPy's own ends
CALLBACK = "callback" in inspect.signature(least_squares).parameters


class Progress:
    """The polish's least squares watched after each iteration (SciPy's ``callback``): stopped once the Gauss-Newton
    step from where it is would move the unknowns by less than a share of their standard errors, or, for dogbox,
    once it crawls.

    **Converged** (``reason`` ``"converged"``): at ``x``, with the Jacobian ``J`` the solver took there
    (``jacobian(x)``, None when it has none) and residuals ``f`` (``m`` rows, ``d`` unknowns), the Gauss-Newton
    step's length in the metric of the unknowns' white covariance is ``|Q^T f| / s``, ``Q`` an orthonormal basis
    of ``J``'s columns (the triangle of a QR of ``[J | f]``, :func:`rideid.estimate.fit.tall.tall_r`),
    ``s^2 = |f|^2 / (m - d)``: it bounds every unknown's remaining move in its own standard error. Below setting
    ``identify.converged_step_std`` the least squares end. Unknowns on a bound (``active(x)``) are left out: a
    step into the bound is not a move; so are columns of zeros (a knot force the monotone repair hides: it moves
    nothing, and a QR without pivoting would count the residual's component along an arbitrary direction).
    **Crawl** (dogbox only, ``"crawl"``: trf continues, as after a dogbox that ran out of evaluations): setting
    ``identify.crawl_iterations`` iterations in a row each moving the unknowns (read from the cost it took off,
    ``sqrt(dF (m - d) / F)``) more than setting ``identify.crawl_ratio`` of the one before, the slow linear
    progress of dogbox's steps cut at a bound. **Repaired** (with ``repaired``, from the second iteration): the
    row is one the damper curves' monotone repair changes, for the polish to start again from the physical row.

    Measured on the knee car (benchmarks/bench_realtest.py ``knees``, the curves' polish): dogbox crawled beside
    tire damping held at 0 (steps of 10, 5.8, 5.3, 4.7, 4.5, 4.0 ... 1.7 standard errors to its 30 evaluations;
    trf then took 7.5 in its first), and a polish stuck at a row the damper curves' monotone repair changes took
    eight more Jacobians after its last useful step. A rule on the steps' lengths alone (two under 0.05) stopped
    the all-realities SUV's polish in the engine's pitch mode's flat valley: small steps of a small trust region
    are not an end; the Gauss-Newton step is."""

    def __init__(self, d: int, crawl: bool = True, jacobian=None, active=None, repaired=None, bounds=None):
        self.d, self.crawl, self.reason = d, crawl, None
        self.jacobian, self.active, self.repaired, self.bounds = jacobian, active, repaired, bounds
        self.costs, self.z, self.step_std = [], [], []

    def __call__(self, intermediate_result):  # the name SciPy's introspection looks for (else it passes x alone)
        x, f = intermediate_result.x, intermediate_result.fun
        if self.repaired is not None and self.costs and self.repaired(x):
            self.reason = "repaired"
            raise StopIteration
        F = 0.5 * float(f @ f)
        dof = max(f.size - self.d, 1)
        if self.costs and F > 0:
            self.z.append(math.sqrt(max(self.costs[-1] - F, 0.0) * dof / F))
        self.costs.append(F)
        small = defaults["identify.converged_step_std"]
        step = self.step_length(x, f, self.jacobian(x) if self.jacobian is not None else None)
        if step is not None:
            self.step_std.append(step)
            if step < small:
                self.reason = "converged"
        n, z = defaults["identify.crawl_iterations"], self.z
        if self.crawl and len(z) > n and all(z[-k] >= small and z[-k] > defaults["identify.crawl_ratio"] * z[-k - 1]
                                             for k in range(1, n + 1)):
            self.reason = self.reason or "crawl"
        if self.reason:
            raise StopIteration

    def step_length(self, x, f, J) -> float | None:
        """The Gauss-Newton step's length from ``x`` in standard errors (None without a Jacobian ``J`` or a cost).
        From the reduction of ``[J | f]`` on the columns dogbox will take as free there (:meth:`step_columns`),
        kept for dogbox's step from the same point (:func:`rideid.estimate.fit.tall.reduced`)."""
        F = 0.5 * float(f @ f)
        if J is None or F <= 0:
            return None
        cols = self.step_columns(x, J, f)
        T = reduced(J, f, cols)
        free = np.ones(J.shape[1], dtype=bool) if self.active is None else ~self.active(x)
        if cols is not None:  # the watch's free unknowns among dogbox's (those on a bound are near it)
            within = np.zeros(J.shape[1], dtype=bool)
            within[cols] = True
            if (free & ~within).any():
                T, cols = tall_r(J, f), None
        length = gauss_newton_length(J, f, free if cols is None else free[cols], T=T)
        return length * math.sqrt(max(f.size - self.d, 1) / (2 * F))

    def step_columns(self, x, J, f) -> np.ndarray | None:
        """The unknowns SciPy's dogbox takes as free at ``x``, as indices (None without ``bounds``: every one): all
        but those exactly on a bound whose gradient ``J^T f`` points out of it (dogbox's own rule and arithmetic,
        its ``compute_grad``; a wrong guess costs a second reduction, not a wrong step: rideid.estimate.fit.tall
        checks the step's columns)."""
        if self.bounds is None:
            return None
        lo, hi = self.bounds
        on_bound = np.where(x == lo, -1, np.where(x == hi, 1, 0))
        return np.flatnonzero(~(on_bound * J.T.dot(f) < 0))


def gauss_newton_length(J, f, free=None, T=None) -> float:
    """``|Q^T f|``: the length of ``f``'s projection on ``J``'s columns (``Q`` their orthonormal basis; only those
    of ``free`` when given, a mask), the cost a Gauss-Newton step from here would take off as ``|Q^T f|^2 / 2``.

    From ``T``, the triangle of a QR of ``[J | f]`` (:func:`rideid.estimate.fit.tall.tall_r`, or its block-by-block
    form; reduced here when not given; or of ``[J[:, cols] | f]``, ``free`` then a mask of those columns): a QR of
    its columns of ``free`` and of ``f`` (``T^T T`` is ``[J | f]``'s Gram matrix, so the projection's length is the
    same). The equilibrated Gram matrix this took while well
    conditioned cost a product of all of ``J`` on top of the reduction dogbox's step makes anyway (0.23 s at
    105 000 x 297, shared now: :func:`rideid.estimate.fit.tall.reduced`). Columns of zeros take no part (a knot
    the curves' repair hides moves nothing; a QR without pivoting would count the residual's component along an
    arbitrary direction)."""
    J = np.asarray(J, dtype=float)
    T = tall_r(J, f) if T is None else T
    c = np.linalg.norm(T[:, :-1], axis=0)
    keep = (c > 0) & (True if free is None else np.asarray(free, dtype=bool))
    if not keep.any():
        return 0.0
    n = int(keep.sum())
    R = np.linalg.qr(np.column_stack([T[:, :-1][:, keep], T[:, -1]]), mode="r")
    return float(np.linalg.norm(R[:min(n, R.shape[0]), n]))


@dataclass(frozen=True)
class _Polish:
    """The polish's least-squares problem in bound-normalised coordinates ``v = (z, start shifts)``.

    ``z`` in ``[0, 1]`` per free parameter (``x = lo + span z``), then one shift per run of ``align``
    (samples, within setting ``identify.start_bound``). The residuals are the cost function's at ``weights``;
    the measured data of an aligned run move by ``delta D`` (the start's linearisation, :func:`_polish`), or,
    with ``at``, the runs are read at the moved starts themselves (exact).
    """

    cf: CostFunction
    weights: np.ndarray
    align: tuple = ()
    #: the residual noise level the distance corrections' prior rows are scaled to (:meth:`prior_rows`)
    prior_scale: float = 1.0
    #: exact starts: run id -> start (s) of every run of ``align`` -> the cost function on the runs read there
    #: (None: the round's model of a start's move, ``D`` and ``D2``). Runs without a distance correction only.
    at: object = None
    #: runs whose speed joins the unknowns (:class:`_Pace`), read exactly at each trial speed (``at``)
    paced: tuple = ()
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
        return (self.d + len(self.align) + sum(sh.warp.free.size for sh in self.align if sh.warp is not None)
                + len(self.paced))

    @property
    def pace_slice(self) -> slice:
        """The slice of ``v`` holding the paced runs' speed moves (setting ``asbuilt.motion_scale`` units)."""
        return slice(self.n_unknowns - len(self.paced), self.n_unknowns)

    def speeds_of(self, v) -> dict:
        """Run id -> the speed (m/s) of each paced run at ``v``."""
        moves = v[self.pace_slice]
        return {pc.run_id: pc.speed_at(m) for pc, m in zip(self.paced, moves)}

    def prior_rows(self, v):
        """The distance corrections' prior residuals ``s A (w + dw) / sigma`` (the random walk's increments,
        :meth:`rideid.conditioning.starts.DistanceWarp.prior`, scaled to the data's residual level ``s``), then each
        paced run's declared speed's row ``s (v - declared) / std``, and their Jacobian ``(rows, v.size)``."""
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
        for j, pc in zip(range(self.pace_slice.start, self.pace_slice.stop), self.paced):
            # SPEC §13: the declared speed's row, weighed against the data at their residual level
            rows.append(np.array([self.prior_scale * (pc.speed_at(v[j]) - pc.declared) / pc.prior_std]))
            Jp = np.zeros((1, v.size))
            Jp[0, j] = self.prior_scale * pc.speed * pc.unit / pc.prior_std
            jac.append(Jp)
        if not rows:
            return np.zeros(0), np.zeros((0, v.size))
        return np.concatenate(rows), np.vstack(jac)

    def measured(self, v):
        """The measured data with each aligned run moved by its shift's linearisation (None: no shift)."""
        if not self.align or self.at is not None:
            return None
        cf, d = self.cf, self.d
        Y = cf.Y.copy()
        for k, (sh, sl) in enumerate(zip(self.align, self.warp_slices)):
            a, b = cf.sim.run_start[sh.run_index], cf.sim.run_start[sh.run_index + 1]
            delta = v[d + k] / sh.fs  # y_model + delta D + delta^2 D2 / 2 - y  ==  y_model - (y - ...)
            Y[a:b] -= delta * sh.D if sh.ydot0 is None else delta * (sh.D + sh.ydot0) + 0.5 * delta ** 2 * sh.D2
            if sl is not None:
                Y[a:b] -= np.tensordot(v[sl], sh.Dw, axes=1)
        return Y

    def advance(self, v) -> dict | None:
        """Run index -> its start's move (s) at ``v``, the part of the move the car changes:
        :meth:`rideid.estimate.problem.cost.CostFunction.residuals`' ``advance`` (None: no shift)."""
        return {sh.run_index: v[self.d + k] / sh.fs for k, sh in enumerate(self.align) if sh.ydot0 is not None} or None

    def residuals(self, v) -> np.ndarray:
        """Stacked weighted residuals ``(m,)`` at ``v``, the distance corrections' prior rows last.

        A start's move ``delta`` moves car ``P``'s response by ``delta D(P) + delta^2 D2 / 2``, ``D(P)`` taken as
        ``D + ydot0 - ydot(P)`` (``D = -dy/dt`` on a constant speed): the move is a model of the car as well.
        Held at the round's car (``D`` alone), a car that misfits (a rival of the model choice) and the starts
        traded against each other, the model's cost below the true one by up to 8 % on the van's logger
        files, and the rounds never settled; with ``D(P)`` within 0.05 % (docs/performance.md)."""
        r = self.cost_at(v).residuals(self.to_x(v[:self.d])[None], self.weights, Y=self.measured(v),
                                      advance=self.advance(v))[0]
        self._last["v"], self._last["r"] = v.copy(), r
        return np.concatenate([r, self.prior_rows(v)[0]]) if self.has_priors else r

    def cost_at(self, v) -> CostFunction:
        """The cost function whose runs are read at ``v``'s starts (with ``at``, which keeps the last few: least_squares
        asks for the Jacobian where it just evaluated; else :attr:`cf`, the round's)."""
        if self.at is None:
            return self.cf
        return self.at({sh.run_id: self.start_of(v, k) for k, sh in enumerate(self.align)}, self.speeds_of(v))

    @property
    def has_warps(self) -> bool:
        return any(sh.warp is not None for sh in self.align)

    @property
    def has_priors(self) -> bool:
        """Whether the residuals end in prior rows (:meth:`prior_rows`): distance corrections or paced runs."""
        return self.has_warps or bool(self.paced)

    def jacobian(self, v) -> np.ndarray:
        """``(m, d + len(align))``: forward differences (step 1e-7 in ``z``) as one batch, the shifts' columns
        from their ``D`` (exact starts: :meth:`_exact_start_columns`)."""
        memo = self._jacobian_at(v)
        if memo is not None:  # the least squares' first, taken by the check before them (_least_squares)
            return memo.copy()
        d, cf = self.d, self.cf
        D = self._differences(v)
        prior = self.prior_rows(v)[1] if self.has_priors else np.zeros((0, v.size))
        J = np.zeros((D.shape[0] + prior.shape[0], v.size))  # the distance corrections' prior rows last
        J[:D.shape[0], :d] = D
        J[D.shape[0]:] = prior
        offsets = self._run_offsets()
        if self.at is not None:
            return self._exact_start_columns(v, J, offsets)
        at_car = any(sh.ydot0 is not None for sh in self.align)
        y = cf.simulate(cf.space.full(self.to_x(v[:d])[None])[0]) if at_car else {}
        for k, (sh, sl) in enumerate(zip(self.align, self.warp_slices)):
            cols, sc = cf.residual_scale(sh.run_index, self.weights)
            rows = slice(offsets[sh.run_index], offsets[sh.run_index + 1])
            dy = sh.D
            if sh.ydot0 is not None:
                ydot = time_derivative(y[sh.run_id], cf.run_times[sh.run_index])
                dy = dy + sh.ydot0 - ydot + (v[d + k] / sh.fs) * sh.D2
            a, b = cf.sim.run_start[sh.run_index], cf.sim.run_start[sh.run_index + 1]
            keep = 1.0 if cf.keep is None else cf.keep[a:b]
            J[rows, d + k] = ((dy * keep)[:, cols] * sc / sh.fs).ravel()
            if sl is not None:
                J[rows, sl] = (sh.Dw[:, :, cols] * sc).reshape(sh.Dw.shape[0], -1).T
        self._last["J"] = (v.copy(), J)
        return J

    def _exact_start_columns(self, v, J, offsets) -> np.ndarray:
        """``J`` with the starts' columns of :meth:`jacobian` by a forward difference of the runs read at every
        start moved by setting ``identify.exact_start_step`` (samples) at once: each run's residuals depend on its
        own start alone, so one evaluation gives every column; the paced runs' speed columns the same way (every
        speed moved by setting ``identify.exact_speed_step``)."""
        d, h = self.d, defaults["identify.exact_start_step"]
        r0 = self._residuals_at(v)
        if self.align:
            vh = v.copy()
            vh[d:d + len(self.align)] += h
            rh = self.cost_at(vh).residuals(self.to_x(v[:d])[None], self.weights)[0]
            for k, sh in enumerate(self.align):
                rows = slice(offsets[sh.run_index], offsets[sh.run_index + 1])
                J[rows, d + k] = (rh[rows] - r0[rows]) / h
        if self.paced:  # each paced run's residuals depend on its own speed alone: one read gives every column
            hp = defaults["identify.exact_speed_step"]
            vh = v.copy()
            vh[self.pace_slice] += hp
            rh = self.cost_at(vh).residuals(self.to_x(v[:d])[None], self.weights)[0]
            for j, pc in zip(range(self.pace_slice.start, self.pace_slice.stop), self.paced):
                rows = slice(offsets[pc.run_index], offsets[pc.run_index + 1])
                J[rows, j] = (rh[rows] - r0[rows]) / hp
        self._last["J"] = (v.copy(), J)
        return J

    def _repaired(self, v) -> bool:
        """Whether the curves' monotone repair changes the row at ``v`` (a knot force the simulator does not see)."""
        x = self.to_x(v[:self.d])
        return not np.array_equal(self.cf.space.reduce(x, self.cf.space), x)

    def _jacobian_at(self, v):
        """The Jacobian last computed, if at ``v`` (else None)."""
        got = self._last.get("J")
        return got[1] if got is not None and np.array_equal(got[0], v) else None

    def _differences(self, v) -> np.ndarray:
        """The parameters' forward-difference columns ``(m, d)`` at ``v`` (the last residuals reused)."""
        h = 1e-7
        z = v[:self.d]
        steps = np.where(z + h <= 1, h, -h)
        Z = np.tile(z, (self.d, 1))
        Z[np.arange(self.d), np.arange(self.d)] += steps
        R = self.cost_at(v).residuals(self.to_x(Z), self.weights, Y=self.measured(v), advance=self.advance(v))
        return ((R - self._residuals_at(v)) / steps[:, None]).T

    def _residuals_at(self, v) -> np.ndarray:
        """The cost function's residuals at ``v`` (no prior rows): the last :meth:`residuals` call's when at ``v``."""
        last = self._last
        if "v" in last and np.array_equal(last["v"], v):
            return last["r"]
        return self.cost_at(v).residuals(self.to_x(v[:self.d])[None], self.weights, Y=self.measured(v),
                                         advance=self.advance(v))[0]

    def _run_offsets(self) -> np.ndarray:
        """Row where each run's residuals start in the stacked vector (and the end)."""
        cf = self.cf
        return np.cumsum([0] + [(e - s) * cf.residual_scale(ri, self.weights)[0].size
                                for ri, (s, e) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))])

    def solve(self, x0, shifts=None, repair_stop: bool = False) -> OptimizeResult:
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
        d, n_al, n_p = self.d, len(self.align), len(self.paced)
        n_w = self.n_unknowns - d - n_al - n_p
        z0 = np.clip((x0 - self.lo) / self.span, 0, 1)
        v0 = np.concatenate([z0, np.zeros(n_al + n_w + n_p) if shifts is None else np.asarray(shifts, dtype=float)])
        sb, wb = defaults["identify.start_bound"], defaults["identify.warp_bound"]
        pb = np.array([pc.bound for pc in self.paced])
        blo = np.concatenate([np.zeros(d), np.full(n_al, -sb), np.full(n_w, -wb), -pb])
        bhi = np.concatenate([np.ones(d), np.full(n_al, sb), np.full(n_w, wb), pb])
        near = defaults["identify.bound_snap"] * (bhi - blo)
        v0 = np.where(v0 - blo < near, blo, np.where(bhi - v0 < near, bhi, v0))
        sol = self._least_squares(v0, (blo, bhi), "dogbox", defaults["identify.dogbox_max_nfev"], repair_stop)
        if sol.get("progress") == "repaired":
            return sol
        beside = ((sol.x - blo < near) & (sol.x != blo)) | ((bhi - sol.x < near) & (sol.x != bhi))
        if (sol.status == 0 or sol.get("progress") == "crawl"
                or (beside.any() and sol.optimality > defaults["identify.stall_optimality"])):
            more = self._least_squares(sol.x, (blo, bhi), "trf", defaults["identify.polish_max_nfev"] - sol.nfev,
                                       repair_stop)
            more.nfev += sol.nfev
            if more.cost <= sol.cost:
                return more
            sol.nfev = more.nfev
        return sol

    def _least_squares(self, v0, bounds, method, max_nfev, repair_stop: bool = False) -> OptimizeResult:
        """SciPy's ``least_squares`` with ``method``, watched by :class:`Progress` (``progress`` in the result:
        why it stopped it, or None); with ``repair_stop`` also stopped on a row the curves' repair changes."""
        lo, hi = bounds
        near = defaults["identify.bound_snap"] * (hi - lo)
        watch = Progress(self.d, crawl=method == "dogbox", jacobian=self._jacobian_at,
                         active=lambda v: (v - lo <= near) | (hi - v <= near),
                         repaired=self._repaired if repair_stop else None,
                         bounds=(lo, hi) if method == "dogbox" else None)
        kw = {"callback": watch} if CALLBACK else {}
        # already where the car stops moving: no solve (its steps, below rounding, would be refused). Not with
        # distance corrections: their hundreds of knots make the check's QR cost a second (the GPS SUV 64 -> 70 s)
        if CALLBACK and not self.has_warps:
            f0 = self.residuals(v0)
            J0 = self.jacobian(v0)
            step = watch.step_length(v0, f0, J0)
            if step is not None and step < defaults["identify.converged_step_std"]:
                return self._converged_at(v0, f0, J0, watch.active(v0), step)
        with tall_steps():  # dogbox's steps on the tall Jacobian reduced once (rideid.estimate.fit.tall)
            sol = least_squares(self.residuals, v0, jac=self.jacobian, bounds=bounds, method=method,
                                x_scale="jac", ftol=1e-15, xtol=1e-12, gtol=1e-15, max_nfev=max_nfev, **kw)
        sol.progress = watch.reason
        if watch.reason == "converged":
            sol.success, sol.message = True, (f"a Gauss-Newton step from here would move the unknowns by less than "
                                              f"{defaults['identify.converged_step_std']} of their standard errors")
        return sol

    @staticmethod
    def _converged_at(v0, f0, J0, active, step) -> OptimizeResult:
        """The least squares' result at their start ``v0`` (residuals ``f0``, Jacobian ``J0``, the unknowns on a
        bound ``active``), where the Gauss-Newton step is ``step`` standard errors long, below setting
        ``identify.converged_step_std``: a polish from a parent's converged fit, or a start's round that
        changed nothing (dogbox took 8 evaluations there, its steps below rounding refused one by one)."""
        g = J0.T @ f0
        return OptimizeResult(x=v0.copy(), fun=f0, jac=J0, cost=0.5 * float(f0 @ f0), nfev=1, njev=1, status=2,
                              optimality=float(np.max(np.abs(np.where(active, 0.0, g)), initial=0.0)),
                              active_mask=np.zeros(v0.size, dtype=int), success=True, progress="converged",
                              message=(f"a Gauss-Newton step from here would move the unknowns by {step:.2g} of their "
                                       f"standard errors (below {defaults['identify.converged_step_std']})"))

    def scale(self) -> np.ndarray:
        """``dx/dv`` of every unknown: the bounds' spans, one sample interval per shift, 1 per knot (m)."""
        n_w = self.n_unknowns - self.d - len(self.align) - len(self.paced)
        return np.concatenate([self.span, [1.0 / sh.fs for sh in self.align], np.ones(n_w),
                               [pc.speed * pc.unit for pc in self.paced]])

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
        return run_blocks(self.cf)

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
        if self.paced:  # SPEC §13: each paced run's speed as estimated with the car (m/s)
            speeds, sl = self.speeds_of(sol.x), self.pace_slice
            info["speeds"] = {pc.run_id: {"value": speeds[pc.run_id], "std": float(sd), "std_robust": float(sr),
                                          "declared": pc.declared, "prior_std": pc.prior_std}
                              for pc, sd, sr in zip(self.paced, std_all[sl], std_rob[sl])}
        return info, std_all[:d]


@dataclass(frozen=True)
class _Shift:
    """A run whose start joins the polish: its index in the cost, id, rate, start, ``D = dy/d(start)`` and
    ``D2 = d2y/d(start)2``."""

    run_index: int
    run_id: str
    fs: float
    start: float
    #: None with exact starts (:attr:`_Polish.at`)
    D: np.ndarray | None
    #: ``D``'s derivative, and the time derivative (central differences of the samples) of the response ``D``
    #: belongs to, the car the round began from: ``D`` at another car is taken as ``D + ydot0 - ydot``
    #: (:meth:`_Polish.residuals`); both None: the move linear, at the round's car (a run with a ``warp``)
    D2: np.ndarray | None = None
    ydot0: np.ndarray | None = None
    #: a noisy speed channel's distance correction (:class:`rideid.conditioning.starts.DistanceWarp`, as the
    #: runs are read now) and the response's derivative with respect to its free knots ``(K, n, 10)``
    warp: object = None
    Dw: np.ndarray | None = None


@dataclass(frozen=True)
class _Pace:
    """A run on a track as drawn whose speed joins the polish (:func:`paced_runs`): its index in the cost, id, the
    speed the round reads it at (m/s), its declared speed and that prior's std (m/s)."""

    run_index: int
    run_id: str
    speed: float
    declared: float
    prior_std: float

    @property
    def unit(self) -> float:
        """A move's unit, relative to the speed: the first of setting ``asbuilt.motion_scale`` (as built's)."""
        return float(defaults["asbuilt.motion_scale"][0])

    def speed_at(self, move: float) -> float:
        """The speed (m/s) at a move of ``move`` (:attr:`unit`) from :attr:`speed`."""
        return self.speed * (1.0 + move * self.unit)

    @property
    def bound(self) -> float:
        """How far the speed may move in a round (:attr:`unit` units): setting ``anyroad.joint_motion_bound``, or four
        prior std where that is wider (as a road run's: rideid.estimate.problem.blocks.RoadBlock)."""
        return speed_move_bound(self.speed, self.prior_std)


def paced_runs(ds, cf) -> list:
    """The runs whose speed the polish estimates with the car (SPEC §13: a declared speed is a prior): on a car with
    damper curves or bump stops (which cannot take its tracks as built, where a linear car's fit estimates each
    run's speed), every run on a known track at a declared constant speed, from the speed load put it at (the
    declared one, or where load found the data contradict it). Held there, the van's twist run typed 3.03 m/s
    (driven 3.0, put at 2.9927 by load) gave k_tr +19 %, and typed 3.006 (within the declared speed's prior, not
    moved at load) k_tr -17 %, both not adequate; estimated, the car within 0.63 % (docs/dampers.md, "A run's
    speed under a nonlinear car"). The runs are those the road fit's blocks estimate the speed of
    (:func:`rideid.estimate.problem.blocks.speed_runs`), in the cost function's order."""
    runs = {r.id: r for r in speed_runs(ds, cf.space.extensions)}
    return [_Pace(ri, rid, float(runs[rid].speed), *map(float, runs[rid].speed_prior()[:2]))
            for ri, rid in enumerate(cf.run_ids) if rid in runs]


@stage("polish with starts")
def _polish_aligned(ds, cf, x_best, equal):
    """Polish the parameters and the estimated starts together (and, on a nonlinear car, the runs' speeds:
    :func:`paced_runs`, read exactly at each trial speed as the starts are).

    Runs without a distance correction (a constant speed, or a speed channel trusted as it is): the starts'
    moves are exact, every evaluation of the least squares reading the runs at its starts (:attr:`_Polish.at`),
    in one round, a second only where a constant-speed run's correlation with the polished car peaks a cycle away
    (:func:`rideid.conditioning.starts.cycle_slips`: moved there, polished again). Measured on the shared damper
    van's logger files, the damper-curve candidate: the rounds of a modelled start took five polishes (its
    parameters moving 848, 330, 154, 25 and 0.3 standard errors round to round while the starts moved 0.9, 0.2,
    0.09, 0.02 samples: the model's cost at a round's end was off the runs' by up to 60 % on the bump runs,
    whose response to a start's move is not a time shift of the car's, ``D(P) = D + ydot0 - ydot(P)`` a poor
    model of it once the car moves), exact one polish; docs/performance.md.

    Runs with a distance correction (a noisy speed channel's, :func:`rideid.conditioning.starts.distance_warp`):
    the starts' and the corrections' moves are modelled (:func:`rideid.conditioning.starts.linearise_starts`: the
    derivative of the car's response there), the model centred again round after round (new model time axes,
    the same samples) until no start moves by more than ``identify.realign_tol`` of a sample interval or
    ``identify.realign_std`` of its standard error, whichever is larger (:func:`_move`), or until no parameter
    moves by more than ``identify.realign_parameter_std`` of its standard error (:func:`_settled`).

    Once the starts settle, the runs are read at the settled starts and the cost function on them is returned.
    Works on its own copy of the run data: ``ds`` is not changed.
    """
    starts = {rid: ds.measured[rid].start for rid in ds.auto_start_runs}
    warps = {rid: w for rid in starts if (w := distance_warp(ds.measured[rid], starts[rid])) is not None}
    exact = not warps
    paced = paced_runs(ds, cf) if exact else []  # the speeds the polish estimates (exact reads only)
    speeds = {pc.run_id: pc.speed for pc in paced}
    read = {}  # exact starts: the runs read at the last few trial starts, the polish's end among them
    rounds, settled = [], False
    for _ in range(defaults["identify.realign_max"] + 1):
        P = cf.space.full(x_best[None])[0]
        last = settled or len(rounds) == defaults["identify.realign_max"]
        if exact and _key(starts, speeds) in read:  # read there by the polish already
            cf = read[_key(starts, speeds)]
        else:
            with timing("linearise starts"):
                ds_now, D, D2, Dw = linearise_starts(warped(ds, warps).with_speeds(speeds), P, starts, cf.simulator,
                                                     derivative=not (last or exact), warps=warps)
            # the model's time axes moved with the starts: the cost function (space, simulator, pin) on them
            cf = cf.with_data(ds_now)
            if exact:  # the polish's first trial reads the runs here
                _read_at(ds, cf, read, starts, speeds, known=cf)
        if last:
            break
        x_before = x_best
        if exact:
            shifts = [_Shift(cf.run_ids.index(rid), rid, ds.measured[rid].fs, s, None) for rid, s in starts.items()]
            now = [replace(pc, speed=speeds[pc.run_id]) for pc in paced]  # this round's speeds: the moves' origin
            x_best, info, std = _polish(cf, x_best, equal, shifts, at=partial(_read_at, ds, cf, read), paced=now)
        else:
            x_best, info, std = _polish(cf, x_best, equal, _modelled_shifts(ds, cf, P, starts, D, D2, Dw, warps))
        with np.errstate(divide="ignore", invalid="ignore"):
            steps = np.abs(x_best - x_before) / std
        param_move = float(np.max(np.where(np.isfinite(steps), steps, 0.0), initial=0.0))
        fitted, moves, warps = _moves(ds, info, starts, warps)
        new_speeds = {rid: rec["value"] for rid, rec in info.get("speeds", {}).items()}
        # a speed on its round's bound moves on in the next round (the bound is centred where this one ended)
        paced_bound = exact and any(abs(new_speeds[pc.run_id] / speeds[pc.run_id] - 1.0)
                                    >= pc.bound * pc.unit * (1 - 1e-9) for pc in now)
        speeds = new_speeds
        with timing("cycle slips"):
            moved = cycle_slips(ds.with_speeds(speeds), cf.space.full(x_best[None])[0], fitted, cf.simulator)
        slipped = {rid: s - fitted[rid] for rid, s in moved.items()}
        starts = {**fitted, **moved}
        rounds.append({"max_change_samples": max((m[0] for m in moves), default=0.0),
                       "max_change_share": max((m[1] for m in moves), default=0.0),
                       "max_parameter_move_std": param_move, "exact": exact,
                       **({"cycle_slips": slipped} if slipped else {})})
        # exact: settled unless a run slipped a cycle or a start or a speed ended on the round's bound (its move is
        # bounded round by round: the next round's bound is centred on where this one ended)
        on_bound = (max((m[0] for m in moves[:len(fitted)]), default=0.0)
                    >= defaults["identify.start_bound"] * (1 - 1e-9)) or paced_bound
        settled = not (slipped or on_bound) if exact else _settled(rounds[-1])
    return x_best, dict(info, alignment_rounds=rounds), std, cf, _start_records(ds, starts, info, warps)


def _start_records(ds, starts: dict, info: dict, warps: dict) -> dict:
    """result.json ``starts``: each start the polish settled, with its standard errors and, along a noisy speed
    channel, its distance correction."""
    out = {rid: {"value": float(starts[rid]), "source": "estimated with the parameters (least squares)",
                 **_start_std(info["starts"][rid], ds.measured[rid].record.get("start", {}), rid in warps)}
           for rid in starts}
    for rid in warps:
        out[rid]["distance_correction"] = info["starts"][rid]["distance_correction"]
    return out


def _moves(ds, info, starts: dict, warps: dict) -> tuple[dict, list, dict]:
    """A round's end (:func:`_polish_aligned`): the starts the polish fitted (run id -> s), each start's and each
    distance knot's move (:func:`_move`; a knot's in sample intervals at the run's mean speed) and the distance
    corrections as fitted (run id -> :class:`rideid.conditioning.starts.DistanceWarp`)."""
    fitted = {rid: st["value"] for rid, st in info.get("starts", {}).items()}
    moves = [_move(abs(v - starts[rid]) * ds.measured[rid].fs, info["starts"][rid]["std"] * ds.measured[rid].fs)
             for rid, v in fitted.items()]
    out = {}
    for rid, w in warps.items():
        dc = info["starts"][rid]["distance_correction"]
        new = np.asarray(dc["values_m"])
        per_m = ds.measured[rid].fs / max(float(ds.measured[rid].record.get("speed", {}).get("mean") or 1.0), 1e-3)
        moves += [_move(abs(a - b) * per_m, s * per_m) for a, b, s in zip(new, w.values, dc["std_m"])]
        out[rid] = replace(w, values=new)
    return fitted, moves, out


def _key(starts: dict, speeds: dict | None = None) -> tuple:
    return tuple(sorted(starts.items())), tuple(sorted((speeds or {}).items()))


def _read_at(ds, cf, read: dict, starts: dict, speeds: dict | None = None, known=None):
    """``cf`` on the runs of ``ds`` read at ``starts`` (run id -> s) and ``speeds`` (run id -> m/s, the paced runs'),
    kept in ``read`` (the last four); ``known``: that cost function already (the round's)."""
    key = _key(starts, speeds)
    if key not in read:
        if len(read) >= 4:
            read.pop(next(iter(read)))
        read[key] = known if known is not None else cf.with_data(ds.with_speeds(speeds or {}).with_starts(starts))
    return read[key]


def _modelled_shifts(ds, cf, P, starts, D, D2, Dw, warps) -> list:
    """The round's :class:`_Shift` of every run of ``starts``: its start's move modelled by ``D`` and ``D2`` (and
    the time derivative of car ``P``'s response, the car the round began from), a distance correction's by ``Dw``.

    A run with a distance correction keeps its start's move as the correction's is modelled, linear and at the
    round's car (no D2, no ydot0): a start and a constant correction are the same move (a start modelled otherwise
    opened a valley the two slid along, 0.2 samples a round on the GPS runs, or took twice the evaluations a
    round)."""
    y0 = cf.simulate(P) if D2 else {}
    shifts = []
    for rid, s in starts.items():
        ri = cf.run_ids.index(rid)
        ydot0 = time_derivative(y0[rid], cf.run_times[ri]) if rid in D2 else None
        shifts.append(_Shift(ri, rid, ds.measured[rid].fs, s, D[rid], D2.get(rid), ydot0, warps.get(rid), Dw.get(rid)))
    return shifts


def _settled(round_record: dict) -> bool:
    """A round of :func:`_polish_aligned` (its ``alignment_rounds`` record) leaves the starts settled: no cycle
    slip, and every start within its tolerance (``max_change_share`` below 1, :func:`_move`) or the car no longer
    moving (``max_parameter_move_std`` below ``identify.realign_parameter_std``: a start the data barely know,
    traded against its distance correction, can drift on without changing the car or the cost)."""
    if round_record.get("cycle_slips"):
        return False
    return (round_record["max_change_share"] < 1.0
            or round_record["max_parameter_move_std"] < defaults["identify.realign_parameter_std"])


def _move(change: float, std: float) -> tuple[float, float]:
    """A start's (or a distance knot's) move in one round, ``change`` and its standard error ``std`` both in
    sample intervals: ``(change, share)``, ``share`` the move over what the round may move and still count
    as settled, the larger of ``identify.realign_tol`` (a sample interval's share) and ``identify.realign_std``
    of the standard error: a start known to a tenth of a sample need not settle to a thousandth (the
    polish's own termination moves it by 0.01-0.04 samples, docs/performance.md)."""
    std = std if std is not None and np.isfinite(std) else 0.0
    allowed = max(defaults["identify.realign_tol"], defaults["identify.realign_std"] * std)
    return float(change), float(change) / allowed


def _start_std(fitted: dict, record: dict, warped_run: bool = False) -> dict:
    """A start's standard errors: the fit's (``fitted``: the polish's ``std``, ``std_robust``) and, where the
    start's load ``record`` has one, a noisy speed channel's (:func:`rideid.conditioning.starts.speed_channel_std`:
    the channel's integral drifting from the start to the road's features).

    Without a distance correction the two are added in quadrature (the fit's assumes the distance exact). With
    one (``warped_run``) the correction was estimated with the start, under the channel's random-walk prior, and
    its fit's standard error should hold the drift; measured, it does not (benchmarks/bench_realtest.py ``gps``,
    true start 1.0 s): H_HL -2.6 ms at a fit's std of 0.21 ms (std_robust 0.05), H_HH -1.75 ms at 0.35, T_HH
    -4.4 ms at 0.98, all five early, each within 1.8 of the channel's drift (6.1, 2.5, 2.6, 1.0, 1.0 ms). So the
    channel's drift is a floor under both of a corrected run's standard errors (``std_speed_channel`` recorded),
    not added to them: where the fit's is the larger (T_HL, 2.55 ms) it stands."""
    std_fit = fitted["std"]
    out = {"std": std_fit, "std_fit": std_fit, "std_robust": fitted["std_robust"]}
    s_speed = record.get("std_speed_channel")
    if s_speed is None:
        return out
    out["std_speed_channel"] = s_speed
    if warped_run:
        for key in ("std", "std_robust"):
            if out[key] is not None and np.isfinite(out[key]) and out[key] < s_speed:
                out[key] = float(s_speed)
    elif std_fit is not None and np.isfinite(std_fit):
        out["std"] = float(math.hypot(std_fit, s_speed))
    return out


def unpolished(ds: Dataset, cf: CostFunction, x0, bumps=None):
    """No polish (``polish=False``): the search's row stands, without standard errors, starts or a ``polish``
    block; ``(fit, bumps)`` as :func:`polished` returns them."""
    d = len(cf.names)
    fit = OptimizeResult(x=np.asarray(x0, dtype=float), std=np.full(d, np.nan), info=None, cost=cf, starts={},
                         covariance=np.full((d, d), np.nan), success=True, message="")
    return fit, bumps


def polished(ds: Dataset, cf: CostFunction, x0, bumps=None):
    """The polish stage of the fit (:func:`polish_fit`), the stops a polished car no longer reaches held
    (:func:`bump_recheck`) and a nonlinear cost function's sub-steps unpinned (the result's cost function
    evaluates as any other). Returns ``(fit, bumps)``: ``fit`` with ``covariance`` (white, the free
    parameters'), ``success`` and ``message`` (the polish's, for the result's)."""
    fit = polish_fit(ds, cf, x0)
    if cf.space.bump:
        fit, bumps = bump_recheck(ds, fit, bumps)
    if cf.space.layout is not None:
        fit.cost = fit.cost.with_pin(None)
    fit.update(covariance=np.array(fit.info["covariance"], dtype=float), success=bool(fit.info["success"]),
               message=f" Polish: {fit.info['message']}")
    return fit, bumps


#: the polish stage by the fit's ``polish`` option
POLISH = {True: polished, False: unpolished}
