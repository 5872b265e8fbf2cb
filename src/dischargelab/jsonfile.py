"""Small JSON files (battery, calibration): atomic writes, one-line read errors."""

from __future__ import annotations

import json
from pathlib import Path

from .errors import DataError


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON via a temporary file and a rename; returns the path.

    A crash mid-write leaves the previous file intact, never a truncated one.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def read_json(path, missing: str) -> dict:
    """Parse a JSON file; ``missing`` is the one-line message when it does not exist."""
    path = Path(path)
    if not path.is_file():
        raise DataError(missing)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"{path}: not valid JSON ({exc})") from None
