"""Damper curves on unknown roads (docs/any-road.md "Damper curves on unknown roads"): the suspension velocities read
off the accelerometers, the curves' departure from the linear car as a known input, and a fit end to end."""

import contextlib
import io
import json
import shutil
from types import SimpleNamespace

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.cli import main
from rideid.estimate.assess.responses import run_velocities
from rideid.estimate.sections import DampersSection
from rideid.data.scenario import default_scenario
from rideid.estimate.fit import road_curves
from rideid.estimate.problem import roadfit
from rideid.estimate.problem.blocks import speed_runs
from rideid.model.nonlinear import DEFAULT_KNOTS
from rideid.model.params import INDEX, SUSPENSION_NAMES, total_mass

from test_checks import VAN as VAN_TWIST
from test_roadfit import FS, car, road_run


def test_suspension_velocities_from_the_accelerometers():
    """Closed form: a wheel moving ``A sin(w t + p)`` under a body moving at half its frequency, off the DFT's bins,
    sampled at 200 Hz (a suspension on a road moves at 1-2 Hz, body, and 10-15 Hz, wheel). Less its drift (a cubic
    spline, knots setting ``roadfit.velocity_drift`` apart) the velocity is within 3 % of its RMS away from the
    record's first and last second, there within 30 % (26 % measured for the 1.65 Hz body: the spline takes some of
    the motion with it); a constant accelerometer bias (a ramp of velocity, cubic) leaves it as it was."""
    t = np.arange(int(10.37 * FS)) / FS
    y = np.zeros((t.size, 10))
    v_true = np.zeros((t.size, 4))
    for i, (f, p) in enumerate(((3.3, 0.2), (2.4, 1.0), (8.9, 2.0), (11.3, -0.5))):
        w = 2 * np.pi * f
        y[:, 4 + i] = -0.01 * w * w * np.sin(w * t + p)           # axle i
        y[:, i] = 0.002 * w * w * np.sin(0.5 * w * t)             # and the body corner above it
        v_true[:, i] = 0.01 * w * np.cos(w * t + p) + 0.004 * w * np.cos(0.5 * w * t)
    v = roadfit.suspension_velocities(y, FS)
    v_true -= v_true.mean(axis=0)
    inner = slice(int(FS), -int(FS))
    rms = v_true.std(axis=0)
    assert np.all(np.sqrt(np.mean((v - v_true)[inner] ** 2, axis=0)) < 0.03 * rms)
    for end in (slice(0, int(FS)), slice(-int(FS), None)):
        assert np.all(np.sqrt(np.mean((v - v_true)[end] ** 2, axis=0)) < 0.3 * rms)
    biased = y.copy()
    biased[:, 5] += 0.05                                          # 0.05 m/s^2 on the front right axle
    assert np.max(np.abs(roadfit.suspension_velocities(biased, FS) - v)) < 1e-9


@pytest.fixture(scope="module")
def linear_road(tmp_path_factory):
    geom, P = car()
    P = P[:len(SUSPENSION_NAMES)]
    y, _ = road_run(tmp_path_factory.mktemp("road"), P, geom, T=12.0)
    return geom, P, y


def test_a_linear_curve_on_a_wrong_linear_car_is_the_true_car(linear_road):
    """Two formulations of one car: the true linear dampers, or a linear car with half their rate plus curves
    ``F = c v`` (the departure ``F - c/2 v`` a known force pair at each corner, at the measured velocities). Both fit
    the noise-free road run to its rounding and the velocities' reading; the half-rate car alone does not."""
    geom, P, y = linear_road
    rr = roadfit.prepare_road_run("R", y, FS, 12.0, geom)
    knots = DEFAULT_KNOTS
    half = P.copy()
    half[[INDEX["c_sf"], INDEX["c_sr"]]] *= 0.5
    curves = np.concatenate([P[INDEX["c_sf"]] * np.array(knots), P[INDEX["c_sr"]] * np.array(knots)])
    with_curves = roadfit.RoadRun(**{**rr.__dict__, "dep": roadfit.departure_of(y, FS, knots)})
    energy = np.sum(np.abs(rr.Y[rr.fit]) ** 2)

    def rel(e):
        return np.sum(e ** 2) / (2 * energy)

    exact, wrong = rel(roadfit.residuals(P, geom, rr)), rel(roadfit.residuals(half, geom, rr))
    curved = rel(roadfit.residuals(np.concatenate([half, curves]), geom, with_curves))
    assert exact < 1e-7 and wrong > 1e-2
    assert curved < 1e-4, curved  # the velocities read off sampled accelerations: ~1 % in band
    # and the road under it is the same road, but for the record's ends: there the velocities read off the
    # accelerations ring (their cut below setting roadfit.velocity_low), 2 s each end (measured: 0.3 % of the
    # road's RMS from 3 s in, 100 % in the first second)
    _, z0 = roadfit.road(P, geom, rr)
    _, z1 = roadfit.road(np.concatenate([half, curves]), geom, with_curves)
    mid = slice(int(3 * FS), -int(3 * FS))
    assert np.sqrt(np.mean((z1 - z0)[mid] ** 2)) < 0.01 * z0[mid].std()


#: digressive dampers, rebound about twice compression, bent at 0.05 m/s (the built-in car's c_s is 1786 / 1649
#: N s/m): on the knots [model] damper_knots = [0.05, 0.2] gives, so the curve the fit can take is the truth's
CURVES = {"velocity": [-0.2, -0.05, 0.05, 0.2], "front": [-900.0, -300.0, 150.0, 390.0],
          "rear": [-830.0, -280.0, 140.0, 360.0]}
ROADS = [{"id": "B40", "road_class": "B", "speed": 11.0, "fs": 200.0, "duration": 9.0},
         {"id": "C25", "road_class": "C", "speed": 7.0, "fs": 200.0, "duration": 9.0}]


@pytest.fixture(scope="module")
def curved(tmp_path_factory):
    """The built-in car with the curves above on two short unknown roads (2 % noise), identified with the defaults
    (``auto``): the linear model is not adequate, so the curves are tried."""
    d = tmp_path_factory.mktemp("road_curves")
    sc = default_scenario()
    g = sc.geometry
    doc = {"name": "curves on roads", "vehicle": {k: getattr(g, k) for k in g.KEYS},
           "known": {"total_mass": float(total_mass(dict(sc.truth))), "k_arf": 0.0, "k_arr": 0.0, "c_tf": 0.0,
                     "c_tr": 0.0},
           "truth": {k: v for k, v in sc.truth.items() if k not in ("c_sf", "c_sr")}, "dampers": CURVES,
           "runs": ROADS}
    (d / "sc.toml").write_text(tomli_w.dumps(doc))
    assert main(["simulate", str(d / "sc.toml"), "--out", str(d / "sim"), "--noise", "0.02", "--seed", "3",
                 "--quiet"]) == 0
    manifest = d / "sim" / "dataset.toml"
    manifest.write_text(manifest.read_text() + "\n[model]\ndamper_knots = [0.05, 0.2]\n")
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(["identify", str(d / "sim"), "--out", str(d / "fit"), "--seed", "1"])
    return rc, json.loads((d / "fit" / "result.json").read_text()), sc.truth, out.getvalue(), d


@pytest.mark.heavy
def test_curves_on_unknown_roads_end_to_end(curved):
    rc, doc, truth, text, d = curved
    assert rc == 0
    model = doc["model"]
    # the bars and the tire damping are known (0): in every candidate
    assert set(model["extensions"]) == {"anti_roll_bars", "tire_damping", "damper_curves"}
    assert model["selection"] == "auto"
    cands = {"damper_curves" in c["extensions"]: c for c in model["candidates"]}
    # the road runs alone: the linear car fails its residual's size, the curves pass it (not fully assessed)
    assert cands[False]["adequate"] is False and cands[True]["fits_better"] and cands[True]["adequate"] is None
    assert all("judged (passed" in doc["roads"][r["id"]]["note"] for r in ROADS)
    par = doc["parameters"]
    for n in ("m_s", "I_xx", "I_yy", "a", "m_uf", "m_ur", "k_sf", "k_sr", "k_tf", "k_tr"):
        p = par[n]
        assert abs(p["value"] / truth[n] - 1) < 0.02, n
        assert abs(p["value"] - truth[n]) < 3 * p["std_total"], n
    damp = doc["dampers"]
    assert damp["velocity"] == CURVES["velocity"] and "velocity_note" in damp
    for axle in ("front", "rear"):
        for F, t, sv in zip(damp[axle]["force"], CURVES[axle], damp[axle]["std_velocity"]):
            assert abs(F / t - 1) < 0.05, (axle, F, t)
            assert sv is not None and sv > 0
    assert par["m_uf"]["std_velocity"] > 0  # the velocities' noise reaches the car's parameters too
    assert "kept: anti_roll_bars + tire_damping + damper_curves" in text
    assert (d / "fit" / "report.html").is_file()
    # `rideid report` again, from result.json alone: the road runs' suspension velocities (the report's histograms)
    # are the measured ones the fit read, not a simulation over a road nobody measured (before, it stopped: "unknown-
    # road runs ... are not supported by rideid.CostFunction")
    (d / "fit" / "report.html").unlink()
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["report", str(d / "fit")]) == 0
    assert (d / "fit" / "report.html").is_file() and (d / "fit" / "figures" / "damper_velocities.png").is_file()
    ds = rideid.load_dataset(d / "sim")
    back = rideid.load_result(d / "fit")
    # the curves' section typed as written (rideid.estimate.sections)
    assert type(back.dampers) is DampersSection and list(back.dampers) == list(damp)
    assert back.dampers.velocity == damp["velocity"] and back.dampers.velocity_note == damp["velocity_note"]
    vel = run_velocities(back, ds)
    assert list(vel) == [r["id"] for r in ROADS]
    for r in ROADS:
        run = ds.data[r["id"]]
        v = roadfit.suspension_velocities(run.matrix(), run.fs)
        np.testing.assert_array_equal(vel[r["id"]][0], v[:, :2].ravel())
        np.testing.assert_array_equal(vel[r["id"]][1], v[:, 2:].ravel())


# the van of ../shared/cases/van-roads-dampers (3 t, digressive dampers, rebound about twice compression) on one short
# unknown road and its twist run, the curves' knots where the dampers bend (a small case of the shared one)
VAN = {**VAN_TWIST, "name": "van road and twist",
       "runs": [{"id": "B_50", "road_class": "B", "road_seed": 1, "speed": 13.889, "fs": 200.0, "duration": 12.0},
                *VAN_TWIST["runs"]]}


@pytest.fixture(scope="module")
def van_road_twist(tmp_path_factory):
    """The van above (2 % noise) fitted with damper curves (``--model damper_curves``), its twist run declared at the
    3.0 m/s driven and typed 3.03: ``{declared: (rc, result.json, terminal)}``, and the dataset folders."""
    d = tmp_path_factory.mktemp("van_road_twist")
    (d / "sc.toml").write_text(tomli_w.dumps(VAN))
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", str(d / "sc.toml"), "--out", str(d / "sim"), "--noise", "0.02", "--seed", "1",
                     "--quiet"]) == 0
    manifest = d / "sim" / "dataset.toml"
    manifest.write_text(manifest.read_text() + "\n[model]\ndamper_knots = [0.05, 0.15, 0.3, 0.6]\n")
    slip = d / "slip"
    shutil.copytree(d / "sim", slip)
    (slip / "dataset.toml").write_text(manifest.read_text().replace("speed = 3.0,", "speed = 3.03,"))
    out = {}
    for declared, ds in ((3.0, d / "sim"), (3.03, slip)):
        text = io.StringIO()
        with contextlib.redirect_stdout(text), contextlib.redirect_stderr(text):
            rc = main(["identify", str(ds), "--out", str(d / f"fit{declared}"), "--seed", "1", "--no-report",
                       "--model", "damper_curves"])
        out[declared] = (rc, json.loads((d / f"fit{declared}" / "result.json").read_text()), text.getvalue())
    return out, {3.0: d / "sim", 3.03: slip}


@pytest.mark.heavy
def test_a_track_runs_speed_is_estimated_with_damper_curves_on_roads(van_road_twist):
    """SPEC §13: a declared speed is a prior. A car with damper curves cannot take its track as built, where the
    run's speed was estimated with the car; taken as drawn, the speed was held where load put it (the grid of its
    scan, 2.9927 m/s typed 3.03, driven 3.0): k_tf +19 %, k_tr +17 %, not adequate on this case. Now the run is a
    block of its own whose speed is estimated with the car (rideid.estimate.problem.blocks.DrawnRun): found within
    0.001 % of the truth, named, and the car the same as with the speed declared right, to 0.1 of its std_total."""
    fits, _ = van_road_twist
    (rc0, clean, _), (rc1, slipped, text) = fits[3.0], fits[3.03]
    assert rc0 == 0 and rc1 == 0
    for doc, declared in ((clean, 3.0), (slipped, 3.03)):
        motion = doc["preprocessing"]["T_HL"]["motion"]
        sp = motion["speed"]
        assert motion["track"] == "twist_high" and "with the car on the track as drawn" in motion["estimated"]
        assert sp["declared"] == declared and 0 < sp["std"] < 1e-3
        assert abs(sp["estimate"] - 3.0) < max(3 * sp["std"], 3e-5), sp
        assert doc["adequacy"]["adequate"] is True
    assert not clean["preprocessing"]["T_HL"]["motion"]["named"]
    assert slipped["preprocessing"]["T_HL"]["motion"]["named"]
    assert any(c["check"] == "motion" and c["run"] == "T_HL" and c["severity"] == "warning" for c in slipped["checks"])
    assert "T_HL: speed 3.0000" in text and "on track 'twist_high' as drawn" in text
    run_block = {"name": "run T_HL", "kind": "run", "unknowns": ["speed"], "fixed": [], "runs": ["T_HL"]}
    assert run_block in slipped["plan"]["blocks"]  # SPEC §13: the plan names the speed among the unknowns
    assert "NOT A CLEAN VERDICT" in text and "the data 3.000 m/s" in text  # the fit's speed, not the load's 2.993
    for n in ("I_xx", "I_yy", "a", "m_uf", "m_ur", "k_sf", "k_sr", "k_tf", "k_tr", "c_sf", "c_sr"):
        a, b = clean["parameters"][n], slipped["parameters"][n]
        assert abs(a["value"] - b["value"]) < 0.1 * a["std_total"], n
    for n in ("k_tf", "k_tr"):  # the runs' speeds' uncertainty is in the error bars (the budget's "speed and start")
        assert slipped["parameters"][n]["std_motion"] > 0.3 * slipped["parameters"][n]["std_robust"], n


def test_the_curves_follow_a_speed_slip_the_curves_fit_estimates(van_road_twist, tmp_path):
    """The road model choice tries damper curves after a speed slip when their fit estimates that run's speed (a road
    run, or a run on a known track at a declared speed: :func:`rideid.estimate.problem.blocks.speed_runs`, with or
    without its roll gyro, which a track as built needs); a slip whose speed the data did not give (no value to
    start from) still stops them: curves would take up what no extension mends."""
    fits, dirs = van_road_twist
    parent = SimpleNamespace(checks=fits[3.03][1]["checks"])
    ds = rideid.load_dataset(dirs[3.03])
    assert [r.id for r in speed_runs(ds, ("damper_curves",))] == ["T_HL"] and speed_runs(ds, ()) == ()
    assert road_curves.held_slips(ds, parent, ("damper_curves",)) == []
    blind = tmp_path / "no_roll_rate"
    shutil.copytree(dirs[3.03], blind)
    run = blind / "runs" / "T_HL.csv"
    rows = run.read_text().splitlines()
    col = rows[0].split(",").index("roll_rate")
    run.write_text("\n".join(",".join(c for i, c in enumerate(r.split(",")) if i != col) for r in rows) + "\n")
    ds = rideid.load_dataset(blind)
    assert [r.id for r in speed_runs(ds, ("damper_curves",))] == ["T_HL"]
    assert road_curves.held_slips(ds, parent, ("damper_curves",)) == []
    unknown = SimpleNamespace(checks=[{"check": "speed", "severity": "warning", "run": "T_HL", "message": "..."}])
    assert [s["run"] for s in road_curves.held_slips(ds, unknown, ("damper_curves",))] == ["T_HL"]
