"""Speed as driven (SPEC §11): does a run declared at a constant speed hold it?

A run without a speed or distance channel is driven, in the model, at its
declared constant ``speed``. When the driver's speed wandered, the data's
time axis is stretched against the response at the declared speed: the road
under the front axle at time ``t`` is ``x(t) = v0 (t + l(t))``, and the
data at ``t`` look like the nominal car's response at ``t + l(t)``. The lag
``l`` is the speed's deviation integrated, ``l'(t) = v(t) / v0 - 1``:

* a constant speed, as declared: a constant lag (the start's own error, 0
  after the start is estimated);
* a constant speed other than the declared one: a lag growing linearly,
  its slope the relative difference;
* a wandering speed: a lag that drifts non-linearly.

:func:`window_lags` cuts the stretch of the run where the wheels are on the
track's features into :data:`WINDOWS` windows and finds, in each, the lag of
the data against the nominal response (normalised cross-correlation summed
over the channels, to a fraction of a sample by a parabola through the
peak); on a periodic track the lag is followed from window to window within
half the response's period, so it never jumps a cycle. The speed's
deviation between two neighbouring windows is their lags' difference over
their distance in time. :func:`speed_finding` refuses a run whose speed,
so measured, leaves the declared one by more than setting ``speed.wander_max``, and
by more than setting ``speed.z_min`` times the deviation's uncertainty.

The car is the nominal one, not the car in the data: a different car (other
modes, damper curves, bump stops) lags the road differently, and by a
different amount in windows of different content (a bump, the free response
after it). That is why a deviation counts only beyond its uncertainty: each
window's lag is uncertain by what the nominal response does not explain,
``sqrt(1 - rho^2)`` of it for a window correlating ``rho``, over the
sharpness of the correlation peak (``sigma`` of :func:`window_lags`). On a
slow response (the twist at 3 m/s, body modes at 1-2 Hz) that is several
per cent of speed and the check sees little; on a herringbone or a
washboard at speed a few tenths of a per cent.
"""

from __future__ import annotations

import numpy as np

from ..settings import defaults, legacy_names
from ..data.checks import ERROR, Finding

#: windows over the stretch where the wheels are on the track's features
WINDOWS = 4
#: the lag is searched within this fraction of the response's period (on a periodic track) of its prediction
HALF_PERIOD = 0.45
#: ... and never further than this (s) from it
LAG_MAX = 0.08


def _norm_cols(Y, Yhat):
    """Channels that are measured and excited."""
    return [i for i in range(Y.shape[1])
            if np.any(Y[:, i] != 0) and np.any(Yhat[:, i] != 0) and not np.any(np.isnan(Y[:, i]))]


def _xcorr(Y, Yhat, i0, i1, lags, cols):
    """Normalised cross-correlation summed over ``cols`` of the data on samples ``i0:i1`` with the response
    ``lags`` samples later (the response padded with zeros). The lags whose window lies inside the response are
    one product over a sliding view of it (the data's window the same for each); the few that reach past an end,
    one at a time."""
    n = Yhat.shape[0]
    lags = np.asarray(lags, dtype=int)
    out = np.zeros(lags.size)
    inside = (i0 + lags >= 0) & (i1 + lags <= n)
    if inside.any():
        d = Y[i0:i1][:, cols]                                                        # (W, C)
        ls = lags[inside]
        a, b = int(ls.min()), int(ls.max())
        win = np.lib.stride_tricks.sliding_window_view(Yhat[i0 + a:i1 + b][:, cols], i1 - i0, axis=0)[ls - a]
        out[inside] = _normalised(np.einsum("lcw,wc->lc", win, d), np.linalg.norm(d, axis=0)[None],
                                  np.sqrt(np.einsum("lcw,lcw->lc", win, win)), len(cols))
    for j in np.flatnonzero(~inside):
        lag = int(lags[j])
        lo, hi = max(i0 + lag, 0), min(i1 + lag, n)
        if hi <= lo:
            continue
        d = Y[lo - lag:hi - lag][:, cols]
        m = Yhat[lo:hi][:, cols]
        out[j] = _normalised(np.sum(d * m, axis=0)[None], np.linalg.norm(d, axis=0)[None],
                             np.linalg.norm(m, axis=0)[None], len(cols))[0]
    return out


def _normalised(num, nd, nm, c: int) -> np.ndarray:
    """Each row's sum over its channels of ``num / (nd nm)``, over ``c`` (a channel of no signal adds 0)."""
    ok = (nd > 0) & (nm > 0)
    return np.sum(np.where(ok, num / np.where(ok, nd * nm, 1.0), 0.0), axis=1) / c


def _period(Yhat, i0, i1, cols, cap: int) -> int:
    """Samples to the first peak of the response's autocorrelation on ``i0:i1`` (``cap`` if none before it)."""
    ac = _xcorr(Yhat, Yhat, i0, i1, range(0, cap + 2), cols)
    for k in range(1, cap + 1):
        if ac[k] >= ac[k - 1] and ac[k] > ac[k + 1] and ac[k] > 0:
            return k
    return cap


def _peak(c, lags):
    """Sub-sample lag, height and curvature (per sample squared, 0 at an edge) of the highest point of ``c``
    over ``lags`` (a parabola through it and its neighbours)."""
    j = int(np.argmax(c))
    if 0 < j < len(c) - 1:
        ym, y0, yp = c[j - 1], c[j], c[j + 1]
        den = ym - 2 * y0 + yp
        if den < 0:
            off = float(np.clip(0.5 * (ym - yp) / den, -0.5, 0.5))
            return lags[j] + off, float(y0 - 0.25 * (ym - yp) * off), float(-den)
    return float(lags[j]), float(c[j]), 0.0


def window_lags(Y, Yhat, t, span, fs: float, windows: int = WINDOWS) -> dict | None:
    """The lag (s) of the data against the nominal response in ``windows`` windows over ``span``.

    Parameters
    ----------
    Y, Yhat : (n, 10) arrays
        The data (NaN: not measured) and the nominal car's response at the declared speed on the same samples.
    t : (n,) array
        The samples' model times (s; 0 at the start).
    span : (float, float)
        Model times (s) between which the wheels are on the track's features.

    Returns
    -------
    dict or None
        ``t`` (window centres, s), ``lag`` (s: the data at ``t`` look like the response at ``t + lag``),
        ``correlation`` (at each window's peak), ``sigma`` (s: how far what the nominal response does not
        explain, ``sqrt(1 - correlation^2)`` of the window, can move its peak, given the peak's curvature:
        wide on a slow response, narrow on a sharp one) and ``deviation``: the speed's relative deviation
        from the declared one between neighbouring windows (``diff(lag) / diff(t)``); None when the span
        holds too few samples.
    """
    Y = np.asarray(Y, dtype=float)
    cols = _norm_cols(Y, Yhat)
    i_lo = int(np.searchsorted(t, span[0]))
    i_hi = int(np.searchsorted(t, span[1]))
    size = (i_hi - i_lo) // windows
    if not cols or size < 8:
        return None
    edges = [i_lo + k * size for k in range(windows + 1)]
    cap = int(np.ceil(LAG_MAX * fs))
    radius = [max(1, min(cap, int(HALF_PERIOD * _period(Yhat, a, b, cols, cap))))
              for a, b in zip(edges[:-1], edges[1:])]
    lag = np.full(windows, np.nan)
    rho = np.full(windows, np.nan)
    curv = np.zeros(windows)

    def at(k, centre):
        c0 = int(round(centre))
        lags = np.arange(c0 - radius[k] - 1, c0 + radius[k] + 2)
        c = _xcorr(Y, Yhat, edges[k], edges[k + 1], lags, cols)
        return _peak(c[1:-1], lags[1:-1])

    # the start aligns the run as a whole: the best-matching window's lag is near 0 (a peak inside the search
    # range, not at its edge); follow it to both ends
    first = [at(k, 0.0) for k in range(windows)]
    inside = [r if abs(lg) < radius[k] else -np.inf for k, (lg, r, _) in enumerate(first)]
    k0 = int(np.argmax(inside)) if np.isfinite(max(inside)) else int(np.argmax([r for _, r, _ in first]))
    lag[k0], rho[k0], curv[k0] = first[k0]
    for order in (range(k0 + 1, windows), range(k0 - 1, -1, -1)):
        prev = [k0]
        for k in order:
            guess = lag[prev[-1]]
            if len(prev) > 1:  # a constant speed error makes the lag grow linearly: extrapolate
                guess += (lag[prev[-1]] - lag[prev[-2]]) * (k - prev[-1]) / (prev[-1] - prev[-2])
            lag[k], rho[k], curv[k] = at(k, guess)
            prev.append(k)
    centres = t[[(a + b) // 2 for a, b in zip(edges[:-1], edges[1:])]]
    lag_s = lag / fs
    # how far what the nominal response does not explain can move a window's peak: a part of relative size
    # sqrt(1 - rho^2) with the same bandwidth tilts a peak of curvature kappa (1/s^2) by up to that over
    # sqrt(rho kappa) seconds
    kappa = curv * fs ** 2
    r = np.clip(rho, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.where((kappa > 0) & (r > 0), np.sqrt(1.0 - r ** 2) / np.sqrt(r * kappa), np.inf)
    return {"t": centres, "lag": lag_s, "correlation": rho, "sigma": sigma,
            "deviation": np.diff(lag_s) / np.diff(centres)}


def speed_summary(w: dict) -> dict | None:
    """What the lags say of the speed (None with fewer than three windows).

    ``deviation``: the relative deviation from the declared speed of the mean speed between two neighbouring
    windows (their lags' difference over their distance in time), ``std`` its uncertainty (the two windows'
    ``sigma`` combined, over the same time); ``low`` and ``high`` the lowest and the highest deviation;
    ``beyond`` the largest deviation that exceeds setting ``speed.z_min`` times its uncertainty (0 if none does: the
    lags cannot tell the speed from the declared one); ``mean``: the relative difference from the declared speed
    of the constant speed that best explains the lags (the slope of a straight line through them);
    ``wander``: the largest departure of a deviation from ``mean``.
    """
    tc, lag, sig = w["t"], w["lag"], w["sigma"]
    ok = np.isfinite(lag)
    if ok.sum() < 3:
        return None
    tc, lag, sig = tc[ok], lag[ok], sig[ok]
    dev = np.diff(lag) / np.diff(tc)
    std = np.hypot(sig[:-1], sig[1:]) / np.diff(tc)
    seen = np.abs(dev) > defaults["speed.z_min"] * std
    k = int(np.argmax(np.where(seen, np.abs(dev), -1.0)))
    mean = float(np.polyfit(tc, lag, 1)[0])
    return {"mean": mean, "low": float(dev.min()), "high": float(dev.max()),
            "wander": float(np.max(np.abs(dev - mean))), "beyond": float(abs(dev[k])) if seen.any() else 0.0,
            "beyond_std": float(std[k]) if seen.any() else None, "deviation": dev, "std": std}


def speed_finding(run_id: str, where: str, speed: float, s: dict, limit: float | None = None) -> Finding | None:
    """The error refusing a run whose speed, as the data show it (:func:`speed_summary`), leaves the declared
    ``speed`` by more than ``limit`` (default setting ``speed.wander_max``); None when it holds it."""
    limit = defaults["speed.wander_max"] if limit is None else limit
    if s["beyond"] <= limit:
        return None
    log = ("log speed: map a speed or distance channel (GPS, wheel speed or odometer) in [channels], see "
           "docs/real-data.md")
    if s["wander"] <= defaults["speed.steady"] * limit and abs(s["mean"]) > limit:
        v = speed * (1 + s["mean"])
        msg = (f"run '{run_id}'{where}: its speed looks steady but not {speed:g} m/s: the data match the track "
               f"at about {v:.3g} m/s ({100 * s['mean']:+.1f} %). Set speed = {v:.3g} for run '{run_id}', or "
               f"{log}")
    else:
        msg = (f"run '{run_id}'{where}: its speed wanders: the data put it between {100 * s['low']:+.1f} % and "
               f"{100 * s['high']:+.1f} % of the declared {speed:g} m/s along the track (measured to "
               f"+-{100 * s['beyond_std']:.1f} %; {100 * limit:g} % is allowed without a speed channel): {log}, or "
               "drive the run again at a steady speed")
    return Finding(ERROR, "track", msg, run_id, "speed")


__all__ = ["WINDOWS", "speed_finding", "speed_summary", "window_lags"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "WANDER_MAX": "speed.wander_max", "Z_MIN": "speed.z_min", "STEADY": "speed.steady"})
