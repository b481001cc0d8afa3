"""The identified car's responses on a dataset's runs: what the report and the notebook figures draw.

:func:`rideid.identify` computes them with the fit (``result.response``, run id
-> ``(n_time, 10)``; with damper curves ``result.velocities``, run id ->
``(front, rear)`` suspension velocities for the report's histograms). A
result read back from ``result.json`` has neither: :func:`complete`
simulates them once, with the result's own model (the curves' car for a
result with damper curves, the linear car otherwise), before the report is
written. The report itself never simulates.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...data.scenario import LIFT_OFF_RHO
from ...model.params import ALL_NAMES, as_vector
from ...model.simulator import Simulator
from ..problem.cost import CostFunction, ParameterSpace, bind_runs
from ..problem import roadfit
from ..problem.dampers import suspension_velocities_by_run


def simulate_runs(dataset, parameters: dict, simulator: Simulator | None = None) -> dict:
    """The response of the linear car ``parameters`` on every run of ``dataset``, as the runs' declared sensor
    chains record it (SPEC §11): run id -> (n_time, 10)."""
    sim = bind_runs(Simulator() if simulator is None else simulator.linear(), dataset)
    outs = sim.outputs(as_vector(parameters)[None])
    return {r.id: o[0] for r, o in zip(dataset.runs, outs)}


def curve_car(result, dataset, simulator: Simulator | None = None):
    """A cost function of ``dataset`` on the curve model of ``result`` and the identified car's full row."""
    knots = [v for v in result.dampers["velocity"] if v > 0]
    ext = (result.model or {}).get("extensions") or ["damper_curves"]
    space = ParameterSpace(dataset.known, dataset.geometry, dataset.manifest.bounds, extensions=ext,
                           damper_knots=knots)
    cf = CostFunction(dataset, space=space, simulator=simulator)
    return cf, space.full(np.array([[result.parameters[n] for n in space.names]]))[0]


def curve_responses(result, dataset, simulator: Simulator | None = None) -> dict:
    """The response of the identified car with damper curves (the nonlinear simulator) on every run:
    run id -> (n_time, 10); what :func:`simulate_runs` gives a linear result."""
    cf, P = curve_car(result, dataset, simulator)
    return {r.id: o[0] for r, o in zip(dataset.runs, cf.sim.outputs(P[None]))}


def suspension_velocities(cf: CostFunction, P) -> dict:
    """Run id -> ``(front, rear)`` suspension velocities (m/s, compression +, both corners of the axle) of
    car ``P`` (a full row of ``cf.space``, with damper curves) on each run of ``cf``
    (:func:`rideid.estimate.problem.dampers.suspension_velocities_by_run`, the excitation check's, at the looser
    sub-step bound :data:`rideid.data.scenario.LIFT_OFF_RHO`: a histogram needs no more)."""
    return {rid: v for rid, v in zip(cf.run_ids, suspension_velocities_by_run(cf, P, rho=LIFT_OFF_RHO))}


def result_suspension_velocities(result, dataset, simulator: Simulator | None = None) -> dict:
    """:func:`suspension_velocities` of the identified car with damper curves on ``dataset``'s runs."""
    return suspension_velocities(*curve_car(result, dataset, simulator))


def run_velocities(result, dataset, simulator: Simulator | None = None) -> dict:
    """Run id -> ``(front, rear)`` suspension velocities of every run of ``dataset`` for a result with damper curves,
    as the fit read them: on a known road the identified car's (:func:`result_suspension_velocities`), on an unknown
    road the measured ones, read off its body and axle accelerometers
    (:func:`rideid.estimate.problem.roadfit.suspension_velocities`, :func:`rideid.estimate.fit.road_curves.velocities`);
    a road run without all eight of those channels has none."""
    known = [r for r in dataset.runs if dataset.road_known(r.id)]
    sim = result_suspension_velocities(result, dataset.subset(known), simulator) if known else {}
    out = {}
    for r in dataset.runs:
        if r.id in sim:
            out[r.id] = sim[r.id]
            continue
        run = dataset.data[r.id]
        y = run.matrix()
        if not roadfit.missing_corners(y):
            v = roadfit.suspension_velocities(y, run.fs)
            out[r.id] = (v[:, :2].ravel(), v[:, 2:].ravel())
    return out


def _matches(per_run: dict | None, dataset, rows: bool = True) -> bool:
    """``per_run`` holds every run of ``dataset`` (with ``rows``: each with the run's number of samples)."""
    if per_run is None or set(per_run) != {r.id for r in dataset.runs}:
        return False
    return not rows or all(len(per_run[r.id]) == len(dataset.data[r.id].time) for r in dataset.runs)


def complete(result, dataset, simulator: Simulator | None = None):
    """``result`` with its response (and with damper curves its suspension velocities) on ``dataset``'s runs:
    the result's own where it has them for exactly these runs and samples, else simulated here.

    Returns a new result (``result`` is not changed)."""
    response, velocities = result.response, getattr(result, "velocities", None)
    curves = bool(getattr(result, "dampers", None))
    if not _matches(response, dataset):
        # the result's own where a run has it (a road it estimated: unknown roads, tracks as built, read back
        # from road/<run>.response.csv), the rest simulated
        own = {r.id: response[r.id] for r in dataset.runs if response and r.id in response
               and len(response[r.id]) == len(dataset.data[r.id].time)}
        missing = [r for r in dataset.runs if r.id not in own]
        rest = dataset if not own else (dataset.subset(missing) if missing else None)
        sim = {} if rest is None else (curve_responses(result, rest, simulator) if curves else simulate_runs(
            rest, {n: result.parameters[n] for n in ALL_NAMES if n in result.details}, simulator))
        response = {r.id: own[r.id] if r.id in own else sim[r.id] for r in dataset.runs}
    if curves and not _matches(velocities, dataset, rows=False):
        velocities = run_velocities(result, dataset, simulator)
    return replace(result, response=response, velocities=velocities)


__all__ = ["complete", "curve_car", "curve_responses", "result_suspension_velocities", "run_velocities",
           "simulate_runs", "suspension_velocities"]
