"""``result.json`` read back: the checks a file must pass before it is a result.

:mod:`rideid.estimate.result` writes the file (``IdentificationResult.save``)
and turns the checked document into an
:class:`~rideid.estimate.result.IdentificationResult` (``load``); ``rideid
score`` reads it through the same check.
"""

from __future__ import annotations

import json
from pathlib import Path

from ...errors import DataError
from ...model.params import NAMES

#: result.json's schema version (raised on any change of meaning; docs/formats.md "result.json"). 1: the files
#: written before the field existed (no ``schema_version``); 2: ``schema_version``, ``plan``, ``settings``,
#: ``assessments`` added, every key of 1 still written with its meaning
SCHEMA_VERSION = 2


def read_result_json(path) -> dict:
    """``result.json`` as a dict, checked for every parameter's value; :class:`DataError` naming the file."""
    given = Path(path)
    path = given if given.suffix == ".json" else given / "result.json"
    if not path.is_file():
        raise DataError(f"{path}: file not found" if path is given else
                        f"{path}: not found (is {given} an identification folder?)")
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DataError(f"{path}: not valid JSON: {e}") from None
    version = doc.get("schema_version", 1) if isinstance(doc, dict) else 1
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise DataError(f"{path}: schema_version must be a positive integer, got {version!r}")
    if version > SCHEMA_VERSION:
        raise DataError(f"{path}: schema_version {version} was written by a newer rideid; this one reads up to "
                        f"{SCHEMA_VERSION} (upgrade rideid)")
    pars = doc.get("parameters") if isinstance(doc, dict) else None
    if not isinstance(pars, dict):
        raise DataError(f"{path}: missing key 'parameters'")
    for n in NAMES:
        if n not in pars or not isinstance(pars[n], dict) or "value" not in pars[n]:
            raise DataError(f"{path}: parameters.{n}.value missing")
    return doc


__all__ = ["SCHEMA_VERSION", "read_result_json"]
