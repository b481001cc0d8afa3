"""An independent car for the frequency-response tests and their study (benchmarks/study_frf.py): the 7-DOF car of
SPEC §1 written out from the SPEC (not rideid's code), its frequency response by a direct solve per frequency, its
time response by SciPy's ``lsim``, and a dataset of it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.signal as sg

import rideid
from rideid.data.dataset import prepare_inputs
from rideid.model.frf import OUTPUTS
from rideid.model.params import DEFAULT_CAR, DEFAULT_GEOMETRY, Geometry
from rideid.synth.scenario import simulate_manifest, write_dataset

TRUTH = dict(DEFAULT_CAR)
OUT = {n: i for i, n in enumerate(OUTPUTS)}



def spec_matrices(p: dict, geom: Geometry):
    """M, C, K (7x7), the road's force per metre ``Bf`` and per m/s ``Bd`` (7x4), and the output rows of the ten
    channels as ``y = Oa q'' + Ov q'``, from SPEC §1 directly (tire damping c_t of SPEC §6 too)."""
    b = geom.wheelbase - p["a"]
    xs = [p["a"], p["a"], -b, -b]
    ys = [geom.track_front / 2, -geom.track_front / 2, geom.track_rear / 2, -geom.track_rear / 2]
    ks = [p["k_sf"]] * 2 + [p["k_sr"]] * 2
    cs = [p["c_sf"]] * 2 + [p["c_sr"]] * 2
    kt = [p["k_tf"]] * 2 + [p["k_tr"]] * 2
    ct = [p.get("c_tf", 0.0)] * 2 + [p.get("c_tr", 0.0)] * 2
    mu = [p["m_uf"]] * 2 + [p["m_ur"]] * 2
    M = np.diag([p["m_s"], p["I_yy"], p["I_xx"], *mu])
    K, C = np.zeros((7, 7)), np.zeros((7, 7))
    Bf, Bd = np.zeros((7, 4)), np.zeros((7, 4))
    Oa, Ov = np.zeros((10, 7)), np.zeros((10, 7))
    for i in range(4):
        # suspension deflection d_i = z_i - (z - x_i theta + y_i phi); F_i = k d_i + c d_i' acts up on the body:
        # body rows get +F_i (z), -x_i F_i (theta), +y_i F_i (phi); the wheel -F_i; so the stiffness is k e e^T
        e = np.zeros(7)
        e[0], e[1], e[2], e[3 + i] = -1.0, xs[i], -ys[i], 1.0
        K += ks[i] * np.outer(e, e)
        C += cs[i] * np.outer(e, e)
        K[3 + i, 3 + i] += kt[i]
        C[3 + i, 3 + i] += ct[i]
        Bf[3 + i, i], Bd[3 + i, i] = kt[i], ct[i]
        Oa[i, :3] = [1.0, -xs[i], ys[i]]
        Oa[4 + i, 3 + i] = 1.0
    Ov[8, 1] = Ov[9, 2] = 1.0
    return M, C, K, Bf, Bd, Oa, Ov


def spec_response(p: dict, geom: Geometry, freq) -> np.ndarray:
    """``H`` (n_f, 13, 4) of the car of SPEC §1 by solving ``(-w^2 M + jw C + K) q = (Bf + jw Bd) r``."""
    M, C, K, Bf, Bd, Oa, Ov = spec_matrices(p, geom)
    out = np.zeros((len(freq), 13, 4), dtype=complex)
    for k, f in enumerate(freq):
        w = 2 * np.pi * f
        q = np.linalg.solve(-w * w * M + 1j * w * C + K, Bf + 1j * w * Bd)
        out[k, :10] = -w * w * (Oa @ q) + 1j * w * (Ov @ q)
        out[k, 10:] = q[:3]
    return out


def spec_simulate(p: dict, geom: Geometry, t, r, rdot) -> np.ndarray:
    """The ten channels (n, 10) of the SPEC §1 car at rest at ``t[0]``, driven by ``r`` (n, 4) and ``rdot``,
    by SciPy's ``lsim`` (its own discretisation: inputs linear between the given times)."""
    M, C, K, Bf, Bd, Oa, Ov = spec_matrices(p, geom)
    Mi = np.linalg.inv(M)
    A = np.block([[np.zeros((7, 7)), np.eye(7)], [-Mi @ K, -Mi @ C]])
    B = np.vstack([np.zeros((7, 8)), Mi @ np.hstack([Bf, Bd])])
    acc_x, acc_u = A[7:], B[7:]  # q'' as a function of the state and the inputs
    Cy = Oa @ acc_x + np.hstack([np.zeros((10, 7)), Ov])
    Dy = Oa @ acc_u
    _, y, _ = sg.lsim(sg.StateSpace(A, B, Cy, Dy), np.hstack([r, rdot]), t)
    return y


def independent_dataset(folder, runs, noise: float, seed: int, truth=TRUTH, oversample: int = 40):
    """The built-in tracks and ``runs`` with ``truth``, the ten channels from :func:`spec_simulate` (SciPy's lsim at
    ``oversample`` times the sample rate, the road under each wheel from rideid's envelope) with ``noise`` x each
    channel's RMS of white noise; written as a dataset."""
    sc = rideid.default_scenario()
    sc = replace(sc, runs=[r for r in sc.runs if r.id in runs])
    data, _ = simulate_manifest(sc, noise=0.0, seed=1)
    write_dataset(sc, data, folder)
    ds = rideid.load_dataset(folder)
    rng = np.random.default_rng(seed)
    for r, inp in zip(ds.runs, prepare_inputs(ds)):
        t = ds.data[r.id].time
        tf = np.linspace(t[0], t[-1], oversample * (t.size - 1) + 1)
        rr, rd = inp.inputs_at(tf)
        Y = spec_simulate(truth, ds.geometry, tf, rr, rd)[::oversample]
        Y = Y + noise * np.sqrt(np.mean(Y ** 2, axis=0)) * rng.standard_normal(Y.shape)
        path = folder / "runs" / f"{r.id}.csv"
        header = path.read_text().splitlines()[0]
        np.savetxt(path, np.column_stack([t, Y]), delimiter=",", header=header, comments="", fmt="%.12g")
    return rideid.load_dataset(folder)


def coverage(res, truth=TRUTH, freq=None):
    """Share of (frequency, output, input) over 0.5-25 Hz where the true |H| is inside ±2 std_abs of the
    identified car's, and the views' share."""
    freq = np.geomspace(0.5, 25, 120) if freq is None else freq
    fr = res.frequency_response(freq)
    true = spec_response(truth, DEFAULT_GEOMETRY, freq)
    inside = np.abs(np.abs(true) - np.abs(fr.H)) <= 2 * fr.std_abs
    views = [np.abs(np.abs(true[:, OUT[v["output"]]] @ v["weights"]) - np.abs(v["H"])) <= 2 * v["std_abs"]
             for v in fr.views.values()]
    return float(inside.mean()), float(np.mean(views)), fr



def h1_accuracy(m, truth=TRUTH, geom=DEFAULT_GEOMETRY, coherence=0.9):
    """The measured H1 (:func:`rideid.estimate.assess.frequency.measured_response`) against the true car over 0.5-25 Hz
    where its coherence exceeds ``coherence``: (points, median relative error of |H|, share within 2 std)."""
    true = spec_response(truth, geom, m["freq"])[:, :10]
    sel = (m["coherence"] > coherence) & ((m["freq"] >= 0.5) & (m["freq"] <= 25))[:, None, None]
    err = np.abs(np.abs(m["H"]) - np.abs(true))
    within = float(np.mean(err[sel] < 2 * m["std_abs"][sel]))
    return int(sel.sum()), float(np.median(err[sel] / np.abs(true[sel]))), within
