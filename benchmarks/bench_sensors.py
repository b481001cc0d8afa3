"""The price of a declared sensor chain (SPEC §11): the same data identified with and without it.

The built-in car's ten runs, simulated at 1 kHz with 2 % white noise, its
four hub channels AC-coupled at 0.5 Hz (first order, an independent lsim),
written as SPEC-named CSVs (``tests/sensor_case.py``). Measured on the same
files, in the same process:

* a cost evaluation of a JADE population of 32 (the search's unit of work):
  no chain (the compiled kernel's errors mode, today's fast path) against
  the four high-passes declared (the kernel's outputs mode, the batched
  filter, the errors in NumPy);
* a whole ``rideid.identify(ds, seed=1, model="base")`` both ways (the
  undeclared fit's numbers are the sensors', its time is the price's
  baseline).

Run: ``python benchmarks/bench_sensors.py [--quick]`` (``--quick``: the cost
evaluations only).
"""

from __future__ import annotations

import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np
import tomli_w

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
from sensor_case import write_sensor_dataset  # noqa: E402

HUBS = ("axle_az_fl", "axle_az_fr", "axle_az_rl", "axle_az_rr")


def best_of(f, repeat=5):
    f()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(quick: bool = False):
    with tempfile.TemporaryDirectory() as tmp:
        declared, _ = write_sensor_dataset(Path(tmp) / "declared", highpass=(HUBS, 0.5, 1))
        plain = Path(tmp) / "plain"
        import shutil
        shutil.copytree(declared, plain)
        doc = tomllib.loads((plain / "dataset.toml").read_text())
        doc["channels"] = {"time": {"name": "time", "unit": "s"}}
        (plain / "dataset.toml").write_text(tomli_w.dumps(doc))
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ds_plain, ds_decl = rideid.load_dataset(plain), rideid.load_dataset(declared)
        # the same starts for both: the cost functions see the same samples
        ds_plain = ds_plain.with_starts({r.id: ds_decl.measured[r.id].start for r in ds_decl.runs})
        cf_plain, cf_decl = rideid.CostFunction(ds_plain), rideid.CostFunction(ds_decl)
        rng = np.random.default_rng(0)
        lo, hi = cf_plain.bounds.T
        X = lo + (hi - lo) * rng.random((32, len(cf_plain.names)))
        t_plain, t_decl = best_of(lambda: cf_plain(X)), best_of(lambda: cf_decl(X))
        n = cf_plain.sim.n_samples
        print(f"cost of a population of 32 over {n} samples x 10 channels: no chain {1e3 * t_plain:.1f} ms, "
              f"four hub high-passes declared {1e3 * t_decl:.1f} ms (x{t_decl / t_plain:.2f})")
        if quick:
            return
        for name, ds in (("no chain declared", ds_plain), ("four hub high-passes declared", ds_decl)):
            t0 = time.perf_counter()
            res = rideid.identify(ds, seed=1, model="base")
            wall = time.perf_counter() - t0
            truth = rideid.default_scenario().truth
            worst = max(abs(res.parameters[k] / truth[k] - 1) for k in rideid.NAMES)
            print(f"identify (--model base), {name}: {wall:.1f} s, {res.evaluations} evaluations, "
                  f"largest error {100 * worst:.2f} %")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
