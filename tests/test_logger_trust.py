"""Logger files with estimated starts are as trustworthy as simulated CSVs (issue: a 2.1 t SUV).

The path users take: accelerations in g with gravity and bias, gyros in
deg/s, own column names, a standing lead-in, starts not given
(:mod:`logger_case`). Before the model moved instead of the data, every
estimated start came out 1.0-1.65 ms late (interpolating noisy samples at a
fractional offset smooths their noise, and the cost preferred that), with
unsprung masses and tire rates 8-12 % off at |z| up to 20.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import rideid
from logger_case import LEAD, suv_scenario, write_logger
from rideid.data.measured import _filter_resample
from rideid.data.readers import Signal
from rideid.estimate.assess.adequacy import assess_fit


def _identify(folder, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = rideid.load_dataset(folder)
        return ds, rideid.identify(ds, seed=1, **kw)


def _z(res, truth):
    return {n: (res.parameters[n] - truth.get(n, 0.0)) / res.details[n]["std_robust"] for n in res.names}


def test_estimated_starts_are_unbiased_and_the_car_within_its_error_bars(tmp_path):
    sc = suv_scenario(tmp_path)
    ds, res = _identify(write_logger(sc, tmp_path / "log", seed=3))
    for rid, st in res.starts.items():
        assert abs(st["value"] - LEAD) < 1e-4, (rid, st["value"] - LEAD)  # within 0.1 ms (was 1.0-1.65 ms late)
    z = _z(res, sc.truth)
    assert max(abs(v) for v in z.values()) < 3.5, z
    assert res.adequacy["adequate"], res.adequacy["reasons"]
    # the data never moved: the samples identify used are the loaded samples, on time axes moved by the starts
    fitted = ds.with_starts(res.starts)
    for rid in res.starts:
        assert np.array_equal(fitted.data[rid].matrix(), ds.data[rid].matrix())
        mr = ds.measured[rid]
        i0, i1 = mr.window
        np.testing.assert_allclose(fitted.data[rid].time, mr.times[i0:i1] - res.starts[rid]["value"], atol=1e-12)


def test_the_full_model_of_a_car_without_bars_finds_zeros_and_keeps_the_starts(tmp_path):
    """``--model full`` on logger files of a car whose bars and tire damping are truly 0 (issue 37: a van).

    The polish (dogbox) stopped after one step beside a bound: a Gauss-Newton step had left an extension
    a rounding error above 0, dogbox cut every step to that distance and ended on ``xtol``; the next round
    of start alignment found no start moved and called them settled. The twist runs' starts stayed
    1.9-6.1 ms late, the dampers 13 % off, bars of 760 N/m and tire damping of 130 N s/m were "found",
    and the verdict was "not adequate".
    """
    sc = suv_scenario(tmp_path, bars=False)
    assert not any(n in sc.truth for n in ("k_arf", "k_arr", "c_tf", "c_tr"))
    ds, res = _identify(write_logger(sc, tmp_path / "log", noise=0.01, seed=1), model="full")
    assert res.model["extensions"] == ["anti_roll_bars", "tire_damping"]
    for rid, st in res.starts.items():
        assert abs(st["value"] - LEAD) < 1e-4, (rid, st["value"] - LEAD)  # within 0.1 ms (was up to 6.1 ms late)
    err = {n: res.parameters[n] / v - 1.0 for n, v in sc.truth.items()}
    assert max(abs(e) for e in err.values()) < 2e-3, err  # within 0.2 % (c_sf was 13 % off)
    ext = {n: res.parameters[n] for n in ("k_arf", "k_arr", "c_tf", "c_tr")}
    assert max(ext["k_arf"], ext["k_arr"]) < 50.0 and max(ext["c_tf"], ext["c_tr"]) < 10.0, ext  # zeros
    z = _z(res, sc.truth)
    assert max(abs(v) for v in z.values()) < 3.5, z
    assert res.adequacy["adequate"], res.adequacy["reasons"]
    assert res.polish["success"]


def _sine(t, f=7.0):
    return np.sin(2 * np.pi * f * t) + 0.3 * np.cos(2 * np.pi * 2.3 * t)


def test_a_channel_at_the_model_rate_keeps_its_own_samples_and_upsampling_keeps_the_gain():
    t200 = np.arange(2000) / 200.0
    t100 = np.arange(1000) / 100.0
    raw = {"body_az_fl": Signal(t200, _sine(t200), "m/s^2"), "pitch_rate": Signal(t100, _sine(t100), "rad/s")}
    rec = {c: {} for c in raw}
    ch, _ = _filter_resample(raw, rec, list(raw), 200.0)
    # at the model rate: the samples themselves (SciPy's polyphase filter had put a gain of 1.00065 on them)
    assert np.array_equal(ch["body_az_fl"].samples(0.0, 200.0, t200.size), raw["body_az_fl"].values)
    # a 100 Hz gyro read at 200 Hz: band-limited, gain within 1e-5 away from the ends
    inner = slice(200, -200)
    y, x = ch["pitch_rate"](t200)[inner], _sine(t200)[inner]
    assert abs(float(y @ x / (x @ x)) - 1.0) < 1e-5
    assert "upsampled" in rec["pitch_rate"] and "upsampled" not in rec["body_az_fl"]


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_auto_judges_the_kept_candidate_at_its_own_final_starts(tmp_path):
    """The kept candidate's adequacy is computed at its own parameters and the starts its own polish
    settled, not at the starts the nested fit began from (which gave false 'not adequate')."""
    sc = suv_scenario(tmp_path, extensions=None)
    ds, res = _identify(write_logger(sc, tmp_path / "log", seed=5, ar1=0.9), model="auto")
    assert res.model["extensions"] == ["anti_roll_bars"]
    assert res.adequacy["adequate"], res.adequacy["reasons"]
    space = rideid.ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=("anti_roll_bars",))
    cf = rideid.CostFunction(ds.with_starts(res.starts), space=space)
    P = space.full(np.array([[res.parameters[n] for n in cf.names]]))[0]
    again = assess_fit(cf, P)
    assert again["adequate"] == res.adequacy["adequate"]
    for rid, chans in again["runs"].items():
        for c, fig in chans.items():
            assert fig["input_f"] == pytest.approx(res.adequacy["runs"][rid][c]["input_f"], rel=1e-9), (rid, c)


def _study(tmp_path, seeds, ar1):
    sc = suv_scenario(tmp_path / f"sc{ar1}")
    rows = []
    for seed in seeds:
        _, res = _identify(write_logger(sc, tmp_path / f"log{ar1}_{seed}", seed=seed, ar1=ar1))
        rows.append(res)
    return sc, rows


@pytest.mark.slow
@pytest.mark.parametrize("ar1", [0.0, 0.9])
def test_suv_logger_study_unbiased_honest_and_near_the_crlb(tmp_path, ar1):
    """Twenty noise seeds: starts within 0.1 ms, no bias, spread within 1.5x the plan's CRLB,
    ±2 std_robust covering at least 90 % of the estimates."""
    sc, rows = _study(tmp_path, range(20), ar1)
    names = rows[0].names
    for res in rows:
        for rid, st in res.starts.items():
            assert abs(st["value"] - LEAD) < 1e-4, (rid, st["value"] - LEAD)
    est = np.array([[r.parameters[n] for n in names] for r in rows])
    truth = np.array([sc.truth[n] for n in names])
    n = len(rows)
    mean_err = est.mean(axis=0) - truth
    sem = est.std(axis=0, ddof=1) / math.sqrt(n)
    assert np.all(np.abs(mean_err) < 3 * sem), dict(zip(names, mean_err / sem))
    z = np.array([[v for v in _z(r, sc.truth).values()] for r in rows])
    assert np.mean(np.abs(z) <= 2) >= 0.9, np.mean(np.abs(z) <= 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = rideid.plan(sc, noise=0.02, noise_ar1=ar1)
    crlb = {nm: p.all_runs.rel_crlb[j] * abs(p.all_runs.x0[j]) for j, nm in enumerate(p.names)}
    spread = est.std(axis=0, ddof=1)
    ratio = {nm: spread[j] / crlb[nm] for j, nm in enumerate(names) if nm in crlb}
    # a sample std over 20 seeds: its own 95 % band is about 0.69-1.31 of the true spread
    assert max(ratio.values()) < 1.5, ratio


@pytest.mark.slow
@pytest.mark.expensive
def test_adequacy_false_alarm_rate_on_model_exact_logger_data(tmp_path):
    """The verdict calibrated on the path users take: logger files of a car that is exactly the
    model (the SUV with bars, fitted with bars), 200 Hz files and 400 Hz files resampled to 200 Hz,
    white and AR(1) 0.9 noise, starts estimated. 50 seeds each: at most 2 % 'not adequate'."""
    alarms, total = [], 0
    for fs in (200.0, 400.0):
        sc = suv_scenario(tmp_path / f"sc{fs:g}", fs=fs)
        for ar1 in (0.0, 0.9):
            for seed in range(50):
                folder = write_logger(sc, tmp_path / f"log{fs:g}_{ar1}_{seed}", seed=seed, ar1=ar1, model_fs=200.0)
                _, res = _identify(folder)
                total += 1
                if not res.adequacy["adequate"]:
                    alarms.append((fs, ar1, seed, res.adequacy["reasons"][0]))
    assert len(alarms) <= 0.02 * total, alarms
