"""Reading small CSV tables with errors that name the file."""

from __future__ import annotations

import csv
from pathlib import Path

from .errors import DataError


def read_csv_rows(path: Path, missing: str, what: str = "file") -> tuple[list[str], list[list[str]]]:
    """Header (stripped) and the rows after it; ``missing`` is the message if absent."""
    path = Path(path)
    if not path.is_file():
        raise DataError(missing)
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(f"{path}: cannot read {what}: {e}") from None
    if not rows:
        raise DataError(f"{path}: empty {what} (expected a header row)")
    return [c.strip() for c in rows[0]], rows[1:]
