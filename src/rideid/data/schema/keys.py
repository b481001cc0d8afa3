"""Declarative TOML keys: one table of :class:`Key` per section, one checker.

A section of a file (``[vehicle]``, a ``[[runs]]`` table, a track kind,
a study's ``[data]``) is described by a :class:`Section`: its keys in file
order, each a :class:`Key` (type, required or default, range, unit), and the
wording of its messages. :meth:`Section.read` checks a parsed table against
it, in a fixed order (unknown keys, missing keys, types, ranges), and
returns the values with the defaults filled. Every message names the file
and section (``where``) and the key.

The tables themselves live beside their formats: :data:`rideid.data.schema.manifest.SECTIONS`
(scenario and ``dataset.toml``), :data:`rideid.data.schema.tracks.TRACK_SECTIONS`
(``[[tracks]]`` kinds), :data:`rideid.studies.spec.SECTIONS` (study files).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ...errors import DataError

#: value types a :class:`Key` may take
TYPES = ("number", "string", "bool", "any")


@dataclass(frozen=True)
class Key:
    """One key of a TOML section.

    Parameters
    ----------
    type : {"number", "string", "bool", "any"}
        ``number``: a finite int or float (a TOML bool is not one), read as float;
        ``any``: checked by the section's parser itself.
    required : bool
        Missing is an error (else ``default`` is filled, when not None).
    default : object, optional
    unit : str
        SI unit of a number (for the documentation and messages).
    positive : bool
        A number must be > 0.
    whole : bool
        A number must be a non-negative whole number (a count).
    between : (float, float), optional
        A number must lie strictly between the two.
    choices : tuple of str
        A string must be one of these.
    """

    type: str = "number"
    required: bool = False
    default: object = None
    unit: str = ""
    positive: bool = False
    whole: bool = False
    between: tuple | None = None
    choices: tuple = ()

    def __post_init__(self):
        if self.type not in TYPES:
            raise ValueError(f"Key type {self.type!r}: expected one of {', '.join(TYPES)}")


@dataclass(frozen=True)
class Messages:
    """The wording of a section's messages: :meth:`str.format` templates.

    Fields available: ``where`` (file and section), ``key``, ``value`` (as written), ``number``
    (a number's value as float),
    ``allowed`` (the allowed keys, comma-separated), ``hint`` (the section's
    hint for an unknown key, or ""), ``unit``, ``lo``/``hi`` (of ``between``),
    ``choices`` (``"a" or "b"``) and any extra field passed to :meth:`Section.read`.
    """

    unknown: str = "{where}: unknown key '{key}'{hint}; allowed: {allowed}"
    missing: str = "{where}: missing key '{key}'"
    number: str = "{where} {key}: expected a finite number, got {value!r}"
    positive: str = "{where} {key}: must be positive, got {value!r}"
    whole: str = "{where}: key '{key}' must be a non-negative whole number, got {number}"
    between: str = "{where}: key '{key}' must be between {lo:g} and {hi:g} {unit}, got {number}"
    string: str = "{where}: key '{key}' must be a string, got {value!r}"
    choice: str = "{where}: key '{key}' must be {choices}, got {value!r}"
    bool: str = "{where}: key '{key}' must be true or false, got {value!r}"


@dataclass(frozen=True)
class Section:
    """A TOML section: its keys (in file order) and the wording of its messages.

    ``also``: keys allowed in the table but read elsewhere (e.g. a track's
    ``id`` and ``kind``), listed first among the allowed keys; ``hints``: key
    -> extra words for an unknown key that belongs somewhere else.
    """

    keys: dict
    messages: Messages = field(default_factory=Messages)
    also: tuple = ()
    hints: dict = field(default_factory=dict)

    @property
    def allowed(self) -> tuple:
        """Every key the table may hold."""
        return tuple(self.also) + tuple(self.keys)

    def check_unknown(self, tab: dict, where: str, **extra) -> None:
        """Refuse a key the section does not have."""
        for k in tab:
            if k not in self.keys and k not in self.also:
                raise self._error("unknown", where, k, None, extra, hint=self.hints.get(k, ""))

    def read(self, tab, where: str, **extra) -> dict:
        """The section's values from the parsed table ``tab``: checked, numbers as float, defaults filled.

        Checks, in this order: ``tab`` is a table; no unknown key; every required key
        present; each value's type; each number's range. Keys of type ``any`` and the
        ``also`` keys are returned as written. ``extra``: further fields for the messages.
        """
        if not isinstance(tab, dict):
            raise DataError(f"{where} must be a table")
        self.check_unknown(tab, where, **extra)
        for k, spec in self.keys.items():
            if spec.required and k not in tab:
                raise self._error("missing", where, k, None, extra)
        out = {}
        for k, spec in self.keys.items():
            if k in tab:
                out[k] = self._typed(k, tab[k], spec, where, extra)
            elif spec.default is not None:
                out[k] = spec.default
        for k, spec in self.keys.items():
            if k in tab and spec.type == "number":
                self._in_range(k, tab[k], spec, where, extra)
        return out

    def _typed(self, k, v, spec: Key, where, extra):
        if spec.type == "number":
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise self._error("number", where, k, v, extra)
            return float(v)
        if spec.type == "string":
            if not isinstance(v, str):
                raise self._error("string", where, k, v, extra)
            if spec.choices and v not in spec.choices:
                raise self._error("choice", where, k, v, extra, choices=" or ".join(f'"{c}"' for c in spec.choices))
            return v
        if spec.type == "bool" and not isinstance(v, bool):
            raise self._error("bool", where, k, v, extra)
        return v

    def _in_range(self, k, v, spec: Key, where, extra):
        x = float(v)
        if spec.positive and x <= 0:
            raise self._error("positive", where, k, v, extra)
        if spec.whole and (x < 0 or x != int(x)):
            raise self._error("whole", where, k, v, extra)
        if spec.between is not None and not (spec.between[0] < x < spec.between[1]):
            raise self._error("between", where, k, v, extra, lo=spec.between[0], hi=spec.between[1])

    def _error(self, what, where, key, value, extra, **more) -> DataError:
        spec = self.keys.get(key)
        number = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else value
        fields = {"where": where, "key": key, "value": value, "number": number, "allowed": ", ".join(self.allowed),
                  "hint": "", "unit": spec.unit if spec is not None else "", **extra, **more}
        return DataError(getattr(self.messages, what).format(**fields))


__all__ = ["Key", "Messages", "Section", "TYPES"]
