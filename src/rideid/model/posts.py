"""Four-post rig inputs (SPEC §13): the road under each wheel is a measured post displacement.

A rig run has no track, speed or tire envelope: the wheel input ``r_i`` of
SPEC §1 is the post's displacement itself (the tire stands on the post's
flat pan). :func:`prepare_posts` turns the sampled post displacements
``(n, 4)`` (fl, fr, rl, rr, m) into the :class:`rideid.model.simulate.RunInput`
every simulator takes: the inputs at the samples, their moments over every
sample interval (:mod:`rideid.model.discretize`), their rates, and the inputs
between the samples (for the nonlinear car's integrator).

Between the samples the posts follow the cubic spline through them (not-a-knot
ends); with measured post velocities (``post_vel_*``) the cubic Hermite spline
through displacements and velocities instead, so the rates are the measured
ones at the samples. A rig drives its posts with band-limited signals well
below the sample rate (a sweep to 25 Hz logged at 200 Hz or more): the
spline's error is then of order ``(2 pi f h)^4 / 384`` of the signal, 1e-3 at a
quarter of the Nyquist frequency.

:class:`PostSignal` makes the rig's drive signals for scenarios: logarithmic
sine sweeps in a pattern of the four posts (heave, pitch, roll, warp) and
independent band-limited random motion of each post, each a smooth function
of time with its rate, faded in and out so the car starts and ends at rest.
Pure arrays; randomness from the generator passed in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .equations import CORNER_TO_DECOMPOSED
from .simulate import RunInput, input_moments

#: post channels, in corner order fl, fr, rl, rr (SPEC §13)
POST_CHANNELS = ("post_fl", "post_fr", "post_rl", "post_rr")
#: measured post velocities (optional; else the displacement spline's derivative)
POST_VEL_CHANNELS = ("post_vel_fl", "post_vel_fr", "post_vel_rl", "post_vel_rr")
#: the signs of the four posts (fl, fr, rl, rr) of each sweep pattern
PATTERNS = {"heave": (1.0, 1.0, 1.0, 1.0), "pitch": (1.0, 1.0, -1.0, -1.0),
            "roll": (1.0, -1.0, 1.0, -1.0), "warp": (1.0, -1.0, -1.0, 1.0)}
SIGNALS = ("sweep", "random")
#: quadrature of the input moments over one sample interval: panels and Gauss order (a cubic per interval
#: times the moment basis: exact to degree 7 per panel)
MOMENT_PANELS, MOMENT_ORDER = 8, 4


def _spline(t, z, v=None):
    """The posts between the samples: cubic (not-a-knot) through ``z``, or Hermite through ``z`` and ``v``."""
    from scipy.interpolate import CubicHermiteSpline, CubicSpline

    if v is not None:
        return CubicHermiteSpline(t, z, v, axis=0)
    return CubicSpline(t, z, axis=0, bc_type="not-a-knot")


def prepare_function(t, inputs_at):
    """A :class:`rideid.model.simulate.RunInput` of a run sampled at ``t`` whose four wheel inputs are
    ``inputs_at(times) -> (u (k, 4), rate (k, 4))`` at any times (m, m/s)."""
    t = np.asarray(t, dtype=float)
    h = float(t[1] - t[0])
    u, rate = inputs_at(t)
    mu = input_moments(t, lambda tq: inputs_at(tq)[0], MOMENT_PANELS, MOMENT_ORDER)
    u = np.ascontiguousarray(u, dtype=float)
    rate = np.ascontiguousarray(rate, dtype=float)
    run = RunInput(t=t, h=h, u=u, ud=u @ CORNER_TO_DECOMPOSED.T, moments=mu, rate=rate,
                   rated=rate @ CORNER_TO_DECOMPOSED.T, inputs_at=inputs_at)
    for arr in (run.t, run.u, run.ud, run.mu, run.rate, run.rated):
        arr.flags.writeable = False
    return run


#: the last few prepared rig runs (loading checks a dataset, each model-choice candidate builds a cost on it)
_PREPARED: list = []
PREPARED_MAX = 12


def prepare_posts(t, posts, post_vel=None):
    """The :class:`rideid.model.simulate.RunInput` of a rig run (SPEC §13).

    Parameters
    ----------
    t : (n,) uniform sample times, s
    posts : (n, 4) post displacements fl, fr, rl, rr, m (the wheel inputs ``r_i``)
    post_vel : (n, 4), optional
        Measured post velocities, m/s; default: the derivative of the cubic
        spline through ``posts``.
    """
    for tt, zz, vv, res in _PREPARED:  # the same arrays (not compared by value) and the same grid
        if zz is posts and vv is post_vel and np.shape(tt) == np.shape(t) and np.array_equal(tt, t):
            return res
    res = _prepare_posts(t, posts, post_vel)
    _PREPARED.append((np.array(t, dtype=float), posts, post_vel, res))
    del _PREPARED[:-PREPARED_MAX]
    return res


def _prepare_posts(t, posts, post_vel):
    t = np.asarray(t, dtype=float)
    z = np.asarray(posts, dtype=float)
    if z.shape != (t.size, 4):
        raise ValueError(f"posts: expected shape ({t.size}, 4), got {z.shape}")
    sp = _spline(t, z, None if post_vel is None else np.asarray(post_vel, dtype=float))
    d1 = sp.derivative()

    def inputs_at(times):
        """Post displacements and velocities at ``times`` (s): the spline's (the samples' own at the samples)."""
        times = np.asarray(times, dtype=float)
        return sp(times), d1(times)

    run = prepare_function(t, inputs_at)
    # at the samples the inputs are the data themselves (the spline reproduces them to rounding)
    run.u = z.copy()
    run.ud = z @ CORNER_TO_DECOMPOSED.T
    if post_vel is not None:
        run.rate = np.asarray(post_vel, dtype=float).copy()
        run.rated = run.rate @ CORNER_TO_DECOMPOSED.T
    for arr in (run.u, run.ud, run.rate, run.rated):
        arr.flags.writeable = False
    return run


#: a post channel's sensor chain is divided out where its gain is at least this; where it is less (beyond a
#: low-pass's corner, below a high-pass's) the recording holds too little of the post to restore: left out
MIN_CHAIN_GAIN = 0.1


def unfilter(t, z, filters, min_gain: float = MIN_CHAIN_GAIN):
    """The posts before their sensor chain: ``z`` (``(n,)`` or ``(n, k)``, uniform ``t``) divided by the chain's
    frequency response (:meth:`rideid.model.sensors.AnalogFilter.response` of each of ``filters``) where its gain
    is at least ``min_gain``, the rest left out. On the even extension of the record, so a run at rest at both
    ends has no edge to ring; a rig's chain filters far from its drive band (an anti-alias low-pass near the
    Nyquist frequency) then changes the posts only where they carry the chain's own lag and droop."""
    z = np.asarray(z, dtype=float)
    if not filters:
        return z.copy()
    n = z.shape[0]
    ext = np.concatenate([z, z[::-1]], axis=0)
    f = np.fft.rfftfreq(2 * n, float(t[1] - t[0]))
    H = np.ones(f.size, dtype=complex)
    for flt in filters:
        H = H * flt.response(f)
    gain = np.abs(H)
    inv = np.where(gain >= min_gain, 1.0 / np.where(gain > 0, H, 1.0), 0.0)
    Z = np.fft.rfft(ext, axis=0) * (inv if z.ndim == 1 else inv[:, None])
    return np.fft.irfft(Z, n=2 * n, axis=0)[:n]


@dataclass(frozen=True)
class PostSignal:
    """A rig's drive signal of the four posts (SPEC §13 scenarios): a function of time with its rate.

    ``kind``: ``"sweep"``, a logarithmic sine sweep from ``f_low`` to ``f_high`` (Hz) over the run, peak
    ``amplitude`` (m), the four posts in ``pattern`` (:data:`PATTERNS`); or ``"random"``, each post its own
    Gaussian band-limited motion, flat in displacement over ``[f_low, f_high]``, RMS ``amplitude`` (m).
    Both fade in and out over ``fade`` s (a raised cosine), so the car stands at rest at the first sample.
    """

    kind: str
    amplitude: float
    f_low: float
    f_high: float
    duration: float
    pattern: str = "heave"
    fade: float = 1.0

    def __post_init__(self):
        if self.kind not in SIGNALS:
            raise ValueError(f"signal: expected one of {', '.join(SIGNALS)}, got {self.kind!r}")
        if self.pattern not in PATTERNS:
            raise ValueError(f"pattern: expected one of {', '.join(PATTERNS)}, got {self.pattern!r}")

    def _envelope(self, t):
        """The fade (raised cosine in and out) and its rate, at ``t``."""
        T, f = self.duration, min(self.fade, self.duration / 4)
        s = np.clip(np.minimum(t, T - t) / f, 0.0, 1.0)
        e = 0.5 - 0.5 * np.cos(np.pi * s)
        sign = np.where(t < T / 2, 1.0, -1.0)
        de = np.where((s > 0) & (s < 1), 0.5 * np.pi / f * np.sin(np.pi * s) * sign, 0.0)
        return e, de

    def function(self, rng=None):
        """``inputs_at(times) -> (r (k, 4), rdot (k, 4))``: the posts' displacements (m) and velocities (m/s).

        ``rng``: a :class:`numpy.random.Generator` (the random signal's phases; unused by a sweep)."""
        if self.kind == "sweep":
            return self._sweep()
        if rng is None:
            raise ValueError("a random post signal needs a seeded numpy.random.Generator")
        return self._random(rng)

    def _sweep(self):
        T, f0, f1 = self.duration, self.f_low, self.f_high
        signs = np.array(PATTERNS[self.pattern])
        k = np.log(f1 / f0) / T

        def inputs_at(times):
            t = np.asarray(times, dtype=float)
            phase = 2 * np.pi * f0 * np.expm1(k * t) / k
            omega = 2 * np.pi * f0 * np.exp(k * t)
            e, de = self._envelope(t)
            z = self.amplitude * e * np.sin(phase)
            zd = self.amplitude * (de * np.sin(phase) + e * omega * np.cos(phase))
            return z[..., None] * signs, zd[..., None] * signs

        return inputs_at

    def _random(self, rng):
        # a multisine on the run's frequency grid (spacing 1/T): every post its own random phases, equal
        # amplitudes over the band, scaled to the RMS asked (before the fade)
        T = self.duration
        freqs = np.arange(np.ceil(self.f_low * T), np.floor(self.f_high * T) + 1) / T
        if freqs.size == 0:
            raise ValueError("random post signal: no frequency of the band fits the run's duration")
        phases = rng.uniform(0, 2 * np.pi, size=(4, freqs.size))
        amp = self.amplitude * np.sqrt(2.0 / freqs.size)
        w = 2 * np.pi * freqs

        def inputs_at(times):
            t = np.asarray(times, dtype=float).reshape(-1)
            z = np.empty((t.size, 4))
            zd = np.empty((t.size, 4))
            for lo in range(0, t.size, 20_000):
                arg = t[lo:lo + 20_000, None] * w[None, :]
                for i in range(4):
                    a = arg + phases[i]
                    z[lo:lo + 20_000, i] = amp * np.sin(a).sum(axis=1)
                    zd[lo:lo + 20_000, i] = amp * (np.cos(a) * w).sum(axis=1)
            e, de = self._envelope(t)
            return ((e[:, None] * z).reshape(np.shape(times) + (4,)),
                    (de[:, None] * z + e[:, None] * zd).reshape(np.shape(times) + (4,)))

        return inputs_at


__all__ = ["MIN_CHAIN_GAIN", "unfilter", "PATTERNS", "POST_CHANNELS", "POST_VEL_CHANNELS", "PostSignal",
           "SIGNALS", "prepare_function", "prepare_posts"]
