"""BioLogic EC-Lab ``.mpr`` files, read with galvani.

galvani gives one row per point with EC-Lab's column names: ``time/s``,
``Ewe/V``, the measured current ``I/mA`` (or ``<I>/mA``) where it was recorded,
else only ``control/V/mA``: the set point, a current [mA] in galvanostatic
points and a voltage [V] in potentiostatic ones; ``Ns`` (the sequence of the
technique), ``cycle number`` or ``half cycle``, the flags ``mode`` (1
galvanostatic, 2 potentiostatic, 3 rest) and ``ox/red`` (1 oxidation),
``Q charge/discharge/mA.h`` (restarting every half cycle, negative on
discharge), ``dq/mA.h`` and ``Temperature/°C`` where recorded.

EC-Lab's sign: reduction current negative. Reduction discharges the working
electrode (its voltage falls), so discharge is negative in the file; the ox/red
flag of each point gives the state.

References
----------
galvani, https://github.com/echemdata/galvani; EC-Lab Software User's Manual
(BioLogic): data file columns and the GCPL technique.
"""

from __future__ import annotations

import struct
import warnings
from datetime import datetime
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import DataError, require
from .exports import _version
from .steps import TesterRecords

#: ``mode`` flag values.
GALVANOSTATIC, POTENTIOSTATIC, REST = 1, 2, 3

_ERRORS = (ValueError, KeyError, IndexError, TypeError, EOFError, OSError, NotImplementedError,
           AssertionError, UnicodeDecodeError, struct.error)


def read_biologic(path) -> TesterRecords:
    """Records of a BioLogic ``.mpr`` file (see the module docstring)."""
    require("galvani", "cyclers")
    from galvani import BioLogic

    path = Path(path)
    version = _version("galvani")
    try:
        with warnings.catch_warnings():   # galvani's own warnings are not the user's
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", FutureWarning)
            mpr = BioLogic.MPRfile(str(path))
        data = pd.DataFrame(mpr.data)
    except _ERRORS as exc:
        text = str(exc).strip().splitlines()
        reason = text[0] if text else type(exc).__name__
        hint = ("newer EC-Lab versions write columns galvani does not know yet: export the "
                "data from EC-Lab as text (.mpt) or try a newer galvani"
                if "column" in reason.lower() or isinstance(exc, NotImplementedError) else
                "the file is damaged or cut short; copy it from the EC-Lab computer again")
        raise DataError(f"{path.name}: galvani {version} cannot read this file ({reason}); "
                        f"{hint}") from None
    for needed in ("time/s", "Ewe/V"):
        if needed not in data:
            raise DataError(f"{path.name}: no {needed} column in the file (galvani {version} "
                            f"read {', '.join(map(str, data.columns))})")
    notes: list[str] = []
    # the cell's voltage where a reference electrode was recorded beside it
    volts = next(n for n in ("Ecell/V", "Ewe-Ece/V", "Ewe/V") if n in data)
    frame = pd.DataFrame({"time_s": data["time/s"].to_numpy(dtype=float),
                          "voltage_V": data[volts].to_numpy(dtype=float)})
    mode = _flag(mpr, data, "mode")
    if mode is None:
        mode = np.full(len(data), GALVANOSTATIC)
    frame["current_A"] = _current(data, mode, notes)
    if "cycle number" in data:
        frame["cycle_index"] = data["cycle number"].to_numpy(dtype=float).astype(np.int64)
    elif "half cycle" in data:
        frame["cycle_index"] = data["half cycle"].to_numpy(dtype=np.int64) // 2
        notes.append("cycle number from EC-Lab's half-cycle counter (two half cycles a cycle)")
    else:
        frame["cycle_index"] = 0
    frame["step_index"] = data["Ns"].to_numpy(dtype=np.int64) if "Ns" in data else 0
    oxidation = _flag(mpr, data, "ox/red")
    if oxidation is not None:
        oxidation = oxidation.astype(bool)
        frame["state"] = np.where(mode == REST, "rest",
                                  np.where(oxidation, "charge", "discharge")).astype(object)
    if "Q charge/discharge/mA.h" in data:
        q = data["Q charge/discharge/mA.h"].to_numpy(dtype=float) * 1e-3
        frame["tester_charge_Ah"] = np.where(q > 0, q, 0.0)
        frame["tester_discharge_Ah"] = np.where(q < 0, -q, 0.0)
    for name in ("Temperature/°C", "Temperature/degC"):
        if name in data:
            frame["temperature_C"] = data[name].to_numpy(dtype=float)
    meta = {"format": "biologic-mpr", "reader": f"galvani {version}", "notes": notes,
            "column_map": {"time_s": "time/s", "voltage_V": volts,
                           "step_index": "Ns", "state": "ox/red and mode flags"},
            "units": {"current_A": "mA"}}
    if "<I>/mA" in data and "I/mA" not in data:
        meta["current_interval_mean"] = "<I>/mA"   # counted over each interval (steps.finish)
    stamp = getattr(mpr, "timestamp", None)
    if isinstance(stamp, datetime):
        meta["start_time"] = stamp.isoformat(timespec="seconds")
    return TesterRecords(frame=frame, records=np.arange(1, len(frame) + 1), meta=meta)


def _flag(mpr, data: pd.DataFrame, name: str) -> np.ndarray | None:
    """A flag column (``mode``, ``ox/red``) from the packed flags, or None."""
    if name in data:
        return data[name].to_numpy()
    if name in getattr(mpr, "flags_dict", {}):
        return np.asarray(mpr.get_flag(name))
    return None


def _current(data: pd.DataFrame, mode: np.ndarray, notes: list[str]) -> np.ndarray:
    """Current [A, EC-Lab's sign]: measured where recorded, else the set point."""
    for name in ("I/mA", "<I>/mA"):
        if name in data:
            return data[name].to_numpy(dtype=float) * 1e-3
    if "control/V/mA" not in data:
        raise DataError("no current in the file (neither I/mA, <I>/mA nor control/V/mA)")
    control = data["control/V/mA"].to_numpy(dtype=float)
    current = np.where(mode == GALVANOSTATIC, control * 1e-3, 0.0)
    notes.append("the file holds no measured current: the set point control/V/mA is used as "
                 "the current of its galvanostatic points")
    held = mode == POTENTIOSTATIC
    if held.any() and "dq/mA.h" in data:
        t = data["time/s"].to_numpy(dtype=float)
        dq = data["dq/mA.h"].to_numpy(dtype=float) * 3.6   # mA.h -> A.s
        dt = np.diff(t, prepend=np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            derived = np.where(dt > 0, dq / dt, np.nan)
        current = np.where(held, derived, current)
        notes.append(f"{int(held.sum())} potentiostatic point(s): current from the charge "
                     "counter dq/mA.h over the time step")
    return current


__all__ = ["read_biologic"]
