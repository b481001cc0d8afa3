"""rideid export (SPEC §10): the parameter card and the FMI 2.0 FMU of an identified car.

The FMU is driven with FMPy on each run's wheel inputs and compared with
``rideid simulate`` of the same car (the card's ``car.toml`` with runs added):
within 1e-4 of each channel's RMS, for a linear car and for a car with damper
curves, bump stops and a CG height.
"""

import tomllib
import warnings
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import rideid
from rideid.cli import main
from rideid.synth.scenario import simulate_manifest, write_dataset
from rideid.model.equations import CHANNELS
from rideid.model.simulate import prepare_run

fmpy = pytest.importorskip("fmpy")
from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

from rideid.exporter import car_from_scenario, export  # noqa: E402
from rideid.exporter.fmu import INPUTS, find_compiler  # noqa: E402

needs_cc = pytest.mark.skipif(find_compiler() is None, reason="no C compiler")
ROOT = Path(__file__).resolve().parents[1]
#: FMU communication steps per sample: the master's inputs (cubic Hermite through r and rdot) between them
SUB = 16
RUNS = ("T_LH", "H_LH", "W_L")


def drive_fmu(path, t, r, rdot, sub=SUB):
    """Outputs ``(n, 10)`` of the FMU at the samples ``t`` driven with road inputs ``r``, ``rdot`` ``(n*sub-sub+1, 4)``
    given at ``sub`` points per sample interval: at each communication point the inputs are set, the outputs
    read, and the cubic Hermite through the inputs and their rates at both ends of the step handed over as
    input derivatives (orders 1-3) for the FMU to interpolate within the step."""
    md = read_model_description(path)
    unzipped = extract(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    vin = [vr[n] for n in INPUTS]
    vout = [vr[c] for c in CHANNELS]
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="car")
    s.instantiate()
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.setReal(vin, list(np.r_[r[0], rdot[0]]))
    s.exitInitializationMode()
    dt = (t[1] - t[0]) / sub
    Y = np.empty((t.size, 10))
    for k in range(r.shape[0]):
        s.setReal(vin, list(np.r_[r[k], rdot[k]]))
        if k % sub == 0:
            Y[k // sub] = s.getReal(vout)
        if k + 1 < r.shape[0]:
            dr, d0, d1 = r[k + 1] - r[k], rdot[k], rdot[k + 1]
            s.setRealInputDerivatives(vin[:4], [1] * 4, list(d0))
            s.setRealInputDerivatives(vin[:4], [2] * 4, list((6 * dr / dt - 4 * d0 - 2 * d1) / dt))
            s.setRealInputDerivatives(vin[:4], [3] * 4, list((-12 * dr / dt + 6 * (d0 + d1)) / dt ** 2))
            s.setRealInputDerivatives(vin[4:], [1] * 4, list((d1 - d0) / dt))
            s.doStep(k * dt, dt)
    s.terminate()
    s.freeInstance()
    return Y


def relative_error(Y, Yref):
    """Largest over the channels of RMS(Y - Yref) / RMS(Yref) (channels that stay 0: their largest |Y|)."""
    rms = np.sqrt(np.mean(Yref ** 2, axis=0))
    err = np.sqrt(np.mean((Y - Yref) ** 2, axis=0))
    live = rms > 1e-12
    assert np.abs(Y[:, ~live]).max(initial=0.0) < 1e-9
    return float((err[live] / rms[live]).max())


def card_scenario(card_toml, runs_from, run_ids, folder):
    """The card with the tracks and runs of another scenario file added (as a user would), loaded."""
    doc = tomllib.loads(Path(runs_from).read_text())
    text = Path(card_toml).read_text()
    import tomli_w
    for key, tabs in (("tracks", doc["tracks"]), ("runs", [r for r in doc["runs"] if r["id"] in run_ids])):
        text += "".join(f"\n[[{key}]]\n" + tomli_w.dumps(tab) for tab in tabs)
    path = Path(folder) / "car_with_runs.toml"
    path.write_text(text)
    return rideid.load_scenario(path)


def fmu_versus_simulate(fmu, sc):
    """Worst relative error over the scenario's runs of the FMU against ``rideid simulate`` of the scenario."""
    data, _ = simulate_manifest(sc)
    worst = {}
    for run in sc.runs:
        t, Yref = data[run.id]
        ri = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t)
        tf = np.arange((t.size - 1) * SUB + 1) * ((t[1] - t[0]) / SUB)
        r, rdot = ri.inputs_at(tf)
        worst[run.id] = relative_error(drive_fmu(fmu, t, r, rdot), Yref)
    return worst


@pytest.fixture(scope="module")
def fit(tmp_path_factory):
    """The built-in car identified (noise-free) on three runs: a fit folder with result.json."""
    base = tmp_path_factory.mktemp("export")
    sc = rideid.default_scenario()
    sc = replace(sc, runs=[r for r in sc.runs if r.id in RUNS])
    data, _ = simulate_manifest(sc, noise=0.0, seed=1)
    write_dataset(sc, data, base / "sim")
    res = rideid.identify(rideid.load_dataset(base / "sim"), seed=1, population=16, generations=30, model="base")
    res.save(base / "fit")
    return base / "fit"


def test_result_json_carries_the_vehicle(fit):
    res = rideid.load_result(fit)
    sc = rideid.default_scenario()
    assert res.vehicle == {k: getattr(sc.geometry, k) for k in ("wheelbase", "track_front", "track_rear",
                                                                 "tire_radius")}


@needs_cc
def test_fmu_of_an_identified_linear_car_matches_simulate(fit, tmp_path):
    out = export(fit, tmp_path / "car")
    assert out.compiled and out.note is None
    fmu = tmp_path / "car" / "car.fmu"
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.fmiVersion == "2.0" and md.coSimulation.modelIdentifier == "car"
    assert md.coSimulation.canInterpolateInputs
    by = {v.name: v for v in md.modelVariables}
    assert [n for n in by if by[n].causality == "input"] == list(INPUTS)
    assert [n for n in by if by[n].causality == "output"] == list(CHANNELS)
    res = rideid.load_result(fit)
    for n in rideid.NAMES:
        assert by[n].causality == "parameter" and float(by[n].start) == res.parameters[n]
    assert by["lift_off"].start == "false"
    with zipfile.ZipFile(fmu) as z:
        names = z.namelist()
    assert {"modelDescription.xml", "sources/model.c", "sources/fmi2_api.h", "binaries/linux64/car.so"} <= set(names)
    sc = card_scenario(tmp_path / "car" / "car.toml", rideid.default_scenario_path(), RUNS, tmp_path)
    worst = fmu_versus_simulate(str(fmu), sc)
    assert max(worst.values()) <= 1e-4, worst


@needs_cc
def test_fmu_of_a_car_with_damper_curves_matches_simulate(tmp_path):
    """Asymmetric digressive curves, bump stops, CG height 0.25 m: the nonlinear car of SPEC §8."""
    src = ROOT / "examples" / "dampers" / "real_dampers.toml"
    sc = rideid.load_scenario(src)
    assert sc.dampers is not None and sc.bump_stops and sc.geometry.cg_height > 0
    car = car_from_scenario(sc)
    export(car, tmp_path / "car")
    fmu = str(tmp_path / "car" / "car.fmu")
    assert validate_fmu(fmu) == []
    by = {v.name: v for v in read_model_description(fmu).modelVariables}
    assert by["lift_off"].start == "true"
    assert [float(by[f"damper_v{k + 1}"].start) for k in range(len(sc.dampers.velocity))] == list(sc.dampers.velocity)
    assert [float(by[f"F_r{k + 1}"].start) for k in range(len(sc.dampers.rear))] == list(sc.dampers.rear)
    # the card drives the same car: its runs added, simulate gives what the FMU gives
    card = card_scenario(tmp_path / "car" / "car.toml", src, ("T_HL", "W_H"), tmp_path)
    assert card.dampers == sc.dampers and card.bump_stops == sc.bump_stops and card.geometry == sc.geometry
    worst = fmu_versus_simulate(fmu, card)
    assert max(worst.values()) <= 1e-4, worst


def test_card_round_trip(fit, tmp_path):
    """export -> simulate (runs added) -> identify gives the same car (noise-free: within 1e-6)."""
    export(fit, tmp_path / "car", format="card")
    assert not (tmp_path / "car" / "car.fmu").exists()
    res = rideid.load_result(fit)
    rows = (tmp_path / "car" / "car.csv").read_text().splitlines()
    assert rows[0] == "parameter,value,unit,std,std_robust,fixed,derived"
    table = {ln.split(",")[0]: ln.split(",") for ln in rows[1:]}
    assert set(table) == set(res.details)
    for n, d in res.details.items():
        assert float(table[n][1]) == d["value"] and table[n][2] == d["unit"]
        if d.get("std_robust") is not None:
            assert float(table[n][4]) == d["std_robust"]
    sc = card_scenario(tmp_path / "car" / "car.toml", rideid.default_scenario_path(), RUNS, tmp_path)
    assert sc.known == res.known and sc.extensions == ()
    data, _ = simulate_manifest(sc, noise=0.0, seed=2)
    write_dataset(sc, data, tmp_path / "sim2")
    again = rideid.identify(rideid.load_dataset(tmp_path / "sim2"), seed=3, population=16, generations=30)
    assert again.model["extensions"] == []
    for n in rideid.NAMES:
        assert again.parameters[n] == pytest.approx(res.parameters[n], rel=1e-6), n


def test_source_only_fmu_and_one_note_without_a_compiler(fit, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CC", "/nonexistent/cc")
    assert main(["export", str(fit), "--out", str(tmp_path / "car"), "--format", "fmu"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    notes = [ln for ln in out if ln.startswith("note:")]
    assert len(notes) == 1 and "no C compiler" in notes[0] and "sources only" in notes[0]
    with zipfile.ZipFile(tmp_path / "car" / "car.fmu") as z:
        names = z.namelist()
    assert "sources/model.c" in names and not any(n.startswith("binaries/") for n in names)
    assert validate_fmu(str(tmp_path / "car" / "car.fmu")) == []


@pytest.mark.parametrize("case", ["no result.json", "unknown format", "unwritable folder"])
def test_bad_input_is_one_line_exit_2_nothing_written(case, fit, tmp_path, capsys):
    src, fmt, out = str(fit), "all", tmp_path / "car"
    if case == "no result.json":
        (tmp_path / "empty").mkdir()
        src = str(tmp_path / "empty")
    elif case == "unknown format":
        fmt = "step"
    else:
        (tmp_path / "a_file").write_text("not a folder")
        out = tmp_path / "a_file" / "car"
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["export", src, "--out", str(out), "--format", fmt]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rideid: error:"), err
    expected = {"no result.json": "result.json", "unknown format": "--format", "unwritable folder": "a_file"}[case]
    assert expected in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no output, no temporary folder


def test_export_into_an_existing_folder_keeps_other_files(fit, tmp_path):
    (tmp_path / "car").mkdir()
    (tmp_path / "car" / "notes.txt").write_text("mine")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = export(rideid.load_result(fit), tmp_path / "car", format="card", compiler=None)
    assert res.compiled is None
    assert sorted(p.name for p in (tmp_path / "car").iterdir()) == ["car.csv", "car.toml", "notes.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["car"]
