"""Which candidate runs carry the information about a powertrain on mounts (SPEC §11, group ``powertrain``).

The plan's precision table covers the powertrain's seven parameters like any other free parameter (the Fisher
information of :mod:`rideid.design.fisher`, sensitivities through the simulator). This module
says where that information comes from, per candidate run:

- ``share``: the run's share of the candidates' Fisher information about each powertrain parameter alone
  (the diagonal of ``F_r`` in relative coordinates over its sum over the candidates; the others held known, as the
  sensitivity-map comparison does);
- ``loss_without``: the factor by which the parameter's CRLB from all candidates grows when this run is left out
  (the others free: the measure that counts correlations);
- ``input_hz``: the fundamental frequency of a periodic track's road input, ``speed / wavelength`` (washboard,
  herringbone); ``None`` for other roads;
- ``band_energy``: the fraction of the road input's rate power (``r'``, summed over the four wheels, over the run)
  in the band of the powertrain's modes, ``[0.8 f_lo, 1.25 f_hi]`` with ``f_lo``, ``f_hi`` the lower and higher
  of the whole car's two powertrain modes (:func:`rideid.model.equations.modal_summary`, body free).

A run carries the powertrain's information when it is among the fewest runs (largest shares first) that together
hold :data:`CARRY` of the candidates' information about ``f_pb`` or about ``f_pp``.
"""

from __future__ import annotations

import numpy as np

from ..model.equations import POWERTRAIN_MODES, modal_summary
from ..model.params import INDEX, POWERTRAIN_NAMES
from .fisher import precision

#: the runs that together hold this fraction of the information about f_pb (or f_pp) carry the powertrain's
CARRY = 0.9
#: the modes' band: from this factor times the lower powertrain mode to ``BAND[1]`` times the higher one
BAND = (0.8, 1.25)
#: the parameters whose shares the terminal prints
SHOWN = ("f_pb", "f_pp", "m_p")


def band_energy(rate: np.ndarray, h: float, band) -> float:
    """Fraction of the power of ``rate`` ((n, 4) road-input rates, m/s, sample interval ``h``) in ``band`` (Hz),
    summed over the wheels (one-sided periodogram of the whole run, mean removed)."""
    r = np.asarray(rate, float)
    r = r - r.mean(0)
    P = (np.abs(np.fft.rfft(r, axis=0)) ** 2).sum(1)
    f = np.fft.rfftfreq(r.shape[0], h)
    tot = P[1:].sum()
    if tot <= 0:
        return 0.0
    m = (f >= band[0]) & (f <= band[1])
    return float(P[m].sum() / tot)


def input_frequency(track, speed) -> float | None:
    """The fundamental frequency (Hz) of a periodic track's road input at ``speed``: ``speed / wavelength``."""
    if track is None or speed is None or track.kind not in ("washboard", "herringbone"):
        return None
    return float(speed) / float(track.keys["wavelength"])


def loss_without(F: np.ndarray, idx) -> np.ndarray:
    """(R, len(idx)): the CRLB of parameters ``idx`` from all runs of ``F`` (R, d, d) but run r, over the CRLB
    from all runs (inf where leaving the run out makes the parameter unidentifiable, NaN where it is not
    identifiable from all runs; identifiability as :func:`rideid.design.fisher.precision` decides it)."""
    d = F.shape[1]

    def crlb(M):
        return precision(M, M, M, [""] * d, np.ones(d)).rel_crlb[idx]

    base = crlb(F.sum(0))
    with np.errstate(invalid="ignore"):
        out = np.array([crlb(F.sum(0) - F[r]) / base for r in range(F.shape[0])])
    out[:, ~np.isfinite(base)] = np.nan
    return out


def powertrain_block(names, P0, geom, F, runs, tracks, speeds, run_ids, selected) -> dict | None:
    """plan.json ``"powertrain"``: the modes, and per candidate run the shares, leave-one-out losses, input
    frequency and band energy (module docstring); ``None`` when no powertrain parameter is free.

    ``F``: (R, d, d) Fisher information per run (relative coordinates, the nominal car); ``runs``: the runs'
    :class:`rideid.model.simulate.RunInput` (None for a run without one); ``tracks``, ``speeds``: each run's track
    (or None) and speed (m/s);
    ``selected``: indices of the selected runs.
    """
    pt = [n for n in POWERTRAIN_NAMES if n in names]
    if not pt:
        return None
    idx = [names.index(n) for n in pt]
    modes = modal_summary(P0, geom)
    fm = [modes[m]["frequency_hz"] for m in POWERTRAIN_MODES if m in modes]
    band = (BAND[0] * min(fm), BAND[1] * max(fm))
    diag = np.stack([np.diag(Fr)[idx] for Fr in F])  # (R, k)
    share = diag / np.maximum(diag.sum(0, keepdims=True), 1e-300)
    loss = loss_without(F, idx)
    carriers = set()
    for n in ("f_pb", "f_pp"):
        if n in pt:
            s = share[:, pt.index(n)]
            order = np.argsort(-s)
            k = int(np.searchsorted(np.cumsum(s[order]), CARRY - 1e-12)) + 1
            carriers |= set(order[:k].tolist())
    out_runs = []
    for r, rid in enumerate(run_ids):
        ri = runs[r]
        out_runs.append({
            "id": rid,
            "input_hz": input_frequency(tracks[r], speeds[r]),
            "band_energy": None if ri is None else band_energy(ri.rate, ri.h, band),
            "share": {n: float(share[r, j]) for j, n in enumerate(pt)},
            "loss_without": {n: (float(loss[r, j]) if np.isfinite(loss[r, j]) else None) for j, n in enumerate(pt)},
            "carries": r in carriers})
    sel = list(selected)
    return {
        "modes_hz": {m: float(modes[m]["frequency_hz"]) for m in POWERTRAIN_MODES if m in modes},
        "mounts_hz": {n: float(P0[INDEX[n]]) for n in ("f_pb", "f_pp")},
        "band_hz": [float(band[0]), float(band[1])],
        "runs": out_runs,
        "carriers": [run_ids[r] for r in sorted(carriers)],
        "selected_share": {n: float(share[sel, j].sum()) for j, n in enumerate(pt)},
        "method": ("share: the run's share of the candidates' Fisher information about the parameter alone (the "
                   "diagonal of F_r in relative coordinates; the others known); loss_without: the factor by which "
                   "the parameter's CRLB from all candidates grows without the run (the others free); input_hz: a "
                   "periodic track's speed / wavelength; band_energy: the fraction of the road input's rate power "
                   f"(four wheels) within band_hz = [{BAND[0]:g} x the lower, {BAND[1]:g} x the higher] of the whole "
                   f"car's powertrain modes; carries: among the fewest runs holding {CARRY:.0%} of the information "
                   "about f_pb or f_pp"),
    }


#: a note when the selected runs hold less than this share of the candidates' information about f_pb or f_pp
THIN = 0.5


def selection_note(block: dict, selected_ids) -> list:
    """A note when the selected runs hold under :data:`THIN` of the candidates' information about ``f_pb`` or
    ``f_pp``, naming the unselected run with the largest share (the budget or criterion left it out)."""
    if not block:
        return []
    thin = [n for n in ("f_pb", "f_pp") if n in block["selected_share"] and block["selected_share"][n] < THIN]
    if not thin:
        return []
    rest = [r for r in block["runs"] if r["id"] not in set(selected_ids)]
    best = max(rest, key=lambda r: sum(r["share"][n] for n in thin)) if rest else None
    held = ", ".join(f"{100 * block['selected_share'][n]:.3g} % ({n})" for n in thin)
    add = (f"; {best['id']} holds " + ", ".join(f"{100 * best['share'][n]:.3g} %" for n in thin)
           + ": add it, or a run whose road input lies near the powertrain's modes") if best else ""
    return [f"powertrain: the selected runs hold only {held} of all candidates' information about its mounts{add}"]


def _share(v: float) -> str:
    """A share in per cent: one decimal, or three significant digits below 0.1 %."""
    return f"{100 * v:.1f} %" if v >= 1e-3 else f"{100 * v:.2g} %"


def summary_lines(block: dict, selected_ids) -> list:
    """The terminal's lines: the modes, and per run the shares of f_pb, f_pp, m_p."""
    if not block:
        return []
    modes = ", ".join(f"{m.split()[-1]} {v:.2f} Hz" for m, v in block["modes_hz"].items())
    lo, hi = block["band_hz"]
    shown = [n for n in SHOWN if n in block["runs"][0]["share"]]
    lines = [f"powertrain: whole-car modes {modes} (mounts f_pb {block['mounts_hz']['f_pb']:g}, f_pp "
             f"{block['mounts_hz']['f_pp']:g} Hz); share of the information about "
             f"{', '.join(shown)} per run (band {lo:.1f}-{hi:.1f} Hz energy of the road input):"]
    for r in block["runs"]:
        f = "" if r["input_hz"] is None else f", input {r['input_hz']:.3g} Hz"
        e = "" if r["band_energy"] is None else f", band energy {100 * r['band_energy']:.3g} %"
        mark = " carries" if r["carries"] else ""
        lines.append(f"  {r['id']:8s} " + " ".join(f"{n} {_share(r['share'][n]):>8s}" for n in shown)
                     + f"{f}{e}{mark}")
    sel = block["selected_share"]
    lines.append(f"powertrain: the runs carrying its information: {', '.join(block['carriers'])}; the selected runs "
                 f"hold " + ", ".join(f"{100 * sel[n]:.0f} % of {n}'s" for n in shown))
    return lines
