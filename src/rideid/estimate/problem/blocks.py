"""The residual blocks of a fit with roads (SPEC §9, §11, §13): each block owns its nuisance unknowns.

A fit with unknown roads or tracks as built (:mod:`rideid.estimate.fit.anyroad`) is one least-squares problem
over the car's parameters whose residual is a list of blocks of three kinds, with one interface:

- :class:`DrawnTracks`: the runs on tracks taken as drawn, in the time domain
  (:class:`rideid.estimate.problem.cost.CostFunction`, the runs weighed alike);
- :class:`RoadBlock`: a run on an unknown road, the road projected out frequency by frequency
  (:mod:`rideid.estimate.problem.roadfit`; the state at the first sample and the road its nuisances);
- :class:`TrackBlock`: a run on a track as built (:mod:`rideid.estimate.problem.asbuilt`; the track's amplitude
  factor and unevenness its nuisances) and where the car was on it, the run's constant speed and start, each
  under its prior (SPEC §13; :class:`rideid.estimate.problem.asbuilt.MotionPrior`).

Each block gives its residuals at a car (:meth:`residuals`), whether the fit divides it by its own RMS
(``reweighted``: a track as built is whitened bin by bin already), its share of the sandwich's meat
(:meth:`meat`), its thread-scheduling key (``order``: the longest first) and its line of the polish's
``method``. A track block's motion is solved with the car: :meth:`TrackBlock.moved` places the drawing,
:meth:`TrackBlock.prior_rows` weighs the set-up's priors, :meth:`TrackBlock.motion_jacobian` gives the error
bars' columns (the start's placement before the solve, :func:`rideid.estimate.problem.asbuilt.align_motion`,
is the same block's cost minimised over its motion alone)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from . import asbuilt, roadfit
from ..fit.uncertainty import andrews_bandwidth, long_run_covariance, run_scores


def road_meat(J, e, m_per_bin: int) -> np.ndarray:
    """Sum over DFT bins of ``(J_k^T e_k)(J_k^T e_k)^T`` (each bin's rows one cluster)."""
    g = (J * e[:, None]).reshape(-1, m_per_bin, J.shape[1]).sum(axis=1)
    return g.T @ g


def track_meat(J, e, cf) -> np.ndarray:
    """The HAC long-run covariance of the gradient of the runs on tracks as drawn (``cf``), run by run."""
    blocks = [(int(e_ - s), int(np.count_nonzero(cf.W[ri] > 0)))
              for ri, (s, e_) in enumerate(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))]
    S = np.zeros((J.shape[1], J.shape[1]))
    for G in run_scores(J, e, blocks):
        S += long_run_covariance(G, andrews_bandwidth(G))
    return S


@dataclass(frozen=True)
class DrawnTracks:
    """The runs on tracks taken as drawn: the time-domain residuals of ``cf``, every run weighed alike."""

    cf: object
    reweighted = True
    rank = 2
    method = "runs on tracks as drawn in the time domain"

    @property
    def order(self) -> float:
        return -np.inf

    def residuals(self, x, P, geom) -> np.ndarray:
        n = len(self.cf.run_ids)
        return self.cf.residuals(x[None], np.full(n, 1.0 / n))[0]

    def meat(self, J, e, s2) -> np.ndarray:
        return track_meat(J, e, self.cf)


@dataclass(frozen=True)
class RoadBlock:
    """A run on an unknown road (or moving at its first sample): ``rr`` its
    :class:`rideid.estimate.problem.roadfit.RoadRun`; the meat the gradient's spread over DFT bins."""

    rr: roadfit.RoadRun
    reweighted = True
    rank = 0
    method = "road runs by frequency-domain variable projection (rideid.estimate.problem.roadfit)"

    @property
    def run_id(self) -> str:
        return self.rr.run_id

    @property
    def order(self) -> float:
        return -self.rr.fit.size

    def residuals(self, x, P, geom) -> np.ndarray:
        return roadfit.residuals(P, geom, self.rr)

    def meat(self, J, e, s2) -> np.ndarray:
        return road_meat(J, e, 2 * len(self.rr.cols))


@dataclass(frozen=True)
class TrackBlock:
    """A run on a track as built, ``tr`` (:class:`rideid.estimate.problem.asbuilt.TrackRun`), with where the car
    was on it: ``run`` (the manifest's run), ``prior`` (:class:`rideid.estimate.problem.asbuilt.MotionPrior`) and
    ``record`` (the motion as last placed or solved: ``speed_m_s``, ``start_shift_s``, ...; the result's
    ``motion``). The meat is the white one (:func:`rideid.estimate.problem.asbuilt.meat` says why)."""

    tr: asbuilt.TrackRun
    run: object
    prior: asbuilt.MotionPrior
    record: dict = field(default_factory=dict)
    reweighted = False
    rank = 1
    method = "runs on tracks as built (rideid.estimate.problem.asbuilt)"

    @property
    def run_id(self) -> str:
        return self.tr.run_id

    @property
    def rr(self) -> roadfit.RoadRun:
        """The run's channels as an unknown-road run (the road fit's view of it)."""
        return self.tr.rr

    @property
    def order(self) -> float:
        return -self.tr.fit.size

    def residuals(self, x, P, geom) -> np.ndarray:
        return asbuilt.residuals(P, geom, self.tr)

    def meat(self, J, e, s2) -> np.ndarray:
        return asbuilt.meat(J, e, self.tr, s2)

    def with_prior(self, P, geom) -> TrackBlock:
        """The block with its noise and unevenness levels estimated at the car ``P``
        (:func:`rideid.estimate.problem.asbuilt.estimate_prior`)."""
        return replace(self, tr=replace(self.tr, prior=asbuilt.estimate_prior(P, geom, self.tr)))

    def aligned(self, P, geom, ds, mode: str) -> TrackBlock:
        """The block placed at the car ``P`` by its motion alone (:func:`rideid.estimate.problem.asbuilt.align_motion`
        in ``mode``), its record the placement's."""
        tr, rec = asbuilt.align_motion(P, geom, self.tr, ds, self.run, mode, self.prior)
        return replace(self, tr=tr, record=rec)

    def moved(self, ds, p) -> TrackBlock:
        """The block with its drawing moved by ``p`` (the speed's relative change, the start's shift; setting
        ``asbuilt.motion_scale`` units), the tabulated inputs as they were."""
        return replace(self, tr=asbuilt.moved(self.tr, ds, self.run, p))

    def settled(self, ds) -> TrackBlock:
        """The block with its inputs tabulated at its speed and start, its record theirs."""
        tr = replace(self.tr, inputs=asbuilt.nominal_inputs(ds, self.run, self.tr.rr.speed, self.tr.shift))
        return replace(self, tr=tr, record=dict(self.record, speed_m_s=float(tr.rr.speed),
                                                start_shift_s=float(tr.shift)))

    def level(self, P, geom) -> float:
        """The RMS of the block's residual at the car ``P``: the weight its priors' rows take."""
        return float(np.sqrt(np.mean(asbuilt.residuals(P, geom, self.tr) ** 2)))

    def prior_rows(self, p, weight: float) -> np.ndarray:
        """The set-up priors' rows at the motion ``p`` moved from the block as it is placed."""
        return self.prior.rows(self.tr.rr.speed, self.tr.shift, p, weight)

    def motion_jacobian(self, P, geom, ds) -> np.ndarray:
        """(m, 2): the residuals' derivatives in the speed (relative) and the start shift (s)."""
        return asbuilt.motion_jacobian(P, geom, self.tr, ds, self.run)

    def prior_jacobian(self, weight: float) -> np.ndarray:
        """(rows, 2): the priors' rows' derivatives in the speed (relative) and the start shift (s)."""
        return self.prior.jacobian(self.tr.rr.speed, weight)


def method(blocks) -> str:
    """The polish's ``method``: the kinds of ``blocks``, unknown roads, tracks as built, tracks as drawn."""
    return "joint: " + ", ".join(m for _, m in sorted({(b.rank, b.method) for b in blocks}))


__all__ = ["DrawnTracks", "RoadBlock", "TrackBlock", "road_meat", "track_meat", "method"]
