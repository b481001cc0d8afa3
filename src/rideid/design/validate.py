"""Monte Carlo check of a plan: simulate the planned runs with noise, identify, compare spreads.

Used by ``benchmarks/study_plan.py`` and the slow tests; see ``docs/planning.md``.
"""

from __future__ import annotations

import dataclasses
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ..conditioning.load import load_dataset
from ..estimate.fit.identify import identify
from ..synth.scenario import simulate_manifest, write_dataset
from ..estimate.problem.cost import CostFunction, channel_weights
from ..data.noise import sensor_noise


def sub_scenario(sc, run_ids):
    """The scenario restricted to ``run_ids`` (in the scenario's order)."""
    keep = [r for r in sc.runs if r.id in set(run_ids)]
    return dataclasses.replace(sc, runs=keep)


def gauss_newton_from_truth(ds, names, x0, step: float = 1e-5) -> np.ndarray:
    """One Gauss-Newton step from ``x0`` on identify's own cost of dataset ``ds``.

    At small noise identify's least-squares polish converges to this point:
    the linearised estimator whose spread the plan predicts.
    """
    cf = CostFunction(ds)
    if list(cf.names) != list(names):
        raise ValueError(f"free parameters differ: {cf.names} vs {names}")
    x0 = np.asarray(x0, dtype=float)
    d, h = x0.size, step * x0
    R = cf.residuals(np.vstack([x0, x0 + np.diag(h), x0 - np.diag(h)]))
    J = ((R[1:1 + d] - R[1 + d:]) / (2 * h[:, None])).T
    return x0 - np.linalg.lstsq(J, R[0], rcond=None)[0]


def monte_carlo(sc, run_ids, names, noise: float, seeds, identify_kw=None, progress=None,
                linearised: bool = False, noise_ar1: float = 0.0):
    """Identify ``len(seeds)`` noisy simulations of the runs ``run_ids``.

    Each seed ``s`` draws the noise with ``simulate_manifest(seed=s)`` (SPEC
    ``--noise``: fraction of each channel's RMS; ``noise_ar1``: AR(1) in time
    with that coefficient, as ``simulate --noise-ar1``) and runs
    :func:`rideid.identify` with ``seed=s``.

    Returns
    -------
    ndarray (n_seeds, len(names))
        The estimates of ``names``; with ``linearised`` also the
        :func:`gauss_newton_from_truth` estimates on the same data.
    """
    sub = sub_scenario(sc, run_ids)
    out = np.zeros((len(seeds), len(names)))
    lin = np.zeros_like(out)
    x_true = np.array([sc.truth[n] for n in names])
    with tempfile.TemporaryDirectory() as tmp:
        for k, s in enumerate(seeds):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                data, _ = simulate_manifest(sub, noise=noise, seed=int(s), noise_ar1=noise_ar1)
            folder = Path(tmp) / f"s{s}"
            write_dataset(sub, data, folder)
            ds = load_dataset(folder)
            res = identify(ds, seed=int(s), **(identify_kw or {}))
            out[k] = [res.parameters[n] for n in names]
            if linearised:
                lin[k] = gauss_newton_from_truth(ds, names, x_true)
            if progress is not None:
                progress(k + 1, len(seeds), out[k])
    return (out, lin) if linearised else out


def linearised_monte_carlo(sc, run_ids, names, noise: float, seeds, step: float = 1e-5,
                           noise_ar1: float = 0.0) -> np.ndarray:
    """:func:`gauss_newton_from_truth` for many seeds without writing a dataset per seed.

    The runs are simulated once without noise and identify's cost is
    linearised once at the truth; each seed then draws exactly the noise that
    ``simulate_manifest(noise=noise, seed=s, noise_ar1=noise_ar1)`` adds (same
    generator, same order: run by run, :func:`rideid.data.noise.sensor_noise`,
    white or AR(1), times ``noise`` times each channel's noise-free RMS), recomputes identify's channel
    weights from the noisy data (:func:`rideid.estimate.problem.cost.channel_weights`)
    and takes the Gauss-Newton step. About 10 ms a seed for the ten built-in
    runs, so thousands of seeds pin the spread of the estimator the plan
    predicts to ~1 % (the sampling sd of a ratio of standard deviations from
    ``n`` seeds is ``1 / sqrt(2 (n - 1))``). Where identify converges to the
    linearised estimate (:func:`monte_carlo` with ``linearised=True`` checks
    it seed by seed), this is the spread of identify's estimates.

    Returns
    -------
    ndarray (n_seeds, len(names))
        The same numbers as ``monte_carlo(..., linearised=True)[1]`` (to
        round-off and the 12 significant digits of the run files).
    """
    sub = sub_scenario(sc, run_ids)
    with tempfile.TemporaryDirectory() as tmp:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data, _ = simulate_manifest(sub, noise=0.0)
        write_dataset(sub, data, Path(tmp) / "clean")
        cf = CostFunction(load_dataset(Path(tmp) / "clean"))
    if list(cf.names) != list(names):
        raise ValueError(f"free parameters differ: {cf.names} vs {names}")
    x0 = np.array([sc.truth[n] for n in names], dtype=float)
    d, h = x0.size, step * x0
    outs = cf.sim.outputs(cf.space.full(np.vstack([x0, x0 + np.diag(h), x0 - np.diag(h)])))
    order = [cf.run_ids.index(r.id) for r in sub.runs]  # simulate_manifest draws in scenario order
    bounds = list(zip(cf.sim.run_start[:-1], cf.sim.run_start[1:]))
    clean = [data[r.id][1] for r in sub.runs]
    rms = [np.sqrt(np.mean(y * y, axis=0)) for y in clean]
    # per run: d(model)/dx (d, n, 10), J^T J per channel (10, d, d), J^T (model - data) per channel (10, d)
    J = [(o[1:1 + d] - o[1 + d:]) / (2 * h[:, None, None]) for o in outs]
    G = [np.einsum("itc,jtc->cij", Jr, Jr) for Jr in J]
    g0 = [np.einsum("itc,tc->ci", Jr, o[0] - cf.Y[a:b]) for Jr, o, (a, b) in zip(J, outs, bounds)]
    out = np.zeros((len(seeds), d))
    for k, s in enumerate(seeds):
        rng = np.random.default_rng(int(s))
        A, g = np.zeros((d, d)), np.zeros(d)
        for i, ri in enumerate(order):
            a, b = bounds[ri]
            e = sensor_noise(rng, clean[i].shape, noise_ar1) * (noise * rms[i])[None, :]
            S = cf.weights[ri] * channel_weights(cf.Y[a:b] + e)  # squared residual scale per channel
            A += np.einsum("c,cij->ij", S, G[ri])
            g += S @ g0[ri] - np.einsum("c,itc,tc->i", S, J[ri], e)
        out[k] = x0 - np.linalg.solve(A, g)
    return out


def spread_ratio(estimates: np.ndarray, truth: np.ndarray, predicted_std: np.ndarray) -> dict:
    """Observed spread vs prediction, per parameter.

    ``sd``: sample standard deviation (ddof 1); ``rmse``: root mean square
    error about the truth; ``ratio``: sd / predicted; ``bias_in_sd``: mean
    error over the standard error of the mean (|.| < 3 expected).
    """
    e = np.asarray(estimates, float)
    sd = e.std(axis=0, ddof=1)
    rmse = np.sqrt(np.mean((e - truth[None]) ** 2, axis=0))
    bias = (e.mean(0) - truth) / (sd / np.sqrt(e.shape[0]))
    return {"sd": sd, "rmse": rmse, "ratio": sd / predicted_std, "rmse_ratio": rmse / predicted_std,
            "bias_in_sd": bias}
