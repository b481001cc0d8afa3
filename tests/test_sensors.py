"""Sensors as wired (SPEC §11): the sensor chain's filters, the samples left out at a channel's range.

The filters are checked against an independent continuous-time simulation
(:func:`scipy.signal.lsim` of the analog Butterworth at 1/32 of a sample);
the cost with a chain against the plain NumPy sum over the filtered outputs;
bad ``[channels]`` keys through the command line. The identifications on
sensor-chain data (an independent lsim high-pass, numpy clipping) are in the
slow pass (``RIDEID_SLOW=1``).
"""

from __future__ import annotations

import shutil
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

sys.path.insert(0, str(Path(__file__).parent))

from rideid.model.equations import CHANNELS  # noqa: E402
from rideid.model.sensors import AnalogFilter, SensorChain, discretise  # noqa: E402

FS = 200.0
H = 1 / FS
HUBS = ("axle_az_fl", "axle_az_fr", "axle_az_rl", "axle_az_rr")


def _lsim(filt, signal, T, fine=8):
    """The analog filter on the continuous ``signal(t)`` by lsim at ``H / fine``, read at the samples."""
    from scipy.signal import lsim
    tf = np.arange(int(round(T * FS * fine)) + 1) * H / fine
    y = lsim(filt.analog_ss(), signal(tf), tf)[1]
    return y[::fine]


def _chain(filt, h=H):
    return SensorChain(((filt,),) + ((),) * 9, h)


def _smooth(t):
    """Sines from 0.3 to 17 Hz under a raised-cosine onset: at rest before t = 0, like a run's pre-roll."""
    f, a, p = [0.3, 1.1, 3.7, 11.0, 17.0], [1.0, 0.5, 0.8, 0.4, 0.3], [0.1, 1.0, 2.0, 0.5, 1.5]
    s = sum(ai * np.sin(2 * np.pi * fi * t + pi) for fi, ai, pi in zip(f, a, p))
    return s * np.where(t < 1, 0.5 - 0.5 * np.cos(np.pi * np.clip(t, 0, 1)), 1.0)


FILTERS = [AnalogFilter("highpass", 0.5, 1), AnalogFilter("highpass", 0.5, 2), AnalogFilter("highpass", 0.5, 8),
           AnalogFilter("lowpass", 40.0, 4), AnalogFilter("lowpass", 80.0, 8)]


@pytest.mark.parametrize("filt", FILTERS, ids=lambda f: f.describe())
def test_first_order_hold_is_exact_for_a_signal_linear_between_samples(filt):
    """The discretisation's claim: exact when the continuous signal is the straight line between samples
    (lsim interpolates its input linearly too, at 1/8 of a sample here)."""
    rng = np.random.default_rng(5)
    T = 2.0
    t = np.arange(int(T * FS) + 1) * H
    u = np.concatenate([[0.0], rng.standard_normal(t.size - 1)])  # at rest at the first sample

    def signal(tt):
        return np.interp(tt, t, u)

    ref = _lsim(filt, signal, T)
    Y = np.zeros((t.size, 10))
    Y[:, 0] = u
    got = _chain(filt).apply(Y)[:, 0]
    assert np.max(np.abs(got - ref)) < 1e-7 * np.max(np.abs(ref))  # rounding: 2e-8 for the 8th order


@pytest.mark.parametrize("filt", FILTERS, ids=lambda f: f.describe())
def test_smooth_signal_against_a_fine_step_continuous_filter(filt):
    """On a smooth signal the error is the linear interpolation's, integrated by the filter: measured
    2.2e-4 (high-pass 0.5 Hz, order 1) to 1.2e-3 (order 8) of the peak with content to 17 Hz at 200 Hz,
    4-5e-3 for the low-passes; it falls as h^2 (a quarter at 400 Hz)."""
    T = 4.0
    errs = []
    for fs in (FS, 2 * FS):
        h = 1 / fs
        t = np.arange(int(T * fs) + 1) * h
        from scipy.signal import lsim
        fine = 32 if fs == FS else 16
        tf = np.arange(int(round(T * FS * 32)) + 1) * H / 32
        ref = lsim(filt.analog_ss(), _smooth(tf), tf)[1][::fine]
        Y = np.zeros((t.size, 10))
        Y[:, 3] = _smooth(t)
        got = SensorChain(((),) * 3 + ((filt,),) + ((),) * 6, h).apply(Y)[:, 3]
        errs.append(np.max(np.abs(got - ref)) / np.max(np.abs(ref)))
    tol = 2e-3 if filt.kind == "highpass" else 1e-2
    assert errs[0] < tol
    assert 3.0 < errs[0] / errs[1] < 5.0  # second order in h


def test_initial_state_and_gains():
    """A run at rest gives 0 through any chain; a constant held from before the record passes a low-pass
    and is removed by a high-pass (the steady state at the first sample); a sine far above a high-pass's
    corner passes with the analog filter's gain and phase."""
    t = np.arange(2000) * H
    hp, lp = AnalogFilter("highpass", 0.5, 2), AnalogFilter("lowpass", 30.0, 4)
    Y = np.zeros((3, t.size, 10))
    Y[1] = 2.5
    Y[2, :, 0] = np.sin(2 * np.pi * 8.0 * t)
    chain = SensorChain(((hp, lp),) + ((lp,),) + ((),) * 8, H)
    out = chain.apply(Y)
    assert np.array_equal(out[0], np.zeros_like(out[0]))
    assert np.max(np.abs(out[1, :, 0])) < 1e-9          # high-pass then low-pass: the constant removed
    assert np.max(np.abs(out[1, :, 1] - 2.5)) < 1e-9    # low-pass: kept
    assert np.array_equal(out[1, :, 2:], Y[1, :, 2:])   # unfiltered channels as they are
    # steady state of the 8 Hz sine, compared with the analog response (the hold's sinc^2 gain: 1 - (w h)^2/12)
    Hc = complex(hp.response(8.0)[0] * lp.response(8.0)[0])
    tail = t > 5.0
    ref = np.abs(Hc) * np.sin(2 * np.pi * 8.0 * t[tail] + np.angle(Hc))
    hold = 1 - (2 * np.pi * 8.0 * H) ** 2 / 12
    assert np.max(np.abs(out[2, tail, 0] - hold * ref)) < 2e-3


def test_modal_form_matches_the_state_space_response():
    """The modal form is the discrete state space itself: their frequency responses agree to rounding,
    for an 8th-order filter whose hold-equivalent zeros span four decades."""
    from scipy.signal import cont2discrete
    filt = AnalogFilter("lowpass", 80.0, 8)
    A, B, C, D = filt.analog_ss()
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, D), H, method="foh")
    m = discretise(filt, H)
    for w in (0.01, 0.5, 2.0, 3.0):
        z = np.exp(1j * w)
        ss = (Cd @ np.linalg.solve(z * np.eye(8) - Ad, Bd) + Dd)[0, 0]
        modal = m.d + np.sum(m.c * m.g / (z - m.lam))
        assert abs(ss - modal) < 1e-10


def test_at_range_and_the_model_samples_it_reaches():
    from rideid.data.measured import at_range, clipped_samples
    v = np.array([0.0, 4.0, 5.0, 5.0, 3.0, -5.0, -2.0, 5.0])
    assert at_range(v, 5.0).tolist() == [False, False, True, True, False, True, False, True]
    # detected: 3 or more samples at the maximum make it the rail; every sample at it is clipped
    w = np.array([0.0, 1.0, 2.0, 2.0, 2.0, 1.0, 2.0, -1.0])
    assert at_range(w).tolist() == [False, False, True, True, True, False, True, False]
    assert not at_range(np.array([0.0, 2.0, 2.0, 1.0])).any()  # two at the extreme: a peak, not a rail
    # same clock: exactly the clipped samples; a coarser model clock: the samples a clipped one touches
    tf = np.arange(10) * 0.001
    tc = tf[[3, 4]]
    assert np.nonzero(clipped_samples(tf, tc, 0.001))[0].tolist() == [3, 4]
    tm = np.arange(5) * 0.0025
    assert clipped_samples(tm, tc, 0.001).tolist() == [False, True, False, False, False]


# ---------------------------------------------------------------------------------------------------
# the cost on a dataset with a sensor chain

def _logger_dataset(sim_dataset, tmp_path, channels):
    d = tmp_path / "ds"
    shutil.copytree(sim_dataset, d)
    doc = tomllib.loads((d / "dataset.toml").read_text())
    doc["channels"] = channels
    for r in doc["runs"]:
        r["start"] = 0.0  # SPEC CSVs: time 0 is the start
        r["pre_roll"] = 0.0
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    return d


def test_cost_with_a_chain_is_the_sum_over_filtered_outputs(sim_dataset, tmp_path):
    """Through the kernels' outputs mode and the batched filter, the errors equal the NumPy sum of the
    chain applied to each candidate's outputs, over the kept samples only; a dataset without a chain keeps
    the kernels' errors mode (the simulator is the plain bound one)."""
    import rideid
    from rideid.model.batch import BatchSimulator
    from rideid.model.sensors import SensorSimulator

    plain = rideid.CostFunction(rideid.load_dataset(sim_dataset))
    assert isinstance(plain.sim, BatchSimulator) and plain.keep is None

    d = _logger_dataset(sim_dataset, tmp_path, {"axle_az_fl": {"highpass": {"hz": 0.5, "order": 2}},
                                                "body_az_rr": {"lowpass": 60.0, "range": 1.0}})
    ds = rideid.load_dataset(d)
    cf = rideid.CostFunction(ds)
    assert isinstance(cf.sim, SensorSimulator) and cf.keep is not None
    assert 0 < (cf.keep == 0).sum() and np.all(cf.keep[:, [i for i, c in enumerate(CHANNELS) if c != "body_az_rr"]])
    rng = np.random.default_rng(2)
    lo, hi = cf.bounds.T
    X = lo + (hi - lo) * (0.4 + 0.2 * rng.random((3, len(cf.names))))
    E = cf.run_errors(X)
    outs = plain.sim.outputs(cf.space.full(X))
    hp, lp = AnalogFilter("highpass", 0.5, 2), AnalogFilter("lowpass", 60.0, 1)
    for ri in range(len(cf.run_ids)):
        s, e = cf.sim.run_start[ri], cf.sim.run_start[ri + 1]
        o = outs[ri].copy()
        from scipy.signal import cont2discrete, lfilter
        for c, f in (("axle_az_fl", hp), ("body_az_rr", lp)):
            # an independent route: the hold-equivalent state space stepped by lfilter on its transfer function
            A, B, C, D = f.analog_ss()
            Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, D), cf.sim.runs[ri].h, method="foh")
            from scipy.signal import ss2tf
            b, a = ss2tf(Ad, Bd, Cd, Dd)
            i = CHANNELS.index(c)
            o[:, :, i] = lfilter(b[0], a, o[:, :, i], axis=1)  # at rest at the first sample: zero state
        diff = (o - cf.Y[None, s:e]) * cf.keep[None, s:e]
        ref = np.einsum("ntq,q->n", diff ** 2, cf.W[ri])
        np.testing.assert_allclose(E[ri], ref, rtol=1e-7)
    # residuals: zero where a sample is left out, and their squares sum to the cost
    R = cf.residuals(X[:1])
    np.testing.assert_allclose(np.sum(R ** 2), cf(X[:1])[0], rtol=1e-9)


# ---------------------------------------------------------------------------------------------------
# bad input through the command line

BAD_CHANNELS = {
    "negative_hz": ({"axle_az_fl": {"highpass": -0.5}}, "[channels] axle_az_fl highpass: expected a corner frequency"),
    "zero_hz": ({"axle_az_fl": {"lowpass": {"hz": 0.0, "order": 2}}}, "[channels] axle_az_fl lowpass: expected"),
    "order_9": ({"axle_az_fl": {"highpass": {"hz": 0.5, "order": 9}}},
                "[channels] axle_az_fl highpass order: expected an integer from 1 to 8, got 9"),
    "order_0": ({"axle_az_fl": {"highpass": {"hz": 0.5, "order": 0}}}, "highpass order: expected an integer"),
    "hz_missing": ({"axle_az_fl": {"highpass": {"order": 2}}}, "[channels] axle_az_fl highpass: missing key 'hz'"),
    "filter_text": ({"axle_az_fl": {"highpass": "0.5 Hz"}}, "[channels] axle_az_fl highpass: expected"),
    "range_zero": ({"axle_az_fl": {"range": 0.0}}, "[channels] axle_az_fl range: expected the sensor's full scale"),
    "range_negative": ({"axle_az_fl": {"range": -5.0}}, "[channels] axle_az_fl range: expected"),
    "speed_filter": ({"speed": {"name": "v", "highpass": 0.5}}, "[channels] speed highpass: highpass is for"),
}


@pytest.mark.parametrize("case", list(BAD_CHANNELS))
def test_bad_sensor_keys(case, sim_dataset, tmp_path, capsys):
    from rideid.cli import main
    channels, msg = BAD_CHANNELS[case]
    d = _logger_dataset(sim_dataset, tmp_path, channels)
    out = tmp_path / "fit"
    rc = main(["identify", str(d), "--out", str(out), "--quiet"])
    _, err = capsys.readouterr()
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rideid: error: "), err
    assert msg in lines[0], lines[0]
    assert "Traceback" not in err and not out.exists()


def test_quality_table_replaces_the_per_run_warnings(sim_dataset, tmp_path, capsys):
    """A hub sensor declared with a range its signal reaches: the terminal shows one data-quality table (the
    clipped share per channel) and no per-run clipping line; result.json keeps the table and the fit leaves
    those samples out."""
    import json

    from rideid.cli import main
    d = _logger_dataset(sim_dataset, tmp_path, {"axle_az_fl": {"range": 30.0}, "axle_az_rr": {"highpass": 0.5}})
    out = tmp_path / "fit"
    rc = main(["identify", str(d), "--out", str(out), "--quiet", "--no-report", "--generations", "2",
               "--population", "8", "--no-polish", "--model", "base"])
    stdout, err = capsys.readouterr()
    assert rc == 0, err
    assert "clipped:" not in err and "data quality (10 runs):" in stdout
    row = next(line for line in stdout.splitlines() if line.startswith("axle_az_fl"))
    doc = json.loads((out / "result.json").read_text())
    q = doc["data_quality"]["channels"]
    share = q["axle_az_fl"]["clipped_share"]
    print(stdout)
    assert 0 < share < 0.5 and f"{100 * share:.2f}%" in row
    assert q["axle_az_rr"]["filters"] == ["high-pass 0.5 Hz, order 1"] and not q["axle_az_rr"]["clipped_runs"]
    # the same share from the data themselves: the SPEC CSV's samples at |a| >= 30 m/s^2
    import rideid
    ds = rideid.load_dataset(d)
    worst = max(float(np.mean(np.abs(ds.data[r.id].channels["axle_az_fl"]) >= 30.0)) for r in ds.runs)
    assert share == pytest.approx(worst, abs=1e-12)


# ---------------------------------------------------------------------------------------------------
# identification on sensor-chain data (independent lsim high-pass, numpy clipping): slow




def _identify_case(folder, **kw):
    import warnings

    import rideid
    from sensor_case import write_sensor_dataset
    write_sensor_dataset(folder, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the washboard runs' roll rate is exactly 0: flat-lined
        ds = rideid.load_dataset(folder)
    return ds, rideid.identify(ds, seed=1)


def _score(res):
    import rideid
    truth = rideid.default_scenario().truth
    errs = {n: res.parameters[n] / truth[n] - 1 for n in rideid.NAMES}
    covered = sum(abs(res.parameters[n] - truth[n]) <= 2 * res.details[n]["std_robust"] for n in rideid.NAMES)
    return errs, covered


@pytest.mark.slow
def test_declared_ac_coupling_gives_the_car(tmp_path):
    """Four IEPE hub sensors coupled at 0.5 Hz, declared: the twelve within 1 % (measured 0.025 %), +-2
    std_robust covering at least 10 (measured 12), the base model kept, adequate, no hint (100 s)."""
    ds, res = _identify_case(tmp_path / "hp", highpass=(HUBS, 0.5, 1))
    errs, covered = _score(res)
    assert max(abs(e) for e in errs.values()) < 0.01, errs
    assert covered >= 10
    assert res.model["extensions"] == [] and res.adequacy["adequate"]
    assert res.adequacy["sensor_hints"] == []
    assert all(q["filters"] == ["high-pass 0.5 Hz, order 1"] for c, q in res.data_quality["channels"].items()
               if c in HUBS)


@pytest.mark.slow
def test_undeclared_ac_coupling_is_named(tmp_path):
    """The same data without the declaration: the base fit is off by percents (measured: k_sf -2.0 %,
    c_sf -2.2 %) and not adequate, and the hint names the four hub channels and the key (60 s)."""
    import warnings

    import rideid
    from sensor_case import write_sensor_dataset
    write_sensor_dataset(tmp_path / "hp", highpass=(HUBS, 0.5, 1), declare=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = rideid.load_dataset(tmp_path / "hp")
    res = rideid.identify(ds, seed=1, model="base")
    errs, _ = _score(res)
    assert max(abs(e) for e in errs.values()) > 0.01 and not res.adequacy["adequate"]
    hints = res.adequacy["sensor_hints"]
    assert sorted(h["channel"] for h in hints) == sorted(HUBS)
    assert all(0.1 <= h["highpass_hz"] <= 1.0 and h["rss_reduction"] > 0.5 for h in hints)
    assert "[channels] axle_az_fl = { ..., highpass =" in next(h["message"] for h in hints
                                                                if h["channel"] == "axle_az_fl")
    assert res.adequacy["advice"].startswith(hints[0]["message"])


@pytest.mark.slow
def test_clipping_hub_sensor_is_left_out(tmp_path):
    """One hub sensor clipping at +-5 g, detected (no range declared: the defaults): the samples at the rail
    are left out, the twelve within 1 % (measured 0.03 %), +-2 std_robust covering at least 10, adequate;
    the data-quality table gives the clipped shares numpy counts in the files (100 s)."""
    ds, res = _identify_case(tmp_path / "clip", clip=("axle_az_fl", 5.0), declare_range=False)
    errs, covered = _score(res)
    assert max(abs(e) for e in errs.values()) < 0.01, errs
    assert covered >= 10 and res.adequacy["adequate"]
    q = res.data_quality["channels"]["axle_az_fl"]
    assert set(q["clipped_runs"]) == {"H_HH", "W_H"}
    for rid, share in q["clipped_runs"].items():
        y = ds.data[rid].channels["axle_az_fl"]
        assert share == pytest.approx(float(np.mean(np.abs(y) >= 5.0 * 9.80665 * (1 - 1e-9))), abs=1e-12)


def test_clipping_advice_names_the_clipped_flagged_pairs():
    """The not-adequate advice names the flagged run/channel pairs whose channel clipped, with their shares;
    nothing when the flagged pairs did not clip or the model is adequate."""
    from types import SimpleNamespace

    from rideid.estimate.assess.sensor_check import clipping_advice
    rec = {"channels": {"axle_az_fl": {"clipped": {"samples": 41, "share": 0.041}}, "body_az_fl": {}}}
    ds = SimpleNamespace(measured={"W_H": SimpleNamespace(record=rec)})
    flagged = {"adequate": False, "runs": {"W_H": {"axle_az_fl": {"structure": True},
                                                   "body_az_fl": {"structure": True}}}}
    text = clipping_advice(ds, flagged)
    assert text.startswith("Flagged pairs whose sensor clipped: W_H/axle_az_fl (4.1 % of its samples at the range).")
    assert "body_az_fl" not in text
    other = {"adequate": False, "runs": {"W_H": {"axle_az_fl": {"structure": False},
                                                 "body_az_fl": {"structure": True}}}}
    assert clipping_advice(ds, other) is None
    assert clipping_advice(ds, {**flagged, "adequate": True}) is None


def test_start_estimate_sees_the_declared_chain(tmp_path):
    """The nominal car's start estimate correlates the data with its response through the declared chain:
    one twist run with its hub sensors AC-coupled (an independent lsim) gives the true start (2.3 s of file
    time) within 0.05 ms declared (measured 0.014 ms); read as if unfiltered it is off by a sample's
    fraction (measured 4.4 ms early), which is what the chain's phase does to the correlation."""
    import warnings

    import rideid
    from sensor_case import OFFSET, write_sensor_dataset
    starts = {}
    for declare in (True, False):
        d, _ = write_sensor_dataset(tmp_path / str(declare), highpass=(HUBS, 0.5, 1), declare=declare,
                                    runs=("T_LL",))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            starts[declare] = rideid.load_dataset(d).measured["T_LL"].start - OFFSET
    assert abs(starts[True]) < 5e-5
    assert starts[False] < -1e-3
