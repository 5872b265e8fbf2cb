"""Live samples of a running test, fanned out to browser subscribers without slowing the test.

:class:`LiveHub` is a pipeline :class:`~dischargelab.acquire.pipeline.Consumer`. For every
sample it appends one record to a bounded ring (the history a page gets when it connects or
reloads) and to each subscriber's bounded queue, then wakes the subscriber's event loop; it
never waits for a subscriber. A subscriber whose queue (or its queue of events) is full is
marked *behind*: its queues are dropped and its next read is a resync (the whole ring again),
so a slow page can miss nothing silently. Every record carries ``n``, its index in the run
(0, 1, 2 ... with no gaps), so a page (and a test) can prove that it has every sample.

The numbers in a record (per-cell voltage, power, charge and energy) come from
:class:`~dischargelab.acquire.live.LiveDisplay`, the same object as the terminal view's.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections import deque

from ..acquire.live import LiveDisplay

#: Fields of one sample record, in order (``null`` where not measured).
RECORD_FIELDS = ("n", "time_s", "voltage_V", "cell_V", "current_A", "power_W", "charge_Ah",
                 "energy_Wh", "temperature_C", "seq")

#: Samples kept for a page that connects late (about 14 h at 1 Hz, 1.4 h at 10 Hz).
RING_SAMPLES = 50_000
#: Samples queued for one subscriber before it is resynchronised from the ring.
SUBSCRIBER_SAMPLES = 4_096
#: Events (cutoff, gap, alarm, ...) kept for a page that connects late.
RING_EVENTS = 200


def _num(value, digits: int = 6):
    if value is None:
        return None
    value = float(value)
    return round(value, digits) if math.isfinite(value) else None


class Subscriber:
    """One connected page: a bounded queue and a wake-up for its event loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop, limit: int):
        self.loop = loop
        self.limit = limit
        self.queue: deque = deque()
        self.events: deque = deque()
        self.behind = True            # the first read is a full snapshot
        self.wake = asyncio.Event()
        self._wake_pending = False
        self.resyncs = 0

    def add_sample(self, record: tuple) -> None:
        """Queue a sample record (hub lock held); see :meth:`_add`."""
        self._add(self.queue, self.limit, record)

    def add_event(self, record: dict) -> None:
        """Queue an event record (hub lock held); see :meth:`_add`."""
        self._add(self.events, RING_EVENTS, record)

    def _add(self, queue: deque, limit: int, record) -> None:
        """Append ``record``, or fall behind when ``queue`` already holds ``limit`` records.

        Falling behind drops everything queued; the next read is a resync from the ring.
        A subscriber already behind queues nothing.
        """
        if self.behind:
            return
        if len(queue) >= limit:
            self.behind = True
            self.queue.clear()
            self.events.clear()
        else:
            queue.append(record)

    def _set(self) -> None:
        self._wake_pending = False
        self.wake.set()

    def notify(self) -> None:
        """Wake the subscriber's loop (thread-safe, never blocks, coalesced)."""
        if self._wake_pending:
            return
        self._wake_pending = True
        try:
            self.loop.call_soon_threadsafe(self._set)
        except RuntimeError:          # the loop is closed: the page is gone
            pass


class LiveHub:
    """Ring buffer + fan-out of a test's samples and events (a pipeline Consumer).

    Parameters
    ----------
    ring_samples : int
        History kept for late subscribers (oldest dropped first; a page is told
        where its history starts).
    subscriber_samples : int
        Queue length per subscriber before it gets a resync instead.
    """

    def __init__(self, *, ring_samples: int = RING_SAMPLES,
                 subscriber_samples: int = SUBSCRIBER_SAMPLES, clock=time.monotonic):
        if subscriber_samples > ring_samples:
            raise ValueError("subscriber_samples must not exceed ring_samples (a resync would "
                             "lose samples)")
        self.ring_samples = int(ring_samples)
        self.subscriber_samples = int(subscriber_samples)
        self._clock = clock
        self._lock = threading.Lock()
        self._subscribers: list[Subscriber] = []
        self.run_id = 0
        self.info: dict = {}
        self.ring: deque = deque(maxlen=self.ring_samples)
        self.events: deque = deque(maxlen=RING_EVENTS)
        self.display = LiveDisplay()
        self.count = 0
        self.active = False
        self.ended_by: str | None = None
        self.end_message = ""

    # ------------------------------------------------------------------ runs
    def begin(self, info: dict, *, cells_series: int = 1, cutoff_pack_V: float | None = None,
              current_given_A: float | None = None, stats=None, safety=None,
              battery=None) -> None:
        """Start a new run: clears the history; every subscriber gets a resync. ``battery``
        (the pack's model, optional) gives the time to cutoff by the model."""
        with self._lock:
            self.run_id += 1
            self.info = dict(info)
            self.ring.clear()
            self.events.clear()
            self.count = 0
            self.display = LiveDisplay(cells_series=cells_series, cutoff_pack_V=cutoff_pack_V,
                                       current_given_A=current_given_A, stats=stats,
                                       safety=safety, clock=self._clock, battery=battery)
            self.active = True
            self.ended_by = None
            self.end_message = ""
            subs = list(self._subscribers)
            for sub in subs:
                sub.behind = True
                sub.queue.clear()
                sub.events.clear()
        for sub in subs:
            sub.notify()

    def finish(self, ended_by: str, message: str = "") -> None:
        """Mark the run as ended (after the pipeline has stopped)."""
        with self._lock:
            self.active = False
            self.ended_by = ended_by
            self.end_message = message
            subs = list(self._subscribers)
        for sub in subs:
            sub.notify()

    # ------------------------------------------------------------------ Consumer
    def handle(self, sample) -> None:
        disp = self.display
        disp.handle(sample)
        current = disp.current_of(sample)
        volts = sample.voltage_V
        has_i = current is not None
        record = (self.count, _num(sample.time_s), _num(volts),
                  _num(volts / disp.cells_series),
                  _num(current), _num(volts * current) if has_i else None,
                  _num(disp.charge_Ah, 7) if has_i else None,
                  _num(disp.energy_Wh, 6) if has_i else None,
                  _num(sample.temperature_C, 3), sample.seq)
        with self._lock:
            self.count += 1
            self.ring.append(record)
            subs = list(self._subscribers)
            for sub in subs:
                sub.add_sample(record)
        for sub in subs:
            sub.notify()

    def event(self, kind: str, **fields) -> None:
        self.display.event(kind, **fields)
        record = {"kind": kind, "after_n": self.count - 1,
                  **{k: _json_value(v) for k, v in fields.items()}}
        with self._lock:
            self.events.append(record)
            subs = list(self._subscribers)
            for sub in subs:
                sub.add_event(record)
        for sub in subs:
            sub.notify()

    def close(self) -> None:
        pass

    # ------------------------------------------------------------------ subscribers
    def subscribe(self, loop: asyncio.AbstractEventLoop) -> Subscriber:
        sub = Subscriber(loop, self.subscriber_samples)
        with self._lock:
            self._subscribers.append(sub)
        return sub

    def unsubscribe(self, sub: Subscriber) -> None:
        with self._lock:
            if sub in self._subscribers:
                self._subscribers.remove(sub)

    @property
    def subscribers(self) -> int:
        return len(self._subscribers)

    def take(self, sub: Subscriber) -> tuple[str, dict] | None:
        """What the subscriber should send next: ``("snapshot", ...)``, ``("samples", ...)``
        or None (nothing new). Called from the subscriber's event loop."""
        with self._lock:
            sub.wake.clear()
            if sub.behind:
                sub.behind = False
                sub.queue.clear()
                sub.events.clear()
                samples = list(self.ring)
                events = list(self.events)
                run_id = self.run_id
            elif sub.queue or sub.events:
                samples = list(sub.queue)
                events = list(sub.events)
                sub.queue.clear()
                sub.events.clear()
                return "samples", {"run": self.run_id, "samples": samples, "events": events}
            else:
                return None
        sub.resyncs += 1
        return "snapshot", {"run": run_id, "fields": list(RECORD_FIELDS), "samples": samples,
                            "events": events, "first_n": samples[0][0] if samples else self.count,
                            "status": self.status()}

    # ------------------------------------------------------------------ numbers
    def status(self) -> dict:
        """The run's state and derived numbers (elapsed, time to cutoff, rate, link)."""
        disp = self.display
        last = disp.last
        summary = disp.summary()
        safety = disp.safety
        left, how = disp.time_to_cutoff() if self.active else (None, None)
        return {
            "run": self.run_id, "active": self.active, "info": self.info,
            "samples": self.count, "ended_by": self.ended_by, "end_message": self.end_message,
            "elapsed_s": None if last is None else _num(last.time_s, 3),
            "time_to_cutoff_s": _num(left, 1), "time_to_cutoff_method": how,
            "min_voltage_V": _num(disp.min_voltage_V) if last is not None else None,
            "rate_Hz": _num(disp.rate_Hz, 2), "link": disp.link,
            "safety": safety.pending if safety is not None else "",
            "frames_lost": summary.get("frames_lost"),
            "frames_corrupt": summary.get("frames_corrupt"),
            "reconnects": summary.get("reconnects"),
        }


def _json_value(value):
    if isinstance(value, float):
        return _num(value)
    if isinstance(value, (int, str, bool)) or value is None:
        return value
    return str(value)
