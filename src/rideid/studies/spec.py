"""Study files: parse and validate a study TOML into an immutable list of tasks.

A study is the product of its axes (see ``docs/studies.md``)::

    data (datasets, or noise levels x noise seeds of one scenario)
      x subsets of runs x every identify option given as a list

Every task has a key: a hash of its options and of its data's content
(the dataset files, or the scenario file with the noise level and seed), so
a restarted study recognises the tasks it already finished, and a changed
dataset is recomputed.
"""

from __future__ import annotations

import glob
import hashlib
import inspect
import itertools
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..data.scenario import BUILTIN, default_scenario, default_scenario_path, load_scenario
from ..data.schema import Key, Messages, Section, read_toml
from ..errors import DataError
from ..estimate.fit.identify import DEFAULT_GENERATIONS, DEFAULT_POPULATION
from ..estimate.choice.model_choice import identify

TOP_KEYS = ("name", "data", "identify", "subsets")
DATA_KEYS = ("datasets", "scenario", "noise", "noise_seeds")
#: identify options a study may set, in the order they vary in the task list (last varies fastest)
IDENTIFY_KEYS = ("model", "weights", "population", "generations", "polish", "spread_tol", "seed")
IDENTIFY_DEFAULTS = {"population": DEFAULT_POPULATION, "generations": DEFAULT_GENERATIONS, "polish": True,
                     "weights": "adaptive", "seed": 1}


def _section(keys, what: str) -> Section:
    """A study section whose values (one or a list: an axis of the study) its parser checks."""
    return Section({k: Key("any") for k in keys},
                   Messages(unknown="{where}: unknown key '{key}' in " + what + " (allowed: {allowed})"))


#: The declarative key tables of a study file: section -> :class:`rideid.data.schema.Section`
SECTIONS = {"study": _section(TOP_KEYS, "the study file"), "data": _section(DATA_KEYS, "[data]"),
            "identify": _section(IDENTIFY_KEYS, "[identify]"),
            "noise_seeds": _section(("first", "count"), "noise_seeds")}


@dataclass(frozen=True)
class Task:
    """One identification of a study.

    Attributes
    ----------
    index : int
        Position in the study's task list (the row order of the results).
    key : str
        16 hex digits: hash of ``options`` and of the data's content.
    options : dict
        ``data`` (the dataset as written in the study file, or ``scenario``,
        ``noise``, ``noise_seed``), ``subset`` (name or None), ``runs`` (run
        ids or None = all) and ``identify`` (keyword arguments of
        :func:`rideid.identify`).
    dataset_path : str or None
        Absolute path of the dataset folder (dataset tasks).
    """

    index: int
    key: str
    options: dict
    dataset_path: str | None = None


@dataclass(frozen=True)
class Study:
    """A validated study file: its name, where it came from, its tasks."""

    name: str
    path: Path | None
    tasks: tuple[Task, ...]
    #: the scenario file (absolute, or "builtin") of a scenario study, else None
    scenario: str | None = None
    doc: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------

def _err(where, msg):
    return DataError(f"{where}: {msg}")


def _as_list(v):
    return list(v) if isinstance(v, list) else [v]


def _int(v, where, lo):
    if isinstance(v, bool) or not isinstance(v, int):
        raise _err(where, f"expected a whole number, got {v!r}")
    if v < lo:
        raise _err(where, f"must be at least {lo}, got {v}")
    return int(v)


def _hash_files(h, paths):
    for p in paths:
        h.update(str(p.name).encode() + b"\0")
        try:
            h.update(p.read_bytes())
        except OSError:
            h.update(b"<missing>")  # the task fails when it loads the dataset, and says why
        h.update(b"\0")


def dataset_content_hash(folder: Path) -> str:
    """sha256 of ``dataset.toml`` and of every file it names (runs, profiles).

    A ``dataset.toml`` that cannot be read hashes as it is (the task then
    fails with the loader's message).
    """
    folder = Path(folder)
    h = hashlib.sha256()
    toml = folder / "dataset.toml"
    _hash_files(h, [toml])
    try:
        doc = tomllib.loads(toml.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return h.hexdigest()
    names = []
    for sect in ("runs", "tracks"):
        for t in doc.get(sect, []) if isinstance(doc.get(sect), list) else []:
            if isinstance(t, dict) and isinstance(t.get("file"), str):
                names.append(t["file"])
    truth = folder / "truth.toml"  # the truth is part of a row (errors vs truth)
    _hash_files(h, [folder / n for n in names] + ([truth] if truth.is_file() else []))
    return h.hexdigest()


def scenario_content_hash(path) -> str:
    p = default_scenario_path() if path == BUILTIN else Path(path)
    h = hashlib.sha256()
    _hash_files(h, [p])
    doc = tomllib.loads(p.read_text())
    files = [t["file"] for t in doc.get("tracks", []) if isinstance(t, dict) and isinstance(t.get("file"), str)]
    _hash_files(h, [p.parent / f for f in files])
    return h.hexdigest()


def task_key(options: dict, content: str) -> str:
    blob = json.dumps({"options": options, "content": content}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def identify_accepts(name: str) -> bool:
    """Whether the installed :func:`rideid.identify` takes keyword ``name``."""
    return name in inspect.signature(identify).parameters


# ---------------------------------------------------------------------------

def _parse_identify(tab, where):
    SECTIONS["identify"].check_unknown(tab, where)
    axes = {}
    for k in IDENTIFY_KEYS:
        if k not in tab:
            if k in IDENTIFY_DEFAULTS:
                axes[k] = [IDENTIFY_DEFAULTS[k]]
            continue
        vals = _as_list(tab[k])
        w = f"{where} [identify] {k}"
        if not vals:
            raise _err(w, "an empty list gives no tasks")
        out = []
        for v in vals:
            if k in ("population",):
                out.append(_int(v, w, 4))
            elif k == "generations":
                out.append(_int(v, w, 1))
            elif k == "seed":
                out.append(_int(v, w, 0))
            elif k == "weights":
                if v not in ("adaptive", "fixed"):
                    raise _err(w, f"expected \"adaptive\" or \"fixed\", got {v!r}")
                out.append(v)
            elif k == "polish":
                if not isinstance(v, bool):
                    raise _err(w, f"expected true or false, got {v!r}")
                out.append(v)
            elif k == "spread_tol":
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                    raise _err(w, f"expected a non-negative number (0 disables JADE's early stop), got {v!r}")
                out.append(float(v))
            elif k == "model":
                if not isinstance(v, str):
                    raise _err(w, f"expected a model name such as \"base\", \"full\" or \"auto\", got {v!r}")
                if not identify_accepts("model"):
                    raise _err(w, "this version of rideid.identify has no model choice (it fits the "
                                  "twelve-parameter model of SPEC §1); remove 'model' from [identify]")
                out.append(v)
        if len(set(map(repr, out))) != len(out):
            raise _err(w, f"a value is listed twice: {vals!r}")
        axes[k] = out
    return axes


def _parse_seeds(v, where):
    if isinstance(v, dict):
        SECTIONS["noise_seeds"].check_unknown(v, where)
        if "count" not in v:
            raise _err(where, "missing key 'count' (noise_seeds = { first = 1, count = 40 })")
        first = _int(v.get("first", 1), f"{where}.first", 0)
        count = _int(v["count"], f"{where}.count", 1)
        return list(range(first, first + count))
    vals = _as_list(v)
    if not vals:
        raise _err(where, "an empty list gives no tasks")
    out = [_int(s, where, 0) for s in vals]
    if len(set(out)) != len(out):
        raise _err(where, f"a seed is listed twice: {out}")
    return out


def _parse_data(tab, where, base):
    """-> (items, scenario): items = [(options['data'], dataset path or None, content hash)]."""
    SECTIONS["data"].check_unknown(tab, where)
    has_ds, has_sc = "datasets" in tab, "scenario" in tab
    if has_ds == has_sc:
        raise _err(where, "[data] needs either 'datasets' (folders or globs) or 'scenario' "
                          "(a scenario file or \"builtin\", with 'noise' and 'noise_seeds'), not both")
    if has_ds:
        for k in ("noise", "noise_seeds"):
            if k in tab:
                raise _err(f"{where} [data] {k}", "belongs to a scenario study; a dataset already holds "
                                                  "its measurement noise")
        w = f"{where} [data] datasets"
        pats = _as_list(tab["datasets"])
        if not pats or not all(isinstance(p, str) and p for p in pats):
            raise _err(w, "expected a list of folder paths or glob patterns (relative to the study file)")
        items, seen = [], set()
        for pat in pats:
            full = str(base / pat)
            matches = sorted(glob.glob(full)) if glob.has_magic(pat) else [full]
            matches = [m for m in matches if (Path(m) / "dataset.toml").is_file() or not glob.has_magic(pat)]
            if not matches:
                raise _err(w, f"'{pat}' matches no dataset folder (a folder with dataset.toml) under {base}")
            for m in matches:
                p = Path(m)
                if not p.is_dir():  # a broken dataset inside a folder is a failed task, a wrong path is this
                    raise _err(w, f"'{pat}': {p} is not a folder" if p.exists() else f"'{pat}': no such folder {p}")
                label = (Path(m).resolve().relative_to(base.resolve()).as_posix()
                         if Path(m).resolve().is_relative_to(base.resolve()) else str(Path(m).resolve()))
                if label in seen:
                    continue
                seen.add(label)
                items.append(({"dataset": label}, str(p.resolve()), dataset_content_hash(p)))
        return items, None
    w = f"{where} [data] scenario"
    sc = tab["scenario"]
    if not isinstance(sc, str) or not sc:
        raise _err(w, f"expected a scenario file (relative to the study file) or \"builtin\", got {sc!r}")
    if sc == BUILTIN:
        sc_path, label = BUILTIN, BUILTIN
    else:
        p = base / sc
        if not p.is_file():
            raise _err(w, f"scenario file not found: {p}")
        sc_path, label = str(p.resolve()), sc
    default_scenario() if sc_path == BUILTIN else load_scenario(sc_path)  # validate now
    if "noise" not in tab:
        raise _err(where, "[data] missing key 'noise' (fraction of each channel's RMS, e.g. 0.01; a list is an axis)")
    noises = []
    for v in _as_list(tab["noise"]):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise _err(f"{where} [data] noise", f"expected a non-negative fraction, got {v!r}")
        noises.append(float(v))
    if not noises:
        raise _err(f"{where} [data] noise", "an empty list gives no tasks")
    seeds = _parse_seeds(tab.get("noise_seeds", [1]), f"{where} [data] noise_seeds")
    content = scenario_content_hash(sc_path)
    items = [({"scenario": label, "noise": n, "noise_seed": s}, None, content)
             for n in noises for s in seeds]
    return items, sc_path


def _parse_subsets(tab, where, scenario_runs):
    if not isinstance(tab, dict) or not tab:
        raise _err(where, "[subsets] must be a table of name = [run ids] (or name = \"all\")")
    out = []
    for name, ids in tab.items():
        w = f"{where} [subsets] {name}"
        if ids == "all":
            out.append((name, None))
            continue
        if not isinstance(ids, list) or not ids or not all(isinstance(i, str) for i in ids):
            raise _err(w, "expected a non-empty list of run ids, or \"all\"")
        if len(set(ids)) != len(ids):
            raise _err(w, f"a run is listed twice: {ids}")
        if scenario_runs is not None:
            bad = [i for i in ids if i not in scenario_runs]
            if bad:
                raise _err(w, f"unknown run '{bad[0]}' (the scenario's runs: {', '.join(scenario_runs)})")
        out.append((name, list(ids)))
    return out


def parse_study(doc: dict, path: Path | None = None, base: Path | None = None) -> Study:
    """Validate a study document (parsed TOML) into a :class:`Study`.

    Parameters
    ----------
    doc : dict
        The study file's content.
    path : Path, optional
        The file it came from (for messages).
    base : Path, optional
        Folder relative paths are taken from (default: the file's folder, or
        the current folder).

    Raises
    ------
    rideid.DataError
        Naming the file and the key at fault.
    """
    where = str(path) if path is not None else "study"
    base = Path(base) if base is not None else (Path(path).parent if path is not None else Path.cwd())
    if not isinstance(doc, dict):
        raise _err(where, "a study must be a table")
    SECTIONS["study"].check_unknown(doc, where)
    name = doc.get("name", Path(path).stem if path is not None else "study")
    if not isinstance(name, str):
        raise _err(f"{where} name", f"expected a string, got {name!r}")
    if "data" not in doc or not isinstance(doc["data"], dict):
        raise _err(where, "missing table [data] (datasets = [...], or scenario = ... with noise and noise_seeds)")
    items, scenario = _parse_data(doc["data"], where, base)
    idt = doc.get("identify", {})
    if not isinstance(idt, dict):
        raise _err(where, "[identify] must be a table")
    axes = _parse_identify(idt, where)
    sc_runs = None
    if scenario is not None:
        sc = default_scenario() if scenario == BUILTIN else load_scenario(scenario)
        sc_runs = [r.id for r in sc.runs]
    subsets = _parse_subsets(doc["subsets"], where, sc_runs) if "subsets" in doc else [(None, None)]
    keys = [k for k in IDENTIFY_KEYS if k in axes]
    tasks = []
    for (data, ds_path, content), (sub, runs) in itertools.product(items, subsets):
        for combo in itertools.product(*(axes[k] for k in keys)):
            opts = {"data": data, "subset": sub, "runs": runs, "identify": dict(zip(keys, combo))}
            tasks.append(Task(len(tasks), task_key(opts, content), opts, ds_path))
    seen = {}
    for t in tasks:  # identical content and options: one computation would serve two rows
        if t.key in seen:
            raise _err(where, f"tasks {seen[t.key]} and {t.index} are the same identification "
                              f"({json.dumps(t.options['data'])}); list each dataset once")
        seen[t.key] = t.index
    return Study(name, Path(path) if path is not None else None, tuple(tasks), scenario, doc)


def load_study(path) -> Study:
    """Read and validate a study TOML file (format: ``docs/studies.md``).

    Parameters
    ----------
    path : str or Path
        The study file; relative paths in it are taken from its folder.

    Returns
    -------
    Study

    Raises
    ------
    rideid.DataError
        Naming the file and the key at fault.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: study file not found")
    return parse_study(read_toml(path), path)
