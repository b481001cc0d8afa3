"""The simulator as a value (rideid.model.simulator): one value, passed to every stage; evaluations never
change it, so cost functions, threads and model candidates share it safely."""

import dataclasses
import numpy as np
import pytest

import rideid
from rideid.errors import ArgumentError
from rideid.estimate.problem.cost import CostFunction, ParameterSpace
from rideid.estimate.fit.identify import identify as identify_model
from rideid.model.batch import BatchSimulator, single_threaded_blas, thread_map
from rideid.model.nonlinear import DEFAULT_KNOTS, NonlinearLayout, NonlinearSimulator
from rideid.model.params import DEFAULT_CAR, DEFAULT_GEOMETRY, as_vector
from rideid.model.simulate import prepare_run
from rideid.model.simulator import Simulator

CURVES = NonlinearLayout(knots=tuple(DEFAULT_KNOTS))


def _runs():
    """The built-in twist and herringbone, 3 s each at 200 Hz."""
    tracks = rideid.default_scenario().tracks
    t = np.arange(0, 3.0, 1 / 200)
    return [prepare_run(tracks["twist_high"], DEFAULT_GEOMETRY, 4.0, t),
            prepare_run(tracks["herringbone_high"], DEFAULT_GEOMETRY, 8.0, t)]


def test_the_value_is_frozen_checked_and_names_its_model():
    s = Simulator()
    assert s.layout is None and not s.nonlinear and hash(s) == hash(Simulator())
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.rho = 0.1
    with pytest.raises(ArgumentError, match="backend"):
        Simulator(backend="fortran")
    with pytest.raises(ArgumentError, match="rho"):
        Simulator(rho=0.0)
    # a linear layout is the linear car: one value for one model
    assert Simulator(NonlinearLayout()) == Simulator()
    c = Simulator(CURVES)
    assert c.nonlinear and c.width == 16 + 2 * len(DEFAULT_KNOTS) and c.linear() == Simulator()
    assert isinstance(Simulator().bind(DEFAULT_GEOMETRY, _runs()), BatchSimulator)
    assert isinstance(c.bind(DEFAULT_GEOMETRY, _runs()), NonlinearSimulator)


def test_a_linear_car_as_curves_gives_the_linear_response():
    """``row`` maps a linear car into the curve model (F = c v): the nonlinear integrator then reproduces the
    exact discretisation of the linear car (within the RK4 sub-steps' error: the largest deviation < 1e-3 of
    each channel's RMS; 2.3e-4 measured, a curve in the wrong column or at the wrong scale is off by O(1))."""
    runs = _runs()
    P = as_vector(DEFAULT_CAR)
    c = Simulator(CURVES)
    row = c.row(P)
    assert row.shape == (1, c.width)
    F = row[0, 16:]
    assert np.allclose(F[:len(DEFAULT_KNOTS)], DEFAULT_CAR["c_sf"] * np.array(DEFAULT_KNOTS))
    lin = Simulator().bind(DEFAULT_GEOMETRY, runs).outputs(P[None])
    cur = c.bind(DEFAULT_GEOMETRY, runs).outputs(row)
    for a, b in zip(lin, cur):
        rms = np.sqrt(np.mean(a[0] ** 2, axis=0))
        assert np.all(np.abs(b[0] - a[0]).max(axis=0) < 1e-3 * rms)


def test_an_evaluation_never_changes_the_simulator():
    """A pin is an argument: evaluating with one leaves the simulator's own answers bit for bit as a fresh
    simulator's."""
    runs = _runs()
    c = Simulator(CURVES)
    sim, fresh = c.bind(DEFAULT_GEOMETRY, runs), c.bind(DEFAULT_GEOMETRY, runs)
    P = c.row(as_vector(DEFAULT_CAR))
    pin = sim.pin_at(P, margin=3.0)
    assert all(m >= 3 for m in pin.substeps)
    pinned = sim.outputs(P, pin=pin)
    after = sim.outputs(P)
    ref = fresh.outputs(P)
    for a, b, p in zip(after, ref, pinned):
        assert np.array_equal(a, b)
        assert not np.array_equal(a, p)  # the pin did change that evaluation's integrator


def _curve_dataset(tmp_path):
    """The built-in car with digressive dampers on two short runs, noise-free (SPEC CSV)."""
    from rideid.data.schema import read_toml, write_toml
    from rideid.synth.scenario import simulate_manifest, write_dataset

    doc = read_toml(rideid.default_scenario_path())
    pos = [0.025, 0.05, 0.1, 0.2, 0.4]
    f_pos = [1300 * min(v, 0.1) + 450 * max(v - 0.1, 0) for v in pos]
    doc["dampers"] = {"velocity": [-v for v in reversed(pos)] + pos,
                      "front": [-2 * f for f in reversed(f_pos)] + f_pos,
                      "rear": [-2 * 0.9 * f for f in reversed(f_pos)] + [0.9 * f for f in f_pos]}
    del doc["truth"]["c_sf"], doc["truth"]["c_sr"]
    doc["runs"] = [dict(r, duration=min(r["duration"], 4.0)) for r in doc["runs"] if r["id"] in ("T_HH", "H_HH")]
    write_toml(tmp_path / "sc.toml", doc)
    sc = rideid.load_scenario(tmp_path / "sc.toml")
    data, _ = simulate_manifest(sc, noise=0.002, seed=2)
    write_dataset(sc, data, tmp_path / "ds")
    return rideid.load_dataset(tmp_path / "ds")


def test_two_candidate_models_on_threads_equal_one_after_the_other(tmp_path, both_cores):
    """Two curve models (with and without tire damping) polished from one cost function's simulator on two
    threads give bit for bit the numbers of the same fits one after the other. (Before the simulator was a
    value the polish pinned the shared simulator's sub-steps, and a neighbour's pin leaked into the other
    fit.)"""
    ds = _curve_dataset(tmp_path)
    full = ParameterSpace(ds.known, ds.geometry, extensions=("tire_damping", "damper_curves"))
    cf = CostFunction(ds, space=full)
    spaces = [full, ParameterSpace(ds.known, ds.geometry, extensions=("damper_curves",))]
    base = {**DEFAULT_CAR, "c_tf": 0.0, "c_tr": 0.0}
    # the second starts from stiffer tires: its pin (sub-steps) differs from the first's
    starts = [base, {**base, "k_tf": 1.6 * base["k_tf"], "k_tr": 1.6 * base["k_tr"]}]

    def fit(k):
        space, car = spaces[k], starts[k]
        cost = cf.with_space(space)
        x0 = np.array([car.get(n, np.nan) for n in space.names])
        knots = [i for i, n in enumerate(space.names) if n.startswith("F_")]
        v = space.knot_velocities()
        x0[knots] = np.r_[np.full(len(v) // 2, car["c_sf"]), np.full(len(v) // 2, car["c_sr"])] * v
        res = identify_model(ds, cost=cost, start=x0, assess=False)
        return np.array([res.parameters[n] for n in space.names]), res.polish["cost_after"]

    assert cf.sim.pin_at(Simulator(full.layout).row(as_vector(starts[0]))).substeps != \
        cf.sim.pin_at(Simulator(full.layout).row(as_vector(starts[1]))).substeps
    one_by_one = [fit(k) for k in range(2)]
    # as the model choice fits its candidates: on the kernel's threads, BLAS held at one thread around them
    with single_threaded_blas():
        threaded = thread_map(fit, range(2), "test-candidates")
    for (a, ca), (b, cb) in zip(one_by_one, threaded):
        assert np.array_equal(a, b) and ca == cb
    assert cf.pin is None  # nothing was pinned on the shared cost function either


NO_NUMBA = """
import sys, json, warnings
sys.modules["numba"] = None      # `import numba` raises ImportError, as where the compiled kernels cannot load
sys.modules["llvmlite"] = None
import numpy as np
import rideid
with warnings.catch_warnings(record=True) as w:
    warnings.simplefilter("always")
    ds = rideid.load_dataset(sys.argv[1])
    cf = rideid.CostFunction(ds)
    x0 = cf.space.nominal()
    X = np.array([x0[cf.space.col[n]] for n in cf.names])[None] * np.array([[1.01], [1.03]])
    costs = cf(X)
print(json.dumps({"costs": costs.tolist(), "numba": "numba" in sys.modules and sys.modules["numba"] is not None,
                  "warnings": [str(x.message) for x in w if "could not be built" in str(x.message)]}))
"""


def test_numpy_backend_when_the_compiled_kernels_cannot_be_imported(sim_dataset, tmp_path):
    """With Numba's import failing, loading a dataset (start alignment, checks, the disc envelope) and the
    cost work on the NumPy backends, with one warning, and give the compiled kernels' costs (1e-10)."""
    import json
    import subprocess
    import sys

    short = tmp_path / "short"
    from rideid.data.schema import read_toml, write_toml
    import shutil
    shutil.copytree(sim_dataset, short)
    doc = read_toml(short / "dataset.toml")
    doc["runs"] = doc["runs"][:2]
    write_toml(short / "dataset.toml", doc)
    out = subprocess.run([sys.executable, "-c", NO_NUMBA, str(short)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["numba"] is False and len(got["warnings"]) == 1
    ds = rideid.load_dataset(short)
    cf = rideid.CostFunction(ds)
    x0 = cf.space.nominal()
    X = np.array([x0[cf.space.col[n]] for n in cf.names])[None] * np.array([[1.01], [1.03]])
    np.testing.assert_allclose(got["costs"], cf(X), rtol=1e-10)
    assert np.all(cf(X) > 1e-6)
