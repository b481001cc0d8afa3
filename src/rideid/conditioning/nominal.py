"""The nominal responses: a car simulated on request, every request of a round in one batch.

The analyses of conditioning (start estimation, :mod:`.starts`; the checks,
:mod:`.checks`) are written as *steps*: generators that yield the
simulations they need (a list of :class:`Job`) and receive the responses
back, and return their result. They never run the model themselves.
:func:`run_steps` is the one place that does: it takes the requests of
every pending step, simulates them together (the inputs of the jobs
prepared on parallel threads, then the :class:`rideid.model.simulator.Simulator` it is
given, bound to all of them), hands every step its responses, and goes on until all
have returned. :func:`gather` runs many steps side by side (every run of a
dataset, every start candidate of a run), so a round simulates what all of
them need at once; a step whose next simulation depends on a result (the
response at an estimated start) asks for it in a later round.

A response is the one the job simulated alone gives
(:func:`rideid.model.simulate.prepare_run`, then the batch simulator), bit for
bit; only the order and the grouping of the simulations change.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..model import backend
from ..model.batch import single_threaded_blas, thread_map
from ..model.contact import envelope_grid
from ..model.simulate import ENVELOPE_DX, prepare_run
from ..model.simulator import Simulator


class Job(NamedTuple):
    """One simulation of the car: on ``track`` at the model times ``t`` (s, uniform), at constant ``speed``
    (m/s) or along ``distance`` (a vectorised x(t), m), at rest at ``t[0]``, or ``lead_in`` s before it
    (SPEC §9, a moving start)."""

    track: object
    t: np.ndarray
    speed: float | None
    distance: object = None
    lead_in: float = 0.0


def _grid(job: Job) -> tuple[np.ndarray, int]:
    """``(t, k)``: the job's model times with ``k`` samples of lead-in ahead of ``job.t``."""
    t = np.asarray(job.t, dtype=float)
    k = int(np.ceil(job.lead_in / (t[1] - t[0]) - 1e-9)) if job.lead_in > 0 else 0
    if k:
        t = np.concatenate([t[0] + (t[1] - t[0]) * np.arange(-k, 0), t])
    return t, k


def _prefetch_envelopes(jobs, geom) -> None:
    """Tabulate every wheel path's envelope on parallel threads, the longest first (with one thread: nothing
    ahead; :func:`rideid.model.simulate.prepare_run` tabulates them as it goes)."""
    if backend.threads() < 2:
        return
    paths = {}
    for job in jobs:
        for y in geom.corner_y:
            p = job.track.path(y)
            if p.extent is not None:
                paths[id(p)] = p
    if len(paths) < 2:
        return

    def envelope(p):
        envelope_grid(p, geom.tire_radius, ENVELOPE_DX)

    thread_map(envelope, sorted(paths.values(), key=lambda p: -(p.extent[1] - p.extent[0])), "rideid-inputs")


def simulate_jobs(P, geom, jobs: list[Job], simulator: Simulator | None = None) -> list:
    """The response ``(n, 10)`` of the car ``P`` (one row of ``simulator``'s model, or of the linear car;
    None: the nominal car :meth:`rideid.model.simulator.Simulator.nominal`) for every job, in one batch,
    simulated by ``simulator`` (default the linear car, ``Simulator()``).

    The jobs' inputs are prepared on parallel threads
    (:func:`rideid.model.batch.thread_map`), then simulated together. A job
    whose inputs cannot be made (a distance profile that does not reach,
    say) gives its exception in its place: the step that asked raises it
    (:func:`responses`).
    """
    grids = [_grid(job) for job in jobs]
    _prefetch_envelopes(jobs, geom)

    def inputs(i):
        job = jobs[i]
        try:
            return prepare_run(job.track, geom, job.speed, grids[i][0], distance=job.distance), grids[i][1]
        except Exception as e:  # noqa: BLE001 - handed to the step that asked
            return e

    prepared = thread_map(inputs, range(len(jobs)), "rideid-inputs")
    ok = [p for p in prepared if not isinstance(p, Exception)]
    simulator = Simulator() if simulator is None else simulator
    car = simulator.nominal(geom) if P is None else simulator.row(P)
    outs = iter(simulator.bind(geom, [ri for ri, _ in ok]).outputs(np.atleast_2d(car)) if ok else [])
    return [p if isinstance(p, Exception) else next(outs)[0][p[1]:] for p in prepared]


def responses(got: list) -> list:
    """The responses a step received, or the first job's exception raised."""
    for r in got:
        if isinstance(r, Exception):
            raise r
    return got


def gather(steps):
    """A step running ``steps`` side by side; returns their results, in order.

    Every round asks for what all pending steps ask for, together. A step
    that raises stops the whole as the same steps run one after the other
    would: once every step before it has returned, with its exception.
    """
    steps = list(steps)
    results: list = [None] * len(steps)
    failed: dict[int, Exception] = {}
    pending: dict[int, list] = {}

    def advance(i, got):
        try:
            jobs = next(steps[i]) if got is None else steps[i].send(got)
        except StopIteration as stop:
            results[i] = stop.value
        except Exception as e:  # noqa: BLE001 - raised below, in the order of the steps
            failed[i] = e
        else:
            pending[i] = list(jobs)

    def advance_all(moves):
        # the steps are independent (each its own run or candidate): their work between simulations side by side
        # (rideid.model.batch.thread_map), BLAS on one thread however many workers, so the same numbers on one
        # or two cores
        with single_threaded_blas():
            thread_map(lambda move: advance(*move), moves, "rideid-steps")

    advance_all([(i, None) for i in range(len(steps))])
    while True:
        first_failed = min(failed, default=len(steps))
        order = [i for i in sorted(pending) if i < first_failed]
        if not order:
            break
        got = yield [job for i in order for job in pending[i]]
        ends = np.cumsum([0] + [len(pending[i]) for i in order])
        for i in order:
            del pending[i]
        advance_all([(i, got[a:b]) for i, a, b in zip(order, ends[:-1], ends[1:])])
    for g in steps:
        g.close()
    if failed:
        raise failed[min(failed)]
    return results


def run_steps(step, geom, car=None, simulator: Simulator | None = None):
    """Run a step to its end, simulating what it asks for with the car ``car`` (one row of ``simulator``'s
    model, or of the linear car; default the nominal car) by ``simulator`` (default the linear car,
    ``Simulator()``); returns the step's result."""
    got = None
    while True:
        try:
            jobs = next(step) if got is None else step.send(got)
        except StopIteration as stop:
            return stop.value
        got = simulate_jobs(car, geom, jobs, simulator)


__all__ = ["Job", "gather", "responses", "run_steps", "simulate_jobs"]
