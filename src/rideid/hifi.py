"""An independent multibody car in MuJoCo, driven on a 4-poster (verification data).

Work in progress (issue 8): the linear car of SPEC §1 built as a MuJoCo
multibody model — sprung body with heave, pitch and roll joints at its CG,
four wheels on vertical slides (suspension spring and damper as joint
stiffness and damping, preloaded through ``springref`` so the car starts in
equilibrium), each tire resting on a heavy post whose position and velocity
are set every step to the rigid-wheel envelope under that wheel. The tire's
vertical stiffness is MuJoCo's soft contact with a tiny constant impedance
and a direct (negative) ``solref`` scaled by the wheel's ``body_invweight0``.
Integration: RK4 at 1 ms. Outputs: the SPEC channels from accelerometers at
the body corners and wheel centres (gravity removed in the sensor frame) and
a body gyro.
"""

from __future__ import annotations

import numpy as np

from .errors import DataError
from .model import CHANNELS
from .params import CORNERS, GRAVITY, NAMES, Geometry

#: contact impedance (solimp dmin = dmax): tiny, so the contact adds no normal "mass"
IMPEDANCE = 1e-3
POST_MASS = 1e6
TIMESTEP = 1e-3


def _require():
    try:
        import mujoco
    except ImportError:
        raise DataError("the MuJoCo engine needs the package 'mujoco-core': pip install 'rideid[hifi]'") from None
    return mujoco


def corner_xy(P, geom: Geometry):
    a = P[NAMES.index("a")]
    b = geom.wheelbase - a
    hf, hr = geom.track_front / 2, geom.track_rear / 2
    return [(a, hf), (a, -hf), (-b, hr), (-b, -hr)]


def build_mjcf(P, geom: Geometry, cg_height: float = 0.0, wheel_inertia: float = 0.0) -> str:
    """MJCF text of the car. ``cg_height``: CG above the wheel centres (m)."""
    p = dict(zip(NAMES, np.asarray(P, dtype=float)))
    R = geom.tire_radius
    izz = p["I_xx"] + p["I_yy"]
    loads = _static_loads(p, geom)
    wheels, posts = [], []
    for i, (c, (x, y)) in enumerate(zip(CORNERS, corner_xy(np.asarray(P, dtype=float), geom))):
        front = c.startswith("f")
        mu, ks, cs = (p["m_uf"], p["k_sf"], p["c_sf"]) if front else (p["m_ur"], p["k_sr"], p["c_sr"])
        spring_force = loads["spring"][i]
        wi = max(wheel_inertia, 1e-6 * mu * R * R)
        wheels.append(f"""
      <site name="body_{c}" pos="{x} {y} 0" size="0.01"/>
      <body name="wheel_{c}" pos="{x} {y} {-cg_height}">
        <joint name="susp_{c}" type="slide" axis="0 0 1" stiffness="{ks}" damping="{cs}"
               springref="{-spring_force / ks}"/>
        <inertial pos="0 0 0" mass="{mu}" diaginertia="{wi} {wi} {wi}"/>
        <geom name="tire_{c}" type="sphere" size="{R}" priority="1" contype="1" conaffinity="1"
              solimp="{IMPEDANCE} {IMPEDANCE} 0.001 0.5 2" margin="0" friction="0 0 0" condim="1"/>
        <site name="axle_{c}" size="0.01"/>
      </body>""")
        pen = loads["tire"][i] / (p["k_tf"] if front else p["k_tr"])
        posts.append(f"""
    <body name="post_{c}" pos="{x} {y} {pen}" gravcomp="1">
      <joint name="post_{c}" type="slide" axis="0 0 1"/>
      <inertial pos="0 0 -0.05" mass="{POST_MASS}" diaginertia="1e4 1e4 1e4"/>
      <geom name="pad_{c}" type="box" size="0.2 0.2 0.05" pos="0 0 -0.05" contype="2" conaffinity="1"/>
    </body>""")
    z0 = R + cg_height
    return f"""<mujoco model="rideid-car">
  <option timestep="{TIMESTEP}" integrator="RK4" gravity="0 0 {-GRAVITY}"/>
  <worldbody>
    <body name="chassis" pos="0 0 {z0}">
      <joint name="heave" type="slide" axis="0 0 1"/>
      <joint name="pitch" type="hinge" axis="0 1 0"/>
      <joint name="roll" type="hinge" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="{p['m_s']}" diaginertia="{p['I_xx']} {p['I_yy']} {izz}"/>
      <site name="gyro" size="0.01"/>{''.join(wheels)}
    </body>{''.join(posts)}
  </worldbody>
  <sensor>
{''.join(f'    <accelerometer name="acc_body_{c}" site="body_{c}"/>{chr(10)}' for c in CORNERS)}\
{''.join(f'    <accelerometer name="acc_axle_{c}" site="axle_{c}"/>{chr(10)}' for c in CORNERS)}\
    <gyro name="gyro" site="gyro"/>
  </sensor>
</mujoco>"""


def _static_loads(p, geom):
    a = p["a"]
    b = geom.wheelbase - a
    fb = p["m_s"] * GRAVITY * b / geom.wheelbase / 2
    rb = p["m_s"] * GRAVITY * a / geom.wheelbase / 2
    spring = [fb, fb, rb, rb]
    tire = [fb + p["m_uf"] * GRAVITY, fb + p["m_uf"] * GRAVITY, rb + p["m_ur"] * GRAVITY, rb + p["m_ur"] * GRAVITY]
    return {"spring": spring, "tire": tire}


class MujocoCar:
    """A compiled MuJoCo car with the tire contact tuned to ``k_tf``/``k_tr``."""

    def __init__(self, P, geom: Geometry, cg_height: float = 0.0, wheel_inertia: float = 0.0,
                 tire_damping: float = 0.0):
        mujoco = _require()
        self.mj = mujoco
        self.P = np.asarray(P, dtype=float)
        self.geom = geom
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(self.P, geom, cg_height, wheel_inertia))
        m = self.model
        p = dict(zip(NAMES, self.P))
        d_imp = IMPEDANCE
        for c in CORNERS:
            gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"tire_{c}")
            bid = m.geom_bodyid[gid]
            A = m.body_invweight0[bid, 0]
            K = p["k_tf"] if c.startswith("f") else p["k_tr"]
            m.geom_solref[gid] = (-K * (1 - d_imp) * A, -tire_damping * (1 - d_imp) * A)
        self.data = mujoco.MjData(m)
        self._qadr = {c: m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"post_{c}")]
                      for c in CORNERS}
        self._vadr = {c: m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"post_{c}")]
                      for c in CORNERS}
        self._sens = {}
        for name in [f"acc_body_{c}" for c in CORNERS] + [f"acc_axle_{c}" for c in CORNERS] + ["gyro"]:
            sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, name)
            self._sens[name] = m.sensor_adr[sid]
        self._site = {n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n)
                      for n in [f"body_{c}" for c in CORNERS] + [f"axle_{c}" for c in CORNERS] + ["gyro"]}

    def set_road(self, r, rdot):
        d = self.data
        for i, c in enumerate(CORNERS):
            d.qpos[self._qadr[c]] = r[i]
            d.qvel[self._vadr[c]] = rdot[i]

    def outputs(self, raw: bool = False) -> np.ndarray:
        """The ten SPEC channels (vertical accelerations, gravity removed; ISO 8855 rates) from the sensors."""
        d = self.data
        out = np.empty(len(CHANNELS))
        for k, kind in enumerate(("body", "axle")):
            for i, c in enumerate(CORNERS):
                a = self._sens[f"acc_{kind}_{c}"]
                f = d.sensordata[a:a + 3]
                R = d.site_xmat[self._site[f"{kind}_{c}"]].reshape(3, 3)
                out[4 * k + i] = (R @ f)[2] - GRAVITY
        g = self._sens["gyro"]
        w = d.sensordata[g:g + 3]
        out[8], out[9] = w[1], w[0]
        return out

    def tire_loads(self) -> np.ndarray:
        """Normal force of each tire contact (N), 0 where a tire has lifted."""
        mujoco, m, d = self.mj, self.model, self.data
        loads = np.zeros(4)
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"tire_{c}") for c in CORNERS]
        f6 = np.zeros(6)
        for j in range(d.ncon):
            con = d.contact[j]
            for i, gid in enumerate(ids):
                if gid in (con.geom1, con.geom2):
                    mujoco.mj_contactForce(m, d, j, f6)
                    loads[i] += f6[0]
        return loads


def simulate_mujoco(P, geom: Geometry, track, speed, t, distance=None, **hifi) -> np.ndarray:
    """Outputs ``(n, 10)`` of the MuJoCo car at the sample times ``t``.

    ``t`` must be uniform with a step that is a multiple of 1 ms; the posts
    follow the rigid-wheel envelope (SPEC §2) at the front-axle distance
    ``speed * t`` (or ``distance(t)``), their velocity from a central
    difference of the envelope. ``hifi``: keyword arguments of :class:`MujocoCar`.
    """
    from .simulate import corner_inputs

    car = MujocoCar(P, geom, **hifi)
    mj, m, d = car.mj, car.model, car.data
    t = np.asarray(t, dtype=float)
    h = float(t[1] - t[0])
    sub = int(round(h / TIMESTEP))
    if sub < 1 or abs(sub * TIMESTEP - h) > 1e-9:
        raise DataError(f"MuJoCo engine: the sample interval {h} s must be a multiple of {TIMESTEP} s")
    tf = t[0] + TIMESTEP * np.arange((t.size - 1) * sub + 1)
    x_of = (lambda tt: speed * tt) if distance is None else distance
    eps = 1e-5
    r = corner_inputs(track, geom, x_of(tf))
    rdot = (corner_inputs(track, geom, x_of(tf + eps)) - corner_inputs(track, geom, x_of(tf - eps))) / (2 * eps)
    out = np.empty((t.size, len(CHANNELS)))
    for j in range(tf.size):
        car.set_road(r[j], rdot[j])
        mj.mj_step(m, d)  # sensordata (and site frames) now describe the start of this step, time tf[j]
        if j % sub == 0:
            out[j // sub] = car.outputs()
    return out


__all__ = ["MujocoCar", "build_mjcf", "simulate_mujoco"]
