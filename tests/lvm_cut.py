"""A LabVIEW cycle file of the ageing cell cut short: a partial discharge for the tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np


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


def lvm_storage(path: Path, out: Path, share: float, dated: bool = True) -> float:
    """Write the file as if its discharge had started from a storage charge: one rest sample
    at the open-circuit voltage ``share`` of its charge down (the loaded voltage there plus
    the drop the file's own load shows 300 s in, its polarisation built as a learned curve
    takes it), then its discharge from there to its end; return the full file's discharge
    charge [Ah]."""
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    start = next(k for k, line in enumerate(lines) if line.startswith("X_Value")) + 1
    data = [line for line in lines[start:] if line.strip()]
    cols = np.array([[float(x) for x in line.split("\t")[:3]] for line in data])
    current = np.where(cols[:, 1] < -1.0, -cols[:, 1], 0.0)
    charge = np.concatenate(([0.0], np.cumsum(0.5 * (current[1:] + current[:-1])
                                                * np.diff(cols[:, 0])))) / 3600.0
    at = int(np.searchsorted(charge, share * charge[-1]))
    settled = int(np.searchsorted(cols[:, 0], cols[0, 0] + 300.0))
    drop = cols[0, 2] - cols[settled, 2]    # rest minus loaded 300 s in [V]
    rest = data[0].split("\t")
    rest[2] = f"{cols[at, 2] + drop:.6f}"
    shifted = []
    for line in data[at:]:
        parts = line.split("\t")
        parts[0] = f"{float(parts[0]) - cols[at, 0] + cols[1, 0]:.6f}"
        shifted.append("\t".join(parts))
    header = [line for line in lines[:start]
              if dated or not line.startswith(("Date\t", "Time\t"))]
    out.write_text("".join(header + ["\t".join(rest)] + shifted), encoding="utf-8")
    return float(charge[-1])
