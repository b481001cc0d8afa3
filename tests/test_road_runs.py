"""Runs on roads nobody measured (SPEC §9): scenario keys, generated roads and moving starts in
`rideid simulate`, datasets with unknown-road runs, and the code that refuses them clearly."""

import math
import re
import shutil
import tomllib
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import rideid
from cars import SUV_TOTAL_MASS, SUV_TRUTH, SUV_VEHICLE
from rideid.cli import main
from rideid.data.dataset import MIN_ROAD_RUN_S, MIN_ROAD_RUN_SAMPLES
from rideid.data.scenario import ROAD_DX, ROAD_MARGIN, generate_road, lead_in, settle_time
from rideid.synth.scenario import simulate_manifest, write_dataset
from rideid.data.schema import UNKNOWN_ROAD, RoadSpec, parse_dataset_manifest, parse_scenario, read_run_csv
from rideid.errors import ArgumentError, DataError, DataWarning
from rideid.model.equations import CHANNELS, modal_summary
from rideid.model.params import as_vector
from rideid.model.roads import ROAD_CLASSES, iso8608_class
from rideid.model.simulate import prepare_run, simulate_reference


def suv_doc(runs, tracks=None):
    doc = {"name": "suv-roads", "vehicle": dict(SUV_VEHICLE), "known": {"total_mass": SUV_TOTAL_MASS},
           "truth": dict(SUV_TRUTH), "runs": runs}
    if tracks:
        doc["tracks"] = tracks
    return doc


ROAD_RUN = {"id": "B", "road_class": "B", "speed": 12.0, "fs": 200.0, "duration": 8.0}
TWIST = {"id": "tw", "kind": "chassis_twist", "start": 3.0, "height": 0.03, "bump_length": 1.6, "spacing": 4.0,
         "bumps": 2}


def scenario(tmp_path, runs, tracks=None, name="sc.toml"):
    (tmp_path / name).write_text(tomli_w.dumps(suv_doc(runs, tracks)))
    return rideid.load_scenario(tmp_path / name)


def run_cli(args, capsys):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


# -- the files: scenario and dataset keys ---------------------------------------------------------

def test_scenario_road_runs_parse_with_their_defaults(tmp_path):
    sc = scenario(tmp_path, [ROAD_RUN, {**ROAD_RUN, "id": "C", "road_class": "c", "road_seed": 7, "coherence": 2.5,
                                        "moving": False},
                             {"id": "T", "track": "tw", "speed": 4.0, "fs": 200.0, "duration": 6.0}], [TWIST])
    b, c, t = sc.runs
    assert b.track is None and not b.road_known and b.moving and b.road == RoadSpec("B", None, 1.0)
    assert c.road == RoadSpec("C", 7, 2.5) and not c.moving
    assert t.road_known and t.track == "tw" and not t.moving and t.road is None
    # defaults are not written back; what differs from them is
    assert b.to_table() == {"id": "B", "road_class": "B", "speed": 12.0, "fs": 200.0, "duration": 8.0}
    assert c.to_table()["moving"] is False and c.to_table()["road_seed"] == 7
    assert "moving" not in t.to_table()
    # a scenario of road runs alone needs no [[tracks]]
    assert dict(scenario(tmp_path, [ROAD_RUN], name="alone.toml").tracks) == {}
    inf = scenario(tmp_path, [{**ROAD_RUN, "coherence": math.inf}], name="inf.toml").runs[0]
    assert inf.road.coherence == math.inf


BAD_SCENARIO_RUNS = {
    "both": ({**ROAD_RUN, "track": "tw"}, "give either 'track' (a [[tracks]] id) or 'road_class'"),
    "neither": ({k: v for k, v in ROAD_RUN.items() if k != "road_class"}, "missing key 'track' or 'road_class'"),
    "class": ({**ROAD_RUN, "road_class": "Z"}, "road_class must be an ISO 8608 class letter (A, B, C"),
    "seed": ({**ROAD_RUN, "road_seed": -1}, "road_seed must be a non-negative whole number, got -1"),
    "seed_float": ({**ROAD_RUN, "road_seed": 1.5}, "road_seed must be a non-negative whole number"),
    "coherence": ({**ROAD_RUN, "coherence": -1.0}, "coherence must be a number >= 0"),
    "moving": ({**ROAD_RUN, "moving": "yes"}, "moving must be true or false, got 'yes'"),
    "seed_without_class": ({"id": "T", "track": "tw", "road_seed": 3, "speed": 4.0, "fs": 200.0, "duration": 6.0},
                           "key 'road_seed' belongs to a generated road; give 'road_class' too"),
}


@pytest.mark.parametrize("case", list(BAD_SCENARIO_RUNS))
def test_bad_scenario_road_keys_name_run_and_key(case, tmp_path):
    run, msg = BAD_SCENARIO_RUNS[case]
    with pytest.raises(DataError) as e:
        parse_scenario(suv_doc([run], [TWIST]), tmp_path / "s.toml")
    assert msg in str(e.value) and f"(id '{run['id']}')" in str(e.value)


def test_dataset_runs_without_a_track(tmp_path):
    runs = [{"id": "U1", "file": "runs/U1.csv"}, {"id": "U2", "track": UNKNOWN_ROAD, "file": "runs/U2.csv",
                                                 "moving": True},
            {"id": "T", "track": "tw", "speed": 4.0, "file": "runs/T.csv"}]
    doc = {"vehicle": dict(SUV_VEHICLE), "known": {"total_mass": SUV_TOTAL_MASS}, "tracks": [TWIST], "runs": runs}
    man = parse_dataset_manifest(doc, tmp_path / "dataset.toml")
    u1, u2, t = man.runs
    assert (u1.track, u1.moving, u2.track, u2.moving, t.track, t.moving) == (None, False, None, True, "tw", False)
    assert [r.road_known for r in man.runs] == [False, False, True]
    assert u1.to_table()["track"] == UNKNOWN_ROAD and u2.to_table()["moving"] is True
    again = parse_dataset_manifest(man.to_dataset_doc(), tmp_path / "dataset.toml")
    assert again.runs == man.runs
    with pytest.raises(DataError, match=r"runs\[0\] \(id 'U1'\): unknown key 'road_class' \(road_class belongs to a "
                                        r"scenario"):
        parse_dataset_manifest({**doc, "runs": [{**runs[0], "road_class": "B"}]}, tmp_path / "dataset.toml")
    with pytest.raises(DataError, match="track id 'unknown' is reserved for runs on roads nobody measured"):
        parse_dataset_manifest({**doc, "tracks": [{**TWIST, "id": "unknown"}]}, tmp_path / "dataset.toml")
    with pytest.raises(DataError, match=r"needs at least one \[\[tracks\]\] table \(run 'T' names track 'tw'\)"):
        parse_dataset_manifest({k: v for k, v in doc.items() if k != "tracks"}, tmp_path / "dataset.toml")


# -- simulate: generated roads and moving starts ----------------------------------------------------

def test_settle_time_is_the_slowest_modes_decay():
    # two computations: eigenvalues of the 14-state model against the modal summary's f_n and zeta
    P = as_vector(SUV_TRUTH)
    geom = rideid.Geometry(**SUV_VEHICLE)
    sigma = min(2 * np.pi * m["frequency_hz"] * m["damping_ratio"]  # |lambda| zeta = -Re(lambda), block by block
                for m in modal_summary(SUV_TRUTH, geom).values())
    assert settle_time(P, geom) == pytest.approx(math.log(1e3) / sigma, rel=1e-6)
    assert 2.0 < settle_time(P, geom) < 4.0


@pytest.fixture(scope="module")
def road_sim(tmp_path_factory):
    d = tmp_path_factory.mktemp("roads")
    sc = scenario(d, [ROAD_RUN, {**ROAD_RUN, "id": "Brest", "moving": False, "road_seed": 11},
                      {"id": "T", "track": "tw", "speed": 4.0, "fs": 200.0, "duration": 6.0}], [TWIST])
    data, lifts = simulate_manifest(sc, seed=5)
    assert lifts == []
    write_dataset(sc, data, d / "ds")
    return sc, data, d / "ds"


def test_simulate_writes_an_unknown_road_run_and_its_road_truth(road_sim):
    sc, data, out = road_sim
    doc = tomllib.loads((out / "dataset.toml").read_text())
    runs = {r["id"]: r for r in doc["runs"]}
    assert runs["B"] == {"id": "B", "track": "unknown", "moving": True, "speed": 12.0, "file": "runs/B.csv"}
    assert runs["Brest"]["track"] == "unknown" and "moving" not in runs["Brest"]
    assert runs["T"]["track"] == "tw" and "moving" not in runs["T"]
    assert sorted(p.name for p in (out / "road_truth").iterdir()) == ["B.csv", "Brest.csv"]
    road = np.loadtxt(out / "road_truth" / "B.csv", delimiter=",", skiprows=1)
    assert (out / "road_truth" / "B.csv").read_text().splitlines()[0] == "x,z_left,z_right"
    x = road[:, 0]
    wb, R = SUV_VEHICLE["wheelbase"], SUV_VEHICLE["tire_radius"]
    assert -wb - R - ROAD_MARGIN - ROAD_DX < x[0] <= -wb - ROAD_MARGIN  # behind the rear axle at t = 0
    assert x[-1] >= 12.0 * 8.0 + ROAD_MARGIN
    assert np.allclose(np.diff(x), ROAD_DX) and np.any(np.abs(x) < 1e-12)  # x = 0 is a grid point
    # it is the road driven: the generated road's heights, not faded where the recording sees it
    gen = data.roads["B"]
    k = int(np.searchsorted(gen.x, x[0] - 1e-9))
    assert np.allclose(gen.z_left[k:], road[:, 1], rtol=1e-11, atol=0)
    assert np.allclose(gen.z_right[k:], road[:, 2], rtol=1e-11, atol=0)
    assert iso8608_class(x, road[:, 1:])[0] == "B"
    truth = tomllib.loads((out / "truth.toml").read_text())
    rec = truth["roads"]["B"]
    assert rec["road_class"] == "B" and rec["coherence"] == 1.0 and rec["gd_n0_class"] == ROAD_CLASSES["B"]
    assert rec["fitted_class"] == "B" and rec["road_seed"] == gen.seed
    assert truth["roads"]["Brest"]["road_seed"] == 11
    assert rideid.load_truth(out / "truth.toml") == pytest.approx(SUV_TRUTH)


def test_road_seeds_are_deterministic(road_sim, tmp_path):
    sc, data, _ = road_sim
    again, _ = simulate_manifest(sc, seed=5)
    other, _ = simulate_manifest(sc, seed=6)
    assert np.array_equal(again["B"][1], data["B"][1])
    assert np.array_equal(again.roads["B"].z_left, data.roads["B"].z_left)
    assert not np.array_equal(other.roads["B"].z_left, data.roads["B"].z_left)  # derived from --seed
    assert np.array_equal(other["Brest"][1], data["Brest"][1])  # road_seed given: --seed does not matter
    assert np.array_equal(other["T"][1], data["T"][1])
    # the seed of a derived road, written to truth.toml, reproduces it as road_seed
    sc2 = scenario(tmp_path, [{**ROAD_RUN, "road_seed": data.roads["B"].seed}])
    assert np.array_equal(generate_road(sc2, sc2.runs[0], 0, seed=99).z_left, data.roads["B"].z_left)


def test_moving_start_begins_moving_and_the_transient_has_decayed(road_sim):
    sc, data, _ = road_sim
    (t, Y), (_, Yrest) = data["B"], data["Brest"]
    assert t[0] == 0.0 and t.size == 1601
    rms = np.sqrt(np.mean(Y ** 2, axis=0))
    # at rest in static equilibrium, every acceleration and rate is 0 at the first sample; moving, it is not
    assert np.max(np.abs(Yrest[0])) < 1e-9 * np.max(np.sqrt(np.mean(Yrest ** 2, axis=0)))
    assert np.all(np.abs(Y[0, :8]) > 1e-3 * rms[:8]) and np.mean(np.abs(Y[0]) / rms) > 0.1
    # the criterion: started instead from rest on the full road (no fade) one settle time before x = 0,
    # the car's response at x >= 0 differs from the recorded one by its slowest mode decayed to 1e-3
    run, road = sc.runs[0], data.roads["B"]
    T = settle_time(as_vector(sc.truth), sc.geometry)
    k = int(np.ceil(T * run.fs))
    tt = np.arange(-k, t.size) / run.fs
    y2 = simulate_reference(as_vector(sc.truth)[None], sc.geometry, prepare_run(road.track(), sc.geometry,
                                                                                 run.speed, tt))[0]
    body = [0, 1, 2, 3, 8, 9]  # the body channels carry the slowest modes
    first = np.max(np.abs(y2[:k // 4, body] - Y[0, body]), axis=0)  # its start transient: the order of the motion
    late = np.max(np.abs(y2[k:, body] - Y[:, body]), axis=0)
    assert np.all(late < 1e-3 * first) and np.all(first > 0.1 * rms[body])
    assert lead_in(sc, run) > T + 1.0  # the road fades in and the rear wheels reach it first


def test_track_runs_are_unchanged_and_a_moving_track_run_has_a_lead_in(road_sim, tmp_path):
    sc, data, _ = road_sim
    t, Y = data["T"]
    run = sc.runs[2]
    ref = simulate_reference(as_vector(sc.truth)[None], sc.geometry,
                             prepare_run(sc.tracks["tw"], sc.geometry, run.speed, t))[0]
    assert np.array_equal(Y, ref) and lead_in(sc, run) == 0.0
    # a profile that starts at x = 0 under the front wheels: allowed when moving, refused at rest on loading
    x = np.arange(-4.0, 20.0, 0.05)
    np.savetxt(tmp_path / "road.csv", np.column_stack([x, 0.01 * np.sin(x), 0.01 * np.cos(x)]), delimiter=",",
               header="x,z_left,z_right", comments="")
    prof = {"id": "p", "kind": "profile", "file": "road.csv"}
    prun = {"id": "P", "track": "p", "speed": 5.0, "fs": 200.0, "duration": 6.0}
    for moving in (True, False):
        sc2 = scenario(tmp_path, [{**prun, "moving": moving}], [prof], name=f"p{moving}.toml")
        d2, _ = simulate_manifest(sc2, seed=1)
        y0 = d2["P"][1][0]
        assert (np.max(np.abs(y0)) > 1e-3) == moving
        write_dataset(sc2, d2, tmp_path / f"ds{moving}")
        if moving:
            ds = rideid.load_dataset(tmp_path / f"ds{moving}")
            assert ds.moving("P") and ds.road_known("P")
        else:
            with pytest.raises(DataError, match="the car must start at rest on flat road"):
                rideid.load_dataset(tmp_path / f"ds{moving}")


def test_both_engines_drive_the_generated_road(tmp_path):
    pytest.importorskip("mujoco")
    sc = scenario(tmp_path, [{**ROAD_RUN, "road_class": "A", "speed": 10.0, "duration": 5.0}])
    y7 = simulate_manifest(sc, seed=2)[0]["B"][1]
    ym, lifts = simulate_manifest(sc, seed=2, engine="mujoco")
    assert lifts == []
    ym = ym["B"][1]
    rms = np.sqrt(np.mean(y7 ** 2, axis=0))
    err = np.sqrt(np.mean((ym - y7) ** 2, axis=0))
    assert np.all(err < 0.02 * rms), err / rms  # the independent multibody car, within 2 % of each channel's RMS
    with pytest.raises(ArgumentError, match="--raw writes a logger's recording that starts standing still"):
        simulate_manifest(sc, engine="mujoco", raw=True)


# -- datasets with unknown-road runs -----------------------------------------------------------------

def test_mixed_dataset_loads_and_says_which_roads_are_known(road_sim):
    _, _, out = road_sim
    ds = rideid.load_dataset(out)
    assert ds.unknown_road_runs == ["B", "Brest"]
    assert [ds.road_known(r) for r in ("B", "Brest", "T")] == [False, False, True]
    assert [ds.moving(r) for r in ("B", "Brest", "T")] == [True, False, False]
    assert "(2 on unknown roads)" in repr(ds)
    assert not [f for f in ds.findings if f.severity == "error"]


def _edit_run_csv(path, fn):
    rd = read_run_csv(path)
    cols = fn(dict(rd.channels))
    np.savetxt(path, np.column_stack([rd.time] + list(cols.values())), delimiter=",",
               header=",".join(["time", *cols]), comments="", fmt="%.12g")


def _copy(out, tmp_path):
    d = tmp_path / "ds"
    shutil.copytree(out, d)
    return d


@pytest.mark.parametrize("drop", [["axle_az_rl"], ["body_az_fl", "axle_az_fr", "axle_az_rr"]])
def test_unknown_road_run_without_its_channels_is_refused(drop, road_sim, tmp_path, capsys):
    d = _copy(road_sim[2], tmp_path)
    _edit_run_csv(d / "runs" / "B.csv", lambda ch: {c: v for c, v in ch.items() if c not in drop})
    rc, _, err = run_cli(["identify", d, "--out", tmp_path / "fit", "--quiet"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    names = ", ".join(c for c in CHANNELS if c in drop)
    assert (f"run 'B' is on an unknown road (no track), which needs all four body and all four axle acceleration "
            f"channels (SPEC §9); missing: {names}") in err
    assert not (tmp_path / "fit").exists()


def test_short_unknown_road_run_is_refused(road_sim, tmp_path, capsys):
    d = _copy(road_sim[2], tmp_path)
    p = d / "runs" / "B.csv"
    p.write_text("\n".join(p.read_text().splitlines()[:901]) + "\n")  # 900 samples, 4.5 s
    rc, _, err = run_cli(["identify", d, "--out", tmp_path / "fit", "--quiet"], capsys)
    assert rc == 2 and (f"run 'B' is on an unknown road and holds 4.5 s (900 samples): too short to identify "
                        f"anything; a run on an unknown road needs at least {MIN_ROAD_RUN_S:g} s and "
                        f"{MIN_ROAD_RUN_SAMPLES} samples") in err
    assert not (tmp_path / "fit").exists()


def test_unknown_road_runs_still_get_the_rigid_body_check(road_sim, tmp_path):
    d = _copy(road_sim[2], tmp_path)
    _edit_run_csv(d / "runs" / "B.csv", lambda ch: {**ch, "pitch_rate": -ch["pitch_rate"]})
    with pytest.raises(DataError) as e:
        rideid.load_dataset(d)
    msg = str(e.value)
    assert "run 'B': the channels look wired differently from the map: pitch_rate has its sign flipped" in msg
    assert "without a known road this cannot be told from body_az_fl and body_az_rl swapped" in msg


def test_unknown_road_runs_name_a_hub_channel_in_g(road_sim, tmp_path, capsys):
    """A hub accelerometer logged in g but mapped as m/s^2, on a road nobody measured: no nominal response to
    compare with, so its RMS against the other hubs' (the same road's), and the identify command stops naming
    the channel, the factor and the fix; the clean run raises nothing; with wiring = "warn" it is a warning."""
    d = _copy(road_sim[2], tmp_path)
    rideid.load_dataset(d)  # the clean data: no finding
    _edit_run_csv(d / "runs" / "B.csv", lambda ch: {**ch, "axle_az_rr": ch["axle_az_rr"] / 9.80665})
    rc, _, err = run_cli(["identify", d, "--out", tmp_path / "fit", "--quiet"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1 and not (tmp_path / "fit").exists()
    assert "run 'B': axle_az_rr reads 9.81x too small (g mapped as m/s^2?): its RMS is" in err
    assert "the other hub channels' about" in err and 'axle_az_rr = { name = "axle_az_rr", unit = "g" }' in err
    rms = [float(x) for x in re.findall(r"RMS is ([0-9.]+) m/s\^2 as mapped, the other hub channels' about ([0-9.]+)",
                                        err)[0]]
    assert rms[1] / rms[0] == pytest.approx(9.80665, rel=0.15)  # the hubs of one road agree to 0.89-1.12
    doc = (d / "dataset.toml").read_text()
    (d / "dataset.toml").write_text(doc + '\n[checks]\nwiring = "warn"\n')
    with pytest.warns(DataWarning, match="axle_az_rr reads 9.81x too small"):
        rideid.load_dataset(d)


def test_measured_unknown_road_run_starts_at_its_first_sample(road_sim, tmp_path):
    d = _copy(road_sim[2], tmp_path)
    p = d / "runs" / "B.csv"
    rd = read_run_csv(p)
    _edit_run_csv(p, lambda ch: ch)  # same data, the clock shifted by 12.5 s as a logger's
    text = p.read_text().splitlines()
    rows = [f"{float(r.split(',', 1)[0]) + 12.5:.12g}," + r.split(",", 1)[1] for r in text[1:]]
    p.write_text("\n".join([text[0]] + rows) + "\n")
    doc = tomllib.loads((d / "dataset.toml").read_text())
    doc["runs"][0]["pre_roll"] = 0.0  # a preprocessing key: the run goes through rideid.data.measured
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    ds = rideid.load_dataset(d)
    assert "B" in ds.measured and ds.measured["B"].start == pytest.approx(12.5)
    assert ds.preprocessing()["B"]["start"]["source"].startswith("unknown road (SPEC §9)")
    assert np.allclose(ds.data["B"].time, rd.time) and np.allclose(ds.data["B"].channels["axle_az_fl"],
                                                                   rd.channels["axle_az_fl"])
    assert "B" not in ds.auto_start_runs


def test_commands_that_need_a_known_road_refuse_unknown_road_runs(road_sim, tmp_path, capsys):
    sc, _, out = road_sim
    # (rideid identify fits them: tests/test_anyroad.py; a CostFunction of known tracks refuses them)
    with pytest.raises(DataError, match="run 'B': unknown-road runs .* not supported by rideid.CostFunction"):
        rideid.CostFunction(rideid.load_dataset(out))
    rc, _, err = run_cli(["sensitivity", out, "--out", tmp_path / "maps", "--quiet"], capsys)
    assert rc == 2 and "run 'B': unknown-road runs" in err and "not supported by rideid sensitivity" in err
    assert not (tmp_path / "maps").exists()
    # (rideid plan takes them: tests/test_plan_roads.py)


EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "roads" / "class_b.toml"


def test_example_scenario_is_what_its_comments_say(tmp_path):
    sc = rideid.load_scenario(EXAMPLE)
    assert sc.geometry == rideid.Geometry(**SUV_VEHICLE) and dict(sc.truth) == pytest.approx(SUV_TRUTH)
    assert [(r.road.road_class, round(r.speed * 3.6), r.fs, r.duration, r.moving) for r in sc.runs] == \
        [("B", 50, 200.0, 40.0, True), ("B", 80, 200.0, 40.0, True), ("A", 100, 200.0, 30.0, True),
         ("C", 30, 200.0, 60.0, True)]
    # its runs driven 6 s: no wheel lifts, every run starts moving
    short = replace(sc, runs=tuple(replace(r, duration=6.0) for r in sc.runs))
    with warnings.catch_warnings():
        warnings.simplefilter("error", rideid.ModelValidityWarning)
        data, lifts = simulate_manifest(short, seed=1)
    assert lifts == []
    for r in sc.runs:
        y = data[r.id][1]
        assert np.all(np.abs(y[0, :8]) > 1e-3 * np.sqrt(np.mean(y[:, :8] ** 2, axis=0)))


@pytest.mark.slow  # the whole example through the command line (about 15 s)
def test_example_scenario_simulates_from_the_command_line(tmp_path, capsys):
    rc, out, err = run_cli(["simulate", EXAMPLE, "--out", tmp_path / "sim", "--noise", "0.01", "--seed", "1",
                            "--quiet"], capsys)
    assert rc == 0, err
    truth = tomllib.loads((tmp_path / "sim" / "truth.toml").read_text())
    assert {k: v["fitted_class"] for k, v in truth["roads"].items()} == {"B_50": "B", "B_80": "B", "A_100": "A",
                                                                        "C_30": "C"}
    ds = rideid.load_dataset(tmp_path / "sim")
    assert ds.unknown_road_runs == ["B_50", "B_80", "A_100", "C_30"]
