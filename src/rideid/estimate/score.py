"""Scoring an identification against the truth (``rideid score``, the demo)."""

from __future__ import annotations

from ..settings import defaults, legacy_names
from ..model.params import ALL_NAMES, EXT_NAMES

AXLES = (("front", "f", "c_sf"), ("rear", "r", "c_sr"))


def _get(result, key):
    return getattr(result, key, None) if hasattr(result, "details") else result.get(key)


def _row(est, tr, status, rob, total=None, **extra) -> dict:
    """One row of the score: relative error (None for a zero or unknown truth), coverage by ±2 ``total``
    (``std_total``) where given, else by ±2 ``rob`` (``std_robust``); ``covered_robust`` by ±2 ``rob``."""
    err = None if not tr else 100.0 * (est - tr) / tr
    judged = status in ("estimated", "derived")
    rob = float(rob) if judged and rob else None  # 0 or null: no standard error to judge by
    total = float(total) if judged and total else rob

    def covers(s):
        return None if s is None or tr is None else bool(abs(est - tr) <= defaults["score.coverage_k"] * s)
    return {"estimate": est, "truth": tr, "error_percent": err, "status": status, "std_robust": rob,
            "std_total": total, "covered": covers(total), "covered_robust": covers(rob), **extra}


def score(result, truth: dict, dampers=None) -> dict:
    """Relative error of every parameter of ``result`` against ``truth``, the damper curves and bump stops too.

    Parameters
    ----------
    result : IdentificationResult or dict
        A result, or ``result.json`` read as a dict (``parameters`` ->
        name -> ``{"value", "fixed", "derived"}``; ``dampers``, ``bump_stops``).
    truth : dict
        Parameter name -> true value (SI), e.g. :func:`rideid.load_truth` (the bump stops ``bs_*`` with it).
    dampers : DamperCurves, optional
        The true damper curves (``truth.toml``'s ``[dampers]``,
        :func:`rideid.data.schema.load_truth_dampers`); None: the truth's dampers are linear (``c_sf``, ``c_sr``).

    Returns
    -------
    dict
        ``{"parameters": {name: {"estimate", "truth", "error_percent",
        "status", "std_robust", "std_total", "covered", "covered_robust"}},
        "worst_percent": largest |error| over the estimated (not fixed)
        parameters, "covered": how many estimates ±2 ``std_total`` covers
        the truth of (``std_robust`` in a result without ``std_total``),
        "coverable": of how many (those with a standard error),
        "covered_robust": how many ±2 ``std_robust`` covers, "basis":
        "std_total" or "std_robust", "notes": [lines]}``; ``status`` is
        ``"estimated"``, ``"known"``, ``"derived"`` or ``"not in the model"``
        (an extension of the truth the model lacks: estimate 0), for a knot force ``"not excited"`` (no run
        reached it: its force is not trusted, not judged), for a bump stop ``"not reached"`` (likewise);
        ``error_percent`` is None for a zero truth; ``covered`` (``|estimate
        - truth| <= 2 std_total``) is None without a standard error (known
        values, no polish).

        With damper curves in the result, ``F_f1 ..``, ``F_r1 ..`` are the forces at its knots (each row has
        its ``velocity``), the truth there read off the true curves (SPEC §8: piecewise linear through (0, 0),
        continued with the last slope), or ``c_s v`` when the truth's dampers are linear. With bump stops in
        the result or the truth, ``bs_clear_*`` and ``bs_rate_*``; a stop the truth lacks has rate 0.
    """
    details = result.details if hasattr(result, "details") else result["parameters"]
    rows, notes = {}, []
    for n in ALL_NAMES:
        if n in EXT_NAMES and n not in details and n not in truth:
            continue
        d = details.get(n, {})
        est = float(d["value"]) if n in details else 0.0
        tr = float(truth.get(n, 0.0))  # an extension absent from the truth is 0
        status = ("not in the model" if n not in details else "known" if d.get("fixed")
                  else "derived" if d.get("derived") else "estimated")
        rows[n] = _row(est, tr, status, d.get("std_robust"), d.get("std_total"))
    curves = _get(result, "dampers")
    if curves:
        for axle, a, c in AXLES:
            ax = curves[axle]
            for j, v in enumerate(curves["velocity"]):
                tr = dampers.force(axle, v) if dampers is not None else float(truth[c]) * v
                excited = ax.get("excited", [True] * len(ax["force"]))[j]
                rob = (ax.get("std_robust") or [None] * len(ax["force"]))[j]
                rows[f"F_{a}{j + 1}"] = _row(float(ax["force"][j]), tr, "estimated" if excited else "not excited",
                                             rob, velocity=float(v))
    elif dampers is not None:
        notes.append("the truth has damper curves and the model linear dampers: c_sf and c_sr are compared with "
                     "the curves' mean slope between -0.1 and 0.1 m/s")
    stops = _get(result, "bump_stops")
    for axle, a, _ in AXLES:
        c, r = f"bs_clear_{a}", f"bs_rate_{a}"
        if stops:
            e = stops[axle]
            known = e.get("known", [False, False])
            rob = e.get("std_robust") or [None, None]
            for k, n in enumerate((c, r)):
                status = "known" if known[k] else "estimated" if e.get("reached", True) else "not reached"
                if n == c and c not in truth:
                    continue  # the truth has no stop on this axle: no clearance to compare
                rows[n] = _row(float(e["clearance" if n == c else "rate"]), float(truth.get(n, 0.0)), status,
                               rob[k])
        elif r in truth:
            rows[r] = _row(0.0, float(truth[r]), "not in the model", None)
    worst = max((abs(x["error_percent"]) for x in rows.values()
                 if x["error_percent"] is not None and x["status"] in ("estimated", "derived")), default=0.0)
    judged = [x["covered"] for x in rows.values() if x["covered"] is not None]
    basis = "std_total" if any(isinstance(d, dict) and "std_total" in d for d in details.values()) else "std_robust"
    return {"parameters": rows, "worst_percent": worst, "covered": sum(judged), "coverable": len(judged),
            "covered_robust": sum(bool(x["covered_robust"]) for x in rows.values()), "basis": basis,
            "notes": notes}


__all__ = ["score"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "COVERAGE_K": "score.coverage_k"})
