"""A pack's events in the order of its life (see :mod:`.health`): by the clock times their
files record, else by when they were added or the cycle numbers in their names; and how
much later in the life one event is than another."""

from __future__ import annotations

from bisect import bisect_right
from datetime import UTC, datetime


def parse_clock(text) -> datetime | None:
    """An ISO 8601 clock time as written (with its offset when it has one), or None when
    missing or unreadable."""
    if not text:
        return None
    try:
        return datetime.fromisoformat(str(text))
    except ValueError:
        return None


def _stamp(text) -> datetime | None:
    """A clock time as a naive UTC datetime (None when missing or unreadable)."""
    stamp = parse_clock(text)
    if stamp is not None and stamp.tzinfo is not None:
        stamp = stamp.astimezone(UTC).replace(tzinfo=None)
    return stamp


def source_of(e: dict):
    """The id of the file an event came from."""
    return e.get("source_id") if e.get("source_id") is not None else e.get("id") or 0


def order_events(events: list[dict]) -> list[dict]:
    """Events in the pack's life order (the **Order** of :mod:`.health`'s docstring)."""
    by_source: dict = {}
    for e in events:
        by_source.setdefault(source_of(e), []).append(e)
    horizon = datetime.min
    keyed = []
    undated_groups: dict = {}
    for sid in sorted(by_source):
        evs = sorted(by_source[sid], key=lambda e: (e.get("idx") or e.get("index") or 0,
                                                    e.get("id") or 0))
        stamps = [_stamp(e.get("start_time")) for e in evs]
        if any(s is not None for s in stamps):
            last = next(s for s in stamps if s is not None)
            for e, s in zip(evs, stamps):
                last = s if s is not None else last
                keyed.append(((last, 0, -1 if e.get("cycle") is None else e["cycle"], sid,
                               e.get("idx") or 0), e))
            horizon = max(horizon, max(s for s in stamps if s is not None))
        else:
            undated_groups.setdefault(horizon, []).append((sid, evs))
    # dated events with a cycle number place an undated one that carries a number: just
    # after the dated one of the highest number below it
    numbered = sorted((int(e["cycle"]), key[0]) for key, e in keyed
                      if e.get("cycle") is not None)
    numbers = [c for c, _ in numbered]
    for at, group in undated_groups.items():
        cycles = [evs[0].get("cycle") for _, evs in group]
        by_cycle = all(c is not None for c in cycles)
        for rank, (sid, evs) in enumerate(group):
            order = cycles[rank] if by_cycle else rank
            for e in evs:
                place = at
                if by_cycle and numbered and e.get("cycle") is not None:
                    below = bisect_right(numbers, int(e["cycle"]))
                    place = numbered[below - 1][1] if below else numbered[0][1]
                keyed.append(((place, 1, order, sid, e.get("idx") or 0), e))
    keyed.sort(key=lambda item: item[0])
    return [e for _, e in keyed]


def later_in_life(a: dict, b: dict) -> tuple[int, float] | None:
    """How much later in the pack's life event ``b`` is than ``a``: ``(0, days)`` by their
    clock times, else ``(1, cycles)`` by their cycle numbers; None when it is not later or
    they cannot say (an undated, unnumbered file is placed only by when it was added)."""
    ta, tb = _stamp(a.get("start_time")), _stamp(b.get("start_time"))
    if ta is not None and tb is not None:
        days = (tb - ta).total_seconds() / 86400.0
        return (0, days) if days > 0 else None
    ca, cb = a.get("cycle"), b.get("cycle")
    if ca is not None and cb is not None:
        return (1, float(cb - ca)) if cb > ca else None
    return None


__all__ = ["order_events", "later_in_life", "source_of", "parse_clock"]
