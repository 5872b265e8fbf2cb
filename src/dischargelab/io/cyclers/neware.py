"""Neware BTS files, ``.nda`` and ``.ndax``, read with NewareNDA.

NewareNDA returns one row per record: ``Cycle`` (the cycle as Neware's software
counts it: a new cycle at a charge that follows a discharge; the raw numbers in the
file differ between NewareNDA versions), ``Step`` (the running step number Neware
records), ``Status`` (``CC_Chg``, ``CC_DChg``, ``CCCV_Chg``, ``Rest``...),
``Time`` [s, test time], ``Voltage`` [V], ``Current(mA)`` (discharge negative),
``Charge_Capacity(mAh)`` and ``Discharge_Capacity(mAh)`` (restarting every
step), ``Timestamp`` and auxiliary channels (``T1`` [degC]...).

References
----------
NewareNDA, https://github.com/d-cogswell/NewareNDA
"""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import DataError, require
from ..flightlog_base import quiet
from .exports import PLAUSIBLE_C, _version, state_of
from .steps import TesterRecords

#: What NewareNDA raises on a file it cannot decode.
_ERRORS = (ValueError, KeyError, IndexError, TypeError, EOFError, OSError, NotImplementedError,
           AttributeError, AssertionError, UnicodeDecodeError, OverflowError)


def read_neware(path) -> TesterRecords:
    """Records of a Neware ``.nda`` / ``.ndax`` file (see the module docstring)."""
    require("NewareNDA", "cyclers")
    import struct
    import zipfile

    import NewareNDA

    path = Path(path)
    version = _version("NewareNDA")
    said = _Said()
    logger = logging.getLogger("newarenda")
    logger.addHandler(said)
    try:
        with quiet() as printed, warnings.catch_warnings():
            # NewareNDA's own deprecation warnings from newer pandas are not the user's
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", FutureWarning)
            table = NewareNDA.read(str(path))
        said.messages.append(printed.getvalue())
    except (*_ERRORS, struct.error, zipfile.BadZipFile) as exc:
        text = str(exc).strip().splitlines()
        raise DataError(f"{path.name}: NewareNDA {version} cannot read this file "
                        f"({text[0] if text else type(exc).__name__}); a newer NewareNDA may "
                        "(pip install -U NewareNDA), or export the test from BTSDA as CSV"
                        ) from None
    finally:
        logger.removeHandler(said)
    if len(table) == 0:
        raise DataError(f"{path.name}: NewareNDA {version} found no records in the file")
    notes = []
    if "interpolat" in " ".join(said.messages).lower():
        notes.append(f"the file lacks some records' time and capacity: NewareNDA {version} "
                     "filled them in by interpolation (time, capacity and energy of those "
                     "records are not measured)")
    frame = table[[]].copy()
    frame["time_s"] = _test_time(table, notes)
    frame["voltage_V"] = table["Voltage"].to_numpy(dtype=float)
    frame["current_A"] = table["Current(mA)"].to_numpy(dtype=float) * 1e-3
    frame["cycle_index"] = table["Cycle"].to_numpy(dtype=np.int64)
    frame["step_index"] = table["Step"].to_numpy(dtype=np.int64)
    frame["state"] = state_of(table["Status"].astype(str))
    frame["tester_charge_Ah"] = table["Charge_Capacity(mAh)"].to_numpy(dtype=float) * 1e-3
    frame["tester_discharge_Ah"] = table["Discharge_Capacity(mAh)"].to_numpy(dtype=float) * 1e-3
    if "T1" in table:
        values = table["T1"].to_numpy(dtype=float)
        if np.isfinite(values).any() and \
                PLAUSIBLE_C[0] <= float(np.nanmedian(values)) <= PLAUSIBLE_C[1]:
            frame["temperature_C"] = values
            notes.append("temperature from the auxiliary channel T1")
    meta = {"format": "neware-" + path.suffix.lower().lstrip(".") if path.suffix else "neware",
            "reader": f"NewareNDA {version}", "notes": notes,
            "column_map": {"time_s": "Time", "voltage_V": "Voltage", "current_A": "Current(mA)",
                           "cycle_index": "Cycle", "step_index": "Step", "state": "Status"},
            "units": {"current_A": "mA", "tester_discharge_Ah": "mAh"}}
    if "Timestamp" in table and len(table):
        stamp = table["Timestamp"].iloc[0]
        if stamp is not None and str(stamp) != "NaT":
            start = stamp - pd.to_timedelta(float(frame["time_s"].iat[0]), "s")
            meta["start_time"] = start.tz_localize(None).isoformat(timespec="seconds") \
                if start.tzinfo is not None else start.isoformat(timespec="seconds")
    return TesterRecords(frame=frame, records=np.arange(1, len(frame) + 1), meta=meta)


class _Said(logging.Handler):
    """Keeps what NewareNDA logs while it reads (it says when it interpolates)."""

    def __init__(self):
        super().__init__(level=logging.DEBUG)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def _test_time(table: pd.DataFrame, notes: list[str]) -> np.ndarray:
    """Test time [s]: ``Time`` when it runs on through the test; where it restarts with
    every step (some files), the record time stamps when they never go back, else the
    step times added up."""
    t = table["Time"].to_numpy(dtype=float)
    if np.all(np.diff(t) >= 0):
        return t
    if "Timestamp" in table:
        stamps = (table["Timestamp"] - table["Timestamp"].iloc[0]).dt.total_seconds()
        stamps = stamps.to_numpy(dtype=float)
        if np.all(np.isfinite(stamps)) and np.all(np.diff(stamps) >= 0):
            notes.append("Time restarts with every step: test time from the record time stamps")
            return stamps + t[0]
    step = table["Step"].to_numpy()
    new = np.concatenate(([False], step[1:] != step[:-1]))
    offset = np.cumsum(np.where(new, np.roll(t, 1), 0.0))
    notes.append("Time restarts with every step: test time is the step times added up (the "
                 "pauses between steps are not in the file)")
    return t + offset


__all__ = ["read_neware"]
