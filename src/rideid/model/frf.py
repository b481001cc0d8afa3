"""Frequency responses of the linear car and their measured counterpart (SPEC §13): pure kernels over arrays.

**The model's response.** The car of :func:`rideid.model.equations.state_space`,
``x' = A x + B r + Br r'``, ``y = Cy x + Dy r + Dyr r'``, driven by road inputs
``r = R e^{st}`` at ``s = j 2 pi f`` answers ``Y = H(s) R`` with

    H(s) = Cy (sI - A)^{-1} (B + s Br) + Dy + s Dyr

(``Br``, ``Dyr`` zero without tire damping). :func:`frequency_response` gives
``H`` for the ten channels of SPEC §1 (:data:`rideid.model.equations.CHANNELS`:
accelerations in m/s² and rates in rad/s per metre of road input) and for the
body's ``heave`` (m/m), ``pitch`` and ``roll`` (rad/m, ISO 8855 signs)
displacements at the CG (:data:`OUTPUTS`). So ``heave`` from the four wheels in
phase is the classic transmissibility, 1 at 0 Hz; an acceleration channel's
transmissibility (acceleration over road acceleration) is ``-H / (2 pi f)^2``.

**The measured response** (:func:`h1_estimate`): the H1 estimator over
Welch-averaged spectra of any inputs (the road under each wheel from a track's
geometry, a rig's measured post displacements) and outputs. With several
inputs (Bendat & Piersol, *Random Data*, 4th ed., ch. 7) the response to input
``j`` is the conditioned ratio

    H_yj = G_jy.R / G_jj.R,   G_ab.R = G_ab - G_aR G_RR^+ G_Rb

(``R`` the other inputs: what input ``j`` carries beyond them), equal to
``G_yx G_xx^{-1}`` where ``G_xx`` is invertible, and its **coherence** is the
partial coherence ``|G_jy.R|^2 / (G_jj.R G_yy.R)``: near 1 only where input
``j`` has power of its own (not a copy of another wheel's, as on a washboard
both wheels of an axle see the same road) and the output follows it. With
one input these are the ordinary H1 and coherence. Spectra of several runs
are summed segment by segment (the car is one linear system): runs at other
speeds shift the front-to-rear delay, so together they separate what one run
cannot. The random error of ``|H|`` is ``sqrt(1 - g^2) / (|g| sqrt(2 n_d))``
relative (Bendat & Piersol eq. 9.65, ``n_d`` segments).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import get_window

from .equations import CHANNELS, CHANNEL_UNITS, state_space
from .params import Geometry

#: The inputs: the road height under each wheel, m (SPEC §10's FMU names).
INPUTS: tuple[str, ...] = ("r_fl", "r_fr", "r_rl", "r_rr")
#: The outputs: the ten channels of SPEC §1, then the body's CG displacements.
BODY_MOTIONS: tuple[str, ...] = ("heave", "pitch", "roll")
OUTPUTS: tuple[str, ...] = CHANNELS + BODY_MOTIONS
#: Unit of ``H`` per output (per metre of road input).
OUTPUT_UNITS = {**{c: f"({u})/m" for c, u in CHANNEL_UNITS.items()}, "heave": "m/m", "pitch": "rad/m",
                "roll": "rad/m"}
#: Index of each body motion's coordinate in the state (``q`` of :data:`rideid.model.equations.COORDS`).
_MOTION_STATE = {"heave": 0, "pitch": 1, "roll": 2}

#: The default frequencies (Hz) of a response: log-spaced over the ride band, body modes to wheel hop and past.
DEFAULT_FMIN, DEFAULT_FMAX, DEFAULT_POINTS = 0.2, 30.0, 240


def default_frequencies() -> np.ndarray:
    """:data:`DEFAULT_POINTS` frequencies (Hz), log-spaced from :data:`DEFAULT_FMIN` to :data:`DEFAULT_FMAX`."""
    return np.geomspace(DEFAULT_FMIN, DEFAULT_FMAX, DEFAULT_POINTS)


def frequency_response(P, geom: Geometry, freq) -> np.ndarray:
    """The complex response of a batch of cars at frequencies ``freq``.

    Parameters
    ----------
    P : array_like, shape (n, 12), (n, 16) or (n, 23)
        Parameter rows (:data:`rideid.model.params.ALL_NAMES` order, absent extensions 0).
    geom : Geometry
    freq : array_like, shape (n_freq,)
        Hz (0 allowed: the static gain).

    Returns
    -------
    H : ndarray, complex, shape (n, n_freq, 13, 4)
        Outputs :data:`OUTPUTS` per unit of each road input :data:`INPUTS` (units :data:`OUTPUT_UNITS`).
    """
    freq = np.atleast_1d(np.asarray(freq, dtype=float))
    A, B, Cy, Dy, Br, Dyr = state_space(P, geom, rate=True)
    n = A.shape[0]
    s = 2j * np.pi * freq  # (f,)
    # (sI - A)^{-1} = V diag(1 / (s - lambda)) V^{-1}: one eigendecomposition per car, not one solve per frequency
    lam, V = np.linalg.eig(A)
    Vi = np.linalg.inv(V)
    VB, VBr = Vi @ B, Vi @ Br  # (n, ns, 4)
    modal = 1.0 / (s[None, :, None] - lam[:, None, :])  # (n, f, ns)
    X = V[:, None] @ (modal[..., None] * (VB[:, None] + s[None, :, None, None] * VBr[:, None]))  # (n, f, ns, 4)
    H = np.empty((n, freq.size, len(OUTPUTS), B.shape[-1]), dtype=complex)
    H[:, :, :len(CHANNELS)] = (Cy[:, None] @ X + Dy[:, None] + s[None, :, None, None] * Dyr[:, None])
    for k, name in enumerate(BODY_MOTIONS):
        H[:, :, len(CHANNELS) + k] = X[:, :, _MOTION_STATE[name]]
    return H


# ---------------------------------------------------------------------------
# The measured response: H1 over records (transient runs) or Welch segments (stationary ones)

#: Default Welch segment length, s (frequency resolution 1 / segment), for long stationary runs (a rig's random
#: input, a road); None: each run is one record (transient runs, below).
SEGMENT_S = None
#: Adjacent frequency bins averaged into one estimate (Daniell band averaging) when each run is one record.
BAND_BINS = 1
#: An input whose own power in a bin is below this share of its largest bin's is not exciting the car there:
#: no estimate (measured: a rig's posts swept to 20 Hz carry 1e-9 of their peak power at 25 Hz, and with five
#: records and four inputs the partial coherence of the noise left there exceeds 0.9 in one bin of ten, which the
#: report drew as measured points 100x off the car)
EXCITATION_FLOOR = 1e-6


def _spectra(runs, segment, overlap, m, p):
    """Per run the (density-scaled) DFTs ``(n_blocks, nf, m + p)`` of inputs then outputs, on one frequency grid
    ``k / T`` (``T`` the segment, or the longest run), and the grid."""
    if segment is None:
        T = max(X.shape[0] / fs for fs, X, _ in runs)
    else:
        T = float(segment)
    fmax = min(fs for fs, _, _ in runs) / 2
    k = np.arange(1, int(np.floor(fmax * T)) + 1)
    blocks = []
    for fs, X, Y in runs:
        n_fft = int(round(T * fs))
        Z = np.concatenate([X, Y], axis=1)
        if segment is None:  # the whole run, at rest before and after: rectangular window, zero-padded
            w = np.ones(min(Z.shape[0], n_fft))
            idx = np.arange(w.size)[None]
        else:
            step = max(1, int(round(n_fft * (1 - overlap))))
            starts = np.arange(0, Z.shape[0] - n_fft + 1, step) if Z.shape[0] >= n_fft else np.zeros(0, int)
            if starts.size == 0:
                continue
            w = get_window("hann", n_fft)  # periodic (DFT-even), as scipy.signal.welch's
            idx = starts[:, None] + np.arange(n_fft)
        seg = Z[idx]
        if segment is not None:  # a stationary run's mean is no response
            seg = seg - seg.mean(axis=1, keepdims=True)
        seg = seg * w[None, :, None]
        # energy spectral density of a record (a transient: each run weighs by its energy), power spectral
        # density of a segment; either way in the same units whatever a run's sample rate
        norm = fs if segment is None else fs * np.sum(w * w)
        F = np.fft.rfft(seg, n=n_fft, axis=1)[:, k] / np.sqrt(norm)
        blocks.append(F)
    return blocks, k / T


def h1_estimate(runs, segment: float | None = SEGMENT_S, overlap: float = 0.5, bins: int | None = None) -> dict:
    """The H1 estimate of a linear system's response from measured inputs and outputs of one or more runs.

    Parameters
    ----------
    runs : sequence of (fs, X, Y)
        Per run the sample rate ``fs`` (Hz), inputs ``X`` (n, m) and outputs ``Y`` (n, p) at the same samples
        (NaN in an output column: that output is not measured in this run; it leaves the run, or with
        ``segment`` the segment, out of that output's spectra). Every run has the same ``m`` inputs and ``p``
        outputs, in the same order.
    segment : float or None
        None (default): each run is one record, the system at rest at its start and end (a proving-ground
        run: flat road before and after the feature), rectangular window, zero-padded to the longest run.
        A number: Welch segments of that length (s), Hann windows, for long stationary runs.
    overlap : float
        Welch segment overlap, fraction.
    bins : int, optional
        Adjacent frequency bins averaged into one estimate (default :data:`BAND_BINS` for records, 1 for Welch).

    Returns
    -------
    dict with
        ``freq`` (n_f,) Hz (band centres); ``H`` complex (n_f, p, m): output per unit input; ``coherence``
        (n_f, p, m): the partial coherence of each output with each input given the other inputs (the ordinary
        coherence with one input); ``multiple_coherence`` (n_f, p): of each output with all inputs;
        ``std_abs`` (n_f, p, m): the random error (std) of ``|H|``; ``own_power`` (n_f, p, m): the share of each
        input's power that the other inputs do not carry (``G_jj.R / G_jj``: 0 for a copy of another wheel's
        road, 1 for an input of its own); ``averages`` (p,): spectra averaged per
        estimate (records or segments, times ``bins``).
    """
    runs = [(float(fs), np.asarray(X, dtype=float), np.asarray(Y, dtype=float)) for fs, X, Y in runs]
    if not runs:
        raise ValueError("h1_estimate: no runs")
    m, p = runs[0][1].shape[1], runs[0][2].shape[1]
    for fs, X, Y in runs:
        if X.ndim != 2 or X.shape[1] != m or Y.shape != (X.shape[0], p) or not fs > 0:
            raise ValueError(f"h1_estimate: every run needs fs > 0, X (n, {m}) and Y (n, {p}) at the same samples, "
                             f"got fs {fs}, {X.shape} and {Y.shape}")
    bins = (BAND_BINS if segment is None else 1) if bins is None else int(bins)
    blocks, freq_all = _spectra(runs, segment, overlap, m, p)
    nf = freq_all.size // bins
    if nf == 0 or not blocks:
        raise ValueError("h1_estimate: no run is as long as one segment")
    freq_all = freq_all[:nf * bins]
    # spectral matrix of [inputs, output] per output: S[o, f] = sum over blocks and band of conj(F) F^T
    S = np.zeros((p, nf, m + 1, m + 1), dtype=complex)
    count = np.zeros(p)
    for F in blocks:
        F = F[:, :nf * bins].reshape(F.shape[0], nf, bins, m + p)
        for o in range(p):
            good = np.all(np.isfinite(F[:, :, :, m + o]), axis=(1, 2))
            if not good.any():
                continue
            G = np.concatenate([F[good][..., :m], F[good][..., m + o:m + o + 1]], axis=-1)
            S[o] += np.einsum("sfba,sfbc->fac", G.conj(), G)
            count[o] += good.sum() * bins
    freq = freq_all.reshape(nf, bins).mean(axis=1)
    H = np.full((nf, p, m), np.nan + 0j)
    coh = np.zeros((nf, p, m))
    mult = np.zeros((nf, p))
    std = np.full((nf, p, m), np.nan)
    own = np.full((nf, p, m), np.nan)
    for o in range(p):
        if count[o] == 0:
            coh[:, o] = np.nan
            mult[:, o] = np.nan
            continue
        Sxx, Sxy, Syy = S[o, :, :m, :m], S[o, :, :m, m], S[o, :, m, m].real
        floor = np.maximum(1e-9 * np.trace(Sxx, axis1=-2, axis2=-1).real[:, None],  # power below this is none
                           EXCITATION_FLOOR * np.max(np.diagonal(Sxx, axis1=-2, axis2=-1).real, axis=0)[None, :])
        for j in range(m):
            rest = [i for i in range(m) if i != j]
            if rest:
                Srr_inv = np.linalg.pinv(Sxx[:, rest][:, :, rest], rcond=1e-9, hermitian=True)
                Sjr, Sry = Sxx[:, j, rest], Sxy[:, rest]
                Srj = Sxx[:, rest, j]
                Sjj = Sxx[:, j, j].real - np.einsum("fa,fab,fb->f", Sjr, Srr_inv, Srj).real
                Sjy = Sxy[:, j] - np.einsum("fa,fab,fb->f", Sjr, Srr_inv, Sry)
                Syr = Sxy[:, rest].conj()
                Syy_r = Syy - np.einsum("fa,fab,fb->f", Syr, Srr_inv, Sry).real
            else:
                Sjj, Sjy, Syy_r = Sxx[:, j, j].real, Sxy[:, j], Syy
            ok = (Sjj > floor[:, j]) & (Syy_r > 0)
            with np.errstate(invalid="ignore", divide="ignore"):
                own[:, o, j] = np.clip(Sjj / Sxx[:, j, j].real, 0.0, 1.0)
            with np.errstate(invalid="ignore", divide="ignore"):
                H[:, o, j] = np.where(ok, Sjy / np.where(ok, Sjj, 1.0), np.nan)
                g2 = np.where(ok, np.abs(Sjy) ** 2 / np.where(ok, Sjj * Syy_r, 1.0), 0.0)
            g2 = np.clip(g2, 0.0, 1.0)
            coh[:, o, j] = g2
            with np.errstate(invalid="ignore", divide="ignore"):
                dof = max(count[o] - m + 1, 1.0)  # the other inputs' spectra take m - 1 averages' worth
                std[:, o, j] = np.abs(H[:, o, j]) * np.sqrt((1 - g2) / (2 * dof * g2))
        with np.errstate(invalid="ignore", divide="ignore"):
            Sxx_inv = np.linalg.pinv(Sxx, rcond=1e-9, hermitian=True)
            explained = np.einsum("fa,fab,fb->f", Sxy.conj(), Sxx_inv, Sxy).real
            mult[:, o] = np.clip(np.where(Syy > 0, explained / np.where(Syy > 0, Syy, 1.0), 0.0), 0.0, 1.0)
    return {"freq": freq, "H": H, "coherence": coh, "multiple_coherence": mult, "std_abs": std, "own_power": own,
            "averages": np.where(count > 0, count, np.nan)}


__all__ = ["INPUTS", "OUTPUTS", "BODY_MOTIONS", "OUTPUT_UNITS", "SEGMENT_S", "BAND_BINS", "EXCITATION_FLOOR",
           "default_frequencies", "frequency_response", "h1_estimate"]
