"""The cost kernel as it was before the lane-vectorised rewrite (loops over small matrices,
candidates innermost, ``prange`` over chunks of 8), kept here so that ``make bench`` measures the
current kernel against it in the same run. Not part of the package.

It takes the same discretisation, with the series length of that time (first omitted term below
1e-11, plus one).
"""

from __future__ import annotations

import numba
import numpy as np

from rideid.model.discretize import N_MAX, Discretized, n_terms, spectral_radius
from rideid.model.params import column
from rideid.model.simulate import initial_states

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




def n_terms_before(rho: float) -> int:
    """The series length rule of that time: one term more than today's rule at 1e-11, at least 4."""
    return min(max(n_terms(rho, 1e-11) + 1, 4), N_MAX)


def errors_before(sim, P, Y, W):
    """Per-run weighted squared errors of population ``P`` (a multiple of CHUNK rows) by the former kernel."""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    n = P.shape[0]
    n_chunks = n // CHUNK
    g = len(sim.h_groups)
    nt = np.zeros((g, n_chunks), dtype=np.int64)
    discs = []
    for gi, h in enumerate(sim.h_groups):
        d = Discretized(P, sim.geom, h, nterms=N_MAX)
        rho = np.maximum(spectral_radius(d.As), spectral_radius(d.Aa)) * h / 2
        for ch in range(n_chunks):
            nt[gi, ch] = n_terms_before(float(rho[ch * CHUNK:(ch + 1) * CHUNK].max()))
        discs.append(d)

    def stack(name, lead=0):
        arrs = [getattr(d, name) for d in discs]
        if lead:
            return np.ascontiguousarray(np.stack([np.moveaxis(a, 1, -1) for a in arrs]))
        return np.ascontiguousarray(np.stack([np.moveaxis(a, 0, -1) for a in arrs]))

    X0s = np.zeros((len(sim.runs), 8, n))
    X0a = np.zeros((len(sim.runs), 6, n))
    for ri, r in enumerate(sim.runs):
        xs, xa = initial_states(discs[sim.run_group[ri]], r.ud[0])
        X0s[ri], X0a[ri] = xs.T, xa.T
    a = np.ascontiguousarray(column(P, "a"))
    b = sim.geom.wheelbase - a
    return run_kernel(stack("Phi_s"), stack("G_s", 1), stack("Ca_s"), stack("Da_s"), stack("Dr_s"),
                      stack("Phi_a"), stack("G_a", 1), stack("Ca_a"), stack("Da_a"), stack("Dr_a"), nt,
                      a, b, sim.geom.corner_y[0], sim.geom.corner_y[2], X0s, X0a, sim.run_start, sim.run_group,
                      sim.UD, sim.RD, sim.MU, Y, W, 0, np.zeros((1, 10, 1)))
