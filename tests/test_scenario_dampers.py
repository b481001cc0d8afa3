"""SPEC §8 in scenario and dataset files: [dampers], bump-stop truths, [vehicle] cg_height, [model] damper_knots."""

import math

import pytest
import tomli_w

import rideid
from rideid.data.schema import DamperCurves, parse_scenario, read_toml
from rideid.errors import DataError

#: asymmetric (2:1 rebound:compression) digressive dampers, knee at 0.15 m/s
DAMPERS = {"velocity": [-0.6, -0.15, -0.05, 0.05, 0.15, 0.6],
           "front": [-2600.0, -1800.0, -600.0, 300.0, 900.0, 1300.0],
           "rear": [-2400.0, -1650.0, -550.0, 275.0, 825.0, 1200.0]}


def _doc(runs=("T_LL",)):
    doc = read_toml(rideid.default_scenario_path())
    doc["runs"] = [r for r in doc["runs"] if r["id"] in runs]
    return doc


def test_a_scenario_with_dampers_bump_stops_and_cg_height_parses():
    doc = _doc()
    doc["dampers"] = DAMPERS
    doc["truth"].update(bs_clear_f=0.06, bs_rate_f=5e4, bs_clear_r=0.07, bs_rate_r=4e4)
    doc["vehicle"]["cg_height"] = 0.25
    del doc["truth"]["c_sf"]
    sc = parse_scenario(doc, "sc.toml")
    assert sc.dampers == DamperCurves(**DAMPERS) and sc.nonlinear
    assert sc.geometry.cg_height == 0.25
    assert sc.bump_stops == {"bs_clear_f": 0.06, "bs_rate_f": 5e4, "bs_clear_r": 0.07, "bs_rate_r": 4e4}
    assert sc.bump_stop_pairs == ((0.06, 0.07), (5e4, 4e4))
    # c_sf left out: the front curve's mean slope between -0.1 and +0.1 m/s; c_sr as given (not used)
    assert sc.truth["c_sf"] == pytest.approx((600.0 + 1200.0) / 0.2)
    assert sc.truth["c_sr"] == doc["truth"]["c_sr"]
    # one axle only; velocity 0 with force 0 is the origin, dropped
    doc = _doc()
    doc["truth"].update(bs_clear_r=0.05, bs_rate_r=0.0)
    doc["dampers"] = {"velocity": [-0.2, 0.0, 0.2], "front": [-400, 0, 200], "rear": [-400, 0.0, 200]}
    sc = parse_scenario(doc, "sc.toml")
    assert sc.dampers.velocity == (-0.2, 0.2) and sc.bump_stop_pairs == ((math.inf, 0.05), (0.0, 0.0))
    assert not parse_scenario(_doc(), "sc.toml").nonlinear


def _bad_dampers(**kw):
    return lambda d: d.update(dampers={**DAMPERS, **kw})


BAD_SCENARIOS = {
    "knots_not_increasing": (_bad_dampers(velocity=[-0.6, -0.15, -0.05, 0.05, 0.05, 0.6]),
                             "[dampers] velocity must be strictly increasing (index 4: 0.05 <= 0.05)"),
    "one_sided": (_bad_dampers(velocity=[0.05, 0.1, 0.15, 0.2, 0.3, 0.6]),
                  "[dampers] velocity must reach both rebound and compression"),
    "not_monotone": (_bad_dampers(front=[-2600.0, -1800.0, -600.0, 300.0, 900.0, 820.0]),
                     "[dampers] front must increase with velocity (index 5: 820 < 900)"),
    "pushes_along": (_bad_dampers(rear=[-2400.0, -1650.0, 50.0, 275.0, 825.0, 1200.0]),
                     "[dampers] rear[2] = 50 N at velocity -0.05 m/s: a damper force has the sign of the velocity"),
    "lengths_differ": (_bad_dampers(rear=[-2400.0, -550.0, 275.0, 1200.0]),
                       "[dampers] rear has 4 forces but velocity has 6 values"),
    "missing_curve": (lambda d: d.update(dampers={"velocity": [-0.1, 0.1], "front": [-1, 1]}),
                      "[dampers]: missing key 'rear'"),
    "force_at_rest": (_bad_dampers(velocity=[-0.6, -0.15, 0.0, 0.05, 0.15, 0.6]),
                      "[dampers] front[2] = -600 N at velocity 0: a damper carries no force at rest"),
    "not_a_number": (_bad_dampers(front=[-2600.0, -1800.0, "x", 300.0, 900.0, 1300.0]),
                     "[dampers] front[2]: expected a finite number, got 'x'"),
    "cg_height_negative": (lambda d: d["vehicle"].update(cg_height=-0.1),
                           "[vehicle] cg_height: the CG height above the wheel centres must not be negative"),
    "bump_clearance_negative": (lambda d: d["truth"].update(bs_clear_f=-0.02, bs_rate_f=5e4),
                                "[truth] bs_clear_f: the clearance must be positive"),
    "bump_rate_negative": (lambda d: d["truth"].update(bs_clear_r=0.05, bs_rate_r=-1.0),
                           "[truth] bs_rate_r: the rate must not be negative"),
    "bump_half": (lambda d: d["truth"].update(bs_clear_f=0.05),
                  "[truth]: bs_clear_f is given without bs_rate_f"),
    "cg_twice": (lambda d: (d["vehicle"].update(cg_height=0.2), d.update(hifi={"cg_height": 0.3})),
                 "the CG height is given twice and differs: [vehicle] cg_height = 0.2 m, [hifi] cg_height = 0.3 m"),
    "dampers_twice": (lambda d: (d.update(dampers=DAMPERS), d.update(hifi={"damper_rebound_ratio": 2.0})),
                      "the dampers are given twice"),
    "bump_twice": (lambda d: (d["truth"].update(bs_clear_f=0.05, bs_rate_f=1e4),
                              d.update(hifi={"bumpstop_clearance": 0.05, "bumpstop_rate": 1e4})),
                   "the bump stops are given twice"),
    "knots_bad": (lambda d: d.update(model={"damper_knots": [0.05, 0.03]}),
                  "[model] damper_knots must be strictly increasing (index 1: 0.03 <= 0.05)"),
}


@pytest.mark.parametrize("case", list(BAD_SCENARIOS))
def test_bad_scenarios_end_with_one_line_and_write_nothing(case, tmp_path, capsys):
    from rideid.cli import main
    fn, msg = BAD_SCENARIOS[case]
    doc = _doc()
    fn(doc)
    (tmp_path / "scenario.toml").write_text(tomli_w.dumps(doc))
    rc = main(["simulate", str(tmp_path / "scenario.toml"), "--out", str(tmp_path / "ds"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith(f"rideid: error: {tmp_path / 'scenario.toml'}")  # names the file ...
    assert msg in err  # ... and the key
    assert not (tmp_path / "ds").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["scenario.toml"]


def test_dataset_model_table_takes_the_nonlinear_groups_and_knots(sim_dataset, tmp_path):
    import shutil
    d = tmp_path / "ds"
    shutil.copytree(sim_dataset, d)
    doc = read_toml(d / "dataset.toml")
    doc["model"] = {"extensions": ["bump_stops", "damper_curves", "tire_damping"], "damper_knots": [0.03, 0.08, 0.3]}
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    man = rideid.data.schema.load_manifest(d)
    assert man.extensions == ("tire_damping", "damper_curves", "bump_stops")
    assert man.damper_knots == (0.03, 0.08, 0.3)
    assert man.to_dataset_doc()["model"] == {"extensions": ["tire_damping", "damper_curves", "bump_stops"],
                                             "damper_knots": [0.03, 0.08, 0.3]}
    # knots alone do not choose the model
    doc["model"] = {"damper_knots": [0.05]}
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    man = rideid.data.schema.load_manifest(d)
    assert man.extensions is None and man.damper_knots == (0.05,)


@pytest.mark.parametrize("knots, msg", [
    ([0.0, 0.1], "dataset.toml: [model] damper_knots[0] = 0: knots are positive velocities"),
    ([-0.1, 0.1], "dataset.toml: [model] damper_knots[0] = -0.1: knots are positive velocities"),
    ([0.1, 0.05], "dataset.toml: [model] damper_knots must be strictly increasing (index 1: 0.05 <= 0.1)"),
    ("fast", "dataset.toml: [model] damper_knots: expected a list of numbers"),
])
def test_bad_damper_knots_in_a_dataset(knots, msg, sim_dataset, tmp_path, capsys):
    import shutil

    from rideid.cli import main
    d = tmp_path / "ds"
    shutil.copytree(sim_dataset, d)
    doc = read_toml(d / "dataset.toml")
    doc["model"] = {"damper_knots": knots}
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    assert main(["identify", str(d), "--out", str(tmp_path / "fit"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err
    assert not (tmp_path / "fit").exists()


def test_dataset_model_with_bump_stops_is_identified(sim_dataset, tmp_path):
    """[model] extensions = ["bump_stops"] gives the cost function the stops' four parameters (identified:
    tests/test_bump_stops.py)."""
    import shutil

    d = tmp_path / "ds"
    shutil.copytree(sim_dataset, d)
    doc = read_toml(d / "dataset.toml")
    doc["model"] = {"extensions": ["bump_stops"]}
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    cf = rideid.CostFunction(rideid.load_dataset(d))
    assert cf.names[-4:] == ["bs_clear_f", "bs_clear_r", "bs_rate_f", "bs_rate_r"]
    assert cf.space.layout.bump_stops and cf.space.layout.knots is None


def test_truth_toml_keeps_dampers_and_bump_stops(tmp_path):
    """What simulate writes as truth.toml reads back; load_truth validates its [dampers] too."""
    from rideid.data.schema import load_truth, load_truth_dampers
    doc = {"truth": {**_doc()["truth"], "bs_clear_f": 0.05, "bs_rate_f": 3e4}, "dampers": DAMPERS}
    (tmp_path / "truth.toml").write_text(tomli_w.dumps(doc))
    tr = load_truth(tmp_path / "truth.toml")
    assert tr["bs_clear_f"] == 0.05 and load_truth_dampers(tmp_path / "truth.toml") == DamperCurves(**DAMPERS)
    doc["dampers"] = {**DAMPERS, "rear": DAMPERS["rear"][:3]}
    (tmp_path / "truth.toml").write_text(tomli_w.dumps(doc))
    with pytest.raises(DataError, match=r"truth.toml: \[dampers\] rear has 3 forces"):
        load_truth(tmp_path / "truth.toml")
