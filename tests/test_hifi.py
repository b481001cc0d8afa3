"""The MuJoCo car (rideid.verify.hifi): an independent multibody model of the same physics."""

import numpy as np
import pytest

pytest.importorskip("mujoco")

from rideid.verify.hifi import HifiProperties, MujocoCar, simulate_mujoco  # noqa: E402
from rideid.model.equations import CHANNEL_KIND, CHANNELS, static_corner_loads  # noqa: E402
from rideid.model.params import CORNERS, as_vector  # noqa: E402
from rideid.model.simulate import prepare_run, simulate_reference  # noqa: E402


def test_static_tire_deflection_is_load_over_stiffness(default_scenario):
    import mujoco
    P, geom = as_vector(default_scenario.truth), default_scenario.geometry
    car = MujocoCar(P, geom)
    m, d = car.model, car.data
    for _ in range(2000):  # 2 s held on level posts: the car must not move from its start
        car.set_road(np.zeros(4), np.zeros(4))
        mujoco.mj_step(m, d)
    loads = car.tire_loads()
    np.testing.assert_allclose(loads, static_corner_loads(P[None], geom)[0], rtol=1e-3)
    for i, c in enumerate(CORNERS):
        wheel = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"wheel_{c}")][2]
        post = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"post_{c}")][2]
        deflection = geom.tire_radius - (wheel - post)
        K = P[10] if c.startswith("f") else P[11]
        assert deflection == pytest.approx(loads[i] / K, rel=1e-3)
    assert abs(d.qpos[0]) < 1e-6  # heave: started in equilibrium (springref preload)


@pytest.mark.parametrize("rid", ["T_LL", "H_LL", "W_L"])
def test_mujoco_matches_the_seven_dof_model(rid, default_scenario):
    """CG at wheel-centre height, no wheel inertia: the same physics, within about 1 %."""
    sc = default_scenario
    P, geom, run = as_vector(sc.truth), sc.geometry, sc.run(rid)
    track = sc.tracks[run.track]
    t = np.arange(int(run.duration * 200) + 1) / 200
    y = simulate_mujoco(P, geom, track, run.speed, t)
    yr = simulate_reference(P[None], geom, prepare_run(track, geom, run.speed, t))[0]
    rms = np.sqrt(np.mean(yr ** 2, axis=0))
    err = np.sqrt(np.mean((y - yr) ** 2, axis=0))
    for i, c in enumerate(CHANNELS):
        same_kind = max(rms[j] for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c])
        if c == "roll_rate" or rms[i] > 1e-3 * same_kind:  # roll on a washboard: zero in both
            assert err[i] < 1e-2 * max(rms[i], 1e-3 * rms[8]), (c, err[i] / rms[i])


def _independent_seven_dof(P, geom, track, speed, t, dt=1e-4):
    """SPEC channels of the 7-DOF car of SPEC §1 assembled here from its equations (not rideid's): mass,
    stiffness and damping matrices of q = [z, theta, phi, z_fl, z_fr, z_rl, z_rr], the rigid-wheel envelope
    as the road, scipy.signal.lsim with the road at ``dt``."""
    from scipy.signal import lsim

    from rideid.model.params import NAMES
    from rideid.model.simulate import corner_inputs
    p = dict(zip(NAMES, P))
    b = geom.wheelbase - p["a"]
    x = np.array([p["a"], p["a"], -b, -b])
    y = np.array([1, -1, 0, 0]) * geom.track_front / 2 + np.array([0, 0, 1, -1]) * geom.track_rear / 2
    per_axle = lambda f, r: np.array([p[f], p[f], p[r], p[r]])  # noqa: E731
    T = np.column_stack([np.ones(4), -x, y])  # body heave at the corners: z - x theta + y phi
    D = np.hstack([-T, np.eye(4)])  # suspension deflection z_i - z_bi
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
    rates[0, 8] = rates[1, 9] = 1.0  # pitch rate, roll rate
    Cy = np.vstack([S @ A[7:], rates])
    Dy = np.vstack([S @ B[7:], np.zeros((2, 4))])
    tf = np.arange(int(round(t[-1] / dt)) + 1) * dt
    _, yf, _ = lsim((A, B, Cy, Dy), corner_inputs(track, geom, speed * tf), tf)
    return yf[np.rint(t / dt).astype(int)]


@pytest.mark.parametrize("rid, amplitude, tol", [("H_LH", 1.0, 3e-4), ("W_H", 1.0, 3e-4), ("T_HL", 0.1, 5e-4)])
def test_mujoco_equals_an_independent_linear_seven_dof(rid, amplitude, tol, default_scenario):
    """The reduced car, noise-free, against the 7-DOF assembled from SPEC §1 alone: every channel within
    0.03 % of the RMS of its kind (accelerations, rates) on the herringbone and the washboard (0.023 % and
    0.010 %; they were 0.26 % and 0.42 % while the soft contact's weightless mass, 0.3 % of m_u, rode on the
    wheels and the posts held their velocity over a step). On the twist the body rolls far enough for the
    small-angle model to miss by 0.28 % (T_HL): with the bumps at a tenth of their height, 0.030 % (0.12 %
    before)."""
    from rideid.model.tracks import Track
    sc = default_scenario
    P, geom, run = as_vector(sc.truth), sc.geometry, sc.run(rid)
    track = sc.tracks[run.track]
    key = "height" if track.kind == "chassis_twist" else "amplitude"
    track = Track(track.id, track.kind, dict(track.keys, **{key: amplitude * track.keys[key]}))
    t = np.arange(int(run.duration * 200) + 1) / 200
    y = simulate_mujoco(P, geom, track, run.speed, t)
    yi = _independent_seven_dof(P, geom, track, run.speed, t)
    rms = np.sqrt(np.mean(yi ** 2, axis=0))
    kind = np.array([CHANNEL_KIND[c] for c in CHANNELS])
    # each channel's error against the RMS of the liveliest channel of its kind (the herringbone hardly
    # pitches the car, the washboard does not roll it)
    scale = np.array([rms[kind == k].max() for k in kind])
    rel = np.sqrt(np.mean((y - yi) ** 2, axis=0)) / scale
    assert np.max(rel) < tol, rel


@pytest.mark.parametrize("raw", [False, True], ids=["spec", "raw"])
def test_simulate_engine_mujoco_from_the_command_line(raw, tmp_path, default_scenario):
    """`rideid simulate --engine mujoco` writes a dataset that the 7-DOF model fits to within 1 %.

    ``--raw``: the sensors' own readings (gravity included, 1 s standing
    still first) go through the measured-data pipeline (channel map, gravity
    removal over the lead-in, start) and arrive at the same data.
    """
    import tomli_w

    import rideid
    from rideid.cli import main
    doc = rideid.data.schema.read_toml(rideid.default_scenario_path())
    doc["runs"] = [r for r in doc["runs"] if r["id"] in ("T_HL", "H_LL")]
    (tmp_path / "sc.toml").write_text(tomli_w.dumps(doc))
    assert main(["simulate", str(tmp_path / "sc.toml"), "--out", str(tmp_path / "ds"), "--engine", "mujoco",
                 "--quiet"] + (["--raw"] if raw else [])) == 0
    if raw:
        head = (tmp_path / "ds" / "runs" / "T_HL.csv").read_text().splitlines()[:2]
        assert head[0].split(",")[1] == "acc_body_fl_z"
        assert float(head[1].split(",")[1]) == pytest.approx(9.80665, abs=1e-6)  # at rest: +g (standard) along z
    ds = rideid.load_dataset(tmp_path / "ds")
    cf = rideid.CostFunction(ds)
    truth = as_vector(default_scenario.truth)
    sims = cf.simulate(truth)
    for r in ds.runs:
        Y = ds.data[r.id].matrix()
        rel = np.sqrt(np.mean((sims[r.id] - Y) ** 2, axis=0)) / np.sqrt(np.mean(Y ** 2, axis=0))
        assert np.nanmax(rel[:9]) < 1e-2, (r.id, rel)


# ---------------------------------------------------------------------------
# linearisation: MuJoCo's car against closed-form linear models

def _linearised_eigenvalues(P, geom, hifi):
    """Eigenvalues of MuJoCo's car linearised about static equilibrium (posts held), by central differences."""
    import mujoco
    car = MujocoCar(P, geom, hifi)
    m, d = car.model, car.data
    dofs = np.setdiff1d(np.arange(m.nv), car._post_v)
    n = dofs.size

    def acc(x):
        d.qpos[:] = 0.0
        d.qvel[:] = 0.0
        d.qpos[car._post_q] = 0.0
        d.qpos[dofs], d.qvel[dofs] = x[:n], x[n:]
        with car.active():
            mujoco.mj_forward(m, d)
        return d.qacc[dofs].copy()

    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    for k in range(2 * n):
        e = np.zeros(2 * n)
        e[k] = 1e-7
        A[n:, k] = (acc(e) - acc(-e)) / 2e-7
    return _sorted_modes(np.linalg.eigvals(A))


def _sorted_modes(lam):
    lam = lam[lam.imag > 0]
    return lam[np.argsort(np.abs(lam))]


def _closed_form_state_space(P, geom, cg_height=0.0, wheel_inertia=0.0, tire_damping=0.0):
    """The 7-DOF model (SPEC §1) plus what a raised CG, wheel inertia and tire damping add, by hand.

    With the CG a height h above the wheel centres, each wheel swings about
    the pitch and roll axes through the CG: its horizontal velocity h·θ' or
    h·φ' adds m_u h² per wheel to I_yy and I_xx. Gravity adds a negative
    (toppling) stiffness -m_s g h to pitch and roll: tilting the body by φ
    lowers each tire's contact by h φ²/2 under its static load and raises
    each wheel by the same, net -(Σ static tire load - Σ m_u g) h φ²/2.
    A thin-disc wheel of spin inertia I_w turns with the body: +4 I_w on
    I_yy, +2 I_w on I_xx. Tire damping: +c_t on each wheel's diagonal.
    Returns the state matrices A (14x14) and B (14x4, per unit road input).
    """
    from rideid.model.equations import mck
    from rideid.model.params import GRAVITY, NAMES
    p = dict(zip(NAMES, P))
    M, C, K, Bf = (x[0].copy() for x in mck(P[None], geom))
    unsprung = 2 * (p["m_uf"] + p["m_ur"])
    M[1, 1] += unsprung * cg_height ** 2 + 4 * wheel_inertia
    M[2, 2] += unsprung * cg_height ** 2 + 2 * wheel_inertia
    K[1, 1] -= p["m_s"] * GRAVITY * cg_height
    K[2, 2] -= p["m_s"] * GRAVITY * cg_height
    C[3:, 3:] += tire_damping * np.eye(4)
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((7, 7)), np.eye(7)], [-Minv @ K, -Minv @ C]])
    B = np.vstack([np.zeros((7, 4)), Minv @ Bf])
    return A, B


def _closed_form_eigenvalues(P, geom, **hifi):
    return _sorted_modes(np.linalg.eigvals(_closed_form_state_space(P, geom, **hifi)[0]))


def test_linearised_frequencies_equal_the_seven_dof_ones(default_scenario):
    """Reduced configuration (CG at wheel-centre height, no wheel inertia): the same seven modes."""
    from rideid.model.equations import state_space
    P, geom = as_vector(default_scenario.truth), default_scenario.geometry
    mj = _linearised_eigenvalues(P, geom, None)
    seven = _sorted_modes(np.linalg.eigvals(state_space(P[None], geom)[0][0]))
    # |lambda| (natural frequency) and damping ratio of every mode, the wheel hop's too (the soft contact's
    # weightless mass taken out of the wheel; it put the hop 0.2-0.3 % off): 1e-8 here
    np.testing.assert_allclose(np.abs(mj), np.abs(seven), rtol=1e-6)
    np.testing.assert_allclose(-mj.real / np.abs(mj), -seven.real / np.abs(seven), rtol=1e-6)
    np.testing.assert_allclose(mj, seven, rtol=1e-6)


def test_raised_cg_wheel_inertia_and_tire_damping_match_closed_form(default_scenario):
    P, geom = as_vector(default_scenario.truth), default_scenario.geometry
    hifi = dict(cg_height=0.27, wheel_inertia=1.2, tire_damping=300.0)
    mj = _linearised_eigenvalues(P, geom, HifiProperties(**hifi))
    np.testing.assert_allclose(np.abs(mj), np.abs(_closed_form_eigenvalues(P, geom, **hifi)), rtol=2e-3)
    # the CG alone, as undamped frequencies: pitch -0.7 %, roll -5.6 % (2.2 % from the wheels' swing
    # inertia, 4.5 % of I_xx; the rest from the toppling stiffness m_s g h)
    base = _closed_form_eigenvalues(P, geom)
    raised = _linearised_eigenvalues(P, geom, HifiProperties(cg_height=0.27))
    drop = np.abs(raised[:3]) / np.abs(base[:3]) - 1  # bounce, pitch, roll for this car
    assert drop[1] == pytest.approx(-0.008, abs=0.002)
    assert drop[2] == pytest.approx(-0.061, abs=0.004)


def _modified_linear_response(P, geom, track, speed, t, cg_height):
    """SPEC channels of the closed-form linear car with a raised CG (scipy.signal.lsim on a 1 ms grid)."""
    from scipy.signal import lsim

    from rideid.model.params import NAMES
    from rideid.model.simulate import corner_inputs
    p = dict(zip(NAMES, P))
    A, B = _closed_form_state_space(P, geom, cg_height=cg_height)
    x, y = geom.corner_xy(p["a"])
    G = np.zeros((10, 7))  # accelerations of the body corners and wheels, in generalised accelerations
    G[:4, 0], G[:4, 1], G[:4, 2] = 1.0, -np.ravel(x), np.ravel(y)
    G[4:8, 3:] = np.eye(4)
    Cy = np.zeros((10, 14))
    Dy = np.zeros((10, 4))
    Cy[:8] = G[:8] @ A[7:]
    Dy[:8] = G[:8] @ B[7:]
    Cy[8, 8] = Cy[9, 9] = 1.0  # pitch rate, roll rate
    tf = np.arange(int(round(t[-1] * 1000)) + 1) / 1000
    _, yf, _ = lsim((A, B, Cy, Dy), corner_inputs(track, geom, speed * tf), tf)
    return yf[::int(round((t[1] - t[0]) * 1000))]


@pytest.mark.parametrize("rid", ["T_LL", "H_LL"])
def test_raised_cg_response(rid, default_scenario):
    """CG 0.27 m above the wheel centres: the 7-DOF roll is within about 5 % on the herringbone (the twist,
    which works roll quasi-statically, feels the toppling stiffness more); the closed-form linear car
    with the raised CG matches MuJoCo within 1 % on every channel."""
    sc = default_scenario
    P, geom, run = as_vector(sc.truth), sc.geometry, sc.run(rid)
    track = sc.tracks[run.track]
    t = np.arange(int(run.duration * 200) + 1) / 200
    y = simulate_mujoco(P, geom, track, run.speed, t, cg_height=0.27)
    y7 = simulate_reference(P[None], geom, prepare_run(track, geom, run.speed, t))[0]
    yc = _modified_linear_response(P, geom, track, run.speed, t, 0.27)

    def rel(a, b):
        return np.sqrt(np.mean((a - b) ** 2, axis=0)) / np.sqrt(np.mean(b ** 2, axis=0))

    assert np.max(rel(y, yc)) < 1e-2, rel(y, yc)
    roll = CHANNELS.index("roll_rate")
    if rid == "H_LL":
        assert rel(y, y7)[roll] < 0.055
    else:
        assert 0.08 < rel(y, y7)[roll] < 0.15  # the twist: about 12 %, the closed form explains it


# ---------------------------------------------------------------------------
# dampers, bump stops, lift-off

def test_damper_curves():
    from rideid.verify.hifi import damper_force
    v = np.array([-0.5, -0.1, 0.1, 0.5])
    # rebound twice compression; the two slopes average to c_s
    f = damper_force(v, 1500.0, rebound_ratio=2.0)
    np.testing.assert_allclose(f, [-1000.0, -200.0, 100.0, 500.0])
    # digressive: continuous at the knee, the slope times 0.4 beyond
    f = damper_force(np.array([0.099999, 0.1, 0.3]), 1500.0, 1.0, 0.1, 0.4)
    np.testing.assert_allclose(f, [149.9985, 150.0, 150.0 + 0.4 * 1500 * 0.2])
    # a symmetric cycle: the first harmonic of the asymmetric damper is c_s (what a linear fit sees)
    ph = np.linspace(0, 2 * np.pi, 4001)[:-1]
    vv = 0.3 * np.sin(ph)
    c_eq = np.mean(damper_force(vv, 1500.0, rebound_ratio=3.0) * np.sin(ph)) / (0.3 * 0.5)
    assert c_eq == pytest.approx(1500.0, rel=1e-6)


def test_damper_callback_equals_mujocos_linear_damper(default_scenario):
    """The passive-force callback (used for damper curves) with a knee out of reach = MuJoCo's joint damping."""
    sc = default_scenario
    P, geom, run = as_vector(sc.truth), sc.geometry, sc.run("H_LL")
    t = np.arange(int(run.duration * 200) + 1) / 200
    track = sc.tracks[run.track]
    lin = simulate_mujoco(P, geom, track, run.speed, t)
    cb = simulate_mujoco(P, geom, track, run.speed, t, damper_knee_velocity=1e9, damper_knee_ratio=0.5)
    assert MujocoCar(P, geom, damper_knee_velocity=1e9, damper_knee_ratio=0.5).needs_callback
    np.testing.assert_allclose(cb, lin, atol=1e-6 * np.abs(lin).max())


def test_bump_stop_limits_compression(default_scenario):
    sc = default_scenario
    P, geom, run = as_vector(sc.truth), sc.geometry, sc.run("T_HL")  # 80 mm twist bumps
    t = np.arange(int(run.duration * 200) + 1) / 200
    track = sc.tracks[run.track]
    free = simulate_mujoco(P, geom, track, run.speed, t, details=True)
    assert free.travel_max.max() > 0.05
    stop = simulate_mujoco(P, geom, track, run.speed, t, details=True, bumpstop_clearance=0.03,
                           bumpstop_rate=2e6)
    # a stiff stop: past the clearance by no more than (spring + stop force)/stop rate, a few mm
    assert 0.03 < stop.travel_max.max() < 0.034
    np.testing.assert_allclose(stop.travel_min, free.travel_min, atol=0.02)  # extension is not stopped


def test_lift_off_exactly_when_the_seven_dof_model_warns(default_scenario):
    """Scale the washboard under wheel hop (W_H) to 2 % either side of the amplitude where the 7-DOF
    tire force first reaches zero: MuJoCo's tire leaves the road only above it, on the same wheels, at
    the same moment."""
    import dataclasses
    import warnings

    from rideid.errors import ModelValidityWarning
    from rideid.synth.scenario import lift_offs
    from rideid.model.tracks import Track
    sc = default_scenario
    P, geom, run = as_vector(sc.truth), sc.geometry, sc.run("W_H")
    t = np.arange(int(run.duration * 200) + 1) / 200
    base = sc.tracks[run.track]

    def track(scale):
        return Track(base.id, base.kind, {**base.keys, "amplitude": base.keys["amplitude"] * scale})

    def seven_dof_force(scale):
        ri = prepare_run(track(scale), geom, run.speed, t)
        _, states = simulate_reference(P[None], geom, ri, return_states=True)
        from rideid.model.simulate import wheel_displacements
        kt = np.array([P[10], P[10], P[11], P[11]])
        return static_corner_loads(P[None], geom)[0] + kt * (ri.u - wheel_displacements(states[0]))

    def seven_dof_min_force(scale):
        return seven_dof_force(scale).min()

    lo, hi = 1.0, 3.0  # bisection for the 7-DOF lift-off amplitude
    assert seven_dof_min_force(lo) > 0 > seven_dof_min_force(hi)
    for _ in range(30):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if seven_dof_min_force(mid) > 0 else (lo, mid)
    critical = lo
    for factor, lifts in ((0.98, False), (1.02, True)):
        tr = track(critical * factor)
        ri = prepare_run(tr, geom, run.speed, t)
        _, states = simulate_reference(P[None], geom, ri, return_states=True)
        warned = lift_offs(P, geom, run.id, ri, states[0])
        mj = simulate_mujoco(P, geom, tr, run.speed, t, details=True)
        assert bool(warned) is lifts
        assert bool(np.isfinite(mj.lift_time).any()) is lifts
        if lifts:
            assert sorted(w.wheel for w in warned) == [c for k, c in enumerate(CORNERS)
                                                       if np.isfinite(mj.lift_time[k])]
            force = seven_dof_force(critical * factor)
            for w in warned:
                k = CORNERS.index(w.wheel)
                first = t[np.argmax(force[:, k] < 0)]  # the 7-DOF tire force first below zero
                assert mj.lift_time[k] == pytest.approx(first, abs=0.006)
        else:
            assert mj.tire_load_min.min() > 0
    # and `simulate_manifest` with the MuJoCo engine warns from MuJoCo's own contact
    from rideid.synth.scenario import simulate_manifest
    sc2 = dataclasses.replace(sc, runs=[run], tracks={base.id: track(critical * 1.02)})
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        _, lifts = simulate_manifest(sc2, engine="mujoco")
    assert lifts and all(lo.engine == "mujoco" for lo in lifts)
    assert any(issubclass(r.category, ModelValidityWarning) and "MuJoCo" in str(r.message) for r in rec)


# ---------------------------------------------------------------------------
# the [hifi] table

def test_hifi_table_parses_and_round_trips():
    from rideid.verify.hifi import parse_hifi
    h = parse_hifi({"cg_height": 0.25, "wheel_inertia": [1.1, 0.9], "damper_rebound_ratio": 2,
                    "bumpstop_clearance": 0.05, "bumpstop_rate": 5e4}, "sc.toml: [hifi]")
    assert h.wheel_inertia == (1.1, 0.9) and h.damper_rebound_ratio == (2.0, 2.0)
    assert h.bumpstops and not h.linear_dampers
    assert parse_hifi(h.to_table(), "x") == h
    assert HifiProperties().describe().startswith("reduced configuration")


@pytest.mark.parametrize("tab, msg", [
    ({"cg_hieght": 0.2}, "sc.toml: [hifi]: unknown key 'cg_hieght'; allowed: cg_height"),
    ({"wheel_inertia": [1, 2, 3]}, "sc.toml: [hifi] wheel_inertia: expected one number or [front, rear]"),
    ({"tire_damping": -5}, "sc.toml: [hifi] tire_damping: expected a finite non-negative number"),
    ({"damper_rebound_ratio": 0}, "sc.toml: [hifi] damper_rebound_ratio: expected a positive finite ratio"),
    ({"cg_height": "high"}, "sc.toml: [hifi] cg_height: expected a number, got 'high'"),
    ({"cg_height": -0.4}, "sc.toml: [hifi] cg_height: a CG 0.4 m below the wheel centres is under the road"),
])
def test_hifi_table_errors_name_the_key(tab, msg, tmp_path, capsys):
    import tomli_w

    import rideid
    from rideid.cli import main
    doc = rideid.data.schema.read_toml(rideid.default_scenario_path())
    doc["hifi"] = tab
    doc["runs"] = doc["runs"][:1]
    (tmp_path / "sc.toml").write_text(tomli_w.dumps(doc))
    assert main(["simulate", str(tmp_path / "sc.toml"), "--out", str(tmp_path / "ds"), "--engine", "mujoco",
                 "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err
    assert not (tmp_path / "ds").exists()


def test_raw_needs_the_mujoco_engine(tmp_path, capsys):
    import rideid
    from rideid.cli import main
    assert main(["simulate", str(rideid.default_scenario_path()), "--out", str(tmp_path / "ds"), "--raw",
                 "--quiet"]) == 2
    assert "--raw needs --engine mujoco" in capsys.readouterr().err


@pytest.mark.slow
def test_verification_study(tmp_path):
    """`make verify`'s key rows (about 2 minutes alone): the reduced MuJoCo car, and the car with anti-roll
    bars and tire damping identified with the base model, the full model and ``--model auto``."""
    import io
    import json

    import benchmark_module
    mod = benchmark_module.load("verify_mujoco")
    labels = [c[0] for c in mod.CONFIGS]
    i_red, i_ext = labels.index("reduced (7-DOF physics)"), labels.index("bars + tire damping")
    assert mod.main(["--only", str(i_red), str(i_ext), "--out", str(tmp_path)], out=io.StringIO()) == 0
    check_verification_rows(json.loads((tmp_path / "verification.json").read_text()), labels[i_red], labels[i_ext])
    assert (tmp_path / "verification.md").read_text().startswith("| configuration |")


def check_verification_rows(rows, reduced_label, extended_label):
    """The findings docs/verification.md states for these two rows (1 % white noise, seed 1)."""
    rows = {r["config"]: r["fits"] for r in rows}
    reduced, ext = rows[reduced_label], rows[extended_label]
    # the 7-DOF physics in another engine: every model recovers the twelve within 0.15 % (0.10-0.12 %, the
    # twist runs' second-order kinematics; 0.37-0.40 % while the contact's weightless mass rode on the
    # wheels), auto keeps the base model, and the residuals are adequate; +-2 std_robust covers 6 of 11
    # (2-3 then)
    for m in ("base", "full", "auto"):
        assert reduced[m]["largest_error_pct"] < 0.15, m
    assert reduced["auto"]["extensions"] == []
    assert reduced["base"]["adequate"] is True
    assert reduced["base"]["covered_std_robust"] >= 5
    # bars (15/6 kN/m) and tire damping (150 N s/m): the full model removes the bias (twelve within 0.15 %,
    # the four extensions within 1 %; measured 0.10 % and 0.35 %), auto picks exactly both groups, the fit
    # is adequate ...
    full = ext["full"]
    assert full["largest_error_pct"] < 0.15
    for n, v in full["extension_values"].items():
        assert v["estimate"] == pytest.approx(v["truth"], rel=0.01), n
    assert sorted(ext["auto"]["extensions"]) == ["anti_roll_bars", "tire_damping"]
    # auto reaches the same model's fit by another path: the same end to the polish's own (a Gauss-Newton step
    # under 0.05 std from it, rideid.estimate.fit.polish.Progress): 0.1040022 against 0.1040055 %
    assert ext["auto"]["largest_error_pct"] == pytest.approx(full["largest_error_pct"], abs=1e-4)
    assert full["adequate"] is True
    # ... while the base model is biased by far more than that (springs > 20 %, unsprung masses > 10 %),
    # its residuals are flagged, and the sandwich's error bars do not cover the bias (model structure, not
    # noise). The runs disagree about such a car (each track bends the missing bars into other parameters
    # differently): the delete-one-run jackknife finds a between-runs share in most parameters, which widens
    # std_robust (measured, seed 1: 5 of 11 then cover, the sandwich's share alone 1 of 11); the verdict says
    # not adequate, so those numbers are not offered as trustworthy
    base = ext["base"]
    assert base["error_pct"]["k_sf"] > 20 and base["error_pct"]["k_sr"] > 15
    assert base["error_pct"]["m_uf"] < -10 and base["error_pct"]["m_ur"] < -10
    assert base["adequate"] is False
    assert base["covered_std_hac"] <= 2 and base["estimated"] == 11
    assert base["between_runs"] >= 8 and base["covered_std_robust"] < base["estimated"]
