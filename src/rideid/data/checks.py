"""Checks of a dataset's numbers, made while it is read: catch the user's mistakes before they become confident
wrong answers.

Each check is a pure function over numbers (a manifest's values, an
estimate's details) and returns :class:`Finding` objects: a severity, the run
and channel concerned, a plain message that names the likely cause, and, for
wiring mistakes, the ``[channels]`` entries that fix it. :func:`enforce`
raises on the errors and warns of the rest.

* **Numbers** (:func:`check_numbers`): every value of the manifest against
  the range a road vehicle on a ride track can have (a 1e308 kg car, a
  300 m/s run, a 5 m tire are typing errors, not data). Reading a dataset or
  a scenario runs it.
* **Bounds** (:func:`bound_findings`): an estimate at or within 1 % (of the
  search range) of a bound was stopped by the bound, not by the data; the
  identification runs it after the fit.

The checks that compare the data with a nominal car's response (coverage,
wiring, units, track and speed) sit one layer up, with the loader that
simulates it: :mod:`rideid.conditioning.checks` and
:mod:`rideid.conditioning.wiring`.
"""

from __future__ import annotations

import copy
import warnings
from dataclasses import dataclass

from ..errors import DataError, DataWarning
from ..model.params import EXT_NAMES

#: severities, in order
ERROR, WARNING = "error", "warning"
#: the checks a dataset may relax (``[checks]``) are named in rideid.data.schema.manifest (CHECK_NAMES)

#: estimates within this fraction of the search range of a bound are flagged
BOUND_FRACTION = 0.01


#: where a channel-map fix goes (:attr:`MapFix.where`) and how its message says so
FIX_HEADS = {"map": "Fix the channel map: ",
             "channels": "Fix the channel map ([channels]: every run's file is wired so): ",
             "run": ("Fix this run's channel map only (its [[runs]] entry: channels = { ... }; the other runs read "
                     "as mapped): ")}


@dataclass(frozen=True)
class MapFix:
    """The channel-map entries that fix a wiring finding and where they go, said once in its message
    (:attr:`Finding.message`).

    Attributes
    ----------
    entries : tuple of str
        The map entries (TOML, ``axle_az_fl = { name = "AccZ_Hub_RL", unit = "m/s^2" }``) that apply the
        finding's ``fix`` to the map the run was read with (:func:`rideid.conditioning.wiring.fix_entries`).
    where : {"map", "channels", "run"}
        ``"map"``: the run's channel map (a dataset of one checked run); ``"channels"``: the dataset's
        ``[channels]``, every checked run needing the same fix; ``"run"``: this run's own ``[[runs]]`` entry,
        the other runs read as mapped (:func:`rideid.conditioning.load.where_to_fix` decides).
    level : {"error", "warn"}
        The run's ``[checks] wiring`` level: at ``"error"`` the message also says how to go on with the map as it
        is (:func:`keep_map`); at ``"warn"`` that is already done.
    """

    entries: tuple[str, ...]
    where: str = "map"
    level: str = "error"
    #: with ``where == "run"``: the checked runs that need this same fix, this one among them, and how many runs
    #: were checked (a run the check could not read, or one wired as mapped, keeps the fix out of ``[channels]``)
    shared: tuple[str, ...] = ()
    checked: int = 0

    def text(self) -> str:
        head = f'{FIX_HEADS[self.where]}{"; ".join(self.entries)}{keep_map(self.level)}'
        if self.where != "run" or len(self.shared) < 2:
            return head
        return (f"{head}; {len(self.shared)} of the {self.checked} checked runs need this same fix "
                f"({', '.join(self.shared)}): if every run's file is wired so, it goes once in [channels]")


def keep_map(level: str) -> str:
    """How a wiring finding at the run's ``[checks] wiring`` level says to go on with the map as it is: at
    ``"error"`` (a refusal) by setting the level to ``"warn"``; nothing where it is set so."""
    return ' (or set [checks] wiring = "warn" if the map is right)' if level == "error" else ""


@dataclass(frozen=True)
class Finding:
    """One result of a check.

    Attributes
    ----------
    severity : {"error", "warning", "note"}
        ``"error"``: the data are refused (:func:`enforce` raises :class:`rideid.DataError` naming the first);
        ``"warning"``: warned of (:class:`rideid.DataWarning`); ``"note"``
        (:data:`rideid.conditioning.checks.NOTE`): recorded (result.json ``checks``), neither warned of nor refused.
    check : str
        Which check: "numbers", "coverage", "wiring", "track", "speed", "bounds" (the middle four:
        :mod:`rideid.conditioning.checks`).
    text : str
        One line: what is wrong, the likely cause and, without a ``remedy``, the fix.
    run : str or None
        The run concerned (None for the manifest or the fit).
    channel : str or None
        The SPEC channel or key concerned.
    fix : dict or None
        SPEC channel -> ``{source, factor}``: the corrected channel is
        ``factor`` times the channel currently mapped to ``source``.
    remedy : MapFix or None
        A wiring finding's fix as channel-map entries, and where they go; said after ``text`` in :attr:`message`.
    """

    severity: str
    check: str
    text: str
    run: str | None = None
    channel: str | None = None
    fix: dict | None = None
    remedy: MapFix | None = None

    @property
    def message(self) -> str:
        """What the user reads: the text, then the remedy's entries and where they go."""
        return self.text if self.remedy is None else f"{self.text}. {self.remedy.text()}"

    def to_dict(self) -> dict:
        d = {"severity": self.severity, "check": self.check, "message": self.message, "run": self.run,
             "channel": self.channel, "fix": copy.deepcopy(self.fix)}
        return {k: v for k, v in d.items() if v is not None}


# ---------------------------------------------------------------------------
# Numbers: physical plausibility of every value of a manifest

#: (lower, upper) a value may take; outside is a typing error, not a car
PLAUSIBLE = {
    "wheelbase": (0.5, 20.0), "track_front": (0.3, 5.0), "track_rear": (0.3, 5.0), "tire_radius": (0.05, 2.0),
    "total_mass": (50.0, 1.0e5), "m_s": (30.0, 1.0e5), "m_uf": (1.0, 2000.0), "m_ur": (1.0, 2000.0),
    "I_xx": (1.0, 1.0e6), "I_yy": (1.0, 1.0e7),
    "k_sf": (100.0, 1.0e8), "k_sr": (100.0, 1.0e8), "c_sf": (1.0, 1.0e6), "c_sr": (1.0, 1.0e6),
    "k_tf": (1.0e3, 1.0e9), "k_tr": (1.0e3, 1.0e9),
    "speed": (0.1, 100.0),
    # track dimensions, m (start and extent: a proving-ground track is not kilometres away)
    "start": (-1.0e4, 1.0e4), "amplitude": (0.0, 0.5), "height": (0.0, 0.5), "wavelength": (0.01, 1.0e3),
    "bump_length": (0.01, 1.0e3), "spacing": (0.01, 1.0e3), "cycles": (0.0, 1.0e5), "bumps": (0.0, 1.0e5),
}
UNIT_OF = {"wheelbase": "m", "track_front": "m", "track_rear": "m", "tire_radius": "m", "total_mass": "kg",
           "m_s": "kg", "m_uf": "kg", "m_ur": "kg", "I_xx": "kg m^2", "I_yy": "kg m^2", "k_sf": "N/m",
           "k_sr": "N/m", "c_sf": "N s/m", "c_sr": "N s/m", "k_tf": "N/m", "k_tr": "N/m", "speed": "m/s",
           "start": "m", "amplitude": "m", "height": "m", "wavelength": "m", "bump_length": "m",
           "spacing": "m", "cycles": "", "bumps": "", "fs": "Hz", "duration": "s"}


def _range_finding(where: str, key: str, value: float, lo: float, hi: float, absolute: bool = False):
    v = abs(value) if absolute else value
    if lo <= v <= hi:
        return None
    unit = UNIT_OF.get(key, "")
    what = f"|{key}|" if absolute else key
    return Finding(ERROR, "numbers", f"{where}: {key} = {value:g} {unit}".rstrip() +
                   f" is not physically plausible (expected {lo:g} <= {what} <= {hi:g} {unit}); "
                   "a typing or unit error?".replace("  ", " "), channel=key)


def check_numbers(man) -> list[Finding]:
    """Plausibility of every number of a manifest (dataset or scenario).

    Parameters
    ----------
    man : rideid.data.schema.Scenario or rideid.data.schema.DatasetManifest

    Returns
    -------
    list of Finding (errors)
    """
    out = []
    where = str(man.path)
    g = man.geometry
    for k in ("wheelbase", "track_front", "track_rear", "tire_radius"):
        out.append(_range_finding(f"{where}: [vehicle]", k, getattr(g, k), *PLAUSIBLE[k]))
    if g.tire_radius >= 0.5 * g.wheelbase:
        out.append(Finding(ERROR, "numbers", f"{where}: [vehicle] tire_radius = {g.tire_radius:g} m is not less "
                           f"than half the wheelbase ({g.wheelbase:g} m): the wheels would overlap",
                           channel="tire_radius"))
    for k, v in man.known.items():
        if k in PLAUSIBLE:
            out.append(_range_finding(f"{where}: [known]", k, v, *PLAUSIBLE[k]))
    truth = getattr(man, "truth", None) or {}
    for k, v in truth.items():
        if k in PLAUSIBLE:
            out.append(_range_finding(f"{where}: [truth]", k, v, *PLAUSIBLE[k]))
    for tid, tr in man.tracks.items():
        w = f"{where}: track '{tid}'"
        for k, v in tr.keys.items():
            if k in PLAUSIBLE and isinstance(v, float):
                out.append(_range_finding(w, k, v, *PLAUSIBLE[k], absolute=k in ("amplitude", "height")))
    for r in man.runs:
        w = f"{where}: run '{r.id}'"
        if r.speed is not None:
            out.append(_range_finding(w, "speed", r.speed, *PLAUSIBLE["speed"]))
        if r.fs is not None:
            out.append(_range_finding(w, "fs", r.fs, 1.0, 1.0e6))
        if r.duration is not None:
            out.append(_range_finding(w, "duration", r.duration, 1e-3, 1.0e5))
            if r.fs is not None and r.fs * r.duration > 5e7:
                out.append(Finding(ERROR, "numbers", f"{w}: fs * duration = {r.fs * r.duration:.3g} samples; "
                                   "more than 5e7 is not a ride run", r.id, "duration"))
    return [f for f in out if f is not None]


def enforce(findings: list[Finding], where: str = ""):
    """Raise :class:`rideid.DataError` with the first error (one line); warn of the rest."""
    errors = [f for f in findings if f.severity == ERROR]
    for f in findings:
        if f.severity == WARNING:
            warnings.warn(f"{where}{f.message}", DataWarning, stacklevel=3)
    if errors:
        more = f" ({len(errors) - 1} more error(s) of this kind)" if len(errors) > 1 else ""
        raise DataError(f"{where}{errors[0].message}{more}")


# ---------------------------------------------------------------------------
# After the fit

def bound_findings(details: dict, fraction: float = BOUND_FRACTION) -> list[Finding]:
    """Estimates at or within ``fraction`` of the search range of a bound.

    Parameters
    ----------
    details : dict
        name -> {"value", "lower", "upper", "fixed", ...} (``IdentificationResult.details``).
    """
    out = []
    for n, d in details.items():
        lo, hi = d.get("lower"), d.get("upper")
        if d.get("fixed") or lo is None or hi is None:
            continue
        v, span = d["value"], hi - lo
        for side, b in (("lower", lo), ("upper", hi)):
            if side == "lower" and b == 0 and n in EXT_NAMES:
                continue  # no bar or no tire damping seen: a physical answer, not one the bound imposed
            if abs(v - b) <= fraction * span:
                out.append(Finding(WARNING, "bounds", f"{n} = {v:.6g} ended at its {side} search bound {b:g}: the "
                                   "bound, not the data, set it; widen [bounds] "
                                   f"{n} (or check the data: a wrong unit, speed or wiring often shows here first)",
                                   channel=n))
    return out


__all__ = ["BOUND_FRACTION", "ERROR", "FIX_HEADS", "Finding", "MapFix", "PLAUSIBLE", "WARNING", "bound_findings",
           "check_numbers", "enforce", "keep_map"]
