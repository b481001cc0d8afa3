"""JADE's population and early stop before the polish: evaluations against the optimum reached.

Five identification problems (the built-in car noise-free and with 2 %
white noise; an SUV with AR(1) 0.8 noise; the SUV with anti-roll bars and
tire damping fitted with the full model; a van with 1 % noise), two search
seeds each, for several ``(population, spread_tol)`` settings. For every
setting: the evaluations (search and polish), and the largest difference of
the final estimate from the most thorough setting's, in units of the
estimate's standard error. A setting is safe when every difference is far
below one standard error (the polish reaches the same optimum).

Run: ``python benchmarks/bench_search.py`` (about 5 minutes on 2 cores).
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import rideid  # noqa: E402
from cars import SUV_BARS, SUV_TIRE_DAMPING, simulated, suv_scenario  # noqa: E402
from conftest import van_scenario  # noqa: E402
from rideid.estimate.fit.identify import identify  # noqa: E402

#: (population, spread_tol); the first is the reference
SETTINGS = ((64, 0.02), (64, 0.1), (48, 0.15), (32, 0.2), (32, 0.3), (24, 0.3))


def cases(tmp: Path) -> dict:
    sc = rideid.default_scenario()
    suv = suv_scenario(tmp, name="suv")
    suvf = suv_scenario(tmp, {**SUV_BARS, **SUV_TIRE_DAMPING}, name="suvfull")
    return {"car, noise-free": (simulated(sc, tmp / "c0", noise=0.0), "base"),
            "car, 2 %": (simulated(sc, tmp / "c2", noise=0.02, seed=2), "base"),
            "SUV, 2 % AR(1) 0.8": (simulated(suv, tmp / "s", noise=0.02, rho=0.8, seed=3), "base"),
            "SUV + bars + tire damping, full": (simulated(suvf, tmp / "sf", noise=0.02, seed=4), "full"),
            "van, 1 %": (simulated(van_scenario(tmp), tmp / "v", noise=0.01, seed=5), "base")}


def main(out=sys.stdout, seeds=(1, 2)):
    def say(*a):
        print(*a, file=out, flush=True)

    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as d:
        problems = cases(Path(d))
        say("## JADE settings: evaluations (search + polish) and distance from the reference optimum\n")
        say("distance: largest |estimate - reference estimate| / std over the parameters (noise-free: / |value|)\n")
        say("| case | " + " | ".join(f"NP {p}, stop {t}" for p, t in SETTINGS) + " |")
        say("|---|" + "---|" * len(SETTINGS))
        totals = np.zeros(len(SETTINGS))
        for name, (ds, model) in problems.items():
            for seed in seeds:
                res = [identify(ds, seed=seed, model=model, population=p, spread_tol=t, assess=False)
                       for p, t in SETTINGS]
                ref = res[0]
                scale = np.where(np.isfinite(ref.std) & (ref.std > 1e-9 * np.abs(ref.x)), ref.std, np.abs(ref.x))
                cells = []
                for k, r in enumerate(res):
                    dist = float(np.max(np.abs(r.x - ref.x) / scale))
                    totals[k] += r.nfev
                    cells.append(f"{r.nfev} ({dist:.1g})")
                say(f"| {name}, seed {seed} | " + " | ".join(cells) + " |")
        say("| **total evaluations, relative to NP 64, stop 0.1** | "
            + " | ".join(f"{t / totals[1]:.2f}" for t in totals) + " |")


if __name__ == "__main__":
    main()
