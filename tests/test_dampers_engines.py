"""SPEC §8 cars in two independent engines: the 7-DOF nonlinear simulator and the MuJoCo car.

The car: the built-in one with asymmetric digressive dampers (2:1 rebound:compression, slope x 0.4
above a 0.15 m/s knee), given as a scenario's ``[dampers]`` table; bump stops from ``[truth]``; the CG
height from ``[vehicle]``. Both engines run from the same scenario through
:func:`rideid.synth.scenario.simulate_manifest`. Reference: the *linear* reduced car agrees with MuJoCo
within 0.1-0.4 % of each channel's RMS on these runs (tests/test_hifi.py holds it to 1 %); the nonlinear
car agrees within 0.6 % on the built-in runs' realistic amplitudes (1 % held here) and within 1.7 % on the
80 mm twist (2 % held), where both engines are converged (kernel sub-steps x4, MuJoCo at 0.25 ms: < 0.1 %)
and the difference grows with the square of the amplitude (0.16, 0.31, 1.29 % at 20, 40, 80 mm): the
large-angle kinematics MuJoCo has and the small-angle model lacks, which the softer digressive dampers let
grow (the linear car with its CG raised 0.25 m shows the same, 1.2 % on the 80 mm twist; the realistic car of
docs/verification.md 2.5 % on the axle channels, taken apart term by term by benchmarks/engines_kinematics.py).
"""

import numpy as np
import pytest
import tomli_w

pytest.importorskip("mujoco")

import rideid  # noqa: E402
from rideid.synth.scenario import simulate_manifest  # noqa: E402
from rideid.data.schema import parse_scenario, read_toml  # noqa: E402
from rideid.model.equations import CHANNEL_KIND, CHANNELS  # noqa: E402
from rideid.verify.hifi import damper_force  # noqa: E402

KNOTS = [-0.6, -0.3, -0.15, -0.05, 0.05, 0.15, 0.3, 0.6]
#: the MuJoCo car's parametric damper, rebound 2 x compression, slope x 0.4 above 0.15 m/s
HIFI_DAMPER = dict(rebound_ratio=2.0, knee_velocity=0.15, knee_ratio=0.4)


def _dampers(truth):
    """Curves through the parametric damper at the knots: piecewise linear, so exactly that damper."""
    return {"velocity": KNOTS,
            **{ax: [float(f) for f in damper_force(np.array(KNOTS), truth[c], **HIFI_DAMPER)]
               for ax, c in (("front", "c_sf"), ("rear", "c_sr"))}}


def _scenario(runs, dampers=True, vehicle=None, truth=None, path="scenario.toml"):
    doc = read_toml(rideid.default_scenario_path())
    doc["runs"] = [r for r in doc["runs"] if r["id"] in runs]
    if dampers:
        doc["dampers"] = _dampers(doc["truth"])
    doc["vehicle"].update(vehicle or {})
    doc["truth"].update(truth or {})
    return doc if path is None else parse_scenario(doc, path)


def _relative_rms(a, b):
    """RMS of ``a - b`` per channel over the RMS of ``b``."""
    return np.sqrt(np.mean((a - b) ** 2, axis=0)) / np.sqrt(np.mean(b ** 2, axis=0))


def _judged(y):
    """Channels with motion to compare (roll on a washboard is zero in both engines)."""
    rms = np.sqrt(np.mean(y ** 2, axis=0))
    return [i for i, c in enumerate(CHANNELS)
            if rms[i] > 1e-3 * max(rms[j] for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c])]


def _both(sc):
    a, la = simulate_manifest(sc)
    b, lb = simulate_manifest(sc, engine="mujoco")
    return a, b, la, lb


def _agree(a, b, tol):
    for rid in a:
        ya, yb = a[rid][1], b[rid][1]
        err = _relative_rms(ya, yb)
        for i in _judged(yb):
            assert err[i] < tol, (rid, CHANNELS[i], err[i])


def test_mujoco_uses_the_kernels_damper_curve():
    """MuJoCo's curve (written from SPEC §8) = the kernel's, inside and beyond the knots."""
    from rideid.model.nonlinear import damper_force as kernel_force
    from rideid.verify.hifi import curve_force
    F = np.array(_dampers(rideid.default_scenario().truth)["front"])
    v = np.linspace(-1.5, 1.5, 3001)
    np.testing.assert_allclose(curve_force(KNOTS, F, v), kernel_force(KNOTS, F, v), rtol=1e-12, atol=1e-9)
    # and the curves through the knots are exactly the [hifi] parametric damper (knots at +-knee)
    np.testing.assert_allclose(curve_force(KNOTS, F, v), damper_force(v, 1786.0, **HIFI_DAMPER), rtol=1e-9)


def test_dampers_table_equals_the_hifi_parametric_damper_in_mujoco():
    """The same damper given as [dampers] curves or as [hifi] keys: the same MuJoCo car."""
    from rideid.data.schema import HifiProperties
    from rideid.model.params import as_vector
    from rideid.verify.hifi import simulate_mujoco
    sc = _scenario(["H_LL"])
    run = sc.runs[0]
    t = np.arange(int(run.duration * 200) + 1) / 200
    P, track = as_vector(sc.truth), sc.tracks[run.track]
    curves = simulate_mujoco(P, sc.geometry, track, run.speed, t, dampers=sc.dampers)
    hifi = simulate_mujoco(P, sc.geometry, track, run.speed, t,
                           hifi=HifiProperties(damper_rebound_ratio=2.0, damper_knee_velocity=0.15,
                                               damper_knee_ratio=0.4))
    np.testing.assert_allclose(curves, hifi, atol=1e-7 * np.abs(hifi).max())


def test_engines_agree_with_damper_curves_on_washboard_twist_and_herringbone():
    """Built-in amplitudes (8 mm washboard at 6 m/s, 40 mm twist, 5 mm herringbone): measured 0.6 % at most."""
    a, b, la, lb = _both(_scenario(["W_L", "T_LL", "H_LL"]))
    assert la == [] and lb == []
    _agree(a, b, 0.01)


def test_engines_agree_with_damper_curves_on_the_high_twist():
    """80 mm twist bumps: measured 1.3 % at most (the large-angle kinematics, module docstring)."""
    a, b, _, _ = _both(_scenario(["T_HL"]))
    _agree(a, b, 0.02)


def test_engines_agree_with_bump_stops_reached():
    """Stops at 25 mm (T_LL compresses 33-38 mm) or 50 mm (T_HL, 75 mm): measured 0.7 % and 1.7 %."""
    from rideid.synth.scenario import nonlinear_car, nonlinear_states
    from rideid.model.simulate import prepare_run
    for rid, clear, tol in (("T_LL", 0.025, 0.01), ("T_HL", 0.05, 0.02)):
        sc = _scenario([rid], truth=dict(bs_clear_f=clear, bs_clear_r=clear, bs_rate_f=5e4, bs_rate_r=5e4))
        a, b, _, _ = _both(sc)
        _agree(a, b, tol)
        # the stops are reached: suspension compression (wheel minus body corner) beyond the clearance
        run = sc.runs[0]
        ri = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, a[rid][0])
        P, layout = nonlinear_car(sc)
        X = nonlinear_states(P, sc.geometry, ri, layout)
        x, y = sc.geometry.corner_xy(sc.truth["a"])
        q = X[:, :7]
        d = q[:, 3:] - (q[:, :1] - x * q[:, 1:2] + y * q[:, 2:3])
        assert d.max() > clear + 0.005, (rid, d.max())


def test_engines_agree_when_wheels_leave_the_road():
    """Washboard at wheel hop (W_H): the softer digressive dampers let every wheel leave the road in both
    engines (physics, not a warning); the responses still agree within 0.7 % (1 % held)."""
    import warnings

    from rideid.errors import ModelValidityWarning
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        a, b, la, lb = _both(_scenario(["W_H"]))
    assert not [r for r in rec if issubclass(r.category, ModelValidityWarning)]
    assert {lo.wheel for lo in la} == {lo.wheel for lo in lb} == {"fl", "fr", "rl", "rr"}
    assert all(lo.physics for lo in la + lb)
    _agree(a, b, 0.01)


def test_cg_height_closed_form_and_mujoco_agree():
    """[vehicle] cg_height = 0.25 m: the linear 7-DOF model with the CG terms against MuJoCo's raised CG,
    within 1 % (measured 0.6 %; without the terms roll on the twist is 12 % off); with damper curves and
    bump stops too (measured 0.3 % on H_HH)."""
    sc = _scenario(["T_LL", "H_LL"], dampers=False, vehicle={"cg_height": 0.25})
    assert not sc.nonlinear and sc.geometry.cg_height == 0.25
    a, b, _, _ = _both(sc)
    _agree(a, b, 0.01)
    flat = _scenario(["T_LL"], dampers=False)
    roll = CHANNELS.index("roll_rate")
    assert _relative_rms(simulate_manifest(flat)[0]["T_LL"][1], b["T_LL"][1])[roll] > 0.08
    a, b, _, _ = _both(_scenario(["H_HH"], vehicle={"cg_height": 0.25},
                                 truth=dict(bs_clear_f=0.05, bs_clear_r=0.05, bs_rate_f=5e4, bs_rate_r=5e4)))
    _agree(a, b, 0.01)


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_simulate_with_dampers_changes_the_data_as_mujoco_says(tmp_path, capsys):
    """`rideid simulate` of the car with [dampers] against the same car with linear c_sf, c_sr: the
    data change by 21-39 % of the channels' RMS on the 40 mm twist and 20-65 % (pitch rate 169 %) on the
    herringbone, and the MuJoCo car changes by the same amount within 1 % of the change (measured 0.7 %)."""
    from rideid.cli import main
    from rideid.data.schema import load_truth, load_truth_dampers
    from rideid.data.schema import read_run_csv
    runs = ["T_LL", "H_LL"]
    for name, dampers in (("linear", False), ("dampers", True)):
        (tmp_path / f"{name}.toml").write_text(tomli_w.dumps(_scenario(runs, dampers=dampers, path=None)))
        assert main(["simulate", str(tmp_path / f"{name}.toml"), "--out", str(tmp_path / name), "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "warning" not in err and "note" not in out
    assert load_truth_dampers(tmp_path / "dampers" / "truth.toml") == _scenario(runs).dampers
    assert load_truth_dampers(tmp_path / "linear" / "truth.toml") is None
    assert load_truth(tmp_path / "dampers" / "truth.toml")["c_sf"] == 1786.0
    mj_lin = simulate_manifest(_scenario(runs, dampers=False), engine="mujoco")[0]
    mj_nl = simulate_manifest(_scenario(runs), engine="mujoco")[0]
    expected_body = {"T_LL": 0.22, "H_LL": 0.21}
    for rid in runs:
        lin = read_run_csv(tmp_path / "linear" / "runs" / f"{rid}.csv")
        nl = read_run_csv(tmp_path / "dampers" / "runs" / f"{rid}.csv")
        Y0, Y1 = lin.matrix(), nl.matrix()
        change = _relative_rms(Y1, Y0)
        mj_change = np.sqrt(np.mean((mj_nl[rid][1] - mj_lin[rid][1]) ** 2, axis=0)) / np.sqrt(np.mean(Y0 ** 2, axis=0))
        assert change[0] == pytest.approx(expected_body[rid], abs=0.015), change
        assert np.all(change > 0.15), change
        np.testing.assert_allclose(change, mj_change, rtol=0.01)
