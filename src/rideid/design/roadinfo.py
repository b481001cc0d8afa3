"""Information of candidate runs on unknown roads (SPEC §9): ``rideid plan`` with ``road_class`` runs.

A candidate run on a road nobody will measure is given by its ISO 8608
class (``road_class``), speed, sample rate and duration. Its precision is
predicted from the road fit identify runs on it
(:mod:`rideid.estimate.problem.roadfit`, frequency-domain variable projection):

1. *Roads.* :data:`ROADS` roads of the class are generated
   (:func:`rideid.data.scenario.generate_road`, the run's coherence): the
   first with the plan's ``seed`` (the road ``rideid simulate --seed SEED``
   drives), the others with seeds derived from it. A run with a
   ``road_seed`` has one road, that one.
2. *Data.* The plan's car drives each road as ``rideid simulate`` would
   (a moving start after its lead-in), without noise: ``y0``.
3. *Jacobian.* ``J = d e / d u`` of the road fit's residual
   (:func:`rideid.estimate.problem.roadfit.residuals`, relative coordinates
   ``u = x / x0``) at the true car, by central differences. With noise-free
   data the residual is zero there and ``J = dP_perp y0`` has no noise term,
   so ``J^T J`` is the expected Hessian of the concentrated cost (the noise
   parts of ``J^T J`` and of the residual's curvature cancel in expectation:
   :meth:`rideid.estimate.problem.joint.JointProblem.hessian`).
4. *Noise in DFT units.* The fit weights channel ``c`` by ``s_c`` (one over
   its measured RMS) and takes an unnormalised ``rfft``; white noise of
   standard deviation ``sigma_c`` gives each real and each imaginary
   residual component at a bin inside the band the variance
   ``v_c = N sigma_c^2 s_c^2 / 2`` (``N`` samples; the projection removes
   noise only along ``J``'s orthogonal complement, so the gradient's
   variance is ``J^T diag(v) J``: verified by ``tests/test_plan_roads.py``).
   Coloured noise (AR(1), a spectrum) multiplies ``v`` by the normalised
   spectrum ``r_c(f_k)`` at each bin.
5. *Matrices.* Identify's fit on its weights: ``A = J^T J``,
   ``B = J^T diag(v) J`` (sandwich ``A^-1 B A^-1``); the Fisher information
   ``F = J_w^T diag(1 / v_w) J_w`` of the whitened fit (channels weighted by
   ``1 / sigma_c``, ``v_w = N r_c / 2``; with ``--noise`` alone ``sigma_c s_c``
   is nearly one number and ``A^-1 B A^-1`` equals ``F^-1`` to 1e-4). With a coloured spectrum the
   bins are weighted after the projection, not inside it (the boundary
   unknowns couple bins): an approximation of the whitened fit.
   Each is the mean over the roads (the expected information).

Combining with the track runs: the information adds (runs have independent
noise). For identify's spread, the joint fit weights the road run's block by
one over its residual RMS (:mod:`rideid.estimate.fit.anyroad`, step 2), so its
``A`` and ``B`` enter divided by ``vbar`` and ``vbar^2`` (``vbar`` the mean
of ``v``), times the track runs' noise level ``c = tr(B) / tr(A)`` of the
track candidates and ``c^2`` (the units of the track runs' matrices; with no
track candidate ``c = 1``). When the noise is a fraction of each channel's
RMS (the default), the ISO class changes nothing: signal and noise scale
alike with the road's level (the classes share the spectrum's shape); with
noise densities, a rougher road buys precision.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..data.scenario import generate_road, lead_in, road_seed, run_times
from ..errors import ArgumentError
from ..estimate.problem import roadfit
from ..model.equations import CHANNEL_KIND, CHANNELS
from ..model.simulate import prepare_run, simulate_reference
from .colour import ar1_psd
from .fisher import SILENT, Information

#: roads generated per unknown-road candidate (their information averaged); 1 for a run with a road_seed
ROADS = 2
#: relative finite-difference step of the road fit's residual (the residual is linear in the data and smooth in
#: the parameters: central differences at 1e-4 and 1e-5 agree to 1e-6 relative in J^T J)
ROAD_STEP = 1e-4


@dataclass
class RoadRunInformation(Information):
    """One unknown-road candidate's information about the free parameters, per car.

    ``F``, ``A``, ``B`` (n_cars, d, d) in relative coordinates; ``A`` and ``B`` already divided by the
    block's mean component variance ``vbar`` and ``vbar^2`` (module docstring); ``sigma``, ``rms``, ``used`` (10,)
    of the first road and car; ``seeds`` the roads' seeds."""

    seeds: list


def road_seeds(run, index: int, seed: int) -> list:
    """Seeds of the :data:`ROADS` roads of candidate ``run`` (position ``index``) for the plan's ``seed``."""
    if run.road.seed is not None:
        return [int(run.road.seed)]
    out = [road_seed(run, index, seed)]
    for j in range(1, ROADS):
        out.append(int(np.random.SeedSequence([int(seed), int(index), j, 8608]).generate_state(1, np.uint32)[0]))
    return out


def road_outputs(sc, run, road_seed_value: int, P) -> np.ndarray:
    """Noise-free channels (n, 10) of cars ``P`` (n_cars, 16) on the generated road of ``run`` with seed
    ``road_seed_value``, simulated as ``rideid simulate`` does (moving start after the lead-in)."""
    r = replace(run, road=replace(run.road, seed=int(road_seed_value)))
    road = generate_road(sc, r, 0)
    t = run_times(r)
    k0 = int(np.ceil(lead_in(sc, r) * r.fs - 1e-9))
    tt = np.arange(-k0, t.size) / r.fs if k0 else t
    ri = prepare_run(road.track(), sc.geometry, r.speed, tt)
    return simulate_reference(np.atleast_2d(P), sc.geometry, ri)[:, k0:]


def _live(rms, sigma) -> np.ndarray:
    kinds = np.array([CHANNEL_KIND[c] for c in CHANNELS])
    live = np.zeros(len(CHANNELS), bool)
    for k in set(kinds):
        m = kinds == k
        live[m] = rms[m] > SILENT * rms[m].max() if rms[m].max() > 0 else False
    return live & (sigma > 0)


def _spectrum_shape(noise, fs: float, f: np.ndarray, cols) -> np.ndarray:
    """Normalised two-sided noise spectrum ``r_c(f)`` (K, c) (mean 1 over 0..fs/2; ones for white noise)."""
    if noise.ar1 > 0:
        r = ar1_psd(noise.ar1, fs, f) * fs / 2
        return np.repeat(r[:, None], len(cols), axis=1)
    if noise.psd is not None:
        p = noise.psd.at(f)[:, cols]
        return p / noise.psd.variance(fs)[cols][None, :] * fs / 2
    return np.ones((f.size, len(cols)))


def residual_jacobian(space, x0, geom, rr, step: float = ROAD_STEP) -> np.ndarray:
    """``d e / d u`` (m, d) of :func:`rideid.estimate.problem.roadfit.residuals` at the car ``x0`` (free parameters),
    ``u = x / x0``, by central differences."""
    x0 = np.asarray(x0, dtype=float)
    d = x0.size
    E = np.eye(d) * (step * x0)[None, :]
    P = space.full(np.vstack([x0 + E, x0 - E]))
    if not space.valid(P).all():
        raise ArgumentError("the nominal car is too close to a physical limit for finite differences")
    cols = [(roadfit.residuals(P[j], geom, rr) - roadfit.residuals(P[d + j], geom, rr)) / (2 * step)
            for j in range(d)]
    return np.stack(cols, axis=1)


def _prepared(run_id, y, fs, speed, geom, cols, scale):
    """A :class:`rideid.estimate.problem.roadfit.RoadRun` of noise-free ``y`` with the channel weights ``scale``."""
    rr = roadfit.prepare_road_run(run_id, y, fs, speed, geom, cols=cols)
    yc = y[:, cols] - y[:, cols].mean(axis=0)
    return replace(rr, scale=np.asarray(scale, float), Y=np.fft.rfft(yc * scale, axis=0))


def road_run_information(sc, space, cars, run, index: int, noise, seed: int,
                         step: float = ROAD_STEP) -> RoadRunInformation:
    """:class:`RoadRunInformation` of the unknown-road candidate ``run`` (position ``index`` in the scenario)
    for each car of ``cars`` (free-parameter vectors), averaged over its roads (module docstring)."""
    geom = sc.geometry
    seeds = road_seeds(run, index, seed)
    d = len(space.names)
    F = np.zeros((len(cars), d, d))
    A = np.zeros_like(F)
    B = np.zeros_like(F)
    meta = None
    Pc = space.full(np.asarray(cars, dtype=float))
    for s in seeds:
        Y = road_outputs(sc, run, s, Pc)
        for k, x in enumerate(cars):
            y = Y[k]
            n = y.shape[0]
            rms = np.sqrt(np.mean(y * y, axis=0))
            sig = noise.sigma(rms, run.fs)
            live = _live(rms, sig)
            cols = np.nonzero(live)[0]
            yc = y[:, cols] - y[:, cols].mean(axis=0)
            # identify's weights: one over the measured RMS (signal and noise)
            s_id = 1.0 / np.sqrt(np.mean(yc ** 2, axis=0) + sig[cols] ** 2)
            rr = _prepared(run.id, y, run.fs, run.speed, geom, cols, s_id)
            J = residual_jacobian(space, x, geom, rr, step)
            f = rr.fit * run.fs / n
            shape = _spectrum_shape(noise, run.fs, f, cols)                                    # (K, c)
            v = 0.5 * n * (sig[cols] * s_id)[None, :] ** 2 * shape                             # (K, c)
            v = np.concatenate([v, v], axis=1).ravel()                                          # bin-major, re|im
            a = J.T @ J
            b = J.T @ (v[:, None] * J)
            vbar = float(np.mean(v))
            # the whitened fit: channels weighted by 1 / sigma (nearly identify's with --noise alone, where
            # sigma_c s_c is one number but for the channels' means, which the fit removes)
            Jw = residual_jacobian(space, x, geom, _prepared(run.id, y, run.fs, run.speed, geom, cols,
                                                             1.0 / sig[cols]), step)
            vw = np.concatenate([shape, shape], axis=1).ravel() * 0.5 * n
            F[k] += Jw.T @ (Jw / vw[:, None]) / len(seeds)
            A[k] += a / vbar / len(seeds)
            B[k] += b / vbar ** 2 / len(seeds)
            if meta is None:
                meta = (sig, rms, live)
    return RoadRunInformation(F, A, B, *meta, seeds)
