"""Standard errors of a least-squares estimate: white and robust (HAC).

Pure functions over the polish's Jacobian ``J`` (m, n) and residuals ``e``
(m,) at the optimum. The stacked residual vector is laid out run by run,
time-major, the run's used channels within each sample
(:meth:`rideid.CostFunction.residuals`); ``blocks`` gives each run's
``(n_time, n_channel)`` so that the layout can be undone.

White (``std``)
    ``cov = s^2 (J^T J)^-1``, ``s^2 = RSS / (m - n)``: correct only when the
    residuals are independent with one variance. Sensor noise that is
    coloured in time, or correlated across channels, or a model that misses
    part of the car, all make it optimistic, often by a large factor.

Robust (``std_robust``): a HAC sandwich
    ``cov = H^-1 S H^-1``, ``H = J^T J``,
    ``S = sum_runs sum_{|l| <= L_r} k(l / (L_r + 1)) Gamma_r(l)``,
    ``Gamma_r(l) = sum_t g_t g_{t-l}^T``,

    with the per-sample score ``g_t = J_t^T e_t`` (J_t: the sample's rows, one
    per channel; e_t: the sample's residual vector across channels, taken as
    one observation, so correlation across channels at one instant is
    included whatever its form), the Bartlett kernel ``k(x) = 1 - |x|``
    (Newey & West 1987: the estimate of S is positive semi-definite), lags
    never crossing a run boundary (runs are independent experiments: their
    cross-covariances are zero), and a data-driven bandwidth ``L_r`` per run
    by Andrews' (1991) AR(1) plug-in rule on the standardised score
    components. The scores are not demeaned, so a run whose residuals pull
    the parameters consistently one way (a model mismatch) widens the error
    bar instead of vanishing in a mean.

Why HAC and not a bootstrap: a bootstrap over runs has ~10 units that are
not exchangeable (each track informs other parameters), so resampled sets
often lose a parameter's information altogether; a block bootstrap over
residual blocks needs one refit (a polish: seconds) per replicate and a
block length chosen by the same kind of rule as ``L_r``; its linearised
one-step version is the HAC estimate with a flat kernel. HAC costs one pass
over the residuals.

``(J^T J)^-1`` is never formed by inverting ``J^T J`` (that squares the
Jacobian's condition number: at ``cond(J) = 1e8`` nothing is left): it is
``V diag(1/s^2) V^T`` from the SVD ``J = U diag(s) V^T``
(:func:`normal_inverse`). Singular values below ``RANK_RTOL * max(s)`` carry
no information and are dropped; a parameter with a share in those directions
(the data determine only a combination of it with others, or nothing) is
*not identified*: its variance is reported as ``inf`` (``std`` None in
result.json, with a note) and its covariances as NaN, never a huge number
that looks like a measurement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from ...settings import defaults, legacy_names
from ..problem.scores import andrews_bandwidth, long_run_covariance, run_scores, takes_residuals
from .tall import tall_r


@takes_residuals
def white_covariance(J, e) -> np.ndarray:
    """Covariance ``s^2 (J^T J)^-1`` assuming independent residuals of one variance.

    Parameters
    ----------
    {residual_parameters}

    Returns
    -------
    ndarray, shape (n, n)
        An unidentified parameter's variance ``inf``, its covariances NaN (:class:`NormalInverse`).
    """
    J = np.asarray(J, dtype=float)
    e = np.asarray(e, dtype=float)
    m, n = J.shape
    s2 = float(e @ e) / max(m - n, 1)
    inv = normal_inverse(J)
    return inv.mark(s2 * inv.matrix)


@dataclass(frozen=True)
class NormalInverse:
    """``(J^T J)^+`` from the SVD of ``J`` and the parameters it leaves undetermined.

    Attributes
    ----------
    matrix : ndarray, shape (n, n)
        ``V diag(1/s^2) V^T`` over the singular values kept (``s > RANK_RTOL max(s)``).
    rank : int
        Singular values kept.
    unidentified : ndarray of bool, shape (n,)
        Parameters with a squared share above setting ``uncertainty.null_share`` in the dropped directions.
    """

    matrix: np.ndarray
    rank: int
    unidentified: np.ndarray

    def mark(self, cov) -> np.ndarray:
        """``cov`` (n, n) with the unidentified parameters' variances ``inf`` and their covariances NaN."""
        cov = np.array(cov, dtype=float)
        bad = self.unidentified
        if bad.any():
            cov[bad, :] = np.nan
            cov[:, bad] = np.nan
            cov[bad, bad] = np.inf
        return cov


def normal_inverse(J, rtol: float | None = None) -> NormalInverse:
    """Pseudo-inverse of ``J^T J`` through the SVD of ``J`` (module docstring).

    Parameters
    ----------
    J : ndarray, shape (m, n)
        Jacobian of the residuals.
    rtol : float
        Singular values below ``rtol * max(s)`` are dropped.

    Returns
    -------
    NormalInverse
        All parameters unidentified (and ``matrix`` NaN) when ``J`` is not finite.
    """
    rtol = defaults["uncertainty.rank_rtol"] if rtol is None else rtol
    J = np.asarray(J, dtype=float)
    n = J.shape[1]
    if not np.all(np.isfinite(J)):
        return NormalInverse(np.full((n, n), np.nan), 0, np.ones(n, dtype=bool))
    _, s, Vt = np.linalg.svd(tall_r(J), full_matrices=False)  # J's singular values and V, from its QR's triangle
    keep = s > rtol * (s[0] if s.size else 0.0)
    V = Vt[keep].T
    Hinv = (V / s[keep] ** 2) @ V.T
    # each parameter's squared share outside the kept directions (the dropped ones, and with m < n the rest)
    share = 1.0 - np.sum(V ** 2, axis=1)
    return NormalInverse(0.5 * (Hinv + Hinv.T), int(keep.sum()), share > defaults["uncertainty.null_share"])


@dataclass(frozen=True)
class Resolution:
    """Which directions of a Hessian taken by second differences of a cost that carries rounding the data fix.

    A second difference divides the cost's rounding ``delta`` by the step squared: on a fit with tracks as built
    and an engine on mounts an eigenvalue of the true Hessian came out -22 with a rounding noise of about 10
    (docs/uncertainty.md, "Directions the cost's rounding hides"). Such a direction's curvature, and every error
    bar it enters, is not measured. :func:`resolve` keeps the eigen-directions whose curvature is above setting
    ``uncertainty.curvature_noise`` times its noise; the bread is the pseudo-inverse on those (:meth:`pinv`: the
    other parameters' error bars hold with the unresolved directions at their estimates), and a parameter is *not
    determined* when even the largest curvature its unresolved directions could have would add more than setting
    ``uncertainty.unresolved_share`` to its variance.

    Attributes
    ----------
    basis : ndarray, shape (n, r)
        The resolved eigenvectors.
    not_determined : ndarray of bool, shape (n,)
    noise : ndarray
        Each unresolved direction's rounding noise (of its eigenvalue, the Hessian's units).
    curvatures, directions : ndarray
        The unresolved directions' eigenvalues and eigenvectors (columns).
    """

    basis: np.ndarray
    not_determined: np.ndarray
    noise: np.ndarray
    curvatures: np.ndarray
    directions: np.ndarray

    def pinv(self, H) -> np.ndarray:
        """The pseudo-inverse of ``H`` on the resolved directions; ``H`` may be larger than the basis (the car's
        unknowns first, then nuisances, all of which are kept)."""
        n, r = self.basis.shape
        q = H.shape[0] - n
        T = np.zeros((n + q, r + q))
        T[:n, :r] = self.basis
        T[n:, r:] = np.eye(q)
        return T @ np.linalg.pinv(T.T @ H @ T, rcond=1e-12, hermitian=True) @ T.T

    def record(self, names) -> dict | None:
        """result.json ``polish.unresolved``: each unresolved direction (its curvature, its rounding noise, the
        parameters along it with their share) and the parameters not determined; None when every direction is
        resolved."""
        if not self.curvatures.size:
            return None
        dirs = [{"curvature": float(w), "noise": float(s), "along": along_record(u, names)}
                for w, s, u in zip(self.curvatures, self.noise, self.directions.T)]
        return {"directions": dirs, "not_determined": [n for n, b in zip(names, self.not_determined) if b],
                "curvature_noise": float(defaults["uncertainty.curvature_noise"])}


def along_record(u, names) -> dict:
    """A unit direction ``u`` as result.json writes it: parameter -> its share (3 digits), those of 0.1 or more,
    the largest first."""
    return {names[i]: round(float(u[i]), 3) for i in np.argsort(-np.abs(u)) if abs(u[i]) >= 0.1}


def _spectrum(H, delta: float, step: float, remeasured=None):
    """``H`` made symmetric, its eigenvalues ``w`` and eigenvectors ``U``, each eigenvalue's rounding noise and the
    mask of those not above setting ``uncertainty.curvature_noise`` times it (:func:`resolve`'s docstring)."""
    H = 0.5 * (np.asarray(H, dtype=float) + np.asarray(H, dtype=float).T)
    w, U = np.linalg.eigh(H)
    noise = delta / step ** 2 * np.sqrt(1.125 + 0.375 * np.sum(U ** 4, axis=0))
    if remeasured is not None:
        D, along = remeasured
        on = np.max(np.abs(np.asarray(D).T @ U), axis=0) > 0.9
        noise = np.where(on, np.sqrt(6.0) * delta / (2 * along ** 2), noise)
    return H, w, U, noise, w <= defaults["uncertainty.curvature_noise"] * noise


def remeasured(H, delta: float, step: float, along: float, measure) -> tuple:
    """``H`` with each direction :func:`resolve` leaves unresolved measured again at the larger step ``along``, and
    its :class:`Resolution`.

    ``measure(U, m)``: the half Hessian's row along eigenvector ``U[:, m]`` in the eigenbasis ``U``, by second
    differences of step ``along`` (the diagonal a secant ``(f(v + a u) + f(v - a u) - 2 f(v)) / (2 a^2)``, each
    coupling four costs over ``8 a^2``; NaN where a coupling was not measured again: it keeps its value), or None
    where the steps would cross a bound. Both the curvature and its
    couplings: at ``step`` the couplings' noise is an eigenvalue's (``delta / (4 h^2)`` each), and a weak
    direction's variance ``1 / (w - sum_j c_j^2 / w_j)`` takes up their squares (on the all-realities gross case
    ``sum_j c_j^2 / w_j`` of noise alone was about 2.5 against a curvature of 4.6). At ``along`` every term's noise
    is ``(along / step)^2`` times smaller. Returns ``(H, Resolution, records)``, ``records`` one dict per direction
    measured again (the parameters along it, its curvature and noise at ``step``, its curvature at ``along``)."""
    spectrum = _spectrum(H, delta, step)
    H, w, U, _, low = spectrum
    if not low.any():
        return H, _resolution(*spectrum), []
    L = U.T @ H @ U
    done, records = [], []
    for m in np.flatnonzero(low):
        row = measure(U, int(m))
        if row is None:
            continue
        row = np.where(np.isfinite(row), row, L[m])  # a coupling not measured again keeps its value at step
        L[m, :] = L[:, m] = row
        done.append(int(m))
        records.append({"curvature": float(w[m]), "curvature_at_step": float(row[m]), "step": float(along),
                        "direction": U[:, m].copy()})
    if not done:
        return H, _resolution(*spectrum), []
    H2 = U @ L @ U.T
    return H2, resolve(H2, delta, step, remeasured=(U[:, done], along)), records


def resolve(H, delta: float, step: float, remeasured=None) -> Resolution:
    """The :class:`Resolution` of the half Hessian ``H`` taken by central second differences at ``step`` of a cost
    whose rounding is ``delta`` (a standard deviation, independent between evaluations).

    A diagonal entry ``(f+ - 2 f0 + f-) / (2 h^2)``: its own costs' noise ``delta / (sqrt(2) h^2)``, and the one
    ``f0`` of every diagonal entry, which shifts every eigenvalue alike by ``delta / h^2``; a cross term (four costs
    over ``8 h^2``) ``delta / (4 h^2)``. An eigenvalue along a unit ``u``, to first order ``u^T N u``, so has the
    variance ``(delta / h^2)^2 (1 + sum_i u_i^4 / 2 + sum_{i<j} u_i^2 u_j^2 / 4)`` = ``(delta / h^2)^2 (9/8 + 3/8
    sum_i u_i^4)``: 1.06 to 1.22 ``delta / h^2``.

    ``remeasured``: ``(D, a)``, directions (columns) whose curvature ``H`` holds as a secant at the step ``a``
    (:func:`remeasured`); an eigenvector along one of them carries that secant's noise instead."""
    return _resolution(*_spectrum(H, delta, step, remeasured))


def _resolution(H, w, U, noise, low) -> Resolution:
    """The :class:`Resolution` of a :func:`_spectrum`."""
    n = H.shape[0]
    if not low.any():
        return Resolution(np.eye(n), np.zeros(n, dtype=bool), np.zeros(0), np.zeros(0), np.zeros((n, 0)))
    kept = U[:, ~low]
    resolved_var = (kept ** 2) @ (1.0 / w[~low])
    # the most curvature an unresolved direction could have: its noise's bound (or its own size, when below -that)
    most = np.maximum(np.maximum(defaults["uncertainty.curvature_noise"] * noise[low], np.abs(w[low])),
                      np.finfo(float).tiny)
    added = (U[:, low] ** 2) @ (1.0 / most)
    bad = added > defaults["uncertainty.unresolved_share"] * resolved_var
    return Resolution(kept, bad, noise[low], w[low], U[:, low])


@dataclass
class RobustCovariance:
    """The HAC sandwich and what went into it.

    Attributes
    ----------
    cov : ndarray, shape (n, n)
        Robust covariance of the unknowns (in the Jacobian's coordinates).
    bandwidths : list of float
        Bartlett bandwidth of each run, samples.
    """

    cov: np.ndarray
    bandwidths: list


@takes_residuals
def hac_covariance(J, e, blocks, bandwidth: float | None = None) -> RobustCovariance:
    """Robust covariance: Bartlett HAC sandwich with runs as independent blocks (module docstring).

    Parameters
    ----------
    {residual_parameters}
    blocks : sequence of (int, int)
        ``(n_time, n_channel)`` of each run, in the residual vector's order.
    bandwidth : float, optional
        Fixed Bartlett bandwidth for every run (samples); default: Andrews'
        plug-in per run (:func:`andrews_bandwidth`).

    Returns
    -------
    RobustCovariance
        ``cov`` is multiplied by ``m / (m - n)`` as the white estimate's
        ``s^2`` is; an unidentified parameter's variance ``inf``, its covariances NaN
        (:class:`NormalInverse`).
    """
    J = np.asarray(J, dtype=float)
    m, n = J.shape
    S = np.zeros((n, n))
    bws = []
    for G in run_scores(J, e, blocks):
        L = andrews_bandwidth(G) if bandwidth is None else float(bandwidth)
        bws.append(L)
        S += long_run_covariance(G, L)
    inv = normal_inverse(J)
    Hinv = inv.matrix
    cov = Hinv @ S @ Hinv * (m / max(m - n, 1))
    return RobustCovariance(cov=inv.mark(0.5 * (cov + cov.T)), bandwidths=bws)


def jackknife_runs(J, e, blocks, rtol: float | None = None, n_checked: int | None = None):
    """Delete-one-run jackknife covariance of the estimate, linearised at the optimum.

    Leaving run ``r`` out moves a least-squares optimum by ``(H - H_r)^+ g_r``
    to first order (``H = J^T J``, ``H_r`` and ``g_r = J_r^T e_r`` the run's
    share of the Hessian and of the gradient, which sums to 0 over the runs at
    the optimum): no new fit. The jackknife covariance is ``(k - 1) / k sum_r
    (d_r - mean d)(d_r - mean d)^T`` over the ``k`` runs whose removal leaves
    every parameter determined (a run that alone measures a parameter is not
    left out). With the model right it estimates the same sampling covariance
    as the robust (HAC) one; where the model errs differently on different
    runs (a nonlinearity one track excites more than another), the estimates
    of the runs disagree by more than their noise and it is larger
    (:func:`between_runs_variance`).

    Parameters
    ----------
    J, e : the stacked residuals' Jacobian ``(m, n)`` and residuals ``(m,)``; rows beyond the runs' blocks
        (prior pseudo-observations) stay in every fit.
    blocks : sequence of (int, int)
        ``(n_time, n_channel)`` of each run.
    n_checked : int, optional
        Only the first ``n_checked`` unknowns must stay determined (the parameters; a run's own start
        shift goes with the run).

    Returns
    -------
    (ndarray (n, n) or None, int)
        The covariance (None with fewer than 3 runs to leave out) and ``k``.
    """
    rtol = defaults["uncertainty.rank_rtol"] if rtol is None else rtol
    J = np.asarray(J, dtype=float)
    e = np.asarray(e, dtype=float)
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(e))):
        return None, 0
    H = J.T @ J
    deltas, i = [], 0
    for T, C in blocks:
        size = int(T) * int(C)
        Jr, er = J[i:i + size], e[i:i + size]
        i += size
        if size == 0:
            continue
        lam, V = np.linalg.eigh(H - Jr.T @ Jr)
        sv = np.sqrt(np.clip(lam, 0, None))
        keep = sv > rtol * sv.max() if sv.size and sv.max() > 0 else np.zeros(lam.size, dtype=bool)
        Vk = V[:, keep]
        if np.any((1.0 - np.sum(Vk ** 2, axis=1))[:n_checked] > defaults["uncertainty.null_share"]):
            continue  # this run alone determines a parameter: it cannot be left out
        deltas.append((Vk / lam[keep]) @ (Vk.T @ (Jr.T @ er)))
    k = len(deltas)
    if k < 3:
        return None, k
    D = np.array(deltas)
    D -= D.mean(axis=0)
    return (k - 1) / k * (D.T @ D), k


def between_runs_variance(v_jack: float, v_robust: float, k: int) -> float:
    """The variance the runs' disagreement adds to an estimate (0 when it is within their noise).

    The Birge ratio ``R^2 = v_jack / v_robust`` is about chi-square(k - 1) / (k - 1) when the runs agree
    within their noise; above its setting ``uncertainty.birge_p`` quantile the excess ``v_jack - v_robust`` is model
    error that differs between runs (dark uncertainty), and is returned."""
    if not (np.isfinite(v_jack) and np.isfinite(v_robust)) or v_robust <= 0 or k < 3:
        return 0.0
    limit = 2.0 * special.gammaincinv(0.5 * (k - 1), defaults["uncertainty.birge_p"]) / (k - 1)
    return float(v_jack - v_robust) if v_jack / v_robust > limit else 0.0


def correlation(cov) -> np.ndarray:
    """Correlation matrix of a covariance (NaN where a variance is not positive)."""
    cov = np.asarray(cov, dtype=float)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        R = cov / np.outer(sd, sd)
    R[np.outer(sd, sd) == 0] = np.nan
    return R


def with_derived(cov, gradient) -> np.ndarray:
    """Append a derived quantity ``q = const + gradient @ x`` to a covariance.

    Parameters
    ----------
    cov : ndarray, shape (n, n)
    gradient : ndarray, shape (n,)

    Returns
    -------
    ndarray, shape (n + 1, n + 1)
        The covariance of ``(x, q)``.
    """
    cov = np.asarray(cov, dtype=float)
    g = np.asarray(gradient, dtype=float)
    n = cov.shape[0]
    out = np.empty((n + 1, n + 1))
    out[:n, :n] = cov
    out[:n, n] = out[n, :n] = cov @ g
    out[n, n] = g @ cov @ g
    return out


@dataclass
class EstimateCovariance:
    """White and robust covariances of the estimated parameters, derived mass included.

    Attributes
    ----------
    names : list of str
        The free parameters in the polish's column order, then the derived
        mass (if any).
    white, robust : ndarray, shape (len(names), len(names))
        In the parameters' own units; NaN-filled (or ``None``) without a polish.
    """

    names: list
    white: np.ndarray | None
    robust: np.ndarray | None
    #: the delete-one-run jackknife covariance (:func:`jackknife_runs`) and its number of runs, when the
    #: polish recorded one
    jackknife: np.ndarray | None = None
    jackknife_runs: int = 0

    @classmethod
    def from_polish(cls, info: dict | None, space, x=None) -> "EstimateCovariance":
        """From the polish's record (``covariance``, ``covariance_robust``) and the ParameterSpace.

        With ``x`` (the free parameters at the optimum) every derived quantity of the space
        (:meth:`rideid.ParameterSpace.derived_names`: the derived mass, with damper curves the
        frozen knot forces and ``c_sf``, ``c_sr``) is appended by the delta method, exact for these
        linear functions; without it only the derived mass.
        """
        if x is None or not getattr(space, "curves", False):
            names = list(space.names) + ([space.derived] if space.derived is not None else [])
            if info is None or "covariance_robust" not in info:
                return cls(names, None, None)
            g = space.derived_gradient()
            mats = []
            for key in ("covariance", "covariance_robust", "covariance_jackknife"):
                if info.get(key) is None:
                    mats.append(None)
                    continue
                C = np.array(info[key], dtype=float)
                mats.append(with_derived(C, g) if space.derived is not None else C)
            return cls(names, *mats, int(info.get("jackknife_runs", 0)))
        names = list(space.names) + space.derived_names()
        if info is None or "covariance_robust" not in info:
            return cls(names, None, None)
        A = np.vstack([np.eye(len(space.names)), space.derived_jacobian(x)])
        mats = [None if info.get(key) is None else A @ np.array(info[key], dtype=float) @ A.T
                for key in ("covariance", "covariance_robust", "covariance_jackknife")]
        return cls(names, *mats, int(info.get("jackknife_runs", 0)))

    def _std(self, cov, name: str) -> float | None:
        """The standard error of ``name`` on the diagonal of ``cov`` (``None`` if unavailable)."""
        if cov is None or name not in self.names:
            return None
        i = self.names.index(name)
        v = cov[i][i]
        return float(np.sqrt(v)) if np.isfinite(v) and v >= 0 else None

    def std_white(self, name: str) -> float | None:
        """White (Jacobian) standard error of one estimated or derived parameter (``None`` if unavailable)."""
        return self._std(self.white, name)

    def std_robust(self, name: str) -> float | None:
        """Robust standard error of one estimated parameter (``None`` if unavailable)."""
        return self._std(self.robust, name)

    def std_jackknife(self, name: str) -> float | None:
        """The delete-one-run jackknife standard error of one parameter (``None`` if unavailable)."""
        return self._std(self.jackknife, name)

    def std_between_runs(self, name: str) -> float | None:
        """The standard uncertainty the runs' disagreement adds (:func:`between_runs_variance`; 0 when they
        agree within their noise, ``None`` without a jackknife)."""
        sj, sr = self.std_jackknife(name), self.std_robust(name)
        if sj is None or sr is None:
            return None
        return float(np.sqrt(between_runs_variance(sj ** 2, sr ** 2, self.jackknife_runs)))

    def correlation_dict(self) -> dict | None:
        """``{"names", "matrix", "basis"}`` for result.json: the estimates' correlations (robust covariance)."""
        if self.robust is None or not np.all(np.isfinite(self.robust)):
            return None
        R = correlation(self.robust)
        return {"names": list(self.names), "basis": "std_robust (HAC covariance)",
                "matrix": [[None if not np.isfinite(v) else round(float(v), 6) for v in row] for row in R]}


def estimate_covariance(info: dict | None, space, x=None) -> EstimateCovariance:
    """Shorthand for :meth:`EstimateCovariance.from_polish`."""
    return EstimateCovariance.from_polish(info, space, x)


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "RHO_MAX": "uncertainty.rho_max", "RANK_RTOL": "uncertainty.rank_rtol", "NULL_SHARE":
    "uncertainty.null_share", "BIRGE_P": "uncertainty.birge_p"})
