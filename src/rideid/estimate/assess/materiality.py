"""Does the structure in the residuals matter? (SPEC §12 materiality)

The adequacy test (:mod:`rideid.estimate.assess.adequacy`) asks whether the road
input explains part of a residual. With long, clean records it always will
somewhere on a real car (large-angle kinematics on an 80 mm twist, a
bushing's stiffening), and what a user needs to know is whether that
structure moves the numbers. So when pairs are flagged, rideid fits the
car again **without the flagged run/channel pairs** (their weights set to
0, the starts and distance corrections as identified, the same polish) and
compares each estimate with the fit on every pair, both polished with
fixed starts so that only the left-out data differ:

``shift_i = |x_i(without) - x_i(all)| / std_total_i``

(``std_total`` where the result has it, else ``std_robust``). The model is
adequate when the largest shift is at most setting ``materiality.material_shift``: what
the model misses in those pairs moves no estimate by more than its error
bar. It is not adequate when a shift is larger, when the pairs left out
leave a parameter undetermined (the flagged data were all that measured
it), or when structure is in more than setting ``materiality.max_share`` of the pairs
(then there is no clean remainder to compare with: the model misses
something everywhere).

Why leave the flagged pairs out rather than compare run subsets: a
run subset changes the estimate by its own noise as well (a run that
carries most of a parameter's information moves it by more than its error
bar with no model error at all), while leaving out the pairs the test
flagged isolates exactly the structure the test found. The price: one
polish on the reduced data and one on all of it, from the identified car
(a few seconds on the built-in car), the two side by side on two cores.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...model.batch import single_threaded_blas, thread_map
from ...profiling import stage
from ...settings import defaults, legacy_names
from ..fit.budget import fit_cost
from ..fit.polish import polish_fixed_starts


METHOD = ("refit without the flagged run/channel pairs (weights 0; starts and distance corrections as identified; "
          "both fits polished from the identified car with fixed starts); shift = |difference| / std_total "
          "(std_robust where no std_total); immaterial when every shift is at most {:g}")  # materiality.material_shift


def flagged_pairs(adequacy: dict) -> list[tuple[str, str]]:
    """The (run, channel) pairs whose residual carries road-driven structure."""
    return [(rid, ch) for rid, rec in (adequacy.get("runs") or {}).items()
            for ch, f in rec.items() if f.get("structure")]


def _error_bar(detail: dict) -> float | None:
    for key in ("std_total", "std_robust"):
        v = detail.get(key)
        if v is not None and np.isfinite(v) and v > 0:
            return float(v)
    return None


def weigh(cf, x, details: dict, adequacy: dict, polish) -> dict:
    """The materiality record of a fit with flagged pairs.

    Parameters
    ----------
    cf : CostFunction
        The identified model on the data as identified (starts settled).
    x : array (d,)
        The identified free parameters (``cf.names`` order).
    details : dict
        The result's ``details`` (their ``std_total`` / ``std_robust``).
    adequacy : dict
        The residual test's record (:func:`rideid.estimate.assess.adequacy.assess`) with structure.
    polish : callable
        ``polish(cf, x0) -> (x, std)``: the least-squares polish with fixed starts.

    Returns
    -------
    dict
        ``material`` (bool), ``method``, ``pairs_left_out``, ``largest_shift`` (``parameter``,
        ``in_std_total``, ``value_all``, ``value_without``), ``shifts`` (parameter -> shift in std_total),
        ``reason`` (a sentence).
    """
    pairs = flagged_pairs(adequacy)
    n_pairs = sum(len(rec) for rec in (adequacy.get("runs") or {}).values())
    shift = defaults["materiality.material_shift"]
    out = {"method": METHOD.format(shift), "pairs_left_out": [f"{r}/{c}" for r, c in pairs], "threshold": shift}
    if len(pairs) > defaults["materiality.max_share"] * n_pairs:
        return {**out, "material": True, "largest_shift": None, "shifts": {},
                "reason": f"structure in {len(pairs)} of {n_pairs} run/channel pairs, more than "
                          f"{defaults['materiality.max_share']:.0%}: the model misses something in most of the "
                          "data, so there is no "
                          "clean remainder to weigh it against"}
    # the two polishes are independent: side by side (rideid.model.batch.thread_map), BLAS on one thread for
    # both however many workers run them, so one or two cores give the same numbers (tests/test_materiality.py)
    with single_threaded_blas():
        (x_all, _), (x_wo, std_wo) = thread_map(lambda c: polish(c, x), [cf, cf.without_pairs(pairs)],
                                                "rideid-materiality")
    shifts, undetermined = {}, []
    for i, n in enumerate(cf.names):
        d = details.get(n, {})
        if d.get("fixed") or n not in details:
            continue
        if not np.isfinite(std_wo[i]):
            undetermined.append(n)
            continue
        bar = _error_bar(d)
        if bar is None:
            continue
        shifts[n] = float(abs(x_wo[i] - x_all[i]) / bar)
    if undetermined:
        return {**out, "material": True, "largest_shift": None, "shifts": shifts,
                "reason": "without the flagged pairs the data no longer determine " + ", ".join(undetermined)
                          + ": the structure is in the only data that measure them"}
    worst = max(shifts, key=shifts.get) if shifts else None
    z = shifts.get(worst, 0.0)
    i = cf.names.index(worst) if worst else None
    material = z > defaults["materiality.material_shift"]
    largest = None if worst is None else {"parameter": worst, "in_std_total": z, "value_all": float(x_all[i]),
                                          "value_without": float(x_wo[i])}
    reason = (f"leaving them out moves {worst} by {z:.2g} std_total" if worst else "no estimate to compare") + (
        f", more than {defaults['materiality.material_shift']:g}: the structure matters" if material
        else f" at most (every estimate within {defaults['materiality.material_shift']:g} std_total): the structure "
        "does not matter")
    return {**out, "material": material, "largest_shift": largest, "shifts": shifts, "reason": reason}


def verdict(adequacy: dict, record: dict) -> dict:
    """``adequacy`` with the materiality ``record`` joined: adequate unless the structure matters; the first
    reason says what was found and whether it matters."""
    pairs = record["pairs_left_out"]
    named = ", ".join(pairs[:6]) + (f" and {len(pairs) - 6} more" if len(pairs) > 6 else "")
    first = (f"road-driven structure in {len(pairs)} run/channel pairs ({named}); {record['reason']}")
    reasons = [first] + list(adequacy.get("reasons", [])[1:]) + [adequacy["reasons"][0]]
    if adequacy.get("sensors_suspect"):  # the sensor chain found wrong stays the first reason
        reasons = [adequacy["reasons"][0], first] + list(adequacy.get("reasons", [])[1:])
    # structure that does not matter clears the structure, not a sensor chain the road fit found wrong
    # (rideid.estimate.fit.anyroad: an undeclared AC coupling, ``sensors_suspect``)
    return {**adequacy, "adequate": not record["material"] and not adequacy.get("sensors_suspect"),
            "structure": True, "reasons": reasons, "materiality": record}


@stage("materiality")
def weigh_result(ds, res, simulator=None):
    """``res`` with its adequacy weighed for materiality (:func:`weigh`, :func:`verdict`) when the residual
    test found structure; unchanged otherwise (adequate, not assessed). ``ds``: the dataset as loaded."""
    ad = res.adequacy
    if not ad or ad.get("adequate", True) or not flagged_pairs(ad):
        return res
    cf = fit_cost(ds, res, simulator)
    if cf is None:
        return res
    x = np.asarray(res.x, dtype=float)
    equal = np.full(len(cf.run_ids), 1.0 / len(cf.run_ids))

    def polish(c, x0):
        c = c.pinned_at(c.space.full(np.asarray(x0, dtype=float)[None]))
        xs, _, std = polish_fixed_starts(c, np.asarray(x0, dtype=float), equal)
        return xs, std

    record = weigh(cf, x, res.details, ad, polish)
    out = verdict(ad, record)
    if out["adequate"]:
        out["advice"] = None
    return replace(res, adequacy=out)


__all__ = ["METHOD", "flagged_pairs", "verdict", "weigh", "weigh_result"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "MATERIAL_SHIFT": "materiality.material_shift", "MAX_SHARE": "materiality.max_share"})
