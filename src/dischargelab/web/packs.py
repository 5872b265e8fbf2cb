"""The logbook's JSON API: pack list, one pack, upload, fit and endurance.

Every handler calls the public library (:class:`dischargelab.Logbook`,
:func:`dischargelab.endurance`, :func:`dischargelab.simulate.curve_family`) in a worker
thread (:mod:`~dischargelab.web.work`: reads and heavy work in separate bounded pools) and
returns its ``to_dict()``; nothing here computes a battery quantity. Answers name things
(packs, files, missions), never a path on the server. The pack list and a pack page read
the figures the logbook stores (:mod:`dischargelab.logbook.figures`) and never compute
them: a pack whose stored figures are older than its data is answered as stored with
``recomputing`` true, and one thread of the server recomputes it in the background.
"""

from __future__ import annotations

import logging
import math
import re
import shutil
import tempfile
import threading

from starlette.requests import Request
from starlette.responses import JSONResponse, PlainTextResponse, Response
from starlette.routing import Route

from ..errors import DischargelabError, MissingExtraError
from ..formatting import pack_text
from .body import check_length, error, read_json
from .guard import RequestRefused
from .limits import Limits
from .upload import UploadReader
from .work import Workers

#: A pack name: what the logbook's command line accepts, 1-100 characters, no control
#: characters and no slash.
_PACK_NAME = re.compile(r"^[^\x00-\x1f\x7f/\\]{1,100}$")
#: What a pack page says when no model is stored.
NO_MODEL = "no model fitted yet — Refit"


#: Files the pack page offers for the autopilot (GET /api/packs/NAME/autopilot/FILE).
AUTOPILOT_FILES = ("ardupilot.param", "ardupilot.lua")


def check_pack_name(name: str) -> str:
    name = (name or "").strip()
    if not _PACK_NAME.match(name) or name in (".", ".."):
        raise RequestRefused(400, "pack name must be 1-100 characters without '/', '\\' or "
                                  "control characters, and not '.' or '..'")
    return name


_PLAIN = (str, int, bool, type(None))


def _clean(value):
    """JSON-safe copy: NaN and infinities become None, tuples lists, numpy scalars floats.

    The common types are recognised by identity first: a pack page holds thousands of
    floats, and this walk is on every answer."""
    kind = type(value)
    if kind is float:
        return value if math.isfinite(value) else None
    if kind is dict:
        return {k if type(k) is str else str(k): _clean(v) for k, v in value.items()}
    if kind is list or kind is tuple:
        return [_clean(v) for v in value]
    if kind in _PLAIN:
        return value
    if isinstance(value, dict):
        return _clean(dict(value))
    if isinstance(value, (list, tuple)):
        return _clean(list(value))
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):
        return _clean(value.item())             # numpy scalars
    if isinstance(value, float):
        return _clean(float(value))
    if isinstance(value, _PLAIN):
        return value
    return str(value)


#: Seconds the server waits at shutdown for the pack being recomputed.
REFRESH_JOIN_S = 60.0


class PackPages:
    """Routes of the logbook API; the logbook is opened at the first request needing it.

    Parameters
    ----------
    url : str, optional
        The logbook (see :class:`dischargelab.Logbook`).
    logbook : Logbook, optional
        An opened logbook instead.
    limits : Limits
    workers : Workers
        Where the logbook is read and the heavy work runs.
    """

    def __init__(self, url=None, *, logbook=None, limits: Limits, workers: Workers):
        self.url = url
        self._logbook = logbook
        self._own = logbook is None
        self.limits = limits
        self.workers = workers
        self._lock = threading.Lock()
        #: Uploads being received or stored now.
        self.uploads = 0
        self._refresher: threading.Thread | None = None
        self._refresh_again = False
        self._stop = threading.Event()
        #: Why the stale figures cannot be recomputed (a read-only logbook), for the pages.
        self.refresh_problem: str | None = None

    # ------------------------------------------------------------------ logbook
    def logbook(self):
        with self._lock:
            if self._logbook is None:
                try:
                    from ..logbook import Logbook
                except ImportError as exc:
                    raise MissingExtraError("the logbook needs SQLAlchemy; install it with: "
                                            "pip install 'dischargelab[logbook]'") from exc
                self._logbook = Logbook(self.url)
            return self._logbook

    def close(self) -> None:
        self._stop.set()
        refresher = self._refresher
        if refresher is not None:
            refresher.join(timeout=REFRESH_JOIN_S)
        lb = self._logbook
        if self._own and lb is not None and hasattr(lb, "close"):
            lb.close()

    # ------------------------------------------------------------------ stale figures
    def refresh_soon(self) -> None:
        """Recompute the stale packs' figures in the background (one thread; asked again
        while it runs, it looks once more when done)."""
        with self._lock:
            if self._refresher is not None:
                self._refresh_again = True
                return
            self._refresher = threading.Thread(target=self._refresh_loop, daemon=True,
                                               name="dischargelab-figures")
            self._refresher.start()

    def _refresh_loop(self) -> None:
        from ..errors import LogbookStorageError

        try:
            while not self._stop.is_set():
                lb = self.logbook()
                for name in lb.stale():
                    if self._stop.is_set():
                        return
                    lb.refresh([name])
                self.refresh_problem = None
                with self._lock:
                    if not self._refresh_again:
                        return
                    self._refresh_again = False
        except LogbookStorageError as exc:
            self.refresh_problem = f"the figures cannot be recomputed: {exc}"
        except DischargelabError:
            logging.getLogger(__name__).exception("recomputing the stored figures failed")
        finally:
            with self._lock:
                self._refresher = None

    def _known(self, name: str) -> str:
        name = check_pack_name(name)
        if name not in self.logbook().pack_names():
            raise RequestRefused(404, f"no pack named {name!r} in the logbook")
        return name

    @staticmethod
    async def _call(run, request, func, *args):
        """``run(request, func, *args)`` (a :class:`Workers` method), the library's errors
        turned into one-line 4xx answers."""
        try:
            return await run(request, func, *args)
        except RequestRefused:
            raise
        except MissingExtraError as exc:
            raise RequestRefused(503, str(exc)) from None
        except DischargelabError as exc:
            raise RequestRefused(400, str(exc)) from None

    # ------------------------------------------------------------------ handlers
    def routes(self) -> list[Route]:
        return [
            Route("/api/packs", self.list_packs, methods=["GET"]),
            Route("/api/packs/{name}", self.one_pack, methods=["GET"]),
            Route("/api/packs/{name}/endurance", self.endurance, methods=["POST"]),
            Route("/api/packs/{name}/fit", self.refit, methods=["POST"]),
            Route("/api/packs/{name}/autopilot/{file}", self.autopilot_file, methods=["GET"]),
            Route("/api/missions", self.missions, methods=["GET"]),
            Route("/api/upload", self.upload, methods=["POST"]),
        ]

    async def list_packs(self, request: Request) -> Response:
        # the rows are the stored figures' JSON as read (plain, no NaN): sent as they are
        rows = await self._call(self.workers.read, request,
                                lambda: self.logbook().packs(recompute=False).rows)
        # each figure also as the one text every view writes (formatting.py)
        rows = [dict(r, text=pack_text(r)) for r in rows]
        data = {"rows": rows}
        if any(r.get("recomputing") for r in rows):
            self.refresh_soon()
            data["recompute_problem"] = self.refresh_problem
        return JSONResponse(data)

    def _pack_detail(self, name: str) -> dict:
        """What is stored about a pack, read only: a GET never computes, fits or writes (a
        pack without a stored model says so; the refit is ``POST /api/packs/NAME/fit``)."""
        name = self._known(name)
        lb = self.logbook()
        figures = lb.figures(name, recompute=False)
        summary = figures.summary or {"name": name,
                                      "events": len(lb.events(name).to_dict()["events"])}
        summary = dict(summary, text=pack_text(summary))
        out = {"name": name, "summary": summary,
               "health": figures.health, "model": None, "model_note": None,
               "recomputing": figures.recomputing, "error": figures.error}
        if figures.recomputing:
            self.refresh_soon()
            out["recompute_problem"] = self.refresh_problem
        model = figures.model
        if model is None:
            out["model_note"] = NO_MODEL
        elif "curves" not in model:
            out["model_note"] = model["note"]
        else:
            out["model"] = model
        return out

    async def one_pack(self, request: Request) -> Response:
        # stored figures' JSON and the events' to_dict(): plain already
        data = await self._call(self.workers.read, request, self._pack_detail,
                                request.path_params["name"])
        return JSONResponse(data)

    async def missions(self, request: Request) -> Response:
        from ..mission import bundled_missions

        return JSONResponse({"missions": sorted(bundled_missions())})

    def _endurance(self, name: str, mission: str) -> dict:
        import dischargelab as dl

        from ..mission import bundled_missions

        name = self._known(name)
        if mission not in bundled_missions():
            raise RequestRefused(400, f"unknown mission {mission!r}; choose one of "
                                      f"{', '.join(sorted(bundled_missions()))}")
        pack = self.logbook().pack(name, store=False)  # a read: nothing stored
        if not pack.fitted and pack.has_full_discharge:  # flying would fit one first
            raise RequestRefused(409, f"pack {name!r} has no fitted model yet; refit it first "
                                      f"(Refit, or POST /api/packs/{name}/fit)")
        return dl.endurance(pack, mission).to_dict()

    async def endurance(self, request: Request) -> Response:
        body = await self._json(request)
        mission = body.get("mission")
        if not isinstance(mission, str) or not mission:
            raise RequestRefused(400, "give the mission's name: {\"mission\": \"paper-table5\"}")
        data = await self._call(self.workers.work, request, self._endurance,
                                request.path_params["name"], mission)
        return JSONResponse(_clean(data))

    def _refit(self, name: str) -> dict:
        name = self._known(name)
        battery = self.logbook().fit(name)
        return {"pack": name, "model": battery.name, "family": battery.model,
                "battery": battery.to_dict()}

    async def refit(self, request: Request) -> Response:
        await self._json(request)
        data = await self._call(self.workers.work, request, self._refit,
                                request.path_params["name"])
        return JSONResponse(_clean(data))

    def _autopilot_file(self, name: str, file: str) -> str:
        """The pack's ArduPilot parameter file or Lua script, made from its model today and
        its flights' typical current, without writing to the logbook."""
        from ..autopilot import autopilot_params
        from ..onboard import autopilot_script

        name = self._known(name)
        if file not in AUTOPILOT_FILES:
            raise RequestRefused(404, f"no file {file!r}; choose one of "
                                      f"{', '.join(AUTOPILOT_FILES)}")
        lb = self.logbook()
        battery = lb.model_today(name)
        typical = lb.flight_current(name)
        amps = typical[0] if typical else None
        if file == "ardupilot.lua":
            return autopilot_script(battery, load_current_A=amps).text
        source = (f"the median mean current of the pack's {typical[1]} logged flight(s)"
                  if typical else None)
        return autopilot_params(battery, firmware="ardupilot", load_current_A=amps,
                                load_source=source).text()

    async def autopilot_file(self, request: Request) -> Response:
        name, file = request.path_params["name"], request.path_params["file"]
        text = await self._call(self.workers.work, request, self._autopilot_file, name, file)
        return PlainTextResponse(text, headers={
            "Content-Disposition": f'attachment; filename="{check_pack_name(name)}-{file}"'})

    async def _json(self, request: Request) -> dict:
        return await read_json(request)

    async def upload(self, request: Request) -> Response:
        # Only a few uploads are received and stored at once (each is parsed in a work
        # thread); the rest are told to try again (503) instead of waiting.
        limits = self.limits
        if self.uploads >= limits.max_uploads:
            raise RequestRefused(503, f"{limits.max_uploads} uploads are being stored; "
                                      "try again when one has finished")
        self.uploads += 1
        folder = None
        try:
            try:
                folder = tempfile.mkdtemp(prefix="dischargelab-upload-")
            except OSError as exc:
                raise RequestRefused(507, "no room on the server to receive the upload "
                                          f"({exc.strerror or exc}); try again later") from None
            received = await self._receive_upload(request, folder)
            pack = check_pack_name(received.pack)
            result = await self._call(self.workers.work, request,
                                      lambda: self.logbook().add_upload(received.path, pack,
                                                                        refresh=False))
        finally:
            self.uploads -= 1
            if folder is not None:
                shutil.rmtree(folder, ignore_errors=True)
        if result.changed:
            self.refresh_soon()     # the figures are recomputed off the request
        if result.rejected:
            return error(422, f"{received.path.name}: {result.rejected[0][1]}")
        return JSONResponse(_clean(result.to_dict()))

    async def _receive_upload(self, request: Request, folder: str):
        """The request body streamed into ``folder`` (see :class:`UploadReader`)."""
        limit = self.limits.max_upload_bytes
        check_length(request, limit, "upload")
        reader = UploadReader(request.headers.get("content-type", ""), folder)
        size = 0
        try:
            async for chunk in request.stream():
                size += len(chunk)
                if size > limit:
                    raise RequestRefused(413, f"upload is over the limit of {limit} bytes")
                reader.write(chunk)
            return reader.finish()
        finally:
            reader.close()
