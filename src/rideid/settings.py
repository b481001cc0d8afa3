"""One registry of every tuning constant: its value, unit, meaning, measured reason and the test that pins it.

Modelled on python-control's ``control.config.defaults``: each constant of
:mod:`rideid.estimate` (and of :mod:`rideid.conditioning` where it shapes a
verdict) that a study may want to vary is a :class:`Setting` named
``"module.param"`` (``"adequacy.alpha"``). The code reads the value at use
time from :data:`defaults`, so a change applies to the next fit:

>>> import rideid.settings as settings
>>> settings.defaults["adequacy.alpha"]
0.01
>>> with settings.using({"adequacy.alpha": 0.05}):
...     pass                                  # rideid.identify(ds) here uses 0.05
>>> settings.set_defaults("adequacy", alpha=0.05)   # until reset_defaults()
>>> settings.reset_defaults()

A dataset sets them in a ``[settings]`` table of ``dataset.toml``
(``"adequacy.alpha" = 0.05``), applied while :func:`rideid.identify` fits it;
``result.json`` records every value used (``settings``). Unknown names and
values of the wrong kind are errors (:class:`rideid.errors.ArgumentError`).
The settings themselves are data: one TOML table each in ``settings.toml``
beside this module (a new setting is a new table there); docs/settings.md is
that list as a table.

The registry is process-wide, as python-control's: a value set in one
thread is seen by the others (the model choice fits candidates on threads,
all with the values in force when the fit began). This module imports
nothing of rideid but its errors, so every layer may read it.
"""

from __future__ import annotations

import contextlib
import difflib
import math
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from .errors import ArgumentError


@dataclass(frozen=True)
class Setting:
    """One tuning constant.

    Attributes
    ----------
    name : str
        ``"module.param"``: the module of :mod:`rideid.estimate` or :mod:`rideid.conditioning` that reads it.
    default : int, float or tuple of them
        The value rideid ships with.
    unit : str
        SI unit, ``"1"`` for a ratio (with what it is a share of in brackets), or a count's noun.
    meaning : str
        What the value does.
    reason : str
        The doc that gives its reason, ``docs/<file>.md#<anchor>``.
    test : str
        The test that pins it, ``tests/<file>.py::<test>``.
    measured : bool
        Whether the value was chosen by a measurement the meaning, the note or the doc states (False: a
        convention or a numerical safeguard, said so in docs/settings.md).
    note : str
        The measurement or the longer story behind the value.
    """

    name: str
    default: object
    unit: str
    meaning: str
    reason: str
    test: str
    measured: bool = False
    note: str = ""


def _read_table(path: Path) -> tuple[Setting, ...]:
    """The settings of the table ``path`` (``settings.toml``), in its order: one TOML table per setting, named
    ``"module.param"``, with the other fields of :class:`Setting` as keys (a list default is a tuple here)."""
    with open(path, "rb") as f:
        doc = tomllib.load(f)
    return tuple(Setting(name, tuple(row.pop("default")) if isinstance(row["default"], list) else row.pop("default"),
                         **row) for name, row in doc.items())


#: every setting, grouped by the module that reads it: the table ``settings.toml`` beside this module, one entry
#: per setting with its value, unit, meaning, reason, test and note (docs/settings.md is this list as a table)
_SETTINGS: tuple[Setting, ...] = _read_table(Path(__file__).with_name("settings.toml"))


#: module-level numbers of :mod:`rideid.estimate` that are not tuning constants, each with what it is instead
#: (tests/test_settings.py: every other module-level number there is in the registry)
NOT_SETTINGS: dict[str, str] = {
    "tall.TALL": "when a least squares is reduced by a QR first: the same solution either way (speed only)",
    "tall.BLOCK_ROWS": "the blocked QR's block size: the same triangle either way (speed only)",
    "tall.LOCAL_MIN_COLUMNS": "when a QR looks for columns local to a few rows: the same R^T R either way (speed only)",
    "tall.ROW_BLOCK": "the rows per block when looking for local columns: the same R^T R either way (speed only)",
    "tall._users": "how many threads are inside tall_steps (state, not a value)",
    "tall.CHECK_EVERY": "the rows read to check a kept reduction is the step's matrix: checked either way (speed only)",
    "identify.DEFAULT_POPULATION": "an argument's default (rideid.identify population=, --population; SPEC §5)",
    "identify.DEFAULT_GENERATIONS": "an argument's default (rideid.identify generations=, --generations; SPEC §5)",
    "cost.BUMP_BOUNDS": "the bump stops' default search bounds: a model default, [bounds] overrides it",
    "scores.ANDREWS_BARTLETT": "a mathematical constant: Andrews (1991), the Bartlett kernel's optimal bandwidth",
    "sensitivity.P2R_STARS": "display: the report's star ratings of the sensitivity maps (docs/report.md)",
    "sensitivity.R2T_STARS": "display: the report's star ratings of the sensitivity maps (docs/report.md)",
    "sensitivity.P2T_STARS": "display: the report's star ratings of the sensitivity maps (docs/report.md)",
    "asbuilt.SIZE_PRIOR_WEIGHT": "a mathematical constant: sqrt(1/2), a complex residual's real and imaginary "
                                 "parts' share of its variance (its comment)",
    "frequency.STEP": "a numerical stencil: the relative step of the central differences of |H|",
    "roadstaged.HOLD_FIX": "a numerical stencil: the first-order-hold correction filter (module docstring)",
    "roadstaged.LOWPASS_HZ": "the compared time-domain road method (docs/road-methods.md#tuning), run by "
                             "benchmarks/road_methods.py only, not by rideid identify",
    "roadstaged.EDGE_SECONDS": "the compared time-domain road method (docs/road-methods.md#tuning), run by "
                               "benchmarks/road_methods.py only, not by rideid identify",
}

REGISTRY: dict[str, Setting] = {s.name: s for s in _SETTINGS}
_values: dict[str, object] = {s.name: s.default for s in _SETTINGS}


def _check(name: str, value) -> object:
    """``value`` as the setting ``name`` holds it; :class:`ArgumentError` naming the setting otherwise."""
    if name not in REGISTRY:
        close = difflib.get_close_matches(str(name), REGISTRY, n=2) or [
            n for n in REGISTRY if n.split(".")[-1] == str(name).split(".")[-1]]
        hint = f" (did you mean {' or '.join(close)}?)" if close else ""
        raise ArgumentError(f"settings: unknown setting '{name}'{hint}; the settings are listed in docs/settings.md")
    default = REGISTRY[name].default

    def number(v, integer):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return None
        if integer:
            return int(v) if float(v).is_integer() else None
        return float(v)

    if isinstance(default, tuple):
        integer = all(isinstance(d, int) for d in default)
        vals = [number(v, integer) for v in value] if isinstance(value, (list, tuple)) else [None]
        if not vals or None in vals or (len(default) == 2 and len(vals) != 2):
            n = "two" if len(default) == 2 else "one or more"
            kind = "integers" if integer else "numbers"
            raise ArgumentError(f"settings: '{name}' must be a list of {n} finite {kind} (default {list(default)}), "
                                f"got {value!r}")
        return tuple(vals)
    v = number(value, isinstance(default, int))
    if v is None:
        kind = "an integer" if isinstance(default, int) else "a finite number"
        raise ArgumentError(f"settings: '{name}' must be {kind} (default {default!r}), got {value!r}")
    return v


class _Defaults(Mapping):
    """The values in force, by name (read-only: change them with :func:`set_defaults` or :func:`using`)."""

    def __getitem__(self, name):
        try:
            return _values[name]
        except KeyError:
            try:
                _check(name, None)
            except ArgumentError as e:  # a KeyError (a Mapping's `in` and `get` rely on it) naming the setting
                raise KeyError(str(e)) from None
            raise

    def __iter__(self) -> Iterator[str]:
        return iter(_values)

    def __len__(self):
        return len(_values)

    def __repr__(self):
        changed = {n: v for n, v in _values.items() if v != REGISTRY[n].default}
        return f"<rideid.settings.defaults: {len(self)} settings, changed: {changed or 'none'}>"


#: the values in force: ``defaults["adequacy.alpha"]``
defaults = _Defaults()


def _flatten(module_or_values, kw) -> dict:
    """``("adequacy", alpha=0.05)`` or ``({"adequacy.alpha": 0.05})`` -> ``{"adequacy.alpha": 0.05}``."""
    if isinstance(module_or_values, str):
        return {f"{module_or_values}.{k}": v for k, v in kw.items()}
    if module_or_values is None and kw:
        raise ArgumentError(f"settings: {', '.join(kw)}: a keyword needs the module it belongs to, "
                            f"as set_defaults('adequacy', alpha=0.05)")
    values = dict(module_or_values or {})
    if kw:
        raise ArgumentError("settings: give a module name with keywords (set_defaults('adequacy', alpha=0.05)) "
                            "or one mapping of full names ({'adequacy.alpha': 0.05}), not a mapping and keywords")
    return values


def checked(values: Mapping) -> dict:
    """``values`` (name -> value) checked against the registry, as the settings hold them (tuples for lists);
    :class:`ArgumentError` naming the first unknown or malformed one."""
    return {n: _check(n, v) for n, v in values.items()}


def set_defaults(module_or_values=None, /, **kw) -> None:
    """Change settings until :func:`reset_defaults`.

    ``set_defaults("adequacy", alpha=0.05, min_relative=0.01)`` (python-control's form) or
    ``set_defaults({"adequacy.alpha": 0.05})``. All are checked before any is changed.
    """
    _values.update(checked(_flatten(module_or_values, kw)))


def reset_defaults() -> None:
    """Every setting back to the value rideid ships with."""
    _values.update({n: s.default for n, s in REGISTRY.items()})


@contextlib.contextmanager
def using(module_or_values=None, /, **kw):
    """The settings given, inside a ``with`` block; the previous values after it (also on an error).

    Same arguments as :func:`set_defaults`: ``with using("adequacy", alpha=0.05):`` or
    ``with using({"adequacy.alpha": 0.05}):``.
    """
    new = checked(_flatten(module_or_values, kw))
    before = {n: _values[n] for n in new}
    _values.update(new)
    try:
        yield defaults
    finally:
        _values.update(before)


def current() -> dict:
    """Every value in force, name -> value (tuples as lists): what ``result.json`` records as ``settings``."""
    return {n: list(v) if isinstance(v, tuple) else v for n, v in _values.items()}


def changed() -> dict:
    """The settings whose value differs from the shipped default, name -> value."""
    return {n: v for n, v in current().items() if _values[n] != REGISTRY[n].default}


def legacy_names(module: str, names: dict[str, object]):
    """A module ``__getattr__`` (PEP 562) that reads the old constant names of ``module`` (its ``__name__``)
    from the registry: ``rideid.estimate.assess.adequacy.ALPHA`` -> ``defaults["adequacy.alpha"]`` (the names code
    outside rideid may still import; read when imported, so they do not follow a later change). A value that is
    not a setting's name is a function of none, called (``PENALTY`` -> ``penalty()``)."""

    def __getattr__(attr):
        if attr in names:
            return _values[names[attr]] if isinstance(names[attr], str) else names[attr]()
        raise AttributeError(f"module {module!r} has no attribute {attr!r}")

    return __getattr__


def markdown_table() -> str:
    """Every setting as a Markdown table (docs/settings.md holds it; tests/test_settings.py checks they agree)."""
    rows = ["| setting | default | unit | meaning | measured | reason | test |", "|---|---|---|---|---|---|---|"]
    for s in _SETTINGS:
        default = list(s.default) if isinstance(s.default, tuple) else s.default
        test = s.test.split("::")
        rows.append(f"| `{s.name}` | `{default}` | {s.unit} | {s.meaning.replace('|', '/')} | "
                    f"{'yes' if s.measured else 'no'} | [{s.reason.split('/')[-1]}]({s.reason.replace('docs/', '')}) | "
                    f"`{test[0].replace('tests/', '')}::{test[1]}` |")
    return "\n".join(rows) + "\n"


__all__ = ["Setting", "REGISTRY", "NOT_SETTINGS", "defaults", "set_defaults", "reset_defaults", "using", "checked",
           "current", "changed", "markdown_table"]


if __name__ == "__main__":  # python -m rideid.settings: the table of docs/settings.md
    print(markdown_table(), end="")
