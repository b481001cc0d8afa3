"""Damper curves in an identification (SPEC §8): which knots the runs excite, and the result's block.

Excitation
----------
A knot's force shapes the curve only where a suspension velocity passes the
knot before it (towards 0): the segment between them, and beyond the
outermost knot its continuation. After the global search the best car's
suspension velocities ``v_i = z_i' - z_bi'`` are simulated over every run
(the nonlinear car's states from the compiled kernel, plain RK4 sub-steps at the lift-off sub-step bound
:data:`rideid.data.scenario.LIFT_OFF_RHO`: outputs within 0.02 % of their RMS of the split sub-steps'),
and a knot of an axle counts as **excited** when at least
:data:`MIN_SAMPLES` samples of the axle's two corners over all runs go beyond
the previous knot on its side (beyond 0 for the innermost knots, which are
always kept). 20 samples at 200 Hz are 0.1 s of travel in the knot's
segment: below that the force rests on a handful of peaks and its error bar
on the noise of those few samples. A knot that is not excited is not free in
the polish nor in the uncertainty: its force continues the last excited
segment's slope (derived, reported with ``excited: false`` and no standard
error: "not excited — not a number to trust").
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..model.nonlinear import check_nonlinear, travel_by_run
from ..data.scenario import LIFT_OFF_RHO

#: samples (both corners of the axle, all runs) beyond the previous knot that make a knot excited
MIN_SAMPLES = 20
#: how the text output marks a knot no run excites
NOT_EXCITED = "not excited — not a number to trust"


def suspension_velocities_by_run(cf, P, rho: float | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Suspension velocities (m/s, compression +) of car ``P`` (a full row of ``cf.space``) on each run
    of ``cf``: per run ``(front, rear)``, the samples of the axle's two corners concatenated.

    ``rho``: the sub-step bound (:func:`rideid.model.nonlinear.substeps`) of the simulation; default the
    simulator's (sub-steps split at the kinks). With ``rho`` plain RK4 sub-steps: the report's histograms take
    the lift-off bound (:data:`rideid.data.scenario.LIFT_OFF_RHO`, within 0.02-0.3 % of the kernel's
    outputs)."""
    geom, layout = cf.space.geometry, cf.space.layout
    settings = cf.simulator.for_layout(layout) if rho is None else replace(cf.simulator, layout=layout, rho=rho,
                                                                           split=False)
    sim = settings.bind(geom, cf.sim.runs)
    v = travel_by_run(sim, check_nonlinear(P, geom, layout), P[cf.space.col["a"]], rates=True)
    return [(t[:, :2].ravel(), t[:, 2:].ravel()) for t in v]


def suspension_velocities(cf, P, rho: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Suspension velocities (m/s, compression +) of car ``P`` (a full row of ``cf.space``) over every
    run: ``(front, rear)``, the samples of both corners of each axle concatenated (``rho``: as
    :func:`suspension_velocities_by_run`)."""
    runs = suspension_velocities_by_run(cf, P, rho)
    return np.concatenate([f for f, _ in runs]), np.concatenate([r for _, r in runs])


def knot_counts(knots, v) -> np.ndarray:
    """Per knot: the samples of ``v`` beyond the previous knot on its side (beyond 0 for the innermost)."""
    knots = np.asarray(knots, dtype=float)
    j0 = int(np.searchsorted(knots, 0.0))
    out = np.zeros(knots.size, dtype=int)
    for j, k in enumerate(knots):
        if k > 0:
            prev = knots[j - 1] if j > j0 else 0.0
            out[j] = int(np.count_nonzero(v > prev))
        else:
            prev = knots[j + 1] if j + 1 < j0 else 0.0
            out[j] = int(np.count_nonzero(v < prev))
    return out


def knot_excitation(cf, P, min_samples: int = MIN_SAMPLES) -> dict:
    """Which knots the runs excite with car ``P`` (module docstring).

    Returns
    -------
    dict
        ``counts`` and ``excited`` per axle (``"front"``, ``"rear"``; lists in knot order), ``frozen``:
        the knot-force names not excited, ``rule``: the criterion in words.
    """
    knots = np.asarray(cf.space.layout.knots)
    K = knots.size
    j0 = int(np.searchsorted(knots, 0.0))
    names = cf.space.knot_names
    out = {"counts": {}, "excited": {}, "frozen": [],
           "rule": f"a knot is excited when at least {min_samples} samples (both corners of the axle, all runs, "
                   "the car of the global search) go beyond the previous knot on its side"}

    for a, (axle, v) in enumerate(zip(("front", "rear"), suspension_velocities(cf, P, rho=LIFT_OFF_RHO))):
        counts = knot_counts(knots, v)
        exc = counts >= min_samples
        exc[[j0 - 1, j0]] = True  # the innermost knots: always free (the curve needs a slope at 0)
        # beyond a knot that is not excited, none is
        for side in (range(j0, K), range(j0 - 1, -1, -1)):
            on = True
            for j in side:
                on = on and bool(exc[j])
                exc[j] = on
        out["counts"][axle] = counts.tolist()
        out["excited"][axle] = exc.tolist()
        out["frozen"] += [names[a * K + j] for j in range(K) if not exc[j]]
    return out


def dampers_block(space, P, cov_white, cov_robust, names, excitation=None) -> dict:
    """``result.json`` ``"dampers"``: velocity knots, per axle the forces, their ``std`` and ``std_robust``
    (None for knots not excited) and ``excited``.

    ``cov_white``, ``cov_robust``: covariances over ``names`` (free parameters then derived quantities).
    """
    K = space.layout.n_knots
    knot_names = space.knot_names
    frozen = set(space.frozen)

    def sd(cov, n):
        if cov is None or n in frozen or n not in names:
            return None
        v = cov[names.index(n)][names.index(n)]
        return float(np.sqrt(v)) if np.isfinite(v) and v >= 0 else None

    out = {"velocity": list(space.layout.knots), "unit": {"velocity": "m/s", "force": "N"}}
    for a, axle in enumerate(("front", "rear")):
        ns = knot_names[a * K:(a + 1) * K]
        out[axle] = {"force": [float(P[space.col[n]]) for n in ns],
                     "std": [sd(cov_white, n) for n in ns],
                     "std_robust": [sd(cov_robust, n) for n in ns],
                     "excited": [n not in frozen for n in ns]}
        if excitation is not None:
            out[axle]["samples_beyond_previous_knot"] = excitation["counts"][axle]
    if excitation is not None:
        out["excitation_rule"] = excitation["rule"]
    out["mean_slope_velocity"] = 0.1
    return out


def format_dampers(dampers: dict) -> str:
    """The curves as a compact text table: velocity, front and rear force ± 2 std_robust."""
    if not dampers:
        return ""
    lines = ["damper curves (force at the wheel, N; ± 2 std_robust; compression +)",
             f"{'v (m/s)':>8}  {'front':>22}  {'rear':>22}"]

    def cell(ax, j):
        F = ax["force"][j]
        if not ax["excited"][j]:
            return f"{F:9.0f}  (not excited)"
        s = ax["std_robust"][j]
        return f"{F:9.1f} ± {2 * s:<9.2g}" if s is not None else f"{F:9.1f}"

    for j, v in enumerate(dampers["velocity"]):
        lines.append(f"{v:8.3f}  {cell(dampers['front'], j):>22}  {cell(dampers['rear'], j):>22}")
    if not all(dampers["front"]["excited"] + dampers["rear"]["excited"]):
        lines.append(f"(not excited: no run reached the knot — {NOT_EXCITED.split(' — ')[1]})")
    return "\n".join(lines)
