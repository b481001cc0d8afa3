"""The nonlinear car (SPEC §8): integration error on every track kind, the two backends,
closed-form and cross checks against the linear kernel."""

import warnings

import numpy as np
import pytest

from rideid.model import backend, kernel_nl
from rideid.model import nonlinear as nl
from rideid.model.batch import BatchSimulator
from rideid.model.equations import CHANNELS, static_corner_loads
from rideid.model.nonlinear import (DEFAULT_KNOTS, NonlinearLayout, NonlinearSimulator, damper_force,
                                    linear_curve, simulate_nonlinear)
from rideid.model.simulator import make_simulator
from rideid.verify.hifi import hifi_curve
from rideid.model.params import DEFAULT_CAR, DEFAULT_GEOMETRY, GRAVITY, INDEX, Geometry, SUSPENSION_NAMES, as_vector
from rideid.model.simulate import prepare_run, simulate_reference
from rideid.data.schema.tracks import track_from_table

from cars import bump_tracks, write_profile_road

G0 = DEFAULT_GEOMETRY
GH = Geometry(G0.wheelbase, G0.track_front, G0.track_rear, G0.tire_radius, cg_height=0.25)
FS = 200.0
CAR = {**DEFAULT_CAR, "k_arf": 9000.0, "k_arr": 4000.0, "c_tf": 150.0, "c_tr": 120.0}
FULL = NonlinearLayout(knots=DEFAULT_KNOTS, bump_stops=True)

# severe runs: every one reaches the bump stops and lifts a wheel (checked)
TRACKS = {
    **bump_tracks(0.011, wavelength=0.7, height=0.07, bump_length=1.2, spacing=3.0, twist_speed=6.0),
    "profile": (dict(id="p", kind="profile", file="road.csv"), 8.0),
    "flat": (dict(id="f", kind="flat"), 8.0),
}


def nasty_row(P16=None):
    """Asymmetric digressive dampers (2:1 and 1.6:1, knee 0.1 m/s), bars, tire damping, bump stops."""
    P16 = as_vector(CAR, extended=True)[:16] if P16 is None else P16
    Ff = hifi_curve(CAR["c_sf"], DEFAULT_KNOTS, 2.0, 0.1, 0.4)
    Fr = hifi_curve(CAR["c_sr"], DEFAULT_KNOTS, 1.6, 0.1, 0.5)
    return np.concatenate([P16, [0.02, 0.025, 60000.0, 50000.0], Ff, Fr])


@pytest.fixture(scope="module")
def road_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("road")
    write_profile_road(d, 0.03, 0.012)
    return d


def make_run(kind, road_dir, geom=GH, duration=2.5, scale=1.0):
    table, V = TRACKS[kind]
    table = dict(table)
    for k in ("amplitude", "height"):
        if k in table:
            table[k] *= scale
    tr = track_from_table(table, "t", base_dir=road_dir)
    return prepare_run(tr, geom, V, np.arange(int(duration * FS) + 1) / FS)


def compiled(P, geom, run, layout, m):
    co, xk, Fk, Sk = nl.coefficients(P, geom, layout)
    X0 = nl.shifted(co, nl.initial_state(P, geom, layout, run.u[0]), run.u[0])[None]
    _, out, _ = kernel_nl.run(co, xk, Fk, Sk, layout.knots is not None, X0, np.array([0, run.n]), [run.h],
                              np.array([m]), [nl.fine_inputs(run, m)], np.zeros((run.n, 10)), np.zeros((1, 10)), 1)
    return out


def rel_rms(y, ref):
    rms = np.sqrt(np.mean(ref ** 2, axis=-2))
    err = np.sqrt(np.mean((y - ref) ** 2, axis=-2))
    ok = rms > 1e-9 * rms.max()
    return np.where(ok, err / np.where(ok, rms, 1), 0.0)


def deflections(P, geom, states):
    q = states[..., :7]
    x, y = geom.corner_xy(P[..., INDEX["a"]])
    zb = q[..., :1] - x[:, None] * q[..., 1:2] + y[:, None] * q[..., 2:3]
    return q[..., 3:] - zb


@pytest.mark.parametrize("kind", list(TRACKS))
def test_integration_error_every_track_kind(kind, road_dir):
    """Sub-steps chosen by the simulator (RK4 split at the kinks) against the same at 64x the sub-steps:
    < 1e-4 of every channel's RMS, on runs that reach the bump stops and lift wheels off the road."""
    run = make_run(kind, road_dir)
    P = nasty_row()[None]
    sim = NonlinearSimulator(GH, [run], FULL)
    y = sim.outputs(P)[0]
    m = sim.substeps(P)[0]
    if kind == "flat":
        assert np.all(y == 0)
        return
    ref = compiled(P, GH, run, FULL, 64 * m)
    err = rel_rms(y[0], ref[0])
    print(kind, "m", m, "error", err.max())
    assert err.max() < 1e-4, dict(zip(CHANNELS, err))
    # the run is as severe as claimed: a bump stop reached and a wheel off the road
    _, X = simulate_nonlinear(P, GH, run, FULL, return_states=True)
    d = deflections(P, GH, X)[0]
    assert np.any(d[:, :2] > 0.02) or np.any(d[:, 2:] > 0.025)
    kt = np.array([CAR["k_tf"]] * 2 + [CAR["k_tr"]] * 2)
    ct = np.array([CAR["c_tf"]] * 2 + [CAR["c_tr"]] * 2)
    tire = static_corner_loads(P[:, :16], GH)[0] + kt * (run.u - X[0, :, 3:7]) + ct * (run.rate - X[0, :, 10:])
    assert np.any(tire < 0)



def _road(run):
    """The run's road input and rate as a function of time: the envelope model tabulated at 10 us (0.06 mm of
    travel, finer than the envelope's own 0.5 mm grid), interpolated linearly (one cell lookup for the eight
    columns)."""
    tt = np.arange(0.0, run.t[-1] + 1e-4, 1e-5)
    table = np.concatenate(run.inputs_at(tt), axis=1)  # (n, 8): the four inputs, then their rates
    step = np.diff(table, axis=0)

    def at(t):
        j = min(max(int(t / 1e-5), 0), tt.size - 2)
        w = (t - tt[j]) / (tt[j + 1] - tt[j])
        row = table[j] + w * step[j]
        return row[:4], row[4:]
    return at


def _rhs_physical(P, geom, run):
    """The equations of SPEC §1/§6/§8 written out again, unshifted states, one candidate (for solve_ivp): the
    right-hand side ``(t, X) -> (dX/dt, accelerations)``, its constants computed once."""
    p = dict(zip(FULL.names, P))
    h = geom.cg_height
    a, b = p["a"], geom.wheelbase - p["a"]
    xs = np.array([a, a, -b, -b])
    ys = np.array(geom.corner_y)
    road = _road(run)
    ks = np.array([p["k_sf"]] * 2 + [p["k_sr"]] * 2)
    kt = np.array([p["k_tf"]] * 2 + [p["k_tr"]] * 2)
    ct = np.array([p["c_tf"]] * 2 + [p["c_tr"]] * 2)
    mu = np.array([p["m_uf"]] * 2 + [p["m_ur"]] * 2)
    kn = np.array(DEFAULT_KNOTS)
    xk = np.concatenate([kn[:5], [0.0], kn[5:]])
    Fk = [np.concatenate([[p[f"F_{s}{j + 1}"] for j in range(5)], [0.0],
                          [p[f"F_{s}{j + 1}"] for j in range(5, len(DEFAULT_KNOTS))]]) for s in "fr"]
    slopes = [np.diff(F) / np.diff(xk) for F in Fk]
    clear = np.array([p["bs_clear_f"]] * 2 + [p["bs_clear_r"]] * 2)
    rate = np.array([p["bs_rate_f"]] * 2 + [p["bs_rate_r"]] * 2)
    L = np.array([p["m_s"] * GRAVITY * b / geom.wheelbase / 2 + p["m_uf"] * GRAVITY] * 2
                 + [p["m_s"] * GRAVITY * a / geom.wheelbase / 2 + p["m_ur"] * GRAVITY] * 2)
    mw = 2 * (p["m_uf"] + p["m_ur"]) * h * h
    Iyy, Ixx, ms, kaf, kar = p["I_yy"] + mw, p["I_xx"] + mw, p["m_s"], p["k_arf"], p["k_arr"]

    def curve(axle, vv):
        j = min(max(int(np.searchsorted(xk, vv)) - 1, 0), xk.size - 2)
        return Fk[axle][j] + slopes[axle][j] * (vv - xk[j])

    def rhs(t, X):
        u, ud = road(t)
        q, qd = X[:7], X[7:]
        d = q[3:] - (q[0] - xs * q[1] + ys * q[2])
        v = qd[3:] - (qd[0] - xs * qd[1] + ys * qd[2])
        damp = np.array([curve(0, v[0]), curve(0, v[1]), curve(1, v[2]), curve(1, v[3])])
        bars = np.array([kaf * (d[0] - d[1]), kaf * (d[1] - d[0]), kar * (d[2] - d[3]), kar * (d[3] - d[2])])
        F = ks * d + bars + damp + rate * np.maximum(d - clear, 0)
        T = np.maximum(L + kt * (u - q[3:]) + ct * (ud - qd[3:]), 0) - L
        qdd = np.concatenate([[F.sum() / ms, (-(xs * F).sum() + ms * GRAVITY * h * q[1]) / Iyy,
                               ((ys * F).sum() + ms * GRAVITY * h * q[2]) / Ixx], (T - F) / mu])
        return np.concatenate([qd, qdd]), qdd
    return rhs


@pytest.mark.slow
def test_matches_scipy_dop853(road_dir):
    """An independent integrator (DOP853, rtol 1e-10) on independently written equations (the kinks keep DOP853's
    steps short: 0.2 million right-hand sides, 13 s on one core since they are computed once per car and the road
    is one table lookup, 755 s in CI's slow pass before; measured 1.0e-5 of RMS at 3 sub-steps split at the kinks)."""
    from scipy.integrate import solve_ivp

    run = make_run("chassis_twist", road_dir, duration=1.2)
    P = nasty_row()
    y = simulate_nonlinear(P, GH, run, FULL)[0]
    rhs = _rhs_physical(P, GH, run)
    sol = solve_ivp(lambda t, X: rhs(t, X)[0], (0, run.t[-1]), np.zeros(14),
                    method="DOP853", t_eval=run.t, rtol=1e-10, atol=1e-12, max_step=run.h)
    ref = np.empty_like(y)
    x, yy = GH.corner_xy(np.array([P[INDEX["a"]]]))
    for k, t in enumerate(run.t):
        _, qdd = rhs(t, sol.y[:, k])
        ref[k, :4] = qdd[0] - x[0] * qdd[1] + yy[0] * qdd[2]
        ref[k, 4:8] = qdd[3:]
        ref[k, 8:] = sol.y[8:10, k]
    err = rel_rms(y, ref)
    print("DOP853 error", err.max())
    assert err.max() < 1e-4, dict(zip(CHANNELS, err))


def population(n, seed=0):
    rng = np.random.default_rng(seed)
    base = nasty_row()
    P = base * rng.uniform(0.85, 1.15, size=(n, base.size))
    P[:, INDEX["a"]] = base[INDEX["a"]] * rng.uniform(0.95, 1.05, n)
    return P


@pytest.mark.slow  # three NumPy references of three cars: CI's slow pass runs it (six cars took 328 s there)
def test_backends_agree(road_dir, monkeypatch):
    runs = [make_run("herringbone", road_dir, duration=1.5), make_run("chassis_twist", road_dir, duration=1.5)]
    P = population(3)
    sim = NonlinearSimulator(GH, runs, FULL)
    fast = sim.outputs(P)
    ref = sim.outputs_reference(P)
    for a, b in zip(fast, ref):
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    Y = np.concatenate([r[0] for r in ref]) * 1.01
    W = np.ones((2, 10))
    e1, e2 = sim.errors(P, Y, W), sim.errors_reference(P, Y, W)
    np.testing.assert_allclose(e1, e2, rtol=1e-9)
    monkeypatch.setenv("RIDEID_KERNEL", "numpy")
    np.testing.assert_allclose(sim.errors(P, Y, W), e2, rtol=1e-12)
    lin = BatchSimulator(G0, runs)
    Pl = P[:, :16]
    Yl = np.concatenate([r[0] for r in lin.outputs_reference(Pl)])
    np.testing.assert_allclose(lin.errors(Pl, Yl, W), lin.errors_reference(Pl, Yl, W), rtol=1e-12, atol=1e-20)
    monkeypatch.setenv("RIDEID_KERNEL", "fortran")
    with pytest.raises(Exception, match="RIDEID_KERNEL"):
        sim.errors(P, Y, W)


def test_compiled_states_equal_the_numpy_states(road_dir):
    """The kernel's states (mode 2: the suspension travels and velocities behind bump-stop reach and knot
    excitation) are the NumPy backend's, split at the kinks or plain RK4, and its channels come with them. The runs
    are 0.3 s, each long enough to cross kinks (split and plain RK4 differ by 5e-5 to 3e-4 of the states; the NumPy
    backend splits step by step in Python: 4 s here, 11 s on 0.4 s runs)."""
    runs = [make_run("herringbone", road_dir, duration=0.3), make_run("chassis_twist", road_dir, duration=0.3)]
    P = population(2, seed=3)
    split, plain = (NonlinearSimulator(GH, runs, FULL, split=s).states(P) for s in (True, False))
    assert all(np.abs(a[1] - b[1]).max() > 1e-5 * np.abs(b[1]).max() for a, b in zip(split, plain))
    for kw in ({}, {"rho": 0.2}, {"rho": 0.1, "split": False}):
        sim = NonlinearSimulator(GH, runs, FULL, **kw)
        fast, ref = sim.states(P), sim.states_reference(P)
        for (y, X), (y_ref, X_ref), out in zip(fast, ref, sim.outputs(P)):
            assert X.shape == X_ref.shape == (2, y.shape[1], 14)
            assert np.abs(X - X_ref).max() <= 1e-10 * np.abs(X_ref).max()
            np.testing.assert_array_equal(y, out)
            assert np.abs(y - y_ref).max() <= 1e-10 * np.abs(y_ref).max()


def test_suspension_travel_closed_form_and_its_rate(road_dir):
    """The body over its corners is the rigid plate's (heave, pitch nose-down forward of the CG as the
    model's x, roll up on the left); the travel of the velocities is the time derivative of the travel
    of the positions on a simulated run: each sample step's change is the trapezoid of the velocities
    (1.6 % of the largest velocity at 200 Hz on this run's 12 Hz wheel hop; a wrong sign or column
    is off by 100 % and more)."""
    x, y = GH.corner_xy(np.array([CAR["a"]]))
    x, y = x[0], y[0]
    q = np.zeros((3, 7))
    q[0, 0] = 0.02                           # heave up: every corner extends by 2 cm
    q[1, 1] = 0.01                           # pitch: the corners move by -x theta
    q[2, 2], q[2, 3:] = 0.01, 0.005          # roll, wheels up 5 mm
    t = nl.suspension_travel(q, x, y)
    np.testing.assert_allclose(t[0], [-0.02] * 4)
    np.testing.assert_allclose(t[1], 0.01 * x)
    np.testing.assert_allclose(t[2], 0.005 - 0.01 * y)
    assert t[1, 0] == t[1, 1] > 0 > t[1, 2] == t[1, 3]   # front compresses, rear extends
    assert t[2, 0] < 0.005 < t[2, 1] and t[2, 2] < 0.005 < t[2, 3]   # left extends, right compresses
    sim = NonlinearSimulator(GH, [make_run("herringbone", road_dir, duration=1.0)], FULL, rho=0.2)
    P = population(1, seed=5)
    d = nl.travel_by_run(sim, P, float(P[0, INDEX["a"]]))[0]
    v = nl.travel_by_run(sim, P, float(P[0, INDEX["a"]]), rates=True)[0]
    h = sim.runs[0].h
    step = (d[1:] - d[:-1]) / h
    assert np.abs(step - 0.5 * (v[1:] + v[:-1])).max() < 0.03 * np.abs(v).max()
    assert np.abs(v).max() > 0.05           # the run moves the suspension


def test_compile_failure_falls_back_with_one_warning(road_dir, monkeypatch):
    run = make_run("chassis_twist", road_dir, duration=0.5)
    monkeypatch.setattr(backend, "_STATUS", {})
    monkeypatch.setattr(backend, "_WARNED", False)

    def broken(name):
        raise RuntimeError("no compiler")

    monkeypatch.setattr(backend, "module", broken)
    P = nasty_row()[None]
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        sim = NonlinearSimulator(GH, [run], FULL)
        y1 = sim.outputs(P)[0]
        sim.outputs(P)
        BatchSimulator(G0, [run]).outputs(P[:, :16])
    assert len([x for x in w if "could not be built" in str(x.message)]) == 1
    np.testing.assert_array_equal(y1, sim.outputs_reference(P)[0])


def test_linear_curves_equal_the_linear_kernel(road_dir):
    """F = c v, no bump stops, no lift-off: the RK4 car equals the exact discretisation (two methods)."""
    layout = NonlinearLayout(knots=DEFAULT_KNOTS)
    P16 = as_vector(CAR, extended=True)[:16]
    P = np.concatenate([P16, linear_curve(CAR["c_sf"]), linear_curve(CAR["c_sr"])])[None]
    for kind in ("washboard", "herringbone", "chassis_twist"):
        run = make_run(kind, road_dir, scale=0.3)
        y = NonlinearSimulator(GH, [run], layout).outputs(P)[0][0]
        ref = simulate_reference(P16[None], GH, run)[0]
        _, X = simulate_nonlinear(P, GH, run, layout, return_states=True)
        tire = (static_corner_loads(P16[None], GH)[0] + P16[10] * (run.u - X[0, :, 3:7])
                + P16[14] * (run.rate - X[0, :, 10:]))
        assert tire.min() > 0  # no lift-off
        assert rel_rms(y, ref).max() < 1e-4, (kind, rel_rms(y, ref))
    # linear dampers from the row (no curves), lift-off out of reach
    y2 = NonlinearSimulator(GH, [run], NonlinearLayout()).outputs(P16[None])[0][0]
    assert rel_rms(y2, ref).max() < 1e-4


def test_symmetric_car_on_symmetric_track_does_not_roll(road_dir):
    run = make_run("washboard", road_dir)
    y = NonlinearSimulator(GH, [run], FULL).outputs(nasty_row()[None])[0][0]
    assert np.abs(y[:, CHANNELS.index("roll_rate")]).max() == 0
    np.testing.assert_array_equal(y[:, 0], y[:, 1])
    assert np.abs(y[:, 0]).max() > 1


def test_scale_invariance(road_dir):
    """Masses, inertias, stiffnesses, damping, forces x 3 (CG height 0): the same accelerations."""
    run = make_run("herringbone", road_dir, geom=G0)
    P = nasty_row()
    Q = P * 3.0
    Q[INDEX["a"]] = P[INDEX["a"]]
    i = FULL.column
    Q[i["bs_clear_f"]], Q[i["bs_clear_r"]] = P[i["bs_clear_f"]], P[i["bs_clear_r"]]
    sim = NonlinearSimulator(G0, [run], FULL)
    y = sim.outputs(np.stack([P, Q]))[0]
    assert np.abs(y[0] - y[1]).max() <= 1e-9 * np.abs(y[0]).max()


def test_stiff_bump_stop_holds(road_dir):
    """A very stiff stop: the compression beyond the clearance stays below F / rate, F the largest stop force
    an impact could bring (ten times the car's weight); ten times the rate, about sqrt(10) less (an impact)."""
    run = make_run("chassis_twist", road_dir, geom=G0, duration=1.0)
    i = FULL.column
    total = (CAR["m_s"] + 2 * CAR["m_uf"] + 2 * CAR["m_ur"]) * GRAVITY
    overs = []
    for rate in (1e6, 1e7):
        P = nasty_row()
        P[i["bs_rate_f"]] = P[i["bs_rate_r"]] = rate
        y, X = simulate_nonlinear(P[None], G0, run, FULL, return_states=True)
        d = deflections(P[None], G0, X)[0]
        clear = np.array([P[i["bs_clear_f"]]] * 2 + [P[i["bs_clear_r"]]] * 2)
        over = (d - clear).max()
        assert 0 < over < 10 * total / rate
        assert np.all(np.isfinite(y))
        overs.append(over)
    assert overs[1] < overs[0] / 2.5


def test_damper_force_curves():
    v = np.linspace(-1.5, 1.5, 3001)
    for reb, knee, kr in ((1.0, np.inf, 1.0), (2.0, 0.1, 0.4), (0.5, 0.2, 0.3)):
        F = hifi_curve(2000.0, DEFAULT_KNOTS, reb, knee, kr)
        from rideid.verify.hifi import damper_force as hifi_damper
        np.testing.assert_allclose(damper_force(DEFAULT_KNOTS, F, v), hifi_damper(v, 2000.0, reb, knee, kr),
                                   rtol=1e-12, atol=1e-9)
    # batched forces, beyond the knots the last slope, through (0, 0)
    F = np.stack([linear_curve(1000.0), linear_curve(3000.0)])
    out = damper_force(DEFAULT_KNOTS, F, np.array([[0.0], [0.7]]))
    np.testing.assert_allclose(out, [[0.0, 0.0], [700.0, 2100.0]])


def test_layout_and_factory(road_dir):
    lay = NonlinearLayout(knots=(-0.2, 0.1, 0.3), bump_stops=True)
    assert lay.names == SUSPENSION_NAMES + ("bs_clear_f", "bs_clear_r", "bs_rate_f", "bs_rate_r",
                                     "F_f1", "F_f2", "F_f3", "F_r1", "F_r2", "F_r3")
    assert lay.n_columns == 26 and not lay.linear and NonlinearLayout().linear
    with pytest.raises(Exception, match="knots"):
        NonlinearLayout(knots=(0.1, 0.0))
    run = make_run("chassis_twist", road_dir, duration=0.5)
    assert isinstance(make_simulator(GH, [run]), BatchSimulator)
    assert isinstance(make_simulator(GH, [run], NonlinearLayout()), BatchSimulator)
    assert isinstance(make_simulator(GH, [run], lay), NonlinearSimulator)
    with pytest.raises(Exception, match="26 columns"):
        make_simulator(GH, [run], lay).outputs(np.zeros((1, 16)))


def test_split_scheme_cost_is_smooth_in_the_parameters(road_dir):
    """Sub-steps split where a kink is crossed: the cost stays a smooth function of the parameters (a crossing
    that leaves a sub-step makes its piece vanish), as the polish's finite differences need."""
    run = make_run("herringbone", road_dir, duration=1.5)
    base = nasty_row()
    sim = NonlinearSimulator(GH, [run], FULL)
    Y = sim.outputs(population(1, seed=3))[0][0]
    W = np.ones((1, 10))
    t = np.linspace(-1.0, 1.0, 41) * 1e-4
    for col in (INDEX["k_sf"], FULL.column["F_f8"], FULL.column["bs_clear_r"]):
        Q = np.repeat(base[None], t.size, 0)
        Q[:, col] *= 1.0 + t
        e = sim.errors(Q, Y, W)[0]
        resid = e - np.polyval(np.polyfit(t, e, 3), t)
        print(FULL.names[col], np.abs(resid).max() / e.mean())
        assert np.abs(resid).max() < 1e-8 * e.mean()


def test_kink_mask_marks_only_the_knots_where_the_slope_changes():
    """A digressive curve bends at its knee and at 0 (rebound 2:1), not at the knots below and above the knee;
    the outermost knots never split; one mask for the population (a knot bent for any candidate)."""
    co, xk, Fk, Sk = nl.coefficients(nasty_row()[None], GH, FULL)
    mask = nl.kink_mask(Sk)
    assert [float(x) for x in xk[mask[0] == 1]] == [-0.1, 0.0, 0.1]
    assert np.array_equal(mask[0], mask[1])
    lin = NonlinearLayout(knots=DEFAULT_KNOTS)
    P16 = as_vector(CAR, extended=True)[:16]
    P = np.stack([np.concatenate([P16, linear_curve(CAR["c_sf"]), linear_curve(CAR["c_sr"])])] * 2)
    assert not nl.kink_mask(nl.coefficients(P, GH, lin)[3]).any()
    P[1, -3] *= 1.01  # the rear curve's third-last knot force: the knots either side of it bend
    mask = nl.kink_mask(nl.coefficients(P, GH, lin)[3])
    assert not mask[0].any() and [float(x) for x in xk[mask[1] == 1]] == [0.05, 0.1, 0.2]


def test_each_candidates_substeps_in_one_batch_equal_one_by_one():
    """substeps_each (one batched eigenvalue problem) gives every candidate the count substeps gives it
    alone, and the population's count is their largest, at two sample rates; stiffer tires need more."""
    from rideid.model.simulator import Simulator

    lay = NonlinearLayout(knots=tuple(DEFAULT_KNOTS), bump_stops=True)
    rng = np.random.default_rng(1)
    P = np.repeat(Simulator(lay).row(as_vector(DEFAULT_CAR)), 12, 0)
    P[:, INDEX["k_tf"]] *= np.geomspace(1.0, 30.0, 12)
    P *= 1 + 0.1 * rng.random(P.shape)
    for h in (1 / 200, 1 / 100):
        each = nl.substeps_each(P, DEFAULT_GEOMETRY, lay, [h])
        alone = [nl.substeps(P[i:i + 1], DEFAULT_GEOMETRY, lay, h) for i in range(len(P))]
        assert each.tolist() == alone and nl.substeps(P, DEFAULT_GEOMETRY, lay, h) == max(alone)
        assert alone[-1] > alone[0]
    both = nl.substeps_each(P, DEFAULT_GEOMETRY, lay, [1 / 200, 1 / 100])
    assert both.tolist() == nl.substeps_each(P, DEFAULT_GEOMETRY, lay, [1 / 100]).tolist()
