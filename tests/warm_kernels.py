"""Compile the Numba kernels the tests use into their on-disk caches, once, before the test workers need them.

On a fresh clone every test worker otherwise compiles each kernel itself (rideid's linear, contact and nonlinear
kernels, 2, 2 and 8 s; this folder's independent simulator of a powertrain car with damper curves, 5 s): the
workers start at the same time, find no cache and each pays them all. ``tests/conftest.py`` starts this module in
two processes (``python tests/warm_kernels.py nonlinear`` and ``... linear contact simulator``) when pytest starts
its workers, while they collect the tests; a worker that needs a kernel before its process has written it
compiles it as before. Nothing here is asserted: the tests that use the kernels check them.
"""

import sys
from pathlib import Path


def warm(name: str) -> None:
    if name == "simulator":  # tests/nl_powertrain_car.py's RK4 loop, on a two-sample record
        import numpy as np

        import nl_powertrain_car as car
        c, xk, Fk = np.zeros(41), np.array([-1.0, 0.0, 1.0]), np.zeros((2, 3))
        c[[0, 1, 2, 5, 6, 31, 32, 33, 34]] = 1.0
        car._integrate(c, xk, Fk, np.zeros((3, 4)), np.zeros((3, 4)), 2, 1, 0.01)
        return
    from rideid.model import backend
    backend.compiled_available(name)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).parent))
    for arg in sys.argv[1:]:
        warm(arg)
