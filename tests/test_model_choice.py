"""--model auto (rideid.estimate.model_choice): the criterion, then cars of our own in both directions."""

import json

import numpy as np
import pytest

import rideid
from rideid.cli import main
from rideid.estimate.model_choice import PENALTY, criteria, wald

BOTH = ("anti_roll_bars", "tire_damping")
CANDIDATES = [(), ("anti_roll_bars",), ("tire_damping",), BOTH]


def test_wald_and_criterion_closed_form():
    cov = np.diag([4.0, 9.0])
    assert wald([2.0, 3.0], cov) == pytest.approx(1 + 1)
    # correlated: theta^T C^-1 theta by hand
    C = np.array([[1.0, 0.5], [0.5, 1.0]])
    th = np.array([1.0, -1.0])
    assert wald(th, C) == pytest.approx(th @ np.linalg.inv(C) @ th)
    assert PENALTY == pytest.approx(13.8155 / 2, rel=1e-4)  # chi2(2) 99.9 % point / 2
    names = ["k_sf", "k_arf", "k_arr", "c_tf", "c_tr"]
    free = {"anti_roll_bars": ["k_arf", "k_arr"], "tire_damping": ["c_tf", "c_tr"]}
    cov = np.diag([1.0, 1.0, 1.0, 1.0, 1.0])
    # bars clearly non-zero (W = 50), tire damping at noise level (W = 2)
    theta = np.array([3e4, 5.0, 5.0, 1.0, 1.0])
    crit = {tuple(c["extensions"]): c for c in criteria(names, theta, cov, CANDIDATES, free)}
    assert crit[()]["wald"] == pytest.approx(52.0)
    assert crit[("anti_roll_bars",)]["criterion"] == pytest.approx(2.0 + 2 * PENALTY)
    assert crit[BOTH]["criterion"] == pytest.approx(4 * PENALTY)
    assert min(crit.values(), key=lambda c: c["criterion"])["extensions"] == ["anti_roll_bars"]


def test_unknown_model_value_is_one_line_exit_2(sim_dataset, tmp_path, capsys):
    out = tmp_path / "fit"
    assert main(["identify", str(sim_dataset), "--out", str(out), "--model", "bars"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--model must be one of base, full, auto, got 'bars'" in err[0]
    assert not out.exists()


# -- the criterion on the SUV: the full model polished from the truth, then C for each candidate ---------

def _full_polish_criteria(sc, data, folder, truth_ext):
    from cars import SUV_TRUTH
    from rideid.data.scenario import write_dataset
    from rideid.estimate.identify import _polish
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

@pytest.mark.slow
@pytest.mark.expensive
@pytest.mark.parametrize("groups", [(), ("anti_roll_bars",), ("tire_damping",), BOTH])
def test_identify_auto_picks_exactly_the_groups_the_car_has(groups, tmp_path, capsys):
    from cars import SUV_BARS, SUV_TIRE_DAMPING, add_noise, simulate_car, suv_scenario
    from rideid.data.scenario import write_dataset

    sc = suv_scenario(tmp_path)
    ext = {**(SUV_BARS if "anti_roll_bars" in groups else {}), **(SUV_TIRE_DAMPING if "tire_damping" in groups else {})}
    write_dataset(sc, add_noise(simulate_car(sc, ext), 0.02, 0.9, seed=len(groups) + 40), tmp_path / "ds")
    out = tmp_path / "fit"
    # no [model] table in the dataset: auto is the default
    assert main(["identify", str(tmp_path / "ds"), "--out", str(out), "--seed", "1", "--quiet"]) == 0
    res = json.loads((out / "result.json").read_text())
    assert res["model"]["extensions"] == list(groups)
    assert {tuple(c["extensions"]) for c in res["model"]["candidates"]} == set(CANDIDATES)
    assert res["adequacy"]["adequate"]
    printed = capsys.readouterr().out
    assert "--model auto kept" in printed and "MODEL NOT ADEQUATE" not in printed
    html = (out / "report.html").read_text()
    assert 'id="model"' in html and 'class="verdict-ok"' in html
    for n, v in ext.items():
        assert res["parameters"][n]["value"] == pytest.approx(v, rel=0.05), n


@pytest.mark.slow
@pytest.mark.expensive
def test_base_model_on_a_real_car_says_not_adequate_in_terminal_and_report(tmp_path, capsys):
    from cars import SUV_BARS, SUV_TIRE_DAMPING, add_noise, simulate_car, suv_scenario
    from rideid.data.scenario import write_dataset

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
