"""Figures for a notebook: built on :class:`matplotlib.figure.Figure` directly.

Never pyplot, never ``matplotlib.use``: the caller's backend (Jupyter's
inline one, a GUI, Agg in a script) stays as it was. A script saves a
figure with ``fig.savefig``. A notebook shows it as the value of a cell:
Jupyter's own display of Matplotlib figures is only switched on by pyplot
or ``%matplotlib inline``, so the figures are :class:`NotebookFigure`, which
also render themselves as PNG (``_repr_png_``) for a notebook that has
imported neither.
They are public as ``rideid.plot_fit``, ``rideid.plot_parameters``,
``rideid.plot_budget``, ``rideid.plot_dampers`` and ``rideid.plot_frequency_response``
(functions of the result, not its methods: the result belongs to the estimate layer, which never imports the report).
"""

from __future__ import annotations

import io
import math

import numpy as np
from matplotlib.figure import Figure

from ..conditioning.load import load_dataset
from ..estimate.assess.frequency import frequency_response, measured_response
from ..estimate.assess.responses import complete
from ..data.dataset import Dataset
from ..errors import ArgumentError, DataError
from ..model.equations import CHANNELS

#: channel groups of the fit figure: title, unit, channel indices
GROUPS = (("body accelerations", "m/s²", (0, 1, 2, 3)), ("axle accelerations", "m/s²", (4, 5, 6, 7)),
          ("rates", "rad/s", (8, 9)))


def _figure(width, height):
    return NotebookFigure(figsize=(width, height), layout="constrained")


class NotebookFigure(Figure):
    """A :class:`matplotlib.figure.Figure` that a notebook shows as PNG without pyplot.

    IPython displays any object with ``_repr_png_``; where pyplot or ``%matplotlib inline`` has registered
    Matplotlib's own display of figures, that one is used instead (one image either way).
    """

    def _repr_png_(self) -> bytes:
        buf = io.BytesIO()
        self.savefig(buf, format="png", dpi=100)
        return buf.getvalue()


def result_dataset(result, dataset=None):
    """The dataset a result identified: ``dataset`` (a Dataset or a folder) or the folder the result names."""
    if isinstance(dataset, Dataset):
        return dataset
    path = dataset if dataset is not None else result.dataset
    if not path:
        raise DataError("the result names no dataset; pass dataset= (a Dataset or its folder)")
    return load_dataset(path, starts=result.start_records()).with_speeds(result.speed_values())


def responses(result, dataset) -> dict:
    """The identified car's channels on every run of ``dataset``: run id -> ``(n_time, 10)``.

    The response kept in memory by :func:`rideid.identify`, else simulated with the result's model
    (:func:`rideid.estimate.assess.responses.complete`: the curves' car for a result with damper curves).
    """
    return complete(result, dataset).response


def fit_figure(result, run: str, dataset=None, channels=None):
    """Measured (colour) against the identified car (dashed, black) for one run.

    Parameters
    ----------
    result : IdentificationResult
    run : str
        A run id of the dataset.
    dataset : Dataset or path, optional
        Default: the dataset the result names.
    channels : sequence of str, optional
        The channels to draw (default: every channel the run has).

    Returns
    -------
    matplotlib.figure.Figure
        One axes per channel group (body, axle, rates) that has a channel to draw; time in s.
    """
    ds = result_dataset(result, dataset)
    ids = [r.id for r in ds.runs]
    if run not in ids:
        raise ArgumentError(f"run {run!r} is not in the dataset; its runs: {', '.join(ids)}")
    unknown = [c for c in (channels or ()) if c not in CHANNELS]
    if unknown:
        raise ArgumentError(f"unknown channel {unknown[0]!r}; channels: {', '.join(CHANNELS)}")
    t = ds.data[run].time
    Y = ds.data[run].matrix()
    Ysim = responses(result, ds)[run]
    want = set(CHANNELS) if channels is None else set(channels)
    rows = [(title, unit, [i for i in idx if CHANNELS[i] in want and not np.all(np.isnan(Y[:, i]))])
            for title, unit, idx in GROUPS]
    rows = [r for r in rows if r[2]]
    fig = _figure(9.0, 2.2 * max(len(rows), 1))
    axes = fig.subplots(max(len(rows), 1), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (title, unit, idx) in zip(axes, rows):
        for k, i in enumerate(idx):
            ax.plot(t, Y[:, i], lw=0.8, color=f"C{k}", label=CHANNELS[i])
            ax.plot(t, Ysim[:, i], lw=0.8, ls="--", color="k", alpha=0.7)
        ax.set_ylabel(f"{title}\n[{unit}]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right", ncol=len(idx))
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(f"run {run}: measured (colour) vs identified car (dashed)")
    return fig


def _relative(std, value) -> float:
    """``2 std / |value|`` in % (NaN without a std or a value)."""
    return math.nan if std is None or not value else 200.0 * abs(std / value)


def parameters_figure(result):
    """Each estimated parameter's relative standard error: ±2 ``std_robust`` (and ±2 ``std``) in % of its value.

    Known and derived parameters are listed with no bar. Returns a ``matplotlib.figure.Figure``.
    """
    names, white, robust, notes = [], [], [], []
    for n, d in result.details.items():
        if n.startswith("F_"):
            continue  # the curves: plot_dampers
        names.append(n)
        white.append(_relative(d.get("std"), d.get("value")))
        robust.append(_relative(d.get("std_robust"), d.get("value")))
        notes.append("known" if d.get("fixed") else ("derived" if d.get("derived") else ""))
    fig = _figure(7.0, 0.3 * len(names) + 1.2)
    ax = fig.subplots()
    y = np.arange(len(names))
    ax.barh(y + 0.2, np.nan_to_num(robust), height=0.4, color="C0", label="±2 std_robust")
    ax.barh(y - 0.2, np.nan_to_num(white), height=0.4, color="C1", alpha=0.7, label="±2 std (white residuals)")
    ax.set_yticks(y, [f"{n} ({note})" if note else n for n, note in zip(names, notes)])
    ax.invert_yaxis()
    ax.set_xlabel("relative standard error ×2 [% of the value]")
    ax.set_title("parameters: how well the data fix them")
    ax.grid(alpha=0.3, axis="x")
    ax.legend(fontsize=7, loc="lower right")
    return fig


#: colour of the budget's statistical part (the sensor noise): grey, which no other source gets
STATISTICAL_COLOUR = "0.55"
#: the other sources' first colours: tab10's without its grey; then :func:`budget_palette` adds tab20's,
#: tab20b's and tab20c's (no greys), each the farthest from those before it, then ``turbo`` past 54
BUDGET_COLOURS = tuple(f"C{i}" for i in (0, 1, 2, 3, 4, 5, 6, 8, 9))


def _lab(rgb) -> np.ndarray:
    """CIE L*a*b* (D65) of sRGB colours ``(..., 3)`` in 0-1: distances in it are differences as the eye sees them."""
    c = np.asarray(rgb, dtype=float)
    c = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = c @ np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]).T
    xyz = xyz / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


def budget_palette(n: int) -> list[tuple]:
    """``n`` RGB colours for the budget's sources other than the statistical part, as far apart as the eye sees
    (and from its grey) as the tab palettes allow: 30 sources at least 15 CIE76 units apart, 40 at least 12."""
    from matplotlib import colormaps, colors

    chosen = [colors.to_rgb(c) for c in BUDGET_COLOURS]
    pool = [tuple(c) for m in ("tab20", "tab20b", "tab20c") for c in colormaps[m].colors
            if np.ptp(c) > 0.05 and tuple(c) not in chosen]
    grey = colors.to_rgb(STATISTICAL_COLOUR)
    while len(chosen) < n and pool:  # the candidate farthest from every colour taken (and the grey) next
        taken = _lab(np.array(chosen + [grey]))
        gap = [np.min(np.linalg.norm(taken - _lab(c), axis=1)) for c in pool]
        chosen.append(pool.pop(int(np.argmax(gap))))
    if len(chosen) < n:  # more sources than 54: evenly along turbo
        chosen = [tuple(colormaps["turbo"](x)[:3]) for x in np.linspace(0.05, 0.95, n)]
    return chosen[:n]


def budget_colours(sources) -> dict:
    """Source name -> RGB colour: ``statistical`` grey, every other source a colour of its own
    (:func:`budget_palette`)."""
    from matplotlib import colors

    others = [s for s in sources if s != "statistical"]
    out = dict(zip(others, budget_palette(len(others))))
    if "statistical" in sources:
        out["statistical"] = colors.to_rgb(STATISTICAL_COLOUR)
    return out


def budget_figure(result):
    """Each estimate's uncertainty budget (SPEC §12): a horizontal bar of ±2 ``std_total`` in % of the value,
    cut into one segment per source in proportion to its share of the variance (``statistical`` =
    ``std_robust``, then each declared input), so the longest segment is what to improve first.

    Parameters without a budget (known, not identified) are left out. Returns a ``matplotlib.figure.Figure``.
    """
    rows = [(n, d) for n, d in result.details.items() if d.get("budget") and not d.get("fixed")
            and d.get("std_total") and d.get("value")]
    sources = []
    for _, d in rows:
        sources += [k for k in d["budget"] if k not in sources]
    # the legend beside the bars (one line per source), so that it hides none of them
    fig = _figure(9.5, max(0.3 * max(len(rows), 1) + 1.6, 0.2 * len(sources) + 0.8))
    ax = fig.subplots()
    y = np.arange(len(rows))
    left = np.zeros(len(rows))
    total = np.array([200.0 * d["std_total"] / abs(d["value"]) for _, d in rows])
    colour = budget_colours(sources)
    for src in sources:
        var = np.array([(d["budget"].get(src) or 0.0) ** 2 for _, d in rows])
        share = var / np.array([d["std_total"] ** 2 for _, d in rows])
        width = total * share
        ax.barh(y, width, left=left, height=0.6, color=colour[src], label=src)
        left += width
    for k, t in enumerate(total):
        ax.annotate(f"{t:.2g} %", (t, k), xytext=(3, 0), textcoords="offset points", va="center", fontsize=7)
    ax.set_yticks(y, [n for n, _ in rows])
    ax.invert_yaxis()
    ax.set_xlabel("±2 std_total [% of the value], each source's segment its share of the variance")
    note = (result.uncertainty or {}).get("notes") or []
    ax.set_title("uncertainty budget" + (" (total mass taken as exact)" if any("taken as exact" in n for n in note)
                                         else ""))
    ax.grid(alpha=0.3, axis="x")
    if rows:
        ax.set_xlim(0, 1.15 * max(total))
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    return fig


def dampers_figure(result):
    """The identified damper curves with ±2 ``std_robust`` bands (knots not excited marked ×).

    Raises
    ------
    ArgumentError
        The result has no damper curves.
    """
    d = result.dampers
    if not d:
        raise ArgumentError("the result has no damper curves (fit the damper_curves model to get them)")
    v = np.array(d["velocity"], dtype=float)
    j0 = int(np.searchsorted(v, 0.0))
    fig = _figure(7.0, 4.0)
    ax = fig.subplots()
    for k, axle in enumerate(("front", "rear")):
        F = np.array(d[axle]["force"], dtype=float)
        s = np.array([np.nan if x is None else x for x in d[axle].get("std_robust", [None] * v.size)], dtype=float)
        exc = np.array(d[axle].get("excited", [True] * v.size), dtype=bool)
        vv, FF, ss = np.insert(v, j0, 0.0), np.insert(F, j0, 0.0), np.insert(s, j0, 0.0)
        ax.plot(vv, FF, "-o", ms=3, color=f"C{k}", label=axle)
        ax.fill_between(vv, FF - 2 * np.nan_to_num(ss), FF + 2 * np.nan_to_num(ss), color=f"C{k}", alpha=0.2)
        if not exc.all():
            ax.plot(v[~exc], F[~exc], "x", color="k", ms=7)
        for side in ("compression", "rebound"):  # the knees found (rideid.estimate.problem.dampers.knees)
            vk = (((d.get("knees") or {}).get(axle) or {}).get(side) or {}).get("velocity")
            if vk is not None:
                ax.axvline(vk, color=f"C{k}", ls=":", lw=1.2)
    ax.axhline(0, color="0.5", lw=0.5)
    ax.axvline(0, color="0.5", lw=0.5)
    ax.set_xlabel("suspension velocity [m/s] (compression +)")
    ax.set_ylabel("damper force at the wheel [N]")
    ax.set_title("damper curves (±2 std_robust; × not excited; dotted: knees found)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


#: the frequency-response figure's coherence threshold: measured H1 points are drawn where it is exceeded
COHERENCE_MIN = 0.9
_CORNERS = ("fl", "fr", "rl", "rr")


def frequency_figure(result, dataset=None, measured=None, freq=None):
    """The identified car's frequency responses with ±2 std bands and the measured H1 points (SPEC §13).

    Row 1: body acceleration at each corner from its own wheel's road; row 2: the axle's; row 3: heave, pitch
    and roll from the wheels in phase, front against rear and left against right
    (:data:`rideid.estimate.assess.frequency.VIEWS`), and the coherence of the measured points. Measured H1 points
    (:func:`rideid.estimate.assess.frequency.measured_response`, ±2 std random error) only where their partial
    coherence exceeds :data:`COHERENCE_MIN`.

    Parameters
    ----------
    result : IdentificationResult
    dataset : Dataset, str or Path, optional
        The runs for the measured points (default: the dataset the result names; none when it is not found).
        ``False``: no measured points.
    measured : dict, optional
        A :func:`rideid.estimate.assess.frequency.measured_response` already computed (then ``dataset`` is not read).
    freq : array_like, optional
        The model's frequencies, Hz (default 0.2-30 Hz).

    Returns a ``matplotlib.figure.Figure``.
    """
    fr = frequency_response(result, freq)
    if measured is None and dataset is not False:
        try:
            measured = measured_response(result_dataset(result, dataset), result)
        except DataError:  # the dataset is not there (a result moved elsewhere): the model alone
            measured = None
    # a fixed layout and no minor ticks: twelve log-log panels laid out by constrained layout take seconds
    fig = NotebookFigure(figsize=(12.0, 8.2))
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.07, top=0.92, wspace=0.28, hspace=0.32)
    axes = fig.subplots(3, 4)
    f = fr.freq
    for row, kind in enumerate(("body", "axle")):
        for c, corner in enumerate(_CORNERS):
            ax = axes[row, c]
            out, inp = f"{kind}_az_{corner}", f"r_{corner}"
            H, sd = fr.response(out, inp)
            _band(ax, f, np.abs(H), sd, f"C{row}")
            if measured is not None:
                o, i = list(measured["outputs"]).index(out), list(measured["inputs"]).index(inp)
                _points(ax, measured, o, i)
            ax.set_title(f"{out} ← {inp}", fontsize=9)
            if c == 0:
                ax.set_ylabel(f"|H| [{fr.units[out]}]", fontsize=8)
    for c, (name, v) in enumerate(fr.views.items()):
        ax = axes[2, c]
        _band(ax, f, np.abs(v["H"]), v["std_abs"], "C2")
        ax.set_title(f"{name} ← {v['label']}", fontsize=9)
        ax.set_ylabel(f"|H| [{fr.units[v['output']]}]", fontsize=8)
    ax = axes[2, 3]
    if measured is not None:
        for row, kind in enumerate(("body", "axle")):
            for c, corner in enumerate(_CORNERS):
                o = list(measured["outputs"]).index(f"{kind}_az_{corner}")
                ax.plot(measured["freq"], measured["coherence"][:, o, c], lw=0.6, color=f"C{row}", alpha=0.6,
                        label=f"{kind} ← own wheel" if c == 0 else None)
        ax.axhline(COHERENCE_MIN, color="k", ls=":", lw=0.8)
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=7, loc="lower left")
    else:
        ax.text(0.5, 0.5, "no measured response\n(no run on a known road)", ha="center", va="center",
                transform=ax.transAxes, fontsize=8)
    ax.set_title("partial coherence of the measured H1", fontsize=9)
    ax.set_xscale("log")
    ticks = [t for t in (0.2, 0.5, 1, 2, 5, 10, 20, 50, 100) if f[0] <= t <= f[-1]]
    for a in axes.flat:
        a.set_xlim(f[0], f[-1])
        a.minorticks_off()
        a.set_xticks(ticks, [f"{t:g}" for t in ticks])
        a.grid(alpha=0.3, lw=0.4)
        a.tick_params(labelsize=7)
    for a in axes[2]:
        a.set_xlabel("frequency [Hz]", fontsize=8)
    rel = _max_relative(fr)
    fig.suptitle("frequency responses of the identified car: ±2 std band (from std_total)"
                 + (f", at most ±{2 * rel:.2g} % of these |H| over 0.5-25 Hz" if rel is not None else "")
                 + (f"; measured H1 points where coherence > {COHERENCE_MIN:g}" if measured is not None else ""),
                 fontsize=10)
    return fig


def _max_relative(fr):
    """The largest std of ``|H|`` in % of ``|H|`` over 0.5-25 Hz of the figure's curves, or None."""
    sel = (fr.freq >= 0.5) & (fr.freq <= 25)
    if not sel.any():
        return None
    vals = []
    for kind in ("body", "axle"):
        for corner in _CORNERS:
            H, sd = fr.response(f"{kind}_az_{corner}", f"r_{corner}")
            vals.append(np.max(sd[sel] / np.abs(H[sel])))
    vals += [np.max(v["std_abs"][sel] / np.abs(v["H"][sel])) for v in fr.views.values()]
    vals = np.asarray(vals, dtype=float)
    return 100.0 * float(np.max(vals[np.isfinite(vals)])) if np.isfinite(vals).any() else None  # no std: no band


def _band(ax, f, mag, sd, colour):
    ax.fill_between(f, np.clip(mag - 2 * sd, mag * 1e-3, None), mag + 2 * sd, color=colour, alpha=0.3, lw=0)
    ax.plot(f, mag, color=colour, lw=1.0)
    ax.set_xscale("log")
    ax.set_yscale("log")


def _points(ax, measured, o, i):
    """The measured H1 of output ``o`` from input ``i`` where its coherence exceeds :data:`COHERENCE_MIN`."""
    sel = (measured["coherence"][:, o, i] > COHERENCE_MIN) & np.isfinite(measured["H"][:, o, i])
    if not sel.any():
        return
    mag = np.abs(measured["H"][sel, o, i])
    err = 2 * np.nan_to_num(measured["std_abs"][sel, o, i])
    ax.errorbar(measured["freq"][sel], mag, yerr=[np.minimum(err, 0.9 * mag), err], fmt="o", ms=2.2, lw=0.5,
                color="k", alpha=0.7, label="measured H1")


__all__ = ["fit_figure", "parameters_figure", "dampers_figure", "frequency_figure", "responses", "result_dataset"]
