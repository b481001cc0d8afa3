"""Frequency responses of the identified car with their uncertainty, and the responses the data measured (SPEC §13).

:func:`frequency_response` evaluates the linear car of a result
(:func:`rideid.model.frf.frequency_response`) and propagates the estimates'
uncertainty to ``|H|`` to first order:

    var |H| = g^T Sigma g,   g = d|H| / d theta   (central differences)

over every estimated or derived parameter ``theta``, with ``Sigma`` built
from what the result holds (docs/frequency-response.md):

- **statistical**: ``std_robust`` with the robust (HAC) correlation of the
  estimates (``result.correlation``; the white-noise covariance's
  correlation when the result has none). This is the part of ``std_total``
  that carries its correlations, and they matter: the stiffness and mass
  errors of one axle move a resonance together.
- **the scale anchor** (``total_mass`` from a weighbridge, declared with a
  std): every mass, inertia, stiffness and damping scales with it (SPEC §1),
  so it moves the car along a direction in which every response driven by
  the road does not change. Its contribution is computed exactly along that
  direction: it is zero to rounding (the transmissibilities are ratios).
- **every other declared input** (a tape's length, a sensor's sensitivity, a
  known parameter's std): result.json keeps only the size of each input's
  contribution to each estimate, not its sign, so its contribution to
  ``|H|`` is bounded by the triangle inequality, ``sum_theta |g| u_theta``
  (plus the input's own direct effect when it is a dimension of the model),
  and added in quadrature: conservative, never optimistic.

A result with damper curves (SPEC §8) has ``c_sf``, ``c_sr`` as the curves'
mean slope over the excited knots; the response is that of the car
linearised there (stated in :attr:`FrequencyResponse.notes`), with the
slopes' std from their ``std_total`` taken as independent of the rest.

:func:`measured_response` is the H1 estimate (:func:`rideid.model.frf.h1_estimate`)
from a dataset's runs on known tracks, whose road under each wheel is
known from the track's geometry, the speed and the start.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...data.dataset import Dataset, lead_ins, prepare_inputs
from ...errors import ArgumentError, DataError
from ...model.frf import INPUTS, OUTPUT_UNITS, OUTPUTS, SEGMENT_S, default_frequencies, frequency_response as _kernel
from ...model.equations import CHANNELS
from ...model.frf import h1_estimate
from ...model.params import ALL_NAMES, SCALE_FREE, Geometry

#: Relative step of the central differences of ``|H|`` in each parameter.
STEP = 1e-5
#: Budget entries that are part of ``std_robust`` (already in the statistical covariance).
_IN_ROBUST = ("statistical", "between runs", "speed and start")
#: The figure's and the notebook's views of the body: output and the wheel inputs' weights
#: (``heave``: all four wheels up 1 m; ``pitch``: front up, rear down 1 m; ``roll``: left up, right down 1 m).
VIEWS = {"heave": ("heave", (1.0, 1.0, 1.0, 1.0), "all four wheels in phase"),
         "pitch": ("pitch", (1.0, 1.0, -1.0, -1.0), "front up, rear down"),
         "roll": ("roll", (1.0, -1.0, 1.0, -1.0), "left up, right down")}


@dataclass(frozen=True, repr=False)
class FrequencyResponse:
    """The identified car's frequency responses with their ±std (SPEC §13).

    Also readable as a mapping: ``fr["H"]`` is ``fr.H``.

    Attributes
    ----------
    freq : ndarray, shape (n_freq,)
        Hz.
    inputs : tuple of str
        The four wheel inputs ``r_fl, r_fr, r_rl, r_rr`` (road height under each wheel, m).
    outputs : tuple of str
        The ten channels of SPEC §1, then ``heave``, ``pitch``, ``roll`` (the body's CG displacements).
    H : ndarray, complex, shape (n_freq, n_out, n_in)
        Output per metre of road input (``units``).
    std_abs : ndarray, shape (n_freq, n_out, n_in)
        Standard deviation of ``|H|`` from the estimates' ``std_total`` (the module docstring).
    units : dict
        Output -> unit of ``H``.
    views : dict
        ``heave``, ``pitch``, ``roll`` from their wheel combination (:data:`VIEWS`): ``{"output", "weights",
        "label", "H" (n_freq,), "std_abs" (n_freq,)}``.
    notes : list of str
        How the uncertainty was built and what it leaves out.
    """

    freq: np.ndarray
    inputs: tuple
    outputs: tuple
    H: np.ndarray
    std_abs: np.ndarray
    units: dict = field(default_factory=lambda: dict(OUTPUT_UNITS))
    views: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def __getitem__(self, key):
        if key not in ("freq", "inputs", "outputs", "H", "std_abs", "units", "views", "notes"):
            raise KeyError(f"{key!r}: a frequency response has freq, inputs, outputs, H, std_abs, units, views, notes")
        return getattr(self, key)

    def __repr__(self):
        return (f"FrequencyResponse({self.freq.size} frequencies {self.freq[0]:g}-{self.freq[-1]:g} Hz, "
                f"{len(self.outputs)} outputs x {len(self.inputs)} inputs)")

    @property
    def magnitude(self) -> np.ndarray:
        """``|H|``, shape (n_freq, n_out, n_in)."""
        return np.abs(self.H)

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase of ``H`` in degrees (-180, 180], shape (n_freq, n_out, n_in)."""
        return np.degrees(np.angle(self.H))

    def response(self, output: str, input: str):
        """``(H, std_abs)`` of one output from one input, each shape (n_freq,)."""
        if output not in self.outputs:
            raise ArgumentError(f"output {output!r}: one of {', '.join(self.outputs)}")
        if input not in self.inputs:
            raise ArgumentError(f"input {input!r}: one of {', '.join(self.inputs)}")
        o, i = self.outputs.index(output), self.inputs.index(input)
        return self.H[:, o, i], self.std_abs[:, o, i]

    def rows(self):
        """``(f_hz, output, input, magnitude, phase_deg, magnitude_std)`` per frequency, output and input:
        the rows of ``frf.csv`` (SPEC §13)."""
        mag, ph = self.magnitude, self.phase_deg
        for k, f in enumerate(self.freq):
            for o, out in enumerate(self.outputs):
                for i, inp in enumerate(self.inputs):
                    yield float(f), out, inp, float(mag[k, o, i]), float(ph[k, o, i]), float(self.std_abs[k, o, i])

    def to_frame(self):
        """The rows of :meth:`rows` as a ``pandas.DataFrame`` (needs pandas)."""
        import pandas as pd
        return pd.DataFrame(list(self.rows()), columns=list(FRF_COLUMNS))


#: The columns of ``frf.csv`` (SPEC §13).
FRF_COLUMNS = ("f_hz", "output", "input", "magnitude", "phase_deg", "magnitude_std")


def result_geometry(result) -> Geometry:
    """The geometry a result carries (its ``vehicle``)."""
    veh = getattr(result, "vehicle", None)
    if not veh:
        raise DataError("the result carries no [vehicle] geometry (written by an older rideid?); identify again "
                        "to compute its frequency response")
    return Geometry(**{k: float(veh[k]) for k in Geometry.KEYS},
                    **{k: float(veh.get(k, d)) for k, d in Geometry.OPTIONAL_KEYS.items()})


def _row(result) -> np.ndarray:
    return np.array([float(result.parameters.get(n, 0.0)) for n in ALL_NAMES])


def _statistical(result, details):
    """``(names, covariance)`` of the estimates' statistical part: std_robust with the robust correlation."""
    corr = getattr(result, "correlation", None) or {}
    names = [n for n in corr.get("names") or [] if n in ALL_NAMES]
    notes = []
    if names and corr.get("matrix") is not None:
        cnames = list(corr["names"])
        R = np.array([[np.nan if v is None else v for v in row] for row in corr["matrix"]], dtype=float)
        idx = [cnames.index(n) for n in names]
        R = R[np.ix_(idx, idx)]
    else:
        names = [n for n in result.names if n in ALL_NAMES]
        cov = np.asarray(result.covariance, dtype=float)
        if cov.shape == (len(result.names), len(result.names)) and np.all(np.isfinite(cov)) and names:
            idx = [list(result.names).index(n) for n in names]
            sd = np.sqrt(np.clip(np.diag(cov)[idx], 0, None))
            with np.errstate(invalid="ignore", divide="ignore"):
                R = cov[np.ix_(idx, idx)] / np.outer(sd, sd)
            notes.append("the result has no robust correlation: the white-noise covariance's correlation is used")
        else:
            R = np.eye(len(names))
            notes.append("the result has no covariance: the estimates are taken as independent (std_total each)")
    sd = np.array([float(details[n].get("std_robust") or 0.0) for n in names])
    undetermined = [n for n in names if details[n].get("determined") is False]
    if undetermined:  # a road fit's Hessian left them without an error bar (docs/uncertainty.md)
        notes.append(f"{', '.join(undetermined)}: not determined by the data (no error bar), so the band holds with "
                     "them at their estimates; where they move the response (near their modes) it is no bound")
    R = np.where(np.isfinite(R), R, 0.0)
    np.fill_diagonal(R, 1.0)
    return names, R * np.outer(sd, sd), notes


def _declared(result):
    """The declared inputs: ``(anchor std or None, anchor value, {name: (kind, key, std)})`` of the others."""
    unc = getattr(result, "uncertainty", None) or {}
    anchor = unc.get("anchor") or ("total_mass" if "total_mass" in (result.known or {}) else None)
    anchor_std, others = None, {}
    for name, d in (unc.get("declared") or {}).items():
        if d.get("kind") == "known" and d.get("key") == anchor:
            anchor_std = float(d["std"])
        else:
            others[name] = (d.get("kind"), d.get("key") or d.get("channel"), float(d.get("std") or 0.0))
    value = (result.known or {}).get(anchor) if anchor else None
    return anchor, anchor_std, value, others


def _abs_and_view(H):
    """``|H|`` and the views' ``|H w|`` of a batch: (n, f, o, i) -> (n, f, o, i), (n, f, len(VIEWS))."""
    views = np.stack([np.abs(H[:, :, OUTPUTS.index(out)] @ np.array(w)) for out, w, _ in VIEWS.values()], -1)
    return np.abs(H), views


def frequency_response(result, freq=None) -> FrequencyResponse:
    """The identified car's frequency responses with the std of ``|H|`` (SPEC §13; the module docstring).

    Parameters
    ----------
    result : IdentificationResult
        With its ``vehicle`` geometry (every result written since SPEC §10).
    freq : array_like, optional
        Frequencies, Hz (default :func:`rideid.model.frf.default_frequencies`: 240 log-spaced, 0.2-30 Hz).

    Returns
    -------
    FrequencyResponse
    """
    freq = default_frequencies() if freq is None else np.atleast_1d(np.asarray(freq, dtype=float))
    if freq.ndim != 1 or freq.size == 0 or not np.all(np.isfinite(freq)) or np.any(freq < 0):
        raise ArgumentError("freq: a 1-D array of frequencies (Hz, >= 0)")
    geom = result_geometry(result)
    details = result.details
    row0 = _row(result)
    names, cov, notes = _statistical(result, details)
    anchor, anchor_std, anchor_value, others = _declared(result)
    cols, extra_sd = _columns(result, names, others, notes)
    # relative steps; a parameter at 0 (a tire damping the data put at its bound) steps by a part of its std
    own_sd = {**{n: float(np.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(names)}, **extra_sd,
              **{key: std for kind, key, std in others.values() if kind == "known"}}
    steps = np.array([STEP * abs(row0[ALL_NAMES.index(n)]) if row0[ALL_NAMES.index(n)] != 0
                      else max(1e-3 * own_sd.get(n, 0.0), 1e-9) for n in cols])
    H, grad, scale = _gradients(row0, geom, freq, cols, steps)
    # statistical: g^T Sigma g over the statistical block, the damper slopes independent of it
    ks = len(names)
    var = [np.einsum("a...,ab,b...->...", g[:ks], cov, g[:ks]) for g in grad]
    for n, sd in extra_sd.items():
        j = cols.index(n)
        var = [v + (g[j] * sd) ** 2 for v, g in zip(var, grad)]
    # the anchor: exactly along the scale direction (zero to rounding: responses to the road are ratios)
    if anchor_std and anchor_value:
        var = [v + (d * anchor_std / anchor_value) ** 2 for v, d in zip(var, scale)]
        notes.append(f"{anchor} (declared ± {anchor_std:g}): propagated along the scale direction, where the "
                     "responses to the road do not change")
    elif anchor:
        notes.append(f"{anchor} taken as exact; its uncertainty would not change these responses (they are "
                     "ratios: every mass, inertia, stiffness and damping scales with it)")
    for name, (kind, key, std) in others.items():
        b = _declared_bound(details, name, kind, key, std, cols, grad, (row0, geom, freq))
        var = [v + bb * bb for v, bb in zip(var, b)]
    if others:
        notes.append(f"{', '.join(others)}: bounded by the triangle inequality over the estimates (result.json keeps "
                     "each contribution's size, not its sign): conservative")
    std, std_v = (np.sqrt(np.clip(v, 0, None)) for v in var)
    if not np.any(np.diag(cov) > 0) and not any(v > 0 for v in extra_sd.values()):
        # no standard error at all (an identification without the polish): no band, rather than a band of 0
        std[:] = np.nan
        std_v[:] = np.nan
        notes.append("the estimates have no standard errors (no polish): std_abs is NaN")
    Hc = H[0]
    views = {v: {"output": out, "weights": list(w), "label": label, "H": Hc[:, OUTPUTS.index(out)] @ np.array(w),
                 "std_abs": std_v[:, j]} for j, (v, (out, w, label)) in enumerate(VIEWS.items())}
    return FrequencyResponse(freq=freq, inputs=INPUTS, outputs=OUTPUTS, H=Hc, std_abs=std, views=views,
                             notes=notes)


def _columns(result, names, others, notes):
    """``(columns, extra std)``: the parameters differentiated, the statistical block's ``names``, then the
    damper slopes of a result with curves (their ``std_total`` in ``extra std``, taken as independent; a note
    says so), then the known values declared with a std."""
    cols, extra_sd = list(names), {}
    if getattr(result, "dampers", None):
        for n in ("c_sf", "c_sr"):
            if n not in cols:
                cols.append(n)
                extra_sd[n] = float(result.details.get(n, {}).get("std_total") or 0.0)
        notes.append("damper curves: the response of the car linearised at the curves' mean slope over the "
                     "excited knots (c_sf, c_sr), their std taken as independent of the rest")
    known_declared = [key for kind, key, _ in others.values() if kind == "known" and key in ALL_NAMES]
    return cols + [k for k in known_declared if k not in cols], extra_sd


def _gradients(row0, geom: Geometry, freq, cols, steps):
    """``(H, (G, G_views), (scale, scale_views))`` from one batch of the car, each column +- its step and the
    anchor's scale direction +-: ``H`` the batch's responses (the car's first), ``G`` ``d|H|/d column``
    ``(k, f, o, i)`` and the views' ``(k, f, len(VIEWS))`` by central differences, ``scale`` ``d|H|/d(log
    scale)`` and the views'."""
    P = [row0]
    for n, h in zip(cols, steps):
        for sgn in (1, -1):
            r = row0.copy()
            r[ALL_NAMES.index(n)] += sgn * h
            P.append(r)
    scaled = np.array([0.0 if n in SCALE_FREE else 1.0 for n in ALL_NAMES])
    for sgn in (1, -1):
        P.append(row0 * (1 + sgn * STEP * scaled))
    H = _kernel(np.array(P), geom, freq)
    mag, view = _abs_and_view(H)
    k = len(cols)
    G = (mag[1:2 * k + 1:2] - mag[2:2 * k + 2:2]) / (2 * steps[:, None, None, None])
    Gv = (view[1:2 * k + 1:2] - view[2:2 * k + 2:2]) / (2 * steps[:, None, None])
    return H, (G, Gv), ((mag[-2] - mag[-1]) / (2 * STEP), (view[-2] - view[-1]) / (2 * STEP))


def _declared_bound(details, name, kind, key, std, cols, grad, car):
    """The bound on the change of ``|H|`` and of the views a declared input ``name`` makes: the triangle
    inequality over its contributions to the estimates (result.json keeps their sizes, not their signs), plus
    its own direct effect when it is a known value differentiated (``cols``) or a dimension of the car
    (``car``: the row, the geometry and the frequencies)."""
    G, Gv = grad
    b, bv = np.zeros(G.shape[1:]), np.zeros(Gv.shape[1:])
    for j, n in enumerate(cols):
        c = ((details.get(n) or {}).get("budget") or {}).get(name)
        if c and not (details.get(n) or {}).get("fixed"):
            b += np.abs(G[j]) * c
            bv += np.abs(Gv[j]) * c
    if kind == "known" and key in cols:
        j = cols.index(key)
        b += np.abs(G[j]) * std
        bv += np.abs(Gv[j]) * std
    elif kind == "vehicle" and key in Geometry.KEYS + tuple(Geometry.OPTIONAL_KEYS) and std > 0:
        row0, geom, freq = car
        d, dv = _geometry_derivative(row0, geom, key, std, freq)
        b += np.abs(d)
        bv += np.abs(dv)
    return b, bv


def _geometry_derivative(row0, geom: Geometry, key: str, std: float, freq):
    """The direct change of ``|H|`` and the views when the dimension ``key`` moves by ``std`` (central)."""
    out = []
    for sgn in (1, -1):
        g = replace(geom, **{key: getattr(geom, key) + sgn * 0.5 * std})
        out.append(_abs_and_view(_kernel(row0[None], g, freq)))
    return out[0][0][0] - out[1][0][0], out[0][1][0] - out[1][1][0]


# ---------------------------------------------------------------------------
# What the data measured

def measured_response(dataset: Dataset, result=None, segment: float | None = SEGMENT_S, bins: int | None = None
                      ) -> dict | None:
    """The H1 estimate of every channel from the four wheel inputs over the runs whose road is known.

    A run counts when its road under each wheel follows from its track's geometry, speed and start:
    a known track, not fitted as built nor estimated (``result.estimated_road_runs()``) — the inputs are
    then exactly what the identification fed the car — and, with one record per run, when it starts at
    rest (not a moving start). A channel recorded through a sensor chain's filters (SPEC §11) measured the
    chain and the car together: it is left out. Clipped samples leave their record (or segment) out of that
    channel. Rig runs and any other source of measured inputs use :func:`rideid.model.frf.h1_estimate`
    directly.

    Parameters
    ----------
    dataset : Dataset
        At the starts the identification settled (``load_dataset(..., starts=result.start_records())``).
    result : IdentificationResult, optional
        Leaves out the runs whose road it estimated.
    segment : float or None
        None: each run is one record (a proving-ground run starts and ends at rest); a number: Welch segments
        of that length, s.
    bins : int, optional
        Adjacent frequency bins averaged (:func:`rideid.model.frf.h1_estimate`).

    Returns
    -------
    dict or None
        :func:`rideid.model.frf.h1_estimate`'s (``freq``, ``H`` (n_f, 10, 4), ``coherence``,
        ``multiple_coherence``, ``std_abs``, ``averages``) with ``outputs`` (the ten channels), ``inputs`` and
        ``runs`` (those used); None when no run has a known road or every run is shorter than a segment.
    """
    skip = set(result.estimated_road_runs()) if result is not None else set()
    # one record per run holds Y = H X only for a run that starts at rest: a moving start (SPEC §9) is left out
    keep = [r for r in dataset.runs if dataset.road_known(r.id) and r.id not in skip
            and (segment is not None or not dataset.moving(r.id))]
    if not keep:
        return None
    sub = dataset.subset(keep) if len(keep) < len(dataset.runs) else dataset
    leads = lead_ins(sub)
    runs, used = [], []
    for r, inp, lead in zip(sub.runs, prepare_inputs(sub, leads), leads):
        rd = sub.data[r.id]
        t = rd.time
        if segment is not None and t.size * (t[1] - t[0]) < segment:
            continue
        Y = np.array(rd.matrix(), dtype=float)  # a copy: channels are blanked below
        clipped = sub.clipped(r.id)
        if clipped is not None:
            Y = np.where(np.asarray(clipped, dtype=bool), np.nan, Y)
        # a channel through a sensor chain's filters (SPEC §11) measured the chain times the car: left out
        for c, filters in enumerate(sub.sensor_filters(r.id)):
            if filters:
                Y[:, c] = np.nan
        runs.append((1.0 / float(t[1] - t[0]), inp.u[lead.samples:], Y))
        used.append(r.id)
    if not runs:
        return None
    est = h1_estimate(runs, segment=segment, bins=bins)
    return {**est, "outputs": CHANNELS, "inputs": INPUTS, "runs": used}


__all__ = ["FrequencyResponse", "FRF_COLUMNS", "VIEWS", "frequency_response", "measured_response",
           "result_geometry"]
