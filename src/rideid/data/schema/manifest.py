"""Scenario files and dataset manifests (SPEC §3, §6): two small frozen types.

A **scenario** (:class:`Scenario`) describes a car to simulate: ``[truth]``,
runs with ``fs`` and ``duration``, optionally ``[hifi]`` for the MuJoCo car.
A **dataset manifest** (:class:`DatasetManifest`, ``dataset.toml``)
describes recorded runs: a ``file`` per run and how the files were logged
(``[channels]``, ``[preprocess]``, ``[csv]``, ``[checks]``). Both share the
car's geometry, ``[known]``, ``[bounds]``, ``[model]``, ``[[tracks]]`` and
``[[runs]]`` (:class:`Manifest`). Every problem is a :class:`rideid.DataError`
naming the file and the key at fault; unknown keys are errors.

The types are frozen and their tables read-only: change one with
:func:`dataclasses.replace`, e.g. ``replace(sc, runs=sc.runs[:2])``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path

from ... import settings
from ...errors import ArgumentError, DataError
from ...model.posts import PATTERNS, SIGNALS, PostSignal
from ...model.params import (EXT_NAMES, EXTRA_KNOWN, GROUPS, NAMES, SIGNED, Geometry, as_vector, check_parameters,
                             total_mass)
from ...model.roads import ROAD_CLASSES
from ...model.tracks import Track
from .channels import (RUN_PREPROCESS_KEYS, ChannelEntry, CsvOptions, parse_channel_map, parse_csv_options,
                       parse_preprocess)
from .common import ReadOnlyDict, in_folder, number, read_only, read_toml, table
from .declared import check_std, declared_table, refuse_declared, split_declared, split_sensitivity
from .dampers import (BUMP_NAMES, NONLINEAR_GROUPS, DamperCurves, bump_stop_pairs, parse_bump_stops,
                      parse_damper_knots, parse_dampers)
from .hifi import HifiProperties, parse_hifi, tire_damping_of
from .keys import Key, Messages, Section
from .tracks import track_from_table

#: a scenario may also describe the multibody car of rideid.verify.hifi (``[hifi]``, used by --engine mujoco)
TOP_KEYS_SCENARIO = ("name", "vehicle", "known", "bounds", "model", "tracks", "runs", "truth", "dampers", "hifi")
#: a dataset may also describe how its files were logged (rideid.data.measured)
TOP_KEYS_DATASET = ("name", "vehicle", "known", "bounds", "model", "channels", "preprocess", "csv", "checks",
                    "tracks", "runs", "settings")
RUN_KEYS_DATASET = ("id", "track", "speed", "file", "moving", "channels", "checks", "input") + RUN_PREPROCESS_KEYS
#: a scenario run drives a known track (``track``) or a generated ISO 8608 road (``road_class``, SPEC §9), or
#: stands on a four-post rig (``input = "posts"``, SPEC §13) driven by a post signal (:data:`SIGNAL_KEYS`)
RUN_KEYS_SCENARIO = ("id", "track", "road_class", "road_seed", "coherence", "speed", "fs", "duration", "moving",
                     "input", "signal", "amplitude", "f_low", "f_high", "pattern", "signal_seed")
#: the run's input when it stands on a four-post rig (SPEC §13: ``input = "posts"``)
POSTS_INPUT = "posts"
#: the keys of a scenario rig run's post signal (:class:`rideid.model.posts.PostSignal`)
SIGNAL_KEYS = ("signal", "amplitude", "f_low", "f_high", "pattern", "signal_seed")
#: the keys of a scenario run's generated road (:class:`RoadSpec`)
ROAD_KEYS = ("road_class", "road_seed", "coherence")
#: the ``track`` of a run on a road nobody measured (SPEC §9); no [[tracks]] id may take it
UNKNOWN_ROAD = "unknown"
#: the data checks (rideid.data.checks) a ``[checks]`` table may set, and their levels
CHECK_NAMES = ("wiring", "track")
CHECK_LEVELS = ("error", "warn", "off")
#: ``[vehicle]`` keys that may be left out (SPEC §8: ``cg_height``, 0 when absent)
OPTIONAL_VEHICLE_KEYS = tuple(Geometry.OPTIONAL_KEYS)
#: every model group a ``[model] extensions`` list may name: the linear ones (SPEC §6), then SPEC §8's
MODEL_GROUPS = tuple(GROUPS) + NONLINEAR_GROUPS
MODEL_KEYS = ("extensions", "damper_knots")
#: SPEC §13, set-up values are priors: the default standard uncertainty of a run's ``speed`` written as a plain
#: number (relative: 0.3 % of it), of its ``start`` (s; SPEC CSV: time 0, the front axle at x = 0) and of a
#: track's drawn size (``amplitude``, a twist's ``height``; relative). docs/formats.md says why these.
SPEED_STD_DEFAULT = 0.003
START_STD_DEFAULT = 0.005
SIZE_STD_DEFAULT = 0.05
#: a run's keys that may be written ``{ value, std }`` (SPEC §13), and a track's
RUN_PRIOR_KEYS = ("speed", "start")
TRACK_PRIOR_KEYS = ("amplitude", "height")

#: a key whose value its section's parser checks itself (a table, a list, an id, a flag with its own words)
_ANY = Key("any")
_RUN_HINTS_DATASET = {
    **{k: " (fs and duration belong to scenarios; a dataset run names its 'file')" for k in ("fs", "duration")},
    **{k: (f" ({k} belongs to a scenario, whose roads rideid simulate generates; a dataset run on a road nobody "
           f"measured gives track = \"{UNKNOWN_ROAD}\" or leaves 'track' out)") for k in ROAD_KEYS},
    **{k: " (a rig run's drive signal belongs to a scenario; a dataset rig run gives input = \"posts\" and the "
          "post_fl ... post_rr columns)" for k in SIGNAL_KEYS}}
_RUN_MESSAGES = Messages(number="{where}: {key}: expected a finite number, got {value!r}",
                         positive="{where}: {key}: must be positive, got {value!r}",
                         string="{where}: key '{key}' must be a path string")

#: The declarative key tables of scenario files and ``dataset.toml``: section -> :class:`Section`
#: (keys in file order, type, required, unit, range; the wording of the section's messages)
SECTIONS = {
    "scenario": Section({k: _ANY for k in TOP_KEYS_SCENARIO}),
    "dataset": Section({k: _ANY for k in TOP_KEYS_DATASET},
                       hints={"truth": " (a [truth] table belongs in a scenario or in truth.toml)"}),
    "vehicle": Section({**{k: Key(required=True, unit="m", positive=True) for k in Geometry.KEYS},
                        **{k: Key(unit="m") for k in OPTIONAL_VEHICLE_KEYS}},
                       Messages(unknown="{where}: [vehicle]: unknown key '{key}'; allowed: {allowed}",
                                missing="{where}: [vehicle]: missing key '{key}'",
                                number="{where}: [vehicle] {key}: expected a finite number, got {value!r}",
                                positive="{where}: [vehicle] {key}: must be positive, got {value!r}")),
    "model": Section({"extensions": _ANY, "damper_knots": _ANY},
                     Messages(unknown="{where}: [model]: unknown key '{key}'; allowed: {allowed}")),
    "runs.scenario": Section({"id": Key("any", required=True), "track": _ANY, "road_class": _ANY,
                              "road_seed": _ANY, "coherence": _ANY,
                              "speed": Key(unit="m/s", positive=True),
                              "fs": Key(required=True, unit="Hz", positive=True),
                              "duration": Key(required=True, unit="s", positive=True), "moving": _ANY,
                              "input": _ANY, "signal": _ANY, "amplitude": Key(unit="m", positive=True),
                              "f_low": Key(unit="Hz", positive=True), "f_high": Key(unit="Hz", positive=True),
                              "pattern": _ANY, "signal_seed": _ANY},
                             _RUN_MESSAGES,
                             hints={"file": " (a scenario run gives 'fs' and 'duration' instead of a file)"}),
    "runs.dataset": Section({"id": Key("any", required=True), "track": _ANY, "speed": Key(unit="m/s", positive=True),
                             "file": Key("string", required=True), "moving": _ANY, "channels": _ANY, "checks": _ANY,
                             "input": _ANY, **{k: _ANY for k in RUN_PREPROCESS_KEYS}},
                            _RUN_MESSAGES, hints=_RUN_HINTS_DATASET),
}
assert (tuple(SECTIONS["runs.scenario"].keys) == RUN_KEYS_SCENARIO
        and tuple(SECTIONS["runs.dataset"].keys) == RUN_KEYS_DATASET)


# ---------------------------------------------------------------------------
# The types

@dataclass(frozen=True)
class RoadSpec:
    """The generated road of a scenario run (SPEC §9): an ISO 8608 class (:mod:`rideid.model.roads`).

    ``seed``: the road's seed (None: derived from ``rideid simulate --seed`` and the run's
    position); ``coherence``: the lateral stretch of the isotropic road
    (:func:`rideid.model.roads.road_coherency`; 1 isotropic).
    """

    road_class: str
    seed: int | None = None
    coherence: float = 1.0

    def to_table(self) -> dict:
        d = {"road_class": self.road_class}
        if self.seed is not None:
            d["road_seed"] = self.seed
        if self.coherence != 1.0:
            d["coherence"] = self.coherence
        return d


@dataclass(frozen=True)
class RunSpec:
    """One run of a manifest: its track (or road), speed and file (dataset) or rate and duration (scenario).

    ``track`` is None for a run on a road nobody measured (SPEC §9: ``track``
    left out or ``"unknown"``); a scenario's such run has a ``road`` to
    generate. ``moving``: the car is already moving at the first sample
    (SPEC §9), not at rest.
    """

    id: str
    track: str | None
    speed: float | None
    file: str | None = None
    fs: float | None = None
    duration: float | None = None
    #: measured-data options of this run (rideid.data.measured): its channel map and preprocessing keys
    channels: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    options: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    #: this run's levels of the data checks (rideid.data.checks), over the dataset's [checks]
    checks: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    #: the car is moving at the first sample (SPEC §9); default False, True for a scenario's generated road
    moving: bool = False
    #: a scenario run's generated road (SPEC §9), or None
    road: RoadSpec | None = None
    #: ``"posts"``: the run stands on a four-post rig (SPEC §13), its wheel inputs the measured posts; None: a road
    input: str | None = None
    #: a scenario rig run's drive signal (:class:`rideid.model.posts.PostSignal`); None: measured posts, or a road
    signal: PostSignal | None = None
    signal_seed: int | None = None  #: the seed of a random ``signal``; None: derived (rideid.data.scenario.post_seed)
    #: SPEC §13: the standard uncertainty (m/s) declared with ``speed`` as ``{ value, std }``; None: a plain number,
    #: whose default width :meth:`speed_prior` gives
    speed_std: float | None = None
    #: SPEC §13: the standard uncertainty (s) declared with ``start`` as ``{ value, std }``; None: a plain number,
    #: whose default width :meth:`start_prior_std` gives
    start_std: float | None = None
    #: SPEC §13: the speed as declared when loading moved ``speed`` to where the data put it (beyond its prior,
    #: said in a warning; :func:`rideid.conditioning.load.align_starts`); None: ``speed`` is the declared one
    declared_speed: float | None = None

    def __post_init__(self):
        for k in ("channels", "options", "checks"):
            object.__setattr__(self, k, read_only(getattr(self, k)))

    def speed_prior(self) -> tuple[float, float, bool] | None:
        """SPEC §13: ``(declared speed m/s, its std m/s, declared with a std)``; a plain number's std is
        :data:`SPEED_STD_DEFAULT` of it. None without a declared speed (a speed channel's run)."""
        if self.speed is None:
            return None
        v = float(self.speed if self.declared_speed is None else self.declared_speed)
        if self.speed_std is not None:
            return v, float(self.speed_std), True
        return v, SPEED_STD_DEFAULT * v, False

    def start_prior_std(self) -> float:
        """SPEC §13: the standard uncertainty (s) of the run's start where it is given (a logger file's ``start``,
        or a SPEC CSV's time 0 at x = 0): the declared std, else :data:`START_STD_DEFAULT`. A start estimated
        at load (``"auto"``, or left out of a logger file's run) has no prior."""
        return START_STD_DEFAULT if self.start_std is None else float(self.start_std)

    @property
    def road_known(self) -> bool:
        """Whether the run's road is known: a known track, or a rig's measured posts (False: an unknown or
        generated road, SPEC §9)."""
        return self.track is not None or self.posts

    @property
    def posts(self) -> bool:
        """Whether the run stands on a four-post rig (SPEC §13): no track, speed or start; the posts are the road."""
        return self.input == POSTS_INPUT

    def to_table(self) -> dict:
        d = {"id": self.id}
        if self.posts:
            d["input"] = POSTS_INPUT
            if self.signal is not None:
                sg = self.signal
                d.update(signal=sg.kind, amplitude=sg.amplitude, f_low=sg.f_low, f_high=sg.f_high)
                if sg.kind == "sweep":
                    d["pattern"] = sg.pattern
                if self.signal_seed is not None:
                    d["signal_seed"] = self.signal_seed
        elif self.road is not None:
            d.update(self.road.to_table())
        else:
            d["track"] = self.track if self.track is not None else UNKNOWN_ROAD
        if self.moving != (self.road is not None):  # the default: at rest on a track, moving on a generated road
            d["moving"] = self.moving
        if self.speed is not None:
            d["speed"] = declared_table(self.speed if self.declared_speed is None else self.declared_speed,
                                        self.speed_std)
        if self.file is not None:
            d["file"] = self.file
        else:
            d["fs"] = self.fs
            d["duration"] = self.duration
        if self.channels:
            d["channels"] = {k: e.to_table() for k, e in self.channels.items()}
        for k, v in self.options.items():
            d[k] = list(v) if isinstance(v, tuple) else v
        if self.start_std is not None and "start" in d:
            d["start"] = declared_table(d["start"], self.start_std)
        if self.checks:
            d["checks"] = dict(self.checks)
        return d


@dataclass(frozen=True)
class Manifest:
    """What a scenario and a dataset manifest share: the car, what is known, the tracks and the runs.

    Attributes
    ----------
    path : Path
        The file read (``base_dir`` is its folder).
    name : str
    geometry : Geometry
    known : mapping name -> float
        ``[known]``: fixed parameters and ``total_mass``.
    bounds : mapping name -> (float, float)
        ``[bounds]``: search ranges given in the file.
    tracks : mapping track id -> Track
    runs : tuple of RunSpec
    extensions : tuple of str or None
        ``[model] extensions`` (SPEC §6, §8), canonical order (:data:`MODEL_GROUPS`); None without a
        ``[model]`` table (or one that only sets ``damper_knots``).
    damper_knots : tuple of float or None
        ``[model] damper_knots`` (SPEC §8): the positive knot velocities (m/s) of damper curves to
        identify; None: not given (the default knots of SPEC §8).
    declared : mapping key -> float
        The standard uncertainties declared in ``[known]`` and ``[vehicle]`` (SPEC §12: a value written
        ``{ value, std }``), in the value's unit; a key absent here is exact.
    size_std : mapping track id -> float
        SPEC §13: the standard uncertainty (m) declared with a track's drawn size (``amplitude``, a twist's
        ``height``, written ``{ value, std }``); a track absent here has the default width
        (:meth:`size_prior`).
    """

    path: Path
    name: str
    geometry: Geometry
    known: ReadOnlyDict
    bounds: ReadOnlyDict
    tracks: ReadOnlyDict
    runs: tuple
    extensions: tuple[str, ...] | None = None
    damper_knots: tuple[float, ...] | None = None
    declared: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    size_std: ReadOnlyDict = field(default_factory=ReadOnlyDict)

    def __post_init__(self):
        object.__setattr__(self, "path", Path(self.path))
        for k in ("known", "bounds", "tracks", "declared", "size_std"):
            object.__setattr__(self, k, read_only(getattr(self, k)))
        object.__setattr__(self, "runs", tuple(self.runs))
        if self.extensions is not None:
            object.__setattr__(self, "extensions", tuple(self.extensions))
        if self.damper_knots is not None:
            object.__setattr__(self, "damper_knots", tuple(float(k) for k in self.damper_knots))

    @property
    def base_dir(self) -> Path:
        return self.path.parent

    def run(self, run_id: str) -> RunSpec:
        for r in self.runs:
            if r.id == run_id:
                return r
        raise KeyError(run_id)

    def size_prior(self, track_id: str) -> tuple[float, bool]:
        """SPEC §13: the relative standard uncertainty of a track's drawn size (its amplitude factor's prior
        std about 1) and whether it was declared; a plain number's is :data:`SIZE_STD_DEFAULT`."""
        tr = self.tracks[track_id]
        if track_id in self.size_std:
            size = next((abs(float(tr.keys[k])) for k in TRACK_PRIOR_KEYS if k in tr.keys), 0.0)
            if size > 0:
                return float(self.size_std[track_id]) / size, True
        return SIZE_STD_DEFAULT, False

    def shared(self) -> dict:
        """The fields of :class:`Manifest` as keywords, to build the other kind from this one."""
        return {f.name: getattr(self, f.name) for f in fields(Manifest)}


@dataclass(frozen=True)
class Scenario(Manifest):
    """A parsed, validated scenario file: a car to simulate (``[truth]``) on runs of given rate and duration."""

    #: ``[truth]``: the twelve parameters, any extensions (absent means 0, not stored) and bump stops (SPEC §8)
    truth: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    #: ``[hifi]``: the MuJoCo car's properties (rideid.verify.hifi), or None
    hifi: HifiProperties | None = None
    #: ``[dampers]``: the car's damper curves (SPEC §8), or None (linear c_sf, c_sr)
    dampers: DamperCurves | None = None

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "truth", read_only(self.truth))

    @property
    def bump_stops(self) -> dict[str, float]:
        """The bump-stop truths given (SPEC §8), name -> value; empty without bump stops."""
        return {n: self.truth[n] for n in BUMP_NAMES if n in self.truth}

    @property
    def bump_stop_pairs(self):
        """``((clear_f, clear_r), (rate_f, rate_r))``; an axle without a stop ``(inf, 0)``."""
        return bump_stop_pairs(self.truth)

    @property
    def nonlinear(self) -> bool:
        """Whether the car has damper curves or bump stops (SPEC §8): its tires then push but never pull."""
        return self.dampers is not None or bool(self.bump_stops)


@dataclass(frozen=True)
class DatasetManifest(Manifest):
    """A parsed, validated ``dataset.toml``: recorded runs and how their files were logged."""

    #: ``[channels]``: SPEC target -> ChannelEntry, for every run (a run's own ``channels`` take precedence)
    channel_map: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    #: ``[preprocess]``: key -> validated value (rideid.data.measured)
    preprocess: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    csv_options: CsvOptions | None = None
    #: ``[csv]`` as written, to write it back
    csv_table: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    #: ``[checks]``: check name -> "error" | "warn" | "off" (rideid.data.checks)
    checks: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    #: ``[channels]`` ``sensitivity_std`` (SPEC §12): channel -> relative standard uncertainty of its sensitivity
    sensitivity_std: ReadOnlyDict = field(default_factory=ReadOnlyDict)
    #: ``[settings]``: setting name -> value (:mod:`rideid.settings`), in force while the dataset is loaded and fitted
    settings: ReadOnlyDict = field(default_factory=ReadOnlyDict)

    def __post_init__(self):
        super().__post_init__()
        for k in ("channel_map", "preprocess", "csv_table", "checks", "sensitivity_std", "settings"):
            object.__setattr__(self, k, read_only(getattr(self, k)))

    def is_measured(self, run: RunSpec) -> bool:
        """Whether a run goes through rideid.data.measured (anything beyond a SPEC §3 CSV taken as it is)."""
        return bool(self.channel_map or self.preprocess or self.csv_table or run.channels or run.options
                    or (run.speed is None and not run.posts)
                    or (run.file is not None and not run.file.lower().endswith(".csv")))

    def to_dataset_doc(self) -> dict:
        """The ``dataset.toml`` document (plain dicts and lists, ready for TOML)."""
        doc = {"name": self.name, "vehicle": vehicle_table(self.geometry, self.declared)}
        if self.known:
            doc["known"] = {k: declared_table(v, self.declared.get(k)) for k, v in self.known.items()}
        if self.bounds:
            doc["bounds"] = {k: list(v) for k, v in self.bounds.items()}
        model = model_table(self)
        if model is not None:
            doc["model"] = model
        if self.channel_map or self.sensitivity_std:
            doc["channels"] = {k: e.to_table() for k, e in self.channel_map.items()}
            for k, s in self.sensitivity_std.items():
                doc["channels"][k] = {**doc["channels"].get(k, {}), "sensitivity_std": s}
        if self.preprocess:
            doc["preprocess"] = {k: list(v) if isinstance(v, tuple) else v for k, v in self.preprocess.items()}
        if self.csv_table:
            doc["csv"] = dict(self.csv_table)
        if self.checks:
            doc["checks"] = dict(self.checks)
        if self.settings:
            doc["settings"] = {k: list(v) if isinstance(v, tuple) else v for k, v in self.settings.items()}
        if self.tracks:  # none when every run is on an unknown road (SPEC §9)
            doc["tracks"] = [_size_table(t.to_table(), self.size_std.get(t.id)) for t in self.tracks.values()]
        doc["runs"] = [r.to_table() for r in self.runs]
        return doc


# ---------------------------------------------------------------------------
# Tables

def _size_table(tab: dict, std: float | None) -> dict:
    """A track's table with its drawn size written ``{ value, std }`` when a std was declared (SPEC §13)."""
    if std is not None:
        for k in TRACK_PRIOR_KEYS:
            if k in tab:
                tab = dict(tab, **{k: declared_table(tab[k], std)})
    return tab


def _split_priors(t: dict, keys, where: str) -> tuple[dict, dict]:
    """SPEC §13: a run's or a track's table with its ``{ value, std }`` entries among ``keys`` made plain, and
    those keys' stds (each finite, >= 0 and below the value's magnitude)."""
    out, stds = dict(t), {}
    for k in keys:
        if isinstance(t.get(k), dict):
            v, std = split_declared(t[k], f"{where} {k}")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise DataError(f"{where} {k} value: expected a finite number, got {v!r}")
            check_std(v, std, f"{where} {k}")
            out[k], stds[k] = v, std
    return out, stds


def _param_value(v, name, where):
    """A parameter value: the twelve positive, the extensions (SPEC §6) non-negative."""
    v = number(v, where)
    if name in SIGNED:  # the powertrain's position: ahead of the CG +, behind it -
        return v
    if name in EXT_NAMES or name.startswith("bs_rate"):
        if v < 0:
            raise DataError(f"{where}: must not be negative (0 means none), got {v!r}")
    elif v <= 0:
        raise DataError(f"{where}: must be positive, got {v!r}")
    return v


def parse_model(tab, where: str) -> tuple[str, ...]:
    """The ``[model]`` table's ``extensions = [group, ...]`` (SPEC §6, §8) -> the groups in canonical order."""
    return parse_model_table(tab, where)[0] or ()


def parse_model_table(tab, where: str) -> tuple[tuple[str, ...] | None, tuple[float, ...] | None]:
    """The ``[model]`` table: ``(extensions, damper_knots)``.

    ``extensions``: the groups (:data:`MODEL_GROUPS`, canonical order); None
    when the table only sets ``damper_knots`` (the model is then chosen as
    without a table). ``damper_knots``: None when not given.
    """
    if not isinstance(tab, dict):
        raise DataError(f"{where}: [model] must be a table")
    SECTIONS["model"].check_unknown(tab, where)
    knots = (parse_damper_knots(tab["damper_knots"], f"{where}: [model] damper_knots") if "damper_knots" in tab
             else None)
    if "extensions" not in tab and knots is not None:
        return None, knots
    ext = tab.get("extensions", [])
    if not isinstance(ext, list) or not all(isinstance(g, str) for g in ext):
        raise DataError(f"{where}: [model] extensions: expected a list of group names ({', '.join(MODEL_GROUPS)})")
    for g in ext:
        if g not in MODEL_GROUPS:
            raise DataError(f"{where}: [model] extensions: unknown group '{g}'; groups are: {', '.join(MODEL_GROUPS)}")
    return tuple(g for g in MODEL_GROUPS if g in ext), knots


def model_table(man: Manifest) -> dict | None:
    """The ``[model]`` table of a manifest (None: none to write)."""
    if man.extensions is None and man.damper_knots is None:
        return None
    out = {}
    if man.extensions is not None:
        out["extensions"] = list(man.extensions)
    if man.damper_knots is not None:
        out["damper_knots"] = list(man.damper_knots)
    return out


def vehicle_table(geom: Geometry, declared: dict | None = None) -> dict:
    """The ``[vehicle]`` table of a geometry (``cg_height`` only when not 0); a key with a std in
    ``declared`` (SPEC §12) is written ``{ value, std }``."""
    declared = declared or {}
    out = {k: declared_table(getattr(geom, k), declared.get(k)) for k in Geometry.KEYS}
    for k in OPTIONAL_VEHICLE_KEYS:
        v = getattr(geom, k)
        if v != Geometry.OPTIONAL_KEYS[k]:
            out[k] = declared_table(v, declared.get(k))
    return out


def parse_checks(tab, where: str) -> dict:
    """``[checks]`` (or a run's ``checks``): check name -> "error", "warn" or "off"."""
    if not isinstance(tab, dict):
        raise DataError(f"{where} must be a table, e.g. {{ wiring = \"warn\" }}")
    for k, v in tab.items():
        if k not in CHECK_NAMES:
            raise DataError(f"{where}: unknown check '{k}'; allowed: {', '.join(CHECK_NAMES)}")
        if v not in CHECK_LEVELS:
            raise DataError(f"{where} {k}: expected one of {', '.join(CHECK_LEVELS)}, got {v!r}")
    return dict(tab)


def parse_settings(tab, where: str) -> dict:
    """``[settings]``: setting name -> value, checked against :mod:`rideid.settings` (a dotted key,
    ``adequacy.alpha = 0.05``, or a quoted one, ``"adequacy.alpha" = 0.05``, or a ``[settings.adequacy]`` table)."""
    if not isinstance(tab, dict):
        raise DataError(f"{where}: must be a table of setting = value (docs/settings.md)")
    flat = {}
    for k, v in tab.items():
        if isinstance(v, dict):  # adequacy.alpha = 0.05 (TOML's dotted key) or [settings.adequacy]
            flat.update({f"{k}.{k2}": v2 for k2, v2 in v.items()})
        else:
            flat[k] = v
    out = {}
    for k, v in flat.items():
        if k not in settings.REGISTRY:
            raise DataError(f"{where}: unknown setting '{k}'; the settings (module.name) are listed in "
                            "docs/settings.md")
        try:
            out.update(settings.checked({k: v}))
        except ArgumentError as e:
            raise DataError(f"{where}: {str(e).removeprefix('settings: ')}") from None
    return out


def parse_truth(tab: dict, where: str, geom: Geometry | None) -> dict[str, float]:
    """The twelve parameters, any of the four extensions (SPEC §6; absent means 0, not stored) and the bump stops
    (SPEC §8)."""
    for k in tab:
        if k not in NAMES and k not in EXT_NAMES and k not in BUMP_NAMES:
            raise DataError(f"{where}: unknown parameter '{k}'; expected the twelve: {', '.join(NAMES)} "
                            f"(and optionally {', '.join(EXT_NAMES + BUMP_NAMES)})")
    missing = [k for k in NAMES if k not in tab]
    if missing:
        raise DataError(f"{where}: missing {', '.join(missing)} (all twelve parameters are needed)")
    vals = {k: _param_value(tab[k], k, f"{where} {k}") for k in NAMES + EXT_NAMES if k in tab}
    vals.update(parse_bump_stops(tab, where))
    if geom is not None:
        check_parameters([vals[n] for n in NAMES], geom, where)
        if vals.get("m_p", 0.0) > 0:
            check_parameters(as_vector(vals, extended=True), geom, where)
    return vals


def _split_declared(tab: dict, where: str, section: str) -> tuple[dict, dict]:
    """A ``[known]`` or ``[vehicle]`` table as plain values, and the stds declared in it (SPEC §12)."""
    values, stds = {}, {}
    for k, v in tab.items():
        values[k], std = split_declared(v, f"{where}: [{section}] {k}")
        if std is not None:
            stds[k] = std
    return values, stds


def _parse_geometry(doc: dict, where: str, declared: dict | None = None) -> Geometry:
    tab, stds = _split_declared(table(doc, "vehicle", where), where, "vehicle")
    kw = SECTIONS["vehicle"].read(tab, where)
    for k, std in stds.items():
        if k in kw:
            check_std(kw[k], std, f"{where}: [vehicle] {k}")
            if declared is not None:
                declared[k] = std
    if "cg_height" in kw:
        h = kw.pop("cg_height")
        if h < 0:
            raise DataError(f"{where}: [vehicle] cg_height: the CG height above the wheel centres must not be "
                            f"negative (m), got {h:g}")
        if h:
            kw["cg_height"] = h
    return Geometry(**kw)


def _parse_known(doc: dict, where: str, geom: Geometry, declared: dict | None = None) -> dict[str, float]:
    known = {}
    tab, stds = _split_declared(table(doc, "known", where, required=False), where, "known")
    for k, v in tab.items():
        if k not in NAMES and k not in EXT_NAMES and k not in EXTRA_KNOWN and k not in BUMP_NAMES:
            raise DataError(f"{where}: [known]: unknown key '{k}'; allowed: total_mass or one of "
                            f"{', '.join(NAMES + EXT_NAMES + BUMP_NAMES)}")
        known[k] = (number(v, f"{where}: [known] {k}", positive=True) if k in EXTRA_KNOWN
                    else _param_value(v, k, f"{where}: [known] {k}"))
        if k == "a" and not known[k] < geom.wheelbase:
            raise DataError(f"{where}: [known] a = {known[k]} must be less than the wheelbase {geom.wheelbase}")
        if k in stds:
            check_std(known[k], stds[k], f"{where}: [known] {k}")
            if declared is not None:
                declared[k] = stds[k]
    return known


def _parse_bounds(doc: dict, where: str, geom: Geometry, known: dict) -> dict[str, tuple[float, float]]:
    bounds = {}
    for k, v in table(doc, "bounds", where, required=False).items():
        w = f"{where}: [bounds] {k}"
        if k not in NAMES and k not in EXT_NAMES and k not in BUMP_NAMES:
            raise DataError(f"{w}: unknown parameter; allowed: {', '.join(NAMES + EXT_NAMES + BUMP_NAMES)}")
        if not isinstance(v, list) or len(v) != 2:
            raise DataError(f"{w}: expected [lower, upper]")
        lo, hi = number(v[0], w), number(v[1], w)
        if not lo < hi:
            raise DataError(f"{w}: lower bound {lo} must be less than upper bound {hi}")
        if (k in EXT_NAMES or k.startswith("bs_rate")) and k not in SIGNED and lo < 0:
            raise DataError(f"{w}: lower bound must not be negative, got {lo}")
        if k != "a" and k not in EXT_NAMES and not k.startswith("bs_rate") and lo <= 0:
            raise DataError(f"{w}: lower bound must be positive, got {lo}")
        if k == "a" and not (0 < lo and hi < geom.wheelbase):
            raise DataError(f"{w}: must lie within (0, wheelbase = {geom.wheelbase})")
        if k in known:
            raise DataError(f"{w}: parameter is known (fixed) in [known]; remove one of the two")
        bounds[k] = (lo, hi)
    return bounds


def _parse_tracks(doc: dict, where: str, base_dir: Path, size_std: dict | None = None) -> dict[str, Track]:
    """The ``[[tracks]]`` tables; none at all is allowed (every run then on an unknown road, checked with the runs).
    ``size_std`` (filled): track id -> the std declared with its drawn size (SPEC §13)."""
    raw_tracks = doc.get("tracks", [])
    if not isinstance(raw_tracks, list):
        raise DataError(f"{where}: tracks must be [[tracks]] tables")
    tracks: dict[str, Track] = {}
    for i, t in enumerate(raw_tracks):
        if not isinstance(t, dict):
            raise DataError(f"{where}: tracks[{i}] must be a table")
        if t.get("id") == UNKNOWN_ROAD:
            raise DataError(f"{where}: tracks[{i}]: track id '{UNKNOWN_ROAD}' is reserved for runs on roads nobody "
                            "measured (SPEC §9); give the track another id")
        label = f" (id '{t['id']}')" if isinstance(t.get("id"), str) else ""
        t, stds = _split_priors(t, TRACK_PRIOR_KEYS, f"{where}: tracks[{i}]{label}")
        tr = track_from_table(t, f"{where}: tracks[{i}]", base_dir=base_dir)
        if tr.id in tracks:
            raise DataError(f"{where}: tracks[{i}]: duplicate track id '{tr.id}'")
        tracks[tr.id] = tr
        if stds and size_std is not None:
            size_std[tr.id] = next(iter(stds.values()))
    return tracks


def _run_track(r: dict, w: str, where: str, tracks: dict, scenario: bool) -> str | None:
    """The run's track id, or None for an unknown (dataset) or generated (scenario) road (SPEC §9)."""
    track = r.get("track", UNKNOWN_ROAD)
    if not isinstance(track, str) or not track:
        raise DataError(f"{w}: key 'track' must be a track id (a string) or \"{UNKNOWN_ROAD}\"")
    road = "road_class" in r
    if scenario:
        if road and track != UNKNOWN_ROAD:
            raise DataError(f"{w}: give either 'track' (a [[tracks]] id) or 'road_class' (a generated road), "
                            "not both")
        if not road and track == UNKNOWN_ROAD:
            raise DataError(f"{w}: missing key 'track' or 'road_class': a scenario run drives a [[tracks]] id or "
                            "a generated ISO 8608 road (road_class = \"A\" ... \"H\")")
        for k in ROAD_KEYS[1:]:
            if k in r and not road:
                raise DataError(f"{w}: key '{k}' belongs to a generated road; give 'road_class' too (or leave "
                                f"'{k}' out)")
    if track == UNKNOWN_ROAD:
        return None
    if track not in tracks:
        if not tracks:
            raise DataError(f"{where}: needs at least one [[tracks]] table (run '{r['id']}' names track "
                            f"'{track}')")
        raise DataError(f"{w}: unknown track '{track}'; tracks are: {', '.join(tracks)} "
                        f"(or \"{UNKNOWN_ROAD}\" for a road nobody measured)")
    return track


def _parse_road(r: dict, w: str) -> RoadSpec:
    """A scenario run's ``road_class``, ``road_seed`` and ``coherence`` (SPEC §9)."""
    c = r["road_class"]
    if not isinstance(c, str) or c.strip().upper() not in ROAD_CLASSES:
        raise DataError(f"{w}: road_class must be an ISO 8608 class letter ({', '.join(ROAD_CLASSES)}), got {c!r}")
    seed = r.get("road_seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise DataError(f"{w}: road_seed must be a non-negative whole number, got {seed!r}")
    coh = r.get("coherence", 1.0)
    if isinstance(coh, bool) or not isinstance(coh, (int, float)) or math.isnan(coh) or coh < 0:
        raise DataError(f"{w}: coherence must be a number >= 0 (1: the isotropic road; inf: identical wheel "
                        f"paths; 0: independent ones), got {coh!r}")
    return RoadSpec(c.strip().upper(), seed, float(coh))


def _parse_runs(doc: dict, where: str, tracks: dict, scenario: bool) -> list[RunSpec]:
    raw_runs = doc.get("runs", [])
    if not isinstance(raw_runs, list) or not raw_runs:
        raise DataError(f"{where}: needs at least one [[runs]] table")
    run_keys = SECTIONS["runs.scenario" if scenario else "runs.dataset"]
    runs: list[RunSpec] = []
    seen = set()
    for i, r in enumerate(raw_runs):
        w = f"{where}: runs[{i}]"
        if not isinstance(r, dict):
            raise DataError(f"{w} must be a table")
        rid = r.get("id")
        if not isinstance(rid, str) or not rid:
            raise DataError(f"{w}: missing key 'id' (a non-empty string)")
        w = f"{w} (id '{rid}')"
        stds = {}
        if not scenario:  # SPEC §13: a dataset run's speed and start may carry their std
            r, stds = _split_priors(r, RUN_PRIOR_KEYS, w)
        vals = run_keys.read(r, w)
        if rid in seen:
            raise DataError(f"{w}: duplicate run id '{rid}'")
        seen.add(rid)
        rig = _run_input(r, w, scenario)
        track = None if rig else _run_track(r, w, where, tracks, scenario)
        road = _parse_road(r, w) if scenario and "road_class" in r else None
        moving = r.get("moving", road is not None)
        if not isinstance(moving, bool):
            raise DataError(f"{w}: moving must be true or false, got {moving!r}")
        speed = vals.get("speed")
        if scenario and not rig and speed is None:
            raise DataError(f"{w}: missing key 'speed'")
        rig_kw = {"input": POSTS_INPUT} if rig else {}
        if scenario:
            fs, dur = vals["fs"], vals["duration"]
            if round(dur * fs) < 2:
                raise DataError(f"{w}: duration * fs gives fewer than 3 samples")
            if rig:
                rig_kw.update(_parse_signal(r, vals, w, dur))
            runs.append(RunSpec(rid, track, speed, fs=fs, duration=dur, moving=moving, road=road, **rig_kw))
        else:
            chans = parse_channel_map(r["channels"], f"{w}: channels") if "channels" in r else {}
            opts = parse_preprocess({k: v for k, v in r.items() if k in RUN_PREPROCESS_KEYS}, w,
                                    RUN_PREPROCESS_KEYS)
            lv = parse_checks(r["checks"], f"{w}: checks") if "checks" in r else {}
            if "start" in stds and isinstance(opts.get("start"), str):
                raise DataError(f"{w} start: a start estimated (\"{opts['start']}\") takes no std")
            runs.append(RunSpec(rid, track, speed, file=r["file"], channels=chans, options=opts, checks=lv,
                                moving=moving, speed_std=stds.get("speed"), start_std=stds.get("start"),
                                **rig_kw))
    return runs


def _run_input(r: dict, w: str, scenario: bool) -> bool:
    """Whether the run stands on a four-post rig (SPEC §13: ``input = "posts"``); what such a run cannot have
    (a track, a speed, a moving start, a start to find) is refused in one line naming the key."""
    if "input" not in r:
        for k in SIGNAL_KEYS:
            if scenario and k in r:
                raise DataError(f"{w}: key '{k}' belongs to a four-post rig run; give input = \"{POSTS_INPUT}\" "
                                f"too (or leave '{k}' out)")
        return False
    if r["input"] != POSTS_INPUT:
        raise DataError(f"{w}: input: expected \"{POSTS_INPUT}\" (a four-post rig run, SPEC §13), got {r['input']!r}")
    why = {"track": "its road is the measured posts", "road_class": "its road is the measured posts",
           "speed": "a rig does not drive", "moving": "a rig run starts with the car at rest on its posts"}
    for k, reason in why.items():
        if k in r and not (k == "moving" and r[k] is False):
            raise DataError(f"{w}: key '{k}' does not apply to a four-post rig run (input = \"{POSTS_INPUT}\": "
                            f"{reason}); leave it out")
    return True


def _parse_signal(r: dict, vals: dict, w: str, duration: float) -> dict:
    """A scenario rig run's drive signal (SPEC §13, :class:`rideid.model.posts.PostSignal`) and seed."""
    kind = r.get("signal")
    if kind not in SIGNALS:
        raise DataError(f"{w}: signal: a four-post rig run of a scenario needs signal = \"sweep\" or \"random\" "
                        f"(the posts' drive), got {kind!r}")
    for k in ("amplitude", "f_low", "f_high"):
        if k not in vals:
            raise DataError(f"{w}: missing key '{k}' of the post signal (amplitude in m, f_low and f_high in Hz)")
    if not vals["f_low"] < vals["f_high"] < vals["fs"] / 2:
        raise DataError(f"{w}: the post signal's band needs f_low < f_high < fs / 2 = {vals['fs'] / 2:g} Hz, got "
                        f"f_low = {vals['f_low']:g}, f_high = {vals['f_high']:g}")
    pattern = r.get("pattern", "heave")
    if kind == "random" and "pattern" in r:
        raise DataError(f"{w}: key 'pattern' belongs to a sweep (signal = \"random\" moves each post on its own)")
    if pattern not in PATTERNS:
        raise DataError(f"{w}: pattern: expected one of {', '.join(PATTERNS)}, got {pattern!r}")
    seed = r.get("signal_seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise DataError(f"{w}: signal_seed must be a non-negative whole number, got {seed!r}")
    if kind == "sweep" and seed is not None:
        raise DataError(f"{w}: key 'signal_seed' belongs to a random signal (a sweep has no randomness)")
    sig = PostSignal(kind, vals["amplitude"], vals["f_low"], vals["f_high"], duration, pattern=pattern)
    return {"signal": sig, "signal_seed": seed}


def _parse_shared(doc: dict, path: Path, scenario: bool) -> dict:
    """The :class:`Manifest` fields, in the order the file's tables are checked."""
    where = str(path)
    SECTIONS["scenario" if scenario else "dataset"].check_unknown(doc, where)
    name = doc.get("name", path.parent.name if not scenario else path.stem)
    if not isinstance(name, str):
        raise DataError(f"{where}: key 'name' must be a string")
    declared = {}
    geom = _parse_geometry(doc, where, declared)
    known = _parse_known(doc, where, geom, declared)
    _refuse_declared_elsewhere(doc, where, scenario)
    bounds = _parse_bounds(doc, where, geom, known)
    size_std = {}
    tracks = _parse_tracks(doc, where, path.parent, size_std)
    runs = _parse_runs(doc, where, tracks, scenario)
    return dict(path=path, name=name, geometry=geom, known=known, bounds=bounds, tracks=tracks, runs=runs,
                declared=declared, size_std=size_std)


def _refuse_declared_elsewhere(doc: dict, where: str, scenario: bool = False) -> None:
    """A ``{ value, std }`` in ``[bounds]``, a track or a run: one line naming the key (SPEC §12 declares
    uncertainties in ``[known]`` and ``[vehicle]``; SPEC §13 a track's drawn size and a dataset run's speed and
    start)."""
    if isinstance(doc.get("bounds"), dict):
        for k, v in doc["bounds"].items():
            refuse_declared(v, f"{where}: [bounds] {k}")
    for section in ("tracks", "runs"):
        items = doc.get(section)
        if isinstance(items, list):
            for i, t in enumerate(items):
                if isinstance(t, dict):
                    label = f" (id '{t['id']}')" if isinstance(t.get("id"), str) else ""
                    allowed = TRACK_PRIOR_KEYS if section == "tracks" else () if scenario else RUN_PRIOR_KEYS
                    for k, v in t.items():
                        if k not in allowed:
                            refuse_declared(v, f"{where}: {section}[{i}]{label} {k}")


# ---------------------------------------------------------------------------
# The two documents

def parse_scenario(doc: dict, path) -> Scenario:
    """Validate a scenario document (already parsed TOML) read from ``path``."""
    path = Path(path)
    where = str(path)
    kw = _parse_shared(doc, path, scenario=True)
    geom, known = kw["geometry"], kw["known"]
    dampers = parse_dampers(doc["dampers"], f"{where}: [dampers]") if "dampers" in doc else None
    truth_tab = table(doc, "truth", where)
    if dampers is not None:  # the curves are the dampers; c_sf, c_sr (if left out) their mean slope over +-0.1 m/s
        truth_tab = {**{n: float(f"{dampers.slope_between(ax):.12g}") for n, ax in (("c_sf", "f"), ("c_sr", "r"))},
                     **truth_tab}
    truth = parse_truth(truth_tab, f"{where}: [truth]", geom)
    if "total_mass" in known:
        tm = total_mass(truth)
        if abs(tm - known["total_mass"]) > 1e-6 * tm:
            raise DataError(f"{where}: [known] total_mass = {known['total_mass']} disagrees with [truth] "
                            f"(m_s + 2 m_uf + 2 m_ur = {tm:.6g})")
    for k, v in known.items():
        tv = truth.get(k, 0.0 if k in EXT_NAMES else None)
        if tv is not None and abs(tv - v) > 1e-9 * abs(v):
            raise DataError(f"{where}: [known] {k} = {v} disagrees with [truth] {k} = {tv}")
    extensions, knots = parse_model_table(doc["model"], where) if "model" in doc else (None, None)
    hifi = None
    if "hifi" in doc:
        hifi = parse_hifi(doc["hifi"], f"{where}: [hifi]")
        tire_damping_of([truth[n] for n in NAMES] + [truth.get(n, 0.0) for n in EXT_NAMES], hifi, where)
        if hifi.cg_height <= -geom.tire_radius:
            raise DataError(f"{where}: [hifi] cg_height: a CG {-hifi.cg_height} m below the wheel centres "
                            f"is under the road (tire_radius {geom.tire_radius} m)")
        _check_hifi_against_scenario(hifi, geom, truth, dampers, where)
    return Scenario(**kw, extensions=extensions, damper_knots=knots, truth=truth, hifi=hifi, dampers=dampers)


def _check_hifi_against_scenario(hifi: HifiProperties, geom: Geometry, truth: dict, dampers, where: str):
    """What ``[hifi]`` and the SPEC §8 keys both describe must be given once (or agree, for the CG height)."""
    h = geom.cg_height
    if h and hifi.cg_height and abs(h - hifi.cg_height) > 1e-12:
        raise DataError(f"{where}: the CG height is given twice and differs: [vehicle] cg_height = {h:g} m, "
                        f"[hifi] cg_height = {hifi.cg_height:g} m; give it once, in [vehicle]")
    if dampers is not None and not hifi.linear_dampers:
        raise DataError(f"{where}: the dampers are given twice, as [dampers] curves and as [hifi] "
                        "damper_rebound_ratio/damper_knee_*; give them in one place ([dampers])")
    if any(n in truth for n in BUMP_NAMES) and hifi.bumpstops:
        raise DataError(f"{where}: the bump stops are given twice, as [truth] bs_clear_*/bs_rate_* and as [hifi] "
                        "bumpstop_clearance/bumpstop_rate; give them in one place ([truth])")


def parse_dataset_manifest(doc: dict, path) -> DatasetManifest:
    """Validate a ``dataset.toml`` document (already parsed TOML) read from ``path``."""
    path = Path(path)
    where = str(path)
    kw = _parse_shared(doc, path, scenario=False)
    extensions, knots = parse_model_table(doc["model"], where) if "model" in doc else (None, None)
    extra = {}
    if "channels" in doc:
        tab, extra["sensitivity_std"] = split_sensitivity(doc["channels"], f"{where}: [channels]")
        extra["channel_map"] = parse_channel_map(tab, f"{where}: [channels]")
    if "preprocess" in doc:
        extra["preprocess"] = parse_preprocess(doc["preprocess"], f"{where}: [preprocess]")
    if "csv" in doc:
        extra["csv_options"] = parse_csv_options(doc["csv"], f"{where}: [csv]")
        extra["csv_table"] = dict(doc["csv"])
    if "checks" in doc:
        extra["checks"] = parse_checks(doc["checks"], f"{where}: [checks]")
    if "settings" in doc:
        extra["settings"] = parse_settings(doc["settings"], f"{where}: [settings]")
    return DatasetManifest(**kw, extensions=extensions, damper_knots=knots, **extra)


def load_manifest(path) -> DatasetManifest:
    """``dataset.toml`` of a dataset folder (or the file itself)."""
    if not Path(path).exists():
        raise DataError(f"{path}: no such dataset folder")
    path = in_folder(path, "dataset.toml")
    return parse_dataset_manifest(read_toml(path), path)


def load_truth(path, geom: Geometry | None = None) -> dict[str, float]:
    """``truth.toml`` (a ``[truth]`` table alone), as written beside a simulated dataset (the file, or the
    folder that holds it)."""
    path = in_folder(path, "truth.toml")
    doc = read_toml(path)
    for k in doc:
        if k not in ("truth", "dampers", "roads"):
            raise DataError(f"{path}: unknown key '{k}'; expected a [truth] table (and [dampers], [roads])")
    if "dampers" in doc:
        parse_dampers(doc["dampers"], f"{path}: [dampers]")
    if "roads" in doc:
        load_truth_roads(path)
    return parse_truth(table(doc, "truth", str(path)), f"{path}: [truth]", geom)


def load_truth_roads(path) -> dict[str, dict]:
    """The ``[roads]`` table of a ``truth.toml``: run id -> how its generated road was made (SPEC §9:
    ``road_class``, ``road_seed``, ``coherence``, and the class its road_truth fits); empty without one."""
    path = in_folder(path, "truth.toml")
    roads = read_toml(path).get("roads", {})
    if not isinstance(roads, dict) or not all(isinstance(v, dict) and isinstance(v.get("road_class"), str)
                                              for v in roads.values()):
        raise DataError(f"{path}: [roads] must hold one table per run, each with its road_class")
    return roads


def load_truth_dampers(path) -> DamperCurves | None:
    """The ``[dampers]`` table of a ``truth.toml`` (SPEC §8: the simulated car's damper curves), or None."""
    path = in_folder(path, "truth.toml")
    doc = read_toml(path)
    return parse_dampers(doc["dampers"], f"{path}: [dampers]") if "dampers" in doc else None


__all__ = ["SPEED_STD_DEFAULT", "START_STD_DEFAULT", "SIZE_STD_DEFAULT", "RUN_PRIOR_KEYS", "TRACK_PRIOR_KEYS",
           "Manifest", "Scenario", "DatasetManifest", "RunSpec", "RoadSpec", "UNKNOWN_ROAD", "ChannelEntry",
           "parse_scenario", "parse_dataset_manifest", "parse_model", "parse_model_table", "parse_checks",
           "parse_truth", "load_manifest", "load_truth", "load_truth_dampers", "load_truth_roads", "model_table",
           "vehicle_table", "MODEL_GROUPS", "CHECK_NAMES", "CHECK_LEVELS", "TOP_KEYS_SCENARIO", "TOP_KEYS_DATASET",
           "RUN_KEYS_SCENARIO", "RUN_KEYS_DATASET", "ROAD_KEYS", "SECTIONS"]
__all__ += ["parse_settings"]
