"""Least squares on a tall Jacobian, reduced once: a QR of ``[J | f]`` leaves an ``n x n`` problem with the same
solution and singular values.

The polish's Jacobian has a row per residual (every run's samples times its channels: 60 000 to 300 000) and a
column per unknown (12 to 60). :func:`numpy.linalg.lstsq` (LAPACK ``gelsd``: a bidiagonalisation and an SVD of
all of it) took 0.38 s a step on the all-realities SUV, 38 % of the polish (docs/performance.md#the-tall-jacobian);
a blocked Householder QR of the same matrix leaves a square problem of the columns' size (0.085 s against 0.16 s
on a 300 000 x 30 matrix, two cores). :func:`tall_lstsq` is that for SciPy's ``dogbox`` (:func:`tall_steps`
swaps it in while the polish's ``least_squares`` runs, on the polish's thread alone), :func:`tall_svd` for SciPy's
``trf`` (from the Gram matrix where the columns are well-conditioned, else an SVD of the triangle, its left vectors
kept as the blocks' Householder reflections: 1.15 s a step of the all-realities SUV's 155 unknowns before, 0.06 s now;
docs/performance.md#the-all-realities-suv-under-two-minutes), :func:`tall_r` the same reduction for the
covariance's SVD.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager

import numpy as np
from scipy import linalg
from scipy.linalg import lapack

from scipy.optimize._lsq import dogbox as _dogbox
from scipy.optimize._lsq import trf as _trf
from scipy.optimize._lsq.common import compute_jac_scale as _compute_jac_scale

from ...settings import defaults

#: a matrix at least this many times taller than wide is reduced first (below, LAPACK's own lstsq is as quick)
TALL = 4


#: rows per block of the blocked QR (:func:`tall_r`): 0.08 s against 0.18 s for one QR of a 300 000 x 31 matrix
#: (two cores; 8192-32768 rows alike, 1024 0.12 s)
BLOCK_ROWS = 16384


def tall_r(a, b=None, cols=None) -> np.ndarray:
    """The triangle ``R`` ``(n, n)`` of a QR of ``a`` ``(m, n)`` when ``a`` is tall (else ``a`` itself): the same
    singular values and right singular vectors, ``R^T R = a^T a``. A blocked QR (each block of
    :data:`BLOCK_ROWS` rows reduced to its triangle, then the stacked triangles once): the blocks stay in cache,
    2.3x quicker than one QR of it all, the triangle the same up to rows' signs (1e-13 relative).

    ``b`` ``(m,)``: the same of ``[a | b]``, never formed (a copy of a 100 000 x 300 Jacobian took longer than its
    reduction: 0.2 s against 0.13 s); each block of rows takes its part of ``b`` as it is read. ``cols`` (indices,
    ascending): the same of ``a[:, cols]`` (without its copy), to the last bit.

    A matrix with many columns local to a few rows (each run's start and distance corrections: nonzero on that
    run's residuals and their priors only) is reduced group by group (:func:`_block_angular_r`); its ``R`` is then
    the triangle of ``a`` with its columns reordered (the local ones of each group first, the others last, the
    last column always among them), put back in ``a``'s column order: ``R^T R = a^T a`` still, its last row the last
    column's alone (the residual of a right-hand side there), but not triangular."""
    a = np.asarray(a, dtype=float)
    b = None if b is None else np.asarray(b, dtype=float)
    if cols is not None and len(cols) == a.shape[1]:
        cols = None
    cmap = None if cols is None else np.asarray(cols, dtype=int)
    m, n = a.shape[0], (a.shape[1] if cmap is None else cmap.size) + (b is not None)
    if not n or m < TALL * n:
        return _take(a, b, slice(None), cmap=cmap)
    if n >= LOCAL_MIN_COLUMNS:
        r = _block_angular_r(a, b, cmap)
        if r is not None:
            return r
    return _dense_r(a, b, cmap)


def _take(a, b, rows, cols=None, cmap=None) -> np.ndarray:
    """Rows ``rows`` (a slice or indices) of ``[a[:, cmap] | b]`` (``b`` None: of ``a[:, cmap]``; ``cmap`` None: of
    every column of ``a``), at columns ``cols`` (indices into that matrix, ascending where ``b``'s is among them;
    None: every column)."""
    if cols is None:
        part = a[rows] if cmap is None else a[rows][:, cmap]
        return part if b is None else np.column_stack([part, b[rows]])
    cols = np.asarray(cols)
    with_b = b is not None and cols.size and cols[-1] == (a.shape[1] if cmap is None else cmap.size)
    ac = cols[:-1] if with_b else cols
    ac = ac if cmap is None else cmap[ac]
    part = a[np.ix_(np.arange(a.shape[0])[rows] if isinstance(rows, slice) else rows, ac)]
    return np.column_stack([part, b[rows]]) if with_b else part


def _dense_r(a, b=None, cmap=None) -> np.ndarray:
    """:func:`tall_r` of ``[a[:, cmap] | b]`` (at least as many rows as columns) without regard to its zeros."""
    m = a.shape[0]
    if m <= BLOCK_ROWS:
        return np.linalg.qr(_take(a, b, slice(None), cmap=cmap), mode="r")
    return np.linalg.qr(np.vstack([np.linalg.qr(_take(a, b, slice(i, i + BLOCK_ROWS), cmap=cmap), mode="r")
                                   for i in range(0, m, BLOCK_ROWS)]), mode="r")


#: rows per block when looking for local columns (:func:`_local_groups`)
ROW_BLOCK = 256
#: a matrix of at least this many columns is looked at for columns local to a few rows (:func:`tall_r`): the look
#: reads each column in the blocks of rows it touches (0.1 s at 100 000 x 300, where a QR of it all takes 0.8 s;
#: the QR of 100 000 x 30 takes 15 ms)
LOCAL_MIN_COLUMNS = 64


def _local_groups(a, b=None, cmap=None) -> tuple[list, np.ndarray] | None:
    """The columns of ``a`` nonzero in fewer than half its blocks of :data:`ROW_BLOCK` rows, grouped with the rows
    they touch (two such columns that share a row share a group; the rows in any order, since a QR's
    ``R^T R = a^T a`` does not depend on it): ``([(rows, columns)], the other columns)``, the last column always
    among the others (``b``'s, when given, as column ``n`` of ``[a | b]``); None when fewer than half the columns
    are local, or a group has fewer rows than its columns and the others. The polish's distance corrections are
    each nonzero on a stretch of their run's residuals and on a prior row after all the runs'. Each column's rows
    are read in the blocks it touches only (0.1 s at 100 000 x 300, against 0.5 s for the nonzeros of it all).
    ``cmap``: of ``a[:, cmap]`` (the columns numbered as there)."""
    m, n = a.shape
    B = ROW_BLOCK
    whole = m - m % B
    touched = (a[:whole] != 0).reshape(-1, B, n).any(axis=1)  # along the rows' memory order: 3 ms at 100 000 x 300
    if whole < m:
        touched = np.vstack([touched, (a[whole:] != 0).any(axis=0)])
    if cmap is not None:
        touched, n = touched[:, cmap], cmap.size
    local = touched.any(axis=0) & (touched.sum(axis=0) < touched.shape[0] // 2)
    if b is None:
        local[-1] = False
    else:
        local = np.append(local, False)
        n += 1
    if local.sum() < n // 2:
        return None
    root = list(range(n))

    def find(j):
        while root[j] != j:
            root[j] = root[root[j]]
            j = root[j]
        return j

    cols = np.flatnonzero(local)
    owner = np.full(m, -1)
    for j in cols:
        rows = np.concatenate([np.arange(k * B, min(k * B + B, m)) for k in np.flatnonzero(touched[:, j])])
        rows = rows[a[rows, j if cmap is None else cmap[j]] != 0]
        prev = owner[rows]
        prev = prev[prev >= 0]
        for g in set(prev[np.r_[True, prev[1:] != prev[:-1]]].tolist()) if prev.size else ():  # owners come in runs
            root[find(g)] = j
        owner[rows] = j
    col_root = np.array([find(j) for j in range(n)])
    group = col_root[cols]
    row_group = np.where(owner >= 0, col_root[np.maximum(owner, 0)], -1)
    others = np.flatnonzero(~local)
    groups = [(np.flatnonzero(row_group == g), cols[group == g]) for g in np.unique(group)]
    if any(r.size < c.size + others.size for r, c in groups):
        return None
    return groups, others


def _block_angular_r(a, b=None, cmap=None) -> np.ndarray | None:
    """:func:`tall_r` of a tall ``[a | b]`` whose columns are mostly local to groups of rows (:func:`_local_groups`;
    None when they are not): each group's rows reduced on its own columns and the others (a QR of
    ``rows x (local + others)``), the others' remaining rows of every group stacked with the rows outside any group
    and reduced once. On the polish of the built-in car's ten runs with every reality (105 000 x 297: the car's
    16, ten starts, 271 distance corrections) 0.26 s against 0.80 s for the blocked QR of it all, ``R^T R`` the
    same to 1e-17 (tests/test_tall.py)."""
    found = _local_groups(a, b, cmap)
    if found is None:
        return None
    groups, others = found
    m, n = a.shape[0], (a.shape[1] if cmap is None else cmap.size) + (b is not None)
    k = others.size
    order = np.concatenate([c for _, c in groups] + [others])
    R = np.zeros((n, n))
    rest, row, covered = [], 0, np.zeros(m, dtype=bool)
    for rows, cols in groups:
        c = cols.size
        r = _dense_r(_take(a, b, rows, np.concatenate([cols, others]), cmap))
        R[row:row + c, row:row + c] = r[:c, :c]
        R[row:row + c, n - k:] = r[:c, c:]
        rest.append(r[c:, c:])
        row += c
        covered[rows] = True
    outside = _take(a, b, np.flatnonzero(~covered), others, cmap)
    if outside.shape[0]:
        rest.append(outside)
    R[n - k:, n - k:] = _dense_r(np.vstack(rest))[:k]
    out = np.empty((n, n))
    out[:, order] = R
    return out


#: this thread's reduction of the last Jacobian and residuals the polish's watch looked at (:func:`reduced`), kept
#: for the Gauss-Newton step SciPy's dogbox solves next from the same Jacobian (:func:`tall_lstsq`)
_kept = threading.local()
#: rows compared of a step's columns and the kept Jacobian's (every this many; :func:`_recall`)
CHECK_EVERY = 97


def reduced(J, f, cols=None) -> np.ndarray:
    """:func:`tall_r` of ``[J[:, cols] | f]`` (``cols`` None: every column); inside :func:`tall_steps`, kept on this
    thread, so that SciPy's dogbox's step from the same ``J`` and ``f`` on those columns takes it instead of
    reducing them again (:func:`tall_lstsq`: the polish's watch and dogbox's step each reduced the same
    105 000 x 297 matrix on the ten-run real test)."""
    cols = np.arange(J.shape[1]) if cols is None else np.asarray(cols, dtype=int)
    T = tall_r(J, f, cols)
    if getattr(_inside, "depth", 0) and T.shape[0] == T.shape[1]:
        _kept.value = (J, f, cols, T, _column_norms(J)[cols])
    return T


def _column_norms(a) -> np.ndarray:
    return np.einsum("ij,ij->j", a, a)


def _recall(a, b):
    """The kept reduction of ``[J[:, cols] | f]`` (:func:`reduced`) as the one of ``[a | b]``, when ``a`` is
    ``J[:, cols]`` and ``b`` is ``-f`` (dogbox's step), else None: ``[J[:, cols] | -f]``'s is ``T`` with its last
    column negated, to the last bit, so the step is the one reduced afresh. Checked, not assumed: ``b`` against
    ``-f`` exactly, the columns' count, ``a`` against those columns of ``J`` on every :data:`CHECK_EVERY`-th row
    exactly and in every column's sum of squares (to 1e-12: a column that differs off the rows read; 15 ms at
    105 000 x 297, against 0.13-0.2 s for the reduction)."""
    kept = getattr(_kept, "value", None)
    if kept is None:
        return None
    J, f, cols, T, norms = kept
    if a.shape != (J.shape[0], cols.size) or b.shape != f.shape or not np.array_equal(b, -f):
        return None
    if (not np.array_equal(a[::CHECK_EVERY], J[::CHECK_EVERY][:, cols])
            or not np.allclose(_column_norms(a), norms, rtol=1e-12, atol=0)):
        return None
    M = T.copy()
    M[:, -1] *= -1.0
    return M


def tall_lstsq(a, b, rcond=None):
    """:func:`numpy.linalg.lstsq` of a tall ``a`` ``(m, n)`` and one right-hand side ``b`` ``(m,)``, reduced first:
    ``[R | c]`` the triangle of a QR of ``[a | b]``, then ``lstsq(R, c[:n], rcond)``, whose least-norm solution,
    rank and singular values are ``a``'s (``|a x - b|^2 = |R x - c|^2 + c_n^2``). Returns the same four items
    (the residual's squared norm only at full rank, as numpy). ``rcond`` None or negative (machine precision, as
    dogbox asks) cuts at ``eps * m``. The reduction the polish's watch kept for this ``a`` and ``b`` is taken
    (:func:`reduced`). Other shapes go to numpy's own."""
    a, b = np.asarray(a), np.asarray(b)
    m, n = a.shape if a.ndim == 2 else (0, 0)
    if b.ndim != 1 or not n or m < TALL * (n + 1):
        return np.linalg.lstsq(a, b, rcond=rcond)
    r = _recall(a, b)
    if r is None:
        r = tall_r(a, b)
    if rcond is None or rcond < 0:
        # the singular values a full SVD puts at rounding level (eps * s_max) come out of the QR up to m * eps:
        # numpy's own default cut-off, eps * max(m, n), keeps a rank-deficient a rank-deficient
        rcond = np.finfo(float).eps * m
    x, _, rank, s = np.linalg.lstsq(r[:n, :n], r[:n, n], rcond=rcond)
    resid = np.array([r[n, n] ** 2]) if rank == n and r.shape[0] > n else np.empty(0)
    return x, resid, rank, s


def _geqrf(a):
    """LAPACK's Householder QR of ``a`` ``(m, n)``: its reflections and factors, and its triangle ``(min(m, n), n)``."""
    h, tau, _, info = lapack.dgeqrf(np.asarray(a, dtype=float))
    if info != 0:
        raise np.linalg.LinAlgError(f"dgeqrf: info {info}")
    return h, tau, np.triu(h[:min(a.shape), :])


def _qt(h, tau, c) -> np.ndarray:
    """``Q^T c`` of the reflections ``(h, tau)`` of :func:`_geqrf`: the first ``min(m, n)`` entries."""
    k = tau.size
    out, _, info = lapack.dormqr("L", "T", h[:, :k], tau, np.asarray(c, dtype=float)[:, None], max(1, k) * 64)
    if info != 0:
        raise np.linalg.LinAlgError(f"dormqr: info {info}")
    return out[:k, 0]


class _LeftVectors:
    """Left singular vectors that only compute ``U^T y`` (``U.T.dot(y)``, all SciPy's trf asks of them)."""

    @property
    def T(self):  # noqa: N802 (numpy's name)
        return self


class _ReducedU(_LeftVectors):
    """The left singular vectors ``U = Q U_R`` of a tall matrix reduced by a blocked QR (:func:`tall_svd`), kept
    as the QR's reflections: ``U.T.dot(y)`` (all SciPy's trf asks of them) is ``U_R^T Q^T y``."""

    def __init__(self, blocks, top, u_r):
        self.blocks, self.top, self.u_r = blocks, top, u_r

    def dot(self, y):
        y = np.asarray(y, dtype=float)
        c = np.concatenate([_qt(h, tau, y[i:i + h.shape[0]]) for i, h, tau in self.blocks])
        if self.top is not None:
            c = _qt(*self.top, c)
        return self.u_r.T @ c


class _GramU(_LeftVectors):
    """The left singular vectors ``U = a V diag(1/s)`` of a well-conditioned tall ``a`` whose SVD came from its
    Gram matrix (:func:`tall_svd`): ``U.T.dot(y)`` is ``diag(1/s) V^T (a^T y)``, one product with ``a``."""

    def __init__(self, a, v, s):
        self.a, self.v, self.s = a, v, s

    def dot(self, y):
        return (self.v.T @ (self.a.T @ np.asarray(y, dtype=float))) / self.s


def tall_svd(a, full_matrices=True, **kw):
    """:func:`scipy.linalg.svd` of a tall ``a`` ``(m, n)`` (``full_matrices=False``, as trf asks) reduced first:
    from the eigenvectors of ``a^T a`` while their condition is above setting ``identify.gram_rcond`` (the left
    vectors a :class:`_GramU`), else the triangle ``R`` of a blocked QR (:func:`tall_r`'s blocks) and the SVD of
    ``R``, the left vectors a :class:`_ReducedU`: the same singular values and right vectors, and ``U^T y``.
    Other shapes and options go to SciPy's own."""
    a = np.asarray(a)
    m, n = a.shape if a.ndim == 2 else (0, 0)
    if full_matrices or kw or not n or m < TALL * n:
        return linalg.svd(a, full_matrices=full_matrices, **kw)
    w, v = np.linalg.eigh(a.T @ a)
    if w[-1] > 0 and w[0] > defaults["identify.gram_rcond"] * w[-1]:
        # well-conditioned (below 1e5): the Gram matrix's eigenvectors are the right singular vectors to
        # rounding, one product of a (0.06 s against 0.22 s for the blocked QR of 100 000 x 157)
        s = np.sqrt(w[::-1])
        return _GramU(a, v[:, ::-1], s), s, v[:, ::-1].T
    blocks, tri = [], []
    for i in range(0, m, BLOCK_ROWS):
        h, tau, r = _geqrf(a[i:i + BLOCK_ROWS])
        blocks.append((i, h, tau))
        tri.append(r)
    top = None
    if len(blocks) > 1:
        h, tau, r = _geqrf(np.vstack(tri))
        top = (h, tau)
    else:
        r = tri[0]
    u_r, s, vt = linalg.svd(r, full_matrices=False)
    return _ReducedU(blocks, top, u_r), s, vt


def jac_scale(J, scale_inv_old=None):
    """SciPy's ``compute_jac_scale`` of a dense ``J`` (``x_scale="jac"``: each column's norm, at least the last
    one's; a column of zeros scaled 1 at the start) without the squares' temporary: ``np.sum(J**2, axis=0)`` wrote
    a copy of the Jacobian each step (0.05-0.37 s at 105 000 x 297, against 0.015 s for the same sums by
    :func:`numpy.einsum`; 12 s of the ten-run real test's polish)."""
    if not isinstance(J, np.ndarray):
        return _compute_jac_scale(J, scale_inv_old)
    scale_inv = np.sqrt(np.einsum("ij,ij->j", J, J))
    if scale_inv_old is None:
        scale_inv[scale_inv == 0] = 1
    else:
        scale_inv = np.maximum(scale_inv, scale_inv_old)
    return 1 / scale_inv, scale_inv


_lock = threading.Lock()
_users = [0]
#: this thread's depth inside :func:`tall_steps` (the module attributes are SciPy's for every thread; a call from a
#: thread that is not inside takes SciPy's own function)
_inside = threading.local()


def _dispatch(own, name: str):
    """SciPy's ``own`` function, or this module's ``name`` (looked up at the call) on a thread inside
    :func:`tall_steps`."""
    def call(*args, **kwargs):
        return (globals()[name] if getattr(_inside, "depth", 0) else own)(*args, **kwargs)
    call.own = own
    return call


@contextmanager
def tall_steps():
    """While inside, SciPy's ``dogbox`` solves its Gauss-Newton steps with :func:`tall_lstsq`, its ``trf`` takes
    its SVDs from :func:`tall_svd`, and both their scales from :func:`jac_scale` on this thread: the modules'
    attributes dispatch on the calling thread (another thread's least squares at the same time takes SciPy's
    own), put back when the last thread leaves (counted). Without those module attributes (a SciPy that no longer
    has them) nothing is changed."""
    swaps = [(mod, name, new) for mod, name, new in ((_dogbox, "lstsq", "tall_lstsq"), (_trf, "svd", "tall_svd"),
                                                     (_dogbox, "compute_jac_scale", "jac_scale"),
                                                     (_trf, "compute_jac_scale", "jac_scale"))
             if hasattr(mod, name)]
    with _lock:
        if _users[0] == 0:
            for mod, name, new in swaps:
                setattr(mod, name, _dispatch(getattr(mod, name), new))
        _users[0] += 1
    _inside.depth = getattr(_inside, "depth", 0) + 1
    try:
        yield
    finally:
        _inside.depth -= 1
        if not _inside.depth:
            _kept.value = None  # a Jacobian's worth of memory
        with _lock:
            _users[0] -= 1
            if _users[0] == 0:
                for mod, name, _ in swaps:
                    setattr(mod, name, getattr(mod, name).own)
