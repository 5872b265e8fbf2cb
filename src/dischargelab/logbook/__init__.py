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

import functools
from pathlib import Path

from ..errors import DischargelabError, LogbookError
from .results import (
    DEFAULT_EOL,
    EventTable,
    Forecast,
    Health,
    Pack,
    PackTable,
    build_health,
)

#: Event columns listed by :meth:`Logbook.events` (in this order).
EVENT_COLUMNS = ("id", "source", "idx", "kind", "start_time", "cycle", "duration_s",
                 "discharged_Ah", "discharged_Wh", "mean_current_A", "max_current_A",
                 "rest_voltage_V", "rest_after_V", "min_voltage_V", "end_voltage_V",
                 "resistance_ohm", "temperature_start_C", "temperature_max_C", "ambient_C",
                 "cell_spread_V", "reaches_knee", "samples")

#: Export formats.
EXPORT_FORMATS = ("csv", "parquet")
#: Pack names a "no such pack" error lists.
SHOWN_PACK_NAMES = 8


class Logbook:
    """A logbook database (see the module docstring).

    Parameters
    ----------
    url : str or path-like, optional
        Where it is (see the module docstring).
    create : bool
        Create a SQLite logbook that does not exist yet (the default); False raises
        LogbookError instead, for code that only reads.

    Raises
    ------
    MissingExtraError
        SQLAlchemy (extra ``logbook``) or psycopg (extra ``postgres``) is missing.
    LogbookError
        The database cannot be reached, is not a logbook, or has a newer schema.
    """

    def __init__(self, url=None, create: bool = True):
        from ..errors import require

        require("sqlalchemy", "logbook")
        from . import schema

        self.url = schema.resolve_url(url)
        self._engine = schema.create(self.url, new=create)
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
            recursive: bool = False, executor=None, progress=None, keep_raw: bool = True,
            refresh: bool = True, **reader_options):
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
        keep_raw : bool
            Keep each file's bytes (compressed) in the database, so every figure can be
            recomputed from it. False records only its path and SHA-256: a fleet's
            database stays small, and the files must stay where they are.
        refresh : bool
            Recompute and store the figures of the packs that got events, on the same
            executor (:meth:`refresh`); False leaves them stale for a later refresh.
        **reader_options
            As :func:`dischargelab.read` (``columns``, ``current_A``, ``sign``...).

        Returns
        -------
        AddResult
            ``.added``, ``.skipped`` (already in the logbook), ``.rejected``
            (``(path, one-line reason)``), ``.events``, ``.changed`` (packs that got
            events); ``.lines()`` for printing.

        Raises
        ------
        LogbookStorageError
            The database refuses the write (full disk, read-only, server gone): one line;
            the batches written before are kept whole and a rerun adds only the rest.
        """
        from .ingest import add_files

        with self._errors():
            result = add_files(self._engine, paths, pack=pack, pack_from=pack_from,
                               recursive=recursive, executor=executor, progress=progress,
                               reader_options=reader_options, keep_raw=keep_raw)
        if refresh and result.changed:
            self.refresh(sorted(result.changed), executor=executor, progress=progress)
        return result

    def add_bytes(self, file_name: str, data: bytes, pack: str, refresh: bool = True,
                  **reader_options):
        """Add one file given as bytes (an upload); returns an AddResult (``refresh`` as
        :meth:`add`)."""
        from .ingest import add_upload

        with self._errors():
            result = add_upload(self._engine, (file_name, data), pack, reader_options)
        if refresh and result.changed:
            self.refresh(sorted(result.changed))
        return result

    def add_upload(self, path, pack: str, refresh: bool = True, **reader_options):
        """Add one uploaded file that the server received to ``path`` (a temporary file
        named as the upload): it is read from there once, stored under its name, and its
        location is not recorded. Returns an AddResult (``refresh`` as :meth:`add`)."""
        from .ingest import add_upload

        with self._errors():
            result = add_upload(self._engine, path, pack, reader_options)
        if refresh and result.changed:
            self.refresh(sorted(result.changed))
        return result

    def set_pack(self, name: str, *, label_capacity_Ah: float | None = None,
                 chemistry: str | None = None, cells: int | None = None,
                 refresh: bool = True) -> None:
        """Create a pack or store its label capacity [Ah], chemistry and cells in series
        (``refresh``: recompute its figures, as :meth:`add`)."""
        from ..ocv import check_chemistry
        from . import schema, store

        if chemistry is not None:
            check_chemistry(chemistry)
        if label_capacity_Ah is not None and not float(label_capacity_Ah) > 0:
            raise LogbookError(f"label_capacity_Ah must be positive, got {label_capacity_Ah!r}")
        if cells is not None and int(cells) < 1:
            raise LogbookError(f"cells must be at least 1, got {cells!r}")
        name = str(name).strip()
        with self._errors():
            schema.write(self._engine, lambda conn: store.set_pack(
                conn, name, label_capacity_Ah=label_capacity_Ah, chemistry=chemistry,
                cells=None if cells is None else int(cells)))
        if refresh:
            self.refresh([name])

    # ------------------------------------------------------------------ stored figures
    def refresh(self, names=None, executor=None, progress=None) -> list[str]:
        """Recompute and store the figures of the packs whose stored ones are stale.

        A pack's figures (health, forecast, fleet row, model curves: :mod:`.figures`)
        are stored with the pack's version; every write raises it. The writing methods
        refresh what they changed; this does the rest (after an upgrade, or a write made
        with ``refresh=False``).

        Parameters
        ----------
        names : list of str, optional
            Packs to look at (all by default); those already current are left alone.
        executor : optional
            Where the figures are computed (in this process by default).
        progress : callable, optional
            ``progress(done, total, message)`` after each pack.

        Returns
        -------
        list of str
            The packs recomputed.
        """
        return sorted(self._recompute(self.stale(names), executor, progress, store=True))

    def stale(self, names=None) -> list[str]:
        """Packs (among ``names``, all by default) whose stored figures are missing or older
        than their data or this code: what :meth:`refresh` would recompute."""
        from . import figures

        with self._errors(), self._read() as conn:
            return figures.stale_names(conn, names)

    def _recompute(self, names: list[str], executor=None, progress=None,
                   store: bool | None = True) -> dict:
        """Compute the figures of ``names`` (``{name: figures dict or one-line reason}``) and
        store them; ``store=None`` stores when the logbook can be written, else keeps them in
        memory (for reads of a read-only or full logbook)."""
        from ..errors import LogbookStorageError
        from ..fleet import InProcessExecutor
        from . import figures, schema

        out: dict = {}
        if not names:
            return out
        ids: dict = {}

        def jobs():
            # read as the executor asks for the next: only the jobs in flight are in memory
            for name in names:
                with self._errors(), self._read() as conn:
                    job = figures.read_job(conn, name)
                ids[name] = (job["row"]["id"], job["row"]["version"])
                yield job

        executor = executor or InProcessExecutor()
        failure = None
        storing = store is not False
        for done, (job, outcome) in enumerate(executor.map_unordered(figures.pack_figures,
                                                                     jobs()), 1):
            name = job["row"]["name"]
            if isinstance(outcome, DischargelabError):
                value, error = None, str(outcome).splitlines()[0]
            elif isinstance(outcome, BaseException):
                failure = failure or outcome
                continue
            else:
                value, error = outcome, None
            out[name] = error if value is None else value
            if storing:
                try:
                    with self._errors():
                        schema.write(self._engine, functools.partial(
                            figures.store_figures, pack_id=ids[name][0],
                            version=ids[name][1], figures=value, error=error))
                except LogbookStorageError as exc:
                    if store is True or exc.reason not in ("read-only", "full"):
                        raise
                    storing = False
            if progress is not None:
                progress(done, len(names), f"figures of {name}")
        if failure is not None:
            raise failure
        return out

    def _stored(self, names, columns: tuple, recompute: bool = True,
                store: bool = True) -> dict:
        """``{name: figures.Stored}`` of the packs named (all for None), stale ones computed
        first when ``recompute`` (stored when the logbook can be written and ``store``)."""
        from . import figures
        from . import store as stored_rows  # (not `store`: that is the argument)

        with self._errors(), self._read() as conn:
            found = figures.read_stored(conn, names, columns)
            if names is not None:
                for name in names:
                    if name not in found:
                        stored_rows.pack_row(conn, name)     # raises: no such pack
        stale = [n for n, s in found.items() if not s.current]
        if recompute and stale:
            for name, value in self._recompute(stale, store=None if store else False).items():
                error = value if isinstance(value, str) else None
                found[name] = figures.Stored(
                    name=name, pack_id=found[name].pack_id, current=True, error=error,
                    figures=None if error else {c: value[c] for c in columns})
        return found

    def _stored_one(self, name: str, columns: tuple, store: bool = True) -> dict:
        stored = self._stored([name], columns, store=store)[name]
        if stored.error:
            raise LogbookError(f"pack {name!r}: its figures cannot be computed: {stored.error}")
        return stored.figures

    def figures(self, name: str, recompute: bool = True):
        """What a pack page shows: its summary, health, model curves, all as stored.

        Parameters
        ----------
        name : str
        recompute : bool
            Recompute stale figures first (the library's reads). False answers from what
            is stored at once, with ``recomputing`` true when that is older than the pack
            (or missing): what the pages do, which never compute on a request.

        Returns
        -------
        dischargelab.logbook.figures.PackFigures
        """
        from .figures import PackFigures

        stored = self._stored([name], ("pack", "health", "model"), recompute)[name]
        return PackFigures.from_stored(stored)

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
            End of life as a share of the reference capacity (0 < eol < 1). The default
            one is read from the stored figures (recomputed first when stale); another
            is computed now.
        """
        eol = _check_eol(eol)
        if eol == DEFAULT_EOL:
            return Health.from_dict(self._stored_one(name, ("health",))["health"])
        row, events, model = self._pack_data(name)
        return build_health(row, events, model, eol)

    def events(self, name: str) -> EventTable:
        """The stored events of a pack (without their curves)."""
        from . import store
        from .health import order_events

        with self._errors(), self._read() as conn:
            row = store.pack_row(conn, name)
            events = store.pack_events(conn, row["id"], curves=False)
        rows = [{k: e.get(k) for k in EVENT_COLUMNS} for e in order_events(events)]
        return EventTable(pack=name, rows=rows)

    def packs(self, eol: float = DEFAULT_EOL, recompute: bool = True) -> PackTable:
        """One row per pack: events, EFC, capacity today, resistance, end of life.

        ``recompute=False`` answers from the stored figures at once (the pages): a pack
        whose figures are older than its data has its older row and ``recomputing``
        true, one with none stored only its name. A pack whose figures cannot be made
        has ``error``.
        """
        from .figures import ROW_KEYS

        eol = _check_eol(eol)
        if eol != DEFAULT_EOL:
            from .fleet_report import pack_summary

            return PackTable(rows=[
                {k: s[k] for k in ROW_KEYS} | {"recomputing": False}
                for s in (pack_summary((*self._pack_data(n), eol)) for n in self.pack_names())])
        from . import store

        found = self._stored(None, ("row",), recompute)
        counts = {}
        if not all(s.current for s in found.values()):    # a stale row's events are counted
            with self._errors(), self._read() as conn:
                counts = store.counts(conn)
        rows = []
        for name, stored in found.items():
            row = dict.fromkeys(ROW_KEYS)
            if stored.figures and stored.figures["row"]:
                row.update(stored.figures["row"])
            row.update(name=name, recomputing=not stored.current)
            if not stored.current:
                row["events"] = counts.get(stored.pack_id, 0)
            if stored.error:
                row["error"] = stored.error
            rows.append(row)
        return PackTable(rows=rows)

    def fleet(self, eol: float = DEFAULT_EOL, executor=None, progress=None):
        """Every pack's health, soonest end of life first (the fleet report).

        Parameters
        ----------
        eol : float
            End of life as a share of each pack's reference capacity.
        executor : optional
            Where the figures of packs whose stored ones are stale (or of every pack for
            another ``eol``) are made (:func:`dischargelab.fleet.executor`; in this process
            by default).
        progress : callable, optional
            ``progress(done, total, pack name)`` after each pack computed.

        Returns
        -------
        dischargelab.logbook.fleet_report.FleetReport
            ``.rows``, ``.retire_soon(efc)``, ``.to_html()``, ``.save(path)``.
        """
        from ..fleet import InProcessExecutor
        from .fleet_report import FleetReport, pack_summary, retire_order

        eol = _check_eol(eol)
        rows, failed = [], []
        if eol == DEFAULT_EOL:
            self.refresh(executor=executor, progress=progress)
            for name, stored in self._stored(None, ("fleet",)).items():
                if stored.error:
                    failed.append((name, stored.error))
                else:
                    rows.append(stored.figures["fleet"])
            return FleetReport(rows=sorted(rows, key=retire_order), eol=eol,
                               failed=sorted(failed))
        names = self.pack_names()
        jobs = ((*self._pack_data(name), eol) for name in names)
        executor = executor or InProcessExecutor()
        for done, (job, outcome) in enumerate(executor.map_unordered(pack_summary, jobs), 1):
            if isinstance(outcome, DischargelabError):
                failed.append((job[0]["name"], str(outcome).splitlines()[0]))
            elif isinstance(outcome, BaseException):
                raise outcome
            else:
                rows.append(outcome)
            if progress is not None:
                progress(done, len(names), job[0]["name"])
        return FleetReport(rows=sorted(rows, key=retire_order), eol=eol,
                           failed=sorted(failed))

    def pack(self, name: str, *, store: bool = True) -> Pack:
        """A pack with its health today; ``.battery()`` is its model at that health (its
        fitted model scaled to today, else the chemistry's prior at today's figures).

        ``store=False`` reads without writing anything: stale figures and a model fitted
        for ``.battery()`` are computed in memory only (what ``autopilot-params --pack``
        and ``autopilot-script --pack`` use)."""
        from . import store as stored_rows
        from .figures import make_pack
        from .refit import fit_job

        stored = self._stored_one(name, ("pack", "health"), store=store)
        health = Health.from_dict(stored["health"])
        with self._errors(), self._read() as conn:
            row = stored_rows.pack_row(conn, name)
            model = stored_rows.latest_model(conn, row["id"])
        fit = (lambda: self._fit(name, health)) if store else \
            (lambda: fit_job(self._job(name, health, {})))
        return make_pack(row, stored["pack"]["events"], health, model, fit=fit,
                         seen=stored["pack"].get("seen") or {})

    def model_today(self, name: str):
        """The model of a pack as of today, read without writing anything: what
        ``dischargelab report --pack`` reports and ``endurance --pack`` flies.

        :meth:`pack` with ``store=False``, then :meth:`Pack.battery`: a pack with a full
        discharge but no stored model has its model fitted in memory, not stored; a pack
        that only flies gets its chemistry's model built to its figures today. The
        Battery keeps the pack's identity (cells, strings, chemistry, cutoff) and its
        ``extra["note"]`` (which model, scaled to which figures of which events); a
        mission flown with it keeps them too (:mod:`dischargelab.identity`).

        Raises
        ------
        LogbookError
            No pack of that name (some of the logbook's names listed); a pack with no
            model yet: no fitted model, no full discharge to fit one to and no capacity
            to build its chemistry's model at (what to add is said).
        """
        names = self.pack_names()
        if name not in names:
            if not names:
                raise LogbookError(f"no pack named {name!r}: the logbook has no packs yet; "
                                   f"add a pack's files with `dischargelab logbook add FILES "
                                   f"--pack {name}`")
            shown = ", ".join(repr(n) for n in names[:SHOWN_PACK_NAMES])
            more = len(names) - SHOWN_PACK_NAMES
            raise LogbookError(f"no pack named {name!r} in the logbook; its packs: {shown}"
                               + (f" and {more} more" if more > 0 else "")
                               + " (`dischargelab logbook packs` lists them)")
        pack = self.pack(name, store=False)
        if not pack.fitted and not pack.has_full_discharge and pack.capacity_Ah is None \
                and not pack.label_capacity_Ah:
            raise LogbookError(f"pack {name!r} has no model yet: no full discharge to fit one "
                               f"to and no capacity to build its chemistry's model at; add a "
                               f"full discharge (`dischargelab logbook add FILE --pack {name}`) "
                               f"or its label capacity (`dischargelab logbook add FILES --pack "
                               f"{name} --capacity AH`)")
        return pack.battery()

    def flight_current(self, name: str) -> tuple[float, int] | None:
        """The typical pack current [A] of a pack's logged flights: the median of their mean
        currents, with the number of flights (None without flights)."""
        import statistics

        from . import store

        with self._errors(), self._read() as conn:
            row = store.pack_row(conn, name)
            events = store.pack_events(conn, row["id"], curves=False)
        means = [abs(float(e["mean_current_A"])) for e in events
                 if e.get("kind") == "flight" and e.get("mean_current_A")]
        if not means:
            return None
        return float(statistics.median(means)), len(means)

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
        from .refit import fit_job

        battery = self._store_model(fit_job(self._job(name, self.health(name), fit_options)))
        self.refresh([name])
        return battery

    def fit_all(self, executor=None, progress=None, **fit_options) -> dict:
        """Refit every pack from its latest full discharge: ``{name: Battery or reason}``.

        Parameters
        ----------
        executor : optional
            Where the fits run (:func:`dischargelab.fleet.executor`; in this process by
            default). The client reads the jobs and stores each model as it comes back.
        progress : callable, optional
            ``progress(done, total, pack name)`` after each pack.
        **fit_options
            As :func:`dischargelab.fit` (``model``, ``bootstrap``...).
        """
        from ..fleet import InProcessExecutor
        from .refit import fit_job

        out: dict = {}
        names = self.pack_names()
        done = 0

        def report(name: str) -> None:
            nonlocal done
            done += 1
            if progress is not None:
                progress(done, len(names), name)

        def jobs():
            # built as the executor asks for the next one: only the jobs in flight hold
            # their file's bytes, however many packs there are
            for name in names:
                try:
                    yield self._job(name, self.health(name), fit_options)
                except LogbookError as exc:
                    out[name] = str(exc)
                    report(name)

        executor = executor or InProcessExecutor()
        for job, outcome in executor.map_unordered(fit_job, jobs()):
            if isinstance(outcome, DischargelabError):
                out[job["pack"]] = f"cannot fit it: {str(outcome).splitlines()[0]}"
            elif isinstance(outcome, BaseException):
                raise outcome
            else:
                out[job["pack"]] = self._store_model(outcome)
            report(job["pack"])
        self.refresh(executor=executor, progress=progress)
        return dict(sorted(out.items()))

    def pack_names(self) -> list[str]:
        """Every pack's name, sorted."""
        from . import store

        with self._errors(), self._read() as conn:
            return store.pack_names(conn)

    def _job(self, name: str, health: Health, fit_options: dict) -> dict:
        """The refit job of a pack (see :mod:`.refit`)."""
        from . import store
        from .refit import build_job, latest_full

        last = latest_full(name, health)
        with self._errors(), self._read() as conn:
            source = store.source_of_event(conn, last.event_id)
            data = store.raw_file(conn, source["sha256"])
            row = store.pack_row(conn, name)
        return build_job(name, health, source, data, row, fit_options)

    def _store_model(self, model: dict):
        """Store a fitted model (a :func:`.refit.fit_job` result); returns its Battery."""
        from dataclasses import replace

        from ..model import Battery
        from . import schema, store

        def work(conn) -> None:
            row = store.pack_row(conn, model["pack"])
            store.save_model(conn, row["id"], model["battery"], model["event_id"],
                             model["capacity_Ah"], model["resistance_ohm"])

        with self._errors():
            schema.write(self._engine, work)
        bat = Battery.from_dict(model["battery"])
        extra = dict(bat.extra, logbook_fit={"capacity_Ah": model["capacity_Ah"],
                                             "resistance_ohm": model["resistance_ohm"]})
        return replace(bat, extra=extra)

    def _fit(self, name: str, health: Health, **fit_options):
        """Fit and store the model of one pack here; returns the stored model dict."""
        from .refit import fit_job

        model = fit_job(self._job(name, health, fit_options))
        self._store_model(model)
        self.refresh([name])
        return model

    # ------------------------------------------------------------------ export
    def own_files(self) -> list[Path]:
        """Files no output may replace, even with ``force``: the SQLite logbook itself and
        the files it keeps only by path (added with ``keep_raw=False``)."""
        from . import schema, store

        with self._errors(), self._read() as conn:
            kept_by_path = store.path_only_sources(conn)
        return schema.sqlite_files(self.url) + kept_by_path

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
        out = check_outputs([path], inputs=self.own_files(), force=force)[0]
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






def _check_eol(eol) -> float:
    if not 0 < float(eol) < 1:
        raise LogbookError(f"eol must lie between 0 and 1 (a share of the reference "
                           f"capacity), got {eol!r}")
    return float(eol)

__all__ = ["Logbook", "Health", "Forecast", "Pack", "PackTable", "EventTable", "DEFAULT_EOL"]
