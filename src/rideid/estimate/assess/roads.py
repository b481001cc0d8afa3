"""Is the car adequate on the runs on unknown roads? The residual each road run leaves at its own road estimate.

On a known track the adequacy test (:mod:`rideid.estimate.assess.adequacy`) asks whether the road input explains
part of the residual. On an unknown road that test has nothing to ask: the road is estimated from the same
channels (:mod:`rideid.estimate.problem.roadfit`, projected out at every frequency), and the residual is what no
road under the two wheel paths can explain, orthogonal to the estimated road by construction (an F-test of the
estimated road on it finds nothing whatever the car: F 0.01-0.5 on the van with real dampers, c_sf 16 % off).

What a wrong car leaves there is *size*: the ten channels are driven by two road signals, the rear wheels
repeating the front wheels' road a wheelbase later (SPEC §9), so a car that is right explains every channel to
the sensor noise (less what the estimated road takes up of it: 2 of the 10 channels at each frequency), and a car
that is wrong cannot make the front and rear wheels' roads agree and leaves a residual well above it. The figure,
per run and channel, on the fit band's residual (the data less the car at its road estimate,
:func:`rideid.estimate.problem.roadfit.fitted_channels`):

share
    the residual's RMS over the channel's RMS. A right car leaves the noise's fit-band share: 0.42-0.47 % at 1 %
    white noise (the built-in car on a B road, tests/test_road_verdict.py), 0.8-1.0 % at 2 % (tests/test_anyroad.py).
    A channel is *off* above setting ``roads.max_share`` (3 %: no sensor worth fitting has noise near 7 % of a
    road run's signal); the van with real dampers fitted with linear ones leaves 2.5-12 %.

A run fails when its off channels make up at least setting ``adequacy.loud_share`` of its channels (the level
caveat's share on known tracks); the road runs pass when none fails. The verdict joins the dataset's adequacy
(:func:`judge`): a failing road run makes the model not adequate, with the set-up first in the advice; passing
road runs are no longer listed as not assessed, so the amber "not a clean verdict" for them goes away. Without a
known-track run only a failure is a verdict (``adequacy`` stays None when the road runs pass: there is no test of
the F-test's kind on them). The figures are in result.json ``roads.<run>.residual`` and the typed record
:class:`rideid.estimate.records.RoadsAssessment`.

Not used: the noise floor of the known-track runs' quiet lead-ins. It is the same sensors' floor on real data,
but a simulation's noise is a share of each run's own RMS (SPEC §4), and against the floor of a slow twist run
the right car's road run came out 1.1-71x "loud" (axle channels of a B road at 11 m/s).
"""

from __future__ import annotations

import numpy as np

from ...model.equations import CHANNELS
from ...settings import defaults
from ..records import RoadsAssessment
from .adequacy import ADVICE_SETUP

#: the advice when a road run fails: the set-up first, then what unknown roads can and cannot fit (the road is
#: projected out of a car linear but for known inputs)
ROAD_ADVICE = ("The car leaves more than the sensor noise on runs on unknown roads, so the estimates are biased by "
               "more than their error bars say. Try " + ADVICE_SETUP + "then what the model lacks: `--model auto` "
               "weighs anti-roll bars, tire damping and damper curves here (the curves need each road run's eight "
               "accelerometers: docs/any-road.md); bump stops cannot be fitted on unknown roads (the road is "
               "projected out of a car linear but for the dampers' measured velocities): add runs on known tracks "
               "and fit them with `--model auto`.")

#: what the verdict says of road runs that pass (adequacy.note)
PASSED_NOTE = ("runs on unknown roads: each run's residual at its own road estimate is of the sensor noise's size "
               "(rideid.estimate.assess.roads)")


def run_figures(y, fitted, cols) -> dict:
    """The ``share`` (module docstring) of one road run's used channels: channel -> ``rms`` (the residual's),
    ``signal_rms``, ``share``, ``off``. ``y`` (n, 10) the measured channels, ``fitted`` (n, 10) the car at the
    road estimate, ``cols`` the channels the fit used (:data:`rideid.model.equations.CHANNELS` indices)."""
    y = np.asarray(y, dtype=float)
    out = {}
    for j in cols:
        e = y[:, j] - fitted[:, j]
        rms = float(np.sqrt(np.mean(e ** 2)))
        sig = float(np.std(y[:, j]))
        share = rms / sig if sig > 0 else 0.0
        out[CHANNELS[j]] = {"rms": rms, "signal_rms": sig, "share": share,
                            "off": bool(share > defaults["roads.max_share"])}
    return out


def assess(rruns, data: dict, response: dict) -> RoadsAssessment:
    """The road runs' verdict (module docstring): ``rruns`` the prepared runs
    (:class:`rideid.estimate.problem.roadfit.RoadRun`), ``data`` run id -> measured (n, 10), ``response`` run id
    -> the car at the road estimate (n, 10)."""
    runs, failed = {}, []
    for rr in rruns:
        fig = run_figures(data[rr.run_id], response[rr.run_id], rr.cols)
        bad = [ch for ch, f in fig.items() if f["off"]]
        runs[rr.run_id] = fig
        if fig and len(bad) >= defaults["adequacy.loud_share"] * len(fig):
            worst = max(fig.values(), key=lambda f: f["share"])
            failed.append(f"{rr.run_id} ({len(bad)} of {len(fig)} channels; residual up to "
                          f"{100 * worst['share']:.1f} % of the channel)")
    how = f"residual above {100 * defaults['roads.max_share']:g} % of the channel"
    if failed:
        reason = (f"the car leaves more than the sensor noise at its own road estimate on {len(failed)} of "
                  f"{len(runs)} run(s) on unknown roads ({'; '.join(failed)}; {how} in at least "
                  f"{100 * defaults['adequacy.loud_share']:.0f} % of a run's channels): no road under the two wheel "
                  "paths makes the front and rear wheels agree, so the model misses something")
        verdict = "fail"
    else:
        reason = (f"every run on an unknown road is explained to the sensor noise at its own road estimate "
                  f"({len(runs)} run(s); {how} in fewer than {100 * defaults['adequacy.loud_share']:.0f} % of a "
                  "run's channels)")
        verdict = "pass"
    return RoadsAssessment(verdict=verdict, reason=reason, runs=runs, failed=[f.split(" (")[0] for f in failed])


def judge(adequacy: dict | None, roads: dict, rruns, data: dict, response: dict) -> dict | None:
    """``adequacy`` with the road runs' verdict (:func:`assess`) joined in, and each road's record (``roads``,
    run id -> result.json ``roads.<run>``) given its figures. A failing road run makes the model not adequate;
    passing road runs leave ``not_assessed``. Unchanged when there are no road runs."""
    if not rruns:
        return adequacy
    rec = assess(rruns, data, response)
    for rid, fig in rec.runs.items():
        if rid in roads:
            roads[rid]["residual"] = fig
            roads[rid]["note"] = roads[rid]["note"].replace(
                "adequacy not assessed on this run", "its residual at the estimated road judged ("
                + ("failed" if rid in rec.failed else "passed") + ": rideid.estimate.assess.roads)")
    if adequacy is None:
        if rec.verdict == "pass":
            return None
        adequacy = {"adequate": False, "reasons": [], "advice": ROAD_ADVICE, "runs": {},
                    "note": "runs on unknown roads alone: the residual of each at its own road estimate"}
    adequacy = dict(adequacy, roads=rec.to_dict())
    left = [r for r in adequacy.get("not_assessed") or [] if r not in rec.runs]
    adequacy["not_assessed"] = left
    if rec.verdict == "fail":
        return dict(adequacy, adequate=False, advice=ROAD_ADVICE + (" " + adequacy["advice"] if adequacy.get("advice")
                                                                    else ""),
                    reasons=[rec.reason] + list(adequacy.get("reasons") or []))
    note = adequacy.get("note", "")
    return dict(adequacy, note=PASSED_NOTE if "not assessed" in note or not note else note + "; " + PASSED_NOTE)


__all__ = ["assess", "judge", "run_figures", "PASSED_NOTE", "ROAD_ADVICE"]
