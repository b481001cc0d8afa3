"""The ride parameters, the known geometry and the built-in car.

Parameter vectors are in :data:`NAMES` order (the twelve of SPEC §1), a batch
of candidates an array of shape ``(n_pop, 12)``. The model extensions of
SPEC §6 (anti-roll bars, tire damping) and §11 (a powertrain on mounts;
groups :data:`GROUPS`) follow as columns 12-22 (:data:`ALL_NAMES`): model
functions accept rows of 12 or 23 (absent extensions are 0, :func:`full_rows`;
a powertrain of mass 0 is no powertrain).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import DataError

#: The twelve parameter names of SPEC §1, in canonical column order.
NAMES: tuple[str, ...] = (
    "m_s", "I_xx", "I_yy", "a",
    "m_uf", "m_ur",
    "k_sf", "k_sr",
    "c_sf", "c_sr",
    "k_tf", "k_tr",
)

#: Optional extension parameters of SPEC §6 (absent means 0), by group.
GROUPS: dict[str, tuple[str, ...]] = {
    "anti_roll_bars": ("k_arf", "k_arr"),
    "tire_damping": ("c_tf", "c_tr"),
    # SPEC §11: a rigid powertrain on mounts inside the sprung mass, in bounce and pitch
    "powertrain": ("m_p", "x_p", "I_p", "f_pb", "zeta_pb", "f_pp", "zeta_pp"),
}
#: SPEC §6's groups: the ones ``--model full`` fits and ``--model auto`` weighs in its one search (the
#: powertrain is weighed after it, when the car needs more).
SUSPENSION_GROUPS: dict[str, tuple[str, ...]] = {g: GROUPS[g] for g in ("anti_roll_bars", "tire_damping")}
#: The twelve and SPEC §6's four: the parameter columns of the nonlinear car (a powertrain's seven follow them) and the
#: FMU's first sixteen parameters (a powertrain's seven follow them there).
SUSPENSION_NAMES: tuple[str, ...] = NAMES + tuple(n for ns in SUSPENSION_GROUPS.values() for n in ns)
#: The extension names, in column order after the twelve.
EXT_NAMES: tuple[str, ...] = tuple(n for g in GROUPS.values() for n in g)
#: All names: full parameter rows have these columns (23).
ALL_NAMES: tuple[str, ...] = NAMES + EXT_NAMES
#: Column of every name in a full row; the twelve keep their columns.
INDEX = {n: i for i, n in enumerate(ALL_NAMES)}
#: Group of each extension parameter.
GROUP_OF = {n: g for g, ns in GROUPS.items() for n in ns}
#: The powertrain's names (SPEC §11), :data:`GROUPS` ``["powertrain"]``.
POWERTRAIN_NAMES: tuple[str, ...] = GROUPS["powertrain"]
#: Parameters that do not scale with the car (SPEC §1's scale invariance multiplies every other one):
#: lengths, frequencies and damping ratios. None of them anchors the scale.
SCALE_FREE: tuple[str, ...] = ("a", "x_p", "f_pb", "zeta_pb", "f_pp", "zeta_pp")
#: Extension parameters that may be negative (the powertrain's position, ahead of the CG +).
SIGNED: tuple[str, ...] = ("x_p",)

UNITS = {
    "m_s": "kg", "I_xx": "kg m^2", "I_yy": "kg m^2", "a": "m",
    "m_uf": "kg", "m_ur": "kg",
    "k_sf": "N/m", "k_sr": "N/m",
    "c_sf": "N s/m", "c_sr": "N s/m",
    "k_tf": "N/m", "k_tr": "N/m",
    "k_arf": "N/m", "k_arr": "N/m",
    "c_tf": "N s/m", "c_tr": "N s/m",
    "m_p": "kg", "x_p": "m", "I_p": "kg m^2", "f_pb": "Hz", "zeta_pb": "1", "f_pp": "Hz", "zeta_pp": "1",
}

DESCRIPTIONS = {
    "m_s": "sprung mass",
    "I_xx": "sprung-mass roll inertia about its CG",
    "I_yy": "sprung-mass pitch inertia about its CG",
    "a": "CG distance behind the front axle",
    "m_uf": "unsprung mass, one front corner",
    "m_ur": "unsprung mass, one rear corner",
    "k_sf": "suspension wheel rate, one front corner",
    "k_sr": "suspension wheel rate, one rear corner",
    "c_sf": "suspension damping at the wheel, one front corner",
    "c_sr": "suspension damping at the wheel, one rear corner",
    "k_tf": "tire vertical stiffness, one front tire",
    "k_tr": "tire vertical stiffness, one rear tire",
    "k_arf": "anti-roll bar rate at the wheel, front axle",
    "k_arr": "anti-roll bar rate at the wheel, rear axle",
    "c_tf": "tire vertical damping, one front tire",
    "c_tr": "tire vertical damping, one rear tire",
    "m_p": "powertrain mass (part of m_s)",
    "x_p": "powertrain CG position ahead of the sprung-mass CG",
    "I_p": "powertrain pitch inertia about its own CG (part of I_yy)",
    "f_pb": "powertrain bounce frequency on its mounts, body held",
    "zeta_pb": "powertrain bounce damping ratio on its mounts, body held",
    "f_pp": "powertrain pitch frequency on its mounts, body held",
    "zeta_pp": "powertrain pitch damping ratio on its mounts, body held",
}

#: Anchors accepted in ``[known]`` besides the twelve names.
EXTRA_KNOWN = {"total_mass": "kg"}

#: Default search bounds: wide physical ranges for passenger cars and light
#: trucks (small city cars to 3.5 t vans). ``a`` is given as a fraction of
#: the wheelbase. Sources: typical ride frequencies 0.9–2.2 Hz, wheel hop
#: 9–16 Hz, damping ratios 0.1–0.6 (Gillespie, *Fundamentals of Vehicle
#: Dynamics*, ch. 5; Milliken & Milliken, *Race Car Vehicle Dynamics*, ch. 16).
DEFAULT_BOUNDS = {
    "m_s": (300.0, 4000.0),
    "I_xx": (50.0, 2500.0),
    "I_yy": (300.0, 8000.0),
    "a": (0.25, 0.75),  # fraction of wheelbase
    "m_uf": (15.0, 120.0), "m_ur": (15.0, 120.0),
    "k_sf": (8.0e3, 1.5e5), "k_sr": (8.0e3, 1.5e5),
    "c_sf": (300.0, 8.0e3), "c_sr": (300.0, 8.0e3),
    "k_tf": (8.0e4, 6.0e5), "k_tr": (8.0e4, 6.0e5),
    # Extensions (SPEC §6). Bar rates at the wheel: 0 (no bar) to about three
    # times a stiff wheel rate (sports cars and SUVs: 5-60 kN/m per axle).
    # Tire damping: radial tires 50-500 N s/m (Gillespie ch. 5; Pacejka,
    # *Tire and Vehicle Dynamics*, ch. 9), widened.
    "k_arf": (0.0, 1.0e5), "k_arr": (0.0, 1.0e5),
    "c_tf": (0.0, 1.5e3), "c_tr": (0.0, 1.5e3),
    # Powertrain on mounts (SPEC §11): engines and drive units 40-400 kg; position given as a fraction of
    # the wheelbase (ahead of the CG +); pitch inertia about its own CG 1-150 kg m^2 (radius of gyration
    # 0.15-0.6 m); mount frequencies with the body held 5-25 Hz in bounce and pitch (engine mounts are
    # tuned above the wheel hop's 10-15 Hz or between body and hop), damping ratios 0.02-0.5
    # (rubber 0.05-0.1, hydro mounts up to 0.3-0.5): Reimpell, *The Automotive Chassis*, ch. 5;
    # Yu, Naganathan & Dukkipati, "A literature review of automotive vehicle engine mounting systems",
    # Mech. Mach. Theory 36 (2001).
    "m_p": (40.0, 400.0), "x_p": (-0.75, 0.75),  # x_p: fraction of wheelbase
    "I_p": (1.0, 150.0),
    "f_pb": (5.0, 25.0), "zeta_pb": (0.02, 0.5), "f_pp": (5.0, 25.0), "zeta_pp": (0.02, 0.5),
}

#: Typical extension values for the built-in car's size (a mid-size car with
#: anti-roll bars and radial tires), scaled with the car like the rest of the
#: nominal car: the reference point of sensitivity maps when the model has the
#: extensions, never a starting guess.
NOMINAL_EXTENSIONS = {"k_arf": 12000.0, "k_arr": 6000.0, "c_tf": 150.0, "c_tr": 150.0,
                      # a 150 kg engine on mounts, 1.0 m ahead of the CG (at the built-in wheelbase)
                      "m_p": 150.0, "x_p": 1.0, "I_p": 10.0, "f_pb": 11.0, "zeta_pb": 0.1,
                      "f_pp": 13.0, "zeta_pp": 0.1}

#: Standard gravity (m/s^2), the one value used for static loads, the
#: MuJoCo car and the logger unit ``g`` (ISO 80000-3).
GRAVITY = 9.80665

#: total_mass = sum over these of count x mass (one body, two corners per axle).
MASS_COUNT = {"m_s": 1, "m_uf": 2, "m_ur": 2}


def total_mass(values):
    """Total mass (kg) of a car: ``m_s + 2 m_uf + 2 m_ur``.

    Parameters
    ----------
    values : dict or array_like, shape (..., len(NAMES))
        Parameters by name, or rows in :data:`NAMES` order.

    Returns
    -------
    float or ndarray, shape (...)
    """
    if isinstance(values, dict):
        return float(sum(c * float(values[n]) for n, c in MASS_COUNT.items()))
    P = np.asarray(values, dtype=float)
    return sum(c * P[..., INDEX[n]] for n, c in MASS_COUNT.items())


def column(P, name: str) -> np.ndarray:
    """The column of parameter ``name`` in rows ``P`` of shape ``(..., len(NAMES))``."""
    return np.asarray(P)[..., INDEX[name]]


@dataclass(frozen=True)
class Geometry:
    """Known geometry (m): the four tape measures (:data:`KEYS`, required and
    positive) and the optional CG height (:data:`OPTIONAL_KEYS`).

    ``cg_height`` is the sprung mass CG's height above the wheel centres
    (SPEC §8, default 0: the model of SPEC §1). When positive the model adds
    the unsprung masses' swing about the CG (``2 (m_uf + m_ur) h^2`` to
    ``I_xx`` and ``I_yy``) and gravity's toppling stiffness ``-m_s g h`` in
    pitch and roll (:func:`rideid.model.equations.mck`).
    """

    wheelbase: float
    track_front: float
    track_rear: float
    tire_radius: float
    cg_height: float = 0.0

    #: the four tape measures, required in ``[vehicle]``
    KEYS = ("wheelbase", "track_front", "track_rear", "tire_radius")
    #: optional ``[vehicle]`` keys and their defaults
    OPTIONAL_KEYS = {"cg_height": 0.0}

    def __post_init__(self):
        for k in self.KEYS:
            v = getattr(self, k)
            if not (np.isfinite(v) and v > 0):
                raise DataError(f"vehicle.{k} must be a positive number of metres, got {v!r}")
        h = self.cg_height
        try:
            ok = bool(np.isfinite(h) and h >= 0)
        except TypeError:
            ok = False
        if not ok:
            raise DataError(f"vehicle.cg_height must be a number of metres >= 0 (CG above the wheel centres), "
                            f"got {h!r}")

    @property
    def corner_y(self) -> tuple[float, float, float, float]:
        """Lateral wheel positions fl, fr, rl, rr (y left, m)."""
        hf, hr = self.track_front / 2, self.track_rear / 2
        return (hf, -hf, hr, -hr)

    @property
    def corner_x_from_front(self) -> tuple[float, float, float, float]:
        """Longitudinal wheel positions fl, fr, rl, rr relative to the front axle (x forward, m)."""
        return (0.0, 0.0, -self.wheelbase, -self.wheelbase)

    def corner_xy(self, a):
        """Corner coordinates relative to the CG.

        Parameters
        ----------
        a : array_like, shape (n,)
            CG distance behind the front axle (m).

        Returns
        -------
        x, y : ndarray, shape (n, 4)
            Longitudinal and lateral corner positions in corner order
            fl, fr, rl, rr (x forward, y left, m).
        """
        a = np.asarray(a, dtype=float)
        x = a[..., None] + np.array(self.corner_x_from_front)
        y = np.broadcast_to(np.array(self.corner_y), x.shape).copy()
        return x, y


CORNERS = ("fl", "fr", "rl", "rr")


def default_bounds(geometry: Geometry) -> dict[str, tuple[float, float]]:
    """Default search bounds with ``a`` converted to metres."""
    out = dict(DEFAULT_BOUNDS)
    for n in ("a", "x_p"):
        lo, hi = DEFAULT_BOUNDS[n]
        out[n] = (lo * geometry.wheelbase, hi * geometry.wheelbase)
    return out


def as_vector(values: dict[str, float], extended: bool = False) -> np.ndarray:
    """Dict of parameters -> vector in :data:`NAMES` order.

    The twelve must be present. With ``extended`` (or when the dict holds any
    extension name) the vector has all :data:`ALL_NAMES` columns, absent
    extensions 0.
    """
    missing = [n for n in NAMES if n not in values]
    if missing:
        raise DataError(f"parameters missing: {', '.join(missing)}")
    if extended or any(n in values for n in EXT_NAMES):
        return np.array([float(values.get(n, 0.0)) for n in ALL_NAMES])
    return np.array([float(values[n]) for n in NAMES])


def full_rows(P) -> np.ndarray:
    """Parameter rows ``(n, 12)``, ``(n, 16)`` (SPEC §6's extensions only) or ``(n, 23)`` -> ``(n, 23)``,
    absent extensions 0."""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    if P.shape[-1] == len(ALL_NAMES):
        return P
    if P.shape[-1] not in ROW_WIDTHS:
        raise DataError(f"parameter rows must have 12 columns ({', '.join(NAMES)}), 16 or {len(ALL_NAMES)} "
                        f"(then {', '.join(EXT_NAMES)}), got {P.shape[-1]}")
    return np.concatenate([P, np.zeros(P.shape[:-1] + (len(ALL_NAMES) - P.shape[-1],))], axis=-1)


#: Widths of a linear car's parameter rows: the twelve, with SPEC §6's four, with every extension.
ROW_WIDTHS = (len(NAMES), len(NAMES) + 4, len(ALL_NAMES))


def has_powertrain(P) -> bool:
    """Does any of the rows ``P`` (any width of :data:`ROW_WIDTHS`) carry a powertrain (``m_p > 0``)?"""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    return P.shape[-1] == len(ALL_NAMES) and bool(np.any(P[:, INDEX["m_p"]] > 0))


def check_parameters(P, geometry: Geometry, where: str = "parameters") -> np.ndarray:
    """Validate a batch of parameter rows; returns it as an ``(n, w)`` float array, ``w`` in :data:`ROW_WIDTHS`.

    The twelve must be positive (``0 < a < wheelbase``), the extensions
    non-negative (``x_p`` may have either sign); a powertrain must leave the
    rest of the body a positive mass and pitch inertia
    (:func:`powertrain_fits`).
    """
    P = np.atleast_2d(np.asarray(P, dtype=float))
    if P.shape[-1] not in ROW_WIDTHS:
        raise DataError(f"{where}: expected 12 parameters in order {', '.join(NAMES)} "
                        f"(or {len(ALL_NAMES)} with {', '.join(EXT_NAMES)}), got {P.shape[-1]}")
    for i, n in enumerate(ALL_NAMES[:P.shape[-1]]):
        col = P[:, i]
        if not np.all(np.isfinite(col)):
            raise DataError(f"{where}: {n} is not finite")
        if n in SIGNED:
            continue
        if n in EXT_NAMES:
            if np.any(col < 0):
                raise DataError(f"{where}: {n} must not be negative ({UNITS[n]}), got {col.min():g}")
        elif n == "a":
            if np.any(col <= 0) or np.any(col >= geometry.wheelbase):
                raise DataError(
                    f"{where}: a must satisfy 0 < a < wheelbase ({geometry.wheelbase} m), "
                    f"got {col.min():g}..{col.max():g}")
        elif np.any(col <= 0):
            raise DataError(f"{where}: {n} must be positive, got {col.min():g}")
    if has_powertrain(P):
        if not np.all(powertrain_fits(P)):
            raise DataError(f"{where}: the powertrain (m_p, x_p, I_p) must leave the rest of the sprung mass "
                            "a positive mass and pitch inertia: m_p < m_s and I_p + m_p x_p^2 m_s / (m_s - m_p) "
                            "< I_yy")
        on = P[:, INDEX["m_p"]] > 0
        for n in ("I_p", "f_pb", "f_pp"):
            if np.any(on & (P[:, INDEX[n]] <= 0)):
                raise DataError(f"{where}: {n} must be positive when the car has a powertrain (m_p > 0)")
    return P


def powertrain_fits(P) -> np.ndarray:
    """Rows whose powertrain leaves the rest of the sprung mass physical, shape ``(n,)`` bool.

    The body without the powertrain has mass ``m_s - m_p > 0`` and, about its
    own CG, the pitch inertia ``I_yy - I_p - m_p x_p^2 m_s / (m_s - m_p) > 0``
    (parallel axes: the whole CG lies between the body's and the
    powertrain's). True for rows without a powertrain.
    """
    P = full_rows(P)
    m_s, I_yy = P[:, INDEX["m_s"]], P[:, INDEX["I_yy"]]
    m_p, x_p, I_p = P[:, INDEX["m_p"]], P[:, INDEX["x_p"]], P[:, INDEX["I_p"]]
    m_b = m_s - m_p
    with np.errstate(divide="ignore", invalid="ignore"):
        I_b = I_yy - I_p - m_p * x_p * x_p * m_s / np.where(m_b > 0, m_b, 1.0)
    return (m_p <= 0) | ((m_b > 0) & (I_b > 0))


# ---------------------------------------------------------------------------
# The built-in default car: CommonRoad vehicle model 2 (BMW 320i), ride
# parameters converted to SI (CommonRoad "Vehicle Models" documentation,
# parameters_vehicle2). Tire radius 0.30 m as the paper's test vehicle.
DEFAULT_GEOMETRY = Geometry(wheelbase=1.156 + 1.423, track_front=1.387, track_rear=1.364, tire_radius=0.30)
DEFAULT_CAR = {
    "m_s": 965.7,
    "I_xx": 207.3,
    "I_yy": 1565.8,
    "a": 1.156,
    "m_uf": 31.9,
    "m_ur": 31.9,
    "k_sf": 24445.0,
    "k_sr": 19629.0,
    "c_sf": 1786.0,
    "c_sr": 1649.0,
    "k_tf": 158240.0,
    "k_tr": 158240.0,
}


def nominal_car(geometry: Geometry, extensions: bool = False) -> np.ndarray:
    """The built-in car with its CG at the same fraction of ``geometry``'s wheelbase.

    Parameters
    ----------
    geometry : Geometry
    extensions : bool
        Append :data:`NOMINAL_EXTENSIONS` (:data:`ALL_NAMES` columns).

    Returns
    -------
    ndarray, shape (12,) or (23,)
        At the built-in car's scale (callers that need another absolute scale
        multiply it, see :meth:`rideid.ParameterSpace.nominal`).
    """
    P = as_vector({**DEFAULT_CAR, **(NOMINAL_EXTENSIONS if extensions else {})})
    P[INDEX["a"]] *= geometry.wheelbase / DEFAULT_GEOMETRY.wheelbase
    if extensions:
        P[INDEX["x_p"]] *= geometry.wheelbase / DEFAULT_GEOMETRY.wheelbase
    return P
