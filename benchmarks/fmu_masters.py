"""How close the exported car comes to ``rideid simulate`` under different FMI masters (docs/export.md).

``python benchmarks/fmu_masters.py [SCENARIO.toml]`` (FMPy and a C compiler needed; about a minute): the
scenario's car (default: the built-in car) exported as ``car.fmu`` and driven over every run of the scenario

* by FMPy's ``simulate_fmu`` with its defaults, the road given at the communication points only: one, 2, 4
  and 20 points per sample interval (communication step = data interval / points);
* by a master that sets the inputs of a point before it reads the outputs there, no input derivatives;
* by :func:`rideid.exporter.drive_fmu` (16 points per sample, the road's cubic Hermite as input derivatives).

Each row: the range over the runs of each run's worst channel, RMS(difference) / RMS(channel), for the body
accelerations, the axle accelerations and the gyros.
"""

from __future__ import annotations

import functools
import sys
import tempfile
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave

import rideid
from rideid.exporter import car_from_scenario, drive_fmu, export
from rideid.exporter.fmu import INPUTS
from rideid.model.equations import CHANNELS
from rideid.model.simulate import prepare_run

GROUPS = {"body": slice(0, 4), "axle": slice(4, 8), "gyro": slice(8, 10)}


def relative(Y, Yref):
    """RMS(Y - Yref) / RMS(Yref) per channel (NaN for a channel that stays 0)."""
    rms = np.sqrt(np.mean(Yref ** 2, axis=0))
    err = np.sqrt(np.mean((Y - Yref) ** 2, axis=0))
    return err / np.where(rms > 1e-12, rms, np.nan)


def fine_road(sc, run, t, sub):
    """The run's wheel inputs at ``sub`` points per sample interval: times, r, rdot."""
    tf = np.arange((t.size - 1) * sub + 1) * ((t[1] - t[0]) / sub) + t[0]
    r, rdot = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t).inputs_at(tf)
    return tf, r, rdot


def by_simulate_fmu(fmu, t, tf, r, rdot, sub):
    """FMPy's ``simulate_fmu``, the inputs as a table at ``tf``, communication step ``tf[1] - tf[0]``."""
    sig = np.zeros(tf.size, dtype=[("time", float)] + [(n, float) for n in INPUTS])
    sig["time"] = tf
    for k, n in enumerate(INPUTS):
        sig[n] = r[:, k] if k < 4 else rdot[:, k - 4]
    out = simulate_fmu(fmu, input=sig, output=list(CHANNELS), stop_time=tf[-1], output_interval=tf[1] - tf[0])
    assert out.size == tf.size
    return np.stack([out[c][::sub] for c in CHANNELS], axis=1)


def set_then_read(fmu, t, r, rdot):
    """A master that sets the inputs of each sample, reads the outputs there, then steps (no derivatives)."""
    md = read_model_description(fmu)
    unzipped = extract(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    vin, vout = [vr[n] for n in INPUTS], [vr[c] for c in CHANNELS]
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="car", instanceName="car")
    s.instantiate()
    s.setupExperiment(startTime=float(t[0]))
    s.enterInitializationMode()
    s.setReal(vin, list(np.r_[r[0], rdot[0]]))
    s.exitInitializationMode()
    Y = np.empty((t.size, len(CHANNELS)))
    for k in range(t.size):
        s.setReal(vin, list(np.r_[r[k], rdot[k]]))
        Y[k] = s.getReal(vout)
        if k + 1 < t.size:
            s.doStep(float(t[k]), float(t[k + 1] - t[k]))
    s.terminate()
    s.freeInstance()
    return Y


def main(path=None):
    sc = rideid.load_scenario(path) if path else rideid.default_scenario()
    folder = Path(tempfile.mkdtemp()) / "car"
    export(car_from_scenario(sc), folder, format="fmu")
    fmu = str(folder / "car.fmu")
    data, _ = rideid.simulate_manifest(sc)
    masters = {f"`simulate_fmu`, step = 1/{sub} sample" if sub > 1 else "`simulate_fmu`, step = 1 sample":
               functools.partial(lambda t, run, sub: by_simulate_fmu(fmu, t, *fine_road(sc, run, t, sub), sub),
                                 sub=sub) for sub in (1, 2, 4, 20)}
    masters["inputs set before the outputs are read, step = 1 sample"] = lambda t, run: set_then_read(
        fmu, t, *fine_road(sc, run, t, 1)[1:])
    masters["`drive_fmu`, step = 1/16 sample"] = lambda t, run: drive_fmu(
        fmu, t, *fine_road(sc, run, t, 16)[1:], sub=16)
    print(f"{sc.name}: {len(sc.runs)} runs ({', '.join(r.id for r in sc.runs)})\n")
    print("| master | body | axle | gyros |\n|---|---|---|---|")
    for how, drive in masters.items():
        rel = np.array([relative(drive(t, run), Yref) for run in sc.runs for t, Yref in [data[run.id]]])
        cells = []
        for g in GROUPS.values():
            worst = np.nanmax(rel[:, g], axis=1)
            cells.append(f"{worst.min():.2g} – {worst.max():.2g}")
        print(f"| {how} | " + " | ".join(cells) + " |", flush=True)
    print("\nper run, `simulate_fmu` at 1 sample per step (body / axle / gyros):")
    for run in sc.runs:
        t, Yref = data[run.id]
        rel = relative(masters["`simulate_fmu`, step = 1 sample"](t, run), Yref)
        print(f"  {run.id}: " + " / ".join(f"{np.nanmax(rel[g]):.2g}" for g in GROUPS.values()))


if __name__ == "__main__":
    main(*sys.argv[1:2])
