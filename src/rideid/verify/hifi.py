"""An independent multibody car in MuJoCo, driven on a 4-poster (verification data).

The paper checks its estimator on data from an ADAMS car before trusting it
on a real one; this module gives rideid the same step with MuJoCo
(``mujoco-core``, ``pip install 'rideid[hifi]'``).

The car: a sprung body with heave, pitch and roll joints at its CG; four
wheels on vertical slides in the body frame (suspension spring and damper on
the slide, preloaded through ``springref`` so the car starts in static
equilibrium); each tire resting on a heavy post whose position and velocity
are set every step to the rigid-wheel envelope (SPEC §2) under that wheel,
and which accelerates uniformly over the step so that it reaches the road
height of the step's end (the road followed to third order in the step).
The tire's vertical stiffness is MuJoCo's soft contact with MuJoCo's
smallest constant impedance and a direct (negative) ``solref`` scaled by the
contact's ``body_invweight0``; the contact can push but never pull, so a
wheel really leaves the road. A soft contact also adds a weightless mass
d / ((1 - d) A) to the wheel (its force depends on the contact's own
acceleration): the wheel body carries m_u less that mass, with its weight
put back, so a wheel on the road has the 7-DOF model's mass and weight
(:attr:`MujocoCar.contact_mass`). Integration: RK4 at 1 ms.

With the default :class:`HifiProperties` (the ``[hifi]`` table's keys,
defaults and validation live in :mod:`rideid.data.schema.hifi`) this is the physics of SPEC §1 in
another engine. The optional ``[hifi]`` table of a scenario adds what a real
car has and the 7-DOF model lacks:

``cg_height`` (m)
    CG above the wheel centres; the wheels then swing about the body's
    pitch and roll axes (through the CG) instead of moving only vertically.
``wheel_inertia`` (kg m²)
    spin inertia of a wheel and tire (a thin disc: half of it about the
    wheel's other two axes); the wheels turn with the body in pitch and roll.
``damper_rebound_ratio``
    rebound over compression damping rate. The two rates average to the
    scenario's ``c_sf``/``c_sr`` (which is what a linear fit of a symmetric
    cycle returns), e.g. 2.0 gives 2/3 c_s in compression and 4/3 c_s in
    rebound.
``damper_knee_velocity`` (m/s), ``damper_knee_ratio``
    a digressive damper: above the knee velocity each branch continues with
    ``knee_ratio`` times its low-speed slope.
``bumpstop_clearance`` (m), ``bumpstop_rate`` (N/m)
    suspension compression from static ride height at which a linear bump
    stop engages, and its rate.
``tire_damping`` (N s/m)
    vertical damping of the tire contact (or ``c_tf``/``c_tr`` in
    ``[truth]``, SPEC §6; giving both is refused).

The scenario's ``[truth]`` powertrain (SPEC §11: ``m_p``, ``x_p``, ``I_p``,
``f_pb``, ``zeta_pb``, ``f_pp``, ``zeta_pp``) is a body of its own inside the
chassis, at ``x_p`` ahead of the CG, on a vertical slide and a pitch hinge
(its mounts: spring and damper of each, the slide preloaded by its weight);
the chassis then carries the rest of the sprung mass (mass ``m_s - m_p`` at
its own CG ``-m_p x_p / (m_s - m_p)``, pitch inertia by the parallel-axis
theorem), so the whole is the scenario's ``m_s``, ``I_yy``, ``a``. The
powertrain's roll and yaw inertia is taken as ``I_p`` and the chassis's roll
inertia reduced by it (the powertrain turns with the body in roll).

The scenario's ``[truth]`` anti-roll bars (``k_arf``, ``k_arr``, SPEC §6)
are real bars: per axle a force ``k_ar (d_i - d_j)`` on the two suspension
slides (``d`` the compression from static ride height), added in MuJoCo's
passive-force callback, so it acts between wheel and body at each corner.

Every key but ``cg_height`` is one number (all corners) or ``[front, rear]``.

The nonlinear suspension of SPEC §8, given in the scenario as the 7-DOF
engine takes it, is the same car here: ``[dampers]`` curves
(:class:`rideid.data.schema.DamperCurves`, argument ``dampers``) drive the
passive-force callback with the kernel's piecewise-linear force
(:func:`curve_force`); ``[truth]`` bump stops are ``bumpstop_clearance`` and
``bumpstop_rate`` (:func:`scenario_properties`); ``[vehicle] cg_height``
(``Geometry.cg_height``) is ``cg_height`` (giving it in both places with
different values is refused).

Sensors: accelerometers at the four suspension attachment points and the
four wheel centres, a gyro on the body. :meth:`MujocoCar.outputs` gives the
SPEC channels: each accelerometer's reading along its own z axis with
gravity removed in the sensor frame (the strapdown reading minus g times the
vertical component of the sensor's z axis), and the gyro's body-frame roll
and pitch rates (ISO 8855). ``raw=True`` gives what the sensors themselves
read (specific force along the sensor's z axis, gravity included), for
:mod:`rideid.measured`.
"""

from __future__ import annotations

import dataclasses
import math
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from ..data.schema.hifi import HIFI_KEYS, HifiProperties, parse_hifi, tire_damping_of
from ..errors import DataError
from ..model.equations import CHANNELS, static_corner_loads
from ..model.params import CORNERS, GRAVITY, INDEX, NAMES, Geometry, full_rows
from ..model.simulate import corner_inputs

#: contact impedance (solimp dmin = dmax): MuJoCo's smallest (mjMINIMP). A soft contact's force depends on
#: the contact's own acceleration a as well, -d / ((1 - d) A) a with A the contact's diagonal inverse mass
#: (``body_invweight0``): a weightless mass on the wheel (0.096 kg, 0.3 % of m_u at d = 1e-3; 0.01 kg at this
#: d), which :class:`MujocoCar` takes out of the wheel's own mass (:attr:`MujocoCar.contact_mass`)
IMPEDANCE = 1e-4
POST_MASS = 1e6
TIMESTEP = 1e-3

#: logger-style names of the raw sensor channels, in CHANNELS order
RAW_NAMES = tuple([f"acc_body_{c}_z" for c in CORNERS] + [f"acc_axle_{c}_z" for c in CORNERS]
                  + ["gyro_y", "gyro_x"])


def _require():
    try:
        import mujoco
    except ImportError:
        raise DataError("the MuJoCo engine needs the package 'mujoco-core': pip install 'rideid[hifi]'") from None
    return mujoco


def damper_force(v, c_s, rebound_ratio=1.0, knee_velocity=math.inf, knee_ratio=1.0):
    """Damper force (N, resisting, same sign as ``v``) at compression velocity ``v`` (m/s).

    Compression (``v > 0``) and rebound slopes ``2 c_s / (1 + r)`` and
    ``2 r c_s / (1 + r)`` average to ``c_s``; above ``knee_velocity`` each
    continues with ``knee_ratio`` times its slope.
    """
    v = np.asarray(v, dtype=float)
    c_s, r = np.asarray(c_s, dtype=float), np.asarray(rebound_ratio, dtype=float)
    vk, kr = np.asarray(knee_velocity, dtype=float), np.asarray(knee_ratio, dtype=float)
    slope = np.where(v >= 0, 2 * c_s / (1 + r), 2 * r * c_s / (1 + r))
    av = np.abs(v)
    mag = np.where(av <= vk, slope * av, slope * (vk + kr * (av - np.minimum(av, vk))))
    return np.sign(v) * mag


def curve_force(knots, F, v):
    """A SPEC §8 damper curve at compression velocities ``v`` (m/s): piecewise linear through (0, 0)
    and the points ``(knots, F)`` (signed knots, increasing, without 0), continued beyond the outermost
    points with the last segment's slope. The kernel's :func:`rideid.model.nonlinear.damper_force` once
    merged; this one is written from the SPEC alone (an independent check of it).
    """
    xk = np.asarray(knots, dtype=float)
    fk = np.asarray(F, dtype=float)
    k = int(np.searchsorted(xk, 0.0))
    x = np.concatenate([xk[:k], [0.0], xk[k:]])
    f = np.concatenate([fk[:k], [0.0], fk[k:]])
    v = np.asarray(v, dtype=float)
    i = np.clip(np.searchsorted(x, v, side="right") - 1, 0, x.size - 2)
    return f[i] + (f[i + 1] - f[i]) / (x[i + 1] - x[i]) * (v - x[i])


def effective_properties(hifi: HifiProperties | None, geom: Geometry) -> HifiProperties:
    """``hifi`` with the CG height of ``geom`` (SPEC §8 ``[vehicle] cg_height``) when that one is given."""
    hifi = hifi or HifiProperties()
    h = geom.cg_height
    if h:
        if hifi.cg_height and abs(hifi.cg_height - h) > 1e-12:
            raise DataError(f"the CG height is given twice and differs: [vehicle] cg_height = {h:g} m, "
                            f"[hifi] cg_height = {hifi.cg_height:g} m; give it once, in [vehicle]")
        hifi = dataclasses.replace(hifi, cg_height=h)
    return hifi


def scenario_properties(sc) -> HifiProperties:
    """The MuJoCo car's properties of a scenario: its ``[hifi]`` plus the SPEC §8 keys the 7-DOF engine takes too
    (``[truth]`` bump stops; ``[vehicle] cg_height``). The ``[dampers]`` curves are passed on their own."""
    hifi = effective_properties(sc.hifi, sc.geometry)
    if sc.bump_stops:
        clear, rate = sc.bump_stop_pairs
        hifi = dataclasses.replace(hifi, bumpstop_clearance=clear, bumpstop_rate=rate)
    return hifi


def hifi_curve(c_s, knots, rebound_ratio=1.0, knee_velocity=math.inf, knee_ratio=1.0) -> np.ndarray:
    """Forces at the knots of the MuJoCo car's parametric damper (:func:`damper_force`).

    Exact (the same curve everywhere) when the knee velocity is one of the
    positive and negative knots.
    """
    return np.asarray(damper_force(np.asarray(knots, dtype=float), c_s, rebound_ratio, knee_velocity, knee_ratio))



# ---------------------------------------------------------------------------
# the MJCF car

def build_mjcf(P, geom: Geometry, hifi: HifiProperties | None = None, dampers=None) -> str:
    """MJCF text of the car (the contact stiffness is set after compiling, :class:`MujocoCar`).

    ``dampers``: SPEC §8 curves (:class:`rideid.data.schema.DamperCurves`) replace the joints' linear
    damping (they act in the passive-force callback).
    """
    hifi = effective_properties(hifi, geom)
    linear = hifi.linear_dampers and dampers is None
    p = dict(zip(NAMES, np.asarray(P, dtype=float)))
    R = geom.tire_radius
    h = hifi.cg_height
    tire_loads = static_corner_loads(np.asarray(P, dtype=float)[None], geom, GRAVITY)[0]
    wheels, posts = [], []
    xs, ys = geom.corner_xy(p["a"])
    for i, (c, x, y) in enumerate(zip(CORNERS, xs.tolist(), ys.tolist())):
        ax = 0 if c.startswith("f") else 1
        mu, ks, cs = (p["m_uf"], p["k_sf"], p["c_sf"]) if ax == 0 else (p["m_ur"], p["k_sr"], p["c_sr"])
        damping = cs if linear else 0.0  # nonlinear dampers: the passive callback
        spring_force = tire_loads[i] - mu * GRAVITY  # the sprung mass's share
        iw = max(hifi.wheel_inertia[ax], 1e-6 * mu * R * R)
        wheels.append(f"""
      <site name="body_{c}" pos="{x} {y} 0" size="0.01"/>
      <body name="wheel_{c}" pos="{x} {y} {-h}">
        <joint name="susp_{c}" type="slide" axis="0 0 1" stiffness="{ks}" damping="{damping}"
               springref="{-spring_force / ks}"/>
        <inertial pos="0 0 0" mass="{mu}" diaginertia="{iw / 2} {iw} {iw / 2}"/>
        <geom name="tire_{c}" type="sphere" size="{R}" priority="1" contype="1" conaffinity="1"
              solimp="{IMPEDANCE} {IMPEDANCE} 0.001 0.5 2" margin="0" friction="0 0 0" condim="1"/>
        <site name="axle_{c}" size="0.01"/>
      </body>""")
        pen = tire_loads[i] / (p["k_tf"] if ax == 0 else p["k_tr"])
        posts.append(f"""
    <body name="post_{c}" pos="{x} {y} {pen}" gravcomp="1">
      <joint name="post_{c}" type="slide" axis="0 0 1"/>
      <inertial pos="0 0 -0.05" mass="{POST_MASS}" diaginertia="1e4 1e4 1e4"/>
      <geom name="pad_{c}" type="box" size="0.2 0.2 0.05" pos="0 0 -0.05" contype="2" conaffinity="1"/>
    </body>""")
    body_inertial, engine = _powertrain_mjcf(np.asarray(P, dtype=float), p)
    sites = [f"body_{c}" for c in CORNERS] + [f"axle_{c}" for c in CORNERS]
    sensors = "".join(f'    <accelerometer name="acc_{s}" site="{s}"/>\n'
                      f'    <framezaxis name="zaxis_{s}" objtype="site" objname="{s}"/>\n' for s in sites)
    return f"""<mujoco model="rideid-car">
  <option timestep="{TIMESTEP}" integrator="RK4" gravity="0 0 {-GRAVITY}"/>
  <worldbody>
    <body name="chassis" pos="0 0 {R + h}">
      <joint name="heave" type="slide" axis="0 0 1"/>
      <joint name="pitch" type="hinge" axis="0 1 0"/>
      <joint name="roll" type="hinge" axis="1 0 0"/>
      {body_inertial}
      <site name="gyro" size="0.01"/>{''.join(wheels)}{engine}
    </body>{''.join(posts)}
  </worldbody>
  <sensor>
{sensors}    <gyro name="gyro" site="gyro"/>
  </sensor>
</mujoco>"""


def _powertrain_mjcf(P, p) -> tuple[str, str]:
    """The chassis's ``<inertial>`` and the powertrain's body (empty without one, SPEC §11; module docstring)."""
    izz = p["I_xx"] + p["I_yy"]
    row = full_rows(P)[0]
    m_p = float(row[INDEX["m_p"]])
    if m_p <= 0:
        return f'<inertial pos="0 0 0" mass="{p["m_s"]}" diaginertia="{p["I_xx"]} {p["I_yy"]} {izz}"/>', ""
    x_p, I_p = float(row[INDEX["x_p"]]), float(row[INDEX["I_p"]])
    m_b = p["m_s"] - m_p
    x_b = -m_p * x_p / m_b
    I_b = p["I_yy"] - I_p - m_p * x_p ** 2 - m_b * x_b ** 2
    I_xb = p["I_xx"] - I_p
    if I_b <= 0 or I_xb <= 0:
        raise DataError("MuJoCo engine: the powertrain (m_p, x_p, I_p) leaves the rest of the sprung mass no "
                        "positive pitch or roll inertia")
    wb, wt = 2 * np.pi * float(row[INDEX["f_pb"]]), 2 * np.pi * float(row[INDEX["f_pp"]])
    k_p, c_p = m_p * wb * wb, 2 * float(row[INDEX["zeta_pb"]]) * m_p * wb
    k_t, c_t = I_p * wt * wt, 2 * float(row[INDEX["zeta_pp"]]) * I_p * wt
    inertial = (f'<inertial pos="{x_b} 0 0" mass="{m_b}" diaginertia="{I_xb} {I_b} {I_xb + I_b}"/>')
    engine = f"""
      <body name="powertrain" pos="{x_p} 0 0">
        <joint name="mount_bounce" type="slide" axis="0 0 1" stiffness="{k_p}" damping="{c_p}"
               springref="{m_p * GRAVITY / k_p}"/>
        <joint name="mount_pitch" type="hinge" axis="0 1 0" stiffness="{k_t}" damping="{c_t}"/>
        <inertial pos="0 0 0" mass="{m_p}" diaginertia="{I_p} {I_p} {I_p}"/>
      </body>"""
    return inertial, engine


class MujocoCar:
    """A compiled MuJoCo car with the tire contact tuned to ``k_tf``/``k_tr``.

    ``hifi``: :class:`HifiProperties` (or its fields as keyword arguments);
    ``geom.cg_height``, when given, is the car's CG height (:func:`effective_properties`).
    ``dampers``: SPEC §8 damper curves (:class:`rideid.data.schema.DamperCurves`), instead of c_sf/c_sr
    (and of ``[hifi]``'s parametric dampers).
    Nonlinear dampers and bump stops act through MuJoCo's passive-force
    callback, so every RK4 stage sees them; step the car inside
    :meth:`active` (:func:`simulate_mujoco` does).
    """

    def __init__(self, P, geom: Geometry, hifi: HifiProperties | None = None, dampers=None, **kw):
        mujoco = _require()
        if hifi is None:
            hifi = HifiProperties(**kw)
        elif kw:
            raise TypeError("give either hifi or its fields, not both")
        hifi = effective_properties(hifi, geom)
        if dampers is not None and not hifi.linear_dampers:
            raise DataError("the dampers are given twice, as [dampers] curves and as [hifi] "
                            "damper_rebound_ratio/damper_knee_*; give them in one place ([dampers])")
        self.mj = mujoco
        self.hifi = hifi
        self.dampers = dampers
        self.P = np.asarray(P, dtype=float).reshape(-1)
        ext = full_rows(self.P)[0]
        self.tire_damping = tire_damping_of(self.P, hifi)
        #: anti-roll bar rates (front, rear), N/m at the wheel
        self.bars = (float(ext[INDEX["k_arf"]]), float(ext[INDEX["k_arr"]]))
        self.geom = geom
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(self.P, geom, hifi, dampers))
        m = self.model
        p = dict(zip(NAMES, self.P))
        d_imp = IMPEDANCE

        def jid(name):
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)

        self._tire_ids, self._wheel_ids = [], []
        #: per corner, the weightless mass the soft contact adds to the wheel (IMPEDANCE), kg
        self.contact_mass = np.zeros(4)
        for i, c in enumerate(CORNERS):
            ax = 0 if c.startswith("f") else 1
            gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"tire_{c}")
            wheel = m.geom_bodyid[gid]
            post = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"post_{c}")
            # the contact's diagonal inverse mass as MuJoCo approximates it (its regulariser R = (1 - d) / d A)
            A = m.body_invweight0[wheel, 0] + m.body_invweight0[post, 0]
            K = p["k_tf"] if ax == 0 else p["k_tr"]
            m.geom_solref[gid] = (-K * (1 - d_imp) * A, -self.tire_damping[ax] * (1 - d_imp) * A)
            self._tire_ids.append(gid)
            self._wheel_ids.append(wheel)
            # the contact force is K pen + c pen' - m_c a (a the wheel's acceleration into the road, the post's
            # taken out, simulate_mujoco): m_c moves with the wheel but has no weight. The wheel body carries
            # m_u - m_c, and its weight m_c g is put back (a negative gravity compensation), so the wheel in
            # contact has the mass m_u and the weight m_u g of the 7-DOF model
            m_c = d_imp / ((1 - d_imp) * A)
            m_u = m.body_mass[wheel]
            m.body_mass[wheel] = m_u - m_c
            m.body_gravcomp[wheel] = -m_c / (m_u - m_c)
            self.contact_mass[i] = m_c
        self.data = mujoco.MjData(m)
        self._post_q = np.array([m.jnt_qposadr[jid(f"post_{c}")] for c in CORNERS])
        self._post_v = np.array([m.jnt_dofadr[jid(f"post_{c}")] for c in CORNERS])
        self.susp_q = np.array([m.jnt_qposadr[jid(f"susp_{c}")] for c in CORNERS])
        self.susp_v = np.array([m.jnt_dofadr[jid(f"susp_{c}")] for c in CORNERS])

        def sadr(name):
            return m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, name)]

        sites = [f"body_{c}" for c in CORNERS] + [f"axle_{c}" for c in CORNERS]
        self._acc_z = np.array([sadr(f"acc_{s}") + 2 for s in sites])
        self._zax_z = np.array([sadr(f"zaxis_{s}") + 2 for s in sites])
        g = sadr("gyro")
        self._gyro = np.array([g + 1, g])  # pitch rate (about y), roll rate (about x)

        # per-corner damper and bump-stop constants for the passive callback
        axle = np.array([0, 0, 1, 1])
        self._c_s = np.array([p["c_sf"], p["c_sf"], p["c_sr"], p["c_sr"]])
        self._reb = np.array(hifi.damper_rebound_ratio)[axle]
        self._knee_v = np.array(hifi.damper_knee_velocity)[axle]
        self._knee_r = np.array(hifi.damper_knee_ratio)[axle]
        self._bs_clear = np.array(hifi.bumpstop_clearance)[axle]
        self._bs_rate = np.array(hifi.bumpstop_rate)[axle]
        self.susp_q0 = self.data.qpos[self.susp_q].copy()  # static ride height (bar unloaded)
        self.linear_dampers = hifi.linear_dampers and dampers is None
        if dampers is not None:  # the knots with the origin, and per corner its axle's forces there
            x = np.asarray(dampers.velocity)
            k = int(np.searchsorted(x, 0.0))
            self._cx = np.concatenate([x[:k], [0.0], x[k:]])
            self._cf = np.array([np.concatenate([f[:k], [0.0], f[k:]]) for f in
                                 (np.asarray(dampers.curve("f" if c.startswith("f") else "r")) for c in CORNERS)])
        self.needs_callback = not self.linear_dampers or hifi.bumpstops or any(self.bars)

    # -- suspension forces beyond MuJoCo's linear joint spring and damper ------------------
    def damper(self, v):
        """Damper force of the four corners (N, resisting) at compression velocities ``v`` (m/s)."""
        if self.dampers is not None:  # curve_force, for the four corners at once
            x, f = self._cx, self._cf
            i = np.clip(np.searchsorted(x, v, side="right") - 1, 0, x.size - 2)
            c = np.arange(4)
            return f[c, i] + (f[c, i + 1] - f[c, i]) / (x[i + 1] - x[i]) * (v - x[i])
        return damper_force(v, self._c_s, self._reb, self._knee_v, self._knee_r)

    def suspension_force(self, q, v):
        """Generalised force on the four suspension slides (N) from nonlinear dampers, bump stops and anti-roll bars."""
        f = np.zeros(4)
        if any(self.bars):  # bar of each axle: -k_ar (d_i - d_j) on wheel i, the reaction on the body
            d = q - self.susp_q0
            kf, kr = self.bars
            f -= np.array([kf * (d[0] - d[1]), kf * (d[1] - d[0]), kr * (d[2] - d[3]), kr * (d[3] - d[2])])
        if not self.linear_dampers:
            f -= self.damper(v)
        if self.hifi.bumpstops:
            f -= self._bs_rate * np.maximum(q - self._bs_clear, 0.0)
        return f

    def _passive(self, m, d):
        if m.nv != self.model.nv:  # another model stepping meanwhile: not ours
            return
        d.qfrc_passive[self.susp_v] += self.suspension_force(d.qpos[self.susp_q], d.qvel[self.susp_v])

    @contextmanager
    def active(self):
        """Install this car's passive-force callback (if it needs one) for the duration."""
        if not self.needs_callback:
            yield self
            return
        previous = self.mj.get_mjcb_passive()
        self.mj.set_mjcb_passive(self._passive)
        try:
            yield self
        finally:
            self.mj.set_mjcb_passive(previous)

    # -- road, sensors, loads ---------------------------------------------------------------
    def set_road(self, r, rdot, rddot=None):
        """Posts at the road heights ``r`` with velocities ``rdot``, accelerating at ``rddot`` over the step.

        The contact's weightless mass (:attr:`contact_mass`) feels the post's acceleration too: a force
        ``m_c rddot`` on each wheel in contact, taken out here (``xfrc_applied``)."""
        d = self.data
        d.qpos[self._post_q] = r
        d.qvel[self._post_v] = rdot
        if rddot is not None:
            d.qfrc_applied[self._post_v] = POST_MASS * np.asarray(rddot)
            touching = np.isin(self._tire_ids, d.contact.geom[:d.ncon].ravel()) if d.ncon < 4 else np.ones(4, bool)
            d.xfrc_applied[self._wheel_ids, 2] = np.where(touching, -self.contact_mass * rddot, 0.0)

    def outputs(self, raw: bool = False) -> np.ndarray:
        """The ten SPEC channels from the sensors (``raw``: specific force along each sensor's z, with gravity)."""
        s = self.data.sensordata
        out = np.empty(len(CHANNELS))
        out[:8] = s[self._acc_z] if raw else s[self._acc_z] - GRAVITY * s[self._zax_z]
        out[8:] = s[self._gyro]
        return out

    def tire_loads(self) -> np.ndarray:
        """Normal force of each tire contact (N), 0 where a tire has lifted."""
        mujoco, m, d = self.mj, self.model, self.data
        loads = np.zeros(4)
        f6 = np.zeros(6)
        for j in range(d.ncon):
            con = d.contact[j]
            for i, gid in enumerate(self._tire_ids):
                if gid in (con.geom1, con.geom2):
                    mujoco.mj_contactForce(m, d, j, f6)
                    loads[i] += f6[0]
        return loads


@dataclass
class MujocoRun:
    """One simulated run: outputs at the sample times and what happened at every 1 ms step."""

    y: np.ndarray              # (n, 10) SPEC channels (or raw readings)
    tire_load_min: np.ndarray  # (4,) smallest tire load over the run, N (0: the tire left the road)
    lift_time: np.ndarray      # (4,) first time a tire had no load, s (nan: never)
    travel_min: np.ndarray     # (4,) most extension (negative) and compression of each suspension, m
    travel_max: np.ndarray
    damper_work: np.ndarray    # (4,) energy each damper dissipated, J (integral of F v dt)
    damper_v2: np.ndarray      # (4,) integral of v^2 dt, m^2/s


def simulate_mujoco(P, geom: Geometry, track, speed, t, distance=None, hifi: HifiProperties | None = None,
                    raw: bool = False, details: bool = False, dampers=None, inputs=None, **kw):
    """Outputs ``(n, 10)`` of the MuJoCo car at the sample times ``t`` (CHANNELS order).

    ``t`` must be uniform with a step that is a multiple of 1 ms; the posts
    follow the rigid-wheel envelope (SPEC §2) at the front-axle distance
    ``speed * t`` (or ``distance(t)``), their velocity from a central
    difference of the envelope. ``hifi``: :class:`HifiProperties` (or its
    fields as keyword arguments); ``raw``: the sensors' own readings, gravity
    included; ``details``: return a :class:`MujocoRun` with tire loads,
    lift-off times and suspension travel as well; ``dampers``: SPEC §8 damper
    curves (:class:`MujocoCar`); ``inputs``: ``inputs(times) -> (r (k, 4), rdot (k, 4))``, the posts' heights
    and velocities at any times, instead of a track (a four-post rig run, SPEC §13; ``track`` and ``speed``
    then unused).
    """

    car = MujocoCar(P, geom, hifi, dampers=dampers, **kw)
    mj, m, d = car.mj, car.model, car.data
    t = np.asarray(t, dtype=float)
    h = float(t[1] - t[0])
    sub = int(round(h / TIMESTEP))
    if sub < 1 or abs(sub * TIMESTEP - h) > 1e-9:
        raise DataError(f"MuJoCo engine: the sample interval {h} s must be a multiple of {TIMESTEP} s")
    tf = t[0] + TIMESTEP * np.arange((t.size - 1) * sub + 1)
    if inputs is not None:  # a rig's posts (SPEC §13): their heights and velocities given as functions of time
        r, rdot = inputs(tf)
        r_next = inputs(tf + TIMESTEP)[0]
    else:
        x_of = (lambda tt: speed * tt) if distance is None else distance
        eps = 1e-5
        r = corner_inputs(track, geom, x_of(tf))
        rdot = (corner_inputs(track, geom, x_of(tf + eps)) - corner_inputs(track, geom, x_of(tf - eps))) / (2 * eps)
        r_next = corner_inputs(track, geom, x_of(tf + TIMESTEP))
    # over each step the posts accelerate uniformly from (r, rdot) to the road height at the step's end:
    # the road followed to third order in the step (holding rdot, the posts would miss by rddot dt^2 / 2)
    rddot = 2 * (r_next - r - rdot * TIMESTEP) / TIMESTEP ** 2
    out = np.empty((t.size, len(CHANNELS)))
    load_min = np.full(4, np.inf)
    lift = np.full(4, np.nan)
    tmin, tmax = np.zeros(4), np.zeros(4)
    work, v2 = np.zeros(4), np.zeros(4)
    with car.active():
        for j in range(tf.size):
            car.set_road(r[j], rdot[j], rddot[j])
            mj.mj_step(m, d)  # sensordata now describe the start of this step, time tf[j]
            if j % sub == 0:
                out[j // sub] = car.outputs(raw)
            if details:
                loads = car.tire_loads()
                load_min = np.minimum(load_min, loads)
                new = np.isnan(lift) & (loads <= 0)
                lift[new] = tf[j]
                q, v = d.qpos[car.susp_q], d.qvel[car.susp_v]
                tmin, tmax = np.minimum(tmin, q), np.maximum(tmax, q)
                work += car.damper(v) * v * TIMESTEP
                v2 += v * v * TIMESTEP
    if details:
        return MujocoRun(out, load_min, lift, tmin, tmax, work, v2)
    return out


__all__ = ["HIFI_KEYS", "HifiProperties", "MujocoCar", "MujocoRun", "RAW_NAMES", "build_mjcf", "curve_force",
           "damper_force", "hifi_curve", "effective_properties", "parse_hifi", "scenario_properties", "simulate_mujoco",
           "tire_damping_of"]
