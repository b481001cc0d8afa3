"""Verification on an independent multibody car (MuJoCo), as the paper used ADAMS.

The built-in car and its ten runs are simulated by the MuJoCo car of
:mod:`rideid.verify.hifi` — first in the reduced configuration (the 7-DOF physics in
another engine), then with each property a real car has switched on alone:
those the twelve-parameter model lacks and no extension describes (CG height,
wheel spin inertia, asymmetric and digressive dampers, bump stops) and those
the extended model of SPEC section 6 describes (tire damping, anti-roll bars,
both), then all together (a realistic car with bars and tire damping). Each
dataset (1 % white sensor noise, seed 1) is identified by rideid as a user
would with ``--model auto`` and with the base and the full model. Per fit: each
parameter's error against the scenario's truth (and against the effective
values a linear model can see: inertias with the wheels' swing and spin,
energy-equivalent linear damping), the extension estimates, the adequacy
verdict, and how many truths lie within ±2 std and ±2 std_robust. Also
listed: the smallest tire load and the largest suspension compression.

The base and full fits are polished from ``--model auto``'s candidates of the
same name (auto searches once, on the full model, and polishes the nested
models from its estimate), so each has its own std, std_robust and verdict.

Run: ``make verify`` (about 15 minutes on an idle machine) or ``python benchmarks/verify_mujoco.py
--out DIR [--only I ...] [--noise F] [--seed N]``; writes ``DIR/verification.md`` and
``DIR/verification.json``.
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
from rideid.verify.hifi import HifiProperties, hifi_curve, simulate_mujoco
from rideid.estimate.problem.cost import ParameterSpace
from rideid.model.params import EXT_NAMES, NAMES, SUSPENSION_GROUPS, as_vector
from rideid.data.scenario import run_times
from rideid.synth.scenario import write_dataset

#: the realistic car: a saloon's CG about 0.55 m above the ground (0.25 m above the wheel centres), a 16-17"
#: wheel and tire (spin inertia 1.0 kg m^2), dampers with 2:1 rebound:compression and a digressive knee at
#: 0.15 m/s (slope x 0.5 above it), bump stops engaging after 60 mm of compression (50 kN/m)
REALISTIC = dict(cg_height=0.25, wheel_inertia=1.0, damper_rebound_ratio=2.0, damper_knee_velocity=0.15,
                 damper_knee_ratio=0.5, bumpstop_clearance=0.06, bumpstop_rate=50e3)
#: ... with anti-roll bars (front 15 kN/m, rear 6 kN/m at the wheel) and tire damping (150 N s/m per tire),
#: which the extended model (SPEC section 6) describes; they go into the scenario's [truth]
BARS = {"k_arf": 15e3, "k_arr": 6e3}
#: ... an engine on mounts (SPEC section 11, the issue's): 180 kg, 1.2 m ahead of the CG, 12 kg m^2 about its
#: own CG, 10.5 Hz bounce and 13 Hz pitch on its mounts with the body held, 10 % damping; an engine body of
#: its own in the MuJoCo car, the group `powertrain` in rideid's model
POWERTRAIN = {"m_p": 180.0, "x_p": 1.2, "I_p": 12.0, "f_pb": 10.5, "zeta_pb": 0.1, "f_pp": 13.0, "zeta_pp": 0.1}
TIRE_DAMPING = {"c_tf": 150.0, "c_tr": 150.0}

CONFIGS = [
    ("reduced (7-DOF physics)", {}),
    ("CG 0.25 m above wheel centres", {"cg_height": REALISTIC["cg_height"]}),
    ("wheel spin inertia 1.0 kg m²", {"wheel_inertia": REALISTIC["wheel_inertia"]}),
    ("dampers 2:1 rebound:compression", {"damper_rebound_ratio": REALISTIC["damper_rebound_ratio"]}),
    ("dampers digressive above 0.15 m/s", {k: REALISTIC[k] for k in ("damper_knee_velocity", "damper_knee_ratio")}),
    ("bump stops at 60 mm, 50 kN/m", {k: REALISTIC[k] for k in ("bumpstop_clearance", "bumpstop_rate")}),
    ("tire damping 150 N s/m", {"truth": TIRE_DAMPING}),
    ("anti-roll bars 15/6 kN/m", {"truth": BARS}),
    ("bars + tire damping", {"truth": {**BARS, **TIRE_DAMPING}}),
    ("realistic car (all + bars + tire damping)", dict(REALISTIC, truth={**BARS, **TIRE_DAMPING})),
    ("powertrain 180 kg on mounts, 10.5/13 Hz", {"truth": POWERTRAIN}),
]

SHOWN = list(NAMES)
#: the model fits of every row: what `rideid identify --model base|full|auto` would return
MODELS = ("base", "full", "auto")
#: parameter groups of the summary table
PARTS = {"mass, inertia, CG": ("m_s", "I_xx", "I_yy", "a", "m_uf", "m_ur"),
         "suspension": ("k_sf", "k_sr", "c_sf", "c_sr"), "tires": ("k_tf", "k_tr")}


def simulate(sc, hifi: HifiProperties, noise: float, rng):
    P = as_vector(sc.truth)
    data, details = {}, {}
    for run in sc.runs:
        t = run_times(run)
        res = simulate_mujoco(P, sc.geometry, sc.tracks[run.track], run.speed, t, hifi=hifi, details=True)
        y = res.y
        if noise > 0:  # white sensor noise, noise x each channel's RMS (as `rideid simulate --noise`)
            y = y + rng.standard_normal(y.shape) * (noise * np.sqrt(np.mean(y * y, axis=0)))[None, :]
        data[run.id] = (t, y)
        details[run.id] = res
    return data, details


def free_names(ds, extensions):
    """The free parameters (``identify``'s ``start`` order) of the model with these extension groups."""
    return list(ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=tuple(extensions)).names)


def curve_errors(dampers, truth, hifi):
    """Per axle: the fitted knot forces against the MuJoCo car's damper at the same knots (% of the true
    force), and whether each knot was excited."""
    v = np.asarray(dampers["velocity"], dtype=float)
    out = {}
    for k, (axle, c) in enumerate((("front", "c_sf"), ("rear", "c_sr"))):
        F_true = hifi_curve(truth[c], v, hifi.damper_rebound_ratio[k], hifi.damper_knee_velocity[k],
                            hifi.damper_knee_ratio[k])
        F = np.asarray(dampers[axle]["force"], dtype=float)
        sr = np.array([np.nan if x is None else x for x in dampers[axle]["std_robust"]], dtype=float)
        out[axle] = {"truth": F_true.tolist(), "estimate": F.tolist(),
                     "error_pct": (100 * (F / F_true - 1)).tolist(), "excited": list(dampers[axle]["excited"]),
                     "z_std_robust": ((F - F_true) / sr).tolist()}
    return out


def stop_errors(stops, hifi):
    """Per axle reached by the fit: clearance and rate against the MuJoCo car's, with z against std_robust."""
    out = {}
    for k, axle in enumerate(("front", "rear")):
        st = (stops or {}).get(axle) or {}
        if not st.get("reached"):
            out[axle] = {"reached": False}
            continue
        true = (hifi.bumpstop_clearance[k], hifi.bumpstop_rate[k])
        got = (st["clearance"], st["rate"])
        sr = st.get("std_robust") or [None, None]
        out[axle] = {"reached": True, "truth": true, "estimate": got,
                     "error_pct": [100 * (g / t - 1) for g, t in zip(got, true)],
                     "z_std_robust": [(g - t) / s if s else None for g, t, s in zip(got, true, sr)]}
    return out


def fit_record(res, truth, extensions):
    """Errors, coverage and verdict of one fit against the truth."""
    est = res.parameters
    err = {n: 100 * (est[n] / truth[n] - 1) for n in NAMES}
    ext = {n: {"estimate": float(est.get(n, 0.0)), "truth": float(truth.get(n, 0.0))} for n in EXT_NAMES}
    cover = {}
    for n, d in res.details.items():
        if d.get("fixed") or d.get("derived") or n not in truth:
            continue  # knot forces and bump stops: against the MuJoCo car's own (curve_errors, stop_errors)
        miss = abs(est[n] - truth.get(n, 0.0))
        cover[n] = {"std": bool(miss <= 2 * d["std"]) if d.get("std") is not None else None,
                    "std_robust": bool(miss <= 2 * d["std_robust"]) if d.get("std_robust") is not None else None,
                    "z_std": float(miss / d["std"]) if d.get("std") else None,
                    "z_std_robust": float(miss / d["std_robust"]) if d.get("std_robust") else None,
                    # the sandwich's share alone, without the runs' disagreement (std_between_runs)
                    "std_hac": (bool(miss <= 2 * d.get("std_hac", d["std_robust"]))
                                if d.get("std_robust") is not None else None),
                    "between_runs": bool(d.get("std_between_runs"))}
    part = {g: max(abs(err[n]) for n in ns) for g, ns in PARTS.items()}
    return {"extensions": list(extensions), "error_pct": err, "extension_values": ext,
            "largest_error_pct": max(abs(v) for v in err.values()), "largest_error_by_part_pct": part,
            "covered_std": sum(bool(c["std"]) for c in cover.values()),
            "covered_std_robust": sum(bool(c["std_robust"]) for c in cover.values()),
            "covered_std_hac": sum(bool(c["std_hac"]) for c in cover.values()),
            "between_runs": sum(c["between_runs"] for c in cover.values()),
            "estimated": len(cover), "coverage": cover,
            "adequate": (res.adequacy or {}).get("adequate"),
            "dampers": None if res.dampers is None else res.dampers.to_dict(),
            "bump_stops": None if getattr(res, "bump_stops", None) is None else res.bump_stops.to_dict(),
            "adequacy_reasons": (res.adequacy or {}).get("reasons"), "cost": float(res.cost)}


def identify_models(ds, seed, truth):
    """`--model auto` (one search on the full model, nested polishes), then base and full as
    fits of their own polished from auto's candidates (white std, std_robust and adequacy of each)."""
    t0 = time.perf_counter()
    auto = rideid.identify(ds, seed=seed, model="auto")
    t_auto = time.perf_counter() - t0
    cands = {tuple(sorted(c["extensions"])): c for c in auto.model["candidates"]}
    fits = {"auto": fit_record(auto, truth, auto.model["extensions"])}
    fits["auto"]["candidates"] = [{k: c[k] for k in ("extensions", "cost", "criterion", "wald")}
                                  for c in auto.model["candidates"]]
    for m, ext in (("base", ()), ("full", tuple(SUSPENSION_GROUPS))):
        c = cands[tuple(sorted(ext))]
        x0 = [c["parameters"][n] for n in free_names(ds, ext)]
        # auto's maps are those of the model it kept: a kept curve model has no bars' or tire damping's rows
        names = free_names(ds, ext)
        maps = auto.maps if all(n in auto.maps.params for n in names) else None
        res = rideid.identify(ds, seed=seed, model=m, start=x0, maps=maps)
        fits[m] = fit_record(res, truth, ext)
    if truth.get("m_p", 0.0) > 0:  # a car with a powertrain: also `--model powertrain`, and its modes
        res = rideid.identify(ds, seed=seed, model=("powertrain",))
        fits["powertrain"] = fit_record(res, truth, ("powertrain",))
        for f, r in ((fits["powertrain"], res), (fits["auto"], auto)):
            fit, true = rideid.modal_summary(r.parameters, ds.geometry), rideid.modal_summary(truth, ds.geometry)
            f["powertrain_modes_error_pct"] = {m: 100 * (fit[m]["frequency_hz"] / true[m]["frequency_hz"] - 1)
                                               for m in ("powertrain bounce", "powertrain pitch") if m in fit}
    return fits, time.perf_counter() - t0, t_auto


def main(argv=None, out=sys.stdout):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench-out/verify", metavar="DIR")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--noise", type=float, default=0.01, help="white sensor noise, fraction of each channel's RMS")
    ap.add_argument("--only", type=int, nargs="*", help="indices of CONFIGS to run (default all)")
    ap.add_argument("--cg-unknown", dest="cg_declared", action="store_false",
                    help="leave [vehicle] cg_height out of the datasets (the model then lacks it)")
    ap.add_argument("--default-knots", dest="knee_knots", action="store_false",
                    help="fit damper curves at the default knots only (not also at the damper's knee velocity)")
    a = ap.parse_args(argv)

    def say(*x):
        print(*x, file=out, flush=True)

    base_sc = rideid.default_scenario()
    outdir = Path(a.out)
    outdir.mkdir(parents=True, exist_ok=True)
    rows = []
    configs = [CONFIGS[i] for i in a.only] if a.only else CONFIGS
    for label, kw in configs:
        kw = dict(kw)
        extra_truth = kw.pop("truth", {})
        truth = dict(base_sc.truth, **extra_truth)
        hifi = HifiProperties(**kw)
        # the CG height is measured (SPEC §8 [vehicle] cg_height): the dataset declares it, so the model
        # includes gravity's toppling stiffness and the wheels' swing, and I_xx, I_yy stay the body's own
        geom = dataclasses.replace(base_sc.geometry, cg_height=hifi.cg_height) if a.cg_declared else base_sc.geometry
        sc = dataclasses.replace(base_sc, truth=truth, geometry=geom)
        knee = min(hifi.damper_knee_velocity)
        if a.knee_knots and np.isfinite(knee):
            # the damper's knee (its valve opening speed, on the data sheet) is one of the knots: a curve
            # through the default knots alone cannot bend there (8 % off at 0.15 m/s between 0.1 and 0.2)
            sc = dataclasses.replace(sc, damper_knots=tuple(sorted({0.025, 0.05, 0.1, 0.2, 0.4, float(knee)})))
        rng = np.random.default_rng(a.seed)
        t0 = time.perf_counter()
        data, det = simulate(sc, hifi, a.noise, rng)
        t_sim = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as tmp:
            write_dataset(sc, data, Path(tmp) / "ds")
            ds = rideid.load_dataset(Path(tmp) / "ds")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fits, t_id, t_auto = identify_models(ds, a.seed, truth)
        # energy-equivalent linear damping over all runs, per axle
        work = sum(d.damper_work for d in det.values())
        v2 = sum(d.damper_v2 for d in det.values())
        c_eq = {"c_sf": float((work[0] + work[1]) / (v2[0] + v2[1])),
                "c_sr": float((work[2] + work[3]) / (v2[2] + v2[3]))}
        # what a linear model can see: the wheels' swing about the CG and their spin inertia in I_xx, I_yy;
        # the energy-equivalent dampers
        swing = 0.0 if a.cg_declared else 2 * (truth["m_uf"] + truth["m_ur"]) * hifi.cg_height ** 2
        iw = 2 * (hifi.wheel_inertia[0] + hifi.wheel_inertia[1])  # 4 thin discs: I_w each in pitch, I_w/2 in roll
        effective = dict(truth, I_xx=truth["I_xx"] + swing + iw / 2, I_yy=truth["I_yy"] + swing + iw, **c_eq)
        for f in fits.values():
            if f.get("bump_stops"):
                f["stop_errors"] = stop_errors(f["bump_stops"], hifi)
            if f.get("dampers"):  # a curve fit: against the true curves at its knots, and c_s as their mean slope
                f["curve_errors"] = curve_errors(f["dampers"], truth, hifi)
                f["largest_curve_error_pct"] = max((abs(e) for ax in f["curve_errors"].values()
                                                    for e, x in zip(ax["error_pct"], ax["excited"]) if x),
                                                   default=float("nan"))
            eff = dict(effective)
            if f.get("dampers"):  # a curve fit's c_sf, c_sr are the curves' mean slope over +-0.1 m/s: the truth's
                for k, c in enumerate(("c_sf", "c_sr")):
                    F = hifi_curve(truth[c], np.array([-0.1, 0.1]), hifi.damper_rebound_ratio[k],
                                   hifi.damper_knee_velocity[k], hifi.damper_knee_ratio[k])
                    eff[c] = float((F[1] - F[0]) / 0.2)
            f["error_vs_effective_pct"] = {n: 100 * (f["error_pct"][n] / 100 + 1) * truth[n] / eff[n] - 100
                                           for n in NAMES}
            f["largest_error_vs_effective_pct"] = max(abs(v) for v in f["error_vs_effective_pct"].values())
        load_min = min(float(d.tire_load_min.min()) for d in det.values())
        lifted = sorted(rid for rid, d in det.items() if np.isfinite(d.lift_time).any())
        travel = max(float(d.travel_max.max()) for d in det.values())
        row = {"config": label, "hifi": hifi.to_table(), "truth_extensions": extra_truth, "noise": a.noise,
               "fits": fits, "effective": effective, "c_eq": c_eq,
               "min_tire_load_N": load_min, "lift_off_runs": lifted, "max_compression_m": travel,
               "simulate_s": t_sim, "identify_s": t_id, "identify_auto_s": t_auto}
        rows.append(row)
        (outdir / "verification.json").write_text(json.dumps(rows, indent=1))  # each row as it is done
        say(f"{label:<42} " + "; ".join(
            f"{m} {f['largest_error_pct']:.2f} % (eff {f['largest_error_vs_effective_pct']:.2f} %), "
            f"{'adequate' if f['adequate'] else 'NOT adequate'}, 2std {f['covered_std']}/{f['estimated']}, "
            f"2std_robust {f['covered_std_robust']}/{f['estimated']}" for m, f in fits.items())
            + f"; auto chose [{', '.join(fits['auto']['extensions']) or 'base'}] "
            + "".join(f"({m}: powertrain modes "
                      + ", ".join(f"{k} {v:+.2f} %" for k, v in f["powertrain_modes_error_pct"].items()) + ") "
                      for m, f in fits.items() if f.get("powertrain_modes_error_pct"))
            + (f"(curves within {fits['auto']['largest_curve_error_pct']:.2f} % at the excited knots) "
               if fits["auto"].get("curve_errors") else "")
            + f"(lift-off {', '.join(lifted) or 'none'}; max compression {1000 * travel:.0f} mm; "
            f"sim {t_sim:.0f} s, identify {t_id:.0f} s)")

    text = tables(rows)
    (outdir / "verification.md").write_text(text)
    say("")
    say(f"errors against the scenario's truth, % (m_s derived from total_mass; {100 * a.noise:g} % white noise, "
        f"seed {a.seed}):")
    say(text)
    say(f"written to {outdir}")
    return 0


def _ext(f):
    v = f["extension_values"]
    return (f"{v['k_arf']['estimate'] / 1e3:.1f}/{v['k_arr']['estimate'] / 1e3:.1f}",
            f"{v['c_tf']['estimate']:.0f}/{v['c_tr']['estimate']:.0f}")


def _median_z(f, key):
    z = [c[key] for c in f["coverage"].values() if c[key] is not None]
    return float(np.median(z)) if z else float("nan")


def tables(rows) -> str:
    """The study's tables (markdown)."""
    head = "| configuration | model | " + " | ".join(SHOWN) + " |"
    sep = "|" + "---|" * (len(SHOWN) + 2)
    lines = [head, sep]
    for r in rows:
        for m in ("base", "full"):
            f = r["fits"][m]
            lines.append(f"| {r['config']} | {m} | " + " | ".join(f"{f['error_pct'][n]:+.2f}" for n in SHOWN) + " |")
    lines += ["", "Summary per fit: largest |error| (%) per part of the twelve (against the truth; in brackets "
              "against the effective values a linear model can see), the extension estimates (truth in the "
              "configuration's name, else 0), auto's choice, the adequacy verdict, and how many of the estimated "
              "parameters' truths lie within ±2 std and ±2 std_robust, with the median of |error| / std and "
              "|error| / std_robust over them:", "",
              "| configuration | model | mass, inertia, CG | suspension | tires | largest (vs effective) | "
              "k_arf/k_arr (kN/m) | c_tf/c_tr (N s/m) | adequate | ±2 std | ±2 std_robust | median z std, robust |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for m in MODELS:
            f = r["fits"][m]
            p = f["largest_error_by_part_pct"]
            bars, td = _ext(f)
            name = m if m != "auto" else f"auto → {'+'.join(f['extensions']) or 'base'}"
            lines.append(f"| {r['config']} | {name} | {p['mass, inertia, CG']:.2f} | {p['suspension']:.2f} | "
                         f"{p['tires']:.2f} | {f['largest_error_pct']:.2f} "
                         f"({f['largest_error_vs_effective_pct']:.2f}) | "
                         f"{bars} | {td} | {'yes' if f['adequate'] else 'no'} | "
                         f"{f['covered_std']}/{f['estimated']} | {f['covered_std_robust']}/{f['estimated']} | "
                         f"{_median_z(f, 'z_std'):.1f}, {_median_z(f, 'z_std_robust'):.1f} |")
    lines += ["", "| configuration | c_eq front / rear (N s/m) | min tire load (N) | lift-off | max compression (mm) |",
              "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['config']} | {r['c_eq']['c_sf']:.0f} / {r['c_eq']['c_sr']:.0f} | "
                     f"{r['min_tire_load_N']:.0f} | {', '.join(r['lift_off_runs']) or 'none'} | "
                     f"{1000 * r['max_compression_m']:.0f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
