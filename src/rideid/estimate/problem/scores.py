"""The score series of a problem's residual blocks and their long-run covariance: the pieces each block's share
of the error bars is made of.

A block's share of a sandwich's meat (:func:`rideid.estimate.problem.blocks.track_meat`, the staged road fit's
bins, :mod:`rideid.estimate.problem.roadstaged`) and the fit's robust covariance
(:func:`rideid.estimate.fit.uncertainty.hac_covariance`, whose docstring states the estimator) are built from
the same three functions: the per-sample scores ``g_t = J_t^T e_t`` of each run (:func:`run_scores`), Andrews'
(1991) plug-in Bartlett bandwidth of a score series (:func:`andrews_bandwidth`) and its Bartlett-weighted sum
of autocovariances (:func:`long_run_covariance`). They live with the blocks, which own their share of the error
bars; the fit composes them. Pure functions over arrays; the clip of the plug-in rule's autocorrelations is the
uncertainty estimator's setting ``uncertainty.rho_max``.
"""

from __future__ import annotations

import numpy as np

from ...settings import defaults

#: Andrews (1991) constant of the Bartlett kernel's optimal bandwidth
ANDREWS_BARTLETT = 1.1447


#: the two arguments every estimator here takes, written once (``{residual_parameters}`` in their docstrings)
RESIDUAL_PARAMETERS = """J : ndarray, shape (m, n)
        Jacobian of the residuals at the optimum.
    e : ndarray, shape (m,)
        Residuals at the optimum."""


def takes_residuals(f):
    """Put :data:`RESIDUAL_PARAMETERS` into ``f``'s numpydoc Parameters section."""
    if f.__doc__:  # None under python -OO
        f.__doc__ = f.__doc__.replace("{residual_parameters}", RESIDUAL_PARAMETERS)
    return f


def andrews_bandwidth(G) -> float:
    """Bartlett-kernel bandwidth by Andrews' (1991) AR(1) plug-in rule.

    Each column of ``G`` (a score component over time) is standardised and
    fitted with an AR(1), ``rho_a``; then
    ``alpha = sum 4 rho^2 s^4 / ((1-rho)^6 (1+rho)^2) / sum s^4 / (1-rho)^4``
    with ``s^2 = 1 - rho^2`` the innovation variance, and
    ``L = 1.1447 (alpha T)^(1/3)``, at most ``T - 1``.

    Parameters
    ----------
    G : ndarray, shape (T, n)

    Returns
    -------
    float
        The bandwidth in samples (lags ``|l| <= L`` get weight ``1 - l/(L+1)``).
    """
    G = np.asarray(G, dtype=float)
    T = G.shape[0]
    if T < 3:
        return 0.0
    sd = G.std(axis=0)
    keep = sd > 0
    if not keep.any():
        return 0.0
    Z = (G[:, keep] - G[:, keep].mean(axis=0)) / sd[keep]
    rho = np.sum(Z[1:] * Z[:-1], axis=0) / np.sum(Z[:-1] ** 2, axis=0)
    rho = np.clip(rho, -defaults["uncertainty.rho_max"], defaults["uncertainty.rho_max"])
    s4 = (1 - rho ** 2) ** 2
    num = np.sum(4 * rho ** 2 * s4 / ((1 - rho) ** 6 * (1 + rho) ** 2))
    den = np.sum(s4 / (1 - rho) ** 4)
    alpha = num / den
    return float(min(ANDREWS_BARTLETT * (alpha * T) ** (1.0 / 3.0), T - 1))


def long_run_covariance(G, bandwidth: float) -> np.ndarray:
    """Bartlett-weighted sum of the autocovariances of the rows of ``G`` (not demeaned).

    ``sum_{|l| <= L} (1 - |l|/(L+1)) sum_t g_t g_{t-l}^T`` (a sum, not a mean).

    Parameters
    ----------
    G : ndarray, shape (T, n)
    bandwidth : float
        ``L`` in samples (0: the heteroscedasticity-only estimate).

    Returns
    -------
    ndarray, shape (n, n)
    """
    G = np.asarray(G, dtype=float)
    # sum_l w_l sum_t g_t g_{t-l}^T = G^T H, H_t = sum_l w_l g_{t-l} (the rows filtered by the symmetric
    # kernel): one product of G's size instead of one per lag (6000 x 157 at a bandwidth of 40: 0.21 -> 0.06 s)
    L = min(int(np.floor(bandwidth)), G.shape[0] - 1)
    if L < 1:
        return G.T @ G
    H = G.copy()
    for lag in range(1, L + 1):
        w = 1.0 - lag / (bandwidth + 1.0)
        H[lag:] += w * G[:-lag]
        H[:-lag] += w * G[lag:]
    S = G.T @ H
    return 0.5 * (S + S.T)


@takes_residuals
def run_scores(J, e, blocks) -> list[np.ndarray]:
    """Per-sample scores ``g_t = J_t^T e_t`` of each run.

    Parameters
    ----------
    {residual_parameters}
    blocks : sequence of (int, int)
        ``(n_time, n_channel)`` of each run; ``sum n_time * n_channel == m``.

    Returns
    -------
    list of ndarray, each (n_time, n)
    """
    J = np.asarray(J, dtype=float)
    e = np.asarray(e, dtype=float)
    m, n = J.shape
    sizes = [int(T) * int(C) for T, C in blocks]
    if sum(sizes) != m or e.shape != (m,):
        raise ValueError(f"blocks cover {sum(sizes)} residuals, the Jacobian has {m} rows and e {e.shape}")
    out, i = [], 0
    for (T, C), size in zip(blocks, sizes):
        Jr = J[i:i + size].reshape(T, C, n)
        er = e[i:i + size].reshape(T, C, 1)
        out.append(np.sum(Jr * er, axis=1))
        i += size
    return out


__all__ = ["ANDREWS_BARTLETT", "RESIDUAL_PARAMETERS", "andrews_bandwidth", "long_run_covariance", "run_scores",
           "takes_residuals"]
