"""The ride parameters, the known geometry and the built-in car.

Parameter vectors are in :data:`NAMES` order (the twelve of SPEC §1), a batch
of candidates an array of shape ``(n_pop, 12)``. The model extensions of
SPEC §6 (anti-roll bars, tire damping; groups :data:`GROUPS`) follow as
columns 12-15 (:data:`ALL_NAMES`): model functions accept rows of 12 or 16
(absent extensions are 0, :func:`full_rows`).
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
}
#: The four extension names, in column order after the twelve.
EXT_NAMES: tuple[str, ...] = tuple(n for g in GROUPS.values() for n in g)
#: All sixteen names: full parameter rows have these columns.
ALL_NAMES: tuple[str, ...] = NAMES + EXT_NAMES
#: Column of every name in a full (16-column) row; the twelve keep their columns.
INDEX = {n: i for i, n in enumerate(ALL_NAMES)}
#: Group of each extension parameter.
GROUP_OF = {n: g for g, ns in GROUPS.items() for n in ns}

UNITS = {
    "m_s": "kg", "I_xx": "kg m^2", "I_yy": "kg m^2", "a": "m",
    "m_uf": "kg", "m_ur": "kg",
    "k_sf": "N/m", "k_sr": "N/m",
    "c_sf": "N s/m", "c_sr": "N s/m",
    "k_tf": "N/m", "k_tr": "N/m",
    "k_arf": "N/m", "k_arr": "N/m",
    "c_tf": "N s/m", "c_tr": "N s/m",
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
}

#: Typical extension values for the built-in car's size (a mid-size car with
#: anti-roll bars and radial tires), scaled with the car like the rest of the
#: nominal car: the reference point of sensitivity maps when the model has the
#: extensions, never a starting guess.
NOMINAL_EXTENSIONS = {"k_arf": 12000.0, "k_arr": 6000.0, "c_tf": 150.0, "c_tr": 150.0}

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
    lo, hi = DEFAULT_BOUNDS["a"]
    out["a"] = (lo * geometry.wheelbase, hi * geometry.wheelbase)
    return out


def as_vector(values: dict[str, float], extended: bool = False) -> np.ndarray:
    """Dict of parameters -> vector in :data:`NAMES` order.

    The twelve must be present. With ``extended`` (or when the dict holds any
    extension name) the vector has all sixteen columns (:data:`ALL_NAMES`),
    absent extensions 0.
    """
    missing = [n for n in NAMES if n not in values]
    if missing:
        raise DataError(f"parameters missing: {', '.join(missing)}")
    if extended or any(n in values for n in EXT_NAMES):
        return np.array([float(values.get(n, 0.0)) for n in ALL_NAMES])
    return np.array([float(values[n]) for n in NAMES])


def full_rows(P) -> np.ndarray:
    """Parameter rows ``(n, 12)`` or ``(n, 16)`` -> ``(n, 16)``, absent extensions 0."""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    if P.shape[-1] == len(ALL_NAMES):
        return P
    if P.shape[-1] != len(NAMES):
        raise DataError(f"parameter rows must have 12 columns ({', '.join(NAMES)}) or 16 "
                        f"(then {', '.join(EXT_NAMES)}), got {P.shape[-1]}")
    return np.concatenate([P, np.zeros(P.shape[:-1] + (len(EXT_NAMES),))], axis=-1)


def check_parameters(P, geometry: Geometry, where: str = "parameters") -> np.ndarray:
    """Validate a batch of parameter rows; returns it as an ``(n, 12)`` or ``(n, 16)`` float array.

    The twelve must be positive (``0 < a < wheelbase``), the extensions non-negative.
    """
    P = np.atleast_2d(np.asarray(P, dtype=float))
    if P.shape[-1] not in (len(NAMES), len(ALL_NAMES)):
        raise DataError(f"{where}: expected 12 parameters in order {', '.join(NAMES)} "
                        f"(or 16 with {', '.join(EXT_NAMES)}), got {P.shape[-1]}")
    for i, n in enumerate(ALL_NAMES[:P.shape[-1]]):
        col = P[:, i]
        if not np.all(np.isfinite(col)):
            raise DataError(f"{where}: {n} is not finite")
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
    return P


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
        Append :data:`NOMINAL_EXTENSIONS` (16 columns, :data:`ALL_NAMES`).

    Returns
    -------
    ndarray, shape (12,) or (16,)
        At the built-in car's scale (callers that need another absolute scale
        multiply it, see :meth:`rideid.ParameterSpace.nominal`).
    """
    P = as_vector({**DEFAULT_CAR, **(NOMINAL_EXTENSIONS if extensions else {})})
    P[INDEX["a"]] *= geometry.wheelbase / DEFAULT_GEOMETRY.wheelbase
    return P
