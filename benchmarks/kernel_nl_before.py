"""The nonlinear car's compiled kernel as it was before the lane-vectorised rewrite (one candidate at a
time, scalar, in Numba), kept here so that ``benchmarks/bench_nonlinear.py`` measures the current kernel
against it in the same run. Not part of the package. Same arguments and results as
:func:`rideid.model.kernel_nl.run`.

Its description then:
Compiled kernel of the nonlinear car (:mod:`rideid.model.nonlinear`): RK4 at ``m`` sub-steps per sample,
split at the kinks.

The same equations, the same scheme and the same operations as the NumPy
backend (:func:`rideid.model.nonlinear.simulate_numpy`), compiled with
Numba: one candidate at a time, states in a 14-vector, the forces corner by
corner (damper curves by a short walk from the zero-velocity segment: most
velocities are small), squared errors accumulated on the fly (mode 0:
memory O(states) per candidate), the channels written (mode 1), the states
(mode 2) or both (mode 3).
Candidates are shared among ``numba.get_num_threads()`` threads; the
compiled function releases the GIL.

Each sub-step is a plain RK4 step; its end evaluation (which is the next
sub-step's first stage, so it costs nothing extra) also gives each corner's
curve segment, bump-stop side and tire-load sign. Where one differs from
the sub-step's start the step is redone out of line (:func:`_pieces`) in
pieces ending at the crossings (:func:`_crossings`, located on the cubic
Hermite of the switching quantity between the ends); the road inputs
inside the sub-step are the cubic Hermite of the tabulated ones.

Measured (``benchmarks/bench_nonlinear.py``, 10 runs, 9470 samples, 64
candidates with digressive curves, on a shared 2-core machine): one thread
5.2 ms per candidate at 2 sub-steps against 16.8 ms for plain RK4 at 13
(the same accuracy; the former kernel 17.0 ms), the linear kernel 0.17 ms
(30x); two threads 2.7 ms, 8.6 ms, 0.11 ms (24x). SciPy ``solve_ivp``
(DOP853) about 1e5 times slower.
"""

from __future__ import annotations

import numba
import numpy as np

from rideid.model.nl_coef import CI, COEF
from rideid.model.kernel import thread_pool

_NC = len(COEF)
_I_MS, _I_IYY, _I_IXX, _I_TOP, _I_KF, _I_KR = (CI[n] for n in ("inv_ms", "inv_Iyy", "inv_Ixx", "topple",
                                                              "kar_f", "kar_r"))
_I_MU, _I_X, _I_Y, _I_KS, _I_CS, _I_KT, _I_CT, _I_L, _I_BC, _I_BR = (
    CI[f"{n}0"] for n in ("inv_mu", "x", "y", "ks", "cs", "kt", "ct", "L", "bs_clear", "bs_rate"))


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _accel(co, p, xk, j0, Fk, Sk, curves, X, u, ud, dX, qdd, d, v, g, vd, seg, ends):
    """State derivative ``dX`` (14,) and accelerations ``qdd`` (7,) of state ``X`` (14,) for candidate ``p``;
    the switching quantities: deflections ``d``, damper velocities ``v`` and their rates ``vd``, tire loads
    ``g`` (4,) each, the curve segments ``seg`` (4,) (``vd`` and ``seg`` only at the sub-step ``ends``).

    ``X = [q, theta', phi', z', p_1..4]``, ``p_i = z_i' - (c_t/m_u) r_i`` (as
    :func:`rideid.model.nonlinear.accelerations`).
    """
    z, th, ph = X[0], X[1], X[2]
    dz, dth, dph = X[7], X[8], X[9]
    nseg = xk.shape[0] - 1
    for c in range(4):
        x = co[p, _I_X + c]
        y = co[p, _I_Y + c]
        w = X[10 + c] + co[p, _I_CT + c] * co[p, _I_MU + c] * u[c]
        dX[3 + c] = w
        d[c] = X[3 + c] - (z - x * th + y * ph)
        v[c] = w - (dz - x * dth + y * dph)
    bf = co[p, _I_KF] * (d[0] - d[1])
    br = co[p, _I_KR] * (d[2] - d[3])
    sx = 0.0
    sy = 0.0
    sf = 0.0
    for c in range(4):
        f = co[p, _I_KS + c] * d[c]
        if c == 0:
            f += bf
        elif c == 1:
            f -= bf
        elif c == 2:
            f += br
        else:
            f -= br
        vc = v[c]
        if curves:
            a = c // 2
            j = j0 if vc >= 0.0 else j0 - 1
            if j < 0:
                j = 0
            if j > nseg - 1:
                j = nseg - 1
            while j < nseg - 1 and vc >= xk[j + 1]:
                j += 1
            while j > 0 and vc < xk[j]:
                j -= 1
            f += Fk[p, a, j] + Sk[p, a, j] * (vc - xk[j])
            if ends:
                seg[c] = j
        else:
            f += co[p, _I_CS + c] * vc
        e = d[c] - co[p, _I_BC + c]
        if e > 0.0:
            f += co[p, _I_BR + c] * e
        L = co[p, _I_L + c]
        ct = co[p, _I_CT + c]
        imu = co[p, _I_MU + c]
        t0 = L + co[p, _I_KT + c] * (u[c] - X[3 + c]) - ct * dX[3 + c]
        crd = ct * ud[c]
        g[c] = t0 + crd
        if t0 + crd >= 0.0:
            dp = (t0 - L - f) * imu
        else:
            dp = (-L - f - crd) * imu
        dX[10 + c] = dp
        qdd[3 + c] = dp + ct * imu * ud[c]
        sf += f
        sx += co[p, _I_X + c] * f
        sy += co[p, _I_Y + c] * f
    top = co[p, _I_TOP]
    qdd[0] = sf * co[p, _I_MS]
    qdd[1] = (-sx + top * th) * co[p, _I_IYY]
    qdd[2] = (sy + top * ph) * co[p, _I_IXX]
    dX[0] = dz
    dX[1] = dth
    dX[2] = dph
    dX[7] = qdd[0]
    dX[8] = qdd[1]
    dX[9] = qdd[2]
    if ends:
        for c in range(4):
            vd[c] = qdd[3 + c] - (qdd[0] - co[p, _I_X + c] * qdd[1] + co[p, _I_Y + c] * qdd[2])


def hermite_value_slope(t, s0, s1, m0, m1):
    """Value and derivative at ``theta = t`` of the cubic Hermite with values ``s0, s1`` and slopes ``m0, m1``
    (per unit ``theta``) at 0 and 1. Plain arithmetic: the same operations on scalars in the compiled kernel
    (:func:`_hermite_value_slope`) and on arrays in :func:`rideid.model.nonlinear.hermite_root`."""
    t2 = t * t
    t3 = t2 * t
    val = (2.0 * t3 - 3.0 * t2 + 1.0) * s0 + (t3 - 2.0 * t2 + t) * m0 + (3.0 * t2 - 2.0 * t3) * s1 \
        + (t3 - t2) * m1
    der = (6.0 * t2 - 6.0 * t) * (s0 - s1) + (3.0 * t2 - 4.0 * t + 1.0) * m0 + (3.0 * t2 - 2.0 * t) * m1
    return val, der


_hermite_value_slope = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")(hermite_value_slope)


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _root(s0, s1, m0, m1):
    """Crossing ``0 < theta <= 1`` of the cubic Hermite ``s`` with values ``s0, s1`` and slopes ``m0, m1`` (per
    unit ``theta``) at 0 and 1, ``s0 != s1`` of opposite signs: the chord's root, then two Newton steps kept
    in ``[0, 1]`` (as :func:`rideid.model.nonlinear.hermite_root`)."""
    t = s0 / (s0 - s1)
    for _ in range(2):
        val, der = _hermite_value_slope(t, s0, s1, m0, m1)
        if der != 0.0:
            t = t - val / der
        if t < 0.0:
            t = 0.0
        if t > 1.0:
            t = 1.0
    return t


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _inputs(UF, RF, js, tau, dt, uu, rr):
    """Road inputs ``uu`` and rates ``rr`` (4,) at ``tau`` (0..1) of the sub-step starting at table row ``js``:
    cubic Hermite of the inputs (with their rates) over the half sub-step ``dt``, rates linear."""
    x = 2.0 * tau
    if x < 1.0:
        i = js
        s = x
    else:
        i = js + 1
        s = x - 1.0
    s2 = s * s
    om = 1.0 - s
    h00 = (1.0 + 2.0 * s) * om * om
    h10 = s * om * om * dt
    h01 = s2 * (3.0 - 2.0 * s)
    h11 = s2 * (s - 1.0) * dt
    for c in range(4):
        uu[c] = h00 * UF[i, c] + h10 * RF[i, c] + h01 * UF[i + 1, c] + h11 * RF[i + 1, c]
        rr[c] = om * RF[i, c] + s * RF[i + 1, c]


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _crossings(xk, kink, clear, h, d0, v0, g0, a0, s0, d1, v1, g1, a1, s1, th):
    """Fractions ``theta`` (sorted into ``th``) of the sub-step where a corner's damper velocity crosses an
    interior knot marked in ``kink`` (2, K + 1) (segments ``s0``, ``s1`` differ), its deflection the
    bump-stop clearance or its tire load zero; returns their number."""
    nc = 0
    for c in range(4):
        va = v0[c]
        vb = v1[c]
        ma = h * a0[c]
        mb = h * a1[c]
        for j in range(min(s0[c], s1[c]) + 1, max(s0[c], s1[c]) + 1):
            if kink[c // 2, j]:
                kn = xk[j]
                th[nc] = _root(va - kn, vb - kn, ma, mb)
                nc += 1
        ea = d0[c] - clear[c]
        eb = d1[c] - clear[c]
        if (ea > 0.0) != (eb > 0.0):
            th[nc] = _root(ea, eb, h * va, h * vb)
            nc += 1
        ga = g0[c]
        gb = g1[c]
        if (ga >= 0.0) != (gb >= 0.0):
            th[nc] = ga / (ga - gb)
            nc += 1
    for i in range(1, nc):  # insertion sort
        t = th[i]
        k = i - 1
        while k >= 0 and th[k] > t:
            th[k + 1] = th[k]
            k -= 1
        th[k + 1] = t
    return nc


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pieces(co, p, xk, j0, Fk, Sk, curves, UF, RF, js, h, th, nc, X, Xt, acc, dX, qdd, d, v, g, vd, seg, uu, rr):
    """RK4 over the sub-step from table row ``js`` in pieces ending at the ``nc`` sorted fractions ``th``
    (then at 1): ``X`` (14,) the state at the start and ``dX`` its derivative on entry, the end state on exit.
    Rare (a kink crossed), so kept out of line."""
    hh = 0.5 * h
    a = 0.0
    fresh = True
    for q in range(nc + 1):
        b = th[q] if q < nc else 1.0
        hp = (b - a) * h
        if hp > 0.0:
            if not fresh:
                _inputs(UF, RF, js, a, hh, uu, rr)
                _accel(co, p, xk, j0, Fk, Sk, curves, X, uu, rr, dX, qdd, d, v, g, vd, seg, False)
            hph = 0.5 * hp
            _inputs(UF, RF, js, 0.5 * (a + b), hh, uu, rr)
            for i in range(14):
                acc[i] = dX[i]
                Xt[i] = X[i] + hph * dX[i]
            _accel(co, p, xk, j0, Fk, Sk, curves, Xt, uu, rr, dX, qdd, d, v, g, vd, seg, False)
            for i in range(14):
                acc[i] += 2.0 * dX[i]
                Xt[i] = X[i] + hph * dX[i]
            _accel(co, p, xk, j0, Fk, Sk, curves, Xt, uu, rr, dX, qdd, d, v, g, vd, seg, False)
            for i in range(14):
                acc[i] += 2.0 * dX[i]
                Xt[i] = X[i] + hp * dX[i]
            _inputs(UF, RF, js, b, hh, uu, rr)
            _accel(co, p, xk, j0, Fk, Sk, curves, Xt, uu, rr, dX, qdd, d, v, g, vd, seg, False)
            for i in range(14):
                X[i] += (hp / 6.0) * (acc[i] + dX[i])
            fresh = False
        a = b


@numba.njit(cache=True, nogil=True, error_model="numpy")
def run_range(c0, c1, co, xk, j0, Fk, Sk, curves, split, kink, X0, run_start, hs, ms, fine_start, UF, RF, Y, W, mode,
              err, out, states):
    """Candidates ``c0 <= p < c1`` over every run (see :func:`run` for the arguments)."""
    X = np.empty(14)
    Xs = np.empty(14)
    Xt = np.empty(14)
    acc = np.empty(14)
    dX = np.empty(14)
    D0 = np.empty(14)
    qdd = np.empty(7)
    d = np.empty(4)
    v = np.empty(4)
    g = np.empty(4)
    vd = np.empty(4)
    d0 = np.empty(4)
    v0 = np.empty(4)
    g0 = np.empty(4)
    vd0 = np.empty(4)
    seg = np.zeros(4, dtype=np.int64)
    seg0 = np.zeros(4, dtype=np.int64)
    uu = np.empty(4)
    rr = np.empty(4)
    clear = np.empty(4)
    th = np.empty(4 * (xk.shape[0] + 2))
    y = np.empty(10)
    n_runs = run_start.shape[0] - 1
    for p in range(c0, c1):
        for c in range(4):
            clear[c] = co[p, _I_BC + c]
        for r in range(n_runs):
            for i in range(14):
                X[i] = X0[r, p, i]
            m = ms[r]
            h = hs[r]
            hh = 0.5 * h
            f0 = fine_start[r]
            n = run_start[r + 1] - run_start[r]
            e_sum = 0.0
            _accel(co, p, xk, j0, Fk, Sk, curves, X, UF[f0], RF[f0], dX, qdd, d, v, g, vd, seg, True)
            for k in range(n):
                jf = f0 + 2 * m * k
                for c in range(4):
                    y[c] = qdd[0] - co[p, _I_X + c] * qdd[1] + co[p, _I_Y + c] * qdd[2]
                    y[4 + c] = qdd[3 + c]
                y[8] = X[8]
                y[9] = X[9]
                row = run_start[r] + k
                if mode & 2:  # the states, wheel velocities shifted back (nonlinear.shifted)
                    for i in range(10):
                        states[p, row, i] = X[i]
                    for c in range(4):
                        states[p, row, 10 + c] = X[10 + c] + co[p, _I_CT + c] * co[p, _I_MU + c] * UF[jf, c]
                if mode & 1:
                    for q in range(10):
                        out[p, row, q] = y[q]
                elif mode == 0:
                    for q in range(10):
                        dq = y[q] - Y[row, q]
                        e_sum += W[r, q] * dq * dq
                if k + 1 == n:
                    break
                for s in range(m):
                    js = jf + 2 * s
                    for i in range(14):
                        Xs[i] = X[i]
                        D0[i] = dX[i]
                    for c in range(4):
                        d0[c] = d[c]
                        v0[c] = v[c]
                        g0[c] = g[c]
                        vd0[c] = vd[c]
                        seg0[c] = seg[c]
                    # the classical RK4 step
                    for i in range(14):
                        acc[i] = dX[i]
                        Xt[i] = X[i] + hh * dX[i]
                    _accel(co, p, xk, j0, Fk, Sk, curves, Xt, UF[js + 1], RF[js + 1], dX, qdd, d, v, g, vd, seg, False)
                    for i in range(14):
                        acc[i] += 2.0 * dX[i]
                        Xt[i] = X[i] + hh * dX[i]
                    _accel(co, p, xk, j0, Fk, Sk, curves, Xt, UF[js + 1], RF[js + 1], dX, qdd, d, v, g, vd, seg, False)
                    for i in range(14):
                        acc[i] += 2.0 * dX[i]
                        Xt[i] = X[i] + h * dX[i]
                    _accel(co, p, xk, j0, Fk, Sk, curves, Xt, UF[js + 2], RF[js + 2], dX, qdd, d, v, g, vd, seg, False)
                    for i in range(14):
                        X[i] += (h / 6.0) * (acc[i] + dX[i])
                    _accel(co, p, xk, j0, Fk, Sk, curves, X, UF[js + 2], RF[js + 2], dX, qdd, d, v, g, vd, seg, True)
                    if not split:
                        continue
                    nc = _crossings(xk, kink, clear, h, d0, v0, g0, vd0, seg0, d, v, g, vd, seg, th)
                    if nc == 0:
                        continue
                    # a kink inside the step: redo it in pieces that end at the crossings
                    for i in range(14):
                        X[i] = Xs[i]
                        dX[i] = D0[i]
                    _pieces(co, p, xk, j0, Fk, Sk, curves, UF, RF, js, h, th, nc, X, Xt, acc, dX, qdd, d, v, g, vd,
                            seg, uu, rr)
                    _accel(co, p, xk, j0, Fk, Sk, curves, X, UF[js + 2], RF[js + 2], dX, qdd, d, v, g, vd, seg, True)
            err[r, p] = e_sum


def _dummy_args():
    n = 1
    co = np.ones((n, _NC))
    xk = np.array([0.0, 1.0])
    Fk = np.zeros((n, 2, 2))
    Sk = np.zeros((n, 2, 1))
    X0 = np.zeros((1, n, 14))
    return (0, 1, co, xk, 0, Fk, Sk, False, True, np.ones((2, 2), dtype=np.int64), X0,
            np.array([0, 2], dtype=np.int64), np.array([0.01]), np.array([1], dtype=np.int64),
            np.array([0, 3], dtype=np.int64), np.zeros((3, 4)), np.zeros((3, 4)), np.zeros((2, 10)),
            np.zeros((1, 10)), 0, np.zeros((1, n)), np.zeros((n, 2, 10)), np.zeros((n, 1, 14)))


def compile_kernel() -> None:
    """Compile (or load from Numba's cache) the kernel; raises if that fails."""
    run_range(*_dummy_args())


def run(co, xk, Fk, Sk, curves, X0, run_start, h, ms, fines, Y, W, mode, split=True, kinks=None):
    """Simulate every run for every candidate.

    Parameters
    ----------
    co : (n, len(COEF)) coefficients, xk (K+1,) knots with 0, Fk (n, 2, K+1), Sk (n, 2, K)
        (:func:`rideid.model.nonlinear.coefficients`); curves : bool
    X0 : (r, n, 14) initial states; run_start (r + 1,); h (r,) sample intervals; ms (r,) sub-steps
    fines : list over runs of ``(U, R)``, inputs and rates at the sub-step and half-step instants
        (:func:`rideid.model.nonlinear.fine_inputs`)
    Y : (T, 10), W : (r, 10), mode : 0 errors only, 1 the channels, 2 the states, 3 both
    split : split the sub-steps at the kinks they cross (False: plain RK4 sub-steps)
    kinks : (2, K + 1) which knots of ``xk`` are kinks, per axle (:func:`rideid.model.nonlinear.kink_mask`;
        None: every interior knot)

    Returns
    -------
    err : (r, n) (with mode 0); out : (n, T, 10) with mode 1 or 3, else None; states : (n, T, 14) with
    mode 2 or 3, else None: ``[q, q']`` (deviations from static equilibrium, as
    :func:`rideid.model.nonlinear.simulate_numpy`'s)
    """

    n = co.shape[0]
    n_runs = len(fines)
    fine_start = np.zeros(n_runs + 1, dtype=np.int64)
    for i, (U, _) in enumerate(fines):
        fine_start[i + 1] = fine_start[i] + U.shape[0]
    UF = np.ascontiguousarray(np.concatenate([f[0] for f in fines]))
    RF = np.ascontiguousarray(np.concatenate([f[1] for f in fines]))
    hs = np.ascontiguousarray(np.asarray(h, dtype=float) / np.asarray(ms, dtype=float))
    j0 = int(np.flatnonzero(xk == 0.0)[0])
    kinks = np.ones((2, xk.size), dtype=np.int64) if kinks is None else np.ascontiguousarray(kinks, dtype=np.int64)
    err = np.zeros((n_runs, n))
    T = int(run_start[-1])
    out = np.zeros((n, T, 10) if mode & 1 else (n, 1, 10))
    states = np.zeros((n, T, 14) if mode & 2 else (n, 1, 14))
    args = (np.ascontiguousarray(co), np.ascontiguousarray(xk, dtype=float), j0, np.ascontiguousarray(Fk),
            np.ascontiguousarray(Sk), bool(curves), bool(split), kinks, np.ascontiguousarray(X0),
            np.asarray(run_start, dtype=np.int64), hs, np.asarray(ms, dtype=np.int64), fine_start, UF, RF,
            np.ascontiguousarray(Y, dtype=float), np.ascontiguousarray(W, dtype=float), int(mode), err, out, states)
    threads = max(1, min(numba.get_num_threads(), n))
    if threads == 1:
        run_range(0, n, *args)
    else:
        bounds = np.linspace(0, n, threads + 1).round().astype(int)
        futures = [thread_pool(threads).submit(run_range, int(a), int(b), *args)
                   for a, b in zip(bounds[:-1], bounds[1:])]
        for f in futures:
            f.result()
    return err, (out if mode & 1 else None), (states if mode & 2 else None)
