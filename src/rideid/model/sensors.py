"""Sensors as wired (SPEC §11): the analog filters a sensor chain applies before a value is recorded.

An IEPE accelerometer is AC-coupled (a high-pass of about 0.5 Hz), a logger
low-passes before it samples. rideid passes the model's channels through the
same filters before comparing them with the data, so the parameters it
returns are the car's and not the sensor chain's.

**The filter.** ``[channels] <name> highpass = 0.5`` is a first-order analog
high-pass at 0.5 Hz; ``{ hz = 0.5, order = 2 }`` an analog Butterworth of
that order (:func:`scipy.signal.butter` with ``analog=True``); ``lowpass``
likewise. A channel may have both; they act in series (high-pass first; the
order does not matter for linear filters).

**Discretisation: first-order hold.** The analog filter acts on the
continuous signal; the model gives its instantaneous values at the samples.
Between two samples the continuous signal is taken as the straight line
through them (first-order hold), and the filter's state equation is solved
exactly over each interval for that input (:func:`scipy.signal.cont2discrete`
``method="foh"``, the matrix exponential of the augmented system). This is
exact for a piecewise-linear input (to 2e-8 against :func:`scipy.signal.lsim`,
``tests/test_sensors.py``), and for a smooth signal its error is the linear
interpolation's, integrated by the filter: with content to 17 Hz at 200 Hz,
2.2e-4 (0.5 Hz high-pass, order 1) to 1.2e-3 (order 8) of the signal's peak
against lsim at 1/32 of a sample, about 5e-3 for low-passes at 20-80 Hz,
falling as ``h**2``. A zero-order hold would instead delay the signal by
half a sample inside the filter; the bilinear transform warps frequencies.

The discrete state space is diagonalised (a Butterworth filter's poles are
distinct, ``exp(p h)`` of the analog ones) and run as real first-order
recursions (a real mode) and second-order sections (a conjugate pair) in
parallel (:func:`scipy.signal.lfilter`, compiled, along time, all candidates
and all channels with the same filters in one call). No transfer-function
polynomial and no zeros are formed: the hold-equivalent of an 8th-order
filter has zeros that span four decades, which the system pencil does not
give to useful accuracy (tried: 130 % wrong responses); the modes are exact.

**The state at the first sample.** A run on a known track begins at rest
(SPEC §2): the model's channels are exactly 0 there and long before, so the
filter's state is 0. In general (a moving start) the state is the steady
state of the model's first sample held forever (:func:`scipy.signal.lfilter_zi`
times that value): for a rest start it is the same 0, and it is the one
choice that is linear in the signal (the start derivative of the polish
passes through the same filter). A real high-pass sensor's state at the
record start is unknown for a car already moving: what the choice gets wrong
decays with the filter's time constant ``1 / (2 pi f)`` (0.32 s for 0.5 Hz),
so leave five of them out of a moving start's window.

**In the frequency domain.** Where the road is fitted per DFT bin (unknown
roads, tracks as built: :mod:`rideid.estimate.problem.roadfit`,
:mod:`rideid.estimate.problem.asbuilt`) the same discrete filter enters as its
response at ``z = exp(i omega h)`` (``d + sum c g / (z - lam)`` of
:class:`DiscreteFilter`), and its state at the first sample is not chosen
but estimated with the car's (the modes' free responses are boundary
unknowns): a moving start needs nothing left out there.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

#: the orders an analog Butterworth filter of a ``[channels]`` entry may have
ORDERS = (1, 8)
KINDS = ("highpass", "lowpass")


@dataclass(frozen=True)
class AnalogFilter:
    """An analog Butterworth filter of a sensor chain.

    Parameters
    ----------
    kind : {"highpass", "lowpass"}
        Which side of ``hz`` passes: ``"highpass"`` above (an AC-coupled sensor), ``"lowpass"`` below (a logger's
        anti-alias filter).
    hz : float
        Corner (-3 dB) frequency, Hz, positive.
    order : int
        1 to 8 (:data:`ORDERS`).
    """

    kind: str
    hz: float
    order: int = 1

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"AnalogFilter kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if not (math.isfinite(self.hz) and self.hz > 0):
            raise ValueError(f"AnalogFilter hz must be a positive frequency, got {self.hz!r}")
        if not (ORDERS[0] <= self.order <= ORDERS[1]):
            raise ValueError(f"AnalogFilter order must be {ORDERS[0]} to {ORDERS[1]}, got {self.order!r}")

    def describe(self) -> str:
        """``"high-pass 0.5 Hz, order 2"``."""
        return f"{'high' if self.kind == 'highpass' else 'low'}-pass {self.hz:g} Hz, order {self.order}"

    def to_table(self):
        """As ``[channels]`` writes it: a number for first order, else ``{ hz, order }``."""
        return self.hz if self.order == 1 else {"hz": self.hz, "order": self.order}

    def analog_ss(self):
        """``(A, B, C, D)`` of the analog filter (:func:`scipy.signal.butter`, ``analog=True``)."""
        from scipy.signal import butter, zpk2ss
        z, p, k = butter(self.order, 2 * math.pi * self.hz, btype=self.kind, analog=True, output="zpk")
        return zpk2ss(z, p, k)

    def response(self, f_hz) -> np.ndarray:
        """The analog filter's complex frequency response at ``f_hz`` (Hz)."""
        from scipy.signal import butter, freqs_zpk
        z, p, k = butter(self.order, 2 * math.pi * self.hz, btype=self.kind, analog=True, output="zpk")
        return freqs_zpk(z, p, k, worN=2 * math.pi * np.atleast_1d(np.asarray(f_hz, dtype=float)))[1]


@dataclass(frozen=True)
class DiscreteFilter:
    """A filter discretised at a sample interval, in modal (parallel) form.

    The discrete state space ``x[k+1] = Ad x[k] + Bd u[k]``, ``y[k] = Cd x[k] + Dd u[k]`` diagonalised,
    ``Ad = V diag(lam) V^-1``: each mode ``z_i[k+1] = lam_i z_i[k] + g_i u[k]`` is a first-order recursion,
    ``y = Re(sum_i c_i z_i) + d u``. A Butterworth filter's poles are distinct, so ``V`` is well conditioned;
    no polynomial coefficients and no zeros are formed (the zeros of an 8th-order hold-equivalent system
    span four decades and are not computable to useful accuracy; the modes are).
    """

    lam: np.ndarray
    g: np.ndarray
    c: np.ndarray
    d: float

    def real_sections(self) -> list:
        """The modes as real recursions ``(b, a)`` for :func:`scipy.signal.lfilter`: a real mode alone
        (``r / (z - lam)``, residue ``r = c g``), a conjugate pair as one second-order section (the sum of
        the two, real)."""
        lam, r = np.asarray(self.lam), np.asarray(self.c) * np.asarray(self.g)
        secs = []
        for i, j in modal_pairs(lam):
            if j is None:
                secs.append((np.array([0.0, r[i].real]), np.array([1.0, -lam[i].real])))
            else:
                secs.append((np.array([0.0, 2 * r[i].real, -2 * (r[i] * np.conj(lam[i])).real]),
                             np.array([1.0, -2 * lam[i].real, abs(lam[i]) ** 2])))
        return secs

    def apply(self, x, axis: int = -1, u0=None, sections=None) -> np.ndarray:
        """Filter ``x`` along ``axis``; the state at the first sample the steady state of ``u0`` held
        forever (default: the first sample's value). ``sections``: :meth:`real_sections`, computed once."""
        from scipy.signal import lfilter, lfilter_zi
        x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
        u0 = x[..., 0] if u0 is None else np.asarray(u0, dtype=float)
        y = self.d * x
        for b, a in (self.real_sections() if sections is None else sections):
            zi = lfilter_zi(b, a)  # the state of a unit step held forever
            y += lfilter(b, a, x, axis=-1, zi=u0[..., None] * zi)[0]
        return np.moveaxis(y, -1, axis)


def modal_pairs(lam) -> list:
    """The modes ``lam`` of a real discrete filter as ``(i, None)`` for a real mode and ``(i, j)`` for a conjugate
    pair (``j`` the mode nearest ``conj(lam[i])``), each mode once, in order of first appearance."""
    lam = np.asarray(lam)
    out, used = [], np.zeros(lam.size, dtype=bool)
    for i in range(lam.size):
        if used[i]:
            continue
        used[i] = True
        if abs(lam[i].imag) <= 1e-12 * max(1.0, abs(lam[i])):
            out.append((i, None))
            continue
        j = min((j for j in range(lam.size) if not used[j]), key=lambda j: abs(lam[j] - np.conj(lam[i])))
        used[j] = True
        out.append((i, j))
    return out


@functools.lru_cache(maxsize=256)
def discretise(filt: AnalogFilter, h: float) -> DiscreteFilter:
    """``filt`` discretised by first-order hold at the sample interval ``h`` (s), in modal form
    (module docstring). Cached: a filter and a rate give one discrete filter (a few ms to make, the
    matrix exponential), made once for every run, candidate and call."""
    from scipy.signal import cont2discrete
    A, B, C, D = filt.analog_ss()
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, C, D), h, method="foh")
    lam, V = np.linalg.eig(Ad)
    g = np.linalg.solve(V, Bd[:, 0].astype(complex))
    c = (Cd @ V)[0]
    return DiscreteFilter(lam, g, c, float(Dd[0, 0]))


@dataclass(frozen=True)
class SensorChain:
    """The filters of each channel of one run: ``filters[c]`` the tuple of :class:`AnalogFilter` of channel
    ``c`` (the ten SPEC channels' order, :data:`rideid.model.equations.CHANNELS`), applied in that order.

    Parameters
    ----------
    filters : tuple of 10 tuples of AnalogFilter
    h : float
        The run's sample interval, s.
    """

    filters: tuple
    h: float

    @property
    def active(self) -> bool:
        """Whether any channel has a filter."""
        return any(self.filters)

    def sections(self) -> list:
        """Per channel its filters discretised, each with its real sections
        (``[(DiscreteFilter, sections), ...]``; an empty list: unfiltered)."""
        out = []
        for fs in self.filters:
            chain = []
            for f in fs:
                d = discretise(f, self.h)
                chain.append((d, d.real_sections()))
            out.append(chain)
        return out

    def apply(self, Y, sections=None, out=None) -> np.ndarray:
        """The channels ``Y`` as recorded through this chain.

        Parameters
        ----------
        Y : array_like, shape (..., n_time, 10)
            Instantaneous channel values at the run's samples (a population's outputs stack candidates
            in front).
        sections : list, optional
            :meth:`sections` computed once (default: computed here).
        out : ndarray, optional
            Where to write (may be ``Y`` itself: filtered in place); default a copy of ``Y``.

        Returns
        -------
        ndarray, same shape: filtered along time, the filters' state at the first sample the steady
        state of that sample's value (module docstring); unfiltered channels returned as they are.
        Channels with the same filters are filtered together (one call per section for all of them).
        """
        Y = np.asarray(Y, dtype=float)
        out = Y.copy() if out is None else out
        sections = self.sections() if sections is None else sections
        groups: dict = {}
        for c, fs in enumerate(self.filters):
            if fs:
                groups.setdefault(fs, []).append(c)
        for cols in groups.values():
            x = np.moveaxis(Y[..., cols], -1, -2)  # (..., k, n_time)
            for filt, secs in sections[cols[0]]:
                x = filt.apply(x, axis=-1, sections=secs)
            out[..., cols] = np.moveaxis(x, -2, -1)
        return out


class SensorSimulator:
    """A bound simulator (:meth:`rideid.model.simulator.Simulator.bind`) whose channels are recorded through
    the runs' sensor chains, compared only where the data are kept, and cut to the recorded samples.

    Parameters
    ----------
    sim : BatchSimulator or NonlinearSimulator
        The bound simulator of the car; every attribute not defined here is its (``groups``, ``pin_at``,
        ``states`` ...).
    chains : list of SensorChain
        One per run, in the runs' order.
    keep : ndarray, shape (n_samples, 10), optional
        1 where a sample is compared, 0 where it is left out (a channel at its range, a moving start's settling
        time); None: every sample. ``n_samples``: the recorded samples of every run.
    lead : sequence of int, optional
        Per run, the samples ``sim`` simulates before the run's first recorded one (a moving start's lead-in,
        SPEC §9; :func:`rideid.data.dataset.run_lead_in`): the car starts at rest there, the sensor chains
        filter from there, and the outputs begin at the first recorded sample. Default none.

    Its ``errors`` simulate the channels (the kernels' ``outputs`` mode), filter them along time
    (:meth:`SensorChain.apply`, vectorised over the candidates) and sum the weighted squared errors in NumPy:
    a run without filters and without left-out samples takes that path too, once any run needs it. A
    dataset with neither never builds this class (today's fast path, the kernels' ``errors`` mode).

    Attributes
    ----------
    run_start : ndarray of int
        Where each run's recorded samples start in the stacked data (and the end).
    runs : list of RunInput
        Each run's inputs at its recorded samples (``lead_runs``: from the start of the lead-in, as simulated).
    """

    def __init__(self, sim, chains, keep=None, lead=None):
        self.inner = sim
        self.chains = list(chains)
        self._sections = [ch.sections() if ch.active else None for ch in self.chains]
        self.keep = None if keep is None else np.ascontiguousarray(keep, dtype=float)
        self.lead = tuple(int(k) for k in (lead if lead is not None else [0] * len(sim.runs)))
        lens = [int(e - s) - k for s, e, k in zip(sim.run_start[:-1], sim.run_start[1:], self.lead)]
        self.run_start = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        self.lead_runs = list(sim.runs)
        self.runs = [r.tail(k) for r, k in zip(sim.runs, self.lead)]  # a moving start's recorded part

    def __getattr__(self, name):
        if name == "inner":  # not set yet (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def record(self, outs) -> list:
        """Per-run outputs ``(n, T, 10)`` as the sensor chains record them, from the first recorded sample."""
        # the outputs are the simulator's fresh arrays: filtered in place
        out = [o if sec is None else ch.apply(o, sec, out=o) for o, ch, sec in zip(outs, self.chains, self._sections)]
        return [o[:, k:] if k else o for o, k in zip(out, self.lead)]

    def outputs(self, P, pin=None):
        """Simulated channels as recorded: list over runs of ``(n_pop, n_time, 10)``."""
        return self.record(self.inner.outputs(P, pin=pin))

    def outputs_reference(self, P, pin=None):
        return self.record(self.inner.outputs_reference(P, pin=pin))

    def _errors(self, outs, Y, W) -> np.ndarray:
        err = np.empty((len(outs), outs[0].shape[0] if outs else 0))
        starts = self.run_start
        for ri, (s, e) in enumerate(zip(starts[:-1], starts[1:])):
            d = outs[ri] - Y[None, s:e]
            if self.keep is not None:
                d = d * self.keep[None, s:e]
            err[ri] = np.einsum("ntq,q->n", d * d, W[ri])
        return err

    def errors(self, P, Y, W, pin=None):
        """Per-run weighted squared errors ``(n_runs, n_pop)`` of the recorded channels over the kept samples."""
        return self._errors(self.outputs(P, pin=pin), np.asarray(Y, dtype=float), np.asarray(W, dtype=float))

    def errors_reference(self, P, Y, W, pin=None):
        return self._errors(self.outputs_reference(P, pin=pin), np.asarray(Y, dtype=float),
                            np.asarray(W, dtype=float))


def unfiltered(n_channels: int = 10) -> tuple:
    """The filters of a chain with none: ``((),) * n_channels``."""
    return ((),) * n_channels


__all__ = ["AnalogFilter", "DiscreteFilter", "KINDS", "ORDERS", "SensorChain", "SensorSimulator", "discretise",
           "modal_pairs", "unfiltered"]
