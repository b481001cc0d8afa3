"""Exponential integrators for the nonlinear car at one step per sample: accuracy study (issue 37, item 3).

The candidate's *linear* car (springs, bars, tires in contact, each damper
at a reference slope ``c_ref``; shifted states as in
:mod:`rideid.model.nonlinear`) is integrated exactly over each step,
``X' = A X + Bt u(t) + N(X, t)``, the road's forcing by fine Gauss
quadrature of ``e^{A (h - s)} Bt u(t_k + s)`` (the linear kernel's moments,
written out); only the residual ``N = f(X) - A X - Bt u`` (curve minus the
reference slope, bump stops, lift-off; nonzero in the seven acceleration
rows only) is integrated numerically:

* ``etd2``: Cox-Matthews ETD2RK (predictor with ``phi1 N_k``, corrector with
  ``phi2 (N(a) - N_k)``), two residuals per step, no half-step state;
* ``etd4``: Cox-Matthews ETDRK4, four residuals per step, the road's forcing
  over each half step exact too;
* ``lawson4``: Lawson RK4 (RK4 on ``e^{-A t} X``), four residuals per step.

Each at ``m`` steps per sample. Error: largest over the ten channels of the
RMS difference relative to the channel's RMS, against the present scheme
(RK4 split at the kinks) at 64x its sub-steps, as ``tests/test_nonlinear.py``.
Cases: the tests' severe runs (asymmetric digressive dampers, bump stops that
are reached, wheels that lift; CG 0.25 m) and the built-in scenario's runs
with the bench's digressive cars. The reference slope: the mean slope of the
two curve segments around zero velocity.

With ``--crossings`` (issue 52, item 4): every corner held over the step in the region it starts in (its
curve's segment, its bump stop on or off, its tire in contact or not; that car is affine, so ETDRK4 integrates
it to its order) and what that misses added in closed form: from each crossing of a kink, a clearance or
zero tire load on, the change of force along the switching quantity, carried to the step's end by the
phi-functions of the car after the crossing (their series on the force's column: no matrix exponential per
crossing), crossing after crossing, each timed on the true car (:func:`kink_corrections`).

Run: ``python benchmarks/study_expint.py [SCHEME ...]`` (about 8 minutes of one core), ``--shapes``: the
curve shapes' table (ETDRK4 on two runs, about 2 minutes), ``--crossings``: the frozen regions with the
crossings in closed form (about 10 minutes), ``--dop853``: the reference checked against SciPy's DOP853 on
one run (about 20 minutes).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.linalg

from rideid.data.scenario import default_scenario, run_times
from rideid.model import kernel_nl
from rideid.model import nonlinear as nl
from rideid.model.nonlinear import DEFAULT_KNOTS, NonlinearLayout, NonlinearSimulator
from rideid.model.params import ALL_NAMES, SUSPENSION_NAMES, as_vector
from rideid.model.simulate import prepare_run
from rideid.verify.hifi import hifi_curve

sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))

#: Gauss-Legendre nodes (two per panel) for the road's forcing over a step
PANELS = 32


def reference_slopes(Sk, xk):
    """Per candidate and axle the reference damper slope ``(n, 2)``: the mean of the two segments at zero."""
    j0 = int(np.flatnonzero(xk == 0.0)[0])
    return 0.5 * (Sk[:, :, j0 - 1] + Sk[:, :, j0])


def linear_parts(co, xk, Fk, Sk, c_ref):
    """``A`` (n, 14, 14) and ``Bt`` (n, 14, 4) of the linear car (shifted states), from the nonlinear right-hand
    side with linear dampers ``c_ref``, no bump stops, every tire loaded (small perturbations of rest)."""
    n = co.shape[0]
    cl = co.copy()
    for c in range(4):
        cl[:, nl.CI[f"cs{c}"]] = c_ref[:, c // 2]
        cl[:, nl.CI[f"bs_clear{c}"]] = np.inf
        cl[:, nl.CI[f"bs_rate{c}"]] = 0.0
    eps = 1e-5
    A = np.empty((n, 14, 14))
    Bt = np.empty((n, 14, 4))
    z4 = np.zeros(4)
    for j in range(14):
        X = np.zeros((n, 14))
        X[:, j] = eps
        A[:, :, j] = nl.accelerations(cl, xk, Fk, Sk, False, X, z4, z4)[0] / eps
    for c in range(4):
        u = np.zeros(4)
        u[c] = eps
        Bt[:, :, c] = nl.accelerations(cl, xk, Fk, Sk, False, np.zeros((n, 14)), u, z4)[0] / eps
    return A, Bt


def phis(A, tau, k=3):
    """``[e^{A tau}, phi_1, .., phi_k]`` of ``A tau`` (each (n, 14, 14)), from one augmented exponential."""
    n, s, _ = A.shape
    M = np.zeros((n, (k + 1) * s, (k + 1) * s))
    M[:, :s, :s] = A * tau
    for i in range(k):
        M[:, i * s:(i + 1) * s, (i + 1) * s:(i + 2) * s] = np.eye(s)
    E = scipy.linalg.expm(M)
    return [E[:, :s, i * s:(i + 1) * s] for i in range(k + 1)]


def forcing(A, Bt, run, a, b):
    """``int_a^b e^{A (b - s)} Bt u(t_k + s) ds`` for every interval ``k``: (n, n_int, 14)."""
    xg, wg = np.polynomial.legendre.leggauss(2)
    x = ((np.arange(PANELS)[:, None] + 0.5 * (xg[None, :] + 1.0)) / PANELS).ravel()
    w = np.repeat(wg[None, :] * 0.5 / PANELS, PANELS, 0).ravel()
    s = a + (b - a) * x
    Mq = np.stack([scipy.linalg.expm(A * (b - sq)) @ Bt * (wq * (b - a)) for sq, wq in zip(s, w)], 1)
    t0 = run.t[:-1]
    uq, _ = run.inputs_at((t0[:, None] + s[None, :]).ravel())
    uq = uq.reshape(t0.size, s.size, 4)
    return np.einsum("nqij,kqj->nki", Mq, uq)


def simulate_exp(P, geom, run, layout, scheme="etd2", m=1):
    """Channels (n, n_time, 10) by exponential integrator ``scheme`` at ``m`` steps per sample."""
    co, xk, Fk, Sk = nl.coefficients(P, geom, layout)
    curves = layout.knots is not None
    c_ref = reference_slopes(Sk, xk) if curves else co[:, [nl.CI["cs0"], nl.CI["cs2"]]]
    A, Bt = linear_parts(co, xk, Fk, Sk, c_ref)
    if m != 1:
        sub = run.h / m
        fine_t = run.t[0] + sub * np.arange(m * (run.n - 1) + 1)
        run_f = prepare_run_like(run, fine_t)
    else:
        run_f = run
    h = run_f.h
    E, p1, p2, p3 = phis(A, h)
    Eh, q1, _, _ = phis(A, h / 2)
    Ff = forcing(A, Bt, run_f, 0.0, h)
    Fa = forcing(A, Bt, run_f, 0.0, h / 2)
    Fb = forcing(A, Bt, run_f, h / 2, h)
    um, rm = run_f.inputs_at(run_f.t[:-1] + h / 2)
    U, R = run_f.u, run_f.rate
    mv = lambda M, x: np.einsum("nij,nj->ni", M, x)  # noqa: E731

    def resid(X, u, r):
        d, _ = nl.accelerations(co, xk, Fk, Sk, curves, X, u, r)
        return d - mv(A, X) - np.einsum("nij,j->ni", Bt, u)

    X = nl.shifted(co, nl.initial_state(P, geom, layout, run.u[0]), run.u[0])
    n = X.shape[0]
    y = np.empty((n, run.n, 10))
    f1 = p1 - 3 * p2 + 4 * p3
    f2 = p2 - 2 * p3
    f3 = -p2 + 4 * p3
    for k in range(run_f.n):
        if k % m == 0:
            _, qdd = nl.accelerations(co, xk, Fk, Sk, curves, X, U[k], R[k])
            y[:, k // m] = nl.channels(co, X, qdd)
        if k + 1 == run_f.n:
            break
        Nk = resid(X, U[k], R[k])
        lin = mv(E, X) + Ff[:, k]
        if scheme == "etd2":
            a = lin + h * mv(p1, Nk)
            X = a + h * mv(p2, resid(a, U[k + 1], R[k + 1]) - Nk)
        elif scheme == "etd4":
            half = mv(Eh, X) + Fa[:, k]
            a = half + (h / 2) * mv(q1, Nk)
            Na = resid(a, um[k], rm[k])
            b = half + (h / 2) * mv(q1, Na)
            Nb = resid(b, um[k], rm[k])
            c = mv(Eh, a) + Fb[:, k] + (h / 2) * mv(q1, 2 * Nb - Nk)
            Nc = resid(c, U[k + 1], R[k + 1])
            X = lin + h * (mv(f1, Nk) + 2 * mv(f2, Na + Nb) + mv(f3, Nc))
        elif scheme == "lawson4":
            # RK4 on v = e^{-A s} (X - linear forced response): stages carried to the step's end
            half = mv(Eh, X) + Fa[:, k]
            k1 = Nk
            x2 = half + (h / 2) * mv(Eh, k1)
            k2 = resid(x2, um[k], rm[k])
            x3 = half + (h / 2) * k2
            k3 = resid(x3, um[k], rm[k])
            x4 = lin + h * mv(Eh, k3)
            k4 = resid(x4, U[k + 1], R[k + 1])
            X = lin + (h / 6) * (mv(E, k1) + 2 * mv(Eh, k2 + k3) + k4)
        else:
            raise ValueError(scheme)
    return y


# ---------------------------------------------------------------------------
# the kinks' contributions in closed form (issue 52, item 4)
#
# Within a step every corner is held in the region it starts in (the damper on its segment's line, the bump
# stop on or off, the tire in contact or not): that car is affine, so the exponential scheme integrates it to
# its order. What it misses is, per crossing at time t_c of a switching quantity sigma (a damper velocity
# less a kink's knot, a deflection less the clearance, a tire load), the change of force
# ``vec * sigma(X(s))`` from t_c on. With delta = X_true - X_frozen, exactly
# ``delta' = (A_frozen + sum over crossings passed of vec grad^T) delta + sum 1[s > t_c] vec sigma_frozen(s)``,
# sigma_frozen the switching quantity along the frozen car (a cubic Hermite from the step's ends), so the
# correction is ``int e^{A' (h - s)} vec sigma_frozen(s) ds``: phi-functions of ``A' (h - t_c)`` applied to
# ``vec``, by their series (matrix-vector products, no matrix exponential per crossing).


def frozen_regions(co, xk, curves, X, r):
    """Each corner's curve segment ``j`` and bump stop ``on`` at a step's start (the tire's contact: the load of
    :func:`rideid.model.nonlinear.switching` at or above zero)."""
    d, v, _, _ = nl.switching(co, X, np.zeros((X.shape[0], 7)), r, np.zeros(4))
    j = np.clip(np.searchsorted(xk, v, side="right") - 1, 0, xk.size - 2) if curves else np.zeros(v.shape, int)
    return j, d > co[:, nl._C4["bs_clear"]]


def accelerations_frozen(co, xk, Fk, Sk, curves, X, r, rd, reg):
    """:func:`rideid.model.nonlinear.accelerations` (14 states) with every corner held in region ``reg``: the
    damper on its segment's line, the bump stop on or off, the tire in contact or not (straight continuations)."""
    j, on, contact = reg
    c = lambda name: co[:, nl._C4[name]]  # noqa: E731
    q = X[:, :7]
    ctm = c("ct") * c("inv_mu")
    w = X[:, 10:14] + ctm * r
    x, y = c("x"), c("y")
    d = nl.suspension_travel(q, x, y)
    v = w - nl.body_corners(X[:, 7:], x, y)
    F = c("ks") * d
    bf = co[:, nl.CI["kar_f"]] * (d[:, 0] - d[:, 1])
    br = co[:, nl.CI["kar_r"]] * (d[:, 2] - d[:, 3])
    F = F + np.stack([bf, -bf, br, -br], -1)
    if curves:
        ax = np.array([0, 0, 1, 1])
        rows = np.arange(v.shape[0])[:, None]
        F = F + Fk[rows, ax, j] + Sk[rows, ax, j] * (v - xk[j])
    else:
        F = F + c("cs") * v
    with np.errstate(invalid="ignore"):
        F = F + np.where(on, c("bs_rate") * (d - c("bs_clear")), 0.0)
    L = c("L")
    t0 = L + c("kt") * (r - q[:, 3:]) - c("ct") * w
    crd = c("ct") * rd
    dp = np.where(contact, t0 - L - F, -L - F - crd) * c("inv_mu")
    qdd = np.empty_like(q)
    qdd[:, 0] = F.sum(-1) * co[:, nl.CI["inv_ms"]]
    qdd[:, 1] = (-(x * F).sum(-1) + co[:, nl.CI["topple"]] * q[:, 1]) * co[:, nl.CI["inv_Iyy"]]
    qdd[:, 2] = ((y * F).sum(-1) + co[:, nl.CI["topple"]] * q[:, 2]) * co[:, nl.CI["inv_Ixx"]]
    qdd[:, 3:] = dp + ctm * rd
    return np.concatenate([X[:, 7:10], w, qdd[:, :3], dp], axis=1), qdd


def force_columns(co):
    """``(n, 14, 4)``: the state derivative per newton of suspension force at each corner, and ``(n, 14, 4)``
    per newton of tire force."""
    n = co.shape[0]
    c = lambda name: co[:, nl._C4[name]]  # noqa: E731
    BF = np.zeros((n, 14, 4))
    BF[:, 7, :] = co[:, [nl.CI["inv_ms"]]]
    BF[:, 8, :] = -c("x") * co[:, [nl.CI["inv_Iyy"]]]
    BF[:, 9, :] = c("y") * co[:, [nl.CI["inv_Ixx"]]]
    BT = np.zeros((n, 14, 4))
    for k in range(4):
        BF[:, 10 + k, k] = -c("inv_mu")[:, k]
        BT[:, 10 + k, k] = c("inv_mu")[:, k]
    return BF, BT


def switch_gradients(co, c):
    """d(damper velocity)/dX, d(deflection)/dX, d(tire load)/dX at corner ``c``: each (n, 14)."""
    n = co.shape[0]
    x, y = co[:, nl._C4["x"][c]], co[:, nl._C4["y"][c]]
    gv, gd, gg = np.zeros((n, 14)), np.zeros((n, 14)), np.zeros((n, 14))
    gv[:, 10 + c], gv[:, 7], gv[:, 8], gv[:, 9] = 1.0, -1.0, x, -y
    gd[:, 3 + c], gd[:, 0], gd[:, 1], gd[:, 2] = 1.0, -1.0, x, -y
    gg[:, 3 + c], gg[:, 10 + c] = -co[:, nl._C4["kt"][c]], -co[:, nl._C4["ct"][c]]
    return gv, gd, gg


def frozen_matrix(co, xk, Sk, curves, A, BF, BT, c_ref, reg):
    """``A_frozen`` (n, 14, 14): the reference car plus each corner's departure in its region (rank one each)."""
    j, on, contact = reg
    n = co.shape[0]
    Af = A.copy()
    for c in range(4):
        gv, gd, gg = switch_gradients(co, c)
        dS = (Sk[np.arange(n), c // 2, j[:, c]] if curves else co[:, nl._C4["cs"][c]]) - c_ref[:, c // 2]
        Af += (BF[:, :, c] * dS[:, None])[:, :, None] * gv[:, None, :]
        rate = np.where(on[:, c], co[:, nl._C4["bs_rate"][c]], 0.0)
        Af += (BF[:, :, c] * rate[:, None])[:, :, None] * gd[:, None, :]
        Af -= (BT[:, :, c] * np.where(contact[:, c], 0.0, 1.0)[:, None])[:, :, None] * gg[:, None, :]
    return Af


def ramp_response(A, vec, tau, s, terms=8):
    """``int_0^tau e^{A (tau - u)} vec sigma(u) du`` with ``sigma(u) = s0 + s1 u + s2 u^2 / 2 + s3 u^3 / 6``:
    ``sum_i tau^(i+1) phi_(i+1)(A tau) vec s_i`` (``A`` (14, 14), ``vec`` (14,), ``s`` four numbers), by the
    phi-functions' series."""
    out = np.zeros_like(vec)
    z = vec.copy()
    fact = np.array([1.0, 2.0, 6.0, 24.0])
    for i in range(terms):
        out += z * sum(tau ** (i + 1 + p) * s[p] / fact[p] for p in range(4))
        z = A @ z
        fact *= np.arange(i + 2, i + 6)
    return out


def hermite_taylor(theta, s0, s1, m0, m1, h):
    """Value and first three time derivatives at ``theta`` of the cubic Hermite over a step of ``h`` seconds."""
    t2 = theta * theta
    val = (2 * t2 * theta - 3 * t2 + 1) * s0 + (t2 * theta - 2 * t2 + theta) * m0 + (3 * t2 - 2 * t2 * theta) * s1 \
        + (t2 * theta - t2) * m1
    der = (6 * t2 - 6 * theta) * (s0 - s1) + (3 * t2 - 4 * theta + 1) * m0 + (3 * t2 - 2 * theta) * m1
    sec = (12 * theta - 6) * (s0 - s1) + (6 * theta - 4) * m0 + (6 * theta - 2) * m1
    third = 12 * (s0 - s1) + 6 * (m0 + m1)
    return val, der / h, sec / h ** 2, third / h ** 3


def tire_load_rate(co, X, qdd, r, rd, rdd):
    """The tire loads' rates ``k_t (r' - z') + c_t (r'' - z'')`` (n, 4), ``rdd`` the road's second derivative."""
    c = lambda name: co[:, nl._C4[name]]  # noqa: E731
    w = X[:, 10:14] + c("ct") * c("inv_mu") * r
    return c("kt") * (rd - w) + c("ct") * (rdd - qdd[:, 3:])


def crossing_events(co, xk, Sk, curves, h, sw0, sw1, kinks, sw_true=None, gslope=None):
    """Per row: the step's crossings ``(vec, grad, hermite, first guess of t_c)``: a switching quantity whose end
    (the frozen car's, ``sw1``; with ``sw_true`` the corrected end's) is on the other side of its start;
    ``hermite``: ``(s0, s1, m0, m1)`` of the quantity along the frozen car (a tire load's slopes ``gslope``,
    without them its chord)."""
    d0, v0, g0, a0 = sw0
    d1, v1, g1, a1 = sw1
    dt, vt, gt, _ = sw1 if sw_true is None else sw_true
    BF, BT = force_columns(co)
    per = {}

    def add(sel, vec, grad, s0, s1, m0, m1, st):
        rows = np.flatnonzero(sel)
        s0, s1, m0, m1, st = s0[rows], s1[rows], m0[rows], m1[rows], st[rows]
        with np.errstate(divide="ignore", invalid="ignore"):
            guess = np.where((s0 > 0) != (s1 > 0), nl.hermite_root(s0, s1, m0, m1), s0 / (s0 - st))
        for q, r in enumerate(rows):
            per.setdefault(int(r), []).append((vec[r], grad[r], (s0[q], s1[q], m0[q], m1[q]), guess[q] * h))

    for c in range(4):
        gv, gd, gg = switch_gradients(co, c)
        for k in range(1, xk.size - 1) if curves else ():
            if kinks is not None and not kinks[c // 2, k]:
                continue
            up = (v1[:, c] > xk[k]) if sw_true is None else (vt[:, c] > xk[k])
            sel = (v0[:, c] > xk[k]) != up
            dS = Sk[:, c // 2, k] - Sk[:, c // 2, k - 1]
            coef = np.where(up, dS, -dS)
            add(sel, BF[:, :, c] * coef[:, None], gv, v0[:, c] - xk[k], v1[:, c] - xk[k], h * a0[:, c],
                h * a1[:, c], vt[:, c] - xk[k])
        cl = co[:, nl._C4["bs_clear"][c]]
        with np.errstate(invalid="ignore"):
            e0, e1, et = d0[:, c] - cl, d1[:, c] - cl, dt[:, c] - cl
        on = (e1 > 0.0) if sw_true is None else (et > 0.0)
        coef = np.where(on, 1.0, -1.0) * co[:, nl._C4["bs_rate"][c]]
        add((e0 > 0.0) != on, BF[:, :, c] * coef[:, None], gd, e0, e1, h * v0[:, c], h * v1[:, c], et)
        # contact -> off: the tire's force g leaves (-g); off -> contact: it comes back; the load's chord
        contact = (g1[:, c] >= 0.0) if sw_true is None else (gt[:, c] >= 0.0)
        chord = g1[:, c] - g0[:, c]
        gm0, gm1 = (chord, chord) if gslope is None else (h * gslope[0][:, c], h * gslope[1][:, c])
        add((g0[:, c] >= 0.0) != contact, BT[:, :, c] * np.where(contact, 1.0, -1.0)[:, None], gg, g0[:, c],
            g1[:, c], gm0, gm1, gt[:, c])
    for evs in per.values():
        evs.sort(key=lambda e: e[3])
    return per


def expv(A, tau, x, terms=10):
    """``e^{A tau} x`` by its series."""
    out = x.copy()
    z = x.copy()
    for i in range(1, terms):
        z = (tau / i) * (A @ z)
        out += z
    return out


def kink_corrections(Af, h, per):
    """What the step with every region frozen at its start misses, ``(n, 14)``: ``delta = X_true - X_frozen``
    carried from crossing to crossing, ``delta' = (A_frozen + sum_passed vec grad^T) delta + sum_passed vec
    sigma(s)`` (each source the switching quantity along the frozen car), by series of the phi-functions. A
    crossing's time is the root of its switching quantity along the true car, ``sigma_frozen + grad . delta``
    (Newton steps kept in the step)."""
    corr = np.zeros((Af.shape[0], 14))
    for r, evs in per.items():
        A_now = Af[r].copy()
        t_now, delta = 0.0, np.zeros(14)
        active = []  # (vec, hermite)

        def advance(t, A_now, t_now, delta, active):
            tau = t - t_now
            out = expv(A_now, tau, delta)
            for v2, herm2 in active:
                out = out + ramp_response(A_now, v2, tau, hermite_taylor(t_now / h, *herm2, h))
            return out

        for vec, grad, herm, t in evs:
            t = max(t, t_now)
            for _ in range(4):
                f0, f1, _, _ = hermite_taylor(t / h, *herm, h)
                d = advance(t, A_now, t_now, delta, active)
                dd = A_now @ d + sum((v2 * hermite_taylor(t / h, *h2, h)[0] for v2, h2 in active), np.zeros(14))
                val, der = f0 + grad @ d, f1 + grad @ dd
                if der != 0.0:
                    t = min(max(t - val / der, t_now), h)
            delta = advance(t, A_now, t_now, delta, active)
            t_now = t
            A_now = A_now + np.outer(vec, grad)
            active.append((vec, herm))
        corr[r] = advance(h, A_now, t_now, delta, active)
    return corr


def simulate_expk(P, geom, run, layout, m=1, kinks=None, passes=0, scheme="etd4"):
    """Channels (n, n_time, 10) by ETDRK4 (Cox-Matthews; ``scheme="etd2"``: ETD2RK) at ``m`` steps per sample
    with every corner's region frozen at the step's start, plus :func:`kink_corrections`; then ``passes``
    passes that find the crossings again on the corrected end (the true car's: after a first crossing the
    frozen car's may differ)."""
    co, xk, Fk, Sk = nl.coefficients(P, geom, layout)
    curves = layout.knots is not None
    kinks = nl.kink_mask(Sk) if kinks is None else kinks
    c_ref = reference_slopes(Sk, xk) if curves else co[:, [nl.CI["cs0"], nl.CI["cs2"]]]
    A, Bt = linear_parts(co, xk, Fk, Sk, c_ref)
    BF, BT = force_columns(co)
    run_f = run if m == 1 else prepare_run_like(run, run.t[0] + (run.h / m) * np.arange(m * (run.n - 1) + 1))
    h = run_f.h
    E, p1, p2, p3 = phis(A, h)
    Eh, q1, _, _ = phis(A, h / 2)
    Ff = forcing(A, Bt, run_f, 0.0, h)
    Fa = forcing(A, Bt, run_f, 0.0, h / 2)
    Fb = forcing(A, Bt, run_f, h / 2, h)
    um, rm = run_f.inputs_at(run_f.t[:-1] + h / 2)
    U, R = run_f.u, run_f.rate
    mv = lambda M, x: np.einsum("nij,nj->ni", M, x)  # noqa: E731

    def resid(X, u, r, reg):
        return accelerations_frozen(co, xk, Fk, Sk, curves, X, u, r, reg)[0] - mv(A, X) \
            - np.einsum("nij,j->ni", Bt, u)

    X = nl.shifted(co, nl.initial_state(P, geom, layout, run.u[0]), run.u[0])
    y = np.empty((X.shape[0], run.n, 10))
    f1, f2, f3 = p1 - 3 * p2 + 4 * p3, p2 - 2 * p3, -p2 + 4 * p3
    _, qdd = nl.accelerations(co, xk, Fk, Sk, curves, X, U[0], R[0])
    sw = nl.switching(co, X, qdd, U[0], R[0])
    for k in range(run_f.n):
        if k % m == 0:
            y[:, k // m] = nl.channels(co, X, qdd)
        if k + 1 == run_f.n:
            break
        # the regions at the step's start, as nonlinear.accelerations decides them
        j, on = frozen_regions(co, xk, curves, X, U[k])
        reg = (j, on, sw[2] >= 0.0)
        Nk = resid(X, U[k], R[k], reg)
        if scheme == "etd2":
            a = mv(E, X) + Ff[:, k] + h * mv(p1, Nk)
            Xn = a + h * mv(p2, resid(a, U[k + 1], R[k + 1], reg) - Nk)
        else:
            half = mv(Eh, X) + Fa[:, k]
            a = half + (h / 2) * mv(q1, Nk)
            Na = resid(a, um[k], rm[k], reg)
            b = half + (h / 2) * mv(q1, Na)
            Nb = resid(b, um[k], rm[k], reg)
            c = mv(Eh, a) + Fb[:, k] + (h / 2) * mv(q1, 2 * Nb - Nk)
            Nc = resid(c, U[k + 1], R[k + 1], reg)
            Xn = mv(E, X) + Ff[:, k] + h * (mv(f1, Nk) + 2 * mv(f2, Na + Nb) + mv(f3, Nc))
        # the frozen car's switching quantities at the step's end, their rates on the frozen side too
        _, qf = accelerations_frozen(co, xk, Fk, Sk, curves, Xn, U[k + 1], R[k + 1], reg)
        sw1 = nl.switching(co, Xn, qf, U[k + 1], R[k + 1])
        # the tire loads' rates (the road's second derivative: its rate's chord over the step)
        rdd = (R[k + 1] - R[k]) / h
        gslope = (tire_load_rate(co, X, qdd, U[k], R[k], rdd), tire_load_rate(co, Xn, qf, U[k + 1], R[k + 1], rdd))
        per = crossing_events(co, xk, Sk, curves, h, sw, sw1, kinks, gslope=gslope)
        if per:
            Af = frozen_matrix(co, xk, Sk, curves, A, BF, BT, c_ref, reg)
            Xf = Xn
            Xn = Xf + kink_corrections(Af, h, per)
            for _ in range(passes):
                _, qdd = nl.accelerations(co, xk, Fk, Sk, curves, Xn, U[k + 1], R[k + 1])
                per = crossing_events(co, xk, Sk, curves, h, sw, sw1, kinks,
                                      nl.switching(co, Xn, qdd, U[k + 1], R[k + 1]), gslope)
                Xn = Xf + kink_corrections(Af, h, per)
        _, qdd = nl.accelerations(co, xk, Fk, Sk, curves, Xn, U[k + 1], R[k + 1])
        X, sw = Xn, nl.switching(co, Xn, qdd, U[k + 1], R[k + 1])
    return y


def prepare_run_like(run, t):
    """``run`` at finer sample times ``t`` (the same road model)."""
    u, r = run.inputs_at(t)
    return type("R", (), dict(t=t, h=t[1] - t[0], u=u, rate=r, inputs_at=staticmethod(run.inputs_at),
                              n=t.size))()


def reference(P, geom, run, layout, sim):
    m = sim.substeps(P)[0]
    co, xk, Fk, Sk = nl.coefficients(P, geom, layout)
    X0 = nl.shifted(co, nl.initial_state(P, geom, layout, run.u[0]), run.u[0])[None]
    _, out, _ = kernel_nl.run(co, xk, Fk, Sk, layout.knots is not None, X0, np.array([0, run.n]), [run.h],
                              np.array([64 * m]), [nl.fine_inputs(run, 64 * m)], np.zeros((run.n, 10)),
                              np.zeros((1, 10)), 1, kinks=sim.kinks(P))
    return out, m


def rel_rms(y, ref):
    rms = np.sqrt(np.mean(ref ** 2, axis=-2))
    err = np.sqrt(np.mean((y - ref) ** 2, axis=-2))
    ok = rms > 1e-9 * rms.max()
    return np.where(ok, err / np.where(ok, rms, 1), 0.0).max(axis=-1)


def cases():
    import tempfile
    from cars import write_profile_road
    import test_nonlinear as tn

    d = Path(tempfile.mkdtemp())
    write_profile_road(d, 0.03, 0.012)
    P = tn.nasty_row()[None]
    for kind in ("washboard", "herringbone", "chassis_twist", "profile"):
        yield f"severe {kind}", P, tn.GH, tn.make_run(kind, d), tn.FULL
    sc = default_scenario()
    P16 = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)[:len(SUSPENSION_NAMES)]
    rng = np.random.default_rng(1)
    Pb = P16 * rng.uniform(0.95, 1.05, (4, P16.size))
    Ff = np.stack([hifi_curve(c, DEFAULT_KNOTS, 2.0, 0.1, 0.4) for c in Pb[:, 8]])
    Fr = np.stack([hifi_curve(c, DEFAULT_KNOTS, 2.0, 0.1, 0.4) for c in Pb[:, 9]])
    Pn = np.concatenate([Pb, Ff, Fr], axis=1)
    for r in sc.runs:
        run = prepare_run(sc.tracks[r.track], sc.geometry, r.speed, run_times(r))
        yield f"built-in {r.track} {r.speed:g} m/s", Pn, sc.geometry, run, NonlinearLayout(knots=DEFAULT_KNOTS)


def shapes():
    """What limits the exponential schemes: ETDRK4 on two built-in runs with other curve shapes (rebound ratio,
    slope above the 0.1 m/s knee): a linear curve leaves only the lift-off residual."""
    cs = list(cases())
    print("| case | rebound ratio | slope above knee | RK4 split | etd4 m=1 | etd4 m=2 |")
    for name, P, geom, run, layout in (cs[4], cs[11]):
        for ratio, above in ((2.0, 0.4), (1.0, 0.4), (2.0, 1.0), (1.0, 1.0)):
            Pn = np.concatenate([P[:, :16]] + [np.stack([hifi_curve(c, DEFAULT_KNOTS, ratio, 0.1, above)
                                                         for c in P[:, col]]) for col in (8, 9)], 1)
            sim = NonlinearSimulator(geom, [run], layout)
            ref, _ = reference(Pn, geom, run, layout, sim)
            errs = [rel_rms(sim.outputs(Pn)[0], ref).max()] + \
                [rel_rms(simulate_exp(Pn, geom, run, layout, "etd4", m=m), ref).max() for m in (1, 2)]
            print(f"| {name} | {ratio:g} | {above:g} | " + " | ".join(f"{e:.1e}" for e in errs) + " |", flush=True)


def crossings_table():
    """The frozen regions with the crossings in closed form (:func:`simulate_expk`) against the present scheme
    and unsplit ETDRK4, on every case."""
    print("| case | RK4 split (m) | etd4 m=1 | frozen + crossings m=1 | m=2 | ETD2RK frozen + crossings m=1 |")
    for name, P, geom, run, layout in cases():
        sim = NonlinearSimulator(geom, [run], layout)
        ref, m0 = reference(P, geom, run, layout, sim)
        errs = [rel_rms(sim.outputs(P)[0], ref).max(), rel_rms(simulate_exp(P, geom, run, layout, "etd4"), ref).max()]
        errs += [rel_rms(simulate_expk(P, geom, run, layout, m=m, kinks=sim.kinks(P)), ref).max() for m in (1, 2)]
        errs.append(rel_rms(simulate_expk(P, geom, run, layout, kinks=sim.kinks(P), scheme="etd2"), ref).max())
        print(f"| {name} | {errs[0]:.1e} ({m0}) | " + " | ".join(f"{e:.1e}" for e in errs[1:]) + " |", flush=True)


def dop853_check(case=4):
    """The yardstick checked: SciPy's DOP853 (rtol 1e-10, steps at most a sample) on the same equations, one car,
    one run (built-in twist_low 3 m/s: about 20 minutes of one core), against the reference, the present
    scheme and :func:`simulate_expk`."""
    from scipy.integrate import solve_ivp

    name, P, geom, run, layout = list(cases())[case]
    P = P[:1]
    sim = NonlinearSimulator(geom, [run], layout)
    ref, _ = reference(P, geom, run, layout, sim)
    co, xk, Fk, Sk = nl.coefficients(P, geom, layout)
    curves = layout.knots is not None
    X0 = nl.shifted(co, nl.initial_state(P, geom, layout, run.u[0]), run.u[0])[0]

    def rhs(t, X):
        u, ud = run.inputs_at(np.array([t]))
        return nl.accelerations(co, xk, Fk, Sk, curves, X[None], u[0], ud[0])[0][0]

    sol = solve_ivp(rhs, (run.t[0], run.t[-1]), X0, method="DOP853", t_eval=run.t, rtol=1e-10, atol=1e-13,
                    max_step=run.h)
    y = np.empty((1, run.n, 10))
    for k, X in enumerate(sol.y.T):
        _, qdd = nl.accelerations(co, xk, Fk, Sk, curves, X[None], run.u[k], run.rate[k])
        y[0, k] = nl.channels(co, X[None], qdd)[0]
    yk = simulate_expk(P, geom, run, layout, kinks=sim.kinks(P))
    print(f"{name}: DOP853 ({sol.nfev} evaluations) against the reference {rel_rms(ref, y).max():.1e}, the present "
          f"scheme {rel_rms(sim.outputs(P)[0], y).max():.1e}, frozen + crossings m=1 {rel_rms(yk, y).max():.1e}")


def main():
    if "--shapes" in sys.argv[1:]:
        return shapes()
    if "--dop853" in sys.argv[1:]:
        return dop853_check()
    if "--crossings" in sys.argv[1:]:
        return crossings_table()
    schemes = [a for a in sys.argv[1:] if not a.startswith("--")] or ["etd2", "etd4", "lawson4"]
    ms = (1, 2)
    print("| case | RK4 split (m) | " + " | ".join(f"{s} m={m}" for s in schemes for m in ms) + " |")
    for name, P, geom, run, layout in cases():
        sim = NonlinearSimulator(geom, [run], layout)
        ref, m0 = reference(P, geom, run, layout, sim)
        base = rel_rms(sim.outputs(P)[0], ref).max()
        errs = [rel_rms(simulate_exp(P, geom, run, layout, s, m=m), ref).max() for s in schemes for m in ms]
        print(f"| {name} | {base:.1e} ({m0}) | " + " | ".join(f"{e:.1e}" for e in errs) + " |", flush=True)


if __name__ == "__main__":
    main()
