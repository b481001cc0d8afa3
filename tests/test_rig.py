"""Four-post rig runs (SPEC §13): the posts as the wheel inputs, rig scenarios, identification, bad rig input."""

import csv
import json
import tomllib

import numpy as np
import pytest
import tomli_w

from rideid.cli import main
from rideid.data.schema.runfiles import missing_post_channel
from rideid.model.equations import CHANNEL_KIND, CHANNELS
from rideid.model.params import NAMES, as_vector
from rideid.model.posts import POST_CHANNELS, POST_VEL_CHANNELS, PostSignal, prepare_function, prepare_posts
from rideid.model.simulate import simulate_reference

TRUTH = {"m_s": 965.7, "I_xx": 207.3, "I_yy": 1565.8, "a": 1.156, "m_uf": 31.9, "m_ur": 31.9, "k_sf": 24445.0,
         "k_sr": 19629.0, "c_sf": 1786.0, "c_sr": 1649.0, "k_tf": 158240.0, "k_tr": 158240.0}
VEHICLE = {"wheelbase": 2.579, "track_front": 1.387, "track_rear": 1.364, "tire_radius": 0.30}


def rig_scenario(duration=4.0, runs=("sweep_heave", "random"), **extra):
    """A scenario document: the built-in car on a four-post rig, a heave sweep and random post motion."""
    table = {"sweep_heave": {"signal": "sweep", "pattern": "heave", "amplitude": 0.002},
             "sweep_pitch": {"signal": "sweep", "pattern": "pitch", "amplitude": 0.002},
             "sweep_roll": {"signal": "sweep", "pattern": "roll", "amplitude": 0.002},
             "sweep_warp": {"signal": "sweep", "pattern": "warp", "amplitude": 0.002},
             "random": {"signal": "random", "amplitude": 0.0015}}
    doc = {"name": "rig", "vehicle": dict(VEHICLE), "known": {"total_mass": 1093.3}, "truth": dict(TRUTH),
           "runs": [{"id": r, "input": "posts", **table[r], "f_low": 0.5, "f_high": 20.0, "fs": 200,
                     "duration": duration} for r in runs]}
    doc.update(extra)
    return doc


def run_cli(args, capsys):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def simulate(tmp_path, capsys, doc, name="sim", noise=0.0, engine="rideid"):
    (tmp_path / f"{name}.toml").write_text(tomli_w.dumps(doc))
    out = tmp_path / name
    rc, _, err = run_cli(["simulate", tmp_path / f"{name}.toml", "--out", out, "--noise", noise, "--seed", "1",
                          "--engine", engine, "--quiet"], capsys)
    assert rc == 0, err
    return out


def read_csv(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


def write_csv(path, header, data):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows([[repr(float(v)) for v in row] for row in data])


def independent_seven_dof(P, geom, inputs_at, t, dt=2e-4):
    """SPEC channels of the 7-DOF car of SPEC §1 assembled here from its equations (not rideid's): mass,
    stiffness and damping matrices of q = [z, theta, phi, z_fl, z_fr, z_rl, z_rr], the posts as the road
    under each tire (``inputs_at(times) -> (r, rdot)``), scipy.signal.lsim on a grid ``dt`` fine."""
    from scipy.signal import lsim

    p = dict(zip(NAMES, P))
    b = geom.wheelbase - p["a"]
    x = np.array([p["a"], p["a"], -b, -b])
    y = np.array([1, -1, 0, 0]) * geom.track_front / 2 + np.array([0, 0, 1, -1]) * geom.track_rear / 2
    per_axle = lambda f, r: np.array([p[f], p[f], p[r], p[r]])  # noqa: E731
    T = np.column_stack([np.ones(4), -x, y])
    D = np.hstack([-T, np.eye(4)])
    M = np.diag(np.concatenate([[p["m_s"], p["I_yy"], p["I_xx"]], per_axle("m_uf", "m_ur")]))
    K = D.T @ np.diag(per_axle("k_sf", "k_sr")) @ D + np.diag(np.r_[np.zeros(3), per_axle("k_tf", "k_tr")])
    C = D.T @ np.diag(per_axle("c_sf", "c_sr")) @ D
    E = np.vstack([np.zeros((3, 4)), np.diag(per_axle("k_tf", "k_tr"))])
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((7, 7)), np.eye(7)], [-Mi @ K, -Mi @ C]])
    B = np.vstack([np.zeros((7, 4)), Mi @ E])
    S = np.zeros((8, 7))
    S[:4, :3], S[4:, 3:] = T, np.eye(4)
    rates = np.zeros((2, 14))
    rates[0, 8] = rates[1, 9] = 1.0
    Cy = np.vstack([S @ A[7:], rates])
    Dy = np.vstack([S @ B[7:], np.zeros((2, 4))])
    sub = int(round((t[1] - t[0]) / dt))
    tf = t[0] + np.arange((t.size - 1) * sub + 1) * (t[1] - t[0]) / sub
    u = inputs_at(tf)[0]
    x0 = np.concatenate([np.linalg.solve(K, E @ u[0]), np.zeros(7)])  # at rest on the posts
    _, yf, _ = lsim((A, B, Cy, Dy), u, tf, X0=x0)
    return yf[::sub]


def kind_scale(y):
    """Per channel: the RMS of the liveliest channel of its kind (accelerations, rates)."""
    rms = np.sqrt(np.mean(y ** 2, axis=0))
    kind = np.array([CHANNEL_KIND[c] for c in CHANNELS])
    return np.array([rms[kind == k].max() for k in kind])


# ---------------------------------------------------------------------------
# The posts as the wheel inputs

def test_post_signals_are_what_they_say():
    """A sweep: peak amplitude as asked, the pattern's signs, its rate the derivative of its displacement, at rest
    at both ends. Random: RMS as asked in the middle, each post its own, nothing outside the band."""
    T, fs = 10.0, 200
    t = np.arange(int(T * fs) + 1) / fs
    sweep = PostSignal("sweep", 0.002, 0.5, 20.0, T, pattern="pitch").function()
    z, zd = sweep(t)
    assert np.max(np.abs(z)) == pytest.approx(0.002, rel=1e-3)
    np.testing.assert_array_equal(np.sign(z[:, 0]), np.sign(z[:, 1]))
    np.testing.assert_array_equal(z[:, 2], -z[:, 0])
    e = 1e-6
    np.testing.assert_allclose(zd, (sweep(t + e)[0] - sweep(t - e)[0]) / (2 * e), atol=1e-6 * np.max(np.abs(zd)))
    assert np.all(np.abs(z[[0, -1]]) < 1e-15) and np.all(np.abs(zd[[0, -1]]) < 1e-12)
    rnd = PostSignal("random", 0.0015, 1.0, 15.0, T).function(np.random.default_rng(3))
    z, zd = rnd(t)
    np.testing.assert_allclose(zd, (rnd(t + e)[0] - rnd(t - e)[0]) / (2 * e), atol=1e-6 * np.max(np.abs(zd)))
    mid = (t > 2) & (t < T - 2)
    # a 6 s window of a multisine of 140 tones: its RMS within 10 % of the whole period's
    np.testing.assert_allclose(np.sqrt(np.mean(z[mid] ** 2, axis=0)), 0.0015, rtol=0.1)
    # independent posts: 2000 samples of a 15 Hz band hold ~300 independent values, so |rho| < 4 / sqrt(300)
    assert np.max(np.abs(np.corrcoef(z.T) - np.eye(4))) < 0.23
    Z = np.abs(np.fft.rfft(z[mid], axis=0)) ** 2
    f = np.fft.rfftfreq(mid.sum(), 1 / fs)
    assert Z[(f > 17) | (f < 0.5)].sum() < 1e-2 * Z.sum()


def test_rig_run_equals_an_independent_seven_dof():
    """The posts' samples through rideid's rig path (cubic spline, its moments, the exact discretisation) against
    the 7-DOF assembled here from SPEC §1 alone, driven by scipy's own not-a-knot spline of the same samples at
    0.2 ms: every channel within 1e-4 of the RMS of its kind (measured 2e-6)."""
    from scipy.interpolate import CubicSpline

    from rideid.model.params import Geometry
    geom = Geometry(**VEHICLE)
    P = as_vector(TRUTH)
    t = np.arange(601) / 200
    z = PostSignal("random", 0.0015, 0.5, 20.0, 3.0).function(np.random.default_rng(7))(t)[0]
    y = simulate_reference(P[None], geom, prepare_posts(t, z))[0]
    sp = CubicSpline(t, z, axis=0)
    yi = independent_seven_dof(P, geom, lambda tt: (sp(tt), None), t)
    rel = np.sqrt(np.mean((y - yi) ** 2, axis=0)) / kind_scale(yi)
    assert np.max(rel) < 1e-4, rel


def test_samples_of_the_posts_carry_the_signal_itself():
    """The posts read back from their 200 Hz samples (the identification's path) against the signal itself
    (the simulation's): the channels agree within 2e-3 of the RMS of their kind on a random signal to 20 Hz
    (the spline's error, of order (2 pi f h)^4 / 384 near the band's top); with the measured post velocities
    given (a Hermite spline) as well."""
    from rideid.model.params import Geometry
    geom = Geometry(**VEHICLE)
    P = as_vector(TRUTH)[None]
    t = np.arange(601) / 200
    f = PostSignal("random", 0.0015, 0.5, 20.0, 3.0).function(np.random.default_rng(7))
    y = simulate_reference(P, geom, prepare_function(t, f))[0]
    z, zd = f(t)
    scale = kind_scale(y)
    for vel in (None, zd):
        ys = simulate_reference(P, geom, prepare_posts(t, z, vel))[0]
        assert np.max(np.sqrt(np.mean((ys - y) ** 2, axis=0)) / scale) < 2e-3


@pytest.mark.parametrize("raw", [False, True], ids=["spec", "raw"])
def test_mujoco_four_poster_follows_the_posts(raw):
    """The MuJoCo car of rideid.verify.hifi (reduced configuration: the 7-DOF physics) with its posts driven by a
    rig signal (``inputs=``), 2 s of a roll sweep: every channel equals rideid's exact discretisation of the same
    signal within 1e-3 of its kind's RMS (measured 1.8e-5 and 2.8e-5: RK4 at 1 ms against the exact
    discretisation); ``raw``: the readings with gravity, the posts moved 1 s later (a logger's lead-in), equal
    after that second once gravity is taken off the accelerometers."""
    pytest.importorskip("mujoco")
    from rideid.model.params import GRAVITY, Geometry
    from rideid.verify.hifi import simulate_mujoco
    geom = Geometry(**VEHICLE)
    P = as_vector(TRUTH)
    t = np.arange(401) / 200
    f = PostSignal("sweep", 0.002, 1.0, 20.0, 2.0, pattern="roll").function()
    yr = simulate_reference(P[None], geom, prepare_function(t, f))[0]
    if raw:
        tt = np.arange(601) / 200
        y = simulate_mujoco(P, geom, None, None, tt, inputs=lambda x: f(np.asarray(x) - 1.0), raw=True)
        y = y[200:] - np.r_[[GRAVITY] * 8, 0.0, 0.0]
    else:
        y = simulate_mujoco(P, geom, None, None, t, inputs=f)
    rel = np.sqrt(np.mean((y - yr) ** 2, axis=0)) / kind_scale(yr)
    assert np.max(rel) < 1e-3, rel


# ---------------------------------------------------------------------------
# Identification on rig data

def test_rig_dataset_identified(tmp_path, capsys):
    """`rideid simulate` of a rig scenario (a heave sweep and random post motion, 4 s each, 1 % noise) writes the
    posts after the ten channels and `input = "posts"`; `rideid identify` (the model choice, population 16)
    finds the twelve within 0.3 % (measured: 0.06 %) and calls the fit adequate."""
    out = simulate(tmp_path, capsys, rig_scenario(), noise=0.01)
    header, _ = read_csv(out / "runs" / "random.csv")
    assert header == ["time", *CHANNELS, *POST_CHANNELS]
    runs = tomllib.loads((out / "dataset.toml").read_text())["runs"]
    assert all(r["input"] == "posts" and "track" not in r and "speed" not in r for r in runs)
    rc, stdout, err = run_cli(["identify", out, "--out", tmp_path / "fit", "--seed", "1", "--population", "16",
                               "--no-report", "--quiet"], capsys)
    assert rc == 0, err
    res = json.loads((tmp_path / "fit" / "result.json").read_text())
    err = {n: res["parameters"][n]["value"] / TRUTH[n] - 1 for n in NAMES}
    assert max(abs(e) for e in err.values()) < 3e-3, err
    assert res["adequacy"]["adequate"]
    assert res["preprocessing"]["random"]["start"]["value"] == 0.0


def test_mixed_rig_and_track_dataset(tmp_path, capsys):
    """Rig runs and a track run in one dataset: identified together (the twelve within 0.3 %, population 16)."""
    doc = rig_scenario(runs=("random",))
    doc["tracks"] = [{"id": "twist", "kind": "chassis_twist", "start": 3.0, "height": 0.04, "bump_length": 1.6,
                      "spacing": 4.0, "bumps": 2}]
    doc["runs"].append({"id": "T", "track": "twist", "speed": 4.0, "fs": 200, "duration": 5.0})
    out = simulate(tmp_path, capsys, doc, noise=0.01)
    rc, _, err = run_cli(["identify", out, "--out", tmp_path / "fit", "--seed", "1", "--population", "16",
                          "--model", "base", "--no-report", "--quiet"], capsys)
    assert rc == 0, err
    res = json.loads((tmp_path / "fit" / "result.json").read_text())
    err = {n: res["parameters"][n]["value"] / TRUTH[n] - 1 for n in NAMES}
    assert max(abs(e) for e in err.values()) < 3e-3, err


def test_plan_and_sensitivity_take_a_rig_scenario(tmp_path, capsys):
    """`rideid plan` and `rideid sensitivity` on a rig scenario: the posts' signal is the runs' input; every
    free parameter gets a CRLB (on the rig the tire rates as well as the suspension's: below 0.1 % at 1 % noise),
    and plan.md lists the runs as on a four-post rig."""
    (tmp_path / "rig.toml").write_text(tomli_w.dumps(rig_scenario(duration=2.0)))
    rc, _, err = run_cli(["plan", tmp_path / "rig.toml", "--out", tmp_path / "plan", "--noise", "0.01", "--quiet"],
                         capsys)
    assert rc == 0, err
    plan = json.loads((tmp_path / "plan" / "plan.json").read_text())
    crlb = plan["all_runs"]["crlb"]
    assert set(crlb) == set(NAMES) - {"m_s"}
    assert max(v["relative"] for v in crlb.values()) < 1e-3
    assert "| sweep_heave | four-post rig (SPEC §13) | - |" in (tmp_path / "plan" / "plan.md").read_text()
    rc, _, err = run_cli(["sensitivity", tmp_path / "rig.toml", "--out", tmp_path / "maps", "--quiet"], capsys)
    assert rc == 0, err


def test_posts_through_a_channel_map_in_mm(tmp_path, capsys):
    """A rig run as a logger writes it: the posts in mm under their own names, mapped in [channels] with
    unit = "mm" (and the rig's time 0 at the first sample, no start to find): loaded, its posts are the SPEC
    CSV's to rounding, and its wheel inputs the same."""
    import rideid
    out = simulate(tmp_path, capsys, rig_scenario(duration=2.0, runs=("random",)))
    header, data = read_csv(out / "runs" / "random.csv")
    names = ["t_s", *CHANNELS, "LVDT_FL", "LVDT_FR", "LVDT_RL", "LVDT_RR"]
    data[:, -4:] *= 1000.0
    log = tmp_path / "logged"
    (log / "runs").mkdir(parents=True)
    write_csv(log / "runs" / "random.csv", names, data)
    doc = tomllib.loads((out / "dataset.toml").read_text())
    doc["channels"] = {"time": {"name": "t_s", "unit": "s"},
                       **{c: {"name": n, "unit": "mm"} for c, n in zip(POST_CHANNELS, names[-4:])}}
    (log / "dataset.toml").write_text(tomli_w.dumps(doc))
    ds, ref = rideid.load_dataset(log), rideid.load_dataset(out)
    assert "random" in ds.measured
    assert ds.preprocessing()["random"]["start"]["source"].startswith("four-post rig")
    np.testing.assert_allclose(ds.data["random"].posts, ref.data["random"].posts, atol=1e-12)
    np.testing.assert_allclose(ds.data["random"].time, ref.data["random"].time, atol=1e-12)


def test_a_post_channels_sensor_chain_is_divided_out(rig_data, tmp_path):
    """Posts recorded through a 30 Hz second-order low-pass (applied here with scipy.signal.lsim to the posts'
    spline at 0.25 ms): declared as the channel's `lowpass`, the posts loaded are the rig's within 1e-3 of their
    RMS (measured 1.2e-4 on 8 s); not declared, 0.3 and more off (the chain's lag at 20 Hz)."""
    import shutil

    from scipy.interpolate import CubicSpline
    from scipy.signal import butter, lsim

    import rideid
    header, data = read_csv(rig_data / "runs" / "random.csv")
    t, z = data[:, 0], data[:, -4:].copy()
    sub = 20
    tf = np.linspace(t[0], t[-1], (t.size - 1) * sub + 1)
    b, a = butter(2, 2 * np.pi * 30.0, analog=True)
    zs = CubicSpline(t, z, axis=0)(tf)
    data[:, -4:] = np.column_stack([lsim((b, a), zs[:, i], tf)[1] for i in range(4)])[::sub]
    rms = np.sqrt(np.mean(z ** 2, axis=0))
    for declared, lo, hi in ((True, 0.0, 1e-3), (False, 0.3, np.inf)):
        folder = tmp_path / str(declared)
        shutil.copytree(rig_data, folder)
        write_csv(folder / "runs" / "random.csv", header, data)
        doc = tomllib.loads((folder / "dataset.toml").read_text())
        doc["channels"] = {c: {"name": c, **({"lowpass": {"hz": 30.0, "order": 2}} if declared else {})}
                           for c in POST_CHANNELS}
        (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
        ds = rideid.load_dataset(folder)
        err = np.sqrt(np.mean((ds.data["random"].posts - z) ** 2, axis=0)) / rms
        assert np.all((lo < err) & (err < hi)), (declared, err)
    rec = ds.preprocessing()["random"]["channels"]["post_fl"]
    assert "sensor_filters" not in rec  # the undeclared one, read last


# ---------------------------------------------------------------------------
# Bad rig input: one line, exit 2, nothing written

@pytest.fixture(scope="module")
def rig_data(tmp_path_factory):
    """A short noise-free rig dataset (2 s of random post motion), simulated once."""
    from rideid.data.schema import parse_scenario
    from rideid.synth.scenario import simulate_manifest, write_dataset
    folder = tmp_path_factory.mktemp("rig")
    sc = parse_scenario(rig_scenario(duration=2.0, runs=("random",)), folder / "rig.toml")
    data, lifts = simulate_manifest(sc, seed=1)
    assert lifts == []
    return write_dataset(sc, data, folder / "sim")


def _bad_copy(rig_data, tmp_path, edit_csv=None, edit_doc=None):
    import shutil
    bad = tmp_path / "bad"
    shutil.copytree(rig_data, bad)
    if edit_csv is not None:
        header, data = read_csv(bad / "runs" / "random.csv")
        write_csv(bad / "runs" / "random.csv", *edit_csv(header, data))
    if edit_doc is not None:
        doc = tomllib.loads((bad / "dataset.toml").read_text())
        edit_doc(doc)
        (bad / "dataset.toml").write_text(tomli_w.dumps(doc))
    return bad


def _drop_post_rl(header, data):
    j = header.index("post_rl")
    return header[:j] + header[j + 1:], np.delete(data, j, axis=1)


def _posts_times(factor):
    def edit(header, data):
        data[:, -4:] *= factor
        return header, data
    return edit


def _map_post_fl(doc):
    doc["channels"] = {"post_fl": {"name": "post_fl", "unit": "m"}}


def _range_on_a_post(doc):
    doc["channels"] = {"post_fl": {"name": "post_fl", "range": 0.1}}


def _track_on_rig(doc):
    doc["runs"][0]["track"] = "twist"


def _typo_input(doc):
    doc["runs"][0]["input"] = "post"


@pytest.mark.parametrize("edit_csv, edit_doc, message", [
    (_drop_post_rl, None, "random.csv: a four-post rig run (input = \"posts\") needs the four post displacements "
                          "post_fl, post_fr, post_rl, post_rr (m); 'post_rl' is missing"),
    (_posts_times(1000.0), None, "m peak to peak, beyond any ride rig's stroke (0.3 m)"),
    (_posts_times(25.0), None, "the post's acceleration between 3 and 6 Hz is 22.7 times its axle's, where a "
                               "wheel follows its post (about 1): the posts are not in m as SPEC §13 says"),
    (_drop_post_rl, _map_post_fl, "needs the four post displacements post_fl, post_fr, post_rl, post_rr (m); "
                                  "'post_rl' is neither mapped in [channels] nor a column of"),
    (None, _range_on_a_post, "[channels] post_fl range: a post channel has no range to leave samples out at"),
    (None, _track_on_rig, "key 'track' does not apply to a four-post rig run"),
    (None, _typo_input, "input: expected \"posts\" (a four-post rig run, SPEC §13), got 'post'"),
], ids=["missing-post-column", "mm-as-m-stroke", "25x-as-m-by-the-axles", "channel-map-without-a-post",
        "range-on-a-post", "track-on-a-rig", "input-typo"])
def test_bad_rig_input_one_line_exit_2(rig_data, tmp_path, capsys, edit_csv, edit_doc, message):
    bad = _bad_copy(rig_data, tmp_path, edit_csv, edit_doc)
    rc, out, err = run_cli(["identify", bad, "--out", tmp_path / "fit", "--quiet"], capsys)
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rideid: error: "), err
    assert message in lines[0], lines[0]
    assert "Traceback" not in err
    assert not (tmp_path / "fit").exists()


def test_a_rig_run_that_starts_moving_is_warned_of(rig_data, tmp_path):
    """A rig recording cut while the posts move (its first second dropped): a DataWarning names the column and
    says to start where the car stands still; the run as simulated (faded in from rest) gives none."""
    import warnings

    import rideid
    with warnings.catch_warnings():
        warnings.simplefilter("error", rideid.DataWarning)
        rideid.load_dataset(rig_data)

    def cut(header, data):
        data = data[200:].copy()
        data[:, 0] -= data[0, 0]
        return header, data

    bad = _bad_copy(rig_data, tmp_path, cut)
    with pytest.warns(rideid.DataWarning, match=r"random.csv: column 'post_\w+' already moves in the first 0.2 s"):
        rideid.load_dataset(bad)


def test_mm_as_m_names_the_column_and_the_fix(rig_data, tmp_path, capsys):
    """Posts in mm declared m: the line names the file, the column, the stroke and the fix."""
    bad = _bad_copy(rig_data, tmp_path, _posts_times(1000.0))
    rc, _, err = run_cli(["identify", bad, "--out", tmp_path / "fit", "--quiet"], capsys)
    assert rc == 2
    assert "random.csv: column 'post_" in err and "m peak to peak, beyond any ride rig's stroke (0.3 m)" in err
    assert "is the column in mm? convert it, or map it in [channels] with unit = \"mm\"" in err


@pytest.mark.parametrize("run, message", [
    ({"signal": "chirp"}, "signal: a four-post rig run of a scenario needs signal = \"sweep\" or \"random\""),
    ({"f_high": 150.0}, "the post signal's band needs f_low < f_high < fs / 2 = 100 Hz"),
    ({"speed": 5.0}, "key 'speed' does not apply to a four-post rig run"),
    ({"pattern": "bounce"}, "pattern: expected one of heave, pitch, roll, warp, got 'bounce'"),
])
def test_bad_rig_scenario_one_line_exit_2(tmp_path, capsys, run, message):
    doc = rig_scenario(runs=("sweep_heave",))
    doc["runs"][0].update(run)
    (tmp_path / "s.toml").write_text(tomli_w.dumps(doc))
    rc, _, err = run_cli(["simulate", tmp_path / "s.toml", "--out", tmp_path / "o", "--quiet"], capsys)
    assert rc == 2
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------
# The MuJoCo four-poster (slow): the accuracy docs/rig.md quotes

MUJOCO_RUNS = ("sweep_heave", "sweep_pitch", "sweep_roll", "sweep_warp", "random")
CURVES = {"velocity": [-0.6, -0.3, -0.15, -0.05, 0.05, 0.15, 0.3, 0.6],
          "front": [-785.8, -500.1, -357.2, -119.1, 59.5, 178.6, 250.0, 392.9],
          "rear": [-725.6, -461.7, -329.8, -109.9, 55.0, 164.9, 230.9, 362.8]}


@pytest.mark.slow
@pytest.mark.parametrize("car", ["twelve", "bars", "bars-and-curves"])
def test_mujoco_four_poster_accuracy(car, tmp_path, capsys):
    """The MuJoCo four-poster of rideid.verify.hifi driven by four sweeps (heave, pitch, roll, warp; 2 mm,
    0.5-20 Hz) and random post motion (1.5 mm RMS), 10 s each at 200 Hz, 1 % noise, no road: the twelve within
    0.5 % and adequate; with anti-roll bars (within 0.5 %); with bars and damper curves (the twelve and bars
    within 0.5 %, every excited knot's force within 1 %). Measured (docs/rig.md): 0.030 %, 0.04 %, 0.08 %."""
    pytest.importorskip("mujoco")
    doc = rig_scenario(duration=10.0, runs=MUJOCO_RUNS)
    model = "base"
    if car != "twelve":
        doc["truth"].update(k_arf=9000.0, k_arr=4000.0)
        model = "anti_roll_bars"
    if car == "bars-and-curves":
        del doc["truth"]["c_sf"], doc["truth"]["c_sr"]
        doc["dampers"] = CURVES
        model = "damper_curves,anti_roll_bars"
    out = simulate(tmp_path, capsys, doc, noise=0.01, engine="mujoco")
    rc, _, err = run_cli(["identify", out, "--out", tmp_path / "fit", "--seed", "1", "--model", model,
                          "--no-report", "--quiet"], capsys)
    assert rc == 0, err
    res = json.loads((tmp_path / "fit" / "result.json").read_text())
    truth = tomllib.loads((out / "truth.toml").read_text())["truth"]
    names = list(NAMES) + (["k_arf", "k_arr"] if car != "twelve" else [])
    err = {n: res["parameters"][n]["value"] / truth[n] - 1 for n in names}
    assert max(abs(e) for e in err.values()) < 5e-3, err
    assert res["adequacy"]["adequate"]
    if car == "bars-and-curves":
        from rideid.data.schema.dampers import parse_dampers
        curves = parse_dampers(CURVES, "test")
        v = np.array(res["dampers"]["velocity"])
        for ax, key in (("f", "front"), ("r", "rear")):
            true = np.array([curves.force(ax, x) for x in v])
            got = np.array(res["dampers"][key]["force"])
            excited = np.array(res["dampers"][key].get("excited", [True] * v.size), dtype=bool)
            assert np.max(np.abs(got - true)[excited] / np.abs(true[excited])) < 1e-2


def test_missing_post_channel_names_the_first_gap():
    """The four displacements are needed, the four velocities all or none (SPEC §13): the first gap named."""
    assert missing_post_channel(POST_CHANNELS) is None
    assert missing_post_channel(POST_CHANNELS + POST_VEL_CHANNELS + ("time",)) is None
    assert missing_post_channel(("post_fl", "post_fr", "post_rr", "post_vel_fl")) == "post_rl"
    assert missing_post_channel({*POST_CHANNELS, "post_vel_fl", "post_vel_rl"}) == "post_vel_fr"
