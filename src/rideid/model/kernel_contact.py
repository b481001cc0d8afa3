"""The disc envelope's lattice search and its interpolation, compiled (Numba); imported only by
:mod:`rideid.model.backend`.

:func:`rideid.model.contact.lattice_max` calls :func:`lattice_max` where it can be built, else its NumPy brute
force :func:`rideid.model.contact.lattice_max_numpy` (the same maxima); :func:`rideid.model.contact.wheel_input`
calls :func:`interp_grid`, else ``numpy.interp`` (the same values to rounding), and
:func:`rideid.model.contact.wheel_input_slope` :func:`slope_grid`, else its own NumPy arithmetic (the same).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def lattice_max(H, circ):  # pragma: no cover - compiled
    """``max_j H[i + j] + circ[j]`` and its (first) argmax for every i.

    ``circ`` is a disc's height on the lattice: a concave sequence. Then the
    matrix ``M[i, k] = H[k] + circ[k - i]`` (``-inf`` off the disc) is
    inverse-Monge (``M[i, k'] + M[i', k] >= M[i, k] + M[i', k']`` for
    ``i < i'``, ``k' < k``: ``circ``'s inner pair against its outer pair),
    so the first argmax ``k(i)`` never decreases with ``i``: the row in the
    middle of a range is searched over its whole column range, the rows
    above it only up to its argmax, the rows below only from it (divide and
    conquer, ``O((n + m) log n)`` for ``n`` positions and ``m`` offsets
    against ``O(n m)``). Rounding cannot reorder the maxima: the inequality
    holds with a margin of ``circ``'s second difference (``dx^2 / R``, about
    1e-6 m at the grid's step) against rounding near 1e-16 m. The result is
    the brute-force search's, exactly (tested on flat, rough, sine, stepped,
    white and spiked roads). 5x faster than the former block-pruned search
    on a 1 km random road, and free of its worst case (rough roads, where
    little could be pruned).
    """
    n = H.size - circ.size + 1
    m = circ.size
    best = np.empty(max(n, 0))
    arg = np.empty(max(n, 0), dtype=np.int64)
    if n <= 0:
        return best, arg
    # pending (row lo, row hi, column lo, column hi), inclusive, columns in H; the rows before the middle are
    # taken next, so at most one range per halving waits (130 rows: ample for any array)
    stack = np.empty((130, 4), dtype=np.int64)
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, n - 1, 0, H.size - 1
    top = 1
    while top > 0:
        top -= 1
        ilo, ihi, klo, khi = stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3]
        mid = (ilo + ihi) // 2
        a = max(klo, mid)
        b = min(khi, mid + m - 1)
        bv = -np.inf
        bk = a
        for k in range(a, b + 1):
            v = H[k] + circ[k - mid]
            if v > bv:
                bv = v
                bk = k
        best[mid] = bv
        arg[mid] = bk - mid
        if mid < ihi:
            stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = mid + 1, ihi, bk, khi
            top += 1
        if ilo < mid:
            stack[top, 0], stack[top, 1], stack[top, 2], stack[top, 3] = ilo, mid - 1, klo, bk
            top += 1
    return best, arg


@numba.njit(cache=True, nogil=True)
def interp_grid(x, shift, x0, step, vals, out):  # pragma: no cover - compiled
    """``out[i]`` = ``vals`` (tabulated at ``x0 + step k``) linearly interpolated at ``x[i] + shift``, zero outside
    the table: ``numpy.interp(x + shift, x0 + step * arange(n), vals, left=0, right=0)`` without its binary search
    (the grid is uniform, so a position's cell is one division) or its temporaries (``out`` may be a column of a
    wider array). The input moments' quadrature reads the envelope at 60-200 points per sample interval, and that
    was most of a run's preparation (7.0 of its 8.4 ms on a 5 s run)."""
    last = vals.size - 1
    for i in range(x.size):
        p = (x[i] + shift - x0) / step
        if p >= 0.0 and p <= last:
            j = min(int(p), last - 1)
            w = p - j
            out[i] = vals[j] + w * (vals[j + 1] - vals[j])
        else:
            out[i] = 0.0


@numba.njit(cache=True, nogil=True)
def slope_grid(x, shift, x0, step, vals, off, R, out):  # pragma: no cover - compiled
    """``out[i]`` = the envelope's slope ``dr/dx`` at ``x[i] + shift``:
    :func:`rideid.model.contact.wheel_input_slope` (its docstring has the contact geometry) one position at a time,
    without the NumPy version's temporaries; ``off`` the grid's contact offsets. Zero outside the table."""
    last = vals.size - 1
    RR = R * R
    for i in range(x.size):
        xi = x[i] + shift
        p = (xi - x0) / step
        if not (p >= 0.0 and p <= last):
            out[i] = 0.0
            continue
        j = min(int(p), last - 1)
        w = p - j
        d0 = off[j]
        d1 = off[j + 1]
        q0 = np.sqrt(RR - d0 * d0)
        q1 = np.sqrt(RR - d1 * d1)
        xj = x0 + step * j
        c0 = xj + d0
        c1 = xj + step + d1
        if abs(c1 - c0) > 4 * step:  # the contact jumps between the grid points: the higher circle at x
            e0 = c0 - xi
            e1 = c1 - xi
            v0 = vals[j] + R - q0 + np.sqrt(max(RR - e0 * e0, 0.0))
            v1 = vals[j + 1] + R - q1 + np.sqrt(max(RR - e1 * e1, 0.0))
            e = e0 if v0 >= v1 else e1
            e = min(max(e, -0.999 * R), 0.999 * R)
            out[i] = e / np.sqrt(RR - e * e)
        else:
            s0 = d0 / q0
            out[i] = s0 + w * (d1 / q1 - s0)


def compile_kernel() -> None:
    """Compile (or load from Numba's cache) :func:`lattice_max`, :func:`interp_grid` and :func:`slope_grid`, the
    last two writing into a contiguous array and into a column of a wider one (the corner array of
    :func:`rideid.model.simulate.corner_inputs`), as they are called; raises if that fails."""
    lattice_max(np.zeros(4), np.zeros(2))
    for out in (np.zeros(2), np.zeros((2, 4))[:, 0]):
        interp_grid(np.zeros(1), 0.0, 0.0, 1.0, np.zeros(2), out)
        slope_grid(np.zeros(1), 0.0, 0.0, 1.0, np.zeros(3), np.zeros(3), 1.0, out)


__all__ = ["compile_kernel", "interp_grid", "lattice_max", "slope_grid"]
