"""The body sensors' relative gains from rigid-body redundancy (SPEC §12; docs/uncertainty.md).

Four body accelerometers and two gyros measure three body motions (SPEC §1:
``a_i = z'' - x_i theta'' + y_i phi''``; ``pitch_rate = theta'``,
``roll_rate = phi'``), whatever the car's masses, springs and dampers:

1. **Warp.** ``(a_fl - a_fr) / t_f = (a_rl - a_rr) / t_r`` (both are
   ``phi''``). With gains, the recorded ``m_c = g_c a_c`` satisfy
   ``sum_c w_c m_c(t) / g_c = 0`` at every sample (``w = (1/t_f, -1/t_f,
   -1/t_r, 1/t_r)``): ``1/g`` spans the null space of the matrix
   ``[w_c m_c(t)]`` (its smallest right singular vector, total least
   squares). Heave, pitch and roll moving independently leave that null
   space one-dimensional: the four gains are fixed up to one common factor.
2. **Gyros against accelerometers.** The corrected accelerations give
   ``phi'' = (a_fl - a_fr)/t_f`` (and the rear pair's) and ``theta'' =
   ((a_rl + a_rr) - (a_fl + a_fr)) / (2 L)``; each gyro's gain relative to
   the accelerometers' common one is the least-squares ratio of its
   increments over two samples, ``G[k+1] - G[k-1]``, to Simpson's integral of
   that acceleration over the same two samples (error ``(w h)^4 / 180``:
   1e-3 at 20 Hz and 200 Hz; the trapezoid's ``(w h)^2 / 12`` would be 3 %).
   Increments need no integration constant: a run that starts moving counts.

What remains unknown is one common gain of all six body sensors (scaling
accelerations and rates together keeps every relation) and every axle
accelerometer's gain (each wheel is a body of its own: nothing redundant):
those only the model fit can see, weakly (docs/uncertainty.md). The
relations assume a rigid body: a body that twists (its torsion mode,
excited by the chassis-twist track) breaks relation 1 as a gain error would.

Standard errors by the jackknife over runs (runs are independent
experiments). Pure functions of the run data: no simulation.
"""

from __future__ import annotations

import numpy as np

from ...settings import defaults, legacy_names
from ...data.dataset import Dataset

BODY = ("body_az_fl", "body_az_fr", "body_az_rl", "body_az_rr")
GYROS = ("pitch_rate", "roll_rate")


def _runs(ds: Dataset) -> list:
    """``(time, (n, 4) body, (n, 2) gyros or None)`` of every run with all four body channels."""
    out = []
    for r in ds.runs:
        rd = ds.data.get(r.id)
        if rd is None or not all(c in rd.channels for c in BODY):
            continue
        A = np.column_stack([rd.channels[c] for c in BODY])
        G = np.column_stack([rd.channels[c] for c in GYROS]) if all(c in rd.channels for c in GYROS) else None
        out.append((np.asarray(rd.time, dtype=float), A, G))
    return out


def _simpson(t, y):
    """Simpson's integral of ``y`` (uniform ``t``) over each pair of samples ``[t[k-1], t[k+1]]``, ``(n - 2,)``."""
    h = float(t[1] - t[0])
    return h / 3.0 * (y[:-2] + 4.0 * y[1:-1] + y[2:])


def _gains(runs, geometry) -> np.ndarray:
    """The six relative gains (four body accelerometers normalised to mean 1, then pitch and roll gyro
    relative to them; NaN for a gyro no run has) from the runs given."""
    tf, tr, L = geometry.track_front, geometry.track_rear, geometry.wheelbase
    w = np.array([1 / tf, -1 / tf, -1 / tr, 1 / tr])
    M = np.vstack([A for _, A, _ in runs]) * w
    M = M / np.sqrt(np.mean(M * M, axis=0))  # columns of one size: the singular vector weighs them alike
    _, _, Vt = np.linalg.svd(M, full_matrices=False)
    inv = Vt[-1] / np.sqrt(np.mean(np.vstack([A for _, A, _ in runs]) ** 2 * w ** 2, axis=0))
    g = 1.0 / inv
    g = g / np.mean(g)
    num, den = np.zeros(2), np.zeros(2)
    for t, A, G in runs:
        if G is None:
            continue
        a = A / g
        roll = _simpson(t, 0.5 * ((a[:, 0] - a[:, 1]) / tf + (a[:, 2] - a[:, 3]) / tr))
        pitch = _simpson(t, ((a[:, 2] + a[:, 3]) - (a[:, 0] + a[:, 1])) / (2 * L))
        for k, ref in enumerate((pitch, roll)):
            num[k] += (G[2:, k] - G[:-2, k]) @ ref
            den[k] += ref @ ref
    with np.errstate(invalid="ignore", divide="ignore"):
        gy = np.where(den > 0, num / den, np.nan)
    return np.concatenate([g, gy])


def rigid_body_gains(ds: Dataset) -> dict | None:
    """The body sensors' gains relative to each other, from rigid-body redundancy (module docstring).

    Parameters
    ----------
    ds : Dataset

    Returns
    -------
    dict or None
        ``{"gains": {channel: {"relative_gain", "std"}}, "runs": n, "basis": str}`` (the four body
        accelerometers normalised to mean 1; each gyro relative to that mean; ``std`` by the jackknife over
        runs, None with fewer than three runs); None without at least two runs with all four body channels.
    """
    runs = _runs(ds)
    if len(runs) < 2:
        return None
    stacked = np.vstack([A for _, A, _ in runs])
    if not np.all(np.isfinite(stacked)) or np.any(np.sqrt(np.mean(stacked ** 2, axis=0)) == 0):
        return None  # a flat or broken body channel: nothing to compare (the data checks name it)
    g = _gains(runs, ds.geometry)
    if not np.all(np.isfinite(g[:len(BODY)])):
        return None
    n = len(runs)
    std = np.full(g.size, np.nan)
    if n >= 3:
        jk = np.array([_gains(runs[:k] + runs[k + 1:], ds.geometry) for k in range(n)])
        std = np.sqrt((n - 1) / n * np.sum((jk - jk.mean(axis=0)) ** 2, axis=0))
    gains = {}
    for c, v, s in zip(BODY + GYROS, g, std):
        if np.isfinite(v):
            gains[c] = {"relative_gain": float(v), "std": float(s) if np.isfinite(s) else None}
    return {"gains": gains, "runs": n,
            "basis": "rigid-body redundancy of the body sensors (relative to the body accelerometers' mean gain; "
                     "the common gain and the axle accelerometers' are not determined by it)"}


def gain_notes(block: dict | None, sensitivity_std: dict) -> list[str]:
    """A line for each body sensor whose relative gain departs from 1 by more than setting ``redundancy.flag_sigma``
    standard errors and more than twice its declared ``sensitivity_std`` (setting ``redundancy.flag_undeclared``
    without one)."""
    if not block:
        return []
    out = []
    for c, e in block["gains"].items():
        dev, s = e["relative_gain"] - 1.0, e["std"]
        allowed = 2 * sensitivity_std.get(c, defaults["redundancy.flag_undeclared"] / 2)
        if s is not None and abs(dev) > defaults["redundancy.flag_sigma"] * s and abs(dev) > allowed:
            out.append(f"{c} reads {100 * dev:+.2g} % against the other body sensors (rigid-body redundancy, "
                       f"± {100 * s:.2g} %), more than its declared sensitivity allows: check its calibration, "
                       "mounting and sign")
    return out


__all__ = ["rigid_body_gains", "gain_notes", "BODY", "GYROS"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "FLAG_SIGMA": "redundancy.flag_sigma", "FLAG_UNDECLARED": "redundancy.flag_undeclared"})
