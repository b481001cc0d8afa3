"""A car with an engine on mounts and real dampers (issue 50's done-when), for the tests and a benchmark.

The built-in car on the built-in tracks with an engine on mounts whose modes sit at 11.5 Hz (bounce) and 12.5 Hz
(pitch), neither at the model choice's nominal engine (11 / 13 Hz, :data:`rideid.model.params.NOMINAL_EXTENSIONS`),
and smooth digressive dampers (:func:`knee_cars.digressive`: knees at 0.10 and 0.11 m/s, rebound twice the
compression force; not piecewise linear on any knots rideid fits). Simulated by the independent simulator of
:mod:`nl_powertrain_car` (Newton-Euler in absolute coordinates, RK4 at 40 steps per sample, tires that lift off),
1 % white noise, written as SPEC CSV with ``truth.toml``. The dataset names no model: ``rideid identify`` with
defaults chooses it (``auto``).

``RUNS`` (the full size): four of the built-in runs, the high twist at 5 m/s (the body's modes, the dampers past
their knees), the high herringbone at 5 m/s (10 Hz and its harmonics: the engine's modes and roll) and the
washboard at 6 and 10 m/s (7.5 and 12.5 Hz: wheel hop and the engine). ``SMALL``: the size the default test runs
(:func:`small`).
"""

from __future__ import annotations

import dataclasses

import tomli_w

import rideid
from knee_cars import curve_error as knee_curve_error
from knee_cars import scenario_doc

#: the engine (SPEC §11 names): 170 kg, 1.15 m ahead of the CG, modes on its mounts at 11.5 and 12.5 Hz
ENGINE = {"m_p": 170.0, "x_p": 1.15, "I_p": 11.0, "f_pb": 11.5, "zeta_pb": 0.12, "f_pp": 12.5, "zeta_pp": 0.08}
#: the car: the engine, and per axle a digressive damper (knee_cars.digressive's keywords)
CAR = {"front": dict(c1=2400.0, c2=700.0, knee=0.10, rebound=2.0),
       "rear": dict(c1=2200.0, c2=650.0, knee=0.11, rebound=2.0), "truth": ENGINE}
#: the full size's runs (built-in run ids)
RUNS = ("T_HH", "H_HL", "W_L", "W_H")
NOISE = 0.01
SEED = 3


def scenario(folder, runs=RUNS, fs: float | None = None, cut: float | None = None):
    """The case's scenario (``folder/scenario.toml``, loaded): the built-in runs ``runs``, at ``fs`` (Hz, default
    the built-in 200) and each at most ``cut`` s long (default as built in)."""
    doc = scenario_doc(CAR, name="engine-curves")
    doc["runs"] = [dict(r, **({"fs": fs} if fs else {}), **({"duration": min(r["duration"], cut)} if cut else {}))
                   for r in doc["runs"] if r["id"] in runs]
    (folder / "scenario.toml").write_text(tomli_w.dumps(doc))
    return rideid.load_scenario(folder / "scenario.toml")


def write(folder, runs=RUNS, fs: float | None = None, cut: float | None = None, noise: float = NOISE,
          seed: int = SEED):
    """The case's dataset in ``folder/ds`` (:func:`scenario`'s arguments; ``noise`` times each channel's RMS of
    white noise). Returns ``(scenario, dataset folder)``."""
    import nl_powertrain_car

    sc = scenario(folder, runs, fs, cut)
    nl_powertrain_car.write_dataset(dataclasses.replace(sc), folder / "ds", noise=noise, seed=seed)
    return sc, folder / "ds"


def truth(sc) -> dict:
    """The twelve (``c_sf``, ``c_sr`` the curves' mean slopes over +-0.1 m/s, as result.json derives them) and
    the engine's seven."""
    return {n: sc.truth[n] for n in (*rideid.NAMES, *ENGINE)}


def curve_error(dampers: dict) -> float:
    """Largest relative error of a fitted ``dampers`` block (result.json's) against the true curves, over the
    excited knots."""
    return knee_curve_error(CAR, dampers)
