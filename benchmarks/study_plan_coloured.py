"""``rideid plan`` under coloured sensor noise (issue 24): predicted against Monte Carlo spread.

Two runs of the built-in car (T_HL, H_LL), the noise of ``rideid simulate
--noise 0.02 --noise-ar1 0.9``. Prints, per free parameter, the relative
CRLB and identify's predicted spread of the white plan (``--noise 0.02``)
and of the coloured one (``--noise-ar1 0.9``, and the same AR(1) spectrum as
a ``--noise-psd`` file), against the sample sd of ``rideid.identify(model=
"base")`` over seeds 1..N and of its linearised estimate
(:func:`rideid.design.validate.linearised_monte_carlo`) over seeds 1..M.

    python benchmarks/study_plan_coloured.py --seeds 30 --many 1000
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import rideid
from rideid.design.colour import ar1_psd
from rideid.design.validate import linearised_monte_carlo, monte_carlo, sub_scenario

RUNS = ["T_HL", "H_LL"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=30, help="seeds of rideid.identify")
    ap.add_argument("--many", type=int, default=1000, help="seeds of the linearised estimate")
    ap.add_argument("--noise", type=float, default=0.02)
    ap.add_argument("--rho", type=float, default=0.9)
    a = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    sc = rideid.default_scenario()
    sub = sub_scenario(sc, RUNS)
    w = rideid.plan(sub, noise=a.noise, budget_runs=len(RUNS)).all_runs
    c = rideid.plan(sub, noise=a.noise, noise_ar1=a.rho, budget_runs=len(RUNS)).all_runs
    f = np.linspace(0.0, 100.0, 2001)  # fs = 200 Hz
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "ar1.csv"
        p.write_text("frequency,psd\n" + "".join(f"{x:.17g},{y:.17g}\n" for x, y in zip(f, ar1_psd(a.rho, 200.0, f))))
        q = rideid.plan(sub, noise=a.noise, noise_psd=p, budget_runs=len(RUNS)).all_runs
    t0 = time.perf_counter()
    est, lin = monte_carlo(sc, RUNS, c.names, a.noise, range(1, a.seeds + 1), identify_kw={"model": "base"},
                           linearised=True, noise_ar1=a.rho)
    t1 = time.perf_counter()
    many = linearised_monte_carlo(sc, RUNS, c.names, a.noise, range(1, a.many + 1), noise_ar1=a.rho)
    t2 = time.perf_counter()
    x = np.array([sc.truth[n] for n in c.names])
    sd, sdm = est.std(0, ddof=1) / x, many.std(0, ddof=1) / x
    print(f"{', '.join(RUNS)}; noise {a.noise:g} of RMS, AR(1) {a.rho:g}; relative sd in %; "
          f"ratio = observed sd / predicted identify spread (coloured plan unless marked white)\n")
    print(f"| parameter | white CRLB | white identify | AR(1) CRLB | AR(1) identify | PSD-file identify | "
          f"identify sd (1-{a.seeds}) | ratio | ratio to white | linearised sd (1-{a.many}) | ratio |")
    print("|---" * 11 + "|")
    for j, n in enumerate(c.names):
        print(f"| {n} | {100 * w.rel_crlb[j]:.4f} | {100 * w.rel_identify[j]:.4f} | {100 * c.rel_crlb[j]:.4f} | "
              f"{100 * c.rel_identify[j]:.4f} | {100 * q.rel_identify[j]:.4f} | {100 * sd[j]:.4f} | "
              f"{sd[j] / c.rel_identify[j]:.2f} | {sd[j] / w.rel_identify[j]:.2f} | {100 * sdm[j]:.4f} | "
              f"{sdm[j] / c.rel_identify[j]:.3f} |")
    print(f"\nidentify vs its linearised estimate, seeds 1-{a.seeds}: largest gap "
          f"{(np.abs(est - lin).max(0) / c.std_identify).max():.4f} predicted sd")
    print(f"PSD file vs --noise-ar1: largest relative difference identify "
          f"{np.abs(q.rel_identify / c.rel_identify - 1).max():.4f}, "
          f"CRLB {np.abs(q.rel_crlb / c.rel_crlb - 1).max():.4f}")
    print(f"time: identify {t1 - t0:.0f} s, linearised {t2 - t1:.0f} s")


if __name__ == "__main__":
    main()
