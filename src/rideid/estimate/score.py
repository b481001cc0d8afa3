"""Scoring an identification against the truth (``rideid score``, the demo)."""

from __future__ import annotations

from ..model.params import ALL_NAMES, EXT_NAMES


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
        ``"known"``, ``"derived"`` or ``"not in the model"`` (an extension
        of the truth the model lacks: estimate 0); ``error_percent`` is None
        for a zero truth.
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
        rows[n] = {"estimate": est, "truth": tr, "error_percent": err, "status": status}
    return {"parameters": rows, "worst_percent": worst}


__all__ = ["score"]
