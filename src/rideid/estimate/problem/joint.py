"""The joint problem of the fit with unknown roads or tracks as built: the residual blocks
(:mod:`rideid.estimate.problem.blocks`: the runs on tracks as drawn, each unknown road, each track as built), each
times its weight, over one coordinate vector of the car, and its numbers: the stacked residuals, the cost of many
cars at once on both cores, the Jacobian, the cost's true Hessian by second differences, its rounding, its
curvature along a direction. What moves a block's nuisances (a run's speed and start) and what is done with these
numbers (the solve, the Newton steps, the sandwich) is the fit's: :mod:`rideid.estimate.fit.anyroad`.
"""

from __future__ import annotations

import functools

import numpy as np

from ...model.batch import thread_map
from ...settings import defaults


class JointProblem:
    """The joint residual of the problem's blocks (:mod:`rideid.estimate.problem.blocks`: the runs on tracks as
    drawn, each unknown road, each track as built), each block times its weight ``scale``.

    Coordinates ``v``: the logarithm of each parameter bounded away from 0 (relative steps: the road fit's
    valley along the wheels' common scale, unsprung masses and tires together, is long and shallow, and the
    solver crosses it in a few steps in these coordinates, not in the bounds' unit box), the parameter over
    its range's width for those that may be 0 (bars, tire damping). A problem is a value: :meth:`reweighted` and
    :meth:`with_blocks` return new ones."""

    def __init__(self, space, geom, blocks, scale, sizes=()):
        self.space, self.geom, self.parts = space, geom, tuple(blocks)
        lo, hi = space.bounds[:, 0], space.bounds[:, 1]
        self.log = lo > 0
        self.span = np.where(self.log, 1.0, hi - lo)
        self.vbounds = (np.where(self.log, np.log(np.where(self.log, lo, 1.0)), lo / self.span),
                        np.where(self.log, np.log(np.where(self.log, hi, 1.0)), hi / self.span))
        self.scale = np.asarray(scale, dtype=float)  # each block's weight (1 until reweighted)
        self.sizes = list(sizes)  # each block's residual count, set by reweighted
        self.size = sum(self.sizes)

    def with_blocks(self, blocks) -> JointProblem:
        """The same problem (weights, sizes) on ``blocks`` (each block's nuisances moved)."""
        return JointProblem(self.space, self.geom, blocks, self.scale, self.sizes)

    def of(self, kind) -> list[int]:
        """The indices of the blocks of class ``kind``."""
        return [k for k, b in enumerate(self.parts) if isinstance(b, kind)]

    def moving(self) -> list[int]:
        """The indices of the blocks with motion unknowns (SPEC §13): each track as built (its speed and start) and
        each unknown road (its speed), in block order."""
        return [k for k, b in enumerate(self.parts) if getattr(b, "n_motion", 0)]

    def x(self, v):
        v = np.asarray(v, dtype=float)
        return np.where(self.log, np.exp(v), v * self.span)

    def v(self, x):
        x = np.asarray(x, dtype=float)
        return np.clip(np.where(self.log, np.log(np.where(self.log, x, 1.0)), x / self.span), *self.vbounds)

    def dxdv(self, v):
        """``dx/dv`` (d,): Jacobians in ``v`` divided by it are Jacobians in ``x``."""
        return np.where(self.log, self.x(v), self.span)

    def car(self, v):
        """The full parameter row (16+,) at ``v``."""
        return self.space.full(self.x(v)[None])[0]

    def blocks(self, z, threads: bool = True, parts=None):
        """The residual blocks at ``z`` (those of the indices ``parts`` alone, when given), computed on parallel
        threads (their NumPy and LAPACK work releases the GIL; each block is its own), the track runs as drawn and
        then the longest runs first; one after the other without ``threads``; None where the car is not valid."""
        x = self.x(z)
        P = self.space.full(x[None])
        if not self.space.valid(P)[0]:
            return None
        parts = range(len(self.parts)) if parts is None else parts
        if not threads:
            return [self.parts[k].residuals(x, P[0], self.geom) for k in parts]
        order = sorted(parts, key=lambda i: self.parts[i].order)
        done = dict(zip(order, thread_map(lambda i: self.parts[i].residuals(x, P[0], self.geom), order,
                                          "rideid-roads")))
        return [done[i] for i in parts]

    def residual(self, z, parts=None) -> np.ndarray:
        """The weighted residual of the blocks ``parts`` (indices; all when None) at ``z``, one after the other (1e3
        everywhere for a car that is not valid)."""
        return self._stacked(self.blocks(z, threads=False, parts=parts), parts)

    def costs(self, V, parts=None) -> np.ndarray:
        """``sum e^2`` at each row of ``V`` (of the blocks ``parts`` alone, when given), the rows on parallel threads
        (each row's blocks one after the other: many small evaluations keep both cores busier so than each one's
        blocks side by side), the rows of one car (all but the damper curves' knot forces) one after the other: a
        road's projection of a car is then reused for its knot forces
        (:func:`rideid.estimate.problem.roadfit.solve`)."""
        def cost(z):
            return float(np.sum(self.residual(z, parts) ** 2))
        V = np.asarray(V, dtype=float)
        if parts is not None and all(hasattr(self.parts[k], "residual_rows") for k in parts):
            return self._population_costs(V, parts)
        car = [j for j, n in enumerate(self.space.names) if n not in set(self.space.knot_names)]
        order = np.lexsort(V[:, car].T[::-1]) if car else np.arange(len(V))
        out = np.empty(len(V))
        out[order] = thread_map(cost, list(V[order]), "rideid-hessian")
        return out

    def _population_costs(self, V, parts, rows: int = 256) -> np.ndarray:
        """:meth:`costs` of blocks whose residuals come many rows at once (``residual_rows``: the runs as drawn, a
        population of the simulator), ``rows`` rows a call, the calls on parallel threads."""
        X = self.x(V)
        ok = self.space.valid(self.space.full(X))
        out = np.full(len(V), float(np.sum(self._stacked(None, parts) ** 2)))  # a car that is not valid

        def chunk(idx):
            return sum(np.sum((self.scale[k] * self.parts[k].residual_rows(X[idx])) ** 2, axis=1) for k in parts)

        idx = np.flatnonzero(ok)
        if idx.size:
            out[idx] = np.concatenate(thread_map(chunk, np.array_split(idx, -(-idx.size // rows)), "rideid-hessian"))
        return out

    def jacobian(self, v, step: float = 1e-5) -> np.ndarray:
        """Central-difference Jacobian of the residuals at ``v`` (in ``v`` units).

        The step is 1e-5 (relative, for the logarithmic coordinates): the residual carries rounding noise
        (eigenvectors, the boundary unknowns' solve), and at 1e-7 its differences inflated the robust
        error bars of the unsprung masses 15-fold (0.42 % at 1e-6, 0.20 % at 1e-5, measured)."""
        J = np.empty((self.size, v.size))
        for j in range(v.size):
            hi = min(step, self.vbounds[1][j] - v[j])
            lo = min(step, v[j] - self.vbounds[0][j])
            vp, vm = v.copy(), v.copy()
            vp[j] += hi
            vm[j] -= lo
            J[:, j] = (self(vp) - self(vm)) / (hi + lo) if hi + lo > 0 else 0.0
        return J

    def hessian(self, v, step: float = 1e-3) -> np.ndarray:
        """Half the Hessian of the cost ``sum e^2`` at ``v`` (in ``v`` units), by central second differences.

        Not ``J^T J``: the projected residual ``P_perp(theta) Y`` is linear in the
        data, so its Jacobian carries the noise (``dP_perp/dtheta eps``), and
        ``J^T J`` over-states the information by ``sigma^2 tr(dP dP)``, which the
        residual's own curvature ``e . d2e`` cancels in the true Hessian
        (``tr(P d2P) = -tr(dP dP)`` for a projector). Along the wheels' common
        scale (unsprung masses and tires together) the over-statement was a factor
        200 on the built-in SUV's roads (measured): error bars 10-20 times too
        small. The cost is quadratic over ``step`` (checked at 0.25, 0.5 and 1 times
        a 0.2 % step: 4.0 and 4.0 times per doubling).

        A parameter within ``step`` of its bound (a bar or a tire damper of nothing, at 0) has its differences
        taken a step inside: beyond the bound the car is not valid and its cost a penalty, whose second
        difference made such a rate's error bar 1e-7 N/m (and its Wald statistic, which weighs the model choice's
        candidates, 1e16 for a bar rate of 0.3 N/m: measured on the built-in car's roads).

        With damper curves on unknown roads (:meth:`knot_split`) the entries that hold a knot force are not taken
        from the whole cost's second differences: the road blocks' residuals are affine in the knot forces (the
        curves enter as a known input of the linear car, its projection the same), so their part is exact,
        ``J^T J`` among the knots and a difference of the knots' gradient ``J^T e`` across each car parameter
        (:meth:`_knot_entries`); the other blocks' part (the runs on tracks as drawn, a nonlinear simulation) is
        their own cost's second differences. The van on three roads and a twist run
        (../shared/cases/van-roads-dampers, 40 knot forces): 4803 costs of every block before, of which 1602 moved
        the car; now 163 of every block, 731 of the road blocks and 4640 of the twist run's
        (docs/performance.md)."""
        d = v.size
        v = np.clip(v, self.vbounds[0] + step, self.vbounds[1] - step)
        split = self.knot_split()
        if split is None:
            return second_differences(self.costs, v, step, range(d))
        car, knots, affine, other = split
        H = second_differences(self.costs, v, step, car)  # the car's entries, every block
        if other:
            H += second_differences(functools.partial(self.costs, parts=other), v, step, range(d), skip=set(car))
        return H + self._knot_entries(v, step, car, knots, affine)

    def knot_split(self):
        """``(car, knots, affine, other)``: the indices of the free parameters that are not knot forces and of those
        that are, of the blocks whose residuals are affine in the knot forces (``affine_in_knots``: a road run with
        damper curves, :class:`rideid.estimate.problem.roadfit.Departure`) and of the others; None without a free
        knot force or such a block."""
        names = list(self.space.names)
        knot = set(self.space.knot_names)
        knots = [j for j, n in enumerate(names) if n in knot]
        affine = [k for k, b in enumerate(self.parts) if getattr(b, "affine_in_knots", False)]
        if not knots or not affine:
            return None
        return ([j for j, n in enumerate(names) if n not in knot], knots, affine,
                [k for k in range(len(self.parts)) if k not in set(affine)])

    def _knot_entries(self, v, step: float, car, knots, affine) -> np.ndarray:
        """The half Hessian's entries of the blocks ``affine`` (residuals ``e`` affine in the knot forces ``F`` of
        ``knots``) that hold a knot force (d, d). With ``J`` the knots' columns in ``v`` (``de/dF dF/dv``, ``de/dF``
        by forward differences, exact but for rounding): among the knots ``J^T J`` plus, for a knot force in
        logarithmic coordinates (``F = exp(v)``, so ``d2e/dv2 = de/dv``), its half gradient ``(J^T e)_k`` on the
        diagonal; between car parameter ``i`` and the knots the central difference of the knots' half gradient
        ``J^T e`` at ``v +- step e_i``. ``(1 + 2 c) (1 + k)`` evaluations of those blocks for ``c`` car parameters
        and ``k`` knot forces, those of one car together (its projection is reused)."""
        d = v.size
        E = np.eye(d) * step
        points = [v] + [v + E[i] for i in car] + [v - E[i] for i in car]

        def knot_gradient(p):  # (J^T e, J) at p: e the blocks' residuals there, J their knot columns in v
            e0 = self.residual(p, affine)
            x, dxdv = self.x(p), self.dxdv(p)
            J = np.stack([(self.residual(p + E[k], affine) - e0) * (dxdv[k] / (self.x(p + E[k])[k] - x[k]))
                          for k in knots])  # (k, m)
            return J @ e0, J

        got = thread_map(knot_gradient, points, "rideid-hessian")
        g, J = got[0]
        H = np.zeros((d, d))
        H[np.ix_(knots, knots)] = J @ J.T + np.diag(np.where(self.log[knots], g, 0.0))
        nc = len(car)
        cross = np.array([(got[1 + i][0] - got[1 + nc + i][0]) / (2 * step) for i in range(nc)]).reshape(nc, -1)
        H[np.ix_(car, knots)] = cross
        H[np.ix_(knots, car)] = cross.T
        return H

    def along(self, v, U, m: int, step: float = 1e-3) -> np.ndarray | None:
        """The half Hessian's row along ``U[:, m]`` in the orthonormal basis ``U`` at the point :meth:`hessian` takes
        at ``step``, by second differences of step setting ``uncertainty.direction_step`` ``a`` along ``u = U[:,
        m]``: the curvature ``(f(v + a u) + f(v - a u) - 2 f(v)) / (2 a^2)``, each coupling ``(f(++) - f(+-) -
        f(-+) + f(--)) / (8 a t)`` with ``t`` along ``U[:, j]`` as large as ``a`` where the bounds leave room (a bar
        at 0 leaves less: ``t`` then the room's nine tenths; below ``step`` the coupling is not measured again, NaN).
        ``4 (d - 1) + 3`` costs at most; None when ``v +- a u`` crosses a bound."""
        a = defaults["uncertainty.direction_step"]
        lo, hi = self.vbounds
        v = np.clip(v, lo + step, hi - step)
        d = U.shape[1]
        u = U[:, m]
        ends = np.array([v + a * u, v - a * u])
        if np.any(ends < lo) or np.any(ends > hi):
            return None

        def room(base, w):  # how far from base along +-w the bounds allow
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(w > 0, (hi - base) / w, np.where(w < 0, (lo - base) / w, np.inf))
            return float(np.min(r))

        steps = {j: min(a, 0.9 * min(room(b, sg * U[:, j]) for b in ends for sg in (1, -1)))
                 for j in range(d) if j != m}
        steps = {j: t for j, t in steps.items() if t >= step}
        moves = [np.zeros(d), a * u, -a * u] + [a * s * u + t * r * U[:, j] for j, t in steps.items()
                                                for s, r in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
        c = self.costs(v + np.array(moves))
        row = np.full(d, np.nan)
        row[m] = (c[1] + c[2] - 2 * c[0]) / (2 * a * a)
        for (j, t), q in zip(steps.items(), c[3:].reshape(-1, 4)):
            row[j] = (q[0] - q[1] - q[2] + q[3]) / (8 * a * t)
        return row

    def rounding(self, v, step: float = 1e-3, tiny: float = 1e-9, pairs: int = 16) -> float:
        """The cost's rounding at the point :meth:`hessian` takes at ``step``: the standard deviation of one cost,
        from the spread of ``f(v + t e_k) + f(v - t e_k)`` over ``pairs`` moves of ``tiny`` along the unknowns in
        turn (each sum's gradient terms cancel and its curvature term is about 1e-18: what varies is rounding, of
        variance ``2 delta^2``). 2 ``pairs`` costs (the Hessian takes ``2 d^2 + 1``); 16 pairs estimate ``delta``
        to about 18 % (one std), and the costs' rounding is the one of the Hessian's evaluations only under the same
        BLAS threads (one: :func:`rideid.model.batch.single_threaded_blas`; on the all-realities gross case
        1.07e-5 of a cost of 4342 on one thread, 1.60e-5 on two)."""
        d = v.size
        v = np.clip(v, self.vbounds[0] + step, self.vbounds[1] - step)
        E = np.eye(d)[np.arange(pairs) % d] * tiny
        c = self.costs(v + np.vstack([E, -E]))
        return float(np.std(c[:pairs] + c[pairs:], ddof=1) / np.sqrt(2.0))

    def __call__(self, z):
        return self._stacked(self.blocks(z))

    def _stacked(self, b, parts=None) -> np.ndarray:
        """The weighted residual of the blocks ``b`` of the indices ``parts`` (all when None; 1e3 everywhere for
        ``b`` None: a car that is not valid)."""
        parts = range(len(self.parts)) if parts is None else parts
        if b is None:
            return np.full(sum(self.sizes[k] for k in parts) if self.sizes else 0, 1e3)
        return np.concatenate([self.scale[k] * r for k, r in zip(parts, b)])

    def reweighted(self, z) -> JointProblem:
        """The problem with each block divided by its own RMS at ``z``; a run on a track as built is already
        divided by its noise level, bin by bin (:mod:`rideid.estimate.problem.asbuilt`), and keeps its weight 1."""
        b = self.blocks(z)
        scale = np.array([1.0 / max(np.sqrt(np.mean(r ** 2)), 1e-300) if blk.reweighted else 1.0
                          for blk, r in zip(self.parts, b)])
        return JointProblem(self.space, self.geom, self.parts, scale, [r.size for r in b])


def second_differences(costs, v, step: float, index, skip=frozenset()) -> np.ndarray:
    """Half the second differences of ``costs`` (an array of points -> their costs) at ``v`` (d, d): each diagonal
    entry of ``index`` and each pair of them, leaving out the entries of two indices both in ``skip`` (zero
    there). The Hessian's stencils (:meth:`JointProblem.hessian`)."""
    d = v.size
    index = list(index)
    diag = [i for i in index if i not in skip]
    h = np.full(d, step)
    E = np.eye(d) * h
    pairs = [(i, j) for n, i in enumerate(index) for j in index[:n] if not (i in skip and j in skip)]
    moves = ([np.zeros(d)] + [E[i] for i in diag] + [-E[i] for i in diag]
             + [m for i, j in pairs for m in (E[i] + E[j], E[i] - E[j], E[j] - E[i], -E[i] - E[j])])
    c = costs(v + np.array(moves))  # every evaluation at once, on both cores, those of one car together
    n = len(diag)
    c0, plus, minus, cross = c[0], c[1:n + 1], c[n + 1:2 * n + 1], c[2 * n + 1:].reshape(-1, 4)
    H = np.zeros((d, d))
    H[diag, diag] = (plus - 2 * c0 + minus) / h[diag] ** 2
    # four costs a pair, not the two of the diagonal moves +-(e_i + e_j) (f(+) + f(-) - f(+i) - f(-i) - f(+j)
    # - f(-j) + 2 f0): that one sums seven costs where this sums four, and the cost's rounding on a track as
    # built (the all-realities SUV) moved its error bars by up to 25 % between steps of 1e-3 and 5e-4, this
    # one's by 5 %
    for (i, j), q in zip(pairs, cross):
        H[i, j] = H[j, i] = (q[0] - q[1] - q[2] + q[3]) / (4 * h[i] * h[j])
    return 0.5 * H
