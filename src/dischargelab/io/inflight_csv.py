"""In-flight battery loggers that write CSV with per-cell voltages (INA3221 and alike).

The layout, as written by INA3221-based monitors on small multirotors::

    629,16.66,4.14,4.16,4.17,4.18,781.44,0.67,

no header row, a trailing comma, and the columns

1. time [ms since the logger started];
2. pack voltage [V];
3. ... cell voltages [V], one column per cell;
4. current [mA], discharge positive;
5. shunt voltage [mV] (not kept).

The layout is recognised from the values, never from the file name: the
first column rises, and the columns after the pack voltage add up to it
(cell voltages) in most rows. Negative current readings near zero are sensor
noise and are kept; the unplug artefact the logger writes at the end (a cell
voltage collapsing with no current) is dropped with a note (see
:mod:`dischargelab.io.flightlog`).

Loggers glitch: a cell channel may read 0 V or saturate for a few samples. Such
cell samples (outside :data:`PLAUSIBLE_CELL_V`) are masked (NaN), counted in the
notes and in ``BatterySeries.masked``; the record, its pack voltage and current
are kept.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError
from .flightlog_base import BatterySeries, FlightLog, build_flight_log

#: Cells in series accepted (2S ... 16S).
MIN_CELLS, MAX_CELLS = 2, 16
#: Cell voltages outside this range [V] are not cell voltages.
CELL_RANGE_V = (0.5, 5.0)
#: The cells must add up to the pack within max(this [V], PACK_TOLERANCE_FRACTION * pack).
PACK_TOLERANCE_V = 0.05
PACK_TOLERANCE_FRACTION = 0.005
#: Share of rows that must satisfy the sum (and hold cell voltages in every cell
#: column) for the layout to be recognised: a glitching channel may miss it in a few.
MATCH_SHARE = 0.9
#: A cell of a flying lithium pack reads between these [V]: 1.0 V is a cell
#: over-discharged far past any cutoff, 4.5 V above a LiHV cell's 4.35 V full charge.
#: Outside, the channel glitched and the sample is masked.
PLAUSIBLE_CELL_V = (1.0, 4.5)
#: Fewest rows to recognise the layout from.
MIN_ROWS = 5


@dataclass
class CellLayout:
    """Column positions (0-based) of an in-flight logger CSV."""

    pack: int
    first_cell: int
    cells: int
    current: int

    @property
    def time(self) -> int:
        return 0


def _numeric_rows(lines: list[str]) -> np.ndarray | None:
    rows = []
    for line in lines:
        parts = [p.strip() for p in line.strip().rstrip(",").split(",")]
        if len(parts) < 5:
            continue
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            continue
    if len(rows) < MIN_ROWS:
        return None
    width = max(set(map(len, rows)), key=[len(r) for r in rows].count)
    table = np.array([r for r in rows if len(r) == width], dtype=float)
    return table if len(table) >= MIN_ROWS else None


def find_layout(table: np.ndarray) -> CellLayout | None:
    """The pack/cell/current columns of numeric rows, or None if the values do not fit.

    The first column must rise (time); a column between 1 and 100 V must be
    the sum of the 2 to 16 columns right after it, each a plausible cell
    voltage, in at least :data:`MATCH_SHARE` of the rows (a glitching cell
    channel may read nonsense in the others); the column after the cells is
    the current.
    """
    if table.ndim != 2 or table.shape[1] < 5:
        return None
    table = table[np.isfinite(table).all(axis=1)]
    if table.shape[0] < MIN_ROWS:
        return None
    if np.mean(np.diff(table[:, 0]) > 0) < MATCH_SHARE:
        return None
    width = table.shape[1]
    for pack in range(1, width - 3):
        v = table[:, pack]
        if not (np.all(v > 1.0) and np.all(v < 100.0)):
            continue
        for cells in range(MIN_CELLS, min(MAX_CELLS, width - pack - 2) + 1):
            block = table[:, pack + 1:pack + 1 + cells]
            in_range = (block > CELL_RANGE_V[0]) & (block < CELL_RANGE_V[1])
            if np.mean(in_range[:, -1]) < MATCH_SHARE:
                break
            tolerance = np.maximum(PACK_TOLERANCE_V, PACK_TOLERANCE_FRACTION * v)
            if np.mean(np.abs(block.sum(axis=1) - v) <= tolerance) >= MATCH_SHARE:
                return CellLayout(pack=pack, first_cell=pack + 1, cells=cells,
                                  current=pack + 1 + cells)
    return None


def looks_like_inflight_csv(lines: list[str]) -> bool:
    """True when text lines (the start of a file) have the in-flight logger layout."""
    table = _numeric_rows(lines[:200])
    return table is not None and find_layout(table) is not None


def read_inflight_csv(path) -> FlightLog:
    """Read an in-flight logger CSV (see the module docstring) into a FlightLog.

    Raises
    ------
    DataError
        The values do not have the layout, or no row is usable.
    """
    path = Path(path)
    raw = path.read_bytes()
    head = raw[:65536].decode("utf-8", errors="replace").lstrip("\ufeff").splitlines()
    table = _numeric_rows(head[:200])
    layout = find_layout(table) if table is not None else None
    if layout is None:
        raise DataError(f"{path.name}: not an in-flight logger CSV (no pack-voltage column "
                        "equal to the sum of the cell columns after it)")
    skip = 0
    for line in head:
        if not line.strip():
            skip += 1
            continue
        try:
            float(line.split(",")[0])
            break
        except ValueError:
            skip += 1
    values, malformed = _parse(raw, skip, layout, path.name)
    notes = [f"in-flight logger CSV: time [ms] in column 1, pack voltage [V] in column "
             f"{layout.pack + 1}, {layout.cells} cell voltages [V] in columns "
             f"{layout.first_cell + 1}-{layout.first_cell + layout.cells}, current [mA] in "
             f"column {layout.current + 1} (layout recognised from the values)"]
    if skip:
        notes.append(f"{skip} header or blank line(s) at the top skipped")
    frame = pd.DataFrame({
        "time_s": values[:, 0] * 1e-3,
        "voltage_V": values[:, layout.pack],
        "current_A": values[:, layout.current] * 1e-3,
    })
    masked = {}
    for k in range(layout.cells):
        cell = values[:, layout.first_cell + k].copy()
        bad = np.isfinite(cell) & ~((cell >= PLAUSIBLE_CELL_V[0]) & (cell <= PLAUSIBLE_CELL_V[1]))
        if bad.any():
            stretches = int(np.count_nonzero(np.diff(np.r_[0, bad.astype(np.int8)]) == 1))
            masked[f"cell{k + 1}_V"] = int(bad.sum())
            notes.append(f"cell {k + 1}: {int(bad.sum())} sample(s) in {stretches} stretch(es) "
                         f"outside {PLAUSIBLE_CELL_V[0]:g}-{PLAUSIBLE_CELL_V[1]:g} V masked (a "
                         f"glitching cell channel; readings {np.nanmin(cell[bad]):.3g} to "
                         f"{np.nanmax(cell[bad]):.3g} V); the pack voltage and current of "
                         f"those records are kept")
            cell[bad] = np.nan
        frame[f"cell{k + 1}_V"] = cell
    series = BatterySeries(index=0, label="pack", frame=frame, cells=layout.cells,
                           dropped={"malformed": malformed} if malformed else {},
                           masked=masked)
    t = frame["time_s"].to_numpy()
    start = float(np.nanmin(t)) if np.isfinite(t).any() else 0.0
    return build_flight_log(path, "inflight-csv", [series], start_s=start, notes=notes)


def _parse(raw: bytes, skip: int, layout: CellLayout, name: str) -> tuple[np.ndarray, int]:
    """Numeric values of every data line; lines of another width count as malformed."""
    need = layout.current + 1
    options = dict(header=None, skiprows=skip, on_bad_lines="skip", skip_blank_lines=True,
                   usecols=range(need), engine="c", encoding="utf-8", encoding_errors="replace")
    try:
        try:
            frame = pd.read_csv(io.BytesIO(raw), dtype=float, **options)
        except ValueError:  # text in a number column: read as text, coerce below
            frame = pd.read_csv(io.BytesIO(raw), dtype=str, **options)
    except pd.errors.ParserError as exc:
        raise DataError(f"{name}: not a readable CSV ({str(exc).splitlines()[0]})") from None
    except pd.errors.EmptyDataError:
        raise DataError(f"{name}: no data lines") from None
    lines = raw.count(b"\n") + (0 if raw.endswith(b"\n") else 1) - skip \
        - raw.count(b"\n\n") - raw.count(b"\n\r\n")
    malformed = max(lines - len(frame), 0)
    text_columns = [c for c in frame.columns if frame[c].dtype.kind not in "fiu"]
    for column in text_columns:
        frame[column] = pd.to_numeric(frame[column], errors="coerce")
    return frame.to_numpy(dtype=float), malformed


__all__ = ["read_inflight_csv", "looks_like_inflight_csv", "find_layout", "CellLayout"]
