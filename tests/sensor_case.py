"""Sensors as wired (SPEC §11): logger files of the built-in car through real sensor chains (tests only).

The car is rideid's exact 7-DOF response of the built-in scenario
(:func:`tests.logger_files.simulate_raw`, 1 kHz, the recording starting
``OFFSET`` s before the front axle reaches x = 0, the car rolling on flat
road), written with SPEC channel names in SI units. What the sensors do to it
is applied independently of rideid:

* AC coupling: :func:`scipy.signal.lsim` of the analog Butterworth high-pass
  (``scipy.signal.butter(..., analog=True)``) on the 1 kHz signal, the filter
  at rest before the recording (the car stood still): not rideid's
  discretisation at the model's 200 Hz;
* clipping: ``numpy.clip`` at the sensor's full scale.

White sensor noise of ``noise`` times each channel's RMS is added before the
chain (an IEPE sensor's own noise passes its coupling) and before clipping.
"""

from __future__ import annotations

import numpy as np

import rideid
from rideid.data.schema import write_toml
from rideid.model.equations import CHANNELS

from logger_case import _shared_doc
from logger_files import simulate_raw

G0 = 9.80665
OFFSET = 2.3
FILE_FS = 1000.0


def analog_highpass(t, y, hz: float, order: int = 1) -> np.ndarray:
    """``y`` sampled at ``t`` through an analog Butterworth high-pass (lsim, linear between samples)."""
    from scipy.signal import butter, lsim
    z, p, k = butter(order, 2 * np.pi * hz, btype="highpass", analog=True, output="zpk")
    return lsim((z, p, k), y, t - t[0])[1]


def write_sensor_dataset(folder, *, highpass=None, declare=True, clip=None, declare_range=True,
                         noise=0.02, seed=3, runs=None):
    """Write the built-in car's runs as SPEC-named 1 kHz CSVs through the given sensor chain.

    Parameters
    ----------
    highpass : (channels, hz, order), optional
        AC coupling of these channels.
    declare : bool
        Whether ``[channels]`` declares the high-pass.
    clip : (channel, g), optional
        That channel clips at +- this many g.
    declare_range : bool
        Whether ``[channels]`` declares the range.

    Returns
    -------
    (folder, clipped share per run of the clipped channel)
    """
    sc = rideid.default_scenario()
    raw = simulate_raw(sc, offset=OFFSET, fs=FILE_FS, runs=runs)
    rng = np.random.default_rng(seed)
    (folder / "runs").mkdir(parents=True, exist_ok=True)
    doc = _shared_doc(sc)
    entries = {}
    share = {}
    out_runs = []
    for run in sc.runs:
        if run.id not in raw:
            continue
        t, Y = raw[run.id]
        Y = Y.copy()
        rms = np.sqrt(np.mean(Y[t > OFFSET] ** 2, axis=0))
        Y += rng.standard_normal(Y.shape) * noise * rms
        if highpass is not None:
            chans, hz, order = highpass
            for c in chans:
                i = CHANNELS.index(c)
                Y[:, i] = analog_highpass(t, Y[:, i], hz, order)
        if clip is not None:
            c, g = clip
            i = CHANNELS.index(c)
            Y[:, i] = np.clip(Y[:, i], -g * G0, g * G0)
            share[run.id] = float(np.mean(np.abs(Y[:, i]) >= g * G0))
        lines = ["time," + ",".join(CHANNELS)] + [
            f"{ti:.6f}," + ",".join(f"{v:.9g}" for v in row) for ti, row in zip(t, Y)]
        (folder / "runs" / f"{run.id}.csv").write_text("\n".join(lines) + "\n")
        out_runs.append({"id": run.id, "track": run.track, "speed": run.speed, "file": f"runs/{run.id}.csv"})
    if highpass is not None and declare:
        chans, hz, order = highpass
        for c in chans:
            entries[c] = {"name": c, "highpass": hz if order == 1 else {"hz": hz, "order": order}}
    if clip is not None and declare_range:
        c, g = clip
        entries[c] = {**entries.get(c, {"name": c}), "name": c, "unit": "m/s^2", "range": g * G0}
    doc["channels"] = entries or {"time": {"name": "time", "unit": "s"}}
    doc["preprocess"] = {"fs": 200.0}
    doc["runs"] = out_runs
    write_toml(folder / "dataset.toml", doc)
    return folder, share
