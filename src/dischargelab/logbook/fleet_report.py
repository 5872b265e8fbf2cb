"""The fleet at a glance: every pack's health, sorted by how soon it reaches end of life.

:func:`pack_summary` is the pure task (one pack's stored rows -> its health figures and
the points of its capacity and resistance trends), so a fleet of thousands of packs
runs on the same executor as ingest (:mod:`dischargelab.fleet`). :class:`FleetReport`
holds the rows, soonest end of life first, and writes one self-contained HTML page
(inline SVG sparklines, no scripts, nothing loaded from outside).
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from ..formatting import pack_text
from .results import _clean, build_health

#: Width and height of a sparkline [px].
SPARK_W, SPARK_H = 220, 44


def pack_summary(job: tuple) -> dict:
    """One pack's figures from its stored rows (pure; ``job = (row, events, model, eol)``).

    Returns
    -------
    dict
        ``name``, ``events``, ``efc``, ``capacity_Ah`` and ``capacity_interval95``
        (today, from the capacity trend), ``reference_capacity_Ah``,
        ``capacity_fraction``, ``resistance_ohm`` (today) and ``resistance_basis``,
        ``eol_efc``, ``eol_efc_interval95``, ``efc_left`` (EFC from today to the
        forecast end of life), ``observed`` (end of life already logged),
        ``threshold_Ah``, ``shape`` and ``knee_efc`` of the trend, ``forecast_status``
        and ``forecast_note`` (why no end of life is given yet), ``points`` (per
        event: efc, kind, capacity_Ah, capacity_interval95, resistance_ohm, outlier)
        and ``band`` (the capacity trend's 95 % band and the forecast's, or None).
    """
    row, events, model, eol = job
    return fleet_row(build_health(row, events, model, eol), row)


def fleet_row(h, row: dict) -> dict:
    """The fleet report's row of one pack from its health (see :func:`pack_summary`)."""
    ref, cap, f = h.reference_capacity_Ah, h.capacity_now_Ah, h.forecast
    efc = h.efc_now
    left = None
    if f is not None and f.eol_efc is not None and efc is not None:
        left = f.eol_efc - efc
    points = [{"efc": e.efc, "kind": e.to_dict().get("kind"), "capacity_Ah": e.capacity_Ah,
               "capacity_interval95": e.capacity_interval95,
               "resistance_ohm": e.resistance_ohm, "outlier": e.outlier}
              for e in h.events if e.efc is not None]
    return _clean({
        "name": row["name"], "events": len(h.events), "efc": efc, "capacity_Ah": cap,
        "capacity_interval95": h.capacity_now_interval95, "reference_capacity_Ah": ref,
        "capacity_fraction": cap / ref if cap is not None and ref else None,
        "resistance_ohm": h.resistance_now_ohm,
        "resistance_basis": h.today.get("resistance_basis"),
        "eol_efc": None if f is None else f.eol_efc,
        "eol_efc_interval95": None if f is None else list(f.eol_efc_interval95),
        "efc_left": left, "observed": bool(f is not None and f.observed),
        "threshold_Ah": None if f is None else f.threshold_Ah,
        "shape": None if f is None or not f.shape else f.shape,
        "knee_efc": None if f is None else f.knee_efc,
        "forecast_status": "no fade" if f is None else f.status,
        "forecast_note": "no fade measured yet" if f is None else f.message,
        "points": points, "band": None if f is None else f.band_points(points=60)})


def retire_order(row: dict) -> tuple:
    """Sort key: end of life already logged, then the fewest EFC left, then no forecast."""
    if row.get("observed"):
        return (0, row.get("eol_efc") or 0.0, row["name"])
    if row.get("efc_left") is not None:
        return (1, row["efc_left"], row["name"])
    return (2, 0.0, row["name"])


@dataclass
class FleetReport:
    """Every pack's health, soonest end of life first (``rows``: :func:`pack_summary` dicts).

    ``failed`` lists ``(pack, one-line reason)`` for packs whose figures could not be made.
    """

    rows: list[dict]
    eol: float
    failed: list[tuple[str, str]]

    def to_dict(self) -> dict:
        return {"eol": self.eol, "packs": [{k: v for k, v in r.items()
                                            if k not in ("points", "band")} for r in self.rows],
                "failed": [{"pack": p, "reason": r} for p, r in self.failed]}

    def to_pandas(self):
        import pandas as pd

        return pd.DataFrame(self.to_dict()["packs"])

    def retire_soon(self, within_efc: float) -> list[str]:
        """Packs whose end of life is logged or forecast within ``within_efc`` EFC."""
        return [r["name"] for r in self.rows if r.get("observed") or (
            r.get("efc_left") is not None and r["efc_left"] <= within_efc)]

    def to_html(self, title: str = "Fleet health", within_efc: float = 50.0) -> str:
        """One self-contained page: a table of packs with capacity and resistance trends;
        packs :meth:`retire_soon` (``within_efc``) in red."""
        from ..report import CSS

        now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
        head = ["pack", "events", "EFC", "capacity today (95 %)", "of reference", "resistance",
                "trend", "end of life [EFC]", "95 % interval", "EFC left",
                "capacity against EFC", "resistance against EFC"]
        body = []
        due = set(self.retire_soon(within_efc))
        for r in self.rows:
            left = r.get("efc_left")
            status = ("logged" if r.get("observed") else "-" if left is None
                      else f"{left:.0f}")
            cls = ' class="due"' if r["name"] in due else ""
            text = pack_text(r)     # the figures as every view writes them
            body.append(
                f"<tr{cls}><td>{_e(r['name'])}</td><td>{r['events']}</td>"
                f"<td>{text['efc']}</td><td>{text['capacity_Ah']} Ah "
                f"({_span_of(r.get('capacity_interval95'))})</td>"
                f"<td>{text['capacity_fraction']}</td>"
                f"<td>{text['resistance_ohm']} m&Omega;</td>"
                f"<td>{_e(_shape(r))}</td>"
                f"<td>{_eol(r)}</td><td>{_e(text['eol_efc_interval95'])}</td>"
                f"<td>{status}</td><td>{_spark_capacity(r)}</td><td>{_spark_resistance(r)}</td>"
                "</tr>")
        failed = "".join(f'<p class="warn">{_e(p)}: {_e(reason)}</p>'
                         for p, reason in self.failed)
        css = CSS + ("tr.due td{background:#fdecec}svg{display:block}"
                     "main{max-width:1400px}")
        return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
                f"<title>{_e(title)}</title><style>{css}</style></head><body><main>"
                f"<h1>{_e(title)}</h1><p class=\"sub\">{len(self.rows)} pack(s), end of life at "
                f"{100 * self.eol:.0f} % of each pack's reference capacity; soonest first. "
                f"Made {now}.</p>"
                "<table><tr>" + "".join(f"<th>{h}</th>" for h in head) + "</tr>"
                + "".join(body) + "</table>" + failed +
                '<p class="sub">Capacity: dots per event (hollow: outliers, left out of the '
                "trend), shaded: the trend's 95 % band, then the forecast's (95 % of the "
                "simulated futures), red line: end of life. Rows in red "
                f"reached end of life or have at most {within_efc:g} EFC left.</p></main>"
                "</body></html>")

    def save(self, path, force: bool = False, within_efc: float = 50.0) -> Path:
        """Write :meth:`to_html` atomically; an existing file needs ``force``."""
        from ..atomic import check_outputs, write_text

        out = check_outputs([path], force=force)[0]
        return write_text(out, self.to_html(within_efc=within_efc))


#: How each trend shape reads in the report.
SHAPES = {"line": "straight", "early": "early fade, then straight", "knee": "knee",
          "early+knee": "early fade and knee"}


def _eol(row: dict) -> str:
    """The end of life, or why there is none yet (no fade measured, or not enough)."""
    if row.get("eol_efc") is not None:
        return _n(row["eol_efc"], 0)
    words = {"no fade": "no fade measured yet", "uncertain": "fade not yet enough"}
    note = row.get("forecast_note") or ""
    return (f'<span title="{_e(note)}">{_e(words.get(row.get("forecast_status"), "-"))}'
            "</span>")


def _shape(row: dict) -> str:
    if row.get("shape") is None:
        return "-"
    knee = row.get("knee_efc")
    return SHAPES.get(row["shape"], row["shape"]) + ("" if knee is None else f" at {knee:.0f}")


def _span_of(pair) -> str:
    if not pair or None in pair:
        return "-"
    return f"{pair[0]:.3f}-{pair[1]:.3f}"


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _n(value, digits: int, scale: float = 1.0) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


def _scale(values, lo_px: float, hi_px: float, pad: float = 0.05):
    finite = [v for v in values if v is not None and math.isfinite(v)]
    if not finite:
        return None
    lo, hi = min(finite), max(finite)
    span = (hi - lo) or (abs(hi) * 0.1 or 1.0)
    lo, hi = lo - pad * span, hi + pad * span

    def f(v):
        return lo_px + (v - lo) / (hi - lo) * (hi_px - lo_px)
    return f


def _svg(parts: list[str], title: str) -> str:
    return (f'<svg width="{SPARK_W}" height="{SPARK_H}" viewBox="0 0 {SPARK_W} {SPARK_H}" '
            f'role="img"><title>{_e(title)}</title>{"".join(parts)}</svg>')


def _span(values, unit: str, scale: float = 1.0, digits: int = 3) -> str:
    return f"{values[0] * scale:.{digits}g} to {values[-1] * scale:.{digits}g} {unit}"


def _spark_capacity(row: dict) -> str:
    pts = [p for p in row["points"] if p["capacity_Ah"] is not None]
    band = row.get("band")
    xs = [p["efc"] for p in pts] + (band["efc"] if band else [])
    # the scale holds the events and the threshold; the band's far edge is cut at the frame
    ys = [p["capacity_Ah"] for p in pts]
    if row.get("threshold_Ah") is not None:
        ys.append(row["threshold_Ah"])
        ys.append(row["threshold_Ah"] - 0.25 * (max(ys) - row["threshold_Ah"]))
    x, y = _scale(xs, 2, SPARK_W - 2), _scale(ys, SPARK_H - 2, 2)
    if x is None or y is None:
        return "-"
    parts = []
    if band:
        upper = [f"{x(e):.1f},{y(h):.1f}" for e, h in zip(band["efc"], band["hi"])]
        lower = [f"{x(e):.1f},{y(lo):.1f}" for e, lo in zip(band["efc"], band["lo"])]
        parts.append(f'<polygon points="{" ".join(upper + lower[::-1])}" fill="#1f77b4" '
                     'fill-opacity="0.18"/>')
    if row.get("threshold_Ah") is not None:
        ty = y(row["threshold_Ah"])
        parts.append(f'<line x1="0" x2="{SPARK_W}" y1="{ty:.1f}" y2="{ty:.1f}" '
                     'stroke="#d33" stroke-dasharray="3,2"/>')
    for p in pts:
        fill = "none" if p["outlier"] else "#1f77b4"
        parts.append(f'<circle cx="{x(p["efc"]):.1f}" cy="{y(p["capacity_Ah"]):.1f}" r="1.8" '
                     f'fill="{fill}" stroke="#1f77b4" stroke-width="0.8"/>')
    if not pts:
        return _svg(parts, "no capacity yet")
    return _svg(parts, f"capacity {_span([p['capacity_Ah'] for p in pts], 'Ah')} over "
                       f"{_span([p['efc'] for p in pts], 'EFC', digits=4)}")


def _spark_resistance(row: dict) -> str:
    pts = [p for p in row["points"] if p["resistance_ohm"] is not None and not p["outlier"]]
    x = _scale([p["efc"] for p in pts], 2, SPARK_W - 2)
    y = _scale([p["resistance_ohm"] for p in pts], SPARK_H - 2, 2)
    if x is None or y is None:
        return "-"
    line = " ".join(f"{x(p['efc']):.1f},{y(p['resistance_ohm']):.1f}" for p in pts)
    return _svg([f'<polyline points="{line}" fill="none" stroke="#2ca02c" '
                 'stroke-width="1.2"/>'],
                f"resistance {_span([p['resistance_ohm'] for p in pts], 'mOhm', 1000)} over "
                f"{_span([p['efc'] for p in pts], 'EFC', digits=4)}")
