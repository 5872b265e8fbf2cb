"""Producer/consumer acquisition pipeline (the structure of the paper's section 3.2).

One producer thread owns the :class:`SampleSource`: it reads samples, puts them
on a queue, reconnects (with backoff) when the link drops and calls
``source.stop_load()`` as soon as a stop is requested. One consumer thread
takes the queue in order and hands every sample and event to each
:class:`Consumer` (data file, live display, safety monitor, ...). Consumers are
only ever called from that one thread, so they need no locks of their own.

References
----------
.. [1] paper section 3.2: "Producer/Consumer design pattern": the producer reads
   the analog port and scales it by Ke; one consumer updates a meter and a plot,
   another stores the values in a data file.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from ..errors import DischargelabError


@dataclass(frozen=True)
class Sample:
    """One calibrated measurement.

    Attributes
    ----------
    time_s : float
        Seconds since the test started.
    voltage_V : float
        Pack voltage, calibrated [V].
    current_A : float or None
        Pack current [A], discharge positive; None if not measured.
    temperature_C : float or None
        Pack (cell surface) temperature [degC]; None if not measured.
    seq : int or None
        Device sample counter (loss detection), None if the source has none.
    """

    time_s: float
    voltage_V: float
    current_A: float | None = None
    temperature_C: float | None = None
    seq: int | None = None


class SourceDisconnected(DischargelabError, ConnectionError):
    """The link to the measuring device was lost (cable pulled, device silent)."""


@runtime_checkable
class SampleSource(Protocol):
    """Anything that produces :class:`Sample` objects: an Arduino logger, an electronic load...

    A source that switches the load on and off (a relay, an electronic load)
    also has ``controls_load = True``; without it the pipeline takes the load as
    not driven by the host, and never claims to have switched it off.
    """

    name: str
    info: dict
    stats: dict

    def read(self, timeout_s: float) -> list[Sample]:
        """Samples that arrived within ``timeout_s``; raises :class:`SourceDisconnected`."""

    def reconnect(self) -> None:
        """Open the link again and resume; raises :class:`SourceDisconnected` if not possible."""

    def stop_load(self) -> None:
        """Switch the load off (no-op for a source without a controllable load)."""

    def close(self) -> None:
        """Stop streaming and release the port."""


@runtime_checkable
class Consumer(Protocol):
    """Receives every sample and event of a pipeline, in order, from one thread."""

    def handle(self, sample: Sample) -> None: ...

    def event(self, kind: str, **fields) -> None: ...

    def close(self) -> None: ...


@dataclass(frozen=True)
class ReconnectPolicy:
    """Retry schedule after a lost link: exponential backoff, forever by default.

    Attributes
    ----------
    first_delay_s, max_delay_s : float
        Wait before the first retry, and the longest wait between retries [s].
    factor : float
        Growth of the wait after each failed retry.
    give_up_after_s : float or None
        Stop the test when the link has been down this long [s]; None = keep
        trying until the user stops.
    """

    first_delay_s: float = 0.25
    max_delay_s: float = 5.0
    factor: float = 2.0
    give_up_after_s: float | None = None


#: How each way of ending maps to a process exit status (see ``dischargelab acquire --help``).
EXIT_STATUS = {"user": 0, "duration": 0, "source-ended": 0, "cutoff": 3,
               "over-temperature": 4, "link-lost": 5, "error": 6}

_SENTINEL = object()


class Pipeline:
    """Run a source and its consumers on two threads until a stop is requested.

    Parameters
    ----------
    source : SampleSource
    consumers : list of Consumer
        Called in this order for every sample and event.
    read_timeout_s : float
        Longest the producer blocks in ``source.read`` [s]; bounds how late a
        stop request (and so ``stop_load``) is acted on.
    reconnect : ReconnectPolicy
    duration_s : float, optional
        Stop (``ended_by = "duration"``) once a sample at or after this test time arrives.
    prefill : list of Sample, optional
        Samples already read from the source (e.g. to infer the cell count),
        handed to the consumers first.

    Examples
    --------
    >>> pipe = Pipeline(source, [writer, display, safety])      # doctest: +SKIP
    >>> pipe.start(); pipe.wait(); pipe.close()                  # doctest: +SKIP
    """

    def __init__(self, source: SampleSource, consumers: list[Consumer] | None = None, *,
                 read_timeout_s: float = 0.1, reconnect: ReconnectPolicy = ReconnectPolicy(),
                 duration_s: float | None = None, prefill: list[Sample] | None = None,
                 clock: Callable[[], float] = time.monotonic):
        self.source = source
        self.consumers: list[Consumer] = list(consumers or [])
        self.read_timeout_s = float(read_timeout_s)
        self.reconnect_policy = reconnect
        self.duration_s = duration_s
        self._clock = clock
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._done = threading.Event()
        self._load_stop_requested = threading.Event()
        self._lock = threading.Lock()
        self._producer = threading.Thread(target=self._produce, name="dischargelab-producer",
                                          daemon=True)
        self._consumer = threading.Thread(target=self._consume, name="dischargelab-consumer",
                                          daemon=True)
        self.ended_by: str | None = None
        self.end_message = ""
        self.error: BaseException | None = None
        self.samples_handled = 0
        self.connected = True
        self.last_sample: Sample | None = None
        self.started_at: float | None = None
        #: True: the source drives the load and switched it off at the end; False: it drives
        #: the load and could not switch it off; None: the source drives no load.
        self.load_switched_off: bool | None = None
        if prefill:
            self._queue.put(list(prefill))
            self.last_sample = prefill[-1]

    # ------------------------------------------------------------------ control
    def add(self, consumer: Consumer) -> None:
        """Add a consumer (before :meth:`start`)."""
        if self.started_at is not None:
            raise DischargelabError("add consumers before starting the pipeline")
        self.consumers.append(consumer)

    def start(self) -> Pipeline:
        """Start the producer and consumer threads."""
        self.started_at = self._clock()
        self._consumer.start()
        self._producer.start()
        return self

    @property
    def running(self) -> bool:
        return self.started_at is not None and not self._done.is_set()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set()

    def request_stop(self, reason: str = "user", message: str = "", *, kind: str | None = None,
                     **fields) -> None:
        """Stop the test (thread-safe); the first reason given wins.

        The load is switched off (``source.stop_load()``) by the producer within
        ``read_timeout_s``. With ``kind`` (e.g. ``"cutoff"``) an event of that
        kind is recorded by every consumer before any later sample.
        """
        with self._lock:
            first = self.ended_by is None
            if first:
                self.ended_by = reason
                self.end_message = message
        if kind is not None:
            self.emit(kind, message=message, **fields)
        if first:
            self._load_stop_requested.set()
            self._stop.set()

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until both threads have finished; True if they have."""
        return self._done.wait(timeout_s)

    def close(self, timeout_s: float = 10.0) -> None:
        """Request a stop (if none yet), wait for the threads, re-raise a consumer error."""
        self.request_stop("user")
        self._producer.join(timeout_s)
        self._consumer.join(timeout_s)
        if isinstance(self.error, DischargelabError):
            raise self.error

    def run(self, timeout_s: float | None = None) -> str:
        """Start, block until the test ends (or ``timeout_s``), close; returns ``ended_by``."""
        self.start()
        try:
            self.wait(timeout_s)
        finally:
            self.close()
        return self.ended_by or "user"

    @property
    def exit_status(self) -> int:
        """Process exit status for the way the test ended (:data:`EXIT_STATUS`)."""
        return EXIT_STATUS.get(self.ended_by or "user", 6)

    @property
    def stats(self) -> dict:
        """Source statistics plus pipeline counters."""
        out = dict(getattr(self.source, "stats", {}) or {})
        out["samples_handled"] = self.samples_handled
        return out

    # ------------------------------------------------------------------ events
    def emit(self, kind: str, **fields) -> None:
        """Record an event in every consumer (thread-safe, in order with the samples)."""
        if threading.current_thread() is self._consumer:
            self._dispatch_event(kind, fields)   # keep order with the sample being handled
        else:
            self._queue.put(("event", kind, fields))

    def _dispatch_event(self, kind: str, fields: dict) -> None:
        for consumer in self.consumers:
            consumer.event(kind, **fields)

    # ------------------------------------------------------------------ threads
    def _produce(self) -> None:
        source = self.source
        try:
            while not self._stop.is_set():
                try:
                    samples = source.read(self.read_timeout_s)
                except SourceDisconnected as exc:
                    if self._stop.is_set():
                        break
                    self._recover(exc)
                    continue
                if getattr(source, "finished", False) and not self._stop.is_set():
                    why = str(getattr(source, "ended_by", "") or "the source ended the test")
                    if samples:
                        self._queue.put(samples)
                        samples = []
                    if "cutoff" in why:
                        self.request_stop("cutoff", f"{source.name}: {why}", kind="cutoff",
                                          by=source.name)
                    else:
                        self.request_stop("source-ended", f"{source.name}: {why}")
                if samples:
                    self._queue.put(samples)
                    last = samples[-1]
                    self.last_sample = last
                    if self.duration_s is not None and last.time_s >= self.duration_s:
                        self.request_stop("duration", f"duration of {self.duration_s:g} s reached")
        except BaseException as exc:
            self.error = exc
            self.request_stop("error", f"{type(exc).__name__}: {exc}", kind="error")
        finally:
            self._finish_source()
            self._queue.put(_SENTINEL)

    def _finish_source(self) -> None:
        controls = bool(getattr(self.source, "controls_load", False))
        try:
            self.source.stop_load()
            self.load_switched_off = True if controls else None
        except Exception as exc:
            if controls:
                self.load_switched_off = False
                self._queue.put(("event", "alarm",
                                 {"message": f"could not switch the load off: {exc}"}))
        try:
            self.source.close()
        except Exception:
            pass

    def _recover(self, exc: Exception) -> None:
        """Reconnect with backoff until it works, the user stops, or the policy gives up."""
        policy = self.reconnect_policy
        self.connected = False
        down_since = self._clock()
        last = self.last_sample
        self._queue.put(("event", "disconnect", {
            "time_s": None if last is None else last.time_s, "reason": str(exc)}))
        delay = policy.first_delay_s
        attempts = 0
        while not self._stop.wait(delay):
            attempts += 1
            try:
                self.source.reconnect()
            except (DischargelabError, OSError) as again:
                down = self._clock() - down_since
                if policy.give_up_after_s is not None and down >= policy.give_up_after_s:
                    self.request_stop("link-lost", f"link down for {down:.0f} s: {again}",
                                      kind="link-lost", attempts=attempts)
                    return
                delay = min(policy.max_delay_s, delay * policy.factor)
                continue
            self.connected = True
            self._queue.put(("event", "reconnect", {
                "after_s": round(self._clock() - down_since, 3), "attempts": attempts,
                "last_time_s": None if last is None else last.time_s}))
            return

    def _consume(self) -> None:
        consumers = self.consumers
        gap_from: float | None = None
        try:
            while True:
                item = self._queue.get()
                if item is _SENTINEL:
                    break
                if isinstance(item, list):
                    for sample in item:
                        if gap_from is not None:
                            self._dispatch_event("gap", {
                                "start_time_s": gap_from, "end_time_s": sample.time_s,
                                "duration_s": round(sample.time_s - gap_from, 6)})
                            gap_from = None
                        for consumer in consumers:
                            consumer.handle(sample)
                        self.samples_handled += 1
                else:
                    _, kind, fields = item
                    if kind == "reconnect":
                        gap_from = fields.get("last_time_s")
                    self._dispatch_event(kind, fields)
        except BaseException as exc:
            self.error = exc
            self.request_stop("error", f"{type(exc).__name__}: {exc}")
            _drain(self._queue)
        finally:
            try:
                self._dispatch_event("stop", {
                    "ended_by": self.ended_by or "user", "message": self.end_message,
                    **{k: v for k, v in self.stats.items() if isinstance(v, (int, float, str))}})
            except Exception:
                pass
            for consumer in consumers:
                try:
                    consumer.close()
                except BaseException as exc:
                    if self.error is None:
                        self.error = exc
            self._done.set()


def _drain(q: queue.SimpleQueue) -> None:
    while True:
        try:
            if q.get(timeout=30) is _SENTINEL:
                return
        except queue.Empty:
            return
