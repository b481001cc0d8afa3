"""Identification of bump stops (SPEC §8, group bump_stops)."""

import contextlib
import io
import json
import shutil

import numpy as np
import pytest
import tomli_w

from rideid.cli import main
from rideid.data.schema import read_toml
from rideid.estimate.problem.bumps import spring_share
from rideid.estimate.problem.cost import BUMP_BOUNDS, ParameterSpace
from rideid.estimate.result import load
from rideid.model.params import Geometry
from test_damper_curves import VEL, digressive
from test_damper_curves import simulate as simulate_car

BS = ("bs_clear_f", "bs_clear_r", "bs_rate_f", "bs_rate_r")


def simulate(tmp, clear, rate=5e4, dampers=None, noise=0.01):
    """The built-in car with bump stops at ``clear`` (m) and ``rate`` (N/m) on both axles, 1 % noise."""
    return simulate_car(tmp, dampers, noise, truth=dict(bs_clear_f=clear, bs_clear_r=clear, bs_rate_f=rate,
                                                        bs_rate_r=rate))


def identify(ds, out, model="bump_stops", capsys=None):
    assert main(["identify", str(ds), "--out", str(out), "--model", model, "--seed", "1", "--no-report"]) == 0
    text = capsys.readouterr().out if capsys is not None else ""
    return json.loads((out / "result.json").read_text()), text


def check_stops(res, truth):
    for ax in ("f", "r"):
        c, r = res["parameters"][f"bs_clear_{ax}"], res["parameters"][f"bs_rate_{ax}"]
        tc, tr = truth["truth"][f"bs_clear_{ax}"], truth["truth"][f"bs_rate_{ax}"]
        assert c["reached"] and r["reached"]
        assert abs(c["value"] - tc) <= 1e-3 and abs(c["value"] - tc) <= 3 * c["std_robust"], (ax, c, tc)
        assert abs(r["value"] - tr) <= 0.1 * tr and abs(r["value"] - tr) <= 3 * r["std_robust"], (ax, r, tr)


@pytest.fixture(scope="module")
def stops_fit(tmp_path_factory):
    """Stops at 25 mm, 50 kN/m: the twist runs compress the suspension 30-65 mm (front 40-310 samples beyond the
    clearance per run, rear 90-280)."""
    tmp = tmp_path_factory.mktemp("stops25")
    ds, truth = simulate(tmp, 0.025)
    buf = io.StringIO()  # capsys is function-scoped: the terminal output through a redirect
    with contextlib.redirect_stdout(buf):
        res, _ = identify(ds, tmp / "fit")
    return truth, res, tmp / "fit", buf.getvalue(), ds


def test_bump_stops_are_recovered(stops_fit):
    truth, res, _, text, _ = stops_fit
    assert res["model"]["extensions"] == ["bump_stops"]
    check_stops(res, truth)
    for n, v in truth["truth"].items():
        if n not in BS:
            assert res["parameters"][n]["value"] == pytest.approx(v, rel=0.01), n
    bs = res["bump_stops"]
    for axle in ("front", "rear"):
        assert bs[axle]["reached"] and bs[axle]["samples_beyond_clearance"] >= 20
        assert all(s is not None and s > 0 for s in bs[axle]["std_robust"])
    assert res["parameters"]["bs_clear_f"]["unit"] == "m" and res["parameters"]["bs_rate_f"]["unit"] == "N/m"
    assert "bump stops" in text and "clearance 25.0" in text and "not reached" not in text


def test_result_round_trip_keeps_the_stops(stops_fit):
    _, res, out, _, _ = stops_fit
    back = load(out)
    assert back.bump_stops == res["bump_stops"]
    assert back.to_dict()["bump_stops"] == res["bump_stops"]
    assert all(back.details[n]["reached"] for n in BS)
    assert "bump stops" in repr(back) and "bs_clear_f=" in repr(back)


def test_known_clearance_is_held(stops_fit, tmp_path):
    """A clearance from the drawing in [known]: held, the rate fitted."""
    _, _, _, _, ds = stops_fit
    d = tmp_path / "ds"
    shutil.copytree(ds, d)
    doc = read_toml(d / "dataset.toml")
    doc.setdefault("known", {})["bs_clear_f"] = 0.025
    doc["known"]["bs_clear_r"] = 0.025
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    res, _ = identify(d, tmp_path / "fit")
    for ax in "fr":
        c, r = res["parameters"][f"bs_clear_{ax}"], res["parameters"][f"bs_rate_{ax}"]
        assert c["fixed"] and c["value"] == 0.025 and c["reached"]
        assert r["value"] == pytest.approx(5e4, rel=0.1) and abs(r["value"] - 5e4) <= 3 * r["std_robust"]
    assert "bs_clear_f" not in res["names"] and "bs_rate_f" in res["names"]
    assert res["bump_stops"]["front"]["known"] == [True, False]


def test_stops_never_reached(tmp_path, capsys):
    """Stops at 300 mm: no run reaches them. Not reached, held (no std), the other parameters unbiased."""
    ds, truth = simulate(tmp_path, 0.3)
    res, text = identify(ds, tmp_path / "fit", capsys=capsys)
    for n in BS:
        e = res["parameters"][n]
        assert e["reached"] is False and e["std"] is None and e["std_robust"] is None and e["note"] == "not reached"
        assert n not in res["names"]
    for axle in ("front", "rear"):
        b = res["bump_stops"][axle]
        assert not b["reached"] and b["std_robust"] == [None, None] and b["rate"] == 0.0
        assert b["clearance"] > b["max_compression"]
    for n, v in truth["truth"].items():
        if n not in BS:
            e = res["parameters"][n]
            assert e["value"] == pytest.approx(v, rel=0.01), n
            assert abs(e["value"] - v) <= 3 * e["std_robust"], n
    assert "NOT REACHED" in text and "not reached — not a number to trust" in text
    back = load(tmp_path / "fit")
    assert back.bump_stops == res["bump_stops"] and "not reached" in repr(back)


def test_bump_stops_with_damper_curves(tmp_path):
    """Digressive asymmetric dampers and stops at 30 mm: both groups identified together."""
    dampers = {"velocity": VEL, "front": digressive(1200, 400), "rear": digressive(1100, 370)}
    ds, truth = simulate(tmp_path, 0.03, dampers=dampers)
    # the curves at their own knots (a user's damper_knots win: no knee grid, the stops are what is tested)
    doc = read_toml(ds / "dataset.toml")
    doc["model"] = {"damper_knots": [v for v in VEL if v > 0]}
    (ds / "dataset.toml").write_text(tomli_w.dumps(doc))
    res, _ = identify(ds, tmp_path / "fit", model="damper_curves,bump_stops")
    assert res["model"]["extensions"] == ["damper_curves", "bump_stops"]
    check_stops(res, truth)
    for n, v in truth["truth"].items():
        if n not in BS and n not in ("c_sf", "c_sr"):
            assert res["parameters"][n]["value"] == pytest.approx(v, rel=0.01), n
    assert res["dampers"]["knots_from"] == "[model] damper_knots"
    for axle in ("front", "rear"):
        F, F_true = np.array(res["dampers"][axle]["force"]), np.array(truth["dampers"][axle])
        assert np.all(np.abs(F - F_true) <= 0.03 * np.abs(F_true)), axle


def test_space_bounds_and_spring_share():
    geom = Geometry(2.579, 1.387, 1.364, 0.30)
    sp = ParameterSpace({"total_mass": 1093.3}, geom, extensions=["bump_stops"])
    assert sp.width == 20 and sp.names[-4:] == list(BS)
    assert [tuple(b) for b in sp.bounds[-4:]] == [BUMP_BOUNDS[n] for n in BS] == \
        [(0.01, 0.15), (0.01, 0.15), (0.0, 5e5), (0.0, 5e5)]
    sp2 = ParameterSpace({"total_mass": 1093.3, "bs_rate_r": 4e4}, geom, bounds={"bs_clear_f": [0.02, 0.05]},
                         extensions=["bump_stops"])
    assert "bs_rate_r" not in sp2.names and tuple(sp2.bounds[sp2.names.index("bs_clear_f")]) == (0.02, 0.05)
    held = sp.with_bump_frozen({"bs_clear_r": 0.09, "bs_rate_r": 0.0})
    assert held.names[-2:] == ["bs_clear_f", "bs_rate_f"]
    P = held.full(np.array([held.nominal()[held.col[n]] for n in held.names])[None])[0]
    assert P[held.col["bs_clear_r"]] == 0.09 and P[held.col["bs_rate_r"]] == 0.0
    d = np.array([0.01, 0.02, 0.03])
    assert spring_share(d, 0.02) == pytest.approx(0.01 * 0.03 / np.sum(d * d))


@pytest.mark.parametrize("section, key, value, msg", [
    ("bounds", "bs_clear_f", [0.0, 0.1], "[bounds] bs_clear_f: lower bound must be positive, got 0.0"),
    ("bounds", "bs_rate_r", [-1.0, 1e5], "[bounds] bs_rate_r: lower bound must not be negative, got -1.0"),
    ("bounds", "bs_clear_r", [0.1, 0.05], "[bounds] bs_clear_r: lower bound 0.1 must be less than upper bound"),
    ("bounds", "bs_clear", [0.01, 0.05], "[bounds] bs_clear: unknown parameter"),
    ("known", "bs_clear_f", 0.0, "[known] bs_clear_f: must be positive, got 0.0"),
    ("known", "bs_rate_f", -5.0, "[known] bs_rate_f: must not be negative (0 means none), got -5.0"),
    ("known", "bs_rate", 5.0, "[known]: unknown key 'bs_rate'"),
])
def test_bad_bump_stop_bounds_and_known(section, key, value, msg, sim_dataset, tmp_path, capsys):
    d = tmp_path / "ds"
    shutil.copytree(sim_dataset, d)
    doc = read_toml(d / "dataset.toml")
    doc.setdefault(section, {})[key] = value
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    out = tmp_path / "fit"
    assert main(["identify", str(d), "--out", str(out), "--quiet", "--model", "bump_stops"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err, err
    assert not out.exists()


def test_bounds_and_known_of_one_stop_conflict(sim_dataset, tmp_path, capsys):
    d = tmp_path / "ds"
    shutil.copytree(sim_dataset, d)
    doc = read_toml(d / "dataset.toml")
    doc.setdefault("known", {})["bs_clear_f"] = 0.03
    doc.setdefault("bounds", {})["bs_clear_f"] = [0.01, 0.05]
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    assert main(["identify", str(d), "--out", str(tmp_path / "fit"), "--quiet", "--model", "bump_stops"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "[bounds] bs_clear_f: parameter is known (fixed) in [known]" in err
