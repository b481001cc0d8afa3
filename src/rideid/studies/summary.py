"""A study's results analysed: one row per task, and the statistics of each group of tasks.

The files (results.parquet, summary.md/.csv and summary.html with figures)
are written by :mod:`rideid.report.study_files`. Groups: tasks that differ
only in their seeds (``noise_seed``, ``seed``) form a group; a group's
spread over those seeds is the Monte Carlo spread, compared with the mean
reported standard errors and, where :func:`rideid.plan` is available, with
the Cramér-Rao lower bound (CRLB).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ..data.scenario import default_scenario, load_scenario
from ..design import plan
from ..report.study_files import SEED_COLUMNS, estimated_names, group_label, varying_columns, write_outputs
from .spec import BUILTIN, IDENTIFY_KEYS

OPTION_COLUMNS = ("dataset", "scenario", "noise", "noise_seed", "subset", "runs") + IDENTIFY_KEYS


def table_rows(ordered) -> list[dict]:
    """One dict per task (task order): options, status, estimates."""
    rows = []
    for t, rec in ordered:
        o = t.options
        row = {"task": t.index, "key": t.key}
        for c in ("dataset", "scenario", "noise", "noise_seed"):
            row[c] = o["data"].get(c)
        row["subset"] = o["subset"]
        row["runs"] = None if o["runs"] is None else ",".join(o["runs"])
        for k in IDENTIFY_KEYS:
            row[k] = o["identify"].get(k)
        row["status"] = "missing" if rec is None else rec["status"]
        row["error"] = None if rec is None else rec.get("error")
        row["warnings"] = None if rec is None or not rec.get("warnings") else " | ".join(rec["warnings"])
        row["rideid_version"] = None if rec is None else rec.get("rideid_version")
        if rec is not None:
            row.update(rec.get("row", {}))
        rows.append(row)
    return rows


_PLANS: dict = {}


def crlb_for(spec, row) -> tuple[dict | None, str]:
    """CRLB and identify's expected spread for a scenario group, from :func:`rideid.plan`.

    Parameters
    ----------
    spec : Study
    row : dict
        A row of the group (its ``noise`` and ``runs``).

    Returns
    -------
    ({name: (crlb std, expected identify std)}, note), or (None, why not).
    """
    if spec.scenario is None:
        return None, "CRLB: only for scenario studies (the truth and the noise level must be known)"
    if not row.get("noise"):
        return None, "CRLB: not for noise-free data"
    key = (spec.scenario, row["noise"], row.get("runs"))
    if key not in _PLANS:
        try:
            sc = default_scenario() if spec.scenario == BUILTIN else load_scenario(spec.scenario)
            if row.get("runs"):
                keep = set(row["runs"].split(","))
                sc = dataclasses.replace(sc, runs=[r for r in sc.runs if r.id in keep])
            res = plan(sc, noise=row["noise"])
            d = (res.to_dict() if hasattr(res, "to_dict") else res)["all_runs"]
            out = {n: (v.get("std"), d.get("identify_std", {}).get(n, {}).get("std")) for n, v in d["crlb"].items()}
            for n, v in d.get("derived", {}).items():
                out[n] = (v.get("std"), v.get("std_identify"))
            _PLANS[key] = (out, "CRLB and identify's expected spread from rideid.plan (the group's runs and noise)")
        except Exception as e:  # an API this module was not written against: say so, do not guess
            _PLANS[key] = (None, f"CRLB not available (rideid.plan failed: {type(e).__name__}: {e})")
    return _PLANS[key]


def group_stats(spec, rows):
    """Per group and estimated parameter: n, mean, spread, mean std, errors vs truth, coverage, CRLB."""
    done = [r for r in rows if r["status"] == "done"]
    gcols = varying_columns(rows, [c for c in OPTION_COLUMNS if c not in SEED_COLUMNS])
    groups: dict[str, list] = {}
    for r in done:
        groups.setdefault(group_label(r, gcols), []).append(r)
    names = estimated_names(done)
    out, notes = [], []
    for label, rs in groups.items():
        crlb, note = crlb_for(spec, rs[0]) if any("noise" in r and r["noise"] is not None for r in rs) else (None, "")
        if note and note not in notes:
            notes.append(note)
        for n in names:
            v = np.array([r[n] for r in rs if r.get(n) is not None], float)
            if v.size == 0:
                continue
            s = dict(group=label, parameter=n, n=int(v.size), mean=float(v.mean()),
                     spread=float(v.std(ddof=1)) if v.size > 1 else None)
            for k in ("std", "std_robust"):
                q = [r.get(f"{n}_{k}") for r in rs]
                q = np.array([x for x in q if x is not None], float)
                s[f"mean_{k}"] = float(q.mean()) if q.size else None
            if all(r.get(f"{n}_truth") is not None for r in rs):
                e = np.array([r[f"{n}_error"] for r in rs], float)
                s["truth"] = float(rs[0][f"{n}_truth"])
                s["bias_pct"] = float(100 * e.mean())
                s["rms_error_pct"] = float(100 * math.sqrt(np.mean(e * e)))
                for k in ("std", "std_robust"):
                    ok = [abs(r[n] - r[f"{n}_truth"]) <= 2 * r[f"{n}_{k}"] for r in rs
                          if r.get(f"{n}_{k}") is not None]
                    s[f"coverage_2{k}"] = float(np.mean(ok)) if ok else None
            s["crlb_std"], s["plan_identify_std"] = (crlb or {}).get(n, (None, None))
            out.append(s)
    return out, notes


def write_summary(spec, ordered, out: Path) -> Path:
    """The study's rows and group statistics written as its files (:func:`rideid.report.study_files.write_outputs`):
    results.parquet, summary.csv, summary.md, summary.html (+ figures); returns the HTML path."""
    rows = table_rows(ordered)
    stats, notes = group_stats(spec, rows)
    return write_outputs(spec, rows, stats, notes, out, OPTION_COLUMNS)


__all__ = ["OPTION_COLUMNS", "crlb_for", "group_stats", "table_rows", "write_summary"]
