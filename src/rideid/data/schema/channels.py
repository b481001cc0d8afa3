"""How a dataset says its files were logged (docs/formats.md, "Measured runs").

The ``[channels]`` map (and a run's ``channels``), ``[preprocess]`` (and a
run's own preprocessing keys) and ``[csv]``: their keys, the units accepted
for each quantity, and their validation. :mod:`rideid.data.measured` applies
them; :mod:`rideid.data.readers` reads the files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import DataError
from ...model.equations import CHANNEL_KIND, CHANNELS
from ...model.params import GRAVITY
from ...model.posts import POST_CHANNELS, POST_VEL_CHANNELS
from ...model.sensors import ORDERS, AnalogFilter
from .common import checked_items

#: accepted units (lower case, spaces removed) -> factor to SI, per quantity
UNITS = {
    "acceleration": {"m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0, "m/s/s": 1.0, "g": GRAVITY},
    "rate": {"rad/s": 1.0, "deg/s": math.pi / 180, "°/s": math.pi / 180},
    "speed": {"m/s": 1.0, "km/h": 1 / 3.6, "kph": 1 / 3.6, "mph": 0.44704},
    "distance": {"m": 1.0, "km": 1000.0},
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9},
    # a four-post rig's post displacements and velocities (SPEC §13)
    "displacement": {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "in": 0.0254},
    "velocity": {"m/s": 1.0, "mm/s": 1e-3, "cm/s": 1e-2, "in/s": 0.0254},
}
SI = {"acceleration": "m/s^2", "rate": "rad/s", "speed": "m/s", "distance": "m", "time": "s", "displacement": "m",
      "velocity": "m/s"}
#: a four-post rig run's post channels (SPEC §13): displacements (m), optionally velocities (m/s)
RIG_TARGETS = POST_CHANNELS + POST_VEL_CHANNELS
EXTRA_TARGETS = ("time", "speed", "distance") + RIG_TARGETS
#: what a channel map may map file channels to
TARGETS = CHANNELS + EXTRA_TARGETS

PREPROCESS_KEYS = ("gravity_included", "remove_bias", "lead_in", "fs", "start", "window", "pre_roll",
                   "anti_alias")
#: keys a run may set for itself (the rest are dataset-wide)
RUN_PREPROCESS_KEYS = ("gravity_included", "remove_bias", "lead_in", "start", "window", "pre_roll")
CSV_KEYS = ("delimiter", "decimal", "skip_rows")
CHANNEL_KEYS = ("name", "unit", "sign", "scale", "highpass", "lowpass", "range")
#: keys of a measured channel's sensor chain (SPEC §11 "Sensors as wired"), not for time, speed or distance
SENSOR_KEYS = ("highpass", "lowpass", "range")


def quantity(target: str) -> str:
    """The physical quantity of a channel-map target: acceleration, rate, speed, distance or time."""
    if target in CHANNELS:
        return "rate" if CHANNEL_KIND[target] == "rate" else "acceleration"
    if target in RIG_TARGETS:
        return "displacement" if target in POST_CHANNELS else "velocity"
    return target


def unit_factor(unit: str, target: str, where: str) -> float:
    """Factor from ``unit`` to SI for ``target``; :class:`DataError` at ``where`` for an unknown unit."""
    q = quantity(target)
    key = unit.strip().replace(" ", "").lower()
    if key not in UNITS[q]:
        raise DataError(f"{where}: unknown unit '{unit}' for {target} ({q}); use one of "
                        f"{', '.join(UNITS[q])}")
    return UNITS[q][key]


@dataclass(frozen=True)
class ChannelEntry:
    """Where a SPEC channel (or time, speed, distance) comes from in the file."""

    name: str
    unit: str | None = None
    sign: float = 1.0
    scale: float = 1.0
    #: the analog filters the sensor chain applies before a value is recorded (SPEC §11)
    highpass: AnalogFilter | None = None
    lowpass: AnalogFilter | None = None
    #: the sensor's full scale, +- this value in the channel's unit (file unit, before scale and sign)
    range: float | None = None

    @property
    def filters(self) -> tuple:
        """The chain's filters, high-pass first (:class:`rideid.model.sensors.AnalogFilter`)."""
        return tuple(f for f in (self.highpass, self.lowpass) if f is not None)

    def to_table(self):
        d = {"name": self.name}
        if self.unit is not None:
            d["unit"] = self.unit
        if self.sign != 1:
            d["sign"] = int(self.sign)
        if self.scale != 1:
            d["scale"] = self.scale
        for k in ("highpass", "lowpass"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k).to_table()
        if self.range is not None:
            d["range"] = self.range
        return d


@dataclass(frozen=True)
class CsvOptions:
    """``[csv]`` options: ``delimiter`` and ``decimal`` (detected when ``None``), ``skip_rows``."""

    delimiter: str | None = None
    decimal: str | None = None
    skip_rows: int = 0


#: unit factors an acceleration can be off by (g mapped as m/s^2: values 9.81x too small, and back)
ACC_FACTORS = (GRAVITY, 1 / GRAVITY)


def gravity_unit_factor(lead_mean: float) -> float | None:
    """The factor that turns a lead-in mean into gravity, if a unit mistake explains it.

    With gravity included, an acceleration at rest reads about ±g (±20 %); a
    mean of about ±1 m/s^2 is g mapped as m/s^2 (factor 9.81), about ±96
    m/s^2 is m/s^2 mapped as g (factor 1/9.81). The three ranges do not
    overlap, so the factor is unambiguous. Returns the signed factor (minus:
    also upside down), or None when the mean is about ±g or explained by
    no unit.
    """
    for f in ACC_FACTORS:
        for s in (1.0, -1.0):
            if 0.8 * GRAVITY < s * f * lead_mean < 1.2 * GRAVITY:
                return s * f
    return None


def parse_channel_map(tab, where: str) -> dict[str, ChannelEntry]:
    """``[channels]`` (or a run's ``channels``): SPEC target -> :class:`ChannelEntry`."""
    out = {}
    for target, v, w in checked_items(tab, where, TARGETS,
                                      ": SPEC channel = \"file channel\" or { name, unit, sign, scale, highpass, "
                                      "lowpass, range }",
                                      "unknown channel '{key}'; map file channels to {allowed}"):
        if isinstance(v, str):
            v = {"name": v}
        if not isinstance(v, dict):
            raise DataError(f"{w}: expected a file channel name or a table {{ name, unit, sign, scale, highpass, "
                            "lowpass, range }}")
        for k in v:
            if k not in CHANNEL_KEYS:
                hint = (" (a sensor's sensitivity_std is declared once, in the dataset's [channels] table)"
                        if k == "sensitivity_std" else "")
                raise DataError(f"{w}: unknown key '{k}'{hint}; allowed: {', '.join(CHANNEL_KEYS)}")
        name = v.get("name", target if target in CHANNELS and any(k in v for k in SENSOR_KEYS) else None)
        if not isinstance(name, str) or not name:
            raise DataError(f"{w}: missing key 'name' (the channel's name in the file)")
        unit = v.get("unit")
        if unit is not None:
            if not isinstance(unit, str):
                raise DataError(f"{w}: unit must be a string")
            unit_factor(unit, target, f"{w} unit")
        sign = v.get("sign", 1)
        if sign not in (1, -1) or isinstance(sign, bool):
            raise DataError(f"{w}: sign must be 1 or -1, got {sign!r}")
        scale = v.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not math.isfinite(scale) or scale == 0:
            raise DataError(f"{w}: scale must be a finite non-zero number, got {scale!r}")
        if target in ("time", "distance", "speed") and sign != 1:
            raise DataError(f"{w}: sign is for measured channels only")
        sensor = {}
        for k in SENSOR_KEYS:
            if k == "range" and k in v and target in RIG_TARGETS:
                raise DataError(f"{w} range: a post channel has no range to leave samples out at (the posts are the "
                                "model's input, every sample of them is needed); leave it out")
            if k in v and target not in CHANNELS and target not in RIG_TARGETS:
                raise DataError(f"{w} {k}: {k} is for measured channels only (SPEC §11), not {target}")
        for k in ("highpass", "lowpass"):
            if k in v:
                sensor[k] = parse_filter(v[k], k, f"{w} {k}")
        if "range" in v:
            rng = v["range"]
            if isinstance(rng, bool) or not isinstance(rng, (int, float)) or not math.isfinite(rng) or rng <= 0:
                raise DataError(f"{w} range: expected the sensor's full scale, a positive number in the "
                                f"channel's unit (range = 5.0 for +-5 g), got {rng!r}")
            sensor["range"] = float(rng)
        out[target] = ChannelEntry(name, unit, float(sign), float(scale), **sensor)
    return out


def parse_filter(v, kind: str, where: str) -> AnalogFilter:
    """A ``highpass`` or ``lowpass`` value: a corner frequency (Hz, first order) or ``{ hz, order }``
    (an analog Butterworth of that order, 1 to 8); :class:`DataError` at ``where`` otherwise."""
    how = (f"expected a corner frequency in Hz (a positive number, first order) or {{ hz = 0.5, order = 2 }} "
           f"(an analog Butterworth of order {ORDERS[0]} to {ORDERS[1]})")
    order = 1
    if isinstance(v, dict):
        for k in v:
            if k not in ("hz", "order"):
                raise DataError(f"{where}: unknown key '{k}'; allowed: hz, order")
        if "hz" not in v:
            raise DataError(f"{where}: missing key 'hz'; {how}")
        order = v.get("order", 1)
        if isinstance(order, bool) or not isinstance(order, int) or not ORDERS[0] <= order <= ORDERS[1]:
            raise DataError(f"{where} order: expected an integer from {ORDERS[0]} to {ORDERS[1]}, got {order!r}")
        v = v["hz"]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise DataError(f"{where}: {how}, got {v!r}")
    return AnalogFilter(kind, float(v), order)


def _window(v, w):
    if (not isinstance(v, list) or len(v) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
        raise DataError(f"{w}: expected [from, to] in seconds of file time")
    if not v[0] < v[1]:
        raise DataError(f"{w}: from ({v[0]}) must be less than to ({v[1]})")
    return (float(v[0]), float(v[1]))


def parse_preprocess(tab, where: str, keys=PREPROCESS_KEYS) -> dict:
    """``[preprocess]`` (or a run's own keys, ``keys=RUN_PREPROCESS_KEYS``): key -> validated value."""
    out = {}
    for k, v, w in checked_items(tab, where, keys):
        if k in ("gravity_included", "remove_bias", "anti_alias"):
            if not isinstance(v, bool):
                raise DataError(f"{w}: expected true or false")
            out[k] = v
        elif k in ("lead_in", "window"):
            out[k] = _window(v, w)
        elif k == "start":
            if v == "auto":
                out[k] = "auto"
            elif isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                out[k] = float(v)
            else:
                raise DataError(f"{w}: expected a time in seconds of file time, or \"auto\"")
        elif k in ("fs", "pre_roll"):
            if (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0
                    or (k == "fs" and v == 0)):
                raise DataError(f"{w}: expected a {'positive' if k == 'fs' else 'non-negative'} number")
            out[k] = float(v)
    return out


def parse_csv_options(tab, where: str) -> CsvOptions:
    """``[csv]``: one-character ``delimiter`` and ``decimal``, a non-negative ``skip_rows``."""
    checked_items(tab, where, CSV_KEYS)
    kw = {}
    for k in ("delimiter", "decimal"):
        if k in tab:
            v = tab[k]
            if not isinstance(v, str) or len(v) != 1:
                raise DataError(f"{where} {k}: expected one character, got {v!r}")
            kw[k] = v
    if "skip_rows" in tab:
        v = tab["skip_rows"]
        if not isinstance(v, int) or isinstance(v, bool) or v < 0:
            raise DataError(f"{where} skip_rows: expected a non-negative integer")
        kw["skip_rows"] = v
    return CsvOptions(**kw)


__all__ = ["RIG_TARGETS", "UNITS", "SI", "TARGETS", "EXTRA_TARGETS", "PREPROCESS_KEYS", "RUN_PREPROCESS_KEYS",
           "CSV_KEYS", "CHANNEL_KEYS", "ChannelEntry", "CsvOptions", "quantity", "unit_factor", "gravity_unit_factor",
           "ACC_FACTORS", "SENSOR_KEYS", "parse_channel_map", "parse_filter", "parse_preprocess", "parse_csv_options"]
