"""The web application: pages, their static files and the JSON API (Starlette, ASGI).

:func:`create_app` builds it. Pages are static HTML + JavaScript shipped in the package
(``web/static``); they get every number from the JSON API, which calls the public library
(live bench, logbook). Nothing else is served: static files are looked up by exact name in a
table read at start-up, so no request path can reach the file system.

Every error is JSON ``{"error": "one line"}`` with a 4xx status (503 when busy, 5xx
otherwise only for a bug, which is logged; the server stays up). Outermost,
:class:`~dischargelab.web.connections.BodyDeadline` bounds the time a body may take, then
:class:`~dischargelab.web.guard.Guard` checks each request; the logbook and the physics run
in bounded thread pools (:mod:`~dischargelab.web.work`), never on the event loop.
"""

from __future__ import annotations

import asyncio
import json
from contextlib import asynccontextmanager

from ..errors import DataError, DischargelabError, require

require("starlette", "web")

from starlette.applications import Starlette  # noqa: E402
from starlette.exceptions import HTTPException  # noqa: E402
from starlette.requests import ClientDisconnect, Request  # noqa: E402
from starlette.responses import JSONResponse, Response, StreamingResponse  # noqa: E402
from starlette.routing import Route  # noqa: E402

from .assets import Assets  # noqa: E402
from .bench import BenchError, LiveBench  # noqa: E402
from .body import error, read_json  # noqa: E402
from .connections import BodyDeadline  # noqa: E402
from .guard import Guard, RequestRefused  # noqa: E402
from .limits import Limits  # noqa: E402
from .work import ClientGone, Workers  # noqa: E402

#: How often a connected live page gets the status numbers [s].
STATUS_EVERY_S = 0.5
#: Comment sent on an idle event stream so proxies and browsers keep it open [s].
KEEPALIVE_S = 15.0


def _sse(kind: str, data) -> bytes:
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    return f"event: {kind}\ndata: {text}\n\n".encode()


def create_app(logbook_url=None, live: LiveBench | None = None, token: str | None = None,
               limits: Limits | None = None, *, allowed_hosts=None, logbook=None):
    """The ASGI application of ``dischargelab serve``.

    Parameters
    ----------
    logbook_url : str, optional
        Database of the pack pages (see :class:`dischargelab.Logbook`); None = the default
        logbook. Opened on the first request that needs it.
    live : LiveBench, optional
        Source of the live page (an attached acquisition, or a demo bench); None = a bench
        with nothing running.
    token : str, optional
        When given, every request must carry it (``Authorization: Bearer TOKEN``, the
        ``dl_token`` cookie the page sets, or ``?token=`` once).
    limits : Limits, optional
        Time-outs, threads and sizes (default :class:`Limits`'s defaults).
    allowed_hosts : list of str, optional
        Host names accepted in the Host header (default: loopback names only, which
        refuses DNS-rebinding requests).
    logbook : Logbook, optional
        An opened logbook (instead of ``logbook_url``).

    Returns
    -------
    ASGI application
        The Starlette application inside its guards; ``.state`` holds ``bench``,
        ``packs``, ``workers`` and ``limits``.
    """
    from .packs import PackPages

    limits = limits or Limits()
    workers = Workers(limits)
    bench = live or LiveBench()
    assets = Assets.load()
    packs = PackPages(logbook_url, logbook=logbook, limits=limits, workers=workers)

    def page(name: str):
        async def endpoint(request: Request) -> Response:
            return assets.page(name)
        return endpoint

    async def static(request: Request) -> Response:
        return assets.static(request.path_params["name"])

    async def live_state(request: Request) -> Response:
        return JSONResponse(bench.state())

    async def live_start(request: Request) -> Response:
        settings = await read_json(request)
        try:
            started = await workers.work(request, bench.start, settings,
                                         what="tests being started")
        except BenchError as exc:
            return error(409, str(exc))
        except DischargelabError as exc:
            return error(400, str(exc))
        return JSONResponse(started)

    async def live_stop(request: Request) -> Response:
        await read_json(request)
        try:
            return JSONResponse(bench.stop())
        except BenchError as exc:
            return error(409, str(exc))

    async def live_stream(request: Request) -> Response:
        hub = bench.hub
        loop = asyncio.get_running_loop()
        sub = hub.subscribe(loop)

        async def events():
            try:
                yield b"retry: 1000\n\n"
                next_status = 0.0
                quiet_since = loop.time()
                while True:
                    item = hub.take(sub)
                    if item is not None:
                        kind, data = item
                        if kind == "snapshot":
                            data["status"] = bench.state()
                        yield _sse(kind, data)
                        quiet_since = loop.time()
                    now = loop.time()
                    if now >= next_status:
                        yield _sse("status", bench.state())
                        next_status = now + STATUS_EVERY_S
                        quiet_since = now
                    elif now - quiet_since >= KEEPALIVE_S:
                        yield b": keep-alive\n\n"
                        quiet_since = now
                    try:
                        await asyncio.wait_for(sub.wake.wait(), max(0.01, next_status - now))
                    except TimeoutError:
                        pass
            finally:
                hub.unsubscribe(sub)

        return StreamingResponse(events(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    async def not_found(request: Request, exc: Exception) -> Response:
        return error(404, f"nothing at {request.url.path}; the pages are /, /live and "
                          "/packs/NAME, the API is under /api/")

    async def http_error(request: Request, exc: HTTPException) -> Response:
        if exc.status_code == 405:
            return error(405, f"{request.method} is not allowed on {request.url.path}")
        return error(exc.status_code, str(exc.detail))

    async def refused(request: Request, exc: RequestRefused) -> Response:
        return error(exc.status, exc.message)

    async def bad_input(request: Request, exc: DataError) -> Response:
        return error(400, str(exc))

    async def gone(request: Request, exc: Exception) -> Response:
        return error(499, "the client closed the connection before the answer")

    @asynccontextmanager
    async def lifespan(app):
        try:
            yield
        finally:
            shutdown = getattr(bench, "shutdown", None)
            if shutdown is not None:
                await asyncio.to_thread(shutdown)
            packs.close()
            workers.close()

    routes = [
        Route("/", page("packs"), methods=["GET"]),
        Route("/live", page("live"), methods=["GET"]),
        Route("/packs/{name}", page("pack"), methods=["GET"]),
        Route("/static/{name}", static, methods=["GET"]),
        Route("/api/live", live_state, methods=["GET"]),
        Route("/api/live/stream", live_stream, methods=["GET"]),
        Route("/api/live/start", live_start, methods=["POST"]),
        Route("/api/live/stop", live_stop, methods=["POST"]),
        *packs.routes(),
    ]
    app = Starlette(routes=routes, lifespan=lifespan, exception_handlers={
        404: not_found, HTTPException: http_error, RequestRefused: refused, DataError: bad_input,
        ClientGone: gone, ClientDisconnect: gone})
    app.state.bench = bench
    app.state.packs = packs
    app.state.workers = workers
    app.state.limits = limits
    return BodyDeadline(Guard(app, token=token, allowed_hosts=allowed_hosts), limits)
