"""Random roads of ISO 8608: displacement spectra, road classes, two coherent wheel paths.

A road's height along one wheel path is a stationary Gaussian process with
the one-sided displacement power spectral density (m^3, i.e. m^2 per
cycle/m) of ISO 8608:

    Gd(n) = Gd(n0) (n / n0)^-w,    n0 = 0.1 cycles/m,

``n`` the spatial frequency (cycles/m) and ``w`` the waviness (2 in the
standard's classification). The classes A-H differ by a factor 4 in
``Gd(n0)``; :data:`ROAD_CLASSES` holds each class's geometric mean (A: 16e-6,
B: 64e-6, C: 256e-6, D: 1024e-6, E: 4096e-6 m^3, ...), and a class spans a
factor 2 either side of it (the boundaries are the geometric means between
neighbouring classes: B is 32e-6 <= Gd(n0) < 128e-6). The spectrum is
generated and fitted over the standard's band ``n`` in 0.011-2.83 cycles/m
(wavelengths 0.35-90 m).

**Left and right wheel paths.** The two paths, a lateral distance ``B``
(the track width) apart, have the same spectrum; how alike they are at each
``n`` is their coherency ``rho(n) = G_LR(n) / Gd(n)`` (real: neither path
leads). The model is the isotropic road of Dodds and Robson (J. Sound Vib.
31(2), 1973, "The description of road surface roughness"), stretched
across the road by a factor ``a`` (the parameter ``coherence``): a surface
whose two-dimensional spectrum depends only on the wavenumber's length has,
along two parallel lines ``B`` apart, with ``Gd ~ n^-w``,

    rho(n) = 2^(1 - nu) / Gamma(nu) * z^nu K_nu(z),   nu = w / 2,   z = 2 pi n B / a,

``K_nu`` the modified Bessel function of the second kind (for ``w = 2``:
``rho = z K_1(z)``). ``a = 1`` is the isotropic road; ``a > 1`` a road
whose features are ``a`` times longer across than along (the paths more
alike), ``a < 1`` shorter; ``a = inf`` gives two identical paths and
``a = 0`` two independent ones. The ordinary coherence that
``scipy.signal.coherence`` estimates is ``rho(n)^2``.

**Generation** (:func:`iso8608_profile`): a sum of cosines with random
phases on the spectral lines ``n_k = k / L_s`` of a synthesis length
``L_s`` at least the road's length and at least 16 wavelengths of the band's
lowest frequency, each path the sum of a part common to both (power
``rho Gd``) and a part of its own (power ``(1 - rho) Gd``):

    z_L(x) = sum_k A_k [sqrt(rho_k) cos(2 pi n_k x + p_k) + sqrt(1 - rho_k) cos(2 pi n_k x + q_k)]
    z_R(x) = sum_k A_k [sqrt(rho_k) cos(2 pi n_k x + p_k) + sqrt(1 - rho_k) cos(2 pi n_k x + r_k)]

with ``A_k = sqrt(2 Gd(n_k) / L_s)`` for the lines inside the band (none
outside it) and ``p, q, r`` independent phases uniform on ``[0, 2 pi)``.
Each path then has the expected spectrum ``Gd(n_k)`` and the pair the
cross-spectrum ``rho_k Gd(n_k)``; the sum is evaluated by one inverse FFT.
The phases come from the :class:`numpy.random.Generator` given: the same
seed gives the same road.

**Classification** (:func:`iso8608_fit`, :func:`iso8608_class`): the
periodogram ``P(n_k)`` of the record (Hann window, mean removed, density
scaling) over the part of the band it covers (:func:`fit_band`), and the
``Gd(n0)`` of a ``(n/n0)^-w`` line through it with equal weight per
logarithm of frequency (per octave, as the standard's fit in log-log
co-ordinates):

    Gd(n0) = sum_k P(n_k) (n_k / n0)^w (dn / n_k)  /  sum_k (dn / n_k),

which is exact, in expectation, for a road of that spectrum, and gives for
a sinusoid ``A cos(2 pi n1 x)`` on a spectral line in the band, with
``w = 2``, ``Gd(n0) = A^2 n1 / (2 n0^2 S)``, ``S = sum_k dn / n_k``
(about ``ln(n_hi / n_lo)``).

Pure functions over arrays: no files, no printing.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ArgumentError

#: the reference spatial frequency of ISO 8608, cycles/m
N0 = 0.1
#: the spatial-frequency band of ISO 8608 (cycles/m): wavelengths 90 m to 0.35 m
ISO_BAND = (0.011, 2.83)
#: each class's geometric-mean Gd(n0) (m^3), ISO 8608; a class spans a factor 2 either side
ROAD_CLASSES: dict[str, float] = {c: 16e-6 * 4.0 ** i for i, c in enumerate("ABCDEFGH")}
#: the lowest number of cycles of a frequency a record must hold to be fitted (:func:`fit_band`)
FIT_MIN_CYCLES = 4.0
#: the fit's highest frequency as a fraction of the record's Nyquist frequency (:func:`fit_band`)
FIT_NYQUIST_FRACTION = 0.5
#: the synthesis length holds at least this many wavelengths of the band's lowest frequency
SYNTHESIS_CYCLES = 16.0


def class_gd(road_class) -> float:
    """``Gd(n0)`` (m^3) of an ISO 8608 class letter (its geometric mean), or a positive number as it is."""
    if isinstance(road_class, str):
        key = road_class.strip().upper()
        if key not in ROAD_CLASSES:
            raise ArgumentError(f"unknown ISO 8608 road class {road_class!r}; classes are "
                                f"{', '.join(ROAD_CLASSES)}")
        return ROAD_CLASSES[key]
    if (isinstance(road_class, bool) or not isinstance(road_class, (int, float))
            or not (math.isfinite(road_class) and road_class > 0)):
        raise ArgumentError(f"road class must be a letter A-H or a positive Gd(n0) in m^3, got {road_class!r}")
    return float(road_class)


def class_of(gd_n0: float) -> str:
    """The ISO 8608 class whose range holds ``Gd(n0)`` (m^3): boundaries at the geometric means
    between neighbouring classes (A below 32e-6, B up to 128e-6, ..., H from 131072e-6 up)."""
    if not (math.isfinite(gd_n0) and gd_n0 >= 0):
        raise ArgumentError(f"Gd(n0) must be a non-negative number (m^3), got {gd_n0!r}")
    for c, g in ROAD_CLASSES.items():
        if gd_n0 < 2.0 * g:
            return c
    return "H"


def iso8608_psd(n, road_class, waviness: float = 2.0):
    """One-sided displacement PSD ``Gd(n) = Gd(n0) (n/n0)^-w`` (m^3) at spatial frequencies ``n`` (cycles/m).

    Parameters
    ----------
    n : array_like
        Spatial frequencies, cycles/m (positive).
    road_class : str or float
        A class letter (A-H, its geometric-mean ``Gd(n0)``) or ``Gd(n0)`` in m^3.
    waviness : float
        The exponent ``w`` (ISO 8608: 2).
    """
    return class_gd(road_class) * (np.asarray(n, dtype=float) / N0) ** (-float(waviness))


def road_coherency(n, track_width: float, *, waviness: float = 2.0, coherence: float = 1.0):
    """Coherency ``rho(n) = G_LR / Gd`` of two wheel paths ``track_width`` (m) apart (module docstring).

    ``rho = 2^(1-nu)/Gamma(nu) z^nu K_nu(z)``, ``nu = w/2``, ``z = 2 pi n track_width / coherence``:
    the isotropic road of Dodds and Robson for ``coherence = 1``, identical
    paths for ``coherence = inf``, independent ones for ``coherence = 0``.
    The squared coherence (``scipy.signal.coherence``) is ``rho**2``.

    Parameters
    ----------
    n : array_like
        Spatial frequencies, cycles/m (non-negative).
    track_width : float
        Lateral distance of the two paths, m.
    waviness : float
        ``w`` of the paths' spectrum ``(n/n0)^-w``, positive.
    coherence : float
        The lateral stretch ``a`` of the isotropic road, in ``[0, inf]``.

    Returns
    -------
    ndarray, the shape of ``n``, values in ``[0, 1]``.
    """
    from scipy.special import gamma, kve

    _check_shape_keys(track_width, waviness, coherence)
    n = np.asarray(n, dtype=float)
    if coherence == 0:
        return np.where(n == 0, 1.0, 0.0)
    nu = 0.5 * float(waviness)
    z = 2 * np.pi * n * track_width / coherence
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        # z^nu K_nu(z) = z^nu kve(nu, z) e^-z: no overflow of K_nu near 0, no underflow far out
        rho = 2.0 ** (1 - nu) / gamma(nu) * z ** nu * kve(nu, z) * np.exp(-z)
    return np.clip(np.where(z > 0, np.nan_to_num(rho, nan=0.0), 1.0), 0.0, 1.0)


def _check_shape_keys(track_width, waviness, coherence):
    if not (math.isfinite(track_width) and track_width > 0):
        raise ArgumentError(f"track_width must be a positive number of metres, got {track_width!r}")
    if not (math.isfinite(waviness) and 0 < waviness <= 5):
        raise ArgumentError(f"waviness must be a number in (0, 5] (ISO 8608: 2), got {waviness!r}")
    if math.isnan(coherence) or coherence < 0:
        raise ArgumentError(f"coherence must be a number in [0, inf] (1: the isotropic road), got {coherence!r}")


def _check_band(n_band):
    lo, hi = (float(v) for v in n_band)
    if not (0 < lo < hi and math.isfinite(hi)):
        raise ArgumentError(f"n_band must be (lower, upper) cycles/m with 0 < lower < upper, got {n_band!r}")
    return lo, hi


def iso8608_profile(road_class, length: float, rng, *, dx: float = 0.05, x0: float = 0.0,
                    track_width: float = 1.5, waviness: float = 2.0, coherence: float = 1.0,
                    n_band=ISO_BAND):
    """A random road of an ISO 8608 class under two wheel paths (module docstring: the method).

    Parameters
    ----------
    road_class : str or float
        A class letter A-H (its geometric-mean ``Gd(n0)``) or ``Gd(n0)`` in m^3.
    length : float
        Road length, m: the samples run from ``x0`` to ``x0 + length``.
    rng : numpy.random.Generator
        The source of the phases (the same seed, the same road).
    dx : float
        Sample spacing, m; the band's upper end must lie below the Nyquist frequency ``1/(2 dx)``.
    x0 : float
        Position of the first sample, m.
    track_width : float
        Lateral distance of the left and right wheel paths, m.
    waviness : float
        ``w`` of ``Gd(n) = Gd(n0) (n/n0)^-w`` (ISO 8608: 2).
    coherence : float
        Lateral stretch ``a`` of the isotropic road (:func:`road_coherency`): 1 isotropic,
        ``inf`` identical paths, 0 independent paths.
    n_band : (float, float)
        Spatial frequencies (cycles/m) the road holds; none outside.

    Returns
    -------
    x, z_left, z_right : ndarray, shape (n,)
        Positions ``x0 + k dx`` (k = 0 .. floor(length/dx)) and the two paths' heights, m.
    """
    if not isinstance(rng, np.random.Generator):
        raise ArgumentError("rng must be a numpy.random.Generator (e.g. numpy.random.default_rng(seed))")
    gd0 = class_gd(road_class)
    _check_shape_keys(track_width, waviness, coherence)
    lo, hi = _check_band(n_band)
    if not (math.isfinite(dx) and dx > 0):
        raise ArgumentError(f"dx must be a positive number of metres, got {dx!r}")
    if not (math.isfinite(length) and length > 0):
        raise ArgumentError(f"length must be a positive number of metres, got {length!r}")
    if hi >= 0.5 / dx:
        raise ArgumentError(f"dx = {dx:g} m samples up to {0.5 / dx:g} cycles/m, not above the band's upper "
                            f"end {hi:g} cycles/m: take dx below {0.5 / hi:g} m")
    from scipy.fft import irfft, next_fast_len

    n = int(math.floor(length / dx + 1e-9)) + 1
    n_syn = next_fast_len(max(n, int(math.ceil(SYNTHESIS_CYCLES / (lo * dx)))), real=True)
    n_syn += n_syn % 2
    L_s = n_syn * dx
    k = np.arange(n_syn // 2 + 1)
    nk = k / L_s
    inside = (nk >= lo) & (nk <= hi)
    amp = np.where(inside, np.sqrt(2.0 * gd0 * (np.where(inside, nk, 1.0) / N0) ** (-waviness) / L_s), 0.0)
    rho = road_coherency(nk, track_width, waviness=waviness, coherence=coherence)
    p, q, r = (np.exp(2j * np.pi * rng.random(k.size)) for _ in range(3))
    common = np.sqrt(rho) * p
    own = np.sqrt(1.0 - rho)
    # irfft(X) = (1/N) [X_0 + 2 Re sum_k X_k e^(2 pi i k j / N) + ...]: X_k = N/2 A_k e^(i phase) sums the cosines
    scale = 0.5 * n_syn * amp
    z_left = irfft(scale * (common + own * q), n_syn)[:n]
    z_right = irfft(scale * (common + own * r), n_syn)[:n]
    return x0 + dx * np.arange(n), z_left, z_right


def fit_band(length: float, dx: float, n_band=ISO_BAND) -> tuple[float, float]:
    """The part ``(n_lo, n_hi)`` (cycles/m) of ``n_band`` a record of ``length`` m sampled every ``dx`` m covers.

    ``n_lo = max(n_band[0], FIT_MIN_CYCLES / length)`` (at least four cycles in the
    record), ``n_hi = min(n_band[1], FIT_NYQUIST_FRACTION / (2 dx))`` (half the
    Nyquist frequency). :class:`rideid.ArgumentError` when nothing is left.
    """
    lo, hi = _check_band(n_band)
    n_lo = max(lo, FIT_MIN_CYCLES / length)
    n_hi = min(hi, FIT_NYQUIST_FRACTION * 0.5 / dx)
    if not n_lo < n_hi:
        raise ArgumentError(f"a road record of {length:g} m sampled every {dx:g} m covers no part of the band "
                            f"{lo:g}-{hi:g} cycles/m (it needs at least {FIT_MIN_CYCLES:g} cycles of a frequency "
                            "in the band): too short or too coarse to classify")
    return n_lo, n_hi


def _uniform_step(x) -> float:
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or x.size < 8:
        raise ArgumentError(f"x must be a 1-D array of at least 8 positions, got shape {x.shape}")
    d = np.diff(x)
    h = (x[-1] - x[0]) / (x.size - 1)
    if not (h > 0 and np.all(np.abs(d - h) <= 1e-6 * h)):
        raise ArgumentError("x must be uniform and increasing (resample the road first)")
    return float(h)


def iso8608_fit(x, z, *, waviness: float = 2.0, n_band=ISO_BAND) -> float:
    """``Gd(n0)`` (m^3) of the ``(n/n0)^-w`` line that fits a road record (module docstring: the fit).

    Parameters
    ----------
    x : array_like, shape (n,)
        Uniform positions, m.
    z : array_like, shape (n,) or (n, k)
        Heights, m; with ``k`` columns (e.g. left and right paths) their periodograms are averaged.
    waviness : float
        The fixed ``w`` of the line (ISO 8608 classifies with 2).
    n_band : (float, float)
        The band to fit, cycles/m, cut to what the record covers (:func:`fit_band`).
    """
    from scipy.signal import periodogram

    dx = _uniform_step(x)
    z = np.asarray(z, dtype=float)
    if z.shape[0] != np.asarray(x).size or z.ndim not in (1, 2):
        raise ArgumentError(f"z must have shape (n,) or (n, k) with n = {np.asarray(x).size}, got {z.shape}")
    if not np.all(np.isfinite(z)):
        raise ArgumentError("z holds NaN or infinite heights")
    n_lo, n_hi = fit_band(dx * z.shape[0], dx, n_band)
    f, P = periodogram(z, fs=1.0 / dx, window="hann", detrend="constant", scaling="density", axis=0)
    if P.ndim == 2:
        P = P.mean(axis=1)
    band = (f >= n_lo) & (f <= n_hi)
    fk, Pk = f[band], P[band]
    wgt = 1.0 / fk  # dn / n_k: equal weight per octave (dn cancels)
    return float(np.sum(Pk * (fk / N0) ** waviness * wgt) / np.sum(wgt))


def iso8608_class(x, z, *, n_band=ISO_BAND) -> tuple[str, float]:
    """``(class letter, Gd(n0))`` of a road record: :func:`iso8608_fit` with ``w = 2``, then :func:`class_of`.

    Parameters
    ----------
    x : array_like, shape (n,)
        Uniform positions, m.
    z : array_like, shape (n,) or (n, k)
        Heights, m; with ``k`` columns (e.g. both wheel paths) their periodograms are averaged.
    n_band : (float, float)
        The band to fit, cycles/m, cut to what the record covers (:func:`fit_band`).

    Returns
    -------
    (str, float)
        The ISO 8608 class (A-H) and the fitted ``Gd(n0)``, m^3.
    """
    gd = iso8608_fit(x, z, waviness=2.0, n_band=n_band)
    return class_of(gd), gd


__all__ = ["N0", "ISO_BAND", "ROAD_CLASSES", "class_gd", "class_of", "iso8608_psd", "road_coherency",
           "iso8608_profile", "fit_band", "iso8608_fit", "iso8608_class"]
