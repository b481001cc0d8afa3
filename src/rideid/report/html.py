"""The identification report: one self-contained HTML file plus its PNGs.

``write_report(result, dataset, out_dir)`` renders an identification result
(:class:`rideid.IdentificationResult`) beside the dataset it was fitted to:
``report.html`` with every figure embedded (base64 PNG) and also saved under
``figures/``. Nothing here is needed by the numerical core; it reads no
files (the command line loads the result and the dataset).
"""

from __future__ import annotations

import base64
import functools
import gc
import html
import io
import math
import multiprocessing as mp
import os
import sys
from collections.abc import Mapping
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import jinja2
import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure as MplFigure
from PIL import Image

from ..profiling import stage
from ..data.quality import summarised_warning
from ..errors import DataError
from ..estimate.assess.adequacy import caveats
from ..estimate.assess.frequency import frequency_response, measured_response
from ..estimate.assess.shape import table_note
from ..estimate.problem.sensitivity import P2T_STARS, stars
from ..estimate.records import drawn_motion_line, drawn_motions, drawn_speeds_line, error_bar_warning, motion_line
from .sensitivity_files import heatmap_figure
from ..model.equations import CHANNELS
from ..model.params import ALL_NAMES, DESCRIPTIONS
from ..model.roads import iso8608_psd
from .estimate_sections import estimate_context
from .figures import COHERENCE_MIN, budget_figure, frequency_figure

FIG_DPI = 90
#: the report's Matplotlib style, applied around each figure's drawing (never to the user's global rcParams);
#: axes.titley fixed: otherwise every axes of every draw searches its tick labels to place the title
STYLE = {"font.size": 8, "axes.grid": True, "grid.alpha": 0.3, "figure.dpi": FIG_DPI, "axes.titley": 1.0}


@dataclass
class Figure:
    id: str
    title: str
    caption: str
    file: str
    data_uri: str


def styled(fn):
    """Run ``fn`` (a function that builds or draws figures) with the report's :data:`STYLE`."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with matplotlib.rc_context(STYLE):
            return fn(*args, **kwargs)
    return wrapper


class StyledCanvas(FigureCanvasAgg):
    """An Agg canvas that draws with the report's :data:`STYLE`: what Matplotlib makes at draw time
    (ticks, their labels and grid lines) takes the style too, whoever asks for the draw."""

    def draw(self):
        with matplotlib.rc_context(STYLE):
            super().draw()


def new_figure(**kwargs) -> MplFigure:
    """A Matplotlib figure of its own on a :class:`StyledCanvas`: no pyplot, the backend left alone."""
    with matplotlib.rc_context(STYLE):
        fig = MplFigure(**kwargs)
    StyledCanvas(fig)
    return fig


@styled
def _save(fig, out_dir: Path, name: str, title: str, caption: str, keep: bool = False,
          drawn: bool = False) -> Figure:
    """Write ``fig`` as ``figures/<name>.png`` and close it (unless ``keep``: a reused template).
    ``drawn``: the canvas already holds the picture (the caller drew it).

    Drawn once on the Agg canvas and encoded by Pillow as RGB at zlib level 1: the report's
    figures are opaque, so the alpha channel only costs bytes, and level 1 encodes in about
    half the time of the default level 6 for a file of about the same size.
    """
    if not isinstance(fig.canvas, FigureCanvasAgg):  # a figure drawn elsewhere, e.g. through pyplot
        FigureCanvasAgg(fig)
    fdir = out_dir / "figures"
    fdir.mkdir(parents=True, exist_ok=True)
    path = fdir / f"{name}.png"
    if not drawn:
        fig.canvas.draw()
    img = Image.frombuffer("RGBA", fig.canvas.get_width_height(), fig.canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    buf = io.BytesIO()
    img.convert("RGB").save(buf, format="png", compress_level=1)
    png = buf.getvalue()
    path.write_bytes(png)
    pyplot = sys.modules.get("matplotlib.pyplot")
    if not keep and pyplot is not None:
        pyplot.close(fig)  # a pyplot figure (no-op for ours): pyplot must forget it
    uri = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
    return Figure(name, title, caption, f"figures/{name}.png", uri)


@styled
def fig_convergence(hist, out_dir):
    """JADE's convergence: best and mean cost per generation, and its adaptive means."""
    g = [h["generation"] for h in hist]
    fig = new_figure(figsize=(10, 3.2))
    a1, a2 = fig.subplots(1, 2)
    lg = lambda k: [np.log10(max(h[k], 1e-300)) for h in hist]  # noqa: E731
    a1.plot(g, lg("best_cost"), label="best (current weights)")
    a1.plot(g, lg("mean_cost"), label="population mean", alpha=0.8)
    if "best_cost_equal" in hist[0]:
        a1.plot(g, lg("best_cost_equal"), "--", label="best, equal weights")
    a1.set_xlabel("generation")
    a1.set_ylabel("log10 cost")
    a1.legend()
    a2.plot(g, [h["mu_f"] for h in hist], label="μ_F")
    a2.plot(g, [h["mu_cr"] for h in hist], label="μ_CR")
    a2.set_ylim(0, 1)
    a2.set_xlabel("generation")
    a2.legend()
    a2.set_title("JADE adaptation")
    a1.set_title("convergence")
    # fixed margins (the labels are fixed words): tight_layout would cost an extra draw
    fig.subplots_adjust(left=0.06, right=0.985, bottom=0.14, top=0.91, wspace=0.15)
    return _save(fig, out_dir, "convergence", "Convergence",
                 "Best and mean cost per generation (log scale); JADE's adaptive means μ_F and μ_CR.")


def _styles(n):
    """Distinct colour and line style for up to 20 lines."""
    cmap = matplotlib.colormaps["tab10"]
    return [{"color": cmap(i % 10), "ls": "-" if i < 10 else "--"} for i in range(n)]


@styled
def fig_spread(hist, names, out_dir):
    """Each free parameter's spread in the JADE population and its population mean per generation."""
    sty = _styles(len(names))
    g = [h["generation"] for h in hist]
    fig = new_figure(figsize=(10, 3.6))
    a1, a2 = fig.subplots(1, 2)
    for k, n in enumerate(names):
        a1.plot(g, [np.log10(max(h[f"cv_{n}"], 1e-16)) for h in hist], label=n, **sty[k])
    a1.set_xlabel("generation")
    a1.set_ylabel("log10 coefficient of variation")
    a1.set_title("parameter spread (paper eq. 12 before normalisation)")
    a1.legend(ncol=2, fontsize=6)
    final = {n: hist[-1][f"best_{n}"] for n in names}
    for k, n in enumerate(names):
        a2.plot(g, [h[f"mean_{n}"] / final[n] for h in hist], label=n, **sty[k])
    a2.set_xlabel("generation")
    a2.set_ylabel("population mean / final best")
    a2.set_title("parameter traces")
    a2.set_ylim(0, 2.5)
    fig.subplots_adjust(left=0.06, right=0.985, bottom=0.125, top=0.92, wspace=0.18)
    return _save(fig, out_dir, "spread", "Parameter spread",
                 "Each free parameter's coefficient of variation in the JADE population (left) and its population "
                 "mean relative to the final best (right). Parameters whose spread falls slowly are the ones the "
                 "data pin down least.")


@styled
def fig_weights(hist, runs, out_dir, mode):
    """The track weights per generation, stacked."""
    g = [h["generation"] for h in hist]
    runs = [r for r in runs if f"weight_{r}" in hist[0]]  # (unknown-road runs are not weighted by the search)
    W = np.array([[h[f"weight_{r}"] for r in runs] for h in hist]).T
    fig = new_figure(figsize=(10, 3.2))
    ax = fig.subplots()
    ax.stackplot(g, W, labels=runs)
    ax.set_xlim(g[0], g[-1])
    ax.set_ylim(0, 1)
    ax.set_xlabel("generation")
    ax.set_ylabel("track weight")
    ax.legend(ncol=5, fontsize=6, loc="upper center", bbox_to_anchor=(0.5, -0.2))
    ax.set_title(f"track weights ({mode})")
    fig.tight_layout()
    return _save(fig, out_dir, "weights", "Track weights",
                 "Track weights per generation (stacked, sum 1). Adaptive weights follow the parameter spread through "
                 "the parameter→track map (paper eq. 13); fixed weights stay equal.")


def _db(x):
    # decibels on a linear axis: log-scale axes cost matplotlib mathtext per tick
    return 20 * np.log10(np.maximum(np.abs(x), 1e-12))


GROUPS = (("body accelerations", "m/s²", (0, 1, 2, 3)), ("axle accelerations", "m/s²", (4, 5, 6, 7)),
          ("rates", "rad/s", (8, 9)))


@styled
def fig_compare(hist, label, other_hist, other_label, runs, out_dir):
    """Two identifications of one dataset (e.g. adaptive vs fixed weights)."""
    fig = new_figure(figsize=(11, 6.4))
    gs = fig.add_gridspec(2, 2, height_ratios=[1, 1])
    a = fig.add_subplot(gs[:, 0])
    for h, lab, ls in ((hist, label, "-"), (other_hist, other_label, "--")):
        key = "best_cost_equal" if "best_cost_equal" in h[0] else "best_cost"
        a.plot([x["evaluations"] for x in h], [np.log10(max(x[key], 1e-300)) for x in h], ls, label=lab)
    a.set_xlabel("evaluations")
    a.set_ylabel("log10 best cost (equal weights)")
    a.set_title("convergence")
    a.legend()
    for row, (h, lab) in enumerate(((hist, label), (other_hist, other_label))):
        ax = fig.add_subplot(gs[row, 1])
        ax.stackplot([x["generation"] for x in h], np.array([[x.get(f"weight_{r}", 0.0) for r in runs] for x in h]).T,
                     labels=runs)
        ax.set_ylim(0, 1)
        ax.set_title(f"track weights: {lab}")
        if row == 1:
            ax.set_xlabel("generation")
            ax.legend(ncol=5, fontsize=6, loc="upper center", bbox_to_anchor=(0.5, -0.25))
    fig.tight_layout()
    return _save(fig, out_dir, "compare", f"Comparison: {label} vs {other_label}",
                 "Best equal-weight cost against evaluations for both identifications (left) and their track "
                 "weights per generation (right).")


#: One fit figure per channel layout and process, redrawn for every run: the axes, ticks and
#: legends are built once (the first draw of a fresh figure costs 3x a redraw; measured 0.5 s vs 0.17 s)
_FIT_TEMPLATES: dict = {}
#: per channel layout: the spectra limits and the pixels of the figure without its per-run artists
_FIT_BACKGROUNDS: dict = {}
_FIT_LEGENDS: dict = {}


@styled
def _fit_template(present: tuple):
    """Figure, axes and line artists of the fit figure for the channels ``present``.

    Built once per channel layout and process; only what changes between runs is drawn again:
    the lines, the ticks and the title. The time axes share x, as do the spectra, so only the
    bottom row labels them. The legends are the same for every run: drawn once, they are kept
    as pixels (``figimage``, exactly what the legend draws) instead of being laid out again.
    """
    if present in _FIT_TEMPLATES:
        return _FIT_TEMPLATES[present]
    fig = new_figure(figsize=(12, 6.2))
    axes = fig.subplots(3, 2, sharex="col", gridspec_kw={"width_ratios": [2.2, 1]})
    lines = {}
    legends = []
    for row, (label, unit, idx) in enumerate(GROUPS):
        a, b = axes[row]
        for k, i in enumerate(idx):
            if i not in present:
                continue
            name = CHANNELS[i].split("_")[-1] if row < 2 else CHANNELS[i]
            lines[i] = (a.plot([], [], lw=0.7, color=f"C{k}")[0],
                        a.plot([], [], lw=0.7, ls="--", color="k", alpha=0.7)[0],
                        b.plot([], [], lw=0.6, color=f"C{k}", label=name)[0])
        lines[("max", row)] = b.plot([], [], lw=0.6, color="0.6", label="largest\nmeasured")[0]
        b.set_ylabel(f"dB re 1 {unit}")
        a.set_ylabel(f"{label}\n[{unit}]")
        # one legend per row, outside the data: colours are channels in both panels
        legends.append(b.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0))
    title = axes[0, 0].set_title("")
    axes[0, 1].set_title("amplitude spectra of the residuals")
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("frequency [Hz]")
    # fixed margins: tight_layout costs an extra full draw (a third of the time)
    fig.subplots_adjust(left=0.07, right=0.91, bottom=0.08, top=0.95, hspace=0.2, wspace=0.2)
    _FIT_LEGENDS[present] = legends  # replaced by their pixels at the first draw (_fit_background)
    _FIT_TEMPLATES[present] = (fig, axes, lines, title)
    return _FIT_TEMPLATES[present]


def _freeze(fig, artists):
    """Replace ``artists`` that never change (legends outside the axes) by the pixels the last
    draw gave them, and pin the visible axes' x labels where that draw put them.

    An x label's place depends only on the height of the tick labels (one line of digits in a
    fixed font), not on the data; placing it again costs a bounding-box pass over every tick
    label of the column's axes on every draw.
    """
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        if ax.get_visible():
            y = ax.xaxis.label.get_position()[1]  # pixels below the axes, after the draw
            ax.xaxis.set_label_coords(0.5, ax.transAxes.inverted().transform((0.0, y))[1])
    buf = np.asarray(fig.canvas.buffer_rgba())
    height = buf.shape[0]
    for art in artists:
        bb = art.get_window_extent(renderer)
        # two pixels of margin: the frame's anti-aliased edge reaches one pixel past its extent
        x0, y0 = max(int(np.floor(bb.x0)) - 2, 0), max(int(np.floor(bb.y0)) - 2, 0)
        x1, y1 = min(int(np.ceil(bb.x1)) + 2, buf.shape[1]), min(int(np.ceil(bb.y1)) + 2, height)
        fig.figimage(buf[height - y1:height - y0, x0:x1].copy(), xo=x0, yo=y0, origin="upper", zorder=10)
        art.remove()


def _fit_spectra(t, Y, Ysim, present):
    """Frequencies [Hz] and, per channel group, the residual spectra of its channels and the largest
    measured spectrum, in dB: ``(f, {channel: dB}, [dB per group])``."""
    f = np.fft.rfftfreq(t.size, t[1] - t[0])
    res = {i: _db(np.fft.rfft(Y[:, i] - Ysim[:, i]) / t.size) for i in present}
    top = [_db(np.nanmax(np.abs(np.fft.rfft(np.nan_to_num(Y[:, list(idx)]), axis=0)), axis=1) / t.size)
           for _, _, idx in GROUPS]
    return f, res, top


def spectra_limits(runs) -> tuple:
    """Common axis limits of the fit figures' spectra: ``(xlim, (ylim per channel group))``.

    ``runs``: ``(t, Y, Ysim)`` per run. The same dB scale on every run's figure lets the eye
    compare residual levels between runs, and lets each figure reuse the drawn spectra axes.
    Margins as Matplotlib's autoscale (5 % of the range).
    """
    fmax, lo, hi = 0.0, [np.inf] * len(GROUPS), [-np.inf] * len(GROUPS)
    for t, Y, Ysim in runs:
        present = tuple(i for i in range(Y.shape[1]) if not np.all(np.isnan(Y[:, i])))
        f, res, top = _fit_spectra(t, Y, Ysim, present)
        fmax = max(fmax, f[-1])
        for row, (_, _, idx) in enumerate(GROUPS):
            # a channel the fit left out has no model response: its residual spectrum is NaN throughout
            curves = [c for c in [top[row]] + [res[i] for i in idx if i in present] if not np.all(np.isnan(c))]
            if curves:
                lo[row] = min(lo[row], min(float(np.nanmin(c)) for c in curves))
                hi[row] = max(hi[row], max(float(np.nanmax(c)) for c in curves))
    pad = lambda a, b: (a - 0.05 * (b - a), b + 0.05 * (b - a)) if b > a else (a - 1.0, b + 1.0)  # noqa: E731
    return pad(0.0, fmax), tuple(pad(a, b) if np.isfinite(a) else (-1.0, 1.0) for a, b in zip(lo, hi))


@styled
def _fit_background(present: tuple, limits) -> dict:
    """The fit figure of the channels ``present`` drawn without its per-run artists (time-domain
    axes, spectrum lines), for spectra ``limits``: built once per process and limits."""
    fig, axes, lines, title = _fit_template(present)
    spec_lines = [lines[("max", row)] for row in range(len(GROUPS))] + [lines[i][2] for i in present]
    cache = _FIT_BACKGROUNDS.setdefault(present, {})
    if cache.get("limits") != limits:
        for b, ylim in zip(axes[:, 1], limits[1]):
            b.set_xlim(*limits[0])
            b.set_ylim(*ylim)
        for art in list(axes[:, 0]) + spec_lines:
            art.set_visible(False)
        fig.canvas.draw()
        # the first draw of a new template also gives the legends' pixels (one draw, not two)
        if present in _FIT_LEGENDS:
            _freeze(fig, _FIT_LEGENDS.pop(present))
        cache["background"] = fig.canvas.copy_from_bbox(fig.bbox)
        cache["limits"] = limits
        for art in list(axes[:, 0]) + spec_lines:
            art.set_visible(True)
    return cache


@styled
def fig_fit(run_id, t, Y, Ysim, out_dir, limits=None):
    """Measured vs simulated per channel group, and residual spectra.

    ``limits``: the spectra's axis limits (:func:`spectra_limits`), common to the runs of a
    report; by default this run's own. The spectra axes (frame, ticks, labels, legends) are
    then the same for every run of the report: they are drawn once, kept as pixels, and each
    run draws only its time-domain axes and its spectrum lines over them.
    """
    present = tuple(i for i in range(Y.shape[1]) if not np.all(np.isnan(Y[:, i])))
    fig, axes, lines, title = _fit_template(present)
    if limits is None:
        limits = spectra_limits([(t, Y, Ysim)])
    f, res, top = _fit_spectra(t, Y, Ysim, present)
    cache = _fit_background(present, limits)
    for row, (_, _, idx) in enumerate(GROUPS):
        for i in idx:
            if i in present:
                measured, simulated, spectrum = lines[i]
                measured.set_data(t, Y[:, i])
                simulated.set_data(t, Ysim[:, i])
                spectrum.set_data(f, res[i])
        lines[("max", row)].set_data(f, top[row])
        a = axes[row, 0]
        a.relim()
        a.autoscale_view()
    title.set_text(f"run {run_id}: measured (colour) vs simulated (dashed)")
    canvas = fig.canvas
    canvas.restore_region(cache["background"])
    renderer = canvas.get_renderer()
    for a in axes[:, 0]:
        a.draw(renderer)
    for b in axes[:, 1]:
        for ln in b.lines:  # in the order a full draw takes: the same pixels where lines cross
            b.draw_artist(ln)
    return _save(fig, out_dir, f"fit_{run_id}", f"Fit: run {run_id}",
                 f"Run {run_id}: measured channels (colour) and the identified model (dashed), grouped as body "
                 "accelerations, axle accelerations and rates (left); amplitude spectra of each channel's residual "
                 "against the largest measured spectrum (right), on one scale for all runs. A good fit leaves "
                 "residuals at the noise floor, flat across frequency; a peak in a residual spectrum points at "
                 "unmodelled dynamics there.",
                 keep=True, drawn=True)


def fit_statistics(Y, Ysim):
    """Per channel present: the RMS of the residual relative to the measured RMS."""
    out = {}
    for i, c in enumerate(CHANNELS):
        if np.all(np.isnan(Y[:, i])):
            continue
        e = np.sqrt(np.mean((Y[:, i] - Ysim[:, i]) ** 2))
        s = np.sqrt(np.mean(Y[:, i] ** 2))
        if s > 0:  # a channel the run does not excite at all (roll rate on a washboard) has no relative error
            out[c] = float(e / s)
    return out


HEAT_CAPTIONS = {
    "param_response": "Parameter → response: mean |% change of each channel's peak| for +25 % of each parameter, "
                      "over all runs (paper Table 5); stars as in docs/method.md.",
    "response_track": "Response → track: how strongly each run excites each channel (RMS relative to the run "
                      "that excites it most).",
    "param_track": "Parameter → track: share of each parameter's sensitivity carried by each run (rows sum to 1); "
                   "the matrix the adaptive weights use.",
}


@styled
def fig_heatmap(kind, maps, out_dir):
    """One sensitivity map with each cell's star rating (``kind``: a key of ``HEAT_CAPTIONS``;
    drawn by :func:`rideid.report.sensitivity_files.heatmap_figure`)."""
    title = kind.replace("_", " → ").replace("param", "parameter")
    return _save(heatmap_figure(maps, kind), Path(out_dir), kind, title, HEAT_CAPTIONS[kind])


#: the label of a knot no run excites in the damper figure
NOT_EXCITED_LABEL = "not excited — not to be trusted"


def velocity_histograms(vels: dict, n_bins: int = 60):
    """Common bin edges over every run and axle, and per run the counts ``(front, rear)``: every sample
    falls in a bin (the edges span the smallest to the largest velocity)."""
    allv = np.concatenate([np.concatenate(fr) for fr in vels.values()])
    lo, hi = float(allv.min()), float(allv.max())
    if hi <= lo:
        lo, hi = lo - 1e-3, hi + 1e-3
    edges = np.linspace(lo, hi, n_bins + 1)
    return edges, {rid: tuple(np.histogram(v, bins=edges)[0] for v in fr) for rid, fr in vels.items()}


@styled
def fig_road(run_id: str, x, z, rec: dict, out_dir):
    """An unknown-road run's estimated road: both wheel paths against distance, and their spectrum against
    the ISO 8608 class bands."""
    return _save(road_figure(x, z, rec, run_id), Path(out_dir), f"road_{run_id}", f"Road of {run_id}",
                 f"Run {run_id}: the estimated road under the left and right wheel paths (top; over "
                 f"{rec['wavelengths_m'][0]:g}-{rec['wavelengths_m'][1]:g} m wavelengths, x from the front axle at the "
                 f"first sample) and its displacement spectrum (bottom) against the ISO 8608 classes' geometric "
                 f"means (dashed); the fitted class {rec['iso8608_class']}, Gd(n0) = {rec['gd_n0']:.3g} m³.")


@styled
def road_figure(x, z, rec: dict, run_id: str = ""):
    """The Matplotlib figure of :func:`fig_road`."""
    from scipy.signal import welch  # slow to import, for the road figure only
    fig = new_figure(figsize=(10, 6))
    a1, a2 = fig.subplots(2, 1)
    a1.plot(x, 1e3 * z[:, 0], lw=0.7, label="left")
    a1.plot(x, 1e3 * z[:, 1], lw=0.7, label="right")
    a1.set_xlabel("x, m")
    a1.set_ylabel("road height, mm")
    a1.legend(loc="upper right")
    a1.set_title(f"{run_id}: ISO 8608 class {rec['iso8608_class']}")
    dx = float(x[1] - x[0])
    n, P = welch(z, fs=1.0 / dx, nperseg=min(len(x), int(4 * rec["wavelengths_m"][1] / dx)), axis=0)
    band = (n >= 1 / rec["wavelengths_m"][1]) & (n <= 1 / rec["wavelengths_m"][0])
    a2.loglog(n[band], P[band].mean(axis=1), "k", lw=1.2, label="estimated road (mean of both paths)")
    nn = np.geomspace(n[band][0], n[band][-1], 50)
    for cls in "ABCDE":
        a2.loglog(nn, iso8608_psd(nn, cls), "--", lw=0.8, label=f"class {cls}")
    a2.set_xlabel("spatial frequency n, cycles/m")
    a2.set_ylabel("Gd(n), m³")
    a2.legend(loc="lower left", fontsize=7, ncol=3)
    fig.tight_layout()
    return fig


@styled
def fig_damper_curves(dampers: dict, slopes: dict, out_dir):
    """Per axle the identified force-velocity curve, its +-2 std_robust band at the knots, the knots
    no run excites marked, and the derived linear c_s for reference."""
    return _save(damper_curves_figure(dampers, slopes), Path(out_dir), "damper_curves", "Damper curves",
                 "Identified force–velocity curve per axle (piecewise linear through the origin and the knots), "
                 "with ± 2 std_robust at the knots (shaded band and bars). Red crosses: knots no run excites "
                 f"({NOT_EXCITED_LABEL}: the force continues the last excited segment's slope). Dashed: the "
                 "derived linear c_s (the curve's mean slope between ±0.1 m/s) for reference. Green dotted "
                 "lines: the knees found by the data (where the two-segment line fitted to each side bends), "
                 "shaded ± 2 std_robust (statistical only).")


@styled
def damper_curves_figure(dampers: dict, slopes: dict):
    """The Matplotlib figure of :func:`fig_damper_curves` (``slopes``: axle -> derived c_s or None)."""
    v = np.asarray(dampers["velocity"], dtype=float)
    j0 = int(np.searchsorted(v, 0.0))
    fig = new_figure(figsize=(10, 3.8))
    axes = fig.subplots(1, 2)
    for ax, axle, colour in zip(axes, ("front", "rear"), ("tab:blue", "tab:orange")):
        d = dampers[axle]
        F = np.asarray(d["force"], dtype=float)
        exc = np.asarray(d["excited"], dtype=bool)
        sd = np.array([np.nan if s is None else s for s in d["std_robust"]], dtype=float)
        vv, FF = np.insert(v, j0, 0.0), np.insert(F, j0, 0.0)
        ax.plot(vv, FF, "-", color=colour, lw=1.6, label=f"identified curve ({axle})")
        ok = exc & np.isfinite(sd)
        if ok.any():
            band_v = np.insert(v[ok], int(np.searchsorted(v[ok], 0.0)), 0.0)
            lo = np.insert((F - 2 * sd)[ok], int(np.searchsorted(v[ok], 0.0)), 0.0)
            hi = np.insert((F + 2 * sd)[ok], int(np.searchsorted(v[ok], 0.0)), 0.0)
            ax.fill_between(band_v, lo, hi, color=colour, alpha=0.25, lw=0, label="± 2 std_robust")
            ax.errorbar(v[ok], F[ok], yerr=2 * sd[ok], fmt="o", ms=4, color=colour, capsize=3, lw=1)
        if (~exc).any():
            ax.plot(v[~exc], F[~exc], "x", ms=8, mew=2, color="tab:red", label=NOT_EXCITED_LABEL)
            for vk, Fk in zip(v[~exc], F[~exc]):
                ax.annotate("not excited", (vk, Fk), textcoords="offset points", xytext=(0, 8 if vk > 0 else -14),
                            ha="center", fontsize=7, color="tab:red")
        _mark_knees(ax, (dampers.get("knees") or {}).get(axle) or {})
        c = slopes.get(axle)
        if c is not None:
            ax.plot(v[[0, -1]], c * v[[0, -1]], "--", color="0.45", lw=1,
                    label=f"derived c_s{axle[0]} = {c:.0f} N s/m (mean slope ±0.1 m/s)")
        ax.axhline(0, color="0.6", lw=0.6)
        ax.axvline(0, color="0.6", lw=0.6)
        ax.set_xlabel("suspension velocity (m/s, compression +)")
        ax.set_ylabel("damper force at the wheel (N)")
        ax.set_title(f"{axle} axle")
        ax.legend(fontsize=7, loc="upper left")
    fig.subplots_adjust(left=0.08, right=0.985, bottom=0.13, top=0.92, wspace=0.25)
    return fig


def plus_minus(value: float, spread: float | None, decimals: int = 3) -> str:
    """``"+0.13640 ± 0.00021"``: ``value`` signed and ``spread``, both to at least ``decimals`` places and to as
    many as the spread's second significant digit needs (never a zero spread that is not zero)."""
    if not spread:
        return f"{value:+.{decimals}f}"
    places = max(decimals, 1 - math.floor(math.log10(abs(spread))))
    return f"{value:+.{places}f} ± {spread:.{places}f}"


def knee_summary(dampers: dict) -> str:
    """``"; knees found: front +0.136 ± 0.0042 / -0.137 ± 0.0051 m/s, ..."``: the knees of result.json
    ``dampers`` (empty without any), each ± 2 std_robust to its second significant digit (:func:`plus_minus`)."""
    parts = []
    for axle in ("front", "rear"):
        k = (dampers.get("knees") or {}).get(axle) or {}
        vals = [plus_minus(k[s]["velocity"], 2 * (k[s].get("std_robust") or 0.0))
                for s in ("compression", "rebound") if (k.get(s) or {}).get("velocity") is not None]
        if vals:
            parts.append(f"{axle} {' / '.join(vals)}")
    return f"; knees found (± 2 std_robust, m/s): {', '.join(parts)}" if parts else ""


def _mark_knees(ax, knees: dict):
    """The knees found on an axle (result.json ``dampers.knees[axle]``): a dotted line at each, its
    ± 2 std_robust shaded, labelled with the velocity."""
    first = True
    for side in ("compression", "rebound"):
        k = knees.get(side) or {}
        vk = k.get("velocity")
        if vk is None:
            continue
        s = k.get("std_robust") or 0.0
        ax.axvline(vk, color="tab:green", ls=":", lw=1.4, label="knee found (± 2 std_robust)" if first else None)
        ax.axvspan(vk - 2 * s, vk + 2 * s, color="tab:green", alpha=0.2, lw=0)
        ax.annotate(f"knee {abs(vk):.3f} m/s", (vk, 0), textcoords="offset points",
                    xytext=(4 if vk > 0 else -4, -12 if vk > 0 else 6), ha="left" if vk > 0 else "right",
                    fontsize=7, color="tab:green")
        first = False


@styled
def fig_damper_velocities(edges, hists: dict, knots, out_dir):
    """Per run: a histogram of the suspension velocities reached, front and rear."""
    n = len(hists)
    ncol = min(5, n)
    nrow = -(-n // ncol)
    fig = new_figure(figsize=(10, 1.9 * nrow + 0.5))
    axes = fig.subplots(nrow, ncol, sharex=True, squeeze=False)
    for ax, (rid, (cf, cr)) in zip(axes.flat, hists.items()):
        ax.stairs(np.maximum(cf, 0.5), edges, baseline=0.5, color="tab:blue", label="front")
        ax.stairs(np.maximum(cr, 0.5), edges, baseline=0.5, color="tab:orange", label="rear")
        ax.set_yscale("log")
        ax.set_ylim(0.7, None)
        for k in knots:
            ax.axvline(k, color="0.5", lw=0.6, ls=":")
        ax.set_title(rid, fontsize=8)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("velocity (m/s)")
    for ax in axes[:, 0]:
        ax.set_ylabel("samples")
    axes.flat[0].legend(fontsize=6, loc="upper left")
    fig.subplots_adjust(left=0.07, right=0.985, bottom=0.5 / (1.9 * nrow + 0.5) + 0.06, top=0.93,
                        wspace=0.25, hspace=0.45)
    return _save(fig, Path(out_dir), "damper_velocities", "Suspension velocities reached",
                 "Per run, histogram (log scale) of the suspension velocities of the identified car simulated on "
                 "the run (on an unknown road: read off its body and axle accelerometers), both corners of each "
                 "axle; dotted: the damper knots. A knot is excited when at least 20 samples over all runs go "
                 "beyond the knot before it.")


def _fig_job(job):
    name, args = job
    return globals()[name](*args)


#: relative drawing cost of the figures (measured: heat maps and the spread 0.2-0.3 s each, the others
#: 0.1-0.15 s): the pool takes the costly ones first, so that no worker finishes a long one alone
FIGURE_COST = {"fig_heatmap": 3, "fig_spread": 3, "fig_compare": 2, "fig_convergence": 2}


def _map_figures(jobs):
    """Render figures on all cores (matplotlib is single-threaded), the costliest first (:data:`FIGURE_COST`);
    serial fallback. Returns the figures in the order of ``jobs``."""
    n = min(len(jobs), os.cpu_count() or 1)
    if n > 1:
        order = sorted(range(len(jobs)), key=lambda i: -FIGURE_COST.get(jobs[i][0], 1))
        try:
            # the parent's objects (an identification's worth) out of the workers' garbage collection:
            # collecting them would touch, and so copy, every page the workers share with the parent (no
            # collection first: it took 0.1 s, and unfreeze hands any garbage back to the next one)
            gc.freeze()
            try:
                with ProcessPoolExecutor(n, mp_context=mp.get_context("fork")) as ex:
                    done = dict(zip(order, ex.map(_fig_job, [jobs[i] for i in order])))
                    return [done[i] for i in range(len(jobs))]
            finally:
                gc.unfreeze()
        except (OSError, ValueError, RuntimeError):  # no fork on this platform, or a broken pool
            pass
    return [_fig_job(j) for j in jobs]


@stage("report")
def write_report(result, dataset, out_dir, *, compare=None, compare_label: str | None = None) -> Path:
    """Render ``report.html`` (and ``figures/*.png``) into ``out_dir``.

    Only renders: everything comes from ``result`` (estimates, history,
    maps, preprocessing) and ``dataset`` (the measured runs, at the starts
    the identification settled on: ``dataset.with_starts(result.starts)``);
    the one computation is the identified car's response on the runs.

    Parameters
    ----------
    result : IdentificationResult
    dataset : Dataset
    out_dir : str or Path
        An existing folder (normally the identification's).
    compare : IdentificationResult, optional
        Another identification of the same dataset (for example
        ``--weights fixed`` beside an adaptive run), overlaid.
    compare_label : str, optional
        Its label in the comparison (default: its weighting).

    Returns
    -------
    Path of ``report.html``.
    """
    out_dir = Path(out_dir)
    if result.maps is None and not getattr(result, "roads", None):
        raise DataError(f"{out_dir}: the result carries no sensitivity maps (written by an older rideid?); "
                        "identify again to render the report")
    sims = _responses(result, dataset)
    context = {**figure_sections(result, dataset, sims, out_dir, compare, compare_label),
               **road_section(result, out_dir), **fit_section(result, dataset, sims), **data_section(result, dataset),
               **estimate_section(result, dataset), **frequency_section(result, dataset, out_dir)}
    context.update(summary_section(result, context))
    out = out_dir / "report.html"
    out.write_text(render(context))
    return out


def _parameter_names(result) -> list:
    """The parameters of the result: the twelve, and the extensions when fitted."""
    return [n for n in ALL_NAMES if n in result.details]


def _responses(result, dataset) -> dict:
    """The identified car's response on every run, run id -> (n_time, 10): the result's own (the report never
    simulates: a result read back is completed first, :func:`rideid.estimate.assess.responses.complete`)."""
    sims = result.response
    if sims is None or set(sims) != {r.id for r in dataset.runs} or any(
            len(sims[r.id]) != len(dataset.data[r.id].time) for r in dataset.runs):
        raise DataError("the result carries no response of these runs: pass it through "
                        "rideid.estimate.assess.responses.complete(result, dataset) before writing its report")
    return sims


def _measured(dataset) -> dict:
    """Run id -> the measured (n_time, 10) matrix (NaN columns: channels not logged)."""
    return {r.id: dataset.data[r.id].matrix() for r in dataset.runs}


def figure_sections(result, dataset, sims, out_dir, compare=None, compare_label=None) -> dict:
    """Template context of the report's figures: convergence, spread, weights (and the comparison), the fit
    per run, the sensitivity maps and the damper curves. Every figure but the dampers' is an independent
    job, rendered on all cores."""
    hist, maps, run_ids = list(result.history), result.maps, [r.id for r in dataset.runs]
    other = None
    if compare is not None:
        other = (f"{result.weights_mode} (this)", list(compare.history),
                 compare_label or f"{compare.weights_mode} (other)")
    jobs = []
    if hist:
        names = [k[len("cv_"):] for k in hist[0] if k.startswith("cv_")]
        jobs += [("fig_convergence", (hist, out_dir)), ("fig_spread", (hist, names, out_dir)),
                 ("fig_weights", (hist, run_ids, out_dir, result.weights_mode))]
    measured = _measured(dataset)
    limits = spectra_limits([(dataset.data[r.id].time, measured[r.id], sims[r.id]) for r in dataset.runs])
    # the fit figures' common part, drawn here once: the processes that render the runs inherit it
    for present in {tuple(i for i in range(m.shape[1]) if not np.all(np.isnan(m[:, i]))) for m in measured.values()}:
        _fit_background(present, limits)
    jobs += [("fig_fit", (r.id, dataset.data[r.id].time, measured[r.id], sims[r.id], out_dir, limits))
             for r in dataset.runs]
    heat_kinds = list(HEAT_CAPTIONS) if maps is not None else []
    jobs += [("fig_heatmap", (k, maps, out_dir)) for k in heat_kinds]
    if other is not None:
        jobs.append(("fig_compare", (hist, other[0], other[1], other[2], run_ids, out_dir)))
    done = _map_figures(jobs)
    compare_figs = [done.pop()] if other is not None else []
    heat_figs = [done.pop() for _ in heat_kinds][::-1]
    return {"figures": (done[:3] if hist else []) + compare_figs, "fit_figures": done[3:] if hist else done,
            "heat_figures": heat_figs, "damper_figures": damper_section(result, dataset, out_dir),
            "budget_figure": fig_budget(result, out_dir)}


@styled
def fig_budget(result, out_dir):
    """Each estimate's uncertainty budget (SPEC §12), :func:`rideid.report.figures.budget_figure`; None for a
    result without budgets (written before them)."""
    if not any(d.get("budget") for d in result.details.values()):
        return None
    declared = list((result.uncertainty or {}).get("declared") or {})
    what = ("the declared uncertainties of " + ", ".join(declared)) if declared else "nothing declared"
    return _save(budget_figure(result), Path(out_dir), "budget", "Uncertainty budget",
                 "Each estimate's ±2 std_total in % of its value, cut into its sources in proportion to their share "
                 "of the variance: statistical (the sensor noise), between runs (where the runs disagree beyond their "
                 "noise: model error that differs from run to run, part of std_robust), speed and start (of runs on "
                 "tracks as built and on unknown roads, fitted with the car; part of std_robust) and each declared "
                 "input, "
                 f"propagated to first order (GUM; docs/uncertainty.md). Here: {what}.")


@styled
def frequency_section(result, dataset, out_dir) -> dict:
    """Template context of the frequency responses (SPEC §13): the figure, the runs measured and the notes on the
    uncertainty; empty for a result without its geometry (written before it carried it)."""
    if not getattr(result, "vehicle", None):
        return {}
    fr = frequency_response(result)
    measured = measured_response(dataset, result)
    fig = frequency_figure(result, dataset=False if measured is None else dataset, measured=measured)
    runs = ", ".join(measured["runs"]) if measured is not None else ""
    caption = ("The identified car's frequency responses per metre of road height under a wheel: body and axle "
               "acceleration at each corner from its own wheel, and the body's heave, pitch and roll displacement "
               "from the wheels moved in phase, front against rear and left against right (1 m each). Bands: ±2 std "
               "of |H| from the estimates' std_total (docs/frequency-response.md). "
               + (f"Points: the response the data measured (H1 over the runs {runs}, whose road is known from the "
                  f"track, speed and start), ±2 std random error, where its partial coherence exceeds "
                  f"{COHERENCE_MIN:g}; the last panel shows that coherence. " if measured is not None else
                  "No run has a known road: no measured points. ")
               + "All frequencies and every output and input in frf.csv (rideid export).")
    figure = _save(fig, Path(out_dir), "frequency_response", "Frequency responses", caption)
    return {"frequency_figure": figure, "frequency_notes": fr.notes,
            "frequency_summary": frequency_summary(result, fr, measured)}


def frequency_summary(result, fr, measured) -> str:
    """The summary's line on the frequency responses: the bands' largest width over 0.5-25 Hz and how far the
    measured H1 points (partial coherence above :data:`COHERENCE_MIN`) lie from the identified car."""
    sel = (fr.freq >= 0.5) & (fr.freq <= 25)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = fr.std_abs[sel, :10] / np.abs(fr.H[sel, :10])
    text = ("no band (no standard errors)" if not np.any(np.isfinite(rel)) else
            f"±2 std of {200 * np.nanmedian(rel):.2g} % of |H| (median over every channel and wheel, 0.5-25 Hz; "
            f"at most {200 * np.nanmax(rel):.2g} %)")
    if measured is not None:
        model = frequency_response(result, measured["freq"]).H[:, :10]
        keep = (measured["coherence"] > COHERENCE_MIN) & ((measured["freq"] >= 0.5) & (measured["freq"] <= 25))[
            :, None, None]
        if keep.any():
            dev = np.abs(np.abs(measured["H"][keep]) - np.abs(model[keep])) / np.abs(model[keep])
            text += (f"; the measured H1 ({int(keep.sum())} points, coherence > {COHERENCE_MIN:g}) within "
                     f"{100 * np.median(dev):.2g} % of the car (median)")
        else:
            text += f"; no measured H1 point with coherence > {COHERENCE_MIN:g}"
    return text


def damper_section(result, dataset, out_dir) -> list:
    """The damper curves and the suspension velocities reached (a result with damper curves; else none)."""
    if not getattr(result, "dampers", None):
        return []
    if getattr(result, "velocities", None) is None:
        raise DataError("the result carries no suspension velocities: pass it through "
                        "rideid.estimate.assess.responses.complete(result, dataset) before writing its report")
    edges, hists = velocity_histograms(result.velocities)
    slopes = {a: result.parameters.get(n) for a, n in (("front", "c_sf"), ("rear", "c_sr"))}
    return [fig_damper_curves(result.dampers, slopes, out_dir),
            fig_damper_velocities(edges, hists, result.dampers["velocity"], out_dir)]


def road_section(result, out_dir) -> dict:
    """Template context of the unknown-road runs (SPEC §9): their rows, figures and wavelength band."""
    road_figs, road_rows, road_notes, road_speeds = [], [], [], []
    for rid, rec in (getattr(result, "roads", None) or {}).items():
        road_rows.append({"run": rid, "cls": rec["iso8608_class"], "gd": rec["gd_n0"], "speed": rec["speed"],
                          "file": rec["file"]})
        road_notes += [f"{rid}: {c} {why}" for c, why in (rec.get("channels_left_out") or {}).items()]
        if rec.get("motion"):  # its speed as estimated with the car (SPEC §13); named beyond its prior: a SET-UP box
            road_speeds.append(motion_line(rid, rec["motion"]))
            road_notes += [f"SET-UP: {n}" for n in rec["motion"].get("named", [])]
        if result.road_profiles and rid in result.road_profiles:
            x, z = result.road_profiles[rid]
            road_figs.append(fig_road(rid, x, z, rec, out_dir))
    for rid, m in drawn_motions(result).items():  # a run on a track as drawn whose speed was estimated with the car
        road_speeds.append(drawn_motion_line(rid, m))
        road_notes += [f"SET-UP: {n}" for n in m.get("named", [])]
    band = next(iter((result.roads or {}).values()), {}).get("wavelengths_m", (0.5, 20))
    return {"road_figures": road_figs, "road_rows": road_rows, "road_notes": road_notes, "road_speeds": road_speeds,
            "road_band": "{:g}-{:g} m".format(*band),
            "road_judged": roads_judged(result)}


def roads_judged(result) -> bool:
    """Was each road run's residual at its own road estimate judged by its size (rideid.estimate.assess.roads: a
    ``residual`` record) — the summary's verdict line and the roads section say the same of it."""
    return any("residual" in rec for rec in (getattr(result, "roads", None) or {}).values())


def fit_section(result, dataset, sims) -> dict:
    """Template context of the fit table: per run its track, speed, weight and worst/median relative error."""
    measured = _measured(dataset)
    fit_rows = []
    for r in dataset.runs:
        st = fit_statistics(measured[r.id], sims[r.id])
        rig = getattr(r, "posts", False)  # SPEC §13: no track, no speed
        fit_rows.append({"run": r.id, "track": "four-post rig" if rig else r.track, "speed": "–" if rig else r.speed,
                         "weight": result.track_weights.get(r.id),
                         "worst": max(st.values()) if st else float("nan"),
                         "median": float(np.median(list(st.values()))) if st else float("nan")})
    return {"fit_rows": fit_rows}


def data_section(result, dataset) -> dict:
    """Template context of the data section: runs, channel maps, and the data checks' findings."""
    data_rows, channel_rows, data_warnings = data_tables(result.preprocessing or dataset.preprocessing())
    # the data checks' and the bound check's findings (rideid.data.checks)
    data_warnings = data_warnings + [c["message"] for c in (getattr(result, "checks", None) or [])
                                     if isinstance(c, Mapping) and "message" in c]
    quality = quality_rows(getattr(result, "data_quality", None))
    if quality:  # the table stands for the per-run lines on clipping, gaps and flat lines
        data_warnings = [w for w in data_warnings if not summarised_warning(w)]
    return {"dataset": str(dataset.path), "data_rows": data_rows, "channel_rows": channel_rows,
            "data_warnings": data_warnings, "n_runs": len(dataset.runs), "quality_rows": quality}


def quality_rows(quality: dict | None) -> list:
    """Rows of the report's data-quality table from ``result.json``'s ``data_quality``
    (:func:`rideid.data.quality.data_quality`); empty when the result has none."""
    rows = []
    for name, e in ((quality or {}).get("channels") or {}).items():
        notes = []
        if e.get("clipped_runs"):
            notes.append("clipped in " + ", ".join(f"{r} ({100 * v:.2f} %)" for r, v in e["clipped_runs"].items()))
        if e.get("flat_lined"):
            notes.append("flat-lined in " + ", ".join(e["flat_lined"]))
        if e.get("filters"):
            notes.append("sensor " + "; ".join(e["filters"]))
        rows.append({"channel": name, "runs": e.get("runs"),
                     "clipped": f"{100 * e['clipped_share']:.2f} %" if e.get("clipped_runs") else "-",
                     "gaps": e.get("gaps", 0),
                     "noise": "-" if e.get("noise") is None else f"{e['noise']:.3g} {e.get('unit', '')}",
                     "notes": "; ".join(notes)})
    return rows


#: the report's sections in page order: id, title, what it answers (the summary's list of sections and the
#: navigation bar show those the report has)
TOC = (("summary", "Summary", "what to read first"),
       ("verdict", "Verdict", "is the model adequate for these data"),
       ("estimates", "Estimates", "every parameter with its error bar, and how they correlate"),
       ("model", "Model choice", "the candidate models side by side (--model auto)"),
       ("adequacy", "Adequacy", "per run: do the residuals look like sensor noise"),
       ("modal", "Modes", "natural frequencies and damping ratios of the identified car"),
       ("frequency", "Frequency responses", "the identified car's transmissibilities with their bands, and what "
                                            "the data measured"),
       ("dampers", "Damper curves", "the curves with their bands, and the velocities each run reached"),
       ("roads", "Roads", "the estimated roads of the runs on unknown roads and their ISO 8608 classes"),
       ("convergence", "Convergence", "cost per generation of the search"),
       ("spread", "Spread", "how fast each parameter settled in the search"),
       ("weights", "Track weights", "the runs' weights per generation"),
       ("compare", "Comparison", "this identification against the other one given"),
       ("data", "Data", "what was done to each run, channel maps, warnings on the data"),
       ("fits", "Fits", "measured against the identified car, run by run"),
       ("maps", "Sensitivity maps", "which track excites which parameter"))


def summary_section(result, context: dict) -> dict:
    """Template context of the summary a person reads first (the verdict, the car, its error bars, the fit, the
    data, in a few lines) and of the list of sections to jump to (``toc``: those the report has)."""
    res = context["res"]
    adq = context.get("adequacy")
    held = caveats(adq)
    lines = [_verdict_line(result, adq, held)]
    ext = (res.get("model") or {}).get("extensions") or []
    known = ", ".join(f"{k} = {v:g}" for k, v in context["known"].items())
    lines.append(("Car", f"model {' + '.join(ext) if ext else 'base (the twelve parameters)'}; anchored on "
                         f"{known} (every mass, inertia, stiffness and damping scales with it)", "estimates"))
    lines += _estimates_lines(result, context)
    lines += _caveat_lines(result, adq)
    if getattr(result, "dampers", None):
        d = result.dampers
        idle = sum(not e for axle in ("front", "rear") for e in d[axle]["excited"])
        lines.append(("Damper curves", f"{len(d['velocity'])} knots per axle up to {max(d['velocity']):g} m/s"
                      + (f"; {idle} knot force(s) not excited: not to be trusted" if idle else
                         "; every knot excited") + knee_summary(d), "dampers"))
    if context.get("frequency_summary"):
        lines.append(("Frequency responses", context["frequency_summary"], "frequency"))
    rows = [r for r in context["fit_rows"] if r["median"] == r["median"]]
    if rows:
        worst = max(rows, key=lambda r: r["worst"])
        lines.append(("Fit", f"cost {res['cost']:.3g}; median channel NRMSE per run "
                             f"{min(r['median'] for r in rows):.2g} – {max(r['median'] for r in rows):.2g}; "
                             f"worst channel {worst['worst']:.2g} (run {worst['run']})", "fits"))
    lines.append(_data_line(result, context))
    present = {"summary", "estimates", "modal", "data", "fits", "maps"}
    present |= {"verdict", "adequacy"} if adq else set()
    present |= {"model"} if context.get("model_choice") else set()
    present |= {"dampers"} if context.get("damper_figures") else set()
    present |= {"frequency"} if context.get("frequency_figure") else set()
    present |= {"roads"} if context.get("road_figures") else set()
    present |= {f.id for f in context.get("figures", [])}
    return {"summary": lines, "toc": [t for t in TOC if t[0] in present], "verdict_caveats": held}


def _verdict_line(result, adq, held) -> tuple:
    """The summary's verdict: adequate, adequate with caveats ``held``, not adequate, or why not assessed."""
    if adq:
        return ("Verdict", ("MODEL ADEQUATE ON WHAT WAS TESTED, NOT A CLEAN VERDICT "
                            f"({len(held)} caveat{'s' if len(held) > 1 else ''}, below): " if held else
                            "model adequate: " if adq["adequate"] else "MODEL NOT ADEQUATE: ")
                + adq["reasons"][0], "adequacy")
    if getattr(result, "roads", None):
        judged = roads_judged(result)
        return ("Verdict", ("adequacy not fully assessed: each road run's residual at its own road estimate is of "
                            "the noise's size (a car far off would fail it), but rideid has no test of its "
                            "structure on unknown roads; " if judged else
                            "adequacy not assessed: rideid has no residual test on unknown roads yet; the ")
                + "error bars hold only if the model describes the car", "roads")
    return ("Verdict", "adequacy not assessed (no polish)", "estimates")


def _estimates_lines(result, context) -> list:
    """The summary's error bars (the narrowest and the widest, what the budget notes, estimates at a search
    bound) and what the tracks as built needed (SPEC §11)."""
    lines = []
    est = [p for p in context["params"] if p["status"] in ("estimated", "AT A SEARCH BOUND")
           and p["rel_std_total"] is not None]
    if est:
        lo, hi = min(est, key=lambda p: p["rel_std_total"]), max(est, key=lambda p: p["rel_std_total"])
        text = (f"{len(est)} estimated; ±2 std_total from {2 * lo['rel_std_total']:.2g} % ({lo['name']}) to "
                f"{2 * hi['rel_std_total']:.2g} % ({hi['name']})")
        for note in (getattr(result, "uncertainty", None) or {}).get("notes", []):
            text += f"; {note.split(':')[0].upper()}"
        bound = [p["name"] for p in context["params"] if p["status"] == "AT A SEARCH BOUND"]
        if bound:
            text += f"; AT A SEARCH BOUND: {', '.join(bound)}"
        undetermined = [p["name"] for p in context["params"] if p["status"] == "NOT DETERMINED"]
        if undetermined:
            text += f"; NOT DETERMINED (no error bar): {', '.join(undetermined)}"
        conditional = [n for n, d in (getattr(result, "details", None) or {}).items() if d.get("conditional_on")]
        if conditional:
            text += f"; CONDITIONAL (on a parameter at its bound): {', '.join(conditional)}"
        lines.append(("Estimates", text, "estimates"))
    speeds = drawn_speeds_line(result)
    if speeds:  # SPEC §13: a nonlinear car's runs on the tracks as drawn, their speeds estimated with it
        lines.append(("Speeds", speeds[0].upper() + speeds[1:], "data"))
    tracks = getattr(result, "tracks", None) or {}
    built = {tid: rec for tid, rec in tracks.items() if "amplitude_factor" in rec}
    if built:  # SPEC §11: what the tracks as built needed (rideid.estimate.assess.motion.tracks_block)
        rejected = next((rec["rejected"] for rec in tracks.values() if rec.get("rejected")), None)
        text = "; ".join(f"{tid} x {rec['amplitude_factor']:.3f}"
                         + (f" ± {rec['amplitude_factor_std']:.3f}" if rec.get("amplitude_factor_std", 0) > 0.01
                            else "")
                         + f", {1e3 * rec.get('unevenness_rms_surface_m', rec['unevenness_rms_m']):.1f} mm RMS"
                         for tid, rec in built.items())
        lines.append(("Tracks as built", ("REJECTED, the estimates are the tracks' as drawn: " + rejected)
                      if rejected else text + " (amplitude factor, unevenness at waves up to 10 m)", "estimates"))
    return lines


def _caveat_lines(result, adq) -> list:
    """The summary's caveats on the error bars: tracks as drawn, a residual level above the noise, small angles, a
    flat valley of the cost (:mod:`rideid.estimate.assess.shape`)."""
    lines = []
    caveat = (adq or {}).get("tracks_caveat")
    if caveat:  # adequate only by the weighing, on tracks as drawn (model_choice._drawing_caveat)
        lines.append(("Tracks as drawn", "NOT TO BE TRUSTED beyond the error bars: " + caveat, "estimates"))
    loud = (adq or {}).get("level_caveat")
    if loud and adq.get("adequate"):  # adequate by the road-driven test, the residual well above the noise
        lines.append(("Residual level", "MAY NOT BE TRUSTED beyond the error bars: " + loud, "adequacy"))
    small = ((adq or {}).get("small_angle") or {}).get("note")
    if small:  # SPEC §1 is small-angle: which error bars a body that turned degrees makes optimistic
        lines.append(("Small angles", small.split(": ", 1)[-1], "estimates"))
    shape = error_bar_warning(getattr(result, "polish", None))
    if shape:  # a flat valley of the cost: whatever the verdict, these error bars are narrower than the data allow
        lines.append(("Error bars' shape", "NOT TO BE TRUSTED to their std: " + shape, "estimates"))
    return lines


def _data_line(result, context) -> tuple:
    """The summary's data: runs (on unknown roads), warnings on the data, channels left out of a road run."""
    roads = getattr(result, "roads", None) or {}
    n_road = len(roads)
    text = f"{context['n_runs']} runs" + (f" ({n_road} on unknown roads)" if n_road else "")
    nw = len(context["data_warnings"])
    # the per-run lines on clipping and flat lines stand in the data-quality table, not among the warnings
    quality = (getattr(result, "data_quality", None) or {}).get("channels") or {}
    flagged = [name for name, e in quality.items() if e.get("clipped_runs") or e.get("flat_lined")]
    text += f"; {nw} warning{'s' if nw != 1 else ''} on the data" if nw else (
        "; no other warning on the data" if flagged else "; no warning on the data")
    if flagged:
        text += f"; clipped or flat-lined in some run: {', '.join(flagged)} (the data-quality table)"
    left = sum(len(r.get("channels_left_out") or {}) for r in roads.values())
    if left:
        text += f"; {left} channel(s) left out of a road run's fit (no signal)"
    return ("Data", text, "data")


def parameter_rows(result) -> list:
    """One row per parameter: value, unit, standard deviations (absolute and %), bounds, status."""
    params = []
    shape = (getattr(result, "polish", None) or {}).get("shape")
    for n in _parameter_names(result):
        d = result.details[n]
        std = d.get("std")
        rob = d.get("std_robust")
        tot = d.get("std_total", rob)
        params.append({
            "name": n, "meaning": DESCRIPTIONS[n], "value": d["value"], "unit": d["unit"],
            "std": std, "rel_std": (100 * std / abs(d["value"])) if std not in (None, 0.0) and d["value"] else None,
            "std_robust": rob,
            "rel_std_robust": (100 * rob / abs(d["value"])) if rob not in (None, 0.0) and d["value"] else None,
            "std_total": tot,
            "rel_std_total": (100 * tot / abs(d["value"])) if tot not in (None, 0.0) and d["value"] else None,
            "lower": d.get("lower"), "upper": d.get("upper"),
            "status": "known" if d.get("fixed") else ("derived" if d.get("derived") else
                                                      ("AT A SEARCH BOUND" if d.get("at_bound") else
                                                       "NOT DETERMINED" if d.get("determined") is False
                                                       else "estimated")),
            # a flat valley of the cost (rideid.estimate.assess.shape): said beside the number, not only above it
            "note": table_note(shape, n) or ("the data do not fix it: no error bar (the summary's Error bars' shape "
                                             "says why)" if d.get("determined") is False else
                                             d.get("note", "") if d.get("conditional_on") else ""),
        })
    return params


def estimate_section(result, dataset) -> dict:
    """Template context of the estimates: the title, result.json, parameters, modal table, the map's cells,
    and the quality sections (:func:`rideid.report.estimate_sections.estimate_context`)."""
    res, maps = result.to_dict(), result.maps
    p2t = [] if maps is None else [
        {"param": p, "cells": [(f"{maps.M[i, r]:.2f}", stars(maps.M[i, r] * len(maps.runs), P2T_STARS))
                               for r in range(len(maps.runs))]} for i, p in enumerate(maps.params)]
    unc = result.uncertainty or {}
    return {"title": f"rideid identification: {html.escape(dataset.name)}", "res": res,
            "params": parameter_rows(result), "uncertainty": unc, "modal": result.modal or {},
            "runs": [] if maps is None else maps.runs, "p2t": p2t, "known": result.known, **estimate_context(res)}


def render(context: dict) -> str:
    """report.html's text: the template ``report.html.j2`` rendered with ``context``."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(resources.files("rideid.report") / "templates")),
                             autoescape=jinja2.select_autoescape(["html", "j2"]))
    return env.get_template("report.html.j2").render(**context)


def data_tables(pre: dict):
    """Rows of the report's data section from ``result.json``'s ``preprocessing``."""
    rows, chans, warns = [], [], []
    maps_seen = []
    for rid, rec in pre.items():
        st = rec.get("start", {})
        sp = rec.get("speed", {})
        if not sp:
            speed = ""
        elif sp.get("source") == "constant":
            speed = f"constant {sp.get('value'):g} m/s"
        else:
            speed = f"{sp['source']}: {sp.get('min', 0):.2f}..{sp.get('max', 0):.2f} m/s"
        rows.append({"run": rid, "file": Path(rec.get("file", "")).name, "format": rec.get("format", ""),
                     "samples": rec.get("samples"), "fs": rec.get("fs", float("nan")), "start": st.get("value"),
                     "start_std": st.get("std_robust", st.get("std")), "start_source": st.get("source", ""),
                     "speed": speed})
        ch = rec.get("channels")
        if ch:
            key = [(c, {k: v for k, v in d.items() if k not in ("removed", "samples")}) for c, d in ch.items()]
            if key not in maps_seen:  # show a run's channel table only when its map differs from one shown
                maps_seen.append(key)
                for c, d in ch.items():
                    chans.append({"run": rid, "channel": c, **{k: d.get(k) for k in (
                        "source", "unit", "unit_from", "sign", "scale", "rate_hz", "removed", "removed_as",
                        "filter")}})
        warns += rec.get("warnings", [])
    return rows, chans, warns


SECTIONS = ("summary", "estimates", "adequacy", "modal", "frequency", "convergence", "spread", "weights", "data",
            "fits", "maps")
