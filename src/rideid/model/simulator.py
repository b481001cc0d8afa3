"""The simulator as a value: which car model, which backend, which integration settings.

Every stage of rideid that simulates the car — start alignment and the
wiring checks (:mod:`rideid.conditioning`), the cost (:mod:`rideid.estimate.problem.cost`),
the polish's start derivatives, the model choice, adequacy, the damper and
bump-stop checks, planning — is handed one :class:`Simulator` and binds it
to the runs it needs (:meth:`Simulator.bind`). The value is frozen and
hashable; binding it prepares the runs' parameter-independent tables (the
road inputs) into a *bound simulator* (:class:`rideid.model.batch.BatchSimulator`
for the linear car, :class:`rideid.model.nonlinear.NonlinearSimulator` for
damper curves or bump stops) that is never changed by an evaluation: what
varies between calls — the population, the data, a :class:`Pin` of the
nonlinear integrator — is an argument. So copies of a cost function, the
candidates of the model choice fitted on threads, and the start derivative
of a curve model all share one bound simulator safely.

The choice of backend (``"compiled"``, ``"numpy"``; ``None`` follows
``RIDEID_KERNEL`` at each call, :mod:`rideid.model.backend`) is part of the
value; the compiled kernels are imported only when a compiled evaluation
runs, so the NumPy backend works on a machine where they cannot be imported.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import ArgumentError, DataError
from .batch import BatchSimulator
from .nonlinear import RHO_MAX, NonlinearLayout, NonlinearSimulator, Pin, linear_curve
from .params import INDEX, ROW_WIDTHS, Geometry, full_rows, has_powertrain, nominal_car
from .simulate import RunInput

#: backend names a :class:`Simulator` takes (None: ``RIDEID_KERNEL`` decides at each call)
BACKENDS = (None, "compiled", "numpy")


@dataclass(frozen=True)
class Simulator:
    """How the car is simulated: a value made once and passed to every stage that simulates.

    Parameters
    ----------
    layout : NonlinearLayout or None
        The columns of a parameter row and the model they make: ``None`` (or
        a linear layout) the linear car of SPEC §1/§6/§11 (rows of 12, 16 or 23),
        else damper curves and/or bump stops (SPEC §8).
    backend : {None, "compiled", "numpy"}
        The compiled kernels, the NumPy reference, or (None) as
        ``RIDEID_KERNEL`` says at each call.
    rho : float
        The nonlinear integrator's bound on ``h_sub * max|eig|``
        (:data:`rideid.model.nonlinear.RHO_MAX`); unused by the linear car,
        whose discretisation is exact.
    split : bool
        Split the nonlinear sub-steps at the kinks they cross (default).
    """

    layout: NonlinearLayout | None = None
    backend: str | None = None
    rho: float = RHO_MAX
    split: bool = True

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ArgumentError(f"Simulator backend: expected one of compiled, numpy (or None), got {self.backend!r}")
        if not (np.isfinite(self.rho) and self.rho > 0):
            raise ArgumentError(f"Simulator rho must be a positive number, got {self.rho!r}")
        if self.layout is not None and self.layout.linear:
            object.__setattr__(self, "layout", None)  # one value for one model

    @property
    def nonlinear(self) -> bool:
        """Damper curves or bump stops: the nonlinear car (RK4 sub-steps), else the exact linear one."""
        return self.layout is not None

    @property
    def width(self) -> int | None:
        """Columns of a parameter row of this model (None: the linear car, 12, 16 or 23)."""
        return None if self.layout is None else self.layout.n_columns

    def for_layout(self, layout: NonlinearLayout | None) -> "Simulator":
        """The same settings for another model (``layout``)."""
        return replace(self, layout=layout)

    def linear(self) -> "Simulator":
        """The same settings for the linear car (the search of a nonlinear model, the nominal car)."""
        return self.for_layout(None)

    def bind(self, geom: Geometry, runs: list[RunInput]):
        """The runs' prepared tables with this model: a bound simulator whose ``errors(P, Y, W, pin=None)``,
        ``outputs(P, pin=None)`` (and for the nonlinear car ``states``) evaluate populations ``P``."""
        numpy = None if self.backend is None else self.backend == "numpy"
        if self.layout is None:
            return BatchSimulator(geom, runs, numpy=numpy)
        return NonlinearSimulator(geom, runs, self.layout, rho=self.rho, split=self.split, numpy=numpy)

    def row(self, P) -> np.ndarray:
        """Parameter rows ``P`` of the linear car (12, 16 or 23 columns) or of this model as rows of this
        model: a linear car's dampers become curves ``F = c v``, without bump stops (rates 0)."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        lay = self.layout
        if lay is None or P.shape[-1] == lay.n_columns:
            return P if lay is None else lay.rows(P)
        if P.shape[-1] not in ROW_WIDTHS:
            return lay.rows(P)  # the layout's own message
        if has_powertrain(P) and not lay.powertrain:
            raise DataError("parameter rows with a powertrain on mounts (SPEC §11) for a nonlinear car without one: "
                            "give m_p = 0 or a model with the group powertrain")
        base = full_rows(P)[:, :lay.n_car]
        parts = [base]
        if lay.bump_stops:
            parts.append(np.tile([0.15, 0.15, 0.0, 0.0], (base.shape[0], 1)))
        if lay.knots is not None:
            parts += [linear_curve(base[:, INDEX["c_sf"]], lay.knots), linear_curve(base[:, INDEX["c_sr"]], lay.knots)]
        return lay.rows(np.concatenate(parts, axis=-1))

    def nominal(self, geom: Geometry) -> np.ndarray:
        """The built-in nominal car (:func:`rideid.model.params.nominal_car`) as one row of this model."""
        return self.row(nominal_car(geom))[0]


def make_simulator(geom: Geometry, runs: list[RunInput], layout: NonlinearLayout | None = None):
    """``Simulator(layout).bind(geom, runs)``: a :class:`rideid.model.batch.BatchSimulator` for a linear layout
    (``None``, or no curves and no bump stops), else a :class:`rideid.model.nonlinear.NonlinearSimulator`."""
    return Simulator(layout).bind(geom, runs)


__all__ = ["BACKENDS", "Pin", "Simulator", "make_simulator"]
