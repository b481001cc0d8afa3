"""A car with an engine on mounts and damper curves, defaults (issue 50's done-when; tests/engine_curves_case.py).

The full size (four runs at 200 Hz) is benchmarks/engine_curves.py's, its numbers in docs/verification.md; here
the same car at a small size: the high twist at 5 m/s and the washboard at 10 m/s, each cut to 3 s, at 100 Hz,
1 % noise, a short search (population 8, 3 generations: the model choice polishes every rival from its parent).
"""

import warnings

import numpy as np
import pytest

import rideid

import engine_curves_case as case
import nl_powertrain_car

#: the small size (module docstring)
SMALL = dict(runs=("T_HH", "W_H"), fs=100.0, cut=3.0)


def test_the_simulators_bars_act_on_their_axle(tmp_path):
    """tests/nl_powertrain_car.py's anti-roll bars, in closed form: with the front left wheel raised 10 mm (its
    suspension compressed, the front right's not), a front bar of 1000 N/m adds 10 N to the front left corner's
    force on the body and takes 10 N from the front right's: roll acceleration ``+track_front * 10 / I_xx``, the
    front left wheel's ``-10 / m_uf``, the front right wheel's ``+10 / m_uf``; nothing else moves. (The simulator
    read the bar rates from beyond its coefficient array, which numba does not check: whatever lay there, on one
    run in three NaN.)"""
    sc = case.scenario(tmp_path, runs=("W_H",))
    dampers = sc.dampers
    base = dict(sc.truth, k_arf=0.0, k_arr=0.0)
    X = np.zeros(18)
    X[3] = 0.01
    u, ud = np.zeros(4), np.zeros(4)
    out = {}
    for k in (0.0, 1000.0):
        c, xk, Fk = nl_powertrain_car.coefficients(dict(base, k_arf=k), dampers, sc.geometry)
        assert c.size == 41
        out[k], y = np.empty(18), np.empty(10)
        nl_powertrain_car._rhs(c, xk, Fk, X, u, ud, out[k], y)
    d = out[1000.0] - out[0.0]
    expected = np.zeros(18)
    expected[11] = sc.geometry.track_front * 10.0 / sc.truth["I_xx"]
    expected[12], expected[13] = -10.0 / sc.truth["m_uf"], 10.0 / sc.truth["m_uf"]
    np.testing.assert_allclose(d, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.heavy
def test_auto_keeps_the_engine_and_the_curves(tmp_path):
    """Defaults (``auto``) on the small case: the powertrain and the damper curves kept, two steps, adequate; the
    twelve within 1 % (measured 0.58 %, c_sr the curves' mean slope; the rest within 0.18 %), the engine's mass,
    place and frequencies within 0.5 % (measured 0.16 %, f_pp), its pitch inertia and damping ratios within 3 %
    (measured 1.46 %, zeta_pp), the curves within 3 % at the excited knots (measured 1.8 %). Before the screen
    weighed a rival at the fit it is predicted to reach, the full size kept tire damping alone (c_sf -64 %).
    Measured: 27 s of CPU time."""
    sc, folder = case.write(tmp_path, **SMALL)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", rideid.DataWarning)  # short runs: "a longer recording fits better"
        res = rideid.identify(rideid.load_dataset(folder), seed=1, population=8, generations=3)
    assert res.model["extensions"] == ["powertrain", "damper_curves"] and res.model["steps"] == 2
    assert res.adequacy["adequate"]
    err = {n: abs(res.parameters[n] / v - 1) for n, v in case.truth(sc).items()}
    assert max(err[n] for n in rideid.NAMES) < 0.01, err
    assert max(err[n] for n in ("m_p", "x_p", "f_pb", "f_pp")) < 0.005, err
    assert max(err[n] for n in ("I_p", "zeta_pb", "zeta_pp")) < 0.03, err
    assert case.curve_error(res.dampers) < 0.03
