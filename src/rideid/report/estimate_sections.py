"""Report sections on the quality of the estimate: robust errors, correlations, adequacy, model choice.

Builds plain template context from ``result.json`` (no file access).
"""

from __future__ import annotations

import math

from ..estimate.records import candidate_label, first_fit_sentence, kept_candidate


#: the correlation matrix shows at most this many parameters as columns; beyond (a model with damper curves:
#: twenty knot forces more) the knot forces leave the matrix and their strong correlations are listed as pairs
MATRIX_MAX = 16
#: pairs listed: |r| at least this, at most PAIRS_MAX of them, strongest first
PAIR_R, PAIRS_MAX = 0.8, 20


def _cell(v) -> tuple:
    if v is None or not math.isfinite(v):
        return ("–", "")
    # strong correlations (|r| > 0.9) mean the data fix a combination better than each parameter
    alpha = min(abs(v), 1.0) * 0.6
    colour = f"rgba(220,38,38,{alpha:.2f})" if v > 0 else f"rgba(37,99,235,{alpha:.2f})"
    return (f"{v:+.2f}", f"background:{colour}")


def correlation_rows(res: dict) -> dict | None:
    """The estimates' correlation matrix as table rows with a colour per cell, and its strongest pairs.

    With more than :data:`MATRIX_MAX` parameters the damper curves' knot forces (``F_*``) leave the matrix
    (it would overflow the page): the matrix then holds the other parameters, and ``pairs`` lists the
    strongest correlations of all (``|r| >= PAIR_R``, at most ``PAIRS_MAX``).

    Returns ``{"names": [...], "rows": [{"name", "cells": [(text, css)]}], "pairs": [(a, b, text, css)],
    "left_out": [names not in the matrix]}`` or ``None`` when result.json has none.
    """
    cor = res.get("correlation")
    if not cor:
        return None
    names, M = list(cor["names"]), cor["matrix"]
    shown = list(range(len(names)))
    if len(names) > MATRIX_MAX:
        shown = [i for i, n in enumerate(names) if not n.startswith("F_")]
    rows = [{"name": names[i], "cells": [_cell(M[i][j]) for j in shown]} for i in shown]
    pairs = sorted(((abs(M[i][j]), i, j) for i in range(len(names)) for j in range(i)
                    if M[i][j] is not None and math.isfinite(M[i][j]) and abs(M[i][j]) >= PAIR_R), reverse=True)
    return {"names": [names[i] for i in shown], "rows": rows,
            "pairs": [(names[j], names[i], *_cell(M[i][j])) for _, i, j in pairs[:PAIRS_MAX]],
            "more_pairs": max(len(pairs) - PAIRS_MAX, 0),
            "left_out": [n for k, n in enumerate(names) if k not in shown]}


def adequacy_rows(res: dict) -> dict | None:
    """Verdict, reasons, advice and one row per run (worst channel of each figure)."""
    adq = res.get("adequacy")
    if not adq:
        return None
    rows = []
    for rid, rec in adq.get("runs", {}).items():
        if not rec:
            continue
        levels = [(f["level"], c) for c, f in rec.items() if f.get("level") is not None]
        lv, lc = max(levels) if levels else (None, "")
        ex, ec = max((f["input_explained"], c) for c, f in rec.items())
        rows.append({"run": rid, "level": lv, "level_channel": lc, "explained": ex, "explained_channel": ec,
                     "structure": [c for c, f in rec.items() if f["structure"]],
                     "white": sum(f["white"] for f in rec.values()), "channels": len(rec)})
    # the caveats the terminal warns of travel with the verdict (rideid.estimate.assess.adequacy.caveats)
    return {"adequate": adq["adequate"], "reasons": adq["reasons"], "advice": adq.get("advice"),
            "method": adq.get("method", ""), "rows": rows, "small_angle": adq.get("small_angle"),
            **{k: adq[k] for k in ("level_caveat", "tracks_caveat", "setup_caveat", "shape_caveat", "not_assessed",
                                   "note")
               if adq.get(k)}}


def model_rows(res: dict) -> dict | None:
    """The ``--model auto`` candidates side by side: cost, criterion, adequacy, and each parameter's
    value per candidate, marked where it moved by more than 2 std_robust of the chosen model."""
    model = res.get("model") or {}
    cands = model.get("candidates")
    if not cands:
        return None
    kept = kept_candidate(model)
    chosen = " + ".join(model.get("extensions") or ()) or "base"
    heads = [{"label": candidate_label(c), "cost": c["cost"], "criterion": c["criterion"], "wald": c.get("wald"),
              "adequate": c.get("adequate"), "fits_better": c.get("fits_better"), "chosen": i == kept}
             for i, c in enumerate(cands)]
    ref = cands[kept if kept is not None else -1]
    names = []
    for c in cands:
        names += [n for n in c["parameters"] if n not in names]
    rows = []
    for n in names:
        std = (ref.get("std_robust") or {}).get(n)
        v0 = ref["parameters"].get(n, 0.0)
        cells = []
        for c in cands:
            v = c["parameters"].get(n)
            if v is None:
                cells.append(("–", False))
                continue
            moved = bool(std) and abs(v - v0) > 2 * std
            cells.append((f"{v:.5g}", moved))
        rows.append({"name": n, "cells": cells})
    return {"chosen": chosen, "criterion": model.get("criterion", ""),
            "curve_criterion": model.get("extension_criterion", model.get("curve_criterion")),
            "heads": heads, "rows": rows, "rule": model.get("fits_better_rule"),
            "note": model.get("note"),
            "first_fit": first_fit_sentence(model["first_fit"]) if model.get("first_fit") else None,
            # a gross first fit's candidates were not weighed (no criterion, no gate): the note's rule is not said
            "weighed": any(c.get("criterion") is not None for c in cands)}


def estimate_context(res: dict) -> dict:
    """Everything the template's quality sections need, from ``result.json``."""
    return {"correlation": correlation_rows(res), "adequacy": adequacy_rows(res), "model_choice": model_rows(res)}
