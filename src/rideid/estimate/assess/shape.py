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

:func:`profile_reach` then walks a named parameter's line on, on each side
flatter than the quadratic, to the last point where the cost is still below
the rise the error bar assumes at ±2 (setting ``shape.reach``): a bound on
how far the data allow the value, for the same reason a lower one.

It changes no number: the result's ``polish.shape`` holds the ratios, the
``error_bar_shape`` assessment (:class:`rideid.estimate.records.ShapeAssessment`)
names the parameters, and the terminal and the report say it beside the
estimates.
"""

from __future__ import annotations

import numpy as np

from ...settings import defaults


def _lines(C, x0, sigma, a: float, lo, hi) -> list:
    """Each parameter's profile line ``(u, c)``: ``u`` the step that moves ``x_k`` by one, the others following at
    their linearised best, and ``c`` the inverse curvature along it (``C[k, k]``); None where there is none.

    A parameter whose ``±a`` error bars cross a search bound (tire damping at 0) is held on every other parameter's
    line: the line is the one of the cost with it fixed (the inverse curvature conditioned on it, a Schur
    complement), so that a line does not leave the box only because that parameter follows it."""
    d = x0.size
    with np.errstate(invalid="ignore"):
        near = np.isfinite(sigma) & ((x0 - a * sigma < lo) | (x0 + a * sigma > hi))
    conditioned = {}
    out = []
    for k in range(d):
        held = tuple(j for j in np.flatnonzero(near) if j != k)
        if held not in conditioned:
            free = np.array([j for j in range(d) if j not in held])
            Cf = C[np.ix_(free, free)]
            if held:
                Cfa = C[np.ix_(free, held)]
                Cf = Cf - Cfa @ np.linalg.pinv(C[np.ix_(held, held)]) @ Cfa.T
            conditioned[held] = (free, Cf)
        free, Cf = conditioned[held]
        i = int(np.flatnonzero(free == k)[0])
        ckk = Cf[i, i]
        if not (np.isfinite(ckk) and ckk > 0 and np.isfinite(Cf[:, i]).all()):
            out.append(None)
            continue
        u = np.zeros(d)
        u[free] = Cf[:, i] / ckk
        out.append((u, float(ckk)))
    return out


def _within(x, lo, hi) -> bool:
    return bool(np.all(x >= lo) and np.all(x <= hi))


def profile_ratios(cost, x0, C, sigma, bounds, *, a: float | None = None, exact: bool = False, small=None,
                   scale=None) -> list:
    """Each parameter's cost rise at ``±a`` error bars along its profile line, over its quadratic's
    (:func:`ratios_and_curvatures`, the ratios alone)."""
    return ratios_and_curvatures(cost, x0, C, sigma, bounds, a=a, exact=exact, small=small, scale=scale)[0]


def ratios_and_curvatures(cost, x0, C, sigma, bounds, *, a: float | None = None, exact: bool = False, small=None,
                          scale=None) -> tuple[list, list, list]:
    """Each parameter's cost rise at ``±a`` error bars along its profile line, over its quadratic's, the
    curvature used (per unit of ``x_k`` squared; None where not judged) and the lines (:func:`_lines`).

    Parameters
    ----------
    cost : callable
        ``(n, d)`` rows -> ``(n,)`` costs (a sum of squares, or any positive multiple of one).
    x0 : (d,) the minimum; C : (d, d) the inverse curvature of the cost there, up to a positive factor (a white
        covariance): its column ``k`` over ``C[k, k]`` is the step that moves parameter ``k`` by one (with the
        parameters held whose error bars cross a bound, :func:`_lines`)
    sigma : (d,) the error bars, in ``x0``'s units; bounds : (lower (d,), upper (d,))
    a : how many error bars out (None: setting ``shape.error_bars``)
    exact : ``C`` is the inverse of the cost's half Hessian itself (a measured Hessian of a sum of squares): the
        cost's rise per unit of ``x_k`` squared along the line is ``1 / c`` (:func:`_lines`); else measured here
        from two steps of ``small`` (d,) each side
    scale : (d,) each parameter's magnitude (None: ``|x0|``): an error bar whose ``a`` times is within the rounding
        of a number that size (``sqrt(eps)`` of it: a noise-free fit's) is not judged, its cost's rise being rounding
    Returns
    -------
    ratios : list over parameters of ``[minus, plus]`` (float, or None where not judged: no finite error bar, a step
    beyond a bound, a cost that is not finite at the minimum); curvatures : list over parameters; lines : list
    """
    a = defaults["shape.error_bars"] if a is None else float(a)
    x0 = np.asarray(x0, dtype=float)
    C = np.asarray(C, dtype=float)
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    d = x0.size
    floor = np.sqrt(np.finfo(float).eps) * (np.abs(x0) if scale is None else np.asarray(scale, dtype=float))
    sigma = np.asarray(sigma, dtype=float)
    lines = _lines(C, x0, sigma, a, lo, hi)
    rows, plan = [x0], []
    for k in range(d):
        s = float(sigma[k])
        if lines[k] is None or not (np.isfinite(s) and a * s > floor[k]):
            plan.append(None)
            continue
        u = lines[k][0]
        steps = [-a * s, a * s] + ([] if exact else [-small[k], small[k]])
        inside = [_within(x0 + t * u, lo, hi) for t in steps]
        if not exact and not all(inside[2:]):
            plan.append(None)
            continue
        plan.append((len(rows), u, steps, inside))
        rows += [x0 + t * u for t in steps]
    c = np.asarray(cost(np.array(rows)), dtype=float)
    out, curv = [], []
    for k, p in enumerate(plan):
        q = None if p is None else (1.0 / lines[k][1] if exact
                                    else ((c[p[0] + 2] + c[p[0] + 3]) / 2 - c[0]) / p[2][3] ** 2)
        if q is None or not np.isfinite(c[0]) or not (np.isfinite(q) and q > 0):
            out.append([None, None])
            curv.append(None)
            continue
        i, u, steps, inside = p
        b = steps[1]
        out.append([float((c[i + j] - c[0]) / (q * b * b)) if inside[j] and not np.isnan(c[i + j]) else None
                    for j in (0, 1)])
        curv.append(q)
    return out, curv, lines


def check(cost, x0, C, sigma, bounds, names, *, to_x=None, **kw) -> dict:
    """``polish.shape`` (:func:`record`) of a fit at ``x0``: :func:`ratios_and_curvatures` (``kw``: its ``curvature``,
    ``small``, ``scale``), then for each parameter it names optimistic :func:`profile_reach`, as the parameter's
    own values (``to_x``: a row of ``x0``'s coordinates -> the parameters' row; None: the same)."""
    ratios, curv, lines = ratios_and_curvatures(cost, x0, C, sigma, bounds, **kw)
    rec = record(names, ratios, a=kw.get("a"))
    to_x = to_x or (lambda row: row)
    x0 = np.asarray(x0, dtype=float)
    reach = {}
    for k in (names.index(n) for n in rec["optimistic"]):
        u = lines[k][0]
        walked = [r is not None and r < 1 for r in ratios[k]]  # the sides flatter than the quadratic
        t = profile_reach(cost, x0, u, float(sigma[k]), bounds, curv[k], a=kw.get("a"), sides=walked)
        reach[names[k]] = {"value": float(to_x(x0)[k]), "walked": walked,
                           **{side: None if v is None else float(to_x(x0 + v * u)[k])
                              for side, v in zip(("lower", "upper"), t)}}
    rec["reach"] = reach
    return rec


def profile_reach(cost, x0, u, s: float, bounds, q: float, *, a: float | None = None, sides=(True, True)) -> list:
    """How far along a parameter's profile line ``u`` (:func:`_lines`: moving it by one) the cost stays below the
    rise its quadratic has at ``±a`` error bars ``s`` (``a^2 q s^2``, ``q`` the curvature along the line), walking
    out at the multiples of the error bar in setting ``shape.reach``:
    ``[minus, plus]``, each the step ``t`` (``x0 + t u``; negative on the minus side)
    of the last point of the walk still below that rise, or None when the walk ends (at a search bound, at an
    invalid car, or at its last point) still below it. The others on a straight line are not at their own best,
    so the profile's own interval reaches at least this far. ``sides``: which sides to walk (a side whose cost at
    ``±a`` already rose as much as its quadratic is not: None there)."""
    a = defaults["shape.error_bars"] if a is None else float(a)
    x0 = np.asarray(x0, dtype=float)
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    walk = [m for m in defaults["shape.reach"] if m > a]
    steps = [sign * m * s for sign in (-1, 1) for m in walk]
    inside = [bool(side) and _within(x0 + t * u, lo, hi) for side, t in zip(np.repeat(sides, len(walk)), steps)]
    c = np.asarray(cost(np.array([x0] + [x0 + t * u for t, ok in zip(steps, inside) if ok])), dtype=float)
    vals = iter(c[1:] - c[0])
    rises = [next(vals) if ok else None for ok in inside]
    level = a * a * q * s * s
    out = []
    for side in (0, 1):
        if not sides[side]:
            out.append(None)
            continue
        below, found = a, False
        for m, r in zip(walk, rises[side * len(walk):(side + 1) * len(walk)]):
            if r is None or not np.isfinite(r):
                break
            if r >= level:
                found = True
                break
            below = m
        out.append((-1, 1)[side] * below * s if found else None)
    return out


def record(names, ratios, a: float | None = None) -> dict:
    """``polish.shape`` of result.json: the ratios by parameter, the error bars out they were judged at (``a``;
    None: setting ``shape.error_bars``) and the threshold in force, and the parameters whose error bar is
    optimistic (a ratio below ``shape.flat_ratio`` on either side)."""
    flat = defaults["shape.flat_ratio"]
    ratio = {n: r for n, r in zip(names, ratios)}
    optimistic = [n for n, r in ratio.items() if any(v is not None and v < flat for v in r)]
    return {"error_bars": defaults["shape.error_bars"] if a is None else float(a), "flat_ratio": flat,
            "ratio": ratio, "optimistic": optimistic}


def with_shape(cost, x0, info: dict | None) -> dict | None:
    """A track fit's polish record with its ``shape`` (:func:`check`): the cost function ``cost``
    (:class:`rideid.CostFunction`: its ``names`` and ``space.bounds``) at the free parameters ``x0``, each profile
    line from the polish's white covariance, the error bars its ``covariance_robust``, the curvature measured at
    ±0.5 white std, the runs' starts held. ``info`` itself where it has no covariances (no polish)."""
    if not info or info.get("covariance") is None or info.get("covariance_robust") is None:
        return info
    d = len(cost.names)
    C = np.array(info["covariance"], dtype=float)[:d, :d]
    R = np.array(info["covariance_robust"], dtype=float)[:d, :d]
    with np.errstate(invalid="ignore"):
        white, robust = (np.sqrt(np.clip(np.diag(M), 0, None)) for M in (C, R))
    b = cost.space.bounds
    return dict(info, shape=check(cost, x0, C, robust, (b[:, 0], b[:, 1]), list(cost.names), small=0.5 * white))


def caveat(shape: dict | None) -> str | None:
    """The sentence naming the parameters whose error bars are optimistic (None when none is)."""
    if not shape or not shape.get("optimistic"):
        return None
    a, flat = shape["error_bars"], shape["flat_ratio"]
    worst = {n: min(v for v in shape["ratio"][n] if v is not None) for n in shape["optimistic"]}
    one = len(worst) == 1
    rises = ", ".join(f"{100 * w:.0f} %" + ("" if one else f" ({n})") for n, w in worst.items())
    reach = [_reach_words(n, r) for n, r in (shape.get("reach") or {}).items()]
    return (f"the error bar{'' if one else 's'} of {', '.join(worst)} {'is' if one else 'are'} optimistic: out at "
            f"±{a:g} of {'it' if one else 'them'} along {'its' if one else 'their'} profile line the cost rises only "
            f"{rises} of what the error bar assumes (below {100 * flat:.0f} %: no more than it assumes at "
            f"±{a * np.sqrt(flat):g}), so the data allow {'this value' if one else 'these values'} further than "
            "printed (a flat valley of the cost)" + (f"; along it the cost is still below the rise the error bar "
                                                     f"assumes at ±{a:g} at " + "; ".join(reach) if reach else ""))


def _reach_words(name: str, r: dict) -> str:
    """``zeta_pp = 0.081 and 0.104 (the estimate 0.0937)``: the walked sides' reach (``beyond the last point
    walked`` where the walk ended still below the rise)."""
    walked = r.get("walked") or [True, True]
    sides = [f"{r[key]:.4g}" if r.get(key) is not None else f"every point walked {word} it"
             for key, word, w in zip(("lower", "upper"), ("below", "above"), walked) if w]
    return f"{name} = {' and '.join(sides)} (the estimate {r['value']:.4g})"


def table_note(shape: dict | None, name: str) -> str | None:
    """The estimates tables' note of a parameter the check names: ``ERROR BAR OPTIMISTIC: the data allow at least
    0.0833 to 0.1053`` (a side the walk did not reach the rise on: ``beyond``); None for one it does not name."""
    if not shape or name not in (shape.get("optimistic") or ()):
        return None
    r = (shape.get("reach") or {}).get(name)
    if not r:
        return "ERROR BAR OPTIMISTIC"
    walked = r.get("walked") or [True, True]
    ends = [("beyond the walk" if r.get(k) is None else f"{r[k]:.4g}") if w else "the printed ±2 std"
            for k, w in zip(("lower", "upper"), walked)]
    return f"ERROR BAR OPTIMISTIC: the data allow at least {ends[0]} to {ends[1]}"
