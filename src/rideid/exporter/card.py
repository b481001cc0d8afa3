"""The parameter card (SPEC §10): ``car.toml`` (a scenario without runs) and ``car.csv``.

``car.toml`` has ``[vehicle]``, ``[known]``, ``[truth]`` (every identified
value: the twelve, the extensions of the model, the bump stops),
``[dampers]`` when the car has curves and ``[model]`` (the groups it was
identified with, and the damper knots), so that ``rideid simulate`` drives
the identified car once ``[[tracks]]`` and ``[[runs]]`` are added, and
``rideid identify`` of that simulation fits the same model.
``car.csv`` lists every parameter: ``parameter, value, unit, std,
std_robust, std_total, fixed, derived`` (the standard errors empty where
none was computed: a card made from a scenario; ``std_total`` is
``std_robust`` with every uncertainty the dataset declared, SPEC §12).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

from ..data.schema import BUMP_NAMES, write_toml
from ..data.schema.manifest import vehicle_table
from ..model.params import EXT_NAMES, GROUPS, NAMES
from .car import Car

CSV_COLUMNS = ("parameter", "value", "unit", "std", "std_robust", "std_total", "fixed", "derived")

#: appended to car.toml: what to add before ``rideid simulate`` takes it
RUNS_HINT = """
# Add the tracks and runs to simulate, e.g.:
# [[tracks]]
# id = "washboard"
# kind = "washboard"
# start = 5.0
# amplitude = 0.015
# wavelength = 0.8
# cycles = 30
#
# [[runs]]
# id = "W_L"
# track = "washboard"
# speed = 5.0
# fs = 200.0
# duration = 6.0
"""


def _knots(velocity):
    """``[model] damper_knots`` (positive) of signed knots used alike in both directions, else None."""
    pos = sorted(v for v in velocity if v > 0)
    neg = sorted(-v for v in velocity if v < 0)
    return pos if pos == neg else None


def card_document(car: Car, name: str = "identified car") -> dict:
    """``car.toml`` as a dict (scenario tables, no runs)."""
    ext = [g for g in car.extensions]
    truth = {n: car.values[n] for n in NAMES}
    for n in EXT_NAMES:
        in_model = any(n in GROUPS.get(g, ()) for g in ext)
        if in_model or car.values.get(n, 0.0) != 0.0:
            truth[n] = car.values[n]
    for n in BUMP_NAMES:
        v = car.bump_stops.get(n)
        if v is not None and math.isfinite(v):
            truth[n] = v
    doc = {"name": name, "vehicle": vehicle_table(car.geometry), "known": dict(car.known), "truth": truth}
    if car.dampers is not None:
        doc["dampers"] = car.dampers.to_table()
    model = {"extensions": ext}
    if car.dampers is not None and _knots(car.dampers.velocity) is not None:
        model["damper_knots"] = _knots(car.dampers.velocity)
    doc["model"] = model
    return doc


def write_card(car: Car, folder, name: str = "identified car", source: str | None = None):
    """Write ``car.toml`` and ``car.csv`` into ``folder``; returns their paths."""
    folder = Path(folder)
    toml_path, csv_path = folder / "car.toml", folder / "car.csv"
    comment = ("rideid parameter card (SPEC §10)" + (f" of {source}" if source else "") + "\n"
               "a scenario without runs: add [[tracks]] and [[runs]] (fs, duration), then `rideid simulate`\n"
               "the values are only as absolute as the known scale anchor in [known]")
    write_toml(toml_path, card_document(car, name), comment)
    with open(toml_path, "a") as f:
        f.write(RUNS_HINT)
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(CSV_COLUMNS)
        for r in car.rows:
            w.writerow([r["parameter"], repr(float(r["value"])), r["unit"],
                        "" if math.isnan(r["std"]) else repr(r["std"]),
                        "" if math.isnan(r["std_robust"]) else repr(r["std_robust"]),
                        "" if math.isnan(r.get("std_total", math.nan)) else repr(r["std_total"]),
                        str(bool(r["fixed"])).lower(), str(bool(r["derived"])).lower()])
    return toml_path, csv_path


__all__ = ["write_card", "card_document", "CSV_COLUMNS"]
