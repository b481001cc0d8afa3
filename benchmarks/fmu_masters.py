"""How close the exported car comes to ``rideid simulate`` under different FMI masters (docs/export.md).

``python benchmarks/fmu_masters.py [SCENARIO.toml]`` (FMPy and a C compiler needed; a few minutes): the
scenario's car (default: the built-in car) exported as ``car.fmu`` and driven over every run of the scenario,
the road given at the master's points only (no input derivatives, except ``drive_fmu``), at one data sample per
point and at 20 points per sample:

* Co-Simulation: FMPy's ``simulate_fmu`` (it reads the outputs at a step's end before it sets the inputs
  there); a master that sets the inputs of a point before it reads the outputs there (:func:`cs_set_then_get`);
  :func:`rideid.exporter.drive_fmu` (16 points per sample, the road's cubic Hermite as input derivatives);
* Model Exchange: FMPy's ``simulate_fmu`` with CVode (the FMU's default tolerance, 1e-7) and with forward
  Euler at one solver step per point; a master that sets the inputs of a point, reads the outputs, then takes
  one classical RK4 step to the next point (:func:`me_set_then_get`).

Each row: the worst channel over the runs, RMS(difference) / RMS(channel), for the body accelerations, the axle
accelerations and the gyros (``--per-run`` adds each run's; ``--only=TEXT`` keeps the masters whose label has it).
"""

from __future__ import annotations

import ctypes
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Model, FMU2Slave

import rideid
from rideid.exporter import car_from_scenario, drive_fmu, export
from rideid.exporter.fmu import INPUTS
from rideid.model.equations import CHANNELS
from rideid.model.simulate import prepare_run

GROUPS = {"body": slice(0, 4), "axle": slice(4, 8), "gyros": slice(8, 10)}


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


def at_samples(out, t):
    """The rows of a ``simulate_fmu`` result at the times ``t`` (the last row at each: FMPy's Model Exchange loop
    may record a point twice around an event)."""
    idx = np.searchsorted(out["time"], t + 1e-9 * (t[1] - t[0]), side="right") - 1
    assert np.allclose(out["time"][idx], t, rtol=0, atol=1e-9 * (t[1] - t[0]) + 1e-12)
    return np.stack([out[c][idx] for c in CHANNELS], axis=1)


def by_simulate_fmu(fmu, t, tf, r, rdot, fmi_type="CoSimulation", solver="CVode"):
    """FMPy's ``simulate_fmu`` with its defaults, the inputs as a table at ``tf``, output interval (and with
    ``solver="Euler"`` the step) ``tf[1] - tf[0]``: the outputs at ``t``."""
    sig = np.zeros(tf.size, dtype=[("time", float)] + [(n, float) for n in INPUTS])
    sig["time"] = tf
    for k, n in enumerate(INPUTS):
        sig[n] = r[:, k] if k < 4 else rdot[:, k - 4]
    kw = {}
    if fmi_type == "ModelExchange":
        kw = {"solver": solver, "record_events": False}
        if solver == "Euler":
            kw["step_size"] = tf[1] - tf[0]
    out = simulate_fmu(fmu, fmi_type=fmi_type, input=sig, output=list(CHANNELS), start_time=tf[0],
                       stop_time=tf[-1], output_interval=tf[1] - tf[0], **kw)
    return at_samples(out, t)


def _open(fmu, cls):
    md = read_model_description(fmu)
    unzipped = extract(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    s = cls(guid=md.guid, unzipDirectory=unzipped, modelIdentifier="car", instanceName="car")
    return md, unzipped, s, [vr[n] for n in INPUTS], [vr[c] for c in CHANNELS]


def cs_set_then_get(fmu, t, tf, r, rdot):
    """Co-Simulation: set the inputs of each point, read the outputs there (at the samples ``t``), step to the
    next point; no input derivatives."""
    md, unzipped, s, vin, vout = _open(fmu, FMU2Slave)
    sub = (tf.size - 1) // (t.size - 1)
    s.instantiate()
    s.setupExperiment(startTime=float(tf[0]))
    s.enterInitializationMode()
    s.setReal(vin, list(np.r_[r[0], rdot[0]]))
    s.exitInitializationMode()
    Y = np.empty((t.size, len(CHANNELS)))
    for k in range(tf.size):
        s.setReal(vin, list(np.r_[r[k], rdot[k]]))
        if k % sub == 0:
            Y[k // sub] = s.getReal(vout)
        if k + 1 < tf.size:
            s.doStep(float(tf[k]), float(tf[k + 1] - tf[k]))
    s.terminate()
    s.freeInstance()
    shutil.rmtree(unzipped, ignore_errors=True)
    return Y


def me_set_then_get(fmu, t, tf, r, rdot):
    """Model Exchange: at each point set the time and the inputs, read the outputs (at the samples ``t``), then
    one classical RK4 step to the next point, the inputs as set there (the FMU carries the road on along its
    rates between the times the master sets it)."""
    md, unzipped, s, vin, vout = _open(fmu, FMU2Model)
    nx = md.numberOfContinuousStates
    sub = (tf.size - 1) // (t.size - 1)
    x, dx = np.zeros(nx), np.zeros(nx)
    px, pdx = (a.ctypes.data_as(ctypes.POINTER(ctypes.c_double)) for a in (x, dx))

    def f(time, state):
        x[:] = state
        s.setTime(time)
        s.setContinuousStates(px, nx)
        s.getDerivatives(pdx, nx)
        return dx.copy()

    s.instantiate()
    s.setupExperiment(startTime=float(tf[0]))
    s.enterInitializationMode()
    s.setReal(vin, list(np.r_[r[0], rdot[0]]))
    s.exitInitializationMode()
    s.newDiscreteStates()
    s.enterContinuousTimeMode()
    s.getContinuousStates(px, nx)
    state = x.copy()
    Y = np.empty((t.size, len(CHANNELS)))
    for k in range(tf.size):
        s.setTime(float(tf[k]))
        s.setContinuousStates(state.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), nx)
        s.setReal(vin, list(np.r_[r[k], rdot[k]]))
        if k % sub == 0:
            Y[k // sub] = s.getReal(vout)
        if k + 1 < tf.size:
            h, t0 = float(tf[k + 1] - tf[k]), float(tf[k])
            k1 = f(t0, state)
            k2 = f(t0 + h / 2, state + h / 2 * k1)
            k3 = f(t0 + h / 2, state + h / 2 * k2)
            k4 = f(t0 + h, state + h * k3)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    s.terminate()
    s.freeInstance()
    shutil.rmtree(unzipped, ignore_errors=True)
    return Y


def masters(fmu):
    """``{row label: (drive(t, tf, r, rdot), points per sample)}``: every master of the tables."""
    out = {}
    for sub in (1, 20):
        step = "1 sample" if sub == 1 else f"1/{sub} sample"
        out[f"CS, FMPy `simulate_fmu`, step {step}"] = (lambda t, tf, r, rd: by_simulate_fmu(fmu, t, tf, r, rd), sub)
        out[f"CS, set then get, step {step}"] = (lambda t, tf, r, rd: cs_set_then_get(fmu, t, tf, r, rd), sub)
        out[f"ME, FMPy `simulate_fmu` CVode, output interval {step}"] = (
            lambda t, tf, r, rd: by_simulate_fmu(fmu, t, tf, r, rd, "ModelExchange"), sub)
        out[f"ME, FMPy `simulate_fmu` Euler, step {step}"] = (
            lambda t, tf, r, rd: by_simulate_fmu(fmu, t, tf, r, rd, "ModelExchange", "Euler"), sub)
        out[f"ME, set then get (RK4), step {step}"] = (lambda t, tf, r, rd: me_set_then_get(fmu, t, tf, r, rd), sub)
    out["CS, `drive_fmu` (Hermite input derivatives), step 1/16 sample"] = (
        lambda t, tf, r, rd: drive_fmu(fmu, t, r, rd, sub=16), 16)
    return out


def main(args):
    per_run = "--per-run" in args
    only = [a.split("=", 1)[1] for a in args if a.startswith("--only=")]
    paths = [a for a in args if not a.startswith("--")]
    sc = rideid.load_scenario(paths[0]) if paths else rideid.default_scenario()
    folder = Path(tempfile.mkdtemp()) / "car"
    export(car_from_scenario(sc), folder, format="fmu")
    fmu = str(folder / "car.fmu")
    data, _ = rideid.simulate_manifest(sc)
    print(f"{sc.name}: {len(sc.runs)} runs ({', '.join(r.id for r in sc.runs)})\n")
    print("| master, step | body | axle | gyros |\n|---|---|---|---|")
    rows = {}
    for how, (drive, sub) in masters(fmu).items():
        if only and not any(o in how for o in only):
            continue
        rel = {}
        for run in sc.runs:
            t, Yref = data[run.id]
            rel[run.id] = relative(drive(t, *fine_road(sc, run, t, sub)), Yref)
        rows[how] = rel
        worst = np.nanmax(np.array(list(rel.values())), axis=0)
        print(f"| {how} | " + " | ".join(f"{np.nanmax(worst[g]):.2g}" for g in GROUPS.values()) + " |",
              flush=True)
    if per_run:
        for how, rel in rows.items():
            print(f"\n{how} (body / axle / gyros):")
            for rid, e in rel.items():
                print(f"  {rid}: " + " / ".join(f"{np.nanmax(e[g]):.2g}" for g in GROUPS.values()))
    shutil.rmtree(folder.parent, ignore_errors=True)


if __name__ == "__main__":
    main(sys.argv[1:])
