"""Tracks and the two road-contact methods."""

import numpy as np
import pytest

from rideid.model.contact import (ContactODEError, contact_ode, envelope, envelope_grid, wheel_input,
                                  wheel_input_slope)
from rideid.errors import DataError
from rideid.data.schema.tracks import track_from_table

R = 0.3


def washboard(L=0.6, A=0.01, cycles=10):
    return track_from_table(dict(id="w", kind="washboard", start=2.0, amplitude=A, wavelength=L, cycles=cycles), "t")


def brute(h, x, R, n=400001):
    s = np.linspace(x - R, x + R, n)
    return float(np.max(h(s) + np.sqrt(np.maximum(R * R - (s - x) ** 2, 0)) - R))


def test_track_kinds_heights():
    w = washboard()
    x = np.array([1.0, 2.15, 8.5])
    np.testing.assert_allclose(w.path(0.7).height(x), [0, 0.01, 0], atol=1e-15)
    np.testing.assert_array_equal(w.path(0.7).height(x), w.path(-0.7).height(x))
    hb = track_from_table(dict(id="h", kind="herringbone", start=2.0, amplitude=0.01, wavelength=0.5,
                               cycles=10, angle=30.0), "t")
    shift = 2 * 0.7 * np.tan(np.radians(30))
    xs = np.linspace(4, 5, 11)
    # the left wheel sees the right wheel's wave shifted by track * tan(angle)
    np.testing.assert_allclose(hb.path(0.7).height(xs), hb.path(-0.7).height(xs + shift), atol=1e-15)
    tw = track_from_table(dict(id="t", kind="chassis_twist", start=3.0, height=0.05, bump_length=1.0,
                               spacing=4.0, bumps=2), "t")
    assert tw.path(0.7).height(np.array([3.0]))[0] == pytest.approx(0.05)
    assert tw.path(-0.7).height(np.array([3.0]))[0] == 0
    assert tw.path(-0.7).height(np.array([5.0]))[0] == pytest.approx(0.05)
    assert tw.path(0.7).height(np.array([3.25]))[0] == pytest.approx(0.025)
    tr = track_from_table(dict(id="t", kind="chassis_twist", start=3.0, height=0.05, bump_length=1.0,
                               spacing=4.0, bumps=2, first="right"), "t")
    assert tr.path(-0.7).height(np.array([3.0]))[0] == pytest.approx(0.05)
    flat = track_from_table(dict(id="f", kind="flat"), "t")
    assert np.all(flat.path(0.5).height(xs) == 0)


def test_profile_track(tmp_path):
    f = tmp_path / "p.csv"
    f.write_text("x,z_left,z_right\n1.0,0.0,0.0\n1.5,0.02,0.0\n2.0,0.0,0.01\n")
    tr = track_from_table(dict(id="p", kind="profile", file="p.csv"), "t", base_dir=tmp_path)
    np.testing.assert_allclose(tr.path(0.7).height(np.array([0.5, 1.25, 1.5, 3.0])), [0, 0.01, 0.02, 0])
    np.testing.assert_allclose(tr.path(-0.7).height(np.array([1.75])), [0.005])


@pytest.mark.parametrize("table, msg", [
    (dict(id="w", kind="washbord"), "unknown track kind 'washbord'"),
    (dict(id="w", kind="washboard", start=1, amplitude=0.01, wavelength=0.5), "missing key 'cycles'"),
    (dict(id="w", kind="washboard", start=1, amplitude=0.01, wavelength=0.5, cycles=3, angle=3),
     "unknown key 'angle'"),
    (dict(id="w", kind="washboard", start=1, amplitude=0.01, wavelength=-0.5, cycles=3),
     "'wavelength' must be positive"),
    (dict(id="w", kind="profile", file="nope.csv"), "profile file not found"),
])
def test_track_bad_input(table, msg):
    with pytest.raises(DataError, match=msg):
        track_from_table(table, "dataset.toml: tracks[0]")


@pytest.mark.parametrize("L", [0.3, 0.6, 1.2])
def test_envelope_matches_brute_force(L):
    p = washboard(L=L).path(0.7)
    xs = np.array([1.8, 2.05, 3.33, 4.71, 5.0])
    env = envelope(p.h, xs, R)
    x0, dx, vals = envelope_grid(p, R)
    grid = np.interp(xs, x0 + dx * np.arange(vals.size), vals)
    for i, x in enumerate(xs):
        b = brute(p.h, x, R)
        assert env[i] == pytest.approx(b, abs=2e-6)
        assert grid[i] == pytest.approx(b, abs=2e-6)
    # the envelope is never below the road under the wheel centre
    xx = np.linspace(1.5, 9, 2000)
    # (up to the linear interpolation of the tabulated envelope)
    assert np.all(wheel_input(p, xx, R) >= p.h(xx) - 1e-6)


def test_envelope_vs_contact_ode_sinusoid():
    # inside the sinusoid, started from the exact contact point
    p = washboard(L=0.6).path(0.7)
    t = np.linspace(0, 0.7, 1401)  # stays inside the washboard (2 m .. 8 m)
    V = 5.0
    r_ode = contact_ode(p, R, V, t, x0=4.0)
    np.testing.assert_allclose(r_ode, envelope(p.h, 4.0 + V * t, R), atol=1e-9)
    np.testing.assert_allclose(r_ode, wheel_input(p, 4.0 + V * t, R), atol=1e-7)
    # far from a sinusoid: the disc input differs strongly from the profile
    assert np.max(np.abs(r_ode - p.h(4.0 + V * t))) > 0.1 * 0.01


def test_envelope_vs_contact_ode_twist_whole_run():
    tw = track_from_table(dict(id="t", kind="chassis_twist", start=2.0, height=0.08, bump_length=1.5,
                               spacing=4.0, bumps=3), "t")
    p = tw.path(0.69)
    t = np.linspace(0, 3.0, 3001)
    np.testing.assert_allclose(contact_ode(p, R, 5.0, t), envelope(p.h, 5.0 * t, R), atol=1e-8)


def test_contact_ode_invalid_when_wheel_bridges_troughs():
    A, L = 0.01, 0.3
    limit = L * L / (4 * np.pi ** 2 * A)  # 0.228 m: the trough radius of curvature
    p = washboard(L=L, A=A).path(0.7)
    assert p.min_trough_radius == pytest.approx(limit)
    with pytest.raises(ContactODEError, match="bridges"):
        contact_ode(p, R, 5.0, np.linspace(0, 1, 11), x0=4.0)
    # just below the limit the ODE is valid and agrees with the envelope
    r_ok = 0.95 * limit
    t = np.linspace(0, 0.3, 601)
    np.testing.assert_allclose(contact_ode(p, r_ok, 5.0, t, x0=2.5), envelope(p.h, 2.5 + 5.0 * t, r_ok),
                               atol=1e-8)
    # above it the envelope has kinks: the wheel never touches the trough bottoms
    xs = np.linspace(2.5, 4.5, 2001)
    env = envelope(p.h, xs, R)
    assert env.min() > -A + 5e-4


def test_envelope_grid_cached_and_flat_outside():
    p = washboard().path(0.7)
    assert envelope_grid(p, R) is envelope_grid(p, R)
    assert np.all(wheel_input(p, np.array([-5.0, 1.69, 8.31, 20.0]), R) == 0)


def test_compiled_interpolation_is_numpy_interp(monkeypatch):
    """The envelope read at any positions by the compiled uniform-grid interpolation equals ``numpy.interp`` on
    the grid (binary search) to rounding: inside, at the table's ends, outside (zero), written into a column of a
    wider array, and by the NumPy fallback where no compiled kernel can be built; the compiled slope equals the
    NumPy one, contact jumps included."""
    from rideid.model import backend

    p = washboard().path(0.7)
    x0, step, vals = envelope_grid(p, R)
    rng = np.random.default_rng(4)
    x = np.concatenate([rng.uniform(x0 - 1.0, x0 + step * vals.size + 1.0, 20000),
                        x0 - 0.25 + step * np.array([0.0, 0.5, vals.size - 1.5, vals.size - 1.0]), [x0 - 0.25 - 1e-9]])
    want = np.interp(x + 0.25, x0 + step * np.arange(vals.size), vals, left=0.0, right=0.0)
    wide = np.full((x.size, 3), np.nan)
    got = wheel_input(p, x, R, shift=0.25, out=wide[:, 1])
    assert backend.compiled_available("contact")
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13 * np.abs(vals).max())  # positions' rounding
    np.testing.assert_array_equal(wide[:, 1], got)
    assert np.isnan(wide[:, [0, 2]]).all()        # only its column written
    assert np.count_nonzero(want) > 10000 and got[-1] == 0.0
    slope = wheel_input_slope(p, x, R, shift=0.25, out=wide[:, 0])
    monkeypatch.setattr(backend, "_STATUS", {"contact": False})
    np.testing.assert_array_equal(wheel_input(p, x, R, shift=0.25), want)
    # the slope, compiled against NumPy, on a washboard whose troughs the disc bridges (the contact jumps)
    np.testing.assert_allclose(slope, wheel_input_slope(p, x, R, shift=0.25), rtol=0, atol=1e-12)
    monkeypatch.setattr(backend, "_STATUS", {})
    q = washboard(L=0.1).path(0.7)
    off = envelope_grid(q, R) and q._env_cache[(R, 5e-4, "contact")]
    assert (np.abs(np.diff(off)) > 3 * 5e-4).sum() >= 10   # the contact point jumps (the troughs are bridged)
    compiled = wheel_input_slope(q, x, R)
    monkeypatch.setattr(backend, "_STATUS", {"contact": False})
    want_slope = wheel_input_slope(q, x, R)
    assert np.abs(want_slope).max() > 0.2
    np.testing.assert_allclose(compiled, want_slope, rtol=0, atol=1e-12)


@pytest.mark.parametrize("road", ["flat", "rough", "sine", "steps", "white", "spikes"])
def test_lattice_search_equals_brute_force(road):
    """The divide-and-conquer disc search (monotone argmax) returns the brute-force maxima and first
    argmaxima, exactly: on smooth, rough, stepped, white-noise and spiked roads (where ties and jumps of
    the contact point are many)."""
    from numpy.lib.stride_tricks import sliding_window_view

    from rideid.model.contact import lattice_max, lattice_max_numpy
    rng = np.random.default_rng(7)
    dx, R = 5e-4, 0.3
    m = int(R / dx)
    offs = dx * np.arange(-m, m + 1)
    circ = np.sqrt(R * R - offs * offs)
    x = dx * np.arange(20000)
    H = {"flat": np.zeros_like(x),
         "rough": np.cumsum(rng.standard_normal(x.size)) * 1e-4,
         "sine": 0.02 * np.sin(2 * np.pi * x / 0.7) * (x > 3) * (x < 7),
         "steps": 0.03 * np.floor(x / 0.9) % 0.09, "white": rng.standard_normal(x.size) * 1e-3,
         "spikes": (rng.random(x.size) < 0.01) * 0.05}[road]
    best, arg = lattice_max(H, circ)
    V = sliding_window_view(H, circ.size) + circ[None, :]  # every disc position, every offset
    ref, ref_arg = V.max(axis=1), V.argmax(axis=1)
    assert np.array_equal(best, ref)
    assert np.array_equal(arg, ref_arg)
    # the backend without the compiled kernels: the same maxima and argmaxima
    best_np, arg_np = lattice_max_numpy(H, circ)
    assert np.array_equal(best_np, ref) and np.array_equal(arg_np, ref_arg)
