"""Closed-form checks of the 7-DOF model."""

import numpy as np
import pytest
import scipy.linalg

from rideid.model.equations import (blocks, decomposed_mck, mck, modal_summary, output_map, state_space,
                                    static_corner_loads)
from rideid.model.params import DEFAULT_CAR, DEFAULT_GEOMETRY, GRAVITY, INDEX, NAMES, Geometry, as_vector, total_mass

G = DEFAULT_GEOMETRY
P0 = as_vector(DEFAULT_CAR)


def quarter_car_freqs(ms, mu, ks, kt):
    """Undamped 2-DOF quarter-car frequencies (Hz), closed form."""
    a = ms * mu
    b = -(ks * mu + (ks + kt) * ms)
    c = ks * kt
    disc = np.sqrt(b * b - 4 * a * c)
    w2 = np.array([(-b - disc) / (2 * a), (-b + disc) / (2 * a)])
    return np.sqrt(w2) / (2 * np.pi)


def undamped(P, geom):
    M, C, K, _ = mck(P[None], geom)
    w2 = scipy.linalg.eigh(K[0], M[0], eigvals_only=True)
    return np.sort(np.sqrt(w2)) / (2 * np.pi)


def assert_blocks_have_the_full_eigenvalues(P, G):
    """The symmetric and antisymmetric blocks together have the full 14-state model's eigenvalues."""
    A, *_ = state_space(P, G)
    bl = blocks(P, G)
    for i in range(len(A)):
        full = np.sort_complex(np.linalg.eigvals(A[i]))
        parts = np.sort_complex(np.concatenate([np.linalg.eigvals(bl["As"][i]), np.linalg.eigvals(bl["Aa"][i])]))
        np.testing.assert_allclose(full, parts, rtol=1e-9, atol=1e-9)


def test_symmetric_block_splits_into_front_and_rear_quarter_cars():
    # with dynamic index I_yy = m_s a b the body is two point masses over the
    # axles: the symmetric block is then two independent quarter cars
    P = P0.copy()
    a, L = P[INDEX["a"]], G.wheelbase
    b = L - a
    P[INDEX["I_yy"]] = P[0] * a * b
    M, C, K, _ = decomposed_mck(P[None], G)
    s = np.arange(4)
    w2 = scipy.linalg.eigh(K[0][np.ix_(s, s)], M[0][np.ix_(s, s)], eigvals_only=True)
    f = np.sort(np.sqrt(w2) / (2 * np.pi))
    front = quarter_car_freqs(P[0] * b / L / 2, P[INDEX["m_uf"]], P[INDEX["k_sf"]], P[INDEX["k_tf"]])
    rear = quarter_car_freqs(P[0] * a / L / 2, P[INDEX["m_ur"]], P[INDEX["k_sr"]], P[INDEX["k_tr"]])
    np.testing.assert_allclose(f, np.sort(np.concatenate([front, rear])), rtol=1e-10)


def test_rigid_tire_roll_and_heavy_body_wheel_hop_limits():
    P = P0.copy()
    P[INDEX["k_tf"]] = P[INDEX["k_tr"]] = 1e12
    summ = modal_summary(P, G)
    k_roll = 2 * P[INDEX["k_sf"]] * (G.track_front / 2) ** 2 + 2 * P[INDEX["k_sr"]] * (G.track_rear / 2) ** 2
    f_roll = np.sqrt(k_roll / P[INDEX["I_xx"]]) / (2 * np.pi)
    assert summ["roll"]["undamped_frequency_hz"] == pytest.approx(f_roll, rel=1e-6)
    # body infinitely heavy: wheel hop sqrt((k_s + k_t) / m_u)
    P = P0.copy()
    for n in ("m_s", "I_xx", "I_yy"):
        P[INDEX[n]] *= 1e9
    summ = modal_summary(P, G)
    f_front = np.sqrt((P[INDEX["k_sf"]] + P[INDEX["k_tf"]]) / P[INDEX["m_uf"]]) / (2 * np.pi)
    f_rear = np.sqrt((P[INDEX["k_sr"]] + P[INDEX["k_tr"]]) / P[INDEX["m_ur"]]) / (2 * np.pi)
    for m in ("front hop (in phase)", "front hop (anti-phase)"):
        assert summ[m]["undamped_frequency_hz"] == pytest.approx(f_front, rel=1e-6)
    for m in ("rear hop (in phase)", "rear hop (anti-phase)"):
        assert summ[m]["undamped_frequency_hz"] == pytest.approx(f_rear, rel=1e-6)


def test_decomposition_is_exact_and_block_diagonal():
    rng = np.random.default_rng(3)
    P = P0 * np.exp(rng.normal(0, 0.3, (5, 12)))
    M, C, K, Bf = decomposed_mck(P, G)
    for X in (M, C, K):
        assert np.abs(X[:, :4, 4:]).max() == 0 and np.abs(X[:, 4:, :4]).max() == 0
    assert np.abs(Bf[:, :4, 2:]).max() == 0 and np.abs(Bf[:, 4:, :2]).max() == 0
    # same eigenvalues as the full 14-state model
    assert_blocks_have_the_full_eigenvalues(P, G)


def test_equations_of_motion_signs():
    # push the front-left wheel up by 1 mm with the body held: the spring
    # pushes the body up, nose up (theta < 0) and left up (phi > 0)
    M, C, K, Bf = mck(P0[None], G)
    q = np.zeros(7)
    q[3] = 1e-3
    force_on_body = -(K[0] @ q)[:3]
    assert force_on_body[0] > 0          # heave force up
    assert force_on_body[1] < 0          # pitch moment nose-up (theta nose-down +)
    assert force_on_body[2] > 0          # roll moment left-up (phi right-down +)
    np.testing.assert_allclose(force_on_body, P0[INDEX["k_sf"]] * 1e-3 *
                               np.array([1, -P0[INDEX["a"]], G.track_front / 2]))


def test_default_car_modal_summary_in_expected_ranges():
    s = modal_summary(DEFAULT_CAR, G)
    assert 1.0 <= s["bounce"]["frequency_hz"] <= 1.7
    assert 1.0 <= s["pitch"]["frequency_hz"] <= 2.0
    for m in ("front hop (in phase)", "rear hop (in phase)", "front hop (anti-phase)", "rear hop (anti-phase)"):
        assert 10.0 <= s[m]["frequency_hz"] <= 15.0
        assert 0.2 < s[m]["damping_ratio"] < 0.6
    assert 0.15 < s["bounce"]["damping_ratio"] < 0.5


def test_static_loads_sum_to_weight():
    loads = static_corner_loads(P0[None], G)[0]
    total = P0[INDEX["m_s"]] + 2 * P0[INDEX["m_uf"]] + 2 * P0[INDEX["m_ur"]]
    assert total_mass(P0) == total and total_mass(DEFAULT_CAR) == pytest.approx(1093.3, rel=1e-12)
    assert GRAVITY == 9.80665  # standard gravity, also the logger unit "g"
    assert loads.sum() == pytest.approx(total * 9.80665, rel=1e-12)
    # moment balance about the CG for the sprung part
    b = G.wheelbase - P0[INDEX["a"]]
    front_s = loads[0] - P0[INDEX["m_uf"]] * 9.80665
    rear_s = loads[2] - P0[INDEX["m_ur"]] * 9.80665
    assert front_s * P0[INDEX["a"]] == pytest.approx(rear_s * b, rel=1e-12)


def test_geometry_validation():
    from rideid.errors import DataError
    with pytest.raises(DataError, match="vehicle.wheelbase"):
        Geometry(0.0, 1.5, 1.5, 0.3)
    with pytest.raises(DataError, match="tire_radius"):
        Geometry(2.5, 1.5, 1.5, -0.3)
    assert len(NAMES) == 12


def test_output_map_closed_form_and_state_space():
    """Pitch nose-down + moves the front corners down by a and the rear up by b;
    roll right-side-down + moves the left corners up by half the track."""
    Om = output_map(P0[None], G)[0]
    a, b = P0[INDEX["a"]], G.wheelbase - P0[INDEX["a"]]
    hf, hr = G.track_front / 2, G.track_rear / 2
    np.testing.assert_allclose(Om[:4, 0], 1.0)                          # heave
    np.testing.assert_allclose(Om[:4, 1], [-a, -a, b, b], rtol=1e-15)   # pitch
    np.testing.assert_allclose(Om[:4, 2], [hf, -hf, hr, -hr], rtol=1e-15)  # roll
    np.testing.assert_array_equal(Om[4:, 3:], np.eye(4))
    assert not Om[4:, :3].any() and not Om[:4, 3:].any()
    # the state-space outputs are this map applied to the accelerations
    A, B, Cy, Dy = state_space(P0[None], G)
    np.testing.assert_allclose(Cy[0, :8], Om @ A[0, 7:], rtol=1e-14, atol=0)
    np.testing.assert_allclose(Dy[0, :8], Om @ B[0, 7:], rtol=1e-14, atol=0)


def test_modal_summary_names_every_mode_once_when_two_share_a_dominant_coordinate():
    """A light roll inertia beside heavy wheels: two antisymmetric modes are roll-dominated (found by
    fuzzing identify, where an estimate on its bound crashed the modal summary). Every mode is still
    named once, and the named undamped frequencies are exactly the block's generalised eigenvalues."""
    import scipy.linalg

    import rideid
    from rideid.model.equations import MODES, decomposed_mck, modal_summary
    from rideid.model.params import ALL_NAMES, full_rows
    car = {"m_s": 2293.452, "I_xx": 50.75, "I_yy": 555.899, "a": 1.36, "m_uf": 116.782, "m_ur": 113.265,
           "k_sf": 135582.961, "k_sr": 88873.916, "c_sf": 1409.704, "c_sr": 1949.652, "k_tf": 425881.559,
           "k_tr": 247425.405}
    g = rideid.DEFAULT_GEOMETRY
    s = modal_summary(car, g)
    assert list(s) == list(MODES)
    P = full_rows(np.array([[car.get(n, 0.0) for n in ALL_NAMES]]))
    M, _, K, _ = decomposed_mck(P, g)
    for idx, names in ((np.arange(4), MODES[:2] + MODES[3:5]), (np.arange(4, 7), (MODES[2],) + MODES[5:])):
        w2 = scipy.linalg.eigh(K[0][np.ix_(idx, idx)], M[0][np.ix_(idx, idx)], eigvals_only=True)
        got = sorted(s[n]["undamped_frequency_hz"] for n in names)
        np.testing.assert_allclose(got, np.sqrt(w2) / (2 * np.pi), rtol=1e-12)


# ---------------------------------------------------------------------------
# CG height (SPEC §8)

def _with_height(h):
    return Geometry(G.wheelbase, G.track_front, G.track_rear, G.tire_radius, cg_height=h)


def test_cg_height_zero_is_bit_identical():
    P = as_vector({**DEFAULT_CAR, "k_arf": 9000.0, "c_tf": 120.0})[None]
    for a, b in zip(mck(P, G), mck(P, _with_height(0.0))):
        assert np.array_equal(a, b)
    for k, v in blocks(P, G).items():
        assert np.array_equal(v, blocks(P, _with_height(0.0))[k])


def test_cg_height_adds_swing_inertia_and_toppling_stiffness():
    h = 0.27
    P = as_vector({**DEFAULT_CAR, "k_arf": 9000.0, "k_arr": 4000.0, "c_tf": 120.0, "c_tr": 90.0})[None]
    M0, C0, K0, B0 = mck(P, G)
    M, C, K, B = mck(P, _with_height(h))
    p = dict(zip(NAMES, P[0]))
    swing = 2 * (p["m_uf"] + p["m_ur"]) * h * h
    dM, dK = np.zeros((7, 7)), np.zeros((7, 7))
    dM[1, 1] = dM[2, 2] = swing
    dK[1, 1] = dK[2, 2] = -p["m_s"] * GRAVITY * h
    np.testing.assert_allclose(M[0] - M0[0], dM, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(K[0] - K0[0], dK, rtol=1e-12, atol=1e-6)
    assert np.array_equal(C, C0) and np.array_equal(B, B0)
    # the symmetric/antisymmetric blocks still decouple and carry all the modes
    Mt, Ct, Kt, _ = decomposed_mck(P, _with_height(h))
    s, a = np.arange(4), np.arange(4, 7)
    for X in (Mt, Ct, Kt):
        assert np.abs(X[0][np.ix_(s, a)]).max() < 1e-9 * np.abs(X[0]).max()
    assert_blocks_have_the_full_eigenvalues(P[0], _with_height(h))


def test_cg_height_locked_wheels_closed_form():
    """Tires ~rigid: roll frequency sqrt((k_roll - m_s g h) / (I_xx + 2 (m_uf + m_ur) h^2)), pitch-heave 2-DOF."""
    h = 0.3
    car = {**DEFAULT_CAR, "k_tf": 1e13, "k_tr": 1e13, "k_arf": 9000.0, "k_arr": 4000.0}
    P = as_vector(car)
    geom = _with_height(h)
    Mt, _, Kt, _ = decomposed_mck(P[None], geom)
    a_ = np.arange(4, 7)
    w2 = scipy.linalg.eigh(Kt[0][np.ix_(a_, a_)], Mt[0][np.ix_(a_, a_)], eigvals_only=True)
    k_roll = ((car["k_sf"] + 2 * car["k_arf"]) * G.track_front ** 2 / 2
              + (car["k_sr"] + 2 * car["k_arr"]) * G.track_rear ** 2 / 2)
    mu2 = 2 * (car["m_uf"] + car["m_ur"])
    roll = (k_roll - car["m_s"] * GRAVITY * h) / (car["I_xx"] + mu2 * h * h)
    assert abs(w2.min() / roll - 1) < 1e-6
    # pitch and heave of the body on rigid wheels
    a, b = car["a"], G.wheelbase - car["a"]
    kf, kr = 2 * car["k_sf"], 2 * car["k_sr"]
    Kb = np.array([[kf + kr, -kf * a + kr * b], [-kf * a + kr * b, kf * a * a + kr * b * b - car["m_s"] * GRAVITY * h]])
    Mb = np.diag([car["m_s"], car["I_yy"] + mu2 * h * h])
    s = np.arange(4)
    w2s = np.sort(scipy.linalg.eigh(Kt[0][np.ix_(s, s)], Mt[0][np.ix_(s, s)], eigvals_only=True))[:2]
    np.testing.assert_allclose(w2s, np.sort(scipy.linalg.eigh(Kb, Mb, eigvals_only=True)), rtol=1e-6)


def test_cg_height_validation():
    from rideid.errors import DataError
    for bad in (-0.1, float("nan"), float("inf"), "x"):
        with pytest.raises(DataError, match="vehicle.cg_height"):
            Geometry(2.5, 1.5, 1.5, 0.3, cg_height=bad)
    assert Geometry(2.5, 1.5, 1.5, 0.3).cg_height == 0.0
    assert Geometry.KEYS == ("wheelbase", "track_front", "track_rear", "tire_radius")
