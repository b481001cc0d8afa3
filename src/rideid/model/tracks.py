"""Test tracks of SPEC §2: road height under a wheel path.

A :class:`Track` gives, for a lateral offset ``y`` (m, left +), a
:class:`WheelPath`: the road height ``h(x)`` along the distance ``x`` (m),
flat (0) outside the track's features. Analytic kinds also give ``h'`` and
``h''``, which the contact-point ODE (:mod:`rideid.contact`) needs.

Each SPEC kind is one small subclass of :class:`Track` (its wheel path);
:data:`TRACK_KINDS` maps the ``kind`` string to the class, and
``Track(id, kind, keys)`` picks the class from ``kind``. A track holds
numbers and arrays only: reading ``[[tracks]]`` tables and profile files
(their keys, checks and messages) is :mod:`rideid.data.schema.tracks`'s.
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import numpy as np

from ..errors import DataError

@dataclass
class WheelPath:
    """Road height along one wheel path.

    ``h(x)`` is vectorised; ``d1``/``d2`` (first/second derivative) exist
    for analytic kinds only. ``extent`` is ``(lo, hi)``: outside it the road
    is flat (height 0).
    """

    h: object
    extent: tuple[float, float] | None
    d1: object = None
    d2: object = None
    #: smallest radius of curvature of a concave (trough) part, m; inf if none
    min_trough_radius: float = math.inf
    _env_cache: dict = field(default_factory=dict, repr=False)

    def height(self, x):
        x = np.asarray(x, dtype=float)
        return self.h(x)


def _zeros(x):
    """Height 0 (or its derivatives) at every ``x``."""
    return np.zeros_like(np.asarray(x, float))


def _sin_path(start, A, L, n, shift):
    """h = A sin(2 pi u / L) for 0 <= u <= n L, u = x - start + shift."""
    k = 2 * np.pi / L
    end = n * L

    def u_of(x):
        return x - start + shift

    def h(x):
        u = u_of(x)
        return np.where((u >= 0) & (u <= end), A * np.sin(k * u), 0.0)

    def d1(x):
        u = u_of(x)
        return np.where((u >= 0) & (u <= end), A * k * np.cos(k * u), 0.0)

    def d2(x):
        u = u_of(x)
        return np.where((u >= 0) & (u <= end), -A * k * k * np.sin(k * u), 0.0)

    lo = start - shift
    # concave parts (troughs): radius of curvature 1/(A k^2) at the bottom
    return WheelPath(h, (lo, lo + end), d1, d2, min_trough_radius=1.0 / (abs(A) * k * k) if A else math.inf)


def _cos_bumps(centres, H, length):
    """Raised-cosine bumps h = H/2 (1 + cos(2 pi (x - xc)/l)), |x - xc| <= l/2."""
    centres = np.sort(np.asarray(centres, dtype=float))
    k = 2 * np.pi / length
    # the bumps that may reach a point: those whose centres lie within half a length of it (and a rounding's
    # margin: the test of |x - xc| <= length / 2 below decides), found by bisection, not every bump at every point
    reach = length / 2 * (1 + 1e-9) + 1e-12

    def each(x, f):
        x = np.asarray(x, dtype=float)
        out = np.zeros_like(x)
        lo = np.searchsorted(centres, x - reach, side="left")
        hi = np.searchsorted(centres, x + reach, side="right")
        for q in range(int(np.max(hi - lo, initial=0))):
            j = lo + q
            d = x - centres[np.minimum(j, centres.size - 1)]
            m = (j < hi) & (np.abs(d) <= length / 2)
            out = out + np.where(m, f(d), 0.0)
        return out

    h = lambda x: each(x, lambda d: H / 2 * (1 + np.cos(k * d)))  # noqa: E731
    d1 = lambda x: each(x, lambda d: -H / 2 * k * np.sin(k * d))  # noqa: E731
    d2 = lambda x: each(x, lambda d: -H / 2 * k * k * np.cos(k * d))  # noqa: E731
    if centres.size == 0:
        return WheelPath(_zeros, None)
    ext = (float(centres.min() - length / 2), float(centres.max() + length / 2))
    # concave where the bump meets the flat: radius 1/(H/2 k^2)
    return WheelPath(h, ext, d1, d2, min_trough_radius=1.0 / (abs(H) / 2 * k * k) if H else math.inf)


@dataclass
class Track:
    """A test track: ``id``, ``kind`` and the kind's keys (SPEC §2), already checked.

    The base of the per-kind classes; ``Track(id, kind, keys)`` builds the
    class registered for ``kind`` in :data:`TRACK_KINDS`. ``base_dir``: the
    folder a profile's ``file`` is relative to. Build one from a TOML table
    with :func:`rideid.data.schema.tracks.track_from_table`.
    """

    id: str
    kind: str
    keys: dict
    base_dir: Path | None = None
    _profile: tuple | None = field(default=None, repr=False)
    _paths: dict = field(default_factory=dict, repr=False)

    #: the SPEC ``kind`` string of the class
    KIND: ClassVar[str] = ""

    def __new__(cls, *args, **kwargs):
        if cls is Track:
            kind = args[1] if len(args) > 1 else kwargs.get("kind")
            if kind not in TRACK_KINDS:
                raise DataError(f"unknown track kind {kind!r}; expected one of {', '.join(KINDS)}")
            cls = TRACK_KINDS[kind]
        return super().__new__(cls)

    def __post_init__(self):
        if self.kind != self.KIND:
            raise DataError(f"track '{self.id}': kind {self.kind!r} does not match {type(self).__name__} "
                            f"(kind {self.KIND!r})")

    @property
    def data_file(self) -> Path | None:
        """The file the track's road comes from (resolved against ``base_dir``), or None."""
        return None

    def to_table(self) -> dict:
        return {"id": self.id, "kind": self.kind, **{k: (int(v) if k in ("cycles", "bumps") else v)
                                                   for k, v in self.keys.items()}}

    def path(self, y: float) -> WheelPath:
        """The wheel path at lateral offset ``y`` (m, left +): of an analytic kind, one object for every track of
        the same kind and keys (:func:`_shared_path`), so that its tabulated envelope is made once."""
        key = round(float(y), 9)
        if key not in self._paths:
            self._paths[key] = _shared_path(self, float(y))
        return self._paths[key]

    def _wheel_path(self, y: float) -> WheelPath:  # pragma: no cover - every kind overrides
        raise NotImplementedError


class FlatTrack(Track):
    """``flat``: no features; height 0 everywhere."""

    KIND = "flat"

    def _wheel_path(self, y):
        return WheelPath(_zeros, None, _zeros, _zeros)


class WashboardTrack(Track):
    """``washboard``: ``cycles`` sine waves from ``start``, the same under both wheels."""

    KIND = "washboard"

    def _wheel_path(self, y):
        k = self.keys
        return _sin_path(k["start"], k["amplitude"], k["wavelength"], int(k["cycles"]), self._shift(y))

    def _shift(self, y):
        """Distance (m) the wave is ahead at lateral offset ``y``: none on a washboard."""
        return 0.0


class HerringboneTrack(WashboardTrack):
    """``herringbone``: a washboard whose crests cross the road at ``angle`` degrees."""

    KIND = "herringbone"

    def _shift(self, y):
        return y * math.tan(math.radians(self.keys["angle"]))


class ChassisTwistTrack(Track):
    """``chassis_twist``: raised-cosine bumps alternating left and right, ``first`` side first."""

    KIND = "chassis_twist"

    def _wheel_path(self, y):
        k = self.keys
        left_first = k["first"] == "left"
        offset = 0.0 if (y > 0) == left_first else 0.5
        centres = k["start"] + (np.arange(int(k["bumps"])) + offset) * k["spacing"]
        return _cos_bumps(centres, k["height"], k["bump_length"])


class ProfileTrack(Track):
    """``profile``: measured heights ``z_left``/``z_right`` against ``x`` (a CSV file's, read by
    :func:`rideid.data.schema.tracks.read_profile`, or arrays)."""

    KIND = "profile"

    @classmethod
    def from_arrays(cls, tid: str, x, z_left, z_right, file: str | None = None,
                    base_dir: Path | None = None) -> "ProfileTrack":
        """A profile from arrays (a generated road, :mod:`rideid.model.roads`, or a profile file's columns).

        ``x`` (m) strictly increasing, ``z_left``/``z_right`` (m) the heights
        under the left and right wheel paths, shape (n,) each, n >= 2; linearly
        interpolated, flat outside. ``file``: the profile file they were read
        from (relative to ``base_dir``), or None (``data_file`` is then None).
        """
        x, zl, zr = (np.array(a, dtype=float) for a in (x, z_left, z_right))
        if x.ndim != 1 or x.size < 2 or zl.shape != x.shape or zr.shape != x.shape:
            raise DataError(f"track '{tid}': x, z_left and z_right must be 1-D arrays of one length (at least 2)")
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(zl)) and np.all(np.isfinite(zr))):
            raise DataError(f"track '{tid}': NaN or infinite value in the profile")
        if np.any(np.diff(x) <= 0):
            raise DataError(f"track '{tid}': x must be strictly increasing")
        tr = cls(tid, cls.KIND, {"file": file}, base_dir)
        tr._profile = (x, zl, zr)
        return tr

    @property
    def data_file(self) -> Path | None:
        if self.keys["file"] is None:
            return None
        path = Path(self.keys["file"])
        if not path.is_absolute() and self.base_dir is not None:
            path = self.base_dir / path
        return path

    def _wheel_path(self, y):
        xs, zl, zr = self._profile
        z = zl if y > 0 else zr
        return WheelPath(lambda x: np.interp(x, xs, z, left=0.0, right=0.0), (float(xs[0]), float(xs[-1])))


#: the wheel paths of analytic tracks, by kind, keys and offset (:func:`_shared_path`; the last 64)
_PATHS: OrderedDict = OrderedDict()
_PATHS_LOCK = threading.Lock()


def _shared_path(track: Track, y: float) -> WheelPath:
    """``track``'s wheel path at ``y``, shared by every track of its kind and keys (a profile's: its own). A wheel
    path caches its envelopes (:func:`rideid.model.contact.envelope_grid`), and every load of a dataset, every
    simulation and every test builds its tracks again from their tables: the built-in scenario's envelopes took
    5 % of the test suite's time, tabulated again on each load."""
    if isinstance(track, ProfileTrack):
        return track._wheel_path(y)
    try:
        key = (track.KIND, tuple(sorted(track.keys.items())), round(y, 9))
        hash(key)
    except TypeError:
        return track._wheel_path(y)
    with _PATHS_LOCK:
        hit = _PATHS.get(key)
        if hit is not None:
            _PATHS.move_to_end(key)
            return hit
    path = track._wheel_path(y)
    with _PATHS_LOCK:
        path = _PATHS.setdefault(key, path)
        while len(_PATHS) > 64:
            _PATHS.popitem(last=False)
    return path


#: SPEC track kind -> its class
TRACK_KINDS: dict[str, type[Track]] = {c.KIND: c for c in (WashboardTrack, HerringboneTrack, ChassisTwistTrack,
                                                          FlatTrack, ProfileTrack)}
KINDS = tuple(TRACK_KINDS)
