"""The identified car as export sees it: parameters, geometry, damper curves, bump stops, error bars.

:class:`Car` is built from an identification result (:func:`car_from_result`)
or from a scenario's ``[truth]`` (:func:`car_from_scenario`, the car
``rideid simulate`` drives); the card (:mod:`rideid.exporter.card`) and the
FMU (:mod:`rideid.exporter.fmu`) are written from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ..data.schema import BUMP_NAMES, DamperCurves, read_toml
from ..data.schema.dampers import BUMP_UNITS
from ..errors import DataError
from ..model.params import ALL_NAMES, UNITS, Geometry

#: units of every name a card may list (the sixteen, the bump stops, the curve forces)
CARD_UNITS = {**UNITS, **BUMP_UNITS}


@dataclass(frozen=True)
class Car:
    """One car, ready to export.

    Attributes
    ----------
    geometry : Geometry
        Known geometry (m), ``cg_height`` included.
    values : dict
        The sixteen :data:`rideid.model.params.ALL_NAMES` (SI units; absent extensions 0).
    dampers : DamperCurves or None
        Damper curves (SPEC §8): signed knots (m/s) and the forces (N) per axle.
    bump_stops : dict
        ``bs_clear_f, bs_clear_r`` (m), ``bs_rate_f, bs_rate_r`` (N/m) when the car has bump stops, else empty.
    known : dict
        The known values the identification was anchored on (``total_mass`` in kg, ...).
    extensions : list of str
        The model groups the car was identified with (SPEC §6, §8).
    rows : list of dict
        One row per parameter for ``car.csv``: ``parameter, value, unit, std, std_robust, fixed, derived``
        (``std``/``std_robust`` NaN where none was computed).
    """

    geometry: Geometry
    values: dict
    dampers: DamperCurves | None = None
    bump_stops: dict = field(default_factory=dict)
    known: dict = field(default_factory=dict)
    extensions: list = field(default_factory=list)
    rows: list = field(default_factory=list)

    @property
    def nonlinear(self) -> bool:
        """Damper curves or bump stops: the tires then push but never pull (SPEC §8)."""
        return self.dampers is not None or bool(self.bump_stops)

    @property
    def powertrain(self) -> bool:
        """A powertrain on mounts (SPEC §11, ``m_p > 0``): the FMU's equations then have 9 DOF."""
        return self.values.get("m_p", 0.0) > 0


def _num(v) -> float:
    return math.nan if v is None else float(v)


def _geometry_of(res, where: str) -> Geometry:
    veh = getattr(res, "vehicle", None)
    if not veh:  # results written before they carried their vehicle: the dataset they name
        ds = Path(res.dataset) if res.dataset else None
        if ds is None or not (ds / "dataset.toml").is_file():
            raise DataError(f"{where}: the result carries no [vehicle] geometry and the dataset it names "
                            f"({res.dataset!r}) is not found; export needs the wheelbase and tracks")
        veh = read_toml(ds / "dataset.toml").get("vehicle", {})
    try:
        return Geometry(**{k: float(veh[k]) for k in Geometry.KEYS},
                        **{k: float(veh.get(k, d)) for k, d in Geometry.OPTIONAL_KEYS.items()})
    except (KeyError, TypeError, ValueError) as e:
        raise DataError(f"{where}: vehicle geometry incomplete ({e})") from None


def car_from_result(res, where: str = "result") -> Car:
    """The car an identification found (:class:`rideid.IdentificationResult`).

    Raises
    ------
    DataError
        When the result lacks a parameter or its geometry (naming ``where``).
    """
    missing = [n for n in ALL_NAMES[:12] if n not in res.parameters]
    if missing:
        raise DataError(f"{where}: parameter '{missing[0]}' missing")
    values = {n: float(res.parameters.get(n, 0.0)) for n in ALL_NAMES}
    dampers = None
    if res.dampers:
        d = res.dampers
        dampers = DamperCurves(tuple(float(v) for v in d["velocity"]), tuple(float(f) for f in d["front"]["force"]),
                               tuple(float(f) for f in d["rear"]["force"]))
    bumps = {}
    if res.bump_stops:
        for ax, axle in (("f", "front"), ("r", "rear")):
            rec = res.bump_stops.get(axle) or {}
            if "clearance" in rec:
                bumps[f"bs_clear_{ax}"] = float(rec["clearance"])
                bumps[f"bs_rate_{ax}"] = float(rec["rate"])
    rows = []
    for n, d in res.details.items():
        rows.append({"parameter": n, "value": float(d["value"]), "unit": d.get("unit", CARD_UNITS.get(n, "")),
                     "std": _num(d.get("std")), "std_robust": _num(d.get("std_robust")),
                     "std_total": _num(d.get("std_total", d.get("std_robust"))),
                     "fixed": bool(d.get("fixed", False)), "derived": bool(d.get("derived", False))})
    ext = list((res.model or {}).get("extensions") or [])
    return Car(_geometry_of(res, where), values, dampers, bumps, dict(res.known), ext, rows)


def car_from_scenario(sc) -> Car:
    """The car a scenario's ``[truth]`` describes (what ``rideid simulate`` drives); no error bars."""
    values = {n: float(sc.truth.get(n, 0.0)) for n in ALL_NAMES}
    bumps = {n: float(sc.truth[n]) for n in BUMP_NAMES if n in sc.truth}
    rows = [{"parameter": n, "value": v, "unit": CARD_UNITS[n], "std": math.nan, "std_robust": math.nan,
             "std_total": math.nan, "fixed": n in sc.known, "derived": False} for n, v in {**values, **bumps}.items()]
    ext = list(sc.extensions or [])
    return Car(sc.geometry, values, sc.dampers, bumps, dict(sc.known), ext, rows)


__all__ = ["Car", "car_from_result", "car_from_scenario", "CARD_UNITS"]
