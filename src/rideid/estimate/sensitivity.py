"""Response and track prioritisation maps (paper §4.3).

* **Parameter -> response** ``S[p, c, r]``: each parameter raised by 25 %
  one at a time (``a`` too, capped at 95 % of the wheelbase), the percentage
  change of the peak ``max_k |y_c|`` of channel ``c`` on run ``r``. A channel
  a run does not excite (peak below 0.1 % of the largest peak of its kind on
  that run) gives no value (the paper's ⌀). Averaged over runs (mean of the
  absolute values) it is the paper's Table 5, ``S_bar[p, c]``.
* **Response -> track** ``R[c, r]``: how strongly run ``r`` excites channel
  ``c``: its RMS on the run divided by the largest RMS of that channel over
  all runs (0..1).
* **Parameter -> track** ``M[p, r] = sum_c S_bar[p, c] R[c, r]``, each row
  normalised to sum 1: the share of parameter ``p``'s information carried by
  each run. The adaptive weights use it (paper eq. 13).

Star ratings (documented thresholds):

* parameter -> response, ``|% change|``: ⌀ < 1, ★ 1-5, ★★ 5-15, ★★★ >= 15;
* response -> track, ``R``: ⌀ < 0.05, ★ 0.05-0.25, ★★ 0.25-0.6, ★★★ >= 0.6;
* parameter -> track, ``M * n_runs`` (1 = an equal share): ⌀ < 0.25,
  ★ 0.25-0.75, ★★ 0.75-1.5, ★★★ >= 1.5.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data.dataset import Dataset
from ..data.scenario import run_times
from ..errors import ArgumentError
from ..model.batch import BatchSimulator
from ..model.equations import CHANNEL_KIND, CHANNELS
from ..model.params import ALL_NAMES, Geometry, as_vector
from ..model.simulate import prepare_run
from .cost import CostFunction

STEP = 0.25
P2R_STARS = (1.0, 5.0, 15.0)
R2T_STARS = (0.05, 0.25, 0.6)
P2T_STARS = (0.25, 0.75, 1.5)


def stars(value, thresholds) -> str:
    if value is None or not np.isfinite(value):
        return "⌀"
    n = sum(value >= t for t in thresholds)
    return "★" * n if n else "⌀"


@dataclass
class SensitivityMaps:
    params: list[str]
    channels: list[str]
    runs: list[str]
    S: np.ndarray        # (p, c, r) % change of peak, NaN where not excited
    S_bar: np.ndarray    # (p, c)
    R: np.ndarray        # (c, r)
    M: np.ndarray        # (p, r), rows sum to 1
    baseline: np.ndarray  # (12,) or (16,) with the extensions

    def submap(self, names) -> np.ndarray:
        """Rows of ``M`` for the given parameter names."""
        return self.M[[self.params.index(n) for n in names]]


def compute_maps(sim: BatchSimulator, geom: Geometry, baseline, run_ids, channel_mask=None) -> SensitivityMaps:
    """Compute the three maps around ``baseline`` (12 parameters, or 16 with the extensions of SPEC §6).

    ``channel_mask`` (n_runs, 10) bool marks the channels measured per run
    (default: all). An extension at 0 in the baseline is raised from 0 to
    nothing and gets an all-zero row: give the baseline a typical value
    (:data:`rideid.model.params.NOMINAL_EXTENSIONS`).
    """
    base = np.asarray(baseline, dtype=float).reshape(-1)
    names = ALL_NAMES[:base.size]
    P = np.tile(base, (base.size + 1, 1))
    for i, n in enumerate(names):
        v = base[i] * (1 + STEP)
        if n == "a":
            v = min(v, 0.95 * geom.wheelbase)
        P[1 + i, i] = v
    outs = sim.outputs(P)
    n_runs = len(outs)
    if channel_mask is None:
        channel_mask = np.ones((n_runs, len(CHANNELS)), bool)
    peaks = np.stack([np.abs(o).max(axis=1) for o in outs], axis=-1)  # (1 + p, c, r)
    rms = np.stack([np.sqrt(np.mean(o[0] ** 2, axis=0)) for o in outs], axis=-1)  # (c, r)
    excited = np.zeros((len(CHANNELS), n_runs), bool)
    for ci, c in enumerate(CHANNELS):
        same = [j for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c]]
        excited[ci] = peaks[0, ci] > 1e-3 * peaks[0, same].max(axis=0)
    excited &= channel_mask.T
    with np.errstate(divide="ignore", invalid="ignore"):
        S = 100.0 * (peaks[1:] - peaks[0][None]) / peaks[0][None]
    S = np.where(excited[None], S, np.nan)
    with np.errstate(invalid="ignore"):
        S_bar = np.nanmean(np.abs(S), axis=2)
    S_bar = np.nan_to_num(S_bar, nan=0.0)
    rms = np.where(excited, rms, 0.0)
    mx = rms.max(axis=1, keepdims=True)
    R = np.divide(rms, mx, out=np.zeros_like(rms), where=mx > 0)
    M = S_bar @ R
    rs = M.sum(axis=1, keepdims=True)
    M = np.divide(M, rs, out=np.full_like(M, 1.0 / n_runs), where=rs > 0)
    return SensitivityMaps(list(names), list(CHANNELS), list(run_ids), S, S_bar, R, M, base)


def sensitivity_maps(source, *, cost=None) -> SensitivityMaps:
    """The three maps of a dataset or a scenario (``rideid sensitivity``).

    Parameters
    ----------
    source : Dataset or Scenario
        A dataset: maps around the nominal car of its parameter space
        (:meth:`rideid.ParameterSpace.nominal`), over its measured channels.
        A scenario (a manifest with ``[truth]``): around the truth, all channels.
    cost : CostFunction, optional
        A cost function of the dataset to reuse its prepared runs.

    Returns
    -------
    SensitivityMaps
    """
    if isinstance(source, Dataset) or cost is not None:
        cf = cost if cost is not None else CostFunction(source)
        return compute_maps(cf.sim, cf.space.geometry, cf.space.nominal(), cf.run_ids, cf.W > 0)
    if not getattr(source, "truth", None):
        raise ArgumentError("sensitivity_maps: give a Dataset or a scenario with [truth]")
    runs = [prepare_run(source.tracks[r.track], source.geometry, r.speed, run_times(r)) for r in source.runs]
    return compute_maps(BatchSimulator(source.geometry, runs), source.geometry, as_vector(source.truth),
                        [r.id for r in source.runs])


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
    import csv
    from pathlib import Path
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
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # a plain figure on its own Agg canvas:
    from matplotlib.figure import Figure  # no pyplot, the caller's backend untouched

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


__all__ = ["compute_maps", "sensitivity_maps", "SensitivityMaps"]
