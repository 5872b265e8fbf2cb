"""Arbin MITS result files ``.res``: Microsoft Access databases, read with mdbtools.

Debian's ``mdbtools`` (``mdb-export``) exports the tables as CSV:
``Channel_Normal_Table`` holds the records (``Data_Point``, ``Test_Time`` [s],
``DateTime`` [days since 1899-12-30], ``Step_Index``, ``Cycle_Index``,
``Current`` [A, charge positive], ``Voltage`` [V], ``Charge_Capacity`` and
``Discharge_Capacity`` [Ah, restarting every cycle]); ``Auxiliary_Table`` the
auxiliary channels (``Data_Type`` 1: temperature [degC]); ``Global_Table`` the
test's name and start. The records are put in ``Data_Point`` order (a file
can store them out of order).

Arbin's CSV and Excel exports are tester tables (:mod:`.exports`).

References
----------
mdbtools, https://github.com/mdbtools/mdbtools; Arbin MITS Pro data file
description (``Channel_Normal_Table`` columns).
"""

from __future__ import annotations

import io
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import DataError, MissingExtraError
from .exports import tester_records
from .steps import TesterRecords

#: First bytes 4..19 of an MS Access (Jet 3/4, ACE) database.
ACCESS_MAGIC = (b"Standard Jet DB", b"Standard ACE DB")

#: Longest an ``mdb-export`` may run [s] (a results file of a year of records
#: exports in seconds).
EXPORT_TIMEOUT_S = 600.0

#: ``Auxiliary_Table.Data_Type`` of a temperature channel.
AUX_TEMPERATURE = 1


def is_access(head: bytes) -> bool:
    """An MS Access database (Arbin ``.res`` is one)."""
    return head[4:19] in ACCESS_MAGIC


def mdbtools_version() -> str:
    """``mdbtools v1.0.0``, or raise the one-line error naming the Debian package."""
    tool = shutil.which("mdb-export")
    if tool is None:
        raise MissingExtraError("Arbin .res files are MS Access databases read with mdbtools, "
                                "which is not installed; install it with: apt-get install "
                                "mdbtools (Debian/Ubuntu; brew install mdbtools on macOS)")
    result = subprocess.run([tool, "--version"], capture_output=True, text=True, timeout=30,
                            check=False)
    return (result.stdout or result.stderr).strip().splitlines()[0] if (
        result.stdout or result.stderr) else "mdbtools"


def _export(path: Path, table: str, version: str) -> pd.DataFrame:
    try:
        result = subprocess.run(["mdb-export", str(path), table], capture_output=True,
                                timeout=EXPORT_TIMEOUT_S, check=False)
    except subprocess.TimeoutExpired:
        raise DataError(f"{path.name}: {version} took more than {EXPORT_TIMEOUT_S:g} s to "
                        f"export {table}") from None
    if result.returncode != 0:
        text = result.stderr.decode("utf-8", "replace").strip().splitlines()
        raise DataError(f"{path.name}: {version} cannot read the {table} table "
                        f"({text[0] if text else f'exit status {result.returncode}'}); is it "
                        "an Arbin results file?")
    body = result.stdout.decode("utf-8", "replace")
    if not body.strip():
        return pd.DataFrame()
    return pd.read_csv(io.StringIO(body))


def read_arbin_res(path) -> TesterRecords:
    """Records of an Arbin ``.res`` file (see the module docstring)."""
    path = Path(path)
    version = mdbtools_version()
    data = _export(path, "Channel_Normal_Table", version)
    needed = ("Data_Point", "Test_Time", "Current", "Voltage", "Cycle_Index", "Step_Index")
    missing = [c for c in needed if c not in data]
    if missing:
        raise DataError(f"{path.name}: the Channel_Normal_Table has no {', '.join(missing)}; "
                        "not an Arbin results file this reader knows")
    if len(data) == 0:
        raise DataError(f"{path.name}: the Arbin results file holds no records")
    notes = []
    if "Test_ID" in data and data["Test_ID"].nunique() > 1:
        notes.append(f"{data['Test_ID'].nunique()} tests (Test_ID) in the file, read in order")
    order = [c for c in ("Test_ID", "Data_Point") if c in data]
    if not data[order].apply(tuple, axis=1).is_monotonic_increasing:
        notes.append("records stored out of order, put in Data_Point order")
        data = data.sort_values(order, kind="stable").reset_index(drop=True)
    aux = _export(path, "Auxiliary_Table", version)
    if len(aux) and {"Data_Point", "Data_Type", "X"} <= set(aux.columns):
        temps = aux[aux["Data_Type"] == AUX_TEMPERATURE]
        if "Auxiliary_Index" in temps:
            temps = temps[temps["Auxiliary_Index"] == temps["Auxiliary_Index"].min()]
        if len(temps):
            data = data.merge(temps[["Data_Point", "X"]].rename(columns={"X": "Temperature"}),
                              on="Data_Point", how="left")
            notes.append("temperature from the first auxiliary temperature channel")
    meta = {"format": "arbin-res", "reader": version, "notes": notes}
    glob = _export(path, "Global_Table", version)
    if len(glob) and "Test_Name" in glob:
        meta["test_name"] = str(glob["Test_Name"].iloc[0])
    records = tester_records(data, data["Data_Point"].to_numpy(dtype=np.int64), path.name, meta)
    records.meta["units"] = {"time_s": "s", "current_A": "A", "tester_discharge_Ah": "Ah"}
    return records


__all__ = ["read_arbin_res", "is_access", "mdbtools_version", "ACCESS_MAGIC"]
