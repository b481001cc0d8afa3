"""What the data say of each run's set-up values (SPEC §13): its speed, its start and its track's drawn size,
each against its prior, in result.json.

A run on a track as built or on an unknown road carries its motion as unknowns of the problem
(:mod:`rideid.estimate.problem.blocks`), solved with the car (:mod:`rideid.estimate.fit.anyroad`). This module
writes what came of them: a run's ``motion`` record (:func:`motion_record`, :func:`road_motion_record`: the
estimate, its std, the declared value and its prior's width), the track's size as the run saw it
(:func:`with_size`), result.json's ``tracks`` block (:func:`tracks_block`), and the ``motion`` warnings of every
value the data moved further than its prior allows (:func:`motion_findings`), one for a speed off alike on every
road run (:func:`common_speed_offset`: a wheelbase or a sample rate mistyped). A declared value is never silently
moved.
"""

from __future__ import annotations

import numpy as np

from ...model.equations import CHANNELS
from ...settings import defaults
from ..problem import asbuilt


def _entry(est, std, pr, unit) -> dict:
    """One value of a run's ``motion`` record: its estimate and std, the declared value and its prior's std."""
    e = {"estimate": est, "std": std, "unit": unit, "declared": None, "prior_std": None, "prior": "none"}
    if pr is None:
        return e
    e.update(declared=pr[0], prior_std=pr[1], prior=("default", "declared")[bool(pr[2])])
    if pr[1] > 0:
        e["from_declared_in_prior_std"] = (est - pr[0]) / pr[1]
    return e


#: how a motion record's value is named when the data move it beyond its prior: (what, its unit, the estimate's
#: departure from the declared value in words, the prior's std in words)
_NAMED = {
    "speed": ("declared speed {d:.2f} m/s", "m/s", lambda v, d: f"{100 * (v / d - 1):+.2f} %",
              lambda s: f"{s:.2g} m/s"),
    "start": ("declared start {d:.4f} s", "s", lambda v, d: f"{1e3 * (v - d):+.1f} ms", lambda s: f"{1e3 * s:.2g} ms"),
}


def _named(rid: str, key: str, value: float, std, pr) -> list[str]:
    """The sentence naming run ``rid``'s ``key`` (speed, start) when ``value`` is beyond setting
    ``anyroad.motion_named`` times its prior's std from the declared value (none without a prior)."""
    if pr is None or abs(value - pr[0]) <= defaults["anyroad.motion_named"] * pr[1]:
        return []
    what, unit, off, width = _NAMED[key]
    return [f"run {rid}: {what.format(d=pr[0])}, the data show {_pm(value, std)} {unit} ({off(value, pr[0])}, "
            f"{abs(value - pr[0]) / pr[1]:.1f} times the declared value's std of {width(pr[1])}"
            f"{('', ', the default width')[not pr[2]]})"]


def motion_record(fitted: dict, prior, tr) -> dict:
    """A run's ``motion`` record of result.json (SPEC §13): ``speed`` and ``start``, each ``{"estimate", "std",
    "declared", "prior_std", "prior"}`` (``declared`` None where nothing was declared: a speed channel's run, a
    start estimated at load; ``prior``: "declared" with its std, "default" width, or "none"), ``named``: the
    sentences naming what the data moved beyond setting ``anyroad.motion_named`` prior std; with the older keys of a
    run along a speed channel (``speed_m_s``, ``start_shift_s``, their ``_std``, ``speed_channel_mean_m_s``).

    ``fitted``: :meth:`rideid.estimate.problem.blocks.TrackBlock.aligned`'s record with the solve's speed, shift and
    their standard errors; ``prior``: the run's :class:`rideid.estimate.problem.asbuilt.MotionPrior`; ``tr``: its
    :class:`rideid.estimate.problem.asbuilt.TrackRun` as solved."""
    out = {k: v for k, v in fitted.items() if k in ("speed_m_s", "start_shift_s", "speed_std_m_s",
                                                    "start_shift_std_s")}
    if prior.speed is None:
        out["speed_channel_mean_m_s"] = fitted.get("speed_channel_mean_m_s")
    v, sv = float(fitted["speed_m_s"]), fitted.get("speed_std_m_s")
    start0 = float(fitted.get("start_read_s", 0.0)) if prior.start is None else prior.start[0]
    st, sst = start0 + float(fitted["start_shift_s"]), fitted.get("start_shift_std_s")
    out["speed"] = _entry(v, sv, prior.speed, "m/s")
    out["start"] = _entry(st, sst, prior.start, "s")
    out["named"] = _named(tr.run_id, "speed", v, sv, prior.speed) + _named(tr.run_id, "start", st, sst, prior.start)
    return out


def _pm(value: float, std: float | None) -> str:
    """``value ± std`` with the std to two significant digits and the value to the same decimals."""
    if std is None or not np.isfinite(std) or std <= 0:
        return f"{value:.4g}"
    dec = max(0, 1 - int(np.floor(np.log10(std))))
    return f"{value:.{dec}f} ± {std:.{dec}f}"


def with_size(rec: dict, fit, tr, ds) -> dict:
    """A run's motion record (:func:`motion_record`) with ``size``: the track's drawn size as this run saw it
    (SPEC §13), ``{"estimate", "std", "unit": "relative", "declared": 1.0, "prior_std", "prior"}`` from the
    as-built fit ``fit`` (its amplitude factor), named beyond setting ``anyroad.motion_named`` prior std."""
    if tr.size_std is None:
        return rec
    declared = ds.manifest.size_prior(tr.track)[1]
    e = _entry(float(fit.alpha), float(fit.alpha_std), (1.0, float(tr.size_std), declared), "relative")
    named = [m for m in rec.get("named", []) if "drawn size" not in m]
    if abs(fit.alpha - 1.0) > defaults["anyroad.motion_named"] * tr.size_std:
        keys = ds.manifest.tracks[tr.track].keys
        k = next((k for k in ("amplitude", "height") if k in keys), "size")
        named.append(f"track {tr.track} (run {tr.run_id}): drawn size {k} = {keys.get(k, float('nan')):g} m, the "
                     f"data show {_pm(float(fit.alpha), float(fit.alpha_std))} of it "
                     f"({abs(fit.alpha - 1.0) / tr.size_std:.1f} times the declared size's std of "
                     f"{100 * tr.size_std:.2g} %{('', ', the default width')[not declared]})"
                     + _same_size_track(ds, tr.track, k, float(fit.alpha), float(fit.alpha_std)))
    return dict(rec, size=e, named=named)


def _same_size_track(ds, track: str, key: str, alpha: float, alpha_std: float) -> str:
    """``"; track 'X' (key = v m) is that size: is it the run's track?"`` when another declared track of the same
    kind has the size the data show (within 3 std of the factor, or 2 %): a run given the wrong track of a
    family (twist_low for twist_high) names the right one; else ``""``."""
    tracks = ds.manifest.tracks
    here = tracks[track]
    size = here.keys.get(key)
    if not size:
        return ""
    for tid, other in tracks.items():
        v = other.keys.get(key)
        if (tid != track and v and getattr(other, "kind", None) == getattr(here, "kind", None)
                and abs(v / size - alpha) <= max(3 * alpha_std, 0.02 * alpha)):
            return f"; track '{tid}' ({key} = {v:g} m) is that size: is it the run's track?"
    return ""


def motion_findings(motion: dict) -> list[dict]:
    """The result's ``checks`` records (check ``"motion"``, a warning) of every set-up value the data moved beyond
    its prior (:func:`motion_record`'s ``named``): a declared value is never silently moved (SPEC §13)."""
    def what(m):
        return next((k for k, w in (("speed", "declared speed"), ("start", "declared start"), ("size", "drawn size"))
                     if w in m), "speed")

    def fix(rec, m):  # a named speed: the declared value and the data's (rideid.estimate.assess.adequacy.setup_slips)
        sp = rec.get("speed") or {}
        return {"fix": {"declared": sp["declared"], "speed": sp["estimate"]}} if what(m) == "speed" and sp else {}

    return [{"severity": "warning", "check": "motion", "message": m + ": estimated with the car (SPEC §13); check "
             "the run's set-up", "run": rid, "channel": what(m), **fix(rec, m)}
            for rid, rec in motion.items() for m in rec.get("named", [])] + common_speed_offset(motion)


def common_speed_offset(motion: dict) -> list[dict]:
    """One ``motion`` warning when every unknown-road run with a declared speed (two or more; a record without a
    ``start``) has its speed named off by the same share (within three of their combined std, or a tenth of the
    share): the road fit reads the rear wheels' delay ``wheelbase / speed``, so one slip for every run is likelier
    than one per run: a wheelbase typed that share long (or short) reads as every speed that share fast (slow),
    and so does a sample rate typed that share high (low). Else none."""
    roads = {rid: rec for rid, rec in motion.items()  # not a run on a track as drawn (its record names the track)
             if "start" not in rec and "track" not in rec and (rec.get("speed") or {}).get("declared") is not None}
    if len(roads) < 2 or not all(rec.get("named") for rec in roads.values()):
        return []
    r = np.array([rec["speed"]["estimate"] / rec["speed"]["declared"] - 1.0 for rec in roads.values()])
    sd = np.array([(rec["speed"]["std"] or 0.0) / rec["speed"]["declared"] for rec in roads.values()])
    share = float(np.mean(r))
    if np.max(np.abs(r - share)) > max(3.0 * float(np.sqrt(np.sum(sd ** 2))), 0.1 * abs(share)):
        return []
    word = "fast" if share > 0 else "slow"
    return [{"severity": "warning", "check": "motion", "run": None, "channel": "speed",
             "message": f"runs {', '.join(roads)}: every road run's speed is {100 * abs(share):.2f} % {word}er than "
                        f"declared, alike: one slip for all is likelier than one per run; check [vehicle] wheelbase "
                        f"(a wheelbase {100 * abs(share):.2g} % too {('short', 'long')[share > 0]} reads as every "
                        f"speed that much {word}er: the road fit reads the rear wheels' delay wheelbase / speed) "
                        f"and the runs' sample rate (one typed that much too {('low', 'high')[share > 0]} reads the "
                        "same)"}]


#: result.json ``tracks.<track>.runs.<run>.motion.note``
MOTION_NOTE = ("the run taken at a constant speed, placed with its start on the track as built "
                "(estimate.problem.blocks.TrackBlock.aligned), then both solved with the car (anyroad._joint_solve), a "
                "declared speed and a given start as priors (SPEC §13: declared ± prior_std, the default width "
                "docs/formats.md); speed, start: the estimate, its std, the declared value; start_shift_s: the "
                "start's change from the one read; the std are in the car's error bars as the budget's "
                "'speed and start'")
#: result.json ``tracks.<track>.method``, by the as-built mode
_HOW = {"prior": "the drawing times an amplitude factor plus unevenness whose spectrum is estimated from the data",
        "amplitude": "the drawing times an amplitude factor", "free": "the road projected out, the drawing unused"}


def left_out(rr) -> dict:
    """``{"channels_left_out": ...}`` of a road-fitted run that left channels out (without signal, or clipped:
    :func:`rideid.estimate.problem.roadfit.without_clipped`), else nothing."""
    return {"channels_left_out": dict(rr.left_out)} if rr.left_out else {}


def track_run_record(tr, fit) -> dict:
    """One run's entry of result.json ``tracks.<track>.runs``: what the as-built fit ``fit`` learnt of it."""
    hi = min(defaults["roadfit.band"][1], 0.45 * tr.rr.fs)
    rec = {"amplitude_factor": fit.alpha, "amplitude_factor_std": fit.alpha_std,
           "unevenness_rms_m": asbuilt.unevenness_rms(tr),
           "unevenness_rms_surface_m": asbuilt.unevenness_rms(tr, defaults["anyroad.plausible_wavelength"]),
           "wavelengths_m": [tr.rr.speed / hi, tr.rr.speed / defaults["roadfit.band"][0]]}
    rec.update(left_out(tr.rr))
    if tr.prior is not None and tr.prior.held:  # the unevenness not estimated on this run (asbuilt.estimate_prior)
        rec["unevenness_held"] = tr.prior.held
    if tr.rr.clip.shape[0]:  # clipped samples freed as unknowns (roadfit: "Clipped samples")
        pos, count = np.unique(tr.rr.clip[:, 0], return_counts=True)
        rec["clipped_samples_freed"] = {CHANNELS[tr.rr.cols[j]]: int(k) for j, k in zip(pos, count)}
    return rec


def tracks_block(ds, blocks, skipped, P, geom) -> tuple[dict, dict]:
    """result.json ``tracks``: per track what the as-built fit learnt (amplitude factor, unevenness RMS), per
    run and over the track's runs; a run taken as drawn says why; each run's speed and start as fitted (its
    :class:`rideid.estimate.problem.blocks.TrackBlock`'s record, with the track's size, :func:`with_size`).
    Returns the block and the runs' motion records (run id -> record)."""
    out, motion = {}, {}
    for b in blocks:
        fit = asbuilt.solve(P, geom, b.tr, alpha_std=True)
        rec = out.setdefault(b.tr.track, {"runs": {}})
        motion[b.run_id] = with_size(b.record, fit, b.tr, ds)
        rec["runs"][b.run_id] = dict(track_run_record(b.tr, fit), motion=dict(motion[b.run_id], note=MOTION_NOTE))
    for rec in out.values():
        runs = list(rec["runs"].values())
        rec["amplitude_factor"] = float(np.mean([r["amplitude_factor"] for r in runs]))
        rec["amplitude_factor_std"] = float(np.sqrt(np.sum(np.square([r["amplitude_factor_std"] for r in runs])))
                                            / len(runs))
        for key in ("unevenness_rms_m", "unevenness_rms_surface_m"):
            rec[key] = float(np.sqrt(np.mean(np.square([r[key] for r in runs]))))
        rec["method"] = f"as built: {_HOW[blocks[0].tr.mode]} (rideid.estimate.problem.asbuilt)"
        rec["note"] = ("amplitude_factor: the road over its drawing, each run's and their mean (amplitude_factor_std: "
                       "its standard error at the car, the prior's opened bins make it large); unevenness_rms_m: the "
                       "RMS of what the drawing times that factor leaves, one wheel path, over the wavelengths of "
                       "each run's fit band (it holds the envelope's departure from proportionality too), and "
                       "the RMS over the track's runs; unevenness_rms_surface_m: the same over the waves up to "
                       f"{defaults['anyroad.plausible_wavelength']:g} m (the surface; what the verdict judges); "
                       "the parameters' "
                       "std_robust with tracks as built from the white sandwich of their runs (measured on the "
                       "SUV on tracks 4 % off with 1.5 mm unevenness over five seeds: error / std_robust RMS 0.92, "
                       "±2 std_robust covering 12 of 12 on each; the bin-clustered sandwich was 1.8x too narrow; "
                       "docs/tracks-as-built.md); the speed and start fitted along a speed channel are in them as "
                       "nuisance parameters (the budget's 'speed and start'; each run's motion has its std)")
    for r in (r for r in ds.runs if r.id in skipped):
        out.setdefault(r.track, {"runs": {}})["runs"][r.id] = {"fitted": skipped[r.id]}
    return out, motion


def road_motion_record(fitted: dict, prior, run_id: str) -> dict:
    """An unknown-road run's ``motion`` record (SPEC §13): ``speed`` as :func:`motion_record` gives it (a road run
    has no start to place), ``named`` the sentence naming a speed the data moved beyond setting
    ``anyroad.motion_named`` prior std, and ``speed_m_s``, ``speed_std_m_s``."""
    v, sv = float(fitted["speed_m_s"]), fitted.get("speed_std_m_s")
    pr = None if prior is None else prior.speed
    return {"speed_m_s": v, "speed_std_m_s": sv, "speed": _entry(v, sv, pr, "m/s"),
            "named": _named(run_id, "speed", v, sv, pr)}


#: how a run on a track as drawn had its speed estimated (result.json ``preprocessing.<run>.motion.estimated``)
DRAWN_MOTION_NOTE = ("with the car on the track as drawn (SPEC §13: the declared speed its prior; the model's "
                     "damper curves or bump stops keep the track from being fitted as built); its std is in the "
                     "parameters' std_robust (the budget's 'speed and start')")


def drawn_motion_record(record: dict, run) -> dict:
    """The ``motion`` record (result.json ``preprocessing.<run>.motion``) of a run on a track as drawn whose speed
    was estimated with the car: :func:`road_motion_record`'s ``record`` with the run's ``track`` and how."""
    return dict(record, track=run.track, estimated=DRAWN_MOTION_NOTE)


def paced_motion(ds, speeds: dict) -> dict:
    """Run id -> the ``motion`` record (:func:`drawn_motion_record`) of each run whose speed the polish estimated
    (``speeds``: the polish block's ``speeds``, run id -> ``{"value", "std", "std_robust", ...}``, m/s)."""
    out = {}
    for rid, rec in speeds.items():
        run = ds.manifest.run(rid)
        sd = rec.get("std_robust")
        sd = sd if sd is not None and np.isfinite(sd) else rec.get("std")
        fitted = {"speed_m_s": float(rec["value"]), "speed_std_m_s": sd}
        prior = asbuilt.MotionPrior(speed=run.speed_prior(), start=None)
        out[rid] = drawn_motion_record(road_motion_record(fitted, prior, rid), run)
    return out


#: what a road run's motion record says (result.json ``roads.<run>.motion.note``)
ROAD_MOTION_NOTE = ("the run's speed estimated with the car (SPEC §13): it sets the rear wheels' delay "
                     "wheelbase / speed, which the road fit reads from the front and rear wheels' agreement; the "
                     "declared speed is its prior (none along a speed channel); its std is in the parameters' "
                     "std_robust (the budget's 'speed and start')")
