"""JADE: each rule, the interface, and the paper's benchmark results.

Reference values: Zhang & Sanderson (2009), IEEE TEVC 13(5), Table IV, JADE
with archive, D = 30, NP = 100, mean of 50 runs: f1 Sphere 1500 gen
1.3e-54; f5 Rosenbrock 3000 gen 3.2e-1; f6 Step 1500 gen 0; f9 Rastrigin
1000 gen 1.4e-4, 5000 gen 0; f10 Ackley 500 gen 3.0e-9, 2000 gen 4.4e-15.
"""

import numpy as np
import pytest

from rideid import ArgumentError, JadeSolver, jade

D = 30


def sphere(X):
    return np.sum(X * X, axis=1)


def step(X):
    return np.sum(np.floor(X + 0.5) ** 2, axis=1)


def rastrigin(X):
    return np.sum(X * X - 10 * np.cos(2 * np.pi * X) + 10, axis=1)


def ackley(X):
    return (-20 * np.exp(-0.2 * np.sqrt(np.mean(X * X, axis=1))) - np.exp(np.mean(np.cos(2 * np.pi * X), axis=1))
            + 20 + np.e)


def rosenbrock(X):
    return np.sum(100 * (X[:, 1:] - X[:, :-1] ** 2) ** 2 + (X[:, :-1] - 1) ** 2, axis=1)


def median_best(f, half_width, generations, seeds=(1, 2, 3)):
    return float(np.median([jade(f, [(-half_width, half_width)] * D, population=100, generations=generations,
                                 seed=s).fun for s in seeds]))


# -- published results ----------------------------------------------------------

def test_sphere_1500():
    assert median_best(sphere, 100, 1500) < 1e-50  # paper 1.3e-54


def test_step_1500():
    assert median_best(step, 100, 1500) == 0.0  # paper 0


def test_rastrigin_1000():
    assert median_best(rastrigin, 5.12, 1000) < 5e-4  # paper 1.4e-4


def test_ackley_500():
    assert median_best(ackley, 32, 500) < 1e-8  # paper 3.0e-9


@pytest.mark.slow
def test_rastrigin_5000():
    assert median_best(rastrigin, 5.12, 5000) == 0.0  # paper 0


@pytest.mark.slow
def test_ackley_2000():
    assert median_best(ackley, 32, 2000) < 1e-14  # paper 4.4e-15


@pytest.mark.slow
def test_rosenbrock_3000():
    # paper mean 0.32: most runs reach 0, a few end in the 3.99 local minimum
    assert median_best(rosenbrock, 30, 3000, seeds=(1, 2, 3, 4, 5)) < 4.0


# -- the rules ------------------------------------------------------------------

def test_cauchy_f_regenerated_and_capped():
    s = JadeSolver([(-1, 1)] * 3, 5000, rng=1, mu_f=0.05)
    F = s._draw_f()
    assert np.all(F > 0) and np.all(F <= 1)
    # P(F >= 1 | F > 0) for Cauchy(0.05, 0.1)
    from scipy.stats import cauchy
    p1 = cauchy.sf(1, 0.05, 0.1) / cauchy.sf(0, 0.05, 0.1)
    assert np.mean(F == 1) == pytest.approx(p1, abs=0.01)


def test_cr_truncated_normal():
    s = JadeSolver([(-1, 1)] * 3, 5000, rng=2, mu_cr=0.95)
    CR = s._draw_cr()
    assert CR.min() >= 0 and CR.max() <= 1
    assert np.mean(CR == 1) == pytest.approx(0.3085, abs=0.02)  # P(N(0.95, 0.1) >= 1)


def test_midpoint_repair_not_clipping():
    bounds = [(-1.0, 1.0)] * 4
    a = JadeSolver(bounds, 12, rng=5)
    b = JadeSolver(bounds, 12, rng=5)
    f = sphere(a.pop)
    for s in (a, b):
        s.ask()
        s.tell(f)
    F = np.full(12, 1.0)
    repaired = a._mutants(F)
    b.low, b.up = np.full(4, -np.inf), np.full(4, np.inf)
    raw = b._mutants(F)
    assert np.all(repaired >= -1) and np.all(repaired <= 1)
    lo, hi = raw < -1, raw > 1
    assert lo.any() and hi.any()
    np.testing.assert_allclose(repaired[lo], ((-1 + a.pop) / 2)[lo])
    np.testing.assert_allclose(repaired[hi], ((1 + a.pop) / 2)[hi])
    ok = ~(lo | hi)
    np.testing.assert_array_equal(repaired[ok], raw[ok])


def test_crossover_takes_at_least_one_mutant_component():
    s = JadeSolver([(-1, 1)] * 5, 50, rng=3, mu_cr=0.0)
    s.ask()
    s.tell(sphere(s.pop))
    s.mu_cr = 0.0
    U = s.ask()
    changed = (U != s.pop).sum(axis=1)
    assert np.all(changed >= 1)


def test_strict_selection_and_lehmer_update():
    s = JadeSolver([(-1, 1)] * 3, 8, rng=4)
    s.ask()
    f0 = sphere(s.pop)
    s.tell(f0)
    s.ask()
    _, U, F, CR = s._pending
    # equal cost is not better: nothing changes
    pop0, mu_f0, mu_cr0 = s.pop.copy(), s.mu_f, s.mu_cr
    better = s.tell(f0.copy())
    assert not better.any()
    np.testing.assert_array_equal(s.pop, pop0)
    assert (s.mu_f, s.mu_cr, s.archive.shape[0]) == (mu_f0, mu_cr0, 0)
    # now exactly individuals 1 and 5 improve
    s.ask()
    _, U, F, CR = s._pending
    costs = s.costs.copy()
    costs[[1, 5]] -= 1.0
    better = s.tell(costs)
    assert better.tolist() == [i in (1, 5) for i in range(8)]
    sf = F[[1, 5]]
    assert s.mu_f == pytest.approx(0.9 * mu_f0 + 0.1 * np.sum(sf ** 2) / np.sum(sf), rel=1e-15)
    assert s.mu_cr == pytest.approx(0.9 * mu_cr0 + 0.1 * np.mean(CR[[1, 5]]), rel=1e-15)
    np.testing.assert_array_equal(s.archive, pop0[[1, 5]])
    np.testing.assert_array_equal(s.pop[[1, 5]], U[[1, 5]])


def test_archive_capped_at_population():
    sizes = []
    jade(sphere, [(-5, 5)] * 5, population=10, generations=60, seed=1,
         callback=lambda st: sizes.append(st.archive_size))
    assert max(sizes) == 10 and all(x <= 10 for x in sizes)


def test_same_seed_same_bits():
    r1 = jade(rastrigin, [(-5.12, 5.12)] * 10, population=30, generations=50, seed=42)
    r2 = jade(rastrigin, [(-5.12, 5.12)] * 10, population=30, generations=50, seed=np.random.default_rng(42))
    assert r1.fun == r2.fun
    np.testing.assert_array_equal(r1.population, r2.population)
    r3 = jade(rastrigin, [(-5.12, 5.12)] * 10, population=30, generations=50, seed=43)
    assert r3.fun != r1.fun
    # the rng argument (SciPy >= 1.15): an int or a Generator, the same bits as seed=
    r4 = jade(rastrigin, [(-5.12, 5.12)] * 10, population=30, generations=50, rng=42)
    r5 = jade(rastrigin, [(-5.12, 5.12)] * 10, population=30, generations=50, rng=np.random.default_rng(42))
    np.testing.assert_array_equal(r4.population, r1.population)
    np.testing.assert_array_equal(r5.population, r1.population)
    with pytest.raises(ArgumentError, match="rng or seed"):
        jade(rastrigin, [(-5.12, 5.12)] * 2, population=8, generations=1, rng=1, seed=1)


def test_callback_stops_by_stopiteration():
    def cb(st):
        if st.nit == 4:
            raise StopIteration
    r = jade(sphere, [(-5, 5)] * 3, population=20, generations=100, rng=1, callback=cb)
    assert r.stop == "callback" and r.nit == 4


def test_stopping_criteria_and_result():
    r = jade(sphere, [(-5, 5)] * 3, population=20, generations=1000, seed=1, target=1e-6)
    assert r.stop == "target" and r.fun <= 1e-6 and r.nit < 1000 and r.success
    r = jade(sphere, [(-5, 5)] * 3, population=20, generations=1000, seed=1, max_evals=205)
    assert r.stop == "max_evals" and r.nfev == 200 and r.nit == 9
    r = jade(sphere, [(-5, 5)] * 3, population=20, generations=1000, seed=1, callback=lambda st: st.nit >= 7)
    assert r.stop == "callback" and r.nit == 7
    r = jade(sphere, [(-5, 5)] * 3, population=20, generations=12, seed=1)
    assert r.stop == "generations" and r.nit == 12 and r.nfev == 20 * 13
    for key in ("x", "fun", "nfev", "nit", "success", "message", "mu_f", "mu_cr"):
        assert key in r


def test_rescore_changes_pbest_choice():
    s = JadeSolver([(-1, 1)] * 2, 6, rng=9)
    s.ask()
    s.tell(np.arange(6.0))
    s.rescore(np.arange(6.0)[::-1].copy())
    assert s.best_index == 5
    with pytest.raises(ArgumentError, match="shape"):
        s.rescore(np.zeros(5))


@pytest.mark.parametrize("kwargs, msg", [
    (dict(bounds=[(1, 0)]), r"bounds\[0\]: low 1.0 must be less than up 0.0"),
    (dict(bounds=[(0, np.inf)]), "finite"),
    (dict(bounds=[(0, 1)], population=3), "population must be an integer >= 4"),
])
def test_bad_arguments(kwargs, msg):
    kw = dict(population=10, generations=5)
    kw.update(kwargs)
    b = kw.pop("bounds")
    with pytest.raises(ArgumentError, match=msg):
        jade(sphere, b, **kw)


def test_bad_costs():
    with pytest.raises(ArgumentError, match="must return 10 costs"):
        jade(lambda X: np.zeros(3), [(0, 1)], population=10, generations=2)
    with pytest.raises(ArgumentError, match="NaN"):
        jade(lambda X: np.full(len(X), np.nan), [(0, 1)], population=10, generations=2)
    s = JadeSolver([(0, 1)], 4, rng=1)
    with pytest.raises(ArgumentError, match="without a preceding ask"):
        s.tell(np.zeros(4))
