"""How far FMPy's ``simulate_fmu`` is from ``rideid simulate``, against :func:`rideid.exporter.drive_fmu`.

``python benchmarks/fmu_masters.py`` (FMPy and a C compiler needed; about a minute): the built-in
car's FMU driven over every run of the built-in scenario by ``simulate_fmu`` (inputs at the 200 Hz
samples and a 1 ms step; inputs and steps at 16 points per sample) and by ``drive_fmu`` (16 points per
sample), each as the range over the runs of RMS(difference) / RMS(channel) of the body and the axle
channels (docs/export.md quotes it).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu

import rideid
from rideid.exporter import car_from_scenario, drive_fmu, export
from rideid.exporter.fmu import INPUTS
from rideid.model.equations import CHANNELS
from rideid.model.simulate import prepare_run


def relative(Y, Yref):
    rms = np.sqrt(np.mean(Yref ** 2, axis=0))
    err = np.sqrt(np.mean((Y - Yref) ** 2, axis=0))
    return err / np.where(rms > 1e-12, rms, np.nan)


def main():
    sc = rideid.default_scenario()
    fmu = Path(tempfile.mkdtemp()) / "car"
    export(car_from_scenario(sc), fmu, format="fmu")
    fmu = str(fmu / "car.fmu")
    data, _ = rideid.simulate_manifest(sc)
    rows = {}
    for run in sc.runs:
        t, Yref = data[run.id]
        for how, sub in (("simulate_fmu, 200 Hz inputs, 1 ms step", 1), ("simulate_fmu, 16 points per sample", 16),
                         ("drive_fmu, 16 points per sample", 16)):
            tf = np.arange((t.size - 1) * sub + 1) * (t[1] / sub)
            r, rdot = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t).inputs_at(tf)
            if how.startswith("drive_fmu"):
                Y = drive_fmu(fmu, t, r, rdot, sub=sub)
            else:
                sig = np.zeros(tf.size, dtype=[("time", float)] + [(n, float) for n in INPUTS])
                sig["time"] = tf
                for k, n in enumerate(INPUTS):
                    sig[n] = r[:, k] if k < 4 else rdot[:, k - 4]
                step = 1e-3 if sub == 1 else t[1] / sub
                out = simulate_fmu(fmu, input=sig, output=list(CHANNELS), step_size=step, stop_time=t[-1],
                                   output_interval=step)
                Y = np.stack([np.interp(t, out["time"], out[c]) for c in CHANNELS], axis=1)
            rel = relative(Y, Yref)
            rows.setdefault(how, []).append((np.nanmax(rel[:4]), np.nanmax(rel[4:8])))
    print("| master | body channels | axle channels |\n|---|---|---|")
    for how, v in rows.items():
        b, a = np.array(v).T
        print(f"| {how} | {b.min():.2g} – {b.max():.2g} | {a.min():.2g} – {a.max():.2g} |")


if __name__ == "__main__":
    main()
