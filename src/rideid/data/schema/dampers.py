"""The nonlinear suspension of SPEC §8 in files: ``[dampers]``, the bump-stop truths, ``[model] damper_knots``.

A scenario's ``[dampers]`` table gives the car real dampers: one
force-velocity curve per axle, piecewise linear through (0, 0) and through
the given points, continued beyond the outermost points with the last
segment's slope (:func:`rideid.model.nonlinear.damper_force`)::

    [dampers]
    velocity = [-0.4, -0.15, -0.05, 0.05, 0.15, 0.4]    # m/s, compression positive
    front    = [-2400, -1500, -500, 250, 750, 1200]     # N, at those velocities
    rear     = [-2200, -1400, -460, 230, 690, 1100]

Rules (each broken one is one :class:`rideid.DataError` naming the file and
the key):

* ``velocity`` strictly increasing, with at least one negative (rebound) and
  one positive (compression) value: a curve describes both directions.
  ``0`` may appear only with force 0 in both curves (the curve passes
  through the origin anyway; the point is dropped).
* ``front`` and ``rear`` as long as ``velocity``, never decreasing as the
  velocity increases (through the origin too): a damper force has the sign
  of the velocity and never pushes along the motion. Flat segments (a
  blow-off valve) are allowed.

Bump stops (``[truth]``): ``bs_clear_f``/``bs_clear_r`` (m of compression
from static ride height, > 0) and ``bs_rate_f``/``bs_rate_r`` (N/m beyond it,
>= 0), an axle's clearance and rate both or neither (an axle without them
has no stop).

``[model] damper_knots`` (a dataset's or a scenario's): positive, strictly
increasing velocities (m/s), used in compression and rebound alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import DataError
from .common import checked_items, number

#: the bump-stop names of SPEC §8, in the nonlinear simulator's row order
BUMP_NAMES: tuple[str, ...] = ("bs_clear_f", "bs_clear_r", "bs_rate_f", "bs_rate_r")
BUMP_UNITS = {"bs_clear_f": "m", "bs_clear_r": "m", "bs_rate_f": "N/m", "bs_rate_r": "N/m"}
#: the model groups of SPEC §8 (nonlinear: not columns of the linear parameter rows)
NONLINEAR_GROUPS: tuple[str, ...] = ("damper_curves", "bump_stops")
#: SPEC §8 default knots (m/s), used in compression and rebound
DEFAULT_DAMPER_KNOTS: tuple[float, ...] = (0.025, 0.05, 0.1, 0.2, 0.4)
DAMPER_KEYS = ("velocity", "front", "rear")


@dataclass(frozen=True)
class DamperCurves:
    """One damper force-velocity curve per axle (SPEC §8), at the wheel, compression positive.

    ``velocity``: the signed knots (m/s), strictly increasing, without 0;
    ``front``/``rear``: the forces there (N). The curve passes through
    (0, 0) and continues beyond the outermost knots with the last slope.
    """

    velocity: tuple
    front: tuple
    rear: tuple

    def __post_init__(self):
        for k in DAMPER_KEYS:
            object.__setattr__(self, k, tuple(float(x) for x in getattr(self, k)))

    def curve(self, axle: str) -> tuple:
        """``front`` (axle "f" or "front") or ``rear``."""
        return self.front if axle in ("f", "front", 0) else self.rear

    def force(self, axle: str, v: float) -> float:
        """The axle's force (N) at suspension velocity ``v`` (m/s): the curve of SPEC §8."""
        return _interp(v, self.velocity, self.curve(axle))

    def slope_between(self, axle: str, v: float = 0.1) -> float:
        """Mean slope (N s/m) of an axle's curve between -v and +v (SPEC §8: the linear user's c_s)."""
        return (_interp(v, self.velocity, self.curve(axle)) - _interp(-v, self.velocity, self.curve(axle))) / (2 * v)

    def to_table(self) -> dict:
        """The ``[dampers]`` table."""
        return {"velocity": list(self.velocity), "front": list(self.front), "rear": list(self.rear)}


def _interp(v, knots, forces):
    """The curve of SPEC §8 at one velocity (plain Python; the vectorised one is the kernel's)."""
    xs = list(knots)
    fs = list(forces)
    # insert the origin
    k = sum(1 for x in xs if x < 0)
    xs.insert(k, 0.0)
    fs.insert(k, 0.0)
    if v <= xs[0]:
        i = 0
    elif v >= xs[-1]:
        i = len(xs) - 2
    else:
        i = max(j for j in range(len(xs) - 1) if xs[j] <= v)
    return fs[i] + (fs[i + 1] - fs[i]) * (v - xs[i]) / (xs[i + 1] - xs[i])


def _numbers(v, where: str) -> list[float]:
    if not isinstance(v, list) or not v:
        raise DataError(f"{where}: expected a list of numbers")
    return [number(x, f"{where}[{i}]") for i, x in enumerate(v)]


def parse_dampers(tab, where: str) -> DamperCurves:
    """Validate a ``[dampers]`` table (``where``: e.g. ``"scenario.toml: [dampers]"``)."""
    checked_items(tab, where, DAMPER_KEYS, " with velocity, front and rear")
    for k in DAMPER_KEYS:
        if k not in tab:
            raise DataError(f"{where}: missing key '{k}' (velocity in m/s, front and rear forces in N)")
    vel = _numbers(tab["velocity"], f"{where} velocity")
    for i in range(1, len(vel)):
        if not vel[i] > vel[i - 1]:
            raise DataError(f"{where} velocity must be strictly increasing (index {i}: {vel[i]:g} <= {vel[i - 1]:g})")
    if not (vel[0] < 0 < vel[-1]):
        raise DataError(f"{where} velocity must reach both rebound and compression: at least one negative and "
                        f"one positive velocity (m/s, compression positive), got {vel[0]:g} .. {vel[-1]:g}")
    curves = {}
    for k in ("front", "rear"):
        f = _numbers(tab[k], f"{where} {k}")
        if len(f) != len(vel):
            raise DataError(f"{where} {k} has {len(f)} forces but velocity has {len(vel)} values; "
                            "give one force per velocity")
        for i, (v, x) in enumerate(zip(vel, f)):
            if v == 0 and x != 0:
                raise DataError(f"{where} {k}[{i}] = {x:g} N at velocity 0: a damper carries no force at rest "
                                "(the curve passes through (0, 0); leave 0 out or give force 0)")
            if x * v < 0:
                raise DataError(f"{where} {k}[{i}] = {x:g} N at velocity {v:g} m/s: a damper force has the sign "
                                "of the velocity (it never pushes along the motion)")
        for i in range(1, len(f)):
            if f[i] < f[i - 1]:
                raise DataError(f"{where} {k} must increase with velocity (index {i}: {f[i]:g} < {f[i - 1]:g})")
        curves[k] = f
    keep = [i for i, v in enumerate(vel) if v != 0]
    return DamperCurves(tuple(vel[i] for i in keep), tuple(curves["front"][i] for i in keep),
                        tuple(curves["rear"][i] for i in keep))


def parse_bump_stops(tab: dict, where: str) -> dict[str, float]:
    """The bump-stop names of a ``[truth]`` table, validated: clearance > 0 (m), rate >= 0 (N/m), per axle both or
    neither."""
    out = {}
    for ax, axle in (("f", "front"), ("r", "rear")):
        c, r = f"bs_clear_{ax}", f"bs_rate_{ax}"
        if (c in tab) != (r in tab):
            have, miss = (c, r) if c in tab else (r, c)
            raise DataError(f"{where}: {have} is given without {miss}; a {axle} bump stop needs its clearance "
                            "(m of compression from static ride height) and its rate (N/m)")
        if c not in tab:
            continue
        clear = number(tab[c], f"{where} {c}")
        if not clear > 0:
            raise DataError(f"{where} {c}: the clearance must be positive (m of compression from static ride "
                            f"height), got {clear:g}")
        rate = number(tab[r], f"{where} {r}")
        if rate < 0:
            raise DataError(f"{where} {r}: the rate must not be negative (N/m), got {rate:g}")
        out[c], out[r] = clear, rate
    return out


def parse_damper_knots(v, where: str) -> tuple[float, ...]:
    """``[model] damper_knots``: positive, strictly increasing velocities (m/s)."""
    knots = _numbers(v, where)
    for i, k in enumerate(knots):
        if not k > 0:
            raise DataError(f"{where}[{i}] = {k:g}: knots are positive velocities (m/s), used in compression "
                            "and rebound alike")
        if i and not k > knots[i - 1]:
            raise DataError(f"{where} must be strictly increasing (index {i}: {k:g} <= {knots[i - 1]:g})")
    return tuple(knots)


def bump_stop_pairs(values: dict) -> tuple[tuple[float, float], tuple[float, float]]:
    """``((clear_f, clear_r), (rate_f, rate_r))`` of a truth; an axle without a stop: ``(inf, 0)``."""
    clear = tuple(float(values.get(f"bs_clear_{a}", math.inf)) for a in "fr")
    rate = tuple(float(values.get(f"bs_rate_{a}", 0.0)) for a in "fr")
    return clear, rate


__all__ = ["BUMP_NAMES", "BUMP_UNITS", "DAMPER_KEYS", "DEFAULT_DAMPER_KNOTS", "DamperCurves", "NONLINEAR_GROUPS",
           "bump_stop_pairs", "parse_bump_stops", "parse_damper_knots", "parse_dampers"]
