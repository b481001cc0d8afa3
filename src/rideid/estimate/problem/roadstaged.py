"""Identification on roads nobody measured, method 2: a time-domain staged fit.

An independent alternative to :mod:`rideid.estimate.problem.roadfit` (frequency-domain
variable projection, the default), compared with it in docs/road-methods.md.
The linear base car of SPEC §1 (twelve parameters, CG height 0, no anti-roll
bars, no tire damping); all ten channels are needed. The road itself is never
estimated.

Stage 1: the body from the axles
--------------------------------
The body (``q = [z, theta, phi]``) is driven only through the four suspensions,
by the wheel motions ``z_i``::

    M_b q'' + C_b q' + K_b q = K_u z + C_u z',
    M_b = diag(m_s, I_yy, I_xx),  K_b = sum_i k_i G_i^T G_i,  K_u = [k_i G_i^T]_i,

``G_i = [1, -x_i, y_i]`` (body corner ``i`` moves by ``G_i q``; ``C_b``, ``C_u``
likewise with ``c_i``). The system is linear and time-invariant, so its
response to ``z_i''`` is the second derivative of its response to ``z_i``: fed
with the *measured axle accelerations* as if they were wheel displacements,
its "displacements" ``q~`` are the body's accelerations, ``G_i q~`` the body
accelerometers' readings and ``q~_2``, ``q~_3`` the derivatives of the gyros'
readings. No measured signal is integrated, nothing drifts. (The gyros are
compared by differentiating them, not by integrating ``q~``: the integral of
the response to the axles' noise wanders like a random walk; with a 0.1 Hz
high-pass on both sides its residual was still 7-18 % of the gyro RMS.)

Dividing by ``m_s`` leaves seven identifiable numbers, :data:`STAGE1`:
``k_sf/m_s``, ``k_sr/m_s``, ``c_sf/m_s``, ``c_sr/m_s``, ``I_xx/m_s``,
``I_yy/m_s`` and ``a``, fitted by output-error least squares over their logs.
The state at the first fitted sample is unknown (the car is moving): its six
components enter the prediction linearly and are projected out at every trial
(variable projection); :data:`EDGE_SECONDS` at each end are left out for the
filters' edges. The input is sampled: the first-order hold (linear
interpolation between samples) attenuates it by ``sinc^2(f h)``, which the
3-tap filter :data:`HOLD_FIX` undoes to ``O((omega h)^4)``. Body and gyro
channels and the input pass through one Gaussian low-pass (:data:`LOWPASS_HZ`,
it commutes with the body model).

Stage 2: tires and unsprung masses from the front/rear wheel-path consistency
-----------------------------------------------------------------------------
Each wheel: ``m_u z_u'' + F = k_t (r - z_u)``, suspension force
``F = k_s (z_u - z_b) + c_s (z_u' - z_b')``. Differentiated twice and divided
by ``k_t``, in measured accelerations only (``a_u`` axle, ``a_b`` body corner,
``d = a_u - a_b``)::

    r'' = a_u + alpha a_u'' + beta (d + eta d'),
    alpha = m_u / k_t,  beta = k_s / k_t,  eta = c_s / k_s (from stage 1).

The rear wheel rolls over the front wheel's path ``tau = wheelbase / speed``
later: per side ``r''_rear(t) - r''_front(t - tau) = 0``, linear in
:data:`STAGE2` ``= (alpha_f, beta_f, alpha_r, beta_r)``. Every signal passes
through one zero-phase Gaussian low-pass ``L`` (it commutes with the linear
relation); ``L``, ``L d/dt``, ``L d^2/dt^2`` and the fractional delay are one
sampled kernel each (the Gaussian and its derivatives at the shifted tap
times), exact to ``1e-8`` for content below the Nyquist frequency
(:func:`gauss_filter`) as long as the Gaussian spans a few samples.

Ordinary least squares of this consistency is biased (at 2 % noise, measured:
``alpha``, ``beta`` by -2 and -4 % with the 15 Hz low-pass, -16 and -19 % with
25 Hz): the regressors are measured, and ``alpha`` multiplies a second
derivative of a noisy signal. With the sensors'
relative white-noise levels the noise covariance ``Sigma`` of each
consistency row is known up to one factor, ``E[Z^T Z] = S_signal + m Sigma``,
and the Koopmans (errors-in-variables) criterion
``sum_groups c' S c / c' Sigma c`` (:func:`stage2_cost`) has its expectation's
minimum at the true car. Stage 1 uses the same device: each channel's residual
is divided by its predicted noise level (own noise plus the four axle
channels' noise through the body model, :func:`stage1_noise`), which removes
the smaller bias of stage 1's noisy input. The relative noise levels default
to proportional to each channel's RMS (rideid's ``--noise`` convention); give
the sensors' own when they are known (``noise=`` of :func:`prepare_staged_run`).

Scale: ``k_t/m_s = (k_s/m_s) / beta``, ``m_u/m_s = alpha k_t/m_s``; the known
total mass ``m_s (1 + 2 m_uf/m_s + 2 m_ur/m_s)`` fixes ``m_s`` and with it the
rest.

Why the tires are identifiable without the road: with four independent
corner roads any ``alpha``, ``beta`` would do (each corner's road is whatever
its own equation says). The delay ties rear to front; wrong values make the
front- and rear-inferred road accelerations disagree.

Uncertainty
-----------
Both stages are M-estimators. Their estimating equations are stacked
(``psi_1 = J_1^T r_1``; ``psi_2`` the gradient of the Koopmans criterion,
which depends on stage 1 through ``eta``) and the joint sandwich
``A^-1 B A^-T`` is taken, ``A = [[J_1^T J_1, 0], [d psi_2/d theta_1,
d psi_2/d theta_2]]`` (the lower blocks by central differences) and ``B`` the
Bartlett long-run covariance of the per-sample stacked scores per run
(Andrews' bandwidth, :mod:`rideid.estimate.problem.scores`). So stage 1's
uncertainty propagates into stage 2 (through ``eta`` and the scale mapping),
and the correlation of the two stages' scores (same sensors, front/rear
delay) is included. The twelve values' standard errors follow by the delta
method; :attr:`StagedResult.std_stage2_alone` is what stage 2's sandwich
alone would claim (stage 1 taken as exact), for comparison.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal

from ...model.params import INDEX, NAMES, Geometry
from .scores import andrews_bandwidth, long_run_covariance

#: Half-amplitude frequency (Hz) of the Gaussian low-pass of stage 1 (body) and stage 2 (wheels).
#: Chosen by a sweep on class-B roads at 2 % noise (docs/road-methods.md): stage 1 gains up to
#: ~40 Hz and picks up the hold's error above; stage 2 is best at 15-20 Hz (below, the wheel hop's
#: information is lost; above ~35 Hz the Gaussian spans too few samples to differentiate exactly)
LOWPASS_HZ = (30.0, 15.0)
#: Samples left out at each end of a run (filter edges), s
EDGE_SECONDS = 0.25

#: stage-1 parameters (log): ratios to m_s, and a
STAGE1 = ("k_sf", "k_sr", "c_sf", "c_sr", "I_xx", "I_yy", "a")
#: stage-2 parameters (linear)
STAGE2 = ("alpha_f", "beta_f", "alpha_r", "beta_r")

BODY = slice(0, 4)
AXLE = slice(4, 8)
GYRO = slice(8, 10)


# ---------------------------------------------------------------- filters

def gaussian_sigma(f_half: float) -> float:
    """Standard deviation (s) of the Gaussian kernel whose gain is 1/2 at ``f_half`` (Hz)."""
    return np.sqrt(2 * np.log(2)) / (2 * np.pi * f_half)


def gauss_filter(x, h: float, sigma: float, deriv: int = 0, delay: float = 0.0):
    """``(L d^m/dt^m x)(t_j - delay)`` at the samples ``t_j = j h``, for ``x`` (n,) or (n, k).

    ``L`` is the unit-area Gaussian of standard deviation ``sigma``; the result is
    ``h sum_k l^(m)(t_j - delay - t_k) x_k``. Samples whose kernel reaches past the record
    are NaN.
    """
    x = np.asarray(x, dtype=float)
    one = x.ndim == 1
    x2 = x[:, None] if one else x
    n = x2.shape[0]
    if deriv not in (0, 1, 2):
        raise ValueError("deriv must be 0, 1 or 2")
    p = int(np.floor(delay / h))
    K = int(np.ceil(6 * sigma / h)) + 1
    c = gauss_taps(h, sigma, deriv, delay)
    out = np.full(x2.shape, np.nan)
    # out[j] = sum_i c[i] x[j - p - i] for i in [-K, K+1]; valid for p + K + 1 <= j <= n - 1 + p - K
    lo, hi = max(0, p + K + 1), min(n, n + p - K)
    if hi > lo:
        for col in range(x2.shape[1]):
            full = np.convolve(x2[:, col], c)           # full[m] = sum_idx c[idx] x[m - idx], idx = i + K
            out[lo:hi, col] = full[lo - p + K:hi - p + K]
    return out[:, 0] if one else out


def gauss_taps(h: float, sigma: float, deriv: int = 0, delay: float = 0.0):
    """The taps of :func:`gauss_filter` (their squares sum to the white-noise gain)."""
    frac = delay / h - np.floor(delay / h)
    K = int(np.ceil(6 * sigma / h)) + 1
    t = (np.arange(-K, K + 2) - frac) * h
    g = np.exp(-0.5 * (t / sigma) ** 2) / (np.sqrt(2 * np.pi) * sigma)
    return h * [g, -t / sigma ** 2 * g, (t ** 2 / sigma ** 4 - 1 / sigma ** 2) * g][deriv]


#: first-order-hold correction filter (module docstring)
HOLD_FIX = np.array([-1.0, 14.0, -1.0]) / 12.0


# ---------------------------------------------------------------- runs

@dataclass
class StagedRun:
    """One unknown-road run prepared for the staged fit (all ten channels needed)."""

    run_id: str
    fs: float
    speed: float
    tau: float
    y: np.ndarray          # (n, 10) measured, mean removed
    noise: np.ndarray      # (10,) relative noise standard deviation of each channel
    meas1: np.ndarray      # (n, 6) stage-1 outputs: low-passed body accelerations, low-passed gyro derivatives
    u1: np.ndarray         # (n, 4) stage-1 input: low-passed axle accelerations, hold-corrected
    k0: int                # first and last+1 fitted sample of stage 1
    k1: int
    sigma1: float          # stage-1 Gaussian (s)

    @property
    def h(self) -> float:
        return 1.0 / self.fs

    @property
    def n(self) -> int:
        return self.y.shape[0]


def prepare_staged_run(run_id: str, y, fs: float, speed: float, geom: Geometry, noise=None,
                       lowpass_hz: float = LOWPASS_HZ[0]) -> StagedRun:
    """Prepare a run (``y`` (n, 10), all channels). ``noise``: the channels' relative white-noise
    standard deviations (only their ratios matter); default proportional to each channel's RMS."""
    y = np.asarray(y, dtype=float)
    if y.ndim != 2 or y.shape[1] != 10 or not np.isfinite(y).all():
        raise ValueError(f"{run_id}: the staged method needs all ten channels, finite")
    y = y - y.mean(axis=0)
    noise = np.sqrt(np.mean(y ** 2, axis=0)) if noise is None else np.asarray(noise, dtype=float)
    h = 1.0 / fs
    sig = gaussian_sigma(lowpass_hz)
    meas = np.concatenate([gauss_filter(y[:, BODY], h, sig), gauss_filter(y[:, GYRO], h, sig, 1)], axis=1)
    u = gauss_filter(y[:, AXLE], h, sig)
    u[1:-1] = HOLD_FIX[0] * u[:-2] + HOLD_FIX[1] * u[1:-1] + HOLD_FIX[2] * u[2:]
    ok = np.nonzero(np.isfinite(meas).all(axis=1) & np.isfinite(u).all(axis=1))[0]
    edge = int(np.ceil(EDGE_SECONDS * fs))
    return StagedRun(run_id=run_id, fs=float(fs), speed=float(speed), tau=geom.wheelbase / float(speed),
                     y=y, noise=noise, meas1=meas, u1=u, k0=int(ok[0]) + 1 + edge, k1=int(ok[-1]) - edge,
                     sigma1=sig)


# ---------------------------------------------------------------- stage 1

def body_system(theta1, geom: Geometry):
    """Continuous body model per unit ``m_s`` (A, B, C): input the four axle signals, states
    ``[q, q' - M^-1 C_u u]``, outputs the four body corners and pitch and roll."""
    kf, kr, cf, cr, ixx, iyy, a = theta1
    x, y = geom.corner_xy(np.array([a]))
    G = np.stack([np.ones(4), -x[0], y[0]], axis=1)                  # (4, 3)
    k = np.array([kf, kf, kr, kr])
    c = np.array([cf, cf, cr, cr])
    Mi = np.diag(1.0 / np.array([1.0, iyy, ixx]))
    Kb, Cb = G.T @ (k[:, None] * G), G.T @ (c[:, None] * G)
    Ku, Cu = G.T * k[None], G.T * c[None]                              # (3, 4)
    A = np.zeros((6, 6))
    A[0:3, 3:6] = np.eye(3)
    A[3:6, 0:3] = -Mi @ Kb
    A[3:6, 3:6] = -Mi @ Cb
    B = np.zeros((6, 4))
    B[0:3] = Mi @ Cu
    B[3:6] = Mi @ Ku - Mi @ Cb @ Mi @ Cu
    C = np.zeros((6, 6))
    C[0:4, 0:3] = G
    C[4, 1] = C[5, 2] = 1.0
    return A, B, C


def _discrete_modal(theta1, geom, h):
    A, B, C = body_system(theta1, geom)
    Ad, Bd, Cd, Dd, _ = scipy.signal.cont2discrete((A, B, C, np.zeros((6, 4))), h, method="foh")
    lam, V = np.linalg.eig(Ad)
    Vi = np.linalg.inv(V)
    return lam, Vi @ Bd, Cd @ V, Vi, Dd


def _forced(lam, ViB, CV, Dd, u):
    g = u @ ViB.T                                                     # (n, 6) complex
    w = np.empty_like(g)
    for j in range(lam.size):
        w[:, j] = scipy.signal.lfilter([0.0, 1.0], [1.0, -lam[j]], g[:, j])
    return (w @ CV.T).real + u @ Dd.T


def simulate_body(theta1, geom: Geometry, u, h: float):
    """Forced response (n, 6) from zero state, and the free-response columns (n, 6, 6), of the
    first-order-hold discretisation of :func:`body_system` driven by ``u`` (n, 4)."""
    lam, ViB, CV, Vi, Dd = _discrete_modal(theta1, geom, h)
    y = _forced(lam, ViB, CV, Dd, u)
    pw = np.exp(np.outer(np.arange(u.shape[0]), np.log(lam.astype(complex))))
    free = np.einsum("ym,km,mx->kyx", CV, pw, Vi).real
    return y, free


def stage1_noise(theta1, geom: Geometry, rr: StagedRun, seconds: float = 6.0):
    """Relative noise variance (6,) of each stage-1 residual channel at ``theta1``: the output's
    own noise (low-passed) plus the four axle channels' noise seen through the body model."""
    h, sig = rr.h, rr.sigma1
    v = np.empty(6)
    v[:4] = rr.noise[BODY] ** 2 * np.sum(gauss_taps(h, sig) ** 2)
    v[4:] = rr.noise[GYRO] ** 2 * np.sum(gauss_taps(h, sig, 1) ** 2)
    pulse = np.convolve(gauss_taps(h, sig), HOLD_FIX)
    lam, ViB, CV, Vi, Dd = _discrete_modal(theta1, geom, h)
    n = pulse.size + int(seconds * rr.fs)
    for i in range(4):
        u = np.zeros((n, 4))
        u[:pulse.size, i] = pulse
        v += rr.noise[4 + i] ** 2 * np.sum(_forced(lam, ViB, CV, Dd, u) ** 2, axis=0)
    return v


def stage1_residual(ltheta1, geom: Geometry, runs, out=None):
    """Stage-1 residual (stacked over runs, samples, channels), each channel divided by its
    predicted noise standard deviation at ``theta1``, the initial state projected out."""
    theta1 = np.exp(ltheta1)
    res = []
    for rr in runs:
        sl = slice(rr.k0, rr.k1)
        ysim, free = simulate_body(theta1, geom, rr.u1[sl], rr.h)
        wgt = 1.0 / np.sqrt(stage1_noise(theta1, geom, rr))
        e = (rr.meas1[sl] - ysim) * wgt
        Fm = (free * wgt[None, :, None]).reshape(-1, 6)
        x0 = np.linalg.lstsq(Fm, e.ravel(), rcond=1e-12)[0]
        r = (e.ravel() - Fm @ x0).reshape(e.shape)
        res.append(r.ravel())
        if out is not None:
            out.append((rr, r.shape))
    return np.concatenate(res)


# ---------------------------------------------------------------- stage 2

@dataclass
class Stage2Group:
    """The consistency of one run and side: ``e_t = Z_t c``, ``Z`` (m, 8) the filtered signals
    ``[L a_r, L'' a_r, L d_r, L' d_r, same for the front delayed by tau]``; ``Sigma`` (8, 8) their
    relative noise covariance per sample."""

    Z: np.ndarray
    S: np.ndarray
    Sigma: np.ndarray
    t: np.ndarray          # (m,) sample index (rear time)
    run: int


def stage2_groups(rr: StagedRun, run_index: int, lowpass_hz: float = LOWPASS_HZ[1]):
    """The two sides' consistency groups (:class:`Stage2Group`) of run ``rr``."""
    h, sig, tau = rr.h, gaussian_sigma(lowpass_hz), rr.tau
    a_u = rr.y[:, AXLE]
    d = a_u - rr.y[:, BODY]
    out = []
    for cf, cr in ((0, 2), (1, 3)):
        cols, sigma = [], np.zeros((8, 8))
        for blk, (c, dl) in enumerate(((cr, 0.0), (cf, tau))):
            cols += [gauss_filter(a_u[:, c], h, sig, 0, dl), gauss_filter(a_u[:, c], h, sig, 2, dl),
                     gauss_filter(d[:, c], h, sig, 0, dl), gauss_filter(d[:, c], h, sig, 1, dl)]
            taps = np.stack([gauss_taps(h, sig, m, dl) for m in range(3)])
            gram = taps @ taps.T
            # kernel coefficients (on l, l', l'') of the block's four columns, axle and body noise
            Qa = np.array([[1, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=float)
            Qb = -np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
            sb = slice(4 * blk, 4 * blk + 4)
            sigma[sb, sb] = rr.noise[4 + c] ** 2 * Qa @ gram @ Qa.T + rr.noise[c] ** 2 * Qb @ gram @ Qb.T
        Z = np.stack(cols, axis=1)
        idx = np.nonzero(np.isfinite(Z).all(axis=1))[0]
        e = int(np.ceil(EDGE_SECONDS * rr.fs))
        idx = idx[e:idx.size - e]
        Z = Z[idx]
        out.append(Stage2Group(Z=Z, S=Z.T @ Z, Sigma=sigma, t=idx, run=run_index))
    return out


def stage2_coef(theta2, eta):
    """Coefficients ``c`` (8,) of the consistency ``r''_rear - r''_front(t - tau)`` and ``dc/dtheta2`` (8, 4)."""
    af, bf, ar, br = theta2
    c = np.array([1.0, ar, br, br * eta[1], -1.0, -af, -bf, -bf * eta[0]])
    dc = np.zeros((8, 4))
    dc[5, 0] = -1.0
    dc[6, 1], dc[7, 1] = -1.0, -eta[0]
    dc[1, 2] = 1.0
    dc[2, 3], dc[3, 3] = 1.0, eta[1]
    return c, dc


def stage2_cost(theta2, eta, groups):
    """The errors-in-variables (Koopmans) criterion ``sum_groups c' S c / c' Sigma c`` and its gradient.

    ``E[S] = S_signal + m Sigma`` (white sensor noise of known relative levels), so the criterion's
    expectation is ``sum s(theta)/v(theta) + const``, smallest at the true car; ordinary least
    squares ``sum c' S c`` is biased by the noise its regressors carry (alpha multiplies a second
    derivative of a measured signal)."""
    c, dc = stage2_coef(theta2, eta)
    f, g = 0.0, np.zeros(4)
    for gr in groups:
        Sc, Vc = gr.S @ c, gr.Sigma @ c
        q, v = c @ Sc, c @ Vc
        f += q / v
        g += 2 * dc.T @ Sc / v - 2 * q * (dc.T @ Vc) / v ** 2
    return f, g


def stage2_ols(eta, groups):
    """Ordinary least squares of the consistency (biased by noise; the start of :func:`stage2_fit`)."""
    XtX, Xty = np.zeros((4, 4)), np.zeros(4)
    for g in groups:
        c0, dc = stage2_coef(np.zeros(4), eta)
        X, y0 = g.Z @ dc, g.Z @ c0
        XtX += X.T @ X
        Xty += X.T @ y0
    return -np.linalg.solve(XtX, Xty)


def stage2_fit(eta, groups):
    """Minimise :func:`stage2_cost` from the ordinary least-squares solution (BFGS, then Newton steps)."""
    th = stage2_ols(eta, groups)
    sc = np.abs(th)

    def fun(p):
        f, g = stage2_cost(p * sc, eta, groups)
        return f, g * sc

    p = scipy.optimize.minimize(fun, np.ones(4), jac=True, method="BFGS", options={"gtol": 1e-9}).x
    for _ in range(5):
        g0 = fun(p)[1]
        H = np.stack([(fun(p + 1e-6 * e)[1] - fun(p - 1e-6 * e)[1]) / 2e-6 for e in np.eye(4)], axis=1)
        step = np.linalg.solve(0.5 * (H + H.T), g0)
        p = p - step
        if np.max(np.abs(step)) < 1e-10:
            break
    return p * sc


def stage2_scores(theta2, eta, g: Stage2Group):
    """Per-sample gradient (m, 4) of ``sum_t e_t^2 / (2 v)``, ``v = c' Sigma c``."""
    c, dc = stage2_coef(theta2, eta)
    v = c @ g.Sigma @ c
    e = g.Z @ c
    return (e[:, None] * (g.Z @ dc)) / v - (e ** 2)[:, None] * (c @ g.Sigma @ dc)[None] / v ** 2


# ---------------------------------------------------------------- results

def to_parameters(theta1, theta2, total_mass: float):
    """The twelve parameters (dict) from the stage ratios and the known total mass."""
    kf, kr, cf, cr, ixx, iyy, a = theta1
    af, bf, ar, br = theta2
    ktf, ktr = kf / bf, kr / br
    muf, mur = af * ktf, ar * ktr
    m_s = total_mass / (1 + 2 * muf + 2 * mur)
    return {"m_s": m_s, "I_xx": ixx * m_s, "I_yy": iyy * m_s, "a": a, "m_uf": muf * m_s, "m_ur": mur * m_s,
            "k_sf": kf * m_s, "k_sr": kr * m_s, "c_sf": cf * m_s, "c_sr": cr * m_s,
            "k_tf": ktf * m_s, "k_tr": ktr * m_s}


def stage1_start(P):
    """Stage-1 log parameters of a full parameter row ``P`` (the fit's start)."""
    m_s = P[INDEX["m_s"]]
    return np.log(np.array([P[INDEX["k_sf"]] / m_s, P[INDEX["k_sr"]] / m_s, P[INDEX["c_sf"]] / m_s,
                            P[INDEX["c_sr"]] / m_s, P[INDEX["I_xx"]] / m_s, P[INDEX["I_yy"]] / m_s,
                            P[INDEX["a"]]]))


@dataclass
class StagedResult:
    parameters: dict
    std_robust: dict
    theta1: np.ndarray     # stage 1: k_sf, k_sr, c_sf, c_sr, I_xx, I_yy per unit m_s, and a
    theta2: np.ndarray     # stage 2: alpha_f, beta_f, alpha_r, beta_r
    cov: np.ndarray        # joint covariance of (log theta1, theta2)
    nfev: int
    A: np.ndarray = None   # the sandwich's bread and the per-run stacked scores (n, 11)
    scores: list = None
    G: np.ndarray = None   # d(twelve)/d(log theta1, theta2)
    std_stage2_alone: dict = None


def _eta(lt1):
    th1 = np.exp(lt1)
    return np.array([th1[2] / th1[0], th1[3] / th1[1]])


def fit(runs, geom: Geometry, total_mass: float, P0, lowpass2_hz: float = LOWPASS_HZ[1]) -> StagedResult:
    """Both stages from the start ``P0`` (a full parameter row), and the joint sandwich."""
    lt0 = stage1_start(P0)
    sol = scipy.optimize.least_squares(stage1_residual, lt0, args=(geom, runs), diff_step=1e-6, method="lm")
    lt1 = sol.x
    groups = [g for i, rr in enumerate(runs) for g in stage2_groups(rr, i, lowpass2_hz)]
    th2 = stage2_fit(_eta(lt1), groups)

    # ---- joint sandwich of the stacked estimating equations
    shapes = []
    r1 = stage1_residual(lt1, geom, runs, out=shapes)
    J1 = sol.jac
    p1, p2 = len(STAGE1), len(STAGE2)
    A = np.zeros((p1 + p2, p1 + p2))
    A[:p1, :p1] = J1.T @ J1

    def psi2(lt, th):
        eta = _eta(lt)
        return sum(stage2_scores(th, eta, g).sum(axis=0) for g in groups)

    for j in range(p1 + p2):   # d psi2 / d (log theta1, theta2), central differences
        dv = 1e-5 * (1.0 if j < p1 else abs(th2[j - p1]))
        lp, lm, tp, tm = lt1.copy(), lt1.copy(), th2.copy(), th2.copy()
        if j < p1:
            lp[j] += dv
            lm[j] -= dv
        else:
            tp[j - p1] += dv
            tm[j - p1] -= dv
        A[p1:, j] = (psi2(lp, tp) - psi2(lm, tm)) / (2 * dv)
    B = np.zeros_like(A)
    eta = _eta(lt1)
    scores = []
    off = 0
    for i, (rr, shp) in enumerate(shapes):
        m = shp[0] * shp[1]
        S = np.zeros((rr.n, p1 + p2))
        S[rr.k0:rr.k1, :p1] = (J1[off:off + m] * r1[off:off + m, None]).reshape(shp[0], shp[1], p1).sum(axis=1)
        off += m
        for g in groups:
            if g.run == i:
                S[g.t, p1:] += stage2_scores(th2, eta, g)
        scores.append(S)
        B += long_run_covariance(S, andrews_bandwidth(S))
    Ai = np.linalg.inv(A)
    cov = Ai @ B @ Ai.T

    def g12(v):
        P = to_parameters(np.exp(v[:p1]), v[p1:], total_mass)
        return np.array([P[n] for n in NAMES])

    v = np.r_[lt1, th2]
    Gm = np.zeros((len(NAMES), v.size))
    for j in range(v.size):
        dv = 1e-6 * max(1e-3, abs(v[j]))
        vp, vm = v.copy(), v.copy()
        vp[j] += dv
        vm[j] -= dv
        Gm[:, j] = (g12(vp) - g12(vm)) / (2 * dv)
    sd = np.sqrt(np.clip(np.diag(Gm @ cov @ Gm.T), 0, None))
    # for comparison: stage 2's own sandwich, stage 1 taken as exact
    A2i = np.linalg.inv(A[p1:, p1:])
    cov2 = np.zeros_like(cov)
    cov2[p1:, p1:] = A2i @ B[p1:, p1:] @ A2i.T
    sd2 = np.sqrt(np.clip(np.diag(Gm @ cov2 @ Gm.T), 0, None))
    return StagedResult(parameters=dict(zip(NAMES, g12(v))), std_robust=dict(zip(NAMES, sd)), theta1=np.exp(lt1),
                        theta2=th2, cov=cov, nfev=sol.nfev, A=A, scores=scores, G=Gm,
                        std_stage2_alone=dict(zip(NAMES, sd2)))
