"""``[[tracks]]`` tables and profile files (SPEC §2) into :class:`rideid.model.tracks.Track` objects.

The keys of each track kind are one declarative table, :data:`TRACK_SECTIONS`
(kind -> :class:`rideid.data.schema.keys.Section`), checked by
:meth:`Section.read <rideid.data.schema.keys.Section.read>`; a ``profile``'s CSV
file is read here (:func:`read_profile`). The track classes themselves hold
numbers and arrays only.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...csvio import read_csv_rows
from ...errors import DataError
from ...model.tracks import KINDS, ProfileTrack, Track
from .keys import Key, Messages, Section

#: how a track table's problems are worded (``where`` names the file, the table and the track id)
TRACK_MESSAGES = Messages(
    unknown="{where}: unknown key '{key}' for kind '{kind}' (allowed: {allowed})",
    missing="{where}: missing key '{key}' for kind '{kind}'",
    number="{where}: key '{key}' must be a finite number, got {value!r}",
    positive="{where}: key '{key}' must be positive, got {number}",
    whole="{where}: key '{key}' must be a non-negative whole number, got {number}",
    between="{where}: key '{key}' must be between {lo:g} and {hi:g} {unit}, got {number}",
    string="{where}: key '{key}' must be a path string",
    choice="{where}: key '{key}' must be {choices}, got {value!r}")

_WASHBOARD = {"start": Key(required=True, unit="m"), "amplitude": Key(required=True, unit="m"),
              "wavelength": Key(required=True, unit="m", positive=True), "cycles": Key(required=True, whole=True)}

#: SPEC §2 track kind -> its keys, in SPEC order (``id`` and ``kind`` are every kind's)
TRACK_SECTIONS: dict[str, Section] = {kind: Section(keys, TRACK_MESSAGES, also=("id", "kind")) for kind, keys in {
    "washboard": _WASHBOARD,
    "herringbone": {**_WASHBOARD, "angle": Key(required=True, unit="degrees", between=(-89.0, 89.0))},
    "chassis_twist": {"start": Key(required=True, unit="m"), "height": Key(required=True, unit="m"),
                      "bump_length": Key(required=True, unit="m", positive=True),
                      "spacing": Key(required=True, unit="m", positive=True), "bumps": Key(required=True, whole=True),
                      "first": Key("string", default="left", choices=("left", "right"))},
    "flat": {},
    "profile": {"file": Key("string", required=True)},
}.items()}
#: the columns of a profile file (m)
PROFILE_COLUMNS = ("x", "z_left", "z_right")


def track_from_table(table: dict, where: str, base_dir: Path | None = None) -> Track:
    """Build and validate a track from its TOML table (a ``profile`` reads its file).

    Parameters
    ----------
    table : dict
        The ``[[tracks]]`` table: ``id``, ``kind`` and the kind's keys.
    where : str
        The place for messages, e.g. ``"dataset.toml: tracks[0]"``.
    base_dir : Path, optional
        The folder a profile's ``file`` is relative to.

    Returns
    -------
    Track
        Of the class of its kind (:data:`rideid.model.tracks.TRACK_KINDS`).
    """
    table = dict(table)
    tid = table.pop("id", None)
    if not isinstance(tid, str) or not tid:
        raise DataError(f"{where}: missing key 'id' (a non-empty string)")
    where = f"{where} (id '{tid}')"
    kind = table.pop("kind", None)
    if kind not in KINDS:
        raise DataError(f"{where}: unknown track kind {kind!r}; expected one of {', '.join(KINDS)}")
    keys = TRACK_SECTIONS[kind].read(table, where, kind=kind)
    track = Track(tid, kind, keys, base_dir)
    if kind != ProfileTrack.KIND:
        return track
    x, zl, zr = read_profile(track.data_file, where)
    return ProfileTrack.from_arrays(tid, x, zl, zr, file=keys["file"], base_dir=base_dir)


def read_profile(path: Path, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A profile file's columns ``x``, ``z_left``, ``z_right`` (m), each shape (n,), n >= 2, x strictly
    increasing; :class:`DataError` naming the file and line otherwise (``where``: the track, for a missing file)."""
    header, body = read_csv_rows(path, f"{where}: profile file not found: {path}", "profile")
    for c in PROFILE_COLUMNS:
        if c not in header:
            raise DataError(f"{path}: missing column '{c}' (need x, z_left, z_right)")
    idx = [header.index(c) for c in PROFILE_COLUMNS]
    data = []
    for ln, row in enumerate(body, start=2):
        if not row:
            continue
        try:
            vals = [float(row[i]) for i in idx]
        except (ValueError, IndexError):
            raise DataError(f"{path}: line {ln}: not a number in columns x, z_left, z_right") from None
        if not all(math.isfinite(v) for v in vals):
            raise DataError(f"{path}: line {ln}: NaN or infinite value")
        data.append(vals)
    if len(data) < 2:
        raise DataError(f"{path}: a profile needs at least two rows")
    arr = np.array(data)
    if np.any(np.diff(arr[:, 0]) <= 0):
        raise DataError(f"{path}: column 'x' must be strictly increasing")
    return arr[:, 0], arr[:, 1], arr[:, 2]


__all__ = ["TRACK_SECTIONS", "TRACK_MESSAGES", "PROFILE_COLUMNS", "track_from_table", "read_profile"]
