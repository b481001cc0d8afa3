"""Identification of damper curves (SPEC §8, group damper_curves)."""

import json

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.errors import ArgumentError
from rideid.cli import main
from rideid.data.schema import read_toml
from rideid.estimate.problem.cost import ParameterSpace
from rideid.estimate.problem.dampers import KNEE_GRID, knot_counts
from rideid.estimate.result import load
from rideid.model.nonlinear import DEFAULT_KNOTS, damper_force
from rideid.model.params import Geometry

POS = (0.025, 0.05, 0.1, 0.2, 0.4)
VEL = [-k for k in reversed(POS)] + list(POS)


def digressive(c1, c2, knee=0.1, rebound=2.0):
    """Forces at the default knots: slope c1 up to the knee, c2 beyond; rebound ``rebound`` times stiffer."""
    pos = [c1 * min(v, knee) + c2 * max(v - knee, 0.0) for v in POS]
    return [-rebound * f for f in reversed(pos)] + pos


def simulate(tmp, dampers=None, noise=0.01, truth=None):
    """The built-in car (``truth`` updates its [truth]) with ``dampers`` as its [dampers], simulated with
    ``noise`` (seed 3): the dataset folder and its truth.toml."""
    doc = read_toml(rideid.default_scenario_path())
    doc["truth"].update(truth or {})
    if dampers is not None:
        doc["dampers"] = dampers
        del doc["truth"]["c_sf"], doc["truth"]["c_sr"]
    sc = tmp / "sc.toml"
    sc.write_text(tomli_w.dumps(doc))
    out = tmp / "ds"
    assert main(["simulate", str(sc), "--out", str(out), "--noise", str(noise), "--seed", "3", "--quiet"]) == 0
    return out, read_toml(out / "truth.toml")


def identify_curves(ds, out):
    assert main(["identify", str(ds), "--out", str(out), "--model", "damper_curves", "--seed", "1",
                 "--quiet", "--no-report"]) == 0
    return json.loads((out / "result.json").read_text())


@pytest.fixture(scope="module")
def digressive_fit(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("digressive")
    dampers = {"velocity": VEL, "front": digressive(1200, 400), "rear": digressive(1100, 370)}
    ds, truth = simulate(tmp, dampers)
    return truth, identify_curves(ds, tmp / "fit"), tmp / "fit"


def test_digressive_asymmetric_curves_are_recovered(digressive_fit):
    truth, res, _ = digressive_fit
    dm = res["dampers"]
    # no [model] damper_knots: the knee grid, which holds every default knot (so this curve exactly)
    assert dm["velocity"] == pytest.approx([-k for k in reversed(KNEE_GRID)] + list(KNEE_GRID))
    assert dm["knots_from"].startswith("found")
    assert res["model"]["extensions"] == ["damper_curves"]
    for axle in ("front", "rear"):
        F_true = damper_force(DEFAULT_KNOTS, truth["dampers"][axle], np.array(dm["velocity"]))
        # the true knee, 0.1 m/s on both sides, found within 4 std_robust (and 2 mm/s)
        for side, sign in (("compression", 1), ("rebound", -1)):
            k = dm["knees"][axle][side]
            assert abs(k["velocity"] - sign * 0.1) <= max(4 * k["std_robust"], 0.002), (axle, side, k)
        got = dm[axle]
        assert all(got["excited"])  # the built-in runs reach 0.4 m/s on both sides
        F, s = np.array(got["force"]), np.array(got["std_robust"])
        assert np.all(np.abs(F - F_true) <= 0.03 * np.abs(F_true)), (axle, F, F_true)
        assert np.all(np.abs(F - F_true) <= 3 * s), (axle, (F - F_true) / s)
    for n, v in truth["truth"].items():
        if n in ("c_sf", "c_sr"):
            continue
        assert res["parameters"][n]["value"] == pytest.approx(v, rel=0.01), n
    # derived c_sf, c_sr: the true curve's mean slope over +-0.1 m/s, with the delta method's error bar
    for n, axle in (("c_sf", "front"), ("c_sr", "rear")):
        F_true = truth["dampers"][axle]
        slope = (damper_force(DEFAULT_KNOTS, F_true, 0.1) - damper_force(DEFAULT_KNOTS, F_true, -0.1)) / 0.2
        e = res["parameters"][n]
        assert e["derived"] and e["value"] == pytest.approx(slope, rel=0.01)
        assert e["std_robust"] > 0 and abs(e["value"] - slope) <= 3 * e["std_robust"]
        assert e["value"] == pytest.approx(truth["truth"][n], rel=0.01)  # what simulate wrote as truth


def test_result_json_round_trip_keeps_the_curves(digressive_fit):
    _, res, out = digressive_fit
    back = load(out)
    assert back.dampers == res["dampers"]
    assert back.to_dict()["dampers"] == res["dampers"]
    text = repr(back)
    assert "damper curves" in text and "F_f1=" not in text


def test_linear_dampers_fitted_with_curves_give_F_equal_c_v(tmp_path):
    ds, truth = simulate(tmp_path)
    res = identify_curves(ds, tmp_path / "fit")
    for axle, c in (("front", truth["truth"]["c_sf"]), ("rear", truth["truth"]["c_sr"])):
        got = res["dampers"][axle]
        for v, F, exc in zip(res["dampers"]["velocity"], got["force"], got["excited"]):
            if exc:
                assert F == pytest.approx(c * v, rel=0.03), (axle, v)


def test_knot_forces_are_made_physical():
    geom = Geometry(2.579, 1.387, 1.364, 0.30)
    sp = ParameterSpace({"total_mass": 1093.3}, geom, extensions=["damper_curves"])
    assert sp.width == 16 + 20 and "c_sf" not in sp.names and sp.names[-1] == "F_r10"
    assert np.all(sp.bounds[-10:-5] < 0) and np.all(sp.bounds[-5:] > 0)
    x = np.array([sp.nominal()[sp.col[n]] for n in sp.names])
    # monotone already: unchanged
    P = sp.full(x[None])[0]
    assert np.allclose([P[sp.col[n]] for n in sp.names], x)
    # a compression force below the knot before it, a rebound one pushing along the motion: repaired
    y = x.copy()
    i7, i3 = sp.names.index("F_f7"), sp.names.index("F_f3")
    y[i7] = 0.5 * x[sp.names.index("F_f6")]
    y[i3] = 10.0
    Q = sp.full(y[None])[0]
    F = Q[sp.col["F_f1"]:sp.col["F_f10"] + 1]
    assert np.all(np.diff(F) >= 0) and np.all(F[:5] < 0) and np.all(F[5:] > 0)
    # knots not excited continue the last excited segment's slope; c_sf is the mean slope over +-0.1
    fr = sp.with_frozen(["F_f1", "F_f9", "F_f10"])
    assert "F_f9" not in fr.names and fr.derived_names() == ["m_s", "F_f1", "F_f9", "F_f10", "c_sf", "c_sr"]
    z = sp.reduce(x, fr)
    z[fr.names.index("F_f8")] *= 1.5  # 0.1 m/s: the last excited compression knot
    R = fr.full(z[None])[0]
    f = lambda n: R[fr.col[n]]  # noqa: E731
    slope = (f("F_f8") - f("F_f7")) / 0.05
    assert f("F_f9") == pytest.approx(f("F_f8") + slope * 0.1) and f("F_f10") == pytest.approx(f("F_f9") + slope * 0.2)
    assert f("F_f1") == pytest.approx(2 * f("F_f2"))
    assert R[fr.col["c_sf"]] == pytest.approx((f("F_f8") - f("F_f3")) / 0.2)
    # the derived quantities' gradients are exact (linear)
    J = fr.derived_jacobian(z)
    assert J.shape == (6, len(fr.names))
    assert J[-2, fr.names.index("F_f8")] == pytest.approx(5.0) and J[-2, fr.names.index("F_f3")] == pytest.approx(-5.0)
    assert J[2, fr.names.index("F_f8")] == pytest.approx(3.0) and J[2, fr.names.index("F_f7")] == pytest.approx(-2.0)


def test_knot_counts_and_bad_model_names(sim_dataset, tmp_path, capsys):
    c = knot_counts(DEFAULT_KNOTS, np.array([-0.3, -0.15, -0.01, 0.01, 0.03, 0.06, 0.5]))
    # knot -0.4: beyond -0.2 (1 sample); -0.2: beyond -0.1 (2); ... 0.025: beyond 0 (4); 0.4: beyond 0.2 (1)
    assert c.tolist() == [1, 2, 2, 2, 3, 4, 3, 2, 1, 1]
    out = tmp_path / "fit"
    assert main(["identify", str(sim_dataset), "--out", str(out), "--quiet", "--model", "damper_curve"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--model must be one of base, full, auto, got 'damper_curve'" in err
    assert not out.exists()
    from rideid.estimate.problem.build import parse_model_arg
    assert parse_model_arg("damper_curves+bump_stops") == ("damper_curves", "bump_stops")
    with pytest.raises(ArgumentError, match="c_sf"):
        ParameterSpace({"total_mass": 1093.3, "c_sf": 1800.0}, Geometry(2.579, 1.387, 1.364, 0.30),
                       extensions=["damper_curves"])


def test_report_draws_the_curves_and_the_velocities_reached(digressive_fit):
    """The report of a curve result has the "Damper curves" section: both figures, and per run a histogram
    holding every sample of both corners of each axle (a linear result has none: tests/test_report.py)."""
    import rideid as _r
    from rideid.estimate.assess import responses as R
    from rideid.report import html as H

    _, res, out = digressive_fit
    assert main(["report", str(out)]) == 0
    html = (out / "report.html").read_text()
    assert 'id="dampers"' in html and "<h2>Damper curves</h2>" in html
    assert html.count("data:image/png;base64,") == 18 + 2  # the linear report's, then the two curve figures
    for f in ("damper_curves", "damper_velocities"):
        assert (out / "figures" / f"{f}.png").stat().st_size > 5000
    result = load(out)
    ds = _r.load_dataset(result.dataset, starts=result.start_values())
    vels = R.result_suspension_velocities(result, ds)
    edges, hists = H.velocity_histograms(vels)
    assert list(hists) == [r.id for r in ds.runs]
    for r in ds.runs:
        n = len(ds.data[r.id].time)
        assert [int(c.sum()) for c in hists[r.id]] == [2 * n, 2 * n], r.id
    # reached: the built-in runs' suspension velocities pass the outermost knots on both sides
    assert edges[0] < -0.4 and edges[-1] > 0.4
    # the rebuilt report's fits are the curves' car (a linear car with the derived c_s misses by 50 %)
    sims = R.curve_responses(result, ds)
    for r in ds.runs:
        assert max(H.fit_statistics(ds.data[r.id].matrix(), sims[r.id]).values()) < 0.05, r.id


def test_damper_figure_marks_knots_not_excited():
    from rideid.report import html as H

    F = digressive(1200, 400)
    dm = {"velocity": VEL}
    for axle in ("front", "rear"):
        dm[axle] = {"force": F, "std_robust": [5.0] * 8 + [None, None], "excited": [True] * 8 + [False, False]}
    fig = H.damper_curves_figure(dm, {"front": 1800.0, "rear": None})
    labels = [[t.get_text() for t in ax.get_legend().get_texts()] for ax in fig.axes]
    assert all(H.NOT_EXCITED_LABEL in lab and "± 2 std_robust" in lab for lab in labels)
    assert any(t.startswith("derived c_sf") for t in labels[0]) and not any("c_sr" in t for t in labels[1])
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_knot_forces_carry_std_total_and_the_weighbridge_scales_them(digressive_fit, tmp_path):
    """SPEC §12 on the curves: with nothing declared each knot force's std_total is its std_robust (and the
    terminal's table says ± 2 std_total); with a weighbridge of 1 % declared, every force scales with the
    anchor (SPEC §1), so its std_total is hypot(std_robust, 0.01 F) exactly."""
    from dataclasses import replace
    from rideid.estimate.fit.budget import with_budget
    from rideid.estimate.problem.dampers import format_dampers
    _, doc, out = digressive_fit
    for axle in ("front", "rear"):
        assert doc["dampers"][axle]["std_total"] == doc["dampers"][axle]["std_robust"]
    assert "± 2 std_total" in format_dampers(doc["dampers"])
    res = load(out)
    folder = tmp_path / "ds"
    folder.mkdir()
    src = res.dataset if hasattr(res, "dataset") else doc["dataset"]
    from pathlib import Path
    man = read_toml(Path(src) / "dataset.toml")
    m = man["known"]["total_mass"]
    man["known"]["total_mass"] = {"value": m, "std": 0.01 * m}
    for f in Path(src).rglob("*.csv"):
        (folder / f.relative_to(src)).parent.mkdir(parents=True, exist_ok=True)
        (folder / f.relative_to(src)).write_bytes(f.read_bytes())
    (folder / "dataset.toml").write_text(tomli_w.dumps(man))
    ds = rideid.load_dataset(folder)
    got = with_budget(ds, replace(res, polish=None)).dampers  # the anchor's closed form (no refit needed)
    for axle in ("front", "rear"):
        F, s, t = (np.array(got[axle][k], dtype=float) for k in ("force", "std_robust", "std_total"))
        assert np.allclose(t, np.hypot(s, 0.01 * np.abs(F)), rtol=1e-9), axle
        assert np.all(t > s)
