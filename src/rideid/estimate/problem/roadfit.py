"""Identification on roads nobody measured (SPEC §9): frequency-domain variable projection.

The problem
-----------
On an unknown road the car's input is unknown: the road under the left and
right wheel paths, ``rho_L(x)`` and ``rho_R(x)``. The rear wheels roll over
the front wheels' paths ``tau = wheelbase / speed`` later, so one run gives
ten channels driven by two unknown signals. The car is linear (SPEC §1 with
the §6 extensions and the CG height), so at each frequency ``omega`` of the
run's discrete Fourier transform (DFT)

    Y(omega) = A(omega) R(omega) + (boundary terms),
    A = [H_fl + H_rl E, H_fr + H_rr E]                      (10 x 2),

where ``H`` (10 x 4) is the car's transfer function from the four corner
inputs to the channels (:func:`rideid.model.equations.state_space`, road
rate terms included), ``R = [R_L, R_R]`` the DFT of the front wheels' road
and ``E(omega)`` the rear wheels' delay. The road is a free complex pair at
every frequency: it is *projected out* (variable projection, Golub and
Pereyra): for given parameters the best road at each frequency is a 2-column
least-squares solution and what is left, ``P_perp(omega) Y(omega)``, is the
part of the ten channels no road can explain. Its squared sum over the
frequencies is the cost; its stacked real and imaginary parts are the
residuals the polish (:func:`fit`) and the uncertainty use.

Why the car is identifiable although the road is unknown: with four
independent corner inputs any tire and unsprung mass would explain the axle
channels (solve each corner's road from its own axle equation); the delay
ties the rear road to the front road, and ``E(omega) = exp(-i omega tau)``
turns through every phase as the frequency rises, so a wrong tire, wrong
unsprung mass or wrong suspension makes the front-inferred and the
rear-inferred roads disagree at some frequencies. Eight accelerometers and
two gyros against two unknown signals leave eight independent equations per
frequency. What stays unidentifiable is what is unidentifiable with a known
road too: every mass, inertia, stiffness and damping scaled by one factor
leaves every transfer function unchanged (the road carries no scale of its
own: ``A`` is unchanged and so is ``R``). One absolute value, normally the
total mass, must be known, as for track runs.

Exactness (why the DFT relation above holds to rounding)
---------------------------------------------------------
A finite record is not periodic. Two exact correction terms make the DFT
relation exact rather than approximate (the approximate form leaves 0.2 %
of the signal's energy unexplained at the true car and biases tires and
unsprung masses by several per cent):

* the *transient*: the run starts and ends in states the periodic solution
  does not have. For a linear system sampled at ``h`` the sampled free
  response's DFT is ``C (I - Phi z^-1)^-1 f`` with ``Phi = exp(A h)``,
  ``z = exp(i omega h)`` and ``f = (I - Phi^N) x_0`` one real 14-vector per
  run; it is unknown (the car may start moving, SPEC §9) and joins the
  projection as 14 real unknowns (18 with a powertrain on mounts);
* the *rear wheels' lead-in*: during the first ``tau`` the rear wheels roll
  over road the front wheels crossed before the record began, not over the
  record's wrapped end. The rear input there is free: ``D`` real unknowns
  per side (the samples ``0 .. D-1``), each acting through ``H_rl`` (``H_rr``)
  as a delayed impulse.

The delay itself is a fractional number of samples in general. The rear
input is the front road sampled between the front wheels' samples; it is
taken as a Lagrange interpolating filter of order setting ``roadfit.delay_order`` on
the front samples (``E(omega)`` its frequency response), exact for road
content well inside the sampling band. Road content at wavelengths shorter
than about two sample spacings (``speed / fs``) is seen by the rear wheel
between the front wheel's samples and by neither sample sequence: it breaks
the front/rear consistency like input noise. Measured: a road profile given
on a 5 cm grid (linear interpolation kinks) at 15 m/s and 200 Hz biases the
tires by -0.5 %; on a 1 cm grid by < 0.02 %; setting ``roadfit.band`` stops at 25 Hz for
the same reason. docs/roads.md says what this asks of a logging rate.

Sensors as wired (SPEC §11)
---------------------------
A channel declared with a ``highpass`` or ``lowpass`` (:mod:`rideid.model.sensors`)
is recorded through its filters. The time-domain model passes the car's
sampled channel through each filter's first-order-hold discretisation; the
road fit does the same in the frequency domain (:func:`with_sensors`,
:func:`sensor_response`, :func:`recorded_columns`). A discrete LTI filter
``x[k+1] = Ad x[k] + Bd u[k]`` over a finite record has the DFT
``F(z) U(z) + C (I - Ad z^-1)^-1 (x_0 - x_N)``, ``z = exp(i omega h)``: the
channel's row of ``H``, of the car's transient columns and of the rear
lead-in's columns is multiplied by the chain's response ``F(z)`` (filters in
series multiply), and the filter's state at the first and last sample joins
the boundary unknowns: per filter mode one real unknown (a real pole) or two
(a conjugate pair), its column ``1 / (1 - lam z^-1)`` on its own channel,
through the filters after it. This is the car's discrete system augmented
with the filters' states. The unknowns are free, so the record's filters may
be in any state at the first sample (a moving start; the time-domain model
needs the steady state of its first sample instead). At the true car, on a
record filtered by the analog filter itself (``lsim`` at 1/8 of a sample),
the projection leaves 2.6e-8 of the fit band's energy for four hubs coupled
at 0.5 Hz (first order), less than the hold's own error in the time domain
(1.3e-7), against 5.1e-4 with the filter left out and 2.3e-5 without the
filters' states (``tests/test_roadfit_sensors.py``).

Clipped samples (SPEC §11)
--------------------------
A sample at its channel's range is not what the channel saw. The DFT of a
record cannot drop one sample, but it can free it: each clipped sample ``n``
of used channel ``j`` is one more real boundary unknown, its column
``exp(-i omega n h)`` on channel ``j`` alone (the recorded value's error,
after the sensor's filters: the range is the recorder's), solved with the
others at every trial car. That is the least-squares fit with the sample
left out; a clipped peak of several samples in a row is determined in the
band only in its few combinations the band can hold, and the solve takes
the shortest of the equivalent solutions. A channel clipped on more than
setting ``roadfit.clip_share`` of its in-band real values, or a run with more than
setting ``roadfit.clip_max`` clipped samples, leaves that channel out whole instead
(:func:`without_clipped`).

The global unknowns' normal equations are assembled in closed form: the
lead-in columns at one frequency are one projected vector times
``exp(-i omega n h)``, so their Gram matrix is a function of ``n - m`` only
(Toeplitz) and costs one sum over frequencies per lag.

Uncertainty (:mod:`rideid.estimate.fit.anyroad`): DFT residuals at different
frequencies are uncorrelated for any stationary noise (white or coloured),
with a variance that may change with frequency, so each frequency's residual
block is one cluster of a sandwich estimate. Its bread is the cost's true
Hessian, not ``J^T J``: the projected residual is linear in the data, so
``J`` carries the noise and ``J^T J`` over-states the information (by a factor
200 along the wheels' common scale on the built-in SUV's roads, measured).
"""

from __future__ import annotations

import functools
import threading
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.linalg
from scipy.interpolate import make_lsq_spline

from ...settings import defaults, legacy_names
from ...model.equations import CHANNEL_KIND, CHANNEL_UNITS, CHANNELS, force_input, state_space
from ...model.nonlinear import damper_force
from ...model.params import INDEX, Geometry
from ...model.sensors import discretise, modal_pairs


def used_channels(y) -> tuple[np.ndarray, dict]:
    """The channels of ``y`` (n, 10; NaN columns absent) the road fit uses, and those it leaves out: name ->
    why (setting ``roadfit.signal_floor``)."""
    y = np.asarray(y, dtype=float)
    present = np.isfinite(y).all(axis=0)
    rms = np.where(present, np.sqrt(np.mean((np.where(present, y, 0.0) - np.where(present, y, 0.0).mean(axis=0))
                                            ** 2, axis=0)), 0.0)
    cols, left = [], {}
    for i, c in enumerate(CHANNELS):
        if not present[i]:
            continue
        same = [j for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c] and present[j]]
        top = max(rms[j] for j in same)
        if rms[i] > defaults["roadfit.signal_floor"] * top and rms[i] > 0:
            cols.append(i)
            continue
        against = max(same, key=lambda j: rms[j])
        share = "" if top == 0 else f", {rms[i] / top:.1g} of {CHANNELS[against]}'s"
        left[c] = (f"left out: RMS {rms[i]:.1g} {CHANNEL_UNITS[c]}{share}, no signal: not excited by this run, "
                   "or its sensor is dead")
    return np.array(cols, dtype=int), left


def suspension_velocities(y, fs: float, drift: float | None = None) -> np.ndarray:
    """Each corner's suspension velocity ``v_i = z_i' - z_bi'`` (n, 4), m/s, compression +, from its axle and body
    accelerometers (``y`` (n, 10), SPEC channels): the difference integrated bin by bin, ``A_k / (i omega_k)``,
    plus the ramp of the record's change of velocity ``A_0 h`` (the DFT's periodic integral has none), less its
    least-squares cubic spline with knots every setting ``roadfit.velocity_drift`` seconds (the integral's drift:
    the noise's random walk, and the start's velocity; a suspension barely moves so slowly).

    Not in the time domain: a sampled acceleration carries the road's content above the Nyquist frequency folded
    into the band, and a running sum turns it into a drift at every frequency. Not a cut below a frequency either:
    on a finite record it rings at both ends. Measured on ../shared/cases/van-roads-dampers (2 % noise) against
    the simulated car's own velocities: 4.2-6.4 mm/s RMS with the spline at 1.5 s (4-6 % of the velocity),
    8.1-8.7 with a cut below 0.2 Hz (29 mm/s in the first and last second); running sums with a high-pass filter
    10-30 % (docs/any-road.md)."""
    drift = defaults["roadfit.velocity_drift"] if drift is None else drift
    y = np.asarray(y, dtype=float)
    a = y[:, 4:8] - y[:, 0:4]
    n = a.shape[0]
    A = np.fft.rfft(a, axis=0)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    V = np.zeros_like(A)
    V[1:] = A[1:] / (2j * np.pi * f[1:, None])
    t = np.arange(n) / fs
    v = np.fft.irfft(V, n, axis=0) + np.outer(t / t[-1], np.real(A[0]) / fs)  # the ramp of the change A_0 h
    inner = np.linspace(t[0], t[-1], max(int(round(t[-1] / drift)), 1) + 1)[1:-1]
    knots = np.r_[[t[0]] * 4, inner, [t[-1]] * 4]
    return v - make_lsq_spline(t, v, knots, k=3)(t)


@dataclass(frozen=True)
class Departure:
    """A road run's damper curves as a known input of the linear car (module docstring "Damper curves"): the
    measured suspension velocities ``v`` (n, 4) (:func:`suspension_velocities`), their DFT ``V`` (bins, 4) and the
    DFT ``Phi`` (bins, 4, K) of each knot's basis curve at them (the curve is linear in its knot forces), ``knots``
    (K,) m/s. ``c_ref``: the linear car's damper rates front and rear (N s/m), held through a fit so that the knot
    forces move the known input alone, not the car (the projection of a car is then reused, :func:`_context`);
    None: the parameter row's ``c_sf``, ``c_sr``. ``y``: the channels (n, 10) the velocities were read from."""

    knots: tuple
    v: np.ndarray
    V: np.ndarray
    Phi: np.ndarray
    c_ref: tuple | None = None
    y: np.ndarray | None = field(default=None, repr=False)
    _at: dict = field(default_factory=dict, repr=False, compare=False)

    def at(self, bins) -> tuple[np.ndarray, np.ndarray]:
        """``Phi`` and ``V`` at ``bins``, taken once per bins array (a fit evaluates thousands of cars on the same
        bins; the last few kept)."""
        hit = self._at.get(id(bins))
        if hit is None or hit[0] is not bins:
            hit = (bins, self.Phi[bins], self.V[bins])
            if len(self._at) >= 4:
                self._at.pop(next(iter(self._at)))
            self._at[id(bins)] = hit
        return hit[1], hit[2]

    def spectrum(self, bins, P_car, curves) -> np.ndarray:
        """The DFT (K, 4) at ``bins`` of each corner's damper force less the linear car's ``c_s v``."""
        Ff, Fr = curves
        F = np.stack([Ff, Ff, Fr, Fr])                                                       # (4, K)
        c = np.array([P_car[INDEX["c_sf"]]] * 2 + [P_car[INDEX["c_sr"]]] * 2)
        Phi, V = self.at(bins)
        return np.einsum("bik,ik->bi", Phi, F) - c[None] * V


def departure_of(y, fs: float, knots) -> Departure:
    """The :class:`Departure` of a run's channels ``y`` (n, 10) for curves on ``knots``."""
    return departure_at(suspension_velocities(y, fs), knots, y=np.asarray(y, dtype=float))


def departure_at(v, knots, c_ref=None, y=None) -> Departure:
    """The :class:`Departure` of suspension velocities ``v`` (n, 4) for curves on ``knots``."""
    K = len(knots)
    basis = damper_force(tuple(knots), np.eye(K), v[..., None])                                # (n, 4, K)
    return Departure(tuple(float(k) for k in knots), v, np.fft.rfft(v, axis=0), np.fft.rfft(basis, axis=0), c_ref,
                     y)


def channel_noise(sol: Solution) -> np.ndarray:
    """Each used channel's noise level (its units, ``rr.cols`` order) as the projection's residual ``sol`` shows
    it, taken as white: a white noise of ``sigma`` has ``n sigma^2`` per DFT bin (weighted by ``rr.scale``), and
    the projection leaves ``(c - 2) / c`` of it (two road columns in ``c`` channels)."""
    rr = sol.rr
    c = len(rr.cols)
    return np.sqrt(np.mean(np.abs(sol.residual) ** 2, axis=0) * c / max(c - 2, 1) / rr.n) / rr.scale


def missing_corners(y) -> list[str]:
    """The body and axle accelerometers a run lacks (NaN columns) for damper curves on its road."""
    y = np.asarray(y, dtype=float)
    return [CHANNELS[j] for j in range(8) if not np.isfinite(y[:, j]).all()]


def car_and_curves(P, rr: RoadRun):
    """``P`` (a parameter row) split into the linear car's row and the curves' front and rear knot forces (None
    without curves: ``rr.dep`` is None). With curves the row ends with ``F_f1 .. F_fK, F_r1 .. F_rK``
    (:class:`rideid.model.nonlinear.NonlinearLayout`) and the linear car's damper rates are ``rr.dep.c_ref``, else
    the row's ``c_sf``, ``c_sr``."""
    P = np.asarray(P, dtype=float)
    if rr.dep is None:
        return P, None
    K = len(rr.dep.knots)
    car = P[..., :-2 * K]
    if rr.dep.c_ref is not None:
        car = car.copy()
        car[..., [INDEX["c_sf"], INDEX["c_sr"]]] = rr.dep.c_ref
    return car, (P[..., -2 * K:-K], P[..., -K:])


def force_columns(car: System, P_car, geom: Geometry, rr: RoadRun, bins) -> np.ndarray:
    """The used channels' response (K, c, 4), weighted and as recorded, to a force pair at each corner
    (:func:`rideid.model.equations.force_input`) at ``bins``. ``car``: the linear car's :class:`System` (its modes
    serve the force input too)."""
    w = rr.omega(bins)
    Bu, Dyu = force_input(np.atleast_2d(P_car), geom)
    forced = replace(car, B=Bu, Dy=Dyu, Br=np.zeros_like(Bu), Dyr=np.zeros_like(Dyu))
    G = transfer(forced, w, rr.cols)[0]                                                      # (K, c, 4)
    sr = sensor_response(rr, w)
    if sr is not None:
        G = G * sr[0][:, :, None]
    return G * rr.scale[None, :, None]


def departure_response(car: System, P_car, geom: Geometry, rr: RoadRun, bins, curves, G=None) -> np.ndarray:
    """The used channels' response (K, c), weighted and as recorded, to the curves' departure from the linear car's
    dampers at ``bins`` (:meth:`Departure.spectrum`); zero without curves. ``G``: the car's
    :func:`force_columns` there when known."""
    if curves is None or rr.dep is None:
        return 0.0
    G = force_columns(car, P_car, geom, rr, bins) if G is None else G
    u = rr.dep.spectrum(bins, P_car, curves)
    return (G @ u[:, :, None])[..., 0]


@dataclass(frozen=True)
class RoadRun:
    """One unknown-road run prepared for the fit.

    Attributes
    ----------
    run_id : str
    fs, speed : float
        Sample rate (Hz) and constant speed (m/s).
    n : int
        Samples.
    cols : (c,) int
        The channels used (:data:`rideid.model.equations.CHANNELS` indices).
    scale : (c,)
        Each used channel's weight, 1 / its RMS.
    Y : (nbins, c) complex
        ``rfft`` of the weighted channels (every bin).
    fit : (K,) int
        The bins of the fit band.
    search : (Ks,) int, Ys : (Ks, c) complex
        The search's bins and its Hann-windowed DFT there.
    tau : float
        Rear wheels' delay (s).
    left_out : dict
        Channels the run has but the fit leaves out (setting ``roadfit.signal_floor``): name -> why, one line.
    sensors : tuple
        Per used channel (``cols`` order) the analog filters of its sensor chain (SPEC §11, a tuple of
        :class:`rideid.model.sensors.AnalogFilter`); empty: no channel filtered (:func:`with_sensors`).
    clip : (m, 2) int
        The clipped samples freed as unknowns (module docstring): position in ``cols``, sample index.
    lead : int or None
        The rear lead-in unknowns per side when held (a run whose speed is estimated: the count fixed for every
        speed the fit may try, so the cost does not jump where ``tau fs`` crosses a whole sample); None: from
        ``tau`` (:attr:`lead_in`).
    dep : Departure or None
        With damper curves: the run's measured suspension velocities and the curves' basis (:func:`departure_of`,
        module docstring "Damper curves"); the parameter rows then end with the curves' knot forces.
    """

    run_id: str
    fs: float
    speed: float
    n: int
    cols: np.ndarray
    scale: np.ndarray
    Y: np.ndarray
    fit: np.ndarray
    search: np.ndarray
    Ys: np.ndarray
    tau: float
    left_out: dict = field(default_factory=dict)
    sensors: tuple = ()
    clip: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=int))
    lead: int | None = None
    dep: Departure | None = None

    @property
    def h(self) -> float:
        return 1.0 / self.fs

    def omega(self, bins) -> np.ndarray:
        return 2 * np.pi * np.asarray(bins) * self.fs / self.n

    @property
    def lead_in(self) -> int:
        """Rear lead-in unknowns per side (samples ``0 .. D-1``): :attr:`lead` when held, else enough for ``tau``."""
        if self.lead is not None:
            return self.lead
        return int(np.floor(self.tau * self.fs)) + defaults["roadfit.delay_order"] + 2


def prepare_road_run(run_id: str, y, fs: float, speed: float, geom: Geometry, cols=None,
                     band=None, clipped=None) -> RoadRun:
    """Prepare a run's channels ``y`` (n, 10; NaN columns unused) for :func:`residuals` and :func:`search_costs`.

    ``cols``: the channels to use; default those :func:`used_channels` keeps (a channel without signal is left
    out and named in ``left_out``). ``clipped`` (n, 10) bool, optional: where a channel sat at its range
    (SPEC §11, :meth:`rideid.data.dataset.Dataset.clipped`); each such sample is a free unknown of the fit
    (``clip``, module docstring), or, past setting ``roadfit.clip_share`` or setting ``roadfit.clip_max``, its
    channel is left out of this run's fit whole (:func:`without_clipped`) and named in ``left_out``."""
    band = defaults["roadfit.band"] if band is None else band
    y = np.asarray(y, dtype=float)
    n = y.shape[0]
    f = np.fft.rfftfreq(n, 1.0 / fs)
    fit = np.nonzero((f >= band[0]) & (f <= min(band[1], 0.45 * fs)))[0]
    y, left, freed = without_clipped(y, clipped, 2 * fit.size)
    if cols is None:
        cols, quiet = used_channels(y)
        left.update(quiet)
    cols = np.asarray(cols, dtype=int)
    yc = y[:, cols]
    yc = yc - yc.mean(axis=0)
    scale = 1.0 / np.sqrt(np.mean(yc ** 2, axis=0))
    Y = np.fft.rfft(yc * scale, axis=0)
    stride = max(1, fit.size // defaults["roadfit.search_bins"])
    search = fit[::stride]
    Ys = np.fft.rfft(yc * scale * np.hanning(n)[:, None], axis=0)[search]
    pos = {int(ch): k for k, ch in enumerate(cols)}
    clip = np.array([(pos[ch], k) for ch in sorted(freed) if ch in pos for k in freed[ch]], dtype=int).reshape(-1, 2)
    return RoadRun(run_id=run_id, fs=float(fs), speed=float(speed), n=n, cols=cols, scale=scale, Y=Y, fit=fit,
                   search=search, Ys=Ys, tau=geom.wheelbase / float(speed), left_out=left, clip=clip)


def without_clipped(y, clipped=None, values=None) -> tuple[np.ndarray, dict, dict]:
    """The clipped samples of ``y`` (n, 10) (``clipped``, (n, 10) bool: where a channel sat at its range), as the
    road fit takes them: ``y`` with the channels left out whole set to NaN, those channels (name -> why, one
    line), and the others' clipped samples (CHANNELS index -> sample indices), each freed as an unknown.

    On a known track the time-domain cost leaves the clipped samples out one by one (SPEC §11). A road fit
    works on the run's DFT, where a peak cut flat is a distortion of every bin, which the free road would
    partly take up and pass on to the car: each clipped sample is freed instead (module docstring). A channel
    clipped on more than setting ``roadfit.clip_share`` of its ``values`` in-band real values (None: no limit), or
    every clipped channel of a run with more than setting ``roadfit.clip_max`` clipped samples, is left out of that
    run's road fit whole; its other runs keep it, and the road stays determined by the other nine (both wheel paths
    enter every channel)."""
    y = np.array(y, dtype=float)
    left, freed = {}, {}
    if clipped is None:
        return y, left, freed
    clipped = np.asarray(clipped, dtype=bool)
    chans = [i for i in np.nonzero(clipped.any(axis=0))[0] if np.isfinite(y[:, i]).all()]
    total = sum(int(np.count_nonzero(clipped[:, i])) for i in chans)
    for i in chans:
        k = int(np.count_nonzero(clipped[:, i]))
        if total <= defaults["roadfit.clip_max"] and (values is None or k <= defaults["roadfit.clip_share"] * values):
            freed[int(i)] = np.nonzero(clipped[:, i])[0]
            continue
        clip_max = defaults["roadfit.clip_max"]
        why = (f"more than {clip_max} clipped samples in the run" if total > clip_max
               else f"more than {100 * defaults['roadfit.clip_share']:.0f} % of its {values} in-band values")
        left[CHANNELS[i]] = (f"left out: {100 * clipped[:, i].mean():.2g} % of its samples at the channel's range "
                             f"(clipped; {why}: the road fit works on the record's DFT)")
        y[:, i] = np.nan
    return y, left, freed


def _clip_columns(rr: RoadRun, omega) -> np.ndarray:
    """The clipped samples' columns (K, c, m) (module docstring): ``exp(-i omega n h)`` on the sample's channel."""
    m = rr.clip.shape[0]
    C = np.zeros((len(omega), len(rr.cols), m), dtype=complex)
    if m:
        C[:, rr.clip[:, 0], np.arange(m)] = np.exp(-1j * np.outer(np.asarray(omega) * rr.h, rr.clip[:, 1]))
    return C


def delay_filter(tau: float, h: float, order: int | None = None):
    """Lagrange fractional-delay filter: taps ``ks`` (samples) and coefficients ``c`` with
    ``u(t - tau) ~ sum c_j u(t - ks_j h)``."""
    order = defaults["roadfit.delay_order"] if order is None else order
    dl = tau / h
    k0 = int(np.floor(dl)) - (order - 1) // 2
    ks = np.arange(k0, k0 + order + 1)
    c = np.array([np.prod([(dl - j) / (k - j) for j in ks if j != k]) for k in ks])
    return ks, c


def rear_delay(rr: RoadRun, omega) -> np.ndarray:
    """``E`` (K,): the rear wheels' delay ``e^{-i omega tau}`` of run ``rr`` at ``omega`` (rad/s) through the fit's
    fractional-delay filter (:func:`delay_filter`), as every road and track fit of the run has it. The same for
    every car: made once per delay and frequencies (:func:`_kept`), read-only."""
    order = int(defaults["roadfit.delay_order"])

    def make():
        ks, c = delay_filter(rr.tau, rr.h, order)
        return np.exp(-1j * np.outer(np.asarray(omega, dtype=float) * rr.h, ks)) @ c
    return _kept(("delay", float(rr.tau), float(rr.h), order), (), omega, make)


#: what a run's fits compute again and again (:func:`_kept`): key -> (the objects keyed by id, value)
_KEPT: OrderedDict = OrderedDict()
_KEPT_LOCK = threading.Lock()


def _kept(values: tuple, objects: tuple, omega, make):
    """``make()`` for the hashable ``values``, the ``objects`` (keyed by identity: each entry holds them, so their
    ids are not reused while it lives) and the frequencies ``omega``, kept for the next call (the last 128).
    Arrays come back read-only."""
    key = (values, tuple(id(a) for a in objects), np.asarray(omega, dtype=float).tobytes())
    with _KEPT_LOCK:
        hit = _KEPT.get(key)
        if hit is not None and all(a is b for a, b in zip(hit[0], objects)):
            _KEPT.move_to_end(key)
            return hit[1]
    value = make()
    for a in (value if isinstance(value, tuple) else (value,)):
        if isinstance(a, np.ndarray):
            a.flags.writeable = False
    with _KEPT_LOCK:
        _KEPT[key] = (objects, value)
        while len(_KEPT) > 128:
            _KEPT.popitem(last=False)
    return value


def _modal(A):
    """Eigenvalues and eigenvectors of each ``A`` (n, 14, 14), and whether the modal form is safe."""
    lam, V = np.linalg.eig(A)
    ok = np.linalg.cond(V) < defaults["roadfit.modal_cond"]
    Vi = np.full_like(V, np.nan)
    if ok.any():
        Vi[ok] = np.linalg.inv(V[ok])
    return lam, V, Vi, ok


@dataclass(frozen=True)
class System:
    """The linear car of parameter rows ``P`` (n, 16): its state-space matrices with the road rate terms
    (:func:`rideid.model.equations.state_space`) and their modal form (eigenvalues ``lam``, eigenvectors
    ``V`` and their inverse ``Vi``; ``ok`` where they are well conditioned). Built once per car, by
    :func:`system`, and shared by its transfer functions and transient columns."""

    A: np.ndarray
    B: np.ndarray
    Cy: np.ndarray
    Dy: np.ndarray
    Br: np.ndarray
    Dyr: np.ndarray
    lam: np.ndarray
    V: np.ndarray
    Vi: np.ndarray
    ok: np.ndarray


def system(P, geom: Geometry) -> System:
    """:class:`System` of parameter rows ``P`` (n, 16) (or one row)."""
    A, B, Cy, Dy, Br, Dyr = state_space(np.atleast_2d(P), geom, rate=True)
    return System(A, B, Cy, Dy, Br, Dyr, *_modal(A))


def transfer(car: System, omega, cols) -> np.ndarray:
    """``H(i omega)`` (n, K, c, 4) of the cars ``car`` (:func:`system`): the used channels' response to the
    corner inputs fl, fr, rl, rr (road rate terms of tire damping included).

    Modal form ``C V diag(1 / (s - lambda)) V^-1 (B + s B_r)`` where the eigenvectors are well
    conditioned, else one linear solve per frequency (tested equal to the explicit inverse). The modal form is
    one matrix product: ``[g, s g]`` (K, 2m), ``g = 1 / (s - lambda)``, times the modes' outer products
    ``(C V)_cm (V^-1 B)_mj`` and ``(C V)_cm (V^-1 B_r)_mj`` (2m, c 4): 1.7 ms a car at 1500 bins and ten
    channels, 3.7 ms as a product per bin (the same numbers to 6e-16)."""
    A, B, Cy, Dy, Br, Dyr = car.A, car.B, car.Cy, car.Dy, car.Br, car.Dyr
    s = 1j * np.asarray(omega)
    n, c = A.shape[0], len(cols)
    H = np.empty((n, s.size, c, 4), dtype=complex)
    for p in range(n):
        if car.ok[p]:
            CV = (Cy[p, cols] @ car.V[p]).T[:, :, None]                                     # (m,c,1)
            g = 1.0 / (s[:, None] - car.lam[p][None])                                        # (K,m)
            T = np.concatenate([CV * (car.Vi[p] @ B[p])[:, None, :], CV * (car.Vi[p] @ Br[p])[:, None, :]])
            H[p] = (np.concatenate([g, s[:, None] * g], axis=1) @ T.reshape(2 * g.shape[1], c * 4)).reshape(-1, c, 4)
        else:
            Ms = s[:, None, None] * np.eye(A.shape[-1]) - A[p][None]
            X = np.linalg.solve(Ms, B[p][None] + s[:, None, None] * Br[p][None])
            H[p] = Cy[p, cols][None] @ X
        H[p] += Dy[p, cols][None] + s[:, None, None] * Dyr[p, cols][None]
    return H


def _road_columns(H, E):
    """``A`` (..., K, c, 2): the left and right front roads' columns (rear through the delay ``E``)."""
    return np.stack([H[..., 0] + H[..., 2] * E[..., :, None], H[..., 1] + H[..., 3] * E[..., :, None]], -1)


def _projector(Acol):
    """``x -> P_perp x`` at each bin, and the road solution ``x -> (A^H A)^-1 A^H x``."""
    AH = np.conj(np.swapaxes(Acol, -1, -2))
    G = AH @ Acol
    det = (G[..., 0, 0] * G[..., 1, 1] - G[..., 0, 1] * G[..., 1, 0])[..., None, None]
    Gi = np.stack([np.stack([G[..., 1, 1], -G[..., 0, 1]], -1), np.stack([-G[..., 1, 0], G[..., 0, 0]], -1)], -2) / det

    def road(X):
        return Gi @ (AH @ X)

    def perp(X):
        return X - Acol @ road(X)

    return perp, road


def search_costs(P, geom: Geometry, runs) -> np.ndarray:
    """Approximate cost (n,) of parameter rows ``P`` (n, 16) for the global search: the projected
    residual of a Hann-windowed DFT at a few hundred bins, without the boundary unknowns (a few per
    cent of bias, no more than the search needs; the polish uses :func:`residuals`)."""
    P = np.atleast_2d(P)
    cost = np.zeros(P.shape[0])
    car = system(P, geom)
    for rr in runs:
        w = rr.omega(rr.search)
        H = transfer(car, w, rr.cols) * rr.scale[None, None, :, None]
        sr = sensor_response(rr, w)
        if sr is not None:  # the channels as the sensors record them (the filters' transients left out, as the car's)
            H = H * sr[0][None, :, :, None]
        E = rear_delay(rr, w)
        perp, _ = _projector(_road_columns(H, E[None]))
        r = perp(np.broadcast_to(rr.Ys[None, :, :, None], H.shape[:3] + (1,)))[..., 0]
        cost += np.sum(np.abs(r) ** 2, axis=(1, 2)) / np.sum(np.abs(rr.Ys) ** 2)
    return cost / len(runs)


@dataclass
class Solution:
    """The projection at one car: residual (K, c) at the fit bins, the global unknowns and what the
    road solution needs (the car's :class:`System`, reused by :func:`road`)."""

    residual: np.ndarray
    f_state: np.ndarray
    f_lead: np.ndarray
    rr: RoadRun
    car: System
    curves: tuple | None = None
    P_car: np.ndarray | None = None


def _discrete_columns(car: System, omega, cols, h):
    """Transient columns ``C (I - Phi z^-1)^-1`` (K, c, 14) of the sampled free response, ``Phi = exp(A h)``,
    of the one car ``car``: in modal form one matrix product, ``g = 1 / (1 - z^-1 e^{lambda h})`` (K, m) times
    the modes' outer products ``(C V)_cm (V^-1)_mj`` (m, c m) (0.4 ms at 1500 bins and ten channels, 2.0 ms as
    a product per bin)."""
    A, Cy = car.A, car.Cy
    zi = np.exp(-1j * np.asarray(omega) * h)
    if car.ok[0]:
        g = 1.0 / (1.0 - zi[:, None] * np.exp(car.lam[0] * h)[None])                       # (K,m)
        T = (Cy[0, cols] @ car.V[0]).T[:, :, None] * car.Vi[0][:, None, :]                  # (m,c,m)
        return (g @ T.reshape(g.shape[1], -1)).reshape(zi.size, len(cols), -1)
    Phi = scipy.linalg.expm(A[0] * h)
    n = A.shape[-1]
    M = np.eye(n)[None] - zi[:, None, None] * Phi[None]
    X = np.linalg.solve(M, np.broadcast_to(np.eye(n), M.shape))
    return Cy[0, cols][None] @ X


# --- sensors as wired (SPEC §11): the declared filters of each channel, bin by bin (module docstring) ---------

def with_sensors(rr: RoadRun, filters) -> RoadRun:
    """``rr`` with its channels' declared sensor chains: ``filters`` per SPEC channel (the ten, CHANNELS order)
    a tuple of :class:`rideid.model.sensors.AnalogFilter` (:meth:`rideid.data.dataset.Dataset.sensor_filters`);
    the used channels' are kept."""
    chain = tuple(tuple(filters[c]) for c in rr.cols)
    return replace(rr, sensors=chain if any(chain) else ())


def _free_modes(lam, zi) -> np.ndarray:
    """DFT columns (K, m) of a discrete filter's free response over a record, ``1 / (1 - lam z^-1)`` per mode,
    in real coordinates: a real mode one column, a conjugate pair two (``q_i + q_j`` and ``i (q_i - q_j)``: the
    DFT of a real sequence ``w lam_i^k + conj(w lam_i^k)``, ``w`` complex). Their real combinations are every
    free response of the filter whatever its output map (an unobservable mode would only add a free column)."""
    q = 1.0 / (1.0 - zi[:, None] * lam[None])
    cols = []
    for i, j in modal_pairs(lam):
        cols += [q[:, i]] if j is None else [q[:, i] + q[:, j], 1j * (q[:, i] - q[:, j])]
    return np.stack(cols, axis=1)


def sensor_response(rr: RoadRun, omega):
    """The run's sensor chains at the frequencies ``omega`` (rad/s): ``F`` (K, c), each used channel's chain's
    frequency response at ``z = exp(i omega h)`` (the first-order-hold filters of
    :func:`rideid.model.sensors.discretise`, in series; 1 for an unfiltered channel), and ``T`` (K, c, m) the
    filters' free responses (their states at the first and last sample, :func:`_free_modes`), each through the
    filters after it in its chain: ``m`` real boundary unknowns, one column per filter mode, each on its own
    channel. None when no channel of ``rr`` is filtered. The same for every car and speed: made once per chain
    and frequencies (:func:`_kept`), read-only."""
    if not rr.sensors:
        return None
    return _kept(("sensors", float(rr.h)), (rr.sensors, rr.cols), omega, lambda: _sensor_response(rr, omega))


def _sensor_response(rr: RoadRun, omega):
    z = np.exp(1j * np.asarray(omega, dtype=float) * rr.h)
    K, c = z.size, len(rr.cols)
    F = np.ones((K, c), dtype=complex)
    blocks = []
    for ch, chain in enumerate(rr.sensors):
        for filt in chain:
            d = discretise(filt, rr.h)
            Ff = d.d + ((d.c * d.g)[None] / (z[:, None] - d.lam[None])).sum(axis=1)
            for b in blocks:  # the free responses before this filter pass through it
                if b[0] == ch:
                    b[1] *= Ff[:, None]
            blocks.append([ch, _free_modes(d.lam, 1.0 / z)])
            F[:, ch] *= Ff
    T = np.zeros((K, c, sum(b[1].shape[1] for b in blocks)), dtype=complex)
    j = 0
    for ch, cols in blocks:
        T[:, ch, j:j + cols.shape[1]] = cols
        j += cols.shape[1]
    return F, T


def recorded_columns(car: System, rr: RoadRun, omega):
    """The used channels as ``rr``'s sensors record them, weighted (``rr.scale``), at ``omega``: ``H`` (K, c, 4)
    the car's transfer function (:func:`transfer`) and ``S`` (K, c, m) the boundary columns: the car's transient
    (:func:`_discrete_columns`), both through each channel's filters (:func:`sensor_response`), then the
    filters' own free responses (their states at the first sample, unknown like the car's). Without filters
    ``S`` is the car's 14 (18 with a powertrain) transient columns alone; the clipped samples' columns come last
    (:func:`_clip_columns`, not through the filters). One car (``car`` of one row)."""
    H = transfer(car, omega, rr.cols)[0]
    S = _discrete_columns(car, omega, rr.cols, rr.h)
    sr = sensor_response(rr, omega)
    if sr is not None:
        F, T = sr
        H = H * F[:, :, None]
        S = np.concatenate([S * F[:, :, None], T], axis=2)
    if rr.clip.shape[0]:
        S = np.concatenate([S, _clip_columns(rr, omega)], axis=2)
    return H * rr.scale[None, :, None], S * rr.scale[None, :, None]


def car_columns(P, geom: Geometry, rr: RoadRun, bins):
    """``(car, H, S)``: the :class:`System` of the car ``P`` (one row) and its :func:`recorded_columns` on ``rr`` at
    ``bins``, read-only. Kept (:func:`_kept`): a run's placement (the motion alignment, the motion's Jacobian, the
    joint solve's motion columns) moves its speed and start at one car, and a moved run
    (:func:`rideid.estimate.problem.asbuilt.moved`) keeps its channels, sensors, clipped samples and bins, which
    with the car are all these depend on (not the speed, not the delay): a third of each of those evaluations was
    the car and its columns made again."""
    w = rr.omega(bins)

    def make():
        car = system(P, geom)
        return (car, *recorded_columns(car, rr, w))
    return _kept(("car", np.asarray(P, dtype=float).tobytes(), float(rr.h), float(defaults["roadfit.modal_cond"])),
                 (geom, rr.cols, rr.scale, rr.sensors, rr.clip), w, make)


def forget() -> None:
    """Drop what the road fits keep between calls (a car's columns, a run's delay and sensor chains, the
    curves' contexts): for a caller that changes how they are computed (a test's stand-in for one of them)."""
    for cache, lock in ((_KEPT, _KEPT_LOCK), (_CONTEXTS, _CONTEXTS_LOCK)):
        with lock:
            cache.clear()


def lead_in_normal_equations(g, aL, aR, r, wh, D: int):
    """``(G, b, en)``: the real normal equations ``G f = b`` of the data ``r`` (K, c) at the bins ``wh = w h``
    (K,) in the columns ``g`` (K, c, nb) with real coefficients and the rear wheels' ``D`` lead-in samples on
    each side, which enter through ``aL``, ``aR`` (K, c) times ``en`` (K, D) ``= e^{-i w n h}``; the unknowns
    ``f`` are ``[the nb coefficients, the left lead-in, the right lead-in]``."""
    G, en = lead_in_gram(g, aL, aR, wh, D)
    return G, lead_in_rhs(g, aL, aR, r, en), en


def lead_in_gram(g, aL, aR, wh, D: int, gr=None):
    """The matrix ``G`` of :func:`lead_in_normal_equations` (it does not depend on the data) and ``en``. ``gr``:
    ``g`` as real rows (:func:`real_rows`) when known."""
    nb = g.shape[-1]
    gr = real_rows(g) if gr is None else gr
    G = np.zeros((nb + 2 * D, nb + 2 * D))
    G[:nb, :nb] = gr.T @ gr
    ph, en = _lead_in_phases(np.asarray(wh, dtype=float).tobytes(), D)
    gH = np.conj(np.swapaxes(g, 1, 2))                                                        # (K,nb,c)
    for j, a in enumerate((aL, aR)):
        sl = slice(nb + j * D, nb + (j + 1) * D)
        G[:nb, sl] = ((gH @ a[:, :, None])[..., 0].T @ en).real
        G[sl, :nb] = G[:nb, sl].T
        for i, a2 in enumerate((aL, aR)):
            # (n, m): sum_k conj(a e^{-iwnh}) a2 e^{-iwmh} = sum_k conj(a) a2 e^{iw(n-m)h}, a Toeplitz block
            G[sl, slice(nb + i * D, nb + (i + 1) * D)] = _toeplitz((np.sum(np.conj(a) * a2, axis=1) @ ph).real, D)
    return G, en


def _toeplitz(t, D: int) -> np.ndarray:
    """The ``(D, D)`` matrix ``T[n, m] = t[n - m + D - 1]`` of ``t`` ``(2 D - 1,)``, as a strided view of ``t`` (read
    only): the same numbers as indexing ``t`` with the lags' matrix, without building it and gathering (a slow
    run's lead-in is 200 samples a side)."""
    t = np.ascontiguousarray(t)
    return np.lib.stride_tricks.as_strided(t[D - 1:], shape=(D, D), strides=(t.strides[0], -t.strides[0]),
                                           writeable=False)


@functools.lru_cache(maxsize=64)
def _lead_in_phases(wh_bytes: bytes, D: int) -> tuple[np.ndarray, np.ndarray]:
    """``e^{i w h n}`` at the bins ``wh`` (given as the bytes of a float array) for ``n`` = -(D-1) .. D-1, and
    ``en = e^{-i w h n}`` for ``n`` = 0 .. D-1: the same for every car on one run, and a quarter of a road fit's
    time when computed each time (a slow run's lead-in is 80 samples, its fit 300 bins). Read-only."""
    wh = np.frombuffer(wh_bytes, dtype=float)
    ph = np.exp(1j * np.outer(wh, np.arange(-(D - 1), D)))                                   # (K, 2D-1)
    en = np.exp(-1j * np.outer(wh, np.arange(D)))                                            # (K, D)
    ph.flags.writeable = False
    en.flags.writeable = False
    return ph, en


def lead_in_rhs(g, aL, aR, r, en, gr=None) -> np.ndarray:
    """The right-hand side ``b`` of :func:`lead_in_normal_equations` for the data ``r`` (K, c). ``gr``: the
    columns ``g`` as real rows (:func:`real_rows`) when known (a car's context keeps them for every right-hand
    side)."""
    gr = real_rows(g) if gr is None else gr
    b = [gr.T @ np.concatenate([r.real.ravel(), r.imag.ravel()])]
    # Re sum_k conj(a_k) r_k e^{+i w_k n h} = Re sum_k a_k conj(r_k) e^{-i w_k n h}: ``en`` as it is, not conjugated
    rc = np.conj(r)
    b += [(np.sum(a * rc, axis=1) @ en).real for a in (aL, aR)]
    return np.concatenate(b)


def real_rows(g) -> np.ndarray:
    """The complex columns ``g`` (K, c, nb) as real rows (2 K c, nb): the real parts, then the imaginary."""
    gf = g.reshape(-1, g.shape[-1])
    return np.concatenate([gf.real, gf.imag])


def _damped_factor(G, eps: float = 1e-11):
    """The solver ``b -> (G + eps lambda_max I)^-1 b`` of the symmetric positive semi-definite normal equations
    ``G`` (equilibrated), ``eps`` = 1e-11: ``G`` factored once, for every right-hand side.

    Not a pseudo-inverse cut at a relative ``rcond``: the boundary unknowns' normal equations carry eigenvalues near
    any cut, and as the car moves one crossing it switches a direction in or out, so the residual jumps. Measured on
    a 60 s road run (C_30 of examples/roads/class_b.toml, 80 lead-in samples):
    the residual's derivative in m_uf by central differences of 1e-5 was 0.5 % off its 1e-4 value with the cut
    at 1e-13 (at 73, 77 and 80 lead-in samples; below 0.03 % at others), and through the polish's Jacobian the
    unsprung masses' std_robust had doubled; damped at 1e-11 it is the same to five digits at every count from
    72 to 81, the cost within 0.01 % of the cut's. At 1e-13 the damping amplified rounding (one scale of the
    whole car moved the residual by 1e-3, tests/test_roadfit.py); 1e-10 and 1e-9 serve as well.

    The damped matrix is positive definite (its condition at most 1/eps), so a Cholesky factor solves it, with
    ``lambda_max`` from the Rayleigh quotient of a few power steps (a tenth of an eigendecomposition's time at the
    130-180 unknowns of a road run's lead-in: the damping needs its scale, not its digits); an eigendecomposition
    where the factor fails (``G`` not positive semi-definite beyond the damping: its negative eigenvalues taken
    as 0)."""
    d = np.sqrt(np.clip(np.diag(G), 1e-300, None))
    Ge = G / np.outer(d, d)
    Ge = 0.5 * (Ge + Ge.T)
    try:
        c = scipy.linalg.cho_factor(Ge + (eps * _largest_eigenvalue(Ge)) * np.eye(Ge.shape[0]), check_finite=False)
        return lambda b: scipy.linalg.cho_solve(c, b / d, check_finite=False) / d
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(Ge)
        damped = np.clip(w, 0.0, None) + eps * max(w[-1], 1e-300)
        return lambda b: V @ ((V.T @ (b / d)) / damped) / d


def _largest_eigenvalue(A, steps: int = 12) -> float:
    """The largest eigenvalue of the symmetric positive semi-definite ``A``, to a few per cent: the Rayleigh
    quotient after ``steps`` power steps from the vector of ones (deterministic; an under-estimate, never above)."""
    x = np.ones(A.shape[0])
    for _ in range(steps):
        y = A @ x
        x = y / max(float(np.linalg.norm(y)), 1e-300)
    return max(float(x @ (A @ x)), 1e-300)


@dataclass(frozen=True)
class _Context:
    """What the projection of one run at one linear car needs whatever the data (:func:`solve`): the car, its road
    projector, the projected boundary columns (``S``; ``gr`` the same as real rows) and the solver of their normal
    equations (:func:`_damped_factor`); with damper curves its response to the corners' force pairs
    (:func:`force_columns`)."""

    car: System
    perp: object
    S: np.ndarray
    aL: np.ndarray
    aR: np.ndarray
    en: np.ndarray
    solve: object
    gr: np.ndarray
    forces: np.ndarray | None = None


#: with damper curves, the contexts of the last few cars (:func:`_context`): the curves' knot forces move the
#: data's known input, not the car, so the error bars' finite differences in them reuse their car's
_CONTEXTS: OrderedDict = OrderedDict()
_CONTEXTS_LOCK = threading.Lock()


def _context(P, geom: Geometry, rr: RoadRun, bins) -> _Context:
    """The :class:`_Context` of car ``P`` on ``rr`` at ``bins``; with damper curves cached (the last 16)."""
    key = None
    if rr.dep is not None:
        key = (id(rr), id(bins), np.asarray(P, dtype=float).tobytes())
        with _CONTEXTS_LOCK:
            hit = _CONTEXTS.get(key)
            if hit is not None and hit[0] is rr and hit[1] is bins:
                _CONTEXTS.move_to_end(key)
                return hit[2]
    w = rr.omega(bins)
    h = rr.h
    car, H, S = car_columns(P, geom, rr, bins)                                               # (K,c,4), (K,c,ns)
    E = rear_delay(rr, w)
    perp, _ = _projector(_road_columns(H, E))
    S = perp(S)
    aL = perp(H[:, :, 2:3])[..., 0]                                                          # (K,c)
    aR = perp(H[:, :, 3:4])[..., 0]
    gr = real_rows(S)
    G, en = lead_in_gram(S, aL, aR, w * h, rr.lead_in, gr)
    forces = None if rr.dep is None else force_columns(car, P, geom, rr, bins)
    ctx = _Context(car, perp, S, aL, aR, en, _damped_factor(G), gr, forces)
    if key is not None:
        with _CONTEXTS_LOCK:
            _CONTEXTS[key] = (rr, bins, ctx)
            while len(_CONTEXTS) > 16:
                _CONTEXTS.popitem(last=False)
    return ctx


def solve(P, geom: Geometry, rr: RoadRun, bins=None) -> Solution:
    """Project the road out of run ``rr`` at the car ``P`` (16,) (module docstring): the residual at
    the fit bins and the global unknowns (transient ``f``, rear lead-in samples)."""
    bins = rr.fit if bins is None else bins
    P, curves = car_and_curves(P, rr)
    ctx = _context(P, geom, rr, bins)
    Y = rr.Y[bins] - departure_response(ctx.car, P, geom, rr, bins, curves, ctx.forces)
    r = ctx.perp(Y[:, :, None])[..., 0]                                                      # (K,c)
    D = rr.lead_in
    b = lead_in_rhs(ctx.S, ctx.aL, ctx.aR, r, ctx.en, ctx.gr)
    ns = ctx.S.shape[-1]  # the car's states: 14, 18 with a powertrain on mounts, + the sensor filters' (SPEC §11)
    f = ctx.solve(b)
    fS, fL, fR = f[:ns], f[ns:ns + D], f[ns + D:]
    res = r - ctx.S @ fS - ctx.aL * (ctx.en @ fL)[:, None] - ctx.aR * (ctx.en @ fR)[:, None]
    return Solution(residual=res, f_state=fS, f_lead=np.stack([fL, fR]), rr=rr, car=ctx.car, curves=curves,
                    P_car=P)


def residuals(P, geom: Geometry, rr: RoadRun) -> np.ndarray:
    """Real residual vector (2 K c,) of run ``rr`` at the car ``P``: real and imaginary parts, bin-major."""
    r = solve(P, geom, rr).residual
    return np.concatenate([r.real, r.imag], axis=1).ravel()


def road(P, geom: Geometry, rr: RoadRun, sol: Solution | None = None, wavelengths=None):
    """The estimated road under the left and right wheel paths.

    The road's DFT is solved at every bin from half the band's lowest frequency to 1.5 times its highest
    (within 0.45 fs), then band-passed to ``wavelengths`` by a zero-phase Butterworth filter
    (:func:`band_pass`): a smooth filter keeps the record's ends (where the start's state and the road
    just before it cannot be told apart) from ringing into the middle as a brick-wall cut would.

    Returns
    -------
    x : (n,) m, the front axle's position from its position at the first sample
    z : (n, 2) m, left and right road heights over ``wavelengths`` (the road's content the accelerations
        carry; outside, nothing is claimed)
    """
    wavelengths = defaults["roadfit.road_wavelengths"] if wavelengths is None else wavelengths
    sol = solve(P, geom, rr) if sol is None else sol
    f = np.fft.rfftfreq(rr.n, rr.h)
    lo, hi = 0.5 * rr.speed / wavelengths[1], min(1.5 * rr.speed / wavelengths[0], 0.45 * rr.fs)
    bins = np.nonzero((f >= lo) & (f <= hi))[0]
    w = rr.omega(bins)
    h = rr.h
    H, S = recorded_columns(sol.car, rr, w)
    E = rear_delay(rr, w)
    _, road_of = _projector(_road_columns(H, E))
    D = rr.lead_in
    en = np.exp(-1j * np.outer(w * h, np.arange(D)))
    known = (S @ sol.f_state
             + H[:, :, 2] * (en @ sol.f_lead[0])[:, None] + H[:, :, 3] * (en @ sol.f_lead[1])[:, None])
    # the boundary unknowns are fitted in the fit band only: outside it their spectrum is not determined
    # (D free samples have content up to the Nyquist frequency), and subtracting it would add noise there
    known[~np.isin(bins, rr.fit)] = 0.0
    known = known + departure_response(sol.car, sol.P_car, geom, rr, bins, sol.curves)
    R = road_of((rr.Y[bins] - known)[:, :, None])[..., 0]                                  # (K, 2)
    full = np.zeros((f.size, 2), dtype=complex)
    full[bins] = R
    x = rr.speed * np.arange(rr.n) * h
    return x, band_pass(np.fft.irfft(full, n=rr.n, axis=0), rr.speed * h, wavelengths)


def band_pass(z, dx: float, wavelengths=None):
    """Zero-phase 4th-order Butterworth band-pass of road heights ``z`` (n, ...) sampled every ``dx`` m to
    the ``wavelengths`` (m) band (the comparison docs/any-road.md and the tests make with a true road)."""
    wavelengths = defaults["roadfit.road_wavelengths"] if wavelengths is None else wavelengths
    from scipy.signal import butter, sosfiltfilt
    nyq = 0.5 / dx
    hi = min(1.0 / wavelengths[0], 0.95 * nyq)
    sos = butter(4, [1.0 / wavelengths[1], hi], btype="band", fs=1.0 / dx, output="sos")
    return sosfiltfilt(sos, z, axis=0)


def fitted_channels(P, geom: Geometry, rr: RoadRun, y, sol: Solution | None = None) -> np.ndarray:
    """The model's channels (n, 10) at the estimated road: the measured ones minus the residual of the
    fit band (NaN for unused channels). Outside the fit band the residual is not modelled (zero).
    ``sol``: the projection at ``P`` when already solved (:func:`solve`)."""
    sol = solve(P, geom, rr) if sol is None else sol
    return channels_less(rr, y, sol.residual)


def channels_less(rr: RoadRun, y, residual) -> np.ndarray:
    """The channels ``y`` (n, 10) of run ``rr`` less the fit band's ``residual`` (K, c) taken back to time (zero
    outside the fit band; NaN for the channels the run does not use)."""
    full = np.zeros(rr.Y.shape, dtype=complex)
    full[rr.fit] = residual
    e = np.fft.irfft(full, n=rr.n, axis=0) / rr.scale
    out = np.full((rr.n, 10), np.nan)
    out[:, rr.cols] = np.asarray(y, dtype=float)[:, rr.cols] - e
    return out


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "BAND": "roadfit.band", "DELAY_ORDER": "roadfit.delay_order", "ROAD_WAVELENGTHS":
    "roadfit.road_wavelengths", "SEARCH_BINS": "roadfit.search_bins", "CLIP_SHARE": "roadfit.clip_share",
    "CLIP_MAX": "roadfit.clip_max", "SIGNAL_FLOOR": "roadfit.signal_floor", "MODAL_COND": "roadfit.modal_cond"})
