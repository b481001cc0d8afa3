"""Where the MuJoCo car's common bias came from: its channels against an independent linear 7-DOF.

The reduced MuJoCo car (the built-in car, no ``[hifi]`` key) is compared,
noise-free, with a linear 7-DOF written here from SPEC section 1 alone (mass,
stiffness and damping matrices assembled from the twelve parameters, the
rigid-wheel envelope of SPEC section 2 as input, ``scipy.signal.lsim`` with
the road at 0.1 ms): the relative RMS difference of each channel, per run.
``before`` is the previous MuJoCo car (contact impedance 1e-3 whose
weightless mass was left on the wheel, posts holding their velocity over a
step); each ``before + X`` changes one thing of it (time step halved,
integrator, joint armature, contact impedance, the tire as an explicit
spring instead of MuJoCo's soft contact, the contact's mass compensated, the
posts accelerating over the step, the road amplitude scaled, ``amplitude x F``); ``as
is`` is the present car. With ``--fit``, rideid's base model is fitted to the
ten noise-free runs of each (polished from the truth, seed 1) to see the
parameter bias directly. docs/verification.md has the numbers.

Run: ``python benchmarks/mujoco_engine_options.py [--fit] [--runs [ID ...]] [--options ...]``
(``--runs`` with no ID: all ten; about 10-50 s per option with its fit on two shared cores).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy import signal

import rideid
import rideid.verify.hifi as hifi_mod
from rideid.data.scenario import run_times
from rideid.model.equations import CHANNELS
from rideid.model.params import NAMES, as_vector
from rideid.model.simulate import corner_inputs
from rideid.model.tracks import Track
from rideid.synth.scenario import write_dataset


# ---------------------------------------------------------------------------
# an independent linear 7-DOF (SPEC section 1), written from the SPEC alone

def seven_dof(p: dict, geom):
    """State space (A, B, C, D) of the SPEC 7-DOF car: state [q, qdot], q = [z, theta, phi, z_fl, z_fr, z_rl, z_rr],
    input the four road heights r_i, outputs the ten SPEC channels."""
    a = p["a"]
    b = geom.wheelbase - a
    x = np.array([a, a, -b, -b])
    y = np.array([geom.track_front / 2, -geom.track_front / 2, geom.track_rear / 2, -geom.track_rear / 2])
    ks = np.array([p["k_sf"], p["k_sf"], p["k_sr"], p["k_sr"]])
    cs = np.array([p["c_sf"], p["c_sf"], p["c_sr"], p["c_sr"]])
    kt = np.array([p["k_tf"], p["k_tf"], p["k_tr"], p["k_tr"]])
    mu = np.array([p["m_uf"], p["m_uf"], p["m_ur"], p["m_ur"]])
    T = np.column_stack([np.ones(4), -x, y])          # body displacement at the corners: z_b = T [z, theta, phi]
    Dd = np.hstack([-T, np.eye(4)])                   # suspension deflection z_i - z_bi = Dd q
    M = np.diag(np.concatenate([[p["m_s"], p["I_yy"], p["I_xx"]], mu]))
    K = Dd.T @ np.diag(ks) @ Dd
    K[3:, 3:] += np.diag(kt)
    C = Dd.T @ np.diag(cs) @ Dd
    E = np.vstack([np.zeros((3, 4)), np.diag(kt)])    # road force on the wheels
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((7, 7)), np.eye(7)], [-Mi @ K, -Mi @ C]])
    B = np.vstack([np.zeros((7, 4)), Mi @ E])
    acc_x, acc_u = A[7:], B[7:]                        # qddot = acc_x [q, qdot] + acc_u r
    S = np.zeros((8, 7))
    S[:4, :3] = T                                      # body_az at the corners
    S[4:8, 3:] = np.eye(4)                             # axle_az
    Cout = S @ acc_x
    Dout = S @ acc_u
    rates = np.zeros((2, 14))
    rates[0, 7 + 1] = 1.0                              # pitch_rate
    rates[1, 7 + 2] = 1.0                              # roll_rate
    return A, B, np.vstack([Cout, rates]), np.vstack([Dout, np.zeros((2, 4))])


def simulate_7dof(P, geom, track, speed, t, dt=1e-4):
    """Channels of the linear 7-DOF at the sample times ``t`` (road at ``dt``, linearly interpolated)."""
    p = dict(zip(NAMES, np.asarray(P, dtype=float)))
    sys_ = signal.StateSpace(*seven_dof(p, geom))
    tf = np.arange(0.0, t[-1] + dt / 2, dt)
    r = corner_inputs(track, geom, speed * tf)
    _, y, _ = signal.lsim(sys_, r, tf, interp=True)
    idx = np.rint(t / dt).astype(int)
    return y[idx]


# ---------------------------------------------------------------------------
# the MuJoCo car with one option changed

class ProbeCar(hifi_mod.MujocoCar):
    """The MuJoCo car with switches: ``compensate`` (the contact's weightless mass taken out of the wheel),
    ``quadratic`` (posts accelerating over each step), ``spring_tire`` (the tire as an explicit unilateral
    spring, K times the penetration of the post's top into the wheel's disc, in the passive-force callback,
    instead of MuJoCo's soft contact)."""

    compensate = True
    quadratic = True
    spring_tire = False

    def __init__(self, *a, **k):
        super().__init__(*a, **k)
        mj, m = self.mj, self.model
        if not self.compensate or self.spring_tire:  # the wheel's own mass again, no weight added
            for i, w in enumerate(self._wheel_ids):
                m.body_mass[w] += self.contact_mass[i]
                m.body_gravcomp[w] = 0.0
            self.contact_mass[:] = 0.0
        if self.spring_tire:
            m.geom_contype[self._tire_ids] = 0
            m.geom_conaffinity[self._tire_ids] = 0
            p = dict(zip(NAMES, self.P))
            self._K = np.array([p["k_tf"], p["k_tf"], p["k_tr"], p["k_tr"]])
            self._post = [mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, f"post_{c}") for c in hifi_mod.CORNERS]
            self.needs_callback = True

    def set_road(self, r, rdot, rddot=None):
        super().set_road(r, rdot, rddot if self.quadratic else None)

    def _pen(self, d, i):
        return d.xpos[self._post[i], 2] - (d.xpos[self._wheel_ids[i], 2] - self.geom.tire_radius)

    def _passive(self, m, d):
        if m.nv != self.model.nv:
            return
        super()._passive(m, d)
        if self.spring_tire:
            for i in range(4):
                pen = self._pen(d, i)
                if pen > 0:
                    self.mj.mj_applyFT(m, d, np.array([0.0, 0.0, self._K[i] * pen]), np.zeros(3),
                                       d.xpos[self._wheel_ids[i]].copy(), self._wheel_ids[i], d.qfrc_passive)


@contextlib.contextmanager
def mujoco_option(option: str):
    """Patch :mod:`rideid.verify.hifi` for engine options joined by ``" + "`` (``"as is"`` leaves it alone)."""
    saved = (hifi_mod.TIMESTEP, hifi_mod.IMPEDANCE, hifi_mod.build_mjcf, hifi_mod.MujocoCar)
    flags = (ProbeCar.compensate, ProbeCar.quadratic, ProbeCar.spring_tire)
    hifi_mod.MujocoCar = ProbeCar
    try:
        for opt in option.split(" + "):
            build = hifi_mod.build_mjcf
            if opt == "before":  # the MJCF of the previous version: d = 1e-3 uncompensated, posts holding rdot
                hifi_mod.IMPEDANCE = 1e-3
                ProbeCar.compensate = ProbeCar.quadratic = False
            elif opt.startswith("timestep "):
                hifi_mod.TIMESTEP = float(opt.split()[1]) * 1e-3
            elif opt.startswith("integrator "):
                name = opt.split()[1]
                hifi_mod.build_mjcf = (lambda b, n: lambda *a, **k: b(*a, **k).replace(
                    'integrator="RK4"', f'integrator="{n}"'))(build, name)
            elif opt.startswith("impedance "):
                hifi_mod.IMPEDANCE = float(opt.split()[1])
            elif opt == "armature 0.1":  # (default 0) a rotor inertia on every joint
                hifi_mod.build_mjcf = (lambda b: lambda *a, **k: b(*a, **k).replace(
                    "<worldbody>", '<default><joint armature="0.1"/></default>\n  <worldbody>'))(build)
            elif opt == "spring tire":
                ProbeCar.spring_tire = True
            elif opt == "compensated":
                ProbeCar.compensate = True
            elif opt == "quadratic posts":
                ProbeCar.quadratic = True
            elif opt not in ("as is", "numpy 7-DOF") and not opt.startswith("amplitude x "):
                raise ValueError(opt)
        yield
    finally:
        hifi_mod.TIMESTEP, hifi_mod.IMPEDANCE, hifi_mod.build_mjcf, hifi_mod.MujocoCar = saved
        ProbeCar.compensate, ProbeCar.quadratic, ProbeCar.spring_tire = flags


def engine(option, P, geom, track, speed, t):
    """The option's channels: MuJoCo's (patched) or, for ``numpy 7-DOF``, the independent linear model's."""
    track = scaled(track, amplitude(option))
    if "numpy 7-DOF" in option:
        return simulate_7dof(P, geom, track, speed, t)
    return hifi_mod.simulate_mujoco(P, geom, track, speed, t)


def scaled(track, factor):
    key = "height" if track.kind == "chassis_twist" else "amplitude"
    return Track(track.id, track.kind, dict(track.keys, **{key: track.keys[key] * factor}))


def channels(sc, option, runs):
    """MuJoCo's and the 7-DOF's channels of the runs, with the option."""
    P = as_vector(sc.truth)
    out = {}
    with mujoco_option(option):
        for run in sc.runs:
            if runs and run.id not in runs:
                continue
            t = run_times(run)
            track = sc.tracks[run.track]
            y_mj = engine(option, P, sc.geometry, track, run.speed, t)
            y_np = simulate_7dof(P, sc.geometry, scaled(track, amplitude(option)),
                                 run.speed, t)
            out[run.id] = (t, y_mj, y_np)
    return out


def rel_rms(y_mj, y_np):
    """RMS of the difference, % of the 7-DOF channel's RMS (nan for a channel the run does not excite)."""
    ref = np.sqrt(np.mean(y_np ** 2, axis=0))
    diff = np.sqrt(np.mean((y_mj - y_np) ** 2, axis=0))
    return np.where(ref > 1e-6 * ref.max(), 100 * diff / np.maximum(ref, 1e-300), np.nan)


def fit(sc, option):
    """rideid's base model on the ten noise-free MuJoCo runs with the option (polished from the truth)."""
    P = as_vector(sc.truth)
    data = {}
    with mujoco_option(option):
        for run in sc.runs:
            t = run_times(run)
            data[run.id] = (t, engine(option, P, sc.geometry, sc.tracks[run.track], run.speed, t))
    if amplitude(option) != 1.0:
        sc = _scaled_scenario(sc, amplitude(option))
    with tempfile.TemporaryDirectory() as tmp:
        write_dataset(sc, data, Path(tmp) / "ds")
        ds = rideid.load_dataset(Path(tmp) / "ds")
        from rideid.estimate.problem.cost import ParameterSpace
        names = list(ParameterSpace(ds.known, ds.geometry, ds.manifest.bounds, extensions=()).names)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = rideid.identify(ds, seed=1, model="base", start=[sc.truth[n] for n in names])
    return {n: 100 * (res.parameters[n] / sc.truth[n] - 1) for n in NAMES}


def _scaled_scenario(sc, factor):
    import dataclasses
    return dataclasses.replace(sc, tracks={k: scaled(v, factor) for k, v in sc.tracks.items()})


def amplitude(option):
    """The road amplitude factor of an option (``amplitude x F``; 1 without)."""
    for opt in option.split(" + "):
        if opt.startswith("amplitude x "):
            return float(opt.split()[2])
    return 1.0


#: "before" is the previous MJCF (contact impedance 1e-3 not compensated, posts holding their velocity over a
#: step); each option changes one thing of it; "as is" is the present one
OPTIONS = ("before", "before + timestep 0.5", "before + integrator Euler", "before + integrator implicitfast",
           "before + armature 0.1", "before + impedance 1e-4", "before + spring tire", "before + compensated",
           "before + quadratic posts", "before + amplitude x 0.1", "as is", "as is + timestep 0.5",
           "as is + amplitude x 0.5", "as is + amplitude x 0.25", "as is + amplitude x 0.1", "numpy 7-DOF")


def main(argv=None, out=sys.stdout):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="*", default=["T_LL", "H_HH", "W_H"])
    ap.add_argument("--options", nargs="*", default=list(OPTIONS))
    ap.add_argument("--fit", action="store_true", help="also fit rideid's base model to each option's ten runs")
    a = ap.parse_args(argv)
    sc = rideid.default_scenario()

    def say(*x):
        print(*x, file=out, flush=True)

    say("relative RMS difference MuJoCo - linear 7-DOF, % of the 7-DOF channel's RMS, per run")
    say("option | run | " + " | ".join(CHANNELS))
    for option in a.options:
        t0 = time.perf_counter()
        for rid, (_t, y_mj, y_np) in channels(sc, option, a.runs).items():
            say(f"{option} | {rid} | " + " | ".join(f"{v:.3f}" for v in rel_rms(y_mj, y_np)))
        if a.fit:
            err = fit(sc, option)
            say(f"{option} | base fit, noise-free, error % | "
                + " ".join(f"{n} {err[n]:+.3f}" for n in NAMES))
        say(f"   ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
