"""Taking the identified car elsewhere (SPEC §10): the parameter card and the FMI 2.0 FMU.

    rideid.export("fit", "out")                     # car.toml, car.csv, car.fmu
    rideid.export(result, "out", format="card")     # an IdentificationResult works too

Everything is written into a temporary folder and moved in at the end
(:func:`rideid.data.schema.common.atomic_output`): bad input leaves nothing
behind.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..data.schema.common import atomic_output
from ..errors import ArgumentError, DataError
from ..estimate.result import IdentificationResult, load
from ..model.params import ALL_NAMES, check_parameters
from .car import Car, car_from_result, car_from_scenario
from .card import write_card
from .drive import drive_fmu
from .frf import write_frf
from .fmu import NoBinary, find_compiler, write_fmu

FORMATS = ("card", "fmu", "all")
#: the files each format writes (``frf.csv`` with the card when the source is an identification, SPEC §13)
FILES = {"card": ("car.toml", "car.csv"), "fmu": ("car.fmu",), "all": ("car.toml", "car.csv", "car.fmu")}
FRF_FILE = "frf.csv"


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export` wrote: the folder, the files, and whether the FMU carries a binary.

    ``compiled``: None when no FMU was written; ``no_binary``: why the FMU carries its sources only.
    """

    out: Path
    files: tuple
    compiled: bool | None  # None: no FMU written
    no_binary: str | None = None

    @property
    def note(self) -> str | None:
        """One line when the FMU holds sources only (no C compiler, or it failed), else None."""
        if self.compiled is False:
            return (f"{self.no_binary}: car.fmu carries its C sources only; "
                    "build it with your FMI tool or rerun export where a compiler works")
        return None


def _load(source):
    """A result (object), a fit folder or its result.json -> (Car, label, the result or None)."""
    if isinstance(source, Car):
        return source, "car", None
    if isinstance(source, IdentificationResult):
        return car_from_result(source), "result", source
    p = Path(source)
    rj = p if p.suffix == ".json" else p / "result.json"
    if not rj.is_file():
        raise DataError(f"{rj}: not found (export needs an identification folder with result.json)")
    res = load(rj)
    return car_from_result(res, str(rj)), str(p), res


def export(result_or_fit_dir, out, format: str = "all", *, compiler="auto") -> ExportResult:
    """Write the identified car as a parameter card and/or an FMI 2.0 FMU (SPEC §10).

    Parameters
    ----------
    result_or_fit_dir : IdentificationResult, Car, str or Path
        A result, or an identification folder (or its ``result.json``).
    out : str or Path
        Output folder (created; files of the same names there are replaced, others kept).
    format : {"card", "fmu", "all"}
        ``card``: ``car.toml`` + ``car.csv`` (+ ``frf.csv``, the frequency responses with their std, SPEC §13,
        from an identification); ``fmu``: ``car.fmu``; ``all``: both.
    compiler : "auto", None or list of str
        C compiler command for the FMU's binary (``"auto"``: ``$CC``, else ``cc``; None: sources only).
        Without a compiler, or when it fails, the FMU carries its sources only and
        :attr:`ExportResult.note` says why.

    Returns
    -------
    ExportResult
        ``.files`` the paths written, ``.compiled`` whether the FMU has a binary, ``.note`` the one line
        to show when it has none.

    Raises
    ------
    ArgumentError
        An unknown format; an FMU of a car with a powertrain on mounts (SPEC §11) and damper curves or bump
        stops (SPEC §8): the FMU's powertrain car is linear in this version, as ``rideid simulate``'s.
    DataError
        No result.json, a result without geometry, an output folder that cannot be written; an FMU of a car
        whose powertrain leaves the rest of the body no positive mass or pitch inertia.
    """
    if format not in FORMATS:
        raise ArgumentError(f"--format must be one of {', '.join(FORMATS)}, got {format!r}")
    car, label, result = _load(result_or_fit_dir)
    if format in ("fmu", "all") and car.powertrain:
        if car.nonlinear:  # as rideid simulate: the nonlinear car has no powertrain in this version
            raise ArgumentError(f"{label}: the FMU of a car with a powertrain on mounts (SPEC §11) has linear dampers "
                                "and no bump stops in this version, and this car has "
                                f"{'damper curves' if car.dampers is not None else 'bump stops'}; "
                                "export --format card")
        check_parameters([car.values[n] for n in ALL_NAMES], car.geometry, where=label)
    out = Path(out)
    compiled = no_binary = None
    with atomic_output(out) as tmp:  # into an existing folder: only these files are replaced
        files = [out / n for n in FILES[format]]
        if format in ("card", "all"):
            write_card(car, tmp, source=label)
            if result is not None:  # the frequency responses with their std (SPEC §13): an identification's
                write_frf(result, tmp)
                files.insert(2, out / FRF_FILE)
        if format in ("fmu", "all"):
            no_binary = write_fmu(car, tmp / "car.fmu", compiler=compiler, workdir=tmp)
            compiled = no_binary is None
    return ExportResult(out, tuple(files), compiled, no_binary)


__all__ = ["export", "ExportResult", "Car", "car_from_result", "car_from_scenario", "write_card", "write_fmu",
           "find_compiler", "FORMATS", "NoBinary", "drive_fmu", "write_frf"]
