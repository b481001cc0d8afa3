"""Report sections on the quality of the estimate: robust errors, correlations, adequacy, model choice.

Builds plain template context from ``result.json`` (no file access).
"""

from __future__ import annotations

import math


def correlation_rows(res: dict) -> dict | None:
    """The estimates' correlation matrix as table rows with a colour per cell.

    Returns ``{"names": [...], "rows": [{"name", "cells": [(text, css)]}]}``
    or ``None`` when result.json has none.
    """
    cor = res.get("correlation")
    if not cor:
        return None
    rows = []
    for name, row in zip(cor["names"], cor["matrix"]):
        cells = []
        for v in row:
            if v is None or not math.isfinite(v):
                cells.append(("–", ""))
                continue
            # strong correlations (|r| > 0.9) mean the data fix a combination better than each parameter
            alpha = min(abs(v), 1.0) * 0.6
            colour = f"rgba(220,38,38,{alpha:.2f})" if v > 0 else f"rgba(37,99,235,{alpha:.2f})"
            cells.append((f"{v:+.2f}", f"background:{colour}"))
        rows.append({"name": name, "cells": cells})
    return {"names": cor["names"], "rows": rows}


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
    return {"adequate": adq["adequate"], "reasons": adq["reasons"], "advice": adq.get("advice"),
            "method": adq.get("method", ""), "rows": rows}


def model_rows(res: dict) -> dict | None:
    """The ``--model auto`` candidates side by side: cost, criterion, adequacy, and each parameter's
    value per candidate, marked where it moved by more than 2 std_robust of the chosen model."""
    model = res.get("model") or {}
    cands = model.get("candidates")
    if not cands:
        return None

    def label(ext):
        return " + ".join(ext) if ext else "base"

    chosen = label(model.get("extensions", []))
    heads = [{"label": label(c["extensions"]), "cost": c["cost"], "criterion": c["criterion"], "wald": c.get("wald"),
              "adequate": c.get("adequate"), "fits_better": c.get("fits_better"),
              "chosen": label(c["extensions"]) == chosen} for c in cands]
    ref = next(c for c in cands if label(c["extensions"]) == chosen)
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
    return {"chosen": chosen, "criterion": model.get("criterion", ""), "curve_criterion": model.get("curve_criterion"),
            "heads": heads, "rows": rows}


def estimate_context(res: dict) -> dict:
    """Everything the template's quality sections need, from ``result.json``."""
    return {"correlation": correlation_rows(res), "adequacy": adequacy_rows(res), "model_choice": model_rows(res)}
