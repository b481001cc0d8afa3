"""rideid.profiling: stage times recorded only while a Profile is active, nested by path, recursion counted once."""

from __future__ import annotations

import csv
import time

import pytest

from rideid.profiling import Profile, stage, timing


def _busy(seconds: float) -> None:
    """Burn CPU for ``seconds`` of wall time (so the CPU time is about the wall time on one thread)."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        pass


@stage("inner")
def _inner(seconds):
    _busy(seconds)


@stage("outer")
def _outer(depth: int = 0):
    _busy(0.02)
    _inner(0.03)
    if depth < 2:  # a recursion: counted once, at the outer call
        _outer(depth + 1)


def test_stages_nest_by_path_and_add_up(tmp_path):
    with Profile() as prof:
        _outer()
        with timing("tail"):
            _busy(0.01)
    rows = {r["stage"]: r for r in prof.rows()}
    assert list(rows) == ["outer", "outer/inner", "tail"]  # the order first entered
    assert rows["outer"]["calls"] == 1  # the two recursive calls are inside the outer one
    assert rows["outer/inner"]["calls"] == 3
    assert rows["outer/inner"]["depth"] == 1
    # inclusive >= self; the outer stage's self time is its own busy loops (3 x 0.02 s), the inner's 3 x 0.03 s
    assert rows["outer"]["wall_s"] == pytest.approx(rows["outer/inner"]["wall_s"] + rows["outer"]["self_wall_s"])
    assert rows["outer/inner"]["wall_s"] >= 0.09
    assert rows["outer"]["self_wall_s"] >= 0.06
    assert 0.0 < rows["tail"]["share"] < rows["outer"]["share"] < 1.0
    assert prof.wall_s >= rows["outer"]["wall_s"] + rows["tail"]["wall_s"]
    assert prof.cpu_s > 0.0
    prof.write_csv(tmp_path / "profile.csv")
    with open(tmp_path / "profile.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [r["stage"] for r in table] == ["outer", "outer/inner", "tail", "total"]
    assert float(table[-1]["wall_s"]) == pytest.approx(prof.wall_s, rel=1e-5)
    assert "outer" in prof.table() and "whole run" in prof.table()


def test_nothing_is_recorded_without_an_active_profile():
    assert _outer() is None  # runs as the plain function
    with Profile() as prof:
        pass
    _outer()
    assert prof.stages == {}


def test_stages_on_the_candidates_threads_are_counted_under_the_caller(monkeypatch):
    """rideid.model.batch.thread_map runs each item in a copy of the caller's context: the stages on its threads
    are recorded under the stage that started them (the model choice's candidates)."""
    from rideid.model import backend, batch

    monkeypatch.setattr(backend, "threads", lambda: 2)
    with Profile() as prof:
        with timing("model choice"):
            batch.thread_map(lambda s: _inner(s), [0.02, 0.02, 0.02])
    rows = {r["stage"]: r for r in prof.rows()}
    assert rows["model choice/inner"]["calls"] == 3
    assert rows["model choice/inner"]["wall_s"] >= 0.06  # three calls of 0.02 s, on two threads

