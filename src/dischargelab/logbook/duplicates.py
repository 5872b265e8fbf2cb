"""The same flights or tests in two files: recognised by what they hold, not by their bytes.

A ground-station app's raw log and the CSV exported from it, a tester's native file and
its text export, hold the same discharges in different bytes, so their SHA-256 differ.
Counted twice, every flight would double the pack's equivalent full cycles. Two files
hold the same content when they split into the same number of events and every event,
in file order, agrees with its counterpart on

* its kind,
* its duration, the charge it moved and the energy (within :data:`REL_TOL`),
* its number of samples (within :data:`SAMPLES_TOL`, at least one sample),
* its lowest and last voltage, its mean and largest current (within :data:`REL_TOL`),
* its clock time when both files date it (up to a whole time-zone offset, as one
  format may write local time and the other UTC), and its cycle number when both
  number it.

Two different discharges agree on all of these only when they are the same
measurement written twice: two cycles of one test are told apart by their times, or
by their cycle numbers, or by the fade between them; a run from a storage charge
that moves the charge an older cell's full discharge moves, by its energy (0.7 %
more or less: its voltages lie elsewhere on the curve). What is still indistinguishable
(two undated, unnumbered files of two identical cycles) is counted once.

The logbook keeps one copy, the richer file: more samples, then more bytes (a raw log
over its export). The other is reported as skipped, with the file it duplicates.
"""

from __future__ import annotations

from datetime import datetime

from .order import parse_clock

#: Relative agreement of durations, charges, voltages and currents.
REL_TOL = 0.005
#: Relative agreement of sample counts (at least one sample either way).
SAMPLES_TOL = 0.02
#: Absolute agreement of durations [s], charges [Ah], energies [Wh], voltages [V],
#: currents [A] (a rounding in an export).
ABS_TOL = {"duration_s": 2.0, "discharged_Ah": 1e-6, "discharged_Wh": 1e-5,
           "min_voltage_V": 0.002, "end_voltage_V": 0.002, "mean_current_A": 1e-6,
           "max_current_A": 1e-6}
#: Two clock times of one event may differ by a whole time-zone offset (a quarter hour
#: step, up to 14 h) plus this much [s].
CLOCK_TOL_S = 90.0
#: Kinds of event that make a file's content (rests and gaps alone are not compared).
LOAD_KINDS = ("discharge", "flight", "charge")

#: Event fields compared (those stored in the ``events`` table).
FIELDS = ("kind", "idx", "start_time", "cycle", "samples", *ABS_TOL)


def _close(a, b, name: str) -> bool:
    if a is None or b is None:
        return a is None and b is None
    a, b = float(a), float(b)
    return abs(a - b) <= ABS_TOL[name] + REL_TOL * max(abs(a), abs(b))


def _clock(text) -> datetime | None:
    """The wall-clock time as written (its offset dropped: the offsets are compared)."""
    stamp = parse_clock(text)
    return None if stamp is None else stamp.replace(tzinfo=None)


def _same_clock(a, b) -> bool:
    ta, tb = _clock(a), _clock(b)
    if ta is None or tb is None:
        return True
    delta = abs((ta - tb).total_seconds())
    if delta > 14 * 3600 + CLOCK_TOL_S:
        return False
    quarter = 900.0
    return abs(delta - quarter * round(delta / quarter)) <= CLOCK_TOL_S


def same_event(a: dict, b: dict) -> bool:
    """Whether two events (summaries or stored rows) are one measurement (module docstring)."""
    if a.get("kind") != b.get("kind"):
        return False
    na, nb = int(a.get("samples") or 0), int(b.get("samples") or 0)
    if abs(na - nb) > max(1.0, SAMPLES_TOL * max(na, nb)):
        return False
    if any(not _close(a.get(name), b.get(name), name) for name in ABS_TOL):
        return False
    if a.get("cycle") is not None and b.get("cycle") is not None \
            and int(a["cycle"]) != int(b["cycle"]):
        return False
    return _same_clock(a.get("start_time"), b.get("start_time"))


def content(events: list[dict]) -> list[dict]:
    """The events that make a file's content, in file order."""
    order = sorted(events, key=lambda e: int(e.get("idx", e.get("index", 0)) or 0))
    return [e for e in order if e.get("kind") in LOAD_KINDS]


def same_content(a: list[dict], b: list[dict]) -> bool:
    """Whether two files' events are the same measurements (both from :func:`content`)."""
    return bool(a) and len(a) == len(b) and all(same_event(x, y) for x, y in zip(a, b))


def richness(samples: int, size_bytes: int) -> tuple[int, int]:
    """Which copy of the same content to keep: more samples, then more bytes."""
    return int(samples), int(size_bytes)


def reason(kept: str, events: int) -> str:
    """Why a file was skipped as a copy of ``kept``."""
    what = "event" if events == 1 else "events"
    return f"the same {events} {what} as {kept}, which is kept (same times, samples and charge)"


__all__ = ["same_event", "same_content", "content", "richness", "reason", "FIELDS"]
