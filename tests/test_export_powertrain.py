"""The FMU of a car with a powertrain on mounts (SPEC §10, §11): 9 DOF in its C equations.

Driven over tracks (by drive_fmu and by FMPy's simulate_fmu), the FMU gives ``rideid simulate`` of the same car
(the ten channels) and the independent Newton-Euler simulator of tests/powertrain_car.py (the four powertrain
outputs as well); its free response after a road step is the modal superposition of the mass and stiffness
matrices assembled by hand in absolute coordinates (powertrain_car.matrices, not rideid's); and its own outputs
obey the mount law that defines ``f_pb``, ``zeta_pb``, ``f_pp``, ``zeta_pp`` (body held:
``m_p z_p'' = -k_p u_p - c_p u_p'``, ``I_p theta_p'' = -k_pt psi_p - c_pt psi_p'``), which a least-squares fit of
the outputs recovers. The refusals: damper curves or bump stops with a powertrain, an unphysical powertrain (at
export, and at the FMU's initialisation).
"""

import dataclasses
import shutil

import numpy as np
import pytest
import scipy.linalg
from powertrain_car import ENGINE, matrices, mount_deflections, simulate

import rideid
from rideid.errors import ArgumentError, DataError
from rideid.model.equations import CHANNELS
from rideid.model.simulate import corner_inputs, prepare_run
from rideid.synth.scenario import simulate_manifest

fmpy = pytest.importorskip("fmpy")
from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

from rideid.exporter import car_from_scenario, export  # noqa: E402
from rideid.exporter.drive import drive_fmu  # noqa: E402
from rideid.exporter.fmu import INPUTS, POWERTRAIN_OUTPUTS, max_step  # noqa: E402
from test_export import needs_cc  # noqa: E402


OUTPUTS = tuple(CHANNELS) + tuple(o[0] for o in POWERTRAIN_OUTPUTS)
#: FMU communication steps per data sample (the road between samples: the cubic Hermite of drive_fmu)
SUB = 16


@pytest.fixture(scope="module")
def engine_car():
    """The built-in scenario with the issue's engine on mounts (180 kg, 1.2 m ahead, 10.5 / 13 Hz, 10 %)."""
    sc = rideid.default_scenario()
    return dataclasses.replace(sc, truth={**sc.truth, **ENGINE}, extensions=("powertrain",))


@pytest.fixture(scope="module")
def engine_fmu(engine_car, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmu") / "car"
    export(car_from_scenario(engine_car), folder, format="fmu")
    return str(folder / "car.fmu")


def channel_errors(Y, Yref):
    """RMS(Y - Yref) / RMS(Yref) per column; NaN where the column stays 0 (then Y must too)."""
    rms = np.sqrt(np.mean(Yref ** 2, axis=0))
    live = rms > 1e-12
    assert np.abs(Y[:, ~live]).max(initial=0.0) < 1e-9
    return np.where(live, np.sqrt(np.mean((Y - Yref) ** 2, axis=0)) / np.where(live, rms, 1.0), np.nan)


@needs_cc
def test_fmu_of_a_powertrain_car_matches_simulate_and_an_independent_simulator(engine_car, engine_fmu):
    """Driven with each run's wheel inputs by drive_fmu (16 steps a sample): the ten channels within 3e-5 of their
    RMS of ``rideid simulate`` (measured over the ten built-in runs: 1.5e-5 worst, H_HH's pitch rate, where the
    rigid car's FMU gives 1.9e-5: the road between samples, not the powertrain; the twists 2e-7), and all fourteen
    outputs within 1e-4 of the independent Newton-Euler simulator in absolute coordinates (measured: 8.3e-5 on the
    channels, 5.3e-5 on the powertrain's four; lsim's first-order hold at 20x, which puts rideid simulate itself
    8.2e-5 from it)."""
    fmu = engine_fmu
    assert validate_fmu(fmu) == []
    md = read_model_description(fmu)
    by = {v.name: v for v in md.modelVariables}
    assert [n for n in by if by[n].causality == "input"] == list(INPUTS)
    assert [n for n in by if by[n].causality == "output"] == list(OUTPUTS)
    assert [by[n].valueReference for n in OUTPUTS] == list(range(8, 22))
    for n in (*rideid.NAMES, *ENGINE):
        assert by[n].causality == "parameter" and float(by[n].start) == engine_car.truth[n], n
    assert (by["f_pb"].unit, by["zeta_pb"].unit, by["psi_p"].unit, by["u_p"].unit) == ("Hz", None, "rad", "m")
    assert "9-DOF" in md.description
    runs = [r for r in engine_car.runs if r.id in ("T_LH", "H_LH", "W_L")]
    data, _ = simulate_manifest(dataclasses.replace(engine_car, runs=runs))
    car = {n: engine_car.truth[n] for n in (*rideid.NAMES, *ENGINE)}
    G = engine_car.geometry
    for run in runs:
        t, Yref = data[run.id]
        ri = prepare_run(engine_car.tracks[run.track], G, run.speed, t)
        tf = np.arange((t.size - 1) * SUB + 1) * ((t[1] - t[0]) / SUB)
        r, rdot = ri.inputs_at(tf)
        Y = drive_fmu(fmu, t, r, rdot, sub=SUB, outputs=OUTPUTS)
        err = channel_errors(Y[:, :10], Yref)
        assert np.nanmax(err) < 3e-5, (run.id, err)
        track = engine_car.tracks[run.track]
        ref = simulate(car, G, t, lambda tt, tr=track, v=run.speed: corner_inputs(tr, G, v * tt), upsample=20,
                       powertrain_outputs=True)
        ref[:, np.sqrt(np.mean(ref ** 2, axis=0)) < 1e-9] = 0.0  # the roll rate of a symmetric run: lsim's rounding
        err = channel_errors(Y, ref)
        assert np.nanmax(err) < 1e-4, (run.id, err)
        assert np.all(np.isfinite(err[10:]))  # the powertrain moves on every run


def free_decay(fmu, t, r0, parameters=None, outputs=OUTPUTS):
    """The FMU at rest on a road ``r0`` (m, every wheel), the road dropped to 0 at t = 0: ``outputs`` at ``t``
    (uniform, one communication step per interval), with ``parameters`` (name -> value) set before initialisation."""
    md = read_model_description(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipped = extract(fmu)
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="car", instanceName="car")
    s.instantiate()
    try:
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        for n, v in (parameters or {}).items():
            s.setReal([vr[n]], [v])
        vin = [vr[n] for n in INPUTS]
        s.setReal(vin, [r0] * 4 + [0.0] * 4)
        s.exitInitializationMode()
        s.setReal(vin, [0.0] * 8)
        vout = [vr[n] for n in outputs]
        Y = np.empty((t.size, len(vout)))
        for k in range(t.size):
            Y[k] = s.getReal(vout)
            if k + 1 < t.size:
                s.doStep(float(t[k]), float(t[k + 1] - t[k]))
        s.terminate()
    finally:
        s.freeInstance()
        shutil.rmtree(unzipped, ignore_errors=True)
    return Y


def derivative(y, h):
    """d/dt of uniform samples ``y`` (axis 0) by the fourth-order central difference (``(w h)^4 / 30`` relative at
    angular frequency w); the two samples at each end are dropped."""
    return (-y[4:] + 8 * y[3:-1] - 8 * y[1:-3] + y[:-4]) / (12 * h)


@needs_cc
def test_fmu_free_response_is_the_hand_assembled_modes_and_obeys_the_mount_law(engine_car, engine_fmu):
    """A road step of 10 mm under every wheel, the car undamped (every damper, mount damping and tire damping set
    to 0 through the FMU's parameters): the FMU's fourteen outputs over 1 s are the modal superposition
    ``q(t) = V cos(W t) V^T M q0`` of M, K assembled by hand in absolute coordinates (powertrain_car.matrices), within
    1e-7 of each output's peak (measured: 2.3e-9 worst; RK4 at 0.1 ms, (w h)^4 / 120 ~ 5e-10 a step at the
    fastest mode). The whole car's powertrain
    modes are coupled (12.80 and 13.39 Hz undamped on this car); f_pb and f_pp are the mounts' frequencies
    with the body held, which the FMU's own outputs give through the mount law: a least-squares fit of
    ``z_p'' = -w_pb^2 u_p - 2 zeta_pb w_pb u_p'`` (and in pitch ``theta_p'' ...``, the derivatives by the
    fourth-order central difference at 0.1 ms, (w h)^4 / 30 ~ 1e-10) recovers f_pb, f_pp within 1e-8 (relative)
    and zeta_pb, zeta_pp within 1e-8 (absolute; 0 undamped, 0.1 as exported); measured: 9e-11 and 2e-11."""
    fmu = engine_fmu
    G = engine_car.geometry
    car = {n: engine_car.truth[n] for n in (*rideid.NAMES, *ENGINE)}
    undamped = {"c_sf": 0.0, "c_sr": 0.0, "zeta_pb": 0.0, "zeta_pp": 0.0, "c_tf": 0.0, "c_tr": 0.0}
    h, r0 = 1e-4, 0.01
    t = np.arange(10001) * h
    Y = free_decay(fmu, t, r0, undamped)
    # closed form: M q'' + K q = 0 from rest at q0 (every heave r0 above the new equilibrium, angles 0)
    M, _, K, _, xs, ys = matrices({**car, **undamped}, G)
    w2, V = scipy.linalg.eigh(K, M)  # V^T M V = I
    w = np.sqrt(w2)
    q0 = np.zeros(9)
    q0[[0, 3, 4, 5, 6, 7]] = r0  # z_b, the wheels, z_p
    c0 = V.T @ M @ q0
    q = (V @ (np.cos(np.outer(w, t)) * c0[:, None])).T
    qd = -(V @ (w[:, None] * np.sin(np.outer(w, t)) * c0[:, None])).T
    qdd = -(V @ (w2[:, None] * np.cos(np.outer(w, t)) * c0[:, None])).T
    ref = np.zeros_like(Y)
    for i in range(4):
        ref[:, i] = qdd[:, 0] - xs[i] * qdd[:, 1] + ys[i] * qdd[:, 2]
        ref[:, 4 + i] = qdd[:, 3 + i]
    ref[:, 8], ref[:, 9] = qd[:, 1], qd[:, 2]
    ref[:, 10], ref[:, 11] = qdd[:, 7], qd[:, 8]
    ref[:, 12:] = q @ mount_deflections(car).T
    peak = np.abs(ref).max(axis=0)
    live = peak > 1e-12
    assert np.array_equal(live, np.r_[[True] * 9, False, [True] * 4])  # roll is not excited
    assert np.abs(Y[:, ~live]).max() < 1e-12
    err = np.abs(Y - ref).max(axis=0)[live] / peak[live]
    assert err.max() < 1e-7, dict(zip(np.array(OUTPUTS)[live], err))
    # the mount law, from the FMU's outputs alone
    names = {n: k for k, n in enumerate(OUTPUTS)}
    for label, pars in (("undamped", undamped), ("damped", {})):
        Y = free_decay(fmu, t, r0, pars)
        for acc, mount, f, zeta in ((Y[2:-2, names["powertrain_az"]], Y[:, names["u_p"]], "f_pb", "zeta_pb"),
                                    (derivative(Y[:, names["powertrain_pitch_rate"]], h), Y[:, names["psi_p"]],
                                     "f_pp", "zeta_pp")):
            X = np.c_[mount[2:-2], derivative(mount, h)]
            (k, c), *_ = np.linalg.lstsq(X, -acc, rcond=None)
            wn = np.sqrt(k)
            assert wn / (2 * np.pi) == pytest.approx(car[f], rel=1e-8), (label, f)
            assert c / (2 * wn) == pytest.approx(pars.get(zeta, car[zeta]), abs=1e-8), (label, zeta)
    # the whole car's modes are not the mounts' own: none within 1 % of f_pb or f_pp (the two highest, the
    # powertrain's coupled modes: 12.80 and 13.39 Hz undamped, beside the wheel hops at 11.9-12.1 Hz)
    f_modes = w / (2 * np.pi)
    assert np.abs(f_modes / car["f_pb"] - 1).min() > 0.01 and np.abs(f_modes / car["f_pp"] - 1).min() > 0.01


def test_fmu_of_a_powertrain_car_takes_the_same_step_bound(engine_car):
    """The RK4 sub-step of the 9-DOF car: the 7-DOF car's bound (its stiffest mode, at most M_MAX a second), the
    powertrain's modes included; the rigid car's step unchanged."""
    car = car_from_scenario(engine_car)
    rigid = dataclasses.replace(car, values={**car.values, "m_p": 0.0})
    assert car.powertrain and not rigid.powertrain
    assert max_step(car) == max_step(rigid) == 1 / 4096


def test_fmu_refuses_a_powertrain_with_damper_curves_or_a_bad_one(engine_car, tmp_path):
    """The groups the FMU's powertrain car does not have: damper curves and bump stops (as rideid simulate), one
    line naming them, nothing written; a powertrain heavier than the sprung mass names m_p."""
    from rideid.data.schema import DamperCurves
    car = car_from_scenario(engine_car)
    curves = dataclasses.replace(car, dampers=DamperCurves((-0.1, 0.1), (-300.0, 500.0), (-250.0, 450.0)))
    with pytest.raises(ArgumentError, match="powertrain on mounts.*linear dampers and no bump stops.*damper curves"):
        export(curves, tmp_path / "a", format="fmu", compiler=None)
    stops = dataclasses.replace(car, bump_stops={"bs_clear_f": 0.05, "bs_clear_r": 0.05, "bs_rate_f": 1e5,
                                                 "bs_rate_r": 1e5})
    with pytest.raises(ArgumentError, match="this car has bump stops; export --format card"):
        export(stops, tmp_path / "b", format="all", compiler=None)
    heavy = dataclasses.replace(car, values={**car.values, "m_p": 5000.0})
    with pytest.raises(DataError, match="m_p < m_s"):
        export(heavy, tmp_path / "c", format="fmu", compiler=None)
    assert list(tmp_path.iterdir()) == []
    export(curves, tmp_path / "card", format="card")  # the card takes any car


def test_the_refusal_on_the_command_line_is_one_line_exit_2_nothing_written(engine_car, tmp_path, monkeypatch,
                                                                           capsys):
    """``rideid export FIT --format fmu`` of a fit whose car has a powertrain and bump stops (the fit folder's car
    stood in for): one line naming the groups, exit 2, no output folder."""
    import rideid.exporter
    from rideid.cli import main
    car = dataclasses.replace(car_from_scenario(engine_car), bump_stops={"bs_clear_f": 0.05, "bs_clear_r": 0.05,
                                                                         "bs_rate_f": 1e5, "bs_rate_r": 1e5})
    monkeypatch.setattr(rideid.exporter, "_load", lambda source: (car, str(source), None))
    assert main(["export", str(tmp_path / "fit"), "--out", str(tmp_path / "car"), "--format", "fmu"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rideid: error:") and "powertrain" in err[0], err
    assert "this car has bump stops" in err[0]
    assert list(tmp_path.iterdir()) == []


@needs_cc
@pytest.mark.parametrize("parameters", [{"m_p": 0.0}, {"m_p": 2000.0}, {"I_p": 1e4}, {"f_pp": 0.0}])
def test_fmu_refuses_a_powertrain_set_unphysical_at_initialisation(engine_fmu, parameters):
    """Parameters set through the FMU that leave no powertrain or no body (m_p >= m_s, the body's own pitch
    inertia negative, a mount frequency 0): fmi2ExitInitializationMode returns an error, one logged line."""
    t = np.arange(3) * 1e-3
    with pytest.raises(Exception, match="fmi2ExitInitializationMode"):
        free_decay(engine_fmu, t, 0.0, parameters)


@needs_cc
def test_fmpy_simulate_fmu_drives_the_powertrain_car(engine_car, engine_fmu):
    """Any FMI master: FMPy's ``simulate_fmu`` with its defaults (no input derivatives, outputs read before the next
    inputs are set), the road on a grid 20x finer than the data and the step there, all fourteen outputs asked
    for: the ten channels within 1e-4 of their RMS of ``rideid simulate`` (measured: T_LH 6.9e-6, H_LH 1.4e-5, W_L
    2.9e-5, as the rigid car's 3e-5 in docs/export.md)."""
    from fmpy import simulate_fmu
    runs = [r for r in engine_car.runs if r.id in ("H_LH", "W_L")]
    data, _ = simulate_manifest(dataclasses.replace(engine_car, runs=runs))
    sub = 20
    for run in runs:
        t, Yref = data[run.id]
        tf = np.arange((t.size - 1) * sub + 1) * ((t[1] - t[0]) / sub)
        r, rdot = prepare_run(engine_car.tracks[run.track], engine_car.geometry, run.speed, t).inputs_at(tf)
        sig = np.zeros(tf.size, dtype=[("time", float)] + [(n, float) for n in INPUTS])
        sig["time"] = tf
        for k, n in enumerate(INPUTS):
            sig[n] = r[:, k] if k < 4 else rdot[:, k - 4]
        out = simulate_fmu(engine_fmu, input=sig, output=list(OUTPUTS), stop_time=tf[-1],
                           output_interval=tf[1] - tf[0])
        Y = np.stack([out[c][::sub] for c in OUTPUTS], axis=1)
        assert np.nanmax(channel_errors(Y[:, :10], Yref)) < 1e-4, run.id
        assert np.all(np.abs(Y[:, 10:]).max(axis=0) > 0)  # the powertrain's outputs are read
