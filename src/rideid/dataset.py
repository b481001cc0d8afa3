"""Datasets: a validated manifest plus its measured runs."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import DataError, ScaleError
from .files import Manifest, RunData, load_manifest, read_run_csv
from .params import EXTRA_KNOWN, NAMES, Geometry


@dataclass
class Dataset:
    """A dataset (SPEC §3): manifest and the data of every run.

    Attributes
    ----------
    manifest : Manifest
    data : dict run id -> RunData
    """

    manifest: Manifest
    data: dict[str, RunData]

    @property
    def geometry(self) -> Geometry:
        return self.manifest.geometry

    @property
    def runs(self):
        return self.manifest.runs

    @property
    def known(self):
        return self.manifest.known

    @property
    def name(self):
        return self.manifest.name

    @property
    def path(self) -> Path:
        return self.manifest.base_dir


def load_dataset(path) -> Dataset:
    """Load and validate a dataset folder (or its ``dataset.toml``).

    Parameters
    ----------
    path : str or Path
        The dataset folder, or its ``dataset.toml``.

    Returns
    -------
    Dataset

    Raises
    ------
    DataError
        Naming the file, key or column at fault.
    """
    man = load_manifest(path)
    data = {}
    for run in man.runs:
        f = Path(run.file)
        if not f.is_absolute():
            f = man.base_dir / f
        rd = read_run_csv(f)
        data[run.id] = rd
    return Dataset(man, data)


def scale_anchor(known: dict[str, float], where: str = "[known]") -> str:
    """The known value that fixes the absolute scale, or raise :class:`ScaleError`."""
    for k in ("total_mass",) + tuple(n for n in NAMES if n != "a"):
        if k in known:
            return k
    raise ScaleError(
        f"{where}: no scale anchor. Accelerations driven by a known road do not change when every mass, "
        "inertia, stiffness and damping is multiplied by the same factor, so the data fix only ratios. "
        "Give one absolute value in [known], normally total_mass (kg) from a weighbridge "
        f"(any of {', '.join(list(EXTRA_KNOWN) + [n for n in NAMES if n != 'a'])} works).")


def check_known_consistent(known: dict[str, float]):
    if "total_mass" in known:
        fixed_mass = sum(known.get(n, 0.0) * (1 if n == "m_s" else 2) for n in ("m_s", "m_uf", "m_ur"))
        if fixed_mass >= known["total_mass"]:
            raise DataError(f"[known]: total_mass = {known['total_mass']} is not more than the fixed masses "
                            f"(m_s + 2 m_uf + 2 m_ur = {fixed_mass})")
        if all(n in known for n in ("m_s", "m_uf", "m_ur")):
            tm = known["m_s"] + 2 * known["m_uf"] + 2 * known["m_ur"]
            if abs(tm - known["total_mass"]) > 1e-6 * tm:
                raise DataError(f"[known]: total_mass = {known['total_mass']} disagrees with m_s + 2 m_uf + "
                                f"2 m_ur = {tm}")


__all__ = ["Dataset", "load_dataset", "scale_anchor"]
