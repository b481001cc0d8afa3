"""The car on an unknown road (rideid.estimate.problem.roadfit): closed forms, exactness, scale invariance, recovery."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from rideid.data.scenario import default_scenario
from rideid.estimate.problem import roadfit
from rideid.model.equations import CHANNELS, state_space
from rideid.model.params import ALL_NAMES, INDEX, NAMES, as_vector
from rideid.model.roads import iso8608_profile
from rideid.model.simulate import prepare_run, simulate_reference
from rideid.data.schema.tracks import track_from_table

FS = 200.0


def car():
    sc = default_scenario()
    P = as_vector({n: sc.truth.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    P[INDEX["k_arf"]] = 8000.0  # a front bar: the model's extensions too
    return sc.geometry, P


def road_run(tmp_path, P, geom, speed=12.0, T=20.0, pre=3.0, seed=1, road_class="B", dx=0.01):
    """Channels of the car moving over a random road (the first sample already moving) and its true inputs."""
    x0 = -(geom.wheelbase + speed * pre + 2.0)
    length = speed * (T + pre) + geom.wheelbase + 6.0
    x, zl, zr = iso8608_profile(road_class, length, np.random.default_rng(seed), dx=dx, x0=x0,
                                track_width=geom.track_front)
    f = tmp_path / f"road{seed}.csv"
    np.savetxt(f, np.column_stack([x + speed * pre, zl, zr]), delimiter=",", header="x,z_left,z_right",
               comments="")
    tr = track_from_table({"id": "r", "kind": "profile", "file": str(f)}, "test")
    t = np.arange(int(round((T + pre) * FS)) + 1) / FS
    run = prepare_run(tr, geom, speed, t)
    k0 = int(round(pre * FS))
    y = simulate_reference(P[None], geom, run)[0][k0:]
    return y, run.u[k0:]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    geom, P = car()
    y, u = road_run(tmp_path_factory.mktemp("road"), P, geom)
    return geom, P, y, u, roadfit.prepare_road_run("R", y, FS, 12.0, geom)


def test_transfer_matches_the_state_space_and_the_static_limit(data):
    geom, P, _, _, rr = data
    cols = np.arange(10)
    w = np.array([0.02, 2 * np.pi * 1.3, 2 * np.pi * 11.0])
    H = roadfit.transfer(roadfit.system(P[None], geom), w, cols)[0]
    A, B, Cy, Dy, Br, Dyr = (a[0] for a in state_space(P[None], geom, rate=True))
    for k, wk in enumerate(w):  # the modal form against the explicit inverse (both lose digits as w -> 0)
        s = 1j * wk
        ref = Cy @ np.linalg.inv(s * np.eye(14) - A) @ (B + s * Br) + Dy + s * Dyr
        tol = 1e-6 if k == 0 else 1e-9
        assert np.allclose(H[k], ref, rtol=tol, atol=tol * 1e-3 * np.abs(ref).max())
    # a road rising under all four wheels at once lifts the whole car: every accelerometer reads -w^2 times it
    acc = [CHANNELS.index(c) for c in CHANNELS if "_az_" in c]
    assert np.allclose(H[0, acc].sum(axis=1) / -(w[0] ** 2), 1.0, rtol=1e-3)  # (w / w_bounce)^2 ~ 1e-5
    assert np.all(np.abs(H[0, [8, 9]].sum(axis=1)) < 1e-6 * w[0])  # and no gyro sees it
    # the sampled free response's columns C (I - Phi z^-1)^-1, Phi = exp(A h), in modal form, against the inverse
    import scipy.linalg
    S = roadfit._discrete_columns(roadfit.system(P[None], geom), w[1:], cols, 1 / FS)
    Phi = scipy.linalg.expm(A / FS)
    for k, wk in enumerate(w[1:]):
        ref = Cy @ np.linalg.inv(np.eye(14) - np.exp(-1j * wk / FS) * Phi)
        assert np.allclose(S[k], ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_delay_filter_is_exact_on_polynomials():
    ks, c = roadfit.delay_filter(0.3137, 1 / FS)
    assert np.isclose(c.sum(), 1.0)
    t = -ks / FS  # the samples' times relative to "now"; the filter gives the value 0.3137 s ago
    for p in range(roadfit.DELAY_ORDER + 1):
        assert np.isclose(c @ t ** p, (-0.3137) ** p, rtol=1e-8, atol=1e-12)


def test_the_projection_is_exact_at_the_true_car(data):
    geom, P, _, _, rr = data
    _exact_and_a_tire_seen(P, geom, rr)


def _exact_and_a_tire_seen(P, geom, rr):
    """The true car fits ``rr`` to 1e-7 of its signal, and a tire 1 % off is seen (more than a thousand times
    that residual); the true car's relative residual."""
    r = roadfit.residuals(P, geom, rr)
    signal = np.sum(np.abs(rr.Y[rr.fit]) ** 2)
    assert r @ r / signal < 1e-7
    P2 = P.copy()
    P2[INDEX["k_tf"]] *= 1.01
    r2 = roadfit.residuals(P2, geom, rr)
    assert r2 @ r2 > 1e3 * (r @ r)
    return r @ r / signal


def test_clipped_samples_are_freed_in_the_road_fit(data):
    """SPEC §11: samples at a channel's range leave the fit. The road fit works on the record's DFT, so each
    clipped sample is one free unknown (its column exp(-i w n h) on its channel): the true car fits the clipped
    record to the exact record's level and a tire 1 % off is still seen; kept as recorded, the cut peaks are a
    misfit of the true car thousands of times that; past CLIP_SHARE of the channel's in-band values the channel
    leaves the run's fit whole and is named."""
    geom, P, y, _, _ = data
    fl = CHANNELS.index("axle_az_fl")
    cut = 0.8 * np.max(np.abs(y[:, fl]))
    clipped = np.zeros(y.shape, dtype=bool)
    clipped[:, fl] = np.abs(y[:, fl]) >= cut
    yc = y.copy()
    yc[:, fl] = np.clip(y[:, fl], -cut, cut)
    assert 0 < clipped[:, fl].mean() < 0.01
    rr = roadfit.prepare_road_run("R", yc, FS, 12.0, geom, clipped=clipped)
    assert fl in rr.cols and len(rr.cols) == 10 and not rr.left_out
    assert rr.clip.shape == (np.count_nonzero(clipped), 2)
    assert np.array_equal(rr.clip[:, 1], np.nonzero(clipped[:, fl])[0])
    exact = _exact_and_a_tire_seen(P, geom, rr)
    # kept, the cut peaks are a misfit of the true car thousands of times the freed one
    kept = roadfit.prepare_road_run("R", yc, FS, 12.0, geom)
    rk = roadfit.residuals(P, geom, kept)
    assert rk @ rk / np.sum(np.abs(kept.Y[kept.fit]) ** 2) > 1e3 * exact
    # the freed samples come back: the fit's unknowns are the clipped peaks' excess (in the band)
    sol = roadfit.solve(P, geom, rr)
    freed = sol.f_state[-rr.clip.shape[0]:]
    excess = (yc[:, fl] - y[:, fl])[clipped[:, fl]] * rr.scale[list(rr.cols).index(fl)]
    assert np.corrcoef(freed, excess)[0, 1] > 0.9
    # a channel clipped on more than CLIP_SHARE of its in-band values leaves the fit whole
    wide = np.zeros(y.shape, dtype=bool)
    wide[:, fl] = np.abs(y[:, fl]) >= np.quantile(np.abs(y[:, fl]), 0.5)
    rw = roadfit.prepare_road_run("R", y, FS, 12.0, geom, clipped=wide)
    assert fl not in rw.cols and rw.clip.shape == (0, 2)
    assert rw.left_out["axle_az_fl"].startswith("left out: ") and "range" in rw.left_out["axle_az_fl"]


def test_tire_damping_sees_the_road_rate(tmp_path):
    """With tire damping the road's rate drives the wheels: the projection carries it (``i w R``). The true car
    still fits to 1e-6 of the signal (not 1e-9 as without: the rate of a profile interpolated between 1 cm
    samples jumps at every sample, texture the rear wheels meet between the front wheels' samples)."""
    geom, P = car()
    P[INDEX["c_tf"]] = P[INDEX["c_tr"]] = 150.0
    y, _ = road_run(tmp_path, P, geom, T=10.0)
    rr = roadfit.prepare_road_run("R", y, FS, 12.0, geom)
    r = roadfit.residuals(P, geom, rr)
    Q = P.copy()
    Q[INDEX["c_tf"]] = Q[INDEX["c_tr"]] = 0.0
    q = roadfit.residuals(Q, geom, rr)
    signal = np.sum(np.abs(rr.Y[rr.fit]) ** 2)
    assert r @ r / signal < 1e-6
    assert q @ q > 10 * (r @ r)  # and the tire damper is seen


def test_one_scale_is_unidentifiable(data):
    """Every mass, inertia, stiffness and damping times one factor: the same residual (the road absorbs nothing)."""
    geom, P, _, _, rr = data
    Q = P.copy()
    for n in ALL_NAMES:
        if n != "a":
            Q[INDEX[n]] *= 1.7
    r, q = roadfit.residuals(P, geom, rr), roadfit.residuals(Q, geom, rr)
    assert np.allclose(q, r, rtol=1e-6, atol=1e-6 * np.abs(r).max())


def test_the_rear_delay_carries_the_tires(data):
    """Without the delay's phase (rear wheels taken as on the front's road at once) the true car no longer fits."""
    geom, P, _, _, rr = data
    from dataclasses import replace
    r = roadfit.residuals(P, geom, rr)
    wrong = roadfit.residuals(P, geom, replace(rr, tau=rr.tau * 0.9))
    assert wrong @ wrong > 1e4 * (r @ r)


def test_noise_free_recovery_and_the_road(data):
    geom, P, y, u, rr = data
    free = [n for n in NAMES if n != "m_s"]
    M = P[INDEX["m_s"]] + 2 * P[INDEX["m_uf"]] + 2 * P[INDEX["m_ur"]]

    def full(lt):
        Q = P.copy()
        for n, v in zip(free, np.exp(lt)):
            Q[INDEX[n]] = v
        Q[INDEX["m_s"]] = M - 2 * Q[INDEX["m_uf"]] - 2 * Q[INDEX["m_ur"]]
        return Q

    th = np.log([P[INDEX[n]] for n in free])
    start = th + np.log(np.random.default_rng(3).uniform(0.97, 1.03, th.size))
    sol = least_squares(lambda lt: roadfit.residuals(full(lt), geom, rr), start, diff_step=1e-7)
    assert np.max(np.abs(sol.x - th)) < 5e-4, dict(zip(free, np.round(100 * (sol.x - th), 4)))
    # the road: front-left input within 5 % RMS over 0.5-20 m wavelengths, away from the record's ends
    x, z = roadfit.road(full(sol.x), geom, rr)
    truth = roadfit.band_pass(u[:, 0], rr.speed / FS)
    inner = (x > 20.0) & (x < x[-1] - 20.0)
    err = np.sqrt(np.mean((z[inner, 0] - truth[inner]) ** 2) / np.mean(truth[inner] ** 2))
    assert err < 0.05
    assert np.isclose(x[1] - x[0], rr.speed / FS)


def test_search_costs_on_thread_slices_equal_one_batch(data, monkeypatch, both_cores):
    """The search's population cut into slices, one per thread (model.batch.thread_map_rows): the same
    costs, bit for bit, as one batch; on one thread a plain call."""
    import numba

    from rideid.model.batch import thread_map_rows
    geom, P, _, _, rr = data
    rows = P[None] * np.random.default_rng(2).uniform(0.9, 1.1, (7, P.size))
    whole = roadfit.search_costs(rows, geom, [rr])
    np.testing.assert_array_equal(thread_map_rows(lambda Q: roadfit.search_costs(Q, geom, [rr]), rows), whole)
    assert np.argmin(whole) != np.argmax(whole)  # the rows differ: a slice mix-up would show
    calls = []
    monkeypatch.setattr(numba, "get_num_threads", lambda: 1)
    np.testing.assert_array_equal(thread_map_rows(lambda Q: calls.append(len(Q)) or Q.sum(1), rows), rows.sum(1))
    assert calls == [7]


def test_the_projection_is_exact_for_a_powertrain_on_mounts(tmp_path):
    """SPEC §11: a powertrain on mounts adds two coordinates (18 states): the boundary unknowns and the transient
    columns follow the car's state count (they were 14 fixed, and the unknown-road path crashed)."""
    from powertrain_car import ENGINE
    from rideid.model.params import POWERTRAIN_NAMES, ROW_WIDTHS

    geom, P16 = car()
    P = np.zeros(max(ROW_WIDTHS))
    P[:P16.size] = P16
    for n in POWERTRAIN_NAMES:
        P[INDEX[n]] = ENGINE[n]
    y, _ = road_run(tmp_path, P, geom, T=10.0)
    rr = roadfit.prepare_road_run("R", y, FS, 12.0, geom)
    sol = roadfit.solve(P, geom, rr)
    assert sol.f_state.shape == (18,)
    r = roadfit.residuals(P, geom, rr)
    signal = np.sum(np.abs(rr.Y[rr.fit]) ** 2)
    assert r @ r / signal < 1e-7
    # the rigid car (no powertrain) misses what the engine's modes do to the body: many times the residual
    r0 = roadfit.residuals(P16, geom, rr)
    assert r0 @ r0 > 1e3 * (r @ r)


def test_the_damped_normal_equations_by_cholesky_are_the_eigen_solution():
    """The boundary unknowns' damped normal equations ``(G + eps lambda_max I)^-1 b`` (equilibrated) solved by a
    Cholesky factor with ``lambda_max`` from power steps are the eigendecomposition's solution: ``G`` singular to
    rounding (two columns that explain the same thing, as the rear lead-in and the start's state do), its
    largest eigenvalue within 5 % and never above, and the residual the same to 1e-9 of the data; a matrix
    that is not positive semi-definite beyond the damping takes the eigendecomposition's way."""
    rng = np.random.default_rng(4)
    A = rng.standard_normal((400, 60)) * np.logspace(0, 3, 60)
    A[:, 7] = A[:, 3] * 2.0  # an exact dependence
    G, y = A.T @ A, rng.standard_normal(400)
    b = A.T @ y
    d = np.sqrt(np.diag(G))
    Ge = G / np.outer(d, d)
    lam, V = np.linalg.eigh(Ge)
    approx = roadfit._largest_eigenvalue(Ge)
    assert 0.95 * lam[-1] <= approx <= lam[-1] * (1 + 1e-12)
    f = roadfit._damped_factor(G)(b)
    f_eig = V @ ((V.T @ (b / d)) / (np.clip(lam, 0, None) + 1e-11 * lam[-1])) / d
    np.testing.assert_allclose(A @ f, A @ f_eig, atol=1e-9 * np.abs(y).max())
    assert np.linalg.norm(y - A @ f) <= np.linalg.norm(y - A @ f_eig) * (1 + 1e-9)
    # beyond the damping not positive semi-definite (an eigenvalue of -2e-6 where the damping is 1e-11 of the
    # largest): no Cholesky factor, the eigendecomposition's solution with that eigenvalue taken as 0
    Gn = Ge - 2e-6 * np.outer(V[:, 0], V[:, 0])
    dn = np.sqrt(np.diag(Gn))
    wn, Vn = np.linalg.eigh(Gn / np.outer(dn, dn))
    assert wn[0] < -1e-6
    expect = Vn @ ((Vn.T @ (b / dn)) / (np.clip(wn, 0, None) + 1e-11 * wn[-1])) / dn
    np.testing.assert_allclose(roadfit._damped_factor(Gn)(b), expect, rtol=1e-9)


def test_the_lead_in_gram_is_the_normal_matrix_of_its_columns():
    """roadfit.lead_in_gram (the rear lead-in's Toeplitz blocks read as strided views of the lags' sums) is the real
    normal matrix of the stacked columns ``[g, aL e_n, aR e_n]`` (each lead-in sample's column its channel's
    ``a`` times ``e^{-i w n h}``), built here entry by entry, to 1e-12; and its right-hand side the same."""
    rng = np.random.default_rng(4)
    K, c, nb, D = 37, 3, 5, 6

    def cplx(*shape):
        return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)

    g, aL, aR, r = cplx(K, c, nb), cplx(K, c), cplx(K, c), cplx(K, c)
    wh = np.sort(rng.uniform(0.01, 1.5, K))
    G, b, en = roadfit.lead_in_normal_equations(g, aL, aR, r, wh, D)
    e = np.exp(-1j * np.outer(wh, np.arange(D)))
    cols = ([g[:, :, j] for j in range(nb)] + [aL * e[:, n, None] for n in range(D)]
            + [aR * e[:, n, None] for n in range(D)])
    A = np.stack([np.concatenate([x.real.ravel(), x.imag.ravel()]) for x in cols], axis=1)
    want = A.T @ A
    np.testing.assert_allclose(G, want, rtol=0, atol=1e-12 * np.abs(want).max())
    np.testing.assert_allclose(b, A.T @ np.concatenate([r.real.ravel(), r.imag.ravel()]), rtol=1e-12)
    np.testing.assert_allclose(en, e, rtol=1e-15)
    assert not roadfit._toeplitz(np.arange(5.0), 3).flags.writeable
    np.testing.assert_array_equal(roadfit._toeplitz(np.arange(5.0), 3), [[2, 1, 0], [3, 2, 1], [4, 3, 2]])
