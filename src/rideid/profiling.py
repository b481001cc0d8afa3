"""Where an identification's time goes: each stage's wall and CPU time (``rideid identify --profile``).

A stage is a function marked with :func:`stage` (a decorator) or a block in
``with timing("name"):``. Nothing is recorded unless a :class:`Profile` is
active (``with Profile() as prof: ...``): then each stage entered records
its wall time (``time.perf_counter``) and the process's CPU time
(``time.process_time``: every thread's user and system time, so a stage that
keeps both cores busy shows about twice its wall time), under its path in the
call tree (``"model choice/candidate damper_curves/polish"``). A stage entered
again inside itself (a recursion) is counted once, at the outer call.

The record is a flat table, one row per path: ``calls``, ``wall_s``,
``cpu_s`` (inclusive, children included) and ``self_wall_s`` (less the
stages inside it). Off, a stage costs one context-variable look-up.
"""

from __future__ import annotations

import contextvars
import functools
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("rideid_profile", default=None)
#: the stage path the current context is in (a context variable, so a thread that copies the context has its own)
_PATH: contextvars.ContextVar = contextvars.ContextVar("rideid_profile_path", default=())


@dataclass
class StageTime:
    """One path's totals: ``calls``, ``wall_s``, ``cpu_s`` (inclusive) and ``child_wall_s``."""

    calls: int = 0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    child_wall_s: float = 0.0

    @property
    def self_wall_s(self) -> float:
        return max(self.wall_s - self.child_wall_s, 0.0)


@dataclass
class Profile:
    """The stages' times of what runs while it is active (``with Profile() as prof``).

    Threads started inside inherit the active profile where the code copies the
    context (``contextvars.copy_context``, as :func:`rideid.model.batch.thread_map`
    does for the model choice's candidates): their stages then overlap in time,
    so the shares of stages run side by side may add up to more than the whole.
    Elsewhere a thread's time is counted in the stage that waits for it.
    """

    stages: dict = field(default_factory=dict)
    wall_s: float = 0.0
    cpu_s: float = 0.0
    _token: object = None
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _t0: tuple = (0.0, 0.0)

    def __enter__(self):
        self._token = _ACTIVE.set(self)
        self._t0 = (time.perf_counter(), time.process_time())
        return self

    def __exit__(self, *exc):
        self.wall_s += time.perf_counter() - self._t0[0]
        self.cpu_s += time.process_time() - self._t0[1]
        _ACTIVE.reset(self._token)
        return False

    def rows(self) -> list[dict]:
        """One dict per stage path, in the order first entered: ``stage`` (the path, '/'-joined), ``depth``,
        ``calls``, ``wall_s``, ``cpu_s``, ``self_wall_s``, ``share`` (of the profile's whole wall time)."""
        total = self.wall_s or sum(t.wall_s for p, t in self.stages.items() if len(p) == 1) or 1.0
        return [{"stage": "/".join(p), "depth": len(p) - 1, "calls": t.calls, "wall_s": t.wall_s,
                 "cpu_s": t.cpu_s, "self_wall_s": t.self_wall_s, "share": t.wall_s / total}
                for p, t in self.stages.items()]

    def table(self) -> str:
        """The rows as a fixed-width text table (the terminal's), the whole run's wall and CPU last."""
        lines = [f"{'stage':<52} {'calls':>5} {'wall s':>8} {'CPU s':>8} {'self s':>8} {'share':>6}"]
        for r in self.rows():
            name = "  " * r["depth"] + r["stage"].rsplit("/", 1)[-1]
            lines.append(f"{name[:52]:<52} {r['calls']:>5d} {r['wall_s']:>8.2f} {r['cpu_s']:>8.2f} "
                         f"{r['self_wall_s']:>8.2f} {100 * r['share']:>5.1f}%")
        lines.append(f"{'whole run':<52} {'':>5} {self.wall_s:>8.2f} {self.cpu_s:>8.2f}")
        return "\n".join(lines)

    def write_csv(self, path) -> None:
        """``profile.csv``: the rows, with a last row ``total`` for the whole run."""
        keys = ("stage", "depth", "calls", "wall_s", "cpu_s", "self_wall_s", "share")
        out = [",".join(keys)]
        for r in self.rows() + [{"stage": "total", "depth": 0, "calls": 1, "wall_s": self.wall_s,
                                 "cpu_s": self.cpu_s, "self_wall_s": self.wall_s, "share": 1.0}]:
            out.append(",".join(f"{r[k]:.6g}" if isinstance(r[k], float) else str(r[k]) for k in keys))
        with open(path, "w") as f:
            f.write("\n".join(out) + "\n")


@contextmanager
def timing(name: str):
    """Record the block as stage ``name`` in the active :class:`Profile` (nothing when none is)."""
    prof = _ACTIVE.get()
    parent = _PATH.get()
    if prof is None or name in parent:  # off, or a recursion: counted at the outer call
        yield
        return
    path = parent + (name,)
    with prof._lock:
        rec = prof.stages.setdefault(path, StageTime())  # entered now: the rows come in the order first entered
    token = _PATH.set(path)
    w0, c0 = time.perf_counter(), time.process_time()
    try:
        yield
    finally:
        dw, dc = time.perf_counter() - w0, time.process_time() - c0
        with prof._lock:  # stages may end on several threads at once
            rec.calls += 1
            rec.wall_s += dw
            rec.cpu_s += dc
            if parent:
                prof.stages.setdefault(parent, StageTime()).child_wall_s += dw
        _PATH.reset(token)


def stage(name: str):
    """Decorator: every call of the function is stage ``name`` (:func:`timing`)."""
    def deco(fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            if _ACTIVE.get() is None:
                return fn(*args, **kwargs)
            with timing(name):
                return fn(*args, **kwargs)
        return wrapper
    return deco
