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

def _by_name(modules: dict, aliases: dict) -> dict:
    """Name -> (defining module, its name there; None: the same) of the names in ``modules`` (module -> names)
    and of the ``aliases`` (module -> {name: its name there})."""
    return {**{name: (module, None) for module, names in modules.items() for name in names},
            **{name: (module, there) for module, names in aliases.items() for name, there in names.items()}}


#: public name -> (defining module, its name there); imported on first use (PEP 562), so that
#: ``import rideid`` (and the command line's ``--help``) loads neither NumPy nor the compiled kernels
_PUBLIC = _by_name({
    "rideid.estimate.problem.cost": ("CostFunction", "ParameterSpace"), "rideid.data.dataset": ("Dataset",),
    "rideid.conditioning.load": ("load_dataset",), "rideid.design": ("PlanResult", "plan"),
    "rideid.errors": ("ArgumentError", "DataError", "DataWarning", "ModelValidityWarning", "RideidError",
                      "ScaleError"),
    "rideid.data.schema": ("DatasetManifest", "Manifest", "Scenario", "load_truth"),
    "rideid.estimate.choice.model_choice": ("identify",), "rideid.estimate.result": ("History", "IdentificationResult"),
    "rideid.estimate.assess.score": ("score",),
    "rideid.estimate.problem.sensitivity": ("SensitivityMaps", "sensitivity_maps"),
    "rideid.estimate.fit.jade": ("JadeSolver", "jade"), "rideid.model.equations": ("CHANNELS", "modal_summary"),
    "rideid.model.params": ("DEFAULT_CAR", "DEFAULT_GEOMETRY", "NAMES", "UNITS", "Geometry", "ALL_NAMES",
                            "EXT_NAMES", "GROUPS"),
    "rideid.data.scenario": ("default_scenario", "default_scenario_path", "load_scenario"),
    "rideid.synth.scenario": ("simulate_manifest", "write_dataset"),
    "rideid.model.roads": ("iso8608_class", "iso8608_profile"), "rideid.model.tracks": ("Track",),
    "rideid.studies": ("StudyResult", "load_study", "study"), "rideid.exporter": ("export", "ExportResult"),
}, {
    "rideid.estimate.result": {"load_result": "load"},
    "rideid.report.figures": {"plot_fit": "fit_figure", "plot_parameters": "parameters_figure",
                              "plot_dampers": "dampers_figure", "plot_budget": "budget_figure",
                              "plot_frequency_response": "frequency_figure"},
})

#: what the command line (:mod:`rideid.cli`) uses beyond SPEC §5, reached the same lazy way so that the command
#: line imports nothing but ``rideid``; not in ``__all__`` (not part of the stable API)
_COMMAND_LINE = _by_name({
    "rideid.data.scenario": ("BUILTIN",),
    "rideid.data.schema": ("atomic_output", "read_toml", "read_result_json", "load_truth_dampers"),
    "rideid.data.dataset": ("refuse_unknown_roads",), "rideid.model.equations": ("format_modal_summary",),
    "rideid.model.backend": ("compile_kernels",), "rideid.verify.hifi": ("scenario_properties",),
    "rideid.estimate.fit.identify": ("DEFAULT_GENERATIONS", "DEFAULT_POPULATION"),
    "rideid.estimate.problem.build": ("parse_model_arg",),
    "rideid.estimate.assess.adequacy": ("verdict_paragraph",), "rideid.estimate.problem.dampers": ("format_dampers",),
    "rideid.estimate.problem.bumps": ("format_bump_stops",), "rideid.design": ("parse_target",),
    "rideid.report.html": ("write_report",),
    "rideid.data.quality": ("data_quality", "quality_table", "summarised_warning", "resampling_lines",
                            "partial_channel_lines"),
    "rideid.profiling": ("Profile",),
    "rideid.estimate.records": ("motion_line", "drawn_motions", "drawn_motion_line", "drawn_speeds_line",
                                "error_bar_warning", "candidate_label", "kept_candidate", "first_fit_sentence"),
}, {
    "rideid.estimate.assess.adequacy": {"adequacy_caveats": "caveats"},
    "rideid.estimate.assess.shape": {"error_bar_caveat": "caveat", "error_bar_note": "table_note"},
    "rideid.estimate.assess.responses": {"complete_result": "complete"},
    "rideid.report.sensitivity_files": {"write_sensitivity_csvs": "write_csvs",
                                        "sensitivity_tables_markdown": "tables_markdown",
                                        "sensitivity_heatmaps": "heatmaps"},
})
del _by_name  # the module's namespace (and dir(rideid)) holds the two tables only

#: the subpackages, reachable as attributes (``rideid.model.params``) after a plain ``import rideid`` as before
_SUBPACKAGES = ("conditioning", "csvio", "data", "design", "errors", "estimate", "exporter", "model", "profiling",
                "report", "settings", "studies", "synth",
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
    "plot_fit", "plot_parameters", "plot_dampers", "plot_budget", "plot_frequency_response",
]
