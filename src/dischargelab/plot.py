"""Plots of fits, simulations and curve families.

matplotlib is imported inside each function (``import dischargelab`` stays
light). Every function takes ``ax=None`` (a new figure is made) and returns the
main Axes; nothing is shown: call ``ax.figure.savefig(path)`` or
:func:`save` yourself.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import DataError, require
from .formatting import duration, duration_interval

if TYPE_CHECKING:
    import pandas as pd

    from .flight import FlightReport


def _wrapped(title: str, width: int = 80) -> str:
    """A title broken into lines of at most ``width`` characters (a long battery name, such
    as the list of the runs it was fitted on, would run off the figure)."""
    return "\n".join(textwrap.wrap(title, width)) or title


def pyplot():
    """matplotlib.pyplot, with the Agg backend when there is no display."""
    require("matplotlib", "plot")
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo") and \
            not _has_display():
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _has_display() -> bool:
    import os
    import sys

    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or
                                                       os.environ.get("WAYLAND_DISPLAY"))


def _axes(ax, figsize=(8, 5)):
    if ax is not None:
        return ax
    plt = pyplot()
    fig, ax = plt.subplots(figsize=figsize, layout="constrained")
    return ax


def _stacked_axes(axes, figsize, ratios):
    """The given axes, or a new figure of panels stacked on one time axis (heights ``ratios``)."""
    if axes is None:
        _, axes = pyplot().subplots(len(ratios), 1, figsize=figsize, sharex=True,
                                    layout="constrained", gridspec_kw={"height_ratios": ratios})
    return np.asarray(axes)


#: File suffixes :func:`save` can write (matplotlib's static formats).
FIGURE_SUFFIXES = (".png", ".svg", ".svgz", ".pdf", ".jpg", ".jpeg", ".eps", ".ps", ".tif",
                   ".tiff", ".webp")


def check_path(path) -> Path:
    """Check that ``path`` names a figure format :func:`save` can write; returns it.

    Raises
    ------
    DataError
        The suffix is not one of :data:`FIGURE_SUFFIXES`.
    """
    path = Path(path)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise DataError(f"plot file {path} must end in one of {', '.join(FIGURE_SUFFIXES)} "
                        "(the suffix chooses the format)")
    return path


def save(ax, path, dpi: int = 130) -> Path:
    """Save the figure holding ``ax`` to ``path`` atomically (format from the suffix); close it."""
    from .atomic import save_figure

    plt = pyplot()
    fig = ax.figure
    try:
        return save_figure(fig, path, dpi=dpi)
    finally:
        plt.close(fig)


def plot_fit(result, ax=None, x: str = "charge"):
    """Measured and fitted pack voltage per curve, with a residual panel below.

    With ``ax`` given, the residual panel is an inset under it (leave room).

    Parameters
    ----------
    result : FitResult
    ax : matplotlib Axes, optional
    x : {"charge", "time"}
        Horizontal axis: discharged charge [Ah] or time [min].
    """
    plt = pyplot()
    if ax is None:
        fig, (ax, res_ax) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, layout="constrained",
                                         gridspec_kw={"height_ratios": [3, 1]})
    else:
        res_ax = ax.inset_axes([0.0, -0.42, 1.0, 0.28], sharex=ax)
    colors = _colors(len(result.curves))
    for curve, color in zip(result.curves, colors):
        xs = _xvalues(curve.charge_Ah, curve.time_s, x)
        fitted = result.predicted_voltage(curve)
        label = curve.name or f"{curve.mean_current_A:.3g} A"
        ax.plot(xs, curve.voltage_V, ".", ms=2, color=color, alpha=0.5,
                label=f"{label} measured")
        ax.plot(xs, fitted, "-", lw=1.5, color=color, label=f"{label} model")
        res_ax.plot(xs, (curve.voltage_V - fitted) * 1000, "-", lw=0.8, color=color)
    res_ax.axhline(0, color="0.3", lw=0.8)
    res_ax.set_ylabel("residual [mV]")
    res_ax.set_xlabel(_xlabel(x))
    ax.tick_params(labelbottom=False)
    ax.set_ylabel(f"pack voltage [V] ({result.cells_series}S{result.strings_parallel}P)")
    # wrapped between parameters (ecm names many); no-break spaces hold each one together
    title = f"{_fit_title(result)}   RMSE\u00a0{result.rmse_V * 1000:.1f}\u00a0mV/cell"
    ax.set_title(_wrapped(title, 95), fontsize=9)
    ax.grid(alpha=0.3)
    res_ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2 if len(result.curves) > 2 else 1)
    return ax


def _fit_title(result) -> str:
    """``model: E0=... R=...`` with the headline parameters of the fitted family."""
    from .models import get_family

    family = get_family(getattr(result, "model", "shepherd"))
    p = result.parameters
    shown = [f"{name}={float(p[name]):.4g}" for name in family.headline if name in p]
    return f"{family.name}: " + "  ".join(shown)


def plot_simulation(result, ax=None, x: str = "time", label: str | None = None, **kwargs):
    """Pack voltage of a :class:`~dischargelab.simulate.SimulationResult`.

    ``x`` is "time" [min] or "charge" [Ah].
    """
    ax = _axes(ax)
    xs = _xvalues(result.charge_Ah, result.time_s, x)
    ax.plot(xs, result.voltage_V, label=label, **kwargs)
    ax.set_xlabel(_xlabel(x))
    ax.set_ylabel("pack voltage [V]")
    ax.grid(alpha=0.3)
    return ax


def plot_family(results, ax=None, x: str = "charge", labels=None):
    """Curve family: one discharge per load, like the paper's Figs 5, 7 and 10."""
    ax = _axes(ax)
    colors = _colors(len(results))
    for k, (res, color) in enumerate(zip(results, colors)):
        if labels is not None:
            label = labels[k]
        else:
            step = res.steps[0]
            unit = "A" if step.kind == "current" else "W"
            label = (f"{step.value:g} {unit}: {duration(res.time_to_cutoff_s)}, "
                     f"{res.capacity_Ah:.3g} Ah, {res.energy_Wh_total:.3g} Wh")
        plot_simulation(res, ax=ax, x=x, label=label, color=color)
    if results:
        ax.axhline(results[0].cutoff_pack_V, color="0.4", ls="--", lw=0.8, label="cutoff")
        bat = results[0].battery
        ax.set_title(_wrapped(f"{bat.name or 'battery'} ({bat.cells_series}S"
                              f"{bat.strings_parallel}P): simulated discharges"), fontsize=10)
    ax.legend(fontsize=8)
    return ax



def plot_ocv(battery, ax=None, reference=None, points: int = 201):
    """Open-circuit voltage per cell against the state of charge.

    Parameters
    ----------
    battery : Battery
        Its family's ``open_circuit_voltage`` at rest, from full to the model capacity.
    ax : matplotlib Axes, optional
    reference : tuple (label, soc, voltage_V), optional
        Another curve to compare with, e.g. the chemistry's generic one
        (:func:`dischargelab.ocv.ocv_from_soc`): state of charge [0-1] and voltage per cell
        [V], drawn dashed.
    points : int
        Points along the state of charge.
    """
    ax = _axes(ax, figsize=(6.4, 4.0))
    fam = battery.family
    soc = np.linspace(1.0, 0.0, points)
    p = {n: float(battery.parameters[n]) for n in fam.names}
    state = fam.initial_state(p, charge_Ah=(1.0 - soc) * p["C_Ah"] * (1 - 1e-9))
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        ocv = np.asarray(fam.open_circuit_voltage(p, state), dtype=float)
    ax.plot(100 * soc, ocv, color="C0", lw=2, label=f"fitted ({fam.name})")
    if reference is not None:
        label, ref_soc, ref_V = reference
        ax.plot(100 * np.asarray(ref_soc), ref_V, color="0.45", ls="--", lw=1, label=label)
    ax.set_xlim(100, 0)
    ax.set_xlabel("state of charge [%]")
    ax.set_ylabel("open-circuit voltage per cell [V]")
    ax.set_title(_wrapped(f"{battery.name + ': ' if battery.name else ''}open-circuit voltage "
                          "per cell"), fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return ax


#: Phase shades: calm blues, greens, greys and violets; no red, orange or yellow, which
#: read as warnings (the cutoff line and reserve marker carry those).
PHASE_COLORS = ("#dbe8f6", "#dcefe1", "#e8e4f3", "#e3e6ea", "#d5ecef", "#eef0d9", "#e9e0ee",
                "#d9e3ec")
#: Rows of phase labels under the top of a mission plot before a label is left out.
PHASE_LABEL_ROWS = 3


def _label_phases(ax, spans) -> None:
    """Phase names over their bands, none overlapping: each goes in the first of
    :data:`PHASE_LABEL_ROWS` rows (from the top) where it clears the labels already there,
    turned upright in a band too narrow for it; a label with no room is left out (the
    phase table names every phase)."""
    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    trans = ax.get_xaxis_transform()
    x0, x1 = ax.get_xlim()
    taken = [[] for _ in range(PHASE_LABEL_ROWS)]      # (left, right) in display pixels
    for a, b, name in spans:
        lo, hi = max(a, x0), min(b, x1)
        if hi <= lo:
            continue
        centre = 0.5 * (lo + hi)
        band = ax.transData.transform([(lo, 0), (hi, 0)])[:, 0]
        for row in range(PHASE_LABEL_ROWS):
            label = ax.text(centre, 0.985 - 0.07 * row, name, ha="center", va="top",
                            fontsize=8, transform=trans, clip_on=True)
            box = label.get_window_extent(renderer)
            if box.width > band[1] - band[0] + 2:   # wider than its band: upright
                label.set_rotation(90)
                label.set_y(0.985)
                box = label.get_window_extent(renderer)
                if box.width > band[1] - band[0] + 2 or row:
                    label.remove()
                    continue
            clash = any(box.x0 < right + 3 and box.x1 > left - 3 for left, right in taken[row])
            if label.get_rotation() == 90:   # an upright label spans every row's height
                clash = clash or any(box.x0 < right + 3 and box.x1 > left - 3
                                     for r in taken for left, right in r)
            if clash:
                label.remove()
                continue
            rows = range(PHASE_LABEL_ROWS) if label.get_rotation() == 90 else (row,)
            for r in rows:
                taken[r].append((box.x0, box.x1))
            break


def plot_mission(result, ax=None, show_current: bool = True, label_phases: bool = True):
    """Pack voltage through a flight with the phases shaded (like the paper's Fig. 11).

    Draws the cutoff voltage, the moment the reserve is reached (if it is), the
    pack current on a second axis and a box with the endurance numbers.

    Parameters
    ----------
    result : dischargelab.mission.MissionResult
    ax : matplotlib Axes, optional
    show_current : bool
        Pack current [A] on a right-hand axis.
    label_phases : bool
        Write phase names in the shaded bands wide enough to hold them.
    """
    ax = _axes(ax, figsize=(10, 5.5))
    sim = result.simulation
    mission = result.mission
    minutes = sim.time_s / 60.0
    total = max(float(minutes[-1]), 1e-9)
    names = []
    for row in result.phases:
        if row["phase"] not in names:
            names.append(row["phase"])
    color_of = {n: PHASE_COLORS[k % len(PHASE_COLORS)] for k, n in enumerate(names)}
    # a pack that cannot deliver the first phase has no finite voltage: the cutoff frames it
    volts = np.asarray(sim.voltage_V, dtype=float)
    volts = volts[np.isfinite(volts)]
    v_lo = min(float(np.min(volts)) if volts.size else np.inf, mission.cutoff_pack_V)
    v_hi = max(float(np.max(volts)) if volts.size else -np.inf, mission.cutoff_pack_V)
    pad = 0.08 * max(v_hi - v_lo, 0.05 * v_hi)
    spans = []
    for row in result.phases:
        a, b = row["start_s"] / 60.0, row["end_s"] / 60.0
        ax.axvspan(a, b, color=color_of[row["phase"]], alpha=0.9, lw=0)
        if label_phases and (b - a) > 0.005 * total and row["repetition"] in (None, 1):
            spans.append((a, b, row["phase"]))
    ax.plot(minutes, sim.voltage_V, color="k", lw=1.6, label="pack voltage")
    ax.axhline(mission.cutoff_pack_V, color="tab:red", ls="--", lw=1.0,
               label=f"cutoff {mission.cutoff_pack_V:.2f} V ({mission.cutoff_cell_V:g} V/cell)")
    if np.isfinite(result.reserve_time_s):
        ax.axvline(result.reserve_time_s / 60.0, color="tab:orange", ls="-.", lw=1.2,
                   label=f"reserve {mission.reserve_pct:g} % reached "
                         f"({duration(result.reserve_time_s)})")
    if np.isfinite(result.cutoff_time_s):
        ax.axvline(result.cutoff_time_s / 60.0, color="tab:red", ls=":", lw=1.2,
                   label=f"cutoff reached ({duration(result.cutoff_time_s)})")
    st = result.stretch
    latest = None
    if st is not None and st["binding"] != "infeasible" and \
            abs(result.endurance_s - result.flight_time_s) > 1.0:
        latest = result.endurance_s / 60.0
        text = f"latest landing with the longest {st['phase']} " \
               f"({duration(result.endurance_s)}, " \
               f"{st['binding']})"
        if latest <= total:
            ax.axvline(latest, color="tab:purple", ls="--", lw=1.2, label=text)
        else:
            # the axis ends with the flight: the later landing is marked at its right edge
            ax.annotate(f"{text} \u2192", xy=(1.0, 0.5), xycoords="axes fraction",
                        xytext=(-4, 0), textcoords="offset points", ha="right", va="center",
                        fontsize=8, color="tab:purple",
                        bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": "tab:purple",
                              "lw": 0.8})
    ax.set_ylim(v_lo - pad, v_hi + 2.2 * pad)
    ax.set_xlim(0, total)
    if spans:
        _label_phases(ax, spans)
    ax.set_xlabel("time [min]")
    ax.set_ylabel(f"pack voltage [V] ({mission.battery.cells_series}S"
                  f"{mission.battery.strings_parallel}P)")
    ax.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if show_current:
        cur = ax.twinx()
        cur.plot(minutes, sim.current_A, color="tab:blue", lw=0.9, alpha=0.8,
                 label="pack current")
        cur.set_ylabel("pack current [A]", color="tab:blue")
        cur.tick_params(axis="y", colors="tab:blue")
        amps = np.asarray(sim.current_A, dtype=float)
        amps = amps[np.isfinite(amps)]
        cur.set_ylim(0, 1.6 * max(float(np.max(amps)) if amps.size else 0.0, 1e-6))
        h2, l2 = cur.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
    ax.legend(handles, labels, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.11),
              ncol=min(len(labels), 3), frameon=False)
    lines = [f"flight {duration(result.flight_time_s)}, lands at {result.soc_end_pct:.0f} % "
             f"(reserve {mission.reserve_pct:g} %)"]
    if result.stretch is not None and result.stretch["binding"] != "infeasible":
        st = result.stretch
        lines.append(f"max {st['phase']} {duration(st['max_s'])} -> endurance "
                     f"{duration(result.endurance_s)}")
        if st["margin_s"] is not None:
            lines.append(f"margin {duration(st['margin_s'], signed=True)} of {st['phase']}")
    unc = result.uncertainty or {}
    if unc.get("available"):
        e = unc["endurance_s"]
        lines.append(f"95 % interval {duration_interval([e['low'], e['high']])}")
    if not result.completed:
        lines.append(f"NOT COMPLETED: {result.ended_by} at {duration(result.flight_time_s)}")
    # two short lines rather than one long one, so narrow figures do not clip the title
    half = (len(lines) + 1) // 2
    ax.set_title(f"{mission.name}: {mission.battery.name or 'battery'}\n"
                 + "; ".join(lines[:half]) + ("\n" + "; ".join(lines[half:]) if lines[half:]
                                              else ""), fontsize=9)
    return ax


def plot_validation(cases, ax=None, x: str = "auto"):
    """Measured (solid) and predicted (dashed) discharges per rate (paper Figs 12-14).

    Parameters
    ----------
    cases : sequence of dischargelab.validate.ValidationCase
    ax : matplotlib Axes, optional
    x : {"auto", "time", "charge"}
        Time [min] or discharged charge [Ah] on the horizontal axis; "auto" uses
        time unless the durations differ by more than 4x (then charge).
    """
    from .cell import charge_from_current

    ax = _axes(ax, figsize=(9, 5.5))
    cases = list(cases)
    if x == "auto":
        spans = [float(c.time_s[-1]) for c in cases if c.time_s.size]
        x = "charge" if spans and max(spans) > 4 * max(min(spans), 1e-9) else "time"
    colors = _colors(len(cases))
    for case, color in zip(cases, colors):
        s = case.summary
        if x == "charge":
            xs_meas = charge_from_current(case.time_s, case.current_A)
            xs_pred = case.prediction.charge_Ah
        else:
            xs_meas = case.time_s / 60.0
            xs_pred = case.prediction.time_s / 60.0
        err = s["endurance_error_pct"]
        err_text = "no cutoff" if err is None else f"{err:+.1f} %"
        ax.plot(xs_meas, case.voltage_measured_V, "-", color=color, lw=1.4,
                label=f"{s['current_A']:.3g} A measured")
        ax.plot(xs_pred, case.prediction.voltage_V, "--", color=color, lw=1.4,
                label=f"{s['current_A']:.3g} A model (endurance {err_text})")
    if cases:
        cutoff = cases[0].summary["cutoff_pack_V"]
        ax.axhline(cutoff, color="0.4", ls=":", lw=0.9, label=f"cutoff {cutoff:.2f} V")
    ax.set_xlabel(_xlabel(x))
    ax.set_ylabel("pack voltage [V]")
    ax.set_title("measured vs predicted discharges", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2 if len(cases) > 3 else 1)
    return ax

def _xvalues(charge_Ah, time_s, x):
    if x == "charge":
        return np.asarray(charge_Ah)
    if x == "time":
        return np.asarray(time_s) / 60.0
    raise DataError(f"x must be 'charge' or 'time', got {x!r}")


def _xlabel(x):
    return "discharged charge [Ah]" if x == "charge" else "time [min]"


def _colors(n):
    plt = pyplot()
    cmap = plt.get_cmap("viridis")
    return [cmap(v) for v in np.linspace(0.0, 0.85, max(n, 1))]


def plot_discharge(discharge, ax=None):
    """A measured discharge: voltage (left axis) and current (right axis) against time."""
    ax = _axes(ax)
    ax.plot(discharge.time_s / 60.0, discharge.voltage_V, color="C0", lw=1.2, label="voltage")
    ax.set_xlabel("time from load start [min]")
    ax.set_ylabel("voltage [V]", color="C0")
    twin = ax.twinx()
    twin.plot(discharge.time_s / 60.0, discharge.current_A, color="C3", lw=0.8, alpha=0.7,
              label="current")
    twin.set_ylabel("current [A]", color="C3")
    ax.set_title(discharge.name or "discharge", fontsize=10)
    ax.grid(alpha=0.3)
    return ax


def plot_flight_report(report: FlightReport, axes=None):
    """Voltage (logged, predicted), current and remaining-time replay against log time.

    Parameters
    ----------
    report : FlightReport
    axes : sequence of three matplotlib Axes, optional

    Returns
    -------
    numpy.ndarray of Axes
    """
    axes = _stacked_axes(axes, (9, 8.5), [3, 2, 3])
    av, ai, ar = axes
    seen = set()

    def label(text):
        if text in seen:
            return None
        seen.add(text)
        return text

    tops = []
    for f in report.flights:
        smp = f.samples
        t = smp["time_s"].to_numpy()
        av.plot(t, smp["voltage_V"], color="0.35", lw=0.6, label=label("logged"))
        if "predicted_voltage_V" in smp:
            av.plot(t, smp["predicted_voltage_V"], color="tab:orange", lw=0.8, alpha=0.85,
                    label=label("model flying the logged current"))
        ai.plot(t, smp["current_A"], color="tab:blue", lw=0.6)
        for ax in axes:
            ax.axvspan(f.summary["start_s"], f.summary["end_s"], color="0.94", zorder=0)
        tops.append(_plot_replay(ar, f.replay, label))
    av.axhline(report.cutoff_cell_V * report.cells_series, color="tab:red", ls="--", lw=0.8,
               label=label(f"cutoff {report.cutoff_cell_V:g} V/cell"))
    av.set_ylabel("pack voltage [V]")
    ai.set_ylabel("current [A]")
    ar.set_ylabel("remaining flight time [s]")
    ar.set_xlabel("log time [s] (flights shaded)")
    limits = [x for x in tops if x is not None]
    if limits:
        ar.set_ylim(0, max(limits))
        ar.legend(fontsize=8, loc="upper right")
    else:
        ar.text(0.5, 0.5, "no remaining-time replay: give a battery model or the pack capacity",
                transform=ar.transAxes, ha="center", va="center", color="0.4")
    title = f"{Path(report.source).name}: {report.battery_label} ({report.cells_series} cells " \
            "in series)"
    if report.model:
        title += f"; model {report.model}"
    av.set_title(title, fontsize=10)
    av.legend(fontsize=8, loc="upper right")
    for ax in axes:
        ax.grid(True, lw=0.3, alpha=0.6)
    return axes


def _plot_replay(ax, replay: pd.DataFrame, label) -> float | None:
    """Draw the replay columns; returns a y-limit that keeps the bulk visible (or None)."""
    if replay.empty:
        return None
    t = replay["time_s"].to_numpy()
    styles = [("true_s", "truth: logged voltage stays under the cutoff", "k", "-", None),
              ("model_profile_s", "model repeating the recent load (peaks kept)", "tab:red",
               "-", "D"),
              ("model_s", "model at the recent mean load", "tab:orange", "-", "o"),
              ("model_logged_load_s", "model flying the logged load (hindsight)", "tab:orange",
               ":", None),
              ("px4_s", "PX4 method (remaining x capacity / mean current)", "tab:green", "-",
               "^"),
              ("ardupilot_s", "ArduPilot method ((capacity - used) / mean current)",
               "tab:purple", "-", "s")]
    values = []
    for column, text, color, ls, marker in styles:
        y = replay[column].to_numpy(dtype=float)
        m = np.isfinite(y)
        if m.any():
            ax.plot(t[m], y[m], color=color, ls=ls, marker=marker, ms=3, lw=1.0, label=label(text))
            values.append(y[m])
    if not values:
        return None
    every = np.concatenate(values)
    return float(min(np.max(every), 2.0 * np.percentile(every, 75))) * 1.05


#: Marker and colour of each event kind in :func:`plot_health` (others: grey dots).
KIND_STYLE = {"full": ("o", "C0", "capacity test (full discharge)"),
              "partial": ("s", "C2", "partial discharge"),
              "flight": ("^", "C4", "flight"),
              "charge": ("v", "C5", "charge")}


def cell_figures(event: dict) -> tuple[float | None, float | None]:
    """Rest-voltage spread [V] and weakest cell's share of the capacity of an event's
    per-cell figures (``cells``), when it has them."""
    cells = event.get("cells")
    if not isinstance(cells, dict):
        return None, None
    spread = next((cells[k] for k in ("rest_spread_V", "spread_V", "rest_voltage_spread_V")
                   if cells.get(k) is not None), None)
    share = next((cells[k] for k in ("weakest_share", "weakest_capacity_share")
                  if cells.get(k) is not None), None)
    return spread, share


def plot_health(health, axes=None):
    """A pack's health against equivalent full cycles (``logbook health --plot``).

    Capacity: each event's estimate with its 95 % interval, by kind (outliers
    hollow, left out of the trend); the capacity trend with its 95 % band, carried
    on by the forecast's futures; the knee when the data show one; the end-of-life
    threshold, the EFC where it is reached and its 95 % interval; today's capacity.
    Resistance: per event with its interval and its trend. Cells: the rest-voltage
    spread between cells and the weakest cell's share, when cell voltages are logged.

    Parameters
    ----------
    health : dischargelab.logbook.Health
    axes : sequence of matplotlib Axes, optional
        Two (capacity, resistance), or three when events carry per-cell figures.

    Returns
    -------
    numpy.ndarray of Axes
    """
    rows = [(e, e.to_dict()) for e in health.events if e.efc is not None]
    with_cells = [(d["efc"], *cell_figures(d)) for _, d in rows
                  if any(v is not None for v in cell_figures(d))]
    axes = _stacked_axes(axes, (9, 8.5) if with_cells else (9, 7.5),
                         [3, 2, 1.5] if with_cells else [3, 2])
    ax_c, ax_r = axes[0], axes[1]
    fc, today = health.forecast, health.today
    if fc is not None:
        _plot_forecast(ax_c, fc, health.reference_capacity_Ah)
    elif health.capacity_trend is not None and health.capacity_trend.efc.size > 1:
        _plot_trend(ax_c, health.capacity_trend, 1.0, "C0", "capacity trend, 95 % band")
    caps = [(e, d) for e, d in rows if e.capacity_Ah is not None]
    _plot_estimates(ax_c, caps, "capacity_Ah", "capacity_interval95", 1.0)
    if today.get("capacity_Ah") is not None and today.get("efc") is not None:
        lo, hi = today["capacity_interval95"]
        ax_c.errorbar([today["efc"]], [today["capacity_Ah"]],
                      yerr=[[today["capacity_Ah"] - lo], [hi - today["capacity_Ah"]]],
                      fmt="*", ms=11, color="k", mfc="gold", capsize=3, zorder=5,
                      label=f"today: {today['capacity_Ah']:.3g} Ah ({lo:.3g}-{hi:.3g})")
    if caps:
        # the scale holds the estimates that tell the capacity to within +-PRECISE_SHARE
        # (all when none do) and the threshold: a long log's coarse estimates would else
        # stretch it far beyond the capacity
        values = [e.capacity_Ah for e, _ in caps if _precise(e)] or \
            [e.capacity_Ah for e, _ in caps]
        top = max(values)
        bottom = min(values + ([fc.threshold_Ah] if fc is not None else []))
        span = max(top - bottom, 1e-3)
        ax_c.set_ylim(max(bottom - 0.35 * span, 0.0), top + 0.15 * span)
        ax_c.legend(loc="upper right", fontsize=7.5, ncol=2)
    else:
        ax_c.text(0.5, 0.5, "no capacity measured yet", transform=ax_c.transAxes, ha="center")
    ax_c.set_ylabel("capacity [Ah]")
    ax_c.set_title(_health_title(health), fontsize=10)
    ax_c.grid(alpha=0.3)
    basis = today.get("resistance_basis") or "as measured"
    res = [(e, d) for e, d in rows if d.get("resistance_ref_ohm" if basis.startswith("ref")
                                            else "resistance_ohm") is not None]
    key = "resistance_ref_ohm" if basis.startswith("ref") else "resistance_ohm"
    interval = "resistance_ref_interval95" if basis.startswith("ref") else \
        "resistance_interval95"
    if health.resistance_trend is not None and health.resistance_trend.efc.size > 1:
        _plot_trend(ax_r, health.resistance_trend, 1000.0, "C2", "trend, 95 % band")
    if res:
        _plot_estimates(ax_r, res, key, interval, 1000.0)
        ax_r.legend(loc="lower right", fontsize=7.5, ncol=2)
    else:
        ax_r.text(0.5, 0.5, "no load steps to measure the resistance", transform=ax_r.transAxes,
                  ha="center")
    ax_r.set_ylabel(f"resistance [mOhm]\n({basis})")
    ax_r.grid(alpha=0.3)
    last = axes[-1]
    if len(axes) > 2 and with_cells:
        _plot_cells(axes[2], with_cells)
    last.set_xlabel("equivalent full cycles [EFC]")
    return np.asarray(axes)


def _health_title(health) -> str:
    fc = health.forecast
    if fc is None:
        return f"{health.pack}: capacity and resistance against equivalent full cycles"
    if getattr(fc, "status", "dated") == "no fade":
        return f"{health.pack}: no fade measured yet ({fc.estimates} estimates)"
    if not fc.shape or fc.bend_odds is None or not np.isfinite(fc.bend_odds):
        return (f"{health.pack}: a fade measured, not yet enough for an end of life "
                f"({fc.estimates} estimates)")
    shape = {"line": "no bend", "early": "a fast early fade, then a line",
             "knee": "a knee", "early+knee": "a fast early fade and a knee"}.get(fc.shape,
                                                                                fc.shape)
    return (f"{health.pack}: the capacity trend has {shape} (odds against a straight "
            f"line {fc.bend_odds:.3g}; {fc.estimates} estimates)")


def _plot_trend(ax, trend, scale, color, label):
    lo, hi = trend.band()
    ax.fill_between(trend.efc, lo * scale, hi * scale, color=color, alpha=0.15, lw=0,
                    label=label)
    ax.plot(trend.efc, trend.level * scale, color=color, lw=1.2)


def _plot_forecast(ax, fc, reference):
    band = fc.band
    efc = np.asarray(band["efc"], dtype=float)
    mid = np.asarray(band["capacity_Ah"], dtype=float)
    lo, hi = np.asarray(band["lo"], dtype=float), np.asarray(band["hi"], dtype=float)
    past = efc <= fc.last_efc
    ax.fill_between(efc[past], lo[past], hi[past], color="C0", alpha=0.18, lw=0,
                    label="capacity trend, 95 % band")
    ax.plot(efc[past], mid[past], color="C0", lw=1.2)
    ahead = efc >= fc.last_efc
    if (efc > fc.last_efc).any():  # futures only once an end of life is forecast
        ax.fill_between(efc[ahead], lo[ahead], hi[ahead], color="C1", alpha=0.13, lw=0,
                        label="forecast: median, 95 % of futures")
        ax.plot(efc[ahead], mid[ahead], color="C1", lw=1.2, ls="--")
    ax.axhline(fc.threshold_Ah, color="C3", lw=1, ls=":",
               label=f"end of life ({100 * fc.eol:.0f} % of {reference:.3g} Ah)")
    if fc.knee_efc is not None:
        ax.axvline(fc.knee_efc, color="C5", lw=1.2, ls="-.",
                   label=f"knee at {fc.knee_efc:.0f} EFC (probability "
                         f"{fc.knee_probability:.2f})")
    a, b = fc.eol_efc_interval95
    if getattr(fc, "status", "dated") in ("no fade", "uncertain"):
        words = ("no end of life: no fade measured yet" if fc.status == "no fade"
                 else "no end of life yet: the fade is not measured well enough")
        ax.plot([], [], " ", label=words)
    if fc.reached:
        ax.axvline(fc.last_efc, color="C3", lw=1.2,
                   label=f"end of life reached: the trend is below it at {fc.last_efc:.0f} EFC")
    elif fc.eol_efc is not None:
        ax.axvspan(a if a is not None else efc.min(), b if b is not None else efc.max(),
                   color="C3", alpha=0.07, lw=0)
        how = "observed at" if fc.observed else "at"
        span = "between events" if fc.observed else "95 %"
        ax.axvline(fc.eol_efc, color="C3", lw=1.2,
                   label=f"end of life {how} {fc.eol_efc:.0f} EFC ({span}: "
                         f"{'?' if a is None else f'{a:.0f}'}-"
                         f"{'open' if b is None else f'{b:.0f}'})")


#: An estimate whose 95 % interval is within this share of its value on each side sets the
#: capacity scale of :func:`plot_health`.
PRECISE_SHARE = 0.15
#: A kind with more estimates than this is drawn faint and under the trend's band (a long
#: log's thousands of missions would hide it).
CROWDED = 150


def _precise(e) -> bool:
    iv = e.capacity_interval95
    return (iv is not None and None not in iv
            and iv[1] - iv[0] <= 2 * PRECISE_SHARE * e.capacity_Ah)


def _plot_estimates(ax, rows, key, interval, scale):
    """Per-event estimates with their 95 % intervals, one marker per kind; outliers hollow;
    a kind with more than :data:`CROWDED` estimates faint, under the trend."""
    kinds = sorted({d.get("kind") for _, d in rows}, key=lambda k: (k not in KIND_STYLE, k))
    for kind in kinds:
        crowded = sum(1 for _, d in rows if d.get("kind") == kind) > CROWDED
        look = dict(ms=2, lw=0.4, alpha=0.25, zorder=0.5) if crowded else \
            dict(ms=4, lw=0.8, zorder=3)
        marker, color, label = KIND_STYLE.get(kind, ("o", "0.5", str(kind)))
        for outlier in (False, True):
            sel = [(e, d) for e, d in rows if d.get("kind") == kind and bool(e.outlier) == outlier]
            if not sel:
                continue
            x = np.array([d["efc"] for _, d in sel])
            y = np.array([d[key] for _, d in sel], dtype=float) * scale
            err = np.array([[0.0, 0.0] if not d.get(interval) or None in d[interval] else
                            [d[key] - d[interval][0], d[interval][1] - d[key]]
                            for _, d in sel], dtype=float).T * scale
            ax.errorbar(x, y, yerr=np.clip(err, 0, None), fmt=marker, capsize=0, **look,
                        color=color, mfc="white" if outlier else color,
                        label=f"{label} (outlier, left out)" if outlier else label)


def _plot_cells(ax, with_cells):
    efc = np.array([r[0] for r in with_cells], dtype=float)
    spread = np.array([np.nan if r[1] is None else r[1] for r in with_cells], dtype=float)
    share = np.array([np.nan if r[2] is None else r[2] for r in with_cells], dtype=float)
    if np.isfinite(spread).any():
        ax.plot(efc, spread * 1000, "o-", ms=3, lw=0.8, color="C6",
                label="rest-voltage spread between cells")
        ax.set_ylabel("cell spread [mV]")
        ax.legend(loc="upper left", fontsize=7.5)
    if np.isfinite(share).any():
        twin = ax.twinx()
        twin.plot(efc, share * 100, "s--", ms=3, lw=0.8, color="C7",
                  label="weakest cell's share of the capacity")
        twin.set_ylabel("weakest cell [%]")
        twin.legend(loc="upper right", fontsize=7.5)
    ax.grid(alpha=0.3)

#: Shade of each kind of tester step in :func:`plot_tester_steps`.
STEP_COLORS = {"charge": "C0", "discharge": "C3", "rest": "0.85"}
#: Up to this many steps, the discharge steps are numbered on the plot.
MAX_NUMBERED_STEPS = 60


def plot_tester_steps(frame, steps: list[dict], meta: dict, axes=None):
    """Voltage and current of a battery tester's file over test time, steps shaded by kind.

    Parameters
    ----------
    frame : pandas.DataFrame
        ``time_s`` [s], ``voltage_V`` [V], ``current_A`` [A, discharge positive].
    steps : list of dict
        The steps (:func:`dischargelab.io.cyclers.steps.step_table`).
    meta : dict
        ``source`` and ``format`` for the title.
    axes : sequence of two matplotlib Axes, optional

    Returns
    -------
    numpy.ndarray of Axes
    """
    axes = _stacked_axes(axes, (10, 6), [3, 2])
    av, ai = axes
    t = frame["time_s"].to_numpy(dtype=float)
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    scale, unit = (3600.0, "h") if span > 4 * 3600 else (60.0, "min") if span > 600 else (1.0, "s")
    x = (t - t[0]) / scale
    i = frame["current_A"].to_numpy(dtype=float)
    current_scale, current_unit = (1e3, "mA") if np.max(np.abs(i)) < 0.5 else (1.0, "A")
    av.plot(x, frame["voltage_V"].to_numpy(dtype=float), lw=0.8, color="k")
    ai.plot(x, i * current_scale, lw=0.8, color="k")
    shown = set()
    for s in steps:
        if s["kind"] == "rest" and s["rows"] < 2:
            continue
        a, b = (s["start_s"] - t[0]) / scale, (s["end_s"] - t[0]) / scale
        label = s["kind"] if s["kind"] not in shown else None
        shown.add(s["kind"])
        for ax in axes:
            ax.axvspan(a, b, color=STEP_COLORS.get(s["kind"], "0.9"), alpha=0.18, lw=0,
                       label=label if ax is av else None)
        full = s["kind"] == "discharge" and s.get("after_charge") and s.get("to_limit")
        if len(steps) <= MAX_NUMBERED_STEPS and s["kind"] == "discharge":
            av.annotate(f"{s['number']}" + ("*" if full else ""), ((a + b) / 2, 1.0),
                        xycoords=("data", "axes fraction"), ha="center", va="bottom",
                        fontsize=7, color="C3")
    av.set_ylabel("voltage [V]")
    ai.set_ylabel(f"current [{current_unit}] (discharge +)")
    ai.set_xlabel(f"test time [{unit}]")
    av.legend(loc="lower left", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    name = Path(str(meta.get("source", ""))).name
    numbered = ("; discharge steps numbered, * = full (from a charge to the lower limit)"
                if len(steps) <= MAX_NUMBERED_STEPS else "")
    av.set_title(f"{name} ({meta.get('format')}): {len(steps)} steps{numbered}", fontsize=9,
                 pad=14)
    return axes
