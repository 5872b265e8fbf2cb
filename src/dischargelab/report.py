"""One self-contained HTML page a team can hand to its pilot.

The page holds the battery's coefficients with their intervals and the fit's
warnings, the fit against its measured curves (when the battery file names
source files that can still be read), a family of simulated discharges, the
mission profile with its endurance and margin, and the validation table. Plots
are embedded as base64 PNG; the page has no scripts and loads nothing from
outside, so it opens offline and can be mailed as one file.
"""

from __future__ import annotations

import base64
import html
import io
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from .errors import DataError, DischargelabError
from .formatting import duration, duration_interval, number
from .identity import battery_identity
from .model import CUTOFF_CELL_VOLTAGE_V, Battery, load_battery
from .nexttest import fit_next_test
from .uncertainty import held_out_summary

CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:0;color:#1d2430;
background:#f4f6f9;overflow-wrap:anywhere}
main{max-width:1060px;margin:0 auto;padding:24px 28px 48px;background:#fff}
h1{font-size:1.6em;margin:0 0 4px}h2{font-size:1.25em;margin:32px 0 8px;
border-bottom:2px solid #dfe4ea;padding-bottom:4px}h3{font-size:1.05em;margin:18px 0 6px}
.sub{color:#5b6573;margin:0 0 16px}
.cards{display:grid;grid-template-columns:repeat(auto-fit,minmax(180px,1fr));gap:12px;
margin:16px 0}
.card{border:1px solid #dfe4ea;border-radius:8px;padding:10px 14px;
background:#fafbfc}.card .v{font-size:1.45em;font-weight:600}.card .l{color:#5b6573;
font-size:.85em}
.tw{overflow-x:auto}
table{border-collapse:collapse;margin:8px 0 12px;font-size:.9em;width:100%}
th,td{border-bottom:1px solid #e3e7ec;padding:5px 8px;text-align:right}
td{white-space:nowrap}th{background:#eef1f5;font-weight:600;overflow-wrap:normal}
td:first-child,th:first-child{text-align:left}
td.t,th.t{text-align:left;white-space:normal}
table.facts td:first-child{width:30%;color:#5b6573;white-space:normal}
table.facts td{text-align:left;white-space:normal}
.warn{background:#fff5e0;border-left:4px solid #e5a000;padding:6px 10px;margin:6px 0}
.bad{background:#fdecec;border-left:4px solid #d33;padding:6px 10px;margin:6px 0}
.note{background:#eef5ff;border-left:4px solid #4a86d6;padding:6px 10px;margin:6px 0}
details{margin:8px 0 12px}summary{cursor:pointer;color:#2f5fa8;font-weight:600}
figure{margin:10px 0}figure img{max-width:100%;height:auto;border:1px solid #e3e7ec}
figure.half{max-width:640px}
figcaption{color:#5b6573;font-size:.85em}footer{color:#5b6573;font-size:.8em;margin-top:36px}
@media (max-width:640px){
main{padding:14px 12px 32px}h1{font-size:1.3em}
table.data thead{display:none}
table.data,table.data tbody,table.data tr,table.data td{display:block;width:auto}
table.data tr{border:1px solid #e3e7ec;border-radius:6px;margin:0 0 8px;padding:4px 8px}
table.data td{border:0;padding:2px 0;text-align:right;white-space:normal}
table.data td::before{content:attr(data-label);float:left;color:#5b6573;padding-right:10px;
text-align:left}
table.data td:first-child{font-weight:600}
table.facts td{display:block;width:auto;border:0;padding:2px 0}
table.facts td:first-child{width:auto;padding-top:8px}
table.facts tr{display:block;border-bottom:1px solid #e3e7ec}
}
"""

# ---------------------------------------------------------------------------------------------
# Small HTML helpers
# ---------------------------------------------------------------------------------------------

def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _fmt(value, spec=".4g", none="-") -> str:
    if value is None:
        return none
    try:
        if not np.isfinite(value):
            return none
    except TypeError:
        return _e(value)
    return format(value, spec)


def _table(headers, rows, text_columns=()) -> str:
    """A data table; on a phone each row becomes a card of ``header: value`` lines."""
    text_class = ' class="t"'
    head = "".join(f"<th{text_class if k in text_columns else ''}>{_e(h)}</th>"
                   for k, h in enumerate(headers))
    body = []
    for row in rows:
        cells = []
        for k, cell in enumerate(row):
            cls = ' class="t"' if k in text_columns else ""
            label = f' data-label="{_e(headers[k])}"' if k < len(headers) else ""
            cells.append(f"<td{cls}{label}>{_e(cell)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<div class="tw"><table class="data"><thead><tr>{head}</tr></thead>'
            f"<tbody>{''.join(body)}</tbody></table></div>")


def _facts(rows) -> str:
    """Label / value rows (a summary): the values wrap, nothing runs past the page."""
    body = "".join(f"<tr><td>{_e(label)}</td><td>{_e(value)}</td></tr>" for label, value in rows)
    return f'<table class="facts"><tbody>{body}</tbody></table>'


def _folded(summary: str, content: str) -> str:
    """``content`` one click away under ``summary`` (closed by default)."""
    return f"<details><summary>{_e(summary)}</summary>{content}</details>"


def _messages(items, cls="warn") -> str:
    return "".join(f'<div class="{cls}">{_e(m)}</div>' for m in items)


def _figure(ax, caption: str, alt: str, size: str = "") -> str:
    """Render the figure holding ``ax`` to an embedded PNG and close it."""
    from .plot import pyplot

    plt = pyplot()
    fig = ax.figure
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    cls = f' class="{size}"' if size else ""
    return (f'<figure{cls}><img src="data:image/png;base64,{data}" alt="{_e(alt)}">'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


# ---------------------------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------------------------

def _intervals(battery: Battery) -> dict:
    """95 % interval per parameter: from the fit file, else +/- 1.96 sigma of the covariance."""
    ci = battery.extra.get("ci95")
    out = {}
    for k, name in enumerate(battery.parameter_names):
        if isinstance(ci, dict) and name in ci and ci[name] is not None:
            lo, hi = ci[name]
            out[name] = (lo, hi)
        elif battery.covariance is not None:
            sd = float(np.sqrt(max(battery.covariance[k, k], 0.0)))
            value = float(battery.parameters[name])
            out[name] = (value - 1.96 * sd, value + 1.96 * sd)
        else:
            out[name] = (None, None)
    return out


def _parameter_rows(battery: Battery, names) -> list[list[str]]:
    """Value, standard error, 95 % interval and status of the parameters ``names``."""
    extra = battery.extra
    stderr = extra.get("stderr") if isinstance(extra.get("stderr"), dict) else {}
    fixed = extra.get("fixed") if isinstance(extra.get("fixed"), dict) else {}
    intervals = _intervals(battery)
    rows = []
    for k, par in enumerate(battery.family.parameters):
        name = par.name
        if name not in names:
            continue
        value = float(battery.parameters[name])
        if name in fixed:
            err, lo, hi, status = "fixed", "-", "-", "fixed"
        else:
            sd = stderr.get(name)
            if sd is None and battery.covariance is not None:
                sd = float(np.sqrt(max(battery.covariance[k, k], 0.0)))
            err = _fmt(sd, ".3g")
            lo, hi = (_fmt(x, ".5g") for x in intervals[name])
            status = "fitted" if battery.covariance is not None else "given"
        rows.append([name, par.description, par.unit, _fmt(value, ".6g"), err, lo, hi, status])
    return rows


PARAMETER_HEADERS = ["parameter", "meaning", "unit", "value", "std. error", "95 % low",
                     "95 % high", "status"]


def fitted_data(battery: Battery) -> list[str]:
    """The data the fit saw, as the battery file records it: one name per curve (with
    its cell current when known); empty when the file records none (a preset)."""
    sources = battery.extra.get("source")
    if not isinstance(sources, list):
        return []
    currents = list(battery.fit_currents_A)
    out = []
    for k, entry in enumerate(sources):
        if not isinstance(entry, dict):
            continue
        name = Path(str(entry.get("source") or entry.get("name") or f"curve {k + 1}")).name
        label = entry.get("name")
        text = name if not label or label in (name, Path(name).stem) else f"{label} ({name})"
        if k < len(currents) and currents[k]:
            text += f" at {currents[k]:.3g} A per cell"
        out.append(text)
    return out


def interval_methods(battery: Battery) -> dict:
    """How the intervals of this battery are made, from what its file holds.

    Returns
    -------
    dict
        ``parameters``: the parameters' 95 % intervals; ``predictions``: the draws
        predictions and missions are flown with (before the model error is added).
    """
    boot = battery.extra.get("bootstrap")
    n_boot = len(boot.get("samples") or []) if isinstance(boot, dict) else 0
    if battery.covariance is None and not n_boot:
        none = "none: the battery file holds no covariance or refits (a preset or a " \
               "hand-written file)"
        return {"parameters": none, "predictions": none}
    parameters = ("from the fit's parameter covariance (Student t)"
                  if isinstance(battery.extra.get("ci95"), dict) or battery.covariance
                  is not None else "unavailable")
    predictions = (f"{n_boot} bootstrap refits stored by the fit" if n_boot
                   else "sampling the fit's parameter covariance")
    return {"parameters": parameters, "predictions": predictions}


def model_statement(battery: Battery) -> str:
    """One sentence naming the model family, the data fitted and the interval method."""
    data = fitted_data(battery)
    methods = interval_methods(battery)
    fitted = (f"fitted on {len(data)} measured discharge(s): {'; '.join(data)}" if data
              else "not fitted to data recorded in the battery file")
    return (f"Model: {battery.family.title} (model '{battery.model}'), {fitted}. "
            f"Parameter intervals: {methods['parameters']}; prediction intervals: "
            f"{methods['predictions']}.")


def _battery_facts(battery: Battery) -> list[tuple[str, str]]:
    """The summary rows under the parameter table (label, value); add a row here."""
    extra = battery.extra
    methods = interval_methods(battery)
    facts = [("model family", f"{battery.family.title} ({battery.model})")]
    data = fitted_data(battery)
    if data:
        facts.append(("fitted on", "; ".join(data)))
    facts += [("parameter intervals (95 %)", methods["parameters"]),
              ("prediction intervals", methods["predictions"])]
    if extra.get("rmse_V") is not None:
        facts.append(("fit RMSE", f"{1000 * float(extra['rmse_V']):.2f} mV per cell"))
    error = extra.get("model_error")
    if isinstance(error, dict) and isinstance(error.get("relative_sd"), (int, float)):
        facts.append(("held-out error of the time to cutoff", held_out_summary(error)))
    thermal = extra.get("thermal")
    if isinstance(thermal, dict) and thermal.get("Cth_J_per_K") is not None:
        facts.append(("thermal model", f"heat capacity {float(thermal['Cth_J_per_K']):.3g} J/K, "
                      f"thermal resistance {float(thermal['Rth_K_per_W']):.3g} K/W "
                      f"({thermal.get('source', '')})"))
    if battery.fit_currents_A and not data:
        facts.append(("fitted at (cell current)",
                      ", ".join(f"{x:.3g} A" for x in battery.fit_currents_A)))
    if extra.get("n_samples"):
        facts.append(("samples fitted", str(extra["n_samples"])))
    src = extra.get("source")
    if isinstance(src, dict) and src.get("reference"):
        facts.append(("coefficients from", str(src["reference"])))
    if isinstance(extra.get("logbook"), dict) and extra.get("note"):
        facts.append(("logbook pack today", str(extra["note"])))
    return facts


def _ocv_figure(battery: Battery) -> str:
    """The open-circuit voltage curve the fit found, beside the chemistry's generic one."""
    from .ocv import OCV_SOURCE, check_chemistry, ocv_from_soc
    from .plot import plot_ocv

    chemistry = check_chemistry(battery.chemistry)
    soc = np.linspace(1.0, 0.0, 101)
    label = OCV_SOURCE[chemistry].split(" from ")[0] + (
        "" if battery.chemistry else " (chemistry not given)")
    ax = plot_ocv(battery, reference=(label, soc, ocv_from_soc(soc, chemistry)))
    return _figure(ax, "Open-circuit voltage per cell against the state of "
                   "charge: the fitted curve and the chemistry's generic curve.",
                   "open-circuit voltage curve", "half")


def _battery_section(battery: Battery) -> str:
    extra = battery.extra
    ocv_names = set(battery.family.ocv_parameters)
    main = [n for n in battery.parameter_names if n not in ocv_names]
    parts = ["<h2>Battery model</h2>",
             f'<p class="sub">{_e(battery.family.title)} (model '
             f"<code>{_e(battery.model)}</code>) per cell, pack "
             f"{battery.cells_series}S{battery.strings_parallel}P"
             f"{', ' + _e(battery.chemistry) if battery.chemistry else ''}; model capacity "
             f"{battery.capacity_Ah:.3f} Ah per pack.</p>",
             _table(PARAMETER_HEADERS, _parameter_rows(battery, main), text_columns=(1,))]
    if ocv_names:
        parts.append(_ocv_figure(battery))
        parts.append(_folded(f"the curve's {len(ocv_names)} parameters (open-circuit voltage "
                             f"drops between state-of-charge nodes)",
                             _table(PARAMETER_HEADERS, _parameter_rows(battery, ocv_names),
                                    text_columns=(1,))))
    facts = _battery_facts(battery)
    if facts:
        parts.append(_facts(facts))
    src = extra.get("source")
    if battery.covariance is None:
        parts.append(_messages(["no parameter covariance stored (a preset or hand-written "
                                "file): intervals and the endurance uncertainty are "
                                "unavailable"], "note"))
    if isinstance(src, dict) and src.get("note"):
        parts.append(_messages([src["note"]], "note"))
    parts.append(_messages([str(m) for m in extra.get("notes", []) or []], "note"))
    parts.append(_messages([str(m) for m in extra.get("warnings", []) or []], "warn"))
    advice = fit_next_test(battery)
    if advice is not None:
        parts.append(_messages([advice["text"]], "note"))
    return "".join(parts)


@dataclass
class _StoredFit:
    """What :func:`dischargelab.plot.plot_fit` needs, rebuilt from a battery file."""

    curves: list
    parameters: object
    cells_series: int
    strings_parallel: int
    rmse_V: float
    current_scale: float = 1.0
    model: str = "shepherd"

    def predicted_voltage(self, curve):
        from .fit import _stack
        from .models import get_family

        data = _stack([curve], self.cells_series, self.strings_parallel, use_rest=False,
                      weighting="samples", max_samples=curve.time_s.size)
        data.current = data.current * self.current_scale
        data.charge = data.charge * self.current_scale
        with np.errstate(invalid="ignore", over="ignore"):
            return self.cells_series * get_family(self.model).fit_voltage(self.parameters, data)


def _read_options(entry: dict) -> dict:
    """read_discharge options that reproduce how a fitted file was read."""
    options = {}
    columns = {}
    for key, text in (entry.get("column_map") or {}).items():
        match = re.match(r"column (\d+)", str(text))
        if match:
            columns[key] = int(match.group(1))
    if columns:
        options["columns"] = columns
    units = {}
    for key, text in (entry.get("units") or {}).items():
        if str(text).endswith("(given)"):
            units[key] = str(text).split(" ")[0]
    if units:
        options["units"] = units
    if isinstance(entry.get("segment"), int) and len(entry.get("segments") or []) > 1:
        options["segment"] = entry["segment"]
    return options


def _fit_section(battery: Battery, base_dir: Path | None = None) -> str:
    from .fit import Curve
    from .io import read_discharge
    from .plot import plot_fit

    head = "<h2>Fit to the measured discharge</h2>"
    sources = battery.extra.get("source")
    if not isinstance(sources, list) or not sources:
        return head + _messages(["the battery file names no measured source files (a preset "
                                 "or a hand-written file): fit plot skipped"], "note")
    p = battery.strings_parallel
    paper = battery.extra.get("paper_mode") if isinstance(battery.extra.get("paper_mode"),
                                                          dict) else None
    curves, missing = [], []
    for k, entry in enumerate(sources):
        path = entry.get("source") if isinstance(entry, dict) else None
        if path and not Path(path).exists() and base_dir is not None and \
                (base_dir / path).exists():
            path = str(base_dir / path)       # relative to the battery file
        if not path or not Path(path).exists():
            missing.append(str(path))
            continue
        options = _read_options(entry)
        if entry.get("current_source") == "given":
            measured = (paper or {}).get("measured_currents_A") or battery.fit_currents_A
            if k < len(measured):
                options["current_A"] = float(measured[k]) * p
        try:
            data, meta = read_discharge(path, **options)
            curves.append(Curve.from_frame(data, meta, name=Path(path).name))
        except DischargelabError as exc:
            missing.append(f"{path} ({exc})")
    notes = [f"source file not readable here: {m}" for m in missing]
    if not curves:
        return head + _messages(notes + ["fit plot skipped: none of the fitted files is "
                                         "reachable"], "note")
    stored = _StoredFit(curves, battery.parameters, battery.cells_series, p,
                        float(battery.extra.get("rmse_V") or np.nan),
                        float((paper or {}).get("current_scale", 1.0)), battery.model)
    ax = plot_fit(stored, x="charge")
    return head + _figure(ax, "Measured pack voltage (dots) and the fitted model (lines); "
                              "residuals below.", "fit of the model to the measured discharge") \
        + _messages(notes, "note")


def _family_currents(battery: Battery) -> list[float]:
    p = battery.strings_parallel
    fitted = sorted({round(abs(x), 6) for x in battery.fit_currents_A if x})
    if fitted:
        cell = [fitted[0] / 2, *fitted, fitted[-1] * 2]
    else:
        c = float(battery.parameters.C_Ah)
        cell = [0.2 * c, c, 2 * c, 5 * c]
    return sorted({float(f"{x * p:.3g}") for x in cell})


def _family_section(battery: Battery, cutoff_cell_V, currents_A) -> str:
    from .plot import plot_family
    from .simulate import curve_family

    head = "<h2>Simulated discharges</h2>"
    if cutoff_cell_V is None:
        return head + _messages(["no cutoff voltage known (chemistry unknown): give a cutoff "
                                 "to draw the curve family"], "note")
    currents = list(currents_A) if currents_A else _family_currents(battery)
    results, failed = [], []
    for current in currents:
        try:
            results.extend(curve_family(battery, [current], cutoff_cell_V=cutoff_cell_V))
        except DischargelabError as exc:
            failed.append(f"{current:g} A: {exc}")
    rows = [[f"{r.steps[0].value:.4g}", f"{r.steps[0].value / battery.strings_parallel:.4g}",
             duration(r.time_to_cutoff_s), f"{r.capacity_Ah:.3f}", f"{r.energy_Wh_total:.2f}"]
            for r in results]
    parts = [head, f'<p class="sub">Constant-current discharges to {cutoff_cell_V:g} V per '
                   f"cell (paper Figs 5, 7, 10). Rates far from the fitted ones are "
                   f"extrapolations.</p>"]
    if results:
        parts.append(_figure(plot_family(results, x="charge"), "Pack voltage against the "
                             "charge delivered at each current.", "simulated discharge curves"))
        parts.append(_table(["pack current [A]", "cell current [A]", "time to cutoff",
                             "capacity [Ah]", "energy [Wh]"], rows))
    parts.append(_messages(failed, "warn"))
    return "".join(parts)


def _interval_text(unc: dict | None, key: str, minutes=True) -> str:
    if not unc or not unc.get("available") or key not in unc:
        return "unavailable"
    d = unc[key]
    if minutes:
        return duration_interval([d["low"], d["high"]])
    return f"{d['low']:.1f} to {d['high']:.1f}"


def _mission_section(result) -> str:
    m = result.mission
    unc = result.uncertainty
    st = result.stretch
    parts = ["<h2>Mission</h2>",
             f'<p class="sub">{_e(m.name)} ({_e(Path(m.source).name) if m.source else "in code"})'
             f"; take-off at {m.initial_soc_pct:g} % state of charge, reserve "
             f"{m.reserve_pct:g} %, cutoff {m.cutoff_cell_V:g} V per cell "
             f"({m.cutoff_pack_V:.2f} V pack).</p>"]
    if not result.completed:
        parts.append(_messages([f"the mission does NOT complete: the {result.ended_by} is "
                                f"reached at {duration(result.flight_time_s)}"], "bad"))
    rows = [["flight time as planned", duration(result.flight_time_s)],
            ["endurance (landing at the reserve)" if st else "endurance",
             duration(result.endurance_s)],
            ["95 % interval of the endurance", _interval_text(unc, "endurance_s")],
            ["state of charge at landing", f"{result.soc_end_pct:.1f} %"
             + (f" (95 %: {_interval_text(unc, 'soc_end_pct', False)} %)"
                if unc and unc.get("available") else "")],
            ["reserve reached at", duration(result.reserve_time_s)
             if np.isfinite(result.reserve_time_s) else "not during the flight"],
            ["cutoff reached at", duration(result.cutoff_time_s)
             if np.isfinite(result.cutoff_time_s) else "not during the flight"],
            ["lowest pack voltage", f"{number(result.min_voltage_V, 2)} V (margin "
                                    f"{number(result.voltage_margin_V, 2)} V to the cutoff)"],
            ["charge / energy used", f"{result.simulation.capacity_Ah:.3f} Ah / "
                                     f"{result.simulation.energy_Wh_total:.1f} Wh"]]
    if st:
        rows.insert(2, [f"longest '{st['phase']}'", f"{duration(st['max_s'])} (limited by the "
                                                     f"{st['binding']})"])
        if st["margin_s"] is not None:
            rows.insert(3, [f"margin on '{st['phase']}'", duration(st["margin_s"])])
    if unc is not None and not unc.get("available"):
        rows.append(["uncertainty", unc.get("reason", "unavailable")])
    elif unc and not unc.get("accepted"):
        rows.append(["uncertainty method", unc["method"]])
    elif unc:
        rejected = (f"; {100 * unc['rejected_fraction']:.0f} % of the draws tried were "
                    f"unphysical and rejected" if unc.get("rejected") else "")
        rows.append(["uncertainty method", f"{unc['method']}: {unc['accepted']} parameter sets"
                                           f"{rejected}; the mission completes with "
                                           f"{100 * unc['completed_fraction']:.0f} % of them"])
    if unc and unc.get("interval_includes"):
        rows.append(["the interval includes", " + ".join(unc["interval_includes"])])
    parts.append(_facts(rows))
    parts.append(_figure(result.plot(), "Pack voltage through the flight, phases shaded, "
                                        "cutoff and reserve marked (paper Fig. 11 style).",
                         "mission voltage profile"))
    phase_rows = [[r["phase"] + (f" #{r['repetition']}" if r["repetition"] else ""), r["load"],
                   duration(r["start_s"]), duration(r["duration_s"]),
                   f"{r['mean_current_A']:.2f}", f"{r['mean_power_W']:.1f}",
                   f"{r['charge_Ah']:.3f}", f"{r['end_voltage_V']:.2f}",
                   f"{r['end_soc_pct']:.1f}"] for r in result.phases]
    if len(phase_rows) > 40:
        phase_rows = phase_rows[:20] + [["...", "", "", "", "", "", "", "", ""]] + \
            phase_rows[-19:]
    parts.append(_folded(f"Phase by phase ({len(result.phases)} phases)",
                         _table(["phase", "load", "start", "duration", "current [A]",
                                 "power [W]", "charge [Ah]", "end voltage [V]", "end SOC [%]"],
                                phase_rows)))
    parts.append(_messages(result.warnings, "warn"))
    return "".join(parts)


def split_by_fit(cases) -> tuple[list, list, list]:
    """Validation cases as (held out, seen by the fit, unknown): a case is held out only
    when the battery file records the data its fit saw and this file is not among them."""
    held = [c for c in cases if c.summary.get("in_fit") is False]
    seen = [c for c in cases if c.summary.get("in_fit") is True]
    unknown = [c for c in cases if c.summary.get("in_fit") is None]
    return held, seen, unknown


def _case_names(cases) -> str:
    return ", ".join(f"{Path(c.summary['file']).name} ({c.summary['current_A']:.3g} A)"
                     for c in cases)


def _validation_cards(cases) -> list[tuple[str, str, str]]:
    """Headline cards: "validation" only for data the fit did not see."""
    from .validate import summarise

    held, seen, unknown = split_by_fit(cases)
    cards = []
    for group, head, note in (
            (held, "held-out validation: mean endurance error", ", not in the fit"),
            (seen, "fit check, not a validation: mean endurance error",
             ", data the fit saw"),
            (unknown, "measured discharges: mean endurance error",
             "; the battery file does not record its data, so whether the fit saw them is "
             "unknown")):
        if group:
            agg = summarise([c.summary for c in group])
            cards.append((head, f"{_fmt(agg['mean_abs_endurance_error_pct'], '.1f')} %",
                          _case_names(group) + note))
    return cards


def _validation_section(cases) -> str:
    from .plot import plot_validation
    from .validate import summarise

    rows = []
    warnings = []
    for c in cases:
        s = c.summary
        rows.append([Path(s["file"]).name, f"{s['current_A']:.3g}", s["profile"],
                     duration(s["endurance_measured_s"]), duration(s["endurance_predicted_s"]),
                     duration(s["endurance_error_s"], signed=True),
                     _fmt(s["endurance_error_pct"], "+.2f"),
                     _fmt(s["voltage_rmse_pct"], ".2f"), _fmt(s["voltage_max_error_pct"], ".2f"),
                     _fmt(s["voltage_max_error_operational_pct"], ".2f"),
                     {True: "yes", False: "no", None: "?"}[s["in_fit"]]])
        warnings += [f"{Path(s['file']).name}: {w}" for w in s["warnings"]]
    held, seen, unknown = split_by_fit(cases)
    means = []
    for group, what in ((held, "on the files the fit did not see (validation)"),
                        (seen, "on the files the fit saw (a fit check, not a validation)"),
                        (unknown, "on files the battery file cannot tell apart from its "
                                  "fitted data")):
        if group:
            agg = summarise([c.summary for c in group])
            means.append(f"{_fmt(agg['mean_abs_endurance_error_pct'], '.2f')} % {what}")
    head = ("Validation against measured discharges" if held and not seen and not unknown
            else "Measured discharges against the model")
    parts = [f"<h2>{head}</h2>",
             f'<p class="sub">Model driven with each measured current; endurance to '
             f"{cases[0].summary['cutoff_cell_V']:g} V per cell. Voltage errors in % of the "
             f"measured voltage; 'operational' is the part above 20 % state of charge (paper "
             f"4.4). Mean absolute endurance error {'; '.join(means)}.</p>",
             _table(["file", "current [A]", "profile", "measured", "predicted", "error",
                     "error [%]", "V RMS [%]", "V max [%]", "V max >20% SOC [%]", "in fit"],
                    rows),
             _figure(plot_validation(cases), "Measured (solid) and predicted (dashed) pack "
                                             "voltage per discharge (paper Figs 12-14).",
                     "measured and predicted discharges"),
             _messages(warnings, "warn")]
    return "".join(parts)


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------

def build_report(battery, *, mission_result=None, validation=None, title: str | None = None,
                 cutoff_cell_V: float | None = None, family_currents_A=None,
                 include_fit: bool = True) -> str:
    """HTML text of the report.

    Parameters
    ----------
    battery : Battery, preset name or battery-file path
    mission_result : MissionResult, optional
        From :func:`dischargelab.mission.run_mission` (with ``draws`` for intervals).
    validation : sequence of ValidationCase, optional
        From :func:`dischargelab.validate.compare_files`.
    title : str, optional
    cutoff_cell_V : float, optional
        Cutoff of the curve family; default: the mission's, the validation's, or the
        chemistry's usual value.
    family_currents_A : sequence of float, optional
        Pack currents of the curve family (default around the fitted currents).
    include_fit : bool
        Re-read the fitted source files to plot the fit when they are reachable.
    """
    label = "" if isinstance(battery, Battery) else Path(str(battery)).stem
    base_dir = None if isinstance(battery, Battery) else Path(str(battery)).parent
    battery = load_battery(battery)
    validation = list(validation or [])
    if cutoff_cell_V is None:
        if mission_result is not None:
            cutoff_cell_V = mission_result.mission.cutoff_cell_V
        elif validation:
            cutoff_cell_V = validation[0].summary["cutoff_cell_V"]
        else:   # the battery's own cutoff, else its chemistry's
            cutoff_cell_V = battery_identity(battery).cutoff_cell_V or \
                CUTOFF_CELL_VOLTAGE_V.get(battery.chemistry or "")
    name = battery.name or label or "battery"
    title = title or f"Battery and endurance report: {name}"
    now = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    from ._version import __version__

    cards = []
    if mission_result is not None:
        unc = mission_result.uncertainty
        interval = "" if not unc or not unc.get("available") else \
            f"95 %: {_interval_text(unc, 'endurance_s')}" + \
            ("" if unc.get("accepted") else " (model error only)")
        cards.append(("endurance" + (" (land at reserve)" if mission_result.stretch else ""),
                      duration(mission_result.endurance_s), interval or
                      "interval unavailable (no covariance)"))
        cards.append(("state of charge at landing", f"{mission_result.soc_end_pct:.0f} %",
                      f"reserve {mission_result.mission.reserve_pct:g} %"))
        if mission_result.stretch and mission_result.stretch["margin_s"] is not None:
            cards.append((f"margin on {mission_result.stretch['phase']}",
                          duration(mission_result.stretch["margin_s"]), "beyond the plan"))
    if validation:
        cards += _validation_cards(validation)
    methods = interval_methods(battery)
    cards.append(("model", battery.model, f"{battery.family.title}; prediction intervals: "
                                          f"{methods['predictions']}"))
    flown = mission_result.mission.battery if mission_result is not None else battery
    cards.append(("pack" + (" as flown" if mission_result is not None else ""),
                  f"{flown.cells_series}S{flown.strings_parallel}P",
                  f"{flown.capacity_Ah:.2f} Ah model capacity"))
    card_html = "".join(f'<div class="card"><div class="l">{_e(a)}</div><div class="v">{_e(b)}'
                        f'</div><div class="l">{_e(c)}</div></div>' for a, b, c in cards)
    sections = [_battery_section(battery)]
    if include_fit:
        sections.append(_fit_section(battery, base_dir))
    sections.append(_family_section(battery, cutoff_cell_V, family_currents_A))
    if mission_result is not None:
        sections.append(_mission_section(mission_result))
    if validation:
        sections.append(_validation_section(validation))
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>{_e(title)}</title><style>{CSS}</style></head><body><main>"
        f"<h1>{_e(title)}</h1><p class=\"sub\">Generated {now} by dischargelab "
        f"{_e(__version__)}.</p><div class=\"cards\">{card_html}</div>"
        + "".join(sections) +
        f"<footer>{_e(_footer(battery, mission_result))}</footer></main></body></html>\n"
    )


PAPER = ("\u201cMeasuring battery discharge characteristics for accurate UAV endurance "
         "estimation\u201d")


def _footer(battery: Battery, mission_result=None) -> str:
    """What was done, generated from the battery file and the mission's result."""
    parts = [model_statement(battery)]
    if battery.model == "shepherd":
        parts.append(f"The model is eq. (6) of {PAPER}.")
    elif battery.model.startswith("shepherd"):
        parts.append(f"The model extends eq. (6) of {PAPER}.")
    if mission_result is not None:
        unc = mission_result.uncertainty or {}
        how = ("no interval (no draws asked for)" if not unc else
               f"the 95 % interval from {unc.get('method')}"
               + (f", including {' + '.join(unc['interval_includes'])}"
                  if unc.get("interval_includes") else "")
               if unc.get("available") else f"no interval: {unc.get('reason', '')}")
        parts.append(f"Endurance by simulating each flight phase (as in {PAPER}); {how}.")
    parts.append("Predictions away from the fitted currents and temperatures are "
                 "extrapolations: keep a reserve.")
    return " ".join(parts)


def write_report(path, battery, **kwargs) -> Path:
    """Write :func:`build_report` to ``path`` (UTF-8, atomically); returns the path."""
    from .atomic import write_text

    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise DataError(f"report file must end in .html, got {path.name!r}")
    text = build_report(battery, **kwargs)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_text(path, text)


__all__ = ["build_report", "write_report", "model_statement", "interval_methods",
           "fitted_data", "split_by_fit"]
