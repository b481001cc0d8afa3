"""Scoring an identification against the truth (``rideid score``, the demo)."""

from __future__ import annotations

from ..model.params import NAMES


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
        "status"}}, "worst_percent": largest |error| over the estimated
        (not fixed) parameters}``; ``status`` is ``"estimated"``,
        ``"known"`` or ``"derived"``.
    """
    details = result.details if hasattr(result, "details") else result["parameters"]
    rows, worst = {}, 0.0
    for n in NAMES:
        d = details[n]
        est, tr = float(d["value"]), float(truth[n])
        err = 100.0 * (est - tr) / tr
        status = "known" if d.get("fixed") else ("derived" if d.get("derived") else "estimated")
        if status != "known":
            worst = max(worst, abs(err))
        rows[n] = {"estimate": est, "truth": tr, "error_percent": err, "status": status}
    return {"parameters": rows, "worst_percent": worst}


__all__ = ["score"]
