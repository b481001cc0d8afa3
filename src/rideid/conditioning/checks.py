"""The data checks that run the model: every conditioned run of a dataset against a nominal car.

:func:`check_dataset` is the one hook, called once every run of a dataset is
conditioned and aligned (:func:`rideid.conditioning.load.align_starts`):

* **Coverage** (:func:`check_coverage`): the car starts at rest on flat road
  (SPEC §2), so no feature may lie under a wheel at the start; the run must
  reach its track and, ideally, leave it (:func:`check_reach`: before its
  start is estimated).
* **Wiring and units** (:mod:`rideid.conditioning.wiring`): rigid body and
  road assignment (:func:`rideid.conditioning.wiring.wiring_fix`), the units
  seen in a logger's lead-in or in the axle amplitudes.
* **Track and speed** (:func:`match_finding`): the measurement must
  correlate with the response to the stated track at the stated speed.
  Otherwise the speed (km/h typed as m/s) or the track is wrong; the checks
  re-try other speeds and the manifest's other tracks and the message names
  the one that fits.
* **Speed held** (:func:`speed_held`, SPEC §11): a run at a constant
  declared speed without a speed or distance channel must have held it;
  the lags of its data against the same nominal response, window by window
  along the track (:mod:`rideid.conditioning.speed`), refuse a run whose
  speed wandered or was steadily another.

The checks are steps (:mod:`rideid.conditioning.nominal`): they ask for the
nominal car's responses (:func:`rideid.model.params.nominal_car`) on every
run's time grid, every run in one batch, and, for a run that does not match,
for its alternatives in a later one; the comparisons themselves are pure
functions over numbers and arrays.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..settings import defaults, legacy_names
from ..data.checks import ERROR, PLAUSIBLE, WARNING, Finding, MapFix, keep_map
from ..data.measured import Distance, RelativeDistance
from ..errors import DataError
from ..data.schema.channels import SI, UNITS, quantity
from ..model.equations import CHANNELS
from ..model.sensors import SensorChain
from .nominal import Job, gather, responses, run_steps
from .speed import STEADY, WANDER_MAX, speed_finding, speed_summary, window_lags
from .starts import correlation_score, feature_span, start_check_steps, start_steps
from .wiring import (axle_amplitude_findings, corrected, describe_fix, fix_entries, gyro_or_accelerations,
                     lead_in_units, unit_findings, wiring_fix)

#: a moving run's nominal response starts at rest this long (s) before the first sample: the nominal car's
#: slowest mode decays to 1e-3 in 2.4-2.7 s on the built-in car, the SUV and the van of the tests
#: (rideid.data.scenario.settle_time)
NOMINAL_LEAD_IN = 5.0


# ---------------------------------------------------------------------------
# Coverage: the car starts at rest on flat road, reaches the track and leaves it

def check_coverage(run_id: str, track, geom, x_end: float, x_begin: float = 0.0, where: str = "",
                   moving: bool = False) -> list[Finding]:
    """Does the run start at rest on flat road, reach the track, and leave it?

    A ``moving`` run (SPEC §9) need not start on flat road: the track may begin under its wheels (a ``profile``
    at x = 0).

    Parameters
    ----------
    run_id : str
    track : rideid.model.tracks.Track
    geom : Geometry
    x_end : float
        Front-axle distance (m) past x = 0 at the run's last sample.
    x_begin : float
        Front-axle distance (m) at the run's first sample (negative with a pre-roll).
    """
    span = feature_span(track, geom)
    w = f"{where}run '{run_id}'"
    if span is None:
        return []
    lo, hi = span
    R = geom.tire_radius
    out = []
    # the rigid wheel touches a feature up to R ahead of its centre; the rear axle is a wheelbase behind
    if lo - R < min(x_begin, 0.0) and not moving:
        out.append(Finding(ERROR, "coverage", f"{w}: track '{track.id}' has features from x = {lo:g} m, under or "
                           f"within a tire radius ({R:g} m) of the front wheels at the start: the car must start at "
                           "rest on flat road (SPEC §2); move the track's start to at least "
                           f"{R + max(0.0, -x_begin):g} m",
                           run_id, "start"))
    elif x_end < lo - R:
        out.append(Finding(ERROR, "coverage", f"{w}: never reaches track '{track.id}': the front axle travels "
                           f"{x_end:.3g} m but the first feature is at x = {lo:g} m (check the track's start, the "
                           "run's speed and the recording's length)", run_id, "speed"))
    elif x_end < hi + geom.wheelbase + R:
        out.append(Finding(WARNING, "coverage", f"{w}: ends before the rear wheels leave track '{track.id}' "
                           f"(front axle at {x_end:.3g} m, the rear wheels clear the last feature at "
                           f"{hi + geom.wheelbase + R:.3g} m): a longer recording fits better", run_id, "duration"))
    return out


def check_reach(run_id: str, track, geom, max_distance: float, where: str = "") -> list[Finding]:
    """Before a start is estimated: can the recording reach the track at all?

    ``max_distance``: the most the front axle can travel during the whole
    recording (constant speed x its length, or the distance channel's range).
    """
    return [f for f in check_coverage(run_id, track, geom, max_distance, 0.0, where)
            if f.severity == ERROR and f.channel == "speed"]


# ---------------------------------------------------------------------------
# Track and speed

def match_finding(run_id: str, track_id: str, speed, rho: float, alternatives: list, where: str = "") -> Finding | None:
    """A finding when the run does not match its track and speed.

    Parameters
    ----------
    rho : float
        Mean normalised correlation of the measurement with a nominal car's
        response on the stated track at the stated speed (1 = same shape).
    alternatives : list of (description, correlation)
        Other speeds and tracks tried; the best one is named if it fits.
    """
    if rho >= defaults["checks.match_min"]:
        return None
    what = f"speed {speed:g} m/s" if speed is not None else "its speed channel"
    msg = (f"{where}run '{run_id}' does not match track '{track_id}' at {what}: correlation {rho:.2f} with a "
           f"nominal car's response (a matching run gives 0.8 or more)")
    good = [a for a in alternatives if a[1] >= defaults["checks.match_min"]]
    if good:
        desc, r = max(good, key=lambda a: a[1])
        msg += f"; {desc} fits (correlation {r:.2f})"
    else:
        msg += ("; no other speed or track of the dataset fits either: check the run's track, its speed, its file "
                "and the channel map")
    return Finding(ERROR, "track", msg, run_id, "speed" if good and "speed" in good[0][0] else "track")


def speed_candidates(speed: float) -> list[tuple[float, str]]:
    """Speeds a typing slip makes of the true one: (candidate m/s, how the slip happens)."""
    return [(speed / 3.6, f"{speed:g} is km/h"), (speed * 3.6, f"{speed:g} m/s was meant as km/h the other way"),
            (speed * 0.44704, f"{speed:g} is mph"), (speed / 2.0, "half the speed"), (speed * 2.0, "twice the speed")]


def start_finding(run_id: str, track, given: float, best: float, rho_best: float, rho_given: float, fs: float,
                  travel: float | None = None, where: str = "") -> Finding | None:
    """A finding when a run's given start is not where its data match the track (a bump or a cycle off).

    Parameters
    ----------
    given, best : float
        The start given (file time, s) and the one the all-lags correlation
        with the nominal car picks (:func:`rideid.conditioning.starts.start_check_steps`).
    rho_best, rho_given : float
        That correlation at the best start, and its highest within START_SAMPLES samples of the given one.
    fs : float
        The run's sample rate, Hz.
    travel : float, optional
        The distance (m) the car covers between the two starts, to compare
        with the track's bump spacing or wavelength.
    """
    near = defaults["checks.start_samples"] / fs
    if abs(given - best) <= near or rho_best < rho_given + defaults["checks.start_margin"]:
        return None
    d = given - best
    period = next((track.keys[k] for k in ("spacing", "wavelength") if k in getattr(track, "keys", {})), None)
    how = ""
    if travel is not None:
        how = f", {travel:.3g} m of travel"
        if period:
            name = "bump spacing" if "spacing" in track.keys else "wavelength"
            how += f" ({travel / period:.2g} x the track's {name} of {period:g} m)"
    return Finding(ERROR, "track", f"{where}run '{run_id}': its start is off: start = {given:.6g} s is "
                   f"{abs(d):.3g} s too {'late' if d > 0 else 'early'}{how}: the data match track '{track.id}' "
                   f"best with the front axle at x = 0 at {best:.6g} s of file time (correlation {rho_best:.2f} "
                   f"with a nominal car's response there, {rho_given:.2f} at the given start). Set start = "
                   f"{best:.6g} for run '{run_id}', or remove start to have it estimated", run_id, "start")


# ---------------------------------------------------------------------------
# Every run of a dataset against the nominal car


def _map_entries(ds, rid) -> dict:
    """SPEC channel -> {name, unit, sign, scale} as the run was read."""
    mr = ds.measured.get(rid)
    if mr is not None:
        return {c: dict(name=e["source"], unit=e["unit"], sign=e["sign"], scale=e["scale"],
                        file_unit=e.get("file_unit"))
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


def _nominal_job(track, t, speed, distance, moving: bool = False) -> Job:
    """The simulation of the nominal car on the run's own time grid (a moving run from rest a lead-in before)."""
    return Job(track, t, speed, distance, NOMINAL_LEAD_IN if moving else 0.0)


def _score(Y, Yhat):
    cols = [i for i in range(len(CHANNELS)) if not np.all(np.isnan(Y[:, i]))]
    return correlation_score(Yhat, np.nan_to_num(Y, nan=0.0), cols)


def _realigned(mr, geom, track, **changes):
    """The step estimating the start of the measured run ``mr`` read with ``changes`` (its speed, its distance):
    returns ``(start, correlation)`` (:func:`rideid.conditioning.starts.start_steps`), or None when the run cannot
    even be aligned so."""
    alt = dataclasses.replace(mr, **changes, window=None, start=None, warnings=[])
    try:
        return (yield from start_steps(alt, geom, track))
    except Exception:  # a candidate that cannot even be aligned does not fit
        return None


def _alternatives(ds, rid):
    """The step giving (description, correlation) of the run under other speeds and the dataset's other
    tracks (:mod:`rideid.conditioning.nominal`: every alternative simulated in the same rounds)."""
    man, geom = ds.manifest, ds.geometry
    run = man.run(rid)
    mr = ds.measured.get(rid)
    rd = ds.data[rid]
    tries = []

    def try_it(track, speed, factor=None):
        if mr is not None and mr.auto_start:
            dist = mr.distance
            if factor is not None:
                dist = Distance(dist.t, dist.d * factor)
            found = yield from _realigned(mr, geom, track, speed=speed, distance=dist)
            return -1.0 if found is None else found[1]
        dist = rd.distance
        if factor is not None and dist is not None:
            dist = RelativeDistance(Distance(dist.dist.t, dist.dist.d * factor), dist.start)
        (Yhat,) = responses((yield [_nominal_job(track, rd.time, speed, dist, moving=run.moving)]))
        return _score(rd.matrix(), Yhat)

    track = man.tracks[run.track]
    if run.speed is not None:
        for v, why in speed_candidates(run.speed):
            if PLAUSIBLE["speed"][0] <= v <= PLAUSIBLE["speed"][1]:
                tries.append((f"speed = {v:.4g} m/s ({why})", try_it(track, v)))
    elif mr is not None and mr.distance is not None:
        for f, why in ((1 / 3.6, "km/h mapped as m/s"), (3.6, "m/s mapped as km/h"), (0.44704, "mph mapped as m/s")):
            tries.append((f"the speed channel x {f:.4g} ({why}; fix its unit in the channel map)",
                          try_it(track, None, f)))
    for tid, tr in man.tracks.items():
        if tid != run.track:
            tries.append((f"track = \"{tid}\"", try_it(tr, run.speed)))
    rhos = yield from gather([step for _, step in tries])
    return [(desc, r) for (desc, _), r in zip(tries, rhos)]


def check_dataset(ds, car=None, simulator=None) -> list[Finding]:
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

    Parameters
    ----------
    ds : Dataset
        Every run conditioned and aligned.
    car : (12,) array, optional
        The nominal car's parameter vector (default ``nominal_car(ds.geometry)``).
    simulator : rideid.model.simulator.Simulator, optional
        How it is simulated (its linear car; default ``Simulator()``).
    """
    return run_steps(check_steps(ds), ds.geometry, car, None if simulator is None else simulator.linear())


def check_steps(ds):
    """The step of :func:`check_dataset` (:mod:`rideid.conditioning.nominal`): every run checked side by
    side; returns the findings, run by run."""
    found = yield from gather([_check_run(ds, r) for r in ds.manifest.runs])
    return [f for fs in found for f in fs]


def _check_run(ds, r):
    """The step checking one run (:func:`check_dataset`): returns its findings."""
    man, geom = ds.manifest, ds.geometry
    out: list[Finding] = []
    rid = r.id
    rd = ds.data[rid]
    # a run on an unknown road (SPEC §9): no coverage, no nominal response, no track match; units and the
    # rigid-body identities need no road and still run; so on a four-post rig (SPEC §13): no track to cover,
    # match or check a speed against (its post amplitudes are checked on reading, rideid.data.dataset)
    track = man.tracks[r.track] if r.track is not None else None
    t = rd.time
    if track is not None:
        x_of = (lambda tt: r.speed * tt) if rd.distance is None else rd.distance
        x_end = float(np.asarray(x_of(np.array([t[-1]])))[0])
        x_begin = float(np.asarray(x_of(np.array([min(t[0], 0.0)])))[0])
        cov = check_coverage(rid, track, geom, x_end, x_begin, moving=r.moving)
        out += cov
        if any(f.severity == ERROR for f in cov):
            return out
    entries = _map_entries(ds, rid)
    wiring = _level(ds, rid, "wiring")
    mr = ds.measured.get(rid)
    # a start given a bump or a cycle off moves the model against the data: every road-driven comparison
    # below (the axle channels' assignment and amplitudes, the track and speed) would blame the channels or
    # the speed for it, so the start is named and those comparisons are not made
    start_off = None
    if (track is not None and mr is not None and not r.moving and _level(ds, rid, "track") != "off"
            and mr.record.get("start", {}).get("source") == "given"):
        start_off = yield from _given_start(ds, rid, mr, track)
    # an acceleration in the wrong unit, seen in its lead-in; a re-wiring below that explains it says it better
    units = (unit_findings(rid, entries, mr.record["channels"], wiring)
             if mr is not None and wiring != "off" else [])
    # ... and one whose lead-in read g is in the right unit: no other check may say otherwise
    unit_known = lead_in_units(mr.record["channels"]) if mr is not None else set()
    Y = rd.matrix()
    Yhat = None
    if track is not None:
        (Yhat,) = responses((yield [_nominal_job(track, t, r.speed, rd.distance, moving=r.moving)]))
        if not np.any(Yhat):
            out += units
            return out  # a flat road excites nothing: nothing to check the data against
        Y, Yhat = _as_recorded(ds, rid, Y, Yhat)
    # SPEC §13: a declared speed is a prior, not a fact. The speed the data show (the lags against the nominal
    # response) is tried before the wiring: a speed slip moves the road under the rear wheels against the front
    # ones and reads as swapped axle channels, so the road-driven comparisons below are made at that speed
    seen = shifted = None
    declared = (Y, Yhat)
    if Yhat is not None and start_off is None and rd.distance is None and not r.moving and r.speed:
        line = lag_line(ds, rid, Y, Yhat)
        seen = speed_seen(ds, rid, Y, Yhat, line)
        shifted = start_seen(line, rd.fs) if seen is None else None
    # with the start off, the rigid-body identities alone (they need no road) judge the wiring
    wire = (wiring_fix(Y, None if start_off is not None else Yhat, rd.fs, geom, _entry_factors(entries),
                       unit_known) if wiring != "off" else None)
    if seen is None and shifted is not None and ((wire and wire["fix"])
                                                  or _score(Y, Yhat) < defaults["checks.match_min"]):
        # a start off by some samples moves the road under every wheel alike, and a herringbone's or a twist's
        # left-right pattern with it: tried before a re-wiring is proposed
        (Yhat_s,) = responses((yield [_nominal_job(track, t - shifted, r.speed, None)]))
        Y_s, Yhat_s = _as_recorded(ds, rid, rd.matrix(), Yhat_s)
        wire_s = (wiring_fix(Y_s, Yhat_s, rd.fs, geom, _entry_factors(entries), unit_known) if wiring != "off"
                  else None)
        if not (wire_s and wire_s["fix"]) and _score(Y_s, Yhat_s) >= defaults["checks.match_min"]:
            wire, Y, Yhat = wire_s, Y_s, Yhat_s
            out.append(Finding(WARNING, "track", f"run '{rid}': the data match the track with the front axle at "
                               f"x = 0 at {shifted:+.4f} s of the run's time, not at its start ({1e3 * shifted:+.1f} "
                               "ms): check the run's start (a SPEC CSV's time 0, a logger file's start); the fit "
                               "estimates it with the car (SPEC §13)", rid, "start", {"start_shift": shifted}))
    if (seen is None and Yhat is not None and start_off is None and rd.distance is None and not r.moving and r.speed
            and _score(Y, Yhat) < defaults["checks.match_min"]):
        # the lags could not tell (too few windows they can read: a car far from the nominal one on a short
        # track) and the run does not match at its declared speed: the speeds next to it, a slip of a per cent
        seen = yield from speed_scan(ds, rid, track)
    if seen is not None:
        # the wiring at the speed the data show: a re-wiring that speed makes needless is never proposed, and the
        # checks below compare at that speed; a speed that breaks a wiring the declared one found right is not
        # the data's (a wandering run's mean): the declared speed's comparisons stand
        (Yhat_s,) = responses((yield [_nominal_job(track, t - seen[2], seen[0], None)]))
        Y_s, Yhat_s = _as_recorded(ds, rid, rd.matrix(), Yhat_s)
        wire_s = (wiring_fix(Y_s, Yhat_s, rd.fs, geom, _entry_factors(entries), unit_known) if wiring != "off"
                  else None)
        if not (wire_s and wire_s["fix"]):
            wire, Y, Yhat = wire_s, Y_s, Yhat_s
            # once more against the response at that speed: the nominal car's phase differs between the declared
            # speed's frequencies and the data's, which biased the first line (the washboard at 10 m/s declared
            # 10.1: 10.012 m/s, then 10.00x)
            again = lag_line(ds, rid, Y_s, Yhat_s)
            if again is not None:
                seen = (seen[0] * (1.0 + again["slope"]), seen[1], seen[2])
            f = speed_prior_finding(rid, r, seen)
            if f is not None:
                out.append(f)
        elif not (wire and wire["fix"]):
            seen = None
    Yc = Y
    scale = gyro_or_accelerations(Y, Yhat, wire["fix"]) if wire and wire["fix"] and Yhat is not None else None
    if scale is not None and scale["side"] != "gyros":
        # the rigid body says the gyros and the accelerometers disagree by g; the nominal car says which
        out += units
        out.append(_scale_finding(rid, scale, entries, wiring))
        return out
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
               f"{' and '.join(how)}{alts}")
        out.append(Finding(sev, "wiring", msg, rid, next(iter(wire["fix"])), wire["fix"],
                           MapFix(tuple(lines), level=wiring)))
    elif wire and "rigid_inconsistent" in wire:
        e_id, _ = wire["rigid_inconsistent"]
        out.append(Finding(WARNING, "wiring", f"run '{rid}': the body accelerometers and the gyro do not agree as "
                           f"one rigid body (residual {e_id:.0%}) and no swap, sign or unit explains it: check "
                           "the sensors' positions (at the spring/damper top mounts), units and the map", rid))
    if (wiring != "off" and (Yhat is not None or not r.road_known) and start_off is None
            and not (wire and wire["fix"])):  # a rig's posts may drive one wheel alone: its hubs are not siblings
        units += axle_amplitude_findings(rid, entries, Y, Yhat, skip={f.channel for f in units} | unit_known,
                                         level=wiring)
    out += units
    if track is None or _level(ds, rid, "track") == "off":
        return out
    if start_off is not None:
        out.append(_at_level(ds, rid, start_off))
        return out
    rho = _score(Yc, Yhat)
    if rho < defaults["checks.match_min"]:
        f = match_finding(rid, r.track, r.speed, rho, (yield from _alternatives(ds, rid)))
        out.append(_at_level(ds, rid, f))
    elif rd.distance is None and not r.moving and r.speed:
        # judged at the declared speed, as the lags were read; a steady speed the data put elsewhere is the
        # prior's to weigh (SPEC §13: estimated with the car, named above), a wandering one is refused (SPEC §11)
        f = speed_held(ds, rid, Yc if seen is None else declared[0], declared[1], steady_ok=seen is not None)
        if f is not None:
            out.append(_at_level(ds, rid, f))
    return out


#: SPEC §13: the speed the lags show (:func:`speed_seen`) is taken for the checks' nominal response when it
#: departs from the declared one by at least this share (below it a run's lags are within what a car other than
#: the nominal one puts into them: 0.1-0.3 % on runs held at their speed, docs/common-mistakes.md) and by more
#: than SEEN_Z times its own standard error
SEEN_MIN = 0.004
SEEN_Z = 3.0
SEEN_FLOOR = 0.001


def lag_line(ds, rid, Y, Yhat) -> dict | None:
    """The straight line through the lags of a run at a declared constant speed against the nominal response at
    that speed (:func:`speed_lags`), weighted by each window's ``sigma``: data at ``t`` like the response at
    ``t + l0 + l' t`` are a speed ``v (1 + l')`` from the time ``shift = -l0 / (1 + l')`` (a start estimated at the
    declared speed moves with it). Returns ``{"slope", "slope_std", "shift", "shift_std"}`` (the errors from the
    lags' scatter about the line: each window's sigma bounds what the nominal car can move its peak by, but that
    error is common to the windows, a car's lag on the same road, which the intercept takes up; the slope's floored
    at :data:`SEEN_FLOOR`, four windows leaving two degrees of freedom), or None (fewer than three windows)."""
    w = speed_lags(ds, rid, Y, Yhat)
    if w is None:
        return None
    t, lag, sig = (np.asarray(w[k], dtype=float) for k in ("t", "lag", "sigma"))
    ok = np.isfinite(lag) & np.isfinite(sig) & (sig > 0)
    if ok.sum() < 3:
        return None
    t, lag, wt = t[ok], lag[ok], 1.0 / sig[ok] ** 2
    tm = float(np.sum(wt * t) / np.sum(wt))
    sxx = float(np.sum(wt * (t - tm) ** 2))
    if not sxx > 0:
        return None
    slope = float(np.sum(wt * (t - tm) * lag) / sxx)
    lag0 = float(np.sum(wt * lag) / np.sum(wt)) - slope * tm
    e = lag - (lag0 + slope * t)
    s2 = float(np.sum(wt * e ** 2) / max(t.size - 2, 1))
    return {"slope": slope, "slope_std": max(float(np.sqrt(s2 / sxx)), SEEN_FLOOR), "shift": -lag0 / (1.0 + slope),
            "shift_std": float(np.sqrt(s2 * (1.0 / np.sum(wt) + tm ** 2 / sxx)))}


def speed_seen(ds, rid, Y, Yhat, line: dict | None = None) -> tuple[float, float, float] | None:
    """The constant speed (m/s) the data of a run at a declared constant speed show, its standard error, and the
    start's offset (s) that goes with it (:func:`lag_line`, or its ``line``). None when the lags cannot tell
    (fewer than three windows) or the speed is within :data:`SEEN_MIN` of the declared one or :data:`SEEN_Z` of
    its standard error."""
    line = lag_line(ds, rid, Y, Yhat) if line is None else line
    if line is None:
        return None
    slope, std = line["slope"], line["slope_std"]
    v = float(ds.manifest.run(rid).speed)
    if abs(slope) < SEEN_MIN or abs(slope) < SEEN_Z * std:
        return None
    return v * (1.0 + slope), v * std, line["shift"]


def speed_scan(ds, rid, track):
    """The step giving the speed a constant-speed run matches its track at, among the speeds within setting
    ``checks.speed_scan_span`` of the declared one (a grid of setting ``checks.speed_scan_step``, relative), as
    :func:`speed_seen` gives it: ``(speed, std, start shift)``, or None when none matches (setting
    ``checks.match_min``). Each speed's correlation is the run's against the nominal car at that speed: at the
    run's start, or for a start estimated at load at the start estimated again at that speed (the shift, s, from
    the start it has). The speed is the vertex of the parabola through the best grid point and its neighbours;
    its std a grid step: the nominal car's peak is not the run's (the lags, where they can be read, do better).

    For the runs whose lags cannot tell the speed (:func:`lag_line` None). Measured on the shared van on roads'
    twist run at 3 m/s (``../shared/cases/van-roads-dampers``: a 3 t van far from the nominal car; tests/test_checks.py
    ``van_twist``): two of the four windows' lags without a peak; declared 3.03 m/s the run correlated 0.41 and was
    refused, at 3.0 0.59; the scan finds 2.9927 and 2.9930 m/s declared 3.03 and 3.08, 3.0060 declared 2.94 (0.2-0.25 %
    off, within the grid step of 0.25 %), 2.9996 declared 3.12."""
    r, geom = ds.manifest.run(rid), ds.geometry
    mr, rd = ds.measured.get(rid), ds.data[rid]
    v0, step = float(r.speed), defaults["checks.speed_scan_step"]
    n = int(round(defaults["checks.speed_scan_span"] / step))
    k = np.arange(-n, n + 1)
    speeds = v0 * (1.0 + step * k)

    def at(v):
        shift = 0.0
        if mr is not None and mr.auto_start:
            found = yield from _realigned(mr, geom, track, speed=float(v))
            if found is None:
                return -1.0, 0.0
            shift = float(found[0] - mr.start)
        (Yhat,) = responses((yield [_nominal_job(track, rd.time - shift, float(v), None)]))
        Y, Yhat = _as_recorded(ds, rid, rd.matrix(), Yhat)
        return _score(Y, Yhat), shift

    found = yield from gather([at(v) for v in speeds])
    rho = np.array([f[0] for f in found])
    j = int(np.argmax(rho))
    if rho[j] < defaults["checks.match_min"] or k[j] == 0:
        return None
    off = 0.0
    if 0 < j < rho.size - 1:
        den = rho[j - 1] - 2.0 * rho[j] + rho[j + 1]
        off = float(np.clip(0.5 * (rho[j - 1] - rho[j + 1]) / den, -0.5, 0.5)) if den < 0 else 0.0
    return float(v0 * (1.0 + step * (k[j] + off))), step * v0, found[j][1]


def start_seen(line: dict | None, fs: float) -> float | None:
    """The start's offset (s) the lags show at the declared speed (:func:`lag_line`) when it exceeds half a sample
    and :data:`SEEN_Z` of its error; None otherwise. Only tried where the comparison at the declared start fails
    (a re-wiring proposed, or no match): a car other than the nominal one lags the road by a few ms itself (7 ms
    on the twist at 5 m/s, tests/asbuilt_tracks.py's SUV)."""
    if line is None or abs(line["shift"]) <= max(0.5 / fs, SEEN_Z * line["shift_std"]):
        return None
    return float(line["shift"])


#: the severity of a finding that is recorded (result.json ``checks``) but neither warned of nor refused
NOTE = "note"


def speed_prior_finding(rid: str, run, seen: tuple[float, float]) -> Finding | None:
    """SPEC §13: the finding of a run whose data show another speed than the declared one (:func:`speed_seen`): the
    fit starts from the speed the data show (its ``fix``) and estimates it with the car, the declared value its
    prior. A warning naming the run and the speed when that lies more than 3 of the prior's std from the declared
    one, else a note (recorded, not warned of: the prior covers it)."""
    pr = run.speed_prior()
    if pr is None:
        return None
    file = getattr(run, "file", None)
    fix = {"speed": float(seen[0]), "std": float(seen[1]), "declared": float(pr[0])}
    dec = max(0, 1 - int(np.floor(np.log10(seen[1])))) if seen[1] > 0 else 3
    shown = f"{seen[0]:.{dec}f} ± {seen[1]:.{dec}f}"
    if abs(seen[0] - pr[0]) <= 3.0 * pr[1]:
        return Finding(NOTE, "speed", f"run '{rid}': declared speed {pr[0]:g} ± {pr[1]:.2g} m/s, the data match the "
                       f"track at {shown} m/s: the fit starts from there", rid, "speed", fix)
    width = "its declared std" if pr[2] else "the default width of a declared speed, docs/formats.md"
    return Finding(WARNING, "speed", f"run '{rid}'{f' ({file})' if file else ''}: declared speed {pr[0]:g} m/s, "
                   f"the data match the track at {shown} m/s ({100 * (seen[0] / pr[0] - 1):+.2f} "
                   f"%, more than 3 times {width}, {pr[1]:.2g} m/s): the fit takes {seen[0]:.{dec}f} m/s (held there "
                   "on the tracks as drawn, estimated with the car when they are fitted as built; the verdict is then "
                   "not a clean one); check the run's speed", rid, "speed", fix)


def _scale_finding(rid: str, scale: dict, entries: dict, wiring: str) -> Finding:
    """The finding of :func:`rideid.conditioning.wiring.gyro_or_accelerations`: the accelerometers named with the
    fix when their amplitudes, restored, and the gyros' agree with the nominal car; else no fix, both named."""
    sev = ERROR if wiring == "error" else WARNING
    ratios = scale["ratios"]
    gyro = (f"the gyros' {scale['gyro_ratio']:.2g}x")
    if scale["side"] == "accelerations":
        fix = {c: {"source": c, "factor": scale["factor"]} for c in scale["channels"]}
        unit = "g" if scale["factor"] > 1 else "m/s^2 where g is written"
        acc = ", ".join(scale["channels"])
        return Finding(sev, "wiring", f"run '{rid}': the accelerations read {scale['factor']:.3g}x too "
                       f"{'small' if scale['factor'] > 1 else 'large'}: {acc} look written in {unit} (their amplitude "
                       f"{scale['body_ratio']:.2g}x the nominal car's on this road, {gyro}; the body accelerometers "
                       f"and the gyros then agree as one rigid body and with the nominal car)", rid,
                       scale["channels"][0], fix, MapFix(tuple(fix_entries(fix, entries)), level=wiring))
    acc = ", ".join(f"{c} {ratios[c]:.2g}x" for c in scale["channels"])
    return Finding(sev, "wiring", f"run '{rid}': the body accelerometers and the gyros disagree by g "
                   f"({1 / scale['factor']:.3g}): the accelerations or the gyros are in the wrong unit, and their "
                   f"amplitudes against the nominal car on this road ({acc}; {gyro}) do not say which: check the "
                   f"units of the accelerometers and the gyros in the channel map{keep_map(wiring)}", rid, "pitch_rate")


def speed_lags(ds, rid, Y, Yhat) -> dict | None:
    """The lags of a constant-speed run's data ``Y`` against the nominal response ``Yhat`` at its declared speed
    over the stretch where its wheels are on the track's features (:func:`rideid.conditioning.speed.window_lags`),
    or None (too short a stretch)."""
    geom, r = ds.geometry, ds.manifest.run(rid)
    span = feature_span(ds.manifest.tracks[r.track], geom)
    if span is None:
        return None
    R, v = geom.tire_radius, float(r.speed)
    rd = ds.data[rid]
    return window_lags(Y, Yhat, rd.time, ((span[0] - R) / v, (span[1] + geom.wheelbase + R) / v), rd.fs)


def speed_summaries(ds, car=None, simulator=None) -> dict:
    """Run id -> what the lags say of its speed (:func:`rideid.conditioning.speed.speed_summary`), for every run
    of a loaded dataset that the speed check looks at: on a known track, at a constant declared speed, from
    rest. The nominal car (or ``car``) simulated as :func:`check_dataset` does."""
    rids = [r.id for r in ds.manifest.runs
            if r.road_known and not r.moving and r.speed and ds.data[r.id].distance is None]

    def step():
        jobs = [_nominal_job(ds.manifest.tracks[ds.manifest.run(rid).track], ds.data[rid].time,
                             ds.manifest.run(rid).speed, None) for rid in rids]
        out = {}
        for rid, Yhat in zip(rids, responses((yield jobs))):
            Y, Yhat = _as_recorded(ds, rid, ds.data[rid].matrix(), Yhat)
            w = speed_lags(ds, rid, Y, Yhat)
            summary = None if w is None else speed_summary(w)
            if summary is not None:
                out[rid] = summary
        return out

    return run_steps(step(), ds.geometry, car, None if simulator is None else simulator.linear())


def speed_held(ds, rid, Y, Yhat, steady_ok: bool = False) -> Finding | None:
    """SPEC §11, speed as driven: the error refusing a run without a speed channel whose speed wanders (or
    differs from the declared one), as its lags against the nominal response show (:mod:`rideid.conditioning.speed`).
    ``steady_ok``: a steady speed other than the declared one is not refused (SPEC §13: the fit starts from the
    speed the data show, :func:`speed_seen`, and estimates it with the car); a wandering one still is."""
    w = speed_lags(ds, rid, Y, Yhat)
    summary = None if w is None else speed_summary(w)
    if summary is None:
        return None
    r = ds.manifest.run(rid)
    file = getattr(r, "file", None)
    if steady_ok and summary["wander"] <= STEADY * WANDER_MAX:
        return None
    return speed_finding(rid, f" ({file})" if file else "", float(r.speed), summary)


def _as_recorded(ds, rid, Y, Yhat):
    """The data and the nominal response as the checks compare them (SPEC §11): the response through the
    run's declared sensor chain (an AC-coupled hub sensor's phase lead on a slow bump is the chain's, not a
    wiring mistake), and the samples where a channel sat at its range left out of both (0)."""
    chain = SensorChain(ds.sensor_filters(rid), 1.0 / ds.data[rid].fs)
    if chain.active:
        Yhat = chain.apply(Yhat)
    clipped = ds.clipped(rid)
    if clipped is not None:
        Y, Yhat = np.where(clipped, 0.0, Y), np.where(clipped, 0.0, Yhat)
    return Y, Yhat


def _at_level(ds, rid, f: Finding) -> Finding:
    """A track finding at the run's ``[checks] track`` level, saying how to relax it."""
    if _level(ds, rid, "track") == "warn":
        return Finding(WARNING, f.check, f.message + " ([checks] track = \"warn\")", f.run, f.channel)
    return Finding(f.severity, f.check, f.message + " (set [checks] track = \"warn\" to go on anyway)",
                   f.run, f.channel)


def _given_start(ds, rid, mr, track):
    """The step checking a run's given start (:func:`start_finding`): returns the finding or None."""
    run0 = dataclasses.replace(mr, window=None, start=None)  # the run as read, unaligned, as an estimate sees it
    given = float(mr.start)
    try:
        best, rho_best, rho_given = yield from start_check_steps(run0, ds.geometry, track, given,
                                                                 defaults["checks.start_samples"])
    except DataError:  # nothing to correlate (a response or a recording all zero): the other checks say so
        return None
    if mr.distance is None:
        travel = abs(given - best) * mr.speed
    else:
        travel = float(abs(np.diff(mr.distance(np.array([best, given])))[0]))
    return start_finding(rid, track, given, best, rho_best, rho_given, mr.fs, travel)


__all__ = ["NOMINAL_LEAD_IN", "check_coverage", "check_dataset", "check_reach", "check_steps",
           "feature_span", "match_finding", "speed_candidates", "speed_summaries", "start_finding", "speed_seen",
           "speed_prior_finding", "speed_scan", "SEEN_MIN"]


#: the constants this module had before rideid.settings, read from the registry (PEP 562)
__getattr__ = legacy_names(__name__, {
    "MATCH_MIN": "checks.match_min", "START_MARGIN": "checks.start_margin", "START_SAMPLES":
    "checks.start_samples"})
