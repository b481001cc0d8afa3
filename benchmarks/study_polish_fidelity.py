"""What a cheaper integration of the damper-curve car does to the estimates (issue 37: cost <= 3x the linear kernel).

The polish of a damper-curve model (``rideid.estimate.fit.polish._polish``) is where the nonlinear kernel runs:
its residuals and finite-difference Jacobians. This study fits one dataset with ``--model damper_curves``
(seed 1, no adequacy) at several integrations of the polish and compares each fit's parameters with the
default's, in units of the default's standard errors (``std``) and relative:

* ``default``: ``Simulator()`` (``rho = RHO_MAX``, sub-steps split at the kinks, the polish's floor 1.5x the
  start's sub-steps);
* ``m=K split`` / ``m=K plain``: the polish's sub-steps held at ``K`` per sample (``rho = 1.5``, so that the
  floor decides; RK4 is stable to ``|lambda h| ~ 2.8``), split at the kinks or not;
* ``m=8 split``: a finer integration, how far the default itself is from converged.

and a two-fidelity polish (``two_fidelity``): the polish on a cheap integration, then again on the default
one from its end, whose numbers are the default integration's.

Then, at the default's estimate (the polish's car): every integration's largest output error against the
same kernel at ``rho = 0.01`` (the worst run and channel's ``RMS(y - y_ref) / RMS(y_ref)`` and
``max|y - y_ref| / RMS(y_ref)``) and its cost
per candidate-sample against the linear kernel on the same runs (48 candidates about the estimate, one
thread, CPU time, best of interleaved repeats).

Run: ``python benchmarks/study_polish_fidelity.py [DATASET ...]`` (default: the knee car ``sedan`` of
``tests/knee_cars.py``, simulated with 1 % noise, seed 1). Takes a few minutes per dataset.
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
import tomli_w

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(Path(__file__).parent))

from bench_nonlinear import interleaved  # noqa: E402
from knee_cars import scenario_doc  # noqa: E402

from rideid.cli import main  # noqa: E402
from rideid.conditioning.load import load_dataset  # noqa: E402
from rideid.estimate.problem.cost import CostFunction  # noqa: E402
from rideid.estimate.fit import identify as ident  # noqa: E402
from rideid.model import kernel_nl  # noqa: E402
from rideid.model.nonlinear import NonlinearSimulator  # noqa: E402
from rideid.model.params import INDEX  # noqa: E402
from rideid.model.simulator import Simulator  # noqa: E402

#: name -> (rho, split, the polish's sub-steps held at, or None: the default floor)
SETTINGS = {"default": (0.2, True, None), "m=1 split": (1.5, True, 1), "m=1 plain": (1.5, False, 1),
            "m=2 split": (1.5, True, 2), "m=2 plain": (1.5, False, 2), "m=8 split": (0.2, True, 8)}


def fit(ds, rho, split, m):
    """Identify ``ds`` (damper curves, seed 1) with the polish at one integration: parameters, std, CPU seconds
    (identify, polish, kernel), the polish's cost function and estimate."""
    pin_at = NonlinearSimulator.pin_at
    run, polish_fit = kernel_nl.run, ident.polish_fit
    t = {"polish": 0.0, "kernel": 0.0}
    last = {}

    def held(self, P, margin=1.5):
        p = pin_at(self, P, margin)
        return p if m is None else dataclasses.replace(p, substeps=(m,) * len(p.substeps))

    def timed_run(*a, **k):
        c = time.process_time()
        r = run(*a, **k)
        t["kernel"] += time.process_time() - c
        return r

    def timed_polish(ds, cf, x0):
        c = time.process_time()
        r = polish_fit(ds, cf, x0)
        t["polish"] += time.process_time() - c
        last["cf"], last["x"] = r.cost, r.x
        return r

    NonlinearSimulator.pin_at, kernel_nl.run, ident.polish_fit = held, timed_run, timed_polish
    try:
        c = time.process_time()
        res = ident.identify(ds, model=["damper_curves"], seed=1, simulator=Simulator(rho=rho, split=split),
                             assess=False)
        t["identify"] = time.process_time() - c
    finally:
        NonlinearSimulator.pin_at, kernel_nl.run, ident.polish_fit = pin_at, run, polish_fit
    return res, t, last


def kernel_table(cf, x, out):
    """Output error and cost per candidate-sample of each integration at the polish's car ``x``."""
    core = cf.core_sim
    geom, runs, lay = core.geom, core.runs, core.layout
    P = cf.space.full(np.asarray(x)[None])
    ref = NonlinearSimulator(geom, runs, lay, rho=0.01).outputs(P)
    n, ns = 48, sum(r.n for r in runs)
    Pp = np.repeat(P, n, axis=0) * (1 + 1e-6 * np.random.default_rng(0).standard_normal((n, P.shape[1])))
    Pl = np.repeat(P[:, :16], n, axis=0)
    Pl[:, [INDEX["c_sf"], INDEX["c_sr"]]] = 2000.0  # the linear car's dampers (its cost does not depend on them)
    Y, W = np.zeros((ns, 10)), np.ones((len(runs), 10))
    lin = Simulator().bind(geom, runs)
    sims = {}
    for name, (rho, split, m) in SETTINGS.items():
        sim = NonlinearSimulator(geom, runs, lay, rho=rho, split=split)
        pin = sim.pin_at(P, 1.0)  # as the polish ends: every interior knot split, its sub-steps or m's
        pin = pin if m is None else dataclasses.replace(pin, substeps=(m,) * len(runs))
        sims[name] = (sim, pin)
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    fs = {"linear": lambda: lin.errors(Pl, Y, W)}
    fs.update({k: (lambda s=s, p=p: s.errors(Pp, Y, W, p)) for k, (s, p) in sims.items()})
    b = interleaved(fs, repeat=3, clock=time.process_time)
    numba.set_num_threads(threads)
    out.write(f"\nat the default's estimate: linear kernel {b['linear'] / (n * ns) * 1e9:.0f} ns per "
              "candidate-sample\n\n"
              "| integration | sub-steps | ns | / linear | output error: RMS | largest |\n|---|---|---|---|---|---|\n")
    for k, (s, p) in sims.items():
        worst = np.zeros(2)
        for a, r in zip(s.outputs(P, p), ref):
            rms = np.sqrt(np.mean(r ** 2, axis=(0, 1)))
            ok = rms > 0
            d = a - r
            worst = np.maximum(worst, [np.max(np.sqrt(np.mean(d ** 2, axis=(0, 1)))[ok] / rms[ok]),
                                       np.max(np.max(np.abs(d), axis=(0, 1))[ok] / rms[ok])])
        out.write(f"| {k} | {max(s.substeps(P, p))} | {b[k] / (n * ns) * 1e9:.0f} | {b[k] / b['linear']:.1f}x | "
                  f"{worst[0]:.1e} | {worst[1]:.1e} |\n")


def two_fidelity(ds, rho, split, m):
    """Identify ``ds`` as :func:`fit` with the default integration, its polish first run on the cheap one (``rho``,
    ``split``, ``m``), then again on the default from there: the result, CPU seconds, both polishes' evaluations."""
    polish_fit = ident.polish_fit
    n = {}

    def two(ds, cf, x0):
        cheap = CostFunction(cf.ds, space=cf.space, counter=cf.counter,
                             simulator=dataclasses.replace(cf.simulator, rho=rho, split=split))
        first = polish_fit(ds, cheap.with_pin(dataclasses.replace(cf.pin, substeps=(m,) * len(cf.pin.substeps))),
                           x0)
        final = polish_fit(ds, cf, first.x)
        n["cheap"], n["final"] = first.info["nfev"], final.info["nfev"]
        return final

    ident.polish_fit = two
    try:
        c = time.process_time()
        res = ident.identify(ds, model=["damper_curves"], seed=1, assess=False)
        return res, time.process_time() - c, n
    finally:
        ident.polish_fit = polish_fit


def study(path, out=sys.stdout):
    ds = load_dataset(path)
    fits = {}
    for name, (rho, split, m) in SETTINGS.items():
        fits[name] = fit(ds, rho, split, m)
    res0, t0, last0 = fits["default"]
    x0, s0 = np.asarray(res0.x), np.asarray(res0.std)
    out.write(f"\n## {path}: {len(x0)} free parameters\n\n| polish | max abs(diff)/std | max relative | "
              "identify CPU s | polish | kernel |\n|---|---|---|---|---|---|\n")
    for name, (res, t, _) in fits.items():
        d = np.abs(np.asarray(res.x) - x0)
        k, j = np.argmax(d / s0), np.argmax(d / np.abs(x0))
        out.write(f"| {name} | {d[k] / s0[k]:.3f} ({res0.names[k]}) | {d[j] / abs(x0[j]):.1e} ({res0.names[j]}) | "
                  f"{t['identify']:.1f} | {t['polish']:.1f} | {t['kernel']:.1f} |\n")
    kernel_table(last0["cf"], last0["x"], out)
    out.write("\n| two-fidelity polish | evaluations | max abs(diff)/std | max relative | std, relative | "
              "identify CPU s |\n|---|---|---|---|---|---|\n")
    for name in ("m=2 plain", "m=1 split"):
        res, cpu, n = two_fidelity(ds, *SETTINGS[name])
        d = np.abs(np.asarray(res.x) - x0)
        out.write(f"| {name}, then default | {n['cheap']} + {n['final']} | {np.max(d / s0):.1e} | "
                  f"{np.max(d / np.abs(x0)):.1e} | {np.max(np.abs(np.asarray(res.std) / s0 - 1)):.1e} | {cpu:.1f} "
                  f"(default {fits['default'][1]['identify']:.1f}) |\n")


if __name__ == "__main__":
    paths = sys.argv[1:]
    with tempfile.TemporaryDirectory() as tmp:
        if not paths:
            sc = Path(tmp) / "sedan.toml"
            sc.write_text(tomli_w.dumps(scenario_doc("sedan")))
            assert main(["simulate", str(sc), "--out", f"{tmp}/sedan", "--noise", "0.01", "--seed", "1",
                         "--quiet"]) == 0
            paths = [f"{tmp}/sedan"]
        for p in paths:
            study(p)
