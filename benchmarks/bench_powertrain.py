"""A car with a powertrain on mounts (SPEC §11) on the compiled kernel's 12-state specialisation, against the
NumPy modal recursion (its NumPy backend) and the 8-state kernel of the same car without the group, in one run.

On the built-in scenario's ten runs (noise-free nominal outputs plus 2 % noise as the data), a population of 64
near the built-in car with the engine of docs/powertrain.md (180 kg on 10.5/13 Hz mounts):

* cost per candidate-sample (ns) of the per-run weighted errors (``BatchSimulator.errors``, discretisation
  included), on one thread and on every core, and each path's ratio to the NumPy modal path;
* the kernel alone (one thread, discretisation excluded): the 12-state and the 8-state blocks' ns per
  candidate-sample, against their multiply-add counts (``306 + 36 N`` and ``210 + 28 N``);
* the compiled costs' largest relative difference from the modal path's.

Run: ``python benchmarks/bench_powertrain.py`` (``make bench`` runs it too).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numba
import numpy as np

import rideid
from rideid.data.scenario import run_times
from rideid.model import kernel
from rideid.model.batch import BatchSimulator, single_threaded_blas
from rideid.model.params import as_vector
from rideid.model.simulate import prepare_run

sys.path.insert(0, str(Path(__file__).parent))
from bench_kernel import best_cpu_or_wall  # noqa: E402
from verify_mujoco import POWERTRAIN  # noqa: E402


def kernel_only(sim, P, Y, W):
    """One-thread seconds of the compiled kernel alone on ``P`` (its coefficients packed beforehand), and N."""
    CO, nt, X0 = sim._pack(P)
    fn = kernel.compiled_kernel()
    n_chunks = P.shape[0] // kernel.LANES
    err = np.zeros((len(sim.runs), P.shape[0]))
    out = np.zeros((1, 10, 1))

    def run():
        fn(0, n_chunks, CO, n_chunks, nt, sim.geom.corner_y[0], sim.geom.corner_y[2], X0, sim.run_start,
           sim.run_group, sim.UD, sim.RD, sim.MU, Y, W, 0, err, out)

    return best_cpu_or_wall(run), int(nt.max())


def main(out=sys.stdout, n_pop: int = 64):
    def say(*a):
        print(*a, file=out, flush=True)

    sc = rideid.default_scenario()
    G = sc.geometry
    runs = [prepare_run(sc.tracks[r.track], G, r.speed, run_times(r)) for r in sc.runs]
    compiled, numpy_sim = BatchSimulator(G, runs, numpy=False), BatchSimulator(G, runs, numpy=True)
    car = as_vector({**{k: sc.truth[k] for k in rideid.NAMES}, **POWERTRAIN}, extended=True)
    rng = np.random.default_rng(1)
    P = car * np.exp(rng.normal(0, 0.05, (n_pop, car.size)))
    rigid = np.ascontiguousarray(P[:, :16])  # the same cars without the group: the 8-state kernel
    Y0 = np.concatenate([o[0] for o in compiled.outputs(car[None])])
    Y = np.ascontiguousarray(Y0 * (1 + 0.02 * rng.standard_normal(Y0.shape)))
    W = np.ones((len(runs), 10))
    cs = n_pop * compiled.n_samples
    e_c, e_m = compiled.errors(P, Y, W), numpy_sim.errors(P, Y, W)
    cores = os.cpu_count() or 1
    say(f"## A powertrain on mounts: built-in scenario, {len(runs)} runs, {compiled.n_samples} samples, "
        f"population {n_pop}\n")
    say(f"compiled (12-state) vs NumPy modal, largest relative difference of the per-run costs: "
        f"{np.abs(e_c / e_m - 1).max():.1e}\n")
    before = numba.get_num_threads()
    rows = []
    try:
        with single_threaded_blas():
            t_modal = best_cpu_or_wall(lambda: numpy_sim.errors(P, Y, W), repeat=3)
            for threads in sorted({1, cores}):
                numba.set_num_threads(threads)
                rows.append((threads, best_cpu_or_wall(lambda: compiled.errors(P, Y, W)),
                             best_cpu_or_wall(lambda: compiled.errors(rigid, Y, W))))
            numba.set_num_threads(1)
            k12, n12 = kernel_only(compiled, P, Y, W)
            k8, n8 = kernel_only(compiled, rigid, Y, W)
    finally:
        numba.set_num_threads(before)

    def ns(t):
        return t / cs * 1e9

    say("| path | threads | ms per population | ns per candidate-sample | vs NumPy modal |")
    say("|---|---|---|---|---|")
    say(f"| powertrain, NumPy modal recursion (simulate_modal) | 1 | {t_modal * 1e3:.0f} | {ns(t_modal):.1f} | 1 |")
    for threads, t12, t8 in rows:
        say(f"| powertrain, compiled 12-state kernel | {threads} | {t12 * 1e3:.1f} | {ns(t12):.1f} | "
            f"**{t_modal / t12:.1f}x** |")
        say(f"| same cars without the powertrain, 8-state kernel | {threads} | {t8 * 1e3:.1f} | {ns(t8):.1f} | "
            f"{t_modal / t8:.1f}x |")
    say("\n(ms per population include the discretisation: matrix exponentials and packing, NumPy, one BLAS "
        "thread)\n")
    say("| kernel alone, one thread | moment terms N | multiply-adds per candidate-sample | "
        "ns per candidate-sample |")
    say("|---|---|---|---|")
    say(f"| 12-state (powertrain) | {n12} | {306 + 36 * n12} | {ns(k12):.2f} |")
    say(f"| 8-state | {n8} | {210 + 28 * n8} | {ns(k8):.2f} |")
    say(f"\n12-state / 8-state kernel time: {k12 / k8:.2f} (multiply-adds: "
        f"{(306 + 36 * n12) / (210 + 28 * n8):.2f})")


if __name__ == "__main__":
    t = time.perf_counter()
    main()
    print(f"\n({time.perf_counter() - t:.0f} s)")
