"""rideid: estimate a car's ride parameters from accelerometer and gyro
signals recorded on proving-ground tracks.

Public API (SPEC §5)::

    import rideid
    ds = rideid.load_dataset(path)            # validated Dataset
    res = rideid.identify(ds, rng=1)          # .parameters: name -> value; seed= also works
    res.save(folder); rideid.load_result(folder)
    cost = rideid.CostFunction(ds)            # cost(P): (n, d) -> (n,)
    cost.names                                # free parameter names
    rideid.jade(fun, bounds, population=..., generations=..., seed=...)
    p = rideid.plan(scenario, noise=0.01, budget_runs=4)   # SPEC §7; p.save(dir)
    rideid.study("study.toml", "out")         # many identifications on Dask (SPEC §7)
    x, zl, zr = rideid.iso8608_profile("B", 500.0, rng)   # an ISO 8608 road (SPEC §9)
    rideid.iso8608_class(x, zl)               # -> ("B", Gd(n0) in m^3)
"""

from importlib.metadata import PackageNotFoundError, version

from .estimate.cost import CostFunction, ParameterSpace
from .data.dataset import Dataset
from .conditioning.load import load_dataset
from .design import PlanResult, plan
from .errors import ArgumentError, DataError, DataWarning, ModelValidityWarning, RideidError, ScaleError
from .data.schema import DatasetManifest, Manifest, Scenario, load_truth
from .estimate.model_choice import identify
from .estimate.result import History, IdentificationResult
from .estimate.result import load as load_result
from .estimate.score import score
from .estimate.sensitivity import SensitivityMaps, sensitivity_maps
from .estimate.jade import JadeSolver, jade
from .model.equations import CHANNELS, modal_summary
from .model.params import DEFAULT_CAR, DEFAULT_GEOMETRY, NAMES, UNITS, Geometry
from .model.params import ALL_NAMES, EXT_NAMES, GROUPS
from .data.scenario import default_scenario, default_scenario_path, load_scenario
from .synth.scenario import simulate_manifest, write_dataset
from .model.roads import iso8608_class, iso8608_profile
from .model.tracks import Track
from .studies import StudyResult, load_study, study

try:
    __version__ = version("rideid")
except PackageNotFoundError:  # pragma: no cover
    __version__ = "0+unknown"

__all__ = [
    "CHANNELS", "NAMES", "UNITS", "DEFAULT_CAR", "DEFAULT_GEOMETRY",
    "ArgumentError", "DataError", "DataWarning", "ModelValidityWarning", "RideidError", "ScaleError",
    "CostFunction", "ParameterSpace", "Dataset", "Geometry", "IdentificationResult", "JadeSolver", "Manifest",
    "Track", "default_scenario", "default_scenario_path", "identify", "jade", "load_dataset", "load_scenario",
    "load_truth", "modal_summary", "plan", "PlanResult", "simulate_manifest", "write_dataset", "__version__",
    "History", "SensitivityMaps", "load_result", "score", "sensitivity_maps",
    "ALL_NAMES", "EXT_NAMES", "GROUPS", "Scenario", "DatasetManifest",
    "StudyResult", "load_study", "study", "iso8608_class", "iso8608_profile",
]
