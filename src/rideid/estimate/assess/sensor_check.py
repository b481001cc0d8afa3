"""What the sensor chain may have done that the dataset does not say (SPEC §11 "Sensors as wired").

**An undeclared AC coupling.** An IEPE accelerometer is AC-coupled: it
records the channel high-passed at about 0.5 Hz. A dataset that does not
declare it (``[channels] <name> highpass = ...``) is fitted by a car whose
parameters absorb the coupling (measured on the built-in car with its four
hub sensors coupled at 0.5 Hz: unsprung masses and tire rates off by several
per cent, with error bars that do not cover it). Its signature in the fit:
the identified car's channel, passed through a first-order high-pass of some
corner between 0.1 and 2 Hz, matches the data markedly better than the
channel itself. :func:`coupling_hints` tries those corners on every channel
without a declared high-pass, over all runs at once, and names a channel
whose residual sum of squares falls by at least setting ``sensor_check.hint_reduction``; a
car fitted to data that are not coupled loses by any such filter (it removes
the body's low-frequency motion the data hold). On runs whose road is fitted
(tracks as built, unknown roads) :func:`road_coupling_hints` does the same
with the road free instead of a simulation.

**Clipping.** Samples at a channel's range are left out of the fit; when
the model is still not adequate on the channels that clipped,
:func:`clipping_advice` says so (a sensor near its range also distorts, and
the detected rail may not be the only one).
"""

from __future__ import annotations

import numpy as np

from ...profiling import stage
from ...settings import defaults, legacy_names
from ...model.batch import single_threaded_blas, thread_map
from ...model.equations import CHANNELS
from ...model.sensors import AnalogFilter, SensorChain
from ..problem import roadfit


def coupling_hints(cf, response: dict) -> list[dict]:
    """Channels whose data look AC-coupled without a declared ``highpass`` (module docstring).

    Parameters
    ----------
    cf : CostFunction
        The fit's cost function (its data, channel weights and kept samples).
    response : dict
        run id -> ``(n_time, 10)``: the identified car's channels as the declared chain records them
        (:meth:`CostFunction.simulate`).

    Returns
    -------
    list of dict
        ``{"channel", "highpass_hz", "rss_reduction", "message"}`` per channel named, largest reduction first.
    """
    ds = cf.ds
    hints = []
    for c, name in enumerate(CHANNELS):
        rows = []
        for ri, rid in enumerate(cf.run_ids):
            if cf.W[ri, c] <= 0 or any(f.kind == "highpass" for f in ds.sensor_filters(rid)[c]):
                continue
            s, e = cf.sim.run_start[ri], cf.sim.run_start[ri + 1]
            keep = np.ones(e - s) if cf.keep is None else cf.keep[s:e, c]
            rows.append((ri, rid, cf.Y[s:e, c], response[rid][:, c], keep, cf.W[ri, c]))
        if not rows:
            continue
        rss0 = sum(w * np.sum(k * (yh - y) ** 2) for _, _, y, yh, k, w in rows)
        if not rss0 > 0:
            continue
        best = (0.0, None)
        for hz in defaults["sensor_check.hint_corners"]:
            rss = 0.0
            for ri, _rid, y, yh, k, w in rows:
                chain = SensorChain(((AnalogFilter("highpass", hz),),), cf.sim.runs[ri].h)
                yf = chain.apply(yh[:, None])[:, 0]
                rss += w * np.sum(k * (yf - y) ** 2)
            red = 1.0 - rss / rss0
            if red > best[0]:
                best = (red, hz)
        red, hz = best
        if hz is not None and red >= defaults["sensor_check.hint_reduction"]:
            hints.append({"channel": name, "highpass_hz": hz, "rss_reduction": float(red),
                          "message": (f"{name}: the data look AC-coupled (an IEPE sensor?): the fit of this channel "
                                      f"improves {100 * red:.0f} % when the model's channel passes a {hz:g} Hz "
                                      f"high-pass; declare the sensor's coupling, `[channels] {name} = {{ ..., "
                                      f"highpass = {hz:g} }}` (its data sheet's corner), and identify again")})
    hints.sort(key=lambda h: -h["rss_reduction"])
    return hints


#: the groups of accelerometers a road fit's coupling hint tries together (a test's hub sensors are alike)
ROAD_HINT_GROUPS = (CHANNELS[4:8], CHANNELS[0:4])


@stage("road hints")
def road_coupling_hints(P, geom, rruns, filters, threshold: float | None = None) -> list[dict]:
    """Channels whose data look AC-coupled without a declared ``highpass``, on runs whose road is fitted
    (:mod:`rideid.estimate.problem.roadfit`; tracks as built, :mod:`rideid.estimate.problem.asbuilt`).

    The time-domain hint (:func:`coupling_hints`) compares a simulation with the data; a fitted road has none
    to compare. Here the identified car ``P`` is projected onto each run with its road free
    (:func:`rideid.estimate.problem.roadfit.residuals`, the drawing unused), once as the channels are declared and
    once with a trial first-order high-pass added to a group of channels (the four hub accelerometers, the
    four body accelerometers; then each accelerometer alone at setting ``sensor_check.road_hint_single``): a group whose
    trial cuts the summed squared residual of every run by ``threshold`` (setting ``sensor_check.hint_reduction``; on
    unknown roads setting ``sensor_check.free_road_hint_reduction``) or more is named. Measured
    on the SUV's five runs on tracks as built (4 % off, 1.5 mm), hubs coupled at 0.5 Hz and not declared, at
    the as-built fit (k_sf +21 %): the hubs at 0.5 Hz cut it by 78 %, the best corner tried (one hub alone:
    16-19 %; the body group: worse); at the true car 100 %. The same runs without coupling, or with it
    declared: every trial makes it 5-18 times larger.

    ``rruns``: :class:`rideid.estimate.problem.roadfit.RoadRun` with their declared chains; ``filters``: run id -> the
    dataset's ``sensor_filters``. Returns the hints as :func:`coupling_hints` does, the group's channels each
    named with the group's corner and reduction."""
    threshold = defaults["sensor_check.hint_reduction"] if threshold is None else threshold
    if not rruns:
        return []
    declared = {rr.run_id: [tuple(f) for f in filters[rr.run_id]] for rr in rruns}

    def total(extra: dict) -> float:
        tot = 0.0
        for rr in rruns:
            chain = list(declared[rr.run_id])
            for c, hz in extra.items():
                chain[c] = chain[c] + (AnalogFilter("highpass", hz),)
            e = roadfit.residuals(P, geom, roadfit.with_sensors(rr, tuple(chain)))
            tot += float(e @ e)
        return tot

    def free(names):  # the group's channels every run fits and none declares a high-pass of
        idx = [CHANNELS.index(n) for n in names]
        return [c for c in idx if all(c in rr.cols and not any(f.kind == "highpass" for f in declared[rr.run_id][c])
                                      for rr in rruns)]

    trials = [(tuple(free(g)), defaults["sensor_check.hint_corners"]) for g in ROAD_HINT_GROUPS]
    trials += [((c,), defaults["sensor_check.road_hint_single"]) for c in free(CHANNELS[:8])]
    # every trial (and the declared chain, first) is independent: side by side (rideid.model.batch.thread_map),
    # BLAS on one thread, the best taken in the trials' order, so one or two cores give the same hint
    tried = [{}] + [{c: hz for c in group} for group, corners in trials if group for hz in corners]
    with single_threaded_blas():
        totals = thread_map(total, tried, "rideid-hints")
    base = totals[0]
    if not base > 0:
        return []
    best = (0.0, None, ())
    for extra, tot in zip(tried[1:], totals[1:]):
        red = 1.0 - tot / base
        if red > best[0]:
            best = (red, next(iter(extra.values())), tuple(extra))
    red, hz, group = best
    if hz is None or red < threshold:
        return []
    names = [CHANNELS[c] for c in group]
    others = " (and the same for " + ", ".join(names[1:]) + ")" if len(names) > 1 else ""
    message = (f"{', '.join(names)}: the data look AC-coupled (IEPE sensors?): the road fit of the runs improves "
               f"{100 * red:.0f} % when the model's {'channels pass' if len(names) > 1 else 'channel passes'} a "
               f"{hz:g} Hz high-pass; declare the sensors' coupling, `[channels] {names[0]} = {{ ..., highpass = "
               f"{hz:g} }}`{others} (their data sheet's corner), and identify again")
    return [{"channel": name, "highpass_hz": hz, "rss_reduction": float(red), "message": message} for name in names]


def clipping_advice(ds, adequacy: dict | None) -> str | None:
    """One sentence when the not-adequate verdict's flagged run/channel pairs are channels that reached their
    range (the preprocessing records clipped samples there); None otherwise."""
    if not adequacy or adequacy.get("adequate", True):
        return None
    clipped = []
    for rid, rec in (adequacy.get("runs") or {}).items():
        mr = ds.measured.get(rid)
        if mr is None:
            continue
        for name, fig in rec.items():
            info = mr.record.get("channels", {}).get(name, {}).get("clipped")
            if fig.get("structure") and info:
                clipped.append(f"{rid}/{name} ({100 * info['share']:.1f} % of its samples at the range)")
    if not clipped:
        return None
    return ("Flagged pairs whose sensor clipped: " + ", ".join(clipped[:6]) + ". Samples at the range are left out "
            "of the fit, but a sensor driven to its range distorts near it too: declare the sensor's full scale "
            "(`[channels] <name> range = ...`), use a sensor with a larger range, or leave those runs out.")


def rate_advice(ds, adequacy: dict | None) -> str | None:
    """One sentence when the not-adequate verdict's flagged run/channel pairs are channels rideid low-passed or
    interpolated to the model's rate (the dataset's :attr:`~rideid.data.dataset.Dataset.resampled`: a rate the
    model's does not divide, or ``anti_alias = true``), naming the rate that takes every sample as it is; None
    otherwise."""
    if not adequacy or adequacy.get("adequate", True):
        return None
    hit, fix = [], set()
    for rid, rec in (adequacy.get("runs") or {}).items():
        res = ds.resampled.get(rid)
        if res is None:
            continue
        flagged = [name for name, fig in rec.items() if fig.get("structure") and name in res["channels"]]
        if flagged:
            hit.append(f"{rid} ({'/'.join(f'{r:g}' for r in res['file_rates_hz'])} Hz read at {res['fs']:g} Hz)")
            fix.add(res["divides"])
    if not hit:
        return None
    rate = (f"set [preprocess] fs = {'/'.join(f'{r:g}' for r in sorted(fix))} (or leave fs out: rideid then "
            "chooses a rate the file's divides)")
    return ("Flagged pairs of runs low-passed or interpolated to the model's rate: " + ", ".join(hit[:6]) + "; the "
            "model reproduces that filter only roughly at this rate (docs/real-data.md, Rates and filters): " + rate
            + ".")


def sensor_notes(ds, cf, response, adequacy: dict | None) -> dict | None:
    """``adequacy`` with ``sensor_hints`` (channels that look AC-coupled without a declared ``highpass``,
    :func:`rideid.estimate.assess.sensor_check.coupling_hints`) and, when not adequate, advice that names them and
    the clipped channels among the flagged pairs first (:func:`rideid.estimate.assess.sensor_check.clipping_advice`);
    None when the adequacy was not assessed. ``cf`` and ``response``: the fit's cost function at its final starts
    and the identified car's channels."""
    if adequacy is None:
        return None
    hints = coupling_hints(cf, response)
    out = {**adequacy, "sensor_hints": hints}
    if not adequacy.get("adequate", True):
        first = [h["message"] + "." for h in hints[:4]]
        clip = clipping_advice(ds, adequacy)
        if clip:
            first.append(clip)
        rate = rate_advice(ds, adequacy)  # a rate the file's is no whole multiple of: its filter, roughly modelled
        if rate:
            first.append(rate)
        if first:
            out["advice"] = " ".join(first) + " " + (adequacy.get("advice") or "")
    return out



__all__ = ["clipping_advice", "coupling_hints", "rate_advice", "sensor_notes"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "HINT_CORNERS": "sensor_check.hint_corners", "HINT_REDUCTION": "sensor_check.hint_reduction",
    "ROAD_HINT_SINGLE": "sensor_check.road_hint_single", "FREE_ROAD_HINT_REDUCTION":
    "sensor_check.free_road_hint_reduction"})
