"""A dataset's data quality in one table: per channel, over every run, what the sensors and the logger did.

Per SPEC channel: the share of samples at the channel's range (left out of
the fit, SPEC §11) and in which runs, the gaps in its time bridged by
interpolation, its noise level (the RMS of the quietest quarter second of
each run's model window about its mean, :func:`rideid.data.measured.quietest_rms`,
the median over the runs: the sensor noise where the car stood or rolled on
flat road), the runs where it flat-lined, and its sensor chain as the model passes it (the declared
filters, and rideid's own anti-alias filter where it low-passed the data, marked so).
The terminal prints this table instead of one warning per run and channel;
``result.json`` keeps it under ``data_quality`` and the report shows it.
"""

from __future__ import annotations

import numpy as np

from ..model.equations import CHANNEL_KIND, CHANNELS
from .measured import default_rate, quietest_rms

#: the stretch (s) whose RMS is a channel's noise level
NOISE_WINDOW_S = 0.25
#: warnings the table replaces (the per-run lines about these are not printed one by one)
SUMMARISED = (": clipped: ", "gap(s) in time", ": flat-lined ")


def data_quality(ds) -> dict:
    """``{"channels": {name: {...}}, "runs": n}`` (module docstring); JSON-ready.

    Each channel's entry: ``clipped_share`` (the largest share of a run's model samples at the range),
    ``clipped_runs`` (run -> share, runs with any), ``gaps`` (gaps bridged, over all runs), ``noise``
    (median noise level, SI) and ``unit``, ``flat_lined`` (runs), ``filters`` (the declared chain, as
    described), ``runs`` (how many runs measure it).
    """
    out = {}
    for i, name in enumerate(CHANNELS):
        entry = {"runs": 0, "clipped_share": 0.0, "clipped_runs": {}, "gaps": 0, "noise": None,
                 "unit": "rad/s" if CHANNEL_KIND[name] == "rate" else "m/s^2", "flat_lined": [], "filters": []}
        noise = []
        for r in ds.runs:
            rd = ds.data.get(r.id)
            if rd is None or name not in rd.channels:
                continue
            entry["runs"] += 1
            v = np.asarray(rd.channels[name], dtype=float)
            fs = rd.fs
            clipped = ds.clipped(r.id)
            if clipped is not None and clipped[:, i].any():
                share = float(clipped[:, i].mean())
                entry["clipped_runs"][r.id] = share
                entry["clipped_share"] = max(entry["clipped_share"], share)
            mr = ds.measured.get(r.id)
            rec = (mr.record.get("channels", {}).get(name, {}) if mr is not None else {})
            entry["gaps"] += int(rec.get("gaps", {}).get("count", 0))
            if rec.get("flat_lined") or np.ptp(v) == 0:
                entry["flat_lined"].append(r.id)
            else:
                noise.append(quietest_rms(v, int(round(NOISE_WINDOW_S * fs))))
            declared = rec.get("sensor_filters", [])
            for f in ds.sensor_filters(r.id)[i]:
                d = f.describe()
                d = d if d in declared or mr is None else d + " (rideid's anti-alias)"  # the model's chain passes both
                if d not in entry["filters"]:
                    entry["filters"].append(d)
        if entry["runs"]:
            entry["noise"] = float(np.median(noise)) if noise else None
            out[name] = entry
    return {"channels": out, "runs": len(ds.runs)}


def quality_table(quality: dict) -> str:
    """The terminal's data-quality table: one line per channel."""
    lines = [f"{'channel':<12} {'runs':>4} {'clipped':>8}  {'gaps':>4} {'noise':>10}  {'unit':<6} notes"]
    for name, e in quality["channels"].items():
        clip = f"{100 * e['clipped_share']:.2f}%" if e["clipped_runs"] else "-"
        noise = "-" if e["noise"] is None else f"{e['noise']:.3g}"
        notes = []
        if e["clipped_runs"]:
            notes.append("clipped in " + ", ".join(e["clipped_runs"]) + " (left out of the fit)")
        if e["flat_lined"]:
            notes.append("flat-lined in " + ", ".join(e["flat_lined"]))
        if e["filters"]:
            notes.append("filtered: " + "; ".join(e["filters"]))
        lines.append(f"{name:<12} {e['runs']:>4} {clip:>8}  {e['gaps']:>4} {noise:>10}  {e['unit']:<6} "
                     + "; ".join(notes))
    lines.append("clipped: the largest share of a run's samples at the channel's range; gaps: bridged by "
                 "interpolation; noise: RMS of the quietest 0.25 s (median over runs)")
    return "\n".join(lines)


def summarised_warning(message: str) -> bool:
    """Whether a data warning is one the quality table stands for (clipping, gaps, flat lines)."""
    return any(s in message for s in SUMMARISED)


def partial_channels(ds) -> dict[str, list[str]]:
    """SPEC channel -> the runs that lack it, for each channel some runs measure and others do not (a column left
    out of one file). SPEC says a missing channel is simply not used, so those runs are fitted without it; a
    channel no run has (a car without gyros) is not a slip and is not listed."""
    runs = [r.id for r in ds.runs if r.id in ds.data]
    lacking = {name: [rid for rid in runs if name not in ds.data[rid].channels] for name in CHANNELS}
    return {name: ids for name, ids in lacking.items() if 0 < len(ids) < len(runs)}


def partial_channel_lines(ds) -> list[str]:
    """The terminal's note per channel of :func:`partial_channels`, so that a column deleted by mistake does not
    pass unseen."""
    runs = sum(r.id in ds.data for r in ds.runs)
    return [f"note: {name} is not in run(s) {', '.join(ids)} (measured on {runs - len(ids)} of {runs} runs): fitted "
            "without it there; check the file if it should be" for name, ids in partial_channels(ds).items()]




def resampling_lines(ds) -> list:
    """The terminal's lines on rates and filters: per group of runs read the same way, the file's rates, the
    model's rate and the rule that chose it, and each filter rideid applied to the data (kind, corner, order,
    channels; whether the model's channels pass it too). From each run's ``preprocessing.<run>.resampling``
    record; none for SPEC CSVs taken as they are."""
    groups: dict = {}
    for r in ds.runs:
        mr = ds.measured.get(r.id)
        rec = (mr.record.get("resampling") if mr is not None else None)
        if not rec:
            continue
        parts = [f"{'/'.join(f'{x:g}' for x in rec['file_rates_hz'])} Hz -> {rec['fs']:g} Hz ({rec['rule']})"]
        dec = sorted(set(rec["decimated"].values()))
        if dec:
            parts.append("decimated (1 sample in " + "/".join(str(n) for n in dec) + " taken), no filter")
        for f in rec["filters"]:
            chans = _channels_text(f["channels"])
            if f["kind"] == "lowpass":
                parts.append(f"low-pass {f['hz']:g} Hz, order {f['order']} ({f['design']}, {f['why']}) on {chans}; "
                             "the model's channels pass the same filter")
            else:
                parts.append(f"{f['what']} on {chans}" + ("" if f["model"] else "; NOT seen by the model"))
        groups.setdefault(tuple(parts), []).append(r.id)
    return [f"rates ({', '.join(ids)}): " + "; ".join(parts) for parts, ids in groups.items()]


def _channels_text(chans) -> str:
    """``"the 10 channels"``, ``"the 8 accelerations"`` or the names."""
    if len(chans) == len(CHANNELS):
        return "all 10 channels"
    return ", ".join(chans)


def resampled_runs(measured: dict) -> dict:
    """Run id -> what rideid did to its channels to reach the model's rate, for the runs it low-passed or
    interpolated (``preprocessing.<run>.resampling.filters``: a rate the model's does not divide, or
    ``anti_alias = true``): ``channels`` (the names touched), ``file_rates_hz``, ``fs`` (the model's rate) and
    ``divides`` (the rate that takes every sample as it is, :func:`rideid.data.measured.default_rate`). A fact of
    the files, known at load (:attr:`rideid.data.dataset.Dataset.resampled`); the verdict's advice names it
    (:func:`rideid.estimate.assess.sensor_check.rate_advice`)."""
    out = {}
    for rid, mr in measured.items():
        res = mr.record.get("resampling")
        if not res or not res.get("filters"):
            continue
        out[rid] = {"channels": frozenset(c for f in res["filters"] for c in f["channels"]),
                    "file_rates_hz": list(res["file_rates_hz"]), "fs": res["fs"],
                    "divides": default_rate(res["file_rates_hz"])[0]}
    return out


__all__ = ["NOISE_WINDOW_S", "data_quality", "partial_channel_lines", "partial_channels", "quality_table",
           "resampled_runs", "resampling_lines", "summarised_warning"]
