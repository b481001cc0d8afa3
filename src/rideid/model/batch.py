"""Batched simulation of many candidate cars over many runs.

:class:`BatchSimulator` owns the parameter-independent data of a set of runs
(packed once) and evaluates a population ``P`` of shape ``(n_pop, 12)``,
``(n_pop, 16)`` (with the extensions of SPEC §6) or ``(n_pop, 23)`` (and the
powertrain of SPEC §11)
either to simulated channels or to per-run weighted squared errors, through
the compiled kernel (:mod:`rideid.kernel`) or the plain NumPy reference
(:func:`rideid.simulate.simulate_reference`; ``RIDEID_KERNEL=numpy``, see
:mod:`rideid.model.backend`). A population with a powertrain on mounts (a
symmetric block of 12 states, SPEC §11) runs the kernel's 12-state
specialisation; its NumPy backend is the modal recursion
(:meth:`BatchSimulator.outputs_modal`), the reference loop being too slow
for it. :class:`rideid.model.simulator.Simulator` binds this class or the
nonlinear car's :class:`rideid.model.nonlinear.NonlinearSimulator` by the
parameter layout.
"""

from __future__ import annotations

import contextlib
import threading

import numpy as np
from threadpoolctl import ThreadpoolController

from . import backend
from .kernel_layout import LANES, LAYOUTS
from .discretize import N_MAX, Discretized, n_terms, spectral_radius
from .equations import blocks as blocks_of
from .params import Geometry, column, has_powertrain
from .simulate import RunInput, initial_states, simulate_modal, simulate_reference


# The batched small-matrix work (expm, eig, solve) gains nothing from BLAS
# threads, and OpenBLAS threads keep spinning after each call, taking the
# cores from the compiled kernel's threads (measured: kernel 2x slower).
_BLAS = ThreadpoolController()
_BLAS_LOCK = threading.Lock()
_BLAS_STATE = {"depth": 0, "limiter": None}


@contextlib.contextmanager
def single_threaded_blas():
    """Context manager: BLAS limited to one thread, for as long as any thread is inside one.

    The limit is process-wide: with a plain limit per ``with``, the first of two threads to leave would
    give the second, still inside, multi-threaded BLAS again (and last-bit different sums). Counted: the
    first to enter sets it, the last to leave lifts it. Code that fits on threads holds it around them
    (the model choice): OpenBLAS switched from 2 threads to 1 and back from inside a worker thread gave
    polished parameters 1e-10 apart from the same fit on the main thread; held around, bit for bit
    (``tests/test_simulator.py``).
    """
    with _BLAS_LOCK:
        if _BLAS_STATE["depth"] == 0:
            _BLAS_STATE["limiter"] = _BLAS.limit(limits=1, user_api="blas")
        _BLAS_STATE["depth"] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS_STATE["depth"] -= 1
            if _BLAS_STATE["depth"] == 0:
                _BLAS_STATE["limiter"].restore_original_limits()
                _BLAS_STATE["limiter"] = None


def thread_map(fn, items, name: str = "rideid") -> list:
    """``[fn(x) for x in items]``, on as many threads as the kernel uses (:func:`rideid.model.backend.threads`).

    For work that spends its time in NumPy, LAPACK and compiled loops, which
    release the GIL. One thread (a study's workers): a plain loop.
    """
    items = list(items)
    threads = min(backend.threads(), len(items))
    if threads < 2:
        return [fn(x) for x in items]
    import contextvars
    from concurrent.futures import ThreadPoolExecutor
    # each item in a copy of the caller's context (the stage it is in: rideid.profiling), copied here on the
    # caller's thread, one copy per item since one context cannot be entered on two threads at once
    contexts = [contextvars.copy_context() for _ in items]
    with ThreadPoolExecutor(threads, thread_name_prefix=name) as ex:
        return list(ex.map(lambda ctx, x: ctx.run(fn, x), contexts, items))


def thread_map_rows(fn, P, name: str = "rideid") -> np.ndarray:
    """``fn(P)`` for a function whose every output row depends on its own row of ``P`` only: ``fn`` of
    consecutive slices of the rows, one per thread (:func:`thread_map`), concatenated. The same numbers as
    ``fn(P)``, row by row."""
    P = np.asarray(P)
    slices = np.array_split(np.arange(P.shape[0]), max(1, min(backend.threads(), P.shape[0])))
    return np.concatenate(thread_map(lambda rows: fn(P[rows]), slices, name))


class BatchSimulator:
    """Simulate populations of cars over fixed runs.

    Parameters
    ----------
    geom : Geometry
    runs : list of RunInput
    numpy : bool or None
        The NumPy reference (True), the compiled kernel (False), or as ``RIDEID_KERNEL`` says at each call
        (None, :mod:`rideid.model.backend`).

    Made by :meth:`rideid.model.simulator.Simulator.bind`; an evaluation never changes it. The ``pin``
    argument of the evaluations is the nonlinear car's (:class:`rideid.model.nonlinear.Pin`): the exact
    discretisation has no sub-steps, so it is accepted and has no effect.
    """

    def __init__(self, geom: Geometry, runs: list[RunInput], numpy: bool | None = None):
        self.numpy = numpy
        self.geom = geom
        self.runs = list(runs)
        hs = sorted({round(r.h, 15) for r in self.runs})
        self.h_groups = hs
        self.run_group = np.array([hs.index(round(r.h, 15)) for r in self.runs], dtype=np.int64)
        lens = np.array([r.n for r in self.runs])
        self.run_start = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        T = int(self.run_start[-1])
        self.UD = np.zeros((T, 4))
        self.RD = np.zeros((T, 4))
        self.MU = np.zeros((T, 4, N_MAX))
        # the runs' input moments side by side (a run read at a new start computes them: the quadrature is
        # nogil, and the polish with estimated starts reads its runs at every trial start)
        for r, s, mu in zip(self.runs, self.run_start[:-1], thread_map(lambda r: r.mu, self.runs, "moments")):
            self.UD[s:s + r.n] = r.ud
            self.RD[s:s + r.n] = r.rated
            self.MU[s:s + r.n - 1] = mu
        self.n_samples = T

    # -- packing -----------------------------------------------------------
    def _pack(self, P):
        P = np.atleast_2d(np.asarray(P, dtype=float))
        n = P.shape[0]
        n_chunks = n // LANES
        g = len(self.h_groups)
        nt = np.zeros((g, n_chunks), dtype=np.int64)
        bl = blocks_of(P, self.geom)
        ns = bl["As"].shape[-1]  # 8, or 12 with a powertrain
        blocks = {name: [] for name in LAYOUTS[ns][0]}
        discs = []
        radius = np.maximum(spectral_radius(bl["As"]), spectral_radius(bl["Aa"]))
        for gi, h in enumerate(self.h_groups):
            # one series length for the whole call, set by its fastest car: the truncation is then a
            # smooth function of the parameters within a call (finite-difference sensitivities through
            # this call never see one candidate with a term more than its neighbour)
            nt[gi] = n_terms(float(radius.max()) * h / 2)
            d = Discretized(P, self.geom, h, nterms=int(nt[gi].max()), blocks=bl)
            discs.append(d)
            for name in blocks.keys() - {"a", "b"}:
                blocks[name].append(getattr(d, name))
        a = column(P, "a")
        blocks["a"] = [a] * g
        blocks["b"] = [self.geom.wheelbase - a] * g
        CO = backend.module("linear").pack_coefficients(blocks, n)
        X0 = np.zeros((len(self.runs), ns + 6, n))
        for ri, r in enumerate(self.runs):
            xs, xa = initial_states(discs[self.run_group[ri]], r.ud[0])
            X0[ri, :ns], X0[ri, ns:] = xs.T, xa.T
        return CO, nt, X0

    def _call(self, P, Y, W, mode):
        P = np.atleast_2d(np.asarray(P, dtype=float))
        n0 = P.shape[0]
        pad = (-n0) % LANES  # the kernel works on whole chunks of LANES candidates: pad with copies
        if pad:
            P = np.vstack([P, np.repeat(P[-1:], pad, axis=0)])
        with single_threaded_blas():
            CO, nt, X0 = self._pack(P)
        n = P.shape[0]
        out = np.zeros((self.n_samples, 10, n) if mode == 1 else (1, 10, 1))
        err = backend.module("linear").run_kernel(CO, nt, self.geom.corner_y[0], self.geom.corner_y[2], X0,
                                self.run_start, self.run_group, self.UD, self.RD, self.MU, Y, W, mode, out)
        return err[:, :n0], (out[:, :, :n0] if mode == 1 else out)

    # -- public ------------------------------------------------------------
    def _use_numpy(self) -> bool:
        return backend.runs_numpy("linear", self.numpy)

    def errors(self, P, Y, W, pin=None):
        """Per-run weighted squared errors, shape ``(n_runs, n_pop)``.

        ``Y`` (n_samples, 10) stacks the measured channels of all runs
        (any value where a channel is missing), ``W`` (n_runs, 10) the channel
        weights (0 for a missing channel).
        """
        Y = np.ascontiguousarray(Y, dtype=float)
        W = np.ascontiguousarray(W, dtype=float)
        if self._use_numpy():
            if has_powertrain(P):
                return self._errors_of(self.outputs_modal(P), P, Y, W)
            return self.errors_reference(P, Y, W)
        err, _ = self._call(P, Y, W, 0)
        return err

    def outputs(self, P, pin=None):
        """Simulated channels: list over runs of ``(n_pop, n_time, 10)``."""
        if self._use_numpy():
            return self.outputs_modal(P) if has_powertrain(P) else self.outputs_reference(P)
        P = np.atleast_2d(P)
        Y = np.zeros((self.n_samples, 10))
        W = np.zeros((len(self.runs), 10))
        _, out = self._call(P, Y, W, 1)
        out = np.moveaxis(out, -1, 0)  # (n, T, 10)
        return [out[:, s:e] for s, e in zip(self.run_start[:-1], self.run_start[1:])]

    def outputs_reference(self, P, pin=None):
        """As :meth:`outputs`, by the plain NumPy reference (slow)."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        res = []
        for r in self.runs:
            res.append(simulate_reference(P, self.geom, r))
        return res

    def outputs_modal(self, P, pin=None):
        """As :meth:`outputs`, by the modal recursion of :func:`rideid.model.simulate.simulate_modal` (NumPy,
        any block size: the NumPy backend of a car with a powertrain on mounts, SPEC §11)."""
        P = np.atleast_2d(np.asarray(P, dtype=float))
        with single_threaded_blas():
            bl = blocks_of(P, self.geom)
            radius = np.maximum(spectral_radius(bl["As"]), spectral_radius(bl["Aa"]))
            discs = [Discretized(P, self.geom, h, nterms=n_terms(float(radius.max()) * h / 2), blocks=bl)
                     for h in self.h_groups]
            return [simulate_modal(P, self.geom, r, discs[g]) for r, g in zip(self.runs, self.run_group)]

    def errors_reference(self, P, Y, W, pin=None):
        return self._errors_of(self.outputs_reference(P), P, Y, W)

    def _errors_of(self, outs, P, Y, W):
        """Per-run weighted squared errors ``(n_runs, n_pop)`` of simulated channels ``outs`` (per run)."""
        err = np.empty((len(self.runs), np.atleast_2d(P).shape[0]))
        for ri, (s, e) in enumerate(zip(self.run_start[:-1], self.run_start[1:])):
            d = outs[ri] - Y[None, s:e]
            err[ri] = np.einsum("ntq,q->n", d * d, W[ri])
        return err

