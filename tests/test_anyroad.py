"""Identification with runs on unknown roads (SPEC §9, rideid.estimate.fit.anyroad) from the command line and Python:
the car, its error bars, the estimated roads and their classes, mixed datasets, and what is refused."""

import json
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.cli import main
from rideid.errors import DataError
from rideid.data.scenario import default_scenario
from rideid.estimate.fit import anyroad
from rideid.estimate.problem import roadfit
from rideid.model.params import total_mass

RUNS = [{"id": "B40", "road_class": "B", "speed": 11.0, "fs": 200.0, "duration": 20.0},
        {"id": "C25", "road_class": "C", "speed": 7.0, "fs": 200.0, "duration": 20.0}]
TWIST = {"id": "tw", "kind": "chassis_twist", "start": 3.0, "height": 0.03, "bump_length": 1.6, "spacing": 4.0,
         "bumps": 2}


def simulate(tmp_path, runs, tracks=None, noise=0.02, seed=3):
    """The built-in car on ``runs``. (Not the SUV of tests/cars.py: on these two short slow runs its unsprung
    masses and tires are barely determined, -47 % +- 187 % measured, honestly but uselessly: its front and
    rear ends respond so alike that the rear wheels' repeat of the road tells little; docs/any-road.md.)"""
    sc = default_scenario()
    g = sc.geometry
    doc = {"name": "roads", "vehicle": {k: getattr(g, k) for k in g.KEYS},
           "known": {"total_mass": float(total_mass(dict(sc.truth)))}, "truth": dict(sc.truth), "runs": runs}
    if tracks:
        doc["tracks"] = tracks
    (tmp_path / "sc.toml").write_text(tomli_w.dumps(doc))
    assert main(["simulate", str(tmp_path / "sc.toml"), "--out", str(tmp_path / "sim"), "--noise", str(noise),
                 "--seed", str(seed), "--quiet"]) == 0
    return tmp_path / "sim"


@pytest.fixture(scope="module")
def road_fit(tmp_path_factory):
    d = tmp_path_factory.mktemp("anyroad")
    sim = simulate(d, RUNS)
    rc = main(["identify", str(sim), "--out", str(d / "fit"), "--seed", "1", "--quiet"])
    return rc, sim, d / "fit"


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_the_car_from_two_unknown_roads(road_fit):
    rc, sim, fit = road_fit
    assert rc == 0
    doc = json.loads((fit / "result.json").read_text())
    truth = tomllib.loads((sim / "truth.toml").read_text())["truth"]
    for n, t in truth.items():
        d = doc["parameters"][n]
        err = d["value"] - t
        # within 1 % (issue 26's bar) and within 4 std_robust (one seed; the coverage study is docs/any-road.md's)
        assert abs(err) < 0.01 * t, (n, d["value"], t)
        assert abs(err) < 4 * d["std_robust"], (n, err / d["std_robust"])
    assert doc["adequacy"] is None  # no residual test on unknown roads: said, not faked
    # auto weighs the linear groups on unknown roads (tests/test_road_model_choice.py): the car has none
    assert doc["model"]["selection"] == "auto" and doc["model"]["extensions"] == []
    assert "linear groups" in doc["model"]["note"]


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_rideid_report_again_draws_the_fitted_roads_response(road_fit):
    """The response of a run on an unknown road is the car at the road it estimated, which result.json alone
    cannot simulate again: identify writes it beside the road (road/<run>.response.csv) and `rideid report`
    draws it from there. (Before, `rideid report` on such a result stopped: "unknown-road runs ... are not
    supported by rideid.CostFunction".) The response read back is the fit's: the data minus it is of the size
    of the 2 % sensor noise in every channel (measured 0.8-1.0 %: the estimated road takes up part of the
    noise), not the road's whole response."""
    rc, sim, fit = road_fit
    assert rc == 0
    res = rideid.load_result(fit)
    ds = rideid.load_dataset(sim)
    assert set(res.response) == {r.id for r in ds.runs}
    for r in ds.runs:
        Y = np.column_stack([ds.data[r.id].channels[c] for c in rideid.CHANNELS])
        Yhat = res.response[r.id]
        assert Yhat.shape == Y.shape
        rel = np.sqrt(np.mean((Y - Yhat) ** 2, axis=0) / np.mean(Y ** 2, axis=0))
        assert np.all((rel > 0.005) & (rel < 0.03)), (r.id, rel)
    (fit / "report.html").unlink()
    assert main(["report", str(fit)]) == 0
    assert (fit / "report.html").is_file()


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_the_roads_and_their_classes(road_fit):
    _, sim, fit = road_fit
    doc = json.loads((fit / "result.json").read_text())
    truth_roads = tomllib.loads((sim / "truth.toml").read_text())["roads"]
    for rid, cls in (("B40", "B"), ("C25", "C")):
        rec = doc["roads"][rid]
        assert rec["iso8608_class"] == cls == truth_roads[rid]["road_class"]
        est = np.loadtxt(fit / rec["file"], delimiter=",", skiprows=1)
        assert (fit / rec["file"]).read_text().splitlines()[0] == "x,z_left,z_right"
        tru = np.loadtxt(sim / "road_truth" / f"{rid}.csv", delimiter=",", skiprows=1)
        x = est[:, 0]
        dx = x[1] - x[0]
        inner = (x > 20.0) & (x < x[-1] - 20.0)
        for k in (1, 2):  # left, right: within 10 % RMS over 0.5-20 m wavelengths (issue 26), away from the ends
            zt = roadfit.band_pass(np.interp(x, tru[:, 0], tru[:, k]), dx)
            err = np.sqrt(np.mean((est[inner, k] - zt[inner]) ** 2) / np.mean(zt[inner] ** 2))
            assert err < 0.10, (rid, k, err)
    res = rideid.load_result(fit)  # the roads come back with the result
    assert set(res.road_profiles) == {"B40", "C25"} and res.roads["B40"]["iso8608_class"] == "B"
    assert (fit / "report.html").is_file() and (fit / "figures" / "road_B40.png").is_file()


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_the_cost_of_an_unknown_road_fit_means_what_it_means_on_a_track(road_fit):
    """result.json's cost (and the terminal's "cost ...") was the polish's own objective, about 1 by
    construction ("cost 1"). It is now rideid.cost's E_r on every run: each channel's squared error over its
    energy. With white noise of 2 % of each channel's RMS, the fit band's share of it stays in the residual but
    for what the two wheel paths' road absorbs (2 of the 10 channels at each frequency): E_r = 0.02^2 x (band
    bins / all bins) x (1 - 2/10), 7.9e-5 here."""
    _, sim, fit = road_fit
    doc = json.loads((fit / "result.json").read_text())
    ds = rideid.load_dataset(sim)
    expected = []
    for rr in anyroad.prepare_road_runs(ds):
        assert len(rr.cols) == 10 and not rr.left_out
        expected.append(0.02 ** 2 * rr.fit.size / (rr.n / 2) * (1 - 2 / 10))
    assert doc["cost"] == pytest.approx(np.mean(expected), rel=0.05), (doc["cost"], expected)


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_a_dataset_mixing_a_track_and_a_road(tmp_path):
    sim = simulate(tmp_path, [RUNS[0], {"id": "T", "track": "tw", "speed": 4.0, "fs": 200.0, "duration": 8.0}],
                   [TWIST], noise=0.01)
    ds = rideid.load_dataset(sim)
    assert [r.id for r in anyroad.unknown_road_runs(ds)] == ["B40"]
    res = rideid.identify(ds, rng=2, model="base")
    truth = tomllib.loads((sim / "truth.toml").read_text())["truth"]
    for n, t in truth.items():
        assert abs(res.parameters[n] / t - 1) < 0.01, n
    # every run assessed (issue 51): the road run by its residual at its own road estimate, which passes here
    # (measured: 0.39-0.49 % of each channel over seeds 1-5 of this case, against roads.max_share 3 %)
    assert res.adequacy["not_assessed"] == [] and res.adequacy["roads"]["verdict"] == "pass"
    assert res.adequacy["adequate"] and res.roads["B40"]["residual"]["axle_az_fl"]["share"] < 0.01
    assert set(res.response) == {"B40", "T"}


def test_a_track_run_that_begins_moving_is_fitted_as_a_road_run(tmp_path):
    """With a linear model a run declared moving on a known track goes to the road fit, which estimates the state
    at the first sample (SPEC §9) and does not lean on the track's profile; with damper curves or bump stops,
    which the road's projection cannot take, it stays on its track, simulated from rest a lead-in before its
    first sample (tests/test_moving_starts.py)."""
    sim = simulate(tmp_path, [{"id": "T", "track": "tw", "speed": 4.0, "fs": 200.0, "duration": 8.0},
                              {"id": "Tm", "track": "tw", "speed": 5.0, "fs": 200.0, "duration": 8.0,
                               "moving": True}], [TWIST], noise=0.0)
    ds = rideid.load_dataset(sim)
    assert [r.id for r in anyroad.unknown_road_runs(ds)] == ["Tm"]
    assert [r.id for r in anyroad.unknown_road_runs(ds, ["anti_roll_bars"])] == ["Tm"]
    assert anyroad.unknown_road_runs(ds, ["damper_curves"]) == anyroad.unknown_road_runs(ds, ["bump_stops"]) == []
    assert ds.moving("Tm") and not ds.moving("T") and ds.road_known("Tm")


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_bump_stops_are_refused_with_road_runs(road_fit, tmp_path, capsys):
    """Bump stops cannot be fitted with the road projected out (damper curves can: tests/test_road_curves.py)."""
    _, sim, _ = road_fit
    rc = main(["identify", str(sim), "--out", str(tmp_path / "f"), "--model", "bump_stops", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "f").exists()
    assert "bump_stops" in err and "unknown roads (B40, C25)" in err


def test_an_unknown_road_needs_a_steady_speed():
    t = np.arange(0, 20, 0.005)
    steady = SimpleNamespace(time=t, distance=lambda tt: 10.0 * tt + 0.05 * np.sin(tt))
    run = SimpleNamespace(id="R1", speed=None)
    ds = SimpleNamespace(data={"R1": steady})
    assert anyroad.run_speed(ds, run) == pytest.approx(10.0, rel=1e-3)
    ds.data["R1"] = SimpleNamespace(time=t, distance=lambda tt: 8.0 * tt + 0.1 * tt ** 2)  # 8 -> 12 m/s
    with pytest.raises(DataError,
                       match=r"run 'R1': an unknown-road run needs a constant speed .* from 8\.00 to 12\.00"):
        anyroad.run_speed(ds, run)


def test_a_channel_the_road_run_does_not_excite_is_left_out_with_a_note(tmp_path):
    """A channel that carries rounding only (a roll rate on a washboard declared an unknown road, its bias
    removed: RMS 1e-19 rad/s) was weighted by 1 / its RMS and poisoned the fit ("costs contain NaN"). It is
    left out with a note naming it, and the fit is the fit without that column, exactly."""
    import shutil

    sim = simulate(tmp_path, [{"id": "C25", "road_class": "C", "speed": 7.0, "fs": 100.0, "duration": 8.0}])
    f = sim / "runs" / "C25.csv"
    head, *rows = f.read_text().splitlines()
    cols = head.split(",")
    k = cols.index("roll_rate")
    Y = np.array([[float(v) for v in r.split(",")] for r in rows])
    Y[:, k] = 1e-19 * np.random.default_rng(5).standard_normal(len(rows))
    np.savetxt(f, Y, delimiter=",", header=head, comments="", fmt="%.17g")
    absent = tmp_path / "absent"
    shutil.copytree(sim, absent)
    np.savetxt(absent / "runs" / "C25.csv", np.delete(Y, k, axis=1), delimiter=",",
               header=",".join(c for c in cols if c != "roll_rate"), comments="", fmt="%.17g")
    fits = [rideid.identify(rideid.load_dataset(d), seed=1, model="base", population=10, generations=5,
                            polish=False) for d in (sim, absent)]
    left_out = fits[0].roads["C25"]["channels_left_out"]
    assert list(left_out) == ["roll_rate"] and "RMS 1e-19" in left_out["roll_rate"], left_out
    assert "not excited by this run, or its sensor is dead" in left_out["roll_rate"]
    assert "channels_left_out" not in fits[1].roads["C25"]  # an absent channel is not a left-out one
    assert fits[0].parameters == fits[1].parameters
    assert np.isfinite(fits[0].cost) and fits[0].cost == fits[1].cost
    # the report draws the run without the channel's model response, and says nothing about NaN
    import warnings
    ds = rideid.load_dataset(sim)  # (the data checks warn that the gyro and the body disagree: the roll is gone)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rideid.write_report(fits[0], ds, tmp_path / "report")
    assert "roll_rate left out: RMS 1e-19" in (tmp_path / "report" / "report.html").read_text()
