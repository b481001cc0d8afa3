"""Diagnoses on a car with every reality of SPEC §11 at once (issue 39, item 5): tracks 4 % off their drawing
with 1.5 mm RMS of unevenness, the four hub accelerometers AC-coupled at 0.5 Hz, one clipping at ±5 g, a noisy
10 Hz GPS speed channel, an engine on mounts (tests/realities_case.py, independent simulators). The wiring
check must leave the channels as wired, a start given right must pass, and a start given a cycle off must be
named as the start, nothing else.
"""

import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import rideid
from rideid.conditioning import checks, wiring
from rideid.conditioning.nominal import responses, run_steps
from rideid.errors import DataWarning

sys.path.insert(0, str(Path(__file__).parent))
import realities_case  # noqa: E402

#: the twist, and the two runs on which axle_az_fl clips (2.5 % and 7.8 % of their file samples, seed 1)
RUNS = ("T_HH", "H_HH", "W_H")


@pytest.fixture(scope="module")
def realities(tmp_path_factory):
    folder = tmp_path_factory.mktemp("realities")
    clipped = realities_case.write_dataset(folder, seed=1, runs=RUNS)
    return folder, clipped


def _load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return rideid.load_dataset(path)


def _nominal(ds, rid):
    """The nominal car's response on the run as loaded (what the checks compare the data with)."""
    rd = ds.data[rid]
    track = ds.manifest.tracks[ds.manifest.run(rid).track]

    def step():
        (Yhat,) = responses((yield [checks._nominal_job(track, rd.time, None, rd.distance)]))
        return Yhat
    return run_steps(step(), ds.geometry, None, None)


def test_the_wiring_check_leaves_the_channels_as_wired(realities):
    """No finding; the rigid body as wired holds to 4e-4 (a proposal needs 0.05 and a tenfold gain), and the
    channels as wired are the best assignment to the road of the body, the hubs and the gyro (a re-wiring
    needs to beat it by 0.6 of summed correlation). Measured on the built-in car's ten runs, seeds 1-3: rigid
    residual as wired at most 4.3e-4, hubs as wired 2.41-3.65 of 4 and never beaten (the washboard's
    left/right swap ties: its road is the same under both wheels)."""
    folder, clipped = realities
    assert clipped["W_H"] > 0.01 and clipped["H_HH"] > 0.001  # the hub sensor clips
    ds = _load(folder)
    assert [f for f in ds.findings if f.check in ("wiring", "track")] == []
    for rid in RUNS:
        Y = ds.data[rid].matrix()
        hyps, scores = wiring.rigid_body_scores(Y, ds.data[rid].fs, ds.geometry)
        assert scores[0] < 1e-3, (rid, scores[0])
        A = wiring.assignment(Y, _nominal(ds, rid))
        for group in ("body", "axle", "gyro"):
            idx, perm, signs, score, ident, C = A[group]
            assert score - ident < 1e-6, (rid, group, perm, signs)
        assert A["axle"][4] > 2.0 and A["body"][4] > 2.5, rid
        assert abs(ds.measured[rid].start - realities_case.OFFSET) < 0.01  # estimated within two samples


def _with_starts(folder, tmp_path, starts):
    doc = tomllib.loads((folder / "dataset.toml").read_text())
    for r in doc["runs"]:
        r["file"] = str(folder / r["file"])
        if r["id"] in starts:
            r["start"] = starts[r["id"]]
    out = tmp_path / "ds"
    out.mkdir()
    (out / "dataset.toml").write_text(tomli_w.dumps(doc))
    return out


def test_starts_given_right_pass(realities, tmp_path):
    """The true starts given: the start check (and every other) finds nothing."""
    folder, _ = realities
    ds = _load(_with_starts(folder, tmp_path, {rid: realities_case.OFFSET for rid in RUNS}))
    assert [f for f in ds.findings if f.check in ("wiring", "track")] == []


def test_a_start_a_cycle_off_is_the_one_diagnosis(realities, tmp_path, capsys):
    """W_H's start given one washboard cycle late (0.8 m at 10 m/s): one line naming the start, exit 2."""
    from rideid.cli import main
    folder, _ = realities
    given = realities_case.OFFSET + 0.08
    path = _with_starts(folder, tmp_path, {"W_H": given})
    out = tmp_path / "out"
    code = main(["identify", str(path), "--out", str(out), "--quiet", "--generations", "1", "--population", "8",
                 "--no-polish", "--no-report"])
    errors = [ln for ln in capsys.readouterr().err.splitlines() if not ln.startswith("rideid: warning:")]
    assert code == 2 and not out.exists()
    assert len(errors) == 1, errors
    line = errors[0]
    assert "run 'W_H': its start is off: start = 2.38 s is 0.0857 s too late" in line, line
    # the nominal car (no engine) puts the washboard's x = 0 at 2.294 s, 1.1 samples early: 1.1 cycles
    assert "(1.1 x the track's wavelength of 0.8 m)" in line
    assert "wired" not in line and "unit" not in line and np.isfinite(float(line.split(" at x = 0 at ")[1][:6]))


def _identify_cli(folder, out, model=("--model", "powertrain")):
    """``rideid identify folder --model powertrain --seed 1`` as a user runs it (``model=()``: the defaults): the
    process and result.json."""
    import json
    import os
    import subprocess
    # on one thread, as the test workers run rideid (tests/conftest.py): the other worker has the other core
    env = {**os.environ, "PYTHONPATH": str(Path(rideid.__file__).parents[1]), "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "rideid", "identify", str(folder), "--out", str(out), "--seed", "1",
                           *model, "--no-report", "--quiet"], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    return proc, json.loads((out / "result.json").read_text())


@pytest.mark.slow
def test_identify_runs_on_the_all_realities_case(realities, tmp_path):
    """End to end through the command line, the powertrain in the model: the checks pass the data as wired,
    the starts are estimated and polished, and what the fit gives is recorded (printed) against the truth.

    Measured (seed 1, three runs, each wheel on its own lateral path; 112 s on two cores): the speed channel
    holds (its wander 0 % after its noise), so the runs are fitted as built, each at a constant speed placed with
    its start (two passes, blocks.TrackBlock.aligned) and then solved with the car (anyroad._joint_solve), the hub's
    clipped samples freed (26 and 84). The twelve within 0.60 % (m_ur), every one within 1.4 std_robust (the
    white sandwich of the as-built runs, the speeds and starts in it), the engine's mass -0.24 %, its bounce
    frequency -0.00 %, adequate. The tracks: the washboard is one spectral line whose bins the prior opens, so
    its factor's error is large and the verdict allows twice it; the surface unevenness (waves up to 10 m)
    1.6-1.8 mm where 1.5 mm was laid. Seeds 2-5 of the data (not tested here; seed 3 below): the twelve within
    0.70, 0.09, 0.67 and 1.29 %, 12 of 12 covered on each (docs/tracks-as-built.md). With the speeds held while
    the car was fitted, seed 1 gave 0.76 % and seed 5 2.13 % (2.8 std_robust); with the runs along a speed
    channel taken as drawn, 12.2 % (k_tf), adequate with the tracks caveat."""
    folder, _ = realities
    out = tmp_path / "fit"
    proc, res = _identify_cli(folder, out)
    assert not [c for c in res.get("checks", []) if c["check"] in ("wiring", "track")]
    truth = realities_case.truth()
    errs = {n: res["parameters"][n]["value"] / truth[n] - 1 for n in truth if n in res["parameters"]
            and not res["parameters"][n].get("fixed") and truth[n] != 0}
    print({n: f"{100 * e:+.2f} %" for n, e in errs.items()}, res.get("adequacy", {}).get("adequate"))
    for rid in RUNS:
        assert abs(res["preprocessing"][rid]["start"]["value"] - realities_case.OFFSET) < 0.01
    assert max(abs(e) for n, e in errs.items() if n in rideid.NAMES) < 0.01
    assert abs(errs["m_p"]) < 0.01 and abs(errs["f_pb"]) < 0.002
    ad = res["adequacy"]
    assert ad["adequate"] and "tracks_caveat" not in ad, ad
    assert sorted(ad["as_built"]) == sorted(RUNS)
    tracks = res["tracks"]
    for tid, rec in tracks.items():
        assert abs(rec["amplitude_factor"] - 1.04) < 0.02 + 3 * rec["amplitude_factor_std"], (tid, rec)
        assert 1.0e-3 < rec["unevenness_rms_surface_m"] < 2.5e-3, (tid, rec)
    motion = {rid: r["motion"] for rec in tracks.values() for rid, r in rec["runs"].items() if "motion" in r}
    speeds = {"T_HH": 5.0, "H_HH": 10.0, "W_H": 10.0}
    assert sorted(motion) == sorted(RUNS)
    assert all(abs(m["speed_m_s"] / speeds[rid] - 1) < 1e-3 for rid, m in motion.items()), motion
    # the speed and start are nuisances of the error bars: their own std (measured, solved with the car: speeds
    # within 0.62 std, starts within 1.3 std, seed 1) and their share of every estimate's (the budget's "speed and
    # start")
    for rid, m in motion.items():
        start = res["preprocessing"][rid]["start"]["nominal_estimate"] + m["start_shift_s"] - realities_case.OFFSET
        assert abs(m["speed_m_s"] - speeds[rid]) < 3 * m["speed_std_m_s"] < 2e-3 * speeds[rid], (rid, m)
        assert abs(start) < 3 * m["start_shift_std_s"] < 3e-3, (rid, start, m)
    for n in rideid.NAMES:
        b = res["parameters"][n]["budget"]
        assert 0 < b["speed and start"] < b["statistical"], (n, b)
        assert np.hypot(b["speed and start"], b["statistical"]) == pytest.approx(res["parameters"][n]["std_robust"])
    freed = {rid: r.get("clipped_samples_freed") for rec in tracks.values() for rid, r in rec["runs"].items()}
    assert freed["W_H"]["axle_az_fl"] > 20 and freed["H_HH"]["axle_az_fl"] > 5
    assert "error bars with tracks as built: the white sandwich of their runs" in proc.stdout
    z = {n: (res["parameters"][n]["value"] - truth[n]) / res["parameters"][n]["std_robust"] for n in rideid.NAMES}
    print({n: f"{v:+.1f}" for n, v in z.items()})
    assert max(abs(v) for v in z.values()) < 2.0, z
    # the error bars' shape (docs/uncertainty.md): out at ±2 std_robust the twelve's cost is their curvature's
    # quadratic (measured on the five-run case: 0.96-1.02), none of them named
    shape = res["polish"]["shape"]
    twelve = [v for n in rideid.NAMES if n in shape["ratio"] for v in shape["ratio"][n] if v is not None]
    print(shape["ratio"], shape["optimistic"])
    assert len(twelve) >= 20 and all(0.9 < v < 1.1 for v in twelve), shape
    assert not set(shape["optimistic"]) & set(rideid.NAMES)


@pytest.mark.heavy
def test_a_gross_first_fit_that_the_powertrain_mends_on_the_tracks_as_built(tmp_path):
    """The defaults (``--model auto``) on the built-in car with every reality (its 180 kg engine on 10.5/13 Hz
    mounts, tracks 4 % off their drawing), two of its ten runs: the linear model on the tracks as drawn leaves
    more than ``adequacy.gross_error`` of T_LH's signal unexplained (measured 55 %, H_LH 29 %), which would stop
    the model choice with a set-up check; the powertrain screens above its threshold (122 against 48), still
    misses grossly as drawn, and on the tracks as built is adequate: it is kept (choice.first_fit.as_built).
    Measured (seed 1, 40 s on two cores): the twelve within 2.9 % (m_uf, m_ur; 1.3 std_robust), every one
    within 1.3 std_robust, the engine's mass -0.9 %, its bounce frequency +0.06 %. Before, rideid stopped on the
    linear model and its tracks as built were rejected; on the ten runs that printed I_yy -13.7 %, k_sr
    -18.4 %, NOT ADEQUATE with advice to check a set-up that was right (docs/model-choice.md)."""
    folder = tmp_path / "ds"
    realities_case.write_dataset(folder, car="builtin", seed=1, runs=("T_LH", "H_LH"))
    proc, res = _identify_cli(folder, tmp_path / "fit", model=())
    first = res["model"]["first_fit"]
    gross = first["gross_misfit"]
    assert gross["run_errors"]["T_LH"] > gross["threshold"] == 0.3
    assert first["extension"] == ["powertrain"] and first["tracks"] == "as built"
    assert "powertrain" in res["model"]["extensions"] and res["model"]["selection"].startswith(
        "auto (the first fit missed grossly on the tracks as drawn; powertrain,")
    tried = next(s for s in first["screens"] if s["extensions"] == first["mended_by"])
    assert tried["mends"] is False and tried["passes"] and tried["score"] > 2 * tried["threshold"]  # as drawn: not
    assert res["adequacy"]["adequate"] and "gross_misfit" not in res["adequacy"]
    # SPEC §6's candidates: the first fit, the powertrain as drawn, the powertrain as built (kept)
    cands = res["model"]["candidates"]
    assert [(c["extensions"][-1], c["tracks"], c["adequate"]) for c in cands] == [
        ("tire_damping", "as drawn", False), ("powertrain", "as drawn", False), ("powertrain", "as built", True)]
    assert cands[2]["cost"] == res["cost"] < cands[1]["cost"] < cands[0]["cost"]
    truth = realities_case.truth(car="builtin")
    z = {n: (res["parameters"][n]["value"] - truth[n]) / res["parameters"][n]["std_robust"] for n in rideid.NAMES}
    errs = {n: res["parameters"][n]["value"] / truth[n] - 1 for n in rideid.NAMES}
    print({n: f"{100 * e:+.2f} % ({z[n]:+.1f})" for n, e in errs.items()})
    assert max(abs(v) for v in z.values()) < 2.5 and max(abs(e) for e in errs.values()) < 0.04, (errs, z)
    assert abs(res["parameters"]["m_p"]["value"] / truth["m_p"] - 1) < 0.03
    printed = " ".join(proc.stdout.split())
    assert "--model auto kept: anti_roll_bars + tire_damping + powertrain" in printed
    assert ("first fit: missed grossly (55 % of run T_LH's signal unexplained); the model choice went on because "
            "powertrain, the extension the data called for most (screened at") in printed
    assert "anti_roll_bars + tire_damping + powertrain (as built) 3.2" in printed  # the candidates by their tracks
    # the engine's pitch mode: at the Hessian's step the true Hessian's curvature along I_p + zeta_pp is below its
    # rounding noise (-22 against a noise of 10 on one machine, +0.7 on another: its sign is the rounding's, which
    # differs between machines, docs/uncertainty.md), so it is measured again (the record below); at a 1 % step
    # it curves up (4.6), more than at the Hessian's step: error bars for both, wide (44 % and 37 %; the
    # indefinite Hessian gave 17 % and 16 %), and the cost out at +-2 of them as curved as they say
    again = res["polish"]["remeasured"]
    assert len(again) == 1 and set(again[0]["along"]) == {"I_p", "zeta_pp"} and "unresolved" not in res["polish"]
    assert again[0]["curvature_at_step"] > max(again[0]["curvature"], 0.0), again[0]
    for n in ("I_p", "zeta_pp"):
        assert 0.25 < res["parameters"][n]["std_robust"] / truth[n] < 0.6, res["parameters"][n]
        assert abs(z[n] if n in z else (res["parameters"][n]["value"] - truth[n]) / res["parameters"][n][
            "std_robust"]) < 1
    shape = next(a for a in res["assessments"] if a["kind"] == "error_bar_shape")
    assert shape["verdict"] == "pass" and min(shape["ratio"]["I_p"]) > 0.25
    # a direction no step resolves: no error bar, said in result.json's details, the terminal, the assessment, the
    # report, the score and the frequency responses' notes (the record as rideid writes it, on this result)
    import dataclasses

    from rideid.cli import _summary_table
    from rideid.estimate.assess.details import not_determined
    from rideid.estimate.records import ShapeAssessment
    from rideid.report.html import parameter_rows
    loaded = rideid.load_result(tmp_path / "fit")
    unres = {"directions": [{"curvature": -22.2, "noise": 10.4, "along": {"zeta_pp": 0.71, "I_p": 0.70}}],
             "not_determined": ["I_p", "zeta_pp"], "curvature_noise": 2.0}
    details = {n: dict(d) for n, d in loaded.details.items()}
    from rideid.estimate.assess.frequency import result_geometry
    space = rideid.ParameterSpace(loaded.known, result_geometry(loaded), extensions=loaded.model["extensions"])
    assert not_determined(details, space, np.array([loaded.parameters[n] for n in space.names]), unres) == [
        "I_p", "zeta_pp"]
    hidden = dataclasses.replace(loaded, details=details, polish={**loaded.polish, "unresolved": unres})
    assert all(hidden.details[n]["std_robust"] is None and hidden.details[n]["determined"] is False
               for n in ("I_p", "zeta_pp"))
    table = " ".join(_summary_table(hidden).split())
    assert f"I_p {hidden.details['I_p']['value']:.6g} kg m^2 NOT DETERMINED: the data do not fix it" in table
    warn = rideid.error_bar_warning(hidden.polish)
    assert warn.startswith("I_p, zeta_pp not determined: the cost's curvature along 0.71 zeta_pp + 0.70 I_p")
    assessed = ShapeAssessment.from_result(hidden)
    assert assessed.verdict == "warn" and assessed.not_determined == ["I_p", "zeta_pp"] and assessed.reason == warn
    rows = {p["name"]: p for p in parameter_rows(hidden)}
    assert rows["I_p"]["status"] == "NOT DETERMINED" and rows["zeta_pp"]["note"].startswith("the data do not fix it")
    assert any(n.startswith("I_p, zeta_pp: not determined") for n in hidden.frequency_response().notes)
    assert rideid.score(hidden, truth)["parameters"]["I_p"]["status"] == "not determined"
    # a parameter whose error bar holds only with a not-determined one at its bound (data seed 2 of this case):
    # said beside it in the terminal and the report
    from rideid.estimate.assess.details import conditional_note
    cond = dataclasses.replace(hidden, details={**hidden.details, "x_p": {
        **hidden.details["x_p"], "conditional_on": ["I_p"], "note": conditional_note(["I_p"])}})
    assert "CONDITIONAL: on I_p at a search bound (WARNING below)" in " ".join(_summary_table(cond).split())
    assert {p["name"]: p for p in parameter_rows(cond)}["x_p"]["note"].startswith("its error bar holds only with I_p")
    from rideid.report.html import _estimates_lines
    said = dict((label, text) for label, text, _ in _estimates_lines(cond, {"params": parameter_rows(cond)}))
    assert said["Estimates"].endswith("; CONDITIONAL (on a parameter at its bound): x_p")
    # the report's model section (it raised on these candidates before they carried their estimates): the three by
    # their tracks, the one kept marked, each parameter's value per candidate, the first fit's sentence
    from rideid.report.estimate_sections import model_rows
    section = model_rows(res)
    assert [(h["label"].split(" + ")[-1], h["chosen"]) for h in section["heads"]] == [
        ("tire_damping (as drawn)", False), ("powertrain (as drawn)", False), ("powertrain (as built)", True)]
    m_uf = next(r["cells"] for r in section["rows"] if r["name"] == "m_uf")
    assert float(m_uf[2][0]) == pytest.approx(res["parameters"]["m_uf"]["value"], rel=1e-4) and not m_uf[2][1]
    assert section["weighed"] is False  # no criterion between them: the note does not state the choice's gate
    assert section["first_fit"] == rideid.first_fit_sentence(first) and section["first_fit"].startswith(
        "first fit: missed grossly (55 %")


@pytest.mark.slow
def test_an_engine_mode_left_at_its_bounds_is_started_again(tmp_path):
    """Seed 3 of the all-realities case: the search ends with the engine's pitch mode switched off at its bounds
    (I_p 1 kg m^2, f_pp 5 Hz, zeta_pp 0.02) and the polish kept it there (I_p 1, f_pp 5.6 Hz), the unsprung
    masses taking up what the mode leaves: +2.78 % and +2.38 %, 2.3-2.8 std_robust, under an adequate verdict and
    three bound warnings (the as-drawn fit's, though the as-built one had moved f_pp and zeta_pp off them).
    Polished again from the typical mode (rideid.estimate.fit.polish.mode_restart) the tracks-as-drawn cost falls
    (0.20913 to 0.20880) and the mode lands at the truth: measured, the twelve within 0.71 % (m_uf), every one
    within 1.0 std_robust, f_pp +0.15 %, I_p -1.1 %, no bound warning, adequate; with the speeds and starts solved
    with the car (anyroad._joint_solve) within 0.09 %, 0.6 std_robust, f_pp +0.10 % (100 s on two cores)."""
    folder = tmp_path / "seed3"
    realities_case.write_dataset(folder, seed=3, runs=RUNS)
    out = tmp_path / "fit"
    proc, res = _identify_cli(folder, out)
    restart = res["polish"]["as_drawn"]["mode_restart"]
    assert restart["modes"] == ["the engine's pitch mode"] and restart["first"]["I_p"] == pytest.approx(1.0)
    assert restart["kept"] == "restart" and restart["cost_restart"] < restart["cost"]
    truth = realities_case.truth()
    errs = {n: res["parameters"][n]["value"] / truth[n] - 1 for n in rideid.NAMES if truth[n] != 0}
    print({n: f"{100 * e:+.2f} %" for n, e in errs.items()})
    assert max(abs(e) for e in errs.values()) < 0.01, errs
    assert abs(res["parameters"]["f_pp"]["value"] / truth["f_pp"] - 1) < 0.01
    assert not [c for c in res["checks"] if c["check"] == "bounds"]
    assert "search bound" not in proc.stderr
    assert res["adequacy"]["adequate"]
