"""Which simulation backend runs: the compiled kernels or the plain NumPy references.

``RIDEID_KERNEL=numpy`` selects the NumPy reference backends of the linear
(:class:`rideid.model.batch.BatchSimulator`) and the nonlinear
(:class:`rideid.model.nonlinear.NonlinearSimulator`) simulators; unset (or
``compiled``) the compiled kernels. If a compiled kernel cannot be built
(any exception while compiling or loading it), the NumPy backend is used
instead, with one warning per process.
"""

from __future__ import annotations

import os
import warnings

from ..errors import DataError
from .kernel import compiled_kernel
from .kernel_nl import compile_kernel

#: environment variable naming the backend
ENV = "RIDEID_KERNEL"
CHOICES = ("compiled", "numpy")

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


def _builders():
    def linear():
        compiled_kernel()

    def nonlinear():
        compile_kernel()

    return {"linear": linear, "nonlinear": nonlinear}


def compiled_available(name: str) -> bool:
    """Build the compiled kernel ``name`` ("linear", "nonlinear") once; False (and one warning) if that fails."""
    global _WARNED
    if name not in _STATUS:
        try:
            _builders()[name]()
            _STATUS[name] = True
        except Exception as exc:  # noqa: BLE001 - any failure to build means: use NumPy
            _STATUS[name] = False
            if not _WARNED:
                _WARNED = True
                warnings.warn(f"rideid: the compiled {name} kernel could not be built ({type(exc).__name__}: {exc}); "
                              f"using the NumPy backend (slower)", RuntimeWarning, stacklevel=3)
    return _STATUS[name]
