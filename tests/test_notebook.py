"""The notebook side of the API: docs/notebook.ipynb runs top to bottom; tables, figures and reprs.

Figures are ``matplotlib.figure.Figure`` objects built without pyplot: the
caller's backend is never changed.
"""

import json
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

import rideid

NOTEBOOK = Path(__file__).resolve().parents[1] / "docs" / "notebook.ipynb"


def code_cells(path):
    nb = json.loads(Path(path).read_text())
    assert nb["nbformat"] == 4
    return ["".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code"]


def test_the_notebook_runs_top_to_bottom():
    backend = matplotlib.get_backend()
    pyplot_before = "matplotlib.pyplot" in sys.modules
    ns = {"__name__": "__notebook__"}
    cells = code_cells(NOTEBOOK)
    assert len(cells) >= 6
    try:
        for k, src in enumerate(cells):
            exec(compile(src, f"{NOTEBOOK.name}[cell {k}]", "exec"), ns)
        _check_notebook(ns, backend, pyplot_before)
    finally:
        if "work" in ns:
            shutil.rmtree(ns["work"], ignore_errors=True)  # the notebook's scratch folder


def _check_notebook(ns, backend, pyplot_before):
    assert matplotlib.get_backend() == backend
    if not pyplot_before:
        assert "matplotlib.pyplot" not in sys.modules
    work = ns["work"]
    for name in ("car.toml", "car.csv", "frf.csv", "car.fmu"):
        assert (work / "car" / name).is_file(), name
    assert ns["fr"].H.shape == (240, 13, 4)
    table = ns["table"]
    assert list(table.columns[:7]) == ["value", "unit", "std_total", "std", "std_robust", "fixed", "derived"]
    assert isinstance(ns["fig"], Figure)
    # 1 % noise: the identified car is the built-in one within its error bars
    truth = rideid.default_scenario().truth
    for n in rideid.NAMES:
        row = table.loc[n]
        if not row["fixed"] and not row["derived"]:
            assert abs(row["value"] - truth[n]) <= 4 * row["std_robust"], n


@pytest.fixture(scope="module")
def fitted(sim_dataset):
    ds = rideid.load_dataset(sim_dataset)
    return ds, rideid.identify(ds, seed=1, population=16, generations=10, model="base")


def test_to_frame(fitted, tmp_path):
    ds, res = fitted
    df = res.to_frame()
    assert df.index.name == "parameter" and list(df.index) == list(res.details)
    assert list(df.columns) == ["value", "unit", "std_total", "std", "std_robust", "fixed", "derived"]
    for n, d in res.details.items():
        assert df.loc[n, "value"] == d["value"] and df.loc[n, "unit"] == d["unit"]
        assert bool(df.loc[n, "fixed"]) == bool(d.get("fixed")) and bool(df.loc[n, "derived"]) == bool(d.get("derived"))
    assert df.loc["m_s", "derived"] and np.isfinite(df.loc["k_sf", "std_robust"])
    res.save(tmp_path / "fit")
    back = rideid.load_result(tmp_path / "fit")
    assert back.to_frame().equals(df)
    assert back.vehicle == res.vehicle and back.vehicle["wheelbase"] == ds.geometry.wheelbase


def test_figures_are_figures_and_leave_the_backend_alone(fitted, tmp_path):
    ds, res = fitted
    backend = matplotlib.get_backend()
    fig = rideid.plot_fit(res, "W_L", dataset=ds)
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    body = fig.axes[0]
    # measured and identified car for each of the four body channels
    assert len(body.lines) == 8
    y_meas = ds.data["W_L"].matrix()[:, 0]
    assert np.array_equal(body.lines[0].get_ydata(), y_meas)
    assert np.allclose(body.lines[1].get_ydata(), y_meas, atol=1e-3 * np.abs(y_meas).max())
    only = rideid.plot_fit(res, "W_L", dataset=ds, channels=["pitch_rate"])
    assert len(only.axes) == 1 and len(only.axes[0].lines) == 2
    # a result read back finds its dataset itself and simulates the car again
    res.save(tmp_path / "fit")
    again = rideid.plot_fit(rideid.load_result(tmp_path / "fit"), "W_L")
    assert np.allclose(again.axes[0].lines[1].get_ydata(), body.lines[1].get_ydata(), rtol=0, atol=1e-9)
    par = rideid.plot_parameters(res)
    assert isinstance(par, Figure) and len(par.axes[0].patches) == 2 * len(res.details)
    with pytest.raises(rideid.ArgumentError, match="no damper curves"):
        rideid.plot_dampers(res)
    with pytest.raises(rideid.ArgumentError, match="its runs: T_LL"):
        rideid.plot_fit(res, "nope", dataset=ds)
    # a notebook without pyplot or %matplotlib shows the value of a cell through _repr_png_: a PNG of the figure
    png = fig._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert (width, height) == tuple(round(100 * v) for v in fig.get_size_inches())
    assert matplotlib.get_backend() == backend


def test_reprs_fit_on_a_screen(fitted):
    ds, res = fitted
    for text in (repr(ds), repr(res)):
        lines = text.splitlines()
        assert len(lines) <= 20 and max(len(ln) for ln in lines) <= 100, text
    curves = {"velocity": [-0.4, -0.2, -0.1, -0.05, -0.025, 0.025, 0.05, 0.1, 0.2, 0.4],
              "front": {"force": [0.0] * 10, "excited": [True] * 10}, "rear": {"force": [0.0] * 10}}
    details = dict(res.details, **{f"F_f{k}": {"value": 0.0, "unit": "N"} for k in range(1, 11)})
    text = repr(replace(res, dampers=curves, details=details))
    assert "damper curves: 10 knots per axle up to 0.4 m/s" in text and "F_f1=" not in text
    assert len(text.splitlines()) <= 20


def test_plot_fit_of_a_logger_result_straight_from_identify(tmp_path):
    """A logger dataset whose starts identify() refines: the run's samples are fixed at the first estimate of
    its start, and a dataset read again at the final start chose them anew (one sample more: plot_fit raised
    "x and y must have same first dimension (1200,) vs (1199,)"). The result's records now read the runs as the
    identification read them: plot_fit draws the fitted samples with the response identify() kept, and a
    result read back draws the same samples and the same car."""
    sys.path.insert(0, str(Path(__file__).parent))
    from logger_case import suv_scenario, write_logger
    sc = suv_scenario(tmp_path / "sc", fs=100.0)
    sc = replace(sc, runs=[r for r in sc.runs if r.id == "TW5"])
    write_logger(sc, tmp_path / "log", noise=0.02, seed=1)
    ds = rideid.load_dataset(tmp_path / "log")
    res = rideid.identify(ds, seed=1, population=10, generations=4, model="base", assess=False)
    fig = rideid.plot_fit(res, "TW5")
    n = res.response["TW5"].shape[0]
    assert res.preprocessing["TW5"]["samples"] == n
    body = fig.axes[0].lines
    assert body[0].get_xdata().size == n
    assert np.array_equal(body[1].get_ydata(), res.response["TW5"][:, 0])
    # the samples' model times at the final start, as result.json records them
    start = res.starts["TW5"]["value"]
    first, last = res.preprocessing["TW5"]["model_time"]
    assert body[0].get_xdata()[0] == pytest.approx(first, abs=1e-9)
    assert body[0].get_xdata()[-1] == pytest.approx(last, abs=1e-9)
    assert abs(start - 2.0) < 5e-3  # LEAD: a start estimated, not given
    res.save(tmp_path / "fit")
    again = rideid.plot_fit(rideid.load_result(tmp_path / "fit"), "TW5")
    for a, b in zip(again.axes[0].lines, body):
        assert np.array_equal(a.get_xdata(), b.get_xdata())
        assert np.allclose(a.get_ydata(), b.get_ydata(), rtol=0, atol=1e-9 * np.abs(b.get_ydata()).max())
    # a dataset read at the final start alone (its samples chosen anew): the car simulated on it, no crash
    other = rideid.load_dataset(tmp_path / "log", starts=res.start_values())
    m = other.data["TW5"].time.size
    assert m != n
    assert rideid.plot_fit(res, "TW5", dataset=other).axes[0].lines[1].get_ydata().size == m
