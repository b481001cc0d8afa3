"""Sensors as wired (SPEC §11) where the road is fitted in the frequency domain: unknown roads (SPEC §9,
rideid.estimate.fit.anyroad) and tracks as built (rideid.estimate.problem.asbuilt), with the four hub accelerometers
AC-coupled at 0.5 Hz by an analog filter rideid does not share (tests/coupled_case.py: ``lsim`` on a fine grid).

Before, unknown-road runs with a declared filter were refused, and the as-built fit ignored the filters: on the
SUV's five runs (tracks 4 % off their drawing, 1.5 mm RMS unevenness, hubs coupled and declared) it gave k_sf
+21.5 %, k_sr +20.1 %, the unsprung masses and tires -4 %, errors 4 to 38 times std_robust, the verdict
"adequate" and the twist's factor 0.980 (measured with this file's slow test on the tree before the change).
"""

import json
import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

import rideid
from asbuilt_tracks import RUNS, write_dataset as write_plain
from cars import SUV_TRUTH
from coupled_case import HUBS, write_roads_dataset, write_tracks_dataset
from rideid.cli import main
from rideid.estimate.fit import anyroad
from rideid.estimate.problem import asbuilt
from rideid.estimate.problem import roadfit
from rideid.estimate.problem.cost import ParameterSpace
from rideid.model.equations import CHANNELS
from rideid.model.params import ALL_NAMES, as_vector


def _suv_row(ds):
    space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=())
    return space, space.full(np.array([[SUV_TRUTH[n] for n in space.names]]))[0]


def _at_truth(ds, P):
    """Per run the as-built fit at the true car: (amplitude factor, unevenness RMS m)."""
    out = {}
    for run in ds.runs:
        tr = asbuilt.prepare_track_run(ds, run)
        tr.prior = asbuilt.estimate_prior(P, ds.geometry, tr)
        out[run.id] = (asbuilt.solve(P, ds.geometry, tr).alpha, asbuilt.unevenness_rms(tr))
    return out


def test_tracks_as_built_see_the_declared_coupling(tmp_path, monkeypatch):
    """At the true car, a run on a track as built through coupled hubs, declared, gives the amplitude factor and
    the unevenness of the same run recorded without coupling (same road, same noise stream): factor within 0.002,
    unevenness within 10 % (measured 0.0003 and 4 %). With the declaration ignored (the fit before this change)
    the road absorbs the coupling: the twist's factor 1.026 instead of 1.036, the washboard's unevenness
    3.8 mm instead of 1.9 (measured)."""
    runs = [RUNS[1], RUNS[4]]
    coupled = rideid.load_dataset(write_tracks_dataset(tmp_path / "c", runs=runs, seed=4))
    plain = rideid.load_dataset(write_plain(tmp_path / "p", runs=runs, seed=4))
    assert all(coupled.sensor_filters(r.id)[CHANNELS.index(c)] for r in coupled.runs for c in HUBS)
    _, P = _suv_row(plain)
    want = _at_truth(plain, P)
    got = _at_truth(coupled, P)
    for rid, (a, u) in want.items():
        assert got[rid][0] == pytest.approx(a, abs=0.002) and got[rid][1] == pytest.approx(u, rel=0.10), rid
    monkeypatch.setattr(roadfit, "with_sensors", lambda rr, filters: rr)
    ignored = _at_truth(coupled, P)
    assert abs(ignored["T_HH"][0] - want["T_HH"][0]) > 0.006
    assert ignored["W_H"][1] > 1.5 * want["W_H"][1]


@pytest.mark.slow
def test_identify_on_tracks_as_built_through_coupled_hubs(tmp_path):
    """The SUV's five runs on tracks as built (4 % off, 1.5 mm RMS), hubs coupled at 0.5 Hz and declared, from a
    start 3 % off the truth, ``model="base"`` (as tests/test_tracks_asbuilt.py's test of the uncoupled case):
    the twelve within 1.2 %, every error within 2.5 std_robust, adequate, the twist's factor near 1.04, and no
    coupling hint (the fit on the tracks as drawn, which gives the hints, saw the declared chain).

    Measured (two cores shared with other work): 43 s; largest error 0.58 % (m_ur), largest error over
    std_robust 2.7 (c_sf; the uncoupled case's test measured 2.5: the as-built error bars are optimistic,
    docs/tracks-as-built.md), twist factor 1.038. With every run's speed and start estimated with the car under
    their default priors (SPEC §13; they were held exact): m_ur +1.03 % and m_uf +0.92 % at 1.8 and 1.6
    std_robust, the largest 1.8 (the price of not taking the set-up as exact, inside the error bars: the
    uncoupled case's test, tests/test_tracks_asbuilt.py, moved the same way)."""
    ds = rideid.load_dataset(write_tracks_dataset(tmp_path / "c", seed=4))
    space, _ = _suv_row(ds)
    rng = np.random.default_rng(3)
    start = np.array([SUV_TRUTH[n] for n in space.names]) * (1 + 0.03 * rng.choice([-1, 1], len(space.names)))
    res = rideid.identify(ds, start=start, model="base", rng=1)
    errs = {n: res.parameters[n] / v - 1 for n, v in SUV_TRUTH.items()}
    z = {n: (res.parameters[n] - v) / res.details[n]["std_robust"] for n, v in SUV_TRUTH.items()}
    assert max(abs(e) for e in errs.values()) < 0.012, errs
    assert max(abs(v) for v in z.values()) < 2.5, z
    assert res.adequacy["adequate"] is True
    assert res.adequacy["as_built"] == sorted(r[0] for r in RUNS)
    assert res.adequacy["sensor_hints"] == [] and "tracks as drawn" in res.adequacy["sensor_hints_note"]
    assert res.tracks["twist_high"]["amplitude_factor"] == pytest.approx(1.04, abs=0.015)


@pytest.mark.slow
def test_rideid_identify_on_tracks_as_built_through_coupled_hubs(tmp_path):
    """``rideid identify --model base --seed 1`` on the same five runs (seed 1 of the data): the tracks as drawn
    leave structure, the tracks as built take over; the twelve within 1 % and ±2 std_robust covering at least 11,
    adequate, the twist's factor near 1.04. Measured (two cores shared): identify 27.5 s (the test, with the data
    written, 45 s), largest error 0.24 % (m_ur),
    largest error over std_robust 1.7 (c_sf), twist 1.042, herringbone 1.038, washboard 1.064."""
    truth = SUV_TRUTH
    folder = write_tracks_dataset(tmp_path / "c", seed=1)
    out = tmp_path / "fit"
    assert main(["identify", str(folder), "--out", str(out), "--seed", "1", "--model", "base", "--no-report",
                 "--quiet"]) == 0
    doc = json.loads((out / "result.json").read_text())
    p = doc["parameters"]
    assert max(abs(p[n]["value"] / v - 1) for n, v in truth.items()) < 0.01
    assert sum(abs(p[n]["value"] - v) <= 2 * p[n]["std_robust"] for n, v in truth.items()) >= 11
    assert doc["adequacy"]["adequate"] is True and doc["adequacy"]["as_built"] == sorted(r[0] for r in RUNS)
    assert doc["tracks"]["twist_high"]["amplitude_factor"] == pytest.approx(1.04, abs=0.015)


@pytest.fixture(scope="module")
def coupled_roads(tmp_path_factory):
    return write_roads_dataset(tmp_path_factory.mktemp("coupled_roads"))


def test_unknown_roads_carry_the_declared_chain(coupled_roads):
    """Loaded from the dataset, each road run's hubs carry the declared 0.5 Hz high-pass into the road fit, and at
    the true car the projection leaves the sensor noise alone: white noise of 2 % of each channel's RMS is, per
    real and imaginary part of a weighted DFT bin, ``0.02^2 n / 2``, of which the two wheel paths' road takes 2 of
    the 10 channels: ``0.8 * 0.02^2 n / 2`` (within 5 %; measured 0.99 and 0.97 of it). With the chain left out
    the residual is 7 to 8 times that (the filter's mismatch, not noise)."""
    ds = rideid.load_dataset(coupled_roads)
    rruns = anyroad.prepare_road_runs(ds)
    sc = rideid.default_scenario()
    P = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    assert [rr.run_id for rr in rruns] == ["B40", "C25"]
    for rr in rruns:
        assert [bool(f) for f in rr.sensors] == [c in HUBS for c in CHANNELS]
        noise = 0.8 * 0.02 ** 2 * rr.n / 2
        r = roadfit.residuals(P, ds.geometry, rr)
        assert r @ r / r.size == pytest.approx(noise, rel=0.05), rr.run_id
        q = roadfit.residuals(P, ds.geometry, roadfit.replace(rr, sensors=()))
        assert q @ q / q.size > 5 * noise, rr.run_id


@pytest.mark.slow
def test_rideid_identify_on_unknown_roads_through_coupled_hubs(coupled_roads, tmp_path):
    """``rideid identify --model base`` on the two unknown roads with the hubs' coupling declared (refused before:
    "this version fits sensor chains on known tracks only"): the twelve within 0.5 % and 3 std_robust, the roads'
    classes. Measured (seed 1, two cores shared): 62 s, largest error 0.17 % (k_tf), largest error over
    std_robust 1.6 (a)."""
    out = tmp_path / "fit"
    assert main(["identify", str(coupled_roads), "--out", str(out), "--seed", "1", "--model", "base",
                 "--no-report", "--quiet"]) == 0
    doc = json.loads((out / "result.json").read_text())
    truth = tomllib.loads((coupled_roads / "truth.toml").read_text())["truth"]
    for n, t in truth.items():
        d = doc["parameters"][n]
        assert abs(d["value"] / t - 1) < 0.005, (n, d["value"], t)
        assert abs(d["value"] - t) < 3 * d["std_robust"], (n, (d["value"] - t) / d["std_robust"])
    assert {k: v["iso8608_class"] for k, v in doc["roads"].items()} == {"B40": "B", "C25": "C"}


def test_the_as_built_result_keeps_the_as_drawn_hints_and_says_so():
    """The coupling hints are computed in the time domain on the tracks as drawn
    (rideid.estimate.assess.sensor_check.coupling_hints); the as-built stage's verdict is new, and used to drop them.
    Now they are kept with a note saying where they come from, and lead the advice of a verdict that is not
    adequate; without an as-drawn fit (unknown roads) no hint is made up."""
    hint = {"channel": "axle_az_fl", "highpass_hz": 0.3, "rss_reduction": 0.74,
            "message": "axle_az_fl: the data look AC-coupled"}
    start = SimpleNamespace(adequacy={"adequate": False, "sensor_hints": [hint]})
    bad = {"adequate": False, "reasons": ["structure"], "advice": "Add a model group."}
    out = anyroad._carry_sensor_hints(bad, start)
    assert out["sensor_hints"] == [hint] and "tracks as drawn" in out["sensor_hints_note"]
    assert out["advice"] == "axle_az_fl: the data look AC-coupled. Add a model group."
    good = anyroad._carry_sensor_hints({"adequate": True, "advice": None}, start)
    assert good["advice"] is None and good["sensor_hints"] == [hint]
    assert anyroad._carry_sensor_hints(bad, None) == bad          # unknown roads: nothing carried
    assert anyroad._carry_sensor_hints(None, start) is None       # not assessed
    assert "sensor_hints" not in anyroad._carry_sensor_hints(bad, SimpleNamespace(adequacy=None))


@pytest.mark.parametrize("case", ["coupled", "uncoupled", "declared"])
def test_the_road_fit_names_an_undeclared_coupling(tmp_path, case):
    """On runs whose road is fitted the time-domain hint has no simulation to compare; the road fit's hint
    (sensor_check.road_coupling_hints) projects the car with the road free, with and without a trial high-pass.
    Two of the SUV's runs on tracks as built, at the true car: hubs coupled at 0.5 Hz and not declared -> the four
    hubs at 0.5 Hz, the residual cut by at least 90 % (measured 100 % on five runs); not coupled, or coupled and
    declared -> no hint (every trial made the residual 5-18 times larger on five runs)."""
    from rideid.estimate.assess.sensor_check import road_coupling_hints

    kw = {"coupled": dict(declare=False), "uncoupled": dict(highpass_hz=None), "declared": dict(declare=True)}[case]
    ds = rideid.load_dataset(write_tracks_dataset(tmp_path / case, seed=4, runs=RUNS[1:3], **kw))
    P = as_vector({n: SUV_TRUTH.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    trs = [asbuilt.prepare_track_run(ds, r) for r in ds.runs]
    hints = road_coupling_hints(P, ds.geometry, [tr.rr for tr in trs], {r.id: ds.sensor_filters(r.id)
                                                                        for r in ds.runs})
    if case != "coupled":
        assert hints == []
        return
    assert [h["channel"] for h in hints] == list(HUBS)
    assert all(h["highpass_hz"] == 0.5 and h["rss_reduction"] > 0.9 for h in hints)
    assert "`[channels] axle_az_fl = { ..., highpass = 0.5 }`" in hints[0]["message"]


def test_the_road_fit_hint_trials_run_side_by_side_and_name_the_same_on_one_or_two_cores(tmp_path, both_cores):
    """The road fit's coupling trials (sensor_check.road_coupling_hints: the declared chains and 24 trial
    high-passes, each a road fit of every run) are independent and run on as many threads as the kernel has
    (rideid.model.batch.thread_map); with one (rideid.model.backend.one_thread) one after the other. Two of the
    SUV's runs on tracks as built, hubs coupled at 0.5 Hz and not declared, at the true car: the same hints, their
    reductions equal to the last bit (the best trial is taken in the trials' order, not the order they end)."""
    from rideid.estimate.assess.sensor_check import road_coupling_hints
    from rideid.model import backend

    ds = rideid.load_dataset(write_tracks_dataset(tmp_path / "c", seed=4, runs=RUNS[1:3], declare=False))
    P = as_vector({n: SUV_TRUTH.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    rruns = [asbuilt.prepare_track_run(ds, r).rr for r in ds.runs]
    filters = {r.id: ds.sensor_filters(r.id) for r in ds.runs}
    two = road_coupling_hints(P, ds.geometry, rruns, filters)
    with backend.one_thread():
        one = road_coupling_hints(P, ds.geometry, rruns, filters)
    assert [h["channel"] for h in two] == list(HUBS) and two[0]["rss_reduction"] > 0.9
    assert one == two  # floats compared exactly


@pytest.mark.slow
def test_rideid_identify_names_an_undeclared_coupling_on_tracks_as_built(tmp_path, capsys):
    """The SUV's five runs on tracks as built, hubs coupled at 0.5 Hz and not declared, `rideid identify --model
    base`: the as-built fit takes the coupling up in the springs (k_sf +21 %, 37 std_total, measured) and its
    residual test sees nothing; the road fit's hint names the four hubs at 0.5 Hz and the verdict is not
    adequate, in the terminal and in result.json (30 s). Declared, the same data give the twelve within 0.6 %
    and no hint (test_identify_on_tracks_as_built_through_coupled_hubs)."""
    folder = write_tracks_dataset(tmp_path / "c", seed=4, declare=False)
    code = main(["identify", str(folder), "--out", str(tmp_path / "fit"), "--model", "base", "--seed", "1",
                 "--quiet", "--no-report"])
    out = capsys.readouterr().out
    assert code == 0
    doc = json.loads((tmp_path / "fit" / "result.json").read_text())
    ad = doc["adequacy"]
    assert ad["adequate"] is False and [h["channel"] for h in ad["sensor_hints"]] == list(HUBS)
    assert {h["highpass_hz"] for h in ad["sensor_hints"]} == {0.5}
    assert "road fit" in ad["sensor_hints_note"] and "AC-coupled" in ad["reasons"][0]
    assert out.count("hint: axle_az_fl, axle_az_fr, axle_az_rl, axle_az_rr: the data look AC-coupled") == 1
    assert "MODEL NOT ADEQUATE" in out


def _undeclared(folder, dst):
    """A copy of the dataset ``folder`` whose ``[channels]`` no longer declare the hubs' high-pass."""
    import shutil

    import tomli_w
    shutil.copytree(folder, dst)
    doc = tomllib.loads((dst / "dataset.toml").read_text())
    for c in HUBS:
        doc["channels"][c].pop("highpass")
    (dst / "dataset.toml").write_text(tomli_w.dumps(doc))
    return dst


@pytest.mark.slow  # 40 trial projections per case (10 s each): make test stays under 10 minutes
@pytest.mark.parametrize("declared", [False, True])
def test_the_road_fit_names_an_undeclared_coupling_on_unknown_roads(coupled_roads, tmp_path, declared):
    """On unknown roads there is no drawing and no time-domain hint; the road fit's own trial high-passes
    (sensor_check.road_coupling_hints at FREE_ROAD_HINT_REDUCTION, the free road taking up part of the signature)
    name the four hubs and the corner at the true car when the 0.5 Hz coupling is not declared (the residual cut by
    more than 80 %: without the chain it is 7-8 times the noise, test_unknown_roads_carry_the_declared_chain;
    measured 87 %), and nothing when it is (every trial makes the residual larger)."""
    from rideid.estimate.assess.sensor_check import FREE_ROAD_HINT_REDUCTION

    folder = coupled_roads if declared else _undeclared(coupled_roads, tmp_path / "undeclared")
    ds = rideid.load_dataset(folder)
    rruns = anyroad.prepare_road_runs(ds)
    sc = rideid.default_scenario()
    P = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    hints = anyroad._road_sensor_hints(P, ds.geometry, rruns, ds, FREE_ROAD_HINT_REDUCTION)
    assert FREE_ROAD_HINT_REDUCTION == 0.2
    if declared:
        assert hints == []
        return
    assert [h["channel"] for h in hints] == list(HUBS)
    assert all(h["highpass_hz"] == 0.5 and h["rss_reduction"] > 0.8 for h in hints)


@pytest.mark.slow
def test_rideid_identify_names_an_undeclared_coupling_on_unknown_roads(coupled_roads, tmp_path, capsys):
    """`rideid identify --model base` on the two unknown roads, hubs coupled at 0.5 Hz and not declared: the fit
    takes the coupling up (k_sr +18 %, measured); the road fit's hint names the four hubs (its best trial, 0.2 Hz,
    cut the residual 35 %: benchmarks/road_hints.py), once in the terminal, and result.json, which has no residual
    verdict for road runs alone, says not adequate with the sensors suspect (about 60 s)."""
    folder = _undeclared(coupled_roads, tmp_path / "undeclared")
    code = main(["identify", str(folder), "--out", str(tmp_path / "fit"), "--model", "base", "--seed", "1",
                 "--quiet", "--no-report"])
    out = capsys.readouterr().out
    assert code == 0
    ad = json.loads((tmp_path / "fit" / "result.json").read_text())["adequacy"]
    assert ad["adequate"] is False and ad["sensors_suspect"] is True
    assert [h["channel"] for h in ad["sensor_hints"]] == list(HUBS)
    assert 0.2 <= ad["sensor_hints"][0]["rss_reduction"] < 0.5
    assert "unknown roads" in ad["sensor_hints_note"] and ad["not_assessed"] == ["B40", "C25"]
    assert out.count("hint: axle_az_fl, axle_az_fr, axle_az_rl, axle_az_rr: the data look AC-coupled") == 1
    assert "MODEL NOT ADEQUATE" in out
