"""JADE against its Python peers, in the same run.

* Overhead per generation at NP = 100, D = 30 on a cheap function (sphere):
  ``rideid.jade``, ``scipy.optimize.differential_evolution(vectorized=True)``
  (same population, no polish) and mealpy's ``DE.JADE`` (if installed:
  ``pip install mealpy``; it evaluates one individual at a time).
* Best cost after equal evaluation budgets on Rastrigin and Rosenbrock
  (D = 30, 3 seeds, median).

Run: ``make bench``.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.optimize import differential_evolution

import rideid

D, NP = 30, 100


def sphere(X):
    return np.sum(X * X, axis=-1)


def rastrigin(X):
    return np.sum(X * X - 10 * np.cos(2 * np.pi * X) + 10, axis=-1)


def rosenbrock(X):
    X = np.asarray(X)
    return np.sum(100 * (X[..., 1:] - X[..., :-1] ** 2) ** 2 + (X[..., :-1] - 1) ** 2, axis=-1)


def run_rideid(f, hw, gens, seed):
    t = time.perf_counter()
    r = rideid.jade(f, [(-hw, hw)] * D, population=NP, generations=gens, seed=seed)
    return r.fun, time.perf_counter() - t


def run_scipy(f, hw, gens, seed):
    t = time.perf_counter()
    # scipy's popsize is a multiplier of D; vectorized calls take (D, S)
    r = differential_evolution(lambda x: f(np.asarray(x).T), [(-hw, hw)] * D, popsize=NP // D + (NP % D > 0),
                               maxiter=gens, tol=0, polish=False, vectorized=True, updating="deferred", rng=seed)
    return r.fun, time.perf_counter() - t


def run_mealpy(f, hw, gens, seed):
    from mealpy import DE, FloatVar
    prob = {"obj_func": lambda x: float(f(np.asarray(x)[None])[0]),
            "bounds": FloatVar(lb=[-hw] * D, ub=[hw] * D), "minmax": "min", "log_to": None}
    t = time.perf_counter()
    g = DE.JADE(epoch=gens, pop_size=NP).solve(prob, seed=seed)
    return g.target.fitness, time.perf_counter() - t


def main(out=sys.stdout):
    def say(*a):
        print(*a, file=out, flush=True)

    solvers = [("rideid.jade", run_rideid),
               (f"scipy differential_evolution (vectorized, {(NP // D + 1) * D} individuals)", run_scipy)]
    try:
        import mealpy  # noqa: F401
        solvers.append(("mealpy DE.JADE", run_mealpy))
    except ImportError:
        say("(mealpy not installed: pip install mealpy to include it)")
    say(f"## Overhead per generation, NP = {NP}, D = {D}, sphere\n")
    say("| optimiser | ms per generation | relative to rideid |")
    say("|---|---|---|")
    base = None
    for name, fn in solvers:
        gens = 200 if "mealpy" not in name else 20
        _, t = fn(sphere, 100.0, gens, 1)
        per = t / gens
        base = base or per
        say(f"| {name} | {per * 1e3:.2f} | {per / base:.1f}x |")
    say("\n## Best cost after equal budgets (median of 3 seeds)\n")
    say("| function, budget | " + " | ".join(n for n, _ in solvers) + " |")
    say("|---" * (len(solvers) + 1) + "|")
    for fname, f, hw, gens in (("Rastrigin", rastrigin, 5.12, 1000), ("Rosenbrock", rosenbrock, 30.0, 1000)):
        row = []
        for name, fn in solvers:
            g = gens if "mealpy" not in name else gens // 5
            vals = [fn(f, hw, g, s)[0] for s in (1, 2, 3)]
            row.append(f"{np.median(vals):.3g}" + ("" if g == gens else f" ({g * NP} evals)"))
        say(f"| {fname}, {gens * NP} evals | " + " | ".join(row) + " |")
    say("\n(mealpy runs a fifth of the budget: it evaluates one candidate at a time.)")


if __name__ == "__main__":
    main()
