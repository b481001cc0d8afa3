"""A study's files: results.parquet, summary.md/.csv and summary.html with figures.

The rows and the group statistics come from :mod:`rideid.studies.summary`
(:func:`rideid.studies.summary.write_summary` hands them over with the
study's option columns);
the figures are plain :class:`matplotlib.figure.Figure` objects (no pyplot,
the caller's backend untouched).
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from ..data.schema.common import write_atomic

#: the options that only reseed a task: tasks that differ in these alone form a group
SEED_COLUMNS = ("noise_seed", "seed")


def varying_columns(rows, cols) -> list[str]:
    """The columns of ``cols`` whose value differs between the ``rows`` (dicts)."""
    return [c for c in cols if len({repr(r.get(c)) for r in rows}) > 1]


def group_label(row, cols) -> str:
    """A row's group, named by its values of ``cols`` (``"all tasks"`` without any)."""
    if not cols:
        return "all tasks"
    return " ".join(f"{c}={row.get(c)}" for c in cols)


def estimated_names(rows) -> list[str]:
    """The parameters the rows estimated (their ``estimated`` lists joined), in order of appearance."""
    names = []
    for r in rows:
        for n in (r.get("estimated") or "").split(","):
            if n and n not in names:
                names.append(n)
    return names


def write_parquet(rows, path: Path):
    """``results.parquet``: one row per task, the union of the rows' columns."""
    import pyarrow as pa  # optional and slow to import: only a study writes Parquet
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
    return group_label(r, cols) if cols else f"task {r['task']}"


def _tables(spec, rows, stats, notes, option_columns):
    """(title, header, body) of each summary table."""
    names = estimated_names(rows)
    tables = []
    done = sum(r["status"] == "done" for r in rows)
    failed = [r for r in rows if r["status"] == "failed"]
    tables.append(("Tasks", ["tasks", "done", "failed", "missing"],
                   [[len(rows), done, len(failed), sum(r["status"] == "missing" for r in rows)]]))
    if failed:
        tables.append(("Failed tasks", ["task", "options", "error"],
                       [[r["task"], _task_label(r, varying_columns(rows, option_columns)), r["error"]]
                        for r in failed]))
    gcols = varying_columns(rows, [c for c in option_columns if c not in SEED_COLUMNS])
    groups: dict[str, list] = {}
    for r in rows:
        groups.setdefault(group_label(r, gcols), []).append(r)
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
    tcols = varying_columns(rows, option_columns)
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


def _figures(rows, stats, out: Path, option_columns) -> list[tuple[str, str]]:
    figs = []
    fdir = out / "figures"
    fdir.mkdir(exist_ok=True)
    done = [r for r in rows if r["status"] == "done"]
    names = estimated_names(done)
    if not done or not names:
        return figs
    gcols = varying_columns(rows, [c for c in option_columns if c not in SEED_COLUMNS])
    labels = list(dict.fromkeys(group_label(r, gcols) for r in done))
    ncol = 4
    nrow = math.ceil(len(names) / ncol)

    def save(fig, name, caption):
        tmp = fdir / f".{name}.tmp.png"
        fig.savefig(tmp, dpi=90)
        tmp.replace(fdir / name)
        figs.append((f"figures/{name}", caption))

    # the parameters with a truth in every done task; the others (a car's knot forces F_f1 .., whose truth is a
    # curve, not a value of the scenario's [truth]) are named in the caption, not a reason to draw nothing
    judged = [n for n in names if all(r.get(f"{n}_error") is not None for r in done)]
    if judged:
        erow = math.ceil(len(judged) / ncol)
        fig = Figure(figsize=(3.2 * ncol, 2.6 * erow))
        axs = fig.subplots(erow, ncol, squeeze=False)
        for ax, n in zip(axs.flat, judged):
            data = [[100 * r[f"{n}_error"] for r in done if group_label(r, gcols) == g] for g in labels]
            ax.boxplot(data, showfliers=False)
            for i, d in enumerate(data):
                ax.plot(np.full(len(d), i + 1.0) + np.linspace(-0.15, 0.15, len(d)), d, ".", ms=4, alpha=0.7)
            ax.axhline(0, color="k", lw=0.6)
            ax.set_title(n, fontsize=9)
            ax.set_xticks(range(1, len(labels) + 1), [str(i + 1) for i in range(len(labels))], fontsize=7)
            ax.set_ylabel("error %", fontsize=8)
        for ax in list(axs.flat)[len(judged):]:
            ax.axis("off")
        fig.tight_layout()
        left = [n for n in names if n not in judged]
        save(fig, "errors.png", "Error vs truth per parameter (%); x = group: "
             + "; ".join(f"{i + 1}: {g}" for i, g in enumerate(labels))
             + (f"; not shown (no true value in the tasks): {', '.join(left)}" if left else ""))

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

    tcols = varying_columns(rows, option_columns)
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


def write_outputs(spec, rows, stats, notes, out: Path, option_columns) -> Path:
    """Write results.parquet, summary.csv, summary.md, summary.html (+ figures); return the HTML path.

    Parameters
    ----------
    spec : Study
        Its ``name`` and ``path``.
    rows : list of dict
        One per task (:func:`rideid.studies.summary.table_rows`).
    stats, notes : list
        The groups' statistics and notes (:func:`rideid.studies.summary.group_stats`).
    out : Path
        The study's folder.
    option_columns : tuple of str
        The columns of a task's options (the groups are the tasks alike in these but the seeds).
    """
    write_parquet(rows, out / "results.parquet")
    write_atomic(out / "summary.csv", _csv(stats))
    tables = _tables(spec, rows, stats, notes, option_columns)
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
    figs = _figures(rows, stats, out, option_columns)
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


__all__ = ["SEED_COLUMNS", "STAT_COLUMNS", "estimated_names", "group_label", "varying_columns", "write_outputs",
           "write_parquet"]
