"""Compiled, batched simulation-and-cost kernel.

The same exact discretisation as :func:`rideid.simulate.simulate_reference`
(see :mod:`rideid.discretize`), compiled with Numba and laid out for speed:

* candidates are the innermost (contiguous) axis, so every small matrix
  product is a loop over candidates that LLVM vectorises (SIMD lanes =
  candidates); chunks of :data:`CHUNK` candidates run in parallel threads;
* the model is integrated as its symmetric (8 states, 2 inputs) and
  antisymmetric (6 states, 2 inputs) blocks;
* road inputs enter through precomputed, parameter-independent moments;
  with tire damping the states are shifted (``xi = x - Br u``, see
  :mod:`rideid.model.discretize`) and the input rates enter the
  accelerations at the samples only (``Dr u'``: 14 multiply-adds);
* squared errors are accumulated on the fly: memory per candidate is
  O(states), never O(samples).

Multiply-adds per sample and candidate, with ``N`` moment terms:
state update ``8*8 + 6*6 = 100``, inputs ``(8*2 + 6*2) N = 28 N``,
accelerations ``4*8 + 3*6 + (4 + 3)*2*2 = 78`` (with the rate feedthrough),
channels 12, errors 20: ``210 + 28 N`` (``N = 8..10`` for realistic cars at
200 Hz: 434-490), against about 550 for the plain 14-state update with 10 outputs, which moreover
assumes the input is linear between samples.
"""

from __future__ import annotations

import numba
import numpy as np

#: Candidates per thread chunk (SIMD lanes share a chunk).
CHUNK = 8
#: Largest number of moment terms the kernel accepts (see rideid.discretize.N_MAX).
N_MAX_K = 24


@numba.njit(cache=True, fastmath=True, inline="always")
def _accelerations(g, lC, lD, lR, x, UD, RD, k, u0, S, R):  # pragma: no cover - compiled
    """g[i] = C[i] x + D[i] u_k + Dr[i] u'_k for one block (S states, R acceleration rows)."""
    for i in range(R):
        for c in range(CHUNK):
            g[i, c] = (lD[i, 0, c] * UD[k, u0] + lD[i, 1, c] * UD[k, u0 + 1]
                       + lR[i, 0, c] * RD[k, u0] + lR[i, 1, c] * RD[k, u0 + 1])
        for j in range(S):
            for c in range(CHUNK):
                g[i, c] += lC[i, j, c] * x[j, c]


@numba.njit(cache=True, fastmath=True, inline="always")
def _advance(x, nx, lP, lG, MU, k, u0, S, N):  # pragma: no cover - compiled
    """x <- Phi x + sum_n G_n mu_{k,n} for one block (S states, inputs u0, u0+1)."""
    for i in range(S):
        for c in range(CHUNK):
            nx[i, c] = 0.0
        for j in range(S):
            for c in range(CHUNK):
                nx[i, c] += lP[i, j, c] * x[j, c]
        for t in range(N):
            m0 = MU[k, u0, t]
            m1 = MU[k, u0 + 1, t]
            for c in range(CHUNK):
                nx[i, c] += lG[t, i, 0, c] * m0 + lG[t, i, 1, c] * m1
    for i in range(S):
        for c in range(CHUNK):
            x[i, c] = nx[i, c]


@numba.njit(cache=True, parallel=True, fastmath=True)
def run_kernel(Phi_s, G_s, Ca_s, Da_s, Dr_s, Phi_a, G_a, Ca_a, Da_a, Dr_a, nterms,
               a_arr, b_arr, hf, hr,
               X0_s, X0_a, run_start, run_group, UD, RD, MU, Y, W,
               mode, OUT):  # pragma: no cover - compiled
    """Simulate all runs for all candidates.

    Shapes (``n`` candidates last, ``g`` sample-rate groups, ``r`` runs,
    ``T`` total samples over all runs):

    Phi_s (g, 8, 8, n), G_s (g, Nmax, 8, 2, n), Ca_s (g, 4, 8, n), Da_s (g, 4, 2, n), Dr_s (g, 4, 2, n),
    Phi_a (g, 6, 6, n), G_a (g, Nmax, 6, 2, n), Ca_a (g, 3, 6, n), Da_a (g, 3, 2, n), Dr_a (g, 3, 2, n),
    nterms (g, n_chunks) int, a_arr/b_arr (n,), X0_s (r, 8, n), X0_a (r, 6, n),
    run_start (r + 1,) int, run_group (r,) int, UD (T, 4), RD (T, 4) input rates, MU (T, 4, M), Y (T, 10),
    W (r, 10) channel weights (0 for a missing channel).

    ``n`` must be a multiple of :data:`CHUNK` (the caller pads).

    mode 0: returns per-run weighted squared errors (r, n); OUT unused.
    mode 1: also writes simulated channels into OUT (T, 10, n).
    """
    n = a_arr.size
    n_runs = run_group.size
    n_chunks = (n + CHUNK - 1) // CHUNK
    err = np.zeros((n_runs, n))
    for ch in numba.prange(n_chunks):
        c0 = ch * CHUNK
        c1 = c0 + CHUNK
        m = CHUNK
        xs = np.empty((8, m))
        xa = np.empty((6, m))
        ns = np.empty((8, m))
        na = np.empty((6, m))
        gs = np.empty((4, m))
        ga = np.empty((3, m))
        yh = np.empty((10, m))
        # chunk-local contiguous copies of the coefficients (candidates last)
        lPs = np.empty((8, 8, m))
        lGs = np.empty((N_MAX_K, 8, 2, m))
        lCs = np.empty((4, 8, m))
        lDs = np.empty((4, 2, m))
        lRs = np.empty((4, 2, m))
        lPa = np.empty((6, 6, m))
        lGa = np.empty((N_MAX_K, 6, 2, m))
        lCa = np.empty((3, 6, m))
        lDa = np.empty((3, 2, m))
        lRa = np.empty((3, 2, m))
        g_loaded = -1
        le = np.zeros(m)
        la = np.empty(m)
        lb = np.empty(m)
        for c in range(CHUNK):
            la[c] = a_arr[c0 + c]
            lb[c] = b_arr[c0 + c]
        for r in range(n_runs):
            g = run_group[r]
            N = nterms[g, ch]
            if g != g_loaded:
                lPs[:, :, :] = Phi_s[g, :, :, c0:c1]
                lGs[:N] = G_s[g, :N, :, :, c0:c1]
                lCs[:, :, :] = Ca_s[g, :, :, c0:c1]
                lDs[:, :, :] = Da_s[g, :, :, c0:c1]
                lRs[:, :, :] = Dr_s[g, :, :, c0:c1]
                lPa[:, :, :] = Phi_a[g, :, :, c0:c1]
                lGa[:N] = G_a[g, :N, :, :, c0:c1]
                lCa[:, :, :] = Ca_a[g, :, :, c0:c1]
                lDa[:, :, :] = Da_a[g, :, :, c0:c1]
                lRa[:, :, :] = Dr_a[g, :, :, c0:c1]
                g_loaded = g
            for i in range(8):
                for c in range(CHUNK):
                    xs[i, c] = X0_s[r, i, c0 + c]
            for i in range(6):
                for c in range(CHUNK):
                    xa[i, c] = X0_a[r, i, c0 + c]
            k0 = run_start[r]
            k1 = run_start[r + 1]
            for c in range(CHUNK):
                le[c] = 0.0
            for k in range(k0, k1):
                # outputs at sample k
                _accelerations(gs, lCs, lDs, lRs, xs, UD, RD, k, 0, 8, 4)
                _accelerations(ga, lCa, lDa, lRa, xa, UD, RD, k, 2, 6, 3)
                for c in range(CHUNK):
                    # the output map of rideid.model.equations.output_map (tested against it)
                    fa = gs[0, c] - la[c] * gs[1, c]
                    ra = gs[0, c] + lb[c] * gs[1, c]
                    yh[0, c] = fa + hf * ga[0, c]
                    yh[1, c] = fa - hf * ga[0, c]
                    yh[2, c] = ra + hr * ga[0, c]
                    yh[3, c] = ra - hr * ga[0, c]
                    yh[4, c] = gs[2, c] + ga[1, c]
                    yh[5, c] = gs[2, c] - ga[1, c]
                    yh[6, c] = gs[3, c] + ga[2, c]
                    yh[7, c] = gs[3, c] - ga[2, c]
                    yh[8, c] = xs[5, c]
                    yh[9, c] = xa[3, c]
                for q in range(10):
                    yq = Y[k, q]
                    wq = W[r, q]
                    for c in range(CHUNK):
                        d = yh[q, c] - yq
                        le[c] += wq * d * d
                if mode == 1:
                    for q in range(10):
                        for c in range(CHUNK):
                            OUT[k, q, c0 + c] = yh[q, c]
                if k + 1 == k1:
                    for c in range(CHUNK):
                        err[r, c0 + c] = le[c]
                    break
                # state update over the interval [k, k+1]
                _advance(xs, ns, lPs, lGs, MU, k, 0, 8, N)
                _advance(xa, na, lPa, lGa, MU, k, 2, 6, N)
    return err


def compile_kernels() -> float:
    """Compile (or load from Numba's on-disk cache) the kernels; seconds taken.

    The first call in a fresh install compiles for ~20-40 s; later processes
    load the cache in well under a second. The command line calls this first
    and says so when it takes long, rather than hiding it in the first
    generation.
    """
    import time

    from .contact import lattice_max

    t = time.perf_counter()
    n = CHUNK
    f = np.zeros
    run_kernel(f((1, 8, 8, n)), f((1, N_MAX_K, 8, 2, n)), f((1, 4, 8, n)), f((1, 4, 2, n)), f((1, 4, 2, n)),
               f((1, 6, 6, n)), f((1, N_MAX_K, 6, 2, n)), f((1, 3, 6, n)), f((1, 3, 2, n)), f((1, 3, 2, n)),
               np.ones((1, 1), dtype=np.int64), f(n), f(n), 0.7, 0.7, f((1, 8, n)), f((1, 6, n)),
               np.array([0, 2], dtype=np.int64), np.zeros(1, dtype=np.int64), f((2, 4)), f((2, 4)),
               f((2, 4, N_MAX_K)),
               f((2, 10)), f((1, 10)), 0, f((1, 10, 1)))
    lattice_max(f(4), f(2))
    return time.perf_counter() - t
