"""Logger-style files made from simulated runs, written by the real libraries (tests only).

``simulate_raw`` simulates the built-in scenario's runs on a fine clock that
starts ``offset`` seconds before the front axle reaches x = 0 (the car
rolling on flat road), so the file's time 0 is ``offset`` s before the start.
``write_logger_dataset`` puts gravity, g units, deg/s, a sign flip and mixed
rates in, and writes MDF4, TDMS, Parquet or CSV files with a channel map.
"""

from __future__ import annotations

import numpy as np

from rideid.model.batch import BatchSimulator
from rideid.data.schema import DatasetManifest, RunSpec, write_toml
from rideid.model.equations import CHANNELS
from rideid.model.params import as_vector
from rideid.model.simulate import prepare_run

G0 = 9.80665
#: file channel names, units and signs of a made-up logger
LOGGER = {
    "body_az_fl": ("AccZ_Body_FL", "g", 1), "body_az_fr": ("AccZ_Body_FR", "g", -1),
    "body_az_rl": ("AccZ_Body_RL", "g", 1), "body_az_rr": ("AccZ_Body_RR", "m/s^2", 1),
    "axle_az_fl": ("AccZ_Hub_FL", "m/s^2", 1), "axle_az_fr": ("AccZ_Hub_FR", "m/s^2", 1),
    "axle_az_rl": ("AccZ_Hub_RL", "g", 1), "axle_az_rr": ("AccZ_Hub_RR", "g", 1),
    "pitch_rate": ("Gyro_Y", "deg/s", -1), "roll_rate": ("Gyro_X", "deg/s", 1),
}
#: body at 1 kHz, axles and gyro at 500 Hz
RATE = {c: (1000 if c.startswith("body") else 500) for c in CHANNELS}


def simulate_raw(sc, offset=2.3, fs=1000.0, tail=0.0, runs=None, P=None, distance=None):
    """run id -> (file time, Y (n, 10) SI without gravity) on a ``fs`` clock, file time = model time + offset."""
    P = as_vector(sc.truth) if P is None else P
    out = {}
    for run in sc.runs:
        if runs is not None and run.id not in runs:
            continue
        t = -offset + np.arange(int(round((run.duration + offset + tail) * fs)) + 1) / fs
        dist = None if distance is None else distance(run)
        ri = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t, distance=dist)
        y = BatchSimulator(sc.geometry, [ri]).outputs(P[None])[0][0]
        out[run.id] = (t + offset, y)
    return out


class Wobble:
    """A driver who does not hold speed: v(t) = v0 (1 + amp sin(2 pi t / period)), t from the start."""

    def __init__(self, v0, amp=0.1, period=3.0):
        self.v0, self.amp, self.period = v0, amp, period
        self.max_speed = v0 * (1 + amp)

    def speed(self, t):
        return self.v0 * (1 + self.amp * np.sin(2 * np.pi * t / self.period))

    def __call__(self, t):
        w = 2 * np.pi / self.period
        t = np.asarray(t, dtype=float)
        return self.v0 * (t + self.amp * (1 - np.cos(w * t)) / w)


def logger_channels(t, Y, gravity=True, wobble=None, offset=2.3, distance=False):
    """file channel name -> (time, values in the logger's unit and sign), unit.

    With ``wobble`` a 100 Hz speed channel in km/h (or, ``distance=True``, a
    distance channel in m) is added.
    """
    out = {}
    if wobble is not None:
        tt = t[::10]
        if distance:
            out["Odometer"] = (tt, wobble(tt - offset) - wobble(-offset) + 100.0, "m")
        else:
            out["Speed"] = (tt, wobble.speed(tt - offset) * 3.6, "km/h")
    for i, c in enumerate(CHANNELS):
        name, unit, sign = LOGGER[c]
        step = int(round(1000 / RATE[c]))
        v = Y[::step, i].copy()
        tt = t[::step]
        if c.endswith("rate"):
            v = np.degrees(v)
        else:
            if gravity:
                v = v + G0
            if unit == "g":
                v = v / G0
        out[name] = (tt, sign * v, unit)
    return out


def channel_map():
    return {c: {"name": n, "unit": u, **({"sign": -1} if s < 0 else {})} for c, (n, u, s) in LOGGER.items()}


def write_mdf(path, chans):
    from asammdf import MDF, Signal
    mdf = MDF(version="4.10")
    by_rate = {}
    for name, (t, v, unit) in chans.items():
        by_rate.setdefault(t.tobytes(), []).append(Signal(v, t, name=name, unit=unit))  # one group per time base
    for sigs in by_rate.values():
        mdf.append(sigs)
    mdf.save(str(path), overwrite=True)


def write_tdms(path, chans):
    from nptdms import ChannelObject, TdmsWriter
    objs = []
    for name, (t, v, unit) in chans.items():
        objs.append(ChannelObject("Logger", name, v, properties={
            "wf_start_offset": float(t[0]), "wf_increment": float(t[1] - t[0]), "unit_string": unit}))
    with TdmsWriter(str(path)) as w:
        w.write_segment(objs)


def _table(chans):
    """One time column at the fastest rate; slower channels null where not sampled."""
    t_all = max((c[0] for c in chans.values()), key=len)
    cols = {"Time": t_all}
    for name, (t, v, _unit) in chans.items():
        col = np.full(t_all.size, np.nan)
        idx = np.searchsorted(t_all, t)
        col[idx] = v
        cols[name] = col
    return cols


def write_parquet(path, chans):
    import pyarrow as pa
    import pyarrow.parquet as pq
    cols = _table(chans)
    fields = [pa.field("Time", pa.float64(), metadata={"unit": "s"})]
    arrays = [pa.array(cols["Time"])]
    for name, (_t, _v, unit) in chans.items():
        fields.append(pa.field(name, pa.float64(), metadata={"unit": unit}))
        arrays.append(pa.array(cols[name], from_pandas=True))
    pq.write_table(pa.Table.from_arrays(arrays, schema=pa.schema(fields)), str(path))


def write_csv(path, chans, delimiter=";", decimal=","):
    cols = _table(chans)
    names = list(cols)
    units = ["s"] + [chans[n][2] for n in names[1:]]
    lines = [delimiter.join(names), delimiter.join(units)]
    M = np.column_stack([cols[n] for n in names])
    for row in M:
        cells = ["" if np.isnan(x) else f"{x:.10g}".replace(".", decimal) for x in row]
        lines.append(delimiter.join(cells))
    path.write_text("\n".join(lines) + "\n")


WRITERS = {"mf4": write_mdf, "tdms": write_tdms, "parquet": write_parquet, "csv": write_csv}


def write_logger_dataset(sc, raw, out, fmt="mf4", preprocess=None, runs_extra=None, gravity=True,
                         wobbles=None, distance=False, offset=2.3):
    """A dataset folder of logger files with a channel map and [preprocess].

    ``wobbles``: run id -> :class:`Wobble` (the raw data simulated with it); those runs carry a speed
    (or distance) channel instead of a constant speed.
    """
    out.mkdir(parents=True, exist_ok=True)
    (out / "runs").mkdir(exist_ok=True)
    runs = []
    for run in sc.runs:
        if run.id not in raw:
            continue
        t, Y = raw[run.id]
        f = out / "runs" / f"{run.id}.{fmt}"
        wob = (wobbles or {}).get(run.id)
        WRITERS[fmt](f, logger_channels(t, Y, gravity, wob, offset, distance))
        runs.append(RunSpec(run.id, run.track, None if wob else run.speed, file=f"runs/{run.id}.{fmt}"))
    doc = DatasetManifest(**{**sc.shared(), "runs": runs, "extensions": None}).to_dataset_doc()
    cmap = channel_map()
    if fmt in ("csv", "parquet"):
        cmap["time"] = {"name": "Time", "unit": "s"}
    if wobbles:
        cmap["distance" if distance else "speed"] = ({"name": "Odometer", "unit": "m"} if distance
                                                     else {"name": "Speed", "unit": "km/h"})
    doc["channels"] = cmap
    doc["preprocess"] = preprocess if preprocess is not None else {"gravity_included": gravity}
    for r in doc["runs"]:
        r.update((runs_extra or {}).get(r["id"], {}))
    write_toml(out / "dataset.toml", doc)
    return out
