"""Small JSON files (battery, calibration): atomic writes, one-line read errors.

Writing goes through :mod:`dischargelab.atomic` (the one place for atomic
files); :func:`write_json` is re-exported here for existing imports.
"""

from __future__ import annotations

import json
from pathlib import Path

from .atomic import write_json
from .errors import DataError


def read_json(path, missing: str, what: str | None = None) -> dict:
    """Parse a JSON file.

    Parameters
    ----------
    path : path-like
    missing : str
        The one-line message when the file does not exist.
    what : str, optional
        What the file should be ("battery file", "calibration file"), for messages.

    Raises
    ------
    DataError
        Missing or unreadable file, or not valid JSON (naming the file and ``what``).
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(missing)
    label = f"{what} {path}" if what else str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataError(f"cannot read {label}: {exc.strerror or exc}") from None
    try:
        return json.loads(raw.decode("utf-8-sig"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        reason = " ".join(str(exc).split())
        raise DataError(f"{label}: not valid JSON ({reason})") from None
    except RecursionError:
        raise DataError(f"{label}: not valid JSON (nested too deeply)") from None


__all__ = ["read_json", "write_json"]
