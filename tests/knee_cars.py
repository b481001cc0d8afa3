"""Cars whose dampers bend between the default knots (SPEC §8, issue 38): smooth digressive curves.

The curve is not piecewise linear on any knots rideid fits: slope ``c1`` below the knee ``v_k``, ``c2``
above it, blended by a softplus over ``blend * v_k`` (so it bends smoothly, like a real valve opening);
rebound ``rebound`` times the compression force. ``[dampers]`` gives it to ``rideid simulate`` as a table
of 241 points 0.5 % apart in velocity (geometric from 1 mm/s to 1.5 m/s), so the simulated car's curve is
within 1e-5 of the smooth one and has no kink at any knot of the fit.
"""

from __future__ import annotations

import numpy as np

#: the velocity table of ``[dampers]`` (m/s): 120 points per side, geometric 1 mm/s .. 1.5 m/s
TABLE = np.geomspace(1e-3, 1.5, 120)


def digressive(v, c1, c2, knee, rebound=1.0, blend=0.25):
    """Force (N) of the smooth digressive damper at velocities ``v`` (m/s, compression +)."""
    v = np.asarray(v, dtype=float)
    a = blend * knee
    u = np.abs(v)
    soft = a * np.logaddexp(0.0, (u - knee) / a) - a * np.logaddexp(0.0, -knee / a)  # 0 at u = 0
    f = c1 * u - (c1 - c2) * soft
    return np.where(v < 0, -rebound * f, f)


def dampers_table(front: dict, rear: dict) -> dict:
    """``[dampers]`` of a car whose axles have :func:`digressive` curves with keyword sets ``front``, ``rear``."""
    vel = np.concatenate([-TABLE[::-1], TABLE])
    return {"velocity": vel.tolist(), "front": digressive(vel, **front).tolist(),
            "rear": digressive(vel, **rear).tolist()}


#: three cars of our own, each bending between the default knots (0.025, 0.05, 0.1, 0.2, 0.4 m/s)
CARS = {
    # the built-in car, knee 0.13 m/s, rebound 2:1
    "sedan": {"front": dict(c1=2400.0, c2=700.0, knee=0.13, rebound=2.0),
              "rear": dict(c1=2200.0, c2=650.0, knee=0.13, rebound=2.0), "truth": {}},
    # knees 0.07 / 0.16 m/s, rebound 1.6 and 2.5, anti-roll bars
    "bars": {"front": dict(c1=3000.0, c2=900.0, knee=0.07, rebound=1.6),
             "rear": dict(c1=2600.0, c2=1000.0, knee=0.16, rebound=2.5),
             "truth": {"k_arf": 9000.0, "k_arr": 4000.0}},
    # knee 0.15 m/s, rebound 3:1, bump stops at 30 mm
    "stops": {"front": dict(c1=2000.0, c2=600.0, knee=0.15, rebound=3.0),
              "rear": dict(c1=1900.0, c2=550.0, knee=0.15, rebound=3.0),
              "truth": {"bs_clear_f": 0.03, "bs_rate_f": 50e3, "bs_clear_r": 0.03, "bs_rate_r": 50e3}},
}


def scenario_doc(car: str) -> dict:
    """The built-in scenario with car ``car`` of :data:`CARS` (its dampers, and its extra truths)."""
    import rideid
    from rideid.data.schema import read_toml

    spec = CARS[car]
    doc = read_toml(rideid.default_scenario_path())
    doc["name"] = f"knees-{car}"
    doc["truth"].update(spec["truth"])
    del doc["truth"]["c_sf"], doc["truth"]["c_sr"]
    doc["dampers"] = dampers_table(spec["front"], spec["rear"])
    return doc


def curve_error(car: str | dict, dampers: dict) -> float:
    """Largest relative error of a fitted ``dampers`` block (result.json) against car ``car``'s true curve
    (a name in :data:`CARS`, or its ``{"front": ..., "rear": ...}`` keyword sets), over the excited knots."""
    spec = CARS[car] if isinstance(car, str) else car
    worst = 0.0
    for axle in ("front", "rear"):
        v = np.asarray(dampers["velocity"])
        F = np.asarray(dampers[axle]["force"])
        exc = np.asarray(dampers[axle]["excited"], dtype=bool)
        true = digressive(v, **spec[axle])
        worst = max(worst, float(np.max(np.abs(F[exc] / true[exc] - 1.0))))
    return worst
