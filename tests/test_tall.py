"""The polish's least squares on a tall Jacobian reduced once (rideid.estimate.fit.tall): the same steps, rank and
singular values as numpy's lstsq of all of it, the same singular values and ``U^T y`` as SciPy's SVD, and SciPy's
dogbox and trf solved with them to the same answer."""

import numpy as np
import pytest
import scipy.linalg
from scipy.optimize import least_squares
from scipy.optimize._lsq import dogbox, trf

from rideid.estimate.fit.tall import BLOCK_ROWS, tall_lstsq, tall_r, tall_steps, tall_svd


def _tall(rng, m, n, rank_deficient=False):
    a = rng.standard_normal((m, n)) * np.logspace(0, 4, n)  # columns four decades apart, as a polish's are
    if rank_deficient:
        a[:, 5] = 2.0 * a[:, 3]
    return a, rng.standard_normal(m)


@pytest.mark.parametrize("m, n, rank_deficient", [(3 * BLOCK_ROWS + 17, 30, False), (3 * BLOCK_ROWS + 17, 30, True),
                                                  (5000, 25, True), (200, 12, False), (100, 30, False)])
def test_the_reduced_least_squares_is_numpys(m, n, rank_deficient):
    """The least-norm solution, rank and singular values of numpy's lstsq (rcond=-1, as dogbox asks, and None),
    to rounding; a rank-deficient matrix stays rank-deficient (the QR's rounding-level singular value is cut at
    eps * m, not eps: cut at eps it came back as 1e-15 of the largest and the step as 1e14)."""
    rng = np.random.default_rng(m + n)
    a, b = _tall(rng, m, n, rank_deficient)
    for rcond in (-1, None):
        x0, res0, rank0, s0 = np.linalg.lstsq(a, b, rcond=rcond)
        x1, res1, rank1, s1 = tall_lstsq(a, b, rcond=rcond)
        assert rank1 == rank0 == n - rank_deficient
        np.testing.assert_allclose(x1, x0, rtol=0, atol=1e-10 * np.abs(x0).max())
        np.testing.assert_allclose(s1, s0, rtol=1e-10, atol=1e-10 * s0[0])  # the zero one at rounding level
        np.testing.assert_allclose(res1, res0, rtol=1e-9)


def test_the_blocked_triangle_has_the_matrix_s_gram():
    """R^T R = a^T a and the same singular values, for a matrix of several blocks; a wide one is returned as it is."""
    rng = np.random.default_rng(7)
    a, _ = _tall(rng, 2 * BLOCK_ROWS + 5, 9)
    r = tall_r(a)
    assert r.shape == (9, 9)
    np.testing.assert_allclose(r.T @ r, a.T @ a, rtol=1e-10, atol=1e-10 * np.abs(a.T @ a).max())
    np.testing.assert_allclose(np.linalg.svd(r, compute_uv=False), np.linalg.svd(a, compute_uv=False), rtol=1e-10)
    wide = rng.standard_normal((10, 9))
    assert tall_r(wide) is not None and np.array_equal(tall_r(wide), wide)


def _polish_like(rng, runs=6, rows=3000, knots=12, car=16):
    """A Jacobian shaped as the polish's with distance corrections: the car's columns dense, each run's start
    nonzero on its run's rows, each of its knots on a stretch of them and on one prior row after all the runs';
    the residual last."""
    m = runs * rows + runs * knots
    n = car + runs * (1 + knots) + 1
    a = np.zeros((m, n))
    a[:, :car] = rng.standard_normal((m, car)) * np.logspace(0, 3, car)
    for r in range(runs):
        lo, c0 = r * rows, car + r * (1 + knots)
        a[lo:lo + rows, c0] = rng.standard_normal(rows)
        for k in range(knots):
            s = lo + k * rows // knots
            e = min(s + 2 * rows // knots, lo + rows)
            a[s:e, c0 + 1 + k] = rng.standard_normal(e - s)
            a[runs * rows + r * knots + k, c0 + 1 + k] = 3.0  # its prior row
    a[:, -1] = rng.standard_normal(m)
    return a


def test_a_jacobian_of_local_columns_is_reduced_run_by_run():
    """Columns local to groups of rows (each run's start and knots, the knots' prior rows apart from their runs')
    are reduced group by group: R^T R = a^T a and a^T a's singular values, the last row the last column's alone
    (the residual of a right-hand side there), the least squares and the Gauss-Newton step's length those of
    the whole matrix; a matrix without such columns keeps the blocked triangle."""
    from rideid.estimate.fit import tall
    from rideid.estimate.fit.polish import gauss_newton_length
    rng = np.random.default_rng(11)
    a = _polish_like(rng)
    groups, others = tall._local_groups(a)
    assert len(groups) == 6 and list(others) == list(range(16)) + [a.shape[1] - 1]
    assert all(c.size == 13 and r.size == 3000 + 12 for r, c in groups)
    r = tall_r(a)
    assert np.abs(np.tril(r, -1)).max() > 0  # not the triangle: the block-by-block reduction ran
    gram = a.T @ a
    np.testing.assert_allclose(r.T @ r, gram, rtol=0, atol=1e-12 * np.abs(gram).max())
    np.testing.assert_allclose(np.linalg.svd(r, compute_uv=False), np.linalg.svd(a, compute_uv=False), rtol=1e-10)
    assert np.all(r[-1, :-1] == 0) and abs(r[-1, -1]) > 0
    x0, res0, rank0, s0 = np.linalg.lstsq(a[:, :-1], a[:, -1], rcond=None)
    x1, res1, rank1, s1 = tall_lstsq(a[:, :-1], a[:, -1])
    assert rank1 == rank0
    np.testing.assert_allclose(x1, x0, rtol=0, atol=1e-10 * np.abs(x0).max())
    np.testing.assert_allclose(res1, res0, rtol=1e-9)
    dense = np.linalg.qr(a, mode="r")
    assert np.linalg.norm(r[:-1, -1]) == pytest.approx(np.linalg.norm(dense[:-1, -1]), rel=1e-10)
    J, f = a[:, :-1], a[:, -1]
    J[:, 16] *= 1e6  # a column far out of scale: the Gram matrix's condition fails and the QR decides
    assert gauss_newton_length(J, f) == pytest.approx(
        np.linalg.norm(np.linalg.qr(np.column_stack([J, f]), mode="r")[:-1, -1]), rel=1e-9)
    b = a.copy()
    b[:, 16:-1] = rng.standard_normal((b.shape[0], b.shape[1] - 17))  # every column dense: the plain triangle
    assert tall._local_groups(b) is None and np.allclose(np.tril(tall_r(b), -1), 0)


def test_the_right_hand_side_is_reduced_with_the_matrix_without_forming_them_together():
    """tall_r(a, b) is the reduction of ``[a | b]`` (never formed): the same matrix as tall_r of the two side by side,
    on a dense tall matrix (the blocked triangle) and on one of local columns (the block-by-block form), and
    ``[a | b]`` itself where it is not tall."""
    rng = np.random.default_rng(5)
    local = _polish_like(rng)
    dense, f = _tall(rng, 3 * BLOCK_ROWS + 17, 30)
    for a, b in ((local[:, :-1], local[:, -1]), (dense, f)):
        np.testing.assert_array_equal(tall_r(a, b), tall_r(np.column_stack([a, b])))
    wide = rng.standard_normal((40, 12))
    np.testing.assert_array_equal(tall_r(wide, wide[:, 0]), np.column_stack([wide, wide[:, 0]]))


def test_a_reduction_of_some_columns_is_the_one_of_their_copy_to_the_last_bit():
    """tall_r(a, b, cols) (without copying ``a[:, cols]``) is tall_r(a[:, cols], b) to the last bit, on a matrix of
    local columns (some of them left out) and on a dense one."""
    rng = np.random.default_rng(9)
    local = _polish_like(rng)
    a, b = local[:, :-1], local[:, -1]
    for cols in (np.delete(np.arange(a.shape[1]), [3, 17, 40]), np.arange(a.shape[1])):
        np.testing.assert_array_equal(tall_r(a, b, cols), tall_r(a[:, cols], b))
    dense, f = _tall(rng, 3 * BLOCK_ROWS + 17, 30)
    cols = np.delete(np.arange(30), [0, 29])
    np.testing.assert_array_equal(tall_r(dense, f, cols), tall_r(dense[:, cols], f))
    np.testing.assert_array_equal(tall_r(dense, None, cols), tall_r(dense[:, cols]))


def test_dogboxs_step_takes_the_reduction_the_watch_kept_and_only_that_one(monkeypatch):
    """rideid.estimate.fit.tall.reduced keeps ``[J | f]``'s reduction on the thread inside tall_steps; tall_lstsq of
    ``J`` and ``-f`` (dogbox's step, every unknown free) takes it without reducing again, with the same numbers
    as a reduction afresh to the last bit; a step with fewer columns (unknowns held on a bound), another right-hand
    side or another matrix (a row the check reads, or one it does not) reduces its own; nothing is kept after
    tall_steps or outside it."""
    from rideid.estimate.fit import tall
    rng = np.random.default_rng(7)
    a = _polish_like(rng)
    J, f = a[:, :-1].copy(), a[:, -1].copy()
    J[:, 20] = 0.0
    count = {"n": 0}
    real = tall.tall_r
    monkeypatch.setattr(tall, "tall_r", lambda *x, **k: (count.__setitem__("n", count["n"] + 1), real(*x, **k))[1])
    fresh = tall_lstsq(J, -f, rcond=-1)
    tall.reduced(J, f)
    assert getattr(tall._kept, "value", None) is None  # outside tall_steps: nothing kept
    with tall_steps():
        tall.reduced(J, f)
        assert count["n"] == 3
        kept = tall_lstsq(J, -f, rcond=-1)
        assert count["n"] == 3  # the kept one
        assert all(np.array_equal(k, r) for k, r in zip(kept, fresh))
        want = np.linalg.lstsq(J, -f, rcond=np.finfo(float).eps * J.shape[0])
        np.testing.assert_allclose(kept[0], want[0], rtol=0, atol=1e-10 * np.abs(want[0]).max())
        assert kept[2] == want[2] == J.shape[1] - 1  # the column of zeros
        tall_lstsq(np.delete(J, 3, axis=1), -f, rcond=-1)
        g = f.copy()
        g[0] += 1.0
        tall_lstsq(J, -g, rcond=-1)
        for row in (5 * tall.CHECK_EVERY, 5 * tall.CHECK_EVERY + 1):  # a row the check reads, and one it does not
            moved = J.copy()
            moved[row, 2] += 1.0
            tall_lstsq(moved, -f, rcond=-1)
        assert count["n"] == 7  # each reduced its own
        cols = np.delete(np.arange(J.shape[1]), 3)  # an unknown held on its bound: the columns dogbox takes
        tall.reduced(J, f, cols)
        held = tall_lstsq(J[:, cols], -f, rcond=-1)
        assert count["n"] == 8
        tall._kept.value = None
        assert all(np.array_equal(k, r) for k, r in zip(held, tall_lstsq(J[:, cols], -f, rcond=-1)))
    assert tall._kept.value is None


def test_the_jacobians_scale_is_scipys():
    """rideid.estimate.fit.tall.jac_scale (without the squares' copy) is SciPy's compute_jac_scale to rounding,
    a column of zeros scaled 1 at the start and the old scale kept where larger."""
    from scipy.optimize._lsq.common import compute_jac_scale

    from rideid.estimate.fit.tall import jac_scale
    rng = np.random.default_rng(2)
    J = rng.standard_normal((5000, 9)) * np.logspace(-3, 3, 9)
    J[:, 4] = 0.0
    for old in (None, np.full(9, 50.0)):
        for got, want in zip(jac_scale(J, old), compute_jac_scale(J, old)):
            np.testing.assert_allclose(got, want, rtol=1e-13)


def _exponential_fit(method):
    """A bounded exponential-and-sine fit of 40 000 residuals (the amplitude's bound below its true value) and the
    least squares' options with ``method``."""
    rng = np.random.default_rng(3)
    t = np.linspace(0, 10, 40000)
    y = 2.0 * np.exp(-0.3 * t) + 0.5 * np.sin(1.7 * t) + 0.01 * rng.standard_normal(t.size)

    def f(p):
        return p[0] * np.exp(-p[1] * t) + p[2] * np.sin(p[3] * t) - y

    return f, dict(bounds=([0, 0, 0, 1.0], [5, 2, 0.45, 3]), method=method, x_scale="jac", ftol=1e-15, xtol=1e-12,
                   gtol=1e-15)


def test_dogbox_reaches_the_same_fit_and_scipy_is_left_as_it_was():
    """A bounded exponential fit, 40 000 residuals: dogbox with the reduced steps ends where it ends with its own
    (to 1e-10), its lstsq swapped only while inside (threads counted) and put back after."""
    f, kw = _exponential_fit("dogbox")
    own = dogbox.lstsq
    plain = least_squares(f, [1.5, 0.2, 0.3, 1.65], **kw)
    with tall_steps():
        assert dogbox.lstsq.own is own
        with tall_steps():
            reduced = least_squares(f, [1.5, 0.2, 0.3, 1.65], **kw)
        assert dogbox.lstsq.own is own  # the outer user is still inside
    assert dogbox.lstsq is own
    assert plain.x[2] == reduced.x[2] == 0.45  # the amplitude (0.5 in the data) held on its bound
    np.testing.assert_allclose(reduced.x, plain.x, rtol=1e-10)
    np.testing.assert_allclose(reduced.x[[0, 1, 3]], [2.0, 0.3, 1.7], rtol=0.05)


def test_the_polishs_watch_hands_dogbox_its_reductions_and_the_fit_is_the_same(monkeypatch):
    """The polish's watch (rideid.estimate.fit.polish.Progress) keeps each point's reduction of ``[J | f]``; dogbox's
    step from that point takes it (counted: every step after the first), on all four unknowns while they are free
    and on three while the amplitude is held on its bound (the watch reduces the columns dogbox will take); with
    the watch's reductions taken or every step reduced afresh the fit is the same to the last bit, and SciPy's own
    unwatched fit to 1e-7 (the watch ends it once a Gauss-Newton step would move it by less than 0.05 of its
    standard errors)."""
    from rideid.estimate.fit import tall
    from rideid.estimate.fit.polish import Progress
    f, kw = _exponential_fit("dogbox")
    lo = np.array([0, 0, 0, 1.0])
    t = np.linspace(0, 10, 40000)
    memo = {}

    def jac(p):
        J = np.column_stack([np.exp(-p[1] * t), -p[0] * t * np.exp(-p[1] * t), np.sin(p[3] * t),
                             p[2] * t * np.cos(p[3] * t)])
        memo["J"] = (p.copy(), J)
        return J

    def at(p):
        return memo["J"][1] if np.array_equal(memo["J"][0], p) else None

    hits, real, afresh = [], tall._recall, [False]
    monkeypatch.setattr(tall, "_recall", lambda a, b: (
        hits.append((a.shape[1], (r := None if afresh[0] else real(a, b)) is not None)), r)[1])
    for top, amplitude in ((0.6, 0.5), (0.45, 0.45)):  # the amplitude (0.5 in the data) free, then held on its bound
        kw["bounds"] = ([0, 0, 0, 1.0], [5, 2, top, 3])
        fits, seen = [], []
        for afresh[0] in (False, True):
            hits.clear()
            with tall_steps():
                fits.append(least_squares(f, [1.5, 0.2, 0.3, 1.65], jac=jac, **kw, callback=Progress(
                    4, crawl=False, jacobian=at, bounds=(lo, np.array([5, 2, top, 3])))))
            seen.append(list(hits))
        free = 4 if top > amplitude else 3
        assert len(seen[0]) >= 3 and seen[0][0] == (4, False) and set(seen[0][1:]) == {(free, True)}, seen[0]
        assert not any(took for _, took in seen[1])
        assert np.array_equal(fits[0].x, fits[1].x)
        assert fits[0].x[2] == pytest.approx(amplitude, rel=0.02)
        plain = least_squares(f, [1.5, 0.2, 0.3, 1.65], jac=jac, **kw)
        np.testing.assert_allclose(fits[0].x, plain.x, rtol=1e-7)


@pytest.mark.parametrize("m, n, rank_deficient", [(3 * BLOCK_ROWS + 17, 30, False), (2 * BLOCK_ROWS + 3, 40, True),
                                                  (5000, 25, True), (100, 30, False)])
def test_the_reduced_svd_is_scipys(m, n, rank_deficient):
    """tall_svd: SciPy's singular values and right vectors, and ``U^T y`` (all trf asks of ``U``); the products
    ``V diag(1/s) U^T y`` over the nonzero singular values (sign-free: a vector's sign is the SVD's choice) the
    same: to rounding by the blocked QR (rank-deficient matrices; a last block shorter than the matrix is wide,
    17 rows of 30 columns), to rounding times the condition number squared by the Gram matrix (full rank, columns
    four decades apart: 2e-8)."""
    rng = np.random.default_rng(m + n)
    a, y = _tall(rng, m, n, rank_deficient)
    u0, s0, vt0 = scipy.linalg.svd(a, full_matrices=False)
    u1, s1, vt1 = tall_svd(a, full_matrices=False)
    k = s0 > 1e-10 * s0[0]
    assert k.sum() == n - rank_deficient
    gram = not rank_deficient and m >= 4 * n  # full rank and tall: from the Gram matrix
    assert type(u1).__name__ == ("_GramU" if gram else "_ReducedU" if m >= 4 * n else "ndarray")
    tol = 1e-10 if not gram else 1e-15 * (s0[0] / s0[-1]) ** 2
    np.testing.assert_allclose(s1, s0, rtol=tol, atol=1e-12 * s0[0])
    p0 = vt0[k].T @ (u0.T.dot(y)[k] / s0[k])
    p1 = vt1[k].T @ (u1.T.dot(y)[k] / s1[k])
    np.testing.assert_allclose(p1, p0, rtol=0, atol=tol * np.abs(p0).max())
    np.testing.assert_allclose(np.abs(u1.T.dot(y)[k]), np.abs(u0.T.dot(y)[k]), rtol=max(tol, 1e-8))


def test_trf_reaches_the_same_fit_and_scipy_is_left_as_it_was():
    """The bounded exponential fit of the dogbox test by trf: with the reduced SVD inside tall_steps it ends where
    it ends with SciPy's own (to 1e-9), SciPy's svd put back after."""
    f, kw = _exponential_fit("trf")
    own = trf.svd
    plain = least_squares(f, [1.5, 0.2, 0.3, 1.65], **kw)
    with tall_steps():
        assert trf.svd.own is own and dogbox.lstsq.own is not None  # SciPy's own behind this thread's dispatch
        reduced = least_squares(f, [1.5, 0.2, 0.3, 1.65], **kw)
    assert trf.svd is own
    np.testing.assert_allclose(reduced.x, plain.x, rtol=1e-9)
    assert reduced.x[2] == pytest.approx(0.45, rel=1e-6)  # the amplitude held at its bound


def test_only_the_thread_inside_takes_the_reduced_steps(monkeypatch):
    """While one thread is inside tall_steps, a least squares on another thread at the same time takes SciPy's own
    lstsq and SVD, the thread inside the reduced ones (counted by spies); after, SciPy's own functions are back."""
    import threading

    from rideid.estimate.fit import tall
    calls = {"tall_lstsq": 0, "tall_svd": 0}
    for name in calls:
        real = getattr(tall, name)
        monkeypatch.setattr(tall, name, lambda *a, _real=real, _name=name, **k: (
            calls.__setitem__(_name, calls[_name] + 1), _real(*a, **k))[1])
    own = (dogbox.lstsq, trf.svd)
    A = np.random.default_rng(1).standard_normal((3000, 4))
    b = A @ np.arange(4.0)
    other = {}
    with tall_steps():
        t = threading.Thread(target=lambda: other.update(x=dogbox.lstsq(A, b, rcond=-1)[0], s=trf.svd(A)[1]))
        t.start()
        t.join()
        assert calls == {"tall_lstsq": 0, "tall_svd": 0}  # the other thread took SciPy's own
        inside = dogbox.lstsq(A, b, rcond=-1)[0], trf.svd(A, full_matrices=False)[1]
        assert calls == {"tall_lstsq": 1, "tall_svd": 1}
    np.testing.assert_allclose(inside[0], other["x"], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(inside[1], other["s"], rtol=1e-10)
    assert (dogbox.lstsq, trf.svd) == own
