"""Refitting a pack's model: the pure task, and the job the client builds for it.

The client (the only reader and writer of the database) builds one job per pack:
the stored bytes of the pack's latest full discharge, the reader options it was
added with, and the pack's cells and chemistry. :func:`fit_job` turns a job into
the fitted battery (a dict) on any worker, in process or on a Dask cluster
(:mod:`dischargelab.fleet`); the client stores what comes back.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from ..errors import LogbookError


def build_job(name: str, health, source: dict, data: bytes, row: dict,
              fit_options: dict) -> dict:
    """The job of one pack: its latest full discharge (not an outlier) and how to read it.

    Raises
    ------
    LogbookError
        The pack has no full discharge.
    """
    last = latest_full(name, health)
    return {"pack": name, "event_id": last.event_id, "capacity_Ah": last.capacity_Ah,
            "resistance_ohm": last.resistance_ohm, "file_name": source["file_name"],
            "data": data, "segment": source["segment"], "rows": source.get("rows"),
            "options": dict(source["options"]),
            "cells": row["cells"], "chemistry": row["chemistry"],
            "fit_options": dict(fit_options)}


def latest_full(name: str, health):
    """The pack's latest full discharge that is not an outlier."""
    fulls = [e for e in health.events if e.full and not e.outlier]
    if not fulls:
        raise LogbookError(f"pack {name!r} has no full discharge to fit its model to; add "
                           "a discharge from full charge to the cutoff")
    return fulls[-1]


def _rows_of(path: Path, rows, options: dict):
    """One discharge of a long log: its rows of the file read whole, the sample before them
    as its rest sample when the current there is idle."""
    from ..discharge import Discharge
    from ..io import read_discharge
    from .events import idle_threshold

    frame, meta = read_discharge(path, segment="none", **options)
    a, b = int(rows[0]), int(rows[1])
    part = frame.iloc[a:b].reset_index(drop=True)
    t0 = float(part["time_s"].iloc[0])
    part["time_s"] = part["time_s"] - t0
    meta = dict(meta, rest_sample=None, segment=None)
    i = frame["current_A"].to_numpy(dtype=float)
    if a > 0 and abs(i[a - 1]) <= idle_threshold(i):
        meta["rest_sample"] = {"voltage_V": float(frame["voltage_V"].iloc[a - 1]),
                               "time_s": float(frame["time_s"].iloc[a - 1]) - t0,
                               "current_A": float(i[a - 1]), "rule": "rest before the event"}
    return Discharge.from_frame(part, meta, name=path.name)


def fit_job(job: dict) -> dict:
    """Fit the model of one pack's job (pure: no database; runs on any worker).

    Returns
    -------
    dict
        ``{"pack", "event_id", "battery" (Battery.to_dict()), "capacity_Ah",
        "resistance_ohm"}``.
    """
    from dataclasses import replace

    from ..api import fit as fit_discharges
    from ..api import read

    with tempfile.TemporaryDirectory(prefix="dischargelab-") as folder:
        path = Path(folder) / Path(job["file_name"]).name
        path.write_bytes(job["data"])
        if job.get("rows"):
            discharge = _rows_of(path, job["rows"], job["options"])
        else:
            discharge = read(path, segment=job["segment"], **job["options"])
    options = dict(job["fit_options"])
    options.setdefault("cells", job["cells"])
    battery = fit_discharges(discharge, **options).battery
    chemistry = job["chemistry"]
    if chemistry is None:  # the pack's full discharge says which cutoff it was run to
        from .health import infer_chemistry

        cells = battery.cells_series
        full = discharge.rest_voltage_V or float(discharge.voltage_V[0])
        end = float(discharge.voltage_V[-1])
        chemistry = infer_chemistry(full / cells, end / cells)
        notes = list(battery.extra.get("notes", [])) + [
            f"chemistry taken as {chemistry}: nearest to the full discharge's "
            f"{full / cells:.2f} V and {end / cells:.2f} V per cell (set it with "
            "Logbook.set_pack)"]
        battery = replace(battery, extra=dict(battery.extra, notes=notes))
    if battery.chemistry is None:
        battery = replace(battery, chemistry=chemistry)
    return {"pack": job["pack"], "event_id": job["event_id"], "battery": battery.to_dict(),
            "capacity_Ah": job["capacity_Ah"], "resistance_ohm": job["resistance_ohm"]}
