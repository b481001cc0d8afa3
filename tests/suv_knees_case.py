"""The SUV with anti-roll bars, tire damping and dampers that bend at 0.12 m/s, as a new user's data (issue 50).

One independent simulation, written twice:

* the car: the SUV of :mod:`cars` (its twelve less ``c_sf``, ``c_sr``; its bars ``SUV_BARS``, 15.6 / 6 kN/m, and
  tire damping ``SUV_TIRE_DAMPING``, 180 / 200 N s/m per tire) with smooth digressive dampers bending at
  ``KNEE`` = 0.12 m/s, rebound twice compression (:func:`knee_cars.digressive`, tabulated by
  :func:`knee_cars.dampers_table`), on the built-in tracks (the runs of ``RUNS``, shortened);
* the simulator: :func:`nl_powertrain_car.simulate`, Newton-Euler written in the tests, not rideid's equations
  (the powertrain there made weightless: a car without an engine on mounts), with 1 % white noise;
* SPEC CSV (:func:`rideid.synth.scenario.write_dataset`: ``truth.toml`` with the curves) and logger files
  (:func:`logger_case.write_logger`: g with gravity and biases, deg/s, the logger's own names, a standing
  lead-in of ``logger_case.LEAD`` s and no stated start, so rideid estimates it).

Neither dataset names a model: ``rideid identify`` runs with its defaults (``auto``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

import nl_powertrain_car
from cars import SUV_BARS, SUV_TIRE_DAMPING, SUV_TRUTH, suv_scenario
from knee_cars import curve_error, dampers_table
from logger_case import LEAD, write_logger
from powertrain_car import ENGINE

from rideid.synth.scenario import write_dataset

KNEE = 0.12
#: the SUV's dampers: compression slopes around c_s / 1.5, rebound 2:1, the same knee front and rear
DAMPERS = {"front": dict(c1=2000.0, c2=600.0, knee=KNEE, rebound=2.0),
           "rear": dict(c1=2150.0, c2=650.0, knee=KNEE, rebound=2.0)}
#: the runs (built-in ids) and their durations (s), each ending ~1.5 s after the rear wheels leave the feature: the
#: built-in ten less T_HL and W_H, where the SUV's rear tires leave the road (rideid's simulator warns: 1170 and
#: 663 N short of contact)
RUNS = {"T_LL": 7.5, "T_LH": 5.0, "T_HH": 5.0, "H_LL": 4.5, "H_LH": 3.0, "H_HL": 4.5, "H_HH": 3.0, "W_L": 4.5}
#: the small case of the default tests: one run of each track
SMALL = {"T_HH": 5.0, "H_HH": 3.0, "W_L": 4.5}
#: the extensions' true values (SPEC §6 names)
EXTENSIONS = {**SUV_BARS, **SUV_TIRE_DAMPING}
#: the parameters rideid estimates and their truths: the twelve less the dampers' slopes, and the extensions
TRUTH = {**{n: v for n, v in SUV_TRUTH.items() if n not in ("c_sf", "c_sr")}, **EXTENSIONS}


def scenario(folder, runs=None):
    """The case's scenario (``runs``: ``{run id: duration}``, default :data:`RUNS`), written and loaded."""
    return suv_scenario(folder, EXTENSIONS, name="suv-knees", dampers=dampers_table(**DAMPERS),
                        runs=RUNS if runs is None else runs)


def simulate(sc, *, noise=0.01, seed=1, upsample=40) -> dict:
    """``{run id: (t, Y)}``: the independent simulator's runs of ``sc`` with ``noise`` times each channel's RMS."""
    weightless = {**ENGINE, "m_p": 1e-6, "I_p": 1e-6}
    car = dataclasses.replace(sc, truth={**sc.truth, **weightless})
    return nl_powertrain_car.simulate(car, upsample=upsample, noise=noise, seed=seed)


def write(folder, *, runs=None, noise=0.01, seed=1):
    """Write the case under ``folder``: ``spec/`` (SPEC CSV) and ``logger/`` (logger files, starts unstated).

    Returns ``(spec folder, logger folder)``.
    """
    folder.mkdir(parents=True, exist_ok=True)
    sc = scenario(folder, runs)
    data = simulate(sc, noise=noise, seed=seed)
    write_dataset(sc, data, folder / "spec")
    write_logger(sc, folder / "logger", seed=seed, data=data)
    return folder / "spec", folder / "logger"


def errors(res: dict, logger: bool = False) -> dict:
    """A result.json's errors against the truth: ``{name: relative error}`` for :data:`TRUTH` (NaN when the
    model lacks the parameter), ``"curves"``: the largest at the excited knots (NaN without curves), and
    ``"start"``: with ``logger``, the largest start error of the logger files' runs in seconds (else NaN)."""
    out = {}
    for n, v in TRUTH.items():
        e = res["parameters"].get(n)
        out[n] = np.nan if e is None else e["value"] / v - 1.0
    out["curves"] = curve_error(DAMPERS, res["dampers"]) if res.get("dampers") else np.nan
    starts = [abs(st["start"]["value"] - LEAD) for st in res.get("preprocessing", {}).values()
              if isinstance(st, dict) and isinstance(st.get("start"), dict)]
    out["start"] = max(starts) if starts and logger else np.nan
    return out
