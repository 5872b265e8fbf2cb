"""What the server lets one request, one client and all of them together hold, and for how long.

One :class:`Limits` object carries every limit of ``dischargelab serve``: the time-outs that
close slow or idle connections (:mod:`~dischargelab.web.connections` enforces them), the
connection caps, the worker threads that run the logbook and the physics off the event
loop (:mod:`~dischargelab.web.work`), and the upload size and count. The defaults hold a
team of a few dozen people on one machine; ``docs/web.md`` says when to change them.

References
----------
The time-outs follow Apache's mod_reqtimeout (a fixed time for the request head, a body
time that grows with a minimum rate) and nginx's ``client_header_timeout`` /
``client_body_timeout``; see also uvicorn's deployment notes (``timeout_keep_alive``,
a proxy in front).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from ..errors import DataError

#: Largest upload accepted by default [bytes] (a long 50 Hz log is a few MB).
MAX_UPLOAD_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class Limits:
    """Limits of one server.

    Attributes
    ----------
    header_timeout_s : float
        Time a connection gets to send a whole request head [s], counted from its opening
        (or from the end of the previous answer on a kept-alive connection). Closes idle
        and half-sent connections (408 when part of a request came).
    body_timeout_s : float
        Time the server waits for a request body [s], before :attr:`body_min_rate_Bps`
        extends it; only time spent waiting for the client counts.
    body_min_rate_Bps : float
        Each byte received extends the body time by ``1 / body_min_rate_Bps`` [s]: a body
        slower than this on average is cut off (408) [bytes/s].
    keep_alive_s : float
        An idle kept-alive connection is closed after this [s] (uvicorn's
        ``timeout_keep_alive``).
    max_connections : int
        Open connections at most; one more is answered 503 and closed.
    max_connections_per_client : int
        Open connections from one address at most (429 beyond); 0 = no cap. Leave it at 0
        behind a reverse proxy: every connection then comes from the proxy.
    read_threads : int
        Threads answering logbook reads (pack list, pack page) at once; more wait.
    work_threads : int
        Threads for the heavy work (parsing and storing uploads, refits, missions): kept
        apart from the reads, so a long refit never holds a page.
    max_waiting_work : int
        Refits and missions waiting for a work thread at most; one more gets 503.
    max_uploads : int
        Uploads received and stored at once; one more gets 503 and a line to try again.
    max_upload_bytes : int
        Largest upload [bytes] (413 beyond, before it is read).
    """

    header_timeout_s: float = 10.0
    body_timeout_s: float = 20.0
    body_min_rate_Bps: float = 500.0
    keep_alive_s: float = 5.0
    max_connections: int = 1000
    max_connections_per_client: int = 0
    read_threads: int = 4
    work_threads: int = 2
    max_waiting_work: int = 16
    max_uploads: int = 2
    max_upload_bytes: int = MAX_UPLOAD_BYTES

    def __post_init__(self):
        for name in ("header_timeout_s", "body_timeout_s", "body_min_rate_Bps",
                     "keep_alive_s"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise DataError(f"{name} must be a positive number of "
                                f"{'bytes/s' if name.endswith('Bps') else 'seconds'}; "
                                f"got {value!r}")
        for name, low in (("max_connections", 1), ("max_connections_per_client", 0),
                          ("read_threads", 1), ("work_threads", 1), ("max_waiting_work", 0),
                          ("max_uploads", 1), ("max_upload_bytes", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise DataError(f"{name} must be a whole number >= {low}; got {value!r}")

    def to_dict(self) -> dict:
        """The limits by name (for logs and the docs)."""
        return asdict(self)
