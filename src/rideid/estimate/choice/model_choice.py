"""``--model auto``: the model choice, a loop over extensions of one problem.

**The linear groups** (SPEC §6: ``anti_roll_bars``, ``tire_damping``). One search on the full linear model (the
largest: a smaller model is the full one with some parameters at 0, so its optimum lies near), then each smaller
candidate by a polish from the full estimate without the dropped parameters (on both cores). Criterion: a robust
Wald information criterion, computed from the full fit,

    C(M) = W(M) + penalty() * k(M)
    W(M) = theta_o^T  Cov_robust(theta_o)^-1  theta_o

with ``theta_o`` the full model's estimates of the extension parameters *not* in M, ``Cov_robust`` their HAC
covariance (``std_robust``, :mod:`rideid.estimate.fit.uncertainty`) and ``k(M)`` the number of free extension
parameters in M. The smallest C wins. ``W`` asks whether the omitted parameters are zero with an error bar that
holds under coloured, cross-channel-correlated noise, so the criterion stays honest where a likelihood-ratio test
or an AIC/BIC on the raw residual sum of squares (which count every sample as independent) would add groups the
data do not support. A candidate is eligible only if it fits materially better than every candidate it contains
(:func:`fits_better`: a cost lower by at least :func:`~rideid.estimate.problem.cost.min_improvement`): on
noise-free data, where every standard error is at rounding level, this keeps groups estimated at rounding-level
values out. ``penalty()`` = half the 99.9 % point of chi-square(2): a group of two parameters enters when its Wald
statistic exceeds 13.8, i.e. a test at 0.1 % per group.

**The extensions on top** (:data:`EXTENSIONS`: a powertrain on mounts, damper curves, bump stops; SPEC §8, §11).
While the model chosen is not adequate, one step: every extension not in the model is a rival, each declared by
what it adds (its group), how it starts from the parent's fit (:func:`start_row`: the parent's values, the new
parameters at their null: curves ``F = c v``, stops not reached, a typical engine) and how it is weighed (its Wald
statistic ``W`` of the departure from that null, from its own fit's robust covariance, and its degrees of freedom
``dof``). Each rival is first **screened** at the parent's fit (:func:`screen`): one Gauss-Newton step from its
start with its parameters freed (one batch of forward differences) predicts the cost it can reach; a rival whose
predicted gain over the parent is below what would be accepted
(:func:`~rideid.estimate.problem.cost.min_improvement`, or a score statistic
``gain / s^2`` below ``penalty() * dof``, ``s^2`` the residual variance the step predicts times the variance
inflation of that residual, the median of the HAC over the white variance of the rival's parameters: the scale of
the rival's own fit, at which its Wald statistic is weighed) is skipped and recorded with its statistic
(``model.screens``). The rivals that pass are polished from their parent's fit (no new
search), one at a time (each polish simulates on both cores), the lowest predicted cost first, until an accepted
rival fits below the cost every rival left is predicted to reach (``fitted`` false in its screen record; it is
screened again at the next step's parent). A rival is **accepted** when it fits materially better than every
candidate it contains and ``W > penalty() * dof`` (its criterion, the parent's + ``penalty() * dof``, below the
parent's + ``W``). Of the accepted rivals of one step **the one with the lowest cost** is kept: the same data, the same
equal-weight residual scaling, so the costs compare the rivals' fits directly (their Wald statistics come from
different fits' covariances and do not). With a group kept every linear group is weighed again with it: the
linear groups it lacks are added (a fit from it), the model kept pays their Wald statistic in that fit, then the
linear groups of the larger are weighed from its robust covariance (:func:`_curve_subset`), a smaller set polished
from it; the lowest criterion is kept.
The loop ends when the model is adequate, no rival is accepted, or none is left.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
from scipy import special

from ...profiling import stage
from ...settings import defaults, legacy_names
from ...model.params import NOMINAL_EXTENSIONS, POWERTRAIN_NAMES
from ...model.params import SUSPENSION_GROUPS as GROUPS
from ..fit.budget import with_budget
from ... import settings
from ..assess.adequacy import advise, assess_fit
from . import first_fit
from ..records import assessments_of, candidate_estimates, plan_of, with_caveats
from ..assess.materiality import weigh_result
from ..assess.small_angle import small_angle
from ..fit.identify import identify as identify_model, warn_bounds
from ..problem.build import curve_start, linear_cost, model_extensions
from ..assess.sensor_check import sensor_notes
from ..fit.identify import DEFAULT_GENERATIONS, DEFAULT_POPULATION
from ..fit.polish import run_blocks
from ..fit.uncertainty import hac_covariance, white_covariance
from ..fit.anyroad import TRACK_OPTIONS, as_built_runs, identify_any_road, unknown_road_runs
from ..fit import road_curves
from ...model.batch import single_threaded_blas, thread_map
from ..problem.cost import IDENTIFIABLE_GROUPS, CostFunction, ParameterSpace, refuse_unsupported_groups
from ..problem.cost import min_improvement as least_improvement
from ...errors import ArgumentError
from ...model.simulator import Simulator
from ...data.checks import bound_findings
from ...data.schema import NONLINEAR_GROUPS


def penalty() -> float:
    """The criterion's price per free extension parameter: a group of two enters at the (1 -
    ``model_choice.penalty_level``) point of chi-square(2) (99.9 % by default)."""
    return float(special.chdtri(2, defaults["model_choice.penalty_level"]) / 2)


#: the criterion in words (``{}``: :func:`penalty` and twice it, filled in where written)
CRITERION = ("robust Wald information criterion: C = W + {:.2f} k, W the Wald statistic (HAC covariance, "
             "std_robust) of the full model's extension parameters that the candidate leaves out, k its free "
             "extension parameters; smallest C wins (a group of two enters when W > {:.1f}, a 0.1 % test)"
             )

#: how the extensions on top are weighed (``{}``: :func:`penalty`)
EXTENSION_CRITERION = (
    "extensions on top (powertrain, damper_curves, bump_stops), while the model is not adequate: each rival "
    "screened at the parent's fit by one Gauss-Newton step (skipped when its predicted gain is below the least "
    "improvement or its score statistic below {0:.2f} per degree of freedom), the rest polished from the parent's "
    "fit in order of their predicted cost until an accepted one fits below what those left are predicted to reach; "
    "accepted when it fits materially better and its Wald statistic of departure from its null exceeds "
    "{0:.2f} per degree of freedom; of the accepted rivals the lowest cost (same data, same residual scaling) is "
    "kept, then the linear groups weighed again from its fit")


def wald(theta, cov) -> float:
    """``theta^T cov^-1 theta`` (pseudo-inverse, so a parameter without information adds nothing).

    Parameters
    ----------
    theta : ndarray, shape (k,)
    cov : ndarray, shape (k, k)
    """
    theta = np.asarray(theta, dtype=float)  # no parameter: 0 (the pseudo-inverse of an empty matrix)
    cov = np.asarray(cov, dtype=float)
    if not np.all(np.isfinite(cov)):
        return float("nan")
    return float(theta @ np.linalg.pinv(cov, rcond=1e-12, hermitian=True) @ theta)


def criteria(names, theta, cov, candidates, free_ext) -> list[dict]:
    """Criterion of each candidate from the full model's estimates (module docstring).

    Parameters
    ----------
    names : list of str
        The full model's free parameters (order of ``theta`` and ``cov``).
    theta : ndarray, shape (d,)
    cov : ndarray, shape (d, d)
        Robust covariance.
    candidates : list of tuple of str
        Extension groups of each candidate.
    free_ext : dict
        group -> its free parameter names in the full model.

    Returns
    -------
    list of dict
        ``{"extensions", "wald", "k", "criterion"}`` per candidate.
    """
    out = []
    for cand in candidates:
        omitted = [n for g, ns in free_ext.items() if g not in cand for n in ns]
        idx = [names.index(n) for n in omitted]
        W = wald(np.asarray(theta)[idx], np.asarray(cov)[np.ix_(idx, idx)])
        k = sum(len(free_ext[g]) for g in cand if g in free_ext)
        out.append({"extensions": list(cand), "wald": W, "k": k, "criterion": W + penalty() * k})
    return out


def _key(groups) -> tuple:
    """A candidate's key: its groups in the canonical order of every model (SPEC §6's, the powertrain, the damper
    curves, the bump stops: :data:`rideid.estimate.problem.cost.IDENTIFIABLE_GROUPS`, as a result's ``extensions``)."""
    return tuple(g for g in IDENTIFIABLE_GROUPS if g in set(groups))


def fits_better(extensions, costs: dict, min_improvement: float | None = None) -> bool:
    """Does the candidate fit materially better than every candidate it contains?

    Its cost must be at least ``min_improvement`` below each of theirs. A
    group that does not improve the fit by that much explains nothing that
    matters, however large its Wald statistic: with (nearly) noise-free
    data the robust standard errors shrink to rounding level, and a bar rate
    estimated at 1e-6 N/m would otherwise count as significant. A real bar
    or tire damper changes the fit by percent (cost by 1e-4 or more); a
    spurious group on noisy data by ~1e-8.

    Parameters
    ----------
    extensions : sequence of str
    costs : dict
        candidate (tuple of groups) -> its cost.
    min_improvement : float, optional
        Default :func:`rideid.estimate.problem.cost.min_improvement` (the setting ``adequacy.min_relative`` squared).
    """
    min_improvement = least_improvement() if min_improvement is None else min_improvement
    mine = costs[tuple(extensions)]
    return all(mine <= cost - min_improvement for cand, cost in costs.items() if set(cand) < set(extensions))


def fits_better_relative(extensions, costs: dict) -> bool:
    """:func:`fits_better` on unknown roads: the candidate's residual RMS at least setting ``adequacy.min_relative``
    (0.5 %) below that of every candidate it contains (``cost <= (1 - r)^2 cost_sub``). The road fit takes up most
    of the noise and part of what a group explains (the road is free at every sample), so its cost is below the
    channels' noise and a group's gain is a share of it: on the 3 t van with tire damping of 250 N s/m on three
    unknown roads and a twist run (2 % noise), the tire damping lowered the cost 4.8 % (7.81e-5 against
    8.20e-5), below :func:`fits_better`'s absolute floor of 2.5e-5, and leaving it out put the unsprung masses
    3.8 % low, the tires 2.7 % (docs/any-road.md). A group of nothing on noisy data lowers it by about its
    parameters over the samples (1e-4 of itself)."""
    r = defaults["adequacy.min_relative"]
    mine = costs[tuple(extensions)]
    return all(mine <= (1 - r) ** 2 * cost for cand, cost in costs.items() if set(cand) < set(extensions))


#: ``model.fits_better_rule`` of result.json, by the gate used
FITS_BETTER_RULE = {"absolute": "a cost at least ({:.2g} %)^2 below every candidate it contains",
                    "relative": "a residual RMS at least {:.2g} % below that of every candidate it contains"}


def fits_better_rule(kind: str) -> str:
    """The gate's rule in words (the terminal's and the report's footnote to the candidates)."""
    return FITS_BETTER_RULE[kind].format(100 * defaults["adequacy.min_relative"])


def curve_departure(names, theta, cov, space) -> tuple[float, int]:
    """Wald statistic of a curve fit's departure from linear dampers, and its degrees of freedom.

    Per axle the free knot forces ``F`` at velocities ``v``: linear dampers are ``F = c v`` for some
    ``c``, i.e. ``R F = 0`` with ``R = I - v v^T / v^T v`` (the part of ``F`` no slope explains). ``W =
    (R F)^T (R Cov R^T)^+ (R F)`` over both axles (robust covariance, cross terms kept); the degrees of
    freedom are the free knots less one slope per axle.
    """

    K = space.layout.n_knots
    kv = dict(zip(space.knot_names, space.knot_velocities()))
    idx, blocks = [], []
    for axle in (space.knot_names[:K], space.knot_names[K:]):
        j = [names.index(n) for n in axle if n in names]
        if not j:
            continue
        v = np.array([kv[names[i]] for i in j])
        blocks.append(np.eye(len(j)) - np.outer(v, v) / (v @ v))
        idx += j
    if not idx:
        return 0.0, 0
    R = np.zeros((len(idx), len(idx)))
    o = 0
    for b in blocks:
        R[o:o + len(b), o:o + len(b)] = b
        o += len(b)
    th = np.asarray(theta, dtype=float)[idx]
    C = np.asarray(cov, dtype=float)[np.ix_(idx, idx)]
    return wald(R @ th, R @ C @ R.T), len(idx) - len(blocks)


def powertrain_departure(names, theta, cov, space, res) -> tuple[float, int]:
    """Wald statistic of no powertrain (``m_p = 0``, ``(m_p / std_robust)^2``; 0 when ``m_p`` is not free) and
    the powertrain's free parameters."""
    j = [names.index(n) for n in ("m_p",) if n in names]
    return wald(np.asarray(theta)[j], np.asarray(cov)[np.ix_(j, j)]), sum(n in names for n in POWERTRAIN_NAMES)


def stop_departure(names, theta, cov, space, res) -> tuple[float, int]:
    """Wald statistic of the stops' rates being 0, over the stops reached (a stop not reached is held, not free),
    and their free parameters; 0 when a stop parameter ends at its search bound (the bound's value, not the
    data's: a misfit elsewhere that a stiff stop at the least clearance patches up)."""
    at_bound = [f for f in bound_findings(res.details) if f.channel.startswith("bs_")]
    j = [names.index(n) for n in names if n.startswith("bs_rate") and not at_bound]
    return wald(np.asarray(theta)[j], np.asarray(cov)[np.ix_(j, j)]), sum(n.startswith("bs_") for n in names)


@dataclass(frozen=True)
class Extension:
    """One extension of the model choice: the group it adds, when it applies (the dataset's known values leave
    it free parameters) and how it is weighed (``departure(names, theta, cov, space, result) -> (W, dof)``, from
    its own fit). How it starts from the parent's fit is common to all (:func:`start_row`)."""
    group: str
    applies: Callable
    departure: Callable


CURVES_GROUP, BUMPS_GROUP, POWERTRAIN_GROUP = "damper_curves", "bump_stops", "powertrain"

#: the extensions weighed on top of the linear choice, each step's rivals (module docstring)
EXTENSIONS = (
    Extension(POWERTRAIN_GROUP, lambda ds: not set(POWERTRAIN_NAMES) <= set(ds.known), powertrain_departure),
    Extension(CURVES_GROUP, lambda ds: not {"c_sf", "c_sr"} & set(ds.known),
              lambda names, theta, cov, space, res: curve_departure(names, theta, cov, space)),
    Extension(BUMPS_GROUP, lambda ds: True, stop_departure),
)


def knots_like(ds, res=None):
    """``damper_knots`` of a candidate started from curve result ``res``: the grid its knees were found on
    (setting ``dampers.knee_grid``: its knot forces are then the start's own, no second fit),
    else the dataset's ``[model] damper_knots``."""
    found = res is not None and (res.dampers or {}).get("knots_from", "").startswith("found")
    return defaults["dampers.knee_grid"] if found else ds.manifest.damper_knots


def _space(ds, key, like=None) -> ParameterSpace:
    """The parameter space of candidate ``key``, its knots those of result ``like`` (:func:`knots_like`)."""
    return ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=key, damper_knots=knots_like(ds, like))


def _null_values(space, parameters) -> dict:
    """The values at which each extension of ``space`` is absent, from a car's ``parameters``: damper curves
    ``F = c v`` (the car's linear rates), stops with no rate at the most clearance, a typical engine
    (:data:`rideid.model.params.NOMINAL_EXTENSIONS`: with ``m_p`` > 0 its modes have a gradient to screen)."""
    v = dict(zip(space.knot_names, space.knot_velocities()))
    hi = dict(zip(space.names, space.bounds[:, 1]))
    vals = {n: 0.0 for g in GROUPS.values() for n in g}  # a linear group absent: its rates 0
    vals.update({n: parameters[f"c_s{n[2]}"] * vn for n, vn in v.items()})
    vals.update({n: NOMINAL_EXTENSIONS[n] for n in POWERTRAIN_NAMES}, bs_rate_f=0.0, bs_rate_r=0.0,
                bs_clear_f=hi.get("bs_clear_f", 0.15), bs_clear_r=hi.get("bs_clear_r", 0.15))
    return vals


def start_row(ds, parent, space) -> np.ndarray:
    """A candidate's start from its parent's fit: the parent's values, the new parameters at their null
    (:func:`_null_values`). From a linear parent a nonlinear candidate gets the linear model's row, as
    :func:`rideid.estimate.fit.identify.identify` takes it (curves ``F = c v`` on the knee grid, the stop scan);
    from a nonlinear parent its own row (the parent's knot forces as they are)."""
    linear = not set(parent.model["extensions"]) & set(NONLINEAR_GROUPS)
    row = _space(ds, [g for g in space.extensions if g not in NONLINEAR_GROUPS]) if linear else space
    vals = {**_null_values(space, parent.parameters), **parent.parameters}
    return np.clip([vals[n] for n in row.names], row.bounds[:, 0], row.bounds[:, 1])


def gauss_newton_step(cf: CostFunction, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(J, r, r_next)`` of one Gauss-Newton step from ``x`` on the equal-weight cost: the Jacobian in units of
    the bound spans, the residuals at ``x`` and those predicted after the step.

    The Jacobian by forward differences (step 1e-6 of each bound span, into the box) as one batch of ``d + 1``
    rows; the step is the unbounded least-squares one, ``J dz = -r``, predicting ``r + J dz``.
    """
    x = np.asarray(x, dtype=float)
    lo, hi = cf.space.bounds[:, 0], cf.space.bounds[:, 1]
    h = 1e-6 * (hi - lo)
    h = np.where(x + h <= hi, h, -h)
    R = cf.residuals(np.vstack([x, x + np.diag(h)]), np.full(len(cf.run_ids), 1.0 / len(cf.run_ids)))
    J = (R[1:] - R[0]).T / h * (hi - lo)
    step = np.linalg.lstsq(J, -R[0], rcond=None)[0]
    return J, R[0], R[0] + J @ step


def variance_inflation(J, e, blocks) -> float:
    """The median over the parameters (columns of ``J``) of their HAC variance over their white one at residuals
    ``e`` (:func:`rideid.estimate.fit.uncertainty.hac_covariance`, runs ``blocks`` as independent blocks): how
    much the residuals' correlation in time and across channels widens the error bars; 1 for white residuals
    (tests/test_model_choice_groups.py: 0.99 on white noise, 8.1 on AR(1) noise of coefficient 0.8, whose long-run
    variance is 9 times its variance). Parameters the data leave undetermined are left out; 1 when none is left."""
    white = np.diag(white_covariance(J, e))
    robust = np.diag(hac_covariance(J, e, blocks).cov)
    ok = np.isfinite(white) & np.isfinite(robust) & (white > 0)
    return float(np.median(robust[ok] / white[ok])) if np.any(ok) else 1.0


def screen(ds, parent, key, simulator) -> dict:
    """The score screen of candidate ``key`` at its parent's fit (module docstring): its start
    (:func:`start_row`, mapped as the fit maps it: knots not excited frozen, the stop scan), one Gauss-Newton step
    (:func:`gauss_newton_step`), the predicted gain over the parent and its statistic ``gain / s^2`` against
    ``penalty() * dof``; ``passes`` says whether the candidate is worth its fit.

    ``s^2`` is the residual variance of the fit the rival is predicted to reach (the step's residual) times its
    variance inflation there (:func:`variance_inflation`): the statistic stands in for the rival's Wald
    statistic, which is computed at the rival's own fit with its robust covariance (for a linear model ``gain /
    s1^2`` is the Wald statistic, ``gain / s0^2`` at the parent the score statistic, never larger). At a parent
    that misses what the rival explains, the parent's residual is that structure, and its variance and
    inflation hide the rival: measured on the engine and damper curves case (tests/engine_curves_case.py, four
    runs, 1 % noise) at the tire-damping parent, the parent's inflation 330 scored the powertrain 33.9 and the
    curves 55.4 (against 48.4 and 124: both skipped, c_sf -64 %); at the step's residual (inflation 7.8 and 31)
    2165 and 1310, the stops 18.1 (against 27.6: skipped, the car has none)."""
    space = _space(ds, key, parent)
    x = start_row(ds, parent, space)
    cf = CostFunction(parent.fitted_data(ds), space=space, simulator=simulator)
    cf, x, _, _ = curve_start(cf, cf if len(x) == len(cf.names) else linear_cost(cf.ds, cf), x)
    with single_threaded_blas():
        J, r, r_next = gauss_newton_step(cf, x)
        inflation = variance_inflation(J, r_next, run_blocks(cf))
    cost0, predicted, m = float(r @ r), float(r_next @ r_next), r.size
    gain = parent.cost - predicted
    dof = len(cf.names) - len(parent.names)
    score = gain * max(m - len(cf.names), 1) / max(predicted, np.finfo(float).tiny) / max(inflation, 1.0)
    passes = bool(gain >= least_improvement() and score >= penalty() * dof)
    return {"extensions": list(key), "cost_at_start": cost0, "predicted_cost": predicted, "predicted_gain": gain,
            "score": score, "variance_inflation": inflation, "dof": dof, "threshold": penalty() * dof,
            "least_improvement": least_improvement(),
            "passes": passes}


def _own_adequacy(ds, res, simulator):
    """The adequacy verdict of a candidate at its own final state: its parameters on its own knots, and the
    model's time axes at the starts its own polish settled."""
    cf = _cost_of(ds, res, simulator)
    with single_threaded_blas():
        return assess_fit(cf, cf.space.full(np.array([[res.parameters[n] for n in cf.names]]))[0], res.response)


def _cost_of(ds, res, simulator) -> CostFunction:
    """The cost function of a candidate's result: its model on its knots, the data at its starts."""
    return CostFunction(res.fitted_data(ds), space=_space(ds, _key(res.model["extensions"]), res),
                        simulator=simulator)


@dataclass
class _Choice:
    """The model choice's state: every candidate fitted (``results``: key -> result, ``entries``: its criterion
    record), the screens, and the model kept so far (``key``, its entry ``best``)."""
    ds: object
    simulator: object
    fit_kw: dict
    results: dict = field(default_factory=dict)
    entries: list = field(default_factory=list)
    screens: list = field(default_factory=list)
    key: tuple = ()
    best: dict = field(default_factory=dict)
    #: candidates fitted already: key -> result (:meth:`fit` returns it)
    given: dict = field(default_factory=dict)

    def add(self, key, res, entry) -> dict:
        """Record candidate ``key`` (its result and entry); every candidate's ``fits_better`` again (a new
        candidate may be contained in an older one)."""
        self.results[key] = res
        self.entries.append(dict(entry, extensions=list(key)))
        costs = {c: r.cost for c, r in self.results.items()}
        for e in self.entries:
            e["fits_better"] = self.gate(tuple(e["extensions"]), costs)
        return self.entries[-1]

    def gate(self, key, costs) -> bool:
        """Does candidate ``key`` fit materially better than those it contains (:func:`fits_better`)?"""
        return fits_better(key, costs)

    def keep_best(self, *entries):
        """Keep the lowest criterion (fewer parameters on a tie) of ``entries`` that fit better and have one."""
        live = [e for e in entries if e["fits_better"] and e["criterion"] is not None]
        self.best = min(live, key=lambda e: (e["criterion"], e["k"]), default=self.best)
        self.key = tuple(self.best["extensions"])

    def chosen(self):
        """The result of the model kept, with its own adequacy verdict."""
        r = self.results[self.key]
        if r.adequacy is None:
            r = self.results[self.key] = replace(r, adequacy=_own_adequacy(self.ds, r, self.simulator))
        return r

    def fit(self, parent, key, maps=None, **kw):
        """Candidate ``key`` polished from ``parent``'s fit (:func:`start_row`), no search, no verdict (a candidate
        fitted already, ``given``, is not fitted again)."""
        return self.given.get(key) or self._fit_new(parent, key, maps, **kw)

    def _fit_new(self, parent, key, maps=None):
        space = _space(self.ds, key, parent)
        ds = parent.fitted_data(self.ds)  # the starts (and speeds) the parent settled: the polish starts there
        return identify_model(ds, cost=CostFunction(ds, space=space, simulator=self.simulator),
                              start=start_row(ds, parent, space), maps=maps, assess=False, **self.fit_kw)

    def linear_step(self, full, subsets: bool = True):
        """The linear groups: the full linear model's fit ``full``, its subsets polished from it (on both cores),
        the criterion of each from the full fit's robust covariance; the lowest kept. ``subsets`` False: ``full``
        alone (a first fit that misses grossly, :meth:`mend`: a subset's criterion read from a fit that far off
        says nothing; the linear groups are weighed again once the extension that mends it is in)."""
        pol = full.polish or {}
        names = list(pol.get("names", []))
        free = {g: [n for n in GROUPS[g] if n in names] for g in GROUPS}
        free = {g: ns for g, ns in free.items() if ns}  # fully known groups are in every candidate
        subs = [_key(set(sub) | (set(GROUPS) - set(free))) for r in range(len(free) + 1)
                for sub in itertools.combinations(free, r)]
        subs = subs[(len(subs) - 1) * (not subsets):]  # without the subsets: the full model alone
        cov = np.array(pol.get("covariance_robust", np.full((len(names),) * 2, np.nan)))
        crit = criteria(names, np.array([full.parameters[n] for n in names]), cov, subs, free)
        with single_threaded_blas():
            fits = thread_map(lambda key: self.fit(full, key, full.maps), subs[:-1], "rideid-candidates")
        for key, r, c in zip(subs, fits + [full], crit):
            self.add(key, r, dict(c, criterion=c["criterion"] if np.isfinite(c["criterion"]) else None))
        self.keep_best(*self.entries)

    def mend(self, full, gross):
        """At a first fit ``full`` that misses grossly (``gross``; None: it does not, and nothing is screened): the
        rival the data call for most (:func:`rideid.estimate.choice.first_fit.strongest`), fitted from it. Returns
        ``(screens, key, fit, mends)``: the screens, that rival's key and fit (None, None when no screen passes),
        and whether its fit no longer misses grossly (the misfit was the model's, not the set-up's: the model
        choice goes on, the fit kept for it as :attr:`given`). A rival that still misses grossly on the tracks as
        drawn may be mended by the tracks as built (:func:`rideid.estimate.choice.first_fit.as_built`)."""
        rivals = [_key(self.key + (e.group,)) for e in EXTENSIONS
                  if gross is not None and e.group not in self.key and e.applies(self.ds)]
        with single_threaded_blas():
            screens = thread_map(lambda key: screen(self.ds, full, key, self.simulator), rivals, "rideid-screens")
        best = first_fit.strongest(screens)
        if best is None:
            return screens, None, None, False
        key = tuple(best["extensions"])
        with single_threaded_blas():
            self.given[key] = self.fit(full, key)
        best["mends"] = first_fit.misses(self.ds, self.given[key]) is None
        return screens, key, self.given[key], best["mends"]

    def extend(self) -> bool:
        """One step on top of the model kept (module docstring): the rivals screened on both cores, those that pass
        polished one at a time in order of their predicted cost (:meth:`_fit_rivals`), the accepted one of lowest
        cost kept and the linear groups weighed again with it. Returns whether an extension was kept."""
        parent = self.chosen()
        rivals = {_key(self.key + (e.group,)): e for e in EXTENSIONS if e.group not in self.key and e.applies(self.ds)}
        with single_threaded_blas():
            screens = thread_map(lambda key: screen(self.ds, parent, key, self.simulator), rivals, "rideid-screens")
        self.screens += screens
        accepted = self._fit_rivals(parent, rivals, [s for s in screens if s["passes"]])
        if not accepted:
            return False
        self.best = min(accepted, key=lambda e: self.results[tuple(e["extensions"])].cost)
        group = set(self.best["extensions"]) - set(self.key)
        # every candidate without the group leaves out the departure its fit measured: its criterion pays W
        for e in (e for e in self.entries if e["criterion"] is not None and not group <= set(e["extensions"])):
            e["criterion"], e["wald"] = e["criterion"] + self.best["wald"], e["wald"] + self.best["wald"]
        self.key = tuple(self.best["extensions"])
        self.linear_again()
        return True

    def _fit_rivals(self, parent, rivals, passed) -> list:
        """The rivals that passed their screen (``passed``, screen records) polished from ``parent``'s fit, the most
        promising first; returns the entries of those accepted. Fitting stops once an accepted rival's cost is
        below the cost every rival left is predicted to reach: none of them could be kept over it. Measured on the
        knee car (benchmarks/bench_realtest.py ``knees``): the curves predicted at 0.011 reached 1.1e-4, the stops
        predicted at 0.0890 were polished beside them on the other core (12 s) to 0.0889; one fit at a time the
        curves' polish has both cores. A rival left unfitted is screened again at the next step's parent."""
        parent_entry, accepted = self.best, []
        order = sorted(passed, key=lambda s: s["predicted_cost"])
        for i, s in enumerate(order):
            if accepted and min(self.results[tuple(e["extensions"])].cost for e in accepted) <= s["predicted_cost"]:
                for rest in order[i:]:
                    rest["fitted"] = False
                break
            key = tuple(s["extensions"])
            with single_threaded_blas():
                r = self.fit(parent, key)
            s["fitted"] = True
            pol = r.polish or {}
            names = list(pol.get("names", []))
            W, dof = rivals[key].departure(names, np.array([r.parameters[n] for n in names]),
                                           np.array(pol.get("covariance_robust", np.full((len(names),) * 2, np.nan))),
                                           _space(self.ds, key, r), r)
            e = self.add(key, r, {"wald": W, "k": parent_entry["k"] + dof, "dof": dof, "parent": list(self.key),
                                  "criterion": parent_entry["criterion"] + penalty() * dof})
            accepted += [e] if e["fits_better"] and np.isfinite(W) and W > penalty() * dof else []
        return accepted

    def table(self) -> list:
        """``model.candidates`` of result.json: each entry with its fit's cost, verdict and estimates."""
        out = []
        for e in self.entries:
            r = self.results[tuple(e["extensions"])]
            out.append(dict(e, cost=r.cost, free_extension_parameters=e["k"],
                            adequate=(r.adequacy or {}).get("adequate"), **candidate_estimates(r)))
        return out

    def every_linear_group(self):
        """The model kept with every linear group it lacks (their parameters from 0), polished from its fit. When it
        fits materially better (:func:`fits_better`), the model kept pays the Wald statistic of those groups in that
        fit (as a candidate without a kept extension pays its W) and it is returned; else None (also when no linear
        group is left out): a group that does not improve the fit is not weighed by that fit's covariance (on
        noise-free data a bar of nothing has a Wald statistic at rounding level, tests/test_model_choice_groups.py)."""
        kept, kept_entry = self.results[self.key], self.best
        key = _key(set(self.key) | set(GROUPS))
        if key == self.key:
            return None
        r = self.fit(kept, key)
        pol = r.polish or {}
        names = list(pol.get("names", []))
        added = [n for g in set(key) - set(self.key) for n in GROUPS[g] if n in names]
        if not added or "covariance_robust" not in pol:
            return None
        j = [names.index(n) for n in added]
        W = wald(np.array([r.parameters[n] for n in added]), np.array(pol["covariance_robust"])[np.ix_(j, j)])
        e = self.add(key, r, {"wald": 0.0, "k": kept_entry["k"] + len(added),
                              "criterion": kept_entry["criterion"] + penalty() * len(added)})
        if not (e["fits_better"] and np.isfinite(W)):
            return None
        kept_entry["criterion"], kept_entry["wald"] = kept_entry["criterion"] + W, kept_entry["wald"] + W
        return e

    def linear_again(self):
        """Every linear group weighed again with the group just kept (issue 50): the model kept with every linear
        group (:meth:`every_linear_group`: a linear model makes up for digressive dampers with spurious tire
        damping, or leaves out a real one the curves then need), then the linear groups of the largest of them
        weighed from its fit's robust covariance (:func:`_curve_subset`); a smaller set preferred is polished from
        that fit; of these the lowest criterion is kept."""
        kept_entry = self.best
        grown = self.every_linear_group()
        big_entry = grown or kept_entry
        key = tuple(big_entry["extensions"])
        big = self.results[key]
        sub = _curve_subset(big, key, big_entry)
        if sub is None:
            self.keep_best(kept_entry, big_entry)
            return
        lin, W_sub = sub
        small = _key(set(lin) | (set(key) - set(GROUPS)))
        n_left = sum(n in big.names for g in set(key) - set(lin) for n in GROUPS.get(g, ()))
        crit = {"wald": W_sub, "k": big_entry["k"] - n_left,
                "criterion": big_entry["criterion"] - penalty() * n_left + W_sub}
        if grown and small == tuple(kept_entry["extensions"]):  # the model kept: weighed by the larger fit
            e = kept_entry
            e.update(crit)
        else:
            e = self.add(small, self.fit(big, small), crit)
        self.keep_best(kept_entry, big_entry, e)


def _curve_subset(r_c, chosen, c_crit):
    """The subset of the linear groups ``chosen`` that the criterion prefers once a group is in
    (Wald of the left-out groups' parameters from the fit ``r_c``'s robust covariance), with that
    Wald statistic; None when it is ``chosen`` itself."""
    pol = r_c.polish or {}
    names = list(pol.get("names", []))
    free = {g: [n for n in GROUPS[g] if n in names] for g in chosen if g in GROUPS}
    free = {g: ns for g, ns in free.items() if ns}
    if not free or "covariance_robust" not in pol:
        return None
    lin = tuple(g for g in chosen if g in GROUPS)
    subs = [tuple(g for g in lin if g in sub or g not in free)
            for r in range(len(free) + 1) for sub in itertools.combinations(free, r)]
    theta = np.array([r_c.parameters[n] for n in names])
    crit = criteria(names, theta, np.array(pol["covariance_robust"]), subs, free)
    best = min(crit, key=lambda c: (c["criterion"], c["k"]))
    if set(best["extensions"]) == set(lin) or not np.isfinite(best["wald"]):
        return None
    return tuple(g for g in GROUPS if g in best["extensions"]), best["wald"]


@stage("model choice")
def identify_auto(ds, *, rng=None, seed=None, callback=None, maps=None, simulator=None, tracks: str = "as-built",
                  **kw):
    """:func:`rideid.identify` with ``model="auto"`` (module docstring).

    Returns the chosen candidate's :class:`~rideid.estimate.fit.identify.IdentificationResult`
    whose ``model`` holds ``extensions``, ``selection = "auto"``, the
    criteria's description, every candidate fitted (``extensions``, ``cost``,
    ``criterion``, ``wald``, ``fits_better``, ``adequate``, ``parameters``,
    ``std_robust``) and every screen (``screens``: the candidates skipped with
    their statistic). Its ``evaluations`` and ``wall_time_s`` cover all candidates.
    """
    t0 = time.perf_counter()
    cf_full = CostFunction(ds, extensions=tuple(GROUPS), simulator=simulator)
    simulator = cf_full.simulator  # one value for every candidate
    full = identify_model(ds, rng=rng, seed=seed, callback=callback, maps=maps, cost=cf_full, **kw)
    # SPEC §13: a first fit far beyond what any extension explains stops here, with the set-up to check, unless the
    # extension the data call for most mends it (rideid.estimate.choice.first_fit)
    gross = first_fit.misses(ds, full)
    choice = _Choice(ds, simulator, dict(rng=rng, seed=seed, **{k: v for k, v in kw.items()
                                                                 if k in ("weights", "polish", "population")}),
                     key=_key(GROUPS))
    first_screens, rival, rival_fit, mended = choice.mend(full, gross)
    if gross is not None and not mended:
        return (first_fit.as_built(ds, full, gross, first_screens, rival, rival_fit, GROUPS, simulator, tracks,
                                   dict(rng=rng, seed=seed, callback=callback, maps=maps, **kw))
                or first_fit.stopped(full, gross, first_screens, rival, rival_fit))
    choice.linear_step(full, subsets=not mended)
    steps = 0
    while not choice.chosen().adequacy.get("adequate", True) and choice.extend():
        steps += 1
    res = choice.chosen()
    model = {"extensions": list(choice.key), "selection": "auto",
             "criterion": CRITERION.format(penalty(), 2 * penalty()),
             "extension_criterion": EXTENSION_CRITERION.format(penalty()), "candidates": choice.table(),
             "fits_better_rule": fits_better_rule("absolute"), "screens": choice.screens, "steps": steps,
             "skipped": [s["extensions"] for s in choice.screens if not s["passes"]],
             "first_fit": first_fit.record(gross, rival, first_screens, GROUPS, mended)}
    model.update({} if choice.screens else {"curves": "not tried: the linear model is adequate (its residuals carry "
                                                     "no road-driven structure for damper curves to explain)"})
    # the search was the full model's: its history and counts belong to the result returned
    search = {} if choice.key == tuple(GROUPS) else {"history": full.history, "nit": full.nit, "stop": full.stop,
                                                     "message": full.message, "track_weights": full.track_weights}
    adequacy = advise(res.adequacy, model)
    adequacy = sensor_notes(ds, _cost_of(ds, res, simulator), res.response, adequacy) if res.response else adequacy
    return replace(res, model=model, adequacy=adequacy,  # advice, the candidates weighed
                   nfev=sum(r.nfev for r in choice.results.values()), wall_time_s=time.perf_counter() - t0, **search)


@dataclass
class _RoadChoice(_Choice):
    """The model choice on a problem with unknown roads (SPEC §9): the same loop, each candidate fitted by the road
    pipeline (:func:`rideid.estimate.fit.anyroad.identify_any_road`: the road projected out, each road run's
    speed with the car) from its parent's fit, its verdict its own (the road runs judged by their residual); a
    candidate fitted already (``given``: key -> result) is not fitted again."""

    def _fit_new(self, parent, key, maps=None, **kw):
        space = _space(self.ds, key, parent)
        return identify_any_road(self.ds, model=list(key), start=_inside(space, start_row(self.ds, parent, space)),
                                 simulator=self.simulator, **{**self.fit_kw, **kw})

    def chosen(self):
        return self.results[self.key]

    def gate(self, key, costs) -> bool:
        return fits_better_relative(key, costs)

    def curves_step(self) -> None:
        """Damper curves on top of the linear model kept, when its verdict is not adequate and the roads can take
        them (:func:`rideid.estimate.fit.road_curves.candidates`): fitted from its dampers (``F = c v``), kept as
        the tracks' extensions are (:meth:`_fit_rivals`): when they fit materially better and their departure
        from linear dampers weighs more than the penalty of their knots (:func:`curve_departure`). The linear groups
        are not weighed again with them (on tracks they are)."""
        parent, parent_entry = self.chosen(), self.best
        for key in map(_key, road_curves.candidates(self.ds, parent, self.key)):
            r = identify_any_road(self.ds, model=list(key), parent=dict(parent.parameters),
                                  simulator=self.simulator, **self.fit_kw)
            pol = r.polish or {}
            names = list(pol.get("names", []))
            W, dof = curve_departure(names, np.array([r.parameters[n] for n in names]),
                                     np.array(pol.get("covariance_robust", np.full((len(names),) * 2, np.nan))),
                                     _space(self.ds, key, r))
            e = self.add(key, r, {"wald": W, "k": parent_entry["k"] + dof, "dof": dof, "parent": list(self.key),
                                  "criterion": (parent_entry.get("criterion") or 0.0) + penalty() * dof})
            for kept in [e] if e["fits_better"] and np.isfinite(W) and W > penalty() * dof else []:
                self.key, self.best = key, kept


def _inside(space, row) -> np.ndarray:
    """``row`` with each linear group's rate at its lower bound moved 0.1 % of its range inside (a bar 100 N/m, a
    tire damper 1.5 N s/m): a road fit started with a group's rates at 0 exactly stops there (measured on the
    built-in car with tire damping of 400 N s/m on two roads: trf ended at 2e-4 N s/m after 6 evaluations, from
    1 N s/m at 393-400 after 9: at the bound its scaling froze the rates)."""
    row = np.array(row, dtype=float)
    lo, hi = space.bounds[:, 0], space.bounds[:, 1]
    j = [space.names.index(n) for ns in GROUPS.values() for n in ns if n in space.names]
    row[j] = np.maximum(row[j], lo[j] + 1e-3 * (hi[j] - lo[j]))
    return row


#: result.json ``model.note`` of the model choice on unknown roads
ROADS_NOTE = ("on unknown roads auto weighs SPEC §6's linear groups (anti-roll bars, tire damping): the twelve "
              "searched and polished, the full linear model polished from them; when it fits materially better, "
              "each smaller model is polished from it and the lowest criterion of those that fit materially better "
              "kept (as on known tracks), else the twelve are; then, when the model kept is not adequate, damper "
              "curves from its dampers (their force at the suspension velocities the accelerometers measure: "
              "docs/any-road.md); the powertrain and bump stops are not tried there (a powertrain only when "
              "named: --model powertrain)")


@stage("model choice on unknown roads")
def identify_auto_roads(ds, *, simulator=None, tracks="as-built", rng=None, seed=None, callback=None, **kw):
    """:func:`rideid.identify` with ``model="auto"`` on a dataset with unknown-road runs (:data:`ROADS_NOTE`): the
    linear groups weighed as :func:`identify_auto` weighs them (:meth:`_Choice.linear_step`), every candidate a
    road fit (:class:`_RoadChoice`), once the full linear model, polished from the twelve without error bars,
    has shown it fits materially better than they do (:func:`fits_better_relative`; else no smaller model can,
    and the twelve are kept). ``model`` as :func:`identify_auto`'s, with ``note``; ``evaluations`` and
    ``wall_time_s`` cover every candidate."""
    t0 = time.perf_counter()
    simulator = simulator or Simulator()
    common = {k: v for k, v in kw.items() if k in ("polish", "population", "generations", "assess")}
    # a group whose values are all in [known] is in every candidate (as linear_step keys them)
    known, full_key = _key([g for g in GROUPS if set(GROUPS[g]) <= set(ds.known)]), _key(GROUPS)
    base = identify_any_road(ds, model=list(known), rng=rng, seed=seed, callback=callback, simulator=simulator,
                             tracks=tracks, **common)
    fit_kw = dict(rng=rng, seed=seed, tracks=tracks, **common)
    choice = _RoadChoice(ds, simulator, fit_kw, given={known: base})
    if known == full_key or not (base.polish or {}).get("covariance_robust"):  # no linear group, or no polish
        choice.add(known, base, {"wald": None, "k": 0, "criterion": None})
        choice.key, choice.best = known, choice.entries[0]
        choice.curves_step()
        return _road_choice_result(choice, known, base, t0)
    probe = choice.fit(base, full_key, assess=False, probe=True)
    if choice.gate(full_key, {known: base.cost, full_key: probe.cost}):
        full = identify_any_road(ds, model=list(full_key), start=[probe.parameters[n] for n in probe.names],
                                 simulator=simulator, **fit_kw)
        choice.linear_step(full)
    else:  # the full linear model explains nothing the twelve do not: neither can a smaller one
        choice.add(known, base, {"wald": None, "k": 0, "criterion": None})
        choice.add(full_key, probe, {"wald": None, "k": sum(n in probe.names for g in full_key for n in GROUPS[g]),
                                     "criterion": None,
                                     "note": "one solve from the twelve, no error bars: no materially better "
                                             "fit than the twelve, so no smaller model was fitted"})
        choice.key, choice.best = known, choice.entries[0]
    choice.curves_step()
    return _road_choice_result(choice, known, base, t0)


def _road_choice_result(choice, known, base, t0):
    """The result of the road model choice ``choice``: the model kept, with result.json's ``model`` record."""
    res = choice.chosen()
    model = {"extensions": list(choice.key), "selection": "auto",
             "criterion": CRITERION.format(penalty(), 2 * penalty()), "candidates": choice.table(),
             "screens": [], "steps": 0, "skipped": [], "note": ROADS_NOTE,
             "fits_better_rule": fits_better_rule("relative")}
    search = {} if choice.key == known else {"history": base.history, "nit": base.nit, "stop": base.stop,
                                             "message": base.message}
    return replace(res, model=model, adequacy=advise(res.adequacy, model),
                   nfev=sum(r.nfev for r in choice.results.values()), wall_time_s=time.perf_counter() - t0, **search)


def default_model(ds, model=None):
    """The model ``rideid.identify`` and ``rideid identify`` fit when none is named (SPEC §5 amended).

    ``model`` as given; without it (``None``) the dataset's ``[model]``
    extensions, else ``"auto"`` (SPEC §6).
    """
    if model is None:
        if ds.manifest.extensions is None:
            return "auto"
        refuse_unsupported_groups(ds.manifest.extensions, f"{ds.manifest.path}: [model] extensions")
        return tuple(ds.manifest.extensions)
    return model


def identify(ds, *, model=None, rng=None, seed=None, population: int = DEFAULT_POPULATION,
             generations: int = DEFAULT_GENERATIONS, weights: str = "adaptive", polish: bool = True,
             spread_tol: float | None = None, callback=None, cost: CostFunction | None = None, maps=None,
             start=None, assess: bool = True, simulator: Simulator | None = None, tracks: str = "as-built"):
    """Estimate the ride parameters of a dataset, choosing the model as ``rideid identify`` does (SPEC §5).

    The dispatch of the command line: runs on unknown roads (SPEC §9) are
    fitted with the road projected out (:mod:`rideid.estimate.fit.anyroad`);
    ``model="auto"`` fits the candidate models and keeps the one the data
    support (:func:`identify_auto`); any other model is fitted as given
    (:func:`rideid.estimate.fit.identify.identify`). The result carries the
    dataset's vehicle (for ``rideid export``).

    Parameters
    ----------
    ds : Dataset
        From :func:`rideid.load_dataset`.
    model : {None, "base", "full", "auto"} or sequence of group names
        The model (SPEC §6, §8): None takes the dataset's ``[model]``, else
        ``"auto"`` (:func:`default_model`); ignored when ``cost`` is given.
    rng : int, numpy.random.Generator or None
        Seed or generator of all randomness (same seed, same result).
    seed : int, optional
        The older name of ``rng``.
    population, generations : int
        JADE's population and generation limit.
    weights : {"adaptive", "fixed"}
        Adaptive track weights (paper eq. 12-13) or equal ones.
    polish : bool
        Refine the search's best with least squares (and the estimated starts).
    spread_tol : float, optional
        The search's early stop on the population's spread (default: 0.2 with
        the polish, 1e-5 without).
    callback : callable, optional
        ``callback(state)`` after each search generation; True stops the search.
    cost : CostFunction, optional
        A cost function of ``ds`` to fit (its parameter space is the model).
    maps : SensitivityMaps, optional
        Parameter -> track maps (default: computed around the nominal car).
    start : array_like, optional
        A free-parameter row to polish from, skipping the search.
    assess : bool
        Compute the adequacy verdict.
    simulator : Simulator, optional
        How the car is simulated, for every stage (backend, integration
        settings; :class:`rideid.model.simulator.Simulator`, default
        ``Simulator()``).
    tracks : {"as-built", "as-drawn"}
        SPEC §11: each declared track is the nominal shape of the road the
        car rolled over, its amplitude factor and unevenness fitted with the
        car (:mod:`rideid.estimate.problem.asbuilt`; a linear car with the eight
        accelerometers at a speed held, else the track is taken as
        drawn), or every track exactly as drawn.

    Returns
    -------
    IdentificationResult
        ``parameters`` (name -> value), ``details`` (each estimate's ``std``,
        ``std_robust``), the model kept and the adequacy verdict; ``plan``,
        ``settings`` and ``assessments`` (SPEC §13).

    Notes
    -----
    The dataset's ``[settings]`` (:mod:`rideid.settings`) are in force during
    the fit, over those set in Python; ``settings`` records every value used.
    """
    with settings.using(dataset_settings(ds)):
        res = _identify(ds, model=model, rng=rng, seed=seed, population=population, generations=generations,
                        weights=weights, polish=polish, spread_tol=spread_tol, callback=callback, cost=cost,
                        maps=maps, start=start, assess=assess, simulator=simulator, tracks=tracks)
        return with_records(ds, res)


def dataset_settings(ds) -> dict:
    """The ``[settings]`` of the dataset's ``dataset.toml`` (empty for a scenario or a dataset without)."""
    return dict(getattr(getattr(ds, "manifest", None), "settings", None) or {})


def with_records(ds, res):
    """``res`` with the typed records of SPEC §13 (:mod:`rideid.estimate.records`): the plan, the settings in
    force, the assessments (those that qualify an adequate verdict, a set-up value the data had to mend, written
    into ``adequacy`` as its caveats first: :func:`rideid.estimate.records.with_caveats`)."""
    res = with_caveats(res)
    return replace(res, plan=plan_of(res, [r.id for r in ds.runs]), settings=settings.current(),
                   assessments=assessments_of(res))


def _identify(ds, *, model, rng, seed, population, generations, weights, polish, spread_tol, callback, cost, maps,
              start, assess, simulator, tracks):
    """The body of :func:`identify` (the dataset's settings in force)."""
    if cost is None:
        model = default_model(ds, model)
    common = dict(rng=rng, seed=seed, population=population, generations=generations, weights=weights,
                  polish=polish, spread_tol=spread_tol, callback=callback, maps=maps, assess=assess)
    if tracks not in TRACK_OPTIONS:
        raise ArgumentError(f"tracks: expected one of {', '.join(TRACK_OPTIONS)}, got {tracks!r}")
    # the model asked for: a nonlinear one fits a moving run on a known track on its track (SPEC §9, a lead-in),
    # a linear one projects its road out with the unknown roads' (unknown_road_runs)
    asked = (cost.space.extensions if cost is not None else
             () if isinstance(model, str) and model == "auto" else model_extensions(ds, model))
    if cost is None and unknown_road_runs(ds, asked):  # SPEC §9: the road projected out (rideid.estimate.fit.anyroad)
        if isinstance(model, str) and model == "auto" and start is None:
            res = identify_auto_roads(ds, simulator=simulator, tracks=tracks, **common)
        else:
            res = identify_any_road(ds, model=model, start=start, simulator=simulator, tracks=tracks, **common)
    elif isinstance(model, str) and model == "auto" and cost is None:
        if start is not None:
            raise ArgumentError("start: the model choice fits every candidate from its own search; "
                                "give a model to polish from a start")
        res = identify_auto(ds, simulator=simulator, tracks=tracks, **common)
    else:
        res = identify_model(ds, model=model, cost=cost, start=start, simulator=simulator, **common)
    chosen = tuple((res.model or {}).get("extensions") or ())
    # not assessed (assess=False): no verdict to fault the drawing, so the tracks stay as drawn
    drawn_fits = res.adequacy is None or bool(res.adequacy.get("adequate"))
    if cost is None and polish and not drawn_fits and not unknown_road_runs(ds, chosen) \
            and as_built_runs(ds, chosen, tracks)[0]:
        # SPEC §11: the tracks as built, from the car fitted on them as drawn (estimate.problem.asbuilt), when the
        # drawing taken as exact leaves structure in the residuals (a drawing the data do not fault is kept: on an
        # exact track the as-built stage would only cost time)
        res = identify_any_road(ds, start_result=res, simulator=simulator, tracks=tracks, **common)
    elif cost is None and polish and not drawn_fits and not unknown_road_runs(ds) \
            and isinstance(model, str) and model == "auto":
        res = _tracks_before_curves(ds, res, chosen, simulator, tracks, common)
    res = replace(res, vehicle=dict(ds.vehicle))  # the geometry travels with the car (rideid export)
    # SPEC §12: every declared uncertainty propagated to the estimates (std_total, budget)
    res = with_budget(ds, res, simulator, cost)
    if assess and not unknown_road_runs(ds, chosen):  # SPEC §12: does the structure the residual test found matter?
        res = weigh_result(ds, res, simulator)
    if not drawn_fits:
        res = _drawing_caveat(ds, res, chosen, tracks)
    if res.adequacy is not None:  # SPEC §1 is small-angle: a body that turned degrees says which error bars to doubt
        sa = small_angle(res, {r.id: ds.data[r.id].fs for r in ds.runs if r.id in ds.data})
        if sa is not None:
            res = replace(res, adequacy={**res.adequacy, "small_angle": sa})
    warn_bounds(res)
    return res


def _drawing_caveat(ds, res, chosen, tracks):
    """``res`` with ``adequacy.tracks_caveat`` when the verdict is adequate only because the structure the
    residual test found, in setting ``model_choice.drawing_runs`` or more runs, was weighed immaterial
    (:mod:`rideid.estimate.assess.materiality`) while the tracks stayed as drawn: the as-built stage (SPEC §11) could
    not run or was rejected. Leaving the flagged pairs out cannot show a drawing error, which biases every run
    and channel alike: on the all-realities case (tracks 4 % off their drawing, a GPS speed channel) the
    weighing called 13 flagged pairs immaterial while k_tf was 12 % off, 2.8 std_total
    (tests/test_realities.py). The verdict stands; the statement says which numbers not to trust and why."""
    ad = res.adequacy
    if not ad or not ad.get("adequate") or not ad.get("structure"):
        return res
    runs = {pair.split("/")[0] for pair in (ad.get("materiality") or {}).get("pairs_left_out", [])}
    if len(runs) < defaults["model_choice.drawing_runs"]:  # local to one run, not a drawing's: the weighing judges it
        return res
    built = [t for t in (res.tracks or {}).values() if not t.get("rejected")]
    if built:
        return res
    rejected = [t["rejected"] for t in (res.tracks or {}).values() if t.get("rejected")]
    if rejected:
        why = "the as-built fit was rejected: " + rejected[0]
    else:
        skipped = as_built_runs(ds, chosen, tracks)[1]
        reasons = sorted(set(skipped.values()))
        why = "; ".join(reasons[:2]) if reasons else "no run could be fitted as built"
    caveat = ("the tracks were taken as drawn (" + why + ") while the residuals hold road-driven structure: a track "
              "off its drawing biases every run alike, which leaving the flagged pairs out cannot show, so every "
              "estimate may be off by more than its error bars; fit the tracks as built (SPEC §11: a linear model, "
              "all eight accelerometers, a roll rate, a speed held) or check the tracks' drawings")
    return replace(res, adequacy={**ad, "tracks_caveat": caveat})


@stage("tracks as built before curves")
def _tracks_before_curves(ds, res, chosen, simulator, tracks, common):
    """``--model auto`` kept a nonlinear group (damper curves, bump stops) on tracks taken as drawn, and the fit
    is still not adequate. A track built off its drawing leaves road-driven structure in every run that a damper
    curve's extra freedom partly absorbs (measured: a linear car on tracks 4 % off their drawing, auto kept curves
    bent by 8 % and stayed not adequate), and the tracks as built need a linear car (estimate.problem.asbuilt). So
    the linear part of the pick, polished from its own candidate, is fitted on the tracks as built; when that is
    adequate the drawing, not the dampers, was what the model missed, and that result is returned with the model
    choice's record and a note saying so. Otherwise ``res`` stands, with a line saying what was tried."""
    linear = tuple(g for g in chosen if g not in NONLINEAR_GROUPS)
    if linear == tuple(chosen) or not as_built_runs(ds, linear, tracks)[0]:
        return res
    cand = next((c for c in (res.model or {}).get("candidates", ()) if tuple(c["extensions"]) == linear), None)
    if cand is None:
        return res
    space = ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=linear)
    try:
        start = np.array([cand["parameters"][n] for n in space.names], dtype=float)
    except KeyError:
        return res
    kept = ", ".join(g for g in chosen if g in NONLINEAR_GROUPS)
    lin = identify_model(ds, model=list(linear) if linear else "base", start=start, simulator=simulator, **common)
    ab = identify_any_road(ds, start_result=lin, simulator=simulator, tracks=tracks, **common)
    rejected = any(rec.get("rejected") for rec in (getattr(ab, "tracks", None) or {}).values())
    label = " + ".join(linear) if linear else "base"
    if not rejected and (ab.adequacy or {}).get("adequate"):
        note = (f"on the tracks as drawn auto kept {kept}, not adequate; on the tracks as built the linear "
                f"model ({label}) is adequate, so the drawing, not the car, was what the model missed: {kept} "
                "dropped (docs/tracks-as-built.md)")
        model = dict(res.model, extensions=list(linear), as_drawn_choice=list(chosen), note=note)
        return replace(ab, model=model)
    ad = dict(res.adequacy or {})
    ad["reasons"] = list(ad.get("reasons", [])) + [
        f"tried: the linear model ({label}) on the tracks as built, not adequate either, so {kept} stays"]
    # SPEC §13: the speeds and starts that fit named are the data's whatever model stays: never silently dropped
    named = [c for c in (ab.checks or []) if c.get("check") == "motion"]
    if named:
        ad["reasons"].append("the set-up the tracks as built named: " + "; ".join(c["message"] for c in named))
    return replace(res, adequacy=ad, checks=list(res.checks or []) + named)


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "PENALTY": penalty, "PENALTY_LEVEL": "model_choice.penalty_level", "DRAWING_RUNS": "model_choice.drawing_runs"})
