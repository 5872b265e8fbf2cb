"""Run the web application with uvicorn: bind rules, token, limits, foreground or background.

Listening on loopback (127.0.0.1) is the default. Any other address lets other machines
in, so it needs a token (:func:`check_bind`); the address printed at start carries it.
The socket is bound here, before uvicorn starts, so a busy port is a clear one-line error.
uvicorn runs our h11 protocol (:func:`dischargelab.web.connections.protocol_class`: head
time-out, connection caps) whatever else is installed.
"""

from __future__ import annotations

import ipaddress
import re
import secrets
import socket
import threading
import time
from dataclasses import dataclass

from ..errors import DischargelabError, require
from .guard import LOOPBACK_HOSTS

#: Default port of ``dischargelab serve``.
DEFAULT_PORT = 8050
#: Seconds open event streams get to close when the server stops.
SHUTDOWN_GRACE_S = 1.0
#: Connections the kernel queues before the server accepts them.
BACKLOG = 2048
#: File descriptors kept free of connections (logbook, temporary files, threads).
SPARE_FILES = 64


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def new_token() -> str:
    """A random token (32 URL-safe characters, 192 bits)."""
    return secrets.token_urlsafe(24)


#: What a token given by the user may hold: URL- and cookie-safe characters, long enough.
TOKEN_PATTERN = re.compile(r"[A-Za-z0-9._~-]{12,200}")


def check_bind(host: str, token: str | None) -> None:
    """Refuse to listen beyond loopback without a token, or with one that a URL or a
    cookie cannot carry (one-line DischargelabError)."""
    if token and not TOKEN_PATTERN.fullmatch(token):
        raise DischargelabError("the token must be 12-200 letters, digits or '.', '_', '~', "
                                "'-' (it travels in a URL and a cookie); leave it out for a "
                                "random one")
    if not is_loopback(host) and not token:
        raise DischargelabError(
            f"listening on {host} lets other machines reach the server: give it a token too, "
            "or keep the default host 127.0.0.1")


@dataclass
class Listening:
    """Where a started server listens: ``url`` (with ``?token=`` when there is one)."""

    host: str
    port: int
    token: str | None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        base = f"http://{host}:{self.port}/"
        return f"{base}?token={self.token}" if self.token else base

    def page(self, path: str) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        query = f"?token={self.token}" if self.token else ""
        return f"http://{host}:{self.port}/{path.lstrip('/')}{query}"


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (port 0 = any free port)."""
    family = socket.AF_INET6 if ":" in host.strip("[]") else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host.strip("[]"), int(port)))
    except OSError as exc:
        sock.close()
        if exc.errno in (98, 48, 10048):                 # EADDRINUSE on Linux, macOS, Windows
            raise DischargelabError(f"port {port} on {host} is in use; choose another "
                                    "port (port=0 picks a free one)") from None
        raise DischargelabError(f"cannot listen on {host}:{port}: {exc.strerror or exc}"
                                ) from None
    sock.listen(BACKLOG)
    sock.set_inheritable(True)
    return sock


def open_files_for(connections: int) -> None:
    """Raise this process's limit of open files (up to the hard limit) so that
    ``connections`` connections fit; DischargelabError when the hard limit is too low."""
    try:
        import resource
    except ImportError:                                  # not on Windows
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = connections + SPARE_FILES
    if soft != resource.RLIM_INFINITY and soft < need:
        top = need if hard == resource.RLIM_INFINITY else min(need, hard)
        resource.setrlimit(resource.RLIMIT_NOFILE, (top, hard))
        soft = top
    if soft != resource.RLIM_INFINITY and soft < need:
        raise DischargelabError(
            f"{connections} connections need {need} open files, and this system allows "
            f"{soft}: lower max_connections to {soft - SPARE_FILES} or raise the limit "
            "(ulimit -n)")


class Server:
    """A uvicorn server for ``app`` on an already bound socket.

    Parameters
    ----------
    app : ASGI application (:func:`dischargelab.web.create_app`)
    host, port : str, int
    token : str, optional
        Required when ``host`` is not loopback.
    limits : Limits, optional
        Time-outs and connection caps (default :class:`~dischargelab.web.limits.Limits`).
    """

    def __init__(self, app, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 token: str | None = None, limits=None):
        from .connections import protocol_class
        from .limits import Limits

        uvicorn = require("uvicorn", "web")
        limits = limits or Limits()
        check_bind(host, token)
        open_files_for(limits.max_connections)
        self.sock = bind(host, port)
        self.app = app
        self.limits = limits
        self.listening = Listening(host, self.sock.getsockname()[1], token)
        config = uvicorn.Config(app, log_level="warning", access_log=False, lifespan="on",
                                timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
                                http=protocol_class(limits), backlog=BACKLOG,
                                timeout_keep_alive=limits.keep_alive_s)
        self._server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    def app_state(self, name: str):
        """An object the application keeps (``"bench"``, ``"packs"``)."""
        return getattr(self.app.state, name)

    @property
    def started(self) -> bool:
        return bool(self._server.started)

    def run(self) -> None:
        """Serve in this thread until stopped (Ctrl-C / SIGTERM in the main thread)."""
        try:
            self._server.run(sockets=[self.sock])
        finally:
            self.sock.close()

    def start(self, timeout_s: float = 10.0) -> Server:
        """Serve from a background thread; returns once it accepts connections."""
        self._thread = threading.Thread(target=self.run, name="dischargelab-web", daemon=True)
        self._thread.start()
        for _ in range(int(timeout_s / 0.02)):
            if self._server.started or not self._thread.is_alive():
                break
            time.sleep(0.02)
        if not self._server.started:
            raise DischargelabError("the web server did not start")
        return self

    def stop(self, timeout_s: float = 10.0) -> None:
        """Ask the server to finish and wait for its thread."""
        self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout_s)


def build_server(*, db=None, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 token: str | None = None, demo: bool = False, runs=None, live=None,
                 limits=None, public_hosts=()) -> Server:
    """The server ``dischargelab serve`` runs (not started yet; see :meth:`Server.run`).

    Parameters
    ----------
    db : str, optional
        Logbook database (URL or SQLite path); None = the default logbook.
    host, port, token
        As :class:`Server`; ``token="auto"`` makes a random one (:func:`new_token`).
    demo : bool
        The live page starts virtual-logger tests (:class:`~dischargelab.web.bench.DemoBench`);
        their log files go to ``runs`` (default: a new temporary folder).
    live : LiveBench, optional
        An attached bench instead (``acquire ... --serve``).
    limits : Limits, optional
        Time-outs, connection caps, threads, upload size (default
        :class:`~dischargelab.web.limits.Limits`).
    public_hosts : sequence of str
        Host names the server also answers to on loopback: the name a reverse proxy in
        front of it passes on in the Host header (``dl.example.org``).
    """
    import tempfile

    from .app import create_app
    from .bench import DemoBench
    from .limits import Limits

    if token == "auto":
        token = new_token()
    check_bind(host, token)
    if demo:
        live = DemoBench(runs or tempfile.mkdtemp(prefix="dischargelab-runs-"), hub=None)
    limits = limits or Limits()
    app = create_app(db, live=live, token=token, limits=limits,
                     allowed_hosts=[*LOOPBACK_HOSTS, *public_hosts] if is_loopback(host)
                     else ["*"])
    return Server(app, host, port, token, limits)
