"""Why the MuJoCo car and the 7-DOF model differ on the 80 mm twist: the second-order kinematics, group by group.

The realistic car of ``benchmarks/verify_mujoco.py`` (CG 0.25 m above the wheel centres, wheel spin
inertia, 2:1 digressive dampers, bump stops, anti-roll bars, tire damping) is run on one chassis-twist run
(T_HL: 80 mm bumps at 3 m/s, the body rolls 3.4 deg and pitches 1.9 deg) by

* the 7-DOF nonlinear simulator of SPEC section 8 (``rideid simulate``'s engine; the wheels' spin inertia in
  I_xx, I_yy as docs/verification.md counts it),
* the MuJoCo car of :mod:`rideid.verify.hifi`, and
* :class:`ExactCar`, written here from the MuJoCo car's construction: its exact rigid-body equations in the
  7-DOF coordinates ``q = [z, theta, phi, z_fl, z_fr, z_rl, z_rr]`` (``z_i`` the world-vertical displacement
  of wheel centre ``i``). Every term that is not in the small-angle model belongs to one of five groups, and
  each group can be taken exact (as MuJoCo has it) or small-angle (as the 7-DOF model has it):

  ``inertia``
      the wheel centres' horizontal motion (they swing with the body about the CG, and slide along the
      tilted suspension axis) in the kinetic energy: a configuration-dependent mass matrix and
      centripetal/Coriolis terms (small-angle: the constant swing inertia ``m_u h^2`` of SPEC section 8);
      with the body's rotation kinematics (``omega = (phi', theta' cos phi, -theta' sin phi)``, negligible);
  ``preload``
      the static spring force ``F0`` acting through the exact slide coordinate (small-angle: through its
      quadratic part ``d - h (theta^2 + phi^2) / 2``, which is where the toppling stiffness ``-m_s g h``
      comes from);
  ``deflection``
      the spring, damper, bar and bump stop act on the slide coordinate
      ``s = h + (z_i - z + x sin(theta) - y cos(theta) sin(phi) - h) / (cos(theta) cos(phi))`` and its rate
      (small-angle: ``d = z_i - z + x theta - y phi``; ``s - d = (d - h)(theta^2 + phi^2) / 2 + ...``:
      the wheel hanging ``h`` below the CG rises as the body turns, and the slide is tilted);
  ``direction``
      the suspension force acts along the tilted slide, between the wheel and the body point it moves
      with (small-angle: vertical, at ``(x_i, y_i)``);
  ``sensor``
      each accelerometer reads along its own (tilted) z axis: ``a . z_s`` with the wheel centre's
      horizontal acceleration (small-angle: the vertical acceleration, SPEC section 1).

  The tire is a sphere on a flat pad in MuJoCo, so its contact point stays under the wheel centre whatever
  the tilt (no contact-point term); the wheels do not spin (their inertia turns with the body).

With every group small-angle, :class:`ExactCar` reproduces the 7-DOF simulator (an independent check of
it); with every group exact, MuJoCo within the engines' own floor (the contact's impedance, as on the
reduced car). In between, each group's share of the difference. A second construction
(``vertical slides``: each wheel centre moves world-vertically below the body point ``(x, y, -h)`` it swings
with, the suspension force vertical) shows what a MuJoCo car with vertical wheel travel would give.

The axle reading is also taken apart from MuJoCo's own states (``mj_objectAcceleration`` of each wheel
centre and its site frame): reading ``= a . z_s`` (gravity removed in the sensor frame, as
:meth:`rideid.verify.hifi.MujocoCar.outputs`) ``= a_z + a_y z_sy + a_x z_sx + a_z (z_sz - 1)``.

Run: ``python benchmarks/engines_kinematics.py [--heights 20 40 80] [--run T_HL] [--dt 2.5e-4]`` (about 13
minutes per height on one core; results in docs/verification.md).
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time
import warnings

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np

import rideid
from rideid.data.scenario import run_times
from rideid.synth.scenario import simulate_manifest
from rideid.data.schema import HifiProperties, parse_scenario, read_toml
from rideid.model.equations import CHANNELS, static_corner_loads
from rideid.model.params import CORNERS, GRAVITY, NAMES, as_vector
from rideid.model.simulate import corner_inputs
from rideid.verify.hifi import TIMESTEP, MujocoCar, damper_force

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from verify_mujoco import BARS, REALISTIC, TIRE_DAMPING  # noqa: E402

GROUPS = ("inertia", "preload", "deflection", "direction", "sensor")
#: damper knots of the 7-DOF car: the defaults and the knee, where the MuJoCo car's damper bends (exact curve)
KNOTS = (-0.4, -0.2, -0.15, -0.1, -0.05, -0.025, 0.025, 0.05, 0.1, 0.15, 0.2, 0.4)


def scenarios(height: float, run_id: str, cg: float):
    """The realistic car on one run, the twist bumps ``height`` m high: ``(sc7, scm, hifi)``, the scenario of the
    7-DOF car (``[dampers]`` curves through the MuJoCo car's damper, ``[truth]`` bump stops, the wheels' spin
    inertia in I_xx and I_yy) and the MuJoCo car's (``[truth]`` with bars and tire damping, the rest ``hifi``,
    as ``benchmarks/verify_mujoco.py`` builds it)."""
    hifi = HifiProperties(**dict(REALISTIC, cg_height=cg))
    doc = read_toml(rideid.default_scenario_path())
    doc["runs"] = [r for r in doc["runs"] if r["id"] == run_id]
    track = doc["runs"][0]["track"]
    for tr in doc["tracks"]:
        if tr["id"] == track and tr["kind"] == "chassis_twist":
            tr["height"] = height
    doc["truth"].update(BARS, **TIRE_DAMPING)
    if cg:
        doc["vehicle"]["cg_height"] = cg
    scm = parse_scenario(copy.deepcopy(doc), "mujoco.toml")
    t = doc["truth"]
    (cf, cr), (rf, rr) = hifi.bumpstop_clearance, hifi.bumpstop_rate
    t.update(bs_clear_f=cf, bs_clear_r=cr, bs_rate_f=rf, bs_rate_r=rr)
    doc["dampers"] = {"velocity": list(KNOTS), **{
        ax: [float(f) for f in damper_force(np.array(KNOTS), t[c], hifi.damper_rebound_ratio[k],
                                             hifi.damper_knee_velocity[k], hifi.damper_knee_ratio[k])]
        for k, (ax, c) in enumerate((("front", "c_sf"), ("rear", "c_sr")))}}
    iw = sum(hifi.wheel_inertia)  # four thin discs turning with the body: I_w/2 each in roll, I_w each in pitch
    t["I_xx"] += iw
    t["I_yy"] += 2 * iw
    return parse_scenario(doc, "7dof.toml"), scm, hifi


def mujoco_run(scm, hifi):
    """The MuJoCo car on the scenario's run (as ``simulate_mujoco``), with each wheel centre's world acceleration
    and z axis at the samples."""
    import mujoco
    run = scm.runs[0]
    t = run_times(run)
    car = MujocoCar(as_vector(scm.truth), scm.geometry, hifi)
    m, d = car.model, car.data
    sub = int(round((t[1] - t[0]) / TIMESTEP))
    tf = t[0] + TIMESTEP * np.arange((t.size - 1) * sub + 1)
    r, rd = road(scm)(tf)
    rdd = 2 * (road(scm)(tf + TIMESTEP)[0] - r - rd * TIMESTEP) / TIMESTEP ** 2  # the posts' uniform acceleration
    sid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"axle_{c}") for c in CORNERS]
    y = np.empty((t.size, len(CHANNELS)))
    acc, zax = np.empty((t.size, 4, 3)), np.empty((t.size, 4, 3))
    res = np.zeros(6)
    with car.active():
        for j in range(tf.size):
            car.set_road(r[j], rd[j], rdd[j])
            if j % sub == 0:  # the state at the sample (mj_step's own forward pass gives the same)
                k = j // sub
                mujoco.mj_forward(m, d)
                y[k] = car.outputs()
                for i, s in enumerate(sid):
                    mujoco.mj_objectAcceleration(m, d, mujoco.mjtObj.mjOBJ_SITE, s, res, 0)
                    acc[k, i] = res[3:] - [0.0, 0.0, GRAVITY]  # MuJoCo's includes -gravity (specific force)
                    zax[k, i] = d.site_xmat[s].reshape(3, 3)[:, 2]
            mujoco.mj_step(m, d)
    return y, acc, zax


def road(sc):
    """Road inputs and rates at any times (the rigid-wheel envelope, SPEC section 2), as the MuJoCo posts get them."""
    run = sc.runs[0]
    track, geom = sc.tracks[run.track], sc.geometry

    def f(tt):
        eps = 1e-5
        x = run.speed * np.asarray(tt, dtype=float)
        rd = (corner_inputs(track, geom, x + run.speed * eps)
              - corner_inputs(track, geom, x - run.speed * eps)) / (2 * eps)
        return corner_inputs(track, geom, x), rd
    return f


# ---------------------------------------------------------------------------------------------------------------
# the MuJoCo car's exact equations in the 7-DOF coordinates

class Kinematics:
    """The MuJoCo car's geometry: the body turns about its CG (``R = Ry(theta) Rx(phi)``), wheel centre ``i`` on a
    slide along the body's z axis through ``(x_i, y_i, -h)``; the slide coordinate ``s`` for given ``q``."""

    def __init__(self, x, y, h):
        self.x, self.y, self.h = np.asarray(x, float), np.asarray(y, float), float(h)

    def slide(self, Q):
        Z, th, ph, z = Q[..., :1], Q[..., 1:2], Q[..., 2:3], Q[..., 3:]
        u = z - Z + self.x * np.sin(th) - self.y * np.cos(th) * np.sin(ph)
        return self.h + (u - self.h) / (np.cos(th) * np.cos(ph))

    def slide2(self, Q):
        """Its quadratic part (the small-angle model's, with the CG height's toppling)."""
        Z, th, ph, z = Q[..., :1], Q[..., 1:2], Q[..., 2:3], Q[..., 3:]
        return z - Z + self.x * th - self.y * ph - self.h * (th ** 2 + ph ** 2) / 2

    def horizontal(self, Q):
        """Wheel centres' X_1..4, Y_1..4 (from the CG)."""
        th, ph = Q[..., 1:2], Q[..., 2:3]
        w = self.slide(Q) - self.h
        up = self.y * np.sin(ph) + w * np.cos(ph)
        return np.concatenate([self.x * np.cos(th) + np.sin(th) * up, self.y * np.cos(ph) - w * np.sin(ph)], -1)


class VerticalSlides(Kinematics):
    """Each wheel centre stays horizontally below the body point ``(x, y, -h)`` (it swings with the body) and moves
    world-vertically; the suspension deflection is the vertical distance to that point, its force vertical."""

    def slide(self, Q):
        Z, th, ph, z = Q[..., :1], Q[..., 1:2], Q[..., 2:3], Q[..., 3:]
        return z - Z + self.x * np.sin(th) - self.y * np.cos(th) * np.sin(ph) - self.h * (1 - np.cos(th) * np.cos(ph))

    def horizontal(self, Q):
        th, ph = Q[..., 1:2], Q[..., 2:3]
        return np.concatenate([self.x * np.cos(th) + np.sin(th) * (self.y * np.sin(ph) - self.h * np.cos(ph)),
                               self.y * np.cos(ph) + self.h * np.sin(ph) + 0 * self.x], -1)


_E = np.eye(7)


def _jac(fun, q, eps=1e-6):
    F = fun(np.concatenate([q + eps * _E, q - eps * _E]))
    return ((F[:7] - F[7:]) / (2 * eps)).T


def _jac_quad(fun, q, v, eps=1e-6, eps2=1e-4):
    """Jacobian and ``v^T H v`` (the ``J' v`` of an acceleration), central differences in one batch."""
    nv = float(np.linalg.norm(v))
    u = v / nv if nv > 0 else v
    F = fun(np.concatenate([q + eps * _E, q - eps * _E, [q, q + eps2 * u, q - eps2 * u]]))
    return ((F[:7] - F[7:14]) / (2 * eps)).T, (F[15] - 2 * F[14] + F[16]) / eps2 ** 2 * nv ** 2


class ExactCar:
    """The realistic car's equations with the groups in ``exact`` as MuJoCo has them, the others small-angle."""

    def __init__(self, sc, hifi, exact=(), kinematics=Kinematics):
        """``sc``: the 7-DOF car's scenario (:func:`scenarios`); ``hifi``: the MuJoCo car's properties."""
        p = dict(zip(NAMES, as_vector(sc.truth)[:12]))
        x, y = (v[0] for v in sc.geometry.corner_xy(np.array([p["a"]])))
        h = sc.geometry.cg_height
        self.kin = kinematics(x, y, h)
        self.exact = set(exact)
        self.gd = np.zeros((4, 7))  # d = gd q
        for i in range(4):
            self.gd[i, [0, 1, 2, 3 + i]] = [-1.0, x[i], -y[i], 1.0]
        # body and wheels turning together (sc's I_xx, I_yy hold the wheels' spin inertia; about z the MuJoCo body
        # has I_xx + I_yy of its own, each wheel I_w / 2)
        iw = sum(hifi.wheel_inertia)
        self.I = np.diag([p["I_xx"], p["I_yy"], p["I_xx"] + p["I_yy"] - 2 * iw])
        self.m_s = p["m_s"]
        ax = np.array([0, 0, 1, 1])
        self.m_u = np.array([p["m_uf"], p["m_ur"]])[ax]
        self.k_s = np.array([p["k_sf"], p["k_sr"]])[ax]
        self.k_t = np.array([p["k_tf"], p["k_tr"]])[ax]
        self.c_t = np.array([sc.truth["c_tf"], sc.truth["c_tr"]])[ax]
        self.bars = (sc.truth["k_arf"], sc.truth["k_arr"])
        (cf, cr), (rf, rr) = sc.bump_stop_pairs
        self.bs_clear, self.bs_rate = np.array([cf, cr])[ax], np.array([rf, rr])[ax]
        v = np.asarray(sc.dampers.velocity)
        self.curves = [(v, np.asarray(sc.dampers.curve(a))) for a in "ffrr"]
        self.L0 = static_corner_loads(as_vector(sc.truth)[None, :12], sc.geometry, GRAVITY)[0]
        self.F0 = self.L0 - self.m_u * GRAVITY
        swing = np.sum(self.m_u) * h * h
        self.M = np.diag([self.m_s, self.I[1, 1] + swing, self.I[0, 0] + swing, *self.m_u])
        self.m_u8 = np.concatenate([self.m_u, self.m_u])

    def suspension(self, s, v):
        from rideid.model.nonlinear import damper_force as curve
        f = self.k_s * s + np.array([curve(k, F, vi) for (k, F), vi in zip(self.curves, v)])
        kf, kr = self.bars
        f += np.array([kf * (s[0] - s[1]), kf * (s[1] - s[0]), kr * (s[2] - s[3]), kr * (s[3] - s[2])])
        return f + self.bs_rate * np.maximum(s - self.bs_clear, 0.0)

    def accel(self, q, qd, r, rd):
        ex, kin = self.exact, self.kin
        if "inertia" in ex:
            J, quad = _jac_quad(kin.horizontal, q, qd)
            c, s = np.cos(q[2]), np.sin(q[2])
            Jw = np.zeros((3, 7))
            Jw[0, 2], Jw[1, 1], Jw[2, 1] = 1.0, c, -s
            w = Jw @ qd
            Jw_dot = np.array([0.0, -s * qd[2] * qd[1], -c * qd[2] * qd[1]])
            M = Jw.T @ self.I @ Jw + J.T @ (self.m_u8[:, None] * J)
            M[0, 0] += self.m_s
            M[3:, 3:] += np.diag(self.m_u)
            bias = Jw.T @ (self.I @ Jw_dot + np.cross(w, self.I @ w)) + J.T @ (self.m_u8 * quad)
        else:
            M, bias = self.M, 0.0
        Q = np.zeros(7)
        Q[0] = -self.m_s * GRAVITY
        pen = self.L0 / self.k_t + r - q[3:]  # the tire pushes but never pulls
        Q[3:] = -self.m_u * GRAVITY + np.where(pen > 0, np.maximum(self.k_t * pen + self.c_t * (rd - qd[3:]), 0.0), 0.0)
        gs = _jac(kin.slide, q)
        Q -= self.F0 @ (gs if "preload" in ex else _jac(kin.slide2, q))
        if "deflection" in ex:
            s, v = kin.slide(q), gs @ qd
        else:
            s, v = self.gd @ q, self.gd @ qd
        Q -= self.suspension(s, v) @ (gs if "direction" in ex else self.gd)
        return np.linalg.solve(M, Q - bias)

    def outputs(self, q, qd, qdd):
        th, ph = q[1], q[2]
        y = np.empty(len(CHANNELS))
        kin = self.kin
        if "sensor" in self.exact:
            zs = np.array([np.sin(th) * np.cos(ph), -np.sin(ph), np.cos(th) * np.cos(ph)])

            def body_points(Q):
                Z, t_, p_ = Q[..., :1], Q[..., 1:2], Q[..., 2:3]
                return np.concatenate([kin.x * np.cos(t_) + np.sin(t_) * kin.y * np.sin(p_),
                                       kin.y * np.cos(p_) + 0 * t_,
                                       Z - kin.x * np.sin(t_) + np.cos(t_) * kin.y * np.sin(p_)], -1)
            J, quad = _jac_quad(body_points, q, qd)
            y[:4] = zs @ (J @ qdd + quad).reshape(3, 4)
            J, quad = _jac_quad(kin.horizontal, q, qd)
            a = (J @ qdd + quad).reshape(2, 4)
            y[4:8] = zs[0] * a[0] + zs[1] * a[1] + zs[2] * qdd[3:]
            y[8], y[9] = qd[1] * np.cos(ph), qd[2]  # the gyro's body-frame rates
        else:
            y[:4] = qdd[0] - kin.x * qdd[1] + kin.y * qdd[2]
            y[4:8] = qdd[3:]
            y[8], y[9] = qd[1], qd[2]
        return y

    def simulate(self, road_of, t, dt=2.5e-4):
        """Outputs at the sample times ``t`` (from static equilibrium; RK4 at ``dt``)."""
        sub = int(round((t[1] - t[0]) / dt))
        n = (t.size - 1) * sub + 1
        R, RD = road_of(t[0] + dt * np.arange(2 * n - 1) / 2)
        q, v = np.zeros(7), np.zeros(7)
        out = np.empty((t.size, len(CHANNELS)))
        for j in range(n):
            a1 = self.accel(q, v, R[2 * j], RD[2 * j])
            if j % sub == 0:
                out[j // sub] = self.outputs(q, v, a1)
            if j == n - 1:
                break
            q2, v2 = q + 0.5 * dt * v, v + 0.5 * dt * a1
            a2 = self.accel(q2, v2, R[2 * j + 1], RD[2 * j + 1])
            q3, v3 = q + 0.5 * dt * v2, v + 0.5 * dt * a2
            a3 = self.accel(q3, v3, R[2 * j + 1], RD[2 * j + 1])
            q4, v4 = q + dt * v3, v + dt * a3
            a4 = self.accel(q4, v4, R[2 * j + 2], RD[2 * j + 2])
            q = q + dt / 6 * (v + 2 * v2 + 2 * v3 + v4)
            v = v + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        return out


def rel(a, b):
    """RMS of ``a - b`` per channel, % of the RMS of ``b``."""
    return 100 * np.sqrt(np.mean((a - b) ** 2, axis=0)) / np.sqrt(np.mean(b ** 2, axis=0))


def _row(label, e, extra=""):
    return (f"| {label} | " + " | ".join(f"{v:.2f}" for v in e[4:8]) + f" | {e[:4].max():.2f} | {e[8]:.2f} | "
            f"{e[9]:.2f} |{extra}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--heights", type=float, nargs="*", default=[80.0], help="twist bump heights, mm")
    ap.add_argument("--run", default="T_HL")
    ap.add_argument("--cg", type=float, default=REALISTIC["cg_height"], help="CG above the wheel centres, m")
    ap.add_argument("--dt", type=float, default=2.5e-4, help="RK4 step of the exact equations, s")
    a = ap.parse_args(argv)
    head = ("| | axle fl | axle fr | axle rl | axle rr | body (largest) | pitch rate | roll rate |\n"
            "|---|---|---|---|---|---|---|---|")
    for hmm in a.heights:
        t0 = time.perf_counter()
        sc7, scm, hifi = scenarios(hmm / 1000, a.run, a.cg)
        t = run_times(sc7.runs[0])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            y7 = simulate_manifest(sc7)[0][a.run][1]
        yM, acc, zax = mujoco_run(scm, hifi)
        print(f"\n## {a.run}, twist bumps {hmm:g} mm, CG {a.cg:g} m above the wheel centres\n")
        print("Difference to the MuJoCo car, % of each channel's RMS (MuJoCo's for the first rows):\n")
        print(head)
        print(_row("7-DOF model", rel(y7, yM)))
        # the axle reading from MuJoCo's own states
        world = acc[..., 2]
        rms = np.sqrt(np.mean(yM[:, 4:8] ** 2, axis=0))
        terms = {"a_y z_sy": acc[..., 1] * zax[..., 1], "a_x z_sx": acc[..., 0] * zax[..., 0],
                 "a_z (z_sz - 1)": world * (zax[..., 2] - 1)}
        check = world + sum(terms.values()) - yM[:, 4:8]
        assert np.abs(check).max() < 1e-9 * np.abs(yM).max(), np.abs(check).max()
        e = rel(y7[:, 4:8], world)
        print("| 7-DOF model against MuJoCo's world-vertical wheel-centre acceleration a_z | "
              + " | ".join(f"{v:.2f}" for v in e) + " | | | |")
        for name, v in terms.items():
            print(f"| term {name} of the MuJoCo reading (RMS) | "
                  + " | ".join(f"{x:.2f}" for x in 100 * np.sqrt(np.mean(v ** 2, axis=0)) / rms) + " | | | |")
        print("\nThe exact equations (this module) with the named groups exact, the others small-angle: against "
              "the 7-DOF model and against MuJoCo, % of each channel's RMS:\n")
        print("| exact groups | against | axle fl | axle fr | axle rl | axle rr | body (largest) | pitch rate | "
              "roll rate |\n"
              "|---|---|---|---|---|---|---|---|---|")
        configs = [("none (the 7-DOF model)", ())] + [(g, (g,)) for g in GROUPS] \
            + [(f"all but {g}", tuple(x for x in GROUPS if x != g)) for g in GROUPS] \
            + [("all (the MuJoCo car)", GROUPS)]
        for label, ex in configs:
            y = ExactCar(sc7, hifi, ex).simulate(road(sc7), t, a.dt)
            for against, ref in (("7-DOF", y7), ("MuJoCo", yM)):
                e = rel(y, ref)
                print(f"| {label} | {against} | " + " | ".join(f"{v:.2f}" for v in e[4:8])
                      + f" | {e[:4].max():.2f} | {e[8]:.2f} | {e[9]:.2f} |", flush=True)
        for label, ex in (("vertical slides, all exact", GROUPS),
                          ("vertical slides, all exact but sensor", tuple(g for g in GROUPS if g != "sensor"))):
            y = ExactCar(sc7, hifi, ex, VerticalSlides).simulate(road(sc7), t, a.dt)
            e = rel(y, y7)
            print(f"| {label} | 7-DOF | " + " | ".join(f"{v:.2f}" for v in e[4:8])
                  + f" | {e[:4].max():.2f} | {e[8]:.2f} | {e[9]:.2f} |", flush=True)
        print(f"\n({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
