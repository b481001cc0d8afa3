"""Test planning (SPEC §7): Fisher information of candidate runs, CRLB and
identifiability of run subsets, and D-/A-/target-optimal run selection under a
budget, for white or coloured sensor noise. The public entry point is :func:`rideid.plan`."""

from importlib import resources
from pathlib import Path

from .colour import NoiseSpectrum, ar1_psd, load_noise_psd
from .fisher import NoiseModel, Precision, RunInformation, messages, precision, run_information, subset_precision
from .planner import PlanResult, parse_target, plan
from .select import Selector, brute_force

__all__ = ["NoiseModel", "NoiseSpectrum", "PlanResult", "Precision", "RunInformation", "Selector", "ar1_psd",
           "brute_force", "load_noise_psd", "messages", "parse_target", "plan", "precision", "run_information",
           "subset_precision"]


def catalogue_path():
    """Path of the built-in catalogue of 22 candidate runs (the paper's tracks at several speeds and severities)."""
    return Path(str(resources.files("rideid") / "data" / "plan_catalogue.toml"))


__all__ += ["catalogue_path"]
