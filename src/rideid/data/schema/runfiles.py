"""Run files of SPEC §3 (``time`` and the SPEC channels, SI units) and the model-ready run data.

:class:`RunData` is what every run becomes before identification, whether
read from a SPEC CSV here or conditioned from a logger file by
:mod:`rideid.data.measured`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...csvio import read_csv_rows
from ...errors import DataError, DataWarning
from ...model.equations import CHANNELS
from ...model.posts import POST_CHANNELS, POST_VEL_CHANNELS


@dataclass
class RunData:
    """Measured data of one run: uniform time and the channels present."""

    time: np.ndarray
    channels: dict[str, np.ndarray]
    #: ``distance(t)``: front-axle distance past x = 0 at model time t (varying speed); None for constant speed
    distance: object = None
    #: a four-post rig run's post displacements ``(n, 4)`` fl, fr, rl, rr (m, SPEC §13); None on a road
    posts: np.ndarray | None = None
    #: ... and the measured post velocities ``(n, 4)`` (m/s), None when computed from the displacements
    post_vel: np.ndarray | None = None

    @property
    def fs(self) -> float:
        return 1.0 / float(self.time[1] - self.time[0])

    def matrix(self) -> np.ndarray:
        """(n, 10) in CHANNELS order, NaN where a channel is missing."""
        Y = np.full((self.time.size, len(CHANNELS)), np.nan)
        for i, c in enumerate(CHANNELS):
            if c in self.channels:
                Y[:, i] = self.channels[c]
        return Y


def missing_post_channel(present) -> str | None:
    """The first post channel a four-post rig run (SPEC §13) lacks among the names ``present``: its four
    displacements are needed (:data:`~rideid.model.posts.POST_CHANNELS`), its four velocities all or none
    (:data:`~rideid.model.posts.POST_VEL_CHANNELS`); None when nothing is missing."""
    needed = POST_CHANNELS + (POST_VEL_CHANNELS if any(c in present for c in POST_VEL_CHANNELS) else ())
    return next((c for c in needed if c not in present), None)


def check_post_channels(present, where, absent: str = "is missing"):
    """A :class:`DataError` (``where: ...``) naming the first post channel a four-post rig run lacks among the
    names ``present`` (:func:`missing_post_channel`) and how it is missing (``absent``); nothing if none is."""
    gap = missing_post_channel(present)
    if gap in POST_CHANNELS:
        raise DataError(f"{where}: a four-post rig run (input = \"posts\") needs the four post displacements "
                        f"{', '.join(POST_CHANNELS)} (m); '{gap}' {absent}")
    if gap is not None:
        raise DataError(f"{where}: give all four post velocities {', '.join(POST_VEL_CHANNELS)} (m/s) or none "
                        f"(then computed from the displacements); '{gap}' {absent}")


def read_run_csv(path: Path, posts: bool = False) -> RunData:
    """Read and validate a run CSV (SPEC §3); ``posts``: a four-post rig run's (SPEC §13), whose columns
    ``post_fl … post_rr`` (m) must all be there, and ``post_vel_fl … post_vel_rr`` (m/s) all or none."""
    path = Path(path)
    header, body = read_csv_rows(path, f"{path}: run file not found")
    if "time" not in header:
        raise DataError(f"{path}: missing column 'time'")
    dup = {c for c in header if header.count(c) > 1}
    if dup:
        raise DataError(f"{path}: duplicate column '{sorted(dup)[0]}'")
    data_rows = [r for r in body if r and any(x.strip() for x in r)]
    if not data_rows:
        raise DataError(f"{path}: header only, no data rows")
    if len(data_rows) < 3:
        raise DataError(f"{path}: only {len(data_rows)} data rows; at least 3 are needed")
    rig = POST_CHANNELS + POST_VEL_CHANNELS if posts else ()
    if posts:
        check_post_channels(header, path)
    used = [c for c in header if c == "time" or c in CHANNELS or c in rig]
    extra = [c for c in header if c not in used]
    if extra:
        hint = (" (post channels are read from a rig run: input = \"posts\")"
                if any(c in POST_CHANNELS for c in extra) else "")
        warnings.warn(f"{path}: ignoring column(s) not in the SPEC channels: {', '.join(extra)}{hint}",
                      DataWarning, stacklevel=2)
    idx = {c: header.index(c) for c in used}
    arr = np.empty((len(data_rows), len(used)))
    for ln, row in enumerate(data_rows, start=2):
        if len(row) != len(header):
            raise DataError(f"{path}: line {ln}: {len(row)} fields, header has {len(header)}")
        for j, c in enumerate(used):
            try:
                arr[ln - 2, j] = float(row[idx[c]])
            except ValueError:
                raise DataError(f"{path}: line {ln}, column '{c}': not a number: {row[idx[c]]!r}") from None
    for j, c in enumerate(used):
        bad = ~np.isfinite(arr[:, j])
        if bad.any():
            ln = int(np.argmax(bad)) + 2
            raise DataError(f"{path}: column '{c}' has a NaN or infinite value (line {ln})")
    t = arr[:, used.index("time")]
    dt = np.diff(t)
    if np.any(dt <= 0):
        ln = int(np.argmax(dt <= 0)) + 3
        raise DataError(f"{path}: column 'time' is not strictly increasing (line {ln})")
    h = (t[-1] - t[0]) / (t.size - 1)
    if np.max(np.abs(dt - h)) > 1e-6 * h + 1e-9:
        ln = int(np.argmax(np.abs(dt - h))) + 3
        raise DataError(f"{path}: column 'time' is not uniform (step {dt[ln - 3]:.6g} s at line {ln}, "
                        f"mean step {h:.6g} s)")
    lo, hi = PLAUSIBLE_RATE
    if not lo <= 1.0 / h <= hi:  # a time column in ms (SPEC §3: seconds): one line, not a run 1000 times too long
        fits = time_units_fitting(1.0 / h)
        raise DataError(f"{path}: column 'time' steps {h:.6g} per sample, a sample rate of {1.0 / h:.3g} Hz, not a "
                        f"ride recording's ({lo:g} Hz - {hi / 1000:g} kHz); SPEC §3 wants the time in seconds"
                        + (f": is it in {fits[0]}?" if fits else ""))
    # rebuild an exactly uniform time base
    t = t[0] + h * np.arange(t.size)
    channels = {c: arr[:, j] for j, c in enumerate(used) if c in CHANNELS}
    if not channels:
        raise DataError(f"{path}: no measured channel; expected some of {', '.join(CHANNELS)}")
    post = vel = None
    if posts:
        post = np.column_stack([arr[:, used.index(c)] for c in POST_CHANNELS])
        if POST_VEL_CHANNELS[0] in used:
            vel = np.column_stack([arr[:, used.index(c)] for c in POST_VEL_CHANNELS])
    return RunData(t, channels, posts=post, post_vel=vel)


#: sample rates (Hz) of a ride recording: below, a time column read in too large a unit (ms taken as s); above,
#: in too small a one (s taken as ms)
PLAUSIBLE_RATE = (5.0, 200_000.0)
#: a time column's units and their factors to seconds, for the hint
_TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6}


def time_units_fitting(rate: float, time_scale: float = 1.0) -> list:
    """The time units (of :data:`_TIME_UNITS`) that would give a recording read at ``rate`` Hz (its time column
    scaled by ``time_scale`` to seconds) a rate of 50 Hz - 20 kHz, the middle of :data:`PLAUSIBLE_RATE`."""
    return [u for u, f in _TIME_UNITS.items() if 50.0 <= rate * time_scale / f <= 20_000.0]


def write_run_csv(path: Path, time, Y, channels=CHANNELS):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    M = np.column_stack([time, Y])
    np.savetxt(path, M, delimiter=",", header=",".join(("time",) + tuple(channels)), comments="", fmt="%.12g")


__all__ = ["RunData", "read_run_csv", "write_run_csv", "PLAUSIBLE_RATE", "time_units_fitting"]
