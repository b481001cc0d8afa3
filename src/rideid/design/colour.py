"""Coloured sensor noise for the plan: AR(1) per sample, or a measured noise spectrum.

Within one run and channel the noise is stationary Gaussian with covariance
``sigma² R`` (``R`` the correlation matrix, unit diagonal); channels and runs
stay independent. The plan needs, per channel, three Gram matrices of the
sensitivities ``J`` (samples × parameters)::

    J^T J,     J^T R^-1 J   (Fisher information, the whitened problem),
               J^T R J      (the noise term of identify's least-squares sandwich)

* AR(1) with coefficient ``rho`` per sample (``R_ts = rho^|t-s|``, the noise of
  ``rideid simulate --noise-ar1``), exactly in the time domain:
  ``R^-1 = L^T L / (1 - rho²)`` with the Prais-Winsten whitening
  ``(L e)_0 = sqrt(1 - rho²) e_0``, ``(L e)_t = e_t - rho e_{t-1}``; and
  ``R J = f + b - J`` with ``f``, ``b`` the causal and anti-causal filters
  ``1 / (1 - rho z^-1)`` of ``J``.
* A spectrum (``--noise-psd``), in the frequency domain (Whittle): with the
  sensitivities zero-padded to ``M >= 2 N`` samples and their DFT ``S_k``,
  ``J^T R J = (1/M) sum_k Re(S_k^H S_k) r_k`` and
  ``J^T R^-1 J ~ (1/M) sum_k Re(S_k^H S_k) / r_k``, ``r_k`` the run's
  normalised (unit-variance) two-sided spectrum at ``k fs / M``. Zero padding
  makes the first sum exact for the (aliased) autocovariance of the spectrum,
  and the second differs from the exact ``R^-1`` only at the run's ends
  (for AR(1): ``rho² (J_0² + J_{N-1}²) / (1 - rho²)``).

The file format is documented in ``docs/planning.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..csvio import read_csv_rows
from ..errors import DataError
from ..model.equations import CHANNEL_KIND, CHANNELS

#: columns of a noise PSD file that cover several channels (a channel's own column wins)
GROUP_COLUMNS = {"accel": tuple(c for c in CHANNELS if CHANNEL_KIND[c] != "rate"),
                 "gyro": tuple(c for c in CHANNELS if CHANNEL_KIND[c] == "rate"),
                 "psd": CHANNELS}


@dataclass(frozen=True, eq=False)
class NoiseSpectrum:
    """A one-sided noise power spectral density per SPEC channel, read from a CSV file.

    ``psd[:, c]`` is in (m/s²)²/Hz or (rad/s)²/Hz at ``frequency`` (Hz); its
    integral over 0..fs/2 is the noise variance. Between the listed
    frequencies the logarithm of the PSD is interpolated linearly; below the
    lowest one its value holds.
    """

    path: str
    frequency: np.ndarray
    psd: np.ndarray                       # (n_freq, 10)
    columns: dict = field(default_factory=dict)  # channel -> the file's column used

    def at(self, f: np.ndarray) -> np.ndarray:
        """PSD at frequencies ``f`` (Hz), shape (len(f), 10)."""
        f = np.asarray(f, float)
        lp = np.log(self.psd)
        return np.exp(np.stack([np.interp(f, self.frequency, lp[:, c]) for c in range(lp.shape[1])], axis=1))

    def variance(self, fs: float) -> np.ndarray:
        """Noise variance per channel, (10,): the PSD's integral over 0..fs/2 (trapezoid on a fine grid)."""
        f = np.linspace(0.0, fs / 2, 2 ** 14 + 1)
        return np.trapezoid(self.at(f), f, axis=0)

    def check_covers(self, fs: float, what: str):
        if self.frequency[-1] < fs / 2 * (1 - 1e-9):
            raise DataError(f"{self.path}: column frequency ends at {self.frequency[-1]:g} Hz, below the "
                            f"Nyquist frequency {fs / 2:g} Hz of {what}; the noise spectrum must cover 0..fs/2")

    def to_dict(self) -> dict:
        return {"file": self.path, "columns": dict(self.columns),
                "frequency_hz": [float(self.frequency[0]), float(self.frequency[-1])], "rows": int(self.frequency.size)}


def ar1_psd(rho: float, fs: float, f, sigma=1.0) -> np.ndarray:
    """One-sided PSD (units²/Hz) at ``f`` (Hz) of AR(1) noise with coefficient ``rho`` per sample at
    ``fs`` and standard deviation ``sigma`` (:func:`rideid.data.noise.sensor_noise` scaled by ``sigma``)."""
    f = np.asarray(f, float)
    return 2.0 / fs * np.asarray(sigma) ** 2 * (1 - rho * rho) / (1 - 2 * rho * np.cos(2 * np.pi * f / fs) + rho * rho)


def load_noise_psd(path) -> NoiseSpectrum:
    """Read and validate a noise PSD file (``docs/planning.md``: columns ``frequency`` and per-channel,
    ``accel``/``gyro`` or common ``psd`` columns). Bad input raises :class:`DataError` naming the file and column."""
    path = Path(path)
    header, rows = read_csv_rows(path, f"{path}: noise PSD file not found", "noise PSD file")
    if "frequency" not in header:
        raise DataError(f"{path}: no column frequency (Hz); the noise PSD file needs frequency and "
                        f"psd, accel/gyro or channel columns ({', '.join(CHANNELS)})")
    seen = set()
    for h in header:
        if h in seen:
            raise DataError(f"{path}: column {h} appears twice")
        seen.add(h)
        if h != "frequency" and h not in GROUP_COLUMNS and h not in CHANNELS:
            raise DataError(f"{path}: unknown column {h!r}; expected frequency and psd, accel, gyro or "
                            f"channel names ({', '.join(CHANNELS)})")
    rows = [r for r in rows if any(v.strip() for v in r)]
    if len(rows) < 2:
        raise DataError(f"{path}: the noise PSD needs at least two rows (frequencies), got {len(rows)}")
    vals = np.empty((len(rows), len(header)))
    for i, r in enumerate(rows):
        if len(r) != len(header):
            raise DataError(f"{path}: row {i + 2} has {len(r)} values, the header {len(header)}")
        for j, v in enumerate(r):
            try:
                vals[i, j] = float(v)
            except ValueError:
                raise DataError(f"{path}: column {header[j]}, row {i + 2}: {v.strip()!r} is not a number") from None
    for j, h in enumerate(header):
        bad = ~np.isfinite(vals[:, j])
        if bad.any():
            raise DataError(f"{path}: column {h}, row {int(np.argmax(bad)) + 2}: not a finite number")
    f = vals[:, header.index("frequency")]
    if f[0] < 0:
        raise DataError(f"{path}: column frequency: negative frequency {f[0]:g} Hz (one-sided PSD: 0..fs/2)")
    if np.any(np.diff(f) <= 0):
        k = int(np.argmax(np.diff(f) <= 0))
        raise DataError(f"{path}: column frequency is not strictly increasing (row {k + 3}: {f[k + 1]:g} Hz "
                        f"after {f[k]:g} Hz)")
    psd = np.empty((len(rows), len(CHANNELS)))
    used = {}
    for k, c in enumerate(CHANNELS):
        col = c if c in header else next((g for g in ("accel", "gyro", "psd") if g in header
                                          and c in GROUP_COLUMNS[g]), None)
        if col is None:
            raise DataError(f"{path}: no PSD for channel {c}: give a column {c}, "
                            f"{'gyro' if CHANNEL_KIND[c] == 'rate' else 'accel'} or psd")
        psd[:, k] = vals[:, header.index(col)]
        used[c] = col
    for col in sorted(set(used.values()), key=header.index):
        v = vals[:, header.index(col)]
        if np.any(v <= 0):
            i = int(np.argmax(v <= 0))
            raise DataError(f"{path}: column {col}, row {i + 2}: the PSD must be positive, got {v[i]:g} "
                            "(a noise-free band would make the parameters known exactly)")
    unused = [h for h in header if h != "frequency" and h not in used.values()]
    if unused:
        raise DataError(f"{path}: column {unused[0]} is not used (every channel it covers has its own column)")
    return NoiseSpectrum(str(path), f, psd, used)


# ---------------------------------------------------------------------------
# Gram matrices per channel: J^T R^-1 J and J^T R J

def _gram(X, Y) -> np.ndarray:
    """(10, d, d) ``sum_t X[i, t, c] Y[j, t, c]``, symmetrised."""
    G = np.einsum("itc,jtc->cij", X, Y)
    return 0.5 * (G + G.transpose(0, 2, 1))


def ar1_grams(J: np.ndarray, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """``J^T R^-1 J`` and ``J^T R J`` per channel for AR(1) correlation ``R_ts = rho^|t-s|`` (exact).

    ``J``: (d, n, 10). Returns two (10, d, d) arrays; ``rho = 0`` gives ``J^T J`` twice.
    """
    from scipy.signal import lfilter
    c = 1.0 - rho * rho
    W = J.copy()
    W[:, 1:] -= rho * J[:, :-1]
    W[:, 0] *= np.sqrt(c)
    Gi = _gram(W, W) / c
    f = lfilter([1.0], [1.0, -rho], J, axis=1)
    b = lfilter([1.0], [1.0, -rho], J[:, ::-1], axis=1)[:, ::-1]
    Gc = _gram(J, f + b - J)
    return Gi, Gc


def padded_length(n: int) -> int:
    """DFT length for a run of ``n`` samples: at least ``2 n`` (no wrap-around in ``J^T R J``)."""
    from scipy.fft import next_fast_len
    return int(next_fast_len(2 * n))


def spectral_grams(J: np.ndarray, shape: np.ndarray, M: int) -> tuple[np.ndarray, np.ndarray]:
    """``J^T R^-1 J`` (Whittle) and ``J^T R J`` per channel from a noise spectrum.

    ``J``: (d, n, 10), ``M >= 2 n``; ``shape``: (M // 2 + 1, 10), the spectrum at the ``rfft`` bins
    ``k fs / M`` (any scale: it is normalised here to unit variance per channel).
    """
    K = M // 2 + 1
    w = np.full(K, 2.0)
    w[0] = 1.0
    if M % 2 == 0:
        w[-1] = 1.0
    r = shape / ((w[:, None] * shape).sum(0) / M)[None, :]  # unit variance: (1/M) sum over all M bins = 1
    S = np.fft.rfft(J, n=M, axis=1)  # (d, K, 10)

    def g(weight):
        X = S * np.sqrt(w[:, None] * weight / M)[None]
        return _gram(X.real, X.real) + _gram(X.imag, X.imag)
    return g(1.0 / r), g(r)
