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
"""

from __future__ import annotations

import numpy as np

from ..data.dataset import Dataset, check_known_consistent, prepare_inputs, scale_anchor
from ..model.batch import BatchSimulator
from ..errors import ArgumentError, DataError
from ..model.equations import CHANNEL_KIND, CHANNELS
from ..model.params import (ALL_NAMES, EXT_NAMES, GROUPS, INDEX, MASS_COUNT, NAMES, default_bounds, nominal_car,
                            total_mass)

ENERGY_FLOOR = 0.01


def refuse_unsupported_groups(groups, where: str = "model"):
    """The nonlinear groups of SPEC §8 (damper_curves, bump_stops) are simulated but not identified yet:
    one clear :class:`ArgumentError` rather than a fit that silently leaves them out."""
    from ..data.schema import NONLINEAR_GROUPS
    bad = [g for g in groups if g in NONLINEAR_GROUPS]
    if bad:
        raise ArgumentError(f"{where}: {' and '.join(repr(g) for g in bad)} (SPEC §8) cannot be identified by this "
                            f"version of rideid: it simulates such a car but fits only the linear model "
                            f"(groups {', '.join(GROUPS)}); remove {'them' if len(bad) > 1 else 'it'} from "
                            "[model] extensions or pass --model base|full|auto")


def channel_weights(Y: np.ndarray) -> np.ndarray:
    """Per-channel weights ``1 / (|C| D_c)`` of one run; 0 for missing (NaN) channels."""
    present = ~np.all(np.isnan(Y), axis=0)
    E = np.where(present, np.nansum(Y * Y, axis=0), 0.0)
    D = np.zeros(len(CHANNELS))
    for i, c in enumerate(CHANNELS):
        if not present[i]:
            continue
        same = [j for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c] and present[j]]
        D[i] = max(E[i], ENERGY_FLOOR * max(E[j] for j in same))
    W = np.zeros(len(CHANNELS))
    n = int(present.sum())
    ok = present & (D > 0)
    W[ok] = 1.0 / (n * D[ok])
    return W


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
        The model's extension groups (:data:`rideid.model.params.GROUPS`);
        their parameters are free unless known.

    Attributes
    ----------
    width : int
        Columns of the full rows :meth:`full` returns: 12, or 16 when the
        model has an extension group or an extension value is known.
    param_names : tuple of str
        The names of those columns.
    reported_names : tuple of str
        The twelve, the model's extension parameters and known extensions
        (an extension neither in the model nor known is 0 and not reported).
    """

    def __init__(self, known: dict[str, float], geometry, bounds: dict | None = None, extensions=()):
        scale_anchor(known)
        check_known_consistent(known)
        self.known = dict(known)
        self.geometry = geometry
        extensions = tuple(extensions)
        refuse_unsupported_groups(extensions)
        for g in extensions:
            if g not in GROUPS:
                raise ArgumentError(f"unknown extension group '{g}'; groups are: {', '.join(GROUPS)}")
        self.extensions = tuple(g for g in GROUPS if g in extensions)
        self.derived = None
        if "total_mass" in known:
            for cand in ("m_s", "m_ur", "m_uf"):
                if cand not in known:
                    self.derived = cand
                    break
        self.fixed = {n: v for n, v in known.items() if n in ALL_NAMES}
        model_ext = [n for g in self.extensions for n in GROUPS[g]]
        self.names = [n for n in list(NAMES) + model_ext if n not in self.fixed and n != self.derived]
        self.width = len(ALL_NAMES) if (model_ext or any(n in self.fixed for n in EXT_NAMES)) else len(NAMES)
        self.param_names = ALL_NAMES[:self.width]
        #: what a result reports: the twelve, the model's extensions and any known extension
        self.reported_names = tuple(n for n in ALL_NAMES if n in NAMES or n in model_ext or n in self.fixed)
        db = default_bounds(geometry)
        bounds = dict(bounds or {})
        for k in bounds:
            if k not in ALL_NAMES:
                raise DataError(f"[bounds]: unknown parameter '{k}'")
        self.bounds = np.array([bounds.get(n, db[n]) for n in self.names], dtype=float)

    def full(self, X) -> np.ndarray:
        """Free-parameter rows ``(n, d)`` -> full rows ``(n, width)`` (:attr:`param_names`)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if X.shape[1] != len(self.names):
            raise ArgumentError(f"expected {len(self.names)} columns ({', '.join(self.names)}), got {X.shape[1]}")
        P = np.zeros((X.shape[0], self.width))
        for j, n in enumerate(self.names):
            P[:, INDEX[n]] = X[:, j]
        for n, v in self.fixed.items():
            P[:, INDEX[n]] = v
        if self.derived is not None:
            others = [n for n in MASS_COUNT if n != self.derived]
            rest = sum(MASS_COUNT[n] * P[:, INDEX[n]] for n in others)
            P[:, INDEX[self.derived]] = (self.known["total_mass"] - rest) / MASS_COUNT[self.derived]
        return P

    def derived_gradient(self) -> np.ndarray:
        """d(derived mass)/d(free parameters), shape (d,); zeros if nothing is derived."""
        g = np.zeros(len(self.names))
        if self.derived is not None:
            for n in MASS_COUNT:
                if n != self.derived and n in self.names:
                    g[self.names.index(n)] = -MASS_COUNT[n] / MASS_COUNT[self.derived]
        return g

    def valid(self, P) -> np.ndarray:
        """Rows that are physical: positive masses etc., 0 < a < wheelbase, extensions >= 0."""
        ok = np.all(np.isfinite(P), axis=1)
        for n in NAMES:
            col = P[:, INDEX[n]]
            ok &= (col > 0) & ((col < self.geometry.wheelbase) if n == "a" else True)
        if P.shape[1] > len(NAMES):
            ok &= np.all(P[:, len(NAMES):] >= 0, axis=1)
        return ok

    def nominal(self) -> np.ndarray:
        """A physically consistent nominal car: the built-in car scaled to the
        anchor, clipped into the bounds (used for sensitivity maps and as a
        reference point, never as a starting guess)."""
        base = nominal_car(self.geometry, extensions=True)
        anchor = scale_anchor(self.known)
        if anchor == "total_mass":
            s = self.known["total_mass"] / total_mass(base)
        else:
            s = self.known[anchor] / base[INDEX[anchor]]
        P = base * np.where(np.array(ALL_NAMES) == "a", 1.0, s)
        x = np.clip(P[[INDEX[n] for n in self.names]], self.bounds[:, 0], self.bounds[:, 1])
        return self.full(x)[0]


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

    Attributes
    ----------
    names : list of str
        The free parameter names, in column order.
    bounds : ndarray, shape (d, 2)
    run_ids : list of str
    """

    def __init__(self, ds: Dataset, weights=None, use_kernel: bool = True, space: ParameterSpace | None = None,
                 extensions=None):
        unaligned = [r.id for r in ds.runs if r.id not in ds.data]
        if unaligned:
            raise ArgumentError(f"runs {', '.join(unaligned)} have no start yet: load the dataset with "
                                "rideid.load_dataset (or pass it through rideid.data.dataset.align_starts)")
        self.ds = ds
        if space is None:
            if extensions is None:  # the dataset's [model], else the twelve
                extensions = ds.manifest.extensions or ()
                refuse_unsupported_groups(extensions, f"{ds.manifest.path}: [model] extensions")
            space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=extensions)
        self.space = space
        self.names = list(self.space.names)
        self.bounds = self.space.bounds
        self.run_ids = [r.id for r in ds.runs]
        runs, Ys, Ws = prepare_inputs(ds), [], []
        for r in ds.runs:
            Y = ds.data[r.id].matrix()
            Ws.append(channel_weights(Y))
            Ys.append(np.nan_to_num(Y, nan=0.0))
        self.sim = BatchSimulator(ds.geometry, runs)
        self.Y = np.ascontiguousarray(np.concatenate(Ys))
        self.W = np.array(Ws)
        self.use_kernel = use_kernel
        self.weights = np.full(len(runs), 1.0 / len(runs))
        if weights is not None:
            self.set_weights(weights)
        self.nfev = 0

    def copy(self, weights=None) -> "CostFunction":
        """A copy sharing the prepared runs and data, with its own weights
        (equal unless given) and its own evaluation count (0)."""
        new = object.__new__(CostFunction)
        new.__dict__.update(self.__dict__)
        new.weights = np.full(len(self.run_ids), 1.0 / len(self.run_ids))
        if weights is not None:
            new.set_weights(weights)
        new.nfev = 0
        return new

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
            E[:, ok] = fn(P[ok], self.Y, self.W)
        self.nfev += P.shape[0]
        return E

    def combine(self, E, weights=None) -> np.ndarray:
        w = self.weights if weights is None else np.asarray(weights, dtype=float)
        with np.errstate(invalid="ignore"):
            return w @ E

    def __call__(self, X) -> np.ndarray:
        """Costs ``(n,)`` for free-parameter rows ``X`` of shape ``(n, d)``."""
        return self.combine(self.run_errors(X))

    def residuals(self, X, weights=None, Y=None) -> np.ndarray:
        """Stacked weighted residuals ``(n, m)`` whose squared sum is ``J``.

        ``Y`` replaces the measured data (same layout as :attr:`Y`), e.g. the
        data re-read at other start times. The layout: run by run, time-major,
        the run's used channels (``W[r] > 0``) within each sample.
        """
        P = self.space.full(X)
        outs = self.sim.outputs(P)
        w = self.weights if weights is None else np.asarray(weights, dtype=float)
        Y = self.Y if Y is None else Y
        parts = []
        for ri, (s, e) in enumerate(zip(self.sim.run_start[:-1], self.sim.run_start[1:])):
            cols, sc = self.residual_scale(ri, w)
            d = (outs[ri][:, :, cols] - Y[None, s:e, cols]) * sc
            parts.append(d.reshape(P.shape[0], -1))
        self.nfev += P.shape[0]
        return np.concatenate(parts, axis=1)

    def residual_scale(self, ri, weights):
        """Used channel indices of run ``ri`` and their residual scale ``sqrt(w_r W_rc)``."""
        cols = np.nonzero(self.W[ri] > 0)[0]
        return cols, np.sqrt(weights[ri] * self.W[ri, cols])

    def simulate(self, params) -> dict[str, np.ndarray]:
        """Simulated channels ``(n_time, 10)`` per run for one full parameter vector (12 or 16)."""
        P = np.asarray(params, dtype=float).reshape(1, -1)
        outs = self.sim.outputs(P)
        return {rid: o[0] for rid, o in zip(self.run_ids, outs)}
