"""A pack's figures, computed once per change and stored: health, forecast, fleet row, model.

A pack's health takes seconds to compute (trend fits, simulated futures) and is read
far more often than it changes. So every write that changes a pack (its events, its
settings, its model) raises ``packs.version`` in the same transaction, and after the write
the client that made it (the one writer) computes the pack's figures with
:func:`pack_figures` and stores them in ``pack_figures`` with the version they were
computed from and :func:`figures_key` (:data:`FIGURES_VERSION` and the dischargelab
release, so an upgrade recomputes). A pack whose stored figures are missing or older is
*stale*:

* :meth:`dischargelab.Logbook.refresh` recomputes the stale packs (on any executor: the
  task is pure) and stores them;
* the library's reads (``packs``, ``health``, ``pack``, ``fleet``) refresh a stale pack
  before answering, or compute it in memory when the logbook cannot be written;
* the pages read only what is stored, and say ``recomputing`` for a stale pack while the
  server recomputes it in the background (they never compute on a request).

What is stored is what the result objects say: ``Health.to_dict()``, the fleet report's
row, ``Pack.to_dict()``, the model's curves, as JSON; ``Health.from_dict`` rebuilds the
object. The cache knows nothing of what health holds, so a new figure in ``to_dict``
is stored without a change here (bump :data:`FIGURES_VERSION` so stored ones are redone).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from sqlalchemy import select

from ..errors import DischargelabError
from . import schema
from .results import DEFAULT_EOL, Health, Pack, build_health

#: Version of the figures this code computes: raise it when what build_health,
#: the fleet row or the model curves hold changes (every stored pack is then redone).
FIGURES_VERSION = 15

#: C-rates of the model curves on a pack page.
CURVE_C_RATES = (0.5, 1.0, 2.0)

#: Points per model curve.
CURVE_POINTS = 200

#: Keys of a pack's row in :meth:`dischargelab.Logbook.packs`.
ROW_KEYS = ("name", "events", "efc", "capacity_Ah", "capacity_interval95", "capacity_fraction",
            "resistance_ohm", "eol_efc", "eol_efc_interval95")


def figures_key() -> str:
    """What stored figures must carry to be current: ``"FIGURES_VERSION/release"``."""
    from .._version import __version__

    return f"{FIGURES_VERSION}/{__version__}"


# --------------------------------------------------------------------------- the pure task

def make_pack(row: dict, events: int, health: Health, model: dict | None,
              fit=None, seen: dict | None = None) -> Pack:
    """A pack with its health today (capacity today, else its latest capacity);
    ``seen``: :func:`seen_in`."""
    cap = health.capacity_now_Ah
    if cap is None:
        caps = [e.capacity_Ah for e in health.events if e.capacity_Ah is not None
                and not e.outlier]
        cap = caps[-1] if caps else None
    return Pack(name=row["name"], label_capacity_Ah=row["label_capacity_Ah"],
                reference_capacity_Ah=health.reference_capacity_Ah,
                chemistry=row["chemistry"], cells=row["cells"], events=events,
                efc=health.efc_now, capacity_Ah=cap,
                capacity_interval95=health.capacity_now_interval95,
                resistance_ohm=health.resistance_now_ohm, health=health, _model=model,
                _fit=fit, _seen=seen or {})


def seen_in(events: list[dict], row: dict) -> dict:
    """Cells in series and chemistry as the events show them (for a pack whose settings
    do not say): cells from the latest event, chemistry from the highest rest voltage
    per cell (LiFePO4 below 3.75 V when full, else LiPo), and that voltage
    (``rest_cell_V``, which tells a high-voltage LiPo pack)."""
    from ..thermalprior import chemistry_from_full_voltage
    from .health import order_events, pack_cells

    if not events:
        return {}
    ordered = order_events(events)
    cells = pack_cells(ordered[-1], row["cells"], row["chemistry"])
    rests = [e.get("rest_voltage_V") for e in ordered if e.get("rest_voltage_V")]
    top = max(rests) / cells if rests else None
    chemistry = chemistry_from_full_voltage(top) if rests else None
    return {"cells": cells, "chemistry": chemistry, "rest_cell_V": top}


def _thin(values, points: int = CURVE_POINTS) -> list:
    n = len(values)
    step = max(1, math.ceil(n / points))
    idx = list(range(0, n, step))
    if idx[-1] != n - 1:
        idx.append(n - 1)
    return [float(values[i]) if math.isfinite(float(values[i])) else None for i in idx]


def model_curves(pack: Pack) -> dict | None:
    """The pack's stored model scaled to today, as curves at :data:`CURVE_C_RATES`:
    ``{"name", "family", "statement" (the model family, the data fitted and the interval
    method, in words), "cells_series", "strings_parallel", "capacity_Ah", "note",
    "curves": [{"c_rate", "current_A", "time_to_cutoff_s", "charge_Ah", "voltage_V"}]}``;
    ``{"note": why}`` when it cannot be scaled; None without a stored model when the pack
    has a full discharge to fit one to. A pack that only flies gets its chemistry's prior
    at today's capacity and resistance (:mod:`.today`)."""
    if not pack.fitted and pack.has_full_discharge:
        return None
    try:
        battery = pack.battery()
    except DischargelabError as exc:
        return {"note": str(exc)}
    from ..predict import default_cutoff
    from ..report import model_statement
    from ..simulate import curve_family

    currents = [c * battery.rated_capacity_Ah for c in CURVE_C_RATES]
    curves = curve_family(battery, currents, **default_cutoff(battery))
    return {"name": battery.name, "family": battery.model,
            "statement": model_statement(battery),
            "cells_series": battery.cells_series, "strings_parallel": battery.strings_parallel,
            "capacity_Ah": battery.capacity_Ah, "note": battery.extra.get("note"),
            "curves": [{"c_rate": c, "current_A": sim.to_dict().get("current_A"),
                        "time_to_cutoff_s": sim.time_to_cutoff_s,
                        "charge_Ah": _thin(sim.charge_Ah), "voltage_V": _thin(sim.voltage_V)}
                       for c, sim in zip(CURVE_C_RATES, curves)]}


def pack_figures(job: dict) -> dict:
    """Every stored figure of one pack from its rows (pure: runs on any worker).

    Parameters
    ----------
    job : dict
        ``{"row": pack row (with version), "events": event rows, "model": model row or
        None}`` as :func:`read_job` gives it.

    Returns
    -------
    dict
        ``{"name", "version", "row", "pack", "fleet", "health", "model"}``, each
        JSON-ready (``row``: the pack list's row; ``pack``: ``Pack.to_dict()``; ``health``:
        ``Health.to_dict()``; ``fleet``: the fleet report's row; ``model``:
        :func:`model_curves`). The list's row is kept apart, small, so a list of
        thousands of packs reads only those.
    """
    from .fleet_report import fleet_row
    from .results import _clean

    row, events, model = job["row"], job["events"], job["model"]
    health = build_health(row, events, model, DEFAULT_EOL)
    fleet = fleet_row(health, row)
    seen = seen_in(events, row)
    pack = make_pack(row, len(events), health, model, seen=seen)
    return _clean({"name": row["name"], "version": row["version"],
                   "row": {k: fleet[k] for k in ROW_KEYS},
                   "pack": {**pack.to_dict(), "seen": seen},
                   "fleet": fleet, "health": health.to_dict(), "model": model_curves(pack)})


# --------------------------------------------------------------------------- storage

def read_job(conn, name: str) -> dict:
    """The rows :func:`pack_figures` needs. The pack's version is read first: under read
    committed a later event is then at worst counted in figures labelled older (redone
    later), never left out of figures labelled current."""
    from . import store

    row = store.pack_row(conn, name)
    return {"row": row, "events": store.pack_events(conn, row["id"]),
            "model": store.latest_model(conn, row["id"])}


@dataclass
class Stored:
    """What is stored for one pack: ``current`` says the figures are of its present data
    and this code; ``figures`` the decoded columns asked for (None when none stored)."""

    name: str
    pack_id: int
    current: bool
    error: str | None
    figures: dict | None


def read_stored(conn, names=None, columns=("row",)) -> dict[str, Stored]:
    """Stored figures of the packs named (all by default), by name, in name order."""
    p, f = schema.packs, schema.pack_figures
    cols = [getattr(f.c, f"{c}_json") for c in columns]
    query = (select(p.c.name, p.c.id, p.c.version, f.c.pack_version, f.c.figures_version,
                    f.c.error, *cols)
             .select_from(p.outerjoin(f, f.c.pack_id == p.c.id)).order_by(p.c.name))
    if names is not None:
        query = query.where(p.c.name.in_(list(names)))
    key = figures_key()
    rows = conn.execute(query).all()
    # each column's JSON texts decoded in one call: a list of thousands of packs is one
    # json.loads, not thousands
    decoded = [json.loads("[" + ",".join(r[6 + k] or "null" for r in rows) + "]")
               for k in range(len(columns))]
    out = {}
    for j, (name, pid, version, stored_version, stored_key, error, *_) in enumerate(rows):
        have = stored_version is not None
        figures = {c: decoded[k][j] for k, c in enumerate(columns)} if have else None
        out[name] = Stored(name=name, pack_id=pid, error=error, figures=figures,
                           current=have and stored_version == version and stored_key == key)
    return out


def stale_names(conn, names=None) -> list[str]:
    """Packs among ``names`` (all by default) whose stored figures are missing or older."""
    return [n for n, s in read_stored(conn, names, columns=()).items() if not s.current]


def _upsert(conn):
    if conn.dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert
    else:
        from sqlalchemy.dialects.sqlite import insert
    return insert(schema.pack_figures)


def store_figures(conn, pack_id: int, version: int, figures: dict | None,
                  error: str | None = None) -> None:
    """Store a pack's figures computed from its ``version`` (or the one-line reason they
    could not be computed), unless newer ones are already stored."""
    f = schema.pack_figures
    values = {"pack_id": pack_id, "pack_version": int(version), "figures_version": figures_key(),
              "computed_at": schema.now_iso(), "error": error}
    for column in ("row", "pack", "fleet", "health", "model"):
        value = None if figures is None else figures.get(column)
        values[f"{column}_json"] = None if value is None else json.dumps(value, allow_nan=False)
    insert = _upsert(conn).values(**values)
    conn.execute(insert.on_conflict_do_update(
        index_elements=["pack_id"],
        set_={k: insert.excluded[k] for k in values if k != "pack_id"},
        where=f.c.pack_version <= insert.excluded.pack_version))


@dataclass
class PackFigures:
    """What a pack page shows, as stored (:meth:`dischargelab.Logbook.figures`).

    Attributes
    ----------
    name : str
    summary : dict or None
        ``Pack.to_dict()`` and ``capacity_fraction`` (capacity today / reference).
    health : dict or None
        ``Health.to_dict()``.
    model : dict or None
        :func:`model_curves` (None: no model stored).
    recomputing : bool
        The stored figures are older than the pack's data (or missing): they are being
        recomputed.
    error : str or None
        Why the figures cannot be computed.
    """

    name: str
    summary: dict | None
    health: dict | None
    model: dict | None
    recomputing: bool
    error: str | None = None

    @classmethod
    def from_stored(cls, stored: Stored) -> PackFigures:
        got = stored.figures or {}
        pack = got.get("pack")
        if pack:
            pack = dict(pack)
            ref, cap = pack.get("reference_capacity_Ah"), pack.get("capacity_Ah")
            pack["capacity_fraction"] = cap / ref if cap is not None and ref else None
        return cls(name=stored.name, summary=pack, health=got.get("health"),
                   model=got.get("model"), recomputing=not stored.current, error=stored.error)

    def to_dict(self) -> dict:
        return {"name": self.name, "summary": self.summary, "health": self.health,
                "model": self.model, "recomputing": self.recomputing, "error": self.error}


__all__ = ["PackFigures", "FIGURES_VERSION", "figures_key", "pack_figures", "make_pack",
           "seen_in", "model_curves", "read_job", "read_stored", "stale_names", "store_figures",
           "Stored", "ROW_KEYS", "CURVE_C_RATES", "CURVE_POINTS"]
