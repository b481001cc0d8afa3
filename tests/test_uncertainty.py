"""Robust standard errors (rideid.estimate.fit.uncertainty): closed forms, then coverage on simulated cars."""

import numpy as np
import pytest

import rideid
from rideid.data.noise import sensor_noise
from rideid.estimate.fit.uncertainty import (andrews_bandwidth, correlation, hac_covariance, long_run_covariance,
                                         white_covariance, with_derived)


def ar1(rng, n, rho, sigma=1.0):
    return sigma * sensor_noise(rng, (n, 1), rho)[:, 0]


def test_sensor_noise_is_stationary_ar1():
    rng = np.random.default_rng(7)
    e = sensor_noise(rng, (200_000, 2), 0.8)
    assert np.allclose(e.std(axis=0), 1.0, atol=0.02)
    for lag in (1, 3):
        r = np.mean(e[lag:] * e[:-lag], axis=0)
        assert np.allclose(r, 0.8 ** lag, atol=0.02)
    assert abs(np.mean(e[:, 0] * e[:, 1])) < 0.02  # channels independent
    # rho = 0 draws exactly the white noise of the same generator
    assert np.array_equal(sensor_noise(np.random.default_rng(3), (5, 2), 0.0),
                          np.random.default_rng(3).standard_normal((5, 2)))


def test_long_run_covariance_is_the_bartlett_double_sum():
    rng = np.random.default_rng(1)
    G = rng.standard_normal((40, 3))
    L = 6.5
    t = np.arange(40)
    lag = np.abs(t[:, None] - t[None, :])
    K = np.where(lag <= L, 1 - lag / (L + 1), 0.0)
    assert np.allclose(long_run_covariance(G, L), G.T @ K @ G)
    # Bartlett weights make it positive semi-definite
    assert np.linalg.eigvalsh(long_run_covariance(G, 30.0)).min() > -1e-12


def test_mean_of_ar1_errors_matches_the_long_run_variance():
    """y_t = beta + u_t, u AR(1): Var(beta_hat) -> sigma^2 (1 + rho) / ((1 - rho) T)."""
    rng = np.random.default_rng(2024)
    T, rho = 40_000, 0.6
    u = ar1(rng, T, rho)
    J = np.ones((T, 1))
    exact = (1 + rho) / (1 - rho) / T
    hac = hac_covariance(J, u - u.mean(), [(T, 1)]).cov[0, 0]
    white = white_covariance(J, u - u.mean())[0, 0]
    assert hac == pytest.approx(exact, rel=0.10)
    assert white == pytest.approx(1.0 / T, rel=0.05)  # 4x too small, as the closed form says


def test_regression_with_ar1_errors_matches_the_exact_sandwich():
    """A slope on a smooth regressor: the exact covariance (X'X)^-1 X' Sigma X (X'X)^-1 with
    Sigma_ts = rho^|t-s| sigma^2, against the HAC estimate from one long sample."""
    rng = np.random.default_rng(5)
    T, rho, sigma = 6000, 0.8, 0.3
    t = np.arange(T)
    X = np.column_stack([np.ones(T), np.sin(2 * np.pi * t / 400)])
    u = ar1(rng, T, rho, sigma)
    beta = np.linalg.lstsq(X, u, rcond=None)[0]
    e = u - X @ beta
    # exact sandwich through the AR(1) autocovariance, lag by lag (Toeplitz)
    XtX = X.T @ X
    S = X.T @ X * sigma ** 2
    for lag in range(1, 200):
        G = X[lag:].T @ X[:-lag] * sigma ** 2 * rho ** lag
        S += G + G.T
    exact = np.linalg.solve(XtX, np.linalg.solve(XtX, S).T)
    hac = hac_covariance(X, e, [(T, 1)]).cov
    assert np.sqrt(np.diag(hac)) == pytest.approx(np.sqrt(np.diag(exact)), rel=0.12)
    white = white_covariance(X, e)
    assert np.all(np.sqrt(np.diag(white)) < 0.45 * np.sqrt(np.diag(exact)))


def test_noise_shared_across_channels_counts_once():
    """Two channels carry the same noise at each instant: beta_hat = mean(u), Var = sigma^2 / T,
    while the white estimate sees 2T independent residuals (sigma^2 / (2T))."""
    rng = np.random.default_rng(11)
    T = 20_000
    u = rng.standard_normal(T)
    e = np.repeat(u - u.mean(), 2)  # time-major, two channels per sample
    J = np.ones((2 * T, 1))
    assert hac_covariance(J, e, [(T, 2)], bandwidth=0).cov[0, 0] == pytest.approx(1.0 / T, rel=0.03)
    assert white_covariance(J, e)[0, 0] == pytest.approx(0.5 / T, rel=0.03)


def test_runs_are_independent_blocks():
    rng = np.random.default_rng(3)
    J = rng.standard_normal((50, 2))
    e = rng.standard_normal(50)
    both = hac_covariance(J, e, [(10, 2), (30, 1)], bandwidth=4)
    H = np.linalg.inv(J.T @ J)
    S = long_run_covariance((J[:20].reshape(10, 2, 2) * e[:20].reshape(10, 2, 1)).sum(1), 4) \
        + long_run_covariance(J[20:] * e[20:, None], 4)
    assert np.allclose(both.cov, H @ S @ H * 50 / 48)
    with pytest.raises(ValueError, match="blocks cover"):
        hac_covariance(J, e, [(10, 2)])


def test_andrews_bandwidth_of_an_ar1_series():
    rng = np.random.default_rng(8)
    T, rho = 50_000, 0.9
    G = ar1(rng, T, rho)[:, None]
    alpha = 4 * rho ** 2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    assert andrews_bandwidth(G) == pytest.approx(1.1447 * (alpha * T) ** (1 / 3), rel=0.05)
    assert andrews_bandwidth(rng.standard_normal((T, 1))) < 0.1 * T ** (1 / 3)


def test_correlation_and_derived():
    cov = np.array([[4.0, 1.0], [1.0, 1.0]])
    assert np.allclose(correlation(cov), [[1, 0.5], [0.5, 1]])
    full = with_derived(cov, np.array([-2.0, -2.0]))
    # q = -2 x1 - 2 x2: Var = 4 (4 + 1 + 2)
    assert full[2, 2] == pytest.approx(28.0)
    assert full[0, 2] == pytest.approx(-2 * 4 - 2 * 1)
    assert np.all(np.linalg.eigvalsh(full) > -1e-9)


# -- coverage on a simulated car with coloured sensor noise ----------------------------------------------

#: AR(1) coefficient of the coloured sensor noise at 200 Hz (correlation time ~ 50 ms)
RHO = 0.9


def _estimates(ds, x, info):
    """(names, estimate, std, std_robust) of the free parameters and the derived mass."""
    from rideid.estimate.fit.uncertainty import estimate_covariance

    space = ds.space
    cov = estimate_covariance(info, space)
    P = space.full(x[None])[0]
    est = np.array([P[rideid.NAMES.index(n)] for n in cov.names])
    return cov.names, est, np.sqrt(np.diag(cov.white)), np.sqrt(np.diag(cov.robust))


def _coverage(rows):
    z_w = np.concatenate([r[0] for r in rows])
    z_r = np.concatenate([r[1] for r in rows])
    return np.mean(np.abs(z_w) <= 2), np.mean(np.abs(z_r) <= 2), z_w, z_r



def test_polish_std_robust_on_coloured_noise(tmp_path):
    """One seed of coloured noise on the SUV: the polish from the true car (the estimator at the
    optimum, without the search). std_robust is several times std, as the coloured noise demands,
    and covers the truth where std does not."""
    from cars import SUV_TRUTH, add_noise, suv_scenario
    from rideid.synth.scenario import simulate_manifest, write_dataset
    from rideid.estimate.problem.cost import CostFunction
    from rideid.estimate.fit.polish import _polish
    from rideid.model.batch import single_threaded_blas

    sc = suv_scenario(tmp_path)
    clean, _ = simulate_manifest(sc)
    write_dataset(sc, add_noise(clean, 0.02, RHO, seed=3), tmp_path / "ds")
    ds = rideid.load_dataset(tmp_path / "ds")
    cf = CostFunction(ds)
    x0 = np.array([SUV_TRUTH[n] for n in cf.names])
    with single_threaded_blas():
        x, info, std = _polish(cf, x0, np.full(len(cf.run_ids), 1 / len(cf.run_ids)))
    names, est, sw, sr = _estimates(cf, x, info)
    assert np.allclose(sw[:-1], std)  # the white covariance is the polish's own
    err = est - np.array([SUV_TRUTH[n] for n in names])
    assert np.median(sr / sw) > 1.8
    assert np.mean(np.abs(err) <= 2 * sr) >= 10 / 12
    assert np.mean(np.abs(err) <= 2 * sw) < np.mean(np.abs(err) <= 2 * sr)
    # bandwidths grow with the noise's correlation time (rho = 0.9: ~10 samples)
    assert all(10 < b < 200 for b in info["hac_bandwidths"].values())


@pytest.mark.slow
@pytest.mark.expensive
def test_std_robust_covers_the_truth_under_coloured_noise(tmp_path):
    """rideid.identify (search + polish) on the SUV over 6 seeds of AR(1) noise at 2 % of RMS:
    72 estimates (11 free + the derived m_s per seed)."""
    from cars import SUV_TRUTH, add_noise, suv_scenario
    from rideid.synth.scenario import simulate_manifest, write_dataset

    sc = suv_scenario(tmp_path)
    clean, _ = simulate_manifest(sc)
    rows = []
    for seed in range(6):
        write_dataset(sc, add_noise(clean, 0.02, RHO, seed=100 + seed), tmp_path / f"s{seed}")
        res = rideid.identify(rideid.load_dataset(tmp_path / f"s{seed}"), seed=seed, model="base")
        est = {n: d for n, d in res.details.items() if not d["fixed"]}
        err = np.array([d["value"] - SUV_TRUTH[n] for n, d in est.items()])
        rows.append((err / np.array([d["std"] for d in est.values()]),
                     err / np.array([d["std_robust"] for d in est.values()])))
    cov_w, cov_r, z_w, z_r = _coverage(rows)
    print(f"coverage of +-2 std: white {cov_w:.2f}, robust {cov_r:.2f} ({z_r.size} estimates)")
    assert cov_r >= 0.90
    assert cov_w <= 0.75
    assert 0.5 < np.std(z_r) < 1.2


def _jacobian_with(s, seed=0, m=60):
    """A Jacobian ``U diag(s) V^T`` of known singular values and right vectors, and its exact ``(J^T J)^+``."""
    rng = np.random.default_rng(seed)
    n = len(s)
    U, _ = np.linalg.qr(rng.standard_normal((m, n)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    s = np.asarray(s, dtype=float)
    return (U * s) @ V.T, V, s


def test_white_covariance_of_an_ill_conditioned_jacobian_matches_the_closed_form():
    from rideid.estimate.fit.uncertainty import normal_inverse
    # cond(J) = 1e9: J^T J has condition 1e18, beyond double precision
    J, V, s = _jacobian_with([1.0, 0.3, 1e-3, 1e-6, 1e-9])
    exact = (V / s ** 2) @ V.T
    inv = normal_inverse(J)
    assert inv.rank == 5 and not inv.unidentified.any()
    assert np.max(np.abs(inv.matrix - exact)) / np.max(np.abs(exact)) < 1e-6
    assert np.allclose(np.diag(inv.matrix), np.diag(exact), rtol=1e-6)
    # the normal matrix's inverse (the method it replaces) loses most digits here, or fails outright
    try:
        naive = np.linalg.inv(J.T @ J)
        assert np.max(np.abs(naive - exact)) / np.max(np.abs(exact)) > 1e-3
    except np.linalg.LinAlgError:
        pass
    # at cond(J) = 1e7 it still returns numbers, wrong in the third digit or worse
    J7, V7, s7 = _jacobian_with([1.0, 0.3, 1e-3, 1e-5, 1e-7], seed=3)
    exact7 = (V7 / s7 ** 2) @ V7.T
    assert np.max(np.abs(np.linalg.inv(J7.T @ J7) - exact7)) / np.max(np.abs(exact7)) > 1e-4
    assert np.max(np.abs(normal_inverse(J7).matrix - exact7)) / np.max(np.abs(exact7)) < 1e-8
    # white_covariance: s^2 (J^T J)^+ with s^2 = RSS / (m - n)
    e = np.random.default_rng(5).standard_normal(J.shape[0])
    s2 = e @ e / (J.shape[0] - 5)
    assert np.allclose(white_covariance(J, e), s2 * exact, rtol=1e-6, atol=1e-6 * s2 * np.abs(exact).max())


def test_a_rank_deficient_jacobian_reports_the_unidentified_parameter_as_infinite():
    from rideid.estimate.fit.uncertainty import normal_inverse
    rng = np.random.default_rng(2)
    A = rng.standard_normal((50, 2))
    # parameter 3 has no information; parameters 4 and 5 enter only as their sum
    c = rng.standard_normal(50)
    J = np.column_stack([A, np.zeros(50), c, c])
    inv = normal_inverse(J)
    assert inv.rank == 3
    assert inv.unidentified.tolist() == [False, False, True, True, True]
    e = rng.standard_normal(50)
    cov = white_covariance(J, e)
    assert np.isinf(cov[2, 2]) and np.isinf(cov[3, 3]) and np.isinf(cov[4, 4])
    assert np.isnan(cov[0, 2]) and np.isnan(cov[3, 4])
    # the identified parameters: exactly the fit without the unidentified columns (sum of 4 and 5 as one)
    Jr = np.column_stack([A, c])
    s2 = e @ e / (50 - 5)
    assert np.allclose(cov[:2, :2], s2 * np.linalg.inv(Jr.T @ Jr)[:2, :2], rtol=1e-10)
    # the robust covariance marks the same parameters
    rob = hac_covariance(J, e, [(50, 1)], bandwidth=2.0).cov
    assert np.isinf(np.diag(rob)[2:]).all() and np.isfinite(rob[:2, :2]).all()


def test_an_unidentified_parameter_has_no_standard_error_in_the_details():
    from types import SimpleNamespace

    from rideid.estimate.assess.details import NOT_IDENTIFIED, parameter_detail
    from rideid.estimate.fit.uncertainty import EstimateCovariance
    space = SimpleNamespace(col={"k_sf": 0, "k_sr": 1}, fixed={}, names=["k_sf", "k_sr"], derived=None,
                            bounds=np.array([[1e4, 1e5], [1e4, 1e5]]), derived_names=lambda: [])
    cov = np.array([[4.0, np.nan], [np.nan, np.inf]])
    robust = EstimateCovariance(["k_sf", "k_sr"], cov, cov)
    P = np.array([3e4, 5e4])
    std = np.sqrt(np.diag(cov))
    ok, bad = (parameter_detail(space, P, n, std, cov, robust) for n in ("k_sf", "k_sr"))
    assert ok["std"] == 2.0 and ok["std_robust"] == 2.0 and "note" not in ok
    assert bad["std"] is None and bad["std_robust"] is None and bad["note"] == NOT_IDENTIFIED


def test_jackknife_runs_is_the_exact_delete_one_refit_for_a_linear_model():
    """For a linear least-squares problem the linearised delete-one-run move is exact: the jackknife covariance
    equals the one from refitting without each run (lstsq). A run that alone determines a parameter is not
    left out. Runs that agree within their noise add no between-runs variance (Birge ratio below its 99 %
    quantile); runs whose offsets differ beyond it do, about the offsets' spread."""
    from rideid.estimate.fit.uncertainty import between_runs_variance, jackknife_runs
    rng = np.random.default_rng(3)
    T, C, k = 200, 2, 6
    X = rng.normal(size=(k * T * C, 3))
    beta = np.array([1.0, -2.0, 0.5])
    y = X @ beta + 0.1 * rng.normal(size=k * T * C)
    bhat = np.linalg.lstsq(X, y, rcond=None)[0]
    e = X @ bhat - y
    cov, used = jackknife_runs(X, e, [(T, C)] * k)
    moves = []
    for r in range(k):
        keep = np.ones(len(y), dtype=bool)
        keep[r * T * C:(r + 1) * T * C] = False
        moves.append(np.linalg.lstsq(X[keep], y[keep], rcond=None)[0] - bhat)
    M = np.array(moves) - np.mean(moves, axis=0)
    assert used == k
    assert cov == pytest.approx((k - 1) / k * M.T @ M, rel=1e-9)
    # a parameter only the first run measures: that run is not left out
    Z = np.column_stack([X, np.r_[np.ones(T * C), np.zeros((k - 1) * T * C)]])
    _, used = jackknife_runs(Z, e, [(T, C)] * k)
    assert used == k - 1
    # agreement within the noise: nothing added; offsets of 0.05 per run on the intercept-like column: added
    ones = np.ones((k * T * C, 1))
    e0 = 0.1 * rng.normal(size=k * T * C)
    v_rob = 0.1 ** 2 / (k * T * C)
    cov0, _ = jackknife_runs(ones, e0 - e0.mean(), [(T, C)] * k)
    assert between_runs_variance(cov0[0, 0], v_rob, k) == 0.0
    off = np.repeat(rng.normal(0, 0.05, k), T * C)
    cov1, _ = jackknife_runs(ones, e0 + off - (e0 + off).mean(), [(T, C)] * k)
    extra = between_runs_variance(cov1[0, 0], v_rob, k)
    assert extra > 0 and 0.2 * 0.05 ** 2 / k < extra < 5 * 0.05 ** 2 / k


class _RoundedQuadratic:
    """A cost ``v^T A v`` plus rounding: independent draws of N(0, delta) on every evaluation (seeded). Has what
    a road fit's problem gives the Hessian and the rounding estimate: ``vbounds``, ``costs``, ``knot_split``."""

    def __init__(self, A, delta, rng):
        self.A, self.delta, self.rng = np.asarray(A, float), delta, rng
        d = self.A.shape[0]
        self.vbounds = (np.full(d, -10.0), np.full(d, 10.0))

    def costs(self, V):
        V = np.asarray(V, float)
        return np.einsum("ki,ij,kj->k", V, self.A, V) + self.delta * self.rng.standard_normal(len(V))

    def knot_split(self):
        return None  # no damper curves' knot forces: the Hessian is the cost's second differences throughout


def _rotated(eigs, pairs):
    """A symmetric matrix with eigenvalues ``eigs``: the identity's columns, each pair ``(i, j)`` in ``pairs`` turned
    by 45 degrees."""
    U = np.eye(len(eigs))
    for i, j in pairs:
        U[:, [i, j]] = U[:, [i, j]] @ (np.array([[1.0, -1.0], [1.0, 1.0]]) / np.sqrt(2))
    return U @ np.diag(eigs) @ U.T, U


def test_a_hessian_direction_below_its_rounding_noise_leaves_its_parameters_not_determined():
    """The rounding estimate and the eigenvalues' noise against draws (the road fit's own stencils,
    ``JointProblem.hessian`` and ``JointProblem.rounding``, on a cost ``v^T A v`` with N(0, delta) added to every
    evaluation); then which parameters a direction under ``uncertainty.curvature_noise`` times its noise leaves
    without an error bar, and the others' bread as the closed-form inverse on the resolved directions."""
    from rideid.estimate.problem.joint import JointProblem
    from rideid.estimate.fit.uncertainty import resolve

    rng = np.random.default_rng(7)
    from rideid.settings import defaults

    step, delta = defaults["anyroad.hessian_step"], 2e-6  # the road fits' step, 1e-3: a diagonal entry's noise
    assert step == 1e-3  # sqrt(6) delta / (2 h^2) = 2.45, a 45-degree pair's 2.29
    A, U = _rotated([400.0, 60.0, 30.0, 1.0], [(2, 3)])  # the smallest along (x3 - x2) / sqrt(2)
    prob = _RoundedQuadratic(A, delta, rng)
    v = np.full(4, 0.3)
    got = JointProblem.rounding(prob, v, step, pairs=400)
    assert got == pytest.approx(delta, rel=0.1)
    # the eigenvalues' spread over draws of the Hessian against resolve's noise of each (the 45-degree pair's a
    # little below a diagonal entry's: its own costs' noise averages, the shared f0's does not)
    draws = np.array([np.linalg.eigh(JointProblem.hessian(prob, v, step))[0] for _ in range(400)])
    res = resolve(A, delta, step)
    assert np.mean(draws, axis=0) == pytest.approx([1.0, 30.0, 60.0, 400.0], abs=0.5)
    assert res.curvatures.size == 1 and res.curvatures[0] == pytest.approx(1.0)
    assert np.std(draws[:, 0]) == pytest.approx(res.noise[0], rel=0.15)
    assert res.noise[0] == pytest.approx(delta / step ** 2 * np.sqrt(1.125 + 0.375 / 2), rel=1e-9)
    assert resolve(np.diag([3.0, 4.0]), delta, step).noise[0] == pytest.approx(np.sqrt(6) / 2 * delta / step ** 2)
    # x2 and x3 lie half along the unresolved direction: not determined; x0, x1 untouched by it
    assert list(res.not_determined) == [False, False, True, True]
    rec = res.record(["a", "b", "c", "d"])
    assert rec["not_determined"] == ["c", "d"] and set(rec["directions"][0]["along"]) == {"c", "d"}
    # the bread: the inverse on the three resolved directions (exact), never the unresolved 1 / 1.0
    Hinv = res.pinv(A)
    assert Hinv == pytest.approx(U[:, :3] @ np.diag(1 / np.array([400.0, 60.0, 30.0])) @ U[:, :3].T, abs=1e-12)
    assert Hinv[0, 0] == pytest.approx(1 / 400) and Hinv[2, 2] == pytest.approx(0.5 / 30)
    # with nuisances after the car's unknowns (a run's speed): those kept whole
    Hf = np.block([[A, np.full((4, 1), 0.5)], [np.full((1, 4), 0.5), np.array([[9.0]])]])
    T = np.zeros((5, 4))
    T[:4, :3], T[4, 3] = U[:, :3], 1.0
    assert res.pinv(Hf) == pytest.approx(T @ np.linalg.inv(T.T @ Hf @ T) @ T.T, abs=1e-12)
    # a tenth of the rounding: every direction measured, nothing marked
    clean = resolve(A, delta / 10, step)
    assert not clean.not_determined.any() and clean.record(list("abcd")) is None
    assert clean.pinv(A) == pytest.approx(np.linalg.inv(A), abs=1e-12)
    # a negative eigenvalue (the cost not at a minimum along it) is never measured, however small the noise
    neg, _ = _rotated([400.0, 60.0, 30.0, -5.0], [(2, 3)])
    assert list(resolve(neg, 0.0, step).not_determined) == [False, False, True, True]
    # measured again at ten times the step along the weak direction (the road fit's JointProblem.along on the same
    # rounded cost: its curvature and its couplings to the others, a hundred times less noise): found at 1.0, and
    # the variance along it 1 / 1.0 to a few per cent, where the step's own Hessian had a noise of 2.3 on it
    import functools

    from rideid.estimate.fit.uncertainty import remeasured
    along = defaults["uncertainty.direction_step"]
    assert along == 1e-2
    H = JointProblem.hessian(prob, v, step)
    first = resolve(H, delta, step)
    assert first.curvatures.size == 1 and first.not_determined[2:].all()
    H2, again, rec = remeasured(H, delta, step, along, functools.partial(JointProblem.along, prob, v, step=step))
    assert again.curvatures.size == 0 and not again.not_determined.any()
    assert len(rec) == 1
    assert rec[0]["curvature_at_step"] == pytest.approx(1.0, abs=5 * np.sqrt(6) * delta / (2 * along ** 2))
    u = U[:, 3]
    assert u @ again.pinv(H2) @ u == pytest.approx(1.0, rel=0.05)
    # where the larger step would cross a bound the direction stays as it was (not determined)
    tight = _RoundedQuadratic(A, delta, rng)
    tight.vbounds = (np.full(4, 0.3 - 2e-3), np.full(4, 10.0))
    H3, kept, rec3 = remeasured(H, delta, step, along, functools.partial(JointProblem.along, tight, v, step=step))
    assert rec3 == [] and kept.not_determined[2:].all()


def test_a_direction_not_determined_at_a_search_bound_makes_its_groups_error_bars_conditional():
    """I_p not determined and at its search bound (data seed 2 of the built-in car with every reality: I_p 1 kg m^2,
    f_pp 6.4 Hz against 12 and 13, and x_p, zeta_pb 3.9 and 4.0 of their error bars off): the powertrain's other
    free parameters are marked ``conditional_on`` I_p with a note, the sentence names them, and nothing else is
    marked; the same direction inside its bounds marks nothing."""
    import rideid
    from rideid.estimate.assess.details import not_determined, unresolved_sentence
    from rideid.model.params import POWERTRAIN_NAMES
    sc = rideid.default_scenario()
    space = rideid.ParameterSpace(sc.known, sc.geometry, extensions=("powertrain",))
    truth = {**sc.truth, "m_p": 180.0, "x_p": 1.2, "I_p": 12.0, "f_pb": 10.5, "zeta_pb": 0.1, "f_pp": 13.0,
             "zeta_pp": 0.1}
    lo, hi = space.bounds[:, 0], space.bounds[:, 1]

    def details(ip):
        out = {}
        for j, n in enumerate(space.names):
            v = ip if n == "I_p" else truth[n]
            out[n] = {"value": v, "lower": float(lo[j]), "upper": float(hi[j]), "fixed": False, "derived": False,
                      "std": 0.01 * v, "std_robust": 0.01 * v, "std_total": 0.01 * v}
        return out

    unres = {"directions": [{"curvature": -0.85, "noise": 0.44, "along": {"zeta_pp": 0.95, "I_p": 0.31}}],
             "not_determined": ["I_p", "zeta_pp"], "curvature_noise": 2.0}
    x = np.array([truth[n] for n in space.names])
    at = details(float(lo[space.names.index("I_p")]))
    assert not_determined(at, space, x, unres) == ["I_p", "zeta_pp"]
    coupled = [n for n in POWERTRAIN_NAMES if n not in ("I_p", "zeta_pp")]
    assert unres["at_bound"] == ["I_p"] and unres["conditional"] == coupled
    assert all(at[n]["conditional_on"] == ["I_p"] and at[n]["std_robust"] is not None
               and at[n]["note"].startswith("its error bar holds only with I_p at the search bound") for n in coupled)
    assert not any("conditional_on" in at[n] for n in space.names if n not in coupled)
    assert unresolved_sentence(unres).endswith(
        "; I_p ended at a search bound, so that estimate is the bound's, not the data's, and m_p, x_p, f_pb, "
        "zeta_pb, f_pp, fitted around it, may be off by several of their error bars (measured: 4 of them)")
    inside = {k: v for k, v in unres.items() if k not in ("at_bound", "conditional")}
    free = details(12.0)
    assert not_determined(free, space, x, inside) == ["I_p", "zeta_pp"]
    assert "at_bound" not in inside and not any("conditional_on" in d for d in free.values())
