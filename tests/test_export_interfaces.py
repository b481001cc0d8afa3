"""The FMU's two FMI 2.0 interfaces (SPEC §10, §13): Model Exchange beside Co-Simulation in one ``car.fmu``.

Model Exchange: the model description (states, derivatives, ModelStructure; FMPy's validation clean, the
variables of before unchanged); the static equilibrium and the derivatives against closed forms written here (a
road lifted evenly lifts the car rigidly; a wheel displaced at rest pushes on its wheel and the body with the
spring rates; a tire off the ground lets its wheel fall with the static load; a bump stop adds its rate); a
master written here that sets the exact road at every evaluation (RK4 at 20 steps a sample) against ``rideid
simulate``; FMPy's ``simulate_fmu`` (CVode and Euler) and set-then-get masters at one data sample per point and
at 20 per sample, within what docs/export.md states, for the linear car, the car with damper curves, bump stops
and lift-off, and the car with a powertrain on mounts. Co-Simulation: outputs read before the inputs at a step's
end are set are a prediction; set the inputs and read again, and they are those a set-then-get master reads, bit
for bit.

The default tests drive short stretches (1 s) of the runs; the slow test checks docs/export.md's table over the
built-in scenario's full runs (``benchmarks/fmu_masters.py`` prints it).
"""

import ctypes
import dataclasses
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import rideid
from rideid.model.equations import CHANNELS
from rideid.model.simulate import prepare_run
from rideid.synth.scenario import simulate_manifest

fmpy = pytest.importorskip("fmpy")
from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Model, FMU2Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

from powertrain_car import ENGINE  # noqa: E402
from rideid.exporter import car_from_scenario, export  # noqa: E402
from rideid.exporter.fmu import FMU_NAMES, INPUTS, POWERTRAIN_OUTPUTS, TOLERANCE, VR_DER0, VR_STATE0  # noqa: E402
from test_export import needs_cc  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from fmu_masters import (GROUPS, by_simulate_fmu, cs_set_then_get, fine_road, me_set_then_get,  # noqa: E402
                         relative)

#: the stretch of each run the default tests drive (s)
SHORT = 1.0


def build(sc, folder):
    export(car_from_scenario(sc), folder, format="fmu")
    return str(folder / "car.fmu")


@pytest.fixture(scope="module")
def linear(tmp_path_factory):
    """The built-in car's FMU and the built-in scenario."""
    sc = rideid.default_scenario()
    return build(sc, tmp_path_factory.mktemp("fmu") / "car"), sc


@pytest.fixture(scope="module")
def curves(tmp_path_factory):
    """The car with asymmetric digressive damper curves, bump stops and a CG height 0.25 m (SPEC §8)."""
    sc = rideid.load_scenario(ROOT / "examples" / "dampers" / "real_dampers.toml")
    return build(sc, tmp_path_factory.mktemp("fmu") / "car"), sc


@pytest.fixture(scope="module")
def engine(tmp_path_factory):
    """The built-in car with the issue's engine on mounts (SPEC §11, 9 DOF)."""
    sc = rideid.default_scenario()
    sc = dataclasses.replace(sc, truth={**sc.truth, **ENGINE}, extensions=("powertrain",))
    return build(sc, tmp_path_factory.mktemp("fmu") / "car"), sc


def short_run(sc, run_id, duration=SHORT):
    """The first ``duration`` seconds of a run: the run, its times and ``rideid simulate``'s ten channels."""
    (run,) = [dataclasses.replace(r, duration=duration) for r in sc.runs if r.id == run_id]
    data, _ = simulate_manifest(dataclasses.replace(sc, runs=[run]))
    t, Yref = data[run.id]
    assert np.sqrt(np.mean(Yref[:, 4:8] ** 2, axis=0)).min() > 0.1  # the axles move: the errors mean something
    return run, t, Yref


def worst(Y, Yref):
    """The worst channel of each group (body, axle, gyros): RMS(difference) / RMS(channel)."""
    e = relative(Y, Yref)
    return {g: float(np.nanmax(e[s])) for g, s in GROUPS.items()}


@needs_cc
@pytest.mark.parametrize("which", ["linear", "curves", "engine"])
def test_both_interfaces_in_one_fmu_its_variables_unchanged(which, request):
    fmu, sc = request.getfixturevalue(which)
    assert validate_fmu(fmu) == []
    md = read_model_description(fmu)
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier == "car"
    assert float(md.defaultExperiment.tolerance) == TOLERANCE
    nq = 9 if which == "engine" else 7
    assert md.numberOfContinuousStates == 2 * nq and md.numberOfEventIndicators == 0
    v = md.modelVariables
    # the variables of the co-simulation FMU first, as they were (names, value references, causality), the
    # states and their derivatives after them: no index, name or value reference of before moves
    n_out = 14 if which == "engine" else 10
    n_old = 8 + n_out + len([p for p in v if p.causality == "parameter"])
    assert [p.name for p in v[:8]] == list(INPUTS) and [p.valueReference for p in v[:8]] == list(range(8))
    outs = list(CHANNELS) + ([o[0] for o in POWERTRAIN_OUTPUTS] if which == "engine" else [])
    assert [p.name for p in v[8:8 + n_out]] == outs and [p.valueReference for p in v[8:8 + n_out]] == list(
        range(8, 8 + n_out))
    pars = v[8 + n_out:n_old]
    assert [p.name for p in pars[:len(FMU_NAMES)]] == list(FMU_NAMES) and pars[-1].name == "lift_off"
    assert [p.valueReference for p in pars[:-1]] == list(range(100, 100 + len(pars) - 1))
    states, ders = v[n_old:n_old + 2 * nq], v[n_old + 2 * nq:]
    assert len(ders) == 2 * nq and all(p.causality == "local" for p in states + ders)
    assert [p.valueReference for p in states] == list(range(VR_STATE0, VR_STATE0 + 2 * nq))
    assert [p.valueReference for p in ders] == list(range(VR_DER0, VR_DER0 + 2 * nq))
    assert [d.derivative for d in ders] == states and [d.name for d in ders] == [f"der({s.name})" for s in states]
    # ModelStructure: every derivative, in the states' order; der(q) = q' depends on the state q' alone
    assert [u.variable for u in md.derivatives] == ders
    assert [u.dependencies for u in md.derivatives[:nq]] == [[s] for s in states[nq:]]
    assert {u.variable.name for u in md.initialUnknowns} == set(outs) | {p.name for p in states + ders}


def open_me(fmu, road0, parameters=None):
    """A Model Exchange instance initialised on the road ``road0`` (8 inputs), in continuous-time mode; parameters
    ``{name: value}`` set before."""
    md = read_model_description(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = FMU2Model(guid=md.guid, unzipDirectory=unzipped(fmu), modelIdentifier="car", instanceName="car")
    s.instantiate()
    for n, value in (parameters or {}).items():
        s.setReal([vr[n]], [value])
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setReal(list(range(8)), list(road0))
    s.exitInitializationMode()
    s.newDiscreteStates()
    s.enterContinuousTimeMode()
    return md, s


def unzipped(fmu):
    """The FMU extracted once, beside it (in the test's temporary folder)."""
    folder = Path(fmu).parent / "unzipped"
    if not folder.is_dir():
        extract(fmu, unzipdir=str(folder))
    return str(folder)


def ptr(a):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@needs_cc
def test_model_exchange_equilibrium_and_derivatives_in_closed_form(linear):
    """A road lifted 10 mm under all four wheels lifts the car rigidly: z = z_i = 10 mm, no pitch or roll, every
    derivative and output 0. Wheel fl displaced by 1 mm from there, all at rest: its acceleration is
    -(k_tf + k_sf + k_arf) / m_uf per metre (tire, spring and the bar against the wheel held beside it), the
    body's heave acceleration k_sf / m_s (the bar's two ends cancel on the body), the wheel fr's +k_arf / m_uf."""
    fmu, sc = linear
    p = {**car_from_scenario(sc).values, "k_arf": 15000.0}  # a front bar, set as the tunable parameter it is
    md, s = open_me(fmu, [0.01] * 4 + [0.0] * 4, {"k_arf": p["k_arf"]})
    x, dx = np.zeros(14), np.zeros(14)
    s.getContinuousStates(ptr(x), 14)
    assert np.allclose(x[[0, 3, 4, 5, 6]], 0.01, rtol=0, atol=1e-12) and np.allclose(x[[1, 2, *range(7, 14)]], 0,
                                                                                     atol=1e-12)
    s.getDerivatives(ptr(dx), 14)
    assert np.abs(dx).max() < 1e-9
    assert np.abs(s.getReal(list(range(8, 18)))).max() < 1e-9
    d = 1e-3
    x[3] += d
    s.setContinuousStates(ptr(x), 14)
    s.getDerivatives(ptr(dx), 14)
    assert dx[:7] == pytest.approx(np.zeros(7), abs=1e-15)
    assert dx[7 + 3] == pytest.approx(-(p["k_tf"] + p["k_sf"] + p["k_arf"]) * d / p["m_uf"], rel=1e-12)
    assert dx[7 + 4] == pytest.approx(p["k_arf"] * d / p["m_uf"], rel=1e-12)
    assert dx[7 + 0] == pytest.approx(p["k_sf"] * d / p["m_s"], rel=1e-12)
    # the outputs read the same state: axle fl's acceleration is the wheel's, and der() reads the derivatives
    assert s.getReal([12])[0] == pytest.approx(dx[10], rel=1e-12)
    assert s.getReal(list(range(VR_DER0, VR_DER0 + 14))) == pytest.approx(list(dx), rel=1e-12)
    s.terminate()
    s.freeInstance()


@needs_cc
def test_model_exchange_lift_off_and_bump_stop_in_closed_form(curves):
    """The car with curves, bump stops and lift-off, at rest. The road under wheel fl dropped 0.2 m: the tire
    cannot pull, the wheel falls with the static load it carried, -L_fl / m_uf (L_fl = m_s g b / (2 l) + m_uf g),
    and nothing else moves yet. Wheel fl and the road under it raised 10 mm past the bump stop's clearance: the
    stop adds rate x 10 mm to the spring's force on the body and on the wheel (the tire at its static load)."""
    fmu, sc = curves
    car = car_from_scenario(sc)
    p, g, bs = car.values, car.geometry, car.bump_stops
    G = 9.80665  # standard gravity (m/s^2), the FMU's gravity parameter
    md, s = open_me(fmu, [0.0] * 8)
    x, dx = np.zeros(14), np.zeros(14)
    s.getContinuousStates(ptr(x), 14)
    assert np.abs(x).max() < 1e-12
    s.setReal([0], [-0.2])
    s.getDerivatives(ptr(dx), 14)
    L_fl = p["m_s"] * G * (g.wheelbase - p["a"]) / (2 * g.wheelbase) + p["m_uf"] * G
    assert dx[7 + 3] == pytest.approx(-L_fl / p["m_uf"], rel=1e-12)
    assert np.abs(np.delete(dx, 10)).max() < 1e-12
    d = bs["bs_clear_f"] + 0.01
    x[3] = d
    s.setContinuousStates(ptr(x), 14)
    s.setReal([0], [d])
    s.getDerivatives(ptr(dx), 14)
    F = p["k_sf"] * d + bs["bs_rate_f"] * 0.01
    bar = p.get("k_arf", 0.0) * d
    assert dx[7 + 3] == pytest.approx(-(F + bar) / p["m_uf"], rel=1e-12)
    assert dx[7 + 0] == pytest.approx(F / p["m_s"], rel=1e-12)
    s.terminate()
    s.freeInstance()


@needs_cc
@pytest.mark.parametrize("which, run_id", [("linear", "H_LH"), ("curves", "W_H")])
def test_model_exchange_under_a_continuous_master_matches_simulate(which, run_id, request):
    """A master that sets the exact road (``RunInput.inputs_at``) at every time it evaluates the FMU: classical RK4
    at 20 steps a sample, the time, the states and the inputs set at each stage (written here, not rideid's
    integrator): the outputs at the samples within 5e-5 of each channel's RMS of ``rideid simulate`` (measured:
    2.9e-6 on the herringbone, the linear car; 2.3e-5 on the washboard, the car with curves and stops, where it is
    rideid simulate's own step)."""
    fmu, sc = request.getfixturevalue(which)
    run, t, Yref = short_run(sc, run_id)
    sub = 20
    h = (t[1] - t[0]) / sub
    grid = t[0] + np.arange(2 * (t.size - 1) * sub + 1) * (h / 2)  # the steps' ends and midpoints
    r, rd = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t).inputs_at(grid)
    road = np.hstack([r, rd])
    md, s = open_me(fmu, road[0])
    x, dx = np.zeros(14), np.zeros(14)
    s.getContinuousStates(ptr(x), 14)
    state = x.copy()

    def at(j, st):
        s.setTime(float(grid[j]))
        x[:] = st
        s.setContinuousStates(ptr(x), 14)
        s.setReal(list(range(8)), list(road[j]))

    def f(j, st):
        at(j, st)
        s.getDerivatives(ptr(dx), 14)
        return dx.copy()

    Y = np.empty_like(Yref)
    for n in range((t.size - 1) * sub + 1):
        j = 2 * n
        if n % sub == 0:
            at(j, state)
            Y[n // sub] = s.getReal(list(range(8, 18)))
        if j + 2 < grid.size:
            k1 = f(j, state)
            k2 = f(j + 1, state + h / 2 * k1)
            k3 = f(j + 1, state + h / 2 * k2)
            k4 = f(j + 2, state + h * k3)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    s.terminate()
    s.freeInstance()
    assert max(worst(Y, Yref).values()) < 5e-5, worst(Y, Yref)


def docs_table(text, heading):
    """docs/export.md's table under ``heading``: ``{master: {group: bound}}`` (percent or plain numbers)."""
    block = text.split(heading, 1)[1].split("\n\n", 2)[1]
    out = {}
    for line in block.splitlines()[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        out[cells[0]] = {g: float(re.sub(r"[ %]", "", c)) / (100 if "%" in c else 1)
                         for g, c in zip(GROUPS, cells[1:])}
    return out


#: the masters of the default test: label in docs/export.md's short-run table, driver, points per sample
SHORT_MASTERS = {
    "ME, FMPy CVode, 1 sample": (lambda f, *a: by_simulate_fmu(f, *a, "ModelExchange"), 1),
    "ME, FMPy CVode, 1/20 sample": (lambda f, *a: by_simulate_fmu(f, *a, "ModelExchange"), 20),
    "ME, FMPy Euler, 1/20 sample": (lambda f, *a: by_simulate_fmu(f, *a, "ModelExchange", "Euler"), 20),
    "ME, set then get (RK4), 1 sample": (me_set_then_get, 1),
    "ME, set then get (RK4), 1/20 sample": (me_set_then_get, 20),
    "CS, FMPy, 1/20 sample": (by_simulate_fmu, 20),
    "CS, set then get, 1 sample": (cs_set_then_get, 1),
}


@needs_cc
@pytest.mark.parametrize("which, run_id", [("linear", "H_LH"), ("curves", "W_H"), ("engine", "H_HH")])
def test_each_master_on_a_short_stretch_as_documented(which, run_id, request):
    """The first second of a herringbone (the hardest road) or washboard run, each master: within the bounds of
    docs/export.md's short-stretch table, and at 20 points per sample within 1e-4 of each channel's RMS in both
    interfaces (Euler, first order, excepted)."""
    fmu, sc = request.getfixturevalue(which)
    bounds = docs_table((ROOT / "docs" / "export.md").read_text(), "**The first second of a run**")
    assert set(bounds) == set(SHORT_MASTERS)
    run, t, Yref = short_run(sc, run_id)
    for how, (drive, sub) in SHORT_MASTERS.items():
        w = worst(drive(fmu, t, *fine_road(sc, run, t, sub)), Yref)
        for g, b in bounds[how].items():
            assert w[g] <= b, (how, g, w)
        if sub == 20 and "Euler" not in how:
            assert max(w.values()) <= 1e-4, (how, w)


@needs_cc
def test_co_simulation_outputs_recomputed_when_inputs_set_after_a_step(linear):
    """Read at a step's end before the inputs there are set, the outputs are the FMU's prediction of the road
    (which misses on the herringbone: > 1 % on the axles); set the inputs and read again: they are those of a
    master that sets before it reads, to the last bit, and so is the state the next step starts from."""
    fmu, sc = linear
    run, t, _ = short_run(sc, "H_LH", 0.5)
    r, rdot = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t).inputs_at(t)
    md = read_model_description(fmu)
    pair = []
    for name in ("early", "late"):
        s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped(fmu), modelIdentifier="car", instanceName=name)
        s.instantiate()
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.setReal(list(range(8)), list(np.r_[r[0], rdot[0]]))
        s.exitInitializationMode()
        pair.append(s)
    early, late = pair
    vout = list(range(8, 18))
    first, second, ref = [], [], []
    for k in range(t.size):
        u = list(np.r_[r[k], rdot[k]])
        if k:
            first.append(early.getReal(vout))      # before the inputs at t[k] are set: a prediction
        early.setReal(list(range(8)), u)
        second.append(early.getReal(vout))         # after: recomputed
        late.setReal(list(range(8)), u)
        ref.append(late.getReal(vout))
        assert early.getReal(list(range(VR_STATE0, VR_STATE0 + 14))) == late.getReal(
            list(range(VR_STATE0, VR_STATE0 + 14)))
        if k + 1 < t.size:
            for s in pair:
                s.doStep(float(t[k]), float(t[k + 1] - t[k]))
    assert np.array_equal(np.array(second), np.array(ref))
    first, ref = np.array(first), np.array(ref)[1:]
    assert relative(first, ref)[4:8].max() > 0.01  # the prediction missed: the recomputation mattered
    for s in pair:
        s.terminate()
        s.freeInstance()


@pytest.mark.slow
@needs_cc
def test_docs_table_over_the_built_in_runs(linear):
    """docs/export.md's table of every master over the built-in scenario's ten runs (the worst channel of each
    group over the runs), as ``benchmarks/fmu_masters.py`` measures it: each bound holds (several minutes)."""
    from fmu_masters import masters
    fmu, sc = linear
    bounds = docs_table((ROOT / "docs" / "export.md").read_text(), "**Every master over the built-in runs**")
    data, _ = simulate_manifest(sc)
    drivers = masters(fmu)
    assert set(bounds) == set(drivers)
    for how, (drive, sub) in drivers.items():
        for run in sc.runs:
            t, Yref = data[run.id]
            w = worst(drive(t, *fine_road(sc, run, t, sub)), Yref)
            for g, b in bounds[how].items():
                assert w[g] <= b, (how, run.id, g, w)
