"""The error bars' shape check (rideid.estimate.assess.shape): the cost out at ±2 error bars along each parameter's
profile line against the quadratic its curvature at the minimum draws."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

import rideid
from rideid.estimate.assess.shape import caveat, check, profile_ratios, record, table_note
from rideid.estimate.records import ShapeAssessment, assessments_from_json

#: a two-parameter cost with a known shape: ``Q (x0 + x1 / 2)^2 + g(x1)``; ``g(t) = W^2 (1 - exp(-t^2 / W^2))``
#: is ``t^2`` near 0 and flat beyond ``W`` (a valley), or ``t^2`` itself (a quadratic)
Q, W = 100.0, 1.0


def _cost(flat: bool):
    def g(t):
        return W ** 2 * (1 - np.exp(-t ** 2 / W ** 2)) if flat else t ** 2

    def cost(X):
        X = np.atleast_2d(X)
        return Q * (X[:, 0] + X[:, 1] / 2) ** 2 + g(X[:, 1])
    return cost


#: the half Hessian at 0 (both costs): [[Q, Q/2], [Q/2, Q/4 + 1]]; its inverse is the curvature's covariance
H = np.array([[Q, Q / 2], [Q / 2, Q / 4 + 1]])
C = np.linalg.inv(H)
BOUNDS = (np.full(2, -50.0), np.full(2, 50.0))


def test_a_flat_valleys_error_bar_is_named_and_a_quadratic_ones_is_not():
    """Along x1's profile line (x0 = -x1 / 2) the cost is g(x1): the quadratic's rise at 2 error bars of 1.5 W is
    9 W^2, the valley's W^2 (1 - e^-9): a ratio of 0.111, named; x0's line moves x1 by C10 / C00 = -1.92 per unit,
    0.19 at its 2 error bars of 0.05, where g is still 0.97 of its quadratic. The quadratic cost: every ratio 1.
    The curvature from C (``exact``: the inverse half Hessian here) and measured from small steps agree."""
    sigma = np.array([0.05, 1.5 * W])
    flat = profile_ratios(_cost(True), np.zeros(2), C, sigma, BOUNDS, a=2.0, small=np.full(2, 1e-3))
    given = profile_ratios(_cost(True), np.zeros(2), C, sigma, BOUNDS, a=2.0, exact=True)
    expected = (1 - np.exp(-9.0)) / 9.0
    np.testing.assert_allclose(flat[1], [expected, expected], rtol=1e-5)
    np.testing.assert_allclose(given[1], [expected, expected], rtol=1e-12)
    b = 2 * sigma[0]
    t = b * C[1, 0] / C[0, 0]  # x1 at x0's 2 error bars: the rise falls short of the quadratic's by t^2 - g(t)
    np.testing.assert_allclose(given[0], [1 - (t * t - W ** 2 * (1 - np.exp(-t * t / W ** 2))) * C[0, 0] / b ** 2] * 2,
                               rtol=1e-9)
    assert 0.95 < given[0][0] < 1.0
    quad = profile_ratios(_cost(False), np.zeros(2), C, sigma, BOUNDS, a=2.0, small=np.full(2, 1e-3))
    np.testing.assert_allclose(quad, np.ones((2, 2)), rtol=1e-6)
    rec = record(["x0", "x1"], flat)
    assert rec["optimistic"] == ["x1"] and rec["error_bars"] == 2.0 and rec["flat_ratio"] == 0.25
    assert record(["x0", "x1"], quad)["optimistic"] == []
    # a wider threshold, from the registry, names x1 only down to its ratio
    with rideid.settings.using({"shape.flat_ratio": 0.1}):
        assert record(["x0", "x1"], flat)["optimistic"] == []


def test_an_optimistic_error_bars_reach_is_the_last_point_below_its_quadratics_rise():
    """The valley with a floor that rises again, ``g(t) = W^2 (1 - exp(-t^2 / W^2)) + 0.05 t^2``: x1's quadratic
    rise at 2 error bars of 1.5 is 4 x 1.05 x 2.25 = 9.45; the walk (3, 4, 6, 8, 12, ... error bars) is below it at
    8 (1 + 0.05 x 144 = 8.2) and above at 12 (17.2): the data allow x1 out to at least ±12, said in the record and
    its sentence. Without the floor the cost never gets there inside ±32 error bars: None on both sides."""
    def cost(X, eps):
        X = np.atleast_2d(X)
        return Q * (X[:, 0] + X[:, 1] / 2) ** 2 + W ** 2 * (1 - np.exp(-X[:, 1] ** 2 / W ** 2)) + eps * X[:, 1] ** 2
    Cf = np.linalg.inv(np.array([[Q, Q / 2], [Q / 2, Q / 4 + 1.05]]))
    rec = check(lambda X: cost(X, 0.05), np.zeros(2), Cf, np.array([0.05, 1.5]), BOUNDS, ["x0", "x1"],
                small=np.full(2, 1e-3))
    assert rec["optimistic"] == ["x1"]
    r = rec["reach"]["x1"]
    assert r["walked"] == [True, True] and (r["value"], r["lower"], r["upper"]) == pytest.approx((0, -12, 12))
    assert caveat(rec).endswith("along it the cost is still below the rise the error bar assumes at ±2 at x1 = -12 "
                                "and 12 (the estimate 0)")
    flat = check(lambda X: cost(X, 0.0), np.zeros(2), C, np.array([0.05, 1.5]), BOUNDS, ["x0", "x1"],
                 small=np.full(2, 1e-3))
    assert flat["reach"]["x1"] == {"value": 0.0, "lower": None, "upper": None, "walked": [True, True]}
    assert caveat(flat).endswith("at x1 = every point walked below it and every point walked above it (the estimate 0)")
    # a bound at 10 ends the plus side's walk below the rise: not reached there
    near = check(lambda X: cost(X, 0.05), np.zeros(2), Cf, np.array([0.05, 1.5]),
                 (np.full(2, -50.0), np.array([50.0, 10.0])), ["x0", "x1"], small=np.full(2, 1e-3))
    assert near["reach"]["x1"]["lower"] == pytest.approx(-12.0) and near["reach"]["x1"]["upper"] is None


def test_a_parameter_on_its_bound_is_held_on_the_others_lines():
    """A third parameter x2 on its lower bound 0 (tire damping at 0), tied to x1 by ``Q2 (x2 + 0.3 x1)^2``: x1's
    unconditioned line moves x2 below 0, so it would leave the box and nothing would be judged. With x2 held there
    (its ±2 error bars cross the bound), x1's line is the one of the cost with x2 fixed: its quadratic rises
    ``(1 + 0.09 Q2) t^2`` and the valley ``g(t) + 0.09 Q2 t^2``, at 2 error bars of 1.5: ratio
    ``(W^2 (1 - e^-9) + 0.81) / 9.81``, named; x2 itself crosses its bound on the minus side, its plus side
    judged where the curvature comes from C (a small step below 0 leaves it unjudged otherwise)."""
    Q2 = 1.0

    def cost(X):
        X = np.atleast_2d(X)
        return (Q * (X[:, 0] + X[:, 1] / 2) ** 2 + W ** 2 * (1 - np.exp(-X[:, 1] ** 2 / W ** 2))
                + Q2 * (X[:, 2] + 0.3 * X[:, 1]) ** 2)
    H3 = np.array([[Q, Q / 2, 0], [Q / 2, Q / 4 + 1 + 0.09 * Q2, 0.3 * Q2], [0, 0.3 * Q2, Q2]])
    C3 = np.linalg.inv(H3)
    bounds = (np.array([-50.0, -50.0, 0.0]), np.full(3, 50.0))
    sigma = np.array([0.05, 1.5, 0.5])
    expected = (W ** 2 * (1 - np.exp(-9.0)) + 0.81) / 9.81
    t1 = C3[1, 2] / C3[2, 2]  # x1 at x2's plus error bars (2 x 0.5 = 1): the valley's shortfall there alone
    x2_plus = 1 + (W ** 2 * (1 - np.exp(-t1 ** 2 / W ** 2)) - t1 ** 2) * C3[2, 2]
    for kw, x2 in ((dict(exact=True), [None, x2_plus]), (dict(small=np.full(3, 1e-3)), [None, None])):
        out = profile_ratios(cost, np.zeros(3), C3, sigma, bounds, a=2.0, **kw)
        np.testing.assert_allclose(out[1], [expected, expected], rtol=1e-5)
        # x2's own line: its minus side beyond the bound; measured from small steps, one of them is beyond it too
        assert out[2][0] is None and (out[2][1] is None) == (x2[1] is None), out
        if x2[1] is not None:
            assert out[2][1] == pytest.approx(x2[1], rel=1e-9)
    assert check(cost, np.zeros(3), C3, sigma, bounds, ["x0", "x1", "x2"], exact=True)["optimistic"] == ["x1"]


def test_a_side_beyond_a_bound_is_not_judged_and_a_missing_error_bar_skips_the_parameter():
    """x1's step of 3 W out crosses an upper bound at 2 W: that side None, the other judged; a parameter without
    a finite error bar is not judged at all; a bound inside the small steps leaves the parameter unjudged."""
    bounds = (np.full(2, -50.0), np.array([50.0, 2.0]))
    out = profile_ratios(_cost(True), np.zeros(2), C, np.array([np.inf, 1.5]), bounds, a=2.0, small=np.full(2, 1e-3))
    assert out[0] == [None, None] and out[1][1] is None and out[1][0] == pytest.approx((1 - np.exp(-9.0)) / 9.0,
                                                                                      rel=1e-5)
    tight = (np.full(2, -50.0), np.array([50.0, 1e-4]))
    assert profile_ratios(_cost(True), np.zeros(2), C, np.array([0.05, 1.5]), tight, a=2.0,
                          small=np.full(2, 1e-3))[1] == [None, None]


def test_the_assessment_names_the_optimistic_error_bars_and_says_by_how_much():
    """The record's sentence names each flagged parameter with its worst side's rise, in per cent; a result without a
    polish's shape is not assessed; a result with every ratio near 1 passes."""
    shape = record(["I_p", "zeta_pp", "k_sf"], [[0.59, 0.65], [0.32, 0.229], [1.0, 1.0]])
    a = ShapeAssessment.from_result(SimpleNamespace(polish={"shape": shape}))
    assert a.verdict == "warn" and a.optimistic == ["zeta_pp"]
    assert a.reason == caveat(shape) and a.reason.startswith(
        "the error bar of zeta_pp is optimistic: out at ±2 of it along its profile line the cost rises only 23 % of "
        "what the error bar assumes (below 25 %: no more than it assumes at ±1)")
    assert ShapeAssessment.from_result(SimpleNamespace(polish=None)).verdict == "not assessed"
    ok = ShapeAssessment.from_result(SimpleNamespace(polish={"shape": record(["k_sf"], [[1.0, 0.98]])}))
    assert ok.verdict == "pass" and "1 parameter(s) judged" in ok.reason


def test_the_built_in_cars_error_bars_have_the_shape_they_say(sim_dataset, default_scenario, tmp_path):
    """End to end (the linear car on the built-in runs at 1 % noise): every free parameter's cost out at ±2
    std_robust is its curvature's quadratic (ratios within 2 % of 1: the linear car's outputs are close to linear
    in its parameters over error bars this small), the assessment passes in result.json, and reading the file back
    gives the same record. Noise-free, the error bars are the rounding of the numbers: not assessed."""
    from rideid.synth.scenario import simulate_manifest, write_dataset
    data, _ = simulate_manifest(default_scenario, noise=0.01, seed=1)
    write_dataset(default_scenario, data, tmp_path / "noisy")
    res = rideid.identify(rideid.load_dataset(tmp_path / "noisy"), seed=1, model="base")
    ratios = np.array(list(res.polish["shape"]["ratio"].values()), dtype=float)
    assert ratios.shape == (11, 2) and np.all(np.abs(ratios - 1) < 0.02)
    res.save(tmp_path / "fit")
    doc = json.loads((tmp_path / "fit" / "result.json").read_text())
    rec = [a for a in assessments_from_json(doc["assessments"]) if a.kind == "error_bar_shape"]
    assert len(rec) == 1 and rec[0].verdict == "pass" and rec[0].optimistic == []
    assert rec[0] == ShapeAssessment.from_result(rideid.load_result(tmp_path / "fit" / "result.json"))
    clean = rideid.identify(rideid.load_dataset(sim_dataset), seed=1, model="base")
    assert all(r == [None, None] for r in clean.polish["shape"]["ratio"].values())
    assert ShapeAssessment.from_result(clean).verdict == "not assessed"


def test_a_named_error_bar_is_said_beside_its_number_in_the_terminal_and_the_report(default_scenario, tmp_path):
    """The estimates table of ``rideid identify`` and of the report mark a parameter the shape check names, and the
    terminal and the report's summary say why (the caveat's sentence), whatever the adequacy verdict."""
    from dataclasses import replace

    from rideid import cli
    from rideid.report.html import _caveat_lines, parameter_rows
    from rideid.synth.scenario import simulate_manifest, write_dataset
    data, _ = simulate_manifest(default_scenario, noise=0.01, seed=2)
    write_dataset(default_scenario, data, tmp_path / "noisy")
    res = rideid.identify(rideid.load_dataset(tmp_path / "noisy"), seed=1, model="base")
    flagged = dict(res.polish["shape"], optimistic=["k_sf"], ratio={**res.polish["shape"]["ratio"], "k_sf": [0.2, 0.9]})
    bad = replace(res, polish=dict(res.polish, shape=flagged))
    table = cli._summary_table(bad).splitlines()
    k_sf = next(ln for ln in table if ln.startswith("k_sf"))
    assert k_sf.endswith("ERROR BAR OPTIMISTIC (WARNING below)")  # no reach recorded here
    assert not any("OPTIMISTIC" in ln for ln in cli._summary_table(res).splitlines())
    rows = {p["name"]: p for p in parameter_rows(bad)}
    assert rows["k_sf"]["note"] == "ERROR BAR OPTIMISTIC" and rows["k_sr"]["note"] == ""
    reach = dict(flagged, reach={"k_sf": {"value": 1.0, "lower": 0.8, "upper": None, "walked": [True, True]}})
    assert table_note(reach, "k_sf") == "ERROR BAR OPTIMISTIC: the data allow at least 0.8 to beyond the walk"
    one_side = dict(reach, reach={"k_sf": {"value": 1.0, "lower": 0.8, "upper": None, "walked": [True, False]}})
    assert table_note(one_side, "k_sf") == "ERROR BAR OPTIMISTIC: the data allow at least 0.8 to the printed ±2 std"
    assert table_note(reach, "k_sr") is None and table_note(None, "k_sf") is None
    rows = {p["name"]: p for p in parameter_rows(replace(res, polish=dict(res.polish, shape=reach)))}
    assert rows["k_sf"]["note"] == table_note(reach, "k_sf")
    line = [ln for ln in _caveat_lines(bad, bad.adequacy) if ln[0] == "Error bars' shape"]
    assert line == [("Error bars' shape", "NOT TO BE TRUSTED to their std: " + caveat(flagged), "estimates")]
    assert caveat(flagged).startswith("the error bar of k_sf is optimistic: out at ±2 of it along its profile line "
                                      "the cost rises only 20 %")
    assert not [ln for ln in _caveat_lines(res, res.adequacy) if ln[0] == "Error bars' shape"]
