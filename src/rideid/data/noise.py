"""Sensor noise for simulated runs: white or first-order autoregressive (coloured)."""

from __future__ import annotations

import numpy as np


def sensor_noise(rng: np.random.Generator, shape, rho: float = 0.0) -> np.ndarray:
    """Unit-variance noise, independent per channel, AR(1) in time.

    ``e_0 ~ N(0, 1)``, ``e_k = rho e_{k-1} + sqrt(1 - rho^2) w_k``: stationary
    from the first sample, lag-l autocorrelation ``rho^l``. ``rho = 0`` is
    white noise and draws exactly ``rng.standard_normal(shape)``.

    Parameters
    ----------
    rng : numpy.random.Generator
    shape : (int, int)
        ``(n_time, n_channel)``.
    rho : float
        AR(1) coefficient per sample, ``0 <= rho < 1``.

    Returns
    -------
    ndarray, shape ``shape``
    """
    w = rng.standard_normal(shape)
    if rho == 0.0 or shape[0] < 2:
        return w
    s = np.sqrt(1.0 - rho * rho)
    e = np.empty_like(w)
    e[0] = w[0]
    from scipy.signal import lfilter  # here: scipy.signal takes 0.9 s to import

    e[1:], _ = lfilter([s], [1.0, -rho], w[1:], axis=0, zi=(rho * w[0])[None, :])
    return e
