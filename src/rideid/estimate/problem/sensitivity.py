"""Response and track prioritisation maps (paper §4.3).

* **Parameter -> response** ``S[p, c, r]``: each parameter raised by 25 %
  one at a time (``a`` too, capped at 95 % of the wheelbase), the percentage
  change of the peak ``max_k |y_c|`` of channel ``c`` on run ``r``. A channel
  a run does not excite (peak below 0.1 % of the largest peak of its kind on
  that run) gives no value (the paper's ⌀). Averaged over runs (mean of the
  absolute values) it is the paper's Table 5, ``S_bar[p, c]``.
* **Response -> track** ``R[c, r]``: how strongly run ``r`` excites channel
  ``c``: its RMS on the run divided by the largest RMS of that channel over
  all runs (0..1).
* **Parameter -> track** ``M[p, r] = sum_c S_bar[p, c] R[c, r]``, each row
  normalised to sum 1: the share of parameter ``p``'s information carried by
  each run. The adaptive weights use it (paper eq. 13).

Star ratings (documented thresholds):

* parameter -> response, ``|% change|``: ⌀ < 1, ★ 1-5, ★★ 5-15, ★★★ >= 15;
* response -> track, ``R``: ⌀ < 0.05, ★ 0.05-0.25, ★★ 0.25-0.6, ★★★ >= 0.6;
* parameter -> track, ``M * n_runs`` (1 = an equal share): ⌀ < 0.25,
  ★ 0.25-0.75, ★★ 0.75-1.5, ★★★ >= 1.5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...profiling import stage
from ...settings import defaults, legacy_names
from ...data.dataset import Dataset
from ...data.scenario import scenario_run_input
from ...errors import ArgumentError
from ...model.batch import BatchSimulator
from ...model.equations import CHANNEL_KIND, CHANNELS
from ...model.params import ALL_NAMES, Geometry, as_vector
from .cost import CostFunction

P2R_STARS = (1.0, 5.0, 15.0)
R2T_STARS = (0.05, 0.25, 0.6)
P2T_STARS = (0.25, 0.75, 1.5)


def stars(value, thresholds) -> str:
    if value is None or not np.isfinite(value):
        return "⌀"
    n = sum(value >= t for t in thresholds)
    return "★" * n if n else "⌀"


@dataclass
class SensitivityMaps:
    params: list[str]
    channels: list[str]
    runs: list[str]
    S: np.ndarray        # (p, c, r) % change of peak, NaN where not excited
    S_bar: np.ndarray    # (p, c)
    R: np.ndarray        # (c, r)
    M: np.ndarray        # (p, r), rows sum to 1
    baseline: np.ndarray  # (12,) or (16,) with the extensions

    def submap(self, names) -> np.ndarray:
        """Rows of ``M`` for the given parameter names."""
        return self.M[[self.params.index(n) for n in names]]


def compute_maps(sim: BatchSimulator, geom: Geometry, baseline, run_ids, channel_mask=None) -> SensitivityMaps:
    """Compute the three maps around ``baseline`` (12 parameters, or 16 with the extensions of SPEC §6).

    ``channel_mask`` (n_runs, 10) bool marks the channels measured per run
    (default: all). An extension at 0 in the baseline is raised from 0 to
    nothing and gets an all-zero row: give the baseline a typical value
    (:data:`rideid.model.params.NOMINAL_EXTENSIONS`).
    """
    base = np.asarray(baseline, dtype=float).reshape(-1)
    names = ALL_NAMES[:base.size]
    P = np.tile(base, (base.size + 1, 1))
    for i, n in enumerate(names):
        v = base[i] * (1 + defaults["sensitivity.step"])
        if n == "a":
            v = min(v, 0.95 * geom.wheelbase)
        P[1 + i, i] = v
    outs = sim.outputs(P)
    n_runs = len(outs)
    if channel_mask is None:
        channel_mask = np.ones((n_runs, len(CHANNELS)), bool)
    peaks = np.stack([np.abs(o).max(axis=1) for o in outs], axis=-1)  # (1 + p, c, r)
    rms = np.stack([np.sqrt(np.mean(o[0] ** 2, axis=0)) for o in outs], axis=-1)  # (c, r)
    excited = np.zeros((len(CHANNELS), n_runs), bool)
    for ci, c in enumerate(CHANNELS):
        same = [j for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c]]
        excited[ci] = peaks[0, ci] > 1e-3 * peaks[0, same].max(axis=0)
    excited &= channel_mask.T
    with np.errstate(divide="ignore", invalid="ignore"):
        S = 100.0 * (peaks[1:] - peaks[0][None]) / peaks[0][None]
    S = np.where(excited[None], S, np.nan)
    # mean over the runs that excite the channel; 0 where none does (one run whose channel stays still: no warning)
    n_exc = np.sum(~np.isnan(S), axis=2)
    S_bar = np.nansum(np.abs(S), axis=2) / np.maximum(n_exc, 1)
    rms = np.where(excited, rms, 0.0)
    mx = rms.max(axis=1, keepdims=True)
    R = np.divide(rms, mx, out=np.zeros_like(rms), where=mx > 0)
    M = S_bar @ R
    rs = M.sum(axis=1, keepdims=True)
    M = np.divide(M, rs, out=np.full_like(M, 1.0 / n_runs), where=rs > 0)
    return SensitivityMaps(list(names), list(CHANNELS), list(run_ids), S, S_bar, R, M, base)


def cost_maps(cf: CostFunction) -> SensitivityMaps:
    """The three maps of a cost function's runs around the nominal car of its parameter space
    (:meth:`rideid.ParameterSpace.nominal`), over the channels each run measures."""
    baseline = cf.space.nominal()
    return compute_maps(cf.sim, cf.space.geometry, baseline, cf.run_ids, cf.W > 0)


@stage("sensitivity maps")
def sensitivity_maps(source, *, cost=None) -> SensitivityMaps:
    """The three maps of a dataset or a scenario (``rideid sensitivity``).

    Parameters
    ----------
    source : Dataset or Scenario
        A dataset: maps around the nominal car of its parameter space
        (:meth:`rideid.ParameterSpace.nominal`), over its measured channels.
        A scenario (a manifest with ``[truth]``): around the truth, all channels.
    cost : CostFunction, optional
        A cost function of the dataset to reuse its prepared runs.

    Returns
    -------
    SensitivityMaps
    """
    if isinstance(source, Dataset) or cost is not None:
        return cost_maps(cost if cost is not None else CostFunction(source))
    if not getattr(source, "truth", None):
        raise ArgumentError("sensitivity_maps: give a Dataset or a scenario with [truth]")
    runs = [scenario_run_input(source, r, i) for i, r in enumerate(source.runs)]
    return compute_maps(BatchSimulator(source.geometry, runs), source.geometry, as_vector(source.truth),
                        [r.id for r in source.runs])


__all__ = ["compute_maps", "cost_maps", "sensitivity_maps", "SensitivityMaps"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "STEP": "sensitivity.step"})
