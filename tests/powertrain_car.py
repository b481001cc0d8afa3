"""An independent simulator of a car with a powertrain on mounts (SPEC §11), for the tests.

Written from Newton-Euler in absolute coordinates, not from rideid's
equations: the body without the powertrain (mass ``m_b = m_s - m_p``, its own
CG ``x_b = -m_p x_p / m_b`` from the whole sprung mass's CG, pitch inertia
``I_b`` about that CG by the parallel-axis theorem), the powertrain (mass
``m_p`` at ``x_p``, pitch inertia ``I_p``), four wheels. Coordinates
``[z_b, theta, phi, z_fl, z_fr, z_rl, z_rr, z_p, theta_p]``: the body CG's
heave, the body's pitch and roll, the wheels, the powertrain CG's heave and
its pitch. The mounts: a spring ``k_p`` and damper ``c_p`` between the
powertrain CG and the body point beneath it, a torsion spring ``k_pt`` and
damper ``c_pt`` between the two pitch angles. Integrated by
``scipy.signal.lsim`` (first-order hold) on a fine grid.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

#: the issue's engine: 180 kg, 1.2 m ahead of the CG, 10.5 Hz bounce and 13 Hz pitch on its mounts, ~10 % damping
ENGINE = {"m_p": 180.0, "x_p": 1.2, "I_p": 12.0, "f_pb": 10.5, "zeta_pb": 0.1, "f_pp": 13.0, "zeta_pp": 0.1}


def matrices(car: dict, geom):
    """``M, C, K, Bf`` (9 coordinates, module docstring) of ``car`` (the twelve and the powertrain's names)."""
    m_s, I_yy, I_xx, a = car["m_s"], car["I_yy"], car["I_xx"], car["a"]
    m_p, x_p, I_p = car["m_p"], car["x_p"], car["I_p"]
    m_b = m_s - m_p
    x_b = -m_p * x_p / m_b
    I_b = I_yy - I_p - m_p * x_p ** 2 - m_b * x_b ** 2
    assert I_b > 0 and m_b > 0
    w_b, w_t = 2 * np.pi * car["f_pb"], 2 * np.pi * car["f_pp"]
    k_p, c_p = m_p * w_b ** 2, 2 * car["zeta_pb"] * m_p * w_b
    k_pt, c_pt = I_p * w_t ** 2, 2 * car["zeta_pp"] * I_p * w_t
    b = geom.wheelbase - a
    xs = np.array([a, a, -b, -b]) - x_b  # corners from the body's own CG
    ys = np.array([geom.track_front, -geom.track_front, geom.track_rear, -geom.track_rear]) / 2
    ks = np.array([car["k_sf"]] * 2 + [car["k_sr"]] * 2)
    cs = np.array([car["c_sf"]] * 2 + [car["c_sr"]] * 2)
    kt = np.array([car["k_tf"]] * 2 + [car["k_tr"]] * 2)
    mu = np.array([car["m_uf"]] * 2 + [car["m_ur"]] * 2)
    M = np.diag([m_b, I_b, I_xx, *mu, m_p, I_p])
    K, C = np.zeros((9, 9)), np.zeros((9, 9))
    # force balances written out: suspension deflection d_i = z_i - (z_b - x_i theta + y_i phi)
    for i in range(4):
        g = np.zeros(9)
        g[[0, 1, 2, 3 + i]] = [-1.0, xs[i], -ys[i], 1.0]  # d_i = g q
        K += ks[i] * np.outer(g, g)
        C += cs[i] * np.outer(g, g)
        K[3 + i, 3 + i] += kt[i]
    # mount deflection in bounce: z_p - (z_b - (x_p - x_b) theta); in pitch: theta_p - theta
    gb, gt = mount_deflections(car)
    K += k_p * np.outer(gb, gb) + k_pt * np.outer(gt, gt)
    C += c_p * np.outer(gb, gb) + c_pt * np.outer(gt, gt)
    Bf = np.zeros((9, 4))
    Bf[3 + np.arange(4), np.arange(4)] = kt
    return M, C, K, Bf, xs, ys


def simulate(car: dict, geom, t, road, upsample: int = 20, powertrain_outputs: bool = False):
    """The ten SPEC channels ``(n_time, 10)`` at ``t`` for corner inputs ``road(times) -> (k, 4)`` (m).

    Starts at rest in static equilibrium for the input at ``t[0]``. ``powertrain_outputs``: four more columns
    (``(n_time, 14)``), the FMU's powertrain outputs: the powertrain CG's vertical acceleration and pitch rate, its
    heave relative to the body point beneath it (the bounce mount's deflection) and its pitch relative to the body.
    """
    M, C, K, Bf, xs, ys = matrices(car, geom)
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((9, 9)), np.eye(9)], [-Mi @ K, -Mi @ C]])
    B = np.vstack([np.zeros((9, 4)), Mi @ Bf])
    # outputs: body corners read z_b - x_i theta + y_i phi (x_i from the body's own CG), axles z_i, gyros
    Oacc = np.zeros((8, 9))
    for i in range(4):
        Oacc[i, [0, 1, 2]] = [1.0, -xs[i], ys[i]]
        Oacc[4 + i, 3 + i] = 1.0
    Cy = np.vstack([Oacc @ A[9:], np.eye(18)[[10, 11]]])
    Dy = np.vstack([Oacc @ B[9:], np.zeros((2, 4))])
    if powertrain_outputs:
        mounts = mount_deflections(car)
        Cy = np.vstack([Cy, A[9 + 7], np.eye(18)[17], np.c_[mounts, np.zeros((2, 9))]])
        Dy = np.vstack([Dy, B[9 + 7], np.zeros((3, 4))])
    t = np.asarray(t, dtype=float)
    h = t[1] - t[0]
    tf = t[0] + h / upsample * np.arange((t.size - 1) * upsample + 1)
    u = road(tf)
    x0 = -np.linalg.solve(A, B @ u[0])
    _, y, _ = scipy.signal.lsim(scipy.signal.StateSpace(A, B, Cy, Dy), u, tf, X0=x0, interp=True)
    return y[::upsample]


def mount_deflections(car: dict) -> np.ndarray:
    """Rows ``(2, 9)``: the bounce mount's deflection ``z_p - (z_b - (x_p - x_b) theta)`` and the pitch mount's
    ``theta_p - theta`` as linear maps of the coordinates (module docstring)."""
    m_p, x_p = car["m_p"], car["x_p"]
    x_b = -m_p * x_p / (car["m_s"] - m_p)
    G = np.zeros((2, 9))
    G[0, [7, 0, 1]] = [1.0, -1.0, x_p - x_b]
    G[1, [8, 1]] = [1.0, -1.0]
    return G


def undamped_modes(car: dict, geom):
    """Undamped natural frequencies (Hz) of the car's symmetric motions, ascending, from the 9x9 problem."""
    import scipy.linalg
    M, C, K, _, _, _ = matrices(car, geom)
    w2 = scipy.linalg.eigh(K, M, eigvals_only=True)
    return np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi)


def write_dataset(folder, engine: dict | None = ENGINE, noise: float = 0.0, seed: int = 0, runs=None):
    """The built-in scenario's tracks and runs driven by the built-in car with ``engine`` on mounts (None: the
    rigid car), simulated here, with white noise of ``noise`` times each channel's RMS (SPEC ``--noise``),
    written as a dataset in ``folder`` (``truth.toml`` holds the powertrain too). ``runs``: the run ids to keep
    (default all). Returns the truth (dict)."""
    import dataclasses

    import rideid
    from rideid.model.simulate import corner_inputs
    from rideid.synth.scenario import write_dataset as write

    sc = rideid.default_scenario()
    if runs is not None:
        sc = dataclasses.replace(sc, runs=[r for r in sc.runs if r.id in runs])
    geom = sc.geometry
    car = {k: sc.truth[k] for k in rideid.NAMES}
    rng = np.random.default_rng(seed)
    data = {}
    for run in sc.runs:
        track = sc.tracks[run.track]
        t = np.arange(int(round(run.duration * run.fs)) + 1) / run.fs
        if engine is None:
            # a powertrain of a milligram: the rigid car to 1e-9 (the same simulator, no second one)
            y = simulate({**car, **ENGINE, "m_p": 1e-6, "I_p": 1e-6}, geom, t,
                         lambda tt, tr=track, v=run.speed: corner_inputs(tr, geom, v * tt), upsample=10)
        else:
            y = simulate({**car, **engine}, geom, t,
                         lambda tt, tr=track, v=run.speed: corner_inputs(tr, geom, v * tt), upsample=10)
        rms = np.sqrt(np.mean(y * y, axis=0))
        y[:, rms < 1e-9] = 0.0  # a channel the run does not excite (roll on a washboard): lsim's rounding only
        if noise > 0:
            y = y + noise * rms * rng.standard_normal(y.shape)
        data[run.id] = (t, y)
    truth = {**car, **(engine or {})}
    write(dataclasses.replace(sc, truth=truth), data, folder)
    return truth
