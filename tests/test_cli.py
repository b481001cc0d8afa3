"""The command line: simulate, identify, score, sensitivity, and bad input."""

import json
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from rideid.cli import main
from rideid.data.schema import read_run_csv
from rideid.model.params import DEFAULT_CAR, DEFAULT_GEOMETRY
from rideid.model.simulate import simulate_lsim

SCENARIO_ALL_KINDS = """
name = "all-kinds"
[vehicle]
wheelbase = 2.579
track_front = 1.387
track_rear = 1.364
tire_radius = 0.30
[known]
total_mass = 1093.3
[truth]
m_s = 965.7
I_xx = 207.3
I_yy = 1565.8
a = 1.156
m_uf = 31.9
m_ur = 31.9
k_sf = 24445.0
k_sr = 19629.0
c_sf = 1786.0
c_sr = 1649.0
k_tf = 158240.0
k_tr = 158240.0
[[tracks]]
id = "wb"
kind = "washboard"
start = 2.0
amplitude = 0.006
wavelength = 0.7
cycles = 5
[[tracks]]
id = "hb"
kind = "herringbone"
start = 2.0
amplitude = 0.005
wavelength = 0.5
cycles = 6
angle = 30.0
[[tracks]]
id = "tw"
kind = "chassis_twist"
start = 2.0
height = 0.04
bump_length = 1.6
spacing = 4.0
bumps = 2
first = "right"
[[tracks]]
id = "fl"
kind = "flat"
[[tracks]]
id = "pr"
kind = "profile"
file = "road.csv"
[[runs]]
id = "W"
track = "wb"
speed = 8.0
fs = 200.0
duration = 2.0
[[runs]]
id = "H"
track = "hb"
speed = 6.0
fs = 250.0
duration = 2.0
[[runs]]
id = "T"
track = "tw"
speed = 4.0
fs = 200.0
duration = 3.0
[[runs]]
id = "F"
track = "fl"
speed = 4.0
fs = 100.0
duration = 0.5
[[runs]]
id = "P"
track = "pr"
speed = 5.0
fs = 200.0
duration = 2.0
"""


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("sc")
    x = np.linspace(2.0, 5.0, 301)
    np.savetxt(d / "road.csv", np.column_stack([x, 0.01 * np.hanning(301), 0.004 * np.sin(x) ** 2 *
                                                 np.hanning(301)]),
               delimiter=",", header="x,z_left,z_right", comments="")
    (d / "scenario.toml").write_text(SCENARIO_ALL_KINDS)
    return d / "scenario.toml"


def run_cli(args, capsys):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_simulate_all_kinds_matches_independent_fine_step(scenario_file, tmp_path, capsys):
    out = tmp_path / "ds"
    rc, stdout, err = run_cli(["simulate", scenario_file, "--out", out, "--seed", "1", "--quiet"], capsys)
    assert rc == 0, err
    assert (out / "dataset.toml").is_file() and (out / "truth.toml").is_file()
    assert "bounce" in stdout
    doc = tomllib.loads((out / "dataset.toml").read_text())
    assert [r["file"] for r in doc["runs"]] == [f"runs/{k}.csv" for k in "WHTFP"]
    assert "truth" not in doc
    # the dataset stands on its own: the profile travels with it
    assert doc["tracks"][4]["file"] == "profiles/pr.csv"
    moved = tmp_path / "moved"
    shutil.copytree(out, moved)
    import rideid
    assert len(rideid.load_dataset(moved).runs) == 5
    from rideid.data.scenario import load_scenario
    sc = load_scenario(scenario_file)
    P = np.array([DEFAULT_CAR[n] for n in DEFAULT_CAR])
    for run in sc.runs:
        rd = read_run_csv(out / "runs" / f"{run.id}.csv")
        n = int(round(run.duration * run.fs)) + 1
        assert rd.time.size == n and rd.time[0] == 0 and rd.fs == pytest.approx(run.fs)
        Y = rd.matrix()
        ref = simulate_lsim(P, DEFAULT_GEOMETRY, sc.tracks[run.track], run.speed, rd.time, upsample=100)
        if run.id == "F":
            assert np.all(Y == 0)
            continue
        scale = np.sqrt(np.mean(ref ** 2, axis=0))
        ok = scale > 1e-9
        err_rms = np.sqrt(np.mean((Y - ref) ** 2, axis=0))[ok] / scale[ok]
        assert err_rms.max() < 2e-3, (run.id, err_rms)


def test_simulate_noise_is_seeded(scenario_file, tmp_path, capsys):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    for d, seed in ((a, 3), (b, 3), (c, 4)):
        assert run_cli(["simulate", scenario_file, "--out", d, "--noise", "0.02", "--seed", seed, "--quiet"],
                       capsys)[0] == 0
    ya = read_run_csv(a / "runs" / "W.csv").matrix()
    yb = read_run_csv(b / "runs" / "W.csv").matrix()
    yc = read_run_csv(c / "runs" / "W.csv").matrix()
    np.testing.assert_array_equal(ya, yb)
    assert np.abs(ya - yc).max() > 0
    clean = tmp_path / "clean"
    run_cli(["simulate", scenario_file, "--out", clean, "--quiet"], capsys)
    y0 = read_run_csv(clean / "runs" / "W.csv").matrix()
    rel = np.std(ya - y0, axis=0) / np.sqrt(np.mean(y0 ** 2, axis=0))
    assert np.all(np.abs(rel[:9] - 0.02) < 0.004)


def test_lift_off_warning_names_run_and_wheel(tmp_path, capsys):
    text = SCENARIO_ALL_KINDS.replace("height = 0.04", "height = 0.25").replace('duration = 3.0', 'duration = 3.5')
    (tmp_path / "road.csv").write_text("x,z_left,z_right\n2,0,0\n3,0,0\n")
    (tmp_path / "s.toml").write_text(text.replace("speed = 4.0\nfs = 200.0", "speed = 8.0\nfs = 200.0"))
    rc, out, err = run_cli(["simulate", tmp_path / "s.toml", "--out", tmp_path / "o", "--quiet"], capsys)
    assert rc == 0
    assert "run 'T': wheel" in err and "lifts off" in err


def test_identify_score_and_exit_codes(sim_dataset, tmp_path, capsys):
    out = tmp_path / "fit"
    rc, stdout, err = run_cli(["identify", sim_dataset, "--out", out, "--seed", "1", "--quiet", "--no-report"], capsys)
    assert rc == 0, err
    doc = json.loads((out / "result.json").read_text())
    assert doc["seed"] == 1 and doc["parameters"]["m_s"]["derived"] is True
    assert "k_tf" in stdout and "N/m" in stdout
    rc, stdout, err = run_cli(["score", out / "result.json", sim_dataset / "truth.toml"], capsys)
    assert rc == 0
    worst = float(stdout.strip().splitlines()[-1].split(":")[1].split("%")[0])
    assert worst < 0.1
    # the folders, as a user types them: the fit's and the simulated dataset's (its truth.toml)
    rc, again, err = run_cli(["score", out, sim_dataset], capsys)
    assert rc == 0, err
    assert again == stdout


def test_sensitivity_command(scenario_file, sim_dataset, tmp_path, capsys):
    for src in (scenario_file, sim_dataset):
        out = tmp_path / src.name
        rc, stdout, err = run_cli(["sensitivity", src, "--out", out, "--quiet"], capsys)
        assert rc == 0, err
        for f in ("tables.md", "param_response.csv", "response_track.csv", "param_track.csv",
                  "param_response.png", "response_track.png", "param_track.png"):
            assert (out / f).stat().st_size > 100, f
        md = (out / "tables.md").read_text()
        assert "★" in md and "k_tf" in md


def test_version_and_help():
    r = subprocess.run([sys.executable, "-m", "rideid.cli", "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.startswith("rideid ")
    for cmd in ("simulate", "identify", "sensitivity", "score", "demo"):
        r = subprocess.run([sys.executable, "-m", "rideid.cli", cmd, "--help"], capture_output=True, text=True)
        assert r.returncode == 0 and "example:" in r.stdout


# -- bad input: one line, exit 2, names the culprit, nothing left behind ---------

def _copy(sim_dataset, tmp_path):
    d = tmp_path / "ds"
    shutil.copytree(sim_dataset, d)
    return d


def _edit_toml(d, fn):
    doc = tomllib.loads((d / "dataset.toml").read_text())
    fn(doc)
    (d / "dataset.toml").write_text(tomli_w.dumps(doc))


def _edit_csv(d, run, fn):
    p = d / "runs" / f"{run}.csv"
    lines = p.read_text().splitlines()
    p.write_text("\n".join(fn(lines)) + "\n")


BAD = {
    "missing_dataset": (lambda d: shutil.rmtree(d), "ds: no such dataset folder"),
    "missing_manifest": (lambda d: (d / "dataset.toml").unlink(), "dataset.toml: file not found"),
    "malformed_toml": (lambda d: (d / "dataset.toml").write_text("name = [\n"), "invalid TOML"),
    "unknown_track": (lambda d: _edit_toml(d, lambda x: x["runs"][0].update(track="nope")), "unknown track 'nope'"),
    "unknown_kind": (lambda d: _edit_toml(d, lambda x: x["tracks"][0].update(kind="cobbles")),
                     "unknown track kind 'cobbles'"),
    "unknown_key": (lambda d: _edit_toml(d, lambda x: x["tracks"][0].update(hieght=0.1)), "unknown key 'hieght'"),
    "unknown_top_key": (lambda d: _edit_toml(d, lambda x: x.update(vehicel={})), "unknown key 'vehicel'"),
    "bounds_order": (lambda d: _edit_toml(d, lambda x: x.update(bounds={"k_sf": [5e4, 1e4]})),
                     "[bounds] k_sf: lower bound 50000.0 must be less than upper bound 10000.0"),
    "speed": (lambda d: _edit_toml(d, lambda x: x["runs"][1].update(speed=0.0)), "speed: must be positive"),
    "tire_radius": (lambda d: _edit_toml(d, lambda x: x["vehicle"].update(tire_radius=-0.3)),
                    "[vehicle] tire_radius: must be positive"),
    "duplicate_run": (lambda d: _edit_toml(d, lambda x: x["runs"][1].update(id="T_LL")), "duplicate run id 'T_LL'"),
    "no_anchor": (lambda d: _edit_toml(d, lambda x: x.pop("known")), "no scale anchor"),
    "missing_run_file": (lambda d: (d / "runs" / "W_H.csv").unlink(), "W_H.csv: run file not found"),
    "nan": (lambda d: _edit_csv(d, "T_LH", lambda ls: ls[:5] + [ls[5].rsplit(",", 1)[0] + ",nan"] + ls[6:]),
            "T_LH.csv: column 'roll_rate' has a NaN or infinite value (line 6)"),
    "inf": (lambda d: _edit_csv(d, "T_LH", lambda ls: ls[:5] + [ls[5].rsplit(",", 1)[0] + ",inf"] + ls[6:]),
            "column 'roll_rate' has a NaN or infinite value"),
    "non_increasing": (lambda d: _edit_csv(d, "H_LL", lambda ls: ls[:3] + [ls[4], ls[3]] + ls[5:]),
                       "H_LL.csv: column 'time' is not strictly increasing"),
    "non_uniform": (lambda d: _edit_csv(d, "H_LL", lambda ls: ls[:3] + ls[4:]),
                    "H_LL.csv: column 'time' is not uniform"),
    "header_only": (lambda d: _edit_csv(d, "W_L", lambda ls: ls[:1]), "W_L.csv: header only"),
    # the time in ms (SPEC §3: s): it ran silently on a run 1000 times as long for over ten minutes
    "time_in_ms": (lambda d: _edit_csv(d, "W_L", lambda ls: ls[:1] + [
        f"{1000 * float(x.split(',', 1)[0]):.12g},{x.split(',', 1)[1]}" for x in ls[1:]]),
        "W_L.csv: column 'time' steps 5 per sample, a sample rate of 0.2 Hz, not a ride recording's "
        "(5 Hz - 200 kHz); SPEC §3 wants the time in seconds: is it in ms?"),
    "no_time": (lambda d: _edit_csv(d, "W_L", lambda ls: [ls[0].replace("time", "t")] + ls[1:]),
                "W_L.csv: missing column 'time'"),
    "not_a_number": (lambda d: _edit_csv(d, "W_L", lambda ls: ls[:2] + [ls[2].replace(",", ",x", 1)] + ls[3:]),
                     "W_L.csv: line 3, column 'body_az_fl': not a number"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input(case, sim_dataset, tmp_path, capsys):
    d = _copy(sim_dataset, tmp_path)
    fn, msg = BAD[case]
    fn(d)
    out = tmp_path / "fit"
    rc, stdout, err = run_cli(["identify", d, "--out", out, "--quiet"], capsys)
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("rideid: error: ")
    assert msg in lines[0]
    assert "Traceback" not in err
    assert not out.exists()
    assert not list(tmp_path.glob(".fit.tmp-*"))


def test_a_refused_run_says_the_out_folder_holds_an_earlier_runs_files(sim_dataset, tmp_path, capsys):
    """An error leaves ``--out`` as it was; where it holds an earlier run's result, the error line says so (a user
    looking there must not take it for this run's)."""
    d = _copy(sim_dataset, tmp_path)
    out = tmp_path / "fit"
    out.mkdir()
    (out / "result.json").write_text("{}")
    BAD["speed"][0](d)
    rc, _, err = run_cli(["identify", d, "--out", out, "--quiet"], capsys)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert err.strip().endswith(f"; nothing was written: {out} holds an earlier run's files, left as they were")
    assert (out / "result.json").read_text() == "{}"


def test_extra_column_warns_but_works(sim_dataset, tmp_path, capsys):
    d = _copy(sim_dataset, tmp_path)
    _edit_csv(d, "W_L", lambda ls: [ls[0] + ",temperature"] + [x + ",21.5" for x in ls[1:]])
    from rideid import DataWarning, load_dataset
    with pytest.warns(DataWarning, match="W_L.csv: ignoring column.*temperature"):
        load_dataset(d)


def test_missing_channels_are_allowed(sim_dataset, tmp_path):
    d = _copy(sim_dataset, tmp_path)
    p = d / "runs" / "W_L.csv"
    rd = read_run_csv(p)
    cols = ["time", "axle_az_fl", "pitch_rate"]
    np.savetxt(p, np.column_stack([rd.time, rd.channels["axle_az_fl"], rd.channels["pitch_rate"]]),
               delimiter=",", header=",".join(cols), comments="")
    import rideid
    cost = rideid.CostFunction(rideid.load_dataset(d))
    w = cost.W[cost.run_ids.index("W_L")]
    assert (w > 0).sum() == 2


def test_scenario_bad_input(tmp_path, capsys, scenario_file):
    shutil.copy(scenario_file.parent / "road.csv", tmp_path / "road.csv")
    (tmp_path / "s.toml").write_text(SCENARIO_ALL_KINDS.replace("k_tr = 158240.0", ""))
    rc, _, err = run_cli(["simulate", tmp_path / "s.toml", "--out", tmp_path / "o"], capsys)
    assert rc == 2 and "[truth]: missing k_tr" in err and not (tmp_path / "o").exists()
    (tmp_path / "s.toml").write_text(SCENARIO_ALL_KINDS.replace("total_mass = 1093.3", "total_mass = 1200.0"))
    rc, _, err = run_cli(["simulate", tmp_path / "s.toml", "--out", tmp_path / "o"], capsys)
    assert rc == 2 and "total_mass = 1200.0 disagrees with [truth]" in err


def test_identify_into_a_used_folder_leaves_one_result(sim_dataset, tmp_path, capsys):
    """An earlier identification's report and figures go; the user's own files stay."""
    out = tmp_path / "fit"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "fit_W_L.png").write_bytes(b"old")
    (out / "report.html").write_text("old report")
    (out / "result.json").write_text("{}")
    (out / "notes.txt").write_text("mine")
    (out / "mine").mkdir()
    rc, _, err = run_cli(["identify", sim_dataset, "--out", out, "--seed", "1", "--quiet", "--model", "base",
                          "--population", "8", "--generations", "2", "--no-polish", "--no-report"], capsys)
    assert rc == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["history.csv", "mine", "notes.txt", "result.json"]
    assert json.loads((out / "result.json").read_text())["seed"] == 1


def _subparsers():
    import argparse

    from rideid.cli import _parser
    action = next(a for a in _parser()._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices


def test_every_command_has_quiet_and_every_option_help(capsys):
    """The README promises --quiet on every command; every option and argument says what it is."""
    for name, sp in _subparsers().items():
        assert "--quiet" in sp._option_string_actions, name
        for a in sp._actions:
            assert a.help, f"rideid {name}: {a.option_strings or a.dest} has no help text"
        with pytest.raises(SystemExit):
            sp.parse_args(["--help"])
        text = capsys.readouterr().out
        assert "%%" not in text, f"rideid {name} --help: {text}"
    assert "simulate (1 % noise)" in _subparsers()["demo"].format_help()


def test_simulate_builtin_as_study_files_say(tmp_path, capsys):
    rc, stdout, err = run_cli(["simulate", "builtin", "--out", tmp_path / "sim", "--seed", "1", "--quiet"], capsys)
    assert rc == 0, err
    assert "(10 runs)" in stdout and (tmp_path / "sim" / "truth.toml").is_file()
    import rideid
    assert rideid.load_scenario("builtin") == rideid.default_scenario()


def test_score_says_whether_two_robust_std_cover_the_truth(sim_dataset, tmp_path, capsys):
    import rideid
    truth = rideid.load_truth(sim_dataset / "truth.toml")
    pars = {n: {"value": truth[n], "unit": "", "fixed": False, "derived": False, "std": 1e-9,
                "std_robust": 0.01 * truth[n]} for n in truth}
    pars["k_sf"]["value"] = 1.015 * truth["k_sf"]  # 1.5 robust std off: covered
    pars["k_sr"]["value"] = 1.03 * truth["k_sr"]  # 3 robust std off: not covered
    pars["m_s"].update(derived=True)
    pars["k_tf"].update(fixed=True, std_robust=0.0)  # known: nothing to judge
    (tmp_path / "result.json").write_text(json.dumps({"parameters": pars}))
    rc, stdout, err = run_cli(["score", tmp_path / "result.json", sim_dataset / "truth.toml"], capsys)
    assert rc == 0, err
    rows = {ln.split()[0]: ln.split() for ln in stdout.splitlines()[1:]}
    assert "±2 robust covers" in stdout.splitlines()[0]
    assert rows["k_sf"][4] == "yes" and rows["k_sr"][4] == "NO" and rows["k_tf"][4] == "-"
    n = len(truth) - 1
    assert f"±2 std_robust covers the truth for {n - 1} of {n} estimates" in stdout
    assert stdout.strip().splitlines()[-1].startswith("largest error of the estimated parameters: 3.0000 %")


class _Terminal:
    """A stderr that says it is a terminal, rendering carriage returns as a terminal shows them."""

    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, s):
        self.text += s

    def flush(self):
        pass

    def lines(self):
        out = []
        for raw in self.text.split("\n"):
            screen = ""
            for part in raw.split("\r"):
                screen = part + screen[len(part):]
            out.append(screen.rstrip())
        return out


def test_every_message_is_on_its_own_line(monkeypatch):
    """A warning or error while the progress line shows starts a line of its own; the progress line is
    redrawn on the next update."""
    import warnings

    from rideid.cli import Progress, _warning_line, say
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setattr(warnings, "showwarning", _warning_line)
    prog = Progress()
    prog.line("generation 35/400  best 1.1e+00", force=True)
    warnings.warn("k_sf = 8000 ended at its lower search bound 8000", UserWarning, stacklevel=1)
    prog.line("generation 36/400  best 1.0e+00", force=True)
    say("rideid: compiled the simulation kernel in 1 s (cached for later runs)")
    prog.done()
    assert term.lines() == ["rideid: warning: k_sf = 8000 ended at its lower search bound 8000",
                            "rideid: compiled the simulation kernel in 1 s (cached for later runs)", ""]


def test_score_judges_damper_curves_and_bump_stops_against_truth_toml(tmp_path, capsys):
    """truth.toml with [dampers] and bump stops (examples/dampers/real_dampers.toml's car): score reads the true
    curves at the result's knots (piecewise linear through (0, 0), the last slope beyond) and compares the stops;
    a knot no run excited and a stop not reached are shown but neither judged nor counted (before, score
    listed the sixteen parameters only)."""
    import rideid
    from rideid.data.schema import load_truth_dampers, write_toml
    example = Path(__file__).resolve().parents[1] / "examples" / "dampers" / "real_dampers.toml"
    src = tomllib.loads(example.read_text())
    # as rideid simulate writes it: c_sf, c_sr the curves' mean slopes between -0.1 and 0.1 m/s
    write_toml(tmp_path / "truth.toml", {"truth": {**src["truth"], "c_sf": 1786.0, "c_sr": 1649.0},
                                         "dampers": src["dampers"]})
    truth = rideid.load_truth(tmp_path / "truth.toml")
    knots = [-0.4, -0.2, -0.1, -0.05, -0.025, 0.025, 0.05, 0.1, 0.2, 0.4]
    # the true front curve at the knots, by hand: 0.1 lies halfway between 0.05 (59.5 N) and 0.15 (178.6 N);
    # 0.025 halfway from (0, 0) to 0.05; -0.4 one third of the way from -0.3 (-500.1 N) to -0.6 (-785.8 N)
    true_f = {0.1: (59.5 + 178.6) / 2, 0.025: 59.5 / 2, -0.4: -500.1 + (-785.8 + 500.1) / 3}
    true_r = {v: load_truth_dampers(tmp_path / "truth.toml").force("rear", v) for v in knots}
    front = [true_f.get(v, 0.0) for v in knots]
    front[knots.index(0.1)] *= 1.015      # 1.5 % off, std_robust 1 %: covered
    front[knots.index(0.025)] *= 1.04     # 4 % off, std_robust 1 %: not covered
    front[knots.index(-0.4)] *= 1.5       # 50 % off but not excited: shown, not judged
    excited = [v in true_f and v != -0.4 for v in knots]
    dampers = {"velocity": knots,
               "front": {"force": front, "std_robust": [abs(f) * 0.01 if e else None for f, e in zip(front, excited)],
                         "excited": excited},
               "rear": {"force": [true_r[v] for v in knots], "std_robust": [None] * 10, "excited": [False] * 10}}
    bumps = {"front": {"reached": True, "clearance": 0.051, "rate": 45000.0, "std_robust": [0.001, 2000.0],
                       "known": [False, False]},
             "rear": {"reached": False, "clearance": 0.08, "rate": 1000.0, "std_robust": [None, None],
                      "known": [False, False]}}
    pars = {n: {"value": truth[n], "fixed": False, "derived": n in ("m_s", "c_sf", "c_sr"),
                "std_robust": 0.01 * truth[n]} for n in rideid.NAMES}
    (tmp_path / "result.json").write_text(json.dumps({"parameters": pars, "dampers": dampers, "bump_stops": bumps}))
    rc, stdout, err = run_cli(["score", tmp_path / "result.json", tmp_path / "truth.toml"], capsys)
    assert rc == 0, err
    rows = {ln.split()[0]: ln.split() for ln in stdout.splitlines()[1:] if ln.split()}
    k = knots.index(0.1) + 1
    assert float(rows[f"F_f{k}"][2]) == pytest.approx(119.05) and float(rows[f"F_f{k}"][3]) == pytest.approx(1.5)
    assert rows[f"F_f{k}"][4] == "yes" and rows[f"F_f{k}"][5:7] == ["at", "+0.100"]
    k = knots.index(0.025) + 1
    assert float(rows[f"F_f{k}"][3]) == pytest.approx(4.0) and rows[f"F_f{k}"][4] == "NO"
    k = knots.index(-0.4) + 1
    assert float(rows[f"F_f{k}"][2]) == pytest.approx(-595.333, abs=1e-3)
    assert float(rows[f"F_f{k}"][3]) == pytest.approx(50.0) and rows[f"F_f{k}"][-2:] == ["not", "excited"]
    assert float(rows["bs_clear_f"][3]) == pytest.approx(2.0) and rows["bs_clear_f"][4] == "yes"
    assert float(rows["bs_rate_f"][3]) == pytest.approx(-10.0) and rows["bs_rate_f"][4] == "NO"
    assert rows["bs_rate_r"][-2:] == ["not", "reached"] and rows["bs_rate_r"][4] == "-"
    # judged: the 12 parameters, the two excited front knots, the front stop's two numbers
    assert "±2 std_robust covers the truth for 14 of 16 estimates" in stdout
    # the largest error is the front stop's rate (10 %): not the knot nobody excited (50 %)
    assert stdout.strip().splitlines()[-1] == "largest error of the estimated parameters: 10.0000 %"
    # a linear model against a truth with curves: c_sf compared with the curves' mean slope, and said so
    (tmp_path / "result.json").write_text(json.dumps({"parameters": pars}))
    rc, stdout, err = run_cli(["score", tmp_path / "result.json", tmp_path / "truth.toml"], capsys)
    assert rc == 0 and "the truth has damper curves and the model linear dampers" in stdout
    assert stdout.count("not in the model") == 2  # both stops' rates: the model has none
