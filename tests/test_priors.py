"""Set-up values are priors (SPEC §13): a run's speed and start and a track's drawn size may carry their std, a
plain number a documented default width; a speed the data move beyond its prior is named with the run and the
speed the data show, never blamed on the wiring; accelerations written in g are refused naming the
accelerometers.

The data come from the independent simulator of tests/asbuilt_tracks.py (SciPy ``lsim`` of the SUV written from
SPEC §1, the rigid-disc envelope by brute force, exact drawings here, 1 % white sensor noise), its runs declared
at a speed 1 % off the one driven: the slips of a test day (10.1 typed for 10 m/s).
"""

import csv
import sys
import time
import tomllib
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.cli import main
from rideid.data.schema import manifest as man_schema
from rideid.data.schema.manifest import parse_dataset_manifest
from rideid.errors import DataError
from rideid.estimate.assess import motion
from rideid.estimate.problem import asbuilt, blocks
from rideid.estimate.problem.cost import ParameterSpace

sys.path.insert(0, str(Path(__file__).parent))
from asbuilt_tracks import ACCELS, RUNS, in_g, write_exact  # noqa: E402
from cars import SUV_TRUTH  # noqa: E402

BY_ID = {r[0]: r for r in RUNS}


def _write(folder, runs, speeds=None):
    """The SUV on exact drawings (amplitude 1, no unevenness), 1 % noise; ``speeds``: run id -> declared speed."""
    return write_exact(folder, runs, speeds)


@pytest.fixture(scope="module")
def slipped(tmp_path_factory):
    """H_HH (herringbone, 10 m/s driven, 3 s) declared at 10.1 m/s."""
    return _write(tmp_path_factory.mktemp("slip") / "ds", ["H_HH"], {"H_HH": 10.1})


# -- the manifest ---------------------------------------------------------------------------------------------

def _doc():
    return {"name": "x", "vehicle": {"wheelbase": 2.7, "track_front": 1.5, "track_rear": 1.5, "tire_radius": 0.3},
            "known": {"total_mass": 1500.0},
            "tracks": [{"id": "wb", "kind": "washboard", "start": 3.0, "amplitude": {"value": 0.01, "std": 0.0005},
                        "wavelength": 0.8, "cycles": 10},
                       {"id": "tw", "kind": "chassis_twist", "start": 3.0, "height": 0.08, "bump_length": 1.6,
                        "spacing": 4.0, "bumps": 2}],
            "runs": [{"id": "A", "track": "wb", "speed": {"value": 10.0, "std": 0.02}, "file": "runs/A.csv"},
                     {"id": "B", "track": "tw", "speed": 5.0, "file": "runs/B.mf4",
                      "start": {"value": 2.5, "std": 0.002}},
                     {"id": "C", "track": "tw", "speed": 4.0, "file": "runs/C.csv"}]}


def test_set_up_values_are_read_with_their_std_and_written_back(tmp_path):
    """A declared std is kept (speed m/s, start s, a track's size m, relative about its drawing); a plain number
    gets the default width (0.3 % of a speed, 5 ms of a start, 5 % of a size); the document round-trips."""
    m = parse_dataset_manifest(_doc(), tmp_path / "dataset.toml")
    a, b, c = (m.run(k) for k in "ABC")
    assert a.speed == 10.0 and a.speed_prior() == (10.0, 0.02, True)
    assert c.speed_prior() == (4.0, pytest.approx(man_schema.SPEED_STD_DEFAULT * 4.0), False)
    assert man_schema.SPEED_STD_DEFAULT == 0.003 and man_schema.START_STD_DEFAULT == 0.005
    assert b.options["start"] == 2.5 and b.start_std == 0.002 and b.start_prior_std() == 0.002
    assert c.start_prior_std() == man_schema.START_STD_DEFAULT
    assert m.tracks["wb"].keys["amplitude"] == 0.01
    assert m.size_prior("wb") == (pytest.approx(0.05), True)
    assert m.size_prior("tw") == (man_schema.SIZE_STD_DEFAULT, False)
    back = m.to_dataset_doc()
    assert back["runs"][0]["speed"] == {"value": 10.0, "std": 0.02}
    assert back["runs"][1]["start"] == {"value": 2.5, "std": 0.002} and back["runs"][2]["speed"] == 4.0
    assert back["tracks"][0]["amplitude"] == {"value": 0.01, "std": 0.0005} and back["tracks"][1]["height"] == 0.08
    again = parse_dataset_manifest(back, tmp_path / "dataset.toml")
    assert again.run("A").speed_prior() == a.speed_prior() and again.size_std == m.size_std


@pytest.mark.parametrize("edit, msg", [
    (lambda d: d["runs"][0].update(speed={"value": 10.0, "std": 12.0}),
     "runs[0] (id 'A') speed std: 12 is not smaller than the value 10"),
    (lambda d: d["runs"][1].update(start={"value": "auto", "std": 0.01}),
     "runs[1] (id 'B') start value: expected a finite number, got 'auto'"),
    (lambda d: d["runs"][0].update(speed={"value": 10.0, "sd": 0.1}),
     "runs[0] (id 'A') speed: unknown key 'sd' in a declared value"),
    (lambda d: d["tracks"][0].update(wavelength={"value": 0.8, "std": 0.01}),
     "tracks[0] (id 'wb') wavelength: a standard uncertainty { value, std } is accepted only in [known] and "
     "[vehicle], a dataset run's speed and start and a track's amplitude or height"),
])
def test_a_bad_prior_is_one_line_naming_the_key(edit, msg, tmp_path):
    doc = _doc()
    edit(doc)
    with pytest.raises(DataError) as e:
        parse_dataset_manifest(doc, tmp_path / "dataset.toml")
    assert msg in str(e.value) and "\n" not in str(e.value)


def test_a_scenario_runs_speed_is_the_truth_and_takes_no_std(tmp_path):
    doc = _doc()
    doc["truth"] = dict(SUV_TRUTH)
    doc["known"] = {}
    doc["runs"] = [{"id": "A", "track": "wb", "speed": {"value": 10.0, "std": 0.02}, "fs": 200.0, "duration": 3.0}]
    with pytest.raises(DataError, match=r"runs\[0\] \(id 'A'\) speed: a standard uncertainty"):
        man_schema.parse_scenario(doc, tmp_path / "s.toml")


# -- a speed slip at load ---------------------------------------------------------------------------------------

def test_a_one_percent_speed_slip_is_named_at_load_and_never_blamed_on_the_wiring(slipped):
    """10.1 declared, 10 driven: before SPEC §13 the axle channels were said to be swapped (and a sign) and the
    fix corrupted the data. Now one warning names the run, the declared speed and the one the data show (the
    lags against the nominal car: 10.007 ± 0.029 m/s measured), within a second of loading; the fit starts there,
    the declared speed its prior."""
    t0 = time.perf_counter()
    with pytest.warns(rideid.DataWarning) as rec:
        ds = rideid.load_dataset(slipped)
    wall = time.perf_counter() - t0
    msgs = [str(w.message) for w in rec]
    assert not any("wired" in m for m in msgs), msgs
    named = [m for m in msgs if "declared speed 10.1 m/s" in m]
    assert len(named) == 1 and "run 'H_HH'" in named[0], msgs
    v = float(named[0].split("the data match the track at ")[1].split(" ")[0])
    assert v == pytest.approx(10.0, rel=0.001)
    run = ds.manifest.run("H_HH")
    assert run.speed == pytest.approx(v, rel=1e-3) and run.declared_speed == 10.1
    assert run.speed_prior() == (10.1, pytest.approx(0.0303), False)
    assert any(f.check == "speed" and f.fix["speed"] == run.speed for f in ds.findings)
    assert wall < 60.0
    # what a fit on the tracks as drawn records of it (result.json preprocessing.<run>.motion): never silently
    from rideid.data.dataset import held_motion
    held = held_motion(ds, run)
    assert held["speed"]["estimate"] == run.speed and held["speed"]["declared"] == 10.1
    assert held["speed"]["std"] == pytest.approx(float(named[0].split(" ± ")[1].split(" ")[0]), rel=0.05)
    assert held["estimated"].startswith("at load, from the lags")
    assert ds.preprocessed["H_HH"]["motion"] == held  # the dataset carries it from load (the fit copies it)
    # an adequate verdict on these data is not a clean one: the set-up slip is a caveat (terminal, report, record)
    from rideid.estimate.assess.adequacy import caveats, setup_caveat
    slip = setup_caveat(ds.findings)
    assert slip.startswith(f"a declared speed the data contradict: H_HH (declared 10.1, the data {v:.3f} m/s)")
    # a dataset read anew (a candidate of the model choice polished at its parent's starts) keeps what load found:
    # it lost it, and a fit that kept such a candidate said "model adequate", checks [], the speed "not moved"
    for again in (ds.with_starts({}), ds.with_data(dict(ds.data)), ds.subset(ds.runs)):
        assert again.findings == ds.findings and again.preprocessed["H_HH"]["motion"] == held
    assert caveats({"adequate": True, "reasons": ["ok"], "setup_caveat": slip}) == [slip]
    assert setup_caveat([f for f in ds.findings if f.check != "speed"]) is None
    assert "estimated with the car when they are fitted as built" in named[0]  # what the fit does, said as it is


# -- the speed estimated with the car -----------------------------------------------------------------------------

def test_motion_prior_rows_and_their_jacobian():
    """The rows are (value - declared) / std times the weight; their Jacobian in (relative speed, shift s) by
    central differences (the rows are linear: equal to rounding)."""
    pr = asbuilt.MotionPrior(speed=(10.1, 0.03, False), start=(0.0, 0.005, False))
    v0, s0, w = 10.0, 0.001, 0.7
    r = pr.rows(v0, s0, np.zeros(2), w)
    assert r == pytest.approx([w * (10.0 - 10.1) / 0.03, w * 0.001 / 0.005])
    J = pr.jacobian(v0, w)
    h = 1e-3
    for j in range(2):
        p = np.zeros(2)
        p[j] = h
        fd = (pr.rows(v0, s0, p, w) - pr.rows(v0, s0, -p, w)) / (2 * h * asbuilt.MOTION_SCALE[j])
        assert fd == pytest.approx(J[:, j], rel=1e-9)
    assert asbuilt.MotionPrior(speed=None, start=None).rows(v0, s0, np.zeros(2)).size == 0


def test_a_motion_record_names_a_value_beyond_three_prior_std(slipped):
    """The record of result.json (SPEC §13): estimate, std, declared, prior std; a speed 3.3 prior std from the
    declared one is named with the run and the value, a start 0.2 of them is not."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = rideid.load_dataset(slipped)
    run = ds.manifest.run("H_HH")
    prior = asbuilt.motion_prior(ds, run)
    tr = asbuilt.prepare_track_run(ds, run)
    fitted = {"speed_m_s": 10.0, "speed_std_m_s": 0.0002, "start_shift_s": 0.001, "start_shift_std_s": 0.0001}
    m = motion.motion_record(fitted, prior, tr)
    assert m["speed"] == {"estimate": 10.0, "std": 0.0002, "unit": "m/s", "declared": 10.1,
                          "prior_std": pytest.approx(0.0303), "prior": "default",
                          "from_declared_in_prior_std": pytest.approx(-0.1 / 0.0303)}
    assert m["start"]["estimate"] == 0.001 and m["start"]["declared"] == 0.0 and m["start"]["prior_std"] == 0.005
    assert m["named"] == ["run H_HH: declared speed 10.10 m/s, the data show 10.00000 ± 0.00020 m/s (-0.99 %, "
                          "3.3 times the declared value's std of 0.03 m/s, the default width)"]
    found = motion.motion_findings({"H_HH": m})
    assert len(found) == 1 and found[0]["check"] == "motion" and found[0]["channel"] == "speed"
    assert found[0]["severity"] == "warning" and found[0]["run"] == "H_HH"
    assert motion.motion_record(dict(fitted, speed_m_s=10.05), prior, tr)["named"] == []
    # the track's drawn size as this run saw it: its amplitude factor against the default 5 % prior
    assert tr.size_std == pytest.approx(0.05)
    fit = SimpleNamespace(alpha=1.2, alpha_std=0.004)
    sized = motion.with_size(m, fit, tr, ds)
    assert sized["size"] == {"estimate": 1.2, "std": 0.004, "unit": "relative", "declared": 1.0, "prior_std": 0.05,
                             "prior": "default", "from_declared_in_prior_std": pytest.approx(4.0)}
    assert sized["named"][1] == ("track herringbone_high (run H_HH): drawn size amplitude = 0.008 m, the data show "
                                 "1.2000 ± 0.0040 of it (4.0 times the declared size's std of 5 %, the default width)")
    assert [f["channel"] for f in motion.motion_findings({"H_HH": sized})] == ["speed", "size"]
    assert len(motion.with_size(m, SimpleNamespace(alpha=1.03, alpha_std=0.004), tr, ds)["named"]) == 1
    # the data show the size of another track of the family (herringbone_low, 0.005 m): it is named
    high = ds.manifest.tracks["herringbone_high"]
    family = SimpleNamespace(tracks={"herringbone_high": high, "herringbone_low": SimpleNamespace(
        kind=high.kind, keys=dict(high.keys, amplitude=0.005))}, size_prior=ds.manifest.size_prior)
    low = motion.with_size(m, SimpleNamespace(alpha=0.625, alpha_std=0.004), tr,
                            SimpleNamespace(manifest=family))["named"][1]
    assert low.endswith("; track 'herringbone_low' (amplitude = 0.005 m) is that size: is it the run's track?"), low
    assert "is that size" not in sized["named"][1]  # 1.2 x 0.008 m is no declared track


@pytest.mark.slow  # 10 s on an idle machine, 220 s on two cores shared by other work: two placements of the drawing
def test_the_speed_is_estimated_with_the_car_and_named(slipped):
    """At the true car the herringbone run, started from the speed the lags show, placed with its declared
    speed's prior (10.1 ± 0.03): the speed comes within 0.02 % of the 10 m/s driven (measured 10.000), its
    standard error from the run's motion Jacobian, and the run's motion record names it: more than 3 of the
    prior's std from the declared value."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = rideid.load_dataset(slipped)
    run = ds.manifest.run("H_HH")
    space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=())
    P = space.full(np.array([[SUV_TRUTH[n] for n in space.names]]))[0]
    prior = asbuilt.motion_prior(ds, run)
    assert prior.speed == (10.1, pytest.approx(0.0303), False) and prior.start == (0.0, 0.005, False)
    tr = asbuilt.prepare_track_run(ds, run)
    tr.prior = asbuilt.estimate_prior(P, ds.geometry, tr)
    tr, rec = blocks.align_motion(P, ds.geometry, tr, ds, run, "amplitude", prior)
    tr.prior = asbuilt.estimate_prior(P, ds.geometry, tr)
    tr, rec = blocks.align_motion(P, ds.geometry, tr, ds, run, "prior", prior)
    assert rec["speed_m_s"] == pytest.approx(10.0, rel=2e-4)
    e = asbuilt.residuals(P, ds.geometry, tr)
    Jm = blocks.motion_jacobian(P, ds.geometry, tr, ds, run)
    sd = np.sqrt(np.diag(float(e @ e) / e.size * np.linalg.inv(Jm.T @ Jm)))
    assert abs(rec["speed_m_s"] / 10.0 - 1) < 3 * sd[0] + 1e-5
    m = motion.motion_record(dict(rec, speed_std_m_s=10.0 * sd[0], start_shift_std_s=sd[1]), prior, tr)
    assert m["speed"]["declared"] == 10.1 and m["speed"]["prior"] == "default"
    assert m["speed"]["estimate"] == pytest.approx(10.0, rel=2e-4)
    assert m["speed"]["from_declared_in_prior_std"] == pytest.approx(-0.1 / 0.0303, rel=0.01)
    assert len(m["named"]) == 1 and m["named"][0].startswith("run H_HH: declared speed 10.10 m/s, the data show ")
    shown = float(m["named"][0].split("the data show ")[1].split(" ")[0])
    assert shown == pytest.approx(10.0, rel=2e-4)
    found = motion.motion_findings({"H_HH": m})
    assert found[0]["check"] == "motion" and found[0]["channel"] == "speed" and found[0]["run"] == "H_HH"


# -- units ------------------------------------------------------------------------------------------------------


def test_accelerations_in_g_are_refused_naming_the_accelerometers(tmp_path, capsys):
    """Every acceleration of a SPEC CSV written in g: the rigid-body identities say the gyros and the
    accelerometers disagree by g, and before SPEC §13 the gyros were 'fixed' (scale 0.102; following it: 7
    parameters at their bounds). The amplitudes against the nominal car decide: the accelerometers, all eight
    named, exit 2, one line; the fix rideid prints loads cleanly."""
    src = _write(tmp_path / "ds", ["H_HH"])
    bad = in_g(src, tmp_path / "g")
    rc = main(["identify", str(bad), "--out", str(tmp_path / "fit"), "--quiet", "--no-report"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("rideid: error: "), err
    assert "run 'H_HH': the accelerations read 9.81x too small: " + ", ".join(ACCELS) + " look written in g" in err[0]
    assert "pitch_rate" not in err[0].split("Fix the channel map:")[1]
    assert not (tmp_path / "fit").exists()
    fix = err[0].split("Fix the channel map: ")[1].split(" (or set")[0]
    doc = tomllib.loads((bad / "dataset.toml").read_text())
    doc["channels"] = {}
    for line in fix.split("; "):
        key, tab = line.split(" = ", 1)
        doc["channels"][key] = tomllib.loads(f"x = {tab}")["x"]
    assert sorted(doc["channels"]) == sorted(ACCELS) and {e["unit"] for e in doc["channels"].values()} == {"g"}
    (bad / "dataset.toml").write_text(tomli_w.dumps(doc))
    with warnings.catch_warnings():
        warnings.simplefilter("error", rideid.DataWarning)
        ds = rideid.load_dataset(bad)
    ref = rideid.load_dataset(src)
    assert np.allclose(ds.data["H_HH"].matrix(), ref.data["H_HH"].matrix(), rtol=1e-6, atol=1e-9)


# -- a gross misfit said early ----------------------------------------------------------------------------------

def test_a_gross_first_fit_stops_before_the_model_choice_with_the_set_up_first(slipped):
    """rideid.estimate.assess.adequacy.gross_misfit: a run with more than GROSS_ERROR of its signal unexplained, or
    GROSS_BOUNDS parameters at their bounds, is a verdict naming the runs and the set-up (speed, start, rate,
    units, sensor chain) before any extension; below both, None. run_errors: squared residual over squared data,
    over the channels measured (a closed form on a known response)."""
    from rideid.estimate.assess.adequacy import GROSS_BOUNDS, GROSS_ERROR, gross_misfit, run_errors, verdict_paragraph
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = rideid.load_dataset(slipped)
    y = ds.data["H_HH"].matrix()
    errs = run_errors(ds, {"H_HH": 0.5 * y, "other": y})
    assert list(errs) == ["H_HH"] and errs["H_HH"] == pytest.approx(0.25)
    assert gross_misfit({"H_HH": 0.25}, ["k_sf", "c_sf"]) is None
    v = gross_misfit({"H_HH": 0.6, "W_H": 0.01}, [], ds.findings)
    assert v["adequate"] is False and v["gross_misfit"]["threshold"] == GROSS_ERROR
    assert v["reasons"] == ["the first fit leaves 60 % of run H_HH's signal unexplained (an extension mends at "
                            "most about 10 %)"]
    text = verdict_paragraph(v)
    assert text.index("speed and start") < text.index("the sample rate") < text.index("sensor chain")
    assert "model choice was not run" in text and "declared speed 10.1 m/s" in text
    assert "--model auto" not in text
    bounds = gross_misfit({}, ["m_uf", "k_tf", "k_sr"][:GROSS_BOUNDS])
    assert bounds["reasons"] == [f"{GROSS_BOUNDS} parameters ended at their search bounds (m_uf, k_tf, k_sr)"]


@pytest.mark.parametrize("rid, named", [("T_HH", True), ("W_H", True)])
def test_a_slip_on_the_twist_and_the_washboard(rid, named, tmp_path):
    """1 % high on the twist at 5 m/s (5.05) and on the washboard at 10 m/s (10.1): the lags, read twice (against
    the declared speed, then against the speed they showed), put both within 0.1 % of the speed driven (measured
    4.997 and 10.002; read once, the washboard's was 10.012, 2.9 prior std from the declared value: a note);
    more than 3 of the prior's std from the declared value: a warning naming the run and the speed; no wiring
    blamed."""
    true = BY_ID[rid][2]
    folder = _write(tmp_path / "ds", [rid], {rid: round(true * 1.01, 6)})
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        ds = rideid.load_dataset(folder)
    msgs = [str(w.message) for w in rec]
    assert not any("wired" in m for m in msgs), msgs
    run = ds.manifest.run(rid)
    assert run.speed == pytest.approx(true, rel=0.001) and run.declared_speed == pytest.approx(true * 1.01)
    f = next(f for f in ds.findings if f.check == "speed")
    assert f.severity == ("warning" if named else "note") and f.run == rid
    assert any(f"run '{rid}'" in m and "declared speed" in m for m in msgs) == named


@pytest.mark.slow  # three identifications of three runs with the default settings: minutes on two shared cores
@pytest.mark.parametrize("rid", ["T_HH", "H_HH", "W_H"])
def test_a_one_percent_slip_on_any_run_is_named_or_found(rid, tmp_path, capsys):
    """The SUV's twist, herringbone and washboard runs (exact drawings, 1 % noise), one of them declared 1 % high:
    `rideid identify` with the default settings names the run and the speed (at load, or after the fit from the
    runs on tracks as built), or every estimate is within 1 % of the truth. The load's diagnosis comes within a
    minute. Measured (seed 1): each named at load in 0.2-0.4 s (0.9-2.6 s on two cores shared by other work) and
    again after the fit (the twist's 5.05 found 5.00010 ± 0.00013 m/s), identify 17-18 s (45-51 s shared), the
    worst estimate 0.6-1.8 % off (the tracks as built rejected on the washboard run's low-frequency
    "unevenness", docs/tracks-as-built.md); 0.15-0.16 % with that run's unevenness held at the prior (setting
    asbuilt.boundary_share = 10, off by default: it also hid a car's missing anti-roll bars)."""
    true = BY_ID[rid][2]
    folder = _write(tmp_path / "ds", ["T_HH", "H_HH", "W_H"], {rid: round(true * 1.01, 6)})
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        rideid.load_dataset(folder)
    t_load = time.perf_counter() - t0
    at_load = [str(w.message) for w in rec if f"run '{rid}'" in str(w.message) and "declared speed" in str(w.message)]
    out = tmp_path / "fit"
    t0 = time.perf_counter()
    rc = main(["identify", str(folder), "--out", str(out), "--quiet", "--no-report", "--seed", "1"])
    t_fit = time.perf_counter() - t0
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "wired" not in captured.err
    res = rideid.load_result(out)
    after = [c["message"] for c in res.checks if c.get("check") == "motion" and c.get("run") == rid]
    errors = {n: res.parameters[n] / SUV_TRUTH[n] - 1 for n in SUV_TRUTH}
    worst = max(abs(e) for e in errors.values())
    print(f"{rid}: load {t_load:.1f} s ({'named' if at_load else 'not named'}), identify {t_fit:.1f} s, "
          f"named after the fit: {bool(after)}, worst estimate {100 * worst:.2f} %")
    assert at_load or after or worst < 0.01, (at_load, after, errors)
    if at_load:
        assert t_load < 60.0


def test_a_start_off_by_two_samples_is_named_and_never_blamed_on_the_wiring(tmp_path):
    """A SPEC CSV whose rows begin 10 ms late (two samples at 200 Hz: the front axle at x = 0 at -0.010 s): before,
    the herringbone's axle channels were said to be wired round (and a sign); now a warning names the run and the
    start the lags show, within a sample."""
    src = _write(tmp_path / "ds", ["H_HH"])
    for f in (src / "runs").glob("*.csv"):
        rows = list(csv.reader(f.open()))
        body = rows[1:]
        with f.open("w", newline="") as fh:
            csv.writer(fh).writerows([rows[0]] + [[body[i][0]] + body[i + 2][1:] for i in range(len(body) - 2)])
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        ds = rideid.load_dataset(src)
    msgs = [str(w.message) for w in rec]
    assert not any("wired" in m for m in msgs), msgs
    f = next(f for f in ds.findings if f.check == "track" and f.channel == "start")
    assert f.run == "H_HH" and f.fix["start_shift"] == pytest.approx(-0.010, abs=0.005)
    assert any("run 'H_HH': the data match the track with the front axle at x = 0 at -0.01" in m for m in msgs)


@pytest.mark.slow  # one identification (the first fit, then the tracks as built): about 70 s on two shared cores
def test_a_gross_first_fit_is_said_before_the_model_choice(tmp_path, capsys):
    """Every acceleration in g and the wiring check switched off ([checks] wiring = "off"): the first fit leaves
    most of the signal unexplained, and `rideid identify` stops before the model choice with the set-up to
    check (measured: 20-31 s in all, 73 s with the two cores shared by other work; cost 5.0)."""
    src = _write(tmp_path / "ds", ["T_HH", "H_HH", "W_H"])
    bad = in_g(src, tmp_path / "g")
    doc = tomllib.loads((bad / "dataset.toml").read_text())
    doc["checks"] = {"wiring": "off"}
    (bad / "dataset.toml").write_text(tomli_w.dumps(doc))
    t0 = time.perf_counter()
    rc = main(["identify", str(bad), "--out", str(tmp_path / "fit"), "--quiet", "--no-report", "--seed", "1"])
    wall = time.perf_counter() - t0
    out = capsys.readouterr().out
    assert rc == 0
    res = rideid.load_result(tmp_path / "fit")
    assert "gross_misfit" in res.adequacy and res.adequacy["adequate"] is False
    assert res.model["selection"].startswith("auto (not run")
    assert "so the model choice was not run: check the set-up first" in " ".join(out.split())
    # the report's model section: the first fit (kept, as drawn) and the rival fitted for it, each with its values
    import json
    from rideid.report.estimate_sections import model_rows
    section = model_rows(json.loads((tmp_path / "fit" / "result.json").read_text()))
    assert section["heads"][0]["chosen"] and not any(h["chosen"] for h in section["heads"][1:])
    assert section["heads"][0]["label"].endswith("(as drawn)") and section["first_fit"] is None
    assert section["weighed"] is False
    assert all(len(r["cells"]) == len(section["heads"]) for r in section["rows"]) and section["rows"]
    print(f"gross misfit said after {wall:.0f} s")
    assert wall < 180.0
