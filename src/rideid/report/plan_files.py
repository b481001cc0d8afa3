"""The files of a test plan (SPEC §7): plan.json, plan.md, the CSV tables and the precision figure.

Renders a :class:`rideid.design.PlanResult` (read through its attributes and
``to_dict``; this module imports nothing of :mod:`rideid.design`). The
figure is drawn on its own :class:`matplotlib.figure.Figure`: the Matplotlib
backend and pyplot's state are left alone.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure

from ..model.params import UNITS


def budget_text(b: dict) -> str:
    """plan.md's words for plan.json's ``"budget"``."""
    parts = []
    if b.get("runs") is not None:
        parts.append(f"at most {b['runs']} runs")
    if b.get("time_s") is not None:
        parts.append(f"at most {b['time_s']:g} s of track time")
    if b.get("within") is not None:
        parts.append(f"none (fewest runs within {b['within']:g}x of all candidates' CRLB)")
    parts.append(f"{b.get('overhead_s', 0):g} s overhead per run")
    return ", ".join(parts) if parts else "none"


def pct(v, sign=True) -> str:
    """A relative standard deviation ``v`` in percent (``±`` with ``sign``); not finite: not identifiable."""
    if not np.isfinite(v):
        return "not identifiable" if sign else "—"
    s = f"{100 * v:.3g} %"
    return ("±" + s) if sign else f"{100 * v:.3g}"


def num(v) -> str:
    """A CSV cell: 8 significant digits, empty when not finite."""
    return f"{v:.8g}" if np.isfinite(v) else ""


def _md_candidates(res, d: dict) -> list:
    """plan.md's head and the table of candidate runs."""
    out = [f"# Test plan: {Path(res.scenario).name}\n",
           f"Criterion **{res.criterion}**, noise {res.noise_text}; budget: {budget_text(res.budget)}; robust over "
           f"{res.robust['cars']} car(s) ({res.robust['rule']}).\n",
           f"**Selected runs** ({len(res.selected_runs)}, {d['selected']['track_time_s']:.0f} s of track time): "
           + ", ".join(res.label(r) for r in res.selected_runs) + "\n",
           "| candidate run | road | speed (m/s) | fs (Hz) | duration (s) | selected |",
           "|---|---|---|---|---|---|"]
    for c in res.candidates:
        road = (f"unknown road, ISO 8608 class {c['road']['road_class']}" if c.get("road")
                else "four-post rig (SPEC §13)" if c.get("kind") == "rig" else f"track {c['track']}")
        speed = "-" if c["speed"] is None else f"{c['speed']:g}"
        out.append(f"| {c['id']} | {road} | {speed} | {c['fs']:g} | {c['duration_s']:g} | "
                   f"{'yes' if c['id'] in res.selected_runs else ''} |")
    return out


def _md_precision(res) -> list:
    """plan.md's table of the precision per parameter, and the identifiability messages."""
    out = ["",
           "| parameter | nominal | unit | selected CRLB ± | selected identify ± | all runs CRLB ± | "
           "all runs identify ± |",
           "|---|---|---|---|---|---|---|"]
    for j, n in enumerate(res.names):
        out.append(f"| {n} | {res.nominal[n]:.6g} | {UNITS.get(n, '')} | {pct(res.selected.rel_crlb[j])} | "
                   f"{pct(res.selected.rel_identify[j])} | {pct(res.all_runs.rel_crlb[j])} | "
                   f"{pct(res.all_runs.rel_identify[j])} |")
    out.append("\n± are one relative standard deviation. CRLB: the best any unbiased estimator can do with "
               "this noise; identify: the expected spread of `rideid identify` (its cost is not noise-weighted).\n")
    for title, msgs in (("Selected runs", res.messages_selected), ("All candidate runs", res.messages_all)):
        out.append(f"## Identifiability: {title.lower()}\n")
        out += [f"- {m}" for m in msgs] or ["- every parameter identifiable, no pair with |correlation| > 0.9"]
        out.append("")
    return out


def _md_path(res) -> list:
    """plan.md's greedy path and the comparison with the paper's sensitivity map."""
    out = ["## Greedy path (relative CRLB, % — precision after adding each run)\n",
           "| # | added run | " + " | ".join(res.names) + " |",
           "|---" * (len(res.names) + 2) + "|"]
    for k, (rid, p) in enumerate(res.path):
        out.append(f"| {k + 1} | {res.label(rid)} | " + " | ".join(pct(v, sign=False) for v in p.rel_crlb) + " |")
    if res.comparison:
        c = res.comparison
        out.append("\n## Fisher information vs the paper's sensitivity map\n")
        out.append(c["method"] + "\n")
        out.append("| parameter | top run (map) | top run (Fisher) | rank correlation |")
        out.append("|---|---|---|---|")
        for n, v in c["parameters"].items():
            out.append(f"| {n} | {v['top_map']} | {v['top_fisher']} | {v['spearman']:+.2f} |")
        out.append(f"\nRuns ordered by the map's total share: {', '.join(c['map_order'])}  ")
        out.append(f"Runs in greedy {res.criterion} order: {', '.join(c['greedy_order'])}\n")
    return out


def _md_dampers(res) -> list:
    """plan.md's damper-curve section: the knots excited and their CRLB (empty without curves)."""
    if not res.dampers:
        return []
    dm = res.dampers
    sel = dm["selected"]

    def c(ax, j):
        r = sel[ax]["crlb_relative"][j]
        return "not excited" if not sel[ax]["excited"][j] else ("—" if r is None else f"±{100 * r:.3g} %")

    out = ["\n## Damper curves: knots excited and their CRLB (selected runs)\n", dm["excitation_rule"] + ".\n",
           "| v (m/s) | front F (N) | front CRLB ± | rear F (N) | rear CRLB ± |", "|---|---|---|---|---|"]
    for j, v in enumerate(dm["velocity"]):
        out.append(f"| {v:g} | {dm['nominal']['front'][j]:.6g} | {c('front', j)} | "
                   f"{dm['nominal']['rear'][j]:.6g} | {c('rear', j)} |")
    out.append("\n| run | knots not excited |\n|---|---|")
    for cd in res.candidates:
        out.append(f"| {cd['id']} | {', '.join(cd['dampers']['not_excited']) or 'none'} |")
    out.append("")
    return out


def _md_powertrain(res) -> list:
    """plan.md's powertrain section (SPEC §11): the modes and where the information comes from, per run."""
    pt = res.powertrain
    if not pt:
        return []
    names = list(pt["runs"][0]["share"])
    modes = ", ".join(f"{m} {v:.2f} Hz" for m, v in pt["modes_hz"].items())
    lo, hi = pt["band_hz"]
    out = ["\n## Powertrain on mounts: which runs carry its information\n",
           f"Whole-car modes: {modes} (mounts, body held: f_pb {pt['mounts_hz']['f_pb']:g} Hz, f_pp "
           f"{pt['mounts_hz']['f_pp']:g} Hz); band {lo:.2f}-{hi:.2f} Hz. {pt['method']}.\n",
           "| run | input Hz | band energy | " + " | ".join(f"share {n}" for n in names)
           + " | CRLB x without it (f_pb, f_pp, m_p) | carries |",
           "|---|---|---|" + "---|" * len(names) + "---|---|"]
    for r in pt["runs"]:
        loss = ", ".join("—" if r["loss_without"].get(n) is None else f"{r['loss_without'][n]:.3g}"
                         for n in ("f_pb", "f_pp", "m_p") if n in r["loss_without"])
        out.append(f"| {r['id']} | {'—' if r['input_hz'] is None else format(r['input_hz'], '.3g')} | "
                   f"{'—' if r['band_energy'] is None else format(100 * r['band_energy'], '.3g') + ' %'} | "
                   + " | ".join(f"{100 * r['share'][n]:.3g} %" for n in names)
                   + f" | {loss} | {'yes' if r['carries'] else ''} |")
    out.append("\nSelected runs' share: " + ", ".join(f"{n} {100 * v:.3g} %" for n, v in pt["selected_share"].items())
               + "\n")
    return out


def plan_markdown(res) -> str:
    """plan.md of a :class:`rideid.design.PlanResult`."""
    out = (_md_candidates(res, res.to_dict()) + _md_precision(res) + _md_path(res) + _md_dampers(res)
           + _md_powertrain(res))
    if res.notes:
        out.append("## Notes\n")
        out += [f"- {m}" for m in res.notes]
    return "\n".join(out) + "\n"


def _write_csvs(res, out_dir: Path) -> None:
    """crlb.csv, path.csv and correlation.csv."""
    with open(out_dir / "crlb.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["parameter", "nominal", "selected_std", "selected_relative", "selected_identify_std",
                    "all_std", "all_relative", "all_identify_std"])
        for j, n in enumerate(res.names):
            s, a = res.selected, res.all_runs
            w.writerow([n, f"{res.nominal[n]:.10g}", num(s.std[j]), num(s.rel_crlb[j]), num(s.std_identify[j]),
                        num(a.std[j]), num(a.rel_crlb[j]), num(a.std_identify[j])])
    with open(out_dir / "path.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["n_runs", "added"] + [f"rel_{n}" for n in res.names])
        for k, (rid, p) in enumerate(res.path):
            w.writerow([k + 1, rid] + [num(v) for v in p.rel_crlb])
    with open(out_dir / "correlation.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["selected"] + res.names)
        for n, row in zip(res.names, res.selected.correlation()):
            w.writerow([n] + [num(v) for v in row])


def precision_path_figure(res) -> Figure:
    """The relative CRLB of each parameter (%, log scale) along the greedy path, the selection's size marked."""
    k = np.arange(1, len(res.path) + 1)
    R = np.array([p.rel_crlb for _, p in res.path]) * 100
    fig = Figure(figsize=(8, 5))
    ax = fig.add_subplot()
    cmap = colormaps["tab20"]
    for j, n in enumerate(res.names):
        y = np.where(np.isfinite(R[:, j]), R[:, j], np.nan)
        ax.semilogy(k, y, "o-", ms=3, color=cmap(j % 20), label=n)
    ns = len(res.selected_runs)
    ax.axvline(ns, color="k", ls=":", lw=1)
    ax.text(ns, ax.get_ylim()[1], f" selected size {ns}", va="top", fontsize=8)
    ax.set_xticks(k)
    ax.set_xticklabels([f"{i}\n{rid}" for i, (rid, _) in zip(k, res.path)], fontsize=6)
    ax.set_xlabel(f"runs along the greedy {res.criterion} path (run added)")
    ax.set_ylabel("relative CRLB, % (1 sd)")
    ax.set_title("Precision per parameter vs number of runs (missing points: not identifiable)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def write_plan(res, out_dir) -> Path:
    """Write plan.json, plan.md, crlb.csv, path.csv, correlation.csv and precision_path.png into ``out_dir``
    (created if missing); returns ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "plan.json").write_text(json.dumps(res.to_dict(), indent=2, allow_nan=False) + "\n")
    (out_dir / "plan.md").write_text(plan_markdown(res))
    _write_csvs(res, out_dir)
    precision_path_figure(res).savefig(out_dir / "precision_path.png", dpi=110)
    return out_dir
