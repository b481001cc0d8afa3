"""Compiled kernel of the nonlinear car (:mod:`rideid.model.nonlinear`): RK4 at ``m`` sub-steps per sample,
split at the kinks, four candidates side by side.

The same equations and the same scheme as the NumPy backend
(:func:`rideid.model.nonlinear.simulate_numpy`). Candidates are integrated
four at a time, one per lane of a ``<4 x double>`` vector, as the linear
kernel does (:mod:`rideid.model.kernel`): the sub-steps are LLVM IR
(:mod:`rideid.model.kernel_nl_ir`, which also holds the Numba driver
:func:`rideid.model.kernel_nl_ir.run_chunks`), every per-candidate
coefficient a vector load from the chunk's lane-innermost block
(:func:`pack`), the damper curves looked up branch-free from each lane's
last two segments (the knots scanned, one compare and select each, only
when a lane has left both). The driver loops over the chunks, runs,
samples and sub-steps, accumulates the squared errors on the fly (mode 0:
memory O(states) per candidate), writes the channels (mode 1), the states
(mode 2) or both (mode 3). Chunks of four candidates are shared among
``numba.get_num_threads()`` threads; the compiled function releases the
GIL. A population that is not a multiple of four is padded with copies of
its last candidate.

Each sub-step is a plain RK4 step; its end evaluation (which is the next
sub-step's first stage, so it costs nothing extra) also gives each corner's
kink count (the kinks at or below its damper velocity), bump-stop side and
tire-load sign. In the lanes where one differs from the sub-step's start
the driver finds the crossings (located on the cubic Hermite of the
switching quantity between the ends) and the step is redone in pieces
ending at them, each lane its own pieces, the vector running as many as
its busiest lane needs (a lane's surplus pieces have zero length and leave
it unchanged); the road inputs inside the sub-step are the cubic Hermite of
the tabulated ones. Every lane's numbers are its own: the same candidate
gives the same bits whatever its neighbours, their order and the thread
count. Against the scalar kernel before (one candidate at a time, kept as
``benchmarks/kernel_nl_before.py``) the outputs differ by rounding only
(3e-14 of the largest).

Measured (``benchmarks/bench_nonlinear.py --quick``: the built-in runs,
9470 samples at 200 Hz, m = 2, 64 candidates with digressive curves; one
thread, CPU time, on a shared 2-core machine under a load average of
3-4): ``NonlinearSimulator.errors`` 267-357 ns per candidate-sample against
``BatchSimulator.errors``' 41-43 on the same runs, 6.5-8.2x (the scalar
kernel: 24x; the linear kernel has become faster since the 50-65 ns and
4.7-5.7x measured with this kernel first); the compiled kernels alone
5.3-9.1x. The ratio is bounded by the work, not the lanes: RK4 at two
sub-steps is eight right-hand sides per sample, each 144 vector arithmetic
operations on its hot path (kinematics, spring, bar, damper segment check
and line, bump stop, tire contact and lift-off, moments: about 35 per
corner), 138 per sub-step to combine the stages; measured, the plain
sub-steps cost 158 ns per candidate-sample (3.9x the linear kernel), and
the splitting 135 more: 23 % of the vector sub-steps have a lane crossing a
kink (1.4 crossings on average), each such sub-step costing its trial, one
RK4 step per piece and the crossings' search. One sub-step per sample
would cost 77 ns plain, 196 split, but gives 4e-4 - 8e-4 of RMS on the
built-in runs (two: 3e-5 - 1.2e-4) against the 1e-4 the accuracy tests
hold. An exponential integrator over the candidate's linear car (only the
curve's residual, the bump stops and the lift-off integrated numerically)
does not meet it either: 1e-3 - 1.7e-2 at one step per sample (ETDRK4 or
Lawson RK4, ``benchmarks/study_expint.py``; ``docs/dampers.md``), the
residual's kinks unsplit; with every corner's region frozen over the step and
each crossing's missed force added in closed form (``study_expint.py
--crossings``), 7.3e-5 - 3.7e-4, at about 4x the linear kernel's arithmetic
before any crossing (counted, not compiled). Cold compile (fresh install, empty Numba cache):
about 9 s of CPU.

A car with a powertrain on mounts (SPEC §11) runs a second specialisation
of the same IR with 18 states (:data:`rideid.model.kernel_nl_ir.NX`; its
functions' names suffixed :data:`rideid.model.kernel_nl_ir.PT`, its
coefficients :data:`rideid.model.kernel_nl_ir.ENTRIES_PT`), chosen per call
by the initial states' width; the 14-state functions are generated as
before. Measured on 64 cars with curves and stops, three sub-steps, one
thread: 369 ns per candidate-sample with the engine, 388 without
(docs/powertrain.md).
"""

from __future__ import annotations

import numba
import numpy as np

from .nl_coef import CI
from .kernel import thread_pool
from . import kernel_nl_ir as kir
from .kernel_nl_ir import LANES, hermite_value_slope, run_chunks

__all__ = ["compile_kernel", "hermite_value_slope", "pack", "run"]


def pack(co, xk, Fk, Sk, curves, kinks, pt=False):
    """The kernel's per-chunk tables from :func:`rideid.model.nonlinear.coefficients`'s ``co, xk, Fk, Sk``.

    Returns
    -------
    CF : (n_chunks, len(ENTRIES) * LANES) coefficients, lane innermost (``pt``: a powertrain's too,
    :data:`rideid.model.kernel_nl_ir.ENTRIES_PT`)
    TB : (n_chunks, 2 * 4 * ns * LANES) the curves' intercepts then slopes, ``[corner][segment][lane]``
    XK : (nk + 1,) the interior knots, then inf; KF : (2 * max(nk, 1),) 1.0 where a knot is a kink of the
    axle's curves, else 0.0; nk; ns = nk + 1 segments per curve
    """
    co = np.asarray(co, dtype=float)
    n = co.shape[0]
    n_chunks = -(-n // LANES)
    idx = np.minimum(np.arange(n_chunks * LANES), n - 1)
    co = co[idx]
    cols = {}
    entries = kir.ENTRIES_PT if pt else kir.ENTRIES
    for name in entries:
        if name.startswith("ctm"):
            c = name[-1]
            cols[name] = co[:, CI[f"ct{c}"]] * co[:, CI[f"inv_mu{c}"]]
        elif name.startswith("neg_L"):
            cols[name] = -co[:, CI[f"L{name[-1]}"]]
        else:
            cols[name] = co[:, CI[name]]
    CF = np.stack([cols[nm] for nm in entries], axis=1)  # (n, E)
    CF = np.ascontiguousarray(CF.reshape(n_chunks, LANES, len(entries)).transpose(0, 2, 1)).reshape(n_chunks, -1)
    if curves:
        xk = np.asarray(xk, dtype=float)
        Sk = np.asarray(Sk, dtype=float)[idx]
        Fk = np.asarray(Fk, dtype=float)[idx]
        A = Fk[:, :, :-1] - Sk * xk[:-1]
        S = Sk
        A, S = A[:, [0, 0, 1, 1]], S[:, [0, 0, 1, 1]]  # (n, 4 corners, ns)
        XK = xk[1:-1].copy()
        KF = (np.asarray(kinks)[:, 1:-1] != 0).astype(float)
    else:
        A = np.zeros((n_chunks * LANES, 4, 1))
        S = co[:, [CI[f"cs{c}"] for c in range(4)]][:, :, None]
        XK = np.zeros(0)
        KF = np.zeros((2, 0))
    ns = A.shape[2]
    nk = XK.size
    XK = np.append(XK, np.inf)
    if nk == 0:
        KF = np.zeros((2, 1))
    TB = np.stack([A, S], axis=1)  # (n, 2, 4, ns)
    TB = TB.reshape(n_chunks, LANES, 2, 4, ns).transpose(0, 2, 3, 4, 1)
    TB = np.ascontiguousarray(TB).reshape(n_chunks, -1)
    return CF, TB, np.ascontiguousarray(XK), np.ascontiguousarray(KF.reshape(-1)), nk, int(ns)


def _dummy_args():
    n = 1
    co = np.ones((n, len(CI)))
    CF, TB, XK, KF, nk, ns = pack(co, np.array([0.0, 1.0]), np.zeros((n, 2, 2)), np.zeros((n, 2, 1)), False,
                                  None)
    X0 = np.zeros((1, n, 14))
    return (0, 1, n, CF, TB, XK, KF, nk, ns, True, X0, np.array([0, 2], dtype=np.int64), np.array([0.01]),
            np.array([1], dtype=np.int64), np.array([0, 3], dtype=np.int64), np.zeros((3, 4)), np.zeros((3, 4)),
            np.zeros((2, 10)), np.zeros((1, 10)), 0, np.zeros((1, n)), np.zeros((n, 2, 10)), np.zeros((n, 1, 14)),
            False)


def compile_kernel() -> None:
    """Compile (or load from Numba's cache) the kernel; raises if that fails."""
    run_chunks(*_dummy_args())


def run(co, xk, Fk, Sk, curves, X0, run_start, h, ms, fines, Y, W, mode, split=True, kinks=None):
    """Simulate every run for every candidate.

    Parameters
    ----------
    co : (n, len(COEF)) coefficients, xk (K+1,) knots with 0, Fk (n, 2, K+1), Sk (n, 2, K)
        (:func:`rideid.model.nonlinear.coefficients`); curves : bool
    X0 : (r, n, 14) initial states (18 with a powertrain on mounts: then its coefficients are in ``co``,
        :data:`rideid.model.nl_coef.PT_COEF`); run_start (r + 1,); h (r,) sample intervals; ms (r,) sub-steps
    fines : list over runs of ``(U, R)``, inputs and rates at the sub-step and half-step instants
        (:func:`rideid.model.nonlinear.fine_inputs`)
    Y : (T, 10), W : (r, 10), mode : 0 errors only, 1 the channels, 2 the states, 3 both
    split : split the sub-steps at the kinks they cross (False: plain RK4 sub-steps)
    kinks : (2, K + 1) which knots of ``xk`` are kinks, per axle (:func:`rideid.model.nonlinear.kink_mask`;
        None: every interior knot)

    Returns
    -------
    err : (r, n) (with mode 0); out : (n, T, 10) with mode 1 or 3, else None; states : (n, T, 14) (18) with
    mode 2 or 3, else None: ``[q, q']`` (deviations from static equilibrium, as
    :func:`rideid.model.nonlinear.simulate_numpy`'s)
    """
    nx = np.shape(X0)[-1]
    pt = nx == 18

    n = co.shape[0]
    n_runs = len(fines)
    fine_start = np.zeros(n_runs + 1, dtype=np.int64)
    for i, (U, _) in enumerate(fines):
        fine_start[i + 1] = fine_start[i] + U.shape[0]
    UF = np.ascontiguousarray(np.concatenate([f[0] for f in fines]))
    RF = np.ascontiguousarray(np.concatenate([f[1] for f in fines]))
    hs = np.ascontiguousarray(np.asarray(h, dtype=float) / np.asarray(ms, dtype=float))
    kinks = np.ones((2, np.size(xk)), dtype=np.int64) if kinks is None else kinks
    CF, TB, XK, KF, nk, ns = pack(co, xk, Fk, Sk, curves, kinks, pt)
    err = np.zeros((n_runs, n))
    T = int(run_start[-1])
    out = np.zeros((n, T, 10) if mode & 1 else (n, 1, 10))
    states = np.zeros((n, T, nx) if mode & 2 else (n, 1, nx))
    args = (n, CF, TB, XK, KF, nk, ns, bool(split), np.ascontiguousarray(X0, dtype=float),
            np.asarray(run_start, dtype=np.int64), hs, np.asarray(ms, dtype=np.int64), fine_start, UF, RF,
            np.ascontiguousarray(Y, dtype=float), np.ascontiguousarray(W, dtype=float), int(mode), err, out, states,
            bool(pt))
    n_chunks = CF.shape[0]
    threads = max(1, min(numba.get_num_threads(), n_chunks))
    if threads == 1:
        run_chunks(0, n_chunks, *args)
    else:
        bounds = np.linspace(0, n_chunks, threads + 1).round().astype(int)
        futures = [thread_pool(threads).submit(run_chunks, int(a), int(b), *args)
                   for a, b in zip(bounds[:-1], bounds[1:])]
        for f in futures:
            f.result()
    return err, (out if mode & 1 else None), (states if mode & 2 else None)
