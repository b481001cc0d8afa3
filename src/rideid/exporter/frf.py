"""``frf.csv`` (SPEC §13): the identified car's frequency responses with the std of their magnitude.

One row per frequency, output and input: ``f_hz, output, input, magnitude,
phase_deg, magnitude_std`` (:data:`rideid.estimate.assess.frequency.FRF_COLUMNS`),
``H`` per metre of road height under the wheel in the output's unit
(m/s² or rad/s for the ten channels, m or rad for ``heave``, ``pitch``,
``roll``; docs/frequency-response.md).
"""

from __future__ import annotations

import csv
from pathlib import Path

from ..estimate.assess.frequency import FRF_COLUMNS, frequency_response


def write_frf(result, folder, freq=None) -> Path:
    """Write ``frf.csv`` of ``result`` (:func:`rideid.estimate.assess.frequency.frequency_response`) into ``folder``."""
    fr = frequency_response(result, freq)
    path = Path(folder) / "frf.csv"
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(FRF_COLUMNS)
        for f_hz, out, inp, mag, ph, sd in fr.rows():
            w.writerow([f"{f_hz:.9g}", out, inp, f"{mag:.9g}", f"{ph:.9g}", f"{sd:.6g}"])
    return path


__all__ = ["write_frf"]
