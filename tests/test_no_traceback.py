"""Never a traceback: every help text, damaged files, and a property-based fuzz of datasets (Hypothesis).

Every outcome of ``rideid identify`` on a mutated dataset must be exit 0
(a result written) or exit 2 with exactly one ``rideid: error:`` line and
nothing written: never exit 1 (a bug), never a hang.
"""

import contextlib
import io
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rideid
from rideid.cli import _parser, main

sys.path.insert(0, str(Path(__file__).parent))
from logger_files import WRITERS, channel_map, logger_channels, simulate_raw  # noqa: E402

SUBCOMMANDS = sorted(_parser()._subparsers._group_actions[0].choices)


def test_top_level_help_works_as_a_newcomer_types_it():
    p = subprocess.run([sys.executable, "-m", "rideid", "--help"], capture_output=True, text=True)
    assert p.returncode == 0 and p.stderr == ""
    assert "usage: rideid" in p.stdout and all(c in p.stdout for c in SUBCOMMANDS)


@pytest.mark.parametrize("command", SUBCOMMANDS)
def test_every_subcommand_help(command, capsys):
    with pytest.raises(SystemExit) as e:
        main([command, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr()
    assert out.out.startswith(f"usage: rideid {command}") and "example:" in out.out and out.err == ""


# ---------------------------------------------------------------------------
# A small dataset in every format

FORMATS = ("csv", "mf4", "tdms", "parquet")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """One short washboard run (built-in car, 200 Hz logger, gravity in g) in each format."""
    sc = rideid.default_scenario()
    t, Y = simulate_raw(sc, offset=1.2, fs=1000.0, runs={"W_H"})["W_H"]
    root = tmp_path_factory.mktemp("fuzzbase")
    run = sc.run("W_H")
    for fmt in FORMATS:
        d = root / fmt
        (d / "runs").mkdir(parents=True)
        WRITERS[fmt](d / "runs" / f"W_H.{fmt}", logger_channels(t, Y, True, offset=1.2))
        cmap = channel_map()
        if fmt in ("csv", "parquet"):
            cmap["time"] = {"name": "Time", "unit": "s"}
        doc = {"name": "fuzz", "vehicle": {k: getattr(sc.geometry, k) for k in
                                           ("wheelbase", "track_front", "track_rear", "tire_radius")},
               "known": dict(sc.known), "channels": cmap, "preprocess": {"gravity_included": True},
               "tracks": [sc.tracks["washboard"].to_table()],
               "runs": [{"id": "W_H", "track": "washboard", "speed": run.speed, "file": f"runs/W_H.{fmt}"}]}
        (d / "dataset.toml").write_text(tomli_w.dumps(doc))
    return root


def run_cli(path, out, timeout=120):
    """``rideid identify`` (one short generation) in-process; returns (exit code, stderr lines)."""
    err = io.StringIO()

    def hang(signum, frame):
        raise AssertionError(f"rideid identify did not finish within {timeout} s (a hang)")
    old = signal.signal(signal.SIGALRM, hang)
    signal.alarm(timeout)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            code = main(["identify", str(path), "--out", str(out), "--quiet", "--generations", "1",
                         "--population", "4", "--no-polish", "--no-report"])
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    return code, err.getvalue().splitlines()


def assert_clean_outcome(code, lines, out):
    errors = [ln for ln in lines if not ln.startswith("rideid: warning:")]
    assert code in (0, 2), "\n".join(lines)
    if code == 0:
        assert (out / "result.json").is_file() and errors == []
    else:
        assert len(errors) == 1 and errors[0].startswith("rideid: error: "), "\n".join(lines)
        assert not out.exists()


def test_the_unmutated_base_identifies_in_every_format(base, tmp_path):
    for fmt in FORMATS:
        code, lines = run_cli(base / fmt, tmp_path / fmt)
        assert code == 0, lines


@pytest.mark.parametrize("fmt", ["mf4", "tdms", "parquet"])
def test_a_truncated_file_is_one_line(fmt, base, tmp_path):
    """The reader's own complaints (logging, warnings, a traceback from a destructor) stay silent."""
    d = tmp_path / "ds"
    shutil.copytree(base / fmt, d)
    f = d / "runs" / f"W_H.{fmt}"
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 3])
    p = subprocess.run([sys.executable, "-m", "rideid", "identify", str(d), "--out", str(tmp_path / "out"),
                        "--quiet"], capture_output=True, text=True)
    assert p.returncode == 2, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if not ln.startswith("rideid: warning:")]
    assert len(lines) == 1 and lines[0].startswith(f"rideid: error: {f}"), p.stderr
    assert "Traceback" not in p.stderr and not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------
# The fuzz

#: manifest places a user edits, as key paths into the TOML document
PLACES = [
    ("vehicle", "wheelbase"), ("vehicle", "track_front"), ("vehicle", "tire_radius"), ("known", "total_mass"),
    ("known", "k_sf"), ("bounds", "k_sf"), ("tracks", 0, "start"), ("tracks", 0, "amplitude"),
    ("tracks", 0, "wavelength"), ("tracks", 0, "cycles"), ("tracks", 0, "kind"), ("runs", 0, "speed"),
    ("runs", 0, "track"), ("runs", 0, "file"), ("runs", 0, "start"), ("runs", 0, "window"),
    ("runs", 0, "lead_in"), ("runs", 0, "pre_roll"), ("preprocess", "fs"), ("preprocess", "lead_in"),
    ("preprocess", "gravity_included"), ("preprocess", "remove_bias"), ("channels", "body_az_fl"),
    ("channels", "roll_rate", "unit"), ("channels", "pitch_rate", "sign"), ("channels", "axle_az_rr", "scale"),
    ("channels", "time"), ("channels", "speed"), ("checks", "wiring"), ("csv", "decimal"), ("name",),
    ("unknown_key",), ("runs", 0, "unknown_key"),
]
VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**20, 10**20),
    st.sampled_from([0, -1, 1e308, -3.0, 1e-300, 0.5, 2.0, 200.0, 1e6]),
    st.text(max_size=12), st.booleans(), st.lists(st.floats(-1e3, 1e3), max_size=3),
    st.sampled_from(["auto", "g", "deg/s", "rad/s", "km/h", "washboard", "warn", "off", "AccZ_Body_FR",
                     "runs/W_H.csv", "runs/missing.mf4", ";", ","]),
    st.dictionaries(st.sampled_from(["name", "unit", "sign", "scale", "x"]),
                    st.one_of(st.text(max_size=6), st.floats(-10, 10), st.integers(-2, 2)), max_size=3),
    st.just(None),  # None: delete the key
)
FILE_EDITS = st.one_of(
    st.just(None),
    st.tuples(st.just("truncate"), st.floats(0.0, 1.0)),
    st.tuples(st.just("bytes"), st.floats(0.0, 1.0), st.binary(min_size=1, max_size=8)),
)


def _set(doc, path, value):
    node = doc
    for k in path[:-1]:
        if isinstance(k, int):
            node = node[k] if isinstance(node, list) and k < len(node) else None
        else:
            node = node.setdefault(k, {}) if isinstance(node, dict) else None
        if node is None:
            return
    last = path[-1]
    if isinstance(node, dict):
        if value is None:
            node.pop(last, None)
        else:
            node[last] = value


def _fuzz_one(base, fmt, edits, file_edit):
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp) / "ds"
        shutil.copytree(base / fmt, d)
        doc = tomllib.loads((d / "dataset.toml").read_text())
        for path, value in edits:
            _set(doc, path, value)
        try:
            (d / "dataset.toml").write_text(tomli_w.dumps(doc))
        except (TypeError, ValueError):  # a value TOML cannot hold: write it as text, broken on purpose
            (d / "dataset.toml").write_text(f"broken = {edits!r}\n")
        f = d / "runs" / f"W_H.{fmt}"
        if file_edit is not None:
            data = bytearray(f.read_bytes())
            if file_edit[0] == "truncate":
                data = data[: int(len(data) * file_edit[1])]
            else:
                k = int((len(data) - 1) * file_edit[1])
                data[k:k + len(file_edit[2])] = file_edit[2]
            f.write_bytes(bytes(data))
        out = Path(tmp) / "out"
        code, lines = run_cli(d, out)
        assert_clean_outcome(code, lines, out)


FUZZ = dict(fmt=st.sampled_from(FORMATS), edits=st.lists(st.tuples(st.sampled_from(PLACES), VALUES), max_size=3),
            file_edit=FILE_EDITS)


@settings(max_examples=int(os.environ.get("RIDEID_FUZZ_EXAMPLES", "6")), deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(**FUZZ)
def test_fuzz_short(base, fmt, edits, file_edit):
    _fuzz_one(base, fmt, edits, file_edit)


@pytest.mark.slow
@pytest.mark.expensive
@settings(max_examples=150, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(**FUZZ)
def test_fuzz_long(base, fmt, edits, file_edit):
    _fuzz_one(base, fmt, edits, file_edit)


# ---------------------------------------------------------------------------
# One NaN policy for every format: a NaN value is an error naming file and channel; "not sampled" is not a NaN

@pytest.mark.parametrize("fmt", FORMATS)
def test_a_nan_value_is_an_error_in_every_format(fmt, tmp_path):
    sc = rideid.default_scenario()
    t, Y = simulate_raw(sc, offset=1.2, fs=200.0, runs={"W_H"})["W_H"]
    chans = logger_channels(t, Y, True, offset=1.2)
    tt, v, u = chans["AccZ_Hub_FL"]
    v = v.copy()
    v[300] = np.nan  # at t = 1.5 s
    chans["AccZ_Hub_FL"] = (tt, v, u)
    from rideid.data.readers import open_signals
    f = tmp_path / f"W_H.{fmt}"
    WRITERS[fmt](f, chans)
    if fmt == "csv":  # the test writer leaves NaN cells empty: a logger writes the text
        lines = f.read_text().splitlines()
        j = lines[0].split(";").index("AccZ_Hub_FL")
        k = next(i for i, ln in enumerate(lines[2:], 2) if ln.split(";")[0] == f"{tt[300]:.10g}".replace(".", ","))
        cells = lines[k].split(";")
        cells[j] = "NaN"
        lines[k] = ";".join(cells)
        f.write_text("\n".join(lines) + "\n")
    if fmt == "parquet":  # the test writer turns NaN into a null: write a NaN value
        import pyarrow as pa
        import pyarrow.parquet as pq
        tab = pq.read_table(f)
        i = tab.schema.get_field_index("AccZ_Hub_FL")
        col = tab.column(i).to_numpy(zero_copy_only=False).copy()
        k = int(np.searchsorted(tab.column(0).to_numpy(), tt[300]))
        col[k] = np.nan
        tab = tab.set_column(i, tab.schema.field(i), pa.array(col, from_pandas=False))
        pq.write_table(tab, f)
    sf = open_signals(f)
    kw = {"time_name": "Time"} if fmt in ("csv", "parquet") else {}
    from rideid.errors import DataError
    if fmt in ("csv", "parquet"):  # the reader names the row
        with pytest.raises(DataError, match=r"column 'AccZ_Hub_FL' \(m\): NaN at (line|data row) \d+; "
                                            r"a sample must be a number"):
            sf.get("AccZ_Hub_FL", "m", **kw)
    else:  # the values reach rideid, which names the time
        from rideid.data.measured import load_measured_run  # the check lives there
        assert callable(load_measured_run)
        s = sf.get("AccZ_Hub_FL", "m", **kw)
        assert np.isnan(s.values[300])
    # the other channels read, and an empty cell / null (not sampled) is not a NaN: the gyro at 100 Hz
    g = sf.get("Gyro_X", "m", **kw)
    assert np.all(np.isfinite(g.values))


def test_a_time_column_in_ms_read_as_seconds_names_the_time_base(tmp_path, capsys):
    """A logger CSV whose time column is in ms while the map says s: the channels' rate comes out 0.2 Hz. One
    line names the file, the time column and the unit that fits, exit 2, nothing written (before, the lead-in
    check failed on '0 .. 10000 s' without naming the time base)."""
    from logger_case import suv_scenario, write_logger
    sc = suv_scenario(tmp_path / "sc")
    ds = write_logger(sc, tmp_path / "ds", noise=0.01, seed=1)
    for f in (ds / "runs").glob("*.csv"):
        head, *rows = f.read_text().splitlines()
        f.write_text("\n".join([head] + [",".join([f"{float(r.split(',')[0]) * 1000:.6f}"] + r.split(",")[1:])
                                          for r in rows]) + "\n")
    rc = main(["identify", str(ds), "--out", str(tmp_path / "fit"), "--quiet"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "Traceback" not in err
    assert "time column 'Time_s'" in err and "0.2 Hz" in err and 'unit = "ms"' in err, err
    assert not (tmp_path / "fit").exists()
