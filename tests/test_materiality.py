"""Materiality (SPEC §12): structure in the residuals that moves no estimate by more than its std_total is
immaterial; structure that does, or that is everywhere, keeps the model not adequate."""

import numpy as np
import pytest

import rideid
from rideid.estimate.assess import materiality as mt


class _FakeCost:
    """Names, and a ``without_pairs`` that records what was left out."""

    def __init__(self, names):
        self.names = list(names)
        self.left_out = None

    def without_pairs(self, pairs):
        other = _FakeCost(self.names)
        other.left_out = list(pairs)
        return other


def _adequacy(flags):
    """An adequacy record: run -> {channel: structure?}."""
    return {"adequate": not any(v for rec in flags.values() for v in rec.values()),
            "reasons": ["the road input explains part of the residual", "whiteness"],
            "runs": {r: {c: {"structure": v} for c, v in rec.items()} for r, rec in flags.items()}}


def test_weigh_measures_the_shift_in_std_total_and_decides():
    """The largest |without - all| / std_total decides against MATERIAL_SHIFT; std_robust stands in where a
    parameter has no std_total; a parameter the reduced data leave undetermined, or structure in most pairs,
    is material without a comparison."""
    cf = _FakeCost(["k_sf", "c_sf", "m_uf"])
    details = {"k_sf": {"std_total": 100.0, "std_robust": 50.0}, "c_sf": {"std_robust": 2.0},
               "m_uf": {"std_total": 0.5}}
    flags = {"A": {"x": True, "y": False, "z": False}, "B": {"x": False, "y": False, "z": False}}
    x_all = np.array([30000.0, 2000.0, 40.0])

    def polish(c, x0, moved=(80.0, -1.0, 0.2), std=(1.0, 1.0, 1.0)):
        if c.left_out is None:
            return x_all, np.ones(3)
        assert c.left_out == [("A", "x")]
        return x_all + np.array(moved), np.array(std)

    rec = mt.weigh(cf, x_all, details, _adequacy(flags), polish)
    assert rec["shifts"] == pytest.approx({"k_sf": 0.8, "c_sf": 0.5, "m_uf": 0.4})
    assert not rec["material"] and rec["largest_shift"]["parameter"] == "k_sf"
    assert rec["pairs_left_out"] == ["A/x"]
    big = mt.weigh(cf, x_all, details, _adequacy(flags), lambda c, x0: polish(c, x0, moved=(80.0, -2.5, 0.2)))
    assert big["material"] and big["largest_shift"]["parameter"] == "c_sf"
    assert big["largest_shift"]["in_std_total"] == pytest.approx(1.25)
    lost = mt.weigh(cf, x_all, details, _adequacy(flags), lambda c, x0: polish(c, x0, std=(1.0, np.inf, 1.0)))
    assert lost["material"] and "c_sf" in lost["reason"]
    most = {"A": {"x": True, "y": True, "z": True}, "B": {"x": True, "y": False, "z": False}}
    everywhere = mt.weigh(cf, x_all, details, _adequacy(most), lambda c, x0: pytest.fail("no refit"))
    assert everywhere["material"] and "4 of 6" in everywhere["reason"]
    v = mt.verdict(_adequacy(flags), rec)
    assert v["adequate"] and v["structure"] and v["materiality"] is rec
    assert v["reasons"][0].startswith("road-driven structure in 1 run/channel pairs (A/x)")


@pytest.fixture(scope="module")
def suv(tmp_path_factory):
    from cars import suv_scenario
    return suv_scenario(tmp_path_factory.mktemp("suv"))


def _fit(sc, data, folder, model="base"):
    from cars import SUV_TRUTH
    from rideid.synth.scenario import write_dataset
    write_dataset(sc, data, folder)
    ds = rideid.load_dataset(folder)
    names = rideid.CostFunction(ds).names
    return rideid.identify(ds, model=model, start=[SUV_TRUTH[n] for n in names], seed=1)


def _with_sensor_defect(clean, run, channel, corner_hz, gain):
    """``clean`` with one channel of one run reading ``gain`` x its own content above ``corner_hz`` on top (a
    sensor mount's resonance: road-driven, and nothing the car model can make)."""
    from scipy import signal
    out = {rid: (t, y.copy()) for rid, (t, y) in clean.items()}
    t, y = out[run]
    b, a = signal.butter(4 if corner_hz > 40 else 2, corner_hz, "highpass", fs=1 / (t[1] - t[0]))
    c = rideid.CHANNELS.index(channel)
    y[:, c] += gain * signal.lfilter(b, a, y[:, c])
    return out


@pytest.mark.slow
def test_structure_that_moves_nothing_is_immaterial_and_a_spreading_one_widens_the_error_bars(suv, tmp_path):
    """The SUV (2 % noise, base model, polished from the truth) with one hub accelerometer of one run reading
    its own content above 60 Hz twice (a mount resonance far above the car's modes): the residual test flags
    that pair; without it no estimate moves by more than 0.4 std_total, so the model is adequate, the pair
    named, and every estimate is within 2 std_robust of the truth. Above 30 Hz at 0.3x the same defect
    reaches the wheel hop: the fit bends to it (the structure spreads to other pairs) and the runs disagree
    beyond their noise; with that in std_robust (between runs) the shift is within the error bar and so is
    the truth. (Without the between-runs share the same case was material: c_sf moved 3.9 std_total, the
    truth 3.8 std_robust away; the decision rule itself is tested above.)

    Measured (seed 5): 60 Hz: 1 pair, largest shift c_sf 0.37, truth within 1.8 std_robust; 30 Hz: 3 pairs,
    c_sf std_robust 9.9 N s/m (the sandwich's 2.4), shift 0.93 std_total, every truth within 2.06 std_total."""
    from cars import SUV_TRUTH, add_noise, simulate_car

    clean = simulate_car(suv)
    res = _fit(suv, add_noise(_with_sensor_defect(clean, "H_HH", "axle_az_fl", 60.0, 1.0), 0.02, 0.0, seed=5),
               tmp_path / "hf")
    ad = res.adequacy
    assert ad["structure"] and ad["adequate"] and ad["advice"] is None, ad["reasons"]
    assert ad["materiality"]["pairs_left_out"] == ["H_HH/axle_az_fl"]
    assert ad["materiality"]["largest_shift"]["in_std_total"] < 0.5
    assert ad["reasons"][0].startswith("road-driven structure in 1 run/channel pairs (H_HH/axle_az_fl)")
    z = {n: abs(res.parameters[n] - SUV_TRUTH[n]) / res.details[n]["std_robust"] for n in res.names}
    assert max(z.values()) < 2.0, z

    # above 30 Hz at 0.3x the defect reaches the wheel hop: the fit bends to it and the structure spreads to
    # other pairs; the runs then disagree beyond their noise, which widens c_sf's std_robust (the between-runs
    # share), and within that wider error bar leaving the pairs out moves nothing and the truth is covered
    bad = _fit(suv, add_noise(_with_sensor_defect(clean, "H_HH", "axle_az_fl", 30.0, 0.3), 0.02, 0.0, seed=5),
               tmp_path / "wheelhop")
    ad = bad.adequacy
    assert "H_HH/axle_az_fl" in ad["materiality"]["pairs_left_out"] and len(ad["materiality"]["pairs_left_out"]) > 1
    c = bad.details["c_sf"]
    assert c["std_between_runs"] > 2 * c["std_hac"]
    z = {n: abs(bad.parameters[n] - SUV_TRUTH[n]) / bad.details[n]["std_total"] for n in bad.names}
    assert ad["adequate"] == (ad["materiality"]["largest_shift"]["in_std_total"] <= mt.MATERIAL_SHIFT)
    assert max(z.values()) < 2.5, z  # the verdict and the error bars agree


def test_the_two_refits_run_side_by_side_and_give_the_same_numbers_on_one_or_two_cores(tmp_path, default_scenario,
                                                                                         both_cores):
    """The materiality's two polishes (all pairs, and without the flagged ones) are independent and run on two
    threads (rideid.model.batch.thread_map); with the kernel limited to one thread (a study's worker,
    rideid.model.backend.one_thread) they run one after the other. The built-in car's runs with 2 % noise (seed
    1), polished from its truth, one hub pair flagged: the record is the same to the last bit either way, and
    leaving that pair out moves c_sf most, by 0.05-0.1 std_total (measured 0.064; the stage's wall time in
    docs/performance.md)."""
    from dataclasses import replace

    from rideid.model import backend
    from rideid.synth.scenario import simulate_manifest, write_dataset

    data, _ = simulate_manifest(default_scenario, noise=0.02, seed=1)
    write_dataset(default_scenario, data, tmp_path / "ds")
    ds = rideid.load_dataset(tmp_path / "ds")
    names = rideid.CostFunction(ds).names
    res = rideid.identify(ds, model="base", start=[default_scenario.truth[n] for n in names], seed=1)
    first = ds.runs[0].id
    flags = {r.id: {c: (r.id == first and c == "axle_az_fl") for c in rideid.CHANNELS} for r in ds.runs}
    flagged = replace(res, adequacy={**_adequacy(flags), "advice": None})
    two = mt.weigh_result(ds, flagged).adequacy["materiality"]
    with backend.one_thread():
        one = mt.weigh_result(ds, flagged).adequacy["materiality"]
    assert two["pairs_left_out"] == [f"{first}/axle_az_fl"]
    assert one == two  # floats compared exactly
    shift = two["largest_shift"]
    assert shift["parameter"] == "c_sf" and 0.05 < shift["in_std_total"] < 0.1 and two["material"] is False, shift
