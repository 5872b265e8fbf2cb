"""A pack's health from what it already does, on real and synthetic logs: partial discharges
wherever they sit in the pack's life, long logs through the logbook, flights and cells."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from dischargelab.logbook.health import pack_health
from dischargelab.logbook.summarise import summarise_source

CELL_C = "samsung30q_ageing_cellC"

#: Full discharges of cell C given to the pack, and the cycles cut at 60 % of their charge.
FULL_CYCLES = (1, 100, 200, 300, 400, 500, 600, 660)
CUT_CYCLES = (110, 310, 510)


def lvm_cut(path: Path, out: Path, share: float, dated: bool = True) -> float:
    """Write the file up to ``share`` of its discharge charge (without its clock time when
    ``dated`` is false); return the full file's discharge charge [Ah] (numpy, raw columns)."""
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    start = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 1
    data = [line for line in lines[start:] if line.strip()]
    cols = np.array([[float(x) for x in line.split("\t")[:2]] for line in data])
    current = np.where(cols[:, 1] < -1.0, -cols[:, 1], 0.0)
    charge = np.concatenate(([0.0], np.cumsum(0.5 * (current[1:] + current[:-1])
                                                * np.diff(cols[:, 0])))) / 3600.0
    stop = int(np.searchsorted(charge, share * charge[-1])) + 1
    header = [line for line in lines[:start]
              if dated or not line.startswith(("Date\t", "Time\t"))]
    out.write_text("".join(header + data[:stop]), encoding="utf-8")
    return float(charge[-1])


def as_stored(summary, source_id: int, name: str | None = None) -> list[dict]:
    """Summary events as the logbook returns them (ids in the order files were added)."""
    out = []
    for e in summary.events:
        row = dict(e, id=source_id * 1000 + e["index"], source_id=source_id, idx=e["index"],
                   source=name or summary.file_name)
        lo, hi = e["resistance_interval95"] or (None, None)
        row.update(resistance_low_ohm=lo, resistance_high_ohm=hi)
        out.append(row)
    return out


@pytest.fixture(scope="module")
def cell_c_fulls(shared_data):
    return [summarise_source(shared_data / CELL_C / f"DischargeCycle{c:03d}.txt")
            for c in FULL_CYCLES]


@pytest.mark.parametrize("dated", [True, False], ids=["dated", "undated"])
@pytest.mark.parametrize("added", ["before", "after"])
@pytest.mark.parametrize("named", [True, False], ids=["cycle-in-name", "renamed"])
def test_cell_c_partial_discharges_within_3_percent_wherever_they_sit(
        shared_data, tmp_path, cell_c_fulls, dated, added, named):
    """Cuts at 60 % of their charge, with or without a clock time, with or without the cycle
    number in their names, added before or after the full cycles: each within 3 % of the
    full file's charge, its interval covering it."""
    cuts, truth = [], {}
    for k, c in enumerate(CUT_CYCLES):
        name = f"DischargeCycle{c:03d}.txt" if named else f"partial_{'abc'[k]}.txt"
        path = tmp_path / name
        truth[name] = lvm_cut(shared_data / CELL_C / f"DischargeCycle{c:03d}.txt", path, 0.6,
                              dated)
        cuts.append(summarise_source(path))
    order = [*cuts, *cell_c_fulls] if added == "before" else [*cell_c_fulls, *cuts]
    events = []
    for sid, summary in enumerate(order, 1):
        events += as_stored(summary, sid)
    health, reference, _ = pack_health(events)
    partial = {h.source: h for h in health if not h.full}
    assert set(partial) == set(truth)
    for name, h in partial.items():
        assert h.capacity_Ah == pytest.approx(truth[name], rel=0.03), name
        lo, hi = h.capacity_interval95
        assert lo < truth[name] < hi
        assert "matched full discharge" in h.capacity_method
    if not dated and added == "after":  # placed after what the pack had, never before cycle 1
        first = next(k for k, h in enumerate(health) if h.full)
        assert all(k > first for k, h in enumerate(health) if not h.full)
