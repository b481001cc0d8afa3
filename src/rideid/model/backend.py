"""Which simulation backend runs: the compiled kernels or the plain NumPy references.

This module alone imports the compiled kernels (Numba, and the LLVM IR of
:mod:`rideid.model.kernel_ir`): :mod:`rideid.model.kernel` (the linear car),
:mod:`rideid.model.kernel_nl` (the nonlinear car) and
:mod:`rideid.model.kernel_contact` (the disc envelope's lattice search),
each when a compiled evaluation first asks for it. Nothing else in rideid
imports Numba at the top, so loading a dataset, building a cost function and
identifying work with the NumPy backends on a machine where the compiled
kernels cannot be imported (a Numba that moved an internal, a platform
without it).

``RIDEID_KERNEL=numpy`` selects the NumPy reference backends of the linear
(:class:`rideid.model.batch.BatchSimulator`) and the nonlinear
(:class:`rideid.model.nonlinear.NonlinearSimulator`) simulators; unset (or
``compiled``) the compiled kernels (a :class:`rideid.model.simulator.Simulator`
value may name its backend instead). If a compiled kernel cannot be imported
or built (any exception), the NumPy backend is used instead, with one
warning per process.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from importlib import import_module

from ..errors import DataError

#: environment variable naming the backend
ENV = "RIDEID_KERNEL"
CHOICES = ("compiled", "numpy")

#: compiled kernel name -> (its module, relative to this package, and the function that builds it)
KERNELS = {"linear": ("kernel", "compiled_kernel"), "nonlinear": ("kernel_nl", "compile_kernel"),
           "contact": ("kernel_contact", "compile_kernel")}

#: compiled kernel name -> its Numba dispatcher in the module (whose cache statistics tell a compile from a load)
DISPATCHERS = {"linear": "run_chunks", "nonlinear": "run_chunks", "contact": "lattice_max"}

_STATUS: dict[str, bool] = {}
_WARNED = False


def use_numpy() -> bool:
    """``RIDEID_KERNEL=numpy`` is set (read at every call, so it can be changed at run time)."""
    v = os.environ.get(ENV, "").strip().lower()
    if v in ("", "compiled", "numba"):
        return False
    if v == "numpy":
        return True
    raise DataError(f"{ENV}={os.environ.get(ENV)!r}: expected one of {', '.join(CHOICES)}")


def runs_numpy(name: str, numpy: bool | None = None) -> bool:
    """The NumPy backend runs for the kernel ``name``: asked for (``numpy`` True; None: as ``RIDEID_KERNEL``
    says, :func:`use_numpy`), or the compiled kernel cannot be built (:func:`compiled_available`)."""
    wanted = use_numpy() if numpy is None else bool(numpy)
    return wanted or not compiled_available(name)


def module(name: str):
    """The compiled kernel ``name``'s module (:data:`KERNELS`), imported on first use."""
    return import_module(f"{__package__}.{KERNELS[name][0]}")


def compiled_available(name: str) -> bool:
    """Import and build the compiled kernel ``name`` ("linear", "nonlinear", "contact") once; False (and one
    warning per process) if that fails."""
    global _WARNED
    if name not in _STATUS:
        try:
            mod = module(name)
            getattr(mod, KERNELS[name][1])()
            _STATUS[name] = True
        except Exception as exc:  # noqa: BLE001 - any failure to import or build means: use NumPy
            _STATUS[name] = False
            if not _WARNED:
                _WARNED = True
                warnings.warn(f"rideid: the compiled {name} kernel could not be built ({type(exc).__name__}: {exc}); "
                              f"using the NumPy backend (slower)", RuntimeWarning, stacklevel=3)
    return _STATUS[name]


def _numba():
    """Numba, or None where it cannot be imported."""
    try:
        import numba
    except Exception:  # noqa: BLE001 - no Numba: one thread per core, the NumPy backends
        return None
    return numba


def threads() -> int:
    """Threads the kernels (and the work that runs beside them) use: Numba's thread count, or the cores."""
    nb = _numba()
    return int(nb.get_num_threads()) if nb is not None else max(1, os.cpu_count() or 1)


@contextlib.contextmanager
def kernel_threads(n: int):
    """The kernels (Numba) on ``n`` threads in the calling thread (at most Numba's ``NUMBA_NUM_THREADS``), restored
    afterwards; nothing without Numba."""
    nb = _numba()
    if nb is None:
        yield
        return
    before = nb.get_num_threads()
    nb.set_num_threads(n)
    try:
        yield
    finally:
        nb.set_num_threads(before)


def one_thread():
    """The kernels (Numba) limited to one thread, restored afterwards (a study's worker process)."""
    return kernel_threads(1)


def compiled_cold(name: str) -> bool:
    """The compiled kernel ``name`` was compiled in this process: Numba's on-disk cache (``__pycache__``
    beside the kernel's module, or ``NUMBA_CACHE_DIR``) did not hold it (a fresh install, a changed kernel
    or Numba, a cache dir that is new). False when it was loaded from the cache, or not built."""
    if not _STATUS.get(name):
        return False
    stats = getattr(getattr(module(name), DISPATCHERS[name], None), "stats", None)
    return bool(stats is not None and sum(stats.cache_misses.values()))


def compile_kernels() -> float:
    """Compile (or load from Numba's on-disk cache) the kernels the default run needs; seconds spent compiling.

    The first call in a fresh install compiles (a few seconds); later
    processes load the cache (under a second, more on a loaded machine) and
    get 0.0: a load is not a compile, whatever it took (Numba's cache
    statistics tell them apart, :func:`compiled_cold`). The command line
    calls this first and says so when it compiled, rather than hiding it in
    the first generation. 0.0 with ``RIDEID_KERNEL=numpy``, and for kernels
    an earlier call built.
    """
    import time

    if use_numpy():
        return 0.0
    new = [n for n in ("linear", "contact") if n not in _STATUS]
    t = time.perf_counter()
    for name in new:
        compiled_available(name)
    dt = time.perf_counter() - t
    return dt if any(compiled_cold(n) for n in new) else 0.0


__all__ = ["CHOICES", "DISPATCHERS", "ENV", "KERNELS", "compile_kernels", "compiled_available", "compiled_cold",
           "kernel_threads", "module", "one_thread", "runs_numpy", "threads", "use_numpy"]
