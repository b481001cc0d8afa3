"""Monte Carlo check of a plan: simulate the planned runs with noise, identify, compare spreads.

Used by ``benchmarks/study_plan.py`` and the slow tests; see ``docs/planning.md``.
"""

from __future__ import annotations

import dataclasses
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ..data.dataset import load_dataset
from ..estimate.identify import identify
from ..data.scenario import simulate_manifest, write_dataset


def sub_scenario(sc, run_ids):
    """The scenario restricted to ``run_ids`` (in the scenario's order)."""
    keep = [r for r in sc.runs if r.id in set(run_ids)]
    return dataclasses.replace(sc, runs=keep)


def gauss_newton_from_truth(ds, names, x0, step: float = 1e-5) -> np.ndarray:
    """One Gauss-Newton step from ``x0`` on identify's own cost of dataset ``ds``.

    At small noise identify's least-squares polish converges to this point:
    the linearised estimator whose spread the plan predicts.
    """
    from ..estimate.cost import CostFunction
    cf = CostFunction(ds)
    if list(cf.names) != list(names):
        raise ValueError(f"free parameters differ: {cf.names} vs {names}")
    x0 = np.asarray(x0, dtype=float)
    d, h = x0.size, step * x0
    R = cf.residuals(np.vstack([x0, x0 + np.diag(h), x0 - np.diag(h)]))
    J = ((R[1:1 + d] - R[1 + d:]) / (2 * h[:, None])).T
    return x0 - np.linalg.lstsq(J, R[0], rcond=None)[0]


def monte_carlo(sc, run_ids, names, noise: float, seeds, identify_kw=None, progress=None,
                linearised: bool = False):
    """Identify ``len(seeds)`` noisy simulations of the runs ``run_ids``.

    Each seed ``s`` draws the noise with ``simulate_manifest(seed=s)`` (SPEC
    ``--noise``: fraction of each channel's RMS) and runs
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
                data, _ = simulate_manifest(sub, noise=noise, seed=int(s))
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
