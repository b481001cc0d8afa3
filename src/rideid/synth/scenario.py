"""Simulated datasets: a scenario's runs simulated with its ``[truth]`` car, and written as a dataset.

:func:`simulate_manifest` drives every run of a scenario (parsed by
:mod:`rideid.data.scenario`) through the exact 7-DOF response
(:mod:`rideid.model`), the nonlinear car of SPEC §8, or the independent
MuJoCo car (:mod:`rideid.verify.hifi`); :func:`write_dataset` writes the
result as a dataset folder. Above both the data layer and the MuJoCo car,
so neither needs the other.
"""

from __future__ import annotations

import shutil
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..data.noise import sensor_noise
from ..data.scenario import (LIFT_OFF_RHO, generate_road, lead_in, post_function, road_record, run_times,
                             write_road_csv)
from ..data.schema import (BUMP_NAMES, ChannelEntry, DatasetManifest, RunSpec, Scenario, atomic_output, write_run_csv,
                           write_toml)
from ..errors import ArgumentError, DataWarning, ModelValidityWarning
from ..model.equations import CHANNELS, static_corner_loads
from ..model.nonlinear import NonlinearLayout, NonlinearSimulator, simulate_nonlinear
from ..model.params import (CORNERS, EXT_NAMES, INDEX, NAMES, ROW_WIDTHS, SUSPENSION_NAMES, as_vector,
                            full_rows)
from ..model.posts import POST_CHANNELS, prepare_function
from ..model.simulate import prepare_run, simulate_reference, wheel_displacements, wheel_velocities
from ..verify.hifi import RAW_NAMES, scenario_properties, simulate_mujoco


class SimulatedRuns(dict):
    """What :func:`simulate_manifest` returns first: run id -> ``(t, Y)``, plus ``roads``:
    run id -> :class:`GeneratedRoad` of every run on a generated road (SPEC §9), which
    :func:`write_dataset` writes to ``road_truth/``."""

    def __init__(self, runs=(), roads=None, posts=None):
        super().__init__(runs)
        self.roads = dict(roads or {})
        #: run id -> ``(n, 4)`` post displacements (m) of every four-post rig run (SPEC §13), as the rig's
        #: displacement transducers record them (no noise added)
        self.posts = dict(posts or {})


def _tail(ri, k: int):
    """The run input from sample ``k`` on (a moving run's recorded part), for the lift-off check."""
    return ri if k == 0 else replace(ri.tail(k), inputs_at=None)


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
    ``P`` 12, 16 or 23 parameters (or a nonlinear row: its first 16 columns).
    """
    P = np.asarray(P, dtype=float).reshape(-1)
    P = full_rows(P if P.size in ROW_WIDTHS else P[:len(SUSPENSION_NAMES)])[0]
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
    dm = sc.dampers
    pt = sc.truth.get("m_p", 0.0) > 0
    layout = NonlinearLayout(knots=None if dm is None else tuple(dm.velocity), bump_stops=bool(sc.bump_stops),
                             powertrain=pt)
    row = [float(sc.truth.get(n, 0.0)) for n in layout.names[:layout.n_car]]
    if sc.bump_stops:
        (cf, cr), (rf, rr) = sc.bump_stop_pairs
        # an axle without a stop: rate 0 (the simulator takes finite clearances only; with rate 0 any will do)
        row += [c if np.isfinite(c) else 1.0 for c in (cf, cr)] + [rf, rr]
    if dm is not None:
        row += list(dm.front) + list(dm.rear)
    return np.array(row), layout


def nonlinear_states(Pn, geom, run_input, layout):
    """States ``(n_time, 14)`` (COORDS order, ``[q, q']``) of a nonlinear car, to find lift-off: plain RK4
    sub-steps at the looser :data:`LIFT_OFF_RHO`."""
    sim = NonlinearSimulator(geom, [run_input], layout, rho=LIFT_OFF_RHO, split=False)
    return sim.states(np.atleast_2d(Pn))[0][1][0]


def simulate_manifest(sc: Scenario, noise: float = 0.0, seed: int | None = None, progress=None,
                      engine: str = "rideid", raw: bool = False, noise_ar1: float = 0.0):
    """Simulate every run of a scenario with its ``[truth]`` parameters.

    ``engine``: ``"rideid"`` (the exact 7-DOF response) or ``"mujoco"`` (the
    independent multibody car of :mod:`rideid.verify.hifi` with the scenario's
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

    A run on a generated road (``road_class``, SPEC §9) drives the ISO 8608
    road of :func:`generate_road` (seeded by ``road_seed``, else by ``seed``
    and the run's position: the same command, the same road), a ``profile``
    under each wheel path with the tire envelope as for any profile. A
    moving run (``moving = true``, the default on a generated road) is
    simulated from rest :func:`lead_in` s before its first sample, which is
    taken when the front axle reaches x = 0; its lift-offs are those of the
    recorded samples.

    Returns
    -------
    SimulatedRuns (a dict) run id -> (t, Y) with ``Y`` (n, 10) in CHANNELS order (``.roads``: the
    :class:`GeneratedRoad` of each run on a generated road), and the list of :class:`LiftOff` found
    (for a linear car also issued as :class:`ModelValidityWarning`).
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
    out, lifts = SimulatedRuns(), []
    if raw:
        moving = [r.id for r in sc.runs if r.moving]
        if moving:
            raise ArgumentError(f"--raw writes a logger's recording that starts standing still, but run "
                                f"'{moving[0]}' starts moving (moving = true, the default on a generated road); "
                                "simulate it without --raw")
    for i, run in enumerate(sc.runs):
        t = run_times(run)
        if run.posts:  # SPEC §13: a four-post rig, its posts driven by the run's signal
            y, posts, lf = _simulate_rig(sc, run, i, seed, P, t, engine, raw, nonlinear)
            lifts += lf
            out.posts[run.id] = posts
            if raw:
                t = np.arange(int(round(RAW_LEAD_IN * run.fs)) + t.size) / run.fs
            y = _noisy(y, rng, noise, noise_ar1, raw)
            out[run.id] = (t, y)
            if progress is not None:
                progress(i + 1, len(sc.runs), run.id)
            continue
        if run.road is not None:
            road = generate_road(sc, run, i, seed)
            out.roads[run.id] = road
            track = road.track()
        else:
            track = sc.tracks[run.track]
        # a moving run: simulated from rest, k0 samples (lead_in s) before its first recorded one (SPEC §9)
        k0 = int(np.ceil(lead_in(sc, run) * run.fs - 1e-9))
        tt = np.arange(-k0, t.size) / run.fs if k0 else t
        if engine == "mujoco":
            lead = RAW_LEAD_IN if raw else 0.0
            if raw:  # the same samples, after the lead-in
                t = np.arange(int(round(lead * run.fs)) + t.size) / run.fs
                tt = t
            res = simulate_mujoco(P[0], sc.geometry, track, run.speed, tt,
                                  distance=lambda x, v=run.speed, t0=lead: v * (x - t0),
                                  hifi=scenario_properties(sc), dampers=sc.dampers, raw=raw, details=True)
            y = res.y[k0:]
            lifts += [LiftOff(run.id, w, float(res.lift_time[k]), 0.0, "mujoco", physics=sc.nonlinear)
                      for k, w in enumerate(CORNERS) if res.lift_time[k] >= 0]
        elif nonlinear is not None:
            Pn, layout = nonlinear
            ri = prepare_run(track, sc.geometry, run.speed, tt)
            y = simulate_nonlinear(Pn[None], sc.geometry, ri, layout)[0][k0:]  # the compiled kernel
            lifts += lift_offs(P[0], sc.geometry, run.id, _tail(ri, k0),
                               nonlinear_states(Pn, sc.geometry, ri, layout)[k0:], physics=True, coords=True)
        else:
            ri = prepare_run(track, sc.geometry, run.speed, tt)
            y, states = simulate_reference(P, sc.geometry, ri, return_states=True)
            y = y[0][k0:]
            lifts += lift_offs(P[0], sc.geometry, run.id, _tail(ri, k0), states[0][k0:])
        y = _noisy(y, rng, noise, noise_ar1, raw)
        out[run.id] = (t, y)
        if progress is not None:
            progress(i + 1, len(sc.runs), run.id)
    for lo in lifts:
        if not lo.physics:
            warnings.warn(lo.message(), ModelValidityWarning, stacklevel=2)
    return out, lifts


def _noisy(y, rng, noise: float, noise_ar1: float, raw: bool):
    """``y`` with the sensor noise of ``--noise`` (a fraction of each channel's RMS) added."""
    if noise > 0:
        dyn = y - y[:1] if raw else y  # raw: the noise scales with the motion, not with g
        rms = np.sqrt(np.mean(dyn * dyn, axis=0))
        y = y + sensor_noise(rng, y.shape, noise_ar1) * (noise * rms)[None, :]
    return y


def _simulate_rig(sc: Scenario, run: RunSpec, index: int, seed, P, t, engine: str, raw: bool, nonlinear):
    """A four-post rig run (SPEC §13): ``(y, posts (n, 4), lift-offs)``, the car at rest on its posts at the
    first sample, the posts following the run's signal (:class:`rideid.model.posts.PostSignal`)."""
    inputs_at = post_function(run, index, seed)
    posts = inputs_at(t)[0]
    if engine == "mujoco":
        lead = RAW_LEAD_IN if raw else 0.0
        tt = np.arange(int(round(lead * run.fs)) + t.size) / run.fs if raw else t

        def shifted(times, t0=lead):
            return inputs_at(np.asarray(times, dtype=float) - t0)

        res = simulate_mujoco(P[0], sc.geometry, None, None, tt, inputs=shifted, hifi=scenario_properties(sc),
                              dampers=sc.dampers, raw=raw, details=True)
        lifts = [LiftOff(run.id, w, float(res.lift_time[k]), 0.0, "mujoco", physics=sc.nonlinear)
                 for k, w in enumerate(CORNERS) if res.lift_time[k] >= 0]
        return res.y, (inputs_at(tt - lead)[0] if raw else posts), lifts
    ri = prepare_function(t, inputs_at)
    if nonlinear is not None:
        Pn, layout = nonlinear
        y = simulate_nonlinear(Pn[None], sc.geometry, ri, layout)[0]
        return y, posts, lift_offs(P[0], sc.geometry, run.id, ri, nonlinear_states(Pn, sc.geometry, ri, layout),
                                   physics=True, coords=True)
    y, states = simulate_reference(P, sc.geometry, ri, return_states=True)
    return y[0], posts, lift_offs(P[0], sc.geometry, run.id, ri, states[0])


def raw_names() -> tuple[str, ...]:
    """The logger-style names of the MuJoCo car's raw sensor channels (:data:`rideid.verify.hifi.RAW_NAMES`)."""
    return RAW_NAMES


def write_dataset(sc: Scenario, data: dict, out_dir, comment: str | None = None, raw: bool = False):
    """Write ``dataset.toml``, ``runs/<id>.csv`` and ``truth.toml`` (atomically).

    A run on a generated road (SPEC §9) is written without a track
    (``track = "unknown"``, ``moving`` as simulated); its road goes to
    ``road_truth/<id>.csv`` (columns ``x, z_left, z_right``, m; x measured from
    the front axle at the first sample, from :data:`ROAD_MARGIN` behind the rear
    axle to as far beyond the front axle's last position) and how it was made
    to ``truth.toml`` ``[roads.<id>]`` (:func:`road_record`).

    ``raw``: the runs are raw MuJoCo sensor readings (:func:`simulate_manifest`
    with ``raw=True``); the dataset then maps the logger-style columns
    (:data:`rideid.verify.hifi.RAW_NAMES`) to the SPEC channels and tells
    :mod:`rideid.data.measured` that gravity is included, with the stationary
    lead-in and the start time.
    """
    roads = getattr(data, "roads", {})
    missing = [r.id for r in sc.runs if r.road is not None and r.id not in roads]
    if missing:
        raise ArgumentError(f"run '{missing[0]}' drives a generated road, but the data carry no road for it: pass "
                            "what simulate_manifest returned (its .roads)")
    with atomic_output(out_dir) as tmp:
        runs = []
        for run in sc.runs:
            t, Y = data[run.id]
            names = raw_names() if raw else CHANNELS
            if run.posts:  # SPEC §13: the posts' columns after the ten
                Y, names = np.column_stack([Y, data.posts[run.id]]), names + POST_CHANNELS
            write_run_csv(tmp / "runs" / f"{run.id}.csv", t, Y, names)
            # a generated road is unknown to the dataset (SPEC §9: track "unknown"); its truth goes to road_truth/
            runs.append(RunSpec(run.id, run.track, run.speed, file=f"runs/{run.id}.csv", moving=run.moving,
                                input=run.input))
            if run.road is not None:
                write_road_csv(tmp / "road_truth" / f"{run.id}.csv", *roads[run.id].truth())
        logged = {}
        if raw:
            logged = dict(channel_map={**{c: ChannelEntry(n, "rad/s" if c.endswith("rate") else "m/s^2")
                                          for c, n in zip(CHANNELS, raw_names())},
                                       **({c: ChannelEntry(c, "m") for c in POST_CHANNELS}
                                          if any(r.posts for r in sc.runs) else {})},
                          preprocess={"gravity_included": True, "lead_in": (0.0, RAW_LEAD_IN), "start": RAW_LEAD_IN})
        man = DatasetManifest(**{**sc.shared(), "runs": runs}, **logged)
        doc = man.to_dataset_doc()
        # measured road profiles travel with the dataset
        for tab, tr in zip(doc.get("tracks", []), sc.tracks.values()):
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
            if roads:
                doc["roads"] = {rid: road_record(rd) for rid, rd in roads.items()}
            write_toml(tmp / "truth.toml", doc, "true parameters of the simulated car (rideid simulate)"
                       + ("; [dampers]: its damper curves (SPEC §8)" if sc.dampers is not None else "")
                       + ("; [roads]: the generated roads, their heights in road_truth/ (SPEC §9)" if roads else ""))
    return Path(out_dir)


__all__ = ["LiftOff", "RAW_LEAD_IN", "SimulatedRuns", "lift_offs", "nonlinear_car",
           "nonlinear_states", "raw_names", "simulate_manifest", "write_dataset"]
