"""How long a connection may take and how many one client may hold (uvicorn + ASGI).

uvicorn closes an idle kept-alive connection (``timeout_keep_alive``) but waits for ever on
a connection that sends half a request head, or a body a byte at a time: a few hundred
such clients would hold the server. Two guards close them:

- :func:`protocol_class`: uvicorn's h11 protocol with a **head time-out** (the whole request
  head within :attr:`Limits.header_timeout_s` of the connection opening or of the previous
  answer; 408 if part of a request came, else closed silently) and **connection caps** (all
  connections, and per client address: 503 / 429, then closed).
- :class:`BodyDeadline`: an ASGI middleware giving the request body
  :attr:`Limits.body_timeout_s` plus ``1 / body_min_rate_Bps`` per byte received, counting
  only the time the application spends waiting for the client (408 beyond). An answer sent
  before the body was read whole closes the connection, so the rest of an unread upload is
  never read.

References
----------
Apache HTTP Server, mod_reqtimeout (``RequestReadTimeout header=...,MinRate=... body=...``);
nginx, ``client_header_timeout`` and ``client_body_timeout``; RFC 9110, 15.5.9 (408).
"""

from __future__ import annotations

import asyncio
import json

from .guard import SECURITY_HEADERS, RequestRefused
from .limits import Limits


def _raw_answer(status: int, reason: str, message: str) -> bytes:
    """A whole HTTP/1.1 answer that closes the connection (JSON ``{"error": message}``)."""
    body = json.dumps({"error": message}).encode()
    head = [f"HTTP/1.1 {status} {reason}", "content-type: application/json",
            f"content-length: {len(body)}", "connection: close"]
    head += [f"{k.decode()}: {v.decode()}" for k, v in SECURITY_HEADERS]
    return ("\r\n".join(head) + "\r\n\r\n").encode("latin-1") + body


def protocol_class(limits: Limits):
    """A uvicorn HTTP protocol class (h11) enforcing the head time-out and the caps.

    Parameters
    ----------
    limits : Limits

    Returns
    -------
    type
        A subclass of ``uvicorn.protocols.http.h11_impl.H11Protocol``; give it to
        ``uvicorn.Config(http=...)``. Each server gets its own class (its own counts).
    """
    from uvicorn.protocols.http.h11_impl import H11Protocol

    per_client: dict[str, int] = {}     # open connections by address (event loop only)
    timeout = limits.header_timeout_s
    late = _raw_answer(408, "Request Timeout",
                       f"the request head did not arrive within {timeout:g} s; the "
                       "connection is closed (send the whole request at once)")
    full = _raw_answer(503, "Service Unavailable",
                       f"the server holds its maximum of {limits.max_connections} "
                       "connections; try again in a few seconds")
    crowded = _raw_answer(429, "Too Many Requests",
                          f"this address holds its maximum of "
                          f"{limits.max_connections_per_client} connections to the server; "
                          "close some or try again in a few seconds")

    class GuardedH11Protocol(H11Protocol):
        """uvicorn's h11 protocol with a head time-out and connection caps."""

        def connection_made(self, transport) -> None:
            self._dl_timer = None
            self._dl_bytes = 0
            self._dl_refused = False
            peer = transport.get_extra_info("peername")
            self._dl_peer = str(peer[0]) if peer else ""
            refusal = None
            if len(self.server_state.connections) >= limits.max_connections:
                refusal = full
            elif (limits.max_connections_per_client
                  and per_client.get(self._dl_peer, 0) >= limits.max_connections_per_client):
                refusal = crowded
            if refusal is not None:
                self._dl_refused = True
                transport.write(refusal)
                transport.close()
                return
            per_client[self._dl_peer] = per_client.get(self._dl_peer, 0) + 1
            super().connection_made(transport)
            self._dl_arm()

        def connection_lost(self, exc) -> None:
            if self._dl_refused:
                return
            self._dl_disarm()
            left = per_client.get(self._dl_peer, 1) - 1
            if left > 0:
                per_client[self._dl_peer] = left
            else:
                per_client.pop(self._dl_peer, None)
            super().connection_lost(exc)

        def data_received(self, data: bytes) -> None:
            if self._dl_refused:
                return
            self._dl_bytes += len(data)
            before = self.cycle
            super().data_received(data)
            if self.cycle is not before:        # a whole head came: its request runs
                self._dl_disarm()

        def on_response_complete(self) -> None:
            before = self.cycle
            super().on_response_complete()
            if self.cycle is before and not self.transport.is_closing():
                self._dl_arm()                  # the next request's head starts now

        def _dl_arm(self) -> None:
            self._dl_disarm()
            self._dl_bytes = len(self.conn.trailing_data[0])    # a pipelined request's start
            self._dl_timer = self.loop.call_later(timeout, self._dl_head_timed_out)

        def _dl_disarm(self) -> None:
            if self._dl_timer is not None:
                self._dl_timer.cancel()
                self._dl_timer = None

        def _dl_head_timed_out(self) -> None:
            self._dl_timer = None
            if self.transport.is_closing():
                return
            if self._dl_bytes:
                self.transport.write(late)
            self.transport.close()

    return GuardedH11Protocol


def _expects_body(scope) -> bool:
    for key, value in scope.get("headers", []):
        if key == b"transfer-encoding":
            return True
        if key == b"content-length":
            return value.strip() not in (b"0", b"")
    return False


class BodyDeadline:
    """ASGI middleware: a time limit on reading the request body (see the module docstring).

    Parameters
    ----------
    app : ASGI application
    limits : Limits
    """

    def __init__(self, app, limits: Limits):
        self.app = app
        self.limits = limits
        self.state = getattr(app, "state", None)

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limits = self.limits
        loop = asyncio.get_running_loop()
        body = {"done": not _expects_body(scope), "received": 0, "waited": 0.0}

        async def timed_receive():
            if body["done"]:
                return await receive()
            allowed = (limits.body_timeout_s + body["received"] / limits.body_min_rate_Bps
                       - body["waited"])
            started = loop.time()
            try:
                if allowed <= 0:
                    raise TimeoutError
                async with asyncio.timeout(allowed):
                    message = await receive()
            except TimeoutError:
                raise RequestRefused(
                    408, f"the request body came slower than {limits.body_min_rate_Bps:g} "
                         f"bytes/s after {limits.body_timeout_s:g} s ({body['received']} "
                         "bytes received); the connection is closed") from None
            finally:
                body["waited"] += loop.time() - started
            if message["type"] == "http.request":
                body["received"] += len(message.get("body", b""))
                body["done"] = not message.get("more_body", False)
            else:
                body["done"] = True             # the client has gone
            return message

        async def send_closing(message):
            if message["type"] == "http.response.start" and not body["done"]:
                message = {**message, "headers": [*message.get("headers", []),
                                                  (b"connection", b"close")]}
            await send(message)

        await self.app(scope, timed_receive, send_closing)
