"""Checks every request passes before the application sees it (an ASGI middleware).

In order: a path that climbs (``..``) or hides a separator, raw or percent-encoded once or
more, is refused (400); the Host header must name this server (421; refuses DNS rebinding);
a state-changing request from another site is refused (403, checked with the Origin
header); with a token, the request must carry it (401). Every response gets headers that
keep the pages to their own files (Content-Security-Policy) and out of frames.
"""

from __future__ import annotations

import hmac
import json
import re
from http.cookies import CookieError, SimpleCookie
from urllib.parse import parse_qs, unquote, urlsplit

#: Host names a loopback-only server answers to.
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1", "[::1]")
#: Cookie that carries the token after the first ``?token=`` visit.
TOKEN_COOKIE = "dl_token"
#: Times a path is percent-decoded when looking for a hidden ``..`` (``%252e`` -> ``%2e`` -> .).
DECODE_ROUNDS = 4

SECURITY_HEADERS = [
    (b"content-security-policy",
     b"default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
     b"connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'"),
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
]

_BAD_SEGMENT = re.compile(r"(^|/)\.\.?(/|$)")


class RequestRefused(Exception):
    """A request refused with an HTTP status and a one-line reason."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status
        self.message = message


def path_problem(raw_path: str) -> str | None:
    """Why a request path is refused (None if it is fine): ``..``/``.`` segments,
    backslashes or NUL, in the raw path or after any of :data:`DECODE_ROUNDS` decodings."""
    text = raw_path
    for _ in range(DECODE_ROUNDS + 1):
        if "\\" in text or "\x00" in text:
            return "backslash or NUL in the path"
        if _BAD_SEGMENT.search(text):
            return "'..' or '.' in the path (path traversal is refused)"
        decoded = unquote(text)
        if decoded == text:
            return None
        text = decoded
    return "the path is encoded too many times"


def _host_name(host: str) -> str:
    host = host.strip().lower()
    if host.startswith("["):
        return host[:host.find("]") + 1] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


class Guard:
    """ASGI middleware around the application (see the module docstring).

    Parameters
    ----------
    app : ASGI application
    token : str, optional
    allowed_hosts : list of str, optional
        Host names accepted; default :data:`LOOPBACK_HOSTS`. ``["*"]`` accepts any.
    """

    def __init__(self, app, *, token: str | None = None, allowed_hosts=None):
        self.app = app
        self.token = token or None
        hosts = LOOPBACK_HOSTS if allowed_hosts is None else allowed_hosts
        self.allowed_hosts = {h.lower() for h in hosts}
        self.state = getattr(app, "state", None)

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        try:
            set_cookie = self._check(scope)
        except RequestRefused as exc:
            await _send_json(send, exc.status, {"error": exc.message})
            return

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                headers += SECURITY_HEADERS
                if set_cookie:
                    headers.append((b"set-cookie", set_cookie))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)

    def _check(self, scope) -> bytes | None:
        raw = scope.get("raw_path") or scope.get("path", "").encode()
        why = path_problem(raw.decode("latin-1")) or path_problem(scope.get("path", ""))
        if why:
            raise RequestRefused(400, why)
        headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                   for k, v in scope.get("headers", [])}
        host = headers.get("host", "")
        if "*" not in self.allowed_hosts and _host_name(host) not in self.allowed_hosts:
            raise RequestRefused(421, f"this server does not answer to host {host!r}")
        if scope.get("method") not in ("GET", "HEAD", "OPTIONS"):
            origin = headers.get("origin")
            if origin is not None and urlsplit(origin).netloc.lower() != host.lower():
                raise RequestRefused(403, "request from another site refused")
        if self.token is None:
            return None
        given = None
        auth = headers.get("authorization", "")
        if auth.lower().startswith("bearer "):
            given = auth[7:].strip()
        query_token = parse_qs(scope.get("query_string", b"").decode("latin-1")).get("token")
        if given is None and query_token:
            given = query_token[0]
        if given is None and "cookie" in headers:
            cookie = SimpleCookie()
            try:
                cookie.load(headers["cookie"])
            except CookieError:                 # a malformed cookie header carries no token
                cookie = SimpleCookie()
            if TOKEN_COOKIE in cookie:
                given = cookie[TOKEN_COOKIE].value
        if given is None or not hmac.compare_digest(given.encode(), self.token.encode()):
            raise RequestRefused(401, "this server needs its token: open the address printed "
                                      "when it started (it ends in ?token=...)")
        if query_token:
            return (f"{TOKEN_COOKIE}={self.token}; HttpOnly; SameSite=Strict; Path=/"
                    ).encode("latin-1")
        return None


async def _send_json(send, status: int, data: dict) -> None:
    body = json.dumps(data).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode()), *SECURITY_HEADERS]})
    await send({"type": "http.response.body", "body": body})
