"""Compiled, batched simulation-and-cost kernel.

The same exact discretisation as :func:`rideid.model.simulate.simulate_reference`
(see :mod:`rideid.model.discretize`), compiled with Numba and laid out for speed:

* :data:`LANES` candidates are integrated side by side, one per lane of a
  ``<4 x double>`` vector (the inner loop is written as LLVM IR by
  :mod:`rideid.model.kernel_ir`): states live in registers, coefficients
  are single vector loads from one lane-innermost block
  (:mod:`rideid.model.kernel_layout`), and every multiply-add is one AVX2
  fused multiply-add (checked on the generated assembly by ``make bench``);
* chunks of candidates are shared among threads (the compiled function
  releases the GIL; thread count = ``numba.get_num_threads()``);
* the model is integrated as its symmetric (8 states, 2 inputs) and
  antisymmetric (6 states, 2 inputs) blocks; with a powertrain on mounts
  (SPEC §11) the symmetric block has 12 states, integrated by a second
  specialisation of the same IR (:func:`rideid.model.kernel_ir.generate_ir`
  with ``ns=12``, chosen by the initial states' count);
* road inputs enter through precomputed, parameter-independent moments;
  with tire damping the states are shifted (``xi = x - Br u``, see
  :mod:`rideid.model.discretize`) and the input rates enter the
  accelerations at the samples only (``Dr u'``);
* squared errors are accumulated on the fly: memory per candidate is
  O(states), never O(samples).

Multiply-adds per sample and candidate, with ``N`` moment terms:
state update ``8*8 + 6*6 = 100``, inputs ``(8*2 + 6*2) N = 28 N``,
accelerations ``4*8 + 3*6 + (4 + 3)*2*2 = 78`` (with the rate feedthrough),
channels 12, errors 20: ``210 + 28 N``. With a powertrain (12 symmetric
states): ``12*12 + 6*6 = 180``, ``(12*2 + 6*2) N = 36 N``, ``4*12 + 3*6 +
28 = 94``, 12 and 20: ``306 + 36 N``.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from .kernel_ir import run_chunks
from .kernel_layout import LANES, LAYOUTS, N_COEF, N_MAX_K, n_coef

#: Candidates per chunk (the kernel pads a population to whole chunks).
CHUNK = LANES

__all__ = ["CHUNK", "LANES", "N_MAX_K", "N_COEF", "pack_coefficients", "run_kernel", "vectorised"]


def compiled_kernel():
    """The compiled linear kernel (:func:`rideid.model.kernel_ir.run_chunks`), built for its signature once."""
    fn = run_chunks
    if not fn.signatures:
        fn.compile(_SIGNATURE)
        fn.disable_compile()  # any other argument types are a bug
    return fn


_SIGNATURE = ("(int64, int64, float64[::1], int64, int64[:, ::1], float64, float64, float64[:, :, ::1], "
              "int64[::1], int64[::1], float64[:, ::1], float64[:, ::1], float64[:, :, ::1], float64[:, ::1], "
              "float64[:, ::1], int64, float64[:, ::1], float64[:, :, ::1])")


def pack_coefficients(blocks: dict, n: int) -> np.ndarray:
    """Lane-innermost coefficient blocks for the kernel.

    Parameters
    ----------
    blocks : dict
        Per sample-rate group ``g`` lists of arrays with the candidate axis
        first: ``blocks[name][g]`` of shape ``(n, *shape)`` for the fixed
        blocks of :func:`rideid.model.kernel_layout.fixed_blocks` and
        ``(N, n, *shape)`` for ``G_s``/``G_a`` (``N <= N_MAX_K`` terms). The symmetric block's size
        (8, or 12 with a powertrain) is read off ``Phi_s`` and sets the layout
        (:data:`rideid.model.kernel_layout.LAYOUTS`).
    n : int
        Candidates, a multiple of :data:`LANES`.

    Returns
    -------
    CO : (n_groups * n_chunks * n_coef(ns) * LANES,) float64
    """
    n_groups = len(blocks["Phi_s"])
    n_chunks = n // LANES
    ns = blocks["Phi_s"][0].shape[-1]
    offsets, _, per_term = LAYOUTS[ns]
    co = np.zeros((n_groups, n, n_coef(ns)))
    for name, (off, shape) in offsets.items():
        size = int(np.prod(shape, dtype=int))
        for g in range(n_groups):
            arr = blocks[name][g]
            if name in ("G_s", "G_a"):
                nt = arr.shape[0]
                # (N, n, ...) -> (n, N, size) into the per-term slots
                v = np.moveaxis(arr.reshape(nt, n, size), 0, 1)
                idx = off + per_term * np.arange(nt)[:, None] + np.arange(size)[None, :]
                co[g][:, idx] = v
            else:
                co[g, :, off:off + size] = arr.reshape(n, size)
    # (g, n, C) -> (g, chunk, C, lane)
    co = co.reshape(n_groups, n_chunks, LANES, n_coef(ns)).transpose(0, 1, 3, 2)
    return np.ascontiguousarray(co).ravel()


_POOL: ThreadPoolExecutor | None = None


def thread_pool(threads: int) -> ThreadPoolExecutor:
    """The kernels' shared pool of at least ``threads`` threads (grown, never shrunk)."""
    global _POOL
    if _POOL is None or _POOL._max_workers < threads:
        _POOL = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="rideid-kernel")
    return _POOL


def run_kernel(CO, nterms, hf, hr, X0, run_start, run_group, UD, RD, MU, Y, W, mode, OUT):
    """Simulate all runs for all candidates; per-run weighted squared errors ``(n_runs, n)``.

    Shapes (``n`` candidates, a multiple of :data:`LANES`; ``g`` sample-rate
    groups, ``r`` runs, ``T`` samples over all runs): CO from
    :func:`pack_coefficients`, nterms (g, n_chunks) int, X0 (r, 14, n)
    initial shifted states (symmetric block then antisymmetric; (r, 18, n) with a powertrain, whose
    12-state symmetric block the coefficients must then hold), run_start
    (r + 1,), run_group (r,), UD/RD (T, 4) inputs and their rates, MU (T, 4,
    M) input moments, Y (T, 10), W (r, 10) channel weights (0 for a missing
    channel). mode 1 also writes the simulated channels into OUT (T, 10, n).
    """
    fn = compiled_kernel()
    n = X0.shape[2]
    n_chunks = n // LANES
    err = np.zeros((run_group.size, n))
    args = (CO, n_chunks, nterms, float(hf), float(hr), X0, run_start, run_group, UD, RD, MU, Y, W, int(mode),
            err, OUT)
    threads = max(1, min(numba.get_num_threads(), n_chunks))
    if threads == 1:
        fn(0, n_chunks, *args)
        return err
    bounds = np.linspace(0, n_chunks, threads + 1).round().astype(int)
    futures = [thread_pool(threads).submit(fn, int(a), int(b), *args) for a, b in zip(bounds[:-1], bounds[1:])]
    for f in futures:
        f.result()
    return err


def vectorised() -> dict:
    """Counts of packed (AVX) and scalar fused multiply-adds in the compiled kernel.

    Only available when this process compiled the kernel (Numba does not keep
    the assembly of cached code); ``{}`` otherwise.
    """
    import re
    import warnings

    fn = compiled_kernel()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        asm = fn.inspect_asm(fn.signatures[0])
    if not asm or "vfmadd" not in asm and "mulsd" not in asm:
        return {}
    return {"packed": len(re.findall(r"\bvfmadd\d+pd\b", asm)), "scalar": len(re.findall(r"\bvfmadd\d+sd\b", asm))}
