"""Scoring an identification against the truth (``rideid score``, the demo)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from ...data.schema import load_truth, load_truth_dampers
from ...errors import ArgumentError
from ...settings import defaults, legacy_names
from ...model.params import ALL_NAMES, EXT_NAMES

AXLES = (("front", "f", "c_sf"), ("rear", "r", "c_sr"))
#: a knot force's status when the truth's damper curves were not given: shown, not judged
NO_TRUE_CURVE = "no true curve"
#: the note of a score whose knot forces were not judged for want of the true curves
NO_TRUE_CURVE_NOTE = ("the knot forces F_f1 .. are not judged: the true damper curves were not given (dampers=: "
                      "rideid.data.schema.load_truth_dampers(path), or 'linear' for c_s v; or pass the "
                      "truth.toml path as the truth, which reads them)")


def _get(result, key):
    return getattr(result, key, None) if hasattr(result, "details") else result.get(key)


def _row(est, tr, status, rob, total=None, **extra) -> dict:
    """One row of the score: relative error (None for a zero or unknown truth), coverage by ±2 ``total``
    (``std_total``) where given, else by ±2 ``rob`` (``std_robust``); ``covered_robust`` by ±2 ``rob``."""
    err = None if not tr else 100.0 * (est - tr) / tr  # also None for a truth not known (None)
    judged = status in ("estimated", "derived")
    rob = float(rob) if judged and rob else None  # 0 or null: no standard error to judge by
    total = float(total) if judged and total else rob

    def covers(s):
        return None if s is None or tr is None else bool(abs(est - tr) <= defaults["score.coverage_k"] * s)
    return {"estimate": est, "truth": tr, "error_percent": err, "status": status, "std_robust": rob,
            "std_total": total, "covered": covers(total), "covered_robust": covers(rob), **extra}


def score(result, truth, dampers=None) -> dict:
    """Relative error of every parameter of ``result`` against ``truth``, the damper curves and bump stops too.

    Parameters
    ----------
    result : IdentificationResult or dict
        A result, or ``result.json`` read as a dict (``parameters`` ->
        name -> ``{"value", "fixed", "derived"}``; ``dampers``, ``bump_stops``).
    truth : dict or str or Path
        Parameter name -> true value (SI), e.g. :func:`rideid.load_truth` (the bump stops ``bs_*`` with it);
        or the path of a ``truth.toml`` (or its folder): its ``[truth]``, and its ``[dampers]`` when
        ``dampers`` is None (a file without them: the truth's dampers are linear).
    dampers : DamperCurves or "linear", optional
        The true damper curves (``truth.toml``'s ``[dampers]``,
        :func:`rideid.data.schema.load_truth_dampers`); ``"linear"``: the truth's dampers are linear
        (``c_sf``, ``c_sr``: a knot's true force is ``c_s v``). None with a dict ``truth``: not known, so
        a result's knot forces are shown but not judged (status ``"no true curve"``, a note says why).

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
        ``"estimated"``, ``"known"``, ``"derived"``, ``"not determined"`` (a road fit's Hessian left it without
        an error bar: named in ``notes``, not in ``worst_percent``) or ``"not in the model"``
        (an extension of the truth the model lacks: estimate 0), for a knot force ``"not excited"`` (no run
        reached it: its force is not trusted, not judged) or ``"no true curve"`` (truth None: the true curves
        not given), for a bump stop ``"not reached"`` (likewise);
        ``error_percent`` is None for a zero or unknown truth; ``covered`` (``|estimate
        - truth| <= 2 std_total``) is None without a standard error (known
        values, no polish).

        With damper curves in the result, ``F_f1 ..``, ``F_r1 ..`` are the forces at its knots (each row has
        its ``velocity``), the truth there read off the true curves (SPEC §8: piecewise linear through (0, 0),
        continued with the last slope), or ``c_s v`` when the truth's dampers are linear; judged by the knot's
        ``std_total`` (the result's ``dampers`` block, SPEC §12), ``std_robust`` where it has none. With bump stops in
        the result or the truth, ``bs_clear_*`` and ``bs_rate_*`` (judged by their ``std_total`` in the
        parameters likewise); a stop the truth lacks has rate 0.
    """
    if isinstance(truth, (str, Path)):
        if dampers is None:
            dampers = load_truth_dampers(truth) or "linear"
        truth = load_truth(truth)
    if isinstance(dampers, str) and dampers != "linear":
        raise ArgumentError(f"score: dampers={dampers!r}; expected the true DamperCurves, 'linear' or None")
    details = result.details if hasattr(result, "details") else result["parameters"]
    rows, notes = _parameter_rows(details, truth), []
    if _get(result, "dampers"):
        rows.update(_knot_rows(_get(result, "dampers"), truth, dampers))
        if dampers is None:
            notes.append(NO_TRUE_CURVE_NOTE)
    elif dampers is not None and not isinstance(dampers, str):
        notes.append("the truth has damper curves and the model linear dampers: c_sf and c_sr are compared with "
                     "the curves' mean slope between -0.1 and 0.1 m/s")
    rows.update(_stop_rows(_get(result, "bump_stops"), truth, details))
    undetermined = {n: x["error_percent"] for n, x in rows.items() if x["status"] == "not determined"}
    if undetermined:  # a road fit's Hessian left them without an error bar (docs/uncertainty.md)
        notes.append("not determined by the data (no error bar, not in the largest error): " + ", ".join(
            n + ("" if e is None else f" {e:+.2f} %") for n, e in undetermined.items()))
    worst = max((abs(x["error_percent"]) for x in rows.values()
                 if x["error_percent"] is not None and x["status"] in ("estimated", "derived")), default=0.0)
    judged = [x["covered"] for x in rows.values() if x["covered"] is not None]
    basis = "std_total" if any(isinstance(d, Mapping) and "std_total" in d for d in details.values()) else "std_robust"
    return {"parameters": rows, "worst_percent": worst, "covered": sum(judged), "coverable": len(judged),
            "covered_robust": sum(bool(x["covered_robust"]) for x in rows.values()), "basis": basis,
            "notes": notes}


def _parameter_rows(details, truth) -> dict:
    """The rows of the car's parameters (:data:`rideid.model.params.ALL_NAMES`); an extension neither in the
    result nor in the truth has none, one absent from the truth is 0 there, one absent from the result is
    ``"not in the model"`` (estimate 0)."""
    rows = {}
    for n in ALL_NAMES:
        if n in EXT_NAMES and n not in details and n not in truth:
            continue
        d = details.get(n, {})
        est = float(d["value"]) if n in details else 0.0
        tr = float(truth.get(n, 0.0))
        status = ("not in the model" if n not in details else "known" if d.get("fixed")
                  else "derived" if d.get("derived") else "not determined" if d.get("determined") is False
                  else "estimated")
        rows[n] = _row(est, tr, status, d.get("std_robust"), d.get("std_total"))
    return rows


def _knot_rows(curves, truth, dampers) -> dict:
    """The rows of the result's knot forces ``F_f1 ..``, ``F_r1 ..`` (``curves``: its ``dampers`` block): the
    truth off the true curves ``dampers``, ``c_s v`` when they are ``"linear"``, None (not judged) when None."""
    rows = {}
    for axle, a, c in AXLES:
        ax = curves[axle]
        none = [None] * len(ax["force"])
        for j, v in enumerate(curves["velocity"]):
            tr = (None if dampers is None else float(truth[c]) * v if isinstance(dampers, str)
                  else dampers.force(axle, v))
            excited = ax.get("excited", [True] * len(ax["force"]))[j]
            status = NO_TRUE_CURVE if tr is None else "estimated" if excited else "not excited"
            rows[f"F_{a}{j + 1}"] = _row(float(ax["force"][j]), tr, status, (ax.get("std_robust") or none)[j],
                                         (ax.get("std_total") or none)[j], velocity=float(v))
    return rows


def _stop_rows(stops, truth, details) -> dict:
    """The rows of the bump stops (``stops``: the result's ``bump_stops`` block, or None): a clearance where the
    truth has a stop on that axle, the rate always (0 in a truth without the stop); without stops in the result,
    the truth's rates as ``"not in the model"``."""
    rows = {}
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
                # judged by the parameter's std_total (its entry in the result's parameters, SPEC §12) as the rest
                rows[n] = _row(float(e["clearance" if n == c else "rate"]), float(truth.get(n, 0.0)), status,
                               rob[k], (details.get(n) or {}).get("std_total"))
        elif r in truth:
            rows[r] = _row(0.0, float(truth[r]), "not in the model", None)
    return rows


__all__ = ["score"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "COVERAGE_K": "score.coverage_k"})
