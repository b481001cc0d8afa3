"""The parts of rideid's public API a study uses, imported from the modules that define them.

Not from the package root: ``rideid/__init__`` imports the studies, so
``import rideid`` here would close an import cycle.
"""

from importlib.metadata import PackageNotFoundError, version

from ..data.dataset import Dataset
from ..conditioning.load import load_dataset
from ..data.scenario import default_scenario, default_scenario_path, load_scenario
from ..synth.scenario import simulate_manifest, write_dataset
from ..data.schema import Scenario, load_truth
from ..design import plan
from ..errors import DataError, RideidError
from ..estimate.model_choice import identify

try:
    __version__ = version("rideid")
except PackageNotFoundError:  # pragma: no cover
    __version__ = "0+unknown"

__all__ = ["Dataset", "DataError", "RideidError", "Scenario", "__version__", "default_scenario",
           "default_scenario_path", "identify", "load_dataset", "load_scenario", "load_truth", "plan",
           "simulate_manifest", "write_dataset"]
