"""The pack logbook: every pack's tests and flights in one database, its health, its future.

::

    import dischargelab as dl
    lb = dl.Logbook()                        # the user's logbook.sqlite (or $DISCHARGELAB_DB)
    lb.add("tests/", pack="C", recursive=True).to_dict()
    lb.health("C").to_dict()["forecast"]     # EFC at 80 % of the reference capacity, 95 %
    lb.health("C").plot()
    dl.endurance(lb.pack("C"), "paper-table5")   # the model scaled to today's health

``Logbook(url)``: ``None`` is ``$DISCHARGELAB_DB`` or ``logbook.sqlite`` in the user's
data folder; a path is a SQLite file; ``postgresql+psycopg://user@host/db`` is a
PostgreSQL database (extra ``postgres``). The database needs the extra ``logbook``
(SQLAlchemy); importing dischargelab does not import it.

Where each figure comes from: :mod:`.summarise` (per event, from the readers),
:mod:`.health` (capacity, resistance, EFC, outliers), :mod:`.forecast` (trend, band,
end of life), :mod:`.schema` (tables and versions), :mod:`.ingest` (hash, skip,
summarise, write).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from ..errors import LogbookError
from .results import DEFAULT_EOL, EventTable, Forecast, Health, Pack, PackTable

#: Event columns listed by :meth:`Logbook.events` (in this order).
EVENT_COLUMNS = ("id", "source", "idx", "kind", "start_time", "cycle", "duration_s",
                 "discharged_Ah", "discharged_Wh", "mean_current_A", "max_current_A",
                 "rest_voltage_V", "rest_after_V", "min_voltage_V", "end_voltage_V",
                 "resistance_ohm", "temperature_start_C", "temperature_max_C", "ambient_C",
                 "cell_spread_V", "reaches_knee", "samples")

#: Export formats.
EXPORT_FORMATS = ("csv", "parquet")


class Logbook:
    """A logbook database (see the module docstring).

    Raises
    ------
    MissingExtraError
        SQLAlchemy (extra ``logbook``) or psycopg (extra ``postgres``) is missing.
    LogbookError
        The database cannot be reached, is not a logbook, or has a newer schema.
    """

    def __init__(self, url=None):
        from ..errors import require

        require("sqlalchemy", "logbook")
        from . import schema

        self.url = schema.resolve_url(url)
        self._engine = schema.create(self.url)
        with schema.database_errors(self.url):
            #: Schema version found when opened (0: created now).
            self.opened_version = schema.prepare(self._engine, self.url)

    # ------------------------------------------------------------------ plumbing
    def close(self) -> None:
        """Release the database connections."""
        self._engine.dispose()

    def __enter__(self) -> Logbook:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        from .schema import shown_url

        return f"Logbook({shown_url(self.url)!r})"

    def _read(self):
        from . import schema

        return schema.reading(self._engine)

    def _errors(self):
        from . import schema

        return schema.database_errors(self.url)

    # ------------------------------------------------------------------ writing
    def add(self, paths, pack: str | None = None, pack_from: str | None = None,
            recursive: bool = False, executor=None, progress=None, **reader_options):
        """Add files and folders (tests, logger files, flight logs) to a pack.

        Parameters
        ----------
        paths : path-like or list of them
            Files, or folders (their data files; sub-folders with ``recursive``).
        pack : str, optional
            The pack every file belongs to.
        pack_from : {"parent"}, optional
            Take each file's pack from its folder's name instead.
        recursive : bool
            Descend into sub-folders.
        executor : optional
            Where files are summarised (:class:`dischargelab.fleet.InProcessExecutor`
            by default).
        progress : callable, optional
            ``progress(done, total, message)`` after each file.
        **reader_options
            As :func:`dischargelab.read` (``columns``, ``current_A``, ``sign``...).

        Returns
        -------
        AddResult
            ``.added``, ``.skipped`` (already in the logbook), ``.rejected``
            (``(path, one-line reason)``), ``.events``; ``.lines()`` for printing.
        """
        from .ingest import add_files

        with self._errors():
            return add_files(self._engine, paths, pack=pack, pack_from=pack_from,
                             recursive=recursive, executor=executor, progress=progress,
                             reader_options=reader_options)

    def add_bytes(self, file_name: str, data: bytes, pack: str, **reader_options):
        """Add one file given as bytes (an upload); returns an AddResult."""
        from .ingest import add_upload

        with self._errors():
            return add_upload(self._engine, file_name, data, pack, reader_options)

    def set_pack(self, name: str, *, label_capacity_Ah: float | None = None,
                 chemistry: str | None = None, cells: int | None = None) -> None:
        """Create a pack or store its label capacity [Ah], chemistry and cells in series."""
        from ..ocv import check_chemistry
        from . import schema, store

        if chemistry is not None:
            check_chemistry(chemistry)
        if label_capacity_Ah is not None and not float(label_capacity_Ah) > 0:
            raise LogbookError(f"label_capacity_Ah must be positive, got {label_capacity_Ah!r}")
        if cells is not None and int(cells) < 1:
            raise LogbookError(f"cells must be at least 1, got {cells!r}")
        with self._errors(), schema.writing(self._engine) as conn:
            store.set_pack(conn, str(name).strip(), label_capacity_Ah=label_capacity_Ah,
                           chemistry=chemistry, cells=None if cells is None else int(cells))

    # ------------------------------------------------------------------ reading
    def _pack_data(self, name: str):
        from . import store

        with self._errors(), self._read() as conn:
            row = store.pack_row(conn, name)
            events = store.pack_events(conn, row["id"])
            model = store.latest_model(conn, row["id"])
        return row, events, model

    def health(self, name: str, eol: float = DEFAULT_EOL) -> Health:
        """Capacity, resistance and EFC per event, outliers, trend and end of life.

        Parameters
        ----------
        name : str
            The pack.
        eol : float
            End of life as a share of the reference capacity (0 < eol < 1).
        """
        if not 0 < float(eol) < 1:
            raise LogbookError(f"eol must lie between 0 and 1 (a share of the reference "
                               f"capacity), got {eol!r}")
        row, events, model = self._pack_data(name)
        return _health(row, events, model, float(eol))

    def events(self, name: str) -> EventTable:
        """The stored events of a pack (without their curves)."""
        _, events, _ = self._pack_data(name)
        from .health import order_events

        rows = [{k: e.get(k) for k in EVENT_COLUMNS} for e in order_events(events)]
        return EventTable(pack=name, rows=rows)

    def packs(self, eol: float = DEFAULT_EOL) -> PackTable:
        """One row per pack: events, EFC, capacity today, resistance, end of life."""
        from . import store

        with self._errors(), self._read() as conn:
            names = store.pack_names(conn)
        rows = []
        for name in names:
            h = self.health(name, eol)
            ref = h.reference_capacity_Ah
            cap = h.capacity_now_Ah
            f = h.forecast
            rows.append({"name": name, "events": len(h.events), "efc": h.efc_now,
                         "capacity_Ah": cap,
                         "capacity_fraction": cap / ref if cap is not None and ref else None,
                         "resistance_ohm": h.resistance_now_ohm,
                         "eol_efc": None if f is None else f.eol_efc,
                         "eol_efc_interval95": None if f is None else f.eol_efc_interval95})
        return PackTable(rows=rows)

    def pack(self, name: str) -> Pack:
        """A pack with its health today; ``.battery()`` is its model scaled to it."""
        row, events, model = self._pack_data(name)
        h = _health(row, events, model, DEFAULT_EOL)
        cap = h.capacity_now_Ah
        if cap is None:
            caps = [e.capacity_Ah for e in h.events if e.capacity_Ah is not None and not e.outlier]
            cap = caps[-1] if caps else None
        return Pack(name=name, label_capacity_Ah=row["label_capacity_Ah"],
                    reference_capacity_Ah=h.reference_capacity_Ah, chemistry=row["chemistry"],
                    cells=row["cells"], events=len(events), efc=h.efc_now, capacity_Ah=cap,
                    resistance_ohm=h.resistance_now_ohm, health=h, _model=model,
                    _fit=lambda: self._fit(name, h))

    def raw(self, sha256: str) -> bytes:
        """The stored bytes of a source file, by its SHA-256."""
        from . import store

        with self._errors(), self._read() as conn:
            return store.raw_file(conn, sha256)

    # ------------------------------------------------------------------ models
    def fit(self, name: str, **fit_options):
        """Fit the pack's model to its latest full discharge and store it.

        ``fit_options`` go to :func:`dischargelab.fit` (``model``, ``bootstrap``...).
        Returns the fitted Battery; ``extra["logbook_fit"]`` holds the capacity [Ah] and
        step resistance [ohm] of the discharge it was fitted to (what
        :meth:`Pack.battery` scales from).
        """
        from dataclasses import replace

        from ..model import Battery

        model = self._fit(name, self.health(name), **fit_options)
        bat = Battery.from_dict(model["battery"])
        extra = dict(bat.extra, logbook_fit={"capacity_Ah": model["capacity_Ah"],
                                             "resistance_ohm": model["resistance_ohm"]})
        return replace(bat, extra=extra)

    def fit_all(self, **fit_options) -> dict:
        """Fit every pack that has a full discharge: ``{name: Battery or one-line reason}``."""
        from . import store

        with self._errors(), self._read() as conn:
            names = store.pack_names(conn)
        out: dict = {}
        for name in names:
            try:
                out[name] = self.fit(name, **fit_options)
            except LogbookError as exc:
                out[name] = str(exc)
        return out

    def _fit(self, name: str, health: Health, **fit_options):
        from dataclasses import replace

        from ..api import fit as fit_discharges
        from ..api import read
        from . import schema, store

        fulls = [e for e in health.events if e.full and not e.outlier]
        if not fulls:
            raise LogbookError(f"pack {name!r} has no full discharge to fit its model to; add "
                               "a discharge from full charge to the cutoff")
        last = fulls[-1]
        with self._errors(), self._read() as conn:
            source = store.source_of_event(conn, last.event_id)
            data = store.raw_file(conn, source["sha256"])
            row = store.pack_row(conn, name)
        options = dict(source["options"])
        with tempfile.TemporaryDirectory(prefix="dischargelab-") as folder:
            path = Path(folder) / source["file_name"]
            path.write_bytes(data)
            discharge = read(path, segment=source["segment"], **options)
        fit_options.setdefault("cells", row["cells"])
        result = fit_discharges(discharge, **fit_options)
        battery = result.battery
        chemistry = row["chemistry"]
        if chemistry is None:  # the pack's full discharge says which cutoff it was run to
            from .health import infer_chemistry

            cells = battery.cells_series
            full = discharge.rest_voltage_V or float(discharge.voltage_V[0])
            chemistry = infer_chemistry(full / cells, float(discharge.voltage_V[-1]) / cells)
            notes = list(battery.extra.get("notes", [])) + [
                f"chemistry taken as {chemistry}: nearest to the full discharge's "
                f"{full / cells:.2f} V and {discharge.voltage_V[-1] / cells:.2f} V per cell "
                "(set it with Logbook.set_pack)"]
            battery = replace(battery, extra=dict(battery.extra, notes=notes))
        if battery.chemistry is None:
            battery = replace(battery, chemistry=chemistry)
        model = {"battery": battery.to_dict(), "capacity_Ah": last.capacity_Ah,
                 "resistance_ohm": last.resistance_ohm}
        with self._errors(), schema.writing(self._engine) as conn:
            store.save_model(conn, row["id"], model["battery"], last.event_id,
                             last.capacity_Ah, last.resistance_ohm)
        return model

    # ------------------------------------------------------------------ export
    def export(self, path, format: str = "csv", force: bool = False) -> Path:
        """Write every pack's events with their health figures (CSV or Parquet).

        Raises
        ------
        LogbookError
            Unknown format. OutputExistsError: the file exists and ``force`` is false.
        MissingExtraError
            Parquet without pyarrow (extra ``parquet``).
        """
        import pandas as pd

        from ..atomic import atomic_path, check_outputs
        from ..errors import require
        from . import store

        if format not in EXPORT_FORMATS:
            raise LogbookError(f"format must be one of {', '.join(EXPORT_FORMATS)}; "
                               f"got {format!r}")
        if format == "parquet":
            require("pyarrow", "parquet")
        out = check_outputs([path], force=force)[0]
        with self._errors(), self._read() as conn:
            names = store.pack_names(conn)
        frames = []
        for name in names:
            frame = self.health(name).to_pandas()
            frame.insert(0, "pack", name)
            frames.append(frame)
        table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
        with atomic_path(out) as tmp:
            if format == "csv":
                table.to_csv(tmp, index=False)
            else:
                table.to_parquet(tmp, index=False)
        return out


def _health(row: dict, events: list[dict], model: dict | None, eol: float) -> Health:
    """Health of one pack from its stored rows (pure; see :mod:`.health`)."""
    import numpy as np

    from ..model import Battery
    from .forecast import crossing, fit_trend
    from .health import observed_crossing, pack_health

    battery = Battery.from_dict(model["battery"]) if model else None
    per_event, reference, how = pack_health(
        events, label_capacity_Ah=row["label_capacity_Ah"], cells=row["cells"],
        chemistry=row["chemistry"], model=battery)
    notes = [f"reference capacity: {how}"]
    usable = [e for e in per_event if e.capacity_Ah is not None and not e.outlier
              and e.efc is not None]
    forecast = None
    if reference and len(usable) >= 2:
        efc = np.array([e.efc for e in usable])
        cap = np.array([e.capacity_Ah for e in usable])
        sd = np.array([(e.capacity_interval95[1] - e.capacity_interval95[0]) / 3.92
                       for e in usable])
        trend = fit_trend(efc, cap, sd)
        if trend is not None:
            threshold = eol * reference
            central, interval, band = crossing(trend, threshold, first_efc=float(efc.min()))
            seen = observed_crossing(efc, cap, threshold)
            if seen is not None:
                central, interval = seen
                notes.append(f"end of life observed: the capacity fell below {threshold:.3g} Ah "
                             f"between {interval[0]:.0f} and {interval[1]:.0f} EFC")
            with_r = [e for e in per_event if e.resistance_ohm is not None and not e.outlier
                      and e.efc is not None]
            r_trend = fit_trend([e.efc for e in with_r], [e.resistance_ohm for e in with_r]) \
                if len(with_r) >= 2 else None
            forecast = Forecast(eol=eol, threshold_Ah=threshold, eol_efc=central,
                                eol_efc_interval95=interval, capacity=trend,
                                resistance=r_trend, band=band, first_efc=float(efc.min()),
                                observed=seen is not None)
    return Health(pack=row["name"], events=per_event, reference_capacity_Ah=reference,
                  reference=how, forecast=forecast, notes=notes)


__all__ = ["Logbook", "Health", "Forecast", "Pack", "PackTable", "EventTable", "DEFAULT_EOL"]
