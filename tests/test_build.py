"""The problem built up front (rideid.estimate.problem.build) and the fit pipeline that reads it.

The single-model fit (:func:`rideid.estimate.fit.identify.identify`) builds one frozen :class:`Problem` from the
dataset and its options, then runs search -> nonlinear start -> polish -> result blocks on it; these tests pin
what the problem says (which model is searched, which is fitted, where a given start goes, the plan) and that
the result's blocks follow from it. The built-in car, noise-free (the ``sim_dataset`` fixture); every fit here
is a short search without polish (about 2 s in all on two shared cores).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import rideid
from rideid.errors import ArgumentError
from rideid.estimate.fit.identify import RESULT_BLOCKS, identify
from rideid.estimate.problem.build import (build_problem, curve_start, fit_settings, linear_start,
                                           model_extensions)
from rideid.estimate.records import plan_of
from rideid.settings import defaults


def _settings(**kw):
    opts = dict(population=8, generations=3, weights="adaptive", polish=True, spread_tol=None, assess=True)
    return fit_settings(**{**opts, **kw})


def test_settings_are_checked_and_defaulted_when_built():
    assert _settings().spread_tol == defaults["identify.spread_tol"] == 0.2
    assert _settings(polish=False).spread_tol == defaults["identify.spread_tol_no_polish"] == 1e-5
    assert _settings(spread_tol=0.0).spread_tol == 0.0
    assert _settings().weighting.name == "adaptive" and _settings(weights="fixed").weighting.name == "fixed"
    with pytest.raises(ArgumentError, match="generations must be a positive integer, got 0"):
        _settings(generations=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        _settings().polish = False


def test_a_linear_problem_searches_and_fits_one_model(sim_dataset):
    ds = rideid.load_dataset(sim_dataset)
    p = build_problem(ds, _settings(), model="full")
    assert p.search is p.cost is p.start_cost and p.begin is linear_start and not p.nonlinear
    assert p.cost.names == rideid.CostFunction(ds, extensions=model_extensions(ds, "full")).names
    assert p.cost.names[-4:] == ["k_arf", "k_arr", "c_tf", "c_tr"]
    assert p.search_generations == 3 and p.started({"x": 1, "stop": "spread"}) == {"x": 1, "stop": "spread"}
    x0 = np.ones(len(p.cost.names))
    given = build_problem(ds, _settings(), model="base", start=x0[:10])
    assert given.search_generations == 0
    assert given.started({"x": None, "stop": "generations"}).stop == "start"
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.start = x0
    with pytest.raises(ArgumentError, match="model='auto' is the model choice"):
        build_problem(ds, _settings(), model="auto")


def test_damper_curves_are_searched_on_the_linear_car_and_fitted_on_the_knee_grid(sim_dataset):
    """No [model] damper_knots: the curves are fitted on setting dampers.knee_grid; the search runs on the
    linear car (c_sf, c_sr free, no knot force); a start of the curve model's own width keeps its knots."""
    ds = rideid.load_dataset(sim_dataset)
    p = build_problem(ds, _settings(), model=["damper_curves"])
    assert p.nonlinear and p.begin is curve_start and p.start_cost is p.search
    assert "c_sf" in p.search.names and not any(n.startswith("F_") for n in p.search.names)
    assert tuple(p.cost.space.damper_knots) == tuple(defaults["dampers.knee_grid"])
    n_knots = 4 * len(defaults["dampers.knee_grid"])  # two axles, each in bump and rebound
    assert sum(n.startswith("F_") for n in p.cost.names) == n_knots
    width = len(rideid.CostFunction(ds, extensions=("damper_curves",)).names)  # the default knots' model
    own = build_problem(ds, _settings(), model=["damper_curves"], start=np.ones(width))
    assert own.start_cost is own.cost and own.cost.space.damper_knots is None


def test_the_plan_is_the_problem_and_the_blocks_follow_it(sim_dataset):
    """The plan built up front is the one read back from the result (records.plan_of); the result's blocks of
    RESULT_BLOCKS are None where the problem has no such part (no assessment asked, no curves, no stops)."""
    ds = rideid.load_dataset(sim_dataset)
    res = identify(ds, seed=1, population=8, generations=1, polish=False, assess=False, model="full")
    assert res.plan == plan_of(res, [r.id for r in ds.runs])
    car = res.plan.blocks[0]
    assert car.unknowns == res.names and "k_arf" in car.unknowns and car.runs == [r.id for r in ds.runs]
    assert "total_mass" in car.fixed and len(res.plan.blocks) == 1  # no start estimated on SPEC CSV
    assert [b[0] for b in RESULT_BLOCKS] == ["adequacy", "dampers", "velocities", "bump_stops", "modal"]
    assert res.adequacy is res.dampers is res.velocities is res.bump_stops is None
    assert res.modal is not None and res.polish is None and np.isnan(res.std).all()
    assert res.message == "Maximum number of generations reached."
