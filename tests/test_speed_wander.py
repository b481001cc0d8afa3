"""Speed as driven (SPEC §11): a run without a speed or distance channel whose speed wanders is refused in one
line that says to log speed; a run held at its speed is not.

The wandering runs are the SUV's of tests/driven_speed.py (the independent SciPy car driven along x(t), exact
drawings, 1 % sensor noise), written without the speed column and declared at each run's nominal speed; the
runs that must pass are the same runs with the speed held, the SUV on as-built tracks (tests/asbuilt_tracks.py:
4 % off the drawing, 1.5 mm RMS unevenness), the built-in car's ten runs, and the wandering runs with their
speed channel mapped.
"""

import re
import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.conditioning import speed as speed_check
from rideid.conditioning.checks import feature_span, speed_summaries
from rideid.data.dataset import read_dataset
from rideid.errors import DataError

sys.path.insert(0, str(Path(__file__).parent))
from asbuilt_tracks import RUNS  # noqa: E402
from asbuilt_tracks import write_dataset as write_asbuilt  # noqa: E402
from cars import SUV_VEHICLE  # noqa: E402
from driven_speed import write_case  # noqa: E402

BY_ID = {r[0]: r for r in RUNS}


def _load(folder):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rideid.load_dataset(folder)


def test_window_lags_read_a_known_time_stretch():
    """A signal and the same signal read on a stretched clock, f(t + l(t)): the lags are l averaged over each
    window (to a fifth of a sample) and the summary's slope the stretch (a constant speed
    2 % above the declared one), a lag growing as (t - 3)^2 a speed
    changing along the run (-1.25 % to +1.25 % between the outer windows)."""
    fs = 200.0
    t = np.arange(0.0, 6.0, 1 / fs)
    rng = np.random.default_rng(3)
    f = rng.uniform(1.0, 9.0, 12)
    ph = rng.uniform(0, 2 * np.pi, (12, 10))

    def sig(tt):
        return np.stack([np.sum(np.sin(2 * np.pi * f[:, None] * tt[None, :] + ph[:, c:c + 1]), axis=0)
                         for c in range(10)], axis=1)

    Yhat = sig(t)
    for lag_of, slope, low, high in ((lambda tt: 0.02 * (tt - 3.0), 0.02, 0.02, 0.02),
                                     (lambda tt: 0.005 * (tt - 3.0) ** 2, 0.0, -0.0125, 0.0125)):
        Y = sig(t + lag_of(t))
        w = speed_check.window_lags(Y, Yhat, t, (0.5, 5.5), fs)
        # each window's lag is the lag averaged over it (four windows of 1.25 s over 0.5-5.5 s)
        averaged = [np.mean(lag_of(np.linspace(0.5 + 1.25 * k, 0.5 + 1.25 * (k + 1), 251))) for k in range(4)]
        assert np.allclose(w["lag"], averaged, atol=1e-3)
        s = speed_check.speed_summary(w)
        assert s["mean"] == pytest.approx(slope, abs=1e-3)
        # the mean speed between the first two and the last two window centres (t = 1.125, 2.375; 3.625, 4.875 s)
        assert s["low"] == pytest.approx(low, abs=1e-3)
        assert s["high"] == pytest.approx(high, abs=1e-3)


def test_a_wandering_speed_is_refused_in_one_line_naming_the_run_and_the_wander(tmp_path):
    """H_HL with a +-3 % driver: the run, its file, the speed's range in % (the mean speeds between windows a
    quarter of the track apart, within the driver's true range, one end beyond the limit) and "log speed"."""
    folder = tmp_path / "wander"
    driven = write_case(folder, seed=6, speed_channel=False, speed_column=False, runs=[BY_ID["H_HL"]])
    with pytest.raises(DataError) as e:
        _load(folder)
    msg = str(e.value)
    assert "\n" not in msg
    assert "run 'H_HL' (runs/H_HL.csv): its speed wanders" in msg
    assert "log speed: map a speed or distance channel" in msg and "docs/real-data.md" in msg
    low, high = (float(x) / 100 for x in re.search(r"between ([-+][\d.]+) % and ([-+][\d.]+) % of the declared 5 m/s",
                                                  msg).groups())
    # the driver's speed along the stretch the lags are measured on: the wheels on the features (the start is at
    # 1 s of file time)
    man = read_dataset(folder).manifest
    lo, hi = feature_span(man.tracks["herringbone_high"], man.geometry)
    R, wb = SUV_VEHICLE["tire_radius"], SUV_VEHICLE["wheelbase"]
    v, _ = driven["H_HL"]
    dev = v(1.0 + np.linspace((lo - R) / 5.0, (hi + wb + R) / 5.0, 400)) / 5.0 - 1.0
    assert dev.min() - 0.003 <= low < high <= dev.max() + 0.003
    assert max(-low, high) > speed_check.WANDER_MAX


def test_a_steady_speed_other_than_the_declared_one_names_the_speed_the_data_show(tmp_path):
    """H_HH held at 10 m/s, declared 9.8 (SPEC §13: a declared speed is a prior, 0.3 % wide by default): loaded,
    with a warning naming the run and about 10 m/s (+2 %); the fit starts from there, the declared 9.8 its
    prior."""
    folder = tmp_path / "off"
    write_case(folder, seed=2, speed_channel=False, speed_column=False, wander=0.0, runs=[BY_ID["H_HH"]])
    doc = tomllib.loads((folder / "dataset.toml").read_text())
    doc["runs"][0]["speed"] = 9.8
    (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
    with pytest.warns(rideid.DataWarning) as rec:
        ds = rideid.load_dataset(folder)
    msgs = [str(w.message) for w in rec if "declared speed" in str(w.message)]
    assert len(msgs) == 1, [str(w.message) for w in rec]
    m = re.search(r"run 'H_HH' \(runs/H_HH.csv\): declared speed 9.8 m/s, the data match the track at ([\d.]+) ± "
                  r"([\d.]+) m/s \(\+([\d.]+) %", msgs[0])
    assert m, msgs[0]
    assert float(m.group(1)) == pytest.approx(10.0, abs=0.03)
    assert float(m.group(3)) == pytest.approx(100 * (10.0 / 9.8 - 1), abs=0.3)
    run = ds.manifest.run("H_HH")
    assert run.speed == pytest.approx(float(m.group(1)), rel=1e-3) and run.declared_speed == 9.8
    assert run.speed_prior() == (9.8, pytest.approx(0.003 * 9.8), False)
    assert "wired" not in " ".join(str(w.message) for w in rec)


def _held(s, of_limit, of_std):
    """Every run of the SUV's five checked and passed: each deviation within ``of_limit`` of the limit and
    ``of_std`` of its uncertainty, none beyond it."""
    assert sorted(s) == sorted(BY_ID)
    worst = max(max(abs(v["low"]), abs(v["high"])) for v in s.values())
    assert 0.0 < worst < of_limit * speed_check.WANDER_MAX
    assert max(np.max(np.abs(v["deviation"]) / v["std"]) for v in s.values()) < of_std
    assert all(v["beyond"] == 0.0 for v in s.values())


def test_runs_held_at_their_speed_pass_with_margin(tmp_path):
    """The five runs held exactly, 1 % noise: every deviation within 0.3 % (a third of the limit) and a quarter
    of its uncertainty."""
    folder = tmp_path / "held"
    write_case(folder, seed=1, speed_channel=False, speed_column=False, wander=0.0)
    _held(speed_summaries(_load(folder)), 0.3, 0.25)


def test_tracks_as_built_pass_with_margin(tmp_path):
    """The SUV on tracks 4 % off their drawing with 1.5 mm RMS unevenness: every deviation within 0.6 % (the
    limit is 1 %) and a fifth of its uncertainty."""
    _held(speed_summaries(_load(write_asbuilt(tmp_path / "asbuilt", seed=3))), 0.6, 0.2)


def test_the_built_in_cars_runs_pass(sim_dataset):
    """The built-in car's ten runs, noise-free (the nominal car is this car: each window's lag is certain to a
    few microseconds, and the limit alone decides): every deviation within 0.05 %."""
    s = speed_summaries(_load(sim_dataset))
    assert len(s) == 10
    assert max(max(abs(v["low"]), abs(v["high"])) for v in s.values()) < 5e-4
    assert max(v["beyond"] for v in s.values()) < 5e-4


def test_a_wandering_run_with_its_speed_channel_is_not_checked(tmp_path):
    """The +-3 % driver with the 10 Hz GPS speed mapped: the run drives along its channel; no refusal."""
    folder = tmp_path / "gps"
    write_case(folder, seed=1, gps_noise=0.03, runs=[BY_ID["H_HL"]])
    ds = _load(folder)
    assert ds.data["H_HL"].distance is not None
    assert speed_summaries(ds) == {}


def test_identify_refuses_a_wandering_run_exit_2_one_line_nothing_written(tmp_path, capsys):
    from rideid.cli import main
    folder = tmp_path / "wander"
    write_case(folder, seed=6, speed_channel=False, speed_column=False, runs=[BY_ID["H_HL"]])
    out = tmp_path / "out"
    code = main(["identify", str(folder), "--out", str(out), "--quiet", "--generations", "1", "--population", "8",
                 "--no-polish", "--no-report"])
    err = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("rideid: warning:")]
    assert code == 2
    assert len(err) == 1, err
    assert "run 'H_HL' (runs/H_HL.csv): its speed wanders" in err[0] and "log speed" in err[0]
    assert "Traceback" not in err[0]
    assert not out.exists()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_suvs_five_runs_with_a_3_percent_driver_are_refused(seed, tmp_path):
    folder = tmp_path / f"w{seed}"
    write_case(folder, seed=seed, speed_channel=False, speed_column=False)
    with pytest.raises(DataError, match=r"its speed (wanders|looks steady but not).*log speed"):
        _load(folder)
