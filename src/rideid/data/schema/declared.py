"""Declared uncertainties in files (SPEC §12): ``{ value, std }`` and ``sensitivity_std``.

A ``[known]`` or ``[vehicle]`` value may be written as ``{ value = 2090.0,
std = 10.0 }``: the value and its standard uncertainty (a weighbridge's, a
tape's), in the value's unit. A ``[channels]`` entry may give
``sensitivity_std``: the relative standard uncertainty of that sensor's
sensitivity (``0.02``: calibrated to 2 %). A plain number is exact, as before.
:mod:`rideid.estimate.fit.budget` propagates what is declared to the estimates.
"""

from __future__ import annotations

import math

from ...errors import DataError
from ...model.equations import CHANNELS

#: the keys of a declared value
DECLARED_KEYS = ("value", "std")
#: the key of a ``[channels]`` entry that declares the sensor's relative sensitivity uncertainty
SENSITIVITY_KEY = "sensitivity_std"
#: a relative sensitivity uncertainty must be below this (a sensor known to 50 % is not calibrated at all)
SENSITIVITY_STD_MAX = 0.5

_WHERE_ALLOWED = ("a standard uncertainty { value, std } is accepted only in [known] and [vehicle], a dataset "
                  "run's speed and start and a track's amplitude or height (and sensitivity_std in a [channels] "
                  "entry)")


def split_declared(v, where: str):
    """``(value, std)`` of a value as written: a plain value gives ``(v, None)``; ``{ value, std }`` is checked
    (only those two keys, both present, ``std`` a finite number >= 0) and gives ``(value, std)``, the value
    unchecked (its section's rules apply to it)."""
    if not isinstance(v, dict):
        return v, None
    for k in v:
        if k not in DECLARED_KEYS:
            raise DataError(f"{where}: unknown key '{k}' in a declared value; write {{ value = ..., std = ... }}")
    for k in DECLARED_KEYS:
        if k not in v:
            raise DataError(f"{where}: missing key '{k}' (a declared value is {{ value = ..., std = ... }}, the "
                            "std its standard uncertainty in the value's unit)")
    std = v["std"]
    if isinstance(std, bool) or not isinstance(std, (int, float)) or not math.isfinite(std):
        raise DataError(f"{where} std: expected a finite number (the standard uncertainty, in the value's unit), "
                        f"got {std!r}")
    if std < 0:
        raise DataError(f"{where} std: a standard uncertainty must not be negative, got {std!r}")
    return v["value"], float(std)


def check_std(value: float, std: float | None, where: str) -> None:
    """A declared std must be smaller than the value's magnitude (a value known to 100 % is not measured)."""
    if std is not None and std > 0 and not std < abs(value):
        raise DataError(f"{where} std: {std:g} is not smaller than the value {value:g}; a standard uncertainty "
                        "that large means the value was not measured: leave it out of the file instead")


def declared_table(value, std: float | None):
    """What a file holds for a value: the plain number, or ``{ value, std }`` when a std is declared."""
    return value if std is None else {"value": value, "std": std}


def refuse_declared(v, where: str) -> None:
    """A ``{ value, std }`` table where none may stand: one line naming the key and where one may."""
    if isinstance(v, dict) and "std" in v:
        raise DataError(f"{where}: {_WHERE_ALLOWED}; this key takes a plain value")


def split_sensitivity(tab, where: str):
    """The dataset's ``[channels]`` table less its ``sensitivity_std`` keys, and those keys.

    Returns ``(channel_map_table, sensitivity)``: the table for
    :func:`rideid.data.schema.channels.parse_channel_map` (an entry that held
    only ``sensitivity_std`` is dropped: the channel is read by its SPEC
    name, as without an entry) and ``{channel: relative std}``.
    """
    if not isinstance(tab, dict):
        return tab, {}
    rest, sens = {}, {}
    for target, v in tab.items():
        if not isinstance(v, dict) or SENSITIVITY_KEY not in v:
            rest[target] = v
            continue
        w = f"{where} {target} {SENSITIVITY_KEY}"
        if target not in CHANNELS:
            raise DataError(f"{w}: '{target}' is not a measured channel; a sensitivity_std belongs to an "
                            f"accelerometer or gyro channel ({', '.join(CHANNELS)})")
        s = v[SENSITIVITY_KEY]
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s):
            raise DataError(f"{w}: expected a finite number (the relative standard uncertainty of the sensor's "
                            f"sensitivity: 0.02 for 2 %), got {s!r}")
        if not 0 <= s < SENSITIVITY_STD_MAX:
            raise DataError(f"{w}: must be at least 0 and below {SENSITIVITY_STD_MAX:g} (a relative std: 0.02 for "
                            f"2 %), got {s!r}")
        sens[target] = float(s)
        others = {k: x for k, x in v.items() if k != SENSITIVITY_KEY}
        if others:
            rest[target] = others
    return rest, sens


__all__ = ["DECLARED_KEYS", "SENSITIVITY_KEY", "SENSITIVITY_STD_MAX", "split_declared", "check_std",
           "declared_table", "refuse_declared", "split_sensitivity"]
