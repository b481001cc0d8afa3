"""The result's entries of each estimate and each run: what result.json says of them beside the verdicts.

:func:`parameter_detail` is one parameter's entry (value, unit, fixed or derived, search bounds, white and
robust standard errors, the runs' disagreement), :func:`details_of` every reported parameter's with the marks
of what the data did not measure (a knot no run excites, a stop no run reaches) and of the bound check
(:func:`mark_bounds`: an estimate the bound stopped, not the data); :func:`preprocessing_record` the dataset's
preprocessing with the starts the fit settled (the motion it held, SPEC §13, is the dataset's own record:
:attr:`rideid.data.dataset.Dataset.preprocessed`).
"""

from __future__ import annotations

import copy
import math

import numpy as np

from ...data.checks import bound_findings
from ...model.nonlinear import BUMP_STOP_NAMES
from ...model.params import GROUPS, UNITS
from ..problem.cost import BUMP_UNITS


#: the note of a free parameter the polish's Jacobian does not determine (rideid.estimate.fit.uncertainty)
NOT_IDENTIFIED = ("not identified: the data determine it only in combination with other parameters, or not at "
                  "all (a singular value of the Jacobian below RANK_RTOL of the largest); no standard error")


def parameter_detail(space, P, n: str, std, cov, robust) -> dict:
    """Parameter ``n``'s ``result.json`` entry: value, unit, fixed/derived, search bounds, ``std`` (white)
    and ``std_robust``, from the full row ``P``, the free parameters' ``std`` and white covariance ``cov``
    and the :class:`~rideid.estimate.fit.uncertainty.EstimateCovariance` ``robust``."""
    e = {"value": float(P[space.col[n]]), "unit": UNITS.get(n, BUMP_UNITS.get(n, "N")), "fixed": n in space.fixed,
         "derived": n in space.derived_names()}
    if n in space.names:
        j = space.names.index(n)
        e["lower"], e["upper"] = float(space.bounds[j, 0]), float(space.bounds[j, 1])
        e["std"] = None if not np.isfinite(std[j]) else float(std[j])
        if np.isinf(std[j]):
            e["note"] = NOT_IDENTIFIED
    elif n == space.derived:
        e["std"] = derived_std(space, cov)
        e["lower"] = e["upper"] = None  # follows from the anchor: never searched
    elif e["derived"]:
        e["std"] = robust.std_white(n)
        e["lower"] = e["upper"] = None
    else:
        e["std"] = 0.0
    e["std_robust"] = robust.std_robust(n) if n not in space.fixed else 0.0
    if n not in space.fixed and robust.jackknife is not None:
        # the runs' disagreement beyond their noise (docs/uncertainty.md "Between runs") is part of the robust
        # standard error: the HAC sandwich's share is std_hac
        e["std_jackknife"] = robust.std_jackknife(n)
        e["std_between_runs"] = between = robust.std_between_runs(n)
        if between and e["std_robust"] is not None:
            e["std_hac"] = e["std_robust"]
            e["std_robust"] = float(math.hypot(e["std_robust"], between))
    return e



def unresolved_sentence(unresolved: dict) -> str:
    """What result.json ``polish.unresolved`` (:meth:`rideid.estimate.fit.uncertainty.Resolution.record`) says, in
    one sentence: the parameters not determined and why."""
    dirs = "; ".join(" ".join(f"{'-' if u < 0 else '+' if k else ''} {abs(u):.2f} {n}".strip()
                              for k, (n, u) in enumerate(d["along"].items()))
                     + f" (curvature {d['curvature']:.3g} against a rounding noise of {d['noise']:.2g})"
                     for d in unresolved["directions"])
    said = (f"not determined: the cost's curvature along {dirs} is not above {unresolved['curvature_noise']:g} "
            "times its rounding noise, so the data do not fix it and no error bar is given; the other parameters' "
            "error bars hold with this direction at its estimate (docs/uncertainty.md)")
    if unresolved.get("at_bound"):
        said += (f"; {', '.join(unresolved['at_bound'])} ended at a search bound, so that estimate is the bound's, "
                 "not the data's, and " + (", ".join(unresolved.get("conditional") or []) or "the others")
                 + ", fitted around it, may be off by several of their error bars (measured: 4 of them)")
    return said


def not_determined(details: dict, space, x, unresolved: dict | None) -> list:
    """Mark in ``details`` the parameters of a road fit's Hessian directions that the cost's rounding hides
    (``unresolved``: result.json ``polish.unresolved``), and the derived quantities that depend on them: ``std``,
    ``std_robust``, ``std_total``, ``budget`` None, ``determined`` False and the note :func:`unresolved_sentence`.
    Returns their names."""
    if not unresolved or not unresolved.get("not_determined"):
        return []
    bad = [n for n in unresolved["not_determined"] if n in details]
    cols = [space.names.index(n) for n in bad]
    derived = space.derived_names()
    if derived and cols:
        A = space.derived_jacobian(x)
        bad += [n for n, row in zip(derived, A) if n in details and np.any(row[cols] != 0)]
    # a direction not determined whose estimate a search bound stopped: its value is the bound's, not the data's,
    # and the other parameters of its group were fitted around it (on the built-in car with every reality, data
    # seed 2, I_p at its bound of 1 kg m^2 left x_p and zeta_pb 3.9 and 4.0 of their error bars off): theirs hold
    # only with it there (``conditional_on``, said in the sentence and beside each)
    stopped = [f.channel for f in bound_findings({n: details[n] for n in bad if n in unresolved["not_determined"]})]
    coupled = [n for g in GROUPS.values() if set(g) & set(stopped) for n in g
               if n in details and n not in bad and not details[n].get("fixed") and not details[n].get("derived")]
    if stopped:
        unresolved.update(at_bound=stopped, conditional=coupled)
    note = unresolved_sentence(unresolved)
    for n in bad:
        details[n].update(std=None, std_robust=None, std_total=None, budget=None, determined=False, note=note)
        for k in ("std_jackknife", "std_between_runs", "std_hac", "std_motion"):
            details[n].pop(k, None)
    for n in coupled:
        details[n].update(conditional_on=stopped, note=conditional_note(stopped))
    return bad


def conditional_note(stopped: list) -> str:
    """The note beside an estimate whose error bar holds only with ``stopped`` (not determined, at a search bound)
    where they ended."""
    return (f"its error bar holds only with {', '.join(stopped)} at the search bound where the fit left "
            f"{'them' if len(stopped) > 1 else 'it'} (not determined by the data): it may be off by several error bars")


def details_of(ds, space, P, std, cov, robust, bumps):
    """``details`` (name -> :func:`parameter_detail`, with the knots not excited, the stops not reached and
    the estimates at a bound marked) and the findings of the data and bound checks."""
    details = {}
    for n in space.reported_names:
        e = parameter_detail(space, P, n, std, cov, robust)
        if n in space.frozen:  # a knot no run excites: continued, not measured
            e["std"] = e["std_robust"] = None
            e["excited"] = False
            e["note"] = "not excited"
        elif n.startswith("F_"):
            e["excited"] = True
        if n in BUMP_STOP_NAMES:  # a stop no run reaches: held, not measured
            e["reached"] = n not in space.bump_frozen and bool(
                ((bumps or {}).get("front" if n.endswith("_f") else "rear") or {}).get("reached", True))
            if not e["reached"] and not e["fixed"]:
                e["std"] = e["std_robust"] = None
                e["note"] = "not reached"
        details[n] = e
    # an estimate the bound stopped, not the data (rideid.data.checks); warned of by rideid.identify, once,
    # for the model it returns (warn_bounds), not for every candidate fitted on the way
    return details, list(getattr(ds, "findings", [])) + mark_bounds(details)



def mark_bounds(details: dict) -> list:
    """The findings of the estimates in ``details`` that ended at a search bound
    (:func:`rideid.data.checks.bound_findings`), each such entry marked ``at_bound``."""
    found = bound_findings(details)
    for f in found:
        details[f.channel]["at_bound"] = True
    return found


def preprocessing_record(ds, starts) -> dict:
    """The dataset's preprocessing record (:attr:`rideid.data.dataset.Dataset.preprocessed`: a run that begins
    moving on its track with its lead-in, a run at a held speed with its ``motion``, SPEC §13) with the starts the
    fit settled; ``model_time``, the samples' span of model time, at those starts (the samples stay those read at
    the first start, their model times move)."""
    pre = copy.deepcopy(dict(ds.preprocessed))
    for rid, st in starts.items():
        before = pre[rid].get("start", {}).get("value")
        pre[rid]["start"] = dict(pre[rid].get("start", {}), **st)
        if pre[rid].get("model_time") is not None and before is not None and st.get("value") is not None:
            pre[rid]["model_time"] = [t + before - st["value"] for t in pre[rid]["model_time"]]
    return pre



def derived_std(space, cov):
    """The standard error of the parameter the anchor derives (``space.derived``) by the delta method from the
    free parameters' white covariance ``cov``; None when there is none or ``cov`` is not finite."""
    if space.derived is None or not np.all(np.isfinite(cov)):
        return None
    g = space.derived_gradient()
    return float(np.sqrt(max(g @ cov @ g, 0.0)))

