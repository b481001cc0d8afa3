"""Scoring an identification against the truth (``rideid score``, the demo)."""

from __future__ import annotations

from ..model.params import ALL_NAMES, EXT_NAMES

#: an estimate covers the truth when it lies within this many robust standard errors (about 95 %, SPEC §6)
COVERAGE_K = 2.0


def score(result, truth: dict) -> dict:
    """Relative error of every parameter of ``result`` against ``truth``.

    Parameters
    ----------
    result : IdentificationResult or dict
        A result, or ``result.json`` read as a dict (``parameters`` ->
        name -> ``{"value", "fixed", "derived"}``).
    truth : dict
        Parameter name -> true value (SI), e.g. :func:`rideid.load_truth`.

    Returns
    -------
    dict
        ``{"parameters": {name: {"estimate", "truth", "error_percent",
        "status", "std_robust", "covered"}}, "worst_percent": largest |error|
        over the estimated (not fixed) parameters, "covered": how many
        estimates ±2 ``std_robust`` covers the truth of, "coverable": of how
        many (those with a ``std_robust``)}``; ``status`` is
        ``"estimated"``, ``"known"``, ``"derived"`` or ``"not in the model"``
        (an extension of the truth the model lacks: estimate 0);
        ``error_percent`` is None for a zero truth; ``covered`` (``|estimate
        - truth| <= 2 std_robust``) is None without a ``std_robust`` (known
        values, no polish).
    """
    details = result.details if hasattr(result, "details") else result["parameters"]
    rows, worst = {}, 0.0
    for n in ALL_NAMES:
        if n in EXT_NAMES and n not in details and n not in truth:
            continue
        d = details.get(n, {})
        est = float(d["value"]) if n in details else 0.0
        tr = float(truth.get(n, 0.0))  # an extension absent from the truth is 0
        status = ("not in the model" if n not in details else "known" if d.get("fixed")
                  else "derived" if d.get("derived") else "estimated")
        err = None if tr == 0 else 100.0 * (est - tr) / tr  # no relative error of a zero truth
        if err is not None and status in ("estimated", "derived"):
            worst = max(worst, abs(err))
        rob = d.get("std_robust") if status in ("estimated", "derived") else None
        rob = float(rob) if rob else None  # 0 or null: no standard error to judge by
        covered = None if rob is None else bool(abs(est - tr) <= COVERAGE_K * rob)
        rows[n] = {"estimate": est, "truth": tr, "error_percent": err, "status": status, "std_robust": rob,
                   "covered": covered}
    judged = [r["covered"] for r in rows.values() if r["covered"] is not None]
    return {"parameters": rows, "worst_percent": worst, "covered": sum(judged), "coverable": len(judged)}


__all__ = ["score"]
