"""A study's outputs: results.parquet, summary.md/.csv and summary.html with figures.

Groups: tasks that differ only in their seeds (``noise_seed``, ``seed``)
form a group; a group's spread over those seeds is the Monte Carlo spread,
compared with the mean reported standard errors and, where
:func:`rideid.plan` is available, with the Cramér-Rao lower bound (CRLB).
"""

from __future__ import annotations

import dataclasses
import html
import math
from pathlib import Path

import numpy as np

from ..data.scenario import default_scenario, load_scenario
from ..design import plan
from .task import write_atomic
from .spec import BUILTIN, IDENTIFY_KEYS

OPTION_COLUMNS = ("dataset", "scenario", "noise", "noise_seed", "subset", "runs") + IDENTIFY_KEYS
SEED_COLUMNS = ("noise_seed", "seed")


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


def write_parquet(rows, path: Path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    data = {}
    for c in cols:
        vals = [r.get(c) for r in rows]
        if any(isinstance(v, float) for v in vals) and all(v is None or isinstance(v, (int, float))
                                                           and not isinstance(v, bool) for v in vals):
            vals = [None if v is None else float(v) for v in vals]
        data[c] = pa.array(vals)
    tmp = path.with_name(f".{path.name}.tmp")
    pq.write_table(pa.table(data), tmp)
    tmp.replace(path)


def _varying(rows, cols):
    return [c for c in cols if len({repr(r.get(c)) for r in rows}) > 1]


def _label(row, cols):
    if not cols:
        return "all tasks"
    return " ".join(f"{c}={row.get(c)}" for c in cols)


def _param_names(rows):
    names = []
    for r in rows:
        for n in (r.get("estimated") or "").split(","):
            if n and n not in names:
                names.append(n)
    return names


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
    gcols = _varying(rows, [c for c in OPTION_COLUMNS if c not in SEED_COLUMNS])
    groups: dict[str, list] = {}
    for r in done:
        groups.setdefault(_label(r, gcols), []).append(r)
    names = _param_names(done)
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


STAT_COLUMNS = ("group", "parameter", "n", "mean", "spread", "mean_std", "mean_std_robust", "crlb_std",
                "plan_identify_std", "truth",
                "bias_pct", "rms_error_pct", "coverage_2std", "coverage_2std_robust")


def _fmt(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def _csv(stats):
    lines = [",".join(STAT_COLUMNS)]
    for s in stats:
        lines.append(",".join('"' + str(s.get(c, "")) + '"' if c == "group" else _fmt(s.get(c))
                              for c in STAT_COLUMNS))
    return "\n".join(lines) + "\n"


def _md_table(header, body):
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in body]
    return "\n".join(out)


def _task_label(r, cols):
    return _label(r, cols) if cols else f"task {r['task']}"


def _tables(spec, rows, stats, notes):
    """(title, header, body) of each summary table."""
    names = _param_names(rows)
    tables = []
    done = sum(r["status"] == "done" for r in rows)
    failed = [r for r in rows if r["status"] == "failed"]
    tables.append(("Tasks", ["tasks", "done", "failed", "missing"],
                   [[len(rows), done, len(failed), sum(r["status"] == "missing" for r in rows)]]))
    if failed:
        tables.append(("Failed tasks", ["task", "options", "error"],
                       [[r["task"], _task_label(r, _varying(rows, OPTION_COLUMNS)), r["error"]] for r in failed]))
    gcols = _varying(rows, [c for c in OPTION_COLUMNS if c not in SEED_COLUMNS])
    groups: dict[str, list] = {}
    for r in rows:
        groups.setdefault(_label(r, gcols), []).append(r)
    body = []
    for label, rs in groups.items():
        ok = [r for r in rs if r["status"] == "done"]

        def med(k, scale=1.0, ok=ok):
            v = [r[k] for r in ok if r.get(k) is not None]
            return _fmt(float(np.median(v)) * scale) if v else ""
        body.append([label, len(rs), len(ok), med("evaluations"), med("generations_run"), med("cost"),
                     med("max_abs_error", 100.0), med("identify_wall_s")])
    tables.append(("Per group (medians over the done tasks)",
                   ["group", "tasks", "done", "evaluations", "generations", "cost", "largest error %", "wall s"],
                   body))
    if stats:
        cols = [c for c in STAT_COLUMNS if any(s.get(c) is not None for s in stats)]
        tables.append(("Groups: spread over seeds, reported standard errors, errors vs truth", cols,
                       [[_fmt(s.get(c)) for c in cols] for s in stats]))
    tcols = _varying(rows, OPTION_COLUMNS)
    body = []
    for r in rows:
        if r["status"] != "done":
            continue
        cells = [_task_label(r, tcols)]
        for n in names:
            sd = r.get(f"{n}_std")
            cells.append(f"{r[n]:.5g}" + (f" ± {2 * sd:.2g}" if sd else ""))
        body.append(cells)
    if body:
        tables.append(("Estimates per task (± 2 std)", ["task"] + names, body))
    return tables


def _figures(rows, stats, out: Path) -> list[tuple[str, str]]:
    from matplotlib.figure import Figure  # plain figures: no pyplot, the caller's backend untouched
    from matplotlib.ticker import MaxNLocator

    figs = []
    fdir = out / "figures"
    fdir.mkdir(exist_ok=True)
    done = [r for r in rows if r["status"] == "done"]
    names = _param_names(done)
    if not done or not names:
        return figs
    gcols = _varying(rows, [c for c in OPTION_COLUMNS if c not in SEED_COLUMNS])
    labels = list(dict.fromkeys(_label(r, gcols) for r in done))
    ncol = 4
    nrow = math.ceil(len(names) / ncol)

    def save(fig, name, caption):
        tmp = fdir / f".{name}.tmp.png"
        fig.savefig(tmp, dpi=90)
        tmp.replace(fdir / name)
        figs.append((f"figures/{name}", caption))

    if all(r.get(f"{n}_error") is not None for r in done for n in names):
        fig = Figure(figsize=(3.2 * ncol, 2.6 * nrow))
        axs = fig.subplots(nrow, ncol, squeeze=False)
        for ax, n in zip(axs.flat, names):
            data = [[100 * r[f"{n}_error"] for r in done if _label(r, gcols) == g] for g in labels]
            ax.boxplot(data, showfliers=False)
            for i, d in enumerate(data):
                ax.plot(np.full(len(d), i + 1.0) + np.linspace(-0.15, 0.15, len(d)), d, ".", ms=4, alpha=0.7)
            ax.axhline(0, color="k", lw=0.6)
            ax.set_title(n, fontsize=9)
            ax.set_xticks(range(1, len(labels) + 1), [str(i + 1) for i in range(len(labels))], fontsize=7)
            ax.set_ylabel("error %", fontsize=8)
        for ax in list(axs.flat)[len(names):]:
            ax.axis("off")
        fig.tight_layout()
        save(fig, "errors.png", "Error vs truth per parameter (%); x = group: "
             + "; ".join(f"{i + 1}: {g}" for i, g in enumerate(labels)))

    multi = [s for s in stats if s["n"] > 1 and s.get("spread") is not None]
    if multi:
        fig = Figure(figsize=(11, 2.8 * len(labels)))
        axs = fig.subplots(len(labels), 1, squeeze=False)
        for ax, g in zip(axs[:, 0], labels):
            ss = [s for s in multi if s["group"] == g]
            x = np.arange(len(ss))
            series = [("spread over seeds", "spread"), ("mean std", "mean_std"),
                      ("mean std_robust", "mean_std_robust"), ("CRLB", "crlb_std"),
                      ("plan: identify's expected spread", "plan_identify_std")]
            series = [(lab, k) for lab, k in series if any(s.get(k) for s in ss)]
            wdt = 0.8 / max(len(series), 1)
            for i, (lab, k) in enumerate(series):
                ax.bar(x + i * wdt, [100 * (s.get(k) or np.nan) / abs(s["mean"]) for s in ss], wdt, label=lab)
            ax.set_xticks(x + 0.4 - wdt / 2, [s["parameter"] for s in ss], fontsize=8)
            ax.set_yscale("log")
            ax.set_ylabel("% of the mean", fontsize=8)
            ax.set_title(g, fontsize=9)
            ax.legend(fontsize=7)
        fig.tight_layout()
        save(fig, "spread.png", "Monte Carlo spread over the seeds against the mean reported standard errors "
             "(and the CRLB where available), relative to the mean estimate")

    tcols = _varying(rows, OPTION_COLUMNS)
    fig = Figure(figsize=(3.2 * ncol, max(2.6, 0.18 * len(done) + 1.2) * nrow))
    axs = fig.subplots(nrow, ncol, squeeze=False)
    y = np.arange(len(done))
    for ax, n in zip(axs.flat, names):
        v = np.array([r[n] for r in done])
        sd = np.array([r.get(f"{n}_std") or 0.0 for r in done])
        ax.errorbar(v, y, xerr=2 * sd, fmt="o", ms=3, lw=1)
        tr = [r.get(f"{n}_truth") for r in done]
        if all(t is not None for t in tr):
            ax.plot(tr, y, "k|", ms=8, label="truth")
        ax.set_title(n, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.set_yticks(y, [str(r["task"]) for r in done] if len(done) <= 40 else [])
        ax.invert_yaxis()
    for ax in list(axs.flat)[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    save(fig, "intervals.png", "Estimate ± 2 std per task (rows: task numbers; | the truth where known)"
         + ("; tasks differ by " + ", ".join(tcols) if tcols else ""))
    return figs


def write_outputs(spec, ordered, out: Path) -> Path:
    """Write results.parquet, summary.csv, summary.md, summary.html (+ figures); return the HTML path."""
    rows = table_rows(ordered)
    write_parquet(rows, out / "results.parquet")
    stats, notes = group_stats(spec, rows)
    write_atomic(out / "summary.csv", _csv(stats))
    tables = _tables(spec, rows, stats, notes)
    md = [f"# Study: {spec.name}", ""]
    if spec.path is not None:
        md += [f"Study file: `{spec.path}`", ""]
    for n in notes:
        md += [f"- {n}", ""]
    for title, header, body in tables:
        md += [f"## {title}", "", _md_table(header, body), ""]
    md += ["Spread: sample standard deviation of the estimates over the group's seeds. mean_std: the mean "
           "standard error identify reported (white residuals assumed: optimistic when residuals are "
           "correlated). coverage_2std: share of tasks whose truth lies within ± 2 std. crlb_std: the "
           "Cramér-Rao lower bound of the group's runs at its noise level; plan_identify_std: the spread rideid "
           "plan expects of identify's estimator (both from rideid.plan, where available).", ""]
    write_atomic(out / "summary.md", "\n".join(md))
    figs = _figures(rows, stats, out)
    e = html.escape
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>Study: {e(spec.name)}</title>",
             "<style>body{font-family:sans-serif;margin:2em;max-width:1400px}table{border-collapse:collapse;"
             "font-size:13px;margin-bottom:1.5em}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}"
             "td:first-child{text-align:left}img{max-width:100%}</style></head><body>",
             f"<h1>Study: {e(spec.name)}</h1>"]
    parts += [f"<p>{e(n)}</p>" for n in notes]
    for title, header, body in tables:
        parts.append(f"<h2>{e(title)}</h2><table><tr>" + "".join(f"<th>{e(str(h))}</th>" for h in header) + "</tr>")
        parts += ["<tr>" + "".join(f"<td>{e(str(c))}</td>" for c in row) + "</tr>" for row in body]
        parts.append("</table>")
    for src, cap in figs:
        parts.append(f"<figure><img src='{e(src)}' alt='{e(cap)}'><figcaption>{e(cap)}</figcaption></figure>")
    parts.append("<p>Full rows (options, every estimate, std, truth, errors, cost, wall times): results.parquet. "
                 "Each task's result.json content: tasks/&lt;key&gt;.json.</p></body></html>")
    write_atomic(out / "summary.html", "\n".join(parts) + "\n")
    return out / "summary.html"
