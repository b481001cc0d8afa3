"""Studies: many identifications (Monte Carlo, fleets, run subsets) on Dask, resumable.

``rideid.study(STUDY.toml, DIR)`` runs every task of a study file on a local
Dask cluster (or an existing one) and writes ``DIR/results.parquet`` and a
summary; see ``docs/studies.md`` for the file format and the engine.

Modules: :mod:`.spec` (study files -> tasks), :mod:`.task` (one task, run by
a worker), :mod:`.engine` (the orchestrator: cluster, resume, progress),
:mod:`.summary` (tables and figures).
"""

from .engine import StudyResult, local_cluster, study
from .spec import Study, Task, load_study, parse_study

__all__ = ["Study", "StudyResult", "Task", "load_study", "local_cluster", "parse_study", "study"]
