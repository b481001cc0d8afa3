"""Is the cost as curved as the error bars say, out to ±2 of them? One cost evaluation a side a parameter.

An error bar is read off the cost's curvature at the minimum: ±2 std is
where the quadratic that curvature draws has risen by four times its rise at
one std. In a long, flat valley (an engine's pitch mode on mounts, where its
inertia, frequency and damping trade against one another; measured: the
all-realities SUV's ``zeta_pp`` moved 0.28 of its error bar and that error
bar doubled when the polish was only asked to stop ten times closer) the
cost out there rises much less than the quadratic says, and the printed
error bar is narrower than what the data allow.

:func:`profile_ratios` walks each free parameter ``k`` along its profile
line (the direction in which the other parameters follow it at their
linearised best: the column ``k`` of the inverse curvature) out to ``a``
times its error bar on each side, and divides the cost's rise there by the
quadratic's. The rest of the parameters then sit on a straight line, not at
their own best, so the cost's rise is at least the profile's: a ratio below
setting ``shape.flat_ratio`` (a quarter: the interval at least twice as wide
as printed, where the cost grows as a square beyond) says for certain that
the error bar is optimistic. A ratio above it proves nothing either way; a
side that would cross a search bound is not judged (None).

It changes no number: the result's ``polish.shape`` holds the ratios, the
``error_bar_shape`` assessment (:class:`rideid.estimate.records.ShapeAssessment`)
names the parameters, and the terminal and the report say it beside the
estimates.
"""

from __future__ import annotations

import numpy as np

from ...settings import defaults


def profile_ratios(cost, x0, C, sigma, bounds, *, a: float | None = None, curvature=None, small=None,
                   scale=None) -> list:
    """Each parameter's cost rise at ``±a`` error bars along its profile line, over its quadratic's.

    Parameters
    ----------
    cost : callable
        ``(n, d)`` rows -> ``(n,)`` costs (a sum of squares, or any positive multiple of one).
    x0 : (d,) the minimum; C : (d, d) the inverse curvature of the cost there, up to a positive factor (a white
        covariance): its column ``k`` over ``C[k, k]`` is the step that moves parameter ``k`` by one
    sigma : (d,) the error bars, in ``x0``'s units; bounds : (lower (d,), upper (d,))
    a : how many error bars out (None: setting ``shape.error_bars``)
    curvature : (d,) the cost's rise per unit of ``x_k`` squared along the line, known (a measured Hessian:
        ``1 / Hinv[k, k]`` for the half Hessian of a sum of squares); None: measured here from two steps of
        ``small`` (d,) each side
    scale : (d,) each parameter's magnitude (None: ``|x0|``): an error bar whose ``a`` times is within the rounding
        of a number that size (``sqrt(eps)`` of it: a noise-free fit's) is not judged, its cost's rise being rounding
    Returns
    -------
    list over parameters of ``[minus, plus]`` (float, or None where not judged: no finite error bar, a step beyond a
    bound, a cost that is not finite at the minimum)
    """
    a = defaults["shape.error_bars"] if a is None else float(a)
    x0 = np.asarray(x0, dtype=float)
    C = np.asarray(C, dtype=float)
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    d = x0.size
    floor = np.sqrt(np.finfo(float).eps) * (np.abs(x0) if scale is None else np.asarray(scale, dtype=float))
    rows, plan = [x0], []
    for k in range(d):
        ckk, s = C[k, k], float(sigma[k])
        if not (np.isfinite(ckk) and ckk > 0 and np.isfinite(s) and a * s > floor[k] and np.isfinite(C[:, k]).all()):
            plan.append(None)
            continue
        u = C[:, k] / ckk
        steps = [-a * s, a * s] + ([] if curvature is not None else [-small[k], small[k]])
        inside = [bool(np.all(x0 + t * u >= lo) and np.all(x0 + t * u <= hi)) for t in steps]
        if curvature is None and not all(inside[2:]):
            plan.append(None)
            continue
        plan.append((len(rows), u, steps, inside))
        rows += [x0 + t * u for t in steps]
    c = np.asarray(cost(np.array(rows)), dtype=float)
    out = []
    for k, p in enumerate(plan):
        if p is None or not np.isfinite(c[0]):
            out.append([None, None])
            continue
        i, u, steps, inside = p
        if curvature is not None:
            q = float(curvature[k])
        else:
            h = steps[3]
            q = ((c[i + 2] + c[i + 3]) / 2 - c[0]) / h ** 2
        if not (np.isfinite(q) and q > 0):
            out.append([None, None])
            continue
        b = steps[1]
        out.append([float((c[i + j] - c[0]) / (q * b * b)) if inside[j] and not np.isnan(c[i + j]) else None
                    for j in (0, 1)])
    return out


def record(names, ratios) -> dict:
    """``polish.shape`` of result.json: the ratios by parameter, the error bars out and the threshold in force,
    and the parameters whose error bar is optimistic (a ratio below ``shape.flat_ratio`` on either side)."""
    flat = defaults["shape.flat_ratio"]
    ratio = {n: r for n, r in zip(names, ratios)}
    optimistic = [n for n, r in ratio.items() if any(v is not None and v < flat for v in r)]
    return {"error_bars": defaults["shape.error_bars"], "flat_ratio": flat, "ratio": ratio,
            "optimistic": optimistic}


def caveat(shape: dict | None) -> str | None:
    """The sentence naming the parameters whose error bars are optimistic (None when none is)."""
    if not shape or not shape.get("optimistic"):
        return None
    a, flat = shape["error_bars"], shape["flat_ratio"]
    worst = {n: min(v for v in shape["ratio"][n] if v is not None) for n in shape["optimistic"]}
    one = len(worst) == 1
    rises = ", ".join(f"{100 * w:.0f} %" + ("" if one else f" ({n})") for n, w in worst.items())
    return (f"the error bar{'' if one else 's'} of {', '.join(worst)} {'is' if one else 'are'} optimistic: out at "
            f"±{a:g} of {'it' if one else 'them'} along {'its' if one else 'their'} profile line the cost rises only "
            f"{rises} of what the error bar assumes (below {100 * flat:.0f} %: no more than it assumes at "
            f"±{a * np.sqrt(flat):g}), so the data allow {'this value' if one else 'these values'} further than "
            "printed (a flat valley of the cost)")
