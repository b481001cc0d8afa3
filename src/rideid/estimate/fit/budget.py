"""The uncertainty budget (SPEC §12): declared inputs propagated to every estimate, as the GUM does.

A dataset may declare the standard uncertainty of what rideid otherwise takes
as exact (:mod:`rideid.data.schema.declared`): a ``[known]`` value (the
weighbridge's total mass), a ``[vehicle]`` length (the tape), a sensor's
sensitivity (``[channels]`` ``sensitivity_std``). Each estimate ``theta`` is
a function of those inputs ``u`` through the least-squares fit; to first
order (GUM, JCGM 100:2008 §5.1)

    u_i(theta) = |d theta / d u_i| std(u_i)
    std_total  = sqrt(std_robust^2 + sum_i u_i(theta)^2)

with the inputs independent of each other and of the sensor noise.

**The sensitivities d theta / d u** come from the implicit function theorem
at the optimum: the fit solves ``J^T r(theta, u) = 0``, so

    d theta / d u = -(J^T J)^+ J^T dr/du

(the Gauss–Newton Hessian ``J^T J`` the polish already uses; its second-order
term ``sum r d2r`` is dropped as everywhere in the polish's uncertainty).
``J`` is differenced at the optimum as the polish does it (bound-normalised,
pseudo-inverse by SVD: :func:`rideid.estimate.fit.uncertainty.normal_inverse`),
a parameter held at a search bound is held here too, and ``dr/du``:

- a sensor's sensitivity: the data of channel ``c`` are ``(1 + eps) y``, so
  ``dr/d eps = -Y_c`` (scaled as the residuals are), exact and free;
- a ``[known]`` value: the full parameter row moves (a known parameter's
  column; ``total_mass`` moves the derived mass), central differences of the
  residuals (2 simulations);
- a ``[vehicle]`` length: the cost function rebuilt on that geometry (road
  inputs and model) at the same parameters, central differences.

One residual Jacobian and two simulations per known or geometric input: a
few tenths of a second, where re-fitting with each input perturbed (the
alternative, finite differences of the whole estimate) costs one polish per
input and side. The two agree to the linearisation's accuracy; the tests
check the propagation against a Monte Carlo of re-fits over the declared
distributions (tests/test_budget.py). The scale anchor gives a closed form
the tests check too: with every mass, inertia, stiffness and damping scaled
by the anchor (SPEC §1), ``d theta / d total_mass = theta / total_mass`` for
those, 0 for ``a``: total_mass's contribution is exactly its relative std
times the value.

Results whose fit cannot be rebuilt here (runs on unknown roads, SPEC §9)
get the anchor's closed form only; any other declared input is then listed
under ``not_propagated`` and the result says the budget omits it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...profiling import stage
from ...settings import defaults, legacy_names
from ...data.dataset import Dataset
from ...errors import ArgumentError, DataError
from ...model.equations import CHANNELS
from ...model.batch import single_threaded_blas, thread_map
from ...model.params import EXTRA_KNOWN, MASS_COUNT, UNITS
from ..problem.cost import BUMP_UNITS, CostFunction, ParameterSpace
from ..problem.redundancy import gain_notes, rigid_body_gains
from .uncertainty import normal_inverse

#: the budget's entry for ``std_robust`` (the sensor noise, through the HAC sandwich)
STATISTICAL = "statistical"
#: the budget's name of the runs' disagreement beyond their noise (part of std_robust)
BETWEEN_RUNS = "between runs"
#: the budget's name of the speed and start fitted along a speed channel (part of std_robust: tracks as built)
MOTION = "speed and start"
#: prefix of a sensor's entry: ``"sensitivity body_az_fl"``
SENSITIVITY = "sensitivity"
#: parameters that do not scale with the anchor (lengths): the anchor's closed form gives them 0
LENGTHS = ("a", "bs_clear_f", "bs_clear_r")


@dataclass(frozen=True)
class DeclaredInput:
    """One input with a declared standard uncertainty.

    Attributes
    ----------
    name : str
        Its budget entry: the key (``"total_mass"``, ``"wheelbase"``) or ``"sensitivity <channel>"``.
    kind : {"known", "vehicle", "sensitivity"}
    key : str
        The ``[known]``/``[vehicle]`` key or the channel.
    value : float
        The declared value (1 for a sensitivity: the relative gain).
    std : float
        Standard uncertainty, in the value's unit (relative for a sensitivity).
    unit : str
    """

    name: str
    kind: str
    key: str
    value: float
    std: float
    unit: str

    def to_dict(self) -> dict:
        if self.kind == SENSITIVITY:
            return {"kind": self.kind, "channel": self.key, "std": self.std, "unit": "relative"}
        return {"kind": self.kind, "key": self.key, "value": self.value, "std": self.std, "unit": self.unit}


def declared_inputs(manifest) -> list[DeclaredInput]:
    """The inputs of a manifest with a positive declared std: ``[known]``, ``[vehicle]``, then the sensors."""
    out = []
    declared = getattr(manifest, "declared", {}) or {}
    for k, std in sorted(declared.items(), key=lambda kv: kv[0] not in manifest.known):  # [known] first
        if not std > 0:
            continue
        if k in manifest.known:
            unit = EXTRA_KNOWN.get(k) or UNITS.get(k) or BUMP_UNITS.get(k, "")
            out.append(DeclaredInput(k, "known", k, float(manifest.known[k]), float(std), unit))
        else:
            out.append(DeclaredInput(k, "vehicle", k, float(getattr(manifest.geometry, k)), float(std), "m"))
    for c, s in (getattr(manifest, "sensitivity_std", {}) or {}).items():
        if s > 0:
            out.append(DeclaredInput(f"{SENSITIVITY} {c}", SENSITIVITY, c, 1.0, float(s), "1"))
    return out


def _spoken(key: str) -> str:
    return "total mass" if key == "total_mass" else key


def anchor_note(key: str) -> str:
    """What the result says when the scale anchor is a plain number (SPEC §12)."""
    return (f"{_spoken(key)} taken as exact: every mass, inertia, stiffness and damping scales with it, so its "
            f"real uncertainty (a weighbridge's 0.5-1 %) is missing from every std_total; declare it as "
            f"{key} = {{ value = ..., std = ... }} in [known]")


# ---------------------------------------------------------------------------
# The propagation (a pure function of a cost function at its optimum)

def _direct(space: ParameterSpace, inp: DeclaredInput) -> np.ndarray:
    """``dP/du`` of the full row at fixed free parameters: the column the known value fills, and the derived
    mass where the value enters it (``total_mass``; a known unsprung mass with total_mass known)."""
    g = np.zeros(space.width)
    k = inp.key
    if k in space.col and k in space.fixed:
        g[space.col[k]] = 1.0
    if space.derived is not None:
        c = MASS_COUNT[space.derived]
        if k == "total_mass":
            g[space.col[space.derived]] = 1.0 / c
        elif k in MASS_COUNT and k in space.fixed:
            g[space.col[space.derived]] = -MASS_COUNT[k] / c
    return g


def _full_jacobian(space: ParameterSpace, x) -> np.ndarray:
    """``dP/dx``, shape ``(d, width)``: the identity on the free columns, the derived ones' gradients
    (linear at an interior optimum: one-sided differences are exact)."""
    d = len(space.names)
    h = 1e-6 * np.maximum(np.abs(x), 1.0)
    X = np.tile(x, (d + 1, 1))
    X[1 + np.arange(d), np.arange(d)] += h
    P = space.full(X)
    return (P[1:] - P[0]) / h[:, None]


def residual_jacobian(cf: CostFunction, x, weights) -> tuple[np.ndarray, np.ndarray]:
    """The polish's Jacobian at ``x``: ``(m, d)`` in bound-normalised coordinates (forward differences,
    setting ``budget.jacobian_step``), and the residuals ``(m,)``."""
    lo, span = cf.bounds[:, 0], cf.bounds[:, 1] - cf.bounds[:, 0]
    z = (np.asarray(x, dtype=float) - lo) / span
    d = z.size
    step = defaults["budget.jacobian_step"]
    steps = np.where(z + step <= 1, step, -step)
    Z = np.tile(z, (d + 1, 1))
    Z[1 + np.arange(d), np.arange(d)] += steps
    R = cf.residuals(lo + span * Z, weights)
    return ((R[1:] - R[0]) / steps[:, None]).T, R[0]


def _sensor_column(cf: CostFunction, channel: str, weights) -> np.ndarray:
    """``dr/d eps`` of a relative gain error ``eps`` of ``channel`` (data ``(1 + eps) Y``): ``-Y_c`` on that
    channel's rows, scaled as the residuals (layout of :meth:`CostFunction.residuals`)."""
    c = CHANNELS.index(channel)
    parts = []
    for ri, (s, e) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:])):
        cols, sc = cf.residual_scale(ri, weights)
        block = np.zeros((e - s, cols.size))
        hit = np.nonzero(cols == c)[0]
        if hit.size:
            block[:, hit[0]] = -cf.Y[s:e, c] * sc[hit[0]]
        parts.append(block.ravel())
    return np.concatenate(parts)


def _geometry_cost(cf: CostFunction, key: str, value: float) -> CostFunction:
    """The cost function on the same runs and parameter space with one ``[vehicle]`` length changed."""
    ds = cf.ds
    geom = replace(ds.geometry, **{key: value})
    ds2 = Dataset(replace(ds.manifest, geometry=geom), dict(ds.data), dict(ds.measured))
    return CostFunction(ds2, space=cf.space, simulator=cf.simulator, use_kernel=cf.use_kernel).with_pin(cf.pin)


def _input_column(cf: CostFunction, P0, inp: DeclaredInput, weights) -> np.ndarray:
    """``dr/du`` of one declared input at the full row ``P0``."""
    if inp.kind == SENSITIVITY:
        return _sensor_column(cf, inp.key, weights)
    h = defaults["budget.input_step"] * inp.std
    if inp.kind == "known":
        g = _direct(cf.space, inp)
        R = cf.row_residuals(np.vstack([P0 + h * g, P0 - h * g]), weights)
        return (R[0] - R[1]) / (2 * h)
    r_plus = _geometry_cost(cf, inp.key, inp.value + h).row_residuals(P0[None], weights)[0]
    r_minus = _geometry_cost(cf, inp.key, inp.value - h).row_residuals(P0[None], weights)[0]
    return (r_plus - r_minus) / (2 * h)


def propagate(cf: CostFunction, x, inputs) -> dict[str, np.ndarray]:
    """``dP/du``: each declared input's effect on every column of the full row at the optimum ``x``.

    Parameters
    ----------
    cf : CostFunction
        The fit's cost function (its space and data); evaluated with equal run weights, as the polish.
    x : array_like, shape (d,)
        The free parameters at the optimum.
    inputs : sequence of DeclaredInput

    Returns
    -------
    dict
        Input name -> ndarray ``(width,)`` in the columns of :attr:`ParameterSpace.param_names`
        (per unit of the input; per unit of relative gain for a sensitivity).
    """
    x = np.asarray(x, dtype=float)
    space = cf.space
    if x.shape != (len(space.names),):
        raise ArgumentError(f"x: expected {len(space.names)} free parameters, got shape {x.shape}")
    weights = np.full(len(cf.run_ids), 1.0 / len(cf.run_ids))
    P0 = space.full(x[None])[0]
    Jz, _ = residual_jacobian(cf, x, weights)
    lo, span = cf.bounds[:, 0], cf.bounds[:, 1] - cf.bounds[:, 0]
    z = (x - lo) / span
    at = defaults["budget.at_bound"]
    free = (z > at) & (z < 1 - at)  # held at a bound by the polish: held here
    Jf = Jz[:, free]
    Hinv = normal_inverse(Jf).matrix
    A = _full_jacobian(space, x)
    out = {}
    # each input's column is independent (a geometry input: two simulations on a cost function of its own): side by
    # side, BLAS on one thread, in the inputs' order, so one or two cores give the same numbers (tests/test_budget.py)
    with single_threaded_blas():
        columns = thread_map(lambda inp: _input_column(cf, P0, inp, weights), inputs, "rideid-budget")
    for inp, g in zip(inputs, columns):
        dx = np.zeros(x.size)
        dx[free] = -span[free] * (Hinv @ (Jf.T @ g))
        direct = _direct(space, inp) if inp.kind == "known" else np.zeros(space.width)
        out[inp.name] = dx @ A + direct
    return out


def scale_gradients(space_names, values: dict, anchor: DeclaredInput) -> dict[str, np.ndarray]:
    """The anchor's closed form (SPEC §1 scale invariance): ``d theta / d anchor = theta / anchor`` for every
    parameter but the lengths (:data:`LENGTHS`), which do not move. ``values``: name -> estimate."""
    g = np.array([0.0 if n in LENGTHS else values[n] / anchor.value for n in space_names])
    return {anchor.name: g}


# ---------------------------------------------------------------------------
# The result's entries

def budget_entries(details: dict, names, gradients: dict, inputs) -> dict:
    """``details`` with ``std_total`` and ``budget`` on every parameter (a new dict of new entries).

    ``names``: the columns of the gradients (:attr:`ParameterSpace.param_names`). An estimated parameter's
    budget is ``statistical`` (its ``std_robust``) then each input's ``|d theta/d u| std(u)``; ``std_total``
    their quadrature sum, ``std_robust`` itself when nothing is declared. A known parameter with a declared
    std has that std as its budget; one without, 0. A parameter without a standard error (not identified,
    not excited, not reached) has neither.
    """
    col = {n: i for i, n in enumerate(names)}
    std_of = {i.name: i.std for i in inputs}
    out = {}
    for n, e in details.items():
        e = dict(e)
        stat = e.get("std_robust")
        if e.get("fixed"):
            own = [i for i in inputs if i.kind == "known" and i.key == n]
            e["std_total"] = own[0].std if own else (0.0 if stat is None else stat)
            e["budget"] = {n: own[0].std} if own else {}
        elif stat is None:
            e["std_total"] = None
            e["budget"] = None
        else:
            # the runs' disagreement beyond their noise is in std_robust (rideid.estimate.fit.uncertainty
            # between_runs_variance): shown as its own contribution
            between = float(e.get("std_between_runs") or 0.0)
            # the speed and start fitted along a speed channel (rideid.estimate.fit.anyroad) are in std_robust too
            motion = float(e.get("std_motion") or 0.0)
            parts = {STATISTICAL: float(np.sqrt(max(stat ** 2 - between ** 2 - motion ** 2, 0.0)))}
            if between > 0:
                parts[BETWEEN_RUNS] = between
            if motion > 0:
                parts[MOTION] = motion
            for name, g in gradients.items():
                if n in col:
                    parts[name] = float(abs(g[col[n]]) * std_of[name])
            extra = [v for k, v in parts.items() if k not in (STATISTICAL, BETWEEN_RUNS, MOTION)]
            e["std_total"] = float(stat) if not extra else float(np.sqrt(stat ** 2 + sum(v * v for v in extra)))
            e["budget"] = parts
        out[n] = e
    return out


def fit_cost(ds: Dataset, res, simulator=None, cost: CostFunction | None = None) -> CostFunction | None:
    """The cost function of a known-road fit rebuilt at its result (its model, frozen knots, starts), or None
    where it cannot be (runs on unknown roads or tracks fitted as built: the road fit's; a parameter list that
    does not match the result's)."""
    as_built = any(not rec.get("rejected") for rec in (getattr(res, "tracks", None) or {}).values())
    if ds.unknown_road_runs or as_built:  # the road fit's estimate (unknown roads, tracks as built)
        return None
    if cost is not None:
        cf = cost
    else:
        ext = tuple((res.model or {}).get("extensions") or ())
        # the knots the curves were fitted at: the dataset's, or the knee grid (problem.dampers.KNEE_GRID)
        knots = ([v for v in res.dampers["velocity"] if v > 0] if getattr(res, "dampers", None)
                 else ds.manifest.damper_knots)
        space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=ext, damper_knots=knots)
        frozen = [n for n, d in res.details.items() if d.get("excited") is False]
        if frozen:
            space = space.with_frozen(frozen)
        held = {n: float(d["value"]) for n, d in res.details.items() if d.get("reached") is False
                and not d.get("fixed")}
        if held:
            space = space.with_bump_frozen(held)
        ds_fit = res.fitted_data(ds)
        cf = CostFunction(ds_fit, space=space, simulator=simulator)
    if list(cf.names) != list(res.names):
        return None
    if cf.space.layout is not None:
        cf = cf.pinned_at(cf.space.full(np.asarray(res.x, dtype=float)[None])[0])
    return cf


@stage("budget")
def with_budget(ds: Dataset, res, simulator=None, cost: CostFunction | None = None):
    """``res`` with ``std_total`` and ``budget`` on every parameter and the ``uncertainty`` block (SPEC §12):
    what was declared, the anchor (and whether it is taken as exact), how it was propagated, what was not,
    the body sensors' relative gains from rigid-body redundancy (:func:`rigid_body_gains`) and the notes.

    With nothing declared ``std_total`` is ``std_robust`` exactly and nothing is simulated.
    """
    inputs = declared_inputs(ds.manifest)
    anchor = ds.anchor  # the dataset's own (rideid.data.dataset.Dataset.anchor)
    block = {"declared": {i.name: i.to_dict() for i in inputs}, "anchor": anchor,
             "anchor_exact": anchor is not None and not any(i.key == anchor and i.kind == "known" for i in inputs),
             "method": "none declared: std_total = std_robust" if not inputs else
             "first order (GUM): implicit-function sensitivities from the polish's Jacobian, in quadrature "
             "with std_robust (rideid.estimate.fit.budget)",
             "not_propagated": []}
    notes = []
    if block["anchor_exact"]:
        notes.append(anchor_note(anchor))
    gradients, names = {}, list(res.details)
    usable = inputs and bool(res.polish) and np.all(np.isfinite(np.asarray(res.x, dtype=float)))
    cf = None
    why = ("no polish: no Jacobian to propagate through" if not res.polish else
           "this fit is not rebuilt for the propagation: runs on unknown roads")
    if usable:
        try:
            cf = fit_cost(ds, res, simulator, cost)
            if cf is not None:
                gradients = propagate(cf, res.x, inputs)
                names = list(cf.space.param_names)
        except (DataError, ArgumentError, ValueError, np.linalg.LinAlgError) as e:  # the estimate stands
            cf, why = None, f"the fit could not be rebuilt for the propagation ({e})"
    if cf is None and inputs:
        values = {n: float(d["value"]) for n, d in res.details.items()}
        anchors = [i for i in inputs if i.kind == "known" and i.key == anchor]
        if anchors:
            gradients = scale_gradients(names, values, anchors[0])
        block["not_propagated"] = [i.name for i in inputs if i.name not in gradients]
        if block["not_propagated"]:
            block["method"] = f"closed form of the scale anchor only ({why})"
            notes.append("std_total omits " + ", ".join(block["not_propagated"]) + ": not propagated on this "
                         "fit, so std_total is optimistic about them")
    # what the data tell of the body sensors' gains themselves (rideid.estimate.problem.redundancy): reported, and
    # a sensor that reads off by more than its declared sensitivity allows is named
    block["rigid_body"] = rigid_body_gains(ds)
    notes += gain_notes(block["rigid_body"], dict(getattr(ds.manifest, "sensitivity_std", {}) or {}))
    block["notes"] = notes
    details = budget_entries(res.details, names, gradients, inputs)
    return replace(res, details=details, uncertainty=block, dampers=dampers_with_totals(res, details))


def dampers_with_totals(res, details: dict):
    """The result's ``dampers`` block with ``std_robust`` and ``std_total`` for each axle's knot forces taken
    from the knots' own entries of ``details`` (the block is written before the runs' disagreement is folded
    into std_robust; None where a knot is not excited), or the block as it was (no curves)."""
    block = getattr(res, "dampers", None)
    if not block:
        return block
    out = dict(block)
    for a, axle in enumerate(("front", "rear")):
        if axle not in block:
            continue
        prefix = "F_f" if a == 0 else "F_r"
        ax = dict(block[axle])
        entries = [details.get(f"{prefix}{j + 1}") or {} for j in range(len(ax.get("std_robust", [])))]
        ax["std_robust"] = [None if s is None else e.get("std_robust", s) for s, e in zip(ax["std_robust"], entries)]
        ax["std_total"] = [None if s is None else e.get("std_total", s) for s, e in zip(ax["std_robust"], entries)]
        out[axle] = ax
    return out


__all__ = ["DeclaredInput", "declared_inputs", "propagate", "budget_entries", "with_budget", "fit_cost",
           "scale_gradients", "anchor_note", "dampers_with_totals", "STATISTICAL", "SENSITIVITY", "MOTION"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "AT_BOUND": "budget.at_bound", "JACOBIAN_STEP": "budget.jacobian_step", "INPUT_STEP": "budget.input_step"})
