"""The dischargelab log file: the acquisition's crash-safe CSV.

Layout (version 1)::

    # dischargelab-log v1
    # meta: {"port": "/dev/ttyACM0", "source_kind": "arduino", "rate_Hz": 1.0, ...}
    time_s,voltage_V,current_A,temperature_C,seq
    0.0000,12.5312,,,0
    1.0000,12.5098,,,1
    # event: {"kind": "gap", "start_time_s": 1.0, "end_time_s": 4.0, ...}
    ...

Empty field = not measured. Events (gap, reconnect, cutoff, alarm, stop, ...)
are interleaved where they happened. The writer only appends, flushes the
operating-system buffers and calls ``os.fsync`` at least every
``fsync_interval_s``, so a crash, ``kill -9`` or power cut loses at most the
last interval; the reader tolerates the partial last line such an end leaves.
"""

from __future__ import annotations

import io
import json
import math
import os
import threading
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from ..atomic import OutputError, OutputExistsError
from ..errors import DataError

#: First line of every log file.
LOG_MAGIC = "# dischargelab-log v1"
META_PREFIX = "# meta: "
EVENT_PREFIX = "# event: "
#: Data columns, in file order.
LOG_COLUMNS = ("time_s", "voltage_V", "current_A", "temperature_C", "seq")


def _number(value, digits: int) -> str:
    if value is None:
        return ""
    value = float(value)
    if not math.isfinite(value):
        return ""
    return f"{value:.{digits}f}"


def _json_default(value):
    if hasattr(value, "item"):
        return value.item()
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if isinstance(value, Path):
        return str(value)
    return str(value)


def _dumps(data: dict) -> str:
    return json.dumps(_nan_to_none(data), default=_json_default, separators=(", ", ": "))


def _nan_to_none(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _nan_to_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_nan_to_none(v) for v in value]
    return value


class LogWriter:
    """Append samples and events to a log file, crash-safe.

    Parameters
    ----------
    path : path-like
        File to create. An existing file is refused unless ``overwrite=True``.
    meta : dict
        Test description for the header (port, rate_Hz, calibration,
        cells_series, chemistry, start_time, firmware, source, ...). A
        ``start_time`` (ISO 8601, UTC) is added if missing.
    fsync_interval_s : float
        Longest time written data stays only in memory [s]: a background timer
        flushes and fsyncs the file at this interval whenever there is new data.
    overwrite : bool
        Replace an existing file.

    Notes
    -----
    Also a pipeline ``Consumer``: :meth:`handle` is :meth:`write`.
    """

    def __init__(self, path, meta: dict | None = None, fsync_interval_s: float = 0.5, *,
                 overwrite: bool = False):
        self.path = Path(path)
        self.meta = dict(meta or {})
        self.meta.setdefault("start_time", datetime.now(UTC).isoformat(timespec="seconds"))
        self.fsync_interval_s = float(fsync_interval_s)
        if self.path.parent and not self.path.parent.exists():
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._file = open(self.path, "w" if overwrite else "x", encoding="utf-8",
                              newline="\n")
        except FileExistsError:
            raise OutputExistsError(self.path) from None
        except OSError as exc:
            raise OutputError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self.rows_written = 0
        self.events_written = 0
        self._lock = threading.Lock()
        self._dirty = False
        self._closed = False
        self._file.write(f"{LOG_MAGIC}\n{META_PREFIX}{_dumps(self.meta)}\n{','.join(LOG_COLUMNS)}\n")
        self._sync_locked()
        self._wake = threading.Event()
        self._timer = threading.Thread(target=self._sync_loop, name="dischargelab-logsync",
                                       daemon=True)
        self._timer.start()

    # ------------------------------------------------------------------ writing
    def write(self, sample) -> None:
        """Append one sample (any object with the ``Sample`` attributes)."""
        line = (f"{_number(sample.time_s, 4)},{_number(sample.voltage_V, 4)},"
                f"{_number(getattr(sample, 'current_A', None), 4)},"
                f"{_number(getattr(sample, 'temperature_C', None), 2)},"
                f"{'' if getattr(sample, 'seq', None) is None else int(sample.seq)}\n")
        with self._lock:
            if self._closed:
                raise DataError(f"{self.path} is closed")
            self._file.write(line)
            self._dirty = True
            self.rows_written += 1

    handle = write

    def event(self, kind: str, **fields) -> None:
        """Append an event line ``# event: {"kind": ..., "at": ISO time, ...}``; synced at once."""
        record = {"kind": kind, "at": datetime.now(UTC).isoformat(timespec="milliseconds")}
        record.update(fields)
        with self._lock:
            if self._closed:
                return
            self._file.write(f"{EVENT_PREFIX}{_dumps(record)}\n")
            self.events_written += 1
            self._sync_locked()

    def flush(self) -> None:
        """Flush and fsync now."""
        with self._lock:
            if not self._closed:
                self._sync_locked()

    def close(self) -> None:
        """Flush, fsync and close (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._sync_locked()
            self._file.close()
            self._closed = True
        self._wake.set()

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ syncing
    def _sync_locked(self) -> None:
        self._file.flush()
        os.fsync(self._file.fileno())
        self._dirty = False

    def _sync_loop(self) -> None:
        while not self._wake.wait(self.fsync_interval_s):
            with self._lock:
                if self._closed:
                    return
                if self._dirty:
                    self._sync_locked()


# ---------------------------------------------------------------------- reading

def is_log_file(path) -> bool:
    """True if ``path`` starts with the log magic line."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            return fh.readline().rstrip("\r\n") == LOG_MAGIC
    except OSError:
        return False


def read_log(path) -> tuple[pd.DataFrame, dict]:
    """Read a log file into canonical columns.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    data : pandas.DataFrame
        ``time_s``, ``voltage_V``, ``current_A`` (discharge positive; filled
        with the header's ``current_given_A`` when no current was measured),
        ``temperature_C`` (only if measured), ``seq`` (nullable integer).
    meta : dict
        The header metadata plus ``source``, ``format`` ("dischargelab-log"),
        ``sign_convention``, ``current_source`` ("column", "given" or "none"),
        ``events`` (list of dicts) and ``dropped`` (rows dropped by reason:
        ``partial_last_line`` after a crash, ``malformed``).

    Raises
    ------
    DataError
        Not a log file, or a header that cannot be read.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise DataError(f"cannot read {path}: {exc.strerror or exc}") from None
    lines = text.split("\n")
    dropped = {"partial_last_line": 0, "malformed": 0}
    if lines and lines[-1] == "":
        lines.pop()
    elif lines:
        lines.pop()                     # no newline at the end: cut by a crash
        dropped["partial_last_line"] = 1
    if not lines or lines[0].rstrip("\r") != LOG_MAGIC:
        raise DataError(f"{path} is not a dischargelab log (first line must be {LOG_MAGIC!r})")
    if len(lines) < 3 or not lines[1].startswith(META_PREFIX):
        raise DataError(f"{path}: log header is incomplete (no '# meta:' line)")
    try:
        meta = json.loads(lines[1][len(META_PREFIX):])
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: log header metadata is not valid JSON ({exc})") from None
    columns = lines[2].strip().split(",")
    missing = [c for c in ("time_s", "voltage_V") if c not in columns]
    if missing:
        raise DataError(f"{path}: log column header lacks {', '.join(missing)}")
    n_fields = len(columns)
    events, rows = [], []
    for line in lines[3:]:
        if line.startswith("#"):
            if line.startswith(EVENT_PREFIX):
                try:
                    events.append(json.loads(line[len(EVENT_PREFIX):]))
                except json.JSONDecodeError:
                    dropped["malformed"] += 1
            continue
        if line.count(",") != n_fields - 1:
            if line.strip():
                dropped["malformed"] += 1
            continue
        rows.append(line)
    data = _parse_rows(rows, columns, dropped)
    data = _canonical(data, dropped)
    meta = dict(meta)
    given = meta.get("current_given_A")
    if "current_A" in data and data["current_A"].notna().any():
        current_source = "column"
    elif given is not None:
        data["current_A"] = float(given)
        current_source = "given"
    else:
        current_source = "none"
    meta.update({
        "source": str(path), "format": "dischargelab-log", "sign_convention": "discharge positive",
        "current_source": current_source, "events": events, "dropped": dropped,
    })
    return data, meta


def _parse_rows(rows: list[str], columns: list[str], dropped: dict) -> pd.DataFrame:
    if not rows:
        return pd.DataFrame({c: np.array([], dtype=float) for c in columns})
    try:
        return pd.read_csv(io.StringIO("\n".join(rows)), names=columns, header=None,
                           dtype=float, engine="c")
    except ValueError:
        pass
    good = []
    for row in rows:                    # slow path: find the bad rows
        try:
            good.append([float(x) if x else math.nan for x in row.split(",")])
        except ValueError:
            dropped["malformed"] += 1
    return pd.DataFrame(good, columns=columns, dtype=float)


def _canonical(data: pd.DataFrame, dropped: dict) -> pd.DataFrame:
    bad = data["time_s"].isna() | data["voltage_V"].isna()
    if bad.any():
        dropped["malformed"] += int(bad.sum())
        data = data[~bad]
    out = pd.DataFrame({"time_s": data["time_s"].to_numpy(float),
                        "voltage_V": data["voltage_V"].to_numpy(float)})
    out["current_A"] = (data["current_A"].to_numpy(float) if "current_A" in data
                        else np.full(len(out), np.nan))
    if "temperature_C" in data and data["temperature_C"].notna().any():
        out["temperature_C"] = data["temperature_C"].to_numpy(float)
    if "seq" in data:
        out["seq"] = pd.array(data["seq"].to_numpy(float), dtype="Float64").astype("Int64")
    return out


__all__ = ["LOG_MAGIC", "LOG_COLUMNS", "LogWriter", "read_log", "is_log_file"]
