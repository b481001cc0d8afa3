"""Verification on an independent multibody car (MuJoCo), as the paper used ADAMS.

The built-in car and its ten runs are simulated by the MuJoCo car of
:mod:`rideid.verify.hifi` — first in the reduced configuration (the 7-DOF physics in
another engine), then with each property a real car has and the 7-DOF model
lacks switched on alone, then with all of them together (a realistic car) —
and identified by rideid as a user would (noise-free, seed 1, defaults). The
table gives each parameter's error against the scenario's truth, and for the
dampers also against the energy-equivalent linear damping of the simulated
runs (the damping a linear model can see). Also listed: the smallest tire
load and the largest suspension compression over all runs.

Run: ``make verify`` (about 2.5 minutes on 2 cores) or ``python benchmarks/verify_mujoco.py
--out DIR``; writes ``DIR/verification.md`` and ``DIR/verification.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import rideid
from rideid.verify.hifi import HifiProperties, simulate_mujoco
from rideid.model.params import NAMES, as_vector
from rideid.data.scenario import run_times, write_dataset

#: the realistic car: a saloon's CG about 0.55 m above the ground (0.25 m above the wheel centres), a 16-17"
#: wheel and tire (spin inertia 1.0 kg m^2), dampers with 2:1 rebound:compression and a digressive knee at
#: 0.15 m/s (slope x 0.5 above it), bump stops engaging after 60 mm of compression (50 kN/m), tire damping
#: 150 N s/m
REALISTIC = dict(cg_height=0.25, wheel_inertia=1.0, damper_rebound_ratio=2.0, damper_knee_velocity=0.15,
                 damper_knee_ratio=0.5, bumpstop_clearance=0.06, bumpstop_rate=50e3, tire_damping=150.0)

CONFIGS = [
    ("reduced (7-DOF physics)", {}),
    ("CG 0.25 m above wheel centres", {"cg_height": REALISTIC["cg_height"]}),
    ("wheel spin inertia 1.0 kg m²", {"wheel_inertia": REALISTIC["wheel_inertia"]}),
    ("dampers 2:1 rebound:compression", {"damper_rebound_ratio": REALISTIC["damper_rebound_ratio"]}),
    ("dampers digressive above 0.15 m/s", {k: REALISTIC[k] for k in ("damper_knee_velocity", "damper_knee_ratio")}),
    ("bump stops at 60 mm, 50 kN/m", {k: REALISTIC[k] for k in ("bumpstop_clearance", "bumpstop_rate")}),
    ("tire damping 150 N s/m", {"tire_damping": REALISTIC["tire_damping"]}),
    ("all together (realistic car)", REALISTIC),
    ("all together, without W_H (lift-off)", dict(REALISTIC, drop=["W_H"])),
]

SHOWN = list(NAMES)


def simulate(sc, hifi: HifiProperties):
    P = as_vector(sc.truth)
    data, details = {}, {}
    for run in sc.runs:
        t = run_times(run)
        res = simulate_mujoco(P, sc.geometry, sc.tracks[run.track], run.speed, t, hifi=hifi, details=True)
        data[run.id] = (t, res.y)
        details[run.id] = res
    return data, details


def main(argv=None, out=sys.stdout):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench-out/verify", metavar="DIR")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--only", type=int, nargs="*", help="indices of CONFIGS to run (default all)")
    a = ap.parse_args(argv)

    def say(*x):
        print(*x, file=out, flush=True)

    sc = rideid.default_scenario()
    truth = sc.truth
    rows = []
    configs = [CONFIGS[i] for i in a.only] if a.only else CONFIGS
    full = sc
    for label, kw in configs:
        kw = dict(kw)
        drop = kw.pop("drop", [])
        sc = dataclasses.replace(full, runs=[r for r in full.runs if r.id not in drop])
        hifi = HifiProperties(**kw)
        t0 = time.perf_counter()
        data, det = simulate(sc, hifi)
        t_sim = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as tmp:
            write_dataset(sc, data, Path(tmp) / "ds")
            ds = rideid.load_dataset(Path(tmp) / "ds")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                res = rideid.identify(ds, seed=a.seed)
                t_id = time.perf_counter() - t0
        est = res.parameters
        err = {n: 100 * (est[n] / truth[n] - 1) for n in NAMES}
        # energy-equivalent linear damping over all runs, per axle
        work = sum(d.damper_work for d in det.values())
        v2 = sum(d.damper_v2 for d in det.values())
        c_eq = {"c_sf": float((work[0] + work[1]) / (v2[0] + v2[1])),
                "c_sr": float((work[2] + work[3]) / (v2[2] + v2[3]))}
        err_eq = {k: 100 * (est[k] / v - 1) for k, v in c_eq.items()}
        # what a linear model can see: the wheels' swing about the CG and their spin inertia in I_xx, I_yy;
        # the energy-equivalent dampers
        swing = 2 * (truth["m_uf"] + truth["m_ur"]) * hifi.cg_height ** 2
        iw = 2 * (hifi.wheel_inertia[0] + hifi.wheel_inertia[1])  # 4 thin discs: I_w each in pitch, I_w/2 in roll
        effective = dict(truth, I_xx=truth["I_xx"] + swing + iw / 2, I_yy=truth["I_yy"] + swing + iw, **c_eq)
        err_eff = {n: 100 * (est[n] / effective[n] - 1) for n in NAMES}
        load_min = min(float(d.tire_load_min.min()) for d in det.values())
        lifted = sorted(rid for rid, d in det.items() if np.isfinite(d.lift_time).any())
        travel = max(float(d.travel_max.max()) for d in det.values())
        row = {"config": label, "hifi": hifi.to_table(), "runs_left_out": drop, "error_pct": err,
               "error_vs_effective_pct": err_eff, "effective": effective,
               "c_eq": c_eq, "error_vs_c_eq_pct": err_eq,
               "largest_error_pct": max(abs(v) for v in err.values()),
               "largest_error_vs_effective_pct": max(abs(v) for v in err_eff.values()),
               "min_tire_load_N": load_min, "lift_off_runs": lifted, "max_compression_m": travel,
               "cost": float(res.cost), "simulate_s": t_sim, "identify_s": t_id}
        rows.append(row)
        say(f"{label:<38} largest |error| {row['largest_error_pct']:6.2f} % (vs effective "
            f"{row['largest_error_vs_effective_pct']:5.2f} %) "
            f"(c_eq {c_eq['c_sf']:.0f}/{c_eq['c_sr']:.0f} N s/m; min tire load {load_min:.0f} N; "
            f"lift-off {', '.join(lifted) or 'none'}; max compression {1000 * travel:.0f} mm; "
            f"sim {t_sim:.1f} s, identify {t_id:.1f} s)")

    outdir = Path(a.out)
    outdir.mkdir(parents=True, exist_ok=True)
    (outdir / "verification.json").write_text(json.dumps(rows, indent=1))
    head = "| configuration | " + " | ".join(SHOWN) + " |"
    lines = [head, "|" + "---|" * (len(SHOWN) + 1)]
    for r in rows:
        cells = [f"{r['error_pct'][n]:+.2f}" for n in SHOWN]
        lines.append(f"| {r['config']} | " + " | ".join(cells) + " |")
    lines += ["", "Against the effective values a linear model can see (I_xx, I_yy with the wheels' swing and spin "
              "inertia; c_sf, c_sr the energy-equivalent damping):", "", head, lines[1]]
    for r in rows:
        cells = [f"{r['error_vs_effective_pct'][n]:+.2f}" for n in SHOWN]
        lines.append(f"| {r['config']} | " + " | ".join(cells) + " |")
    lines += ["", "| configuration | c_eq front / rear (N s/m) | c_sf, c_sr error vs c_eq (%) | min tire load (N) | "
              "lift-off | max compression (mm) |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['config']} | {r['c_eq']['c_sf']:.0f} / {r['c_eq']['c_sr']:.0f} | "
                     f"{r['error_vs_c_eq_pct']['c_sf']:+.2f}, {r['error_vs_c_eq_pct']['c_sr']:+.2f} | "
                     f"{r['min_tire_load_N']:.0f} | {', '.join(r['lift_off_runs']) or 'none'} | "
                     f"{1000 * r['max_compression_m']:.0f} |")
    text = "\n".join(lines) + "\n"
    (outdir / "verification.md").write_text(text)
    say("")
    say("errors against the scenario's truth, % (m_s derived from total_mass):")
    say(text)
    say(f"written to {outdir}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
