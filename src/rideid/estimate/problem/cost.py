"""The identification cost.

For a candidate ``p`` and run ``r`` with the set ``C_r`` of measured channels,

    E_r(p) = (1/|C_r|) sum_{c in C_r} sum_k (yhat_{c,k}(p) - y_{c,k})^2 / D_{r,c}
    D_{r,c} = max( sum_k y_{c,k}^2 , 0.01 max_{c' in C_r, kind(c') = kind(c)} sum_k y_{c',k}^2 )

i.e. each channel's squared error normalised by its measured energy (so
accelerations in m/s^2 and rates in rad/s are comparable), floored at 1 % of
the largest energy among channels of the same kind (body, axle, rate) in that
run, so that a channel the run barely excites (roll rate on a washboard) is
not blown up to full weight. The total cost is

    J(p) = sum_r w_r E_r(p),   sum_r w_r = 1,

with equal weights by default; identification adapts them (paper eq. 13).
``E_r`` is a normalised mean squared error: 1 is as bad as predicting zero.

Free parameters: the twelve less those in ``[known]``; with ``total_mass``
known, ``m_s = total_mass - 2 m_uf - 2 m_ur`` is derived (if ``m_s`` itself
is known, ``m_ur`` is derived instead). The model's extension groups (SPEC §6:
``[model] extensions`` or ``identify --model``) add their parameters
(:data:`rideid.model.params.GROUPS`), free unless known; a known extension
value is used whatever the model, and an extension the model lacks is 0.

Damper curves (SPEC §8, group ``damper_curves``): ``c_sf``, ``c_sr`` leave the
free parameters and the forces at the velocity knots join them (names
``F_f1 .. F_fK``, ``F_r1 .. F_rK``, :func:`rideid.model.nonlinear.curve_names`;
knots: the dataset's ``[model] damper_knots`` mirrored into rebound, else
:data:`rideid.model.nonlinear.DEFAULT_KNOTS`). Full rows then have the
:class:`~rideid.model.nonlinear.NonlinearLayout` columns (16 + 2K) and the
cost simulates the nonlinear car (:class:`rideid.model.simulator.Simulator` of that layout;
without curves the linear simulator as before). Every row that reaches the
simulator is a physical damper (:meth:`ParameterSpace.full`): the forces are
made monotone outward from 0 (running maximum in compression, running minimum
in rebound: the identity for a monotone row), knots that no run excites
(``frozen``) continue the last excited segment's slope, and ``c_sf``,
``c_sr`` hold each curve's mean slope between -0.1 and +0.1 m/s
(``(F(0.1) - F(-0.1)) / 0.2``), reported as derived.
"""

from __future__ import annotations

import threading

import numpy as np

from ...settings import defaults, legacy_names
from ...data.dataset import Dataset, check_known_consistent, prepare_inputs, scale_anchor
from ...errors import ArgumentError, DataError
from ...model.equations import CHANNEL_KIND, CHANNELS
from ...model.nonlinear import (BUMP_STOP_NAMES, DEFAULT_KNOTS, NonlinearLayout, NonlinearSimulator, Pin,
                               curve_names, damper_force)
from ...model.sensors import SensorChain, SensorSimulator
from ...model.simulator import Simulator
from ...model.params import (ALL_NAMES, EXT_NAMES, GROUPS, INDEX, MASS_COUNT, NAMES, POWERTRAIN_NAMES, SCALE_FREE,
                            SIGNED, default_bounds, nominal_car, powertrain_fits, total_mass)
from ...data.schema import NONLINEAR_GROUPS


#: the SPEC §8 groups this version identifies
CURVES = "damper_curves"
#: SPEC §11's powertrain on mounts (a linear group, :data:`rideid.model.params.GROUPS`)
POWERTRAIN = "powertrain"
BUMP = "bump_stops"
#: the groups a model may have, canonical order: SPEC §6's linear ones, then the damper curves, the bump stops
IDENTIFIABLE_GROUPS: tuple[str, ...] = tuple(GROUPS) + (CURVES, BUMP)
#: default bounds of the bump stops (SPEC §8): clearance 10-150 mm of compression from static ride height
#: (production cars: 20-80 mm at the wheel), rate 0-500 kN/m at the wheel (rubber/PU stops: 20-200 kN/m
#: before they go solid); ``[bounds]`` overrides them
BUMP_BOUNDS = {"bs_clear_f": (0.01, 0.15), "bs_clear_r": (0.01, 0.15), "bs_rate_f": (0.0, 5.0e5),
               "bs_rate_r": (0.0, 5.0e5)}
BUMP_UNITS = {"bs_clear_f": "m", "bs_clear_r": "m", "bs_rate_f": "N/m", "bs_rate_r": "N/m"}


def refuse_unsupported_groups(groups, where: str = "model"):
    """A nonlinear group of SPEC §8 that this version simulates but does not identify: one clear
    :class:`ArgumentError` rather than a fit that silently leaves it out (damper curves and bump stops are
    identified, with or without a powertrain on mounts)."""
    bad = [g for g in groups if g in NONLINEAR_GROUPS and g not in IDENTIFIABLE_GROUPS]
    if bad:
        raise ArgumentError(f"{where}: {' and '.join(repr(g) for g in bad)} (SPEC §8) cannot be identified by this "
                            f"version of rideid: it simulates such a car but fits only the groups "
                            f"{', '.join(IDENTIFIABLE_GROUPS)}; remove {'them' if len(bad) > 1 else 'it'} from "
                            "[model] extensions or pass another --model")


def curve_knots(damper_knots=None) -> tuple[float, ...]:
    """Signed knots (m/s) of the damper curves: ``[model] damper_knots`` (positive) mirrored into rebound,
    else :data:`rideid.model.nonlinear.DEFAULT_KNOTS`."""
    if not damper_knots:
        return tuple(DEFAULT_KNOTS)
    pos = tuple(float(k) for k in damper_knots)
    if any(not k > 0 for k in pos) or any(b <= a for a, b in zip(pos, pos[1:])):
        raise DataError(f"[model] damper_knots must be positive and strictly increasing (m/s), got {list(pos)}")
    return tuple(-k for k in reversed(pos)) + pos


def channel_weights(Y: np.ndarray) -> np.ndarray:
    """Per-channel weights ``1 / (|C| D_c)`` of one run; 0 for missing (NaN) channels."""
    present = ~np.all(np.isnan(Y), axis=0)
    E = np.where(present, np.nansum(Y * Y, axis=0), 0.0)
    D = np.zeros(len(CHANNELS))
    for i, c in enumerate(CHANNELS):
        if not present[i]:
            continue
        same = [j for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c] and present[j]]
        D[i] = max(E[i], defaults["cost.energy_floor"] * max(E[j] for j in same))
    W = np.zeros(len(CHANNELS))
    n = int(present.sum())
    ok = present & (D > 0)
    W[ok] = 1.0 / (n * D[ok])
    return W


def min_improvement() -> float:
    """The least cost reduction that counts as a better fit: the cost is a relative squared error, so a change
    must move the fit by setting ``adequacy.min_relative`` of the channels' RMS (the model choice, the bump-stop
    scan; the adequacy test's floor of material structure is the same share)."""
    return defaults["adequacy.min_relative"] ** 2


def checked_groups(extensions) -> tuple[str, ...]:
    """The model's extension groups in canonical order (:data:`IDENTIFIABLE_GROUPS`); a group this version
    cannot identify, or an unknown one, is an :class:`ArgumentError`."""
    extensions = tuple(extensions)
    refuse_unsupported_groups(extensions)
    for g in extensions:
        if g not in IDENTIFIABLE_GROUPS:
            raise ArgumentError(f"unknown extension group '{g}'; groups are: {', '.join(IDENTIFIABLE_GROUPS)}")
    return tuple(g for g in IDENTIFIABLE_GROUPS if g in extensions)


class ParameterSpace:
    """Free, fixed and derived parameters of a dataset, and their bounds.

    Parameters
    ----------
    known : dict
        ``[known]`` values (``total_mass`` or parameter names, extensions too).
    geometry : Geometry
    bounds : dict, optional
        ``[bounds]``; bounds of parameters that are not free are not used.
    extensions : sequence of str
        The model's extension groups (:data:`IDENTIFIABLE_GROUPS`); their
        parameters are free unless known.
    damper_knots : sequence of float, optional
        ``[model] damper_knots`` (positive, m/s) for ``damper_curves``
        (default :data:`rideid.model.nonlinear.DEFAULT_KNOTS`).
    frozen : sequence of str, optional
        Knot forces that no run excites: derived (the last excited segment's
        slope continued), not free (:func:`rideid.estimate.problem.dampers.knot_excitation`).

    Attributes
    ----------
    anchor : str
        The known value that fixes the absolute scale (SPEC §1), normally ``total_mass``.
    width : int
        Columns of the full rows :meth:`full` returns: 12, or 16 when the
        model has a group of SPEC §6 or such a value is known, 23 with the
        powertrain (SPEC §11); with damper curves the
        :class:`~rideid.model.nonlinear.NonlinearLayout`'s 16 + 2K.
    param_names : tuple of str
        The names of those columns.
    col : dict
        Name -> column of the full rows.
    layout : NonlinearLayout or None
        The simulator's row layout with damper curves (None: the linear model).
    knot_names : tuple of str
        The knot-force columns ``F_f1 .. F_fK, F_r1 .. F_rK`` (empty without damper curves).
    reported_names : tuple of str
        The twelve, the model's extension parameters and known extensions
        (an extension neither in the model nor known is 0 and not reported),
        then the knot forces.
    """

    def __init__(self, known: dict[str, float], geometry, bounds: dict | None = None, extensions=(),
                 damper_knots=None, frozen=(), bump_frozen=None):
        #: the known value that fixes the absolute scale (:func:`rideid.data.dataset.scale_anchor`)
        self.anchor = scale_anchor(known)
        check_known_consistent(known)
        self.known = dict(known)
        self.geometry = geometry
        self.extensions = checked_groups(extensions)
        self.curves = CURVES in self.extensions
        self.bump = BUMP in self.extensions
        self.damper_knots = None if damper_knots is None else tuple(float(k) for k in damper_knots)
        # a powertrain in the model, or a known one: the nonlinear car carries it too (SPEC §11)
        powertrain = POWERTRAIN in self.extensions or any(n in known for n in POWERTRAIN_NAMES)
        self.layout = self._layout(damper_knots, powertrain)
        knot_names = curve_names(self.layout.n_knots) if self.curves else ()
        #: the knot-force columns, ``F_f1 .. F_fK, F_r1 .. F_rK`` (empty without curves)
        self.knot_names = tuple(knot_names)
        self.frozen = tuple(n for n in knot_names if n in set(frozen))
        #: bump-stop columns of axles whose stop no run reaches: held at these values, not free, not measured
        self.bump_frozen = {n: float(v) for n, v in (bump_frozen or {}).items()
                            if self.bump and n in BUMP_STOP_NAMES and n not in known}
        bump_names = BUMP_STOP_NAMES if self.bump else ()
        if self.curves:
            both = [n for n in ("c_sf", "c_sr") if n in known]
            if both:
                raise ArgumentError(f"[known] {', '.join(both)}: with damper_curves the damping is the curves' "
                                    "(c_sf, c_sr are derived from them); leave it out of [known] or fit "
                                    "linear dampers")
        #: the mass that follows from ``total_mass`` (None without it)
        self.derived = (next((c for c in ("m_s", "m_ur", "m_uf") if c not in known), None)
                        if "total_mass" in known else None)
        # a known bump stop is used by a model with the group bump_stops (without it the car has no stops)
        self.fixed = {n: v for n, v in known.items() if n in ALL_NAMES or n in bump_names}
        model_ext = [n for g in self.extensions if g in GROUPS for n in GROUPS[g]]
        base = [n for n in NAMES if not (self.curves and n in ("c_sf", "c_sr"))]
        self.names = ([n for n in base + model_ext if n not in self.fixed and n != self.derived]
                      + [n for n in bump_names if n not in self.fixed and n not in self.bump_frozen]
                      + [n for n in knot_names if n not in self.frozen])
        self.param_names = self.layout.names if self.layout is not None else self._linear_columns(model_ext)
        self.width = len(self.param_names)
        self.col = {n: i for i, n in enumerate(self.param_names)}
        #: what a result reports: the twelve, the model's extensions and any known extension, the knot forces
        self.reported_names = (tuple(n for n in ALL_NAMES if n in NAMES or n in model_ext or n in self.fixed)
                               + bump_names + knot_names)
        self._bounds_arg = dict(bounds or {})
        self.bounds = self._free_bounds(self._bounds_arg)
        if self.curves:
            # the mean slope over [-V, V] is linear in the knot forces: c = F @ w
            eye = np.eye(self.layout.n_knots)
            V = defaults["cost.mean_slope_velocity"]
            knots = self.layout.knots
            self._slope_w = (damper_force(knots, eye, V) - damper_force(knots, eye, -V)) / (2 * V)
        self._nominal = self._nominal_row()

    def _layout(self, damper_knots, powertrain: bool) -> NonlinearLayout | None:
        """The nonlinear car's row layout with damper curves or bump stops (None: the linear model), with the
        ``powertrain`` or without."""
        if not (self.curves or self.bump):
            return None
        return NonlinearLayout(knots=curve_knots(damper_knots) if self.curves else None, bump_stops=self.bump,
                               powertrain=powertrain)

    def _linear_columns(self, model_ext) -> tuple[str, ...]:
        """The linear model's columns: 12, 16 with SPEC §6's groups, 23 with the powertrain (the narrowest
        row of the model and the known values)."""
        if any(n in POWERTRAIN_NAMES for n in model_ext) or any(n in self.fixed for n in POWERTRAIN_NAMES):
            width = len(ALL_NAMES)
        elif model_ext or any(n in self.fixed for n in EXT_NAMES):
            width = len(NAMES) + 4
        else:
            width = len(NAMES)
        return ALL_NAMES[:width]

    def _free_bounds(self, bounds: dict) -> np.ndarray:
        """The free parameters' bounds ``(d, 2)``: ``[bounds]`` over the defaults (the geometry's, the bump
        stops' :data:`BUMP_BOUNDS`, the knot forces' from their axle's damping bounds); an unknown name in
        ``[bounds]`` is a :class:`DataError`."""
        db = default_bounds(self.geometry)
        db.update(BUMP_BOUNDS)
        for k in bounds:
            if k not in ALL_NAMES and k not in self.knot_names and k not in BUMP_STOP_NAMES:
                raise DataError(f"[bounds]: unknown parameter '{k}'"
                                + ("" if self.curves or not k.startswith("F_") else
                                   " (knot forces are parameters of the damper_curves model only)"))
        if self.curves:
            f_lo, f_hi = defaults["cost.knot_bound_factor"]
            for n, v in zip(self.knot_names, self.knot_velocities()):
                c = "c_sf" if n.startswith("F_f") else "c_sr"
                lo, hi = bounds.get(c, db[c])
                db[n] = (lo * v / f_lo, hi * v * f_hi) if v > 0 else (hi * v * f_hi, lo * v / f_lo)
        return np.array([bounds.get(n, db[n]) for n in self.names], dtype=float)

    def knot_velocities(self) -> np.ndarray:
        """Velocity (m/s) of each knot-force column, ``F_f1 .. F_fK, F_r1 .. F_rK`` (empty without curves)."""
        if not self.curves:
            return np.zeros(0)
        k = np.asarray(self.layout.knots)
        return np.concatenate([k, k])

    def with_frozen(self, frozen) -> "ParameterSpace":
        """The same space with the knot forces ``frozen`` derived instead of free."""
        return ParameterSpace(self.known, self.geometry, self._bounds_arg, self.extensions, self.damper_knots,
                              frozen, self.bump_frozen)

    def with_bump_frozen(self, bump_frozen) -> "ParameterSpace":
        """The same space with the bump-stop columns ``bump_frozen`` (name -> value) held, not free."""
        return ParameterSpace(self.known, self.geometry, self._bounds_arg, self.extensions, self.damper_knots,
                              self.frozen, bump_frozen)

    def reduce(self, x, other: "ParameterSpace") -> np.ndarray:
        """Free row ``x`` of this space -> the free row of ``other`` (same car; dropped columns are lost)."""
        P = self.full(np.asarray(x, dtype=float)[None])[0]
        return np.array([P[self.col[n]] for n in other.names])

    def full(self, X) -> np.ndarray:
        """Free-parameter rows ``(n, d)`` -> full rows ``(n, width)`` (:attr:`param_names`).

        With damper curves the knot forces are made physical (module docstring): monotone outward
        from 0, frozen knots continuing the last excited segment, ``c_sf``, ``c_sr`` the mean slopes.
        """
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if X.shape[1] != len(self.names):
            raise ArgumentError(f"expected {len(self.names)} columns ({', '.join(self.names)}), got {X.shape[1]}")
        P = np.zeros((X.shape[0], self.width))
        col = self.col
        for j, n in enumerate(self.names):
            P[:, col[n]] = X[:, j]
        for n, v in self.fixed.items():
            P[:, col[n]] = v
        for n, v in self.bump_frozen.items():
            P[:, col[n]] = v
        if self.derived is not None:
            others = [n for n in MASS_COUNT if n != self.derived]
            rest = sum(MASS_COUNT[n] * P[:, col[n]] for n in others)
            P[:, col[self.derived]] = (self.known["total_mass"] - rest) / MASS_COUNT[self.derived]
        if self.curves:
            self._physical_curves(P)
        return P

    def _physical_curves(self, P):
        """In place: monotone knot forces, frozen knots continued, ``c_sf``, ``c_sr`` = mean slopes."""
        knots = np.asarray(self.layout.knots)
        K = knots.size
        j0 = int(np.searchsorted(knots, 0.0))
        s = self.col["F_f1"]
        frozen = set(self.frozen)
        for a, (prefix, cname) in enumerate((("F_f", "c_sf"), ("F_r", "c_sr"))):
            F = P[:, s + a * K:s + (a + 1) * K]  # a view
            names = [f"{prefix}{j + 1}" for j in range(K)]
            # compression: running maximum outward from 0; rebound: running minimum outward from 0
            F[:, j0:] = np.maximum.accumulate(np.maximum(F[:, j0:], 0.0), axis=1)
            F[:, :j0] = np.minimum.accumulate(np.minimum(F[:, :j0], 0.0)[:, ::-1], axis=1)[:, ::-1]
            # frozen (not excited) knots: the last excited segment's slope continued outward
            for side in (range(j0, K), range(j0 - 1, -1, -1)):
                prev_v, prev_F, last_v, last_F = 0.0, 0.0, 0.0, np.zeros(P.shape[0])
                slope = None
                for j in side:
                    if names[j] in frozen:
                        if slope is None:
                            slope = (last_F - prev_F) / (last_v - prev_v) if last_v != prev_v else 0.0
                        F[:, j] = last_F + slope * (knots[j] - last_v)
                    else:
                        prev_v, prev_F, last_v, last_F = last_v, last_F, knots[j], F[:, j].copy()
            P[:, self.col[cname]] = F @ self._slope_w

    def derived_names(self) -> list[str]:
        """Reported quantities that follow from the free parameters: the derived mass, then with damper
        curves the frozen knot forces and ``c_sf``, ``c_sr``."""
        out = [self.derived] if self.derived is not None else []
        if self.curves:
            out += list(self.frozen) + ["c_sf", "c_sr"]
        return out

    def derived_jacobian(self, x) -> np.ndarray:
        """``d(derived_names) / d(free parameters)`` at ``x``, shape ``(k, d)``.

        Every derived quantity is piecewise linear in the free parameters (exactly linear where the
        monotone repair is inactive, e.g. at an interior optimum): one-sided differences are exact there.
        """
        names = self.derived_names()
        d = len(self.names)
        if not names:
            return np.zeros((0, d))
        x = np.asarray(x, dtype=float)
        h = 1e-6 * np.maximum(np.abs(x), 1.0)
        steps = np.where(x + h <= self.bounds[:, 1], h, -h)
        X = np.tile(x, (d + 1, 1))
        X[1 + np.arange(d), np.arange(d)] += steps
        P = self.full(X)
        cols = [self.col[n] for n in names]
        return ((P[1:, cols] - P[0, cols]) / steps[:, None]).T

    def derived_gradient(self) -> np.ndarray:
        """d(derived mass)/d(free parameters), shape (d,); zeros if nothing is derived."""
        g = np.zeros(len(self.names))
        if self.derived is not None:
            for n in MASS_COUNT:
                if n != self.derived and n in self.names:
                    g[self.names.index(n)] = -MASS_COUNT[n] / MASS_COUNT[self.derived]
        return g

    def valid(self, P) -> np.ndarray:
        """Rows that are physical: positive masses etc., 0 < a < wheelbase, extensions >= 0 (the knot
        forces are made physical by :meth:`full`)."""
        ok = np.all(np.isfinite(P), axis=1)
        for n in NAMES:
            col = P[:, INDEX[n]]
            ok &= (col > 0) & ((col < self.geometry.wheelbase) if n == "a" else True)
        if P.shape[1] > len(NAMES):
            car = self.layout.n_car if self.layout is not None else P.shape[1]  # the car's columns
            ext = [INDEX[n] for n in ALL_NAMES[len(NAMES):car] if n not in SIGNED]
            ok &= np.all(P[:, ext] >= 0, axis=1)
        if (self.layout.powertrain if self.layout is not None else P.shape[1] == len(ALL_NAMES)):
            # a powertrain leaves the rest of the body a positive mass and inertia, its pitch inertia > 0
            with np.errstate(invalid="ignore"):
                ok &= powertrain_fits(np.where(np.isfinite(P[:, :len(ALL_NAMES)]), P[:, :len(ALL_NAMES)], 0.0))
            on = P[:, INDEX["m_p"]] > 0
            ok &= ~on | ((P[:, INDEX["I_p"]] > 0) & (P[:, INDEX["f_pb"]] > 0) & (P[:, INDEX["f_pp"]] > 0))
        if self.bump:
            for n in BUMP_STOP_NAMES:
                ok &= (P[:, self.col[n]] > 0) if n.startswith("bs_clear") else (P[:, self.col[n]] >= 0)
        return ok

    def nominal(self) -> np.ndarray:
        """A physically consistent nominal car: the built-in car scaled to the
        anchor, clipped into the bounds (used for sensitivity maps and as a
        reference point, never as a starting guess); with damper curves its
        linear dampers as curves (``F = c v``). A full row, :attr:`param_names`
        (a copy of the row the space made when it was built)."""
        return self._nominal.copy()

    def _nominal_row(self) -> np.ndarray:
        """:meth:`nominal`, computed once, when the space is built."""
        base = nominal_car(self.geometry, extensions=True)
        anchor = self.anchor
        if anchor == "total_mass":
            s = self.known["total_mass"] / total_mass(base)
        else:
            s = self.known[anchor] / base[INDEX[anchor]]
        P = base * np.where(np.isin(np.array(ALL_NAMES), SCALE_FREE), 1.0, s)
        P = P[:self.width] if self.layout is None else P[:self.layout.n_car]  # the nonlinear car: 16 or 23
        if self.bump:  # stops at 50 mm, 50 kN/m scaled with the car
            P = np.concatenate([P, [0.05, 0.05, 5.0e4 * s, 5.0e4 * s]])
        if self.curves:
            v = self.knot_velocities()
            K = self.layout.n_knots
            c = np.r_[np.full(K, P[INDEX["c_sf"]]), np.full(K, P[INDEX["c_sr"]])]
            P = np.concatenate([P, c * v])
        x = np.clip(P[[self.col[n] for n in self.names]], self.bounds[:, 0], self.bounds[:, 1])
        return self.full(x)[0]


def _measured(ds: Dataset, leads=None):
    """The runs' measured channels stacked ``(n_samples, 10)`` (0 where missing or left out), the channel
    weights ``(n_runs, 10)`` (:func:`channel_weights`, 0 for a missing channel; a channel's energy over its
    kept samples) and the kept samples ``(n_samples, 10)`` (1 kept, 0 at the channel's range, SPEC §11, or in
    a moving start's settling time, SPEC §9 and :func:`rideid.data.dataset.run_lead_in`; None when every sample
    is kept)."""
    Ys, Ws, Ks = [], [], []
    for r, lead in zip(ds.runs, ds.leads if leads is None else leads):
        Y = ds.data[r.id].matrix()
        clipped = ds.clipped(r.id)
        left_out = np.zeros(Y.shape, dtype=bool) if clipped is None else np.asarray(clipped, dtype=bool).copy()
        left_out[:lead.settle] = True
        keep = np.where(left_out, 0.0, 1.0)
        Y = np.where(left_out, np.nan, Y)
        Ws.append(channel_weights(Y))
        Ys.append(np.nan_to_num(Y, nan=0.0))
        Ks.append(keep)
    K = np.concatenate(Ks)
    return np.ascontiguousarray(np.concatenate(Ys)), np.array(Ws), (None if K.all() else K)


def bind_runs(simulator: Simulator, ds: Dataset, keep=None, leads=None):
    """``simulator`` bound to the runs of ``ds`` (a moving start from the start of its lead-in, SPEC §9),
    recording through their sensor chains (SPEC §11), comparing only the kept samples and cut to the recorded
    ones (:class:`rideid.model.sensors.SensorSimulator`); the bound simulator itself when no run has a filter or
    a lead-in and every sample is kept (the kernels' fast path, unchanged)."""
    filters = [ds.sensor_filters(r.id) for r in ds.runs]
    leads = ds.leads if leads is None else leads
    sim = simulator.bind(ds.geometry, prepare_inputs(ds, leads))
    chains = [SensorChain(f, run.h) for f, run in zip(filters, sim.runs)]
    lead = [lead.samples for lead in leads]
    if keep is None and not any(ch.active for ch in chains) and not any(lead):
        return sim
    return SensorSimulator(sim, chains, keep, lead)


class EvaluationCounter:
    """How many candidates (rows) were evaluated: one count that several cost functions of one
    identification share (:meth:`CostFunction.with_space`), so no caller adds counts up by hand.

    Parameters
    ----------
    n : int
        The count to start from.
    """

    def __init__(self, n: int = 0):
        self._n = int(n)
        self._lock = threading.Lock()  # threads of one fit may count at once

    @property
    def n(self) -> int:
        return self._n

    def add(self, k: int):
        """Count ``k`` more evaluated candidates."""
        with self._lock:
            self._n += int(k)


class CostFunction:
    """``J(X)`` for a batch of free-parameter rows (see module docstring).

    Parameters
    ----------
    ds : Dataset
    weights : array_like, shape (n_runs,), optional
        Run weights (normalised to sum 1); equal by default.
    use_kernel : bool
        Compiled kernel (default) or the plain NumPy reference.
    space : ParameterSpace, optional
        Free/fixed/derived parameters and bounds (default: from the dataset's
        ``[known]`` and ``[bounds]``).
    extensions : sequence of str, optional
        Extension groups of the model when ``space`` is not given (default:
        the dataset's ``[model] extensions``, else none: the twelve).
    counter : EvaluationCounter, optional
        Count evaluations on an existing count (default a new one).
    simulator : Simulator, optional
        How the car is simulated (backend, integration settings;
        :class:`rideid.model.simulator.Simulator`, default ``Simulator()``),
        for the space's model (its layout is the space's).

    Attributes
    ----------
    names : list of str
        The free parameter names, in column order.
    bounds : ndarray, shape (d, 2)
    run_ids : list of str
    nfev : int
        Candidates evaluated, counted by :attr:`counter` (an :class:`EvaluationCounter`, shared with the
        cost functions built with it: ``counter`` argument, :meth:`with_space`).
    simulator : Simulator
        The settings it simulates with; ``sim`` the runs bound to them (never changed by an evaluation).
    pin : Pin or None
        The nonlinear integrator's floor its evaluations use (:meth:`with_pin`; the polish's), else None.
    """

    def __init__(self, ds: Dataset, weights=None, use_kernel: bool = True, space: ParameterSpace | None = None,
                 extensions=None, counter: "EvaluationCounter | None" = None, simulator: Simulator | None = None):
        unaligned = [r.id for r in ds.runs if r.id not in ds.data]
        if unaligned:
            raise ArgumentError(f"runs {', '.join(unaligned)} have no start yet: load the dataset with "
                                "rideid.load_dataset (or pass it through rideid.conditioning.load.align_starts)")
        if space is None:
            if extensions is None:  # the dataset's [model], else the twelve
                extensions = ds.manifest.extensions or ()
                refuse_unsupported_groups(extensions, f"{ds.manifest.path}: [model] extensions")
            space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=extensions,
                                   damper_knots=ds.manifest.damper_knots)
        # the given settings (backend, integration) for this space's model: the linear car unless it has
        # damper curves or bump stops (rideid.model.nonlinear)
        simulator = (Simulator() if simulator is None else simulator).for_layout(space.layout)
        leads = ds.leads  # worked out once per dataset (rideid.data.dataset.Dataset.leads)
        Y, W, keep = _measured(ds, leads)
        sim = bind_runs(simulator, ds, keep, leads)
        self._build(ds, space, simulator, sim, Y, W, use_kernel, weights, counter, None)

    def _build(self, ds, space, simulator, sim, Y, W, use_kernel, weights, counter, pin):
        """Every attribute, set once: the prepared data (``sim``, ``Y``, ``W``) shared by copies, none of
        which is ever changed (a copy that differs, differs by a new value: :meth:`with_pin`)."""
        self.ds = ds
        self.space = space
        self.names = list(space.names)
        self.bounds = space.bounds
        self.run_ids = [r.id for r in ds.runs]
        self.simulator = simulator
        self.sim = sim
        self.pin = pin
        self.Y = Y
        self.W = W
        #: ``(n_samples, 10)``: 1 where a sample is compared, 0 where it is left out (SPEC §11); None: all
        self.keep = getattr(sim, "keep", None)
        self.use_kernel = use_kernel
        self.weights = np.full(len(self.run_ids), 1.0 / len(self.run_ids))
        if weights is not None:
            self.set_weights(weights)
        self.counter = EvaluationCounter() if counter is None else counter

    @property
    def run_times(self) -> list:
        """Per run, its samples' times (s, the model's axis; :attr:`Y`'s rows of the run)."""
        return [self.ds.data[rid].time for rid in self.run_ids]

    @property
    def input_runs(self) -> list:
        """Each run's inputs as simulated: a moving start's from the start of its lead-in (SPEC §9; the
        first :attr:`lead` samples of a simulation of them come before the run's first recorded sample)."""
        return getattr(self.sim, "lead_runs", self.sim.runs)

    @property
    def lead(self) -> tuple:
        """Per run, the samples simulated before its first recorded one (0 for a run that starts at rest)."""
        return getattr(self.sim, "lead", (0,) * len(self.run_ids))

    @property
    def core_sim(self):
        """The bound simulator of the car, without the sensor chains (:attr:`sim` records through them)."""
        return getattr(self.sim, "inner", self.sim)

    @property
    def nfev(self) -> int:
        """Candidates evaluated (rows simulated) through this cost function and those sharing its
        :attr:`counter`."""
        return self.counter.n

    def with_space(self, space: ParameterSpace, weights=None, counter: "EvaluationCounter | None" = None
                   ) -> "CostFunction":
        """A new cost function on ``space`` (a parameter space of the same simulator layout), sharing the
        prepared runs and data (not copied) and the pin.

        Parameters
        ----------
        space : ParameterSpace
        weights : array_like, shape (n_runs,), optional
            Run weights (default equal).
        counter : EvaluationCounter, optional
            Share an evaluation count (e.g. this one's :attr:`counter`, to count on); default a new one (0).
        """
        if (space.layout is None) != (self.space.layout is None) or (
                space.layout is not None and space.layout != self.space.layout):
            raise ArgumentError("with_space: the new parameter space needs another simulator "
                                "(damper curves or bump stops differ); build a CostFunction instead")
        new = CostFunction.__new__(CostFunction)
        new._build(self.ds, space, self.simulator, self.sim, self.Y, self.W, self.use_kernel, weights, counter,
                   self.pin)
        return new

    def with_pin(self, pin: Pin | None) -> "CostFunction":
        """This cost function (same space, data, weights and count) evaluating with the nonlinear
        integrator's floor ``pin`` (:meth:`rideid.model.nonlinear.NonlinearSimulator.pin_at`; None: none)."""
        new = CostFunction.__new__(CostFunction)
        new._build(self.ds, self.space, self.simulator, self.sim, self.Y, self.W, self.use_kernel, self.weights,
                   self.counter, pin)
        return new

    def without_pairs(self, pairs) -> "CostFunction":
        """This cost function (space, simulator, pin, weights; a new count) with the run/channel ``pairs``
        (``(run id, channel name)``) left out: their channel weights 0 (the materiality refit)."""
        W = self.W.copy()
        for rid, ch in pairs:
            W[self.run_ids.index(rid), CHANNELS.index(ch)] = 0.0
        new = CostFunction.__new__(CostFunction)
        new._build(self.ds, self.space, self.simulator, self.sim, self.Y, W, self.use_kernel, self.weights, None,
                   self.pin)
        return new

    def pinned_at(self, P, margin: float = 1.5) -> "CostFunction":
        """:meth:`with_pin` at the polish's start ``P`` (a full row); the linear car has no sub-steps to pin."""
        if not isinstance(self.core_sim, NonlinearSimulator):
            return self
        return self.with_pin(self.sim.pin_at(np.atleast_2d(P), margin))

    def with_data(self, ds: Dataset) -> "CostFunction":
        """The same cost function (space, simulator settings, pin, count; equal weights) on ``ds``, the same
        runs read anew (e.g. at other starts)."""
        new = CostFunction(ds, space=self.space, counter=self.counter, simulator=self.simulator,
                           use_kernel=self.use_kernel)
        return new.with_pin(self.pin)

    def copy(self, weights=None) -> "CostFunction":
        """A copy sharing the prepared runs and data, with its own weights
        (equal unless given) and its own evaluation count (0)."""
        return self.with_space(self.space, weights)

    def set_weights(self, w):
        w = np.asarray(w, dtype=float)
        if w.shape != (len(self.run_ids),) or np.any(w < 0) or not np.isfinite(w).all() or w.sum() <= 0:
            raise ArgumentError(f"weights must be {len(self.run_ids)} non-negative numbers, not all zero")
        self.weights = w / w.sum()

    def run_errors(self, X) -> np.ndarray:
        """Normalised errors ``E_r`` per run, shape ``(n_runs, n)``; inf for unphysical rows."""
        P = self.space.full(X)
        ok = self.space.valid(P)
        E = np.full((len(self.run_ids), P.shape[0]), np.inf)
        if ok.any():
            fn = self.sim.errors if self.use_kernel else self.sim.errors_reference
            if isinstance(self.core_sim, NonlinearSimulator) and self.pin is None:
                # the RK4 sub-step is set by the stiffest candidate of a call: candidates grouped by
                # their own need, so a few stiff ones of a search population do not slow the rest
                idx = np.nonzero(ok)[0]
                for group in self.sim.groups(P[idx]):
                    E[:, idx[group]] = fn(P[idx[group]], self.Y, self.W)
            else:
                E[:, ok] = fn(P[ok], self.Y, self.W, pin=self.pin)
        self.counter.add(P.shape[0])
        return E

    def combine(self, E, weights=None) -> np.ndarray:
        w = self.weights if weights is None else np.asarray(weights, dtype=float)
        with np.errstate(invalid="ignore"):
            return w @ E

    def __call__(self, X) -> np.ndarray:
        """Costs ``(n,)`` for free-parameter rows ``X`` of shape ``(n, d)``."""
        return self.combine(self.run_errors(X))

    def residuals(self, X, weights=None, Y=None, advance=None) -> np.ndarray:
        """Stacked weighted residuals ``(n, m)`` whose squared sum is ``J``.

        ``Y`` replaces the measured data (same layout as :attr:`Y`), e.g. the
        data re-read at other start times. The layout: run by run, time-major,
        the run's used channels (``W[r] > 0``) within each sample. ``advance``: run index -> seconds ``a``,
        that run's response taken as ``y - a dy/dt`` (the time derivative a central difference of the samples):
        the part of a start's move that changes with the car (:class:`rideid.estimate.fit.polish._Polish`).
        """
        return self.row_residuals(self.space.full(X), weights, Y, advance)

    def row_residuals(self, P, weights=None, Y=None, advance=None) -> np.ndarray:
        """:meth:`residuals` of full rows ``P`` ``(n, width)`` (:attr:`ParameterSpace.param_names`): known and
        derived columns as given, not as the space fills them (the uncertainty budget moves a known value)."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        outs = self.sim.outputs(P, pin=self.pin)
        w = self.weights if weights is None else np.asarray(weights, dtype=float)
        Y = self.Y if Y is None else Y
        parts = []
        for ri, (s, e) in enumerate(zip(self.sim.run_start[:-1], self.sim.run_start[1:])):
            cols, sc = self.residual_scale(ri, w)
            out = outs[ri][:, :, cols]
            if advance and advance.get(ri):
                out = out - advance[ri] * time_derivative(out, self.run_times[ri])
            d = (out - Y[None, s:e, cols]) * sc
            if self.keep is not None:  # a left-out sample's residual is 0: it moves nothing
                d = d * self.keep[None, s:e, cols]
            parts.append(d.reshape(P.shape[0], -1))
        self.counter.add(P.shape[0])
        return np.concatenate(parts, axis=1)

    def residual_scale(self, ri, weights):
        """Used channel indices of run ``ri`` and their residual scale ``sqrt(w_r W_rc)``."""
        cols = np.nonzero(self.W[ri] > 0)[0]
        return cols, np.sqrt(weights[ri] * self.W[ri, cols])

    def simulate(self, params) -> dict[str, np.ndarray]:
        """Simulated channels ``(n_time, 10)`` per run for one full parameter vector (12 or 16; with
        damper curves the space's :attr:`ParameterSpace.width`)."""
        P = np.asarray(params, dtype=float).reshape(1, -1)
        outs = self.sim.outputs(P, pin=self.pin)
        return {rid: o[0] for rid, o in zip(self.run_ids, outs)}


def time_derivative(y, time) -> np.ndarray:
    """``dy/dt`` of samples ``y`` (time on axis -2, the rows of one run; ``time`` its uniform axis, s): central
    differences inside, one-sided at the two ends (:func:`numpy.gradient`'s, without its general spacing)."""
    y = np.asarray(y, dtype=float)
    h = float(time[1] - time[0])
    out = np.empty_like(y)
    out[..., 1:-1, :] = (y[..., 2:, :] - y[..., :-2, :]) / (2 * h)
    out[..., 0, :] = (y[..., 1, :] - y[..., 0, :]) / h
    out[..., -1, :] = (y[..., -1, :] - y[..., -2, :]) / h
    return out


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "ENERGY_FLOOR": "cost.energy_floor", "KNOT_BOUND_FACTOR": "cost.knot_bound_factor", "MEAN_SLOPE_VELOCITY":
    "cost.mean_slope_velocity"})
