"""Every file format rideid reads or writes: its keys, its rules, its one clear error line.

One module per format (docs/formats.md is the user's side of the same rules):

=========================  ==========================================================
module                     format
=========================  ==========================================================
:mod:`.manifest`           scenario files (:class:`Scenario`) and ``dataset.toml``
                           (:class:`DatasetManifest`): ``[vehicle]``, ``[known]``,
                           ``[bounds]``, ``[model]``, ``[[runs]]``, ``[truth]``,
                           ``[checks]``; ``truth.toml``
:mod:`.channels`           how logger files are read: ``[channels]`` maps, units,
                           ``[preprocess]``, ``[csv]``
:mod:`.hifi`               a scenario's ``[hifi]`` table (the MuJoCo car)
:mod:`.dampers`            SPEC §8 in files: ``[dampers]`` curves, the bump-stop
                           truths, ``[model] damper_knots``
:mod:`.runfiles`           run CSVs of SPEC §3 and :class:`RunData`
:mod:`.result`             ``result.json`` read back
:mod:`.common`             TOML in and out, number and table checks, read-only
                           tables, all-or-nothing output folders
=========================  ==========================================================

``[[tracks]]`` tables and profile files are read by :mod:`.tracks`
(:func:`track_from_table`; one declarative key table per kind), study files
by :mod:`rideid.studies.spec`; every section's keys are declared with
:mod:`.keys` (:class:`Key`, :class:`Section`). The loaders that add the physics
checks (:mod:`rideid.data.checks`) sit one level up: :func:`rideid.load_scenario`
(:mod:`rideid.data.scenario`) and :func:`rideid.load_dataset` (:mod:`rideid.data.dataset`). This package imports only
:mod:`rideid.errors`, :mod:`rideid.csvio` and :mod:`rideid.model`; the
physics and IO code imports from it, never the other way.
"""

from .channels import (CHANNEL_KEYS, CSV_KEYS, PREPROCESS_KEYS, RUN_PREPROCESS_KEYS, SI, TARGETS, UNITS, ChannelEntry,
                       CsvOptions, parse_channel_map, parse_csv_options, parse_preprocess, quantity, unit_factor)
from .common import ReadOnlyDict, atomic_output, checked_items, in_folder, read_toml, write_toml
from .dampers import (BUMP_NAMES, DEFAULT_DAMPER_KNOTS, NONLINEAR_GROUPS, DamperCurves, parse_bump_stops,
                      parse_damper_knots, parse_dampers)
from .hifi import HIFI_KEYS, HifiProperties, parse_hifi, tire_damping_of
from .manifest import (CHECK_LEVELS, CHECK_NAMES, MODEL_GROUPS, UNKNOWN_ROAD, DatasetManifest, Manifest, RoadSpec,
                       RunSpec, Scenario, load_manifest, load_truth, load_truth_dampers, load_truth_roads,
                       parse_checks, parse_dataset_manifest, parse_model, parse_model_table, parse_scenario,
                       parse_truth)
from .keys import Key, Messages, Section
from .result import read_result_json
from .runfiles import RunData, read_run_csv, write_run_csv
from .tracks import TRACK_SECTIONS, read_profile, track_from_table

__all__ = [
    "Manifest", "Scenario", "DatasetManifest", "RunSpec", "RoadSpec", "UNKNOWN_ROAD", "RunData", "ChannelEntry",
    "CsvOptions", "HifiProperties",
    "ReadOnlyDict", "parse_scenario", "parse_dataset_manifest", "parse_model", "parse_checks", "parse_truth",
    "parse_channel_map", "parse_preprocess", "parse_csv_options", "parse_hifi", "tire_damping_of",
    "load_manifest", "load_truth", "read_toml", "write_toml", "read_run_csv", "write_run_csv", "read_result_json",
    "atomic_output", "checked_items", "in_folder", "quantity", "unit_factor",
    "CHECK_NAMES", "CHECK_LEVELS", "HIFI_KEYS", "UNITS", "SI", "TARGETS", "PREPROCESS_KEYS", "RUN_PREPROCESS_KEYS",
    "CSV_KEYS", "CHANNEL_KEYS",
    "BUMP_NAMES", "DEFAULT_DAMPER_KNOTS", "NONLINEAR_GROUPS", "MODEL_GROUPS", "DamperCurves", "parse_dampers",
    "parse_bump_stops", "parse_damper_knots", "parse_model_table", "load_truth_dampers", "load_truth_roads",
    "Key", "Messages", "Section", "TRACK_SECTIONS", "read_profile", "track_from_table",
]
