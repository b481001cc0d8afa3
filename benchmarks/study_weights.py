"""Fixed vs adaptive track weights (the paper's claim of faster convergence).

Built-in car, noise-free and 1 % noise, 10 seeds each, default population,
JADE run for a fixed number of generations without early stop or polish.
Reports, per mode: JADE evaluations until the best individual has every
parameter within 1 % of the truth (median and range over seeds; "never"
counts as the full budget), and the final largest error. Run: ``make bench``
(about 5 minutes) or ``python benchmarks/study_weights.py --seeds 3``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings

import numpy as np

import rideid
from rideid.estimate.cost import CostFunction
from rideid.data.scenario import simulate_manifest, write_dataset


def evals_to(history, names, truth, tol):
    for h in history:
        err = max(abs(h[f"best_{n}"] / truth[n] - 1) for n in names)
        if err < tol:
            return h["evaluations"]
    return None


def main(argv=None, out=sys.stdout):
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--generations", type=int, default=200)
    a = ap.parse_args(argv)

    def say(*x):
        print(*x, file=out, flush=True)

    sc = rideid.default_scenario()
    truth = sc.truth
    say(f"## Adaptive vs fixed track weights: built-in car, {a.seeds} seeds, {a.generations} generations\n")
    say("| data | weights | evals to 1 % (median, min-max) | reached | final largest error (median) |")
    say("|---|---|---|---|---|")
    for noise in (0.0, 0.01):
        with tempfile.TemporaryDirectory() as d, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data, _ = simulate_manifest(sc, noise=noise, seed=99)
            write_dataset(sc, data, d)
            ds = rideid.load_dataset(d)
            cf = CostFunction(ds)
            for mode in ("fixed", "adaptive"):
                ev, final = [], []
                for seed in range(1, a.seeds + 1):
                    r = rideid.identify(ds, seed=seed, weights=mode, generations=a.generations, spread_tol=0,
                                        polish=False, cost=cf)
                    e = evals_to(r.history, cf.names, truth, 0.01)
                    ev.append(e)
                    final.append(max(abs(r.parameters[n] / truth[n] - 1) for n in cf.names))
                budget = r.history[-1]["evaluations"]
                vals = np.array([budget if e is None else e for e in ev], dtype=float)
                reached = sum(e is not None for e in ev)
                say(f"| {noise:.0%} noise | {mode} | {np.median(vals):.0f} ({vals.min():.0f}-{vals.max():.0f}) | "
                    f"{reached}/{a.seeds} | {100 * np.median(final):.3g} % |")


if __name__ == "__main__":
    main()
