"""The sensitivity maps as files (``rideid sensitivity``, the report): the paper's Tables 4-7 as Markdown,
CSV and heatmaps with their star ratings (:func:`rideid.estimate.problem.sensitivity.stars`).

The maps themselves are computed in :mod:`rideid.estimate.problem.sensitivity`; every
figure here is a plain :class:`matplotlib.figure.Figure` on its own Agg
canvas: no pyplot, the caller's backend untouched.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..estimate.problem.sensitivity import P2R_STARS, P2T_STARS, R2T_STARS, SensitivityMaps, stars


def tables_markdown(m: SensitivityMaps) -> str:
    """The paper's Tables 4-7 as Markdown."""
    out = []
    short = [c.replace("body_az_", "b_").replace("axle_az_", "a_") for c in m.channels]
    out.append("## Parameter → response (mean |% change of peak| over runs, +25 % step)\n")
    out.append("| parameter | " + " | ".join(short) + " |")
    out.append("|---" * (len(short) + 1) + "|")
    for i, p in enumerate(m.params):
        out.append(f"| {p} | " + " | ".join(f"{m.S_bar[i, c]:.1f} {stars(m.S_bar[i, c], P2R_STARS)}"
                                             for c in range(len(short))) + " |")
    out.append("\n## Response → track (RMS relative to the best-exciting run)\n")
    out.append("| response | " + " | ".join(m.runs) + " |")
    out.append("|---" * (len(m.runs) + 1) + "|")
    for c, name in enumerate(m.channels):
        out.append(f"| {name} | " + " | ".join(f"{m.R[c, r]:.2f} {stars(m.R[c, r], R2T_STARS)}"
                                                for r in range(len(m.runs))) + " |")
    out.append("\n## Parameter → track (share of each parameter's sensitivity per run, rows sum to 1)\n")
    out.append("| parameter | " + " | ".join(m.runs) + " |")
    out.append("|---" * (len(m.runs) + 1) + "|")
    n = len(m.runs)
    for i, p in enumerate(m.params):
        out.append(f"| {p} | " + " | ".join(f"{m.M[i, r]:.3f} {stars(m.M[i, r] * n, P2T_STARS)}"
                                             for r in range(n)) + " |")
    out.append("\nStars: parameter→response |%|: ⌀ <1, ★ 1–5, ★★ 5–15, ★★★ ≥15; response→track: ⌀ <0.05, "
               "★ <0.25, ★★ <0.6, ★★★ ≥0.6; parameter→track (share × number of runs): ⌀ <0.25, ★ <0.75, "
               "★★ <1.5, ★★★ ≥1.5.")
    return "\n".join(out) + "\n"


def write_csvs(m: SensitivityMaps, out_dir):
    """``param_response.csv``, ``response_track.csv``, ``param_track.csv`` in ``out_dir``."""
    out_dir = Path(out_dir)
    with open(out_dir / "param_response.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["parameter", "run"] + m.channels)
        for i, p in enumerate(m.params):
            for r, rid in enumerate(m.runs):
                w.writerow([p, rid] + [("" if not np.isfinite(v) else f"{v:.6g}") for v in m.S[i, :, r]])
        for i, p in enumerate(m.params):
            w.writerow([p, "mean_abs"] + [f"{v:.6g}" for v in m.S_bar[i]])
    with open(out_dir / "response_track.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["response"] + m.runs)
        for c, name in enumerate(m.channels):
            w.writerow([name] + [f"{v:.6g}" for v in m.R[c]])
    with open(out_dir / "param_track.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["parameter"] + m.runs)
        for i, p in enumerate(m.params):
            w.writerow([p] + [f"{v:.6g}" for v in m.M[i]])


#: the three maps: file stem -> (SensitivityMaps attributes of the values, row and column labels; title;
#: star thresholds; the parameter -> track shares are rated times the number of runs)
HEATMAPS = {
    "param_response": ("S_bar", "params", "channels", "Parameter → response: mean |% change of peak|", P2R_STARS),
    "response_track": ("R", "channels", "runs", "Response → track: relative RMS", R2T_STARS),
    "param_track": ("M", "params", "runs", "Parameter → track: share per run", P2T_STARS),
}


def star_marks(data, scale, thresholds):
    """Where to draw each cell's star rating: ``(x, y, dash_x, dash_y, rating)``.

    A cell rated n >= 1 (:func:`stars` of ``data * scale``) gets n star marks
    side by side, a cell rated zero (or not finite: not excited) one dash.
    """
    xs, ys, dash_x, dash_y, rating = [], [], [], [], np.zeros(data.shape, dtype=int)
    for i in range(data.shape[0]):
        for j in range(data.shape[1]):
            n = stars(data[i, j] * scale, thresholds).count("★")
            rating[i, j] = n
            if n == 0:
                dash_x.append(j)
                dash_y.append(i)
            for k in range(n):
                xs.append(j + 0.14 * (k - (n - 1) / 2))
                ys.append(i)
    return np.array(xs), np.array(ys), np.array(dash_x), np.array(dash_y), rating


def heatmap_figure(m: SensitivityMaps, kind: str):
    """One map (``kind``: a key of :data:`HEATMAPS`) as a Matplotlib figure, each cell with its star rating.

    The stars are marker symbols of one scatter per colour, not one text per
    cell: a map has up to ~120 cells, and laying out a text each costs more
    than the rest of the figure.
    """
    attr, row_attr, col_attr, title, th = HEATMAPS[kind]
    data, rows, cols = getattr(m, attr), getattr(m, row_attr), getattr(m, col_attr)
    scale = len(m.runs) if kind == "param_track" else 1.0  # shares per run: 1/runs is "average"
    fig = Figure(figsize=(1.0 + 0.75 * len(cols), 1.2 + 0.38 * len(rows)), dpi=110)
    FigureCanvasAgg(fig)  # callers may read its pixels (buffer_rgba)
    ax = fig.subplots()
    im = ax.imshow(data, aspect="auto", cmap="viridis")
    ax.grid(False)
    ax.set_xticks(range(len(cols)), cols, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(rows)), rows, fontsize=8)
    xs, ys, dx, dy, _ = star_marks(data, scale, th)
    # white on the dark part of viridis, black on the light part
    light = data >= 0.6 * np.nanmax(data) if np.isfinite(data).any() else np.zeros(data.shape, bool)
    for x, y, marker, size in ((xs, ys, "*", 30), (dx, dy, "_", 12)):
        if x.size:
            on_light = light[y.astype(int), np.rint(x).astype(int)]
            ax.scatter(x, y, s=size, marker=marker, c=np.where(on_light, "black", "white"), linewidths=0.8)
    ax.set_xlim(-0.5, len(cols) - 0.5)
    ax.set_ylim(len(rows) - 0.5, -0.5)
    ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, fraction=0.04)
    fig.tight_layout()
    return fig


def heatmaps(m: SensitivityMaps, out_dir) -> list:
    """The three heatmap PNGs (:func:`heatmap_figure`); returns their paths."""
    files = []
    for kind in HEATMAPS:
        fig = heatmap_figure(m, kind)
        fig.savefig(Path(out_dir) / f"{kind}.png", dpi=110)
        files.append(Path(out_dir) / f"{kind}.png")
    return files


__all__ = ["HEATMAPS", "heatmap_figure", "heatmaps", "star_marks", "tables_markdown", "write_csvs"]
