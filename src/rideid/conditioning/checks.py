"""The data checks that run the model: every conditioned run of a dataset against a nominal car.

:func:`check_dataset` is the one hook, called once every run of a dataset is
conditioned and aligned (:func:`rideid.conditioning.load.align_starts`):
coverage of the track, the wiring of the channels (rigid body and road
assignment, :func:`rideid.data.checks.wiring_fix`), the units seen in a
logger's lead-in or in the axle amplitudes, and the match of each run with its
track and speed. The checks themselves are pure functions over numbers and
arrays (:mod:`rideid.data.checks`); this module simulates the nominal car
they compare the data with (:func:`rideid.model.params.nominal_car`).
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from ..data.checks import (ERROR, MATCH_MIN, PLAUSIBLE, WARNING, Finding, axle_amplitude_findings, check_coverage,
                           corrected, describe_fix, fix_entries, match_finding, speed_candidates, unit_findings,
                           wiring_fix)
from ..data.measured import Distance, RelativeDistance
from ..data.schema.channels import SI, UNITS, quantity
from ..model.batch import thread_map
from ..model.contact import envelope_grid
from ..model.equations import CHANNELS
from ..model.params import nominal_car
from ..model.simulate import ENVELOPE_DX, PREPARED_MAX, prepare_run
from .starts import correlation_score, estimate_start, simulate_response

#: a moving run's nominal response starts at rest this long (s) before the first sample: the nominal car's
#: slowest mode decays to 1e-3 in 2.4-2.7 s on the built-in car, the SUV and the van of the tests
#: (rideid.data.scenario.settle_time)
NOMINAL_LEAD_IN = 5.0


def _map_entries(ds, rid) -> dict:
    """SPEC channel -> {name, unit, sign, scale} as the run was read."""
    mr = ds.measured.get(rid)
    if mr is not None:
        return {c: dict(name=e["source"], unit=e["unit"], sign=e["sign"], scale=e["scale"], file_unit=e.get("file_unit"))
                for c, e in mr.record["channels"].items() if c in CHANNELS}
    return {c: dict(name=c, unit=SI[quantity(c)], sign=1, scale=1.0) for c in ds.data[rid].channels}


def _entry_factors(entries: dict) -> np.ndarray:
    """(10,) factor (unit x sign x scale) each SPEC channel was read with (1 where missing)."""
    F = np.ones(len(CHANNELS))
    for i, c in enumerate(CHANNELS):
        e = entries.get(c)
        if e is not None:
            u = UNITS[quantity(c)].get(str(e["unit"]).strip().replace(" ", "").lower(), 1.0)
            F[i] = u * e["sign"] * e["scale"]
    return F


def _level(ds, rid, check) -> str:
    lv = dict(getattr(ds.manifest, "checks", {}) or {})
    run = ds.manifest.run(rid)
    lv.update(getattr(run, "checks", {}) or {})
    return lv.get(check, "error")


def _nominal_response(P, geom, track, t, speed, distance, moving: bool = False):
    return simulate_response(P, geom, track, t, speed, distance, lead_in=NOMINAL_LEAD_IN if moving else 0.0)


def _score(Y, Yhat):
    cols = [i for i in range(len(CHANNELS)) if not np.all(np.isnan(Y[:, i]))]
    return correlation_score(Yhat, np.nan_to_num(Y, nan=0.0), cols)


def _alternatives(ds, rid, P, rho_now):
    """(description, correlation) of the run under other speeds and the dataset's other tracks."""
    man, geom = ds.manifest, ds.geometry
    run = man.run(rid)
    mr = ds.measured.get(rid)
    rd = ds.data[rid]
    out = []

    def try_it(track, speed, factor=None):
        if mr is not None and mr.auto_start:
            dist = mr.distance
            if factor is not None:
                dist = Distance(dist.t, dist.d * factor)
            alt = dataclasses.replace(mr, speed=speed, distance=dist, window=None, start=None, warnings=[])
            try:
                _, r = estimate_start(alt, P, geom, track)
            except Exception:  # a candidate that cannot even be aligned does not fit
                return -1.0
            return r
        dist = rd.distance
        if factor is not None and dist is not None:
            dist = RelativeDistance(Distance(dist.dist.t, dist.dist.d * factor), dist.start)
        return _score(rd.matrix(), _nominal_response(P, geom, track, rd.time, speed, dist, moving=run.moving))

    track = man.tracks[run.track]
    if run.speed is not None:
        for v, why in speed_candidates(run.speed):
            if PLAUSIBLE["speed"][0] <= v <= PLAUSIBLE["speed"][1]:
                out.append((f"speed = {v:.4g} m/s ({why})", try_it(track, v)))
    elif mr is not None and mr.distance is not None:
        for f, why in ((1 / 3.6, "km/h mapped as m/s"), (3.6, "m/s mapped as km/h"), (0.44704, "mph mapped as m/s")):
            out.append((f"the speed channel x {f:.4g} ({why}; fix its unit in the channel map)", try_it(track, None, f)))
    for tid, tr in man.tracks.items():
        if tid != run.track:
            out.append((f"track = \"{tid}\"", try_it(tr, run.speed)))
    return out


def _prefetch_inputs(ds) -> None:
    """Tabulate every wheel path's envelope and every run's inputs on parallel threads.

    The checks (and then the identification) take them from the caches of
    :func:`rideid.model.contact.envelope_grid` and
    :func:`rideid.model.simulate.prepare_run` one run at a time; most of the
    work is NumPy and compiled loops that release the GIL, so the cores
    share it (:func:`rideid.model.batch.thread_map`; with one thread, as in
    a study's workers, nothing is done ahead). A run that fails here fails
    again, with its message, in the checks.
    """
    man, geom = ds.manifest, ds.geometry
    runs = [r for r in man.runs[:PREPARED_MAX] if r.road_known]  # what the cache of prepared runs holds
    if min(numba.get_num_threads(), len(runs)) < 2:
        return
    paths = {}
    for r in runs:
        for y in geom.corner_y:
            p = man.tracks[r.track].path(y)
            if p.extent is not None:
                paths[id(p)] = p

    def envelope(p):
        envelope_grid(p, geom.tire_radius, ENVELOPE_DX)

    def inputs(r):
        rd = ds.data[r.id]
        try:
            prepare_run(man.tracks[r.track], geom, r.speed, rd.time, distance=rd.distance)
        except Exception:  # noqa: BLE001 - reported by the checks themselves
            pass

    thread_map(envelope, sorted(paths.values(), key=lambda p: -(p.extent[1] - p.extent[0])), "rideid-inputs")
    thread_map(inputs, runs, "rideid-inputs")


def check_dataset(ds) -> list[Finding]:
    """Run the data checks on every run of a loaded dataset.

    Coverage, wiring (rigid body and road assignment), and the match of
    each run with its track and speed. Returns every finding; the caller
    raises on errors (:func:`enforce`).

    A run on an unknown road (SPEC §9) has no road to simulate: coverage,
    the road assignment of the channels, the axle-amplitude units and the
    track-and-speed match are skipped; the units seen in a logger's
    lead-in and the rigid-body identities of the body accelerometers and
    the gyro still run. A moving run (SPEC §9) may have track features
    under its wheels at the start; its nominal response is simulated from
    rest a lead-in before the first sample, on the road before x = 0.
    """
    man, geom = ds.manifest, ds.geometry
    P = nominal_car(geom)
    out: list[Finding] = []
    _prefetch_inputs(ds)
    for r in man.runs:
        rid = r.id
        rd = ds.data[rid]
        # a run on an unknown road (SPEC §9): no coverage, no nominal response, no track match; units and the
        # rigid-body identities need no road and still run
        track = man.tracks[r.track] if r.road_known else None
        t = rd.time
        if track is not None:
            x_of = (lambda tt: r.speed * tt) if rd.distance is None else rd.distance
            x_end = float(np.asarray(x_of(np.array([t[-1]])))[0])
            x_begin = float(np.asarray(x_of(np.array([min(t[0], 0.0)])))[0])
            cov = check_coverage(rid, track, geom, x_end, x_begin, moving=r.moving)
            out += cov
            if any(f.severity == ERROR for f in cov):
                continue
        entries = _map_entries(ds, rid)
        wiring = _level(ds, rid, "wiring")
        mr = ds.measured.get(rid)
        # an acceleration in the wrong unit, seen in its lead-in; a re-wiring below that explains it says it better
        units = (unit_findings(rid, entries, mr.record["channels"])
                 if mr is not None and wiring != "off" else [])
        if wiring == "warn":
            units = [Finding(WARNING, f.check, f.message, f.run, f.channel, f.fix) for f in units]
        Y = rd.matrix()
        Yhat = None
        if track is not None:
            Yhat = _nominal_response(P, geom, track, t, r.speed, rd.distance, moving=r.moving)
            if not np.any(Yhat):
                out += units
                continue  # a flat road excites nothing: nothing to check the data against
        wire = (wiring_fix(Y, Yhat, rd.fs, geom, _entry_factors(entries))
                if wiring != "off" else None)
        Yc = Y
        if wire and wire["fix"]:
            units = [f for f in units if f.channel not in wire["fix"]]
            Yc = corrected(Y, wire["fix"])
            sev = ERROR if wiring == "error" else WARNING
            lines = fix_entries(wire["fix"], entries)
            how = []
            if "rigid" in wire:
                how.append(f"the body accelerometers and the gyro then agree as one rigid body (residual "
                           f"{wire['rigid'][0]:.0%} -> {wire['rigid'][1]:.1%})")
            if "axle" in wire:
                how.append(f"the axle channels then follow their own wheel paths (summed correlation with the "
                           f"road {wire['axle'][0]:.2f} -> {wire['axle'][1]:.2f} of 4)")
            alts = ""
            if wire.get("alternatives"):
                alts = ("; without a known road this cannot be told from " +
                        " or from ".join(describe_fix(a) for a in wire["alternatives"][:2]) + ": check which")
            msg = (f"run '{rid}': the channels look wired differently from the map: {describe_fix(wire['fix'])}; "
                   f"{' and '.join(how)}{alts}. Fix the channel map: {'; '.join(lines)}"
                   " (or set [checks] wiring = \"warn\" if the map is right)")
            out.append(Finding(sev, "wiring", msg, rid, next(iter(wire["fix"])), wire["fix"]))
        elif wire and "rigid_inconsistent" in wire:
            e_id, _ = wire["rigid_inconsistent"]
            out.append(Finding(WARNING, "wiring", f"run '{rid}': the body accelerometers and the gyro do not agree as "
                               f"one rigid body (residual {e_id:.0%}) and no swap, sign or unit explains it: check "
                               "the sensors' positions (at the spring/damper top mounts), units and the map", rid))
        if wiring != "off" and Yhat is not None and not (wire and wire["fix"]):
            amp = axle_amplitude_findings(rid, entries, Y, Yhat, skip={f.channel for f in units})
            if wiring == "warn":
                amp = [Finding(WARNING, f.check, f.message, f.run, f.channel, f.fix) for f in amp]
            units += amp
        out += units
        if track is None or _level(ds, rid, "track") == "off":
            continue
        rho = _score(Yc, Yhat)
        if rho < MATCH_MIN:
            f = match_finding(rid, r.track, r.speed, rho, _alternatives(ds, rid, P, rho))
            if _level(ds, rid, "track") == "warn":
                f = Finding(WARNING, f.check, f.message + " ([checks] track = \"warn\")", f.run, f.channel)
            else:
                f = Finding(f.severity, f.check, f.message + " (set [checks] track = \"warn\" to go on anyway)",
                            f.run, f.channel)
            out.append(f)
    return out


__all__ = ["NOMINAL_LEAD_IN", "check_dataset"]
