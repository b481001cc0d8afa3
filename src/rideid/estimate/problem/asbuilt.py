"""Tracks as built (SPEC §11): the declared track is the nominal shape, the road under each wheel path is what
the car rolled over.

The model
---------
A proving-ground track is never its drawing: its amplitudes are a few per
cent off and it carries 1-2 mm RMS of unevenness. A run on such a track is
fitted like a run on an unknown road (:mod:`rideid.estimate.problem.roadfit`: the
channels' DFT, 0.2-25 Hz, the car linear, the state at the first sample and
the rear wheels' lead-in as free boundary unknowns), except that the road
is not free: at each frequency ``omega`` of the run's DFT

    Y = alpha H U + A delta + (boundary terms) + noise,

``U`` (4,) the DFT of the drawn track's four corner inputs (the rigid-disc
envelope of SPEC §2), ``alpha`` the track's amplitude factor (one real
unknown per run), ``A`` (c x 2) the left and right wheel paths' columns of
:mod:`rideid.estimate.problem.roadfit` (rear through the delay) and ``delta`` the
unevenness under the front wheels, a complex Gaussian with variance
``sigma_d^2(omega)`` per path, independent of the sensor noise (variance
``sigma_n^2(omega)`` per weighted channel). Integrating ``delta`` out, each
bin's data ``x = Y - alpha H U - boundary`` is Gaussian with covariance
``sigma_n^2 M``, ``M = I + A D A^H``, ``D = sigma_d^2 / sigma_n^2``, and the
negative log-likelihood is, per bin,

    x^H M^-1 x / sigma_n^2 + log det M.

The residual the least squares see is ``M^(-1/2) x / sigma_n`` (``M^(-1/2)``
from the eigen-decomposition of the 2 x 2 matrix ``D A^H A``) followed by
``sqrt(log det M)``: without that log-determinant the fit would prefer cars
whose ``A`` is large (more of the data explained as road) and be biased.
The boundary unknowns and ``alpha`` enter linearly and are solved at every
trial car (variable projection), as on an unknown road.

The unevenness spectrum is estimated from the data (empirical Bayes,
:func:`estimate_prior`), at the start car and again at the first solution:
the road is projected out (an unknown road's fit), the free road estimate
``R`` is regressed on the drawn front road for ``alpha``, and the deviation's
power ``|R - alpha U_front|^2``, less the part the sensor noise puts into
``R`` (``sigma_n^2 (A^H A)^-1``), averaged over both paths and
setting ``asbuilt.smooth_bins`` neighbouring bins, is ``sigma_d^2``, floored at
setting ``asbuilt.prior_floor`` of that noise part. On an exact track ``sigma_d`` comes
out near that floor and the fit is the known-road fit; where the track
carries unevenness the prior widens and the road there is learnt.

Sensors as wired (SPEC §11): a channel with a declared ``highpass`` or ``lowpass`` is compared as its sensor
records it: ``H`` (the drawing's response included) and the boundary columns through the filter's
first-order-hold response, the filters' states at the first sample among the boundary unknowns
(:func:`rideid.estimate.problem.roadfit.recorded_columns`).

Limits (between the two limits of the prior): ``D = 0`` is the drawn track
with an amplitude factor (:data:`MODES` "amplitude"), ``D`` infinite the
unknown road ("free", the road projected out; no log-determinant). Both
are kept for comparison (benchmarks/bench_tracks.py, docs/tracks-as-built.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg

from ...profiling import stage
from ...settings import defaults, legacy_names
from ...model.simulate import RunInput, corner_inputs, prepare_run
from . import roadfit

#: the prior's variants: "prior" (the default, an estimated unevenness spectrum), "amplitude" (no
#: unevenness: the drawn track times a fitted amplitude factor), "free" (the road projected out)
MODES = ("prior", "amplitude", "free")


@dataclass
class Prior:
    """A run's noise and unevenness levels per fit bin: ``noise`` (K,) ``sigma_n^2`` (weighted channels, per
    bin), ``D`` (K,) ``sigma_d^2 / sigma_n^2`` (m^2 per unit of weighted channel^2), ``unevenness`` (K,)
    ``sigma_d^2`` (m^2 per bin of the DFT), ``alpha`` the amplitude factor it was estimated with."""

    noise: np.ndarray
    D: np.ndarray
    unevenness: np.ndarray
    alpha: float
    #: why the unevenness is held at the prior's floor, not estimated (None: estimated; :func:`estimate_prior`)
    held: str | None = None


@dataclass
class TrackRun:
    """One run on a declared track, prepared for the as-built fit.

    Attributes
    ----------
    rr : roadfit.RoadRun
        The run's channels as an unknown-road run (weights, DFT, fit bins, delay).
    track : str
        The ``[[tracks]]`` id.
    U : (nbins, 4) complex
        DFT of the drawn track's corner inputs fl, fr, rl, rr (m), every bin.
    mode : str
        One of :data:`MODES`.
    prior : Prior or None
        Set by :func:`estimate_prior` (needed in mode "prior"; the noise level in every mode).
    inputs : rideid.model.simulate.RunInput or None
        The drawn track's corner inputs and their rates at the run's samples (:func:`nominal_inputs`, tabulated
        once by :func:`prepare_track_run`; ``U`` is their DFT): what the verdict compares the residual with.
    """

    rr: roadfit.RoadRun
    track: str
    U: np.ndarray
    mode: str = "prior"
    prior: Prior | None = field(default=None, repr=False)
    inputs: RunInput | None = field(default=None, repr=False)
    #: the drawing's time shift (s): the front axle at ``x = speed (t - shift)`` (``TrackBlock.aligned``)
    shift: float = 0.0
    #: SPEC §13: the relative std of the track's drawn size (the amplitude factor's prior about 1; None: free)
    size_std: float | None = None

    @property
    def run_id(self) -> str:
        return self.rr.run_id

    @property
    def fit(self) -> np.ndarray:
        return self.rr.fit

    @property
    def per_bin(self) -> int:
        """Residual entries per DFT bin (real and imaginary part of each channel, and the log-determinant)."""
        return 2 * len(self.rr.cols) + (self.mode == "prior")


def nominal_inputs(ds, run, speed=None, shift: float = 0.0):
    """The drawn track's corner inputs of ``run`` (:class:`rideid.model.simulate.RunInput`), as the fit of the
    track as drawn tabulates them; ``speed`` (default the run's) and ``shift`` (s): the front axle at
    ``x = speed (t - shift)`` (a run placed by :meth:`rideid.estimate.problem.blocks.TrackBlock.aligned`)."""
    rd = ds.data[run.id]
    v = float(run.speed) if speed is None else float(speed)
    return prepare_run(ds.manifest.tracks[run.track], ds.geometry, v, rd.time - shift if shift else rd.time)


def held_speed(ds, run) -> float:
    """The run's constant speed (m/s) as the as-built road starts from: the declared one, or, along a speed or
    distance channel (a speed held, :func:`rideid.estimate.fit.anyroad.speed_wander`), the channel's mean over the
    run's samples (refined with the start by :meth:`rideid.estimate.problem.blocks.TrackBlock.aligned`)."""
    rd = ds.data[run.id]
    dist = getattr(rd, "distance", None)
    if dist is None:
        return float(run.speed)
    x = np.asarray(dist(rd.time[[0, -1]]), dtype=float)
    return float((x[1] - x[0]) / (rd.time[-1] - rd.time[0]))


def prepare_track_run(ds, run, mode: str = "prior") -> TrackRun:
    """:class:`TrackRun` of ``run`` (a run on a declared track with all eight accelerometers, a speed held): the
    drawing and the rear wheels' delay at its constant speed (:func:`held_speed`)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    rd = ds.data[run.id]
    v = held_speed(ds, run)
    rr = roadfit.prepare_road_run(run.id, rd.matrix(), rd.fs, v, ds.geometry, clipped=ds.clipped(run.id))
    rr = roadfit.with_sensors(rr, ds.sensor_filters(run.id))  # the channels as wired (SPEC §11)
    ri = nominal_inputs(ds, run, v)
    # the relative std of the track's drawn size (SPEC §13: declared, else the default width); None for a manifest
    # that has none (an older one)
    prior = getattr(ds.manifest, "size_prior", None)
    return TrackRun(rr=rr, track=run.track, U=np.fft.rfft(np.asarray(ri.u, dtype=float), axis=0), mode=mode,
                    inputs=ri, size_std=None if prior is None else float(prior(run.track)[0]))


#: the weight of the drawn size's prior row (SPEC §13): the whitened residual's real and imaginary parts each have
#: variance 1/2 (each bin's complex residual divided by its noise level), so a row ``sqrt(1/2) (alpha - 1) / std``
#: counts the prior as the negative log-likelihood does
SIZE_PRIOR_WEIGHT = float(np.sqrt(0.5))

def moved(tr: TrackRun, ds, run, p) -> TrackRun:
    """``tr`` with its drawing moved by ``p`` = (the speed's relative change, the start's shift) in
    setting ``asbuilt.motion_scale`` units: the drawing at ``x = v (t - shift)``, the rear wheels' delay at ``v`` (the
    tabulated ``inputs`` as they were: :meth:`rideid.estimate.problem.blocks.TrackBlock.aligned` renews them once)."""
    v = tr.rr.speed * (1.0 + p[0] * defaults["asbuilt.motion_scale"][0])
    shift = tr.shift + p[1] * defaults["asbuilt.motion_scale"][1]
    u = corner_inputs(ds.manifest.tracks[run.track], ds.geometry, v * (ds.data[run.id].time - shift))
    return replace(tr, rr=replace(tr.rr, speed=v, tau=ds.geometry.wheelbase / v), U=np.fft.rfft(u, axis=0),
                   shift=shift)


@dataclass(frozen=True)
class MotionPrior:
    """SPEC §13: what a run's set-up says of where the car was on the track, as priors of its motion unknowns.

    ``speed``: ``(declared m/s, std m/s, declared with a std)``, None along a speed or distance channel (the
    channel's mean starts it, unweighted); ``start``: ``(declared file time s, std s, declared with a std)``, None
    when the start was estimated at load (no declared value to hold it to). A plain number's std is the
    documented default (:data:`rideid.data.schema.manifest.SPEED_STD_DEFAULT`, ``START_STD_DEFAULT``)."""

    speed: tuple | None
    start: tuple | None

    def rows(self, v0: float, shift0: float, p, weight: float = 1.0) -> np.ndarray:
        """The prior's residual rows at the motion ``p`` (:data:`MOTION_SCALE` units) moved from the speed ``v0``
        and the start shift ``shift0`` (s) the run was placed at: ``weight (value - declared) / std``, speed then
        start, each only when it has a prior (``weight``: the run's own block's residual level, so a prior
        counts against the data as a measurement of that std would)."""
        out = []
        if self.speed is not None:
            out.append((v0 * (1.0 + p[0] * defaults["asbuilt.motion_scale"][0]) - self.speed[0]) / self.speed[1])
        if self.start is not None:
            # the shift from the start as read
            out.append((shift0 + p[1] * defaults["asbuilt.motion_scale"][1]) / self.start[1])
        return weight * np.asarray(out, dtype=float)

    def jacobian(self, v0: float, weight: float = 1.0) -> np.ndarray:
        """``(rows, 2)``: :meth:`rows`' derivatives in the speed's relative change and the start's shift (s)."""
        out = []
        if self.speed is not None:
            out.append([v0 / self.speed[1], 0.0])
        if self.start is not None:
            out.append([0.0, 1.0 / self.start[1]])
        return weight * np.asarray(out, dtype=float).reshape(-1, 2)


def speed_move_bound(v: float, sd: float) -> float:
    """How far (setting ``asbuilt.motion_scale`` units, either way) a fit may move a speed ``v`` declared with the
    std ``sd`` (m/s): setting ``anyroad.joint_motion_bound``, or four prior std where that is wider (a
    speedometer's ``speed = { value = 11.0, std = 0.4 }``)."""
    return max(float(defaults["anyroad.joint_motion_bound"]), 4.0 * sd / (v * defaults["asbuilt.motion_scale"][0]))


def motion_prior(ds, run) -> MotionPrior:
    """The :class:`MotionPrior` of ``run`` (a run on a declared track) in ``ds``: its declared speed (none along a
    speed or distance channel) and its start where it was given (a SPEC CSV's time 0, a logger file's
    ``start``), each with its declared std or the default width."""
    rd = ds.data[run.id]
    speed = None if getattr(rd, "distance", None) is not None else run.speed_prior()
    auto = run.id in getattr(ds, "auto_start_runs", ())
    mr = getattr(ds, "measured", {}).get(run.id)
    given = 0.0 if mr is None else float(mr.start or 0.0)
    start = None if auto else (given, run.start_prior_std(), run.start_std is not None)
    return MotionPrior(speed=speed, start=start)


@dataclass
class Fit:
    """The as-built fit of one run at one car: ``residual`` (K, c) whitened (``M^(-1/2) x / sigma_n``),
    ``logdet`` (K,), ``plain`` (K, c) the data less the model at the estimated road (weighted channels),
    ``alpha``, the boundary unknowns ``f_state`` (14, 18 with a powertrain, + the sensor filters' modes) and
    ``f_lead`` (2, D)."""

    residual: np.ndarray
    logdet: np.ndarray
    plain: np.ndarray
    alpha: float
    f_state: np.ndarray
    f_lead: np.ndarray
    #: the amplitude factor's standard error at this car (``solve(..., alpha_std=True)``; else NaN)
    alpha_std: float = float("nan")


def _whitener(Acol, D, mode):
    """``x -> M^(-1/2) x`` at each bin and ``log det M`` (K,); ``M = I + A D A^H`` (mode "prior"), ``I``
    ("amplitude") or the projector's limit ("free": the road's directions removed, no log-determinant)."""
    K = Acol.shape[0]
    if mode == "amplitude":
        return (lambda X: X), np.zeros(K)
    if mode == "free":
        perp, _ = roadfit._projector(Acol)
        return (lambda X: perp(X[..., None])[..., 0] if np.ndim(X) == 2 else perp(X)), np.zeros(K)
    AH = np.conj(np.swapaxes(Acol, -1, -2))
    G = (AH @ Acol) * D[:, None, None]                                      # D A^H A, (K, 2, 2) Hermitian
    ev, V = np.linalg.eigh(G)
    ev = np.clip(ev, 0.0, None)
    # U = A sqrt(D) V / sqrt(ev): orthonormal columns of the road's directions; shrink (1 - g) along them
    with np.errstate(divide="ignore", invalid="ignore"):
        U = (Acol @ V) * np.where(ev > 0, np.sqrt(D[:, None] / ev), 0.0)[:, None, :]
    shrink = 1.0 - 1.0 / np.sqrt(1.0 + ev)                                  # (K, 2)
    UH = np.conj(np.swapaxes(U, -1, -2))

    def white(X):
        X = np.asarray(X)
        squeeze = X.ndim == 2
        Xb = X[..., None] if squeeze else X
        out = Xb - U @ (shrink[..., None] * (UH @ Xb))
        return out[..., 0] if squeeze else out

    return white, np.sum(np.log1p(ev), axis=1)


def _normal_solve(G, b):
    """``G^-1 b`` for the normal matrix ``G`` (unit diagonal), regularised by setting ``asbuilt.normal_ridge`` on the
    diagonal: some of the rear lead-in's samples and the start's state explain the same thing, so ``G`` is
    singular to rounding; the ridge picks the smallest of the equivalent solutions (the residual the same to
    1e-9) and lets a Cholesky factor solve it (30 times faster than LAPACK's SVD least squares at the 400
    unknowns of a slow run's lead-in)."""
    A = G + defaults["asbuilt.normal_ridge"] * np.eye(G.shape[0])
    try:
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(A, check_finite=False), b, check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(G, b, rcond=1e-13)[0]


def solve(P, geom, tr: TrackRun, car=None, alpha_std: bool = False) -> Fit:
    """The as-built fit of run ``tr`` at the car ``P`` (16,): the amplitude factor and the boundary unknowns
    solved by least squares on the whitened bins (module docstring). ``alpha_std``: also the amplitude factor's
    standard error at this car (the least squares' ``s^2 (G^-1)_00``, the car fixed): large where the prior
    opened the bins of the track's own lines (a washboard, one line, 4 % off its drawing)."""
    rr = tr.rr
    bins = rr.fit
    w = rr.omega(bins)
    h = rr.h
    if car is None:  # (K,c,4), (K,c,ns): through the sensors (SPEC §11)
        car, H, S = roadfit.car_columns(P, geom, rr, bins)
    else:
        H, S = roadfit.recorded_columns(car, rr, w)
    E = roadfit.rear_delay(rr, w)
    Acol = roadfit._road_columns(H, E)
    pr = tr.prior
    D = pr.D if pr is not None else np.zeros(bins.size)
    white, logdet = _whitener(Acol, D, tr.mode)
    N = H @ tr.U[bins][:, :, None]                                                          # (K,c,1)
    cols = [white(N)[..., 0]]                                                               # alpha
    S = white(S)                                                                            # (K,c,ns)
    aL = white(H[:, :, 2:3])[..., 0]
    aR = white(H[:, :, 3:4])[..., 0]
    r = white(rr.Y[bins][:, :, None])[..., 0]
    # each bin's whitened columns and data divided by its noise level
    sn = np.sqrt(pr.noise) if pr is not None else np.ones(bins.size)
    aN, S, aL, aR, r = cols[0] / sn[:, None], S / sn[:, None, None], aL / sn[:, None], aR / sn[:, None], r / sn[:, None]
    g = np.concatenate([aN[:, :, None], S], axis=2)                                        # (K,c,nb)
    nb = g.shape[-1]  # alpha, the car's states (14, 18 with a powertrain) and the sensor filters' (SPEC §11)
    Dn = rr.lead_in
    G, b, en = roadfit.lead_in_normal_equations(g, aL, aR, r, w * h, Dn)
    m = G.shape[0]
    if tr.size_std is not None and tr.mode != "free":  # SPEC §13: the drawn size's prior, a row of its own
        G[0, 0] += SIZE_PRIOR_WEIGHT ** 2 / tr.size_std ** 2
        b[0] += SIZE_PRIOR_WEIGHT ** 2 / tr.size_std ** 2
    d = np.sqrt(np.clip(np.diag(G), 1e-300, None))
    f = _normal_solve(G / np.outer(d, d), b / d) / d
    alpha, fS, fL, fR = f[0], f[1:nb], f[nb:nb + Dn], f[nb + Dn:]
    res = r - aN * alpha - S @ fS - aL * (en @ fL)[:, None] - aR * (en @ fR)[:, None]
    # the data less the model at the estimated road: M^-1 x = M^(-1/2) (M^(-1/2) x) (weighted channels)
    plain = white(res[:, :, None])[..., 0] * sn[:, None] if tr.mode != "amplitude" else res * sn[:, None]
    sa = float("nan")
    if alpha_std:
        e0 = np.zeros(m)
        e0[0] = 1.0
        g00 = float(_normal_solve(G / np.outer(d, d), e0)[0]) / d[0] ** 2
        s2 = 2.0 * float(np.sum(np.abs(res) ** 2)) / max(2 * res.size - m, 1)
        sa = float(np.sqrt(max(s2 * g00, 0.0)))
    return Fit(residual=res, logdet=logdet, plain=plain, alpha=float(alpha), f_state=fS, f_lead=np.stack([fL, fR]),
               alpha_std=sa)


def residuals(P, geom, tr: TrackRun) -> np.ndarray:
    """Real residual vector of run ``tr`` at the car ``P``: per bin the real and imaginary parts of the whitened
    residual, then (mode "prior") ``sqrt(log det M)``, and (a drawn size with a prior, SPEC §13) the amplitude
    factor's prior row; its squared sum is the negative log-likelihood up to a constant."""
    fit = solve(P, geom, tr)
    parts = [fit.residual.real, fit.residual.imag]
    if tr.mode == "prior":
        parts.append(np.sqrt(np.clip(fit.logdet, 0.0, None))[:, None])
    out = np.concatenate(parts, axis=1).ravel()
    if tr.size_std is not None and tr.mode != "free":
        out = np.append(out, SIZE_PRIOR_WEIGHT * (fit.alpha - 1.0) / tr.size_std)
    return out


def meat(J, e, tr: TrackRun, s2: float | None = None) -> np.ndarray:
    """The sandwich's meat of run ``tr``'s residual block (``e`` (m,), its Jacobian ``J`` (m, d)): ``s2 J^T J``, the
    white meat (``s2``: the residual variance of the whole fit; default this block's mean square). The block is
    whitened bin by bin by construction (each bin divided by its noise level and the unevenness integrated out),
    so this is the Gaussian likelihood's own.

    Not the gradient's spread over DFT bins (:func:`cluster_meat`, as on an unknown road): on the SUV on tracks 4 %
    off with 1.5 mm unevenness (tests/asbuilt_tracks.py, seeds 4-8, a start 3 % off, model base) that gave error
    bars 1.8x too narrow (RMS of error / std_robust 1.81 over the 60 estimates; ±2 std_robust covered 5-12 of 12),
    the white meat the right width (RMS 0.92, 12 of 12 on every seed). Clusters of 8 or 16 bins changed nothing;
    run and track clusters are too few (measured; docs/tracks-as-built.md)."""
    if s2 is None:
        s2 = float(e @ e) / max(e.size, 1)
    return s2 * (J.T @ J)


def cluster_meat(J, e, tr: TrackRun) -> np.ndarray:
    """The gradient's spread over clusters of setting ``asbuilt.cluster_bins`` neighbouring DFT bins of run ``tr``'s
    block (kept for comparison: :func:`meat` says why it is not used)."""
    nb = (J.shape[0] // tr.per_bin) * tr.per_bin  # the drawn size's prior row (SPEC §13) is a cluster of its own
    g = (J[:nb] * e[:nb, None]).reshape(-1, tr.per_bin, J.shape[1]).sum(axis=1)   # per bin
    if nb < J.shape[0]:
        g = np.concatenate([g, (J[nb:] * e[nb:, None])])
    K = g.shape[0]
    groups = np.arange(K) // max(1, defaults["asbuilt.cluster_bins"])
    G = np.zeros((groups[-1] + 1, J.shape[1]))
    np.add.at(G, groups, g)
    return G.T @ G


def _smooth(v, half: int):
    """Moving mean of ``v`` (K, ...) over ``2 half + 1`` bins (fewer at the ends)."""
    c = np.cumsum(np.concatenate([np.zeros((1,) + v.shape[1:]), v]), axis=0)
    k = np.arange(v.shape[0])
    lo, hi = np.clip(k - half, 0, v.shape[0]), np.clip(k + half + 1, 0, v.shape[0])
    return (c[hi] - c[lo]) / (hi - lo).reshape((-1,) + (1,) * (v.ndim - 1))


def _running_median(raw, half: int):
    """Median of ``raw`` (K, 2) over ``2 half + 1`` bins (fewer at the ends) and both columns."""
    K = raw.shape[0]
    out = np.empty(K)
    for k in range(K):
        out[k] = np.median(raw[max(0, k - half):k + half + 1])
    return out


@stage("unevenness prior")
def estimate_prior(P, geom, tr: TrackRun) -> Prior:
    """The noise and unevenness levels of run ``tr`` at the car ``P`` (module docstring): the road projected
    out, the free road regressed on the drawn one for the amplitude factor, the rest's power less the noise's
    share in it, smoothed."""
    rr = tr.rr
    sol = roadfit.solve(P, geom, rr)
    K, c = sol.residual.shape
    # each bin keeps c - 2 of its c complex channels after the road's two; the boundary unknowns (the states,
    # 14 or 18 with a powertrain, + 2 D real) take their share of the rest (14 % on a slow run: an under-stated
    # noise over-weights the quadratic form against the log-determinant, a bias towards cars that explain more
    # as road)
    kept = 2 * K * max(c - 2, 1)
    dof = kept / max(kept - sol.f_state.size - 2 * rr.lead_in, 1)
    noise = _smooth(np.sum(np.abs(sol.residual) ** 2, axis=1) / max(c - 2, 1), defaults["asbuilt.noise_bins"]) * dof
    noise = np.maximum(noise, 1e-30 * max(float(np.mean(np.abs(rr.Y[rr.fit]) ** 2)), 1e-300))
    w = rr.omega(rr.fit)
    h = rr.h
    H, S = roadfit.recorded_columns(sol.car, rr, w)
    E = roadfit.rear_delay(rr, w)
    Acol = roadfit._road_columns(H, E)
    _, road_of = roadfit._projector(Acol)
    en = np.exp(-1j * np.outer(w * h, np.arange(rr.lead_in)))
    known = (S @ sol.f_state
             + H[:, :, 2] * (en @ sol.f_lead[0])[:, None] + H[:, :, 3] * (en @ sol.f_lead[1])[:, None])
    R = road_of((rr.Y[rr.fit] - known)[:, :, None])[..., 0]                                 # (K, 2) m
    # a short run on a track that excites little at its slowest bins (the washboard's one line): the start's state
    # and the rear wheels' lead-in explain those bins as well as a road does, and the free fit's boundary unknowns
    # come out with a road share many times the drawing's; what is left there is theirs, not the track's
    share = float(np.sum(np.abs(road_of(known[:, :, None])[..., 0]) ** 2)
                  / max(float(np.sum(np.abs(tr.U[rr.fit][:, :2]) ** 2)), 1e-300))
    held = None
    if share > defaults["asbuilt.boundary_share"]:
        held = (f"held at the prior's floor: the run's start state and rear lead-in put {share:.2g} times the drawn "
                "road's power into the road estimate (a run too short, or a track too narrow in frequency, to tell "
                f"unevenness from them; more than {defaults['asbuilt.boundary_share']:g} holds it)")
    AH = np.conj(np.swapaxes(Acol, -1, -2))
    Ginv = np.linalg.inv(AH @ Acol)
    v = noise[:, None] * np.real(np.stack([Ginv[:, 0, 0], Ginv[:, 1, 1]], axis=1))          # (K, 2) m^2
    Uf = tr.U[rr.fit][:, :2]
    wt = 1.0 / np.maximum(v, 1e-300)
    den = float(np.sum(wt * np.abs(Uf) ** 2))
    alpha = float(np.sum(wt * np.real(np.conj(Uf) * R)) / den) if den > 0 else 1.0
    raw = np.abs(R - alpha * Uf) ** 2                                                       # (K, 2)
    # the spectrum's background: a running median (robust to the few bins where the drawing itself is off), over
    # ln 2 (the median of an exponential variable, |complex Gaussian|^2, is ln 2 of its mean), less the noise
    bins = defaults["asbuilt.smooth_bins"]
    background = _running_median(raw, bins) / np.log(2.0) - _smooth(np.mean(v, axis=1), bins)
    floor = defaults["asbuilt.prior_floor"] * _smooth(np.mean(v, axis=1), bins)
    background = np.maximum(background, floor)
    # a bin whose deviation is far above the background is where the road departs from the drawing times a
    # factor (the disc's envelope of a taller bump, a feature off its drawn place): the prior opens there
    local = np.max(raw - v, axis=1)
    sd2 = np.where(local > defaults["asbuilt.open_factor"] * background, local, background)
    if held:
        sd2 = floor
    return Prior(noise=noise, D=sd2 / noise, unevenness=sd2, alpha=alpha, held=held)


def unevenness_rms(tr: TrackRun, longest: float | None = None) -> float:
    """RMS (m) of the unevenness the prior found, one wheel path, over the fit band's wavelengths (Parseval on
    the run's DFT); ``longest`` (m): only over the waves up to that long."""
    if tr.prior is None:
        return float("nan")
    sd2 = tr.prior.unevenness
    if longest is not None:
        f = tr.rr.omega(tr.rr.fit) / (2 * np.pi)
        sd2 = np.where(f >= tr.rr.speed / longest, sd2, 0.0)
    return float(np.sqrt(2.0 * np.sum(sd2)) / tr.rr.n)


def fitted_channels(P, geom, tr: TrackRun, y, fit: Fit | None = None) -> np.ndarray:
    """The model's channels (n, 10) at the estimated road: the measured ones less the fit band's residual (NaN
    for unused channels), as :func:`rideid.estimate.problem.roadfit.fitted_channels`."""
    fit = solve(P, geom, tr) if fit is None else fit
    return roadfit.channels_less(tr.rr, y, fit.plain)


__all__ = ["MODES", "Prior", "TrackRun", "Fit", "nominal_inputs", "prepare_track_run", "solve", "residuals",
           "estimate_prior", "unevenness_rms", "fitted_channels", "meat", "cluster_meat",
           "moved", "MotionPrior", "motion_prior", "speed_move_bound"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "SMOOTH_BINS": "asbuilt.smooth_bins", "OPEN_FACTOR": "asbuilt.open_factor", "PRIOR_FLOOR":
    "asbuilt.prior_floor", "NORMAL_RIDGE": "asbuilt.normal_ridge", "CLUSTER_BINS": "asbuilt.cluster_bins",
    "NOISE_BINS": "asbuilt.noise_bins", "MOTION_SCALE": "asbuilt.motion_scale", "MOTION_STEPS":
    "asbuilt.motion_steps", "MOTION_XTOL": "asbuilt.motion_xtol", "MOTION_MAXFEV": "asbuilt.motion_maxfev",
    "MOTION_JACOBIAN_STEPS": "asbuilt.motion_jacobian_steps"})
