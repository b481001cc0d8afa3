"""An independent simulator of a car with a powertrain on mounts and damper curves (SPEC §8 × §11), for the tests.

Newton-Euler in absolute coordinates, written here, not from rideid's equations (the same as
``tests/test_nonlinear_powertrain.py``'s ``_absolute_rhs``, compiled): the body without the powertrain (mass
``m_s - m_p`` at its own CG), the powertrain (``m_p``, ``I_p`` at ``x_p``) on a bounce and a pitch mount, four
wheels; piecewise-linear damper curves through ``(0, 0)`` and the knots (continued beyond the outermost ones),
tires that lift off; CG height 0, no bump stops. Classical RK4 at a fixed step of ``1 / (fs * upsample)`` (not
split at the kinks: the step is small instead), the road tabulated at the half steps from the scenario's own
envelope model (the road input is the data, not the car).
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from rideid.model.params import GRAVITY


@numba.njit(cache=True)
def _rhs(c, xk, Fk, X, u, ud, out, y):
    # c: m_b, I_b, I_xx, x_b, x_p, m_p, I_p, kp, cp, kt_, ct_ (mount rates), then per corner xs(4), ys(4), ks(4),
    # kt(4), ct(4), mu(4), L(4), and kar(2) per axle: c[39], c[40] (numba checks no bounds: a wrong index reads
    # whatever lies beyond the array)
    m_b, I_b, I_xx, x_b, x_p, m_p, I_p, kp, cp, kq, cq = c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], \
        c[9], c[10]
    F = np.empty(4)
    T = np.empty(4)
    d = np.empty(4)
    for i in range(4):
        xs, ys = c[11 + i], c[15 + i]
        d[i] = X[3 + i] - (X[0] - xs * X[1] + ys * X[2])
        v = X[12 + i] - (X[9] - xs * X[10] + ys * X[11])
        ax = i // 2
        j = 0
        while j < xk.size - 2 and v >= xk[j + 1]:
            j += 1
        damp = Fk[ax, j] + (Fk[ax, j + 1] - Fk[ax, j]) / (xk[j + 1] - xk[j]) * (v - xk[j])
        F[i] = c[19 + i] * d[i] + damp
        L = c[35 + i]
        t = L + c[23 + i] * (u[i] - X[3 + i]) + c[27 + i] * (ud[i] - X[12 + i])
        T[i] = (t if t > 0.0 else 0.0) - L
    for ax in range(2):
        bar = c[39 + ax] * (d[2 * ax] - d[2 * ax + 1])
        F[2 * ax] += bar
        F[2 * ax + 1] -= bar
    e = X[7] - (X[0] - (x_p - x_b) * X[1])
    ed = X[16] - (X[9] - (x_p - x_b) * X[10])
    f = kp * e + cp * ed
    tau = kq * (X[8] - X[1]) + cq * (X[17] - X[10])
    sF = 0.0
    sX = 0.0
    sY = 0.0
    for i in range(4):
        sF += F[i]
        sX += c[11 + i] * F[i]
        sY += c[15 + i] * F[i]
    for i in range(9):
        out[i] = X[9 + i]
    out[9] = (sF + f) / m_b
    out[10] = (-sX - (x_p - x_b) * f + tau) / I_b
    out[11] = sY / I_xx
    for i in range(4):
        out[12 + i] = (T[i] - F[i]) / c[31 + i]
    out[16] = -f / m_p
    out[17] = -tau / I_p
    for i in range(4):
        y[i] = out[9] - c[11 + i] * out[10] + c[15 + i] * out[11]
        y[4 + i] = out[12 + i]
    y[8] = X[10]
    y[9] = X[11]


@numba.njit(cache=True)
def _integrate(c, xk, Fk, U, R, n, m, h):
    X = np.zeros(18)
    Y = np.empty((n, 10))
    k1, k2, k3, k4, tmp = np.empty(18), np.empty(18), np.empty(18), np.empty(18), np.empty(18)
    y = np.empty(10)
    _rhs(c, xk, Fk, X, U[0], R[0], k1, y)
    Y[0] = y
    hs = h / m
    for k in range(n - 1):
        for s in range(m):
            j = 2 * (k * m + s)
            _rhs(c, xk, Fk, X, U[j], R[j], k1, y)
            tmp[:] = X + 0.5 * hs * k1
            _rhs(c, xk, Fk, tmp, U[j + 1], R[j + 1], k2, y)
            tmp[:] = X + 0.5 * hs * k2
            _rhs(c, xk, Fk, tmp, U[j + 1], R[j + 1], k3, y)
            tmp[:] = X + hs * k3
            _rhs(c, xk, Fk, tmp, U[j + 2], R[j + 2], k4, y)
            X += hs / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        _rhs(c, xk, Fk, X, U[2 * (k + 1) * m], R[2 * (k + 1) * m], k1, y)
        Y[k + 1] = y
    return Y


def coefficients(car: dict, dampers, geom) -> tuple:
    m_s, m_p, x_p, I_p = car["m_s"], car["m_p"], car["x_p"], car["I_p"]
    m_b = m_s - m_p
    x_b = -m_p * x_p / m_b
    I_b = car["I_yy"] - I_p - m_p * x_p ** 2 - m_b * x_b ** 2
    assert m_b > 0 and I_b > 0
    a, b = car["a"], geom.wheelbase - car["a"]
    wb, wt = 2 * np.pi * car["f_pb"], 2 * np.pi * car["f_pp"]
    pair = lambda f, r: [f, f, r, r]  # noqa: E731
    L = pair(m_s * GRAVITY * b / geom.wheelbase / 2 + car["m_uf"] * GRAVITY,
             m_s * GRAVITY * a / geom.wheelbase / 2 + car["m_ur"] * GRAVITY)
    c = np.array([m_b, I_b, car["I_xx"], x_b, x_p, m_p, I_p, m_p * wb * wb, 2 * car["zeta_pb"] * m_p * wb,
                  I_p * wt * wt, 2 * car["zeta_pp"] * I_p * wt,
                  *(np.array([a, a, -b, -b]) - x_b),
                  geom.track_front / 2, -geom.track_front / 2, geom.track_rear / 2, -geom.track_rear / 2,
                  *pair(car["k_sf"], car["k_sr"]), *pair(car["k_tf"], car["k_tr"]),
                  *pair(car.get("c_tf", 0.0), car.get("c_tr", 0.0)), *pair(car["m_uf"], car["m_ur"]), *L,
                  car.get("k_arf", 0.0), car.get("k_arr", 0.0)])
    vel = np.asarray(dampers.velocity, dtype=float)
    j0 = int(np.searchsorted(vel, 0.0))
    xk = np.insert(vel, j0, 0.0)
    Fk = np.stack([np.insert(np.asarray(dampers.front, float), j0, 0.0),
                   np.insert(np.asarray(dampers.rear, float), j0, 0.0)])
    return c, xk, Fk


def simulate(sc, upsample: int = 40, noise: float = 0.0, seed: int = 0) -> dict:
    """Every run of scenario ``sc`` (its ``[truth]`` with the powertrain's seven, its ``[dampers]``): run id ->
    ``(t, Y)`` with the ten channels, white noise of ``noise`` times each channel's RMS."""
    from rideid.model.simulate import prepare_run

    geom = sc.geometry
    c, xk, Fk = coefficients(sc.truth, sc.dampers, geom)
    rng = np.random.default_rng(seed)
    out = {}
    for run in sc.runs:
        t = np.arange(int(round(run.duration * run.fs)) + 1) / run.fs
        ri = prepare_run(sc.tracks[run.track], geom, run.speed, t)
        tf = (t[1] - t[0]) / (2 * upsample) * np.arange(2 * upsample * (t.size - 1) + 1)
        U, R = ri.inputs_at(tf)
        assert not np.any(U[0]), run.id  # at rest on the flat lead-in
        y = _integrate(c, xk, Fk, np.ascontiguousarray(U), np.ascontiguousarray(R), t.size, upsample, t[1] - t[0])
        assert np.all(np.isfinite(y)), run.id
        rms = np.sqrt(np.mean(y * y, axis=0))
        y[:, rms < 1e-9] = 0.0
        if noise > 0:
            y = y + noise * rms * rng.standard_normal(y.shape)
        out[run.id] = (t, y)
    return out


def write_dataset(sc, folder, noise: float = 0.0, seed: int = 0):
    """``simulate`` written as a dataset (``rideid.synth.scenario.write_dataset``: truth.toml with the curves)."""
    from rideid.synth.scenario import write_dataset as write

    write(dataclasses.replace(sc), simulate(sc, noise=noise, seed=seed), folder)
