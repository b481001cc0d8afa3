"""Track weighting: how much each run counts in the search's cost (paper eq. 12-13).

A strategy object with one rule, :meth:`TrackWeighting.update`, applied by
the search after every generation: ``fixed`` keeps equal weights,
``adaptive`` moves them to the runs that carry most information on the
parameters the population still disagrees on, through the parameter ->
track map ``M`` (:mod:`rideid.estimate.problem.sensitivity`).
"""

from __future__ import annotations

import numpy as np

from ...errors import ArgumentError


def normalised_spread(X) -> np.ndarray:
    """Paper eq. 12: each parameter's population variance normalised by its
    mean, then over all parameters (sums to 1).

    ``var / mean`` has the parameter's unit, so N/m parameters would swamp
    kg m^2 ones; we use the dimensionless ``var / mean^2`` (the squared
    coefficient of variation) as the per-parameter spread.
    """
    X = np.asarray(X, dtype=float)
    mean = X.mean(axis=0)
    v = X.var(axis=0) / np.maximum(mean * mean, 1e-300)
    s = v.sum()
    return v / s if s > 0 else np.full(v.shape, 1.0 / v.size)


def coefficient_of_variation(X) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    return X.std(axis=0) / np.maximum(np.abs(X.mean(axis=0)), 1e-300)


def adaptive_weights(M_free: np.ndarray, spread: np.ndarray) -> np.ndarray:
    """Paper eq. 13: ``w_r ∝ sum_p spread_p M[p, r]``, normalised to sum 1."""
    w = spread @ M_free
    s = w.sum()
    return w / s if s > 0 else np.full(M_free.shape[1], 1.0 / M_free.shape[1])


class TrackWeighting:
    """Equal run weights (``"fixed"``); the base of the strategies."""

    name = "fixed"

    @staticmethod
    def create(mode: str) -> "TrackWeighting":
        """The strategy named ``mode`` (``"adaptive"`` or ``"fixed"``)."""
        kinds = {"adaptive": AdaptiveWeighting, "fixed": TrackWeighting}
        if mode not in kinds:
            raise ArgumentError(f"weights must be 'adaptive' or 'fixed', got {mode!r}")
        return kinds[mode]()

    def initial(self, n_runs: int) -> np.ndarray:
        """Equal weights, shape ``(n_runs,)``, summing to 1."""
        return np.full(n_runs, 1.0 / n_runs)

    def update(self, M_free, population, w):
        """After a generation: ``(spread, weights)``; the same ``w`` object when unchanged.

        Parameters
        ----------
        M_free : ndarray, shape (d, n_runs)
            Parameter -> track map rows of the free parameters.
        population : ndarray, shape (n_pop, d)
        w : ndarray, shape (n_runs,)
            The current weights.
        """
        return normalised_spread(population), w


class AdaptiveWeighting(TrackWeighting):
    """Weights that follow the population's spread through the map (paper eq. 13)."""

    name = "adaptive"

    def update(self, M_free, population, w):
        spread = normalised_spread(population)
        return spread, adaptive_weights(M_free, spread)


__all__ = ["TrackWeighting", "AdaptiveWeighting", "adaptive_weights", "normalised_spread",
           "coefficient_of_variation"]
