"""Test planning (SPEC §7): Fisher information of candidate runs, CRLB and
identifiability of run subsets, and D-/A-/target-optimal run selection under a
budget. The public entry point is :func:`rideid.plan`."""

from .fisher import NoiseModel, Precision, RunInformation, messages, precision, run_information, subset_precision
from .planner import PlanResult, parse_target, plan
from .select import Selector, brute_force

__all__ = ["NoiseModel", "PlanResult", "Precision", "RunInformation", "Selector", "brute_force", "messages",
           "parse_target", "plan", "precision", "run_information", "subset_precision"]


def catalogue_path():
    """Path of the built-in catalogue of 22 candidate runs (the paper's tracks at several speeds and severities)."""
    from importlib import resources
    from pathlib import Path
    return Path(str(resources.files("rideid") / "data" / "plan_catalogue.toml"))


__all__ += ["catalogue_path"]
