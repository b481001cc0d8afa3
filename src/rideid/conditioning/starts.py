"""Start alignment of measured runs: the start that lines a run up with a car's response on its track.

Step 6 of conditioning a measured run (:mod:`rideid.data.measured`): the
file time at which the front axle reaches ``x = 0`` (SPEC §2), estimated by
correlating the run's samples with the response of a car (the nominal car
when a dataset is loaded, :func:`rideid.conditioning.load.align_starts`; the
fitted one in :func:`rideid.identify`). The estimate is a step
(:func:`start_steps`, :mod:`rideid.conditioning.nominal`): it asks for the
responses it correlates with and never runs the model itself; loading runs
the steps of every run side by side, each round of simulations in one batch.

The identification's polish estimates the starts together with the
parameters and asks this module for what it needs of the runs: the runs read
at the current starts with each start's derivative (:func:`linearise_starts`)
and the runs that slipped a cycle of a periodic track with the polished car
(:func:`cycle_slips`). A noisy speed channel's share of a start's standard
error (:func:`speed_channel_std`) is recorded when the start is estimated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..data.dataset import Dataset
from ..data.measured import DEFAULT_PRE_ROLL, MeasuredRun, RelativeDistance
from ..errors import DataError
from ..model.equations import CHANNELS
from ..model.sensors import SensorChain
from ..settings import defaults
from .nominal import Job, gather, responses, run_steps, simulate_jobs


def feature_span(track, geom) -> tuple[float, float] | None:
    """(first, last) x of the track's features over the four wheel paths, or None (flat)."""
    lo, hi = [], []
    for y in geom.corner_y:
        ext = track.path(y).extent
        if ext is not None and ext[1] > ext[0]:
            lo.append(ext[0])
            hi.append(ext[1])
    if not lo:
        return None
    return min(lo), max(hi)


def _feature_end(track, geom) -> float:
    """Distance (front axle) at which the rear wheels leave the last feature."""
    span = feature_span(track, geom)
    return (0.0 if span is None else span[1]) + geom.wheelbase


def correlation_score(Yhat, Y, cols):
    """Mean normalised correlation over the channels ``cols`` that are not zero."""
    s, n = 0.0, 0
    for i in cols:
        a, b = Yhat[:, i], Y[:, i]
        na, nb = np.linalg.norm(a), np.linalg.norm(b)
        if na > 0 and nb > 0:
            s += float(a @ b) / (na * nb)
            n += 1
    return s / max(n, 1)


def _long_grid(mr: MeasuredRun, track, geom, v):
    """Model times covering the whole feature passage (and settling) at speed ``v``, or the recording."""
    h = 1.0 / mr.fs
    pre = mr.options.get("pre_roll", DEFAULT_PRE_ROLL)
    T = min(_feature_end(track, geom) / v + 2.0, mr.t_last - mr.t_first + pre)
    return -pre + h * np.arange(int((T + pre) / h) + 1)


def _measured_at(mr: MeasuredRun, times) -> np.ndarray:
    """(n, 10) measurement at file ``times``, NaN for missing channels.

    Interpolated: for looking at the recording between its samples (the
    coarse alignment of a run with a speed channel), never for a fit.
    """
    Y = np.full((len(times), len(CHANNELS)), np.nan)
    for i, c in enumerate(CHANNELS):
        if c in mr.channels:
            Y[:, i] = mr.channels[c](times)
    return Y


def _correlation(mr: MeasuredRun, Yhat, tm, tau=None):
    """Mean normalised cross-correlation over channels; returns (starts, values) for every lag.

    ``tau``: the file times at which the measurement is read (default: the
    run's own samples :attr:`MeasuredRun.times`); ``Yhat`` at model times
    ``tm`` is then compared with the measurement at ``tau[k + lag]``. ``Yhat``
    (at rest at ``tm[0]``) passes the run's declared sensor chain first.
    """
    from scipy.signal import correlate

    chain = SensorChain(mr.chain_filters(), 1.0 / mr.fs)
    if chain.active:  # the response as the run's declared sensors record it (SPEC §11)
        Yhat = chain.apply(Yhat)
    Y = mr.values if tau is None else _measured_at(mr, tau)
    total, n = None, 0
    for i, c in enumerate(CHANNELS):
        if c not in mr.channels:
            continue
        a, b = Yhat[:, i], Y[:, i]
        na, nb = np.linalg.norm(a), np.linalg.norm(b)
        if na == 0 or nb == 0:
            continue
        cc = correlate(b, a, mode="full", method="fft") / (na * nb)
        total = cc if total is None else total + cc
        n += 1
    if total is None:
        raise DataError(f"{mr.path}: cannot estimate the start: the nominal car's response or the measurement "
                        "is zero on every channel; give start in seconds")
    lags = np.arange(total.size) - (tm.size - 1)
    return lags, total / n


def _peaks(values, k):
    """Indices of the ``k`` highest local maxima."""
    inner = np.nonzero((values[1:-1] >= values[:-2]) & (values[1:-1] > values[2:]))[0] + 1
    return inner[np.argsort(values[inner])[::-1][:k]]


def _vertex(values, j) -> tuple[float, float]:
    """Sub-sample peak of ``values`` near its local maximum ``j``: ``(offset, height)`` of the
    parabola through ``j - 1, j, j + 1`` (offset within ±0.5; 0 at an end)."""
    if j <= 0 or j >= values.size - 1:
        return 0.0, float(values[j])
    ym, y0, yp = (float(v) for v in values[j - 1:j + 2])
    den = ym - 2.0 * y0 + yp
    if den >= 0:
        return 0.0, y0
    off = float(np.clip(0.5 * (ym - yp) / den, -0.5, 0.5))
    return off, y0 - 0.25 * (ym - yp) * off


def start_steps(mr: MeasuredRun, geom, track):
    """The step (:mod:`rideid.conditioning.nominal`) that estimates the run's start: returns
    ``(start, correlation)``, as :func:`estimate_start` describes, asking for the car's responses it
    correlates with (the long grid first; with a speed channel, every candidate's fixed point a round at a
    time, the candidates side by side)."""
    h = 1.0 / mr.fs
    if mr.distance is None:
        tm = _long_grid(mr, track, geom, mr.speed)
        (Yhat,) = responses((yield [Job(track, tm, mr.speed)]))
        lags, corr = _correlation(mr, Yhat, tm)
        # y_hat at model time tm[k] matches the measurement at t_first + (k + lag) h
        j = int(np.argmax(corr))
        off, peak = _vertex(corr, j)
        return float(mr.t_first + (lags[j] + off) * h - tm[0]), peak
    # varying speed: correlate over distance (the road is fixed in x), with the response at the mean speed
    vmean = max(mr.distance.speed_range()[1], 0.1)
    tm = _long_grid(mr, track, geom, vmean)
    dist = mr.distance
    x_all = dist.d
    xs = x_all[0] + vmean * h * np.arange(int((x_all[-1] - x_all[0]) / (vmean * h)) + 1)
    keep = np.concatenate([[True], np.diff(x_all) > 0])
    tau = np.interp(xs, x_all[keep], dist.t[keep])
    (Yv,) = responses((yield [Job(track, tm, vmean)]))
    lags, corr = _correlation(mr, Yv, tm, tau)
    # model x = vmean tm[k] matches the road at distance xs[k + lag]: x = 0 is at xs[lag] - vmean tm[0]
    cand = [float(np.interp(xs[0] + (lags[i] * vmean * h) - vmean * tm[0], x_all[keep], dist.t[keep]))
            for i in _peaks(corr, 5)]
    best, best_score = None, -np.inf
    for s, score in (yield from gather([_fixed_point(mr, track, tm, s) for s in cand])):
        if score > best_score:
            best, best_score = s, score
    return best, best_score


def _fixed_point(mr: MeasuredRun, track, tm, s):
    """The step of one start candidate of a run with a speed channel: ``(start, correlation)`` where the
    response simulated with the start's own distance profile peaks near the start itself."""
    h = 1.0 / mr.fs
    score = -np.inf
    for _ in range(8):  # fixed point: simulate with this start's distance profile, re-pick the lag nearby
        (Yhat,) = responses((yield [Job(track, tm, None, RelativeDistance(mr.distance, s))]))
        lg, cc = _correlation(mr, Yhat, tm)
        st = mr.t_first + lg * h - tm[0]
        near = np.abs(st - s) <= 3.0 * h
        j = int(np.argmax(np.where(near, cc, -np.inf)))
        off, peak = _vertex(cc, j)
        moved = abs(st[j] + off * h - s) > 1e-3 * h
        s, score = float(st[j] + off * h), peak
        if not moved:
            break
    return s, score


def _peak_near(mr: MeasuredRun, track, tm, s: float, near: float):
    """The step giving the highest all-lags correlation of the run with the car's response (the measure
    :func:`start_steps` maximises) within ``near`` samples of the start ``s``."""
    h = 1.0 / mr.fs
    job = (Job(track, tm, mr.speed) if mr.distance is None
           else Job(track, tm, None, RelativeDistance(mr.distance, s)))
    (Yhat,) = responses((yield [job]))
    lags, corr = _correlation(mr, Yhat, tm)
    at = (s + tm[0] - mr.t_first) / h
    close = np.abs(lags - at) <= near
    if not close.any():
        return float(np.interp(at, lags, corr, left=0.0, right=0.0))
    j = int(np.flatnonzero(close)[np.argmax(corr[close])])
    return max(_vertex(corr, j)[1], float(corr[j]))


def start_check_steps(mr: MeasuredRun, geom, track, given: float, near: float = 3.0):
    """The step checking a given start (:func:`rideid.conditioning.checks.check_dataset`): returns
    ``(best start, correlation there, correlation near the given start)``.

    ``mr``: the run as read, unaligned (window and start dropped). The best
    start is the one :func:`start_steps` estimates; near the given start,
    the highest of the same measure within ``near`` samples of it (with a
    speed channel, of the response simulated along the given start's own
    distance profile): a car unlike the nominal one peaks a sample or two
    from the true start, and on a fast run the correlation falls steeply
    within a sample. A given start a bump or a cycle of the track off
    correlates markedly worse than the best start, which lies that bump or
    cycle away.
    """
    v = mr.speed if mr.distance is None else max(mr.distance.speed_range()[1], 0.1)
    tm = _long_grid(mr, track, geom, v)
    (best, rho_best), rho_given = yield from gather([start_steps(mr, geom, track),
                                                     _peak_near(mr, track, tm, given, near)])
    return best, rho_best, rho_given


def estimate_start(mr: MeasuredRun, P, geom, track, simulator=None):
    """``(start, correlation)``: the run's start (file time when the front axle reaches x = 0) for
    the car ``P``, by cross-correlation over all lags, to a fraction of a sample.

    The run's samples are correlated with the car's response at the sample
    rate; the peak lag is refined by a parabola through the correlation at
    it and its neighbours. Constant speed: the model's response only shifts
    with the start, so the highest correlation wins. With a speed channel
    the response depends on the start; each of the best few correlation
    peaks (on a periodic track: the neighbouring cycles) is re-simulated
    with its own distance profile and scored at its own start, and the best
    self-consistent one wins. The correlation returned is the mean normalised
    correlation over the channels that are not zero, at the peak. Only the
    car's response is simulated; the run's samples are read as they are
    (:func:`start_steps`, run by :func:`rideid.conditioning.nominal.run_steps` with ``simulator``, a
    :class:`rideid.model.simulator.Simulator` of ``P``'s model; default the linear car).
    """
    steps = start_steps(mr, geom, track)
    return run_steps(steps, geom, P, simulator)


# ---------------------------------------------------------------------------
# Starts estimated together with the parameters (rideid.estimate.fit.identify's polish)

#: the start derivative's central difference step, in sample intervals
SHIFT_STEP = 0.1


#: knot spacing (s) of a noisy speed channel's distance correction (:class:`DistanceWarp`): between knots a
#: random walk of the channel's noise deviates from the straight line by sigma_v sqrt(dt Delta / 4) at most on
#: average (3 mm for 0.03 m/s at 10 Hz), a few degrees of phase on a 0.6 m herringbone
WARP_SPACING = 0.2
#: the central difference step of a knot's derivative, m
WARP_STEP = 1e-3
#: a speed channel whose integral drifts less than this (m, one standard deviation over the run's window) is
#: taken as exact (no distance correction)
WARP_MIN = 1e-3


@dataclass(frozen=True)
class DistanceWarp:
    """The correction to a run's distance when its speed channel is noisy.

    The integral of a noisy speed channel is a random walk: white noise of
    ``sigma_v`` on samples ``dt`` apart drifts the distance by ``sigma_v
    sqrt(T dt)`` after ``T`` seconds (``rate_std = sigma_v sqrt(dt)``, m per
    sqrt(s)). The distance the car really covered is the channel's integral
    plus ``delta(t)``, piecewise linear in file time between ``knots`` (every
    :data:`WARP_SPACING` s over the run's window), ``values`` at the knots;
    the knot at the run's start (``anchor``) is 0, since only differences of
    distance move the model (the start fixes the rest). The polish estimates
    the other knots with the parameters, their increments held to the random
    walk's by a prior (:meth:`prior`), so the parameters' standard errors
    include what the speed channel's noise leaves unknown.
    """

    knots: np.ndarray
    values: np.ndarray
    anchor: int
    rate_std: float

    @property
    def free(self) -> np.ndarray:
        """Indices of the estimated knots (all but the anchor)."""
        return np.delete(np.arange(self.knots.size), self.anchor)

    def at(self, t) -> np.ndarray:
        """delta at file times ``t`` (m; constant beyond the end knots)."""
        return np.interp(np.asarray(t, dtype=float), self.knots, self.values)

    def with_free(self, free_values) -> "DistanceWarp":
        v = self.values.copy()
        v[self.free] = free_values
        return replace(self, values=v)

    def hat(self, k) -> np.ndarray:
        """The values of the ``k``-th free knot's basis function (1 at that knot, 0 at the others)."""
        e = np.zeros(self.knots.size)
        e[self.free[k]] = 1.0
        return e

    def prior(self):
        """``(A, sigma)``: the increments ``A @ values[free]`` between neighbouring knots and their random
        walk standard deviations (m): prior residuals ``A v / sigma``."""
        n = self.knots.size
        D = np.zeros((n - 1, n))
        D[np.arange(n - 1), np.arange(n - 1)] = -1.0
        D[np.arange(n - 1), np.arange(1, n)] = 1.0
        sigma = self.rate_std * np.sqrt(np.diff(self.knots))
        return D[:, self.free], sigma

    def record(self, std=None) -> dict:
        """The correction as result.json gives it (``std``: the free knots' standard errors, m)."""
        out = {"knots_s": [float(t) for t in self.knots], "values_m": [float(v) for v in self.values],
               "rms_m": float(np.sqrt(np.mean(self.values ** 2))), "max_abs_m": float(np.max(np.abs(self.values))),
               "random_walk_m_per_sqrt_s": float(self.rate_std), "spacing_s": WARP_SPACING}
        if std is not None:
            s = np.zeros(self.knots.size)
            s[self.free] = std
            out["std_m"] = [float(v) for v in s]
        return out


def distance_warp(mr: MeasuredRun, start: float) -> DistanceWarp | None:
    """The run's distance correction (None: the run has no noisy speed channel): all knots 0, or, on a run
    already driven along a correction (a parent's in the model choice, :meth:`rideid.data.dataset.Dataset.with_starts`),
    that correction at the knots, less its value at ``start``.

    A distance channel or a noise-free speed channel is taken as exact; the
    knots span the run's window (:meth:`MeasuredRun.make_grid`) and the
    anchor is at ``start``. Measured on the all-realities SUV (benchmarks/bench_realtest.py ``realities``): every
    rival's corrections began at 0 again (a correction replaces an earlier one), its first round moved them
    2.76 samples and it took four rounds, each rival alike.
    """
    sp = mr.record.get("speed", {})
    if mr.distance is None or not sp.get("noise_std") or not sp.get("noise_interval"):
        return None
    rd = mr.run_data(start)
    lo, hi = start + float(rd.time[0]), start + float(rd.time[-1])
    k0 = int(math.floor((lo - start) / WARP_SPACING))
    k1 = int(math.ceil((hi - start) / WARP_SPACING))
    if k1 - k0 < 2:
        return None
    knots = start + WARP_SPACING * np.arange(k0, k1 + 1)
    rate_std = float(sp["noise_std"]) * math.sqrt(float(sp["noise_interval"]))
    if rate_std * math.sqrt(knots[-1] - knots[0]) < WARP_MIN:
        return None  # the channel's drift over the whole run stays below a millimetre: taken as exact
    values = np.zeros(knots.size)
    if mr.channel_distance is not None:
        t, dd = mr.distance.t, mr.distance.d - mr.channel_distance.d
        values = np.interp(knots, t, dd) - float(np.interp(start, t, dd))
    return DistanceWarp(knots, values, -k0, rate_std)


def _warped_run(mr: MeasuredRun, warp: DistanceWarp, values=None) -> MeasuredRun:
    """``mr`` driven along its channel's distance plus ``warp`` (or the warp's knots at ``values``)."""
    return mr.with_distance_correction(warp.knots, warp.values if values is None else values)


def warped(ds, warps: dict) -> Dataset:
    """``ds`` with each run of ``warps`` (run id -> :class:`DistanceWarp`) driven along its distance plus
    the warp (``ds`` is not changed; its runs are read at their starts)."""
    if not warps:
        return ds
    measured, data = dict(ds.measured), dict(ds.data)
    for rid, w in warps.items():
        measured[rid] = _warped_run(ds.measured[rid], w)
        data[rid] = measured[rid].run_data(measured[rid].start)
    return replace(ds, data=data, measured=measured)


def linearise_starts(ds, P, starts: dict, simulator=None, derivative: bool = True, warps: dict | None = None):
    """The runs of ``starts`` read at those starts, and car ``P``'s response derivative with respect to each.

    ``P`` is one row of ``simulator``'s model (a :class:`rideid.model.simulator.Simulator`; default the
    linear car): the derivative is the model's that is being fitted, damper curves and bump stops included.

    Returns ``(dataset, D, D2, Dw)``: ``ds.with_starts(starts)`` (:meth:`rideid.data.dataset.Dataset.with_starts`;
    ``ds`` is not changed); run id ->
    ``(n, 10)`` derivative of ``P``'s response at the run's fixed samples with
    respect to its start, and its second derivative (both empty when not ``derivative``; no second
    derivative for a run of ``warps``, whose start's move the polish keeps linear): central
    differences of three simulations whose time axes (and, with a speed channel,
    distance profiles) belong to ``start -/+ SHIFT_STEP`` samples and the start, every run's
    in one batch (:func:`rideid.conditioning.nominal.simulate_jobs`). The
    model moves, the samples stay. The second derivative makes the polish's model of a moved start
    quadratic: with the linear one alone, a car that misfits (a rival of the model choice) has a residual
    that correlates with the response's curvature, and the rounds overshoot (each move about -0.55 of the
    last on the van's logger files, docs/performance.md).

    ``Dw``, with ``warps`` (run id -> :class:`DistanceWarp`, already applied to ``ds``'s runs by
    :func:`warped`): run id -> ``(K, n, 10)``, the derivative with respect to each free knot of its warp
    (central differences of :data:`WARP_STEP`, in the same batch); else empty.
    """
    at = ds.with_starts(starts)
    if not derivative:
        return at, {}, {}, {}
    eps = {rid: SHIFT_STEP / ds.measured[rid].fs for rid in starts}
    warps = warps or {}
    jobs, at_job = [], {}
    for rid, s in starts.items():
        mr, track = ds.measured[rid], ds.manifest.tracks[ds.manifest.run(rid).track]
        at_job[rid] = len(jobs)
        for sign in (-1, 1) if rid in warps else (-1, 1, 0):
            rd = mr.run_data(s + sign * eps[rid])
            jobs.append(Job(track, rd.time, mr.speed, rd.distance))
    n_start = len(jobs)
    # a distance correction's knots: the run at its start with one knot moved by -/+ WARP_STEP, over the knot's
    # window only (knot_window)
    order = []
    pre = None if simulator is not None and simulator.nonlinear else 0.0
    for rid, w in warps.items():
        mr, track = ds.measured[rid], ds.manifest.tracks[ds.manifest.run(rid).track]
        t = mr.run_data(starts[rid]).time
        base = (mr.channel_distance or mr.distance).t
        reach = 2.0 * float(np.max(np.diff(base)))  # the distance's PCHIP: a node moves two intervals each side
        for k in range(w.free.size):
            a, b = knot_window(w, k, t, starts[rid], pre, reach)
            for sign in (-1, 1):
                mk = _warped_run(mr, w, w.values + sign * WARP_STEP * w.hat(k))
                jobs.append(Job(track, t[a:b], mr.speed, RelativeDistance(mk.distance, starts[rid])))
            order.append((rid, k, a, b))
    y = responses(simulate_jobs(P, ds.geometry, jobs, simulator)) if jobs else []
    D, D2 = {}, {}
    for rid, j in at_job.items():
        lo, hi = y[j], y[j + 1]
        D[rid] = _recorded(at, rid, (hi - lo) / (2 * eps[rid]))
        if rid not in warps:
            D2[rid] = _recorded(at, rid, (hi - 2 * y[j + 2] + lo) / eps[rid] ** 2)
    Dw = {rid: np.empty((w.free.size, at.data[rid].time.size, len(CHANNELS))) for rid, w in warps.items()}
    for j, (rid, k, a, b) in enumerate(order):
        d = np.zeros(Dw[rid].shape[1:])
        d[a:b] = (y[n_start + 2 * j + 1] - y[n_start + 2 * j]) / (2 * WARP_STEP)
        Dw[rid][k] = _recorded(at, rid, d)
    return at, D, D2, Dw


def knot_window(warp: DistanceWarp, k: int, t, start: float, pre: float | None = 0.0,
                reach: float = 0.0) -> tuple[int, int]:
    """The samples ``[a, b)`` of model times ``t`` over which moving free knot ``k`` of ``warp`` changes the
    response: from ``pre`` s before its hat begins (``None``: setting ``identify.knot_settle`` s) to that setting's
    seconds after it ends (the first knot's hat reaches back to the run's beginning, the last's on to its end),
    the hat widened by ``reach`` s each side (the distance profile's interpolation between its nodes carries a
    node's move that far: :class:`rideid.data.measured.Distance` is a PCHIP, two node intervals).

    Before the hat the two simulations of a knot's central difference have the same road and the same state, so
    their difference is exactly 0 there and each can start at rest at ``a``: for the linear car the difference
    is the response to the road's change, whatever the state (``pre`` 0); a nonlinear car starts
    ``identify.knot_settle`` s early for the state's start to be forgotten. After the hat the difference decays
    with the car's slowest mode; it is cut off after ``identify.knot_settle`` s (docs/performance.md). A knot's
    simulations were the whole run's: 0.2 s apart, a 20 s run's 100 knots took 200 simulations of all of it."""
    settle = defaults["identify.knot_settle"]
    pre = settle if pre is None else pre
    j = int(warp.free[k])
    lo = -np.inf if j == 0 else warp.knots[j - 1] - start - reach - pre
    hi = np.inf if j == warp.knots.size - 1 else warp.knots[j + 1] - start + reach + settle
    t = np.asarray(t, dtype=float)
    a, b = int(np.searchsorted(t, lo, side="left")), int(np.searchsorted(t, hi, side="right"))
    a = min(a, max(t.size - 2, 0))  # at least two samples: a time axis
    return a, max(b, a + 2)


def _recorded(ds, rid, d):
    """A derivative of the model's channels on run ``rid`` as the sensors record it (SPEC §11): the chain is
    linear, so the recorded derivative is the derivative filtered; a sample left out of the fit moves nothing."""
    chain = SensorChain(ds.sensor_filters(rid), 1.0 / ds.measured[rid].fs)
    if chain.active:
        d = chain.apply(d)
    clipped = ds.clipped(rid)
    return d if clipped is None else np.where(clipped, 0.0, d)


def cycle_slips(ds, P, starts: dict, simulator=None) -> dict:
    """The constant-speed runs of ``starts`` whose all-lags correlation with car ``P`` (a row of
    ``simulator``'s model; default the linear car) peaks a cycle away.

    On a periodic track the nominal car may have picked a neighbouring cycle
    (the polish only moves a start by a few samples). Where car ``P``'s
    correlation (:func:`estimate_start`) peaks more than two samples from the
    run's start in ``starts``, that start is the new one.

    Returns
    -------
    dict
        Run id -> its new start (s), for the runs that slipped a cycle (``starts`` is not changed).
    """
    rids = [rid for rid in starts if ds.measured[rid].distance is None]
    # every run's correlation (:func:`estimate_start`) side by side: their simulations in one batch (the kernel on
    # every core), each run's own numbers as when run alone
    found = run_steps(gather(start_steps(ds.measured[rid], ds.geometry, ds.manifest.tracks[ds.manifest.run(rid).track])
                             for rid in rids), ds.geometry, P, simulator)
    return {rid: s for rid, (s, _) in zip(rids, found) if abs(s - starts[rid]) > 2.0 / ds.measured[rid].fs}


def speed_channel_std(mr: MeasuredRun, track, geom) -> float | None:
    """A start's standard error (s) from the drift of a noisy speed channel, or None (no speed channel noise).

    The model drives along ``x(t) = d(start + t) - d(start)``. White noise of
    standard deviation ``sigma_v`` on a speed channel sampled every ``dt``
    makes the integrated distance a random walk, ``sigma_x(T) = sigma_v
    sqrt(T dt)`` after ``T`` seconds; the start is fixed by the road
    features, met about ``T_mid`` (front axle at the middle of the features,
    half a wheelbase on) after it, so the distance error there moves the
    start by ``sigma_x(T_mid) / v_mean``. A property of the recording and the
    track, recorded with the run's start when it is estimated
    (:func:`rideid.conditioning.load.align_starts`); the polish adds it in
    quadrature to the fit's (Jacobian) standard error, which assumes the
    distance exact. A speed channel's calibration error is not included.
    """
    sp = mr.record.get("speed", {})
    if "noise_std" not in sp or not sp.get("mean"):
        return None
    span = feature_span(track, geom)
    x_mid = (0.0 if span is None else 0.5 * (span[0] + span[1])) + 0.5 * geom.wheelbase
    v = max(float(sp["mean"]), 1e-6)
    return float(sp["noise_std"]) * math.sqrt(max(x_mid / v, 0.0) * float(sp["noise_interval"])) / v


__all__ = ["SHIFT_STEP", "WARP_SPACING", "DistanceWarp", "correlation_score", "cycle_slips", "distance_warp",
           "estimate_start", "feature_span", "knot_window", "linearise_starts", "speed_channel_std",
           "start_check_steps", "start_steps", "warped"]
