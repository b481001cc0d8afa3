"""Measured data (rideid.data.measured, rideid.data.readers): logger files written by the real libraries."""

import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.errors import DataError, DataWarning
from rideid.model.equations import CHANNELS
from rideid.model.params import NAMES

sys.path.insert(0, str(Path(__file__).parent))
from logger_files import (G0, Wobble, channel_map, logger_channels, simulate_raw,  # noqa: E402
                          write_logger_dataset)

OFFSET = 2.3  # the recording starts 2.3 s before the front axle reaches x = 0


def max_error(res, truth):
    return max(abs(res.parameters[n] / truth[n] - 1) for n in NAMES)


def quiet_load(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return rideid.load_dataset(path, **kw)


@pytest.fixture(scope="module")
def raw(default_scenario):
    """The built-in runs on a 1 kHz clock starting 2.3 s before the start."""
    return simulate_raw(default_scenario, offset=OFFSET)


@pytest.fixture(scope="module")
def mdf_dataset(tmp_path_factory, default_scenario, raw):
    return write_logger_dataset(default_scenario, raw, tmp_path_factory.mktemp("mdf") / "ds", "mf4")


# ---------------------------------------------------------------------------
# Round trips: gravity, g, deg/s, a sign flip, 1 kHz / 500 Hz, an unknown 2.3 s start

# 33-48 s each: all three in CI's slow pass (make test under 10 minutes on two cores)
@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["mf4", "tdms", "parquet"])
def test_round_trip_identifies_within_half_percent(fmt, tmp_path, default_scenario, raw, mdf_dataset):
    path = mdf_dataset if fmt == "mf4" else write_logger_dataset(default_scenario, raw, tmp_path / "ds", fmt)
    ds = quiet_load(path)
    pre = ds.preprocessing()
    for rid, rec in pre.items():
        assert rec["start"]["source"] == "estimated (nominal car)"
        assert abs(rec["start"]["value"] - OFFSET) < 1e-4, rid
        ch = rec["channels"]
        assert ch["body_az_fl"]["rate_hz"] == pytest.approx(1000) and ch["axle_az_fl"]["rate_hz"] == pytest.approx(500)
        for c in CHANNELS[:8]:  # gravity (plus a zero bias) removed, in m/s^2 whatever the file's unit and sign
            assert ch[c]["removed"] == pytest.approx(G0, rel=1e-6)
        assert ch["body_az_fr"]["sign"] == -1 and ch["pitch_rate"]["unit"] == "deg/s"
        assert rec["fs"] == 250.0  # 1 kHz and 500 Hz: 1 sample in 4 and in 2, nothing filtered
    res = rideid.identify(ds, seed=1, model="base")
    assert max_error(res, default_scenario.truth) < 5e-3
    for rid, rec in res.preprocessing.items():
        assert abs(rec["start"]["value"] - OFFSET) < 2e-5, rid  # a 250th of a sample after the joint polish
        assert rec["start"]["std"] < 1e-5


def test_csv_with_semicolons_decimal_commas_and_a_units_row_reads_like_mdf(tmp_path, default_scenario, raw,
                                                                          mdf_dataset):
    """Two independent readers (csv module, asammdf) give the same model data."""
    path = write_logger_dataset(default_scenario, raw, tmp_path / "ds", "csv")
    assert (path / "runs" / "T_LL.csv").read_text().splitlines()[1].startswith("s;g;g;g;m/s^2")
    a, b = quiet_load(path), quiet_load(mdf_dataset)
    for r in a.runs:
        assert a.measured[r.id].record["csv"] == {"delimiter": ";", "decimal": ","}
        np.testing.assert_allclose(a.data[r.id].matrix(), b.data[r.id].matrix(), rtol=0, atol=1e-7)
        assert a.measured[r.id].start == pytest.approx(b.measured[r.id].start, abs=1e-7)


@pytest.mark.slow  # 33-57 s: CI's slow pass (make test stays under 10 minutes on 2 cores)
def test_nominal_car_misaligns_and_the_joint_polish_recovers(tmp_path):
    """A 2.45 t van: the built-in nominal car puts starts off by up to ~2 samples; identification fixes them."""
    from conftest import VAN_TRUTH as truth
    from conftest import van_scenario
    sc = van_scenario(tmp_path)
    path = write_logger_dataset(sc, simulate_raw(sc, offset=OFFSET), tmp_path / "ds", "tdms")
    ds = quiet_load(path)
    nominal = {rid: rec["start"]["value"] - OFFSET for rid, rec in ds.preprocessing().items()}
    assert max(abs(v) for v in nominal.values()) > 2e-3  # the nominal car is not the van
    data_before = {rid: rd.matrix() for rid, rd in ds.data.items()}
    res = rideid.identify(ds, seed=1, model="base")
    assert max_error(res, truth) < 5e-3
    for rid, rec in res.preprocessing.items():
        assert abs(rec["start"]["value"] - OFFSET) < 5e-5, rid
        assert rec["start"]["source"] == "estimated with the parameters (least squares)"
        assert rec["start"]["nominal_estimate"] - OFFSET == pytest.approx(nominal[rid])
        assert res.starts[rid]["value"] == rec["start"]["value"] and res.starts[rid]["std"] > 0
    # the dataset it was given is untouched: nominal starts and data as loaded
    assert {rid: rec["start"]["value"] - OFFSET for rid, rec in ds.preprocessing().items()} == nominal
    for rid, Y in data_before.items():
        np.testing.assert_array_equal(ds.data[rid].matrix(), Y)
    # the starts it settled on give the aligned dataset
    aligned = ds.with_starts(res.starts)
    assert all(abs(aligned.measured[rid].start - OFFSET) < 5e-5 for rid in res.starts)


@pytest.mark.parametrize("distance", [False, True])
def test_varying_speed_from_a_speed_or_distance_channel(distance, tmp_path, default_scenario):
    """The driver wobbles +-10 % around the nominal speed; the wheel inputs follow the logged speed."""
    wob = {r.id: Wobble(r.speed, 0.1, 2.0) for r in default_scenario.runs}
    raw = simulate_raw(default_scenario, offset=OFFSET, distance=lambda run: wob[run.id])
    path = write_logger_dataset(default_scenario, raw, tmp_path / "ds", "mf4", wobbles=wob, distance=distance)
    ds = quiet_load(path)
    for r in ds.runs:
        assert r.speed is None
        rec = ds.measured[r.id].record
        assert rec["speed"]["min"] == pytest.approx(0.9 * wob[r.id].v0, rel=2e-3)
        assert rec["speed"]["max"] == pytest.approx(1.1 * wob[r.id].v0, rel=2e-3)
        assert abs(ds.measured[r.id].start - OFFSET) < 1e-4, r.id
        # the distance the model drives equals the wobbling driver's, from the start
        t = ds.data[r.id].time
        np.testing.assert_allclose(ds.data[r.id].distance(t), wob[r.id](t), atol=2e-4)
    if distance:
        return  # same data as the speed channel up to integration: identification shown once
    res = rideid.identify(ds, seed=1, model="base")
    assert max_error(res, default_scenario.truth) < 5e-3


def test_given_start_and_window_skip_the_estimate(tmp_path, default_scenario, raw):
    runs = {"T_LL", "W_H"}
    path = write_logger_dataset(default_scenario, {k: v for k, v in raw.items() if k in runs}, tmp_path / "ds",
                                "mf4", preprocess={"gravity_included": True, "start": OFFSET},
                                runs_extra={"W_H": {"window": [1.0, 4.0]}})
    ds = quiet_load(path)
    assert ds.measured["T_LL"].start == OFFSET
    assert ds.preprocessing()["T_LL"]["start"]["source"] == "given"
    t = ds.data["W_H"].time
    assert t[0] == pytest.approx(1.0 - OFFSET) and t[-1] <= 4.0 - OFFSET + 1e-9
    # model time 0 is file time 2.3: the data at model time t equal the simulation at t
    tr, Yr = raw["W_H"]
    k = np.searchsorted(tr, OFFSET + 0.7)
    i = np.searchsorted(t, 0.7)
    assert t[i] == pytest.approx(0.7)
    np.testing.assert_allclose(ds.data["W_H"].matrix()[i, :8], Yr[k, :8], atol=2e-3 * np.abs(Yr[:, :8]).max())


def test_spec_csv_dataset_is_taken_as_it_is(sim_dataset):
    ds = rideid.load_dataset(sim_dataset)
    assert ds.measured == {}
    rec = ds.preprocessing()["T_LL"]
    assert rec["start"]["value"] == 0.0 and "taken as it is" in rec["format"]


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_report_shows_the_data_section(tmp_path, default_scenario, raw):
    from rideid.cli import main
    path = write_logger_dataset(default_scenario, {k: raw[k] for k in ("T_HH", "H_HH", "W_H")},
                                tmp_path / "ds", "mf4")
    doc = rideid.data.schema.read_toml(path / "dataset.toml")
    doc["known"] = {"total_mass": 1093.3, "I_xx": 207.3, "a": 1.156}  # three runs: help the search a little
    (path / "dataset.toml").write_text(tomli_w.dumps(doc))
    assert main(["identify", str(path), "--out", str(tmp_path / "out"), "--quiet", "--seed", "2",
                 "--generations", "60", "--model", "base"]) == 0  # the data section, not the model choice
    res = json.loads((tmp_path / "out" / "result.json").read_text())
    assert abs(res["preprocessing"]["H_HH"]["start"]["value"] - OFFSET) < 1e-4
    html = (tmp_path / "out" / "report.html").read_text()
    assert 'id="data"' in html and "AccZ_Body_FR" in html and "ASAM MDF" in html
    # re-rendering later uses the starts the identification settled on
    assert main(["report", str(tmp_path / "out")]) == 0


# ---------------------------------------------------------------------------
# Units, readers, options

def test_unit_factors():
    from rideid.data.measured import unit_factor
    assert unit_factor("g", "body_az_fl", "") == G0
    assert unit_factor("deg/s", "roll_rate", "") == pytest.approx(math.pi / 180)
    assert unit_factor("km/h", "speed", "") == pytest.approx(1 / 3.6)
    assert unit_factor("ms", "time", "") == 1e-3
    assert unit_factor("M/S^2", "axle_az_rr", "") == 1.0
    with pytest.raises(DataError, match="unknown unit 'deg/s' for body_az_fl"):
        unit_factor("deg/s", "body_az_fl", "x")


def test_csv_detection_and_explicit_options(tmp_path):
    from rideid.data.readers import CsvOptions, open_signals
    f = tmp_path / "a.csv"
    f.write_text("time\tbody_az_fl\n0\t1.5\n0.01\t2.5\n0.02\t3.5\n")
    s = open_signals(f).get("body_az_fl", "x")
    assert s.values.tolist() == [1.5, 2.5, 3.5]
    f.write_text("# logger v1\ntime;x\n0;1,5\n0,01;2,5\n0,02;3,5\n")
    s = open_signals(f, CsvOptions(skip_rows=1)).get("x", "x")
    np.testing.assert_allclose(s.time, [0, 0.01, 0.02])
    np.testing.assert_allclose(s.values, [1.5, 2.5, 3.5])


def test_missing_extra_names_the_package(tmp_path, monkeypatch):
    import builtins
    real = builtins.__import__

    def fake(name, *a, **k):
        if name.startswith("asammdf"):
            raise ImportError(name)
        return real(name, *a, **k)
    monkeypatch.setattr(builtins, "__import__", fake)
    from rideid.data.readers import open_signals
    f = tmp_path / "x.mf4"
    f.write_bytes(b"MDF     ")
    with pytest.raises(DataError, match=r"x.mf4: reading ASAM MDF files needs the package 'asammdf': "
                                        r"pip install 'rideid\[mdf\]'"):
        open_signals(f)


# ---------------------------------------------------------------------------
# Plausibility warnings, each with its message

def _one_run(tmp_path, default_scenario, raw, *, mutate=None, preprocess=None, cmap=None, rid="T_HH",
             gravity=True, fmt="mf4", extra=None):
    """A one-run logger dataset, the file's channels changed by ``mutate(chans)``."""
    from logger_files import WRITERS
    t, Y = raw[rid]
    chans = logger_channels(t, Y, gravity)
    if mutate:
        mutate(chans)
    (tmp_path / "runs").mkdir(parents=True, exist_ok=True)
    WRITERS[fmt](tmp_path / "runs" / f"{rid}.{fmt}", chans)
    run = default_scenario.run(rid)
    doc = {"name": "one", "vehicle": {k: getattr(default_scenario.geometry, k) for k in
                                      ("wheelbase", "track_front", "track_rear", "tire_radius")},
           "known": {"total_mass": 1093.3}, "channels": cmap if cmap is not None else channel_map(),
           "preprocess": preprocess if preprocess is not None else {"gravity_included": gravity},
           "tracks": [default_scenario.tracks[run.track].to_table()],
           "runs": [{"id": rid, "track": run.track, "speed": run.speed, "file": f"runs/{rid}.{fmt}", **(extra or {})}]}
    (tmp_path / "dataset.toml").write_text(tomli_w.dumps(doc))
    return tmp_path


def _warnings_of(path):
    with warnings.catch_warnings(record=True) as wl:
        warnings.simplefilter("always")
        rideid.load_dataset(path)
    return [str(w.message) for w in wl if issubclass(w.category, DataWarning)]


def _set(name, fn):
    def mutate(chans):
        t, v, u = chans[name]
        chans[name] = fn(t, v, u)
    return mutate


WARNINGS = {
    "gravity not declared": (dict(preprocess={}), "AccZ_Body_FL' mapped to body_az_fl: mean 9.81 m/s^2 is about g: "
                             "the channel seems to include gravity; set gravity_included = true"),
    "deg/s labelled rad/s": (dict(cmap={**channel_map(), "pitch_rate": {"name": "Gyro_Y", "unit": "rad/s",
                                                                         "sign": -1}},
                                  extra={"checks": {"wiring": "warn"}}),
                             "mapped to pitch_rate: peaks at"),
    "flat-lined": (dict(mutate=_set("AccZ_Hub_FL", lambda t, v, u: (t, np.full_like(v, 1.0), u))),
                   "AccZ_Hub_FL' mapped to axle_az_fl: flat-lined (every sample is 1)"),
    "clipped": (dict(mutate=_set("AccZ_Hub_RR", lambda t, v, u: (t, np.clip(v, 0.5, 1.5), u))),
                "AccZ_Hub_RR' mapped to axle_az_rr: clipped: "),
    "gap": (dict(mutate=_set("Gyro_X", lambda t, v, u: (np.delete(t, range(2000, 2050)),
                                                        np.delete(v, range(2000, 2050)), u))),
            "Gyro_X' mapped to roll_rate: 1 gap(s) in time, the longest 0.102 s at t = 3.998 s"),
    "upside down": (dict(cmap={**channel_map(), "body_az_fr": {"name": "AccZ_Body_FR", "unit": "g"}},
                         extra={"checks": {"wiring": "warn"}}),  # else an error: tests/test_checks.py
                    "body_az_fr: reads -9.81 m/s^2 at rest (gravity included): mounted upside down? set sign = -1"),
    "lead-in moving": (dict(preprocess={"gravity_included": True, "lead_in": [2.5, 4.0]}),
                       "the lead-in [2.5, 4] s is not stationary"),
    # the map is right and the file's label wrong (a wrong map is an error: tests/test_checks.py)
    "unit disagrees with the file": (dict(mutate=_set("AccZ_Hub_FL", lambda t, v, u: (t, v, "g"))),
                                     "AccZ_Hub_FL' mapped to axle_az_fl: the file says unit 'g' but the map "
                                     "says 'm/s^2'; using the map's"),
    "fs above the slowest channel": (dict(preprocess={"gravity_included": True, "fs": 800.0}),
                                     "resampling to 800 Hz, above the slowest channel's rate (500 Hz)"),
}


@pytest.mark.parametrize("case", list(WARNINGS))
def test_plausibility_warning(case, tmp_path, default_scenario, raw):
    kw, expected = WARNINGS[case]
    msgs = _warnings_of(_one_run(tmp_path, default_scenario, raw, **kw))
    assert any(expected in m for m in msgs), msgs


def test_clean_logger_run_gives_no_warning(tmp_path, default_scenario, raw):
    assert _warnings_of(_one_run(tmp_path, default_scenario, raw)) == []


def test_a_channel_without_signal_has_a_stationary_lead_in(tmp_path, default_scenario, raw):
    """The washboard hardly rolls the car: roll_rate is noise (or rounding) over the lead-in and the run
    alike, which is no reason to say the lead-in moves; a lead-in over moving data still is."""
    rng = np.random.default_rng(3)
    noisy = _set("Gyro_X", lambda t, v, u: (t, v + 0.02 * rng.standard_normal(v.size), u))
    pre = {"gravity_included": True, "remove_bias": True}
    msgs = _warnings_of(_one_run(tmp_path / "a", default_scenario, raw, rid="W_L", preprocess=pre, mutate=noisy))
    assert not [m for m in msgs if "not stationary" in m], msgs
    moving = _warnings_of(_one_run(tmp_path / "b", default_scenario, raw, rid="W_L", mutate=noisy,
                                   preprocess={**pre, "lead_in": [4.0, 5.5]}))
    assert [m for m in moving if "not stationary" in m and "body_az_fl" in m], moving
    assert not [m for m in moving if "not stationary" in m and "roll_rate" in m], moving


def test_a_dead_gyro_is_flat_lined_and_nothing_else(tmp_path, default_scenario, raw):
    """A gyro that reads one value throughout (the washboard run of docs' van case: its roll rate is identically
    zero, the logger adds a bias): one warning, "flat-lined"; the lead-in's rounding (RMS 1.7e-18 against 0)
    is no motion (it was "lead-in not stationary (RMS 1.73e-18 vs 0)")."""
    dead = _set("Gyro_X", lambda t, v, u: (t, np.full_like(v, -0.0520937), u))
    msgs = _warnings_of(_one_run(tmp_path, default_scenario, raw, rid="W_L", mutate=dead,
                                 preprocess={"gravity_included": True, "remove_bias": True}))
    # -0.0520937 deg/s = -0.000909207 rad/s
    assert len(msgs) == 1 and "Gyro_X' mapped to roll_rate: flat-lined (every sample is -0.000909207)" in msgs[0], msgs


# ---------------------------------------------------------------------------
# Bad input: one line naming the file, key or channel; exit 2; nothing written

BAD = {
    "unknown unit": (dict(cmap={**channel_map(), "roll_rate": {"name": "Gyro_X", "unit": "rpm"}}),
                     "[channels] roll_rate unit: unknown unit 'rpm' for roll_rate (rate); use one of rad/s, deg/s"),
    "mapped channel not in the file": (dict(cmap={**channel_map(), "roll_rate": "GyroX"}),
                                       "T_HH.mf4: no channel 'GyroX' (channel 'GyroX' mapped to roll_rate); "
                                       "the file has:"),
    "unknown target": (dict(cmap={**channel_map(), "yaw_rate": "Gyro_Z"}),
                       "[channels]: unknown channel 'yaw_rate'; map file channels to body_az_fl"),
    "bad sign": (dict(cmap={**channel_map(), "roll_rate": {"name": "Gyro_X", "sign": 2}}),
                 "[channels] roll_rate: sign must be 1 or -1, got 2"),
    "bad window": (dict(extra={"window": [5.0, 1.0]}), "window: from (5.0) must be less than to (1.0)"),
    "bad start": (dict(extra={"start": "soon"}), "start: expected a time in seconds of file time, or \"auto\""),
    "empty lead-in": (dict(preprocess={"gravity_included": True, "lead_in": [100.0, 101.0]}),
                      "lead_in [100, 101] s holds fewer than 3 samples of body_az_fl"),
    "speed twice": (dict(cmap={**channel_map(), "speed": {"name": "Gyro_X", "unit": "m/s"}}),
                    "give either a constant 'speed' or a speed/distance channel, not both"),
    "unknown preprocess key": (dict(preprocess={"gravity": True}), "[preprocess]: unknown key 'gravity'"),
    "NaN in a channel": (dict(mutate=_set("AccZ_Hub_FL", lambda t, v, u: (t, np.where(t > 1, np.nan, v), u))),
                         "channel 'AccZ_Hub_FL' mapped to axle_az_fl: NaN or infinite value at t = 1.002 s"),
    "time not increasing": (dict(mutate=_set("Gyro_X", lambda t, v, u: (np.where(t > 1, t - 0.5, t), v, u))),
                            "channel 'Gyro_X' mapped to roll_rate: time is not strictly increasing at t = 1 s"),
    "unknown file type": (dict(extra={"file": "runs/T_HH.xlsx"}), "unknown run file type '.xlsx'"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_measured_input_is_one_clear_line(case, tmp_path, default_scenario, raw, capsys):
    """``rideid identify`` of each bad input: exit 2, one line, nothing written. The command line as a user starts
    it for the first case, in this process for the others (the same ``main``; 1.2 s of Python start-up each)."""
    kw, expected = BAD[case]
    path = _one_run(tmp_path / "ds", default_scenario, raw, **kw)
    out = tmp_path / "out"
    args = ["identify", str(path), "--out", str(out), "--quiet"]
    if case == next(iter(BAD)):
        p = subprocess.run([sys.executable, "-m", "rideid", *args], capture_output=True, text=True)
        code, stderr = p.returncode, p.stderr
    else:
        from rideid.cli import main
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            code = main(args)
        stderr = capsys.readouterr().err
    assert code == 2, stderr
    errors = [ln for ln in stderr.splitlines() if not ln.startswith("rideid: warning:")]
    assert len(errors) == 1 and errors[0].startswith("rideid: error: "), stderr
    assert expected in errors[0], errors[0]
    assert "Traceback" not in stderr and not out.exists()


def test_negative_speed_channel_is_refused(tmp_path, default_scenario, raw):
    def add_speed(chans):
        t = chans["AccZ_Body_FL"][0]
        chans["Speed"] = (t, np.where(t < 1, -1.0, 18.0), "km/h")
    path = _one_run(tmp_path, default_scenario, raw, mutate=add_speed,
                    cmap={**channel_map(), "speed": {"name": "Speed", "unit": "km/h"}})
    doc = rideid.data.schema.read_toml(path / "dataset.toml")
    del doc["runs"][0]["speed"]
    (path / "dataset.toml").write_text(tomli_w.dumps(doc))
    with pytest.raises(DataError, match=r"speed channel 'Speed' goes negative \(-0.278 m/s\)"):
        quiet_load(path)


def test_reading_and_start_estimation_are_separate_steps(tmp_path, default_scenario, raw):
    """read_dataset only reads and conditions; align_starts estimates the starts, on a new dataset."""
    from rideid.data.dataset import read_dataset
    from rideid.conditioning.load import align_starts
    path = _one_run(tmp_path, default_scenario, raw, rid="T_LL")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        unaligned = read_dataset(path)
    assert "T_LL" not in unaligned.data and unaligned.measured["T_LL"].start is None
    with pytest.raises(rideid.ArgumentError, match="T_LL have no start yet"):
        rideid.CostFunction(unaligned)
    ds = align_starts(unaligned)
    assert unaligned.measured["T_LL"].start is None and "T_LL" not in unaligned.data  # not changed
    assert abs(ds.measured["T_LL"].start - OFFSET) < 1e-4
    assert ds.preprocessing()["T_LL"]["start"]["source"] == "estimated (nominal car)"
    given = align_starts(unaligned, {"T_LL": OFFSET + 0.01})
    assert given.measured["T_LL"].start == OFFSET + 0.01
    assert given.preprocessing()["T_LL"]["start"]["source"].startswith("given")
    # a dataset at other starts is a new object; the original keeps its time axis
    moved = ds.with_starts({"T_LL": {"value": OFFSET + 0.02, "std": 1e-4}})
    assert moved.measured["T_LL"].start == OFFSET + 0.02 and ds.measured["T_LL"].start != OFFSET + 0.02
    assert moved.preprocessing()["T_LL"]["start"]["std"] == 1e-4
    # the model moves, the data never do: the same samples on a time axis moved by the start's change
    assert np.array_equal(moved.data["T_LL"].matrix(), ds.data["T_LL"].matrix())
    shift = OFFSET + 0.02 - ds.measured["T_LL"].start
    np.testing.assert_allclose(moved.data["T_LL"].time, ds.data["T_LL"].time - shift, rtol=0, atol=1e-12)


def test_a_clean_read_skips_the_garbage_collection_a_failed_one_runs(mdf_dataset, monkeypatch):
    """quiet_library collects the garbage (finalising a half-built reader while silenced) only after a
    failure: ten clean MDF runs took 8.5-11 s to load with a full collection per channel, 2.9 s without."""
    from rideid.data import readers
    calls = []
    monkeypatch.setattr(readers.gc, "collect", lambda *a: calls.append(a) or 0)
    quiet_load(mdf_dataset)
    assert calls == []
    with readers.quiet_library("asammdf") as quiet:
        quiet.fail()
    assert calls == [()]
    with pytest.raises(KeyError), readers.quiet_library("asammdf"):
        raise KeyError("damaged block")
    assert calls == [(), ()]
