"""Every filter rideid applies to a logger's data, its model sees: the default rate divides the file's rate,
a channel it does not divide is low-passed and its model channel passes the same filter, and each is recorded.

The reference filter is SciPy's continuous simulation (:func:`scipy.signal.lsim`) of the analog Butterworth
on a fine clock, not rideid's discretisation; the known signal is a sum of sines written as a 500 Hz logger CSV.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.signal import butter, lsim

from rideid.data.quality import resampled_runs
from rideid.estimate.assess.sensor_check import rate_advice
from rideid.data.measured import FILTER_CUTOFF, FILTER_ORDER, default_rate, load_measured_run, uniform_clock
from rideid.data.schema.manifest import load_manifest
from rideid.model.equations import CHANNELS
from rideid.model.sensors import AnalogFilter, SensorChain

T_END = 3.0
#: the known signal: components (Hz, amplitude) well inside 0.4 fs of a 200 Hz model
PARTS = ((2.0, 1.0), (7.0, 0.5), (13.0, 0.2))


def _signal(t):
    """The known signal, starting from rest (a smooth ramp in over the first 0.5 s)."""
    ramp = np.clip(t / 0.5, 0.0, 1.0) ** 3
    return ramp * sum(a * np.sin(2 * np.pi * f * t) for f, a in PARTS)


def _logger(folder, fs_file=500.0, preprocess=""):
    """A 500 Hz logger file of the known signal on every channel (m/s^2 and rad/s), and its dataset.toml."""
    t = np.arange(int(round(T_END * fs_file)) + 1) / fs_file
    y = _signal(t)
    (folder / "runs").mkdir(parents=True, exist_ok=True)
    names = [f"ch{i}" for i in range(len(CHANNELS))]
    rows = ["t," + ",".join(names)] + [f"{ti:.9f}," + ",".join([f"{yi:.12g}"] * len(names)) for ti, yi in zip(t, y)]
    (folder / "runs" / "R.csv").write_text("\n".join(rows) + "\n")
    chans = "\n".join(f'{c} = {{ name = "{n}" }}' for c, n in zip(CHANNELS, names))
    (folder / "dataset.toml").write_text(f"""name = "rates"
[vehicle]
wheelbase = 2.7
track_front = 1.55
track_rear = 1.54
tire_radius = 0.3
[known]
total_mass = 1480.0
[channels]
time = {{ name = "t", unit = "s" }}
{chans}
[preprocess]
{preprocess}
[[tracks]]
id = "flat"
kind = "flat"
[[runs]]
id = "R"
track = "flat"
speed = 5.0
start = 0.5
file = "runs/R.csv"
""")
    man = load_manifest(folder / "dataset.toml")
    return t, y, load_measured_run(man.runs[0], man)


@pytest.mark.parametrize("rates, fs", [([300.0], 300.0), ([500.0], 250.0), ([1000.0], 200.0), ([200.0], 200.0),
                                       ([100.0], 100.0), ([1000.0, 500.0], 250.0), ([2048.0], 204.8),
                                       ([300.0, 500.0], 300.0)])
def test_the_default_rate_is_the_lowest_whole_division_at_or_above_200_hz(rates, fs):
    got, rule = default_rate(rates)
    assert got == pytest.approx(fs, rel=1e-12)
    for r in rates:  # every rate a whole multiple, but 500 Hz beside 300 Hz (no common division >= 200 Hz)
        q = r / got
        assert (abs(q - round(q)) < 1e-9) == (rates != [300.0, 500.0] or r == 300.0)
    assert ("cubic spline" in rule) == (rates == [300.0, 500.0])


def test_time_stamps_rounded_to_seven_digits_are_a_uniform_clock_not_a_jittered_one():
    t = np.arange(3500) / 300.0
    assert uniform_clock(np.array([float(f"{x:.7g}") for x in t])) == pytest.approx(1 / 300.0, rel=1e-8)
    jitter = t + np.random.default_rng(1).normal(0, 0.05 / 300.0, t.size)  # 5 % of a sample: jittered
    assert uniform_clock(jitter) is None


def test_a_500_hz_logger_is_read_at_250_hz_by_taking_every_second_sample(tmp_path):
    t, y, mr = _logger(tmp_path)
    assert mr.fs == 250.0
    # the file's own samples, bit for bit (no filter, no interpolation), on every channel
    np.testing.assert_array_equal(mr.values[:, 0], np.array([float(f"{v:.12g}") for v in y[::2]]))
    rec = mr.record["resampling"]
    assert rec["fs"] == 250.0 and rec["filters"] == [] and set(rec["decimated"].values()) == {2}
    assert "500 Hz / 2" in rec["rule"]
    assert mr.chain_filters() == ((),) * len(CHANNELS)  # nothing for the model to pass either
    # nothing filtered to blame
    assert resampled_runs({"R": mr}) == {}
    assert rate_advice(SimpleNamespace(resampled=resampled_runs({"R": mr})), _flagged()) is None


def _flagged():
    """A not-adequate verdict that flags run R's body_az_fl."""
    return {"adequate": False, "runs": {"R": {"body_az_fl": {"structure": True}, "pitch_rate": {"structure": False}}}}


def test_at_200_hz_by_default_a_500_hz_file_is_read_off_by_the_spline_and_warned_of(tmp_path):
    """fs = 200 on a 500 Hz file: no filter (the model could not reproduce one at 200 Hz); every other model
    sample is a file sample, the ones between are the cubic spline's; a warning names the rate that divides."""
    with pytest.warns(UserWarning, match=r"no whole multiple of the model's 200 Hz, so read off between its samples "
                                         r"by a cubic spline.*set \[preprocess\] fs = 250"):
        t, y, mr = _logger(tmp_path, preprocess="fs = 200")
    assert mr.chain_filters() == ((),) * len(CHANNELS)
    (rec,) = mr.record["resampling"]["filters"]
    assert (rec["kind"], rec["model"], rec["channels"]) == ("cubic spline", False, list(CHANNELS))
    file_values = np.array([float(f"{v:.12g}") for v in y])
    np.testing.assert_allclose(mr.values[::2, 0], file_values[::5], rtol=0, atol=1e-12)  # 0, 10 ms, ...: samples
    mid = mr.values[1::2, 0]  # 5 ms, 15 ms, ...: between two file samples
    exact = _signal(mr.times[1::2])
    assert 1e-9 < float(np.max(np.abs(mid - exact))) < 2e-4 * float(np.max(np.abs(y)))  # the spline's own error
    advice = rate_advice(SimpleNamespace(resampled=resampled_runs({"R": mr})), _flagged())
    assert "R (500 Hz read at 200 Hz)" in advice and "set [preprocess] fs = 250" in advice


def test_with_anti_alias_the_data_and_the_model_pass_the_same_low_pass(tmp_path):
    """fs = 200 and anti_alias = true on a 500 Hz file: the data are low-passed (Butterworth, order 8, 80 Hz,
    causal), the model's chain gets that filter; each side against SciPy's continuous simulation of it."""
    with pytest.warns(UserWarning, match=r"low-passed at 80 Hz for the model's 200 Hz \(anti_alias = true\).*"
                                         r"leave anti_alias out and set fs = 250"):
        t, y, mr = _logger(tmp_path, preprocess="fs = 200\nanti_alias = true")
    assert mr.fs == 200.0
    corner = FILTER_CUTOFF * 200.0
    filt = AnalogFilter("lowpass", corner, FILTER_ORDER)
    assert mr.chain_filters() == ((filt,),) * len(CHANNELS)
    (rec,) = mr.record["resampling"]["filters"]
    assert (rec["kind"], rec["hz"], rec["order"], rec["model"]) == ("lowpass", 80.0, 8, True)
    assert rec["channels"] == list(CHANNELS)
    # the reference: the analog Butterworth driven by the continuous signal, simulated at 20 kHz
    z, p, k = butter(FILTER_ORDER, 2 * math.pi * corner, analog=True, output="zpk")
    tf = np.arange(int(T_END * 20000) + 1) / 20000.0
    _, ref, _ = lsim((z, p, k), _signal(tf), tf)
    n = mr.times.size
    ref200 = np.interp(mr.times, tf, ref)
    peak = float(np.max(np.abs(ref)))
    # the data side: filtered at 500 Hz, read off at 200 Hz
    data_err = float(np.max(np.abs(mr.values[:, 0] - ref200)))
    # the model side: the instantaneous signal at 200 Hz through the run's chain
    model = SensorChain(mr.chain_filters(), 1.0 / mr.fs).apply(np.repeat(_signal(mr.times)[:, None], 10, axis=1))
    model_err = float(np.max(np.abs(model[:, 0] - ref200)))
    assert data_err < 2e-3 * peak, data_err / peak
    assert model_err < 1e-2 * peak, model_err / peak
    # unfiltered, the model would miss the filter's delay and gain by far more than either side errs
    assert float(np.max(np.abs(_signal(mr.times) - ref200))) > 5 * max(data_err, model_err)
    assert n == int(T_END * 200) + 1
    # a flagged pair on a channel so filtered: the advice names the run, its rates and the rate that divides
    advice = rate_advice(SimpleNamespace(resampled=resampled_runs({"R": mr})), _flagged())
    assert "R (500 Hz read at 200 Hz)" in advice and "set [preprocess] fs = 250" in advice
    assert rate_advice(SimpleNamespace(resampled=resampled_runs({"R": mr})), {**_flagged(), "adequate": True}) is None


@pytest.mark.slow  # 84-105 s per rate on two quiet cores, 6-10 min shared (4.9 min in all): make test-slow, not CI
@pytest.mark.expensive
@pytest.mark.parametrize("fs_file, fs_model", [(300.0, 300.0), (500.0, 250.0), (1000.0, 200.0)])
def test_a_van_with_real_dampers_logged_at_300_500_or_1000_hz_is_identified_with_the_defaults(
        tmp_path, fs_file, fs_model):
    """The van of ``tests/rate_case.py`` (digressive dampers, bump stops, a CG height; 1 % noise) as its logger
    writes it at ``fs_file``, identified with every default: the twelve within 1 %, and adequate."""
    import sys
    import warnings
    from pathlib import Path

    import rideid
    from rideid.model.params import NAMES
    sys.path.insert(0, str(Path(__file__).parent))
    from rate_case import write_van_logger

    folder = write_van_logger(tmp_path, fs_file)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = rideid.load_dataset(folder)
    assert {ds.measured[r.id].fs for r in ds.runs} == {fs_model}
    assert all(not ds.measured[r.id].record["resampling"]["filters"] for r in ds.runs)
    res = rideid.identify(ds, seed=1)
    sc = rideid.score(res, rideid.load_truth(tmp_path / "sim" / "truth.toml"),
                      dampers=rideid.load_truth_dampers(tmp_path / "sim" / "truth.toml"))
    worst = max(abs(sc["parameters"][n]["error_percent"]) for n in NAMES
                if sc["parameters"][n]["status"] in ("estimated", "derived"))
    assert worst < 1.0, sc["parameters"]
    assert res.adequacy["adequate"], res.adequacy["reasons"]
