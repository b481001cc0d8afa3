"""Test cars for the uncertainty, adequacy and model-choice tests: an SUV of our own on the built-in tracks."""

from __future__ import annotations

import tomllib
import warnings

import numpy as np

import rideid
from rideid.synth.scenario import simulate_manifest, write_dataset

#: a 2.05 t SUV: longer, wider, taller tires and stiffer rates than the built-in car
SUV_VEHICLE = {"wheelbase": 2.85, "track_front": 1.62, "track_rear": 1.62, "tire_radius": 0.36}
SUV_TRUTH = {"m_s": 1850.0, "I_xx": 700.0, "I_yy": 3200.0, "a": 1.30, "m_uf": 48.0, "m_ur": 52.0,
             "k_sf": 38000.0, "k_sr": 42000.0, "c_sf": 3000.0, "c_sr": 3200.0, "k_tf": 250000.0, "k_tr": 260000.0}
SUV_TOTAL_MASS = 1850.0 + 2 * 48.0 + 2 * 52.0
#: anti-roll bars (rate at the wheel) and tire damping of the "real" SUV, SPEC §6 names
SUV_BARS = {"k_arf": 15600.0, "k_arr": 6000.0}
SUV_TIRE_DAMPING = {"c_tf": 180.0, "c_tr": 200.0}


def suv_scenario(folder, extra: dict | None = None, name: str = "suv", dampers: dict | None = None,
                 runs=None):
    """The built-in tracks and runs with the SUV (plus ``extra`` truth values) as truth.

    ``dampers``: a ``[dampers]`` table (``knee_cars.dampers_table``) for real dampers in place of ``c_sf``,
    ``c_sr``; ``runs``: ``{run id: duration}`` to keep only those runs, each that long (s).
    Written to ``folder/<name>.toml`` and loaded.
    """
    import tomli_w

    doc = tomllib.loads(rideid.default_scenario_path().read_text())
    doc["name"] = name
    doc["vehicle"] = dict(SUV_VEHICLE)
    doc["known"] = {"total_mass": SUV_TOTAL_MASS}
    doc["truth"] = {**SUV_TRUTH, **(extra or {})}
    if dampers is not None:
        del doc["truth"]["c_sf"], doc["truth"]["c_sr"]
        doc["dampers"] = dampers
    if runs is not None:
        doc["runs"] = [{**r, "duration": runs[r["id"]]} for r in doc["runs"] if r["id"] in runs]
        doc["tracks"] = [t for t in doc["tracks"] if any(r["track"] == t["id"] for r in doc["runs"])]
    path = folder / f"{name}.toml"
    path.write_text(tomli_w.dumps(doc))
    return rideid.load_scenario(path)


def simulated(sc, out, *, noise=0.02, rho=0.0, seed=1):
    """Simulate ``sc`` with white (``rho = 0``) or AR(1) noise, write a dataset to ``out``, load it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", rideid.ModelValidityWarning)  # no wheel may lift
        data, _ = simulate_manifest(sc, noise=noise, seed=seed, noise_ar1=rho)
    write_dataset(sc, data, out)
    return rideid.load_dataset(out)


def simulate_car(sc, extra: dict | None = None):
    """Noise-free runs of scenario ``sc`` for its twelve ``[truth]`` values plus the extension
    parameters in ``extra`` (SPEC §6 names; absent = 0), through the reference simulation.

    Returns ``{run id: (t, Y)}`` as :func:`rideid.simulate_manifest` does.
    """
    from rideid.data.scenario import run_times
    from rideid.model.params import ALL_NAMES
    from rideid.model.simulate import prepare_run, simulate_reference

    vals = {**{n: 0.0 for n in ALL_NAMES}, **sc.truth, **(extra or {})}
    P = np.array([[vals[n] for n in ALL_NAMES]])
    out = {}
    for run in sc.runs:
        t = run_times(run)
        ri = prepare_run(sc.tracks[run.track], sc.geometry, run.speed, t)
        out[run.id] = (t, simulate_reference(P, sc.geometry, ri)[0])
    return out


def add_noise(data, noise, rho, seed):
    """Noise as ``rideid simulate --noise NOISE --noise-ar1 RHO`` adds it, on already simulated runs."""
    from rideid.data.noise import sensor_noise

    rng = np.random.default_rng(seed)
    out = {}
    for rid, (t, y) in data.items():
        rms = np.sqrt(np.mean(y * y, axis=0))
        out[rid] = (t, y + sensor_noise(rng, y.shape, rho) * (noise * rms)[None, :])
    return out


def truth_vector(names, truth):
    return np.array([truth[n] for n in names])


def bump_tracks(amplitude, *, wavelength, height, bump_length, spacing, twist_speed):
    """The washboard and herringbone (both of ``amplitude``; the herringbone's ``wavelength``) and the chassis
    twist (two bumps of ``height`` and ``bump_length``, ``spacing`` apart, driven at ``twist_speed``) as
    ``{kind: (track table, speed)}``: the tracks the simulation tests drive."""
    return {
        "washboard": (dict(id="w", kind="washboard", start=2.0, amplitude=amplitude, wavelength=0.8, cycles=6), 10.0),
        "herringbone": (dict(id="h", kind="herringbone", start=2.0, amplitude=amplitude, wavelength=wavelength,
                             cycles=8, angle=30.0), 8.0),
        "chassis_twist": (dict(id="t", kind="chassis_twist", start=2.0, height=height, bump_length=bump_length,
                               spacing=spacing, bumps=2), twist_speed),
    }


def write_profile_road(folder, left, right):
    """``folder/road.csv``: a measured-road profile from x = 2 to 6 m, windowed sines of amplitude ``left``
    (wavelength 0.7 m) and ``right`` (1.1 m) under the two wheel tracks, for a ``kind = "profile"`` track."""
    x = np.linspace(2.0, 6.0, 401)
    zl = left * np.sin(2 * np.pi * (x - 2) / 0.7) * np.hanning(x.size)
    zr = right * np.sin(2 * np.pi * (x - 2) / 1.1) * np.hanning(x.size) ** 0.5
    np.savetxt(folder / "road.csv", np.column_stack([x, zl, zr]), delimiter=",", header="x,z_left,z_right",
               comments="")
