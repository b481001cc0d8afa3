"""SPEC §1 is small-angle: the statement of how far the fitted body turned and which error bars that makes
optimistic (estimate.assess.small_angle; the bias per degree measured on the MuJoCo car, docs/verification.md)."""

from types import SimpleNamespace

import numpy as np
import pytest

from rideid.estimate.assess.small_angle import BIAS_PER_DEGREE, THRESHOLD_DEG, body_angles, small_angle
from rideid.model.equations import CHANNELS

FS = 200.0


def _response(roll_deg, pitch_deg, f=1.5, T=4.0):
    """Channels whose gyros are the rates of roll = A sin(w t), pitch = B sin(w t): the angles' closed form."""
    t = np.arange(int(T * FS)) / FS
    w = 2 * np.pi * f
    y = np.zeros((t.size, len(CHANNELS)))
    y[:, CHANNELS.index("roll_rate")] = np.radians(roll_deg) * w * np.cos(w * t)
    y[:, CHANNELS.index("pitch_rate")] = np.radians(pitch_deg) * w * np.cos(w * t)
    return y


def _result(response, std_rel):
    params = {"k_sf": 24000.0, "I_xx": 207.0, "m_s": 965.0}
    details = {"k_sf": {"fixed": False, "std_total": std_rel["k_sf"] * 24000.0},
               "I_xx": {"fixed": False, "std_total": std_rel["I_xx"] * 207.0},
               "m_s": {"fixed": False, "derived": True, "std_total": 1e-9}}
    return SimpleNamespace(response=response, details=details, parameters=params)


def test_body_angles_integrate_the_gyros():
    ang = body_angles({"T": _response(2.3, 0.7), "H": _response(0.4, 1.2)}, {"T": FS, "H": FS})
    assert ang["T"]["roll"] == pytest.approx(2.3, rel=1e-3) and ang["T"]["pitch"] == pytest.approx(0.7, rel=1e-3)
    assert ang["H"]["roll"] == pytest.approx(0.4, rel=1e-3) and ang["H"]["pitch"] == pytest.approx(1.2, rel=1e-3)


def test_a_body_that_rolls_degrees_names_the_error_bars_narrower_than_the_bias():
    """2.3 degrees of roll: the bias measured on the MuJoCo car, 0.12 %; k_sf's ±2 std_total (0.04 %) is narrower
    and named, I_xx's (0.4 %) is not, the derived m_s is not judged."""
    res = _result({"T": _response(2.3, 0.7), "H": _response(0.4, 1.2)}, {"k_sf": 2e-4, "I_xx": 2e-3})
    sa = small_angle(res, {"T": FS, "H": FS})
    assert sa["roll_run"] == "T" and sa["pitch_run"] == "H"
    assert sa["expected_bias"] == pytest.approx(0.0012, rel=1e-3)
    assert sa["optimistic"] == ["k_sf"]
    assert "2.3 deg (T)" in sa["note"] and "0.12 %" in sa["note"] and "k_sf" in sa["note"]
    assert BIAS_PER_DEGREE * 2.3 == pytest.approx(0.0012)


def test_small_angles_say_nothing():
    res = _result({"T": _response(0.8 * THRESHOLD_DEG, 0.3)}, {"k_sf": 1e-5, "I_xx": 1e-5})
    sa = small_angle(res, {"T": FS})
    assert sa["note"] is None and sa["optimistic"] == [] and sa["largest_roll_deg"] == pytest.approx(0.8, rel=1e-3)
    assert small_angle(SimpleNamespace(response=None, details={}, parameters={}), {}) is None
