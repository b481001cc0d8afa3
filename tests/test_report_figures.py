"""The report's figures draw what they claim: cheap drawing paths give the picture a full draw gives."""

import numpy as np

from rideid.estimate.problem.sensitivity import P2R_STARS, stars
from rideid.report.sensitivity_files import star_marks
from rideid.report import html as H


def _run(n=801, fs=200.0, seed=0, amp=1.0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    Y = amp * np.sin(2 * np.pi * 1.3 * t[:, None] + rng.uniform(0, 6, 10)) * np.exp(-t[:, None] / 3)
    Y[:, 8:] *= 0.05
    Ysim = Y + 0.01 * amp * rng.standard_normal(Y.shape)
    return t, Y, Ysim


def test_fit_figure_partial_redraw_equals_a_full_draw(tmp_path):
    """Per run only the time-domain axes and the spectrum lines are drawn over pixels kept from
    the first draw: the PNG must match a complete draw of the same figure."""
    H.fig_fit("other", *_run(601, seed=5, amp=9.0), tmp_path)  # a template already drawn for other limits
    runs = [_run(801, seed=0), _run(1501, seed=1, amp=4.0)]
    lim = H.spectra_limits(runs)
    for k, (t, Y, Ysim) in enumerate(runs):
        H.fig_fit(f"r{k}", t, Y, Ysim, tmp_path, lim)
        fig = H._FIT_TEMPLATES[tuple(range(10))][0]
        partial = np.asarray(fig.canvas.buffer_rgba()).copy()
        fig.canvas.draw()  # everything, legends' kept pixels included
        full = np.asarray(fig.canvas.buffer_rgba())
        differ = np.any(partial != full, axis=2)
        assert differ.sum() == 0, (k, differ.sum())
    # the second run's traces are 4x larger: its axes were rescaled, not left at the first run's limits
    ax = H._FIT_TEMPLATES[tuple(range(10))][1][0, 0]
    assert ax.get_ylim()[1] > 3.0


def test_spectra_limits_hold_every_curve():
    runs = [_run(801, seed=0), _run(1501, seed=1, amp=4.0), _run(601, seed=2, amp=0.1)]
    (f0, f1), ylims = H.spectra_limits(runs)
    assert f0 < 0 and f1 > 100.0  # 0..fs/2 with a margin
    for t, Y, Ysim in runs:
        f, res, top = H._fit_spectra(t, Y, Ysim, tuple(range(10)))
        for row, (_, _, idx) in enumerate(H.GROUPS):
            lo, hi = ylims[row]
            for c in [top[row]] + [res[i] for i in idx]:
                assert lo < c.min() and c.max() < hi


def test_heatmap_star_marks_count_the_ratings():
    """One star mark per star of ``stars()``, a dash where it gives none, each in its own cell."""
    rng = np.random.default_rng(3)
    data = rng.uniform(0, 20, (5, 4))
    data[0, 0] = np.nan
    xs, ys, dx, dy, rating = star_marks(data, 1.0, P2R_STARS)
    for i in range(5):
        for j in range(4):
            n = stars(data[i, j], P2R_STARS).count("★")
            assert rating[i, j] == n
            in_cell = (np.abs(xs - j) < 0.5) & (ys == i)
            assert in_cell.sum() == n
            assert (((dx == j) & (dy == i)).sum() == 1) == (n == 0)
    assert rating[0, 0] == 0


def test_figures_leave_the_backend_and_the_global_style_alone(tmp_path):
    """A notebook user's backend and rcParams survive a report figure and a plan figure; pyplot is not used."""
    import subprocess
    import sys
    code = f"""
import sys
import matplotlib
matplotlib.use("svg")
before = dict(matplotlib.rcParams)
import numpy as np
from pathlib import Path
from rideid.report import html as H
from rideid.report.plan_files import precision_path_figure
hist = [{{"generation": g, "best_cost": 10.0 ** -g, "mean_cost": 10.0 ** (1 - g), "mu_f": 0.5, "mu_cr": 0.5}}
        for g in range(5)]
fig = H.fig_convergence(hist, Path({str(tmp_path)!r}))
assert Path({str(tmp_path)!r}, "figures", "convergence.png").stat().st_size > 1000
assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
changed = [k for k, v in matplotlib.rcParams.items() if before[k] != v]
assert not changed, changed
assert "matplotlib.pyplot" not in sys.modules
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


def test_the_summarys_data_line_names_what_the_quality_table_holds():
    """The summary's Data row: a flat-lined or clipped channel, whose per-run warning the data-quality table stands
    for, is named there ("no other warning"), not hidden behind "no warning on the data"; without one the row reads
    as before."""
    from types import SimpleNamespace

    from rideid.report.html import _data_line
    quality = {"channels": {
        "roll_rate": {"runs": 5, "clipped_share": 0.0, "clipped_runs": {}, "gaps": 0, "noise": 1e-4,
                      "unit": "rad/s", "flat_lined": ["WB7"], "filters": []},
        "body_az_fl": {"runs": 5, "clipped_share": 0.0, "clipped_runs": {}, "gaps": 0, "noise": 0.01,
                       "unit": "m/s^2", "flat_lined": [], "filters": []}}}
    res = SimpleNamespace(roads={}, data_quality=quality)
    ctx = {"n_runs": 5, "data_warnings": []}
    label, text, _ = _data_line(res, ctx)
    assert label == "Data"
    assert "no other warning on the data" in text and "flat-lined in some run: roll_rate" in text
    assert "body_az_fl" not in text
    clean = {"channels": {"body_az_fl": quality["channels"]["body_az_fl"]}}
    assert _data_line(SimpleNamespace(roads={}, data_quality=clean), ctx)[1] == "5 runs; no warning on the data"
