"""Scenarios: loading one, the built-in car and tracks, moving starts and generated roads (SPEC §9).

The scenario file format itself is :mod:`rideid.data.schema.manifest`;
simulating a scenario and writing it as a dataset is :mod:`rideid.synth.scenario`.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import ArgumentError
from . import checks
from .schema import RunSpec, Scenario, parse_scenario, read_toml
from ..model.equations import state_space
from ..model.params import as_vector
from ..model.roads import ROAD_CLASSES, iso8608_class, iso8608_profile
from ..model.tracks import ProfileTrack
from ..model.posts import prepare_function
from ..model.simulate import prepare_run


#: the name that stands for the built-in scenario wherever a scenario file is asked for
BUILTIN = "builtin"


def default_scenario_path() -> Path:
    """Path of the built-in scenario TOML (the BMW 320i on the paper's ten runs)."""
    return Path(str(resources.files("rideid.data") / "default_scenario.toml"))


def load_scenario(path) -> Scenario:
    """Read and validate a scenario file (SPEC §3, §6), its numbers checked for plausibility.

    Parameters
    ----------
    path : str or Path
        The scenario file, or ``"builtin"`` (:data:`BUILTIN`) for the
        built-in one (:func:`default_scenario_path`), as study files say.

    Returns
    -------
    Scenario
        Frozen; derive another with :func:`dataclasses.replace`.

    Raises
    ------
    DataError
        Naming the file and the key at fault.
    """
    path = default_scenario_path() if str(path) == BUILTIN else Path(path)
    sc = parse_scenario(read_toml(path), path)
    checks.enforce(checks.check_numbers(sc))
    return sc


def default_scenario() -> Scenario:
    """The built-in scenario (:func:`default_scenario_path`), loaded."""
    return load_scenario(default_scenario_path())


def run_times(run: RunSpec) -> np.ndarray:
    """``t = k / fs`` for ``k = 0 .. round(duration fs)`` (SPEC §3)."""
    n = int(round(run.duration * run.fs))
    return np.arange(n + 1) / run.fs


# ---------------------------------------------------------------------------
# Moving starts and generated roads (SPEC §9)

#: a moving run's lead-in lets the start transient decay to this fraction of its initial size
SETTLE_FRACTION = 1e-3
#: bounds of the settling part of a lead-in, s
SETTLE_MIN, SETTLE_MAX = 2.0, 30.0
#: a generated road fades in from flat over the distance the car covers in this time, s
ROAD_FADE = 1.0
#: sample spacing of a generated road, m. ISO 8608's band ends at 2.83 cycles/m (a 0.35 m wavelength), but
#: the profile is interpolated linearly between its samples and the kinks are road texture at the spacing's
#: wavelength, which the rear wheels meet between the front wheels' samples: on a 5 cm grid it biased the
#: unknown-road fit's tires by -0.5 % (15 m/s, 200 Hz, no noise), on a 1 cm grid < 0.02 % (docs/any-road.md)
ROAD_DX = 0.01
#: road written to ``road_truth/<run>.csv`` behind the rear axle at t = 0 and beyond the front axle at the end, m
ROAD_MARGIN = 1.0
#: tag of the seed stream of generated roads (independent of the noise's)
_ROAD_STREAM = 8608


def settle_time(P, geom) -> float:
    """Time (s) for the car's slowest mode to decay to :data:`SETTLE_FRACTION` of its size.

    ``ln(1 / SETTLE_FRACTION) / sigma_min``, ``sigma_min`` the smallest decay
    rate ``-Re(lambda)`` over the eigenvalues of the linear 7-DOF model
    (SPEC §1, §6; a nonlinear car by its linear part, c_sf and c_sr the
    curves' mean slope), clipped to [:data:`SETTLE_MIN`, :data:`SETTLE_MAX`].
    """
    A = state_space(np.atleast_2d(np.asarray(P, dtype=float)), geom)[0][0]
    sigma = float(np.min(-np.linalg.eigvals(A).real))
    T = np.log(1.0 / SETTLE_FRACTION) / sigma if sigma > 0 else SETTLE_MAX
    return float(np.clip(T, SETTLE_MIN, SETTLE_MAX))


def flat_before(track, geom, speed: float) -> float:
    """Seconds before x = 0 at ``speed`` (m/s) from which every wheel's road of ``track`` is flat up to the front
    axle's arrival there: the front axle a tire radius before the first feature (0 when none lies before it)."""
    starts = [e[0] for e in (track.path(y).extent for y in geom.corner_y) if e is not None]
    if not starts:
        return 0.0
    return max(0.0, (geom.tire_radius - min(starts)) / speed)


def lead_in(sc: Scenario, run: RunSpec) -> float:
    """Seconds a moving run is simulated before its first sample (0 for a run that starts at rest).

    The car starts at rest, ``lead_in`` s before the front axle reaches x = 0.
    On a track: :func:`settle_time` of the truth (the track's own road before
    x = 0, flat where it has none), or longer, back to where the road under
    every wheel is still flat (:func:`flat_before`, at most :data:`SETTLE_MAX`):
    the car then starts exactly as one that has driven the road from afar, not
    with a start transient decayed to :data:`SETTLE_FRACTION` only (which a
    fit of the noise-free data to 0.01 % would see). On a generated road the road first fades
    in from flat (:data:`ROAD_FADE` s of driving), the rear wheels must then
    reach the full road (``(2 R + wheelbase) / speed``), and then
    :func:`settle_time` passes, at least long enough that the fade lies
    behind the road written to ``road_truth`` (:data:`ROAD_MARGIN`).
    """
    if not run.moving:
        return 0.0
    settle = settle_time(as_vector(sc.truth), sc.geometry)
    if run.road is None:
        return max(settle, min(flat_before(sc.tracks[run.track], sc.geometry, run.speed), SETTLE_MAX))
    g = sc.geometry
    return ROAD_FADE + (2 * g.tire_radius + g.wheelbase) / run.speed + max(settle, ROAD_MARGIN / run.speed)


def road_seed(run: RunSpec, index: int, seed: int | None) -> int:
    """The seed of a run's generated road: its ``road_seed``, else one derived from ``seed``
    (``rideid simulate --seed``, None as 0) and the run's position ``index`` in the scenario."""
    if run.road.seed is not None:
        return int(run.road.seed)
    ss = np.random.SeedSequence([_ROAD_STREAM, 0 if seed is None else int(seed), int(index)])
    return int(ss.generate_state(1, np.uint32)[0])


@dataclass(frozen=True)
class GeneratedRoad:
    """The road a scenario run drives (SPEC §9): its heights and what made them.

    ``x`` (m, front-axle distance from its position at the first sample),
    ``z_left``/``z_right`` (m) on :data:`ROAD_DX` spacing from the start of
    the lead-in (flat, then fading in) to :data:`ROAD_MARGIN` beyond the last
    front-axle position; :meth:`truth` is the part ``road_truth`` holds.
    """

    run: str
    road_class: str
    seed: int
    coherence: float
    x: np.ndarray
    z_left: np.ndarray
    z_right: np.ndarray
    #: first x written to road_truth: the rear axle at t = 0, less ROAD_MARGIN
    x_truth: float

    def track(self):
        """The road as a ``profile`` track (linear interpolation, flat outside; the tire envelope as for any)."""
        return ProfileTrack.from_arrays(f"road:{self.run}", self.x, self.z_left, self.z_right)

    def truth(self):
        """``(x, z_left, z_right)`` from :attr:`x_truth` on: what ``road_truth/<run>.csv`` holds."""
        k = int(np.searchsorted(self.x, self.x_truth - 1e-9))
        return self.x[k:], self.z_left[k:], self.z_right[k:]


def generate_road(sc: Scenario, run: RunSpec, index: int, seed: int | None = None) -> GeneratedRoad:
    """The ISO 8608 road of a scenario run (:func:`rideid.model.roads.iso8608_profile`), seeded by :func:`road_seed`.

    Track width: the mean of ``track_front`` and ``track_rear`` (the rear
    wheels follow the front wheels' paths, SPEC §9). The road covers the
    lead-in (:func:`lead_in`): flat under every wheel at its start, then
    faded in by a raised cosine over ``speed`` x :data:`ROAD_FADE` m.
    Grid points at whole multiples of :data:`ROAD_DX` (x = 0 is one).
    """
    g, v = sc.geometry, run.speed
    R = g.tire_radius
    T = lead_in(sc, run)
    x_car = -v * T  # front axle at the start of the lead-in
    k0 = int(np.floor((x_car - g.wheelbase - R - ROAD_MARGIN) / ROAD_DX))
    k1 = int(np.ceil((v * run.duration + R + ROAD_MARGIN) / ROAD_DX))
    s = road_seed(run, index, seed)
    x, zl, zr = iso8608_profile(run.road.road_class, (k1 - k0) * ROAD_DX, np.random.default_rng(s), dx=ROAD_DX,
                                x0=0.0, track_width=0.5 * (g.track_front + g.track_rear),
                                coherence=run.road.coherence)
    x = ROAD_DX * (k0 + np.arange(x.size))
    if T > 0:  # flat under every wheel at the start, then a raised-cosine fade over ROAD_FADE s of driving
        xf0, xf1 = x_car + R, x_car + R + v * ROAD_FADE
        w = np.clip((x - xf0) / (xf1 - xf0), 0.0, 1.0)
        fade = 0.5 - 0.5 * np.cos(np.pi * w)
        zl, zr = zl * fade, zr * fade
    x_truth = ROAD_DX * np.floor((-g.wheelbase - R - ROAD_MARGIN) / ROAD_DX + 1e-9) if T > 0 else float(x[0])
    return GeneratedRoad(run.id, run.road.road_class, s, run.road.coherence, x, zl, zr, float(x_truth))


#: sub-step bound of the states :func:`rideid.synth.scenario.nonlinear_states` computes to find lift-off, by plain
#: RK4 sub-steps (the kernel splits its sub-steps at the kinks; at this bound the plain ones are within 0.02-0.3 %
#: of its outputs, ample to find when a tire unloads, at less cost)
LIFT_OFF_RHO = 0.25


def road_record(road: GeneratedRoad) -> dict:
    """A generated road in ``truth.toml`` ``[roads.<run>]``: how it was made and the ISO 8608
    class its road_truth (both paths) fits (:func:`rideid.model.roads.iso8608_class`)."""
    rec = {"road_class": road.road_class, "road_seed": road.seed, "coherence": road.coherence,
           "gd_n0_class": ROAD_CLASSES[road.road_class]}
    x, zl, zr = road.truth()
    try:
        c, gd = iso8608_class(x, np.column_stack([zl, zr]))
    except ArgumentError:  # too short a road to fit
        return rec
    rec.update(fitted_class=c, fitted_gd_n0=float(f"{gd:.6g}"))
    return rec


def write_road_csv(path: Path, x, z_left, z_right):
    """``x, z_left, z_right`` (m) as a CSV, the columns of a ``profile`` file (SPEC §2)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, np.column_stack([x, z_left, z_right]), delimiter=",", header="x,z_left,z_right",
               comments="", fmt="%.12g")


#: the stream of the random post signals' seeds (with ``--seed`` and the run's position), apart from the noise's
_POST_STREAM = 1304


def post_seed(run: RunSpec, index: int, seed: int | None) -> int:
    """The seed of a four-post rig run's random post signal (SPEC §13): the run's ``signal_seed``, else one
    derived from ``seed`` (``rideid simulate --seed``, None as 0) and the run's position ``index``."""
    if run.signal_seed is not None:
        return int(run.signal_seed)
    ss = np.random.SeedSequence([_POST_STREAM, 0 if seed is None else int(seed), int(index)])
    return int(ss.generate_state(1, np.uint32)[0])


def post_function(run: RunSpec, index: int, seed: int | None = None):
    """A rig run's posts as ``inputs_at(times) -> (r (k, 4), rdot (k, 4))`` (:class:`rideid.model.posts.PostSignal`,
    a random one seeded by :func:`post_seed`)."""
    return run.signal.function(np.random.default_rng(post_seed(run, index, seed)))


def scenario_run_input(sc: Scenario, run: RunSpec, index: int, seed: int | None = None):
    """The :class:`rideid.model.simulate.RunInput` of scenario run ``run`` (at position ``index``) at its SPEC §3
    sample times: its track at its speed, or a rig run's posts (SPEC §13; ``seed`` as ``rideid simulate
    --seed`` gives it, for a random signal without ``signal_seed``). A run on a generated road (SPEC §9) has
    none here."""
    if run.posts:
        return prepare_function(run_times(run), post_function(run, index, seed))
    return prepare_run(sc.tracks[run.track], sc.geometry, run.speed, run_times(run))
