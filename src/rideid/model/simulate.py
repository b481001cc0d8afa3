"""Wheel inputs of a run and the model's time response.

Driving (SPEC §2): at ``t = 0`` the front axle is at ``x = 0``, the rear at
``-wheelbase``, the car at rest in static equilibrium, moving at the run's
constant speed. Wheel paths: fl at ``y = +track_front/2``, fr at
``-track_front/2``, rl/rr likewise with ``track_rear``.

:class:`RunInput` holds everything parameter-independent about a run: the
corner inputs at the samples and the input moments of every sample interval
(:mod:`rideid.discretize`). :func:`simulate_reference` is the plain NumPy
implementation of the exact discretisation (the compiled kernel in
:mod:`rideid.kernel` is tested against it); :func:`simulate_lsim` is an
independent fine-step check with ``scipy.signal.lsim``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import numpy as np

from .contact import envelope, wheel_input, wheel_input_slope
from .discretize import N_MAX, Discretized, gauss_nodes, moment_weights
from .equations import (CHANNELS, CORNER_TO_DECOMPOSED, DECOMPOSED_TO_COORDS, RATE_COORDS, output_map,
                        state_space, static_state)
from .params import Geometry
from .tracks import Track

#: Spacing (m) of the tabulated envelope.
ENVELOPE_DX = 5e-4


def corner_positions(geom: Geometry, distance):
    """Wheel-centre positions ``(n, 4)`` for front-axle distances ``(n,)``."""
    d = np.asarray(distance, dtype=float)
    return d[..., None] + np.array(geom.corner_x_from_front)


def _at_corners(read, track: Track, geom: Geometry, distance):
    """``read`` (:func:`~rideid.model.contact.wheel_input` or its slope) on each corner's wheel path at front-axle
    distances ``distance``, written into that corner's column: ``(..., 4)``."""
    d = np.asarray(distance, dtype=float).ravel()
    out = np.empty((d.size, 4))
    for i, (y, cx) in enumerate(zip(geom.corner_y, geom.corner_x_from_front)):
        read(track.path(y), d, geom.tire_radius, ENVELOPE_DX, shift=cx, out=out[:, i])
    return out.reshape(np.shape(distance) + (4,))


def corner_inputs(track: Track, geom: Geometry, distance):
    """Road inputs ``(n, 4)`` (envelope, m) at front-axle distances ``(n,)``."""
    return _at_corners(wheel_input, track, geom, distance)


def corner_input_slopes(track: Track, geom: Geometry, distance):
    """Slopes ``dr/dx`` ``(n, 4)`` of the road inputs at front-axle distances ``(n,)``."""
    return _at_corners(wheel_input_slope, track, geom, distance)


@dataclass
class RunInput:
    """Parameter-independent data of one run.

    Attributes
    ----------
    t : (n,) sample times, s (uniform, ``t[0] = 0`` relative to the drive start)
    h : sample interval, s
    u : (n, 4) corner inputs fl, fr, rl, rr at the samples, m
    ud : (n, 4) decomposed inputs ``[rf_s, rr_s, rf_a, rr_a]``
    mu : (n-1, 4, N_MAX) decomposed input moments per interval (the linear car's exact discretisation): given as
        ``moments``, the array or a function that computes it, called on the first read of ``mu`` (the
        nonlinear car never reads them: a damper-curve fit on estimated starts prepares its runs again at every
        trial start, and the moments' quadrature was 52 of its 63 ms a preparation)
    rate : (n, 4) input rates ``r'`` (speed times envelope slope) at the samples, m/s
    rated : (n, 4) decomposed input rates (used with tire damping)
    inputs_at : callable ``times (k,) -> (u (k, 4), rate (k, 4))``, the corner inputs and
        their rates at any times within the run, by the same road model as ``u`` and
        ``rate`` (equal to them at the samples); the nonlinear car's integrator
        (:mod:`rideid.model.nonlinear`) evaluates them between the samples. ``None``
        for a RunInput built by hand.
    values_at : callable ``times (k,) -> u (k, 4)``, optional
        ``inputs_at``'s first half alone (the integrator's quadrature points need no rates: 32 of every 33 points
        it evaluates, and the envelope's slope was two thirds of each evaluation); None: ``inputs_at``'s.
    """

    t: np.ndarray
    h: float
    u: np.ndarray
    ud: np.ndarray
    moments: object
    rate: np.ndarray
    rated: np.ndarray
    inputs_at: object = field(default=None, repr=False, compare=False)
    values_at: object = field(default=None, repr=False, compare=False)

    def inputs_only(self, times) -> np.ndarray:
        """The corner inputs ``(k, 4)`` at ``times`` (m): :attr:`values_at`, else :attr:`inputs_at`'s first half."""
        if self.values_at is not None:
            return self.values_at(times)
        return self.inputs_at(times)[0]

    @property
    def mu(self) -> np.ndarray:
        if callable(self.moments):
            mu = np.asarray(self.moments())
            mu.flags.writeable = False  # shared by every caller with the same arguments (prepare_run)
            self.moments = mu
        return self.moments

    def tail(self, k: int) -> "RunInput":
        """The run from its ``k``-th sample on (a moving start's recorded part), its moments still lazy where they
        are."""
        if not k:
            return self
        moments = (lambda: self.mu[k:]) if callable(self.moments) else self.moments[k:]
        return replace(self, t=self.t[k:], u=self.u[k:], ud=self.ud[k:], moments=moments, rate=self.rate[k:],
                       rated=self.rated[k:])

    @property
    def n(self) -> int:
        return self.t.size


#: the last few prepared runs: loading a dataset (its physics checks) and identifying it
#: prepare the same runs, and the envelope quadrature is most of both (0.1 s per run)
_PREPARED: list = []
PREPARED_MAX = 12  # a dataset's runs; ~1 MB per 1000 samples


def prepare_run(track: Track, geom: Geometry, speed: float | None, t, quad_order: int = 2,
                distance=None) -> RunInput:
    """Tabulate inputs and moments for a run sampled at ``t`` (the same arguments again: the same result).

    The front axle is at ``x = speed t`` (constant speed), or at
    ``x = distance(t)`` when a vectorised ``distance`` function is given
    (varying speed; it then needs a ``max_speed`` attribute or ``speed`` as an
    upper bound of the speed).
    """
    t = np.asarray(t, dtype=float)
    for tr, ge, sp, tt, qo, di, res in _PREPARED:
        # the same objects (tracks and distance functions are not compared by value) and the same grid
        if (tr is track and di is distance and ge == geom and sp == speed and qo == quad_order
                and tt.shape == t.shape and np.array_equal(tt, t)):
            return res
    res = _prepare_run(track, geom, speed, t, quad_order, distance)
    for arr in (res.t, res.u, res.ud, res.rate, res.rated):
        arr.flags.writeable = False  # shared by every caller with the same arguments
    _PREPARED.append((track, geom, speed, t.copy(), quad_order, distance, res))
    del _PREPARED[:-PREPARED_MAX]
    return res


@functools.lru_cache(maxsize=16)
def _quadrature(n_panels: int, quad_order: int):
    """The composite Gauss nodes on [0, 1] and their moment weights ``W (q, N_MAX)``, read-only (a run read at a
    new start needs them again)."""
    nodes, weights = gauss_nodes(n_panels, quad_order)
    W = moment_weights(nodes, weights, N_MAX)
    nodes.flags.writeable = W.flags.writeable = False
    return nodes, W


def input_moments(t, corner_inputs_at, n_panels: int, quad_order: int) -> np.ndarray:
    """The decomposed road inputs' moments over each sample interval, ``(n_t - 1, 4, N_MAX)``: Gauss quadrature
    (``n_panels`` panels of order ``quad_order``) of ``corner_inputs_at(times) -> (k, 4)`` (m) against the moment
    basis, in blocks of about two million quadrature points."""
    h = float(t[1] - t[0])
    nodes, W = _quadrature(n_panels, quad_order)
    n_int = t.size - 1
    mu = np.empty((n_int, 4, N_MAX))
    block = max(1, 2_000_000 // nodes.size)
    for lo in range(0, n_int, block):
        hi = min(n_int, lo + block)
        tq = (t[lo:hi, None] + h * nodes[None, :]).ravel()
        uq = np.asarray(corner_inputs_at(tq)).reshape(hi - lo, nodes.size, 4)
        mc = np.matmul(uq.transpose(0, 2, 1), W)  # (k, 4, N): BLAS, 3x einsum's speed
        mu[lo:hi] = np.matmul(CORNER_TO_DECOMPOSED, mc)
    return mu


def _prepare_run(track, geom, speed, t, quad_order, distance) -> RunInput:
    h = float(t[1] - t[0])
    distance_given = distance is not None
    if distance is None:
        def distance(tt, v=speed):
            return v * tt
        vmax = speed
    else:
        vmax = speed if speed is not None else distance.max_speed
    u = corner_inputs(track, geom, distance(t))
    # quadrature panels no longer than the envelope grid spacing
    n_panels = max(8, int(np.ceil(max(vmax, 1e-3) * h / ENVELOPE_DX)))
    def values_at(times):
        """Corner inputs at ``times`` (s), as ``u`` at the samples (``inputs_at`` without the rates)."""
        return corner_inputs(track, geom, distance(np.asarray(times, dtype=float)))

    def mu():
        return input_moments(t, values_at, n_panels, quad_order)
    ud = u @ CORNER_TO_DECOMPOSED.T
    # input rates at the samples: speed x envelope slope (only the tire dampers use them)
    if distance_given:
        dt = h * 1e-3
        v = (distance(t + dt) - distance(t - dt)) / (2 * dt)
    else:
        v = np.full(t.size, float(speed))
    rate = corner_input_slopes(track, geom, distance(t)) * v[:, None]

    def inputs_at(times):
        """Corner inputs and their rates at ``times`` (s), as ``u`` and ``rate`` at the samples."""
        times = np.asarray(times, dtype=float)
        x = distance(times)
        if distance_given:
            eps = h * 1e-3
            vv = (distance(times + eps) - distance(times - eps)) / (2 * eps)
        else:
            vv = np.full(times.shape, float(speed))
        return corner_inputs(track, geom, x), corner_input_slopes(track, geom, x) * vv[:, None]

    return RunInput(t=t, h=h, u=u, ud=ud, moments=mu, rate=rate, rated=rate @ CORNER_TO_DECOMPOSED.T,
                    inputs_at=inputs_at, values_at=values_at)


def initial_states(disc: Discretized, ud0):
    """Static-equilibrium (shifted) states ``xi`` of both blocks for the input at ``t = 0``.

    At rest ``x = -A^-1 B u0``, so ``xi = x - Br u0 = -A^-1 (A Br + B) u0``.
    """
    xs = static_state(disc.As, disc.Bt_s, ud0[:2])
    xa = static_state(disc.Aa, disc.Bt_a, ud0[2:])
    return xs, xa


def assemble_channels(P, geom: Geometry, gs, ga, rates):
    """Ten SPEC channels from decomposed generalised accelerations and the rates.

    Parameters
    ----------
    P : (n_pop, len(NAMES))
    gs : (n_pop, n_time, 4) ``[z'', theta'', zf_s'', zr_s'']``
    ga : (n_pop, n_time, 3) ``[phi'', zf_a'', zr_a'']``
    rates : (n_pop, n_time, 7) generalised velocities in :data:`rideid.model.equations.COORDS` order

    Returns
    -------
    (n_pop, n_time, 10) through :func:`rideid.model.equations.output_map`.
    """
    qdd = np.concatenate([gs, ga], axis=-1) @ DECOMPOSED_TO_COORDS.T
    acc = np.einsum("pcq,ptq->ptc", output_map(P, geom), qdd)
    gyro = np.stack([rates[..., k] for k in RATE_COORDS.values()], axis=-1)
    return np.concatenate([acc, gyro], axis=-1)


def simulate_reference(P, geom: Geometry, run: RunInput, disc: Discretized | None = None,
                       return_states: bool = False):
    """Outputs of the exact discretisation, plain NumPy (loop over samples).

    Parameters
    ----------
    P : (n_pop, 12), (n_pop, 16) or (n_pop, 23)
    geom : Geometry
    run : RunInput

    Returns
    -------
    y : (n_pop, n_time, 10) in :data:`rideid.model.CHANNELS` order.
    states : (n_pop, n_time, 14) in decomposed order
        ``[z, theta, zf_s, zr_s, rates(4), phi, zf_a, zr_a, rates(3)]``
        (the physical states ``x``, not the shifted ones; a powertrain's
        relative motion is not among them), only with ``return_states``.
    """
    P = np.atleast_2d(np.asarray(P, dtype=float))
    if disc is None:
        disc = Discretized(P, geom, run.h)
    N = disc.N
    xs, xa = initial_states(disc, run.ud[0])
    n = run.n
    gs = np.empty((P.shape[0], n, 4))
    ga = np.empty((P.shape[0], n, 3))
    ns = disc.Phi_s.shape[-1] // 2  # 4 coordinates, 6 with a powertrain (SPEC §11)
    Xs = np.empty((P.shape[0], n, 2 * ns))
    Xa = np.empty((P.shape[0], n, 6))
    for k in range(n):
        Xs[:, k], Xa[:, k] = xs, xa
        gs[:, k] = (np.einsum("pij,pj->pi", disc.Ca_s, xs) + disc.Da_s @ run.ud[k, :2]
                    + disc.Dr_s @ run.rated[k, :2])
        ga[:, k] = (np.einsum("pij,pj->pi", disc.Ca_a, xa) + disc.Da_a @ run.ud[k, 2:]
                    + disc.Dr_a @ run.rated[k, 2:])
        if k + 1 < n:
            mus, mua = run.mu[k, :2, :N], run.mu[k, 2:, :N]
            xs = np.einsum("pij,pj->pi", disc.Phi_s, xs) + np.einsum("npij,jn->pi", disc.G_s, mus)
            xa = np.einsum("pij,pj->pi", disc.Phi_a, xa) + np.einsum("npij,jn->pi", disc.G_a, mua)
    # generalised velocities: decomposed rates -> COORDS
    rates = np.concatenate([Xs[:, :, ns:ns + 4], Xa[:, :, 3:]], axis=-1) @ DECOMPOSED_TO_COORDS.T
    y = assemble_channels(P, geom, gs, ga, rates)
    if return_states:
        Xs = Xs + np.einsum("pij,tj->pti", disc.Brs, run.ud[:, :2])  # x = xi + Br u
        Xa = Xa + np.einsum("pij,tj->pti", disc.Bra, run.ud[:, 2:])
        car = np.r_[0:4, ns:ns + 4]  # the car's states; a powertrain's relative motion left out
        return y, np.concatenate([Xs[:, :, car], Xa], axis=-1)
    return y


def _block_response(Phi, G, mu, x0):
    """States ``(n_pop, m, n_time)`` of ``x_{k+1} = Phi x_k + sum_n G_n mu_{k,n}`` from ``x0``, in modal
    coordinates: ``Phi = V diag(lam) V^-1``, each mode a first-order recursion, all candidates' modes
    advanced together (one complex multiply-add per sample); the rest is BLAS."""
    n_pop, m = x0.shape
    N = G.shape[0]
    k = mu.shape[0]
    # the input over each interval, (n_pop, m, n_time - 1): sum over (input, term) as one matrix product
    f = np.moveaxis(G, 0, -1).reshape(n_pop, m, -1) @ mu[:, :, :N].reshape(k, -1).T
    lam, V = np.linalg.eig(Phi)
    Vinv = np.linalg.inv(V)
    g = Vinv @ f
    z0 = (Vinv @ x0[:, :, None])[:, :, 0]
    z = np.empty((k + 1, n_pop, m), dtype=complex)
    z[0] = zk = z0
    gt = np.ascontiguousarray(g.transpose(2, 0, 1))
    for j in range(k):  # every candidate's every mode at once: one complex multiply-add per sample
        zk = lam * zk + gt[j]
        z[j + 1] = zk
    return (V @ z.transpose(1, 2, 0)).real


def simulate_modal(P, geom: Geometry, run: RunInput, disc: Discretized | None = None):
    """The outputs ``y`` of :func:`simulate_reference` (the same parameters and the same exact discretisation)
    by a modal recursion vectorised over the samples: any block size (a powertrain's 12-state symmetric block,
    SPEC §11)."""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    if disc is None:
        disc = Discretized(P, geom, run.h)
    xs0, xa0 = initial_states(disc, run.ud[0])
    Xs = _block_response(disc.Phi_s, disc.G_s, run.mu[:, :2], xs0)  # (n_pop, states, n_time)
    Xa = _block_response(disc.Phi_a, disc.G_a, run.mu[:, 2:], xa0)
    gs = disc.Ca_s @ Xs + disc.Da_s @ run.ud[:, :2].T + disc.Dr_s @ run.rated[:, :2].T
    ga = disc.Ca_a @ Xa + disc.Da_a @ run.ud[:, 2:].T + disc.Dr_a @ run.rated[:, 2:].T
    ns = disc.Phi_s.shape[-1] // 2
    rates = np.concatenate([Xs[:, ns:ns + 4], Xa[:, 3:]], axis=1).transpose(0, 2, 1) @ DECOMPOSED_TO_COORDS.T
    return assemble_channels(P, geom, gs.transpose(0, 2, 1), ga.transpose(0, 2, 1), rates)


def wheel_displacements(states):
    """Corner wheel heaves ``(…, 4)`` from decomposed states."""
    zfs, zrs = states[..., 2], states[..., 3]
    zfa, zra = states[..., 9], states[..., 10]
    return np.stack([zfs + zfa, zfs - zfa, zrs + zra, zrs - zra], axis=-1)


def wheel_velocities(states):
    """Corner wheel heave rates ``(…, 4)`` from decomposed states."""
    zfs, zrs = states[..., 6], states[..., 7]
    zfa, zra = states[..., 12], states[..., 13]
    return np.stack([zfs + zfa, zfs - zfa, zrs + zra, zrs - zra], axis=-1)


def simulate_lsim(P, geom: Geometry, track: Track, speed: float, t, upsample: int = 100,
                  exact_envelope: bool = True):
    """Independent fine-step reference with ``scipy.signal.lsim``.

    The full 14-state model is driven by the envelope evaluated directly
    (not tabulated) on a grid ``upsample`` times finer than ``t`` with
    first-order hold; outputs are taken at ``t``. One candidate. With tire
    damping the input rate ``r'`` is a second input, taken as the central
    difference of the fine envelope (no state shift: independent of
    :mod:`rideid.model.discretize`).

    Returns
    -------
    y : (n_time, 10)
    """
    import scipy.signal


    t = np.asarray(t, dtype=float)
    h = t[1] - t[0]
    tf = t[0] + h / upsample * np.arange((t.size - 1) * upsample + 1)
    xs = corner_positions(geom, speed * tf)
    if exact_envelope:
        u = np.stack([envelope(track.path(y).h, xs[:, i], geom.tire_radius)
                      for i, y in enumerate(geom.corner_y)], -1)
    else:
        u = corner_inputs(track, geom, speed * tf)
    A, B, Cy, Dy, Br, Dyr = state_space(np.atleast_2d(P), geom, rate=True)
    x0 = static_state(A, B, u[0])[0]
    if not np.any(Br):
        sys = scipy.signal.StateSpace(A[0], B[0], Cy[0], Dy[0])
        _, y, _ = scipy.signal.lsim(sys, u, tf, X0=x0, interp=True)
        return y[::upsample]
    ud = np.gradient(u, tf, axis=0)
    sys = scipy.signal.StateSpace(A[0], np.concatenate([B[0], Br[0]], 1), Cy[0],
                                  np.concatenate([Dy[0], Dyr[0]], 1))
    _, y, _ = scipy.signal.lsim(sys, np.concatenate([u, ud], 1), tf, X0=x0, interp=True)
    return y[::upsample]


__all__ = ["RunInput", "prepare_run", "simulate_reference", "simulate_modal", "simulate_lsim", "CHANNELS",
           "corner_inputs", "corner_positions"]
