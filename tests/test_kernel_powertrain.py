"""The compiled kernel's 12-state specialisation (a powertrain on mounts, SPEC §11) against the NumPy modal
recursion and the reference loop; bit for bit across thread counts and population orders; the 8-state kernel
unchanged; ``RIDEID_KERNEL=numpy`` still the NumPy path."""

import hashlib

import numba
import numpy as np
import pytest
from powertrain_car import ENGINE

import rideid
from rideid.model import kernel_ir
from rideid.model.batch import BatchSimulator
from rideid.model.kernel_layout import LAYOUTS, n_coef
from rideid.model.params import INDEX, as_vector
from rideid.model.simulate import prepare_run

#: sha256 of the 8-state kernel's IR (opaque pointers, typed pointers) as it was before the symmetric block's
#: size became a parameter: the car without a powertrain is compiled from the very same IR
IR_8_SHA256 = {True: "f117b0fe210e4166f77330fa78944bfd3b9913e350efce23cd07c8898ca3a07c",
               False: "6844ac3ff420a9fe9cbe8a0eed6ffa200c4ccaf4deabc1e3706614097125a0e9"}


@pytest.fixture(scope="module")
def case():
    """Three short runs of the built-in tracks (twist and herringbone at 200 Hz, the washboard at 500 Hz: two
    sample-rate groups) and seven cars with a powertrain: engines ahead of and behind the CG (x_p < 0), tire
    damping and anti-roll bars on some, one row without a powertrain (m_p = 0) in the batch."""
    sc = rideid.default_scenario()
    G = sc.geometry
    runs = []
    for rid, fs, dur in (("T_LH", 200.0, 1.5), ("H_LH", 200.0, 1.2), ("W_H", 500.0, 0.6)):
        r = next(x for x in sc.runs if x.id == rid)
        runs.append(prepare_run(sc.tracks[r.track], G, r.speed, np.arange(int(dur * fs) + 1) / fs))
    car = as_vector({**{k: sc.truth[k] for k in rideid.NAMES}, **ENGINE}, extended=True)
    rng = np.random.default_rng(11)
    P = np.tile(car, (7, 1))
    P[:, :12] *= np.exp(rng.normal(0, 0.15, (7, 12)))
    P[:, INDEX["x_p"]] = [1.2, -0.4, 0.3, -1.1, 0.8, 0.0, 1.5]
    P[:, INDEX["m_p"]] = [180.0, 120.0, 240.0, 150.0, 0.0, 200.0, 90.0]
    P[:, INDEX["f_pb"]] *= np.exp(rng.normal(0, 0.2, 7))
    P[:, INDEX["f_pp"]] *= np.exp(rng.normal(0, 0.2, 7))
    P[:, INDEX["zeta_pp"]] = [0.1, 0.05, 0.3, 0.15, 0.1, 0.2, 0.08]
    P[[1, 3, 6], INDEX["c_tf"]] = [150.0, 300.0, 80.0]
    P[[1, 3, 6], INDEX["c_tr"]] = [120.0, 250.0, 60.0]
    P[[2, 3], INDEX["k_arf"]] = [8000.0, 15000.0]
    P[[2, 3], INDEX["k_arr"]] = [4000.0, 6000.0]
    sim = BatchSimulator(G, runs, numpy=False)
    modal = sim.outputs_modal(P)
    Y = np.concatenate([o[0] for o in modal]) + rng.normal(0, 0.05, (sim.n_samples, 10))
    W = rng.random((len(runs), 10))
    return sim, P, modal, Y, W


def test_the_powertrain_population_runs_compiled_and_matches_the_numpy_paths(case):
    """Outputs and weighted errors of the 12-state kernel equal the modal recursion's (the NumPy backend of a
    powertrain) and the reference loop's to 1e-12 of each run's largest channel value (8e-14, 2e-14 measured) for
    seven cars (not a multiple of the four lanes), x_p both signs, over two sample rates."""
    sim, P, modal, Y, W = case
    assert sim._pack(P[:4])[2].shape == (3, 18, 4)  # 12 + 6 states into the kernel
    out = sim.outputs(P)
    ref = sim.outputs_reference(P)
    for o, m, r in zip(out, modal, ref):
        assert o.shape == m.shape == (7,) + m.shape[1:]
        assert np.abs(o - m).max() <= 1e-12 * np.abs(m).max()  # 8e-14 measured (the modal path's own)
        assert np.abs(o - r).max() <= 1e-12 * np.abs(r).max()  # 2e-14 measured
    # the powertrain matters: the rigid car's channels differ by percent
    rigid = sim.outputs(P[:1, :16])[0][0]
    assert np.abs(rigid - out[0][0]).max() > 1e-2 * np.abs(out[0][0]).max()
    err = sim.errors(P, Y, W)
    np.testing.assert_allclose(err, sim._errors_of(modal, P, Y, W), rtol=1e-11)  # 2e-13 measured
    np.testing.assert_allclose(err, sim.errors_reference(P, Y, W), rtol=1e-12)  # 5e-15 measured
    assert err.shape == (3, 7) and np.all(err > 0)


def test_the_powertrain_kernel_is_bit_identical_across_threads_and_orders(case):
    """Every candidate's numbers do not depend on the thread count or on where in the population it sits."""
    sim, P, _, Y, W = case
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        e1, o1 = sim.errors(P, Y, W), sim.outputs(P)
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        e2, o2 = sim.errors(P, Y, W), sim.outputs(P)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(e1, e2) and all(np.array_equal(a, b) for a, b in zip(o1, o2))
    perm = np.array([4, 6, 0, 2, 5, 1, 3])
    ep, op = sim.errors(P[perm], Y, W), sim.outputs(P[perm])
    assert np.array_equal(ep, e1[:, perm]) and all(np.array_equal(a, b[perm]) for a, b in zip(op, o1))


def test_numpy_backend_of_a_powertrain_is_the_modal_recursion(case, monkeypatch):
    """``RIDEID_KERNEL=numpy``: the powertrain population never reaches the compiled kernel and gives the modal
    recursion's numbers exactly."""
    sim, P, modal, Y, W = case
    numpy_sim = BatchSimulator(sim.geom, sim.runs)  # follows RIDEID_KERNEL

    def refuse(*a, **k):
        raise AssertionError("the compiled kernel ran")

    monkeypatch.setenv("RIDEID_KERNEL", "numpy")
    monkeypatch.setattr(numpy_sim, "_call", refuse)
    assert all(np.array_equal(a, b) for a, b in zip(numpy_sim.outputs(P), modal))
    assert np.array_equal(numpy_sim.errors(P, Y, W), sim._errors_of(modal, P, Y, W))


def test_the_8_state_kernel_is_unchanged_and_the_12_state_one_its_specialisation():
    """The car without a powertrain is compiled from the same IR as before (its hash); the 12-state
    specialisation is the same writer with four more states: 18 state vectors, the larger layout."""
    for opaque, sha in IR_8_SHA256.items():
        assert hashlib.sha256(kernel_ir.generate_ir(opaque=opaque).encode()).hexdigest() == sha
    ir12 = kernel_ir.generate_ir(opaque=True, ns=12)
    assert "define void @rideid_kernel_run_12(" in ir12 and "%x17 = phi" in ir12 and "%x18 " not in ir12
    # per lane: Phi_s, Ca_s, Da_s, Dr_s, Phi_a, Ca_a, Da_a, Dr_a, a, b; then G_s and G_a per term
    assert LAYOUTS[8][1:] == (64 + 32 + 8 + 8 + 36 + 18 + 6 + 6 + 2, 16 + 12)
    assert LAYOUTS[12][1:] == (144 + 48 + 8 + 8 + 36 + 18 + 6 + 6 + 2, 24 + 12)
    assert n_coef(12) == 276 + 36 * 24
