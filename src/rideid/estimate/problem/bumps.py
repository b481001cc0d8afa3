"""Bump stops in an identification (SPEC §8, group ``bump_stops``): the start, which stops the runs reach,
and the result's block.

Start (a scan)
--------------
The global search runs on the linear model (as for damper curves), which
has no stops. Its best car is simulated as the nonlinear car without stops
and the compressions ``d_i = z_i - z_bi`` (m, from static ride height) of
each axle's two corners over all runs are collected. For each axle whose
stop is not fully known, candidate clearances are the compressions that
setting ``bumps.scan_counts`` samples exceed (20 .. 1280 samples: from a stop touched
on the highest peaks only to one met on every large stroke), inside the
clearance bounds, crossed with the rates setting ``bumps.scan_rates`` (N/m, inside the
rate bounds); a known clearance or rate is the only candidate of its kind.
Every candidate car (the search's car with that one stop, the other axle
without) is scored on the equal-weight cost in one batch. An axle's best
candidate starts the polish when it lowers the cost by at least
setting ``bumps.min_gain`` (relative) against the car without that stop; otherwise the
stop is **not reached**. The scan is a coarse grid on purpose: the polish
(Gauss-Newton on the nonlinear car) finishes clearance and rate together,
and it only needs the stop engaged (a stop that touches no sample has zero
gradient, so a start above every compression would never move).

Reached
-------
An axle's stop is reached when at least setting ``bumps.min_samples`` samples (both
corners of the axle, all runs) of the fitted car's compression exceed its
clearance (checked on the scan's start and again on the polished car; an
axle that fails after the polish is frozen and the polish repeated). A stop
not reached is not identifiable: its columns leave the free parameters and
are held at clearance = 1.25 x the largest compression the car reaches (or
the known clearance) and rate 0 (or the known rate), so the stop never acts,
and the result reports them ``reached: false`` without standard errors
("not reached — not a number to trust"; the largest compression is a lower
limit of the clearance).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...settings import defaults, legacy_names
from ...model.nonlinear import BUMP_STOP_NAMES, check_nonlinear, travel_by_run
from .cost import min_improvement

#: how the text output marks a stop no run reaches
NOT_REACHED = "not reached — not a number to trust"
AXLES = (("front", "f"), ("rear", "r"))


def compressions(cf, P) -> tuple[np.ndarray, np.ndarray]:
    """Suspension compressions (m, from static ride height, compression +) of car ``P`` (a full row of
    ``cf.space``) over every run of ``cf``: ``(front, rear)``, both corners of each axle concatenated."""
    geom, layout = cf.space.geometry, cf.space.layout
    sim = replace(cf.simulator, layout=layout, rho=defaults["bumps.state_rho"]).bind(geom, cf.input_runs)
    d = travel_by_run(sim, check_nonlinear(P, geom, layout), P[cf.space.col["a"]])
    d = [t[k:] for t, k in zip(d, cf.lead)]  # a moving start's recorded samples (SPEC §9)
    return np.concatenate([t[:, :2].ravel() for t in d]), np.concatenate([t[:, 2:].ravel() for t in d])


def reach(cf, P) -> dict:
    """Per axle: samples beyond the clearance of car ``P``, the largest compression, and reached or not."""
    out = {}
    for (axle, a), d in zip(AXLES, compressions(cf, P)):
        c = float(P[cf.space.col[f"bs_clear_{a}"]])
        n = int(np.count_nonzero(d > c))
        out[axle] = {"samples_beyond_clearance": n, "max_compression": float(d.max()),
                     "reached": n >= defaults["bumps.min_samples"]}
    return out


def frozen_values(space, axle_letter: str, max_compression: float) -> dict:
    """The held columns of a stop not reached: clearance beyond every compression (or known), rate 0 (or known)."""
    out = {}
    c, r = f"bs_clear_{axle_letter}", f"bs_rate_{axle_letter}"
    if c not in space.fixed:
        out[c] = max(defaults["bumps.unreached_factor"] * max_compression, 1e-3)
    if r not in space.fixed:
        out[r] = 0.0
    return out


def spring_share(d, c) -> float:
    """The share of a stop's rate a linear spring fitted to spring + stop over the compressions ``d`` takes up:
    least squares of ``k d`` on ``rate max(d - c, 0)`` over the samples, per unit rate."""
    d = np.asarray(d, dtype=float)
    return float(np.sum(np.maximum(d - c, 0.0) * d) / max(np.sum(d * d), 1e-30))


def scan_start(cf, x) -> tuple[np.ndarray, dict, dict]:
    """The bump-stop start from free row ``x`` of ``cf.space`` (its stop columns ignored): module docstring.

    Returns ``(x with the start stops, bump_frozen for the axles not reached, record)``; the record per axle
    holds the scan's gain, the largest compression and reached.
    """
    space = cf.space
    names = list(space.names)
    x = np.asarray(x, dtype=float).copy()
    bnd = {n: space.bounds[names.index(n)] for n in names}

    def set_stop(row, a, c, k, d=None):
        for n, v in ((f"bs_clear_{a}", c), (f"bs_rate_{a}", k)):
            if n in names:
                row[names.index(n)] = v
        ks = f"k_s{a}"
        if d is not None and ks in names:  # the linear fit's spring carried the stop: take it out
            lo, hi = bnd[ks]
            row[names.index(ks)] = np.clip(row[names.index(ks)] - k * spring_share(d, c), lo, hi)

    def no_stop_clear(a):
        n = f"bs_clear_{a}"
        return space.fixed.get(n, bnd[n][1] if n in bnd else 0.15)

    # the car without stops (a known rate with its clearance beyond every compression)
    x0 = x.copy()
    for _, a in AXLES:
        set_stop(x0, a, no_stop_clear(a), 0.0)
    # compressions of the car without stops (rates 0: the clearances do not matter)
    Pq = space.full(x0[None])[0]
    for _, a in AXLES:
        Pq[space.col[f"bs_rate_{a}"]] = 0.0
    dq = dict(zip((a for _, a in AXLES), compressions(cf, Pq)))
    rows, tags = [x0], [None]
    for _axle, a in AXLES:
        c_name, r_name = f"bs_clear_{a}", f"bs_rate_{a}"
        if c_name not in names and r_name not in names:
            continue
        d = np.sort(dq[a])[::-1]
        if c_name in names:
            lo, hi = bnd[c_name]
            cs = sorted({float(d[n]) for n in defaults["bumps.scan_counts"] if n < d.size and lo <= d[n] <= hi})
        else:
            c = space.fixed[c_name]
            cs = [c] if np.count_nonzero(d > c) >= defaults["bumps.min_samples"] else []
        if r_name in names:
            lo, hi = bnd[r_name]
            ks = [k for k in defaults["bumps.scan_rates"] if lo <= k <= hi] or [0.5 * (lo + hi)]
        else:
            ks = [space.fixed[r_name]]
        for c in cs:
            for k in ks:
                for adjust in (None, dq[a]):
                    row = x0.copy()
                    set_stop(row, a, c, k, adjust)
                    rows.append(row)
                    tags.append((a, c, k, adjust is not None))
    J = cf(np.array(rows))  # equal weights (cf is the identification's copy)
    record, frozen = {}, {}
    for axle, a in AXLES:
        c_name, r_name = f"bs_clear_{a}", f"bs_rate_{a}"
        mine = [(J[i], t) for i, t in enumerate(tags) if t is not None and t[0] == a and np.isfinite(J[i])]
        best = min(mine, key=lambda v: v[0]) if mine else None
        gain = 0.0 if best is None else float((J[0] - best[0]) / J[0])
        rec = {"scan_gain": gain, "max_compression": float(dq[a].max())}
        if c_name not in names and r_name not in names:  # known stop: used as given
            rec["reached"] = bool(np.count_nonzero(dq[a] > space.fixed[c_name]) >= defaults["bumps.min_samples"])
        elif best is not None and (gain >= defaults["bumps.min_gain"] or J[0] - best[0] >= min_improvement()):
            set_stop(x, a, best[1][1], best[1][2], dq[a] if best[1][3] else None)
            rec["reached"] = True
            rec["start"] = {"clearance": best[1][1], "rate": best[1][2]}
        else:
            rec["reached"] = False
            frozen.update(frozen_values(space, a, float(dq[a].max())))
        record[axle] = rec
    return x, frozen, record


def bump_block(space, P, cov_white, cov_robust, names, record) -> dict:
    """``result.json`` ``"bump_stops"``: per axle clearance and rate with ``std``, ``std_robust`` (None when the
    stop is not reached), ``reached``, the samples beyond the clearance and the largest compression."""
    def sd(cov, n):
        if cov is None or n not in names or n in space.bump_frozen:
            return None if n not in space.fixed else 0.0
        v = cov[names.index(n)][names.index(n)]
        return float(np.sqrt(v)) if np.isfinite(v) and v >= 0 else None

    out = {"unit": {"clearance": "m", "rate": "N/m"},
           "rule": f"a stop is reached when at least {defaults['bumps.min_samples']} samples (both corners of the "
                   "axle, all runs) "
                   "of the fitted car's compression exceed its clearance"}
    for axle, a in AXLES:
        rec = (record or {}).get(axle, {})
        c, r = f"bs_clear_{a}", f"bs_rate_{a}"
        out[axle] = {"reached": bool(rec.get("reached", c not in space.bump_frozen)),
                     "clearance": float(P[space.col[c]]), "rate": float(P[space.col[r]]),
                     "std": [sd(cov_white, c), sd(cov_white, r)],
                     "std_robust": [sd(cov_robust, c), sd(cov_robust, r)],
                     "known": [c in space.fixed, r in space.fixed]}
        for k in ("samples_beyond_clearance", "max_compression"):
            if k in rec:
                out[axle][k] = rec[k]
    return out


def format_bump_stops(bs: dict) -> str:
    """The stops as text: per axle clearance and rate ± 2 std_robust, or "not reached"."""
    if not bs:
        return ""
    lines = ["bump stops (at the wheel; clearance from static ride height; ± 2 std_robust)"]
    for axle, _ in AXLES:
        e = bs[axle]
        if not e["reached"]:
            mc = e.get("max_compression")
            lines.append(f"  {axle:<5}  not reached — not a number to trust"
                         + ("" if mc is None else f" (largest compression {1000 * mc:.1f} mm: the clearance is "
                                                  "more than that)"))
            continue
        sc, sr = e["std_robust"]
        c = f"{1000 * e['clearance']:.2f} mm" + ("" if not sc else f" ± {2000 * sc:.2g}")
        r = f"{e['rate']:.4g} N/m" + ("" if not sr else f" ± {2 * sr:.2g}")
        lines.append(f"  {axle:<5}  clearance {c}, rate {r}")
    return "\n".join(lines)


__all__ = ["BUMP_STOP_NAMES", "NOT_REACHED", "bump_block", "compressions", "format_bump_stops",
           "reach", "scan_start"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "MIN_SAMPLES": "bumps.min_samples", "SCAN_COUNTS": "bumps.scan_counts", "SCAN_RATES": "bumps.scan_rates",
    "MIN_GAIN": "bumps.min_gain", "UNREACHED_FACTOR": "bumps.unreached_factor", "STATE_RHO": "bumps.state_rho"})
