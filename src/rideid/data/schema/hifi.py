"""The ``[hifi]`` table of a scenario: the MuJoCo car's properties beyond the twelve parameters.

The meaning of every key is in :mod:`rideid.verify.hifi` (which builds the
car from them) and docs/verification.md; this module holds the keys, their
defaults and their validation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ...errors import DataError
from ...model.params import INDEX, full_rows


@dataclass(frozen=True)
class HifiProperties:
    """What the multibody car has beyond the twelve parameters (:mod:`rideid.verify.hifi`).

    Per-axle properties are ``(front, rear)`` pairs. The defaults are the
    reduced configuration whose physics equal SPEC §1 exactly.
    """

    cg_height: float = 0.0
    wheel_inertia: tuple = (0.0, 0.0)
    damper_rebound_ratio: tuple = (1.0, 1.0)
    damper_knee_velocity: tuple = (math.inf, math.inf)
    damper_knee_ratio: tuple = (1.0, 1.0)
    bumpstop_clearance: tuple = (math.inf, math.inf)
    bumpstop_rate: tuple = (0.0, 0.0)
    tire_damping: tuple = (0.0, 0.0)

    def __post_init__(self):
        for f in fields(self):
            if f.name != "cg_height":
                v = getattr(self, f.name)
                pair = (float(v), float(v)) if np.isscalar(v) else tuple(float(x) for x in v)
                object.__setattr__(self, f.name, pair)

    @property
    def linear_dampers(self) -> bool:
        return self.damper_rebound_ratio == (1.0, 1.0) and self.damper_knee_ratio == (1.0, 1.0)

    @property
    def bumpstops(self) -> bool:
        return any(r > 0 and math.isfinite(c) for c, r in zip(self.bumpstop_clearance, self.bumpstop_rate))

    def to_table(self) -> dict:
        """The ``[hifi]`` table (keys that differ from the defaults)."""
        out, default = {}, HifiProperties()
        for f in fields(self):
            v = getattr(self, f.name)
            if v != getattr(default, f.name):
                out[f.name] = v if f.name == "cg_height" else (v[0] if v[0] == v[1] else list(v))
        return out

    def describe(self) -> str:
        t = self.to_table()
        return ", ".join(f"{k} = {v}" for k, v in t.items()) if t else "reduced configuration (the 7-DOF physics)"


HIFI_KEYS = tuple(f.name for f in fields(HifiProperties))


def parse_hifi(tab, where: str) -> HifiProperties:
    """Validate a ``[hifi]`` table; one clear line naming the key at fault."""
    if not isinstance(tab, dict):
        raise DataError(f"{where} must be a table")

    def num(v, w):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v):
            raise DataError(f"{w}: expected a number, got {v!r}")
        return float(v)

    kw = {}
    for k, v in tab.items():
        w = f"{where} {k}"
        if k not in HIFI_KEYS:
            raise DataError(f"{where}: unknown key '{k}'; allowed: {', '.join(HIFI_KEYS)}")
        if k == "cg_height":
            x = num(v, w)
            if not math.isfinite(x):
                raise DataError(f"{w}: expected a finite height in m, got {v!r}")
            kw[k] = x
            continue
        if isinstance(v, list):
            if len(v) != 2:
                raise DataError(f"{w}: expected one number or [front, rear], got {len(v)} values")
            pair = (num(v[0], w), num(v[1], w))
        else:
            x = num(v, w)
            pair = (x, x)
        need = {"bumpstop_clearance": "a positive compression travel in m (inf: none)",
                "damper_rebound_ratio": "a positive finite ratio",
                "damper_knee_velocity": "a positive velocity in m/s (inf: no knee)"}.get(
                    k, "a finite non-negative number")
        for x in pair:
            if k in ("bumpstop_clearance", "damper_knee_velocity"):
                ok = x > 0
            elif k == "damper_rebound_ratio":
                ok = 0 < x < math.inf
            else:
                ok = 0 <= x < math.inf
            if not ok:
                raise DataError(f"{w}: expected {need}, got {x!r}")
        kw[k] = pair
    return HifiProperties(**kw)


def tire_damping_of(P, hifi: HifiProperties | None, where: str = "scenario") -> tuple[float, float]:
    """Tire damping (front, rear) of the MuJoCo car: ``[truth]`` c_tf/c_tr or ``[hifi] tire_damping``, not both."""
    P = full_rows(np.asarray(P, dtype=float).reshape(-1))[0]
    truth = (float(P[INDEX["c_tf"]]), float(P[INDEX["c_tr"]]))
    hifi_td = (hifi or HifiProperties()).tire_damping
    if any(truth) and any(hifi_td):
        raise DataError(f"{where}: tire damping is given twice, as [truth] c_tf/c_tr = {truth[0]:g}/{truth[1]:g} "
                        f"and as [hifi] tire_damping = {hifi_td[0]:g}/{hifi_td[1]:g}; give it in one place")
    return truth if any(truth) else hifi_td


__all__ = ["HIFI_KEYS", "HifiProperties", "parse_hifi", "tire_damping_of"]
