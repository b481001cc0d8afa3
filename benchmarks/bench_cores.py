"""The stages that run their independent items side by side (issue 52: both cores), on one and on two workers.

Each stage is run with the kernel's threads as they are (two on a two-core
machine) and with one (``rideid.model.backend.one_thread``, which is also
what sets :func:`rideid.model.batch.thread_map`'s workers), ``--repeat``
times each; the table gives the minimum wall time and the CPU time of that
run, and whether the two give the same numbers to the last bit:

* load dataset: the SUV's five logger runs (``tests/logger_case.py``),
  starts estimated: the runs' checks and alignments (``gather``);
* cycle slips: the same runs at the nominal car, the herringbone read 0.3 s
  late (``rideid.conditioning.starts.cycle_slips``);
* materiality: the built-in car's ten runs, 2 % noise, polished from its
  truth (model base), one hub pair flagged: the two refits;
* road hints: the SUV's five runs on tracks as built, hubs coupled at 0.5 Hz
  and not declared, at the true car: the 25 road fits of the coupling trials
  (``sensor_check.road_coupling_hints``);
* budget: the built-in car (clean) with a weighbridge, three tapes and three
  sensor gains declared: ``budget.propagate``'s seven input columns.

Run: ``python benchmarks/bench_cores.py [--repeat 2] [--out bench-out/cores]``. The same script run on an
earlier tree (``PYTHONPATH=<tree>/src``) gives its "before" figures.
"""

from __future__ import annotations

import argparse
import pickle
import shutil
import sys
import time
import tomllib
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import tomli_w

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import rideid  # noqa: E402
from rideid.model import backend  # noqa: E402


def _logger(out: Path) -> Path:
    from logger_case import suv_scenario, write_logger
    folder = out / "logger"
    if not folder.exists():
        write_logger(suv_scenario(out / "logger-sc"), folder, noise=0.02, seed=3)
    return folder


def _builtin(out: Path, noise: float) -> Path:
    from rideid.synth.scenario import simulate_manifest, write_dataset
    folder = out / f"builtin-{noise:g}"
    if not folder.exists():
        sc = rideid.default_scenario()
        data, _ = simulate_manifest(sc, noise=noise, seed=1)
        write_dataset(sc, data, folder)
    return folder


def case_load(out):
    folder = _logger(out)
    rideid.load_dataset(folder)  # the kernels compiled or loaded from the cache
    return lambda: {r: (m.start, m.record) for r, m in rideid.load_dataset(folder).measured.items()}


def case_cycle_slips(out):
    from rideid.conditioning import starts as st
    ds = rideid.load_dataset(_logger(out))
    P = rideid.CostFunction(ds).space.nominal()
    starts = {rid: mr.start + (0.3 if rid == "HB6" else 0.0) for rid, mr in ds.measured.items()}
    return lambda: st.cycle_slips(ds, P, starts)


def case_materiality(out):
    from rideid.estimate.assess import materiality
    sc = rideid.default_scenario()
    ds = rideid.load_dataset(_builtin(out, 0.02))
    names = rideid.CostFunction(ds).names
    res = rideid.identify(ds, model="base", start=[sc.truth[n] for n in names], seed=1)
    first = ds.runs[0].id
    runs = {r.id: {c: {"structure": r.id == first and c == "axle_az_fl"} for c in rideid.CHANNELS} for r in ds.runs}
    flagged = replace(res, adequacy={"adequate": False, "reasons": ["structure", "whiteness"], "runs": runs,
                                     "advice": None})
    return lambda: materiality.weigh_result(ds, flagged).adequacy["materiality"]


def case_road_hints(out):
    from cars import SUV_TRUTH
    from coupled_case import write_tracks_dataset
    from rideid.estimate.assess.sensor_check import road_coupling_hints
    from rideid.estimate.problem import asbuilt
    from rideid.model.params import ALL_NAMES, as_vector
    folder = out / "coupled"
    if not folder.exists():
        write_tracks_dataset(folder, seed=4, declare=False)
    ds = rideid.load_dataset(folder)
    P = as_vector({n: SUV_TRUTH.get(n, 0.0) for n in ALL_NAMES}, extended=True)
    rruns = [asbuilt.prepare_track_run(ds, r).rr for r in ds.runs]
    filters = {r.id: ds.sensor_filters(r.id) for r in ds.runs}
    return lambda: road_coupling_hints(P, ds.geometry, rruns, filters)


def case_budget(out):
    from rideid.estimate.fit.budget import declared_inputs, propagate
    folder = out / "budget"
    if not folder.exists():
        shutil.copytree(_builtin(out, 0.0), folder)
        doc = tomllib.loads((folder / "dataset.toml").read_text())
        doc["known"]["total_mass"] = {"value": 1093.3, "std": 10.933}
        for k in ("wheelbase", "track_front", "track_rear"):
            doc["vehicle"][k] = {"value": doc["vehicle"][k], "std": 0.005}
        doc["channels"] = {"body_az_fl": {"sensitivity_std": 0.02}, "axle_az_rr": {"sensitivity_std": 0.02},
                           "pitch_rate": {"sensitivity_std": 0.01}}
        (folder / "dataset.toml").write_text(tomli_w.dumps(doc))
    ds = rideid.load_dataset(folder)
    truth = rideid.load_truth(folder / "truth.toml")
    cf = rideid.CostFunction(ds, extensions=())
    x = np.array([truth[n] for n in cf.names])
    inputs = declared_inputs(ds.manifest)
    return lambda: propagate(cf, x, inputs)


CASES = {"load dataset": case_load, "cycle slips": case_cycle_slips, "materiality": case_materiality,
         "road hints": case_road_hints, "budget": case_budget}


def timed(fn, repeat: int, one: bool):
    best = None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        if one:
            with backend.one_thread():
                got = fn()
        else:
            got = fn()
        w, c = time.perf_counter() - w0, time.process_time() - c0
        if best is None or w < best[0]:
            best = (w, c)
    return best, got


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--out", default="bench-out/cores")
    ap.add_argument("--cases", default=",".join(CASES))
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name in a.cases.split(","):
            fn = CASES[name](out)
            (w2, c2), two = timed(fn, a.repeat, one=False)
            (w1, c1), one = timed(fn, a.repeat, one=True)
            same = pickle.dumps(one) == pickle.dumps(two)
            rows.append((name, w2, c2, w1, c1, same))
    print(f"two workers: {backend.threads()}; min of {a.repeat}")
    print("| stage | wall s, 2 workers | CPU s | wall s, 1 worker | CPU s | same numbers |")
    print("|---|---|---|---|---|---|")
    for name, w2, c2, w1, c1, same in rows:
        print(f"| {name} | {w2:.2f} | {c2:.2f} | {w1:.2f} | {c1:.2f} | {'yes' if same else 'NO'} |")
    return 0 if all(r[-1] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
