"""Exact discretisation of the ride model for finely resolved road inputs.

Over one sample interval of length ``h`` the state obeys exactly

    x_{k+1} = e^{Ah} x_k + int_0^h e^{A(h-s)} B u(t_k + s) ds .

The road input ``u`` is not linear between samples (envelope kinks, short
wavelengths), so no hold is assumed. Expanding the smooth kernel about the
interval's midpoint, ``e^{A(h-s)} = e^{Ah/2} sum_n (A (h/2 - s))^n / n!``,
gives

    int_0^h e^{A(h-s)} B u ds = sum_n G_n mu_{k,n},
    G_n = e^{Ah/2} (A h/2)^n B h / n!,
    mu_{k,n} = (1/h) int_0^h tau^n u(t_k + s) ds,   tau = 1 - 2 s / h in [-1, 1].

The moments ``mu`` depend only on the road and the run, so they are computed
once per dataset (by fine quadrature of the envelope, :mod:`rideid.simulate`);
the matrices ``G_n`` depend only on the candidate. The series converges like
``rho^n / n!`` with ``rho = h/2 max|eig(A)|``; :func:`n_terms` picks the
shortest series whose first omitted term ``rho^N / N!`` is below :data:`TOL`
(1e-8). The channels' relative RMS error is then below ``100 TOL`` = 1e-6
(the wheel accelerations amplify the fastest mode's share of the error:
25x seen on a stiff tire on a light wheel, tested in
``tests/test_simulate.py``); on the built-in car at 200 Hz (``rho`` = 0.19,
N = 7) it is 2e-10. Both are far below the 1e-5 to which the road input
itself is resolved and the 1e-2 of sensor noise. Each term costs 28
multiply-adds per sample of ~400, so the tolerance is a speed choice: the
former 1e-11 needed three more terms.

Tire damping (SPEC §6) brings the road input's rate in:
``x' = A x + B u + Br u'``. The rate is never integrated (the envelope's
slope has kinks, its derivative would be impulses): the shifted state
``xi = x - Br u`` obeys

    xi' = A xi + (A Br + B) u ,

so the moment scheme above stays exact with ``B~ = A Br + B``. The outputs
(accelerations ``Ca x + Da u + Dr u'``) become ``Ca xi + (Ca Br + Da) u +
Dr u'``: the rate enters only at the sample instants, as the direct
feedthrough ``c_t u' / m_u`` into the wheel accelerations. Velocities of the
body (pitch and roll rate) are unshifted (``Br`` acts on wheel velocities
only). Without tire damping ``Br = 0`` and nothing changes.
"""

from __future__ import annotations


import numpy as np
import scipy.linalg

from .equations import blocks as blocks_of

#: Largest number of moments precomputed per interval.
N_MAX = 24


#: Bound on the first omitted term of the moment series (relative error of the channels).
TOL = 1e-8


def n_terms(rho: float, tol: float = TOL) -> int:
    """Shortest series length ``N`` with ``rho^N / N! < tol`` (at least 4, at most N_MAX)."""
    term, n = 1.0, 0
    while n < N_MAX:
        n += 1
        term *= rho / n
        if term < tol and n >= 4:
            break
    return n


def spectral_radius(A):
    """Largest eigenvalue magnitude of each matrix, shape (n,)."""
    return np.abs(np.linalg.eigvals(A)).max(axis=-1)


def discretize_block(A, B, h: float, nterms: int | None = None, tol: float = TOL):
    """Transition matrix and moment input matrices for one block.

    Parameters
    ----------
    A : (n, m, m), B : (n, m, k)
    h : float
        Sample interval (s).

    Returns
    -------
    Phi : (n, m, m)
    G : (N, n, m, k)
    N : int
    """
    if nterms is None:
        rho = float(spectral_radius(A).max()) * h / 2
        nterms = n_terms(rho, tol)
    E = scipy.linalg.expm(A * (h / 2))
    Phi = E @ E  # e^{Ah} = (e^{Ah/2})^2: one matrix exponential
    G = np.empty((nterms,) + B.shape)
    term = B * h  # (A h/2)^n B h / n!
    Ah2 = A * (h / 2)
    for n in range(nterms):
        G[n] = E @ term
        term = Ah2 @ term / (n + 1)
    return Phi, G, nterms


class Discretized:
    """Per-candidate discrete matrices of both blocks at one sample rate.

    The states are the shifted states ``xi = x - Br u`` (see the module
    docstring; ``xi = x`` without tire damping).

    Attributes (candidate axis first)
    ---------------------------------
    Phi_s (n, 8, 8), G_s (N, n, 8, 2), Ca_s (n, 4, 8), Da_s (n, 4, 2), Dr_s (n, 4, 2):
        symmetric block; the accelerations ``[z'', theta'', zf_s'', zr_s'']``
        are ``Ca_s xi + Da_s u + Dr_s u'``. With a powertrain (SPEC §11) the
        block has 12 states (``Phi_s`` (n, 12, 12), ``Ca_s`` (n, 4, 12), ...).
    Phi_a (n, 6, 6), G_a (N, n, 6, 2), Ca_a (n, 3, 6), Da_a (n, 3, 2), Dr_a (n, 3, 2):
        antisymmetric block; accelerations ``[phi'', zf_a'', zr_a'']``.
    Bt_s, Bt_a : the input matrices ``A Br + B`` of the shifted states;
    Brs, Bra : the rate input matrices ``Br`` (``x = xi + Br u``).

    ``blocks`` (optional) passes :func:`rideid.model.equations.blocks` of
    ``P`` when the caller has them already.
    """

    def __init__(self, P, geom, h: float, nterms: int | None = None, tol: float = TOL, blocks=None):
        bl = blocks_of(P, geom) if blocks is None else blocks
        self.As, self.Bs, self.Aa, self.Ba = bl["As"], bl["Bs"], bl["Aa"], bl["Ba"]
        self.Brs, self.Bra = bl["Brs"], bl["Bra"]
        self.Bt_s = self.As @ self.Brs + self.Bs
        self.Bt_a = self.Aa @ self.Bra + self.Ba
        if nterms is None:
            rho = max(float(spectral_radius(self.As).max()), float(spectral_radius(self.Aa).max())) * h / 2
            nterms = n_terms(rho, tol)
        self.h = h
        self.N = nterms
        self.Phi_s, self.G_s, _ = discretize_block(self.As, self.Bt_s, h, nterms)
        self.Phi_a, self.G_a, _ = discretize_block(self.Aa, self.Bt_a, h, nterms)
        # the accelerations of [z, theta, zf_s, zr_s] (a powertrain's two more coordinates are not read)
        ns = self.As.shape[-1] // 2
        self.Ca_s, self.Ca_a = self.As[:, ns:ns + 4, :], self.Aa[:, 3:, :]
        # = Ca Br + Da (Br has no position rows)
        self.Da_s, self.Da_a = self.Bt_s[:, ns:ns + 4, :], self.Bt_a[:, 3:, :]
        self.Dr_s, self.Dr_a = self.Brs[:, ns:ns + 4, :], self.Bra[:, 3:, :]


def gauss_nodes(n_panels: int, order: int = 2):
    """Composite Gauss-Legendre nodes and weights on [0, 1]."""
    xg, wg = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, 1.0, n_panels + 1)
    mid = (edges[:-1] + edges[1:]) / 2
    half = (edges[1:] - edges[:-1]) / 2
    nodes = (mid[:, None] + half[:, None] * xg[None, :]).ravel()
    weights = (half[:, None] * wg[None, :]).ravel()
    return nodes, weights


def moment_weights(nodes, weights, nmom: int = N_MAX):
    """``W[q, n] = w_q tau_q^n`` so that ``mu_n = sum_q u(s_q) W[q, n]``."""
    tau = 1.0 - 2.0 * nodes
    return weights[:, None] * tau[:, None] ** np.arange(nmom)[None, :]


__all__ = ["Discretized", "N_MAX", "TOL", "n_terms", "gauss_nodes", "moment_weights"]
