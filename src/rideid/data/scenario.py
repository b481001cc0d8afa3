"""Scenarios: loading one, the built-in car and tracks, and scenario -> dataset simulation.

The scenario file format itself is :mod:`rideid.data.schema.manifest`.
"""

from __future__ import annotations

import shutil
import warnings
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import ArgumentError, DataWarning, ModelValidityWarning
from . import checks
from .schema import (BUMP_NAMES, ChannelEntry, DatasetManifest, RunSpec, Scenario, atomic_output, parse_scenario,
                     read_toml, write_run_csv, write_toml)
from .noise import sensor_noise
from ..model.equations import CHANNELS, static_corner_loads
from ..model.params import ALL_NAMES, CORNERS, EXT_NAMES, INDEX, NAMES, as_vector, full_rows
from ..model.simulate import prepare_run, simulate_reference, wheel_displacements, wheel_velocities


#: the name that stands for the built-in scenario wherever a scenario file is asked for
BUILTIN = "builtin"


def default_scenario_path() -> Path:
    """Path of the built-in scenario TOML (the BMW 320i on the paper's ten runs)."""
    return Path(str(resources.files("rideid.data") / "default_scenario.toml"))


def load_scenario(path) -> Scenario:
    """Read and validate a scenario file (SPEC §3, §6), its numbers checked for plausibility.

    Parameters
    ----------
    path : str or Path
        The scenario file, or ``"builtin"`` (:data:`BUILTIN`) for the
        built-in one (:func:`default_scenario_path`), as study files say.

    Returns
    -------
    Scenario
        Frozen; derive another with :func:`dataclasses.replace`.

    Raises
    ------
    DataError
        Naming the file and the key at fault.
    """
    path = default_scenario_path() if str(path) == BUILTIN else Path(path)
    sc = parse_scenario(read_toml(path), path)
    checks.enforce(checks.check_numbers(sc))
    return sc


def default_scenario() -> Scenario:
    """The built-in scenario (:func:`default_scenario_path`), loaded."""
    return load_scenario(default_scenario_path())


def run_times(run: RunSpec) -> np.ndarray:
    """``t = k / fs`` for ``k = 0 .. round(duration fs)`` (SPEC §3)."""
    n = int(round(run.duration * run.fs))
    return np.arange(n + 1) / run.fs


@dataclass
class LiftOff:
    run: str
    wheel: str
    time: float
    force: float  # most negative total tire force, N (7-DOF); 0 for the MuJoCo car, whose tire cannot pull
    engine: str = "rideid"
    #: the car is nonlinear (SPEC §8): its tire pushes but never pulls, so a wheel leaving the road is physics
    #: the simulation includes, not a violated assumption (no warning; the command line says it as a note)
    physics: bool = False

    def message(self) -> str:
        if self.physics:
            where = " in the MuJoCo car" if self.engine == "mujoco" else ""
            return (f"run '{self.run}': wheel {self.wheel} leaves the road{where} at t = {self.time:.3f} s "
                    "(simulated: the nonlinear car's tire pushes but never pulls)")
        if self.engine == "mujoco":
            return (f"run '{self.run}': wheel {self.wheel} leaves the road in the MuJoCo car at t = {self.time:.3f} s; "
                    "the linear model assumes every tire stays on the road")
        return (f"run '{self.run}': wheel {self.wheel} lifts off (tire force would reach {self.force:.0f} N "
                f"at t = {self.time:.3f} s); the linear model assumes every tire stays on the road")


def lift_offs(P, geom, run_id, run_input, states, physics: bool = False, coords: bool = False) -> list[LiftOff]:
    """Wheels whose total tire load (static + k_t (r - z) + c_t (r' - z')) goes negative.

    ``states``: the physical states of :func:`rideid.model.simulate.simulate_reference`
    (``return_states=True``) or of :func:`rideid.model.nonlinear.simulate_nonlinear`
    (``physics=True``: the wheel is then in the air, its tire carrying nothing; ``coords=True``: states in
    :data:`rideid.model.equations.COORDS` order, ``[q, q']``, as that one returns them);
    ``P`` 12 or 16 parameters (or a nonlinear row: its first 16 columns).
    """
    P = np.asarray(P, dtype=float).reshape(-1)
    P = full_rows(P[:len(ALL_NAMES)] if P.size > len(ALL_NAMES) else P)[0]
    static = static_corner_loads(P[None], geom)[0]
    kt = np.array([P[INDEX["k_tf"]]] * 2 + [P[INDEX["k_tr"]]] * 2)
    ct = np.array([P[INDEX["c_tf"]]] * 2 + [P[INDEX["c_tr"]]] * 2)
    zw, vw = (states[..., 3:7], states[..., 10:14]) if coords else (wheel_displacements(states),
                                                                     wheel_velocities(states))
    force = static[None, :] + kt[None, :] * (run_input.u - zw) + ct[None, :] * (run_input.rate - vw)
    out = []
    for i, w in enumerate(CORNERS):
        j = int(np.argmin(force[:, i]))
        if force[j, i] < 0:
            out.append(LiftOff(run_id, w, float(run_input.t[j]), float(force[j, i]), physics=physics))
    return out


#: stationary lead-in of a raw (logger-style) MuJoCo run, s
RAW_LEAD_IN = 1.0


def nonlinear_car(sc: Scenario):
    """``(P, layout)`` of a scenario's nonlinear car (SPEC §8) for :func:`rideid.model.nonlinear.simulate_nonlinear`:
    the row (the sixteen, then the bump stops, then the front and rear forces at the ``[dampers]`` knots)
    and its layout; None for a linear car (no ``[dampers]``, no bump stops)."""
    if not sc.nonlinear:
        return None
    from ..model.nonlinear import NonlinearLayout
    dm = sc.dampers
    layout = NonlinearLayout(knots=None if dm is None else tuple(dm.velocity), bump_stops=bool(sc.bump_stops))
    row = [float(sc.truth.get(n, 0.0)) for n in ALL_NAMES]
    if sc.bump_stops:
        (cf, cr), (rf, rr) = sc.bump_stop_pairs
        # an axle without a stop: rate 0 (the simulator takes finite clearances only; with rate 0 any will do)
        row += [c if np.isfinite(c) else 1.0 for c in (cf, cr)] + [rf, rr]
    if dm is not None:
        row += list(dm.front) + list(dm.rear)
    return np.array(row), layout


#: sub-step bound of the states :func:`nonlinear_states` computes to find lift-off, by plain RK4 sub-steps (the
#: kernel splits its sub-steps at the kinks; at this bound the plain ones are within 0.02-0.3 % of its outputs,
#: ample to find when a tire unloads, at less cost)
LIFT_OFF_RHO = 0.25


def nonlinear_states(Pn, geom, run_input, layout):
    """States ``(n_time, 14)`` (COORDS order, ``[q, q']``) of a nonlinear car, to find lift-off.

    The compiled kernel gives outputs only; its NumPy twin gives states, at a cost that grows with the
    sub-steps, so this takes the NumPy backend with the looser :data:`LIFT_OFF_RHO`.
    """
    from ..model.nonlinear import simulate_numpy, substeps
    Pn = np.atleast_2d(Pn)
    m = substeps(Pn, geom, layout, run_input.h, rho=LIFT_OFF_RHO)
    return simulate_numpy(Pn, geom, run_input, layout, m, return_states=True, split=False)[1][0]


def simulate_manifest(sc: Scenario, noise: float = 0.0, seed: int | None = None, progress=None,
                      engine: str = "rideid", raw: bool = False, noise_ar1: float = 0.0):
    """Simulate every run of a scenario with its ``[truth]`` parameters.

    ``engine``: ``"rideid"`` (the exact 7-DOF response) or ``"mujoco"`` (the
    independent multibody car of :mod:`rideid.hifi` with the scenario's
    ``[hifi]`` properties, RK4 at 1 ms; lift-off is then what happened in
    MuJoCo: a tire contact carrying no load).

    ``raw`` (MuJoCo only): the sensors' own readings, gravity included, as a
    logger would record them, with :data:`RAW_LEAD_IN` s standing still
    before the run (the front axle reaches x = 0 at that file time).

    ``noise_ar1``: the noise is coloured, AR(1) in time with this coefficient
    per sample (:func:`rideid.data.noise.sensor_noise`), same standard
    deviation; 0 (default) is white.

    The nonlinear suspension of SPEC §8 (``[dampers]`` curves, ``[truth]``
    bump stops) goes through :func:`rideid.model.nonlinear.simulate_nonlinear`
    with the rideid engine and through the passive-force callback of the
    MuJoCo car; ``[vehicle] cg_height`` through the geometry in both. Such a
    car's tires push but never pull: a wheel leaving the road is simulated,
    not warned of (its :class:`LiftOff` has ``physics=True``).

    Returns
    -------
    dict run id -> (t, Y) with ``Y`` (n, 10) in CHANNELS order, and the list
    of :class:`LiftOff` found (for a linear car also issued as :class:`ModelValidityWarning`).
    """
    if noise < 0 or not np.isfinite(noise):
        raise ArgumentError(f"--noise must be a non-negative fraction, got {noise}")
    if not (np.isfinite(noise_ar1) and 0 <= noise_ar1 < 1):
        raise ArgumentError(f"--noise-ar1 must be an AR(1) coefficient in [0, 1), got {noise_ar1}")
    if engine not in ("rideid", "mujoco"):
        raise ArgumentError(f"engine must be 'rideid' or 'mujoco', got {engine!r}")
    if raw and engine != "mujoco":
        raise ArgumentError("--raw needs --engine mujoco (raw sensor readings come from the MuJoCo car)")
    if engine == "rideid" and sc.hifi is not None:
        warnings.warn(f"{sc.path}: [hifi] describes the MuJoCo car and is ignored by the 7-DOF engine "
                      "(use --engine mujoco)", DataWarning, stacklevel=2)
    rng = np.random.default_rng(seed)
    P = as_vector(sc.truth)[None]
    nonlinear = nonlinear_car(sc) if engine == "rideid" else None
    out, lifts = {}, []
    for i, run in enumerate(sc.runs):
        t = run_times(run)
        if engine == "mujoco":
            from ..verify.hifi import simulate_mujoco
            lead = RAW_LEAD_IN if raw else 0.0
            if raw:  # the same samples, after the lead-in
                t = np.arange(int(round(lead * run.fs)) + t.size) / run.fs
            from ..verify.hifi import scenario_properties
            res = simulate_mujoco(P[0], sc.geometry, sc.tracks[run.track], run.speed, t,
                                  distance=lambda tt, v=run.speed, t0=lead: v * (tt - t0),
                                  hifi=scenario_properties(sc), dampers=sc.dampers, raw=raw, details=True)
            y = res.y
            lifts += [LiftOff(run.id, w, float(res.lift_time[k]), 0.0, "mujoco", physics=sc.nonlinear)
                      for k, w in enumerate(CORNERS) if np.isfinite(res.lift_time[k])]
        elif nonlinear is not None:
            from ..model.nonlinear import simulate_nonlinear
            Pn, layout = nonlinear
            ri = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t)
            y = simulate_nonlinear(Pn[None], sc.geometry, ri, layout)[0]  # the compiled kernel
            lifts += lift_offs(P[0], sc.geometry, run.id, ri, nonlinear_states(Pn, sc.geometry, ri, layout),
                               physics=True, coords=True)
        else:
            ri = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t)
            y, states = simulate_reference(P, sc.geometry, ri, return_states=True)
            y = y[0]
            lifts += lift_offs(P[0], sc.geometry, run.id, ri, states[0])
        if noise > 0:
            dyn = y - y[:1] if raw else y  # raw: the noise scales with the motion, not with g
            rms = np.sqrt(np.mean(dyn * dyn, axis=0))
            y = y + sensor_noise(rng, y.shape, noise_ar1) * (noise * rms)[None, :]
        out[run.id] = (t, y)
        if progress is not None:
            progress(i + 1, len(sc.runs), run.id)
    for lo in lifts:
        if not lo.physics:
            warnings.warn(lo.message(), ModelValidityWarning, stacklevel=2)
    return out, lifts


def raw_names() -> tuple[str, ...]:
    """The logger-style names of the MuJoCo car's raw sensor channels (:data:`rideid.verify.hifi.RAW_NAMES`)."""
    from ..verify.hifi import RAW_NAMES  # the MuJoCo module; loaded only when raw data are written
    return RAW_NAMES


def write_dataset(sc: Scenario, data: dict, out_dir, comment: str | None = None, raw: bool = False):
    """Write ``dataset.toml``, ``runs/<id>.csv`` and ``truth.toml`` (atomically).

    ``raw``: the runs are raw MuJoCo sensor readings (:func:`simulate_manifest`
    with ``raw=True``); the dataset then maps the logger-style columns
    (:data:`rideid.hifi.RAW_NAMES`) to the SPEC channels and tells
    :mod:`rideid.measured` that gravity is included, with the stationary
    lead-in and the start time.
    """
    with atomic_output(out_dir) as tmp:
        runs = []
        for run in sc.runs:
            t, Y = data[run.id]
            write_run_csv(tmp / "runs" / f"{run.id}.csv", t, Y, raw_names() if raw else CHANNELS)
            runs.append(RunSpec(run.id, run.track, run.speed, file=f"runs/{run.id}.csv"))
        logged = {}
        if raw:
            logged = dict(channel_map={c: ChannelEntry(n, "rad/s" if c.endswith("rate") else "m/s^2")
                                       for c, n in zip(CHANNELS, raw_names())},
                          preprocess={"gravity_included": True, "lead_in": (0.0, RAW_LEAD_IN), "start": RAW_LEAD_IN})
        man = DatasetManifest(**{**sc.shared(), "runs": runs}, **logged)
        doc = man.to_dataset_doc()
        # measured road profiles travel with the dataset
        for tab, tr in zip(doc["tracks"], sc.tracks.values()):
            src = tr.data_file
            if src is not None:
                dst = tmp / "profiles" / f"{tr.id}.csv"
                dst.parent.mkdir(exist_ok=True)
                shutil.copyfile(src, dst)
                tab["file"] = f"profiles/{tr.id}.csv"
        write_toml(tmp / "dataset.toml", doc, comment)
        if sc.truth is not None:
            doc = {"truth": {n: sc.truth[n] for n in NAMES + EXT_NAMES + BUMP_NAMES if n in sc.truth}}
            if sc.dampers is not None:
                doc["dampers"] = sc.dampers.to_table()
            write_toml(tmp / "truth.toml", doc, "true parameters of the simulated car (rideid simulate)"
                       + ("; [dampers]: its damper curves (SPEC §8)" if sc.dampers is not None else ""))
    return Path(out_dir)
