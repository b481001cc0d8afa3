"""Track kinds as classes: the registry, construction by kind, per-kind checks."""

import math

import numpy as np
import pytest

import rideid
from rideid.data.schema.tracks import track_from_table
from rideid.errors import DataError
from rideid.model.tracks import (KINDS, TRACK_KINDS, ChassisTwistTrack, FlatTrack, HerringboneTrack, ProfileTrack,
                                 WashboardTrack)

WB = dict(start=1.0, amplitude=0.01, wavelength=0.5, cycles=3.0)


def test_registry_holds_the_spec_kinds():
    assert set(KINDS) == {"washboard", "herringbone", "chassis_twist", "flat", "profile"}
    assert {k: c.KIND for k, c in TRACK_KINDS.items()} == {k: k for k in KINDS}


@pytest.mark.parametrize("table, cls", [
    (dict(id="w", kind="washboard", **WB), WashboardTrack),
    (dict(id="h", kind="herringbone", angle=30.0, **WB), HerringboneTrack),
    (dict(id="t", kind="chassis_twist", start=2.0, height=0.05, bump_length=1.0, spacing=3.0, bumps=2),
     ChassisTwistTrack),
    (dict(id="f", kind="flat"), FlatTrack),
])
def test_kind_picks_class_and_round_trips(table, cls):
    tr = track_from_table(table, "t")
    assert type(tr) is cls and isinstance(tr, rideid.Track)
    again = rideid.Track(tr.id, tr.kind, dict(tr.keys))  # the constructor dispatches on kind too
    assert type(again) is cls
    x = np.linspace(0.0, 12.0, 241)
    for y in (0.7, -0.7):
        assert np.array_equal(again.path(y).height(x), tr.path(y).height(x))
    back = track_from_table(tr.to_table(), "t")
    assert back.to_table() == tr.to_table() and back.data_file is None


def test_herringbone_shift_is_the_angle():
    # crests at 30 degrees: the right wheel path (y = -0.7) leads by 0.7 tan 30 deg more than the centre
    hb = track_from_table(dict(id="h", kind="herringbone", angle=30.0, **WB), "t")
    wb = track_from_table(dict(id="w", kind="washboard", **WB), "t")
    shift = 0.7 * math.tan(math.radians(30.0))
    x = np.linspace(2.0, 2.4, 9)
    assert np.allclose(hb.path(0.7).height(x - shift), wb.path(0.7).height(x), atol=1e-15)
    assert hb.path(0.7).extent == pytest.approx((1.0 - shift, 2.5 - shift))


def test_chassis_twist_first_right_swaps_sides():
    base = dict(id="t", kind="chassis_twist", start=2.0, height=0.05, bump_length=1.0, spacing=3.0, bumps=2)
    left = track_from_table(base, "t")
    right = track_from_table({**base, "first": "right"}, "t")
    assert left.path(0.7).extent == right.path(-0.7).extent == (1.5, 5.5)
    assert left.path(-0.7).extent == right.path(0.7).extent == (3.0, 7.0)


def test_profile_data_file_resolves_against_base_dir(tmp_path):
    (tmp_path / "p.csv").write_text("x,z_left,z_right\n0,0,0\n1,0.01,0.02\n")
    tr = track_from_table(dict(id="p", kind="profile", file="p.csv"), "t", base_dir=tmp_path)
    assert type(tr) is ProfileTrack and tr.data_file == tmp_path / "p.csv"
    assert tr.path(0.7).height(0.5) == pytest.approx(0.005) and tr.path(-0.7).height(0.5) == pytest.approx(0.01)


@pytest.mark.parametrize("table, msg", [
    (dict(id="t", kind="chassis_twist", start=2.0, height=0.05, bump_length=1.0, spacing=3.0, bumps=2, first="up"),
     "key 'first' must be \"left\" or \"right\", got 'up'"),
    (dict(id="t", kind="chassis_twist", start=2.0, height=0.05, bump_length=1.0, spacing=0.0, bumps=2),
     "key 'spacing' must be positive, got 0.0"),
    (dict(id="t", kind="chassis_twist", start=2.0, height=0.05, bump_length=1.0, spacing=3.0, bumps=1.5),
     "key 'bumps' must be a non-negative whole number, got 1.5"),
    (dict(id="h", kind="herringbone", angle=89.0, **WB), "key 'angle' must be between -89 and 89 degrees, got 89.0"),
    (dict(id="w", kind="washboard", **{**WB, "cycles": True}), "key 'cycles' must be a finite number, got True"),
    (dict(id="p", kind="profile", file=3), "key 'file' must be a path string"),
    (dict(id="f", kind="flat", start=1.0), r"unknown key 'start' for kind 'flat' \(allowed: id, kind\)"),
])
def test_per_kind_checks(table, msg):
    with pytest.raises(DataError, match=msg):
        track_from_table(table, "dataset.toml: tracks[0]")


def test_constructor_rejects_unknown_or_mismatched_kind():
    with pytest.raises(DataError, match="unknown track kind 'bumpy'"):
        rideid.Track("x", "bumpy", {})
    with pytest.raises(DataError, match="kind 'flat' does not match WashboardTrack"):
        WashboardTrack("x", "flat", {})


def test_the_track_model_reads_no_file_and_imports_no_data_layer():
    """model/tracks.py holds numbers and arrays: the CSV and TOML reading is data/schema/tracks.py's."""
    import ast
    from pathlib import Path

    src = Path(rideid.__file__).parent / "model" / "tracks.py"
    tree = ast.parse(src.read_text())
    mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    mods |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert not any(m and ({"csvio", "data"} & set(m.split(".")) or m in ("csv", "tomllib")) for m in mods), mods
    assert "open(" not in src.read_text() and not hasattr(rideid.Track, "from_table")


def test_profile_file_gives_the_track_of_its_arrays(tmp_path):
    x = np.array([0.0, 1.0, 2.5])
    zl, zr = np.array([0.0, 0.02, -0.01]), np.array([0.01, 0.0, 0.03])
    (tmp_path / "p.csv").write_text("x,z_left,z_right\n" + "".join(f"{a},{b},{c}\n" for a, b, c in zip(x, zl, zr)))
    read = track_from_table(dict(id="p", kind="profile", file="p.csv"), "t", base_dir=tmp_path)
    made = ProfileTrack.from_arrays("p", x, zl, zr, file="p.csv", base_dir=tmp_path)
    assert read.to_table() == made.to_table() == {"id": "p", "kind": "profile", "file": "p.csv"}
    assert read.data_file == made.data_file == tmp_path / "p.csv"
    xs = np.linspace(-1, 3, 41)
    for y in (0.8, -0.8):  # left (+) and right wheel paths: linear interpolation, flat outside
        z = zl if y > 0 else zr
        assert np.array_equal(read.path(y).height(xs), np.interp(xs, x, z, left=0.0, right=0.0))
        assert np.array_equal(read.path(y).height(xs), made.path(y).height(xs))
    assert read.path(0.8).height(1.75) == pytest.approx(0.02 + 0.75 / 1.5 * (-0.03))
