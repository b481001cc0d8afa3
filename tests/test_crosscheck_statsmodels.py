"""Cross-checks against statsmodels: the HAC (Newey-West) covariance and the Ljung-Box test.

Test-only: statsmodels is in the ``test`` extra, not a dependency of rideid.
"""

import numpy as np
import pytest

from rideid.data.noise import sensor_noise
from rideid.estimate.assess.adequacy import ljung_box
from rideid.estimate.fit.uncertainty import hac_covariance


@pytest.fixture(scope="module")
def sm():
    """statsmodels' API, imported by the worker that runs these tests (a second at collection otherwise)."""
    return pytest.importorskip("statsmodels.api")


@pytest.fixture(scope="module")
def diagnostic():
    return pytest.importorskip("statsmodels.stats.diagnostic")


def _regression(seed, n=400, rho=0.7):
    """``y = X beta + e`` with an intercept, two regressors and AR(1) errors; its least-squares residuals."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([np.ones(n), rng.standard_normal(n), np.cumsum(rng.standard_normal(n)) / 10])
    e = sensor_noise(rng, (n, 1), rho)[:, 0]
    y = X @ np.array([1.0, -2.0, 0.5]) + e
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    return X, y, y - X @ beta


@pytest.mark.parametrize("seed, lags", [(1, 4), (2, 9), (3, 0)])
def test_hac_covariance_is_statsmodels_newey_west(seed, lags, sm):
    # the residuals r = X beta - y have Jacobian X; rideid's sandwich with a fixed Bartlett bandwidth L is
    # Newey-West with maxlags L (weights 1 - l / (L + 1)), times m / (m - n) (statsmodels' use_correction)
    X, y, e = _regression(seed)
    ours = hac_covariance(X, -e, [(len(y), 1)], bandwidth=float(lags)).cov
    fit = sm.OLS(y, X).fit(cov_type="HAC", cov_kwds={"maxlags": lags, "use_correction": True})
    theirs = np.asarray(fit.cov_params())
    assert np.max(np.abs(ours - theirs)) / np.max(np.abs(theirs)) < 1e-10
    # without the small-sample factor statsmodels' estimate is ours times (m - n) / m
    plain = np.asarray(sm.OLS(y, X).fit(cov_type="HAC", cov_kwds={"maxlags": lags,
                                                                  "use_correction": False}).cov_params())
    m, n = X.shape
    assert np.max(np.abs(ours * (m - n) / m - plain)) / np.max(np.abs(plain)) < 1e-10


@pytest.mark.parametrize("seed, rho, lags", [(4, 0.0, 25), (5, 0.5, 25), (6, 0.9, 10)])
def test_ljung_box_is_statsmodels(seed, rho, lags, diagnostic):
    rng = np.random.default_rng(seed)
    x = 3.0 + sensor_noise(rng, (500, 1), rho)[:, 0]  # a mean: both remove it
    Q, p = ljung_box(x, lags)
    lb = diagnostic.acorr_ljungbox(x, lags=[lags], return_df=True)
    Q_sm, p_sm = float(lb["lb_stat"].iloc[0]), float(lb["lb_pvalue"].iloc[0])
    assert Q == pytest.approx(Q_sm, rel=1e-10)
    assert p == pytest.approx(p_sm, rel=1e-10, abs=1e-300)
