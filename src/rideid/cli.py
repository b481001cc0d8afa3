"""The ``rideid`` command line (SPEC §4). Only calls the public library API.

Exit codes: 0 success, 2 bad input (one line on stderr naming the file, key
or column), 1 internal error (a bug: set ``RIDEID_DEBUG=1`` for the traceback).
"""

from __future__ import annotations

import argparse
import os
import sys
import textwrap
import threading
import time
import traceback
import warnings
from pathlib import Path

import rideid

EXAMPLES = {
    "simulate": "example:\n  rideid simulate scenario.toml --out sim --noise 0.02 --seed 1",
    "identify": "example:\n  rideid identify sim --out fit --seed 1\n  rideid identify sim --out fit-fixed "
                "--weights fixed --no-polish",
    "sensitivity": "example:\n  rideid sensitivity sim --out maps\n  rideid sensitivity scenario.toml --out maps",
    "score": "example:\n  rideid score fit/result.json sim/truth.toml",
    "demo": "example:\n  rideid demo --out rideid-demo",
    "plan": "example:\n  rideid plan scenario.toml --out plan --noise 0.01 --budget-runs 4\n"
            "  rideid plan catalogue.toml --out plan --budget-time 600 --overhead 90 --robust 8\n"
            "  rideid plan catalogue.toml --out plan --target k_sr=0.5% --target I_xx=2%\n"
            "  rideid plan scenario.toml --out plan --noise 0.02 --noise-ar1 0.9\n"
            "  rideid plan scenario.toml --out plan --noise-psd sensor_noise_psd.csv",
    "report": "example:\n  rideid report fit\n  rideid identify sim --out fit-fixed --weights fixed --no-report\n"
              "  rideid report fit --compare fit-fixed",
    "export": "example:\n  rideid export fit --out car\n  rideid export fit --out car --format fmu",
    "study": "example:\n  rideid study monte_carlo.toml --out mc\n"
             "  rideid study fleet.toml --out fleet --scheduler tcp://10.0.0.5:8786\n"
             "a killed study resumes: run the same command again (finished tasks are kept in DIR/tasks)",
}


class _Version(argparse.Action):
    """``--version``: the installed version, looked up only when asked (reading the package metadata costs
    more than building the whole parser)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"rideid {rideid.__version__}")  # on stdout, as argparse's own version action
        parser.exit()


class Progress:
    """A live progress line on stderr (only on a terminal, unless quiet).

    The line ends in no newline (it is redrawn in place), so anything else
    written to the terminal while it shows would continue it; every message
    goes through :func:`say`, which clears it first (the next update redraws it).
    """

    #: the progress line on the terminal now, if any
    showing = None

    def __init__(self, quiet: bool = False, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = not quiet and hasattr(self.stream, "isatty") and self.stream.isatty()
        self._last = 0.0
        self._width = 0

    def line(self, text: str, force: bool = False):
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < 0.1:
            return
        self._last = now
        pad = max(0, self._width - len(text))
        self.stream.write("\r" + text + " " * pad)
        self.stream.flush()
        self._width = len(text)
        Progress.showing = self

    def done(self):
        if self.enabled and self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
            self._width = 0
        if Progress.showing is self:
            Progress.showing = None

    def identify(self, state):
        """The :func:`rideid.identify` callback: one line per generation (never stops the run)."""
        g, G = state.nit, state.generations
        el = state.elapsed
        rate = state.nfev / el if el > 0 else 0.0
        left = el / g * (G - g) if g else 0.0
        self.line(f"generation {g}/{G}  best {state.fun:.3e}  largest spread {state.spread:.2e}  "
                  f"{rate:,.0f} eval/s  at most {left:.0f} s left")
        return False

    def steps(self, i, n, label):
        self.line(f"{label} {i}/{n}", force=i == n)

    def study(self, info):
        eta = "" if info["eta"] is None else f"  ETA {info['eta']:.0f} s"
        failed = f"  {info['failed']} failed" if info["failed"] else ""
        resumed = f"  ({info['resumed']} from an earlier run)" if info["resumed"] else ""
        self.line(f"tasks {info['done'] + info['failed']}/{info['total']} finished{failed}{resumed}  "
                  f"{info['elapsed']:.0f} s{eta}", force=info["running"] == 0)


def say(text: str) -> None:
    """One message line on stderr, on a line of its own (a progress line showing is cleared first)."""
    if Progress.showing is not None:
        Progress.showing.done()
    sys.stderr.write(text + "\n")
    sys.stderr.flush()


def _warning_line(message, category, filename, lineno, file=None, line=None):
    say(f"rideid: warning: {message}")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rideid",
        description="Estimate a car's ride parameters (sprung mass, inertias, CG, unsprung masses, "
                    "suspension and tire rates, damping) from accelerometer and gyro signals on test tracks.",
        epilog="exit codes: 0 ok, 2 bad input, 1 internal error\n"
               "example:\n  rideid demo\n  rideid simulate scenario.toml --out sim && rideid identify sim --out fit",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action=_Version, nargs=0, help="show the version and exit")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    def add(name, help_, source=None, out=None):
        """Subcommand ``name`` with --quiet, its input ``source`` = (argument, metavar, help) and a required
        ``--out DIR`` (help ``out``) when given."""
        # help_ as printed: the command list's help is %-formatted by argparse, the description is not
        s = sub.add_parser(name, help=help_.replace("%", "%%"), description=help_, epilog=EXAMPLES[name],
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        s.add_argument("--quiet", action="store_true", help="no progress line and no compile notice")
        if source is not None:
            argument, metavar, source_help = source
            s.add_argument(argument, metavar=metavar, help=source_help)
        if out is not None:
            s.add_argument("--out", required=True, metavar="DIR", help=out)
        return s

    s = add("simulate", "simulate a scenario (truth + tracks + runs) into a dataset folder",
            ("scenario", "SCENARIO.toml", "the scenario: [truth], [vehicle], [known], tracks and runs with fs and "
                                          "duration; 'builtin' for the built-in car and the paper's ten runs"),
            out="dataset folder to write (dataset.toml, runs/*.csv, truth.toml)")
    s.add_argument("--noise", type=float, default=0.0, metavar="FRACTION",
                   help="white Gaussian noise, standard deviation as a fraction of each channel's RMS")
    s.add_argument("--noise-ar1", type=float, default=0.0, metavar="RHO",
                   help="colour the noise: AR(1) in time with this coefficient per sample (0 <= RHO < 1; "
                        "same standard deviation), as real sensors' noise is")
    s.add_argument("--seed", type=int, default=None, metavar="N",
                   help="seed of the noise (default: a fresh one each time)")
    s.add_argument("--engine", choices=("rideid", "mujoco"), default="rideid",
                   help="rideid's exact 7-DOF response (default), or the independent MuJoCo multibody car "
                        "with the scenario's [hifi] properties (needs: pip install 'rideid[hifi]'; "
                        "sample rates must divide 1 kHz)")
    s.add_argument("--raw", action="store_true",
                   help="with --engine mujoco: write the sensors' own readings (gravity included, "
                        "1 s standing still first) as a logger would, mapped for the measured-data pipeline")

    s = add("identify", "estimate the ride parameters of a dataset (the twelve, plus anti-roll bars, tire damping, "
                        "damper curves, bump stops and a powertrain on mounts when the model has them)",
            ("dataset", "DATASET_DIR", "dataset folder (or its dataset.toml)"),
            out="output folder: result.json, history.csv, report.html, figures/ (rideid's files from "
                "an earlier identification there are replaced; other files stay)")
    s.add_argument("--seed", type=int, default=None, metavar="N",
                   help="seed of the search (same seed, same result; default: a fresh one each time)")
    s.add_argument("--population", type=int, default=None, metavar="NP", help="JADE population (default 32)")
    s.add_argument("--generations", type=int, default=None, metavar="G",
                   help="largest number of JADE generations (default 400)")
    s.add_argument("--weights", choices=("adaptive", "fixed"), default="adaptive",
                   help="adaptive track weights (paper eq. 12-13) or equal weights")
    s.add_argument("--no-polish", action="store_true", help="skip the least-squares polish after JADE")
    s.add_argument("--model", default=None, metavar="MODEL",
                   help="base: the twelve parameters; full: with anti-roll bars (k_arf, k_arr) and tire damping "
                        "(c_tf, c_tr); auto: fit the candidates and keep what the data support (docs/model-choice.md); "
                        "or groups joined by ',': anti_roll_bars, tire_damping, "
                        "damper_curves (SPEC §8: a force-velocity "
                        "curve per axle at the [model] damper_knots, else on a knee grid with the knees found: "
                        "docs/dampers.md), bump_stops (clearance and rate per axle) "
                        "(default: the dataset's [model] extensions, else auto)")
    s.add_argument("--tracks", choices=("as-built", "as-drawn"), default="as-built",
                   help="as-built (default): each [[tracks]] entry is the nominal shape, its amplitude factor and "
                        "unevenness fitted with the car (SPEC §11, docs/tracks-as-built.md); as-drawn: every track "
                        "exactly as declared")
    s.add_argument("--no-report", action="store_true", help="write result.json and history.csv only")
    s.add_argument("--profile", action="store_true",
                   help="print where the time went (each stage's wall and CPU time) and write it to profile.csv")

    s = add("report", "(re)build report.html in an identification folder")
    s.add_argument("result_dir", metavar="RESULT_DIR", help="an identification folder (result.json, history.csv)")
    s.add_argument("--compare", metavar="OTHER_DIR",
                   help="another identification of the same dataset (e.g. --weights fixed) to overlay")

    s = add("sensitivity", "parameter/response/track sensitivity maps (paper Tables 4-7) as CSV, Markdown, PNG",
            ("source", "DATASET_OR_SCENARIO", "a dataset folder or a scenario file ('builtin': the built-in scenario)"),
            out="output folder: tables.md, three CSV and three PNG maps")

    s = add("study", "many identifications (Monte Carlo, fleet, run subsets) on Dask; resumable",
            ("study", "STUDY.toml",
             "the study: its data, identify options and axes (docs/studies.md; examples/studies/)"),
            out="output folder (tasks/, results.parquet, summary.md/.csv/.html); tasks already "
                "there are not recomputed")
    s.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="a running Dask scheduler, e.g. tcp://host:8786 (default: a local cluster, "
                        "one single-threaded worker process per core)")

    s = add("plan", "plan a test: the precision (CRLB) each candidate run buys, and which runs to drive",
            ("scenario", "SCENARIO.toml", "[truth] = the nominal car, [[runs]] = the candidate runs, [known] = the "
                                          "scale anchor ('builtin': the built-in scenario)"),
            out="output folder: plan.json, plan.md, crlb.csv, path.csv, correlation.csv, precision_path.png")
    s.add_argument("--noise", type=float, default=None, metavar="FRACTION",
                   help="noise sd as a fraction of each channel's RMS, per run (as simulate --noise; "
                        "default 0.01, or 0 when a noise density or --noise-psd is given)")
    s.add_argument("--accel-noise-density", type=float, default=0.0, metavar="D",
                   help="accelerometer noise density, (m/s^2)/sqrt(Hz)")
    s.add_argument("--gyro-noise-density", type=float, default=0.0, metavar="D",
                   help="gyro noise density, (rad/s)/sqrt(Hz)")
    s.add_argument("--bandwidth", type=float, default=None, metavar="HZ",
                   help="logger bandwidth for the densities (default each run's fs/2)")
    s.add_argument("--noise-ar1", type=float, default=0.0, metavar="RHO",
                   help="coloured noise: AR(1) per sample with this coefficient, same RMS (as simulate "
                        "--noise-ar1; default 0: white)")
    s.add_argument("--noise-psd", default=None, metavar="FILE.csv",
                   help="coloured noise with a measured spectrum: columns frequency (Hz) and psd, accel/gyro "
                        "or channel names (one-sided, unit^2/Hz); alone it is the absolute noise, with --noise "
                        "or a density only its shape counts (docs/planning.md)")
    s.add_argument("--budget-runs", type=int, default=None, metavar="N", help="drive at most N runs")
    s.add_argument("--budget-time", type=float, default=None, metavar="S",
                   help="at most S seconds of track time (each run: its duration + --overhead)")
    s.add_argument("--overhead", type=float, default=0.0, metavar="S",
                   help="per-run overhead in seconds (turning round, lining up; default 0)")
    s.add_argument("--criterion", default=None, metavar="D|A|target",
                   help="D-optimal (default), A-optimal, or target (the cheapest runs that reach every --target)")
    s.add_argument("--target", action="append", default=[], metavar="NAME=PREC",
                   help="relative precision to reach on a free parameter, e.g. k_sr=0.5%% (repeatable)")
    s.add_argument("--robust", type=int, default=1, metavar="N",
                   help="plan for the worst of N cars: the nominal one and N-1 sampled in the scenario's "
                        "[bounds] (else +-20%% of nominal)")
    s.add_argument("--seed", type=int, default=0, metavar="N", help="seed of the robust cars' sampling")
    s.add_argument("--within", type=float, default=None, metavar="F",
                   help="without a budget: the fewest runs whose CRLB is within F x that of all runs (default 1.5)")

    s = add("score", "compare an identification result with the truth")
    s.add_argument("result", metavar="RESULT.json", help="an identification's result.json (or its folder)")
    s.add_argument("truth", metavar="TRUTH.toml", help="the truth, e.g. the truth.toml rideid simulate writes "
                                                  "(or the folder that holds it)")

    s = add("export", "the identified car as a parameter card (car.toml, car.csv), its frequency responses (frf.csv) "
            "and an FMI 2.0 FMU (car.fmu)",
            ("fit", "FIT_DIR", "an identification folder (result.json)"),
            out="output folder: car.toml, car.csv, frf.csv, car.fmu")
    s.add_argument("--format", default="all", metavar="card|fmu|all",
                   help="card: car.toml (scenario-ready), car.csv and frf.csv (frequency responses with the std "
                        "of their magnitude); fmu: car.fmu (FMI 2.0 Model Exchange and Co-Simulation, C sources and "
                        "a binary for this platform); all: both (default)")

    s = add("demo", "the whole job on the built-in car and tracks: simulate (1 % noise), identify, score")
    s.add_argument("--out", default="rideid-demo", metavar="DIR",
                   help="output folder: dataset/ and identify/ (default rideid-demo)")
    s.add_argument("--seed", type=int, default=1, metavar="N", help="seed of the noise and the search (default 1)")
    return p


# ---------------------------------------------------------------------------

def cmd_simulate(args, out=None):
    out = out or sys.stdout
    sc = rideid.load_scenario(args.scenario)
    prog = Progress(args.quiet)
    data, lifts = rideid.simulate_manifest(sc, noise=args.noise, seed=args.seed, engine=args.engine, raw=args.raw,
                                    noise_ar1=args.noise_ar1,
                                    progress=lambda i, n, rid: prog.steps(i, n, "simulating run"))
    prog.done()
    engine = args.engine
    if engine == "mujoco":
        engine += (f"; MuJoCo car: {rideid.scenario_properties(sc).describe()}"
                   + ("; raw sensor readings" if args.raw else ""))
    if sc.dampers is not None:
        engine += "; [dampers] curves"
    if sc.bump_stops:
        engine += "; bump stops"
    rideid.write_dataset(sc, data, args.out, raw=args.raw,
                         comment=f"simulated by rideid {rideid.__version__} from {Path(args.scenario).name}"
                                 f" (engine {engine}, noise {args.noise}"
                                 + (f" AR(1) {args.noise_ar1}" if args.noise_ar1 else "") + f", seed {args.seed})")
    print(f"dataset written to {args.out} ({len(sc.runs)} runs)", file=out)
    for lo in lifts:  # a nonlinear car's wheel leaving the road: physics, not a warning (SPEC §8)
        if lo.physics:
            print(f"note: {lo.message()}", file=out)
    print(rideid.format_modal_summary(rideid.modal_summary(sc.truth, sc.geometry)), file=out)
    return 0


def _summary_table(res) -> str:
    lines = [f"{'parameter':<10} {'estimate':>14} {'± std_total':>12} {'± robust':>11} {'± std':>11}  {'unit':<8} note"]
    shape = (res.polish or {}).get("shape")  # a flat valley of the cost: its note beside the number
    for n, d in res.details.items():
        if n.startswith("F_") and res.dampers:
            continue  # the curves' table below
        note = "known" if d["fixed"] else ("derived" if d["derived"] else "")
        if d["derived"] and n in ("c_sf", "c_sr") and res.dampers:
            note = "derived: the curve's mean slope over ±0.1 m/s"
        if d.get("reached") is False and not d["fixed"]:
            note = "NOT REACHED: no run compresses the suspension to the stop — not a number to trust"
        elif d.get("at_bound"):
            note = "AT A SEARCH BOUND: set by the bound, not the data"
        elif d.get("determined") is False:
            note = "NOT DETERMINED: the data do not fix it, no error bar (WARNING below)"
        elif d.get("conditional_on"):
            note = f"CONDITIONAL: on {', '.join(d['conditional_on'])} at a search bound (WARNING below)"
        elif flat := rideid.error_bar_note(shape, n):
            note = flat + " (WARNING below)"
        std = "" if d.get("std") in (None, 0.0) else f"{d['std']:.3g}"
        rob = "" if d.get("std_robust") in (None, 0.0) else f"{d['std_robust']:.3g}"
        tot = d.get("std_total", d.get("std_robust"))
        tot = "" if tot in (None, 0.0) else f"{tot:.3g}"
        lines.append(f"{n:<10} {d['value']:>14.6g} {tot:>12} {rob:>11} {std:>11}  {d['unit']:<8} {note}")
    lines += _budget_lines(res)
    if res.dampers:
        lines.append(rideid.format_dampers(res.dampers))
    if res.bump_stops:
        lines.append(rideid.format_bump_stops(res.bump_stops))
    if res.roads:
        lines.append(_roads_table(res))
    if res.tracks:
        lines.append(_tracks_table(res))
    speeds = None if res.roads else rideid.drawn_speeds_line(res)  # with roads: a line a run in their table
    if speeds:
        lines.append(speeds)
    return "\n".join(lines)


def _tracks_table(res) -> str:
    """The tracks as built (SPEC §11): each track's amplitude factor and unevenness, per run."""
    lines = [f"{'track as built':<18} {'run':<10} {'amplitude':>9} {'± std':>7} {'unevenness mm RMS':>18} "
             f"{'(waves <= 10 m)':>15}"]
    for tid, rec in res.tracks.items():
        for rid, r in rec.get("runs", {}).items():
            if "amplitude_factor" in r:
                sa, us = r.get("amplitude_factor_std", float("nan")), r.get("unevenness_rms_surface_m", float("nan"))
                lines.append(f"{tid:<18} {rid:<10} {r['amplitude_factor']:>9.4f} {sa:>7.4f} "
                             f"{1e3 * r['unevenness_rms_m']:>18.2f} {1e3 * us:>15.2f}")
            else:
                lines.append(f"{tid:<18} {rid:<10} {r['fitted']}")
    moving = [(rid, r["motion"]) for rec in res.tracks.values() for rid, r in rec.get("runs", {}).items()
              if "motion" in r]
    for rid, m in moving:  # each run's speed and start as fitted with the car (SPEC §13)
        lines.append(rideid.motion_line(rid, m))
    rejected = next((rec["rejected"] for rec in res.tracks.values() if rec.get("rejected")), None)
    lines.append("tracks as built REJECTED, the estimates are the tracks' as drawn: " + rejected if rejected else
                 "error bars with tracks as built: the white sandwich of their runs (measured right over five seeds, "
                 "docs/tracks-as-built.md)" + ("; the runs' speeds and starts in them (each estimate's budget: "
                                               "'speed and start')" if any("speed_std_m_s" in m for _, m in moving)
                                               else ""))
    return "\n".join(lines)


def _budget_lines(res) -> list[str]:
    """Under the table (SPEC §12): what std_total holds, the anchor taken as exact, what was not propagated."""
    unc = res.uncertainty or {}
    declared = list(unc.get("declared") or {})
    out = []
    if declared:
        out.append("std_total: std_robust with the declared uncertainties of " + ", ".join(declared)
                   + " (each estimate's budget in result.json)")
    return out + [f"NOTE: {n}" for n in unc.get("notes", [])]


def _roads_table(res) -> str:
    """The unknown-road runs (SPEC §9): each road's ISO 8608 class and file, and what is not assessed."""
    lines = [f"{'road run':<12} {'class':>5} {'Gd(n0) m^3':>11} {'speed m/s':>10}  estimated road"]
    for rid, r in res.roads.items():
        lines.append(f"{rid:<12} {r['iso8608_class']:>5} {r['gd_n0']:>11.3g} {r['speed']:>10.4g}  {r['file']} "
                     f"({r['wavelengths_m'][0]:g}-{r['wavelengths_m'][1]:g} m wavelengths)")
    for rid, r in res.roads.items():
        lines += [f"{rid}: {c} {why}" for c, why in (r.get("channels_left_out") or {}).items()]
    # each road run's speed as fitted with the car (SPEC §13: the rear wheels' delay)
    lines += [rideid.motion_line(rid, r["motion"]) for rid, r in res.roads.items() if "motion" in r]
    # a run on a track as drawn whose speed was estimated with the car
    lines += [rideid.drawn_motion_line(rid, m) for rid, m in rideid.drawn_motions(res).items()]
    judged = res.assessment("roads")  # each road run's residual at its own road estimate
    if judged.verdict != "not assessed":
        lines.append(("ROAD RUNS FAIL: " if judged.verdict == "fail" else "road runs: ") + judged.reason)
    if judged.verdict != "fail" and (not res.adequacy or not res.adequacy.get("runs")):
        what = "RESIDUALS" if res.adequacy else "ADEQUACY"  # a verdict from the sensor check alone, or none
        lines.append(f"{what} NOT FULLY ASSESSED: every run is on an unknown road, where rideid judges only the "
                     "residual's size (a car far off), not its structure; the error bars hold only if the model "
                     "describes the car (add a known-track run to test it)" if judged.verdict == "pass" else
                     f"{what} NOT ASSESSED: every run is on an unknown road, where rideid has no residual test yet; "
                     "the error bars hold only if the model describes the car (add a known-track run to "
                     "test it)")
    elif judged.verdict == "not assessed":
        lines.append("the adequacy verdict covers the known-track runs only; the road runs are not assessed")
    note = (res.model or {}).get("note")
    if note:
        lines.append(note)
    return "\n".join(lines)


def _candidates_table(model: dict) -> str:
    cands = model["candidates"]
    names = [rideid.candidate_label(c) for c in cands]
    w = max([30] + [len(n) for n in names])
    lines = [f"--model auto kept: {' + '.join(model['extensions']) or 'base'}",
             f"{'candidate':<{w}} {'cost':>11} {'criterion':>11} {'fits better':>12} {'adequate':>9}"]
    for c, name in zip(cands, names):
        crit = "" if c["criterion"] is None else f"{c['criterion']:.4g}"
        adq = {True: "yes", False: "no", None: "-"}[c.get("adequate")]
        better = {True: "yes", False: "no", None: "-"}[c.get("fits_better")]
        lines.append(f"{name:<{w}} {c['cost']:>11.5g} {crit:>11} {better:>12} {adq:>9}")
    lines += [f"{' + '.join(s['extensions']):<{w}} skipped: its predicted gain {s['predicted_gain']:.3g}, score "
              f"{s['score']:.3g} against {s['threshold']:.3g} (one Gauss-Newton step at its parent's fit)"
              for s in model.get("screens", ()) if not s["passes"]]
    lines += [f"{' + '.join(s['extensions']):<{w}} not fitted: predicted to reach a cost of {s['predicted_cost']:.3g}, "
              f"above a rival accepted at this step"
              for s in model.get("screens", ()) if s["passes"] and s.get("fitted") is False]
    if any(c.get("fits_better") is False for c in model["candidates"]):
        rule = model.get("fits_better_rule") or "a cost at least (0.5 %)^2 below every candidate it contains"
        lines.append(f"fits better: {rule}; a candidate that does not is not kept, whatever its criterion")
    if model.get("as_drawn_choice") is not None and model.get("note"):
        lines.append(model["note"])
    return "\n".join(lines)


#: what ``rideid identify`` writes into its folder: a new identification replaces all of it (the user's files stay)
IDENTIFY_OUTPUTS = ("result.json", "history.csv", "report.html", "figures", "road", "profile.csv")


def _import_ahead(name: str) -> None:
    """Resolve ``rideid.<name>`` (and import its modules) on a background thread.

    The report's modules (Matplotlib, Jinja2: about 0.3 s) load while the
    identification runs, mostly in compiled kernels that release the GIL.
    An import error is left for the main thread to meet and report.
    """
    def resolve():
        try:
            getattr(rideid, name)
        except Exception:  # raised again, and reported, where the main thread needs the name
            pass

    threading.Thread(target=resolve, name=f"rideid-import-{name}", daemon=True).start()


def _load_with_quality(ds_path, out):
    """``rideid.load_dataset``, its per-run warnings on clipping, gaps and flat lines replaced by one
    data-quality table (:func:`rideid.data.quality.quality_table`; printed when a channel has any of them or
    a declared sensor chain); every other warning shown as before."""
    with warnings.catch_warnings(record=True) as caught:
        ds = rideid.load_dataset(ds_path)
    summary = [w for w in caught
               if issubclass(w.category, rideid.DataWarning) and rideid.summarised_warning(str(w.message))]
    for w in caught:
        if w not in summary:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    if ds.unknown_road_runs and len(ds.unknown_road_runs) == len(ds.runs):
        return ds
    for line in rideid.resampling_lines(ds):  # the rate of each run and every filter rideid applied to its data
        print(textwrap.fill(line, 100, subsequent_indent="  "), file=out)
    for line in rideid.partial_channel_lines(ds):  # SPEC: a missing channel is simply not used; never silently
        print(textwrap.fill(line, 100, subsequent_indent="  "), file=out)
    quality = rideid.data_quality(ds)
    if summary or any(e["filters"] for e in quality["channels"].values()):
        print("data quality (" + str(len(ds.runs)) + " runs):\n" + rideid.quality_table(quality), file=out)
    return ds


def run_identify(ds_path, out_dir, *, seed, population=None, generations=None, weights="adaptive",
                 polish=True, quiet=False, out=None, report=True, model=None, tracks="as-built", profile=False):
    out = out or sys.stdout
    if profile:  # every stage below, the loading and the report included (rideid.profiling)
        with rideid.Profile() as prof:
            res = run_identify(ds_path, out_dir, seed=seed, population=population, generations=generations,
                               weights=weights, polish=polish, quiet=quiet, out=out, report=report, model=model,
                               tracks=tracks)
        print("where the time went (wall and CPU seconds; CPU counts every thread):\n" + prof.table(), file=out)
        prof.write_csv(Path(out_dir) / "profile.csv")
        return res
    if model is not None:
        model = rideid.parse_model_arg(model)  # base|full|auto, or groups: damper_curves,anti_roll_bars
    stage = rideid.profiling.timing  # a no-op unless --profile
    with stage("load"):
        ds = _load_with_quality(ds_path, out)
    if report:  # after loading: an import on another thread slows this thread's imports (the GIL)
        _import_ahead("write_report")
    prog = Progress(quiet)
    kw = {"population": population or rideid.DEFAULT_POPULATION,
          "generations": generations or rideid.DEFAULT_GENERATIONS}
    if kw["population"] < 4:
        raise rideid.ArgumentError(f"--population must be at least 4, got {kw['population']}")
    if kw["generations"] < 1:
        raise rideid.ArgumentError(f"--generations must be at least 1, got {kw['generations']}")
    # the model as rideid.identify chooses it (SPEC §5 amended): --model, else the dataset's [model], else auto
    with stage("identify"):
        res = rideid.identify(ds, rng=seed, weights=weights, polish=polish, callback=prog.identify, model=model,
                              tracks=tracks, **kw)
    prog.done()
    with rideid.atomic_output(out_dir, replaces=IDENTIFY_OUTPUTS) as tmp, stage("save and report"):
        res.save(tmp)
        if report:
            if not quiet:
                prog.line("writing the report ...", force=True)
            rideid.write_report(res, res.fitted_data(ds), tmp)
            prog.done()
    print(_summary_table(res), file=out)
    if res.model.get("candidates"):
        print(_candidates_table(res.model), file=out)
    if res.model.get("first_fit"):
        print(textwrap.fill(rideid.first_fit_sentence(res.model["first_fit"]), 100, subsequent_indent="  "), file=out)
    for message in dict.fromkeys(h["message"] for h in (res.adequacy or {}).get("sensor_hints") or []):
        print("hint: " + message, file=out)  # a group of channels shares one message
    small = ((res.adequacy or {}).get("small_angle") or {}).get("note")
    if small:
        print(textwrap.fill("note: " + small, 100, subsequent_indent="  "), file=out)
    for key in ("tracks_caveat", "level_caveat", "setup_caveat"):  # adequate, but which numbers not to trust, why
        caveat = (res.adequacy or {}).get(key)
        if caveat and (key == "tracks_caveat" or res.adequacy.get("adequate")):
            print(textwrap.fill("WARNING: " + caveat, 100, subsequent_indent="  "), file=out)
    shape = rideid.error_bar_warning(res.polish)  # error bars the data or the cost's shape do not bear
    if shape:  # out, whatever the verdict
        print(textwrap.fill("WARNING: " + shape, 100, subsequent_indent="  "), file=out)
    para = rideid.verdict_paragraph(res.adequacy)
    if para:
        print("\n" + textwrap.fill(para, 100) + "\n", file=out)
    elif res.adequacy:
        held = rideid.adequacy_caveats(res.adequacy)
        if held:  # adequate on the pairs tested, but not green: say so where the verdict is read
            short = [held[0]] if res.adequacy.get("not_assessed") else []
            short += (["the WARNING above" + ("s" if len(held) - len(short) > 1 else "")] if len(held) > len(short)
                      else [])
            print(textwrap.fill("model adequate on what was tested, NOT A CLEAN VERDICT: " + "; and ".join(short),
                                100, subsequent_indent="  "), file=out)
        else:
            print("model adequate: " + res.adequacy["reasons"][0], file=out)
    print(f"cost {res.cost:.4g}, {res.generations} generations, {res.evaluations} evaluations, "
          f"{res.wall_time_s:.1f} s; written to {out_dir}" + (f" (open {Path(out_dir) / 'report.html'})"
                                                                if report else ""), file=out)
    return res


def cmd_identify(args, out=None):
    out = out or sys.stdout
    run_identify(args.dataset, args.out, seed=args.seed, population=args.population,
                 generations=args.generations, weights=args.weights, polish=not args.no_polish,
                 quiet=args.quiet, out=out, report=not args.no_report, model=args.model, tracks=args.tracks,
                 profile=args.profile)
    return 0


def cmd_sensitivity(args, out=None):
    out = out or sys.stdout
    src = Path(args.source)
    is_scenario = args.source == rideid.BUILTIN or (src.is_file() and "truth" in rideid.read_toml(src))
    source = rideid.load_scenario(src) if is_scenario else rideid.load_dataset(src)
    rideid.refuse_unknown_roads(source, "rideid sensitivity")
    prog = Progress(args.quiet)
    prog.line("simulating the baseline car and +25 % per parameter ...", force=True)
    maps = rideid.sensitivity_maps(source)
    with rideid.atomic_output(args.out) as tmp:
        rideid.write_sensitivity_csvs(maps, tmp)
        (tmp / "tables.md").write_text(rideid.sensitivity_tables_markdown(maps))
        rideid.sensitivity_heatmaps(maps, tmp)
    prog.done()
    print(f"sensitivity maps written to {args.out} (tables.md, 3 CSV, 3 PNG)", file=out)
    return 0


def cmd_plan(args, out=None):
    out = out or sys.stdout
    targets = {}
    for t in args.target:
        n, v = rideid.parse_target(t)
        targets[n] = v
    kw = {} if args.within is None else {"within": args.within}
    prog = Progress(args.quiet)
    prog.line("simulating the candidate runs and their sensitivities ...", force=True)
    res = rideid.plan(args.scenario, noise=args.noise, accel_density=args.accel_noise_density,
               gyro_density=args.gyro_noise_density, bandwidth=args.bandwidth, noise_ar1=args.noise_ar1,
               noise_psd=args.noise_psd, budget_runs=args.budget_runs,
               budget_time=args.budget_time, overhead=args.overhead, criterion=args.criterion, targets=targets,
               robust=args.robust, seed=args.seed, **kw)
    prog.done()
    with rideid.atomic_output(args.out) as tmp:
        res.save(tmp)
    print(res.summary(), file=out)
    print(f"plan written to {args.out} (plan.json, plan.md, crlb.csv, path.csv, correlation.csv, "
          "precision_path.png)", file=out)
    return 0


def score_table(scored: dict) -> str:
    """The text table of :func:`rideid.score`: error and whether ±2 ``std_total`` (``std_robust`` in a result
    written before SPEC §12) covers the truth."""
    basis = scored.get("basis", "std_robust")
    head = "±2 total covers" if basis == "std_total" else "±2 robust covers"
    lines = [f"{'parameter':<10} {'estimate':>14} {'truth':>14} {'error %':>9} {head:>16}"]
    for n, r in scored["parameters"].items():
        covers = {True: "yes", False: "NO", None: "-"}[r["covered"]]
        if r["error_percent"] is None:  # no relative error of a zero or unknown truth: the estimate in its unit
            truth = "-" if r["truth"] is None else f"{r['truth']:.6g}"
            at = f" at {r['velocity']:+.3f} m/s" if "velocity" in r else ""
            lines.append(f"{n:<10} {r['estimate']:>14.6g} {truth:>14} {'-':>9} {covers:>16}{at}"
                         + (f" ({r['status']})" if r["status"] in ("not in the model", "no true curve") else ""))
            continue
        note = "" if r["status"] == "estimated" else f" {r['status']}"
        if "velocity" in r:  # a damper curve's knot
            note = f" at {r['velocity']:+.3f} m/s" + note
        lines.append(f"{n:<10} {r['estimate']:>14.6g} {r['truth']:>14.6g} {r['error_percent']:>9.4f} "
                     f"{covers:>16}{note}")
    lines += scored.get("notes", [])
    if scored["coverable"]:
        lines.append(f"±2 {basis} covers the truth for {scored['covered']} of {scored['coverable']} estimates "
                     "(about 95 % expected)")
    lines.append(f"largest error of the estimated parameters: {scored['worst_percent']:.4f} %")
    return "\n".join(lines)


def cmd_score(args, out=None):
    out = out or sys.stdout
    res = rideid.read_result_json(args.result)
    # the path: the truth's [dampers] read with it (without them its dampers are linear)
    print(score_table(rideid.score(res, args.truth)), file=out)
    return 0


def cmd_demo(args, out=None):
    out = out or sys.stdout
    root = Path(args.out)
    sc = rideid.default_scenario()
    print("rideid demo: the built-in car (CommonRoad BMW 320i) on the paper's ten runs", file=out)
    print(rideid.format_modal_summary(rideid.modal_summary(sc.truth, sc.geometry)), file=out)
    prog = Progress(args.quiet)
    data, _ = rideid.simulate_manifest(sc, noise=0.01, seed=args.seed,
                                       progress=lambda i, n, rid: prog.steps(i, n, "simulating run"))
    prog.done()
    rideid.write_dataset(sc, data, root / "dataset", comment="rideid demo: built-in scenario, 1 % noise")
    print(f"\n1. simulated {len(sc.runs)} runs with 1 % noise -> {root / 'dataset'}", file=out)
    print(f"2. identifying (total mass {sc.known['total_mass']} kg known) ...", file=out)
    res = run_identify(root / "dataset", root / "identify", seed=args.seed, quiet=args.quiet, out=out)
    rideid.load_truth(root / "dataset" / "truth.toml", sc.geometry)  # checked against the car's geometry
    print("\n3. score against the truth", file=out)
    print(score_table(rideid.score(res, root / "dataset" / "truth.toml")), file=out)
    report = root / "identify" / "report.html"
    if report.is_file():
        print(f"\nreport: {report}", file=out)
    return 0


def cmd_report(args, out=None):
    out = out or sys.stdout
    folder = Path(args.result_dir)
    res = rideid.load_result(folder)
    other = None
    if args.compare is not None:
        compare = Path(args.compare)
        other = rideid.load_result(compare)
        if not other.history or not res.history:
            raise rideid.DataError(f"{compare}: history.csv missing or empty; nothing to compare")
        if other.dataset != res.dataset:
            raise rideid.DataError(f"{compare}: identifies another dataset ({other.dataset}) than {folder} "
                                   f"({res.dataset})")
    if not res.dataset or not Path(res.dataset).exists():
        raise rideid.DataError(f"{folder / 'result.json'}: the dataset it names ({res.dataset!r}) is not found; "
                        "the report needs it")
    ds = rideid.load_dataset(res.dataset, starts=res.start_records()).with_speeds(res.speed_values())
    res = rideid.complete_result(res, ds)  # the car's response on the runs: the report draws it, never simulates
    path = rideid.write_report(res, ds, folder, compare=other,
                        compare_label=None if other is None else f"{other.weights_mode} ({Path(args.compare).name})")
    print(f"report written to {path}", file=out)
    return 0


def cmd_export(args, out=None):
    out = out or sys.stdout
    res = rideid.export(args.fit, args.out, format=args.format)
    print(f"written to {args.out}: {', '.join(p.name for p in res.files)}", file=out)
    if res.note:  # on stderr, beside warnings: the FMU is usable elsewhere but not here as it is
        say(f"note: {res.note}")
    return 0


def cmd_study(args, out=None):
    out = out or sys.stdout
    spec = rideid.load_study(args.study)  # a bad study file stops here, before DIR is created
    prog = Progress(args.quiet)
    try:
        res = rideid.study(spec, args.out, scheduler=args.scheduler, progress=prog.study)
    except KeyboardInterrupt:
        prog.done()
        say(f"rideid: the finished tasks are kept in {Path(args.out) / 'tasks'}; run the same command again "
            "to resume")
        raise
    prog.done()
    print(f"{res.tasks} tasks: {res.done} done, {res.failed} failed ({res.computed} computed now, "
          f"{res.tasks - res.computed} from an earlier run), {res.wall_time_s:.0f} s", file=out)
    print(f"written to {args.out}: results.parquet, summary.md, summary.csv (open {res.summary})", file=out)
    return 0


COMMANDS = {"plan": cmd_plan, "report": cmd_report, "simulate": cmd_simulate, "identify": cmd_identify,
            "sensitivity": cmd_sensitivity, "score": cmd_score, "demo": cmd_demo, "study": cmd_study,
            "export": cmd_export}


def _compile(quiet: bool):
    """Compile or load the kernels up front, and say so when they were compiled (a cold cache: once after
    install), never when loaded from the cache, never with --quiet."""
    prog = Progress(quiet)
    prog.line("loading the compiled simulation kernel (compiles once after install, a few seconds) ...", force=True)
    dt = rideid.compile_kernels()  # seconds compiling: 0.0 when loaded from the cache
    prog.done()
    if dt > 0.0 and not quiet:
        say(f"rideid: compiled the simulation kernel in {dt:.1f} s (cached for later runs)")


def main(argv=None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    warnings.showwarning = _warning_line
    try:
        if args.command in ("simulate", "identify", "sensitivity", "demo", "report", "plan", "study"):
            _compile(getattr(args, "quiet", False))
        return COMMANDS[args.command](args)
    except rideid.RideidError as e:
        msg = str(e).replace("\n", " ") + _stale_note(args)
        say(f"rideid: error: {msg}")
        return 2
    except KeyboardInterrupt:
        say("rideid: interrupted")
        return 130
    except BrokenPipeError:  # output piped into a reader that stopped early (e.g. `| head`): not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except Exception as e:  # a bug: say so, in one line unless debugging
        if os.environ.get("RIDEID_DEBUG"):
            traceback.print_exc()
        say(f"rideid: internal error: {type(e).__name__}: {e} (set RIDEID_DEBUG=1 for the traceback; "
            "please report it)")
        return 1


def _stale_note(args) -> str:
    """What a refused command left in its ``--out`` folder: nothing new; an earlier run's files, when the folder
    holds some, stay as they were (a user looking there after the error must not take them for this run's)."""
    out = getattr(args, "out", None)
    if out is None or args.command == "report" or not Path(out).is_dir() or not any(Path(out).iterdir()):
        return ""
    return f"; nothing was written: {out} holds an earlier run's files, left as they were"


#: commands whose process may end without the interpreter's teardown (no Dask cluster to close)
FAST_EXIT = frozenset(COMMANDS) - {"study"}


def console(argv=None) -> None:  # pragma: no cover - exits the process (tests run it as `rideid ...`)
    """The ``rideid`` command: :func:`main`, then the process ends.

    Once the command has written, closed and flushed everything, the
    interpreter's teardown of every loaded module is pure cost (0.3 s after
    Numba has loaded the kernel: a tenth of ``rideid identify``), so the
    process ends there (``os._exit``), except for ``study``, whose Dask
    cluster closes at exit.
    """
    argv = sys.argv[1:] if argv is None else argv
    rc = main(argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except BrokenPipeError:  # the reader stopped early (`| head`): nothing more to say
        rc = rc or 141
    if command in FAST_EXIT:
        os._exit(rc)
    sys.exit(rc)


if __name__ == "__main__":  # pragma: no cover
    console()
