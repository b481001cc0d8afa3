"""Planning a car with damper curves (SPEC §7 with §8): which knots each candidate run excites.

When the scenario's car has a ``[dampers]`` table (or its ``[model]
extensions`` name ``damper_curves``), the plan's free parameters are those
identify would fit with ``--model damper_curves``: ``c_sf``, ``c_sr`` leave,
the knot forces ``F_f1 .. F_fK``, ``F_r1 .. F_rK`` join
(:class:`rideid.estimate.problem.cost.ParameterSpace`). The knots are the scenario's
``[model] damper_knots`` if given, else the ``[dampers]`` velocities when they
are symmetric (the truth curve is then exactly a car of the model), else
:data:`rideid.model.nonlinear.DEFAULT_KNOTS` (the truth curve sampled at
them). Without ``[dampers]`` the nominal curves are the linear dampers
``F = c_s v``.

The sensitivities are finite differences through the nonlinear car
(:class:`rideid.estimate.problem.cost.CurveSimulator`), its RK4 sub-step count
pinned at the nominal car's for every row of the differences, so the
differenced outputs come from one integrator.

Excitation follows identify (:mod:`rideid.estimate.problem.dampers`): the nominal
car's suspension velocities on each run (the compiled kernel's states at the looser
:data:`rideid.data.scenario.LIFT_OFF_RHO`, as the report's histograms);
per knot, the samples of the axle's two corners beyond the previous knot on
its side (:func:`rideid.estimate.problem.dampers.knot_counts`). A set of runs
excites a knot when those counts, summed over its runs, reach
setting ``dampers.min_samples``; the innermost knots always
count as excited and beyond a knot not excited none is (identify's rule).
A knot a set of runs does not excite is excluded from that set's Fisher
matrix (its rows and columns zero: identify would not fit it, it continues
the last excited segment's slope) and reported "not excited".
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..settings import defaults
from ..data.scenario import LIFT_OFF_RHO
from ..estimate.problem.dampers import knot_counts, suspension_velocities_by_run
from ..model.nonlinear import DEFAULT_KNOTS, curve_names, damper_force
from ..model.simulator import Simulator

CURVES = "damper_curves"
AXLES = ("front", "rear")


def plan_knots(sc) -> tuple[tuple[float, ...] | None, str]:
    """``[model] damper_knots`` for the plan's :class:`ParameterSpace` (None: the defaults) and where they come from."""
    if sc.damper_knots is not None:
        return tuple(sc.damper_knots), "[model] damper_knots"
    dm = sc.dampers
    if dm is not None:
        v = np.asarray(dm.velocity)
        pos = v[v > 0]
        if pos.size and np.allclose(np.sort(-v[v < 0]), pos):
            return tuple(float(k) for k in pos), "[dampers] velocity"
    return None, "default knots (SPEC §8)"


def nominal_forces(sc, layout) -> np.ndarray:
    """Front then rear forces ``(2K,)`` of the nominal car at the plan's knots."""
    k = np.asarray(layout.knots)
    dm = sc.dampers
    if dm is not None:
        return np.concatenate([damper_force(dm.velocity, np.asarray(dm.front), k),
                               damper_force(dm.velocity, np.asarray(dm.rear), k)])
    return np.concatenate([sc.truth["c_sf"] * k, sc.truth["c_sr"] * k])


def run_counts(space, sim, P0, rho: float | None = None) -> np.ndarray:
    """Per run and axle the samples beyond the previous knot, ``(n_runs, 2, K)``, of car ``P0`` (a full row)."""
    if rho is None:
        rho = LIFT_OFF_RHO
    # a plan's candidate runs start at rest: no lead-in (rideid.estimate.problem.cost.CostFunction.input_runs, .lead)
    cf = SimpleNamespace(space=space, sim=sim, simulator=Simulator(space.layout), input_runs=sim.runs,
                         lead=(0,) * len(sim.runs))
    knots = space.layout.knots
    return np.array([[knot_counts(knots, v) for v in pair]
                     for pair in suspension_velocities_by_run(cf, P0, rho=rho)])


def excited(knots, counts, min_samples: int | None = None) -> np.ndarray:
    """Identify's rule on summed ``counts`` ``(2, K)``: excited ``(2, K)`` bool."""
    min_samples = defaults["dampers.min_samples"] if min_samples is None else min_samples
    knots = np.asarray(knots)
    K = knots.size
    j0 = int(np.searchsorted(knots, 0.0))
    out = np.asarray(counts) >= min_samples
    out[:, [j0 - 1, j0]] = True
    for a in range(2):
        for side in (range(j0, K), range(j0 - 1, -1, -1)):
            on = True
            for j in side:
                on = on and bool(out[a, j])
                out[a, j] = on
    return out


def not_excited_names(knots, exc) -> list[str]:
    """Knot-force names of ``exc`` ``(2, K)`` that are False."""
    names = curve_names(len(knots))
    return [n for n, e in zip(names, np.asarray(exc).ravel()) if not e]


class Excitation:
    """Knot excitation of the candidate runs of a plan: ``counts`` ``(n_runs, 2, K)``."""

    def __init__(self, knots, counts, names, min_samples: int | None = None):
        min_samples = defaults["dampers.min_samples"] if min_samples is None else min_samples
        self.knots = tuple(knots)
        self.counts = np.asarray(counts)
        self.names = list(names)  # the plan's free parameters
        self.min_samples = min_samples
        self.knot_names = curve_names(len(self.knots))

    def of(self, runs) -> np.ndarray:
        """Excited ``(2, K)`` by the runs (indices) together."""
        idx = list(runs)
        c = self.counts[idx].sum(0) if idx else np.zeros(self.counts.shape[1:], int)
        return excited(self.knots, c, self.min_samples)

    def not_excited(self, runs) -> list[str]:
        return not_excited_names(self.knots, self.of(runs))

    def mask(self, runs) -> np.ndarray:
        """``(d,)`` bool over the free parameters: False for a knot the runs do not excite."""
        off = set(self.not_excited(runs))
        return np.array([n not in off for n in self.names])

    def run_entry(self, r: int) -> dict:
        """A candidate's ``"dampers"`` entry."""
        exc = self.of([r])
        out = {"excited": [n for n, e in zip(self.knot_names, exc.ravel()) if e],
               "not_excited": not_excited_names(self.knots, exc)}
        for a, axle in enumerate(AXLES):
            out[axle] = {"samples_beyond_previous_knot": self.counts[r, a].tolist(), "excited": exc[a].tolist()}
        return out

    def rule(self) -> str:
        return (f"a knot is excited by a set of runs when at least {self.min_samples} samples (both corners of the "
                "axle, the runs together, the nominal car) go beyond the previous knot on its side; the innermost "
                "knots always count, and beyond a knot not excited none is (identify's rule). Knots not excited "
                "are excluded from the Fisher matrix (not fitted: identify continues the last excited segment's "
                "slope) and their CRLB is reported as null")


def mask_information(M: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``M`` (..., d, d) with the rows and columns of ``~keep`` zeroed."""
    k = np.asarray(keep, float)
    return M * k[:, None] * k[None, :]


__all__ = ["CURVES", "DEFAULT_KNOTS", "Excitation", "excited", "mask_information", "nominal_forces", "plan_knots",
           "run_counts"]
