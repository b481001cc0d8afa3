"""What every format module of :mod:`rideid.data.schema` shares.

TOML in and out, the number and table checks whose messages name the file
and key at fault, the read-only mapping the parsed types hold, and the
all-or-nothing output folder.
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import shutil
import tempfile
import tomllib
from pathlib import Path

import tomli_w

from ...errors import DataError


class ReadOnlyDict(dict):
    """A dict that refuses changes: the tables of a parsed, frozen file type.

    A subclass of ``dict`` (rather than :class:`types.MappingProxyType`) so
    that it pickles, deep-copies and serialises to JSON/TOML like the dict
    it was read as. Build a changed
    copy with ``{**d, key: value}`` and :func:`dataclasses.replace` on its owner.
    """

    __slots__ = ()

    def _refuse(self, *args, **kwargs):
        raise TypeError("this table of a parsed file is read-only; build a new one "
                        "({**table, key: value}) and use dataclasses.replace on its owner")

    __setitem__ = __delitem__ = __ior__ = _refuse
    update = pop = popitem = clear = setdefault = _refuse

    def __reduce__(self):
        return (ReadOnlyDict, (dict(self),))

    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return ReadOnlyDict({k: copy.deepcopy(v, memo) for k, v in self.items()})


def read_only(d) -> ReadOnlyDict:
    """``d`` (a mapping, or None for empty) as a :class:`ReadOnlyDict`."""
    return d if isinstance(d, ReadOnlyDict) else ReadOnlyDict(d or {})


def read_toml(path: Path) -> dict:
    """A TOML file as a dict; :class:`DataError` naming the file when it is missing or not TOML."""
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


def write_toml(path: Path, doc: dict, comment: str | None = None):
    """Write ``doc`` as TOML, with ``comment`` (any number of lines) as a ``#`` header."""
    path = Path(path)
    text = tomli_w.dumps(doc)
    if comment:
        text = "".join(f"# {ln}\n" for ln in comment.splitlines()) + text
    path.write_text(text)


def number(v, where: str, positive: bool = False) -> float:
    """A finite number (a TOML bool is not one); ``positive``: also > 0."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise DataError(f"{where}: expected a finite number, got {v!r}")
    if positive and v <= 0:
        raise DataError(f"{where}: must be positive, got {v!r}")
    return float(v)


def table(doc: dict, key: str, where: str, required: bool = True) -> dict:
    """``doc[key]``, checked to be a table; ``{}`` when absent and not ``required``."""
    if key not in doc:
        if required:
            raise DataError(f"{where}: missing table [{key}]")
        return {}
    v = doc[key]
    if not isinstance(v, dict):
        raise DataError(f"{where}: [{key}] must be a table")
    return v


def checked_items(tab, where: str, allowed, what: str = "", unknown: str = "unknown key '{key}'; allowed: {allowed}"):
    """``(key, value, where key)`` of a TOML table, after checking it is a table with only ``allowed`` keys."""
    if not isinstance(tab, dict):
        raise DataError(f"{where} must be a table{what}")
    for k in tab:
        if k not in allowed:
            raise DataError(f"{where}: " + unknown.format(key=k, allowed=", ".join(allowed)))
    return [(k, v, f"{where} {k}") for k, v in tab.items()]


def in_folder(path, name: str) -> Path:
    """``path/name`` when ``path`` is a folder, else ``path`` itself (a folder's main file given directly)."""
    path = Path(path)
    return path / name if path.is_dir() else path


def write_atomic(path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename (a reader never sees half)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


@contextlib.contextmanager
def atomic_output(out_dir, replaces=()):
    """Write into a temporary folder; move into place on success.

    On any exception nothing is left in ``out_dir`` (files already there are
    kept; new files replace old ones only on success). A new ``out_dir`` is
    the temporary folder renamed (made beside it, with the permissions
    ``mkdir`` gives); into an ``out_dir`` that exists the files are moved
    from a temporary folder inside it, on its own file system (it may be a
    mount point).

    Parameters
    ----------
    out_dir : str or Path
    replaces : sequence of str
        Names of files and folders in ``out_dir`` that belong to the output
        as a whole (what rideid wrote there before): on success they are
        removed before the new files move in, so that the folder describes
        one output even when the new one lacks some of them. Anything else
        in ``out_dir`` (the user's files) is kept.

    Raises
    ------
    DataError
        ``out_dir`` is a file, or cannot be created or written.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise DataError(f"{out_dir}: exists and is not a folder")
    existed = out_dir.exists()
    where = out_dir.resolve() if existed else out_dir.resolve().parent
    try:
        where.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=where))
        mask = os.umask(0)
        os.umask(mask)
        tmp.chmod(0o777 & ~mask)  # as mkdir makes a folder: it may become ``out_dir``
    except OSError as e:
        raise DataError(f"{out_dir}: cannot write the output folder: {e.strerror or e}") from None
    try:
        yield tmp  # what the caller raises in its block goes on as it is; the folder is removed
        try:
            _move_in(tmp, out_dir, existed, replaces)
        except OSError as e:
            raise DataError(f"{out_dir}: cannot write the output folder: {e.strerror or e}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _move_in(tmp: Path, out_dir: Path, existed: bool, replaces) -> None:
    """:func:`atomic_output`'s last step: ``tmp`` becomes ``out_dir``, or its files move into it."""
    if not existed:
        os.replace(tmp, out_dir)
        return
    for name in replaces:
        old = out_dir / name
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old)
        elif old.exists() or old.is_symlink():
            old.unlink()
    for root, _dirs, files in os.walk(tmp):
        rel = Path(root).relative_to(tmp)
        (out_dir / rel).mkdir(parents=True, exist_ok=True)
        for f in files:
            os.replace(Path(root) / f, out_dir / rel / f)


__all__ = ["ReadOnlyDict", "read_only", "read_toml", "write_toml", "number", "table", "checked_items", "in_folder",
           "atomic_output", "write_atomic"]
