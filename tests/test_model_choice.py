"""--model auto (rideid.estimate.choice.model_choice): the criterion, then cars of our own in both directions."""

import json

import numpy as np
import pytest

import rideid
from rideid.cli import main
from rideid.estimate.choice.model_choice import criteria, fits_better, penalty, wald

BOTH = ("anti_roll_bars", "tire_damping")
CANDIDATES = [(), ("anti_roll_bars",), ("tire_damping",), BOTH]


def test_wald_and_criterion_closed_form():
    cov = np.diag([4.0, 9.0])
    assert wald([2.0, 3.0], cov) == pytest.approx(1 + 1)
    # correlated: theta^T C^-1 theta by hand
    C = np.array([[1.0, 0.5], [0.5, 1.0]])
    th = np.array([1.0, -1.0])
    assert wald(th, C) == pytest.approx(th @ np.linalg.inv(C) @ th)
    assert penalty() == pytest.approx(13.8155 / 2, rel=1e-4)  # chi2(2) 99.9 % point / 2
    names = ["k_sf", "k_arf", "k_arr", "c_tf", "c_tr"]
    free = {"anti_roll_bars": ["k_arf", "k_arr"], "tire_damping": ["c_tf", "c_tr"]}
    cov = np.diag([1.0, 1.0, 1.0, 1.0, 1.0])
    # bars clearly non-zero (W = 50), tire damping at noise level (W = 2)
    theta = np.array([3e4, 5.0, 5.0, 1.0, 1.0])
    crit = {tuple(c["extensions"]): c for c in criteria(names, theta, cov, CANDIDATES, free)}
    assert crit[()]["wald"] == pytest.approx(52.0)
    assert crit[("anti_roll_bars",)]["criterion"] == pytest.approx(2.0 + 2 * penalty())
    assert crit[BOTH]["criterion"] == pytest.approx(4 * penalty())
    assert min(crit.values(), key=lambda c: c["criterion"])["extensions"] == ["anti_roll_bars"]


def test_a_candidate_must_fit_better_than_every_candidate_it_contains():
    costs = {(): 1.0, ("anti_roll_bars",): 0.9, ("tire_damping",): 1.2, BOTH: 0.95}
    assert fits_better((), costs)  # contains nothing
    assert fits_better(("anti_roll_bars",), costs)
    assert not fits_better(("tire_damping",), costs)  # worse than base
    assert not fits_better(BOTH, costs)  # better than base and tire damping, not than bars alone
    # materially: (0.5 %)^2 of the relative squared error, whatever the level
    tiny = {(): 1.3e-24, ("anti_roll_bars",): 1.0e-24}
    assert not fits_better(("anti_roll_bars",), tiny)
    assert fits_better(("anti_roll_bars",), {(): 4e-4 + 2.6e-5, ("anti_roll_bars",): 4e-4})


def test_noise_free_data_of_a_twelve_parameter_car_keep_base(sim_dataset, tmp_path, capsys):
    """SPEC §6: on data from a twelve-parameter car --model auto keeps base; without noise every robust
    std is at rounding level, and only the fits-better rule keeps rounding-level bar rates out."""
    assert main(["identify", str(sim_dataset), "--out", str(tmp_path / "o"), "--seed", "1", "--quiet",
                 "--no-report", "--model", "auto"]) == 0
    model = json.loads((tmp_path / "o" / "result.json").read_text())["model"]
    assert model["extensions"] == []
    by = {tuple(c["extensions"]): c for c in model["candidates"]}
    assert by[()]["fits_better"] and not any(c["fits_better"] for c in model["candidates"][1:])
    assert "fits better" in capsys.readouterr().out


def test_unknown_model_value_is_one_line_exit_2(sim_dataset, tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["identify", str(sim_dataset), "--out", str(out), "--model", "bars"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--model must be one of base, full, auto, got 'bars'" in err[0]
    assert not out.exists()


# -- the criterion on the SUV: the full model polished from the truth, then C for each candidate ---------

def _full_polish_criteria(sc, data, folder, truth_ext):
    from cars import SUV_TRUTH
    from rideid.synth.scenario import write_dataset
    from rideid.estimate.fit.polish import _polish
    from rideid.model.batch import single_threaded_blas

    write_dataset(sc, data, folder)
    cf = rideid.CostFunction(rideid.load_dataset(folder), extensions=BOTH)
    vals = {**SUV_TRUTH, "k_arf": 0.0, "k_arr": 0.0, "c_tf": 0.0, "c_tr": 0.0, **truth_ext}
    x = np.array([vals[n] for n in cf.names])
    with single_threaded_blas():
        x, info, _ = _polish(cf, x, np.full(len(cf.run_ids), 1 / len(cf.run_ids)))
    free = {"anti_roll_bars": ["k_arf", "k_arr"], "tire_damping": ["c_tf", "c_tr"]}
    crit = criteria(cf.names, x, np.array(info["covariance_robust"]), CANDIDATES, free)
    return min(crit, key=lambda c: c["criterion"])["extensions"], {n: x[cf.names.index(n)] for n in cf.names}


@pytest.fixture(scope="module")
def suv(tmp_path_factory):
    from cars import suv_scenario
    return suv_scenario(tmp_path_factory.mktemp("suv"))


def test_criterion_keeps_base_on_a_base_car_with_coloured_noise(suv, tmp_path):
    from cars import add_noise, simulate_car

    chosen, _ = _full_polish_criteria(suv, add_noise(simulate_car(suv), 0.02, 0.9, seed=31), tmp_path / "b", {})
    assert chosen == []


def test_criterion_adds_both_groups_on_a_car_with_bars_and_tire_damping(suv, tmp_path):
    from cars import SUV_BARS, SUV_TIRE_DAMPING, add_noise, simulate_car

    ext = {**SUV_BARS, **SUV_TIRE_DAMPING}
    chosen, x = _full_polish_criteria(suv, add_noise(simulate_car(suv, ext), 0.02, 0.9, seed=32), tmp_path / "r", ext)
    assert chosen == list(BOTH)
    for n, v in ext.items():  # the extended model recovers them
        assert x[n] == pytest.approx(v, rel=0.05), n


# -- end to end (slow): rideid identify --model auto, search included ------------------------------------

@pytest.mark.slow  # four identifications, about 40 s on one core: CI's slow pass runs them
@pytest.mark.parametrize("groups", [(), ("anti_roll_bars",), ("tire_damping",), BOTH])
def test_identify_auto_picks_exactly_the_groups_the_car_has(groups, tmp_path, capsys):
    from cars import SUV_BARS, SUV_TIRE_DAMPING, add_noise, simulate_car, suv_scenario
    from rideid.synth.scenario import write_dataset

    sc = suv_scenario(tmp_path)
    ext = {**(SUV_BARS if "anti_roll_bars" in groups else {}), **(SUV_TIRE_DAMPING if "tire_damping" in groups else {})}
    write_dataset(sc, add_noise(simulate_car(sc, ext), 0.02, 0.9, seed=len(groups) + 40), tmp_path / "ds")
    out = tmp_path / "fit"
    # no [model] table in the dataset: auto is the default
    assert main(["identify", str(tmp_path / "ds"), "--out", str(out), "--seed", "1", "--quiet"]) == 0
    res = json.loads((out / "result.json").read_text())
    assert res["model"]["extensions"] == list(groups)
    cands = {tuple(c["extensions"]) for c in res["model"]["candidates"]}
    assert cands == set(CANDIDATES)  # the linear choice is adequate: curves and stops are not tried
    assert res["model"]["curves"].startswith("not tried")
    assert res["adequacy"]["adequate"]
    printed = capsys.readouterr().out
    assert "--model auto kept" in printed and "MODEL NOT ADEQUATE" not in printed
    html = (out / "report.html").read_text()
    assert 'id="model"' in html and 'class="verdict-ok"' in html
    for n, v in ext.items():
        assert res["parameters"][n]["value"] == pytest.approx(v, rel=0.05), n


@pytest.mark.slow  # 33-57 s: CI's slow pass (make test stays under 10 minutes on 2 cores)
def test_base_model_on_a_real_car_says_not_adequate_in_terminal_and_report(tmp_path, capsys):
    from cars import SUV_BARS, SUV_TIRE_DAMPING, add_noise, simulate_car, suv_scenario
    from rideid.synth.scenario import write_dataset

    sc = suv_scenario(tmp_path)
    write_dataset(sc, add_noise(simulate_car(sc, {**SUV_BARS, **SUV_TIRE_DAMPING}), 0.02, 0.0, seed=50),
                  tmp_path / "ds")
    out = tmp_path / "fit"
    assert main(["identify", str(tmp_path / "ds"), "--out", str(out), "--seed", "1", "--quiet",
                 "--model", "base"]) == 0
    printed = capsys.readouterr().out
    assert "MODEL NOT ADEQUATE" in printed and "--model auto" in printed
    html = (out / "report.html").read_text()
    first = html[:html.index('id="estimates"')]
    assert 'class="verdict-bad"' in first and "--model auto" in first
    assert json.loads((out / "result.json").read_text())["adequacy"]["adequate"] is False


def test_curve_departure_wald_closed_form():
    """Linear dampers F = c v depart by nothing; a bend by (R F)^T (R C R^T)^+ (R F), one dof per free knot
    less one slope per axle."""
    from rideid.estimate.problem.cost import ParameterSpace
    from rideid.estimate.choice.model_choice import curve_departure
    from rideid.model.params import Geometry

    sp = ParameterSpace({"total_mass": 1093.3}, Geometry(2.579, 1.387, 1.364, 0.30), extensions=["damper_curves"])
    v = sp.knot_velocities()
    names = ["k_sf"] + [f"F_f{j}" for j in range(1, 11)] + [f"F_r{j}" for j in range(1, 11)]
    cov = np.diag([1.0] + [4.0] * 20)
    F = np.concatenate([1800 * v[:10], 1650 * v[10:]])
    W, df = curve_departure(names, np.concatenate([[3e4], F]), cov, sp)
    assert W == pytest.approx(0.0, abs=1e-9) and df == 18
    bent = F.copy()
    bent[9] -= 20.0  # the front curve's last knot 20 N below the line (std 2 N)
    W, _ = curve_departure(names, np.concatenate([[3e4], bent]), cov, sp)
    R = np.eye(10) - np.outer(v[:10], v[:10]) / (v[:10] @ v[:10])
    d = R @ bent[:10]
    assert W == pytest.approx(d @ np.linalg.pinv(4.0 * R @ R.T) @ d, rel=1e-9) and W > 50
    # a frozen (not free) knot is not counted
    W2, df2 = curve_departure([n for n in names if n != "F_r10"], np.concatenate([[3e4], bent[:-1]]),
                              np.diag([1.0] + [4.0] * 19), sp)
    assert df2 == 17


def _auto(ds, out):
    assert main(["identify", str(ds), "--out", str(out), "--model", "auto", "--seed", "1", "--quiet",
                 "--no-report"]) == 0
    return json.loads((out / "result.json").read_text())


def test_auto_keeps_linear_dampers_of_a_linear_car(tmp_path):
    """SPEC §8: a car with linear dampers keeps them: the linear choice is adequate, so there is nothing
    for curves to explain and they are not tried (about 10 s)."""
    from test_damper_curves import simulate

    ds, _ = simulate(tmp_path)
    res = _auto(ds, tmp_path / "fit")
    model = res["model"]
    assert "damper_curves" not in model["extensions"] and "dampers" not in res
    assert res["adequacy"]["adequate"] is True
    assert model["curves"].startswith("not tried: the linear model is adequate")
    assert not [c for c in model["candidates"] if "damper_curves" in c["extensions"]]


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_auto_picks_curves_for_digressive_asymmetric_dampers(tmp_path):
    """A car with 2:1 asymmetric digressive dampers gets curves, and the curve model is adequate; the
    tire damping the linear model wanted to make up for them is dropped once the curves are in (about 14 s:
    the knots' excitation and the bump stops' reach read the compiled kernel's states)."""
    from test_damper_curves import VEL, digressive, simulate

    ds, truth = simulate(tmp_path, {"velocity": VEL, "front": digressive(1200, 400), "rear": digressive(1100, 370)})
    res = _auto(ds, tmp_path / "fit")
    model = res["model"]
    assert model["extensions"] == ["damper_curves"]
    assert res["adequacy"]["adequate"] is True
    kept = next(c for c in model["candidates"] if c["extensions"] == ["damper_curves"])
    assert kept["fits_better"] and kept["adequate"] is True
    # every other candidate that fits better has a higher criterion (the linear ones pay the curves' departure W);
    # the curves with tire damping do not fit better (cost 9.7932e-05 against 9.7936e-05), so are not kept;
    # measured on the loop over extensions: the rivals on tire damping cost 0.0946 (powertrain), 9.79e-5 (curves),
    # 0.0914 (stops, none reached), the curves kept and tire damping dropped with them (criterion 272.9 against 283.9)
    assert all(c["criterion"] > kept["criterion"] for c in model["candidates"] if c is not kept and c["fits_better"])
    # the curve found (on the knee grid) at the truth's knots
    F = np.interp(VEL, res["dampers"]["velocity"], res["dampers"]["front"]["force"])
    F_true = np.array(truth["dampers"]["front"])
    assert np.all(np.abs(F - F_true) <= 0.03 * np.abs(F_true))


def test_the_tracks_as_drawn_caveat_says_when_the_weighing_cannot_clear_a_drawing():
    """An adequate verdict that rests on the weighing (structure found, immaterial) while the tracks stayed as
    drawn carries a caveat when the structure spans two or more runs (a drawing error is common to every run);
    not when it is local to one run, not when the as-built fit was accepted, not without structure."""
    from dataclasses import dataclass, field

    from rideid.estimate.choice import model_choice

    @dataclass
    class Res:
        adequacy: dict
        tracks: dict = field(default_factory=dict)

    def ad(pairs, adequate=True, structure=True):
        return {"adequate": adequate, "structure": structure, "materiality": {"pairs_left_out": pairs}}

    two = ["T_HH/axle_az_fl", "H_HH/body_az_fl", "H_HH/axle_az_rr"]
    rejected = {"twist": {"rejected": "the tracks as built needed more than a track carries"}}
    out = model_choice._drawing_caveat(None, Res(ad(two), rejected), (), "as-built")
    assert "tracks_caveat" in out.adequacy and "as-built fit was rejected" in out.adequacy["tracks_caveat"]
    assert out.adequacy["adequate"]                               # the verdict stands, with its statement
    for res in (Res(ad(["T_HH/axle_az_fl", "T_HH/axle_az_fr"]), rejected),   # one run: the weighing judges it
                Res(ad(two), {"twist": {"amplitude_factor": 1.04}}),        # fitted as built
                Res(ad(two, adequate=False), rejected),                      # not adequate: said already
                Res(ad(two, structure=False), rejected)):                    # no structure found
        assert "tracks_caveat" not in model_choice._drawing_caveat(None, res, (), "as-built").adequacy


def test_a_rival_on_estimated_starts_is_polished_from_the_starts_its_parent_settled(tmp_path):
    """A candidate of the model choice on runs whose starts are estimated (logger files) is polished from its
    parent's settled starts, not from the starts found at load: its starts barely move (the load's move 1.7
    samples), it takes fewer evaluations (2 against 4), and they land where a polish from the load's starts puts
    them. Measured on the damper van's logger files when the starts' moves were modelled round by round
    (``python benchmarks/bench_realtest.py --cases van-logger``): 121 -> 63 s of CPU, rounds of start
    re-estimation 48 -> 35, estimates moved at most 4e-5 std; with exact starts each polish is one round."""
    from logger_case import suv_scenario, write_logger

    from rideid.estimate.choice.model_choice import _Choice, _space, start_row
    from rideid.estimate.fit.identify import identify as identify_model
    from rideid.estimate.problem.cost import CostFunction

    sc = suv_scenario(tmp_path, fs=100.0)
    ds = rideid.load_dataset(write_logger(sc, tmp_path / "logger", noise=0.01, seed=1))
    parent_key, key = ("anti_roll_bars", "tire_damping"), ("anti_roll_bars",)
    parent = identify_model(ds, cost=CostFunction(ds, space=_space(ds, parent_key)), seed=1, population=20,
                            generations=30)
    rival = _Choice(ds, None, dict(seed=1)).fit(parent, key)
    space = _space(ds, key, parent)
    cold = identify_model(ds, cost=CostFunction(ds, space=space), start=start_row(ds, parent, space), seed=1,
                          assess=False)
    (warm,), (first,) = rival.polish["alignment_rounds"], cold.polish["alignment_rounds"]
    assert warm["max_change_samples"] < 1e-3 and first["max_change_samples"] > 1.0
    assert rival.polish["nfev"] < cold.polish["nfev"]
    for rid, st in rival.starts.items():
        assert abs(st["value"] - cold.starts[rid]["value"]) < 0.05 / 100.0
    for n, d in rival.details.items():
        if not d.get("fixed") and d.get("std"):
            assert abs(rival.parameters[n] - cold.parameters[n]) < 0.1 * d["std"], n
