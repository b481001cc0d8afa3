"""Reading loggers' files: CSV, ASAM MDF (3 and 4), NI TDMS, Parquet.

Each reader opens a file and serves its channels by name as
:class:`Signal` (time in the file's own seconds, values, the unit the file
declares or ``None``). The format is chosen by the file's extension:

=================  ==========================  ==================================
extension          format                      package (optional extra)
=================  ==========================  ==================================
``.csv .txt``      delimited text              standard library
``.mf4 .mdf .dat`` ASAM MDF 3/4 (INCA, CANape)  ``asammdf`` (``rideid[mdf]``)
``.tdms``          NI TDMS (LabVIEW, DIAdem)    ``npTDMS`` (``rideid[tdms]``)
``.parquet .pq``   Apache Parquet               ``pyarrow`` (``rideid[parquet]``)
=================  ==========================  ==================================

Files with one shared time column (CSV, Parquet) name it through the channel
map's ``time`` entry (default: a column called ``time``, any case); an empty
cell (CSV) or a null (Parquet) means the channel was not sampled at that row,
which is how those formats carry mixed rates. MDF channels carry their own
time base (the group's master channel); TDMS channels carry theirs as
waveform properties (``wf_start_offset``, ``wf_increment``) or through the
map's ``time`` channel in the same group.

Every problem raises :class:`rideid.DataError` naming the file and channel.
"""

from __future__ import annotations

import contextlib
import csv
import gc
import io
import logging
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError
from .schema.channels import CsvOptions

FORMATS = {
    ".csv": "csv", ".txt": "csv",
    ".mf4": "mdf", ".mdf": "mdf", ".dat": "mdf",
    ".tdms": "tdms",
    ".parquet": "parquet", ".pq": "parquet",
}
FORMAT_NAMES = {"csv": "CSV", "mdf": "ASAM MDF (asammdf)", "tdms": "NI TDMS (npTDMS)",
                "parquet": "Parquet (pyarrow)"}
_EXTRA = {"mdf": ("asammdf", "mdf"), "tdms": ("nptdms", "tdms"), "parquet": ("pyarrow", "parquet")}


@dataclass
class Signal:
    """One channel as stored: time (s, file clock), values, declared unit."""

    time: np.ndarray
    values: np.ndarray
    unit: str | None = None


def file_format(path: Path) -> str:
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise DataError(f"{path}: unknown run file type '{Path(path).suffix}'; rideid reads "
                        f"{', '.join(sorted(FORMATS))}")
    return fmt


class _Quiet:
    """What a :func:`quiet_library` block reports back: whether the reader failed."""

    failed = False

    def fail(self) -> None:
        """The reader raised (and the caller turns it into one line): half-built objects to finalise."""
        self.failed = True


@contextlib.contextmanager
def quiet_library(*loggers: str):
    """Silence a third-party reader while rideid reports its errors itself.

    asammdf and npTDMS log warnings and errors of damaged files through
    :mod:`logging`, emit Python warnings, and a half-built asammdf object
    raises again from its ``__del__`` (printed as "Exception ignored in ...
    Traceback"). Inside this context none of that reaches the terminal; the
    reader's exception is turned into one :class:`rideid.DataError` line.
    Yields a :class:`_Quiet`: a caller that catches the reader's exception
    calls its ``fail()``, and on leaving, a failed block (or one an exception
    leaves) has the garbage collected while still silenced, which finalises
    the half-built objects. A block that read cleanly does not pay for a full
    collection (60 ms each with an identification's objects alive: 7 s of a
    10 s load of ten MDF runs before).
    """
    names = set(loggers) | {n for n in logging.root.manager.loggerDict
                            if any(n.startswith(p + ".") for p in loggers)}
    saved = [(lg, lg.disabled) for lg in (logging.getLogger(n) for n in sorted(names))]
    hook = sys.unraisablehook
    for lg, _ in saved:
        lg.disabled = True
    sys.unraisablehook = lambda unraisable: None
    state = _Quiet()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield state
    except BaseException:
        state.fail()
        raise
    finally:
        if state.failed:
            gc.collect()  # finalise half-built reader objects while their noise is still silenced
        sys.unraisablehook = hook
        for lg, was in saved:
            lg.disabled = was


def _import(fmt: str, path: Path):
    module, extra = _EXTRA[fmt]
    try:
        if module == "asammdf":
            import asammdf
            return asammdf
        if module == "nptdms":
            import nptdms
            return nptdms
        import pyarrow.parquet
        return pyarrow.parquet
    except ImportError:
        raise DataError(f"{path}: reading {FORMAT_NAMES[fmt].split(' (')[0]} files needs the package "
                        f"'{module}': pip install 'rideid[{extra}]'") from None


_LABEL = {"parquet": "Parquet", "mdf": "MDF", "tdms": "TDMS"}


def _read_with(fmt: str, path: Path, read):
    """``read(library)`` with the format's optional library; a damaged file is a DataError naming it."""
    lib = _import(fmt, path)
    msg = None
    with quiet_library(_LOGGERS[fmt]) as quiet:
        try:
            return read(lib)
        except Exception as e:  # pyarrow, asammdf and npTDMS raise their own errors for damaged files
            msg = str(e) or type(e).__name__
            quiet.fail()
    raise DataError(f"{path}: cannot read {_LABEL[fmt]} file: {msg}") from None


#: the loggers of each format's library (silenced while rideid reports the error itself)
_LOGGERS = {"mdf": "asammdf", "tdms": "nptdms", "parquet": "pyarrow"}


class SignalFile:
    """A run file opened for reading channels by name."""

    format: str = ""

    def __init__(self, path: Path):
        self.path = Path(path)

    def names(self) -> list[str]:
        raise NotImplementedError

    def has(self, name: str) -> bool:
        return name in self.names()

    def get(self, name: str, where: str, time_name: str | None = None, time_scale: float = 1.0) -> Signal:
        raise NotImplementedError

    def _missing(self, name, where):
        names = self.names()
        shown = ", ".join(names[:12]) + (f", ... ({len(names)} in all)" if len(names) > 12 else "")
        return DataError(f"{self.path}: no channel '{name}' ({where}); the file has: {shown}")


def open_signals(path: Path, csv_options: CsvOptions | None = None) -> SignalFile:
    """Open a run file by extension (see the module docstring)."""
    path = Path(path)
    fmt = file_format(path)
    if not path.is_file():
        raise DataError(f"{path}: run file not found")
    if fmt == "csv":
        return CsvFile(path, csv_options or CsvOptions())
    if fmt == "mdf":
        return MdfFile(path)
    if fmt == "tdms":
        return TdmsSignals(path)
    return ParquetFile(path)


# ---------------------------------------------------------------------------
# Shared-time-column formats

class _ColumnFile(SignalFile):
    """Columns sharing one time column.

    NaN policy (every format): an empty CSV cell or a Parquet null means
    "not sampled at this row" (how these formats carry mixed rates); a NaN
    *value* (the text ``nan`` in a CSV, a NaN float in Parquet, MDF or TDMS)
    is an error naming the file, channel and row or time.
    """

    #: column -> first data row (0-based) holding an explicit NaN
    nan_rows: dict = {}

    def _row_name(self, row):
        return f"data row {row + 1}"

    columns: dict[str, np.ndarray]
    units: dict[str, str]

    def names(self):
        return list(self.columns)

    def get(self, name, where, time_name=None, time_scale=1.0):
        if name not in self.columns:
            raise self._missing(name, where)
        tname = time_name
        if tname is None:
            tname = next((c for c in self.columns if c.lower() == "time"), None)
            if tname is None:
                raise DataError(f"{self.path}: no time column: name it in [channels] as "
                                f"time = {{ name = \"...\", unit = \"s\" }}")
        elif tname not in self.columns:
            raise self._missing(tname, "the time column")
        t = self.columns[tname] * time_scale
        v = self.columns[name]
        for col in (name, tname):
            row = getattr(self, "nan_rows", {}).get(col)
            if row is not None:
                raise DataError(f"{self.path}: column '{col}' ({where}): NaN at {self._row_name(row)}; "
                                "a sample must be a number (an empty cell or a null means 'not sampled')")
        if np.isnan(t).any():
            raise DataError(f"{self.path}: time column '{tname}' has an empty or non-numeric cell "
                            f"(row {int(np.argmax(np.isnan(t))) + 1})")
        keep = ~np.isnan(v)
        return Signal(t[keep], v[keep], self.units.get(name))


def _sniff(lines: list[str], path: Path, opts: CsvOptions) -> tuple[str, str]:
    delim = opts.delimiter
    if delim is None:
        sample = "\n".join(lines[:50])
        try:
            delim = csv.Sniffer().sniff(sample, delimiters=",;\t|").delimiter
        except csv.Error:
            delim = ","
    dec = opts.decimal
    if dec is None:
        dec = "."
        if delim != ",":
            body = lines[1:50]
            if any("," in ln for ln in body) and not any("." in ln for ln in body):
                dec = ","
    if dec == delim:
        raise DataError(f"{path}: decimal separator and delimiter are both '{dec}'; set [csv] delimiter "
                        "and decimal")
    return delim, dec


def _to_float(cell: str, dec: str) -> float:
    s = cell.strip()
    if not s:
        return np.nan
    if dec != ".":
        s = s.replace(dec, ".")
    return float(s)


class CsvFile(_ColumnFile):
    format = "csv"

    def __init__(self, path, opts: CsvOptions):
        super().__init__(path)
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except UnicodeDecodeError:
            text = Path(path).read_text(encoding="latin-1")
        except OSError as e:
            raise DataError(f"{path}: cannot read: {e}") from None
        lines = text.splitlines()[opts.skip_rows:]
        lines = [ln for ln in lines if ln.strip()]
        if not lines:
            raise DataError(f"{path}: empty file (expected a header row)")
        delim, dec = _sniff(lines, self.path, opts)
        self.delimiter, self.decimal = delim, dec
        self.nan_rows = {}
        self._first_line = 2 + opts.skip_rows
        rows = list(csv.reader(io.StringIO("\n".join(lines)), delimiter=delim))
        header = [c.strip() for c in rows[0]]
        dup = {c for c in header if header.count(c) > 1}
        if dup:
            raise DataError(f"{path}: duplicate column '{sorted(dup)[0]}'")
        body = rows[1:]
        self.units = {}
        first_data = 0
        # a row of units under the header (common in logger exports)
        if body and not any(_is_number(c, dec) for c in body[0]):
            self.units = {h: u.strip().strip("[]") for h, u in zip(header, body[0]) if u.strip()}
            first_data = 1
        data = body[first_data:]
        if len(data) < 3:
            raise DataError(f"{path}: only {len(data)} data rows; at least 3 are needed")
        arr = np.full((len(data), len(header)), np.nan)
        for i, row in enumerate(data):
            ln = i + 2 + first_data + opts.skip_rows
            if len(row) != len(header):
                raise DataError(f"{path}: line {ln}: {len(row)} fields, header has {len(header)} "
                                f"(delimiter '{delim}')")
            for j, cell in enumerate(row):
                try:
                    arr[i, j] = _to_float(cell, dec)
                    if arr[i, j] != arr[i, j] and cell.strip():  # the text 'nan': a value, not an empty cell
                        self.nan_rows.setdefault(header[j], i)
                        arr[i, j] = 0.0
                except ValueError:
                    raise DataError(f"{path}: line {ln}, column '{header[j]}': not a number: {cell!r} "
                                    f"(decimal '{dec}')") from None
        bad = ~np.isfinite(arr) & ~np.isnan(arr)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise DataError(f"{path}: column '{header[j]}' has an infinite value (line {i + 2 + first_data})")
        self.columns = {h: arr[:, j] for j, h in enumerate(header)}
        self._first_line += first_data

    def _row_name(self, row):
        return f"line {row + self._first_line}"


def _is_number(cell: str, dec: str) -> bool:
    try:
        return np.isfinite(_to_float(cell, dec)) or cell.strip() == ""
    except ValueError:
        return False


class ParquetFile(_ColumnFile):
    format = "parquet"

    def __init__(self, path):
        super().__init__(path)
        table = _read_with("parquet", path, lambda pq: pq.read_table(path))
        self.columns, self.units, self.nan_rows = {}, {}, {}
        for fld, col in zip(table.schema, table.columns):
            try:
                arr = np.asarray(col.to_numpy(zero_copy_only=False), dtype=float)
                nulls = np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)
            except (TypeError, ValueError, AttributeError):
                continue  # text or nested columns are not channels
            bad = np.isnan(arr) & ~nulls
            if bad.any():
                self.nan_rows[fld.name] = int(np.argmax(bad))
            self.columns[fld.name] = np.where(bad, 0.0, arr)
            meta = fld.metadata or {}
            if b"unit" in meta:
                self.units[fld.name] = meta[b"unit"].decode()


# ---------------------------------------------------------------------------
# Formats whose channels carry their own time base

class MdfFile(SignalFile):
    format = "mdf"

    def __init__(self, path):
        super().__init__(path)
        self.mdf = _read_with("mdf", path, lambda asammdf: asammdf.MDF(str(path)))
        masters = set()
        for gi, g in enumerate(self.mdf.groups):
            try:
                masters.add(g.channels[self.mdf.masters_db[gi]].name)
            except (KeyError, IndexError, AttributeError):
                pass
        self._names = [n for n in self.mdf.channels_db if n not in masters]

    def names(self):
        return self._names

    def get(self, name, where, time_name=None, time_scale=1.0):
        occ = self.mdf.channels_db.get(name)
        if not occ:
            raise self._missing(name, where)
        if len(occ) > 1:
            raise DataError(f"{self.path}: channel '{name}' ({where}) occurs in {len(occ)} groups; "
                            "rename it in the logger export")
        g, i = occ[0]
        msg = None
        with quiet_library("asammdf") as quiet:
            try:
                sig = self.mdf.get(name, group=g, index=i)
            except Exception as e:  # a damaged data block
                msg = f"{type(e).__name__}: {e}"
                quiet.fail()
        if msg is not None:
            raise DataError(f"{self.path}: cannot read channel '{name}' ({where}): {msg}")
        values = np.asarray(sig.samples)
        if values.dtype.kind not in "fiub":
            raise DataError(f"{self.path}: channel '{name}' ({where}) is not numeric")
        return Signal(np.asarray(sig.timestamps, dtype=float) * time_scale, values.astype(float),
                      sig.unit or None)


class TdmsSignals(SignalFile):
    format = "tdms"

    def __init__(self, path):
        super().__init__(path)
        self.tdms = _read_with("tdms", path, lambda nptdms: nptdms.TdmsFile.read(str(path)))
        self._by_full, self._by_name = {}, {}
        for grp in self.tdms.groups():
            for ch in grp.channels():
                self._by_full[f"{grp.name}/{ch.name}"] = ch
                self._by_name.setdefault(ch.name, []).append((grp, ch))

    def names(self):
        return list(self._by_full)

    def has(self, name):
        return name in self._by_full or name in self._by_name

    def _find(self, name, where):
        if name in self._by_full:
            grp_name = name.split("/", 1)[0]
            return self.tdms[grp_name], self._by_full[name]
        hits = self._by_name.get(name, [])
        if not hits:
            raise self._missing(name, where)
        if len(hits) > 1:
            raise DataError(f"{self.path}: channel '{name}' ({where}) is in several groups "
                            f"({', '.join(g.name for g, _ in hits)}); write it as 'group/channel'")
        return hits[0]

    def get(self, name, where, time_name=None, time_scale=1.0):
        grp, ch = self._find(name, where)
        try:
            with quiet_library("nptdms"):
                values = np.asarray(ch[:], dtype=float)
        except (ValueError, TypeError) as e:
            raise DataError(f"{self.path}: channel '{name}' ({where}) is not numeric: {e}") from None
        unit = ch.properties.get("unit_string") or None
        if time_name is not None:
            tname = time_name if "/" in time_name else f"{grp.name}/{time_name}"
            if tname not in self._by_full:
                raise DataError(f"{self.path}: no time channel '{time_name}' in group '{grp.name}' "
                                f"(for '{name}')")
            t = np.asarray(self._by_full[tname][:], dtype=float) * time_scale
        else:
            try:
                t = np.asarray(ch.time_track(), dtype=float)
            except (KeyError, ValueError):
                raise DataError(f"{self.path}: channel '{name}' has no waveform timing (wf_increment); "
                                "name its time channel in [channels] as time = { name = \"...\" }") from None
        if t.size != values.size:
            raise DataError(f"{self.path}: channel '{name}' has {values.size} values but its time has {t.size}")
        return Signal(t, values, unit)


__all__ = ["Signal", "CsvOptions", "open_signals", "file_format", "FORMATS", "FORMAT_NAMES"]
