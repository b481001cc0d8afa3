"""How far a logger's data, as rideid resamples them, are from the model's channels at the model's rate.

The van with real dampers of ``tests/rate_case.py`` (its five runs, no noise) is simulated at 1 kHz; every
second sample is the 500 Hz logger's file. The data path is rideid's own
(:func:`rideid.data.measured._filter_resample`, then the run's read-off at the model's samples), the model's
channel is the 1 kHz simulation's sample at each model time, passed through the run's sensor chain as the
cost passes it (:class:`rideid.model.sensors.SensorChain`, with the filters rideid added). Printed per run:
the largest RMS difference over the ten channels, in units of 1 % sensor noise (``--noise 0.01``, each
channel's own RMS), and the channel. A fit cannot tell a difference well below 1 from noise; one above it is
structure in the residual.

    PYTHONPATH=src python benchmarks/resample_mismatch.py        # about a minute
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
from rate_case import van_scenario  # noqa: E402
from rideid.data.measured import _filter_resample  # noqa: E402
from rideid.data.readers import Signal  # noqa: E402
from rideid.model.equations import CHANNELS  # noqa: E402
from rideid.model.sensors import SensorChain  # noqa: E402

CASES = [("500 Hz read at 250 Hz (the default: 1 sample in 2)", 500, 250.0, None),
         ("500 Hz read at 200 Hz, zero-phase low-pass in the data only (the default before)", 500, 200.0, "legacy"),
         ("500 Hz read at 200 Hz, low-pass in the data and in the model (fs = 200, anti_alias = true)", 500, 200.0,
          True),
         ("500 Hz read at 200 Hz, cubic spline, no filter (fs = 200: the default now)", 500, 200.0, None),
         ("1000 Hz read at 200 Hz (the default: 1 sample in 5)", 1000, 200.0, None)]


def mismatch(t, Y, src, fs, anti_alias):
    """Per channel the RMS of data minus model over the run, in units of 1 % of the channel's RMS."""
    k = int(round(1000 / src))
    ts, Ys = t[::k], Y[::k]
    raw = {c: Signal(ts, Ys[:, i], "SI") for i, c in enumerate(CHANNELS)}
    rec = {c: {"rate_hz": float(src)} for c in CHANNELS}
    if anti_alias == "legacy":  # order 8 at 0.4 fs, zero-phase, in the data only; the model unfiltered
        from scipy.signal import butter, sosfiltfilt
        sos = butter(8, 0.4 * fs, fs=src, output="sos")
        raw = {c: Signal(ts, sosfiltfilt(sos, s.values), "SI") for c, s in raw.items()}
        chans, _ = _filter_resample(raw, rec, list(CHANNELS), fs, False)
        added = {}
    else:
        chans, added = _filter_resample(raw, rec, list(CHANNELS), fs, anti_alias)
    n = int(np.floor((ts[-1] - ts[0]) * fs + 1e-9)) + 1
    data = np.column_stack([chans[c].samples(ts[0], fs, n) for c in CHANNELS])
    step = int(round(1000 / fs)) if abs(1000 / fs - round(1000 / fs)) < 1e-9 else None
    if step is not None:
        inst = Y[::step][:n]
    else:  # the model's samples fall between the 1 kHz ones: not used by the cases above
        raise ValueError(fs)
    chain = SensorChain(tuple(tuple(added.get(c, ())) for c in CHANNELS), 1.0 / fs)
    model = chain.apply(inst)
    level = 0.01 * np.sqrt(np.mean(Y ** 2, axis=0))
    edge = int(0.1 * fs)  # the file's last samples: the read-off's end
    diff = np.sqrt(np.mean((data - model)[:-edge] ** 2, axis=0))
    return np.where(level > 0, diff / np.where(level > 0, level, 1.0), 0.0)


def main():
    with tempfile.TemporaryDirectory() as tmp:
        sc = van_scenario(Path(tmp), 1000.0)
        data, _ = rideid.simulate_manifest(sc, noise=0.0, seed=1)
    print("| case | " + " | ".join(data) + " |")
    print("|---|" + "---|" * len(data))
    for name, src, fs, aa in CASES:
        cells = []
        for t, Y in data.values():
            rel = mismatch(t, Y, src, fs, aa)
            cells.append(f"{rel.max():.2f} ({CHANNELS[int(np.argmax(rel))]})")
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
