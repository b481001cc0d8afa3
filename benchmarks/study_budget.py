"""The uncertainty budget (SPEC §12) measured: coverage of ±2 std_total and a Monte Carlo cross-check.

    PYTHONPATH=src python benchmarks/study_budget.py [--seeds 5] [--draws 60] [--out DIR]

The built-in car, simulated with 2 % white sensor noise (``rideid simulate --noise 0.02``), identified with
``rideid.identify`` (model base, JADE + polish) in three cases:

1. **Weighbridge 1 % high.** ``[known] total_mass`` 1 % above the truth, declared ``{ value, std }`` with a std
   of 1 %: how many of the 12 estimates does ±2 std_total cover? And the same file with the plain number:
   the result must say the anchor is taken as exact (and ±2 std_total covers few).
2. **Sensor sensitivities off.** Each accelerometer's data scaled by ``1 + N(0, 2 %)``, each gyro's by
   ``1 + N(0, 1 %)`` (a seeded Generator per seed), the stds declared as ``sensitivity_std``; the estimates of
   all seeds pooled.
3. **Monte Carlo.** On the first seed's data of case 2: re-identify (the polish from the estimate) with the
   sensitivities drawn from their declared distributions (the data divided by ``1 + delta``), ``--draws``
   times; ``sqrt(std_robust^2 + var_MC)`` against the propagated ``std_total``, per parameter, and the
   re-fits' spread against the first-order prediction ``sum_c (d theta / d eps_c) delta_c`` on the same
   draws (that separates the linearisation from the sampling error of a finite Monte Carlo).

``--parts 3`` runs the Monte Carlo alone.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import tomllib
import warnings
from pathlib import Path

import numpy as np
import tomli_w

import rideid
from rideid.data.schema.runfiles import RunData
from rideid.estimate.fit.budget import declared_inputs, propagate
from rideid.estimate.problem.cost import CostFunction
from rideid.estimate.fit.polish import polish_fit
from rideid.model.equations import CHANNEL_KIND, CHANNELS
from rideid.model.params import NAMES
from rideid.synth.scenario import simulate_manifest, write_dataset

ACC_STD, GYRO_STD = 0.02, 0.01


def sensor_stds() -> dict[str, float]:
    """The declared relative std of each channel: 2 % accelerometers, 1 % gyros."""
    return {c: GYRO_STD if CHANNEL_KIND[c] == "rate" else ACC_STD for c in CHANNELS}


def make_dataset(out: Path, seed: int, *, gains=None, known=None, sensitivity=None, noise=0.02):
    """The built-in scenario simulated with ``noise`` (seed ``seed``), each channel times ``gains[c]``,
    written to ``out`` with ``known`` replacing ``[known]`` and ``sensitivity`` (channel -> std) declared."""
    sc = rideid.default_scenario()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data, _ = simulate_manifest(sc, noise=noise, seed=seed)
    if gains is not None:
        g = np.array([gains[c] for c in CHANNELS])
        data = {rid: (t, Y * g[None, :]) for rid, (t, Y) in data.items()}
    write_dataset(sc, data, out)
    path = out / "dataset.toml"
    doc = tomllib.loads(path.read_text())
    if known is not None:
        doc["known"] = known
    if sensitivity:
        doc["channels"] = {c: {"sensitivity_std": s} for c, s in sensitivity.items()}
    path.write_text(tomli_w.dumps(doc))
    return rideid.load_dataset(out), sc.truth


def draw_gains(seed: int) -> dict[str, float]:
    rng = np.random.default_rng(1000 + seed)
    return {c: 1.0 + s * rng.standard_normal() for c, s in sensor_stds().items()}


def covered(res, truth) -> list[bool]:
    """For each of the twelve: |estimate - truth| <= 2 std_total."""
    out = []
    for n in NAMES:
        d = res.details[n]
        out.append(abs(d["value"] - truth[n]) <= 2 * d["std_total"])
    return out


def identify(ds, seed):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rideid.identify(ds, model="base", rng=seed, assess=False)


def scaled(ds, delta: dict) -> "rideid.Dataset":
    """``ds`` with each channel's data divided by ``1 + delta[c]`` (a drawn sensitivity correction)."""
    data = {}
    for r in ds.runs:
        rd = ds.data[r.id]
        data[r.id] = RunData(rd.time, {c: v / (1.0 + delta.get(c, 0.0)) for c, v in rd.channels.items()},
                             rd.distance)
    return ds.with_data(data)


def monte_carlo(ds, res, draws: int, seed: int) -> tuple[dict, dict]:
    """Re-fits (the polish from ``res``) with the sensitivities drawn from their declared distributions.

    Returns ``(refits, linear)``: name -> the estimates ``(draws,)`` (the derived mass included), and name ->
    the first-order prediction of the same draws from the propagated sensitivities (:func:`propagate`).
    """
    rng = np.random.default_rng(seed)
    stds = dict(ds.manifest.sensitivity_std)
    cf = CostFunction(ds, extensions=())
    x0 = np.array([res.parameters[n] for n in cf.names])
    grads = propagate(cf, x0, [i for i in declared_inputs(ds.manifest) if i.kind == "sensitivity"])
    P0 = cf.space.full(x0[None])[0]
    rows, lin = [], []
    for _ in range(draws):
        delta = {c: s * rng.standard_normal() for c, s in stds.items()}
        # the data divided by 1 + delta: a gain error of -delta, first order
        lin.append(P0 - sum(grads[f"sensitivity {c}"] * d for c, d in delta.items()))
        dsk = scaled(ds, delta)
        cfk = CostFunction(dsk, space=cf.space)
        fit = polish_fit(dsk, cfk, x0)
        rows.append(cf.space.full(fit.x[None])[0])
    P, L = np.array(rows), np.array(lin)
    return ({n: P[:, cf.space.col[n]] for n in NAMES}, {n: L[:, cf.space.col[n]] for n in NAMES})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--draws", type=int, default=60)
    ap.add_argument("--out", default=None)
    ap.add_argument("--parts", default="1,2,3", help="which of the three studies to run, e.g. 3")
    args = ap.parse_args(argv)
    parts = {int(p) for p in args.parts.split(",")}
    root = Path(args.out or tempfile.mkdtemp(prefix="rideid-budget-"))
    t0 = time.perf_counter()
    sc = rideid.default_scenario()
    tm = sc.known["total_mass"]

    if 1 in parts:
        weighbridge(root, tm)
    first = None
    if 2 in parts:
        first = sensitivities(root, args.seeds)
    if 3 in parts:
        if first is None:
            first = make_dataset(root / "sens-1", 1, gains=draw_gains(1), sensitivity=sensor_stds())
            first = (first[0], identify(first[0], 1))
        mc_study(*first, args.draws)
    print(f"wall time {time.perf_counter() - t0:.0f} s; datasets in {root}")
    return 0


def weighbridge(root, tm):
    print("1. total_mass 1 % high")
    ds, truth = make_dataset(root / "mass-declared", 1, known={"total_mass": {"value": 1.01 * tm, "std": 0.01 * tm}})
    res = identify(ds, 1)
    cov = covered(res, truth)
    print(f"   declared std 1 %: ±2 std_total covers {sum(cov)} of 12; notes: {res.uncertainty['notes']}")
    ds, truth = make_dataset(root / "mass-plain", 1, known={"total_mass": 1.01 * tm})
    res = identify(ds, 1)
    cov = covered(res, truth)
    print(f"   plain number:     ±2 std_total covers {sum(cov)} of 12; anchor_exact="
          f"{res.uncertainty['anchor_exact']}; note: {res.uncertainty['notes'][0][:60]}...")



def sensitivities(root, seeds):
    print(f"2. sensitivities off by N(0, 2 %) (gyros 1 %), declared, {seeds} seeds")
    pooled, first = [], None
    for seed in range(1, seeds + 1):
        ds, truth = make_dataset(root / f"sens-{seed}", seed, gains=draw_gains(seed), sensitivity=sensor_stds())
        res = identify(ds, seed)
        cov = covered(res, truth)
        pooled += cov
        rob = sum(abs(res.details[n]["value"] - truth[n]) <= 2 * res.details[n]["std_robust"] for n in NAMES)
        print(f"   seed {seed}: ±2 std_total covers {sum(cov)} of 12 (±2 std_robust: {rob} of 12)")
        if first is None:
            first = (ds, res)
    print(f"   pooled: {sum(pooled)} of {len(pooled)} = {100 * np.mean(pooled):.1f} %")
    return first


def mc_study(ds, res, draws):
    print(f"3. Monte Carlo over the declared sensitivities, {draws} re-fits (seed 1's data)")
    mc, lin = monte_carlo(ds, res, draws, seed=7)
    ratios, same = [], []
    for n in NAMES:
        d = res.details[n]
        mc_total = float(np.hypot(d["std_robust"], np.std(mc[n], ddof=1)))
        ratios.append(mc_total / d["std_total"])
        same.append(np.std(mc[n], ddof=1) / np.std(lin[n], ddof=1))
        print(f"   {n:5s} std_total {d['std_total']:.4g}  Monte Carlo {mc_total:.4g}  ratio {ratios[-1]:.3f}  "
              f"re-fits / first order on the same draws {same[-1]:.3f}")
    print(f"   ratio MC / propagated: {min(ratios):.3f} .. {max(ratios):.3f}, median {np.median(ratios):.3f} "
          f"(sampling sd of a std from {draws} draws: {100 / np.sqrt(2 * (draws - 1)):.0f} %); re-fits / first "
          f"order on the same draws: {min(same):.3f} .. {max(same):.3f}")


if __name__ == "__main__":
    sys.exit(main())
