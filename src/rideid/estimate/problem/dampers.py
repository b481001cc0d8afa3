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
setting ``dampers.min_samples`` samples of the axle's two corners over all runs go beyond
the previous knot on its side (beyond 0 for the innermost knots, which are
always kept). 20 samples at 200 Hz are 0.1 s of travel in the knot's
segment: below that the force rests on a handful of peaks and its error bar
on the noise of those few samples. A knot that is not excited is not free in
the polish nor in the uncertainty: its force continues the last excited
segment's slope (derived, reported with ``excited: false`` and no standard
error: "not excited — not a number to trust").

Knees found by the data
-----------------------
Nobody knows where their damper bends before testing it. Without ``[model]
damper_knots`` the curves are fitted on setting ``dampers.knee_grid`` instead of the
default knots: 0.025 m/s apart up to 0.2 m/s (where production dampers bend),
every default knot among them; the excitation rule above freezes the grid
knots no run reaches. Where each curve bends is then read off the fitted curve
(:func:`knees`): per axle and side the one break of a two-segment line
through the origin fitted to the excited knot forces, its standard error from
draws of the forces' robust covariance. A dataset's ``damper_knots`` still
wins (no grid, no second fit).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...settings import defaults, legacy_names
from ...model.nonlinear import check_nonlinear, travel_by_run
from ...data.scenario import LIFT_OFF_RHO

#: how the text output marks a knot no run excites
NOT_EXCITED = "not excited — not a number to trust"
#: what the error bars of curves fitted on the grid leave out (result.json ``dampers.grid_note``)
GRID_NOTE = ("a smooth curve is straight between the grid knots here, which moves the knot forces and the derived "
             "c_s by ~0.2 % at a knee (more than their statistical error at 1 % noise): std_robust includes that "
             "approximation error (std_grid, estimated from the fitted curve's bend); the knees' std_robust is "
             "statistical only")


def knee_rule() -> str:
    """The text of result.json ``dampers.knee_rule``, with the settings in force."""
    significance = defaults["dampers.knee_significance"]
    return ("knee: per axle and side, the break of the two-segment line through the origin (slopes below and "
            "above it) fitted by least squares to the excited knot forces; std_robust from "
            f"{defaults['dampers.knee_draws']} draws of those forces from their robust covariance; a side bends when "
            f"its slope ratio differs from 1 by more than {significance:g} std_robust (else no knee is reported); "
            "bends: the knots whose slope change per stretch of velocity is the largest of its neighbours', above "
            f"{defaults['dampers.bend_share']:g} of the side's steepest slope and {significance:g} std_robust")


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
    sim = settings.bind(geom, cf.input_runs)
    v = travel_by_run(sim, check_nonlinear(P, geom, layout), P[cf.space.col["a"]], rates=True)
    v = [t[k:] for t, k in zip(v, cf.lead)]  # a moving start's recorded samples (SPEC §9)
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


def knot_excitation(cf, P, min_samples: int | None = None) -> dict:
    """Which knots the runs excite with car ``P`` (module docstring).

    Returns
    -------
    dict
        ``counts`` and ``excited`` per axle (``"front"``, ``"rear"``; lists in knot order), ``frozen``:
        the knot-force names not excited, ``rule``: the criterion in words.
    """
    return excitation_of(cf.space, suspension_velocities(cf, P, rho=LIFT_OFF_RHO), min_samples)


def excitation_of(space, velocities, min_samples: int | None = None, by: str = "the car of the global search") -> dict:
    """:func:`knot_excitation`'s record from the suspension velocities ``(front, rear)`` (each the axle's two
    corners over all runs, any shape): simulated with a car, or measured (on unknown roads, ``by`` says which)."""
    min_samples = defaults["dampers.min_samples"] if min_samples is None else min_samples
    knots = np.asarray(space.layout.knots)
    K = knots.size
    j0 = int(np.searchsorted(knots, 0.0))
    names = space.knot_names
    out = {"counts": {}, "excited": {}, "frozen": [],
           "rule": f"a knot is excited when at least {min_samples} samples (both corners of the axle, all runs, "
                   f"{by}) go beyond the previous knot on its side"}

    for a, (axle, v) in enumerate(zip(("front", "rear"), velocities)):
        counts = knot_counts(knots, np.ravel(v))
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
    if space.damper_knots is None:
        out["knots_from"] = "default knots (SPEC §8)"
    elif space.damper_knots == defaults["dampers.knee_grid"]:
        out["knots_from"] = ("found: no [model] damper_knots, so the curves were fitted on a grid 0.025 m/s apart "
                             "to 0.2 m/s and the knees read off them (docs/dampers.md)")
        out["grid_note"] = GRID_NOTE
    else:
        out["knots_from"] = "[model] damper_knots"
    out["knees"] = knees(space, P, cov_robust, names)
    out["knee_rule"] = knee_rule()
    return out


def format_dampers(dampers: dict) -> str:
    """The curves as a compact text table: velocity, front and rear force ± 2 std_total (the budget's, SPEC §12;
    ± 2 std_robust on a block without it)."""
    if not dampers:
        return ""
    key = "std_total" if "std_total" in dampers.get("front", {}) else "std_robust"
    lines = [f"damper curves (force at the wheel, N; ± 2 {key}; compression +)",
             f"{'v (m/s)':>8}  {'front':>22}  {'rear':>22}"]

    def cell(ax, j):
        F = ax["force"][j]
        if not ax["excited"][j]:
            return f"{F:9.0f}  (not excited)"
        s = ax[key][j]
        return f"{F:9.1f} ± {2 * s:<9.2g}" if s is not None else f"{F:9.1f}"

    for j, v in enumerate(dampers["velocity"]):
        lines.append(f"{v:8.3f}  {cell(dampers['front'], j):>22}  {cell(dampers['rear'], j):>22}")
    if not all(dampers["front"]["excited"] + dampers["rear"]["excited"]):
        lines.append(f"(not excited: no run reached the knot — {NOT_EXCITED.split(' — ')[1]})")
    for axle in ("front", "rear"):
        for side in ("compression", "rebound"):
            k = ((dampers.get("knees") or {}).get(axle) or {}).get(side) or {}
            if k.get("velocity") is not None:
                s = k.get("std_robust")
                bends = ", ".join(f"{b['velocity']:+.3f}" for b in k.get("bends") or [])
                lines.append(f"knee {axle} {side}: {k['velocity']:+.4f} m/s"
                             + (f" ± {2 * s:.2g} (2 std_robust, statistical only)" if s is not None else "")
                             + f", slope above/below {k['slope_ratio']:.3f}" + (f"; bends at {bends}" if bends else ""))
    if dampers.get("knots_from", "").startswith("found"):
        lines.append(f"knots: {dampers['knots_from']}; {GRID_NOTE}")
    return "\n".join(lines)


def _two_segments(v, breaks):
    """Regressors ``(..., n, 2)`` of the two-segment line through the origin with its break at ``breaks``
    (``(...)``): ``min(v, b)`` and ``max(v - b, 0)`` at the velocities ``v`` (n,)."""
    b = np.asarray(breaks, dtype=float)[..., None]
    return np.stack([np.minimum(v, b), np.maximum(v - b, 0.0)], axis=-1)


def knee_of(v, F_draws):
    """Break velocity and slopes of the two-segment line through the origin fitted to each row of
    ``F_draws`` (values at positive, ascending ``v``; at least 3): arrays ``(knee, slope_below, slope_above)``,
    each of the rows' length.

    The break is searched on a 0.5 mm/s grid strictly inside ``(v[0], v[-1])``, then placed at the vertex
    of the parabola through the sum of squares at the best grid point and its neighbours."""
    v = np.asarray(v, dtype=float)
    F = np.atleast_2d(np.asarray(F_draws, dtype=float))
    step = 5e-4
    breaks = np.arange(v[0], v[-1], step)[1:]
    B = _two_segments(v, breaks)                                     # (breaks, n, 2)
    pinv = np.linalg.pinv(B)                                         # (breaks, 2, n)
    coef = np.einsum("bkn,dn->dbk", pinv, F)                         # (draws, breaks, 2)
    resid = F[:, None, :] - np.einsum("bnk,dbk->dbn", B, coef)
    sse = np.einsum("dbn,dbn->db", resid, resid)
    j = np.clip(np.argmin(sse, axis=1), 1, breaks.size - 2)
    rows = np.arange(F.shape[0])
    s0, s1, s2 = sse[rows, j - 1], sse[rows, j], sse[rows, j + 1]
    curv = s0 - 2 * s1 + s2
    shift = np.where(curv > 0, 0.5 * (s0 - s2) / np.where(curv > 0, curv, 1.0), 0.0)
    knee = breaks[j] + step * np.clip(shift, -1.0, 1.0)
    Bk = _two_segments(v, knee)                                      # (draws, n, 2)
    c = np.linalg.solve(np.einsum("dnk,dnl->dkl", Bk, Bk), np.einsum("dnk,dn->dk", Bk, F)[..., None])[..., 0]
    return knee, c[:, 0], c[:, 1]


def bends_of(v, F, cov=None) -> list:
    """The knots where a side's curve bends: ``[{"velocity", "slope_change", "std_robust"}, ...]`` for each
    interior knot (``v`` positive ascending, ``F`` the forces there, through the origin) whose change of
    slope over its stretch (half the span to its neighbours) is the largest of its neighbours', and whose
    change is larger than setting ``dampers.bend_share`` of the steepest slope and than setting
    ``dampers.knee_significance`` of
    its std_robust (from ``cov``, the forces' covariance; None: not tested). Several bends (a valve that
    opens in stages) are each listed; a smooth bend shows at one knot or two close together."""
    v = np.asarray(v, dtype=float)
    n = v.size
    if n < 3:
        return []
    u = np.concatenate([[0.0], v])
    D = np.zeros((n, n))  # slopes of the n segments from the forces: s = D F
    for i in range(n):
        D[i, i] = 1.0 / (u[i + 1] - u[i])
        if i:
            D[i, i - 1] = -1.0 / (u[i + 1] - u[i])
    A = np.diff(D, axis=0)  # (n - 1, n): slope change at knots 1 .. n-1 (0-based: v[0] .. v[n-2])
    dS = A @ np.asarray(F, dtype=float)
    sd = np.sqrt(np.clip(np.diag(A @ cov @ A.T), 0, None)) if cov is not None else np.full(n - 1, np.nan)
    steepest = float(np.max(np.abs(D @ np.asarray(F, dtype=float))))
    # neighbours compared by curvature (slope change over the knot's stretch): where the knots spread out
    # (0.2 -> 0.3 m/s) a smooth bend's slope change grows with the stretch, not with the bending
    curv = np.abs(dS) / (0.5 * (u[2:] - u[:-2]))
    out = []
    for i in range(n - 1):
        size = abs(dS[i])
        local = all(curv[i] >= curv[j] for j in (i - 1, i + 1) if 0 <= j < n - 1)
        significant = cov is None or size > defaults["dampers.knee_significance"] * sd[i]
        if local and significant and size > defaults["dampers.bend_share"] * steepest:
            out.append({"velocity": float(v[i]), "slope_change": float(dS[i]),
                        "std_robust": None if cov is None else float(sd[i])})
    return out


def knees(space, P, cov_robust, names, excitation=None) -> dict:
    """result.json ``dampers.knees``: per axle (``front``, ``rear``) and side (``compression``, ``rebound``)
    where the fitted curve bends (:func:`knee_of` on the excited knot forces of full row ``P``) with its
    ``std_robust`` from draws of those forces (covariance ``cov_robust`` over ``names``; rule: :func:`knee_rule`).

    A side with fewer than 3 excited knots, or whose slope ratio does not differ from 1 by more than
    setting ``dampers.knee_significance`` std_robust, has ``velocity`` None (no bend the data can place)."""
    knots = np.asarray(space.layout.knots)
    K = knots.size
    j0 = int(np.searchsorted(knots, 0.0))
    frozen = set(space.frozen)
    rng = np.random.default_rng(defaults["dampers.knee_seed"])
    out = {}
    for a, axle in enumerate(("front", "rear")):
        ns = space.knot_names[a * K:(a + 1) * K]
        out[axle] = {}
        for side, idx in (("compression", list(range(j0, K))), ("rebound", list(range(j0 - 1, -1, -1)))):
            idx = [j for j in idx if ns[j] not in frozen]
            entry = {"velocity": None, "std_robust": None, "bends": [], "slope_below": None, "slope_above": None,
                     "slope_ratio": None, "slope_ratio_std_robust": None, "excited_knots": len(idx)}
            out[axle][side] = entry
            if len(idx) < 3:
                entry["note"] = "fewer than 3 excited knots: no knee can be placed"
                continue
            v = np.abs(knots[idx])
            F = np.abs(np.array([P[space.col[ns[j]]] for j in idx]))
            draws, C = F[None, :], None
            if cov_robust is not None and all(ns[j] in names for j in idx):
                sel = [names.index(ns[j]) for j in idx]
                C = np.asarray(cov_robust, dtype=float)[np.ix_(sel, sel)]
                if not np.all(np.isfinite(C)):
                    C = None
                else:
                    draws = np.vstack([F, rng.multivariate_normal(np.zeros(len(idx)), C, defaults["dampers.knee_draws"],
                                                                  method="eigh") + F])
            sign = 1.0 if side == "compression" else -1.0
            entry["bends"] = [dict(b, velocity=sign * b["velocity"]) for b in bends_of(v, F, C)]
            kv, c1, c2 = knee_of(v, draws)
            ratio = c2 / c1
            s_k = float(np.std(kv[1:])) if kv.size > 1 else None
            s_r = float(np.std(ratio[1:])) if kv.size > 1 else None
            entry.update(slope_below=float(c1[0]), slope_above=float(c2[0]), slope_ratio=float(ratio[0]),
                         slope_ratio_std_robust=s_r)
            if s_r is not None and abs(ratio[0] - 1.0) > defaults["dampers.knee_significance"] * s_r:
                entry.update(velocity=float(kv[0]) * (1 if side == "compression" else -1), std_robust=s_k)
            else:
                entry["note"] = "no significant bend: the curve is straight within its error bars"
    return out


def grid_std(space, P) -> dict:
    """The approximation error of curves fitted on setting ``dampers.knee_grid``, as a standard error per excited knot
    force and for the derived ``c_sf``, ``c_sr`` (name -> N or N s/m) of full row ``P``.

    A smooth curve is straight between the knots here: the least-squares line through a stretch of local
    curvature ``f''`` and knots ``h`` apart sits about ``h^2 |f''| / 12`` off the curve (the mean of the
    chord's sag ``h^2 |f''| / 8`` over the segment, two thirds of it). ``f''`` is read off the fitted forces
    (second divided differences over the excited knots and the origin; the outermost knot takes its
    neighbour's); ``c_s`` (linear in the forces) adds its knots' terms with one sign (a curve that bends
    one way moves them alike)."""
    knots = np.asarray(space.layout.knots)
    K = knots.size
    j0 = int(np.searchsorted(knots, 0.0))
    frozen = set(space.frozen)
    out = {}
    for a, cname in enumerate(("c_sf", "c_sr")):
        ns = space.knot_names[a * K:(a + 1) * K]
        s_knot = np.zeros(K)
        for side in (list(range(j0, K)), list(range(j0 - 1, -1, -1))):
            idx = [j for j in side if ns[j] not in frozen]
            u = np.concatenate([[0.0], np.abs(knots[idx])])
            G = np.concatenate([[0.0], np.abs([P[space.col[ns[j]]] for j in idx])])
            s = np.zeros(len(idx))
            for i in range(1, len(idx)):
                hm, hp = u[i] - u[i - 1], u[i + 1] - u[i]
                f2 = 2 * ((G[i + 1] - G[i]) / hp - (G[i] - G[i - 1]) / hm) / (hm + hp)
                s[i - 1] = abs(f2) * (0.5 * (hm + hp)) ** 2 / 12
            if len(idx) > 1:
                s[-1] = s[-2]
            s_knot[idx] = s
        for j in range(K):
            if ns[j] not in frozen:
                out[ns[j]] = float(s_knot[j])
        out[cname] = float(np.abs(space._slope_w) @ s_knot)
    return out


def add_grid_std(details: dict, dampers: dict, space, P) -> None:
    """In place: :func:`grid_std` combined in quadrature into ``std_robust`` of the knot forces and ``c_sf``,
    ``c_sr`` in ``details`` (result.json ``parameters``) and ``dampers``; each keeps its term as ``std_grid``."""
    add_std_term(details, dampers, space, grid_std(space, P), "std_grid")


def add_std_term(details: dict, dampers: dict, space, term: dict, key: str) -> None:
    """In place: ``term`` (name -> a standard error) combined in quadrature into ``std_robust`` of its parameters in
    ``details`` and of the knot forces in ``dampers``; each keeps its term as ``key``."""
    for n, s in term.items():
        e = details.get(n)
        if e is not None and e.get("std_robust") is not None:
            e[key] = s
            e["std_robust"] = float(np.hypot(e["std_robust"], s))
    K = space.layout.n_knots
    if not K:
        return
    for a, axle in enumerate(("front", "rear")):
        ns = space.knot_names[a * K:(a + 1) * K]
        d = dampers[axle]
        d[key] = [term.get(n) for n in ns]
        d["std_robust"] = [None if sr is None or term.get(n) is None else float(np.hypot(sr, term[n]))
                           for sr, n in zip(d["std_robust"], ns)]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "KNEE_RULE": knee_rule,
    "MIN_SAMPLES": "dampers.min_samples", "KNEE_GRID": "dampers.knee_grid", "KNEE_DRAWS": "dampers.knee_draws",
    "KNEE_SEED": "dampers.knee_seed", "KNEE_SIGNIFICANCE": "dampers.knee_significance", "BEND_SHARE":
    "dampers.bend_share"})
