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
    rideid.export(res, "car")                 # car.toml, car.csv, car.fmu (SPEC §10)
    res.to_frame(); rideid.plot_fit(res, "W_L")  # a notebook's table and figures
"""

from importlib import import_module

#: public name -> (defining module, its name there); imported on first use (PEP 562), so that
#: ``import rideid`` (and the command line's ``--help``) loads neither NumPy nor the compiled kernels
_PUBLIC = {
    "CostFunction": ("rideid.estimate.cost", None), "ParameterSpace": ("rideid.estimate.cost", None),
    "Dataset": ("rideid.data.dataset", None), "load_dataset": ("rideid.conditioning.load", None),
    "PlanResult": ("rideid.design", None), "plan": ("rideid.design", None),
    "ArgumentError": ("rideid.errors", None), "DataError": ("rideid.errors", None),
    "DataWarning": ("rideid.errors", None), "ModelValidityWarning": ("rideid.errors", None),
    "RideidError": ("rideid.errors", None), "ScaleError": ("rideid.errors", None),
    "DatasetManifest": ("rideid.data.schema", None), "Manifest": ("rideid.data.schema", None),
    "Scenario": ("rideid.data.schema", None), "load_truth": ("rideid.data.schema", None),
    "identify": ("rideid.estimate.model_choice", None),
    "History": ("rideid.estimate.result", None), "IdentificationResult": ("rideid.estimate.result", None),
    "load_result": ("rideid.estimate.result", "load"),
    "score": ("rideid.estimate.score", None),
    "SensitivityMaps": ("rideid.estimate.sensitivity", None), "sensitivity_maps": ("rideid.estimate.sensitivity", None),
    "JadeSolver": ("rideid.estimate.jade", None), "jade": ("rideid.estimate.jade", None),
    "CHANNELS": ("rideid.model.equations", None), "modal_summary": ("rideid.model.equations", None),
    "DEFAULT_CAR": ("rideid.model.params", None), "DEFAULT_GEOMETRY": ("rideid.model.params", None),
    "NAMES": ("rideid.model.params", None), "UNITS": ("rideid.model.params", None),
    "Geometry": ("rideid.model.params", None), "ALL_NAMES": ("rideid.model.params", None),
    "EXT_NAMES": ("rideid.model.params", None), "GROUPS": ("rideid.model.params", None),
    "default_scenario": ("rideid.data.scenario", None), "default_scenario_path": ("rideid.data.scenario", None),
    "load_scenario": ("rideid.data.scenario", None),
    "simulate_manifest": ("rideid.synth.scenario", None), "write_dataset": ("rideid.synth.scenario", None),
    "iso8608_class": ("rideid.model.roads", None), "iso8608_profile": ("rideid.model.roads", None),
    "Track": ("rideid.model.tracks", None),
    "StudyResult": ("rideid.studies", None), "load_study": ("rideid.studies", None), "study": ("rideid.studies", None),
    "export": ("rideid.exporter", None), "ExportResult": ("rideid.exporter", None),
    "plot_fit": ("rideid.report.figures", "fit_figure"),
    "plot_parameters": ("rideid.report.figures", "parameters_figure"),
    "plot_dampers": ("rideid.report.figures", "dampers_figure"),
}

#: what the command line (:mod:`rideid.cli`) uses beyond SPEC §5, reached the same lazy way so that the command
#: line imports nothing but ``rideid``; not in ``__all__`` (not part of the stable API)
_COMMAND_LINE = {
    "BUILTIN": ("rideid.data.scenario", None), "atomic_output": ("rideid.data.schema", None),
    "read_toml": ("rideid.data.schema", None), "read_result_json": ("rideid.data.schema", None),
    "refuse_unknown_roads": ("rideid.data.dataset", None),
    "format_modal_summary": ("rideid.model.equations", None), "compile_kernels": ("rideid.model.kernel", None),
    "scenario_properties": ("rideid.verify.hifi", None),
    "DEFAULT_GENERATIONS": ("rideid.estimate.identify", None), "DEFAULT_POPULATION": ("rideid.estimate.identify", None),
    "parse_model_arg": ("rideid.estimate.identify", None), "verdict_paragraph": ("rideid.estimate.adequacy", None),
    "format_dampers": ("rideid.estimate.dampers", None), "format_bump_stops": ("rideid.estimate.bumps", None),
    "write_sensitivity_csvs": ("rideid.estimate.sensitivity", "write_csvs"),
    "sensitivity_tables_markdown": ("rideid.estimate.sensitivity", "tables_markdown"),
    "sensitivity_heatmaps": ("rideid.estimate.sensitivity", "heatmaps"),
    "parse_target": ("rideid.design", None), "write_report": ("rideid.report.html", None),
}

#: the subpackages, reachable as attributes (``rideid.model.params``) after a plain ``import rideid`` as before
_SUBPACKAGES = ("conditioning", "csvio", "data", "design", "errors", "estimate", "exporter", "model", "report",
                "studies", "synth",
                "verify")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version  # 0.1 s to import: only when asked

    try:
        return version("rideid")
    except PackageNotFoundError:  # pragma: no cover
        return "0+unknown"


def __getattr__(name: str):
    """A public name (:data:`__all__`), imported from its defining module on first use and then cached."""
    if name in _SUBPACKAGES:
        return import_module(f"rideid.{name}")
    if name == "__version__":  # the package metadata, read on first use (it costs more than the rest of the import)
        globals()[name] = value = _version()
        return value
    try:
        module, attr = _PUBLIC[name] if name in _PUBLIC else _COMMAND_LINE[name]
    except KeyError:
        raise AttributeError(f"module 'rideid' has no attribute {name!r}") from None
    value = getattr(import_module(module), attr or name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "CHANNELS", "NAMES", "UNITS", "DEFAULT_CAR", "DEFAULT_GEOMETRY",
    "ArgumentError", "DataError", "DataWarning", "ModelValidityWarning", "RideidError", "ScaleError",
    "CostFunction", "ParameterSpace", "Dataset", "Geometry", "IdentificationResult", "JadeSolver", "Manifest",
    "Track", "default_scenario", "default_scenario_path", "identify", "jade", "load_dataset", "load_scenario",
    "load_truth", "modal_summary", "plan", "PlanResult", "simulate_manifest", "write_dataset", "__version__",
    "History", "SensitivityMaps", "load_result", "score", "sensitivity_maps",
    "ALL_NAMES", "EXT_NAMES", "GROUPS", "Scenario", "DatasetManifest",
    "StudyResult", "load_study", "study", "iso8608_class", "iso8608_profile", "export", "ExportResult",
    "plot_fit", "plot_parameters", "plot_dampers",
]
