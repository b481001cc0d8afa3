"""Test tracks of SPEC §2: road height under a wheel path.

A :class:`Track` gives, for a lateral offset ``y`` (m, left +), a
:class:`WheelPath`: the road height ``h(x)`` along the distance ``x`` (m),
flat (0) outside the track's features. Analytic kinds also give ``h'`` and
``h''``, which the contact-point ODE (:mod:`rideid.contact`) needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..csvio import read_csv_rows
from ..errors import DataError

KINDS = ("washboard", "herringbone", "chassis_twist", "flat", "profile")

_KEYS = {
    "washboard": {"start": None, "amplitude": None, "wavelength": None, "cycles": None},
    "herringbone": {"start": None, "amplitude": None, "wavelength": None, "cycles": None, "angle": None},
    "chassis_twist": {"start": None, "height": None, "bump_length": None, "spacing": None, "bumps": None,
                      "first": "left"},
    "flat": {},
    "profile": {"file": None},
}


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
    centres = np.asarray(centres, dtype=float)
    k = 2 * np.pi / length

    def each(x, f):
        x = np.asarray(x, dtype=float)
        out = np.zeros_like(x)
        for xc in centres:
            d = x - xc
            m = np.abs(d) <= length / 2
            out = out + np.where(m, f(d), 0.0)
        return out

    h = lambda x: each(x, lambda d: H / 2 * (1 + np.cos(k * d)))  # noqa: E731
    d1 = lambda x: each(x, lambda d: -H / 2 * k * np.sin(k * d))  # noqa: E731
    d2 = lambda x: each(x, lambda d: -H / 2 * k * k * np.cos(k * d))  # noqa: E731
    if centres.size == 0:
        return WheelPath(lambda x: np.zeros_like(np.asarray(x, float)), None)
    ext = (float(centres.min() - length / 2), float(centres.max() + length / 2))
    # concave where the bump meets the flat: radius 1/(H/2 k^2)
    return WheelPath(h, ext, d1, d2, min_trough_radius=1.0 / (abs(H) / 2 * k * k) if H else math.inf)


@dataclass
class Track:
    """A test track: ``id``, ``kind`` and the kind's keys (SPEC §2)."""

    id: str
    kind: str
    keys: dict
    base_dir: Path | None = None
    _profile: tuple | None = field(default=None, repr=False)
    _paths: dict = field(default_factory=dict, repr=False)

    @classmethod
    def from_table(cls, table: dict, where: str, base_dir: Path | None = None) -> "Track":
        """Build and validate a track from its TOML table.

        ``where`` names the place for messages, e.g. ``"dataset.toml: tracks[0]"``.
        """
        table = dict(table)
        tid = table.pop("id", None)
        if not isinstance(tid, str) or not tid:
            raise DataError(f"{where}: missing key 'id' (a non-empty string)")
        where = f"{where} (id '{tid}')"
        kind = table.pop("kind", None)
        if kind not in KINDS:
            raise DataError(f"{where}: unknown track kind {kind!r}; expected one of {', '.join(KINDS)}")
        spec = _KEYS[kind]
        for k in table:
            if k not in spec:
                allowed = ", ".join(["id", "kind", *spec]) or "id, kind"
                raise DataError(f"{where}: unknown key '{k}' for kind '{kind}' (allowed: {allowed})")
        keys = {}
        for k, default in spec.items():
            if k not in table:
                if default is None:
                    raise DataError(f"{where}: missing key '{k}' for kind '{kind}'")
                keys[k] = default
                continue
            v = table[k]
            if k == "file":
                if not isinstance(v, str):
                    raise DataError(f"{where}: key 'file' must be a path string")
                keys[k] = v
            elif k == "first":
                if v not in ("left", "right"):
                    raise DataError(f"{where}: key 'first' must be \"left\" or \"right\", got {v!r}")
                keys[k] = v
            else:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise DataError(f"{where}: key '{k}' must be a finite number, got {v!r}")
                keys[k] = float(v)
        for k in ("wavelength", "bump_length", "spacing"):
            if k in keys and keys[k] <= 0:
                raise DataError(f"{where}: key '{k}' must be positive, got {keys[k]}")
        for k in ("cycles", "bumps"):
            if k in keys:
                if keys[k] < 0 or keys[k] != int(keys[k]):
                    raise DataError(f"{where}: key '{k}' must be a non-negative whole number, got {keys[k]}")
        if "angle" in keys and not (-89.0 < keys["angle"] < 89.0):
            raise DataError(f"{where}: key 'angle' must be between -89 and 89 degrees, got {keys['angle']}")
        tr = cls(tid, kind, keys, base_dir)
        if kind == "profile":
            tr._load_profile(where)
        return tr

    def to_table(self) -> dict:
        return {"id": self.id, "kind": self.kind, **{k: (int(v) if k in ("cycles", "bumps") else v)
                                                   for k, v in self.keys.items()}}

    def _load_profile(self, where):
        path = Path(self.keys["file"])
        if not path.is_absolute() and self.base_dir is not None:
            path = self.base_dir / path
        header, body = read_csv_rows(path, f"{where}: profile file not found: {path}", "profile")
        for c in ("x", "z_left", "z_right"):
            if c not in header:
                raise DataError(f"{path}: missing column '{c}' (need x, z_left, z_right)")
        idx = [header.index(c) for c in ("x", "z_left", "z_right")]
        data = []
        for ln, row in enumerate(body, start=2):
            if not row:
                continue
            try:
                vals = [float(row[i]) for i in idx]
            except (ValueError, IndexError):
                raise DataError(f"{path}: line {ln}: not a number in columns x, z_left, z_right") from None
            if not all(math.isfinite(v) for v in vals):
                raise DataError(f"{path}: line {ln}: NaN or infinite value")
            data.append(vals)
        if len(data) < 2:
            raise DataError(f"{path}: a profile needs at least two rows")
        arr = np.array(data)
        if np.any(np.diff(arr[:, 0]) <= 0):
            raise DataError(f"{path}: column 'x' must be strictly increasing")
        self._profile = (arr[:, 0], arr[:, 1], arr[:, 2])

    def path(self, y: float) -> WheelPath:
        """The wheel path at lateral offset ``y`` (m, left +)."""
        key = round(float(y), 9)
        if key in self._paths:
            return self._paths[key]
        k = self.keys
        if self.kind == "flat":
            p = WheelPath(lambda x: np.zeros_like(np.asarray(x, float)), None,
                          lambda x: np.zeros_like(np.asarray(x, float)),
                          lambda x: np.zeros_like(np.asarray(x, float)))
        elif self.kind == "washboard":
            p = _sin_path(k["start"], k["amplitude"], k["wavelength"], int(k["cycles"]), 0.0)
        elif self.kind == "herringbone":
            shift = y * math.tan(math.radians(k["angle"]))
            p = _sin_path(k["start"], k["amplitude"], k["wavelength"], int(k["cycles"]), shift)
        elif self.kind == "chassis_twist":
            n = int(k["bumps"])
            left_first = k["first"] == "left"
            is_left = y > 0
            offset = 0.0 if is_left == left_first else 0.5
            centres = k["start"] + (np.arange(n) + offset) * k["spacing"]
            p = _cos_bumps(centres, k["height"], k["bump_length"])
        elif self.kind == "profile":
            xs, zl, zr = self._profile
            z = zl if y > 0 else zr
            lo, hi = float(xs[0]), float(xs[-1])
            p = WheelPath(lambda x, xs=xs, z=z: np.interp(x, xs, z, left=0.0, right=0.0), (lo, hi))
        else:  # pragma: no cover - validated in from_table
            raise DataError(f"unknown kind {self.kind}")
        self._paths[key] = p
        return p
