"""Tracks as built (SPEC §11, estimate.problem.asbuilt): the drawing is the nominal shape, the road is what the car
rolled over. The data come from the independent simulator of tests/asbuilt_tracks.py (SciPy lsim of a 7-DOF car
written from SPEC §1, brute-force disc envelope), driving the drawing times 1.04 plus 1.5 mm RMS of unevenness."""

import json

import numpy as np
import pytest

import rideid
from asbuilt_tracks import RUNS, write_dataset
from cars import SUV_TRUTH
from rideid.cli import main
from rideid.errors import ArgumentError
from rideid.estimate.problem import asbuilt
from rideid.estimate.problem.cost import ParameterSpace


def _truth_row(ds):
    space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=())
    return space, space.full(np.array([[SUV_TRUTH[n] for n in space.names]]))[0]


@pytest.fixture(scope="module")
def as_built(tmp_path_factory):
    return rideid.load_dataset(write_dataset(tmp_path_factory.mktemp("asbuilt") / "ds", seed=4))


def test_the_independent_simulator_drives_the_drawing_as_rideid_does(tmp_path):
    """Two independent simulations of the exact drawing (SciPy lsim of a state space written from SPEC §1 with a
    brute-force envelope, and rideid's exact discretisation with its tabulated envelope) agree to 2e-4 of each
    channel's RMS (cost = mean squared error over channel energy)."""
    ds = rideid.load_dataset(write_dataset(tmp_path / "exact", amplitude=1.0, rms=0.0, noise=0.0, runs=RUNS[1:3]))
    cf = rideid.CostFunction(ds)
    assert cf(np.array([[SUV_TRUTH[n] for n in cf.names]]))[0] < 4e-8


def test_the_whitened_residual_is_the_gaussian_likelihood():
    """Per bin ``|M^(-1/2) x|^2 + log det M`` with ``M = I + A D A^H`` equals the dense ``x^H M^-1 x + log det M``,
    and the limits: D = 0 the identity, 'free' the projector off A's columns."""
    rng = np.random.default_rng(7)
    K, c = 6, 10
    A = rng.standard_normal((K, c, 2)) + 1j * rng.standard_normal((K, c, 2))
    D = rng.uniform(0.01, 5.0, K)
    x = rng.standard_normal((K, c)) + 1j * rng.standard_normal((K, c))
    white, logdet = asbuilt._whitener(A, D, "prior")
    got = np.sum(np.abs(white(x)) ** 2, axis=1) + logdet
    for k in range(K):
        M = np.eye(c) + D[k] * A[k] @ A[k].conj().T
        want = np.real(x[k].conj() @ np.linalg.solve(M, x[k])) + np.linalg.slogdet(M)[1]
        assert got[k] == pytest.approx(want, rel=1e-10)
    ident, ld0 = asbuilt._whitener(A, D, "amplitude")
    assert np.array_equal(ident(x), x) and not ld0.any()
    perp, _ = asbuilt._whitener(A, D, "free")
    Q, _ = np.linalg.qr(A[0])
    assert np.allclose(perp(x)[0], x[0] - Q @ (Q.conj().T @ x[0]), atol=1e-12)


def test_the_amplitude_factor_of_a_track_without_unevenness(tmp_path):
    """Runs on the twist and the washboard 4 % above their drawing, no unevenness, 1 % noise: at the true car the
    fit finds each run's factor to 0.3 % (the disc's envelope of a 4 % taller bump is not exactly 4 % taller),
    and the drawing as it is gives 1 to 1e-3. (Without noise the bins' noise levels are rounding, and their
    weights arbitrary: the twist's factor then came out 1.055.)"""
    runs = [RUNS[1], RUNS[4]]
    for amp, tol in ((1.04, 0.003), (1.0, 1e-3)):
        ds = rideid.load_dataset(write_dataset(tmp_path / f"a{amp}", amplitude=amp, rms=0.0, runs=runs))
        _, P = _truth_row(ds)
        for run in ds.runs:
            tr = asbuilt.prepare_track_run(ds, run, "amplitude")
            tr.prior = asbuilt.estimate_prior(P, ds.geometry, tr)
            assert asbuilt.solve(P, ds.geometry, tr).alpha == pytest.approx(amp, abs=tol), run.id


def test_the_unevenness_found(as_built):
    """At the true car the prior finds each run's unevenness: 1.5 mm RMS in the simulation (0.5-10 m waves, inside
    every run's fit band) plus what the envelope adds; between 1.2 and 3.5 mm on every run, and a factor near
    1.04 on the twist."""
    _, P = _truth_row(as_built)
    for run in as_built.runs:
        tr = asbuilt.prepare_track_run(as_built, run)
        tr.prior = asbuilt.estimate_prior(P, as_built.geometry, tr)
        assert 1.2e-3 < asbuilt.unevenness_rms(tr) < 3.5e-3, run.id
        if run.track == "twist_high":
            assert asbuilt.solve(P, as_built.geometry, tr).alpha == pytest.approx(1.04, abs=0.01)


def test_a_short_washboard_run_holds_its_unevenness_at_the_prior(tmp_path):
    """The SUV's washboard run (3.1 s at 10 m/s, the exact drawing, 1 % noise) at the true car: the free road fit's
    start state and rear lead-in explain its slowest bins as well as a road does (the washboard excites one line,
    at 12.5 Hz), and what they put into the road estimate was taken for unevenness: 310 mm RMS over the surface's
    waves on seed 1 (399 mm on seed 2, 19 mm on seed 3), which rejected the tracks as built for the whole dataset
    (docs/tracks-as-built.md). Now the run's unevenness is held at the prior's floor and result.json says so
    (tracks.<track>.runs.<run>.unevenness_held); the twist and the herringbone of the same dataset, and the same
    washboard run with 1.5 mm of real unevenness, still have theirs estimated (measured boundary shares 2e-4 to
    0.83, against 1.2e3-5.4e5 for the held runs; setting asbuilt.boundary_share = 10). Off by default: the SUV
    without its anti-roll bars, fitted with the base model, puts 4.1e4-7.4e5 there on its washboard runs, and
    holding them hid the only evidence that rejected the tracks as built (tests/test_model_choice.py,
    tests/test_hifi.py: the base model on a car with bars must stay not adequate)."""
    by_id = {r[0]: r for r in RUNS}
    assert rideid.settings.defaults["asbuilt.boundary_share"] == 1e9  # off by default: the SUV without its bars
    with rideid.settings.using("asbuilt", boundary_share=10.0):
        _short_washboard_held(tmp_path, by_id)


def _short_washboard_held(tmp_path, by_id):
    from rideid.estimate.assess import motion
    for seed in (1, 2):
        ds = rideid.load_dataset(write_dataset(tmp_path / f"exact{seed}", amplitude=1.0, rms=0.0, noise=0.01, seed=seed,
                                               runs=[by_id["T_HH"], by_id["H_HH"], by_id["W_H"]]))
        _, P = _truth_row(ds)
        trs = []
        for run in ds.runs:
            tr = asbuilt.prepare_track_run(ds, run)
            tr.prior = asbuilt.estimate_prior(P, ds.geometry, tr)
            trs.append(tr)
            surface = asbuilt.unevenness_rms(tr, 10.0)
            if run.id == "W_H":
                assert tr.prior.held and "too short" in tr.prior.held
                assert surface < 1e-4, surface  # the floor: 0.003 mm measured
                assert asbuilt.solve(P, ds.geometry, tr).alpha == pytest.approx(1.0, abs=2e-3)
            else:
                assert tr.prior.held is None and surface < 1e-3, (run.id, surface)
        held = next(tr for tr in trs if tr.run_id == "W_H")  # its entry of result.json tracks.washboard.runs
        rec = motion.track_run_record(held, asbuilt.solve(P, ds.geometry, held, alpha_std=True))
        assert "too short" in rec["unevenness_held"]
        assert rec["unevenness_rms_surface_m"] < rideid.settings.defaults["anyroad.plausible_rms"]
    ds = rideid.load_dataset(write_dataset(tmp_path / "rough", seed=1, runs=[by_id["W_H"]]))
    _, P = _truth_row(ds)
    tr = asbuilt.prepare_track_run(ds, ds.runs[0])
    tr.prior = asbuilt.estimate_prior(P, ds.geometry, tr)
    assert tr.prior.held is None and 1.2e-3 < asbuilt.unevenness_rms(tr, 10.0) < 3.5e-3


def test_the_prepared_run_holds_the_drawings_inputs(as_built):
    """A run prepared for the as-built fit keeps the drawn track's corner inputs it tabulated (the verdict reads
    them there): those of nominal_inputs, and U their DFT."""
    run = as_built.runs[1]
    tr = asbuilt.prepare_track_run(as_built, run)
    ri = asbuilt.nominal_inputs(as_built, run)
    assert np.array_equal(tr.inputs.u, ri.u) and np.array_equal(tr.inputs.rate, ri.rate)
    assert np.array_equal(tr.U, np.fft.rfft(np.asarray(ri.u, dtype=float), axis=0))


@pytest.mark.slow  # moved to CI's slow pass: make test under 10 minutes on two cores
def test_the_car_on_tracks_as_built_from_a_start(as_built):
    """The default path from a start 3 % off the truth (the search skipped, the polish and the as-built stage
    as rideid identify runs them): the twelve within 1.2 %, every error within 2 std_robust (the white sandwich of
    the as-built runs, asbuilt.meat; measured 1.3 at most, with the bin-clustered one 2.5 and 9 of 12 within 2),
    the verdict adequate, and the tracks block in result.json with the twist's factor near 1.04.

    SPEC §13: every run's speed and start are solved with the car (their priors the declared values, 0.3 % and
    5 ms wide). The speeds come within 0.015 % of the driven ones and the starts within 0.6 ms of the exact 0,
    and the unsprung masses move from +0.51 / +0.61 % (speeds and starts held at the declared values) to +0.95 /
    +1.08 %, 1.7 and 1.8 std_robust (their error bars now hold the motion); the starts' freedom is most of it
    (held: +0.66 / +0.79 %), a 2 ms prior changes nothing (the data decide them). Measured on this seed."""
    space, _ = _truth_row(as_built)
    rng = np.random.default_rng(3)
    start = np.array([SUV_TRUTH[n] for n in space.names]) * (1 + 0.03 * rng.choice([-1, 1], len(space.names)))
    res = rideid.identify(as_built, start=start, model="base", rng=1)
    errs = {n: res.parameters[n] / v - 1 for n, v in SUV_TRUTH.items()}
    assert max(abs(e) for e in errs.values()) < 0.012, errs
    z = {n: (res.parameters[n] - v) / res.details[n]["std_robust"] for n, v in SUV_TRUTH.items()}
    assert max(abs(v) for v in z.values()) < 2.0, z
    assert res.adequacy["adequate"] is True
    assert res.adequacy["as_built"] == sorted(r[0] for r in RUNS)
    tw = res.tracks["twist_high"]
    assert tw["amplitude_factor"] == pytest.approx(1.04, abs=0.015)
    assert set(tw["runs"]) == {"T_HL", "T_HH"}
    doc = json.loads(json.dumps(res.to_dict()))
    assert 1e-3 < doc["tracks"]["washboard"]["runs"]["W_H"]["unevenness_rms_m"] < 4e-3


def test_as_drawn_keeps_the_drawing_and_a_bad_option_is_refused(as_built):
    with pytest.raises(ArgumentError, match="tracks: expected one of as-built, as-drawn, got 'exact'"):
        rideid.identify(as_built, tracks="exact")


@pytest.mark.slow
def test_rideid_identify_on_tracks_as_built_and_exact(tmp_path, capsys):
    """The command line with its defaults, seed 1: on the tracks as built the twelve within 1 %, at least 10 of 12
    covered, adequate; on the exact drawing no error above 0.5 %.

    The car is linear. On the tracks as drawn ``--model auto`` keeps damper curves (seed 1: a cost 0.6 % below
    the base model's, which the drawing's 4 % leaves in every run), and is still not adequate; the tracks as built
    need a linear car, so the linear part of that pick is fitted on them, is adequate, and is kept
    (rideid.estimate.choice.model_choice._tracks_before_curves). Before that step the result was the curves' fit on the
    drawing, the sprung mass's inertias biased and a parameter 10.6 % off on an earlier tree."""
    truth = {"m_s": 1850.0, **SUV_TRUTH}
    folder = write_dataset(tmp_path / "ab", seed=1)
    assert main(["identify", str(folder), "--out", str(tmp_path / "fit"), "--seed", "1", "--no-report",
                 "--quiet"]) == 0
    doc = json.loads((tmp_path / "fit" / "result.json").read_text())
    p = doc["parameters"]
    assert max(abs(p[n]["value"] / v - 1) for n, v in truth.items()) < 0.01
    assert sum(abs(p[n]["value"] - v) <= 2 * p[n]["std_robust"] for n, v in truth.items()) >= 10
    assert doc["adequacy"]["adequate"] is True
    assert doc["model"]["extensions"] == []
    if doc["model"].get("as_drawn_choice"):  # the curves the drawing asked for, dropped, and the user told
        assert "the drawing, not the car, was what the model missed" in doc["model"]["note"]
    assert doc["tracks"]["twist_high"]["amplitude_factor"] == pytest.approx(1.04, abs=0.015)
    exact = write_dataset(tmp_path / "ex", amplitude=1.0, rms=0.0, seed=1)
    assert main(["identify", str(exact), "--out", str(tmp_path / "fx"), "--seed", "1", "--no-report",
                 "--quiet"]) == 0
    doc = json.loads((tmp_path / "fx" / "result.json").read_text())
    assert max(abs(doc["parameters"][n]["value"] / v - 1) for n, v in truth.items()) < 0.005


def test_a_run_without_a_roll_rate_is_taken_as_drawn(as_built, tmp_path):
    """Without the roll gyro a slow road difference between the wheel paths and the body's roll trade off in the
    free-road fit the as-built prior is estimated from (the SUV's five runs, roll_rate removed: boundary unknowns
    of 4-79 against 0.03-0.1 with it, "unevenness" of 0.2-3.6 m RMS, every track as built rejected), and a run
    whose roll rate is dead carries the same. A run without the roll rate is taken as drawn with a line saying
    why; the others stay as built. A roll rate present but without signal stays as built (a symmetric track in
    simulated data: the plausibility check judges it, as before), and a missing pitch rate changes nothing
    (measured) and is not asked for."""
    import shutil

    from rideid.estimate.fit.anyroad import as_built_runs

    runs, skipped = as_built_runs(as_built, ())
    assert [r.id for r in runs] == [r[0] for r in RUNS] and skipped == {}
    folder = tmp_path / "ds"
    shutil.copytree(as_built.manifest.base_dir, folder)
    for rid, how in (("W_H", "absent"), ("H_HH", "dead"), ("T_HL", "no pitch")):
        f = folder / "runs" / f"{rid}.csv"
        head, *rows = f.read_text().splitlines()
        cols = head.split(",")
        Y = np.array([[float(v) for v in r.split(",")] for r in rows])
        if how == "dead":
            Y[:, cols.index("roll_rate")] = 0.0
        else:
            k = cols.index("roll_rate" if how == "absent" else "pitch_rate")
            Y, cols = np.delete(Y, k, axis=1), cols[:k] + cols[k + 1:]
        np.savetxt(f, Y, delimiter=",", header=",".join(cols), comments="", fmt="%.9e")
    runs, skipped = as_built_runs(rideid.load_dataset(folder), ())
    assert sorted(skipped) == ["W_H"] and [r.id for r in runs] == ["T_HL", "T_HH", "H_HL", "H_HH"]
    assert skipped["W_H"].startswith("as drawn: no roll_rate (without the roll gyro")
