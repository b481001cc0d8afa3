"""Scenario and dataset files (SPEC §3): reading, validation, writing.

Every problem is reported as a :class:`rideid.DataError` whose message names
the file and the key or column at fault. Unknown keys are errors.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
import tomllib
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomli_w

from ..csvio import read_csv_rows
from ..errors import DataError, DataWarning
from .measured import RUN_PREPROCESS_KEYS, RunData, parse_channel_map, parse_csv_options, parse_preprocess
from ..model.equations import CHANNELS
from ..model.params import EXT_NAMES, EXTRA_KNOWN, GROUPS, INDEX, NAMES, Geometry, check_parameters, total_mass
from ..model.tracks import Track

#: a scenario may also describe the multibody car of rideid.hifi (``[hifi]``, used by --engine mujoco)
TOP_KEYS_SCENARIO = ("name", "vehicle", "known", "bounds", "model", "tracks", "runs", "truth", "hifi")
#: a dataset may also describe how its files were logged (rideid.measured)
TOP_KEYS_DATASET = ("name", "vehicle", "known", "bounds", "model", "channels", "preprocess", "csv", "checks",
                    "tracks", "runs")
RUN_KEYS_DATASET = ("id", "track", "speed", "file", "channels", "checks") + RUN_PREPROCESS_KEYS
RUN_KEYS_SCENARIO = ("id", "track", "speed", "fs", "duration")


def read_toml(path: Path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: file not found")
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise DataError(f"{path}: invalid TOML: {e}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(f"{path}: cannot read: {e}") from None


def _number(v, where, positive=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise DataError(f"{where}: expected a finite number, got {v!r}")
    if positive and v <= 0:
        raise DataError(f"{where}: must be positive, got {v!r}")
    return float(v)


def _param_value(v, name, where):
    """A parameter value: the twelve positive, the extensions (SPEC §6) non-negative."""
    v = _number(v, where)
    if name in EXT_NAMES:
        if v < 0:
            raise DataError(f"{where}: must not be negative (0 means none), got {v!r}")
    elif v <= 0:
        raise DataError(f"{where}: must be positive, got {v!r}")
    return v


def parse_model(tab, where: str) -> tuple[str, ...]:
    """The ``[model]`` table: ``extensions = [group, ...]`` (SPEC §6) -> the groups in canonical order."""
    if not isinstance(tab, dict):
        raise DataError(f"{where}: [model] must be a table")
    for k in tab:
        if k != "extensions":
            raise DataError(f"{where}: [model]: unknown key '{k}'; allowed: extensions")
    ext = tab.get("extensions", [])
    if not isinstance(ext, list) or not all(isinstance(g, str) for g in ext):
        raise DataError(f"{where}: [model] extensions: expected a list of group names ({', '.join(GROUPS)})")
    for g in ext:
        if g not in GROUPS:
            raise DataError(f"{where}: [model] extensions: unknown group '{g}'; groups are: {', '.join(GROUPS)}")
    return tuple(g for g in GROUPS if g in ext)


def _table(doc, key, where, required=True):
    if key not in doc:
        if required:
            raise DataError(f"{where}: missing table [{key}]")
        return {}
    v = doc[key]
    if not isinstance(v, dict):
        raise DataError(f"{where}: [{key}] must be a table")
    return v


@dataclass
class RunSpec:
    """One run of a manifest: its track, speed and file (dataset) or rate and duration (scenario)."""

    id: str
    track: str
    speed: float | None
    file: str | None = None
    fs: float | None = None
    duration: float | None = None
    #: measured-data options of this run (rideid.measured): its channel map and preprocessing keys
    channels: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    #: this run's levels of the data checks (rideid.data.checks), over the dataset's [checks]
    checks: dict = field(default_factory=dict)

    def to_table(self) -> dict:
        d = {"id": self.id, "track": self.track}
        if self.speed is not None:
            d["speed"] = self.speed
        if self.file is not None:
            d["file"] = self.file
        else:
            d["fs"] = self.fs
            d["duration"] = self.duration
        if self.channels:
            d["channels"] = {k: e.to_table() for k, e in self.channels.items()}
        for k, v in self.options.items():
            d[k] = list(v) if isinstance(v, tuple) else v
        if self.checks:
            d["checks"] = dict(self.checks)
        return d


@dataclass
class Manifest:
    """A parsed, validated ``dataset.toml`` or scenario file."""

    path: Path
    name: str
    geometry: Geometry
    known: dict[str, float]
    bounds: dict[str, tuple[float, float]]
    tracks: dict[str, Track]
    runs: list[RunSpec]
    truth: dict[str, float] | None = None
    channel_map: dict = field(default_factory=dict)
    preprocess: dict = field(default_factory=dict)
    csv_options: object = None
    csv_table: dict = field(default_factory=dict)
    #: ``[checks]``: check name -> "error" | "warn" | "off" (rideid.data.checks)
    checks: dict = field(default_factory=dict)
    #: scenario only: the ``[hifi]`` properties of the MuJoCo car (rideid.hifi.HifiProperties), or None
    hifi: object = None
    #: ``[model] extensions`` (SPEC §6): the extension groups to estimate; None without a [model] table
    extensions: tuple[str, ...] | None = None

    def is_measured(self, run: RunSpec) -> bool:
        """Whether a run goes through rideid.measured (anything beyond a SPEC §3 CSV taken as it is)."""
        return bool(self.channel_map or self.preprocess or self.csv_table or run.channels or run.options
                    or run.speed is None or (run.file is not None and not run.file.lower().endswith(".csv")))

    @property
    def base_dir(self) -> Path:
        return self.path.parent

    def run(self, run_id: str) -> RunSpec:
        for r in self.runs:
            if r.id == run_id:
                return r
        raise KeyError(run_id)

    def to_dataset_doc(self) -> dict:
        doc = {"name": self.name,
               "vehicle": {k: getattr(self.geometry, k) for k in Geometry.KEYS}}
        if self.known:
            doc["known"] = dict(self.known)
        if self.bounds:
            doc["bounds"] = {k: list(v) for k, v in self.bounds.items()}
        if self.extensions is not None:
            doc["model"] = {"extensions": list(self.extensions)}
        if self.channel_map:
            doc["channels"] = {k: e.to_table() for k, e in self.channel_map.items()}
        if self.preprocess:
            doc["preprocess"] = {k: list(v) if isinstance(v, tuple) else v for k, v in self.preprocess.items()}
        if self.csv_table:
            doc["csv"] = dict(self.csv_table)
        if self.checks:
            doc["checks"] = dict(self.checks)
        doc["tracks"] = [t.to_table() for t in self.tracks.values()]
        doc["runs"] = [r.to_table() for r in self.runs]
        return doc


def parse_manifest(doc: dict, path: Path, scenario: bool) -> Manifest:
    """Validate a manifest document (already parsed TOML)."""
    path = Path(path)
    where = str(path)
    allowed = TOP_KEYS_SCENARIO if scenario else TOP_KEYS_DATASET
    for k in doc:
        if k not in allowed:
            hint = ""
            if not scenario and k == "truth":
                hint = " (a [truth] table belongs in a scenario or in truth.toml)"
            raise DataError(f"{where}: unknown key '{k}'{hint}; allowed: {', '.join(allowed)}")
    name = doc.get("name", path.parent.name if not scenario else path.stem)
    if not isinstance(name, str):
        raise DataError(f"{where}: key 'name' must be a string")

    veh = _table(doc, "vehicle", where)
    for k in veh:
        if k not in Geometry.KEYS:
            raise DataError(f"{where}: [vehicle]: unknown key '{k}'; allowed: {', '.join(Geometry.KEYS)}")
    for k in Geometry.KEYS:
        if k not in veh:
            raise DataError(f"{where}: [vehicle]: missing key '{k}'")
    geom = Geometry(**{k: _number(veh[k], f"{where}: [vehicle] {k}", positive=True) for k in Geometry.KEYS})

    known = {}
    for k, v in _table(doc, "known", where, required=False).items():
        if k not in NAMES and k not in EXT_NAMES and k not in EXTRA_KNOWN:
            raise DataError(f"{where}: [known]: unknown key '{k}'; allowed: total_mass or one of "
                            f"{', '.join(NAMES + EXT_NAMES)}")
        known[k] = (_number(v, f"{where}: [known] {k}", positive=True) if k in EXTRA_KNOWN
                    else _param_value(v, k, f"{where}: [known] {k}"))
        if k == "a" and not known[k] < geom.wheelbase:
            raise DataError(f"{where}: [known] a = {known[k]} must be less than the wheelbase {geom.wheelbase}")

    bounds = {}
    for k, v in _table(doc, "bounds", where, required=False).items():
        w = f"{where}: [bounds] {k}"
        if k not in NAMES and k not in EXT_NAMES:
            raise DataError(f"{w}: unknown parameter; allowed: {', '.join(NAMES + EXT_NAMES)}")
        if not isinstance(v, list) or len(v) != 2:
            raise DataError(f"{w}: expected [lower, upper]")
        lo, hi = _number(v[0], w), _number(v[1], w)
        if not lo < hi:
            raise DataError(f"{w}: lower bound {lo} must be less than upper bound {hi}")
        if k in EXT_NAMES and lo < 0:
            raise DataError(f"{w}: lower bound must not be negative, got {lo}")
        if k != "a" and k not in EXT_NAMES and lo <= 0:
            raise DataError(f"{w}: lower bound must be positive, got {lo}")
        if k == "a" and not (0 < lo and hi < geom.wheelbase):
            raise DataError(f"{w}: must lie within (0, wheelbase = {geom.wheelbase})")
        if k in known:
            raise DataError(f"{w}: parameter is known (fixed) in [known]; remove one of the two")
        bounds[k] = (lo, hi)

    raw_tracks = doc.get("tracks", [])
    if not isinstance(raw_tracks, list) or not raw_tracks:
        raise DataError(f"{where}: needs at least one [[tracks]] table")
    tracks: dict[str, Track] = {}
    for i, t in enumerate(raw_tracks):
        if not isinstance(t, dict):
            raise DataError(f"{where}: tracks[{i}] must be a table")
        tr = Track.from_table(t, f"{where}: tracks[{i}]", base_dir=path.parent)
        if tr.id in tracks:
            raise DataError(f"{where}: tracks[{i}]: duplicate track id '{tr.id}'")
        tracks[tr.id] = tr

    raw_runs = doc.get("runs", [])
    if not isinstance(raw_runs, list) or not raw_runs:
        raise DataError(f"{where}: needs at least one [[runs]] table")
    run_keys = RUN_KEYS_SCENARIO if scenario else RUN_KEYS_DATASET
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
        for k in r:
            if k not in run_keys:
                hint = ""
                if k in ("fs", "duration") and not scenario:
                    hint = " (fs and duration belong to scenarios; a dataset run names its 'file')"
                if k == "file" and scenario:
                    hint = " (a scenario run gives 'fs' and 'duration' instead of a file)"
                raise DataError(f"{w}: unknown key '{k}'{hint}; allowed: {', '.join(run_keys)}")
        required = RUN_KEYS_SCENARIO if scenario else ("id", "track", "file")
        for k in required:
            if k not in r:
                raise DataError(f"{w}: missing key '{k}'")
        if rid in seen:
            raise DataError(f"{w}: duplicate run id '{rid}'")
        seen.add(rid)
        if r["track"] not in tracks:
            raise DataError(f"{w}: unknown track '{r['track']}'; tracks are: {', '.join(tracks)}")
        speed = _number(r["speed"], f"{w}: speed", positive=True) if "speed" in r else None
        if scenario:
            fs = _number(r["fs"], f"{w}: fs", positive=True)
            dur = _number(r["duration"], f"{w}: duration", positive=True)
            if round(dur * fs) < 2:
                raise DataError(f"{w}: duration * fs gives fewer than 3 samples")
            runs.append(RunSpec(rid, r["track"], speed, fs=fs, duration=dur))
        else:
            if not isinstance(r["file"], str):
                raise DataError(f"{w}: key 'file' must be a path string")
            chans = parse_channel_map(r["channels"], f"{w}: channels") if "channels" in r else {}
            opts = parse_preprocess({k: v for k, v in r.items() if k in RUN_PREPROCESS_KEYS}, w,
                                    RUN_PREPROCESS_KEYS)
            lv = parse_checks(r["checks"], f"{w}: checks") if "checks" in r else {}
            runs.append(RunSpec(rid, r["track"], speed, file=r["file"], channels=chans, options=opts, checks=lv))

    truth = None
    if scenario:
        truth = parse_truth(_table(doc, "truth", where), f"{where}: [truth]", geom)
        if "total_mass" in known:
            tm = total_mass(truth)
            if abs(tm - known["total_mass"]) > 1e-6 * tm:
                raise DataError(f"{where}: [known] total_mass = {known['total_mass']} disagrees with [truth] "
                                f"(m_s + 2 m_uf + 2 m_ur = {tm:.6g})")
        for k, v in known.items():
            tv = truth.get(k, 0.0 if k in EXT_NAMES else None)
            if tv is not None and abs(tv - v) > 1e-9 * abs(v):
                raise DataError(f"{where}: [known] {k} = {v} disagrees with [truth] {k} = {tv}")
    man = Manifest(path, name, geom, known, bounds, tracks, runs, truth)
    if "model" in doc:
        man.extensions = parse_model(doc["model"], where)
    if scenario and "hifi" in doc:
        from ..verify.hifi import parse_hifi
        man.hifi = parse_hifi(doc["hifi"], f"{where}: [hifi]")
        from ..verify.hifi import tire_damping_of
        tire_damping_of([truth[n] for n in NAMES] + [truth.get(n, 0.0) for n in EXT_NAMES], man.hifi, where)
        if man.hifi.cg_height <= -geom.tire_radius:
            raise DataError(f"{where}: [hifi] cg_height: a CG {-man.hifi.cg_height} m below the wheel centres "
                            f"is under the road (tire_radius {geom.tire_radius} m)")
    if not scenario:
        if "channels" in doc:
            man.channel_map = parse_channel_map(doc["channels"], f"{where}: [channels]")
        if "preprocess" in doc:
            man.preprocess = parse_preprocess(doc["preprocess"], f"{where}: [preprocess]")
        if "csv" in doc:
            man.csv_options = parse_csv_options(doc["csv"], f"{where}: [csv]")
            man.csv_table = dict(doc["csv"])
        if "checks" in doc:
            man.checks = parse_checks(doc["checks"], f"{where}: [checks]")
    return man


def parse_checks(tab, where: str) -> dict:
    """``[checks]`` (or a run's ``checks``): check name -> "error", "warn" or "off"."""
    from .checks import CHECK_LEVELS, CHECK_NAMES
    if not isinstance(tab, dict):
        raise DataError(f"{where} must be a table, e.g. {{ wiring = \"warn\" }}")
    for k, v in tab.items():
        if k not in CHECK_NAMES:
            raise DataError(f"{where}: unknown check '{k}'; allowed: {', '.join(CHECK_NAMES)}")
        if v not in CHECK_LEVELS:
            raise DataError(f"{where} {k}: expected one of {', '.join(CHECK_LEVELS)}, got {v!r}")
    return dict(tab)


def parse_truth(tab: dict, where: str, geom: Geometry | None) -> dict[str, float]:
    """The twelve parameters, and any of the four extensions (SPEC §6; absent means 0, not stored)."""
    for k in tab:
        if k not in NAMES and k not in EXT_NAMES:
            raise DataError(f"{where}: unknown parameter '{k}'; expected the twelve: {', '.join(NAMES)} "
                            f"(and optionally {', '.join(EXT_NAMES)})")
    missing = [k for k in NAMES if k not in tab]
    if missing:
        raise DataError(f"{where}: missing {', '.join(missing)} (all twelve parameters are needed)")
    vals = {k: _param_value(tab[k], k, f"{where} {k}") for k in NAMES + EXT_NAMES if k in tab}
    if geom is not None:
        check_parameters([vals[n] for n in NAMES], geom, where)
    return vals


def load_scenario(path) -> Manifest:
    from .checks import check_numbers, enforce
    path = Path(path)
    man = parse_manifest(read_toml(path), path, scenario=True)
    enforce(check_numbers(man))
    return man


def in_folder(path, name: str) -> Path:
    """``path/name`` when ``path`` is a folder, else ``path`` itself (a folder's main file given directly)."""
    path = Path(path)
    return path / name if path.is_dir() else path


def load_manifest(path) -> Manifest:
    """``dataset.toml`` of a dataset folder (or the file itself)."""
    if not Path(path).exists():
        raise DataError(f"{path}: no such dataset folder")
    path = in_folder(path, "dataset.toml")
    return parse_manifest(read_toml(path), path, scenario=False)


def load_truth(path, geom: Geometry | None = None) -> dict[str, float]:
    path = Path(path)
    doc = read_toml(path)
    for k in doc:
        if k != "truth":
            raise DataError(f"{path}: unknown key '{k}'; expected a [truth] table")
    return parse_truth(_table(doc, "truth", str(path)), f"{path}: [truth]", geom)


# ---------------------------------------------------------------------------
# Run files

def read_run_csv(path: Path) -> RunData:
    """Read and validate a run CSV (SPEC §3)."""
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
    used = [c for c in header if c == "time" or c in CHANNELS]
    extra = [c for c in header if c not in used]
    if extra:
        warnings.warn(f"{path}: ignoring column(s) not in the SPEC channels: {', '.join(extra)}",
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
    # rebuild an exactly uniform time base
    t = t[0] + h * np.arange(t.size)
    channels = {c: arr[:, j] for j, c in enumerate(used) if c != "time"}
    if not channels:
        raise DataError(f"{path}: no measured channel; expected some of {', '.join(CHANNELS)}")
    return RunData(t, channels)


def write_run_csv(path: Path, time, Y, channels=CHANNELS):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    M = np.column_stack([time, Y])
    np.savetxt(path, M, delimiter=",", header=",".join(("time",) + tuple(channels)), comments="", fmt="%.12g")


def write_toml(path: Path, doc: dict, comment: str | None = None):
    path = Path(path)
    text = tomli_w.dumps(doc)
    if comment:
        text = "".join(f"# {ln}\n" for ln in comment.splitlines()) + text
    path.write_text(text)


# ---------------------------------------------------------------------------
# Output folders: all or nothing

@contextlib.contextmanager
def atomic_output(out_dir):
    """Write into a temporary folder beside ``out_dir``; move into place on success.

    On any exception nothing is left in ``out_dir`` (files already there are
    kept; new files replace old ones only on success).
    """
    out_dir = Path(out_dir)
    parent = out_dir.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DataError(f"{out_dir}: cannot create output folder: {e}") from None
    if out_dir.exists() and not out_dir.is_dir():
        raise DataError(f"{out_dir}: exists and is not a folder")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=parent))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if not out_dir.exists():
        os.replace(tmp, out_dir)
        return
    for root, _dirs, files in os.walk(tmp):
        rel = Path(root).relative_to(tmp)
        (out_dir / rel).mkdir(parents=True, exist_ok=True)
        for f in files:
            os.replace(Path(root) / f, out_dir / rel / f)
    shutil.rmtree(tmp, ignore_errors=True)


__all__ = ["Manifest", "RunSpec", "RunData", "load_manifest", "load_scenario", "load_truth", "read_run_csv",
           "write_run_csv", "atomic_output", "INDEX"]
