"""Compiled kernel of the nonlinear car (:mod:`rideid.model.nonlinear`): RK4 at ``m`` sub-steps per sample.

The same equations and the same operations as the NumPy backend
(:func:`rideid.model.nonlinear.simulate_numpy`), compiled with Numba: one
candidate at a time, states in a 14-vector, the forces corner by corner
(damper curves by a short walk from the zero-velocity segment: most
velocities are small), squared errors accumulated on the fly (mode 0: memory
O(states) per candidate) or the channels written (mode 1). Candidates are
shared among ``numba.get_num_threads()`` threads; the compiled function
releases the GIL.
"""

from __future__ import annotations

import numba
import numpy as np

from .nonlinear import CI, COEF

_NC = len(COEF)
_I_MS, _I_IYY, _I_IXX, _I_TOP, _I_KF, _I_KR = (CI[n] for n in ("inv_ms", "inv_Iyy", "inv_Ixx", "topple",
                                                              "kar_f", "kar_r"))
_I_MU, _I_X, _I_Y, _I_KS, _I_CS, _I_KT, _I_CT, _I_L, _I_BC, _I_BR = (
    CI[f"{n}0"] for n in ("inv_mu", "x", "y", "ks", "cs", "kt", "ct", "L", "bs_clear", "bs_rate"))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _accel(co, p, xk, j0, Fk, Sk, curves, X, u, ud, dX, qdd, d, v):
    """State derivative ``dX`` (14,) and accelerations ``qdd`` (7,) of state ``X`` (14,) for candidate ``p``.

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
            while j < nseg - 1 and vc > xk[j + 1]:
                j += 1
            while j > 0 and vc < xk[j]:
                j -= 1
            f += Fk[p, a, j] + Sk[p, a, j] * (vc - xk[j])
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


@numba.njit(cache=True, nogil=True, error_model="numpy")
def run_range(c0, c1, co, xk, j0, Fk, Sk, curves, X0, run_start, hs, ms, fine_start, UF, RF, Y, W, mode, err, out):
    """Candidates ``c0 <= p < c1`` over every run (see :func:`run` for the arguments)."""
    X = np.empty(14)
    Xt = np.empty(14)
    acc = np.empty(14)
    dX = np.empty(14)
    qdd = np.empty(7)
    d = np.empty(4)
    v = np.empty(4)
    y = np.empty(10)
    n_runs = run_start.shape[0] - 1
    for p in range(c0, c1):
        for r in range(n_runs):
            for i in range(14):
                X[i] = X0[r, p, i]
            m = ms[r]
            h = hs[r]
            hh = 0.5 * h
            f0 = fine_start[r]
            n = run_start[r + 1] - run_start[r]
            e_sum = 0.0
            for k in range(n):
                jf = f0 + 2 * m * k
                _accel(co, p, xk, j0, Fk, Sk, curves, X, UF[jf], RF[jf], dX, qdd, d, v)
                for c in range(4):
                    y[c] = qdd[0] - co[p, _I_X + c] * qdd[1] + co[p, _I_Y + c] * qdd[2]
                    y[4 + c] = qdd[3 + c]
                y[8] = X[8]
                y[9] = X[9]
                row = run_start[r] + k
                if mode == 1:
                    for q in range(10):
                        out[p, row, q] = y[q]
                else:
                    for q in range(10):
                        dq = y[q] - Y[row, q]
                        e_sum += W[r, q] * dq * dq
                if k + 1 == n:
                    break
                for s in range(m):
                    js = jf + 2 * s
                    if s > 0:
                        _accel(co, p, xk, j0, Fk, Sk, curves, X, UF[js], RF[js], dX, qdd, d, v)
                    for i in range(14):
                        acc[i] = dX[i]
                        Xt[i] = X[i] + hh * dX[i]
                    _accel(co, p, xk, j0, Fk, Sk, curves, Xt, UF[js + 1], RF[js + 1], dX, qdd, d, v)
                    for i in range(14):
                        acc[i] += 2.0 * dX[i]
                        Xt[i] = X[i] + hh * dX[i]
                    _accel(co, p, xk, j0, Fk, Sk, curves, Xt, UF[js + 1], RF[js + 1], dX, qdd, d, v)
                    for i in range(14):
                        acc[i] += 2.0 * dX[i]
                        Xt[i] = X[i] + h * dX[i]
                    _accel(co, p, xk, j0, Fk, Sk, curves, Xt, UF[js + 2], RF[js + 2], dX, qdd, d, v)
                    for i in range(14):
                        X[i] += (h / 6.0) * (acc[i] + dX[i])
            err[r, p] = e_sum


def _dummy_args():
    n = 1
    co = np.ones((n, _NC))
    xk = np.array([0.0, 1.0])
    Fk = np.zeros((n, 2, 2))
    Sk = np.zeros((n, 2, 1))
    X0 = np.zeros((1, n, 14))
    return (0, 1, co, xk, 0, Fk, Sk, False, X0, np.array([0, 2], dtype=np.int64), np.array([0.01]),
            np.array([1], dtype=np.int64), np.array([0, 3], dtype=np.int64), np.zeros((3, 4)), np.zeros((3, 4)),
            np.zeros((2, 10)), np.zeros((1, 10)), 0, np.zeros((1, n)), np.zeros((n, 2, 10)))


def compile_kernel() -> None:
    """Compile (or load from Numba's cache) the kernel; raises if that fails."""
    run_range(*_dummy_args())


def run(co, xk, Fk, Sk, curves, X0, run_start, h, ms, fines, Y, W, mode):
    """Simulate every run for every candidate.

    Parameters
    ----------
    co : (n, len(COEF)) coefficients, xk (K+1,) knots with 0, Fk (n, 2, K+1), Sk (n, 2, K)
        (:func:`rideid.model.nonlinear.coefficients`); curves : bool
    X0 : (r, n, 14) initial states; run_start (r + 1,); h (r,) sample intervals; ms (r,) sub-steps
    fines : list over runs of ``(U, R)``, inputs and rates at the sub-step and half-step instants
    Y : (T, 10), W : (r, 10), mode : 0 errors only, 1 also the channels

    Returns
    -------
    err : (r, n); out : (n, T, 10) with mode 1, else None
    """
    from .kernel import _pool

    n = co.shape[0]
    n_runs = len(fines)
    fine_start = np.zeros(n_runs + 1, dtype=np.int64)
    for i, (U, _) in enumerate(fines):
        fine_start[i + 1] = fine_start[i] + U.shape[0]
    UF = np.ascontiguousarray(np.concatenate([f[0] for f in fines]))
    RF = np.ascontiguousarray(np.concatenate([f[1] for f in fines]))
    hs = np.ascontiguousarray(np.asarray(h, dtype=float) / np.asarray(ms, dtype=float))
    j0 = int(np.flatnonzero(xk == 0.0)[0])
    err = np.zeros((n_runs, n))
    T = int(run_start[-1])
    out = np.zeros((n, T, 10)) if mode == 1 else np.zeros((n, 1, 10))
    args = (np.ascontiguousarray(co), np.ascontiguousarray(xk, dtype=float), j0, np.ascontiguousarray(Fk),
            np.ascontiguousarray(Sk), bool(curves), np.ascontiguousarray(X0), np.asarray(run_start, dtype=np.int64),
            hs, np.asarray(ms, dtype=np.int64), fine_start, UF, RF, np.ascontiguousarray(Y, dtype=float),
            np.ascontiguousarray(W, dtype=float), int(mode), err, out)
    threads = max(1, min(numba.get_num_threads(), n))
    if threads == 1:
        run_range(0, n, *args)
    else:
        bounds = np.linspace(0, n, threads + 1).round().astype(int)
        futures = [_pool(threads).submit(run_range, int(a), int(b), *args) for a, b in zip(bounds[:-1], bounds[1:])]
        for f in futures:
            f.result()
    return err, (out if mode == 1 else None)
