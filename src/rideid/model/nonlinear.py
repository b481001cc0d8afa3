"""The nonlinear full car of SPEC §8: damper curves, bump stops, lift-off, CG height.

The car is the 7-DOF model of SPEC §1/§6 (:mod:`rideid.model.equations`,
generalised coordinates ``q = [z, theta, phi, z_fl, z_fr, z_rl, z_rr]``,
deviations from static equilibrium) with these forces at corner ``i``
(deflection ``d_i = z_i - z_bi``, velocity ``v_i = d_i'``, both compression
+, at the wheel):

* suspension force on the body ``F_i = k_s d_i + bar_i + D(v_i) + S(d_i)``
  and ``-F_i`` on the wheel, where ``bar_i = k_ar (d_i - d_j)`` (``j`` the
  other corner of the axle), ``D`` the damper: the axle's curve
  (:func:`damper_force`, piecewise linear through ``(0, 0)`` and the forces
  at the knots, continued beyond the outermost knots with the last
  segment's slope) or ``c_s v`` without curves, and ``S`` the bump stop
  ``rate * max(d - clearance, 0)`` (0 without bump stops);
* tire force on the wheel ``T_i = max(L_i + k_t (r_i - z_i) + c_t (r_i' - z_i'), 0) - L_i``
  with ``L_i`` the static corner load
  (:func:`rideid.model.equations.static_corner_loads`): the tire pushes but
  never pulls, a wheel may leave the road;
* CG height ``h = geom.cg_height``: pitch and roll inertias
  ``I + 2 (m_uf + m_ur) h^2`` and gravity's toppling moment ``m_s g h theta``
  (``m_s g h phi``), as the linear model (:func:`rideid.model.equations.mck`).

Equations: ``m_s z'' = sum F_i``, ``I_yy' theta'' = -sum x_i F_i + m_s g h theta``,
``I_xx' phi'' = sum y_i F_i + m_s g h phi``, ``m_u z_i'' = -F_i + T_i``. The
mass matrix stays diagonal. Outputs: the ten SPEC channels
(:data:`rideid.model.equations.CHANNELS`) as in the linear model: body
corner ``i`` reads ``z'' - x_i theta'' + y_i phi''``, axle ``i`` reads
``z_i''``, the gyros ``theta'``, ``phi'``. Initial state: the linear static
equilibrium for the road input at the first sample (``K q = Bf r(0)``,
exact while the bump stops are clear of it and every tire is loaded, e.g.
on every track's flat lead-in), zero velocities.

A powertrain on mounts (SPEC §11, ``NonlinearLayout(powertrain=True)``):
the linear car's (:mod:`rideid.model.equations`), its heave ``u`` and pitch
``psi`` relative to the body four more states after the fourteen
(:data:`POWERTRAIN_STATES`); the generalised forces on ``(z, theta, u,
psi)`` (the suspension's on the body as above, the mounts' springs and
dampers on ``u``, ``psi``) move them through the inverse of their mass
matrix (:func:`powertrain_mass`, per candidate), ``phi`` and the wheels as
above. A row with ``m_p = 0`` gets the linear car's decoupled dummy.

Parameter rows (:class:`NonlinearLayout`): the sixteen
:data:`rideid.model.params.SUSPENSION_NAMES` (with a powertrain then its
seven: the 23 columns of :data:`rideid.model.params.ALL_NAMES`), then with bump stops
:data:`BUMP_STOP_NAMES` (``bs_clear_f, bs_clear_r`` m, ``bs_rate_f,
bs_rate_r`` N/m), then with curves the front forces at the ``K`` knots
``F_f1 .. F_fK`` and the rear ones ``F_r1 .. F_rK`` (N, knots in ascending
order). With curves the columns ``c_sf``, ``c_sr`` are not used.

Integration
-----------
The exact discretisation of the linear kernel (:mod:`rideid.model.discretize`)
needs a linear system; here the forces are piecewise linear in the state
with kinks (damper knots, bump-stop contact, lift-off) that move with the
state. Alternatives considered:

* *exact linear step with the nonlinear remainder as input* (exponential
  integrators): exact for the linear part, but the remainder is not smooth
  either, its quadrature needs the same sub-steps, and the per-candidate
  matrix exponentials and moment matrices (which make the linear kernel
  cheap) would need refreshing whenever a corner changes segment. Measured
  (``benchmarks/study_expint.py``: the linear car with the curves' mean
  slope at zero velocity exact, road forcing included; ETDRK4 or Lawson
  RK4 on the remainder): 1e-3 - 1.7e-2 of RMS at one step per sample,
  2.4e-4 - 8.4e-3 at two, on the runs below and the built-in ones; with
  each corner's region frozen over the step and the crossings' missed
  forces in closed form (``--crossings``) 7.3e-5 - 3.7e-4 at one step, at
  about 4x the linear kernel's arithmetic (``docs/dampers.md``);
* *operator splitting* (linear exact step + nonlinear kick): first or second
  order only, error hard to bound on a stiff bump stop;
* *implicit schemes* (trapezoidal, Radau): unconditionally stable, but a
  Newton solve per step and per candidate, with Jacobians that jump at the
  kinks; the car is not stiff at a sensible sub-step (the fastest mode is
  the wheel hop, ~10-20 Hz, or a bump stop), so stability buys nothing;
* *explicit Runge-Kutta at a fixed sub-step*: classical RK4 with ``m``
  equal sub-steps per sample interval; four cheap force evaluations per
  sub-step, fourth order where the forces are smooth, but only second
  order locally where a stage straddles a kink (damper knot, including
  the zero-velocity knee of an asymmetric damper, bump-stop contact,
  lift-off), so the kinks set the accuracy and need ``h/m * max|eig| <=
  0.03`` (13-15 sub-steps at 200 Hz) for 1e-4 of RMS;
* *RK4 sub-steps split at the kinks* (chosen): the same sub-steps, and a
  sub-step whose ends lie on different sides of a kink (a corner's damper
  velocity in another curve segment, its deflection on the other side of
  the bump-stop clearance, its tire load of the other sign) is redone in
  pieces that end at the crossings: each crossing located on the cubic
  Hermite through the switching quantity's values and rates at the
  sub-step's ends (the rates are known there: the damper velocity's from
  the accelerations, the deflection's is the damper velocity; the tire
  load's crossing by its chord), two Newton steps. Each piece is smooth,
  so RK4 keeps its order; the pieces' ends move continuously with the
  parameters (a crossing leaving the sub-step makes its piece vanish), so
  the cost stays a smooth function of the parameters, as the polish's
  finite differences need. No step-size control, same ``m`` for the whole
  population, and one set of knots split at for the whole population
  (:func:`kink_mask`: the knots where some candidate's curve bends; a
  digressive curve is straight through the knots below and above its knee,
  which then cost nothing; the polish pins the set with the sub-steps,
  :class:`Pin`). On the built-in scenario
  15-35 % of the sub-steps cross a knot, fewer a kink (0.2-1 knot
  crossings per sub-step, the fast runs the most), each such
  sub-step costing its plain step (the trial that finds the crossings) plus
  one RK4 step per piece. Four candidates run side by side in the lanes of
  a vector (:mod:`rideid.model.kernel_nl_ir`); ``benchmarks/bench_nonlinear.py``
  measures the cost per candidate-sample against the linear kernel's on the
  same runs (64 digressive cars, one thread, CPU time): 6.5-8.2x (4.7-5.7x
  against the linear kernel before it became faster), from 24x with one
  candidate at a time.

``m`` is set per call by the fastest mode of the linearised car at its
stiffest (spring plus bump-stop rate, the steepest damper segment, tires
in contact): the smallest ``m`` with ``h/m * max|eig(A)| <= RHO_MAX``
(:data:`RHO_MAX` = 0.2: 2-3 sub-steps at 200 Hz), one ``m`` for the whole
population like the linear kernel's series length. The road input and its
rate are tabulated once per run and ``m`` at the sub-step and half-step
instants ``t_k + j h / (2 m)`` (:func:`fine_inputs`,
:attr:`rideid.model.simulate.RunInput.inputs_at`, the same envelope model
as the samples; inside a split sub-step a cubic Hermite of that table).
The road is not smooth (a profile's table, the envelope's grid: kinks
every few mm), which at so few sub-steps would cost first-order errors, so
the half-step rows hold *Simpson-consistent* values instead of point
values: the input such that Simpson's rule over the sub-step gives its
exact mean (Gauss-Legendre, :data:`QUAD_PANELS` panels), and the rate such
that it gives the input's exact change. Where the road is smooth they
differ from the point values by ``O(h^4)``.

The wheels' velocity states are shifted, ``p_i = z_i' - (c_t/m_u) r_i``
(the linear kernel's shift, :mod:`rideid.model.discretize`): in contact the
tire damper's ``c_t r'`` cancels from ``p'``, so the road's rate, which
jumps where the envelope kinks, enters the integration only while a wheel
is off the road (and the outputs at the samples, as a feedthrough).

Accuracy, measured on runs where the car (asymmetric digressive dampers,
bars, tire damping, CG 0.25 m) reaches its bump stops and lifts wheels,
against the same scheme at 64x the sub-steps (largest error over the ten
channels, relative to the channel's RMS; ``tests/test_nonlinear.py``),
3 sub-steps at 200 Hz: washboard 3.0e-5, herringbone 2.9e-5, chassis
twist 1.0e-5, profile 6.0e-5 (flat: exactly 0); against SciPy's DOP853
(rtol 1e-10) on independently written equations 1.0e-5 (chassis twist). The fine references of the
split and the plain scheme (1024 sub-steps) agree within 5e-8. The plain
RK4 at the same 3 sub-steps: 2.5e-4 - 7.0e-4; at 15 sub-steps (its former
``rho = 0.03``) 7.9e-6 - 4.9e-5. At 2 sub-steps the split scheme is within
4e-5 - 1.4e-4 (the profile the worst).

Backends
--------
:class:`NonlinearSimulator` has two backends behind one seam: a compiled,
threaded kernel (Numba, :mod:`rideid.model.kernel_nl`; candidates shared
among ``numba.get_num_threads()`` threads, the compiled function releases
the GIL) and a pure-NumPy reference (loop over time in Python, vectorised
over candidates). ``RIDEID_KERNEL=numpy`` selects the NumPy backend for the
linear and the nonlinear simulators; if the compiled kernel cannot be built
the NumPy backend is used with one warning (:mod:`rideid.model.backend`).
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

from ..errors import DataError
from . import backend
from .equations import CHANNELS, DUMMY_HZ, mck, blocks as blocks_of, static_corner_loads
from .params import (GRAVITY, INDEX, POWERTRAIN_NAMES, ROW_WIDTHS, SUSPENSION_NAMES, Geometry, check_parameters,
                     full_rows, has_powertrain)
from .nl_coef import CI, COEF, hermite_value_slope
from .simulate import RunInput

#: Default damper velocity knots (m/s), SPEC §8.
DEFAULT_KNOTS: tuple[float, ...] = (-0.4, -0.2, -0.1, -0.05, -0.025, 0.025, 0.05, 0.1, 0.2, 0.4)
#: The powertrain's states (SPEC §11) after the car's fourteen: its heave and pitch relative to the body
#: (:data:`rideid.model.equations.POWERTRAIN_COORDS`), then their rates
POWERTRAIN_STATES: tuple[str, ...] = ("u_p", "psi_p", "u_p'", "psi_p'")
#: Bump-stop columns (after the sixteen): clearance m of compression from static, rate N/m.
BUMP_STOP_NAMES: tuple[str, ...] = ("bs_clear_f", "bs_clear_r", "bs_rate_f", "bs_rate_r")
#: Largest ``h_sub * max|eig|`` of the RK4 sub-step (accuracy, not stability: RK4 is stable to 2.8).
RHO_MAX = 0.2
#: Most sub-steps per sample.
M_MAX = 4096
#: Gauss panels (two nodes each) per sub-step for the mean road input
QUAD_PANELS = 16


def curve_names(n_knots: int) -> tuple[str, ...]:
    """Column names of the curve forces: ``F_f1..F_fK`` then ``F_r1..F_rK``."""
    return tuple(f"F_f{j + 1}" for j in range(n_knots)) + tuple(f"F_r{j + 1}" for j in range(n_knots))


@dataclass(frozen=True)
class NonlinearLayout:
    """Columns of a nonlinear parameter row.

    ``knots``: damper velocity knots (m/s, strictly increasing, nonzero;
    ``None``: linear dampers ``c_sf``, ``c_sr``); ``bump_stops``: the four
    :data:`BUMP_STOP_NAMES` columns are present; ``powertrain``: the car
    carries a powertrain on mounts (SPEC §11, the seven
    :data:`rideid.model.params.POWERTRAIN_NAMES`; a row with ``m_p = 0``
    has none). Rows are the sixteen
    :data:`rideid.model.params.SUSPENSION_NAMES`, with a powertrain its
    seven (the columns of :data:`rideid.model.params.ALL_NAMES`), then the
    bump stops, then the front and rear curve forces (:func:`curve_names`).
    """

    knots: tuple | None = None
    bump_stops: bool = False
    powertrain: bool = False

    def __post_init__(self):
        if self.knots is not None:
            k = tuple(float(v) for v in self.knots)
            if (len(k) < 1 or not all(math.isfinite(v) and v != 0 for v in k)
                    or any(b <= a for a, b in zip(k, k[1:]))):
                raise DataError(f"damper knots must be finite, nonzero and strictly increasing (m/s), got {k}")
            object.__setattr__(self, "knots", k)
        object.__setattr__(self, "bump_stops", bool(self.bump_stops))
        object.__setattr__(self, "powertrain", bool(self.powertrain))

    @property
    def n_knots(self) -> int:
        return 0 if self.knots is None else len(self.knots)

    @property
    def n_car(self) -> int:
        """The car's columns, 16 (:data:`rideid.model.params.SUSPENSION_NAMES`) or 23 with a powertrain (then
        the columns of :data:`rideid.model.params.ALL_NAMES`)."""
        return len(SUSPENSION_NAMES) + (len(POWERTRAIN_NAMES) if self.powertrain else 0)

    @property
    def n_states(self) -> int:
        """States of the integrator: 14, or 18 with a powertrain (:data:`POWERTRAIN_STATES` appended)."""
        return 18 if self.powertrain else 14

    @property
    def names(self) -> tuple[str, ...]:
        return (SUSPENSION_NAMES + (POWERTRAIN_NAMES if self.powertrain else ())
                + (BUMP_STOP_NAMES if self.bump_stops else ()) + curve_names(self.n_knots))

    @property
    def n_columns(self) -> int:
        return len(self.names)

    @property
    def linear(self) -> bool:
        """No curves and no bump stops: the linear model of SPEC §1/§6."""
        return self.knots is None and not self.bump_stops

    @property
    def column(self) -> dict[str, int]:
        """Name -> its column in the rows of this layout."""
        return {n: i for i, n in enumerate(self.names)}

    def curves(self, P):
        """Front and rear curve forces ``(n, K)`` each from rows ``P`` (``None`` without curves)."""
        if self.knots is None:
            return None
        P = np.atleast_2d(P)
        s = self.n_car + (4 if self.bump_stops else 0)
        K = self.n_knots
        return P[:, s:s + K], P[:, s + K:s + 2 * K]

    def rows(self, P) -> np.ndarray:
        """Rows ``P`` as a float array ``(n, n_columns)``; for a linear layout 12 columns are accepted too."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        if self.linear and P.shape[-1] in ROW_WIDTHS:
            if not self.powertrain and has_powertrain(P):
                raise DataError("parameter rows carry a powertrain on mounts (m_p > 0) but the nonlinear layout has "
                                "none: NonlinearLayout(powertrain=True)")
            return full_rows(P)[:, :self.n_car]
        if P.shape[-1] != self.n_columns:
            raise DataError(f"nonlinear parameter rows must have {self.n_columns} columns "
                            f"({', '.join(self.names)}), got {P.shape[-1]}")
        return P


def _knot_table(knots):
    """Knots with 0 inserted (K + 1,) and the position of 0."""
    k = np.asarray(knots, dtype=float)
    j0 = int(np.searchsorted(k, 0.0))
    return np.insert(k, j0, 0.0), j0


def damper_force(knots, F, v):
    """Damper force of a piecewise-linear curve through ``(0, 0)`` and ``(knots, F)``.

    Beyond the outermost knots the curve continues with the last segment's
    slope. Positive in compression (``v = z_i' - z_bi' > 0``); the force on
    the body is ``+D(v)``, on the wheel ``-D(v)``.

    Parameters
    ----------
    knots : (K,) strictly increasing, nonzero velocities, m/s
    F : (..., K) forces at the knots, N
    v : (...) velocities, m/s (broadcast against ``F[..., 0]``)

    Returns
    -------
    ndarray, the broadcast shape of ``v`` and ``F[..., 0]``
    """
    xk, j0 = _knot_table(knots)
    F = np.asarray(F, dtype=float)
    Fk = np.insert(F, j0, 0.0, axis=-1)
    v = np.asarray(v, dtype=float)
    j = np.clip(np.searchsorted(xk, v, side="right") - 1, 0, xk.size - 2)
    shape = np.broadcast_shapes(v.shape, F.shape[:-1])
    Fk = np.broadcast_to(Fk, shape + Fk.shape[-1:])
    vb, jb = np.broadcast_to(v, shape), np.broadcast_to(j, shape)
    f0 = np.take_along_axis(Fk, jb[..., None], -1)[..., 0]
    f1 = np.take_along_axis(Fk, jb[..., None] + 1, -1)[..., 0]
    x0, x1 = xk[jb], xk[jb + 1]
    return f0 + (f1 - f0) / (x1 - x0) * (vb - x0)


def linear_curve(c, knots=DEFAULT_KNOTS) -> np.ndarray:
    """Forces ``c v`` at the knots of a linear damper of rate ``c`` (N s/m): shape ``(..., K)``."""
    return np.asarray(c, dtype=float)[..., None] * np.asarray(knots, dtype=float)


def _slopes(knots, F):
    """Segment slopes ``(..., K)`` of curves ``F`` (..., K) through (0, 0)."""
    xk, j0 = _knot_table(knots)
    Fk = np.insert(np.asarray(F, dtype=float), j0, 0.0, axis=-1)
    return np.diff(Fk, axis=-1) / np.diff(xk)


# ---------------------------------------------------------------------------
# per-candidate coefficients

#: columns of the coefficient table (per candidate) used by both backends
_C4 = {n: [CI[f"{n}{k}"] for k in range(4)]
       for n in ("inv_mu", "x", "y", "ks", "cs", "kt", "ct", "L", "bs_clear", "bs_rate")}


def coefficients(P, geom: Geometry, layout: NonlinearLayout):
    """Per-candidate coefficients.

    Returns
    -------
    co : (n, len(COEF)) float
    xk : (K + 1,) knots with 0 inserted (``[0, 1]`` dummy without curves)
    Fk : (n, 2, K + 1) forces at ``xk`` per axle; Sk : (n, 2, K) segment slopes
    """
    P = layout.rows(P)
    n = P.shape[0]
    p = {nm: P[:, i] for i, nm in enumerate(layout.names)}
    h = geom.cg_height
    co = np.zeros((n, len(COEF)))
    swing = 2.0 * (p["m_uf"] + p["m_ur"]) * h * h
    co[:, CI["inv_ms"]] = 1.0 / p["m_s"]
    co[:, CI["inv_Iyy"]] = 1.0 / (p["I_yy"] + swing)
    co[:, CI["inv_Ixx"]] = 1.0 / (p["I_xx"] + swing)
    co[:, CI["topple"]] = p["m_s"] * GRAVITY * h
    co[:, CI["kar_f"]] = p["k_arf"]
    co[:, CI["kar_r"]] = p["k_arr"]
    x, y = geom.corner_xy(p["a"])
    L = static_corner_loads(P[:, :len(SUSPENSION_NAMES)], geom)

    def put(name, vals):
        for c in range(4):
            co[:, CI[f"{name}{c}"]] = vals[:, c] if np.ndim(vals) == 2 else vals[c]

    axle = lambda f, r: np.stack([f, f, r, r], -1)  # noqa: E731
    put("inv_mu", 1.0 / axle(p["m_uf"], p["m_ur"]))
    put("x", x)
    put("y", y)
    put("ks", axle(p["k_sf"], p["k_sr"]))
    put("cs", axle(p["c_sf"], p["c_sr"]))
    put("kt", axle(p["k_tf"], p["k_tr"]))
    put("ct", axle(p["c_tf"], p["c_tr"]))
    put("L", L)
    if layout.bump_stops:
        put("bs_clear", axle(p["bs_clear_f"], p["bs_clear_r"]))
        put("bs_rate", axle(p["bs_rate_f"], p["bs_rate_r"]))
    else:
        put("bs_clear", np.full((n, 4), np.inf))
    if layout.knots is None:
        xk = np.array([0.0, 1.0])
        Fk = np.zeros((n, 2, 2))
    else:
        xk, j0 = _knot_table(layout.knots)
        Ff, Fr = layout.curves(P)
        Fk = np.insert(np.stack([Ff, Fr], 1), j0, 0.0, axis=-1)
    Sk = np.diff(Fk, axis=-1) / np.diff(xk)
    if layout.powertrain:
        _powertrain_coefficients(co, p, p["I_yy"] + swing)
    return co, xk, np.ascontiguousarray(Fk), np.ascontiguousarray(Sk)


def powertrain_mass(p, I_theta) -> np.ndarray:
    """The mass matrix ``(n, 4, 4)`` over ``(z, theta, u, psi)`` of a car with a powertrain on mounts (SPEC
    §11, :func:`rideid.model.equations.mck`'s): ``p`` the columns by name, ``I_theta`` the pitch inertia (with
    the wheels' swing about a raised CG). A row without a powertrain (``m_p = 0``; or ``I_p = 0``: no pitch
    mount) gets a decoupled unit-mass dummy, as the linear car."""
    m_s, m_p, x_p, I_p = p["m_s"], p["m_p"], p["x_p"], p["I_p"]
    on_u = m_p > 0
    on_p = on_u & (I_p > 0)
    n = m_s.shape[0]
    M = np.zeros((n, 4, 4))
    M[:, 0, 0] = m_s
    M[:, 1, 1] = I_theta
    M[:, 2, 2] = np.where(on_u, m_p, 1.0)
    M[:, 3, 3] = np.where(on_p, I_p, 1.0)
    M[:, 0, 2] = M[:, 2, 0] = np.where(on_u, m_p, 0.0)
    M[:, 1, 2] = M[:, 2, 1] = np.where(on_u, -m_p * x_p, 0.0)
    M[:, 1, 3] = M[:, 3, 1] = np.where(on_p, I_p, 0.0)
    return M


def _powertrain_coefficients(co, p, I_theta):
    """In place: the powertrain's slots of ``co`` (:data:`rideid.model.nl_coef.PT_COEF`)."""
    M = powertrain_mass(p, I_theta)
    Mi = np.linalg.inv(M)
    for i in range(4):
        for j in range(i, 4):
            co[:, CI[f"pt_m{i}{j}"]] = Mi[:, i, j]
    on_u = p["m_p"] > 0
    on_p = on_u & (p["I_p"] > 0)
    for on, mass, f, zeta, k, c in ((on_u, M[:, 2, 2], p["f_pb"], p["zeta_pb"], "pt_ku", "pt_cu"),
                                    (on_p, M[:, 3, 3], p["f_pp"], p["zeta_pp"], "pt_kpsi", "pt_cpsi")):
        w = 2.0 * np.pi * np.where(on, f, DUMMY_HZ)
        co[:, CI[k]] = mass * w * w
        co[:, CI[c]] = 2.0 * np.where(on, zeta, 0.5) * mass * w


def substeps(P, geom: Geometry, layout: NonlinearLayout, h: float, rho: float = RHO_MAX) -> int:
    """Sub-steps per sample interval ``h``: ``h/m * max|eig| <= rho`` for the stiffest linearised car."""
    return int(_substeps_of(_spectral_radii(P, geom, layout).max(), h, rho))


def substeps_each(P, geom: Geometry, layout: NonlinearLayout, hs, rho: float = RHO_MAX) -> np.ndarray:
    """Each candidate's own :func:`substeps`, the largest over the sample intervals ``hs``: ``(n,)`` int (one
    batched eigenvalue problem for the population, not one per candidate)."""
    lam = _spectral_radii(P, geom, layout)
    return np.max([_substeps_of(lam, h, rho) for h in hs], axis=0)


def _substeps_of(lam, h: float, rho: float):
    return np.minimum(M_MAX, np.maximum(1, np.ceil(np.asarray(lam) * h / rho - 1e-9))).astype(np.int64)


def _spectral_radii(P, geom: Geometry, layout: NonlinearLayout) -> np.ndarray:
    """``(n,)``: the largest |eigenvalue| of each candidate's linearised car (its stiffest segments)."""
    P = layout.rows(P)
    Q = full_rows(P[:, :layout.n_car]).copy()
    if layout.bump_stops:
        ix = layout.column
        Q[:, INDEX["k_sf"]] += P[:, ix["bs_rate_f"]]
        Q[:, INDEX["k_sr"]] += P[:, ix["bs_rate_r"]]
    if layout.knots is not None:
        for (c, F) in zip(("c_sf", "c_sr"), layout.curves(P)):
            Q[:, INDEX[c]] = np.abs(_slopes(layout.knots, F)).max(axis=-1)
    Q[:, INDEX["c_sf"]] = np.maximum(Q[:, INDEX["c_sf"]], 0.0)
    Q[:, INDEX["c_sr"]] = np.maximum(Q[:, INDEX["c_sr"]], 0.0)
    bl = blocks_of(Q, geom)
    return np.maximum(np.abs(np.linalg.eigvals(bl["As"])).max(axis=-1),
                      np.abs(np.linalg.eigvals(bl["Aa"])).max(axis=-1))


def initial_state(P, geom: Geometry, layout: NonlinearLayout, u0) -> np.ndarray:
    """Static equilibrium ``(n, 14)`` (18 with a powertrain) for road input ``u0`` (4,): ``K q = Bf u0``, zero
    velocities (the mounts are decoupled in ``K``: the powertrain at rest on them, ``u = psi = 0``)."""
    P = layout.rows(P)
    n = P.shape[0]
    X = np.zeros((n, layout.n_states))
    u0 = np.asarray(u0, dtype=float)
    if np.any(u0):
        _, _, K, Bf = mck(P[:, :len(SUSPENSION_NAMES)], geom)
        X[:, :7] = np.linalg.solve(K, (Bf @ u0)[..., None])[..., 0]
    return X


# ---------------------------------------------------------------------------
# NumPy backend


def _curve_eval(xk, Fk, Sk, v):
    """Curve forces at ``v`` (n, 4); ``Fk`` (n, 2, K+1), ``Sk`` (n, 2, K)."""
    j = np.clip(np.searchsorted(xk, v, side="right") - 1, 0, xk.size - 2)  # (n, 4)
    ax = np.array([0, 0, 1, 1])
    rows = np.arange(v.shape[0])[:, None]
    return Fk[rows, ax, j] + Sk[rows, ax, j] * (v - xk[j])


def accelerations(co, xk, Fk, Sk, curves: bool, X, r, rd):
    """State derivative ``(n, 14)`` (``(n, 18)``) and generalised accelerations ``(n, 7)`` for inputs ``r``, rates
    ``rd`` (4,).

    ``X = [q, z', theta', phi', p]`` with the wheels' shifted velocities
    ``p_i = z_i' - (c_t / m_u) r_i`` (see :func:`shifted`): in contact the
    tire damper's ``c_t r'`` cancels from ``p'``, so the road's rate (which
    jumps where the envelope kinks) enters the integration only while a
    wheel is off the road, and the outputs at the samples. With a
    powertrain (18 columns) :data:`POWERTRAIN_STATES` follow: its heave
    ``u`` and pitch ``psi`` relative to the body and their rates; the
    suspension's forces and the mounts' then move ``(z, theta, u, psi)``
    through the inverse of their mass matrix (SPEC §11,
    :func:`powertrain_mass`).
    """
    def c(name):
        return co[:, _C4[name]]

    q = X[:, :7]
    ctm = c("ct") * c("inv_mu")
    w = X[:, 10:14] + ctm * r  # wheel velocities
    x, y = c("x"), c("y")
    d = suspension_travel(q, x, y)
    v = w - body_corners(X[:, 7:], x, y)
    F = c("ks") * d
    bf = co[:, CI["kar_f"]] * (d[:, 0] - d[:, 1])
    br = co[:, CI["kar_r"]] * (d[:, 2] - d[:, 3])
    F = F + np.stack([bf, -bf, br, -br], -1)
    F = F + (_curve_eval(xk, Fk, Sk, v) if curves else c("cs") * v)
    F = F + c("bs_rate") * np.maximum(d - c("bs_clear"), 0.0)
    L = c("L")
    t0 = L + c("kt") * (r - q[:, 3:]) - c("ct") * w  # tire force without the rate term
    crd = c("ct") * rd
    contact = t0 + crd >= 0.0
    dp = np.where(contact, t0 - L - F, -L - F - crd) * c("inv_mu")
    qdd = np.empty_like(q)
    topple = co[:, CI["topple"]]
    qdd[:, 2] = ((y * F).sum(-1) + topple * q[:, 2]) * co[:, CI["inv_Ixx"]]
    qdd[:, 3:] = dp + ctm * rd
    if X.shape[1] == 14:
        qdd[:, 0] = F.sum(-1) * co[:, CI["inv_ms"]]
        qdd[:, 1] = (-(x * F).sum(-1) + topple * q[:, 1]) * co[:, CI["inv_Iyy"]]
        return np.concatenate([X[:, 7:10], w, qdd[:, :3], dp], axis=1), qdd
    # the powertrain: generalised forces on (z, theta, u, psi), the mounts' on their own coordinates
    g = (F.sum(-1), -(x * F).sum(-1) + topple * q[:, 1],
         -(co[:, CI["pt_ku"]] * X[:, 14] + co[:, CI["pt_cu"]] * X[:, 16]),
         -(co[:, CI["pt_kpsi"]] * X[:, 15] + co[:, CI["pt_cpsi"]] * X[:, 17]))
    acc = [sum(co[:, CI[f"pt_m{min(i, j)}{max(i, j)}"]] * g[j] for j in range(4)) for i in range(4)]
    qdd[:, 0], qdd[:, 1] = acc[0], acc[1]
    dX = np.concatenate([X[:, 7:10], w, qdd[:, :3], dp, X[:, 16:18], acc[2][:, None], acc[3][:, None]], axis=1)
    return dX, qdd


def body_corners(q, x, y):
    """The body over the corners fl, fr, rl, rr (n, 4) (``x`` forward of the CG, ``y`` to the left, as
    :meth:`rideid.model.params.Geometry.corner_xy`) from its heave, pitch and roll in the first three
    columns of ``q`` (n, >= 3): heights, or their rates or accelerations alike."""
    return q[:, :1] - x * q[:, 1:2] + y * q[:, 2:3]


def suspension_travel(q, x, y):
    """Suspension travel (n, 4), compression +: each wheel's coordinate (columns 3-6 of ``q`` (n, 7), in
    :data:`rideid.model.equations.COORDS` order: heights, or their rates or accelerations) less the
    body's over its corner (:func:`body_corners`)."""
    return q[:, 3:7] - body_corners(q, x, y)


def travel_by_run(sim, P, a: float, rates: bool = False) -> list:
    """Per run of ``sim`` (a :class:`NonlinearSimulator`), the suspension travel (n_time, 4) of the car
    ``P`` (a row of ``sim``'s layout) whose CG is ``a`` behind the front axle: of the positions (m), or
    with ``rates`` of the velocities (m/s); compression +."""
    x, y = sim.geom.corner_xy(np.array([a]))
    lo = 7 if rates else 0
    return [suspension_travel(X[0, :, lo:lo + 7], x[0], y[0]) for _, X in sim.states(P)]


def shifted(co, X, r, back: bool = False):
    """States with wheel velocities ``z'`` -> shifted ``p = z' - (c_t/m_u) r`` (``back``: the inverse)."""
    ctm = co[:, _C4["ct"]] * co[:, _C4["inv_mu"]]
    out = X.copy()
    out[..., 10:14] += (ctm if back else -ctm) * r
    return out


def channels(co, X, qdd):
    """The ten channels ``(n, 10)`` from states and accelerations."""
    x, y = co[:, _C4["x"]], co[:, _C4["y"]]
    out = np.empty((X.shape[0], 10))
    out[:, :4] = body_corners(qdd, x, y)
    out[:, 4:8] = qdd[:, 3:]
    out[:, 8] = X[:, 8]
    out[:, 9] = X[:, 9]
    return out


def fine_inputs(run: RunInput, m: int, quad: bool = True):
    """Corner inputs and rates at ``t_k + j h / (2 m)``, ``j = 0 .. 2 m (n - 1)``: ``(U, R)`` each ``(.., 4)``.

    At the sub-steps' ends the point values; at their middles (odd ``j``), with ``quad``, the
    Simpson-consistent values (see the module's Integration section): the input such that Simpson's rule
    gives the sub-step's exact mean input, the rate such that it gives the input's exact change.
    """
    if run.inputs_at is None:
        raise DataError("the nonlinear car needs the road between the samples: prepare the run with prepare_run")
    nf = 2 * m * (run.n - 1) + 1
    tf = run.t[0] + (run.h / (2 * m)) * np.arange(nf)
    U, R = run.inputs_at(tf)
    # at the samples exactly the run's own values
    U[::2 * m], R[::2 * m] = run.u, run.rate
    if quad:
        # mid-step inputs such that Simpson's rule gives each sub-step's exact mean input
        hs = run.h / m
        nodes, weights = np.polynomial.legendre.leggauss(2)
        x = (np.arange(QUAD_PANELS)[:, None] + 0.5 * (nodes[None, :] + 1.0)).ravel() / QUAD_PANELS
        w = np.repeat(weights[None, :] * 0.5, QUAD_PANELS, 0).ravel() / QUAD_PANELS
        starts = tf[:-1:2]
        mean = np.empty((starts.size, 4))
        for lo in range(0, starts.size, 1 << 15):  # bounded memory
            t0 = starts[lo:lo + (1 << 15)]
            uq = run.inputs_only((t0[:, None] + hs * x[None, :]).ravel())
            mean[lo:lo + t0.size] = np.einsum("kqc,q->kc", uq.reshape(t0.size, x.size, 4), w)
        U[1::2] = (6.0 * mean - U[:-1:2] - U[2::2]) / 4.0
        # and mid-step rates such that Simpson's rule integrates them to the input's change
        R[1::2] = (6.0 * (U[2::2] - U[:-1:2]) / hs - R[:-1:2] - R[2::2]) / 4.0
    return np.ascontiguousarray(U), np.ascontiguousarray(R)


#: a knot is a kink where the curve's slope changes by more than this fraction of the axle's steepest slope
KINK_TOL = 1e-9


def kink_mask(Sk, tol: float = KINK_TOL) -> np.ndarray:
    """Knots of the curves that are kinks for some candidate: ``(2, K + 1)`` int, per axle, 1 where a sub-step
    crossing the knot is split (the outermost knots never are: the curves continue straight beyond them).

    One mask for the population, like the sub-step count; a knot where the slope does not change (a
    digressive curve's knots below and above its knee) costs no split. ``Sk`` (n, 2, K) segment slopes.
    """
    Sk = np.asarray(Sk, dtype=float)
    scale = np.abs(Sk).max(axis=-1, keepdims=True)
    jump = np.abs(np.diff(Sk, axis=-1)) > tol * scale  # (n, 2, K - 1), the interior knots
    out = np.zeros((2, Sk.shape[-1] + 1), dtype=np.int64)
    out[:, 1:-1] = jump.any(axis=0)
    return out


def switching(co, X, qdd, r, rd):
    """Switching quantities ``(d, v, g, vd)`` each ``(n, 4)``: deflections, damper velocities, tire loads
    ``L + k_t (r - z_i) + c_t (r' - z_i')`` and the damper velocities' rates (as the compiled kernel)."""
    x, y = co[:, _C4["x"]], co[:, _C4["y"]]
    ct = co[:, _C4["ct"]]
    w = X[:, 10:14] + ct * co[:, _C4["inv_mu"]] * r
    d = suspension_travel(X[:, :7], x, y)
    v = w - body_corners(X[:, 7:], x, y)
    t0 = co[:, _C4["L"]] + co[:, _C4["kt"]] * (r - X[:, 3:7]) - ct * w
    g = t0 + ct * rd
    vd = suspension_travel(qdd, x, y)
    return d, v, g, vd


def hermite_root(s0, s1, m0, m1):
    """Crossing ``0 <= theta <= 1`` of the cubic Hermite with values ``s0, s1`` (opposite signs) and slopes
    ``m0, m1`` (per unit ``theta``): the chord's root, then two Newton steps kept in ``[0, 1]``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = s0 / (s0 - s1)
        for _ in range(2):
            val, der = hermite_value_slope(t, s0, s1, m0, m1)
            t = np.where(der != 0.0, t - val / np.where(der != 0.0, der, 1.0), t)
            t = np.minimum(np.maximum(t, 0.0), 1.0)
    return t


def crossings(xk, clear, h, sw0, sw1, kinks=None):
    """Sorted fractions ``(n, c)`` of a sub-step where a corner's damper velocity crosses an interior knot of
    ``xk``, its deflection the bump-stop ``clear``-ance or its tire load zero (padded with 1), and their
    number ``(n,)``; ``sw0``, ``sw1``: :func:`switching` at the sub-step's ends; ``kinks`` (2, K + 1): the
    knots that are kinks per axle (:func:`kink_mask`; None: every one)."""
    d0, v0, g0, a0 = sw0
    d1, v1, g1, a1 = sw1
    cols, hits = [], []
    for j in range(1, xk.size - 1):
        kn = xk[j]
        hit = (v0 < kn) != (v1 < kn)
        if kinks is not None:
            hit = hit & (kinks[[0, 0, 1, 1], j] != 0)
        cols.append(np.where(hit, hermite_root(v0 - kn, v1 - kn, h * a0, h * a1), 1.0))
        hits.append(hit)
    with np.errstate(invalid="ignore"):
        ea, eb = d0 - clear, d1 - clear
    hit = (ea > 0.0) != (eb > 0.0)
    cols.append(np.where(hit, hermite_root(np.where(hit, ea, 1.0), np.where(hit, eb, -1.0), h * v0, h * v1), 1.0))
    hits.append(hit)
    hit = (g0 >= 0.0) != (g1 >= 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        cols.append(np.where(hit, g0 / (g0 - g1), 1.0))
    hits.append(hit)
    th = np.sort(np.concatenate(cols, axis=1), axis=1)
    return th, np.concatenate(hits, axis=1).sum(axis=1)


def inputs_within(U, R, js, tau, dt):
    """Road inputs and rates ``(k, 4)`` at fractions ``tau`` (k,) of the sub-step starting at table row ``js``
    (cubic Hermite of the inputs with their rates over the half sub-step ``dt``; rates linear)."""
    x = 2.0 * tau
    up = x >= 1.0
    i = js + up.astype(np.int64)
    s = np.where(up, x - 1.0, x)[:, None]
    om = 1.0 - s
    s2 = s * s
    u = (((1.0 + 2.0 * s) * om * om) * U[i] + (s * om * om * dt) * R[i] + (s2 * (3.0 - 2.0 * s)) * U[i + 1]
         + (s2 * (s - 1.0) * dt) * R[i + 1])
    return u, om * R[i] + s * R[i + 1]


def simulate_numpy(P, geom, run: RunInput, layout: NonlinearLayout, m: int, fine=None, return_states=False,
                   split: bool = True, kinks=None):
    """NumPy backend for one run: outputs ``(n, n_time, 10)`` (and states ``(n, n_time, 14)``, 18 with a
    powertrain)."""
    co, xk, Fk, Sk = coefficients(P, geom, layout)
    curves = layout.knots is not None
    kinks = kink_mask(Sk) if kinks is None else kinks
    U, R = fine_inputs(run, m) if fine is None else fine
    X = shifted(co, initial_state(P, geom, layout, run.u[0]), run.u[0])
    n = X.shape[0]
    hs = run.h / m
    hh = 0.5 * hs
    clear = co[:, _C4["bs_clear"]]
    y = np.empty((n, run.n, 10))
    Xs = np.empty((n, run.n, layout.n_states)) if return_states else None

    def f(X, u, ud, rows=slice(None)):
        dX, qdd = accelerations(co[rows], xk, Fk[rows], Sk[rows], curves, X, u, ud)
        return dX, qdd, switching(co[rows], X, qdd, u, ud)

    d1, qdd, sw = f(X, U[0], R[0])
    for k in range(run.n):
        j = 2 * m * k
        y[:, k] = channels(co, X, qdd)
        if return_states:
            Xs[:, k] = shifted(co, X, run.u[k], back=True)
        if k + 1 == run.n:
            break
        for s in range(m):
            js = j + 2 * s
            X0, D0, sw0 = X, d1, sw
            d2 = f(X + hh * d1, U[js + 1], R[js + 1])[0]
            d3 = f(X + hh * d2, U[js + 1], R[js + 1])[0]
            d4 = f(X + hs * d3, U[js + 2], R[js + 2])[0]
            X = X + (hs / 6) * (d1 + 2 * d2 + 2 * d3 + d4)
            d1, qdd, sw = f(X, U[js + 2], R[js + 2])
            if not split:
                continue
            th, nc = crossings(xk if curves else xk[:0], clear, hs, sw0, sw, kinks)
            rows = np.flatnonzero(nc)
            if rows.size == 0:
                continue
            # a kink inside the step: redo it in pieces that end at the crossings
            Xr = X0[rows]
            th = th[rows]
            a = np.zeros(rows.size)
            for q in range(th.shape[1] + 1):
                b = th[:, q] if q < th.shape[1] else np.ones(rows.size)
                hp = ((b - a) * hs)[:, None]
                if q == 0:
                    k1 = D0[rows]
                else:
                    k1 = f(Xr, *inputs_within(U, R, js, a, hh), rows)[0]
                um = inputs_within(U, R, js, 0.5 * (a + b), hh)
                k2 = f(Xr + (0.5 * hp) * k1, *um, rows)[0]
                k3 = f(Xr + (0.5 * hp) * k2, *um, rows)[0]
                k4 = f(Xr + hp * k3, *inputs_within(U, R, js, b, hh), rows)[0]
                Xr = Xr + (hp / 6.0) * ((k1 + 2.0 * k2 + 2.0 * k3) + k4)
                a = b
            X = X.copy()
            X[rows] = Xr
            d1, qdd, sw = f(X, U[js + 2], R[js + 2])
    return (y, Xs) if return_states else y


# ---------------------------------------------------------------------------
# the simulator


@dataclass(frozen=True, eq=False)
class Pin:
    """A floor on the nonlinear integrator, passed to an evaluation (never stored in a simulator).

    ``substeps`` (per run) is a floor on the RK4 sub-steps per sample; ``kinks`` (``(2, K + 1)``, or None)
    the knots where every sub-step is split. The polish pins both at its start (with a margin,
    :meth:`NonlinearSimulator.pin_at`), so every residual it differences is computed with the same
    integrator and the Jacobian sees no jump where the stiffest segment's count would change.
    """

    substeps: tuple[int, ...]
    kinks: np.ndarray | None = None


class NonlinearSimulator:
    """Simulate populations of nonlinear cars over fixed runs (the interface of
    :class:`rideid.model.batch.BatchSimulator`); made by :meth:`rideid.model.simulator.Simulator.bind`.

    An evaluation never changes the simulator: the sub-step floor of the polish is a :class:`Pin`
    argument, so one simulator serves many cost functions and threads at once.

    Parameters
    ----------
    geom : Geometry
    runs : list of RunInput (from :func:`rideid.model.simulate.prepare_run`)
    layout : NonlinearLayout
        Columns of the parameter rows.
    rho : float
        Bound on ``h_sub * max|eig|`` of the sub-step (:data:`RHO_MAX`; larger is faster and less
        accurate).
    split : bool
        Split the sub-steps at the kinks they cross (default); False: plain RK4 sub-steps (which then need
        a much smaller ``rho``, e.g. 0.03, for the same accuracy; kept for comparison).
    numpy : bool or None
        The NumPy backend (True), the compiled kernel (False), or as ``RIDEID_KERNEL`` says at each call
        (None, :mod:`rideid.model.backend`).
    """

    #: sub-step counts of a search population are rounded up to these (:meth:`groups`: few, large groups)
    SUBSTEP_BUCKETS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 256, 512, 1024, 4096)

    def __init__(self, geom: Geometry, runs: list[RunInput], layout: NonlinearLayout, rho: float = RHO_MAX,
                 split: bool = True, numpy: bool | None = None):
        self.rho = float(rho)
        self.split = bool(split)
        self.numpy = numpy
        self.geom = geom
        self.runs = list(runs)
        self.layout = layout
        lens = np.array([r.n for r in self.runs])
        self.run_start = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        self.n_samples = int(self.run_start[-1])
        self._fine: dict = {}
        self._fine_lock = threading.Lock()

    # -- parameter-independent tables ----------------------------------------------------
    def fine(self, ri: int, m: int):
        """Run ``ri``'s inputs at ``m`` sub-steps per sample (:func:`fine_inputs`), tabulated once (a cache
        of the prepared data, safe across threads; it never changes a result)."""
        key = (ri, m)
        with self._fine_lock:
            got = self._fine.get(key)
        if got is None:
            got = fine_inputs(self.runs[ri], m)
            with self._fine_lock:
                if len(self._fine) > 4 * max(1, len(self.runs)):
                    self._fine.clear()
                self._fine[key] = got
        return got

    def substeps(self, P, pin: Pin | None = None) -> list[int]:
        """Sub-steps per sample interval of every run for population ``P`` (the step bound once per sample
        rate), at least ``pin``'s."""
        by_h = {h: substeps(P, self.geom, self.layout, h, self.rho) for h in {r.h for r in self.runs}}
        m = [by_h[r.h] for r in self.runs]
        return m if pin is None else [max(a, b) for a, b in zip(m, pin.substeps)]

    def kinks(self, P, pin: Pin | None = None) -> np.ndarray:
        """The knots where the sub-steps are split, for population ``P`` (:func:`kink_mask`; ``pin``'s if
        it gives them)."""
        if pin is not None and pin.kinks is not None:
            return pin.kinks
        return kink_mask(coefficients(P, self.geom, self.layout)[3])

    def pin_at(self, P, margin: float = 1.5) -> Pin:
        """The :class:`Pin` of the polish's start ``P``: ``margin`` times its sub-steps, and with curves every
        interior knot split (the polish moves the curves, and a bend at a knot the start had not — a linear
        start's ``F = c v`` bends at none — must still be split: 7e-4 unsplit)."""
        m = [int(np.ceil(margin * k)) for k in self.substeps(P)]
        mask = self.kinks(P)
        mask[:, 1:-1] = 1
        return Pin(tuple(m), mask)

    def candidate_substeps(self, P) -> np.ndarray:
        """Largest sub-step count over the runs of each candidate, ``(n,)``."""
        return substeps_each(P, self.geom, self.layout, sorted({r.h for r in self.runs}), self.rho)

    def groups(self, P) -> list[np.ndarray]:
        """Indices of ``P``'s rows grouped by their bucketed sub-step count (the sub-step is set by the
        stiffest candidate of a call: a search evaluates each group in one call, so a few stiff candidates
        do not slow the rest)."""
        m = self.candidate_substeps(P)
        b = np.searchsorted(np.array(self.SUBSTEP_BUCKETS), m)
        return [np.nonzero(b == k)[0] for k in np.unique(b)]

    def _use_numpy(self) -> bool:
        return backend.runs_numpy("nonlinear", self.numpy)

    # -- backends -----------------------------------------------------------------------
    def outputs_reference(self, P, pin: Pin | None = None):
        """As :meth:`outputs`, by the NumPy backend."""
        return self._reference(P, False, pin)

    def states_reference(self, P, pin: Pin | None = None):
        """As :meth:`states`, by the NumPy backend."""
        return self._reference(P, True, pin)

    def _reference(self, P, return_states: bool, pin: Pin | None):
        P = self.layout.rows(P)
        ms = self.substeps(P, pin)
        kinks = self.kinks(P, pin)
        return [simulate_numpy(P, self.geom, r, self.layout, m, self.fine(i, m), return_states=return_states,
                               split=self.split, kinks=kinks) for i, (r, m) in enumerate(zip(self.runs, ms))]

    def errors_reference(self, P, Y, W, pin: Pin | None = None):
        outs = self.outputs_reference(P, pin)
        return _errors_of(outs, self.run_start, Y, W)

    def _compiled(self, P, mode, Y=None, W=None, pin: Pin | None = None):
        """:func:`rideid.model.kernel_nl.run` in ``mode`` (no data ``Y``, ``W``: zeros, for the modes that
        write channels or states)."""
        Y = np.zeros((self.n_samples, 10)) if Y is None else Y
        W = np.zeros((len(self.runs), 10)) if W is None else W
        P = self.layout.rows(P)
        ms = self.substeps(P, pin)
        co, xk, Fk, Sk = coefficients(P, self.geom, self.layout)
        fines = [self.fine(i, m) for i, m in enumerate(ms)]
        X0 = np.stack([shifted(co, initial_state(P, self.geom, self.layout, r.u[0]), r.u[0]) for r in self.runs])
        return backend.module("nonlinear").run(co, xk, Fk, Sk, self.layout.knots is not None, X0, self.run_start,
                             np.array([r.h for r in self.runs]), np.array(ms, dtype=np.int64), fines, Y, W, mode,
                             split=self.split, kinks=self.kinks(P, pin))

    # -- public -------------------------------------------------------------------------
    def errors(self, P, Y, W, pin: Pin | None = None):
        """Per-run weighted squared errors, shape ``(n_runs, n_pop)`` (as :meth:`BatchSimulator.errors`)."""
        Y = np.ascontiguousarray(Y, dtype=float)
        W = np.ascontiguousarray(W, dtype=float)
        if self._use_numpy():
            return self.errors_reference(P, Y, W, pin)
        return self._compiled(P, 0, Y, W, pin)[0]

    def outputs(self, P, pin: Pin | None = None):
        """Simulated channels: list over runs of ``(n_pop, n_time, 10)``."""
        if self._use_numpy():
            return self.outputs_reference(P, pin)
        out = self._compiled(P, 1, pin=pin)[1]
        return self._per_run(out)

    def states(self, P, pin: Pin | None = None):
        """Simulated channels and states: list over runs of ``((n_pop, n_time, 10), (n_pop, n_time, 14))``,
        the states ``[q, q']`` in :data:`rideid.model.equations.COORDS` order (deviations from static
        equilibrium); with a powertrain 18 wide, :data:`POWERTRAIN_STATES` appended."""
        if self._use_numpy():
            return self.states_reference(P, pin)
        _, out, X = self._compiled(P, 3, pin=pin)
        return list(zip(self._per_run(out), self._per_run(X)))

    def _per_run(self, a):
        return [a[:, s:e] for s, e in zip(self.run_start[:-1], self.run_start[1:])]


@dataclass(frozen=True)
class PinnedSimulator:
    """A bound nonlinear simulator and a :class:`Pin`, as one value: every evaluation uses that pin (for code
    that differences many rows with one integrator, e.g. the planner's sensitivities). Everything else is the
    simulator's."""

    sim: NonlinearSimulator
    pin: Pin

    def __getattr__(self, name):
        return getattr(self.sim, name)

    def errors(self, P, Y, W, pin: Pin | None = None):
        return self.sim.errors(P, Y, W, self.pin if pin is None else pin)

    def outputs(self, P, pin: Pin | None = None):
        return self.sim.outputs(P, self.pin if pin is None else pin)

    def states(self, P, pin: Pin | None = None):
        return self.sim.states(P, self.pin if pin is None else pin)


def _errors_of(outs, run_start, Y, W):
    err = np.empty((len(outs), outs[0].shape[0] if outs else 0))
    for ri, (s, e) in enumerate(zip(run_start[:-1], run_start[1:])):
        d = outs[ri] - Y[None, s:e]
        err[ri] = np.einsum("ntq,q->n", d * d, W[ri])
    return err


def check_nonlinear(P, geom: Geometry, layout: NonlinearLayout, where: str = "parameters") -> np.ndarray:
    """Validate rows: the sixteen (23 with a powertrain) as :func:`rideid.model.params.check_parameters`
    (``c_sf``, ``c_sr`` unused with curves), bump stops ``>= 0``, curve forces finite."""
    P = layout.rows(P)
    base = P[:, :layout.n_car].copy()
    if layout.knots is not None:
        base[:, [INDEX["c_sf"], INDEX["c_sr"]]] = 1.0
    check_parameters(base, geom, where)
    for i, nm in enumerate(layout.names[layout.n_car:], start=layout.n_car):
        col = P[:, i]
        if not np.all(np.isfinite(col)):
            raise DataError(f"{where}: {nm} is not finite")
        if nm in BUMP_STOP_NAMES and np.any(col < 0):
            raise DataError(f"{where}: {nm} must not be negative, got {col.min():g}")
    return P


def simulate_nonlinear(P, geom: Geometry, run: RunInput, layout: NonlinearLayout | None,
                       return_states: bool = False):
    """Outputs of the nonlinear car for one run (as :func:`rideid.model.simulate.simulate_reference`).

    Parameters
    ----------
    P : (n_pop, layout.n_columns) or (n_columns,)
    geom : Geometry
    run : RunInput
    layout : NonlinearLayout (``None``: linear dampers, no bump stops, a powertrain if a row has one; the
        tires may still lift)

    Returns
    -------
    y : (n_pop, n_time, 10) in :data:`rideid.model.equations.CHANNELS` order
    states : (n_pop, n_time, 14) ``[q, q']`` in :data:`rideid.model.equations.COORDS`
        order (deviations from static equilibrium), only with ``return_states``; with a powertrain
        (n_pop, n_time, 18), :data:`POWERTRAIN_STATES` appended.
    """
    layout = NonlinearLayout(powertrain=has_powertrain(np.atleast_2d(P))) if layout is None else layout
    P = check_nonlinear(P, geom, layout)
    sim = NonlinearSimulator(geom, [run], layout)
    return sim.states(P)[0] if return_states else sim.outputs(P)[0]


__all__ = ["BUMP_STOP_NAMES", "CHANNELS", "DEFAULT_KNOTS", "NonlinearLayout", "NonlinearSimulator", "Pin",
           "POWERTRAIN_STATES", "powertrain_mass",
           "PinnedSimulator", "RHO_MAX", "curve_names", "damper_force", "kink_mask", "linear_curve",
           "simulate_nonlinear", "substeps"]
