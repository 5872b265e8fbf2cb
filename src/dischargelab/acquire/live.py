"""Live view of a running test: terminal panel (rich), periodic lines, matplotlib window.

:class:`LiveDisplay` is a pipeline Consumer that keeps the numbers (voltage,
per-cell voltage, charge and energy, trend, rates, link state); rendering is
done from the main thread, so a slow terminal never slows the data file.
The terminal view needs no graphics and works over SSH; :class:`LivePlot` is
the optional window (``--plot``), the paper's "meter and graph" consumer.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections import deque

from ..errors import DischargelabError
from ..formatting import duration

SPARK_CHARS = "▁▂▃▄▅▆▇█"

#: Samples kept for the time-to-cutoff estimate, and the test-time window it uses [s]
#: (the voltage trend, or the mean current run through the battery model).
RECENT_POINTS = 600
ETA_WINDOW_S = 120.0
#: Least wall-clock time between two runs of the battery model for the estimate [s].
MODEL_EVERY_S = 1.0
#: Test time at the start whose mean voltage and current say, through the battery model,
#: how much charge the pack had given before the test [s] (one sample is not enough:
#: on a flat curve one ADC step of the pack voltage is several % of the charge).
START_WINDOW_S = 30.0


def sparkline(values, width: int = 48) -> str:
    """Unicode bar sparkline of ``values`` resampled to ``width`` characters."""
    vals = [v for v in values if v is not None and math.isfinite(v)]
    if not vals:
        return ""
    if len(vals) > width:
        step = len(vals) / width
        vals = [vals[min(len(vals) - 1, int((i + 0.5) * step))] for i in range(width)]
    lo, hi = min(vals), max(vals)
    span = hi - lo
    if span <= 0:
        return SPARK_CHARS[len(SPARK_CHARS) // 2] * len(vals)
    top = len(SPARK_CHARS) - 1
    return "".join(SPARK_CHARS[round((v - lo) / span * top)] for v in vals)


class Trend:
    """Whole-test history decimated to at most ``2 * points`` values (constant memory)."""

    def __init__(self, points: int = 240):
        self.points = points
        self.step_s = 0.0
        self.times: list[float] = []
        self.values: list[float] = []
        self._next_t = -math.inf

    def add(self, t: float, value: float) -> None:
        if t < self._next_t:
            return
        self.times.append(t)
        self.values.append(value)
        if len(self.times) >= 2 * self.points:
            self.times = self.times[::2]
            self.values = self.values[::2]
            self.step_s = max(self.step_s * 2, (self.times[-1] - self.times[0]) / self.points)
        self._next_t = t + self.step_s


class LiveDisplay:
    """Numbers of a running test (pipeline Consumer) and their terminal rendering.

    Parameters
    ----------
    cells_series : int
    cutoff_pack_V : float, optional
    current_given_A : float, optional
        Constant current [A] known from the test set-up (``--current``), used for
        charge and energy when no current is measured.
    stats : callable, optional
        Returns the source statistics (frames_ok, frames_lost, ...).
    safety : SafetyMonitor, optional
        Shown as debounce / trip state.
    title : str
    battery : Battery, optional
        Model of the pack on test: the time to cutoff is then the model's
        (:meth:`time_to_cutoff`); otherwise the voltage trend's.
    """

    def __init__(self, *, cells_series: int = 1, cutoff_pack_V: float | None = None,
                 current_given_A: float | None = None, stats=None, safety=None, title: str = "",
                 clock=time.monotonic, battery=None):
        self.cells_series = max(1, int(cells_series))
        if battery is not None:
            from .remaining import for_pack

            battery = for_pack(battery, self.cells_series)
        self.battery = battery
        self._start = [0, 0.0, 0.0, 0.0]      # samples, sums of voltage, current, logged Ah
        self._start_t: float | None = None
        self._charge_before: float | None = None
        self._model_eta: tuple[float, int, float | None] | None = None  # (wall, samples, s)
        self.cutoff_pack_V = cutoff_pack_V
        self.current_given_A = current_given_A
        self._stats = stats or (dict)
        self.safety = safety
        self.title = title
        self._clock = clock
        self.samples = 0
        self.last = None
        self.first_voltage_V = math.nan
        self.min_voltage_V = math.inf
        self.charge_Ah = 0.0
        self.energy_Wh = 0.0
        self.trend = Trend()
        self._recent: deque = deque(maxlen=RECENT_POINTS)   # (time_s, voltage_V, current_A)
        self._arrivals: deque = deque(maxlen=21)          # about 5 s at 4 points per second
        self._prev = None
        self.link = "connecting"
        self.events: deque = deque(maxlen=4)
        self.ended = ""
        self.started_wall = clock()

    # ------------------------------------------------------------------ Consumer
    def current_of(self, sample) -> float | None:
        """Measured current if any, else the given one [A]."""
        if sample.current_A is not None:
            return sample.current_A
        return self.current_given_A

    def handle(self, sample) -> None:
        prev = self._prev
        if prev is None:
            self.first_voltage_V = sample.voltage_V
        else:
            dt = sample.time_s - prev.time_s
            i0, i1 = self.current_of(prev), self.current_of(sample)
            if dt > 0 and i0 is not None and i1 is not None:
                self.charge_Ah += 0.5 * (i0 + i1) * dt / 3600.0
                self.energy_Wh += 0.5 * (i0 * prev.voltage_V + i1 * sample.voltage_V) * dt / 3600.0
        self._prev = sample
        self.last = sample
        self.samples += 1
        if self.battery is not None and math.isfinite(sample.voltage_V):
            if self._start_t is None:
                self._start_t = sample.time_s
            if sample.time_s - self._start_t <= START_WINDOW_S:
                n, v, i, q = self._start
                self._start = [n + 1, v + sample.voltage_V,
                               i + (self.current_of(sample) or 0.0), q + self.charge_Ah]
                self._charge_before = None
        if math.isfinite(sample.voltage_V):
            self.min_voltage_V = min(self.min_voltage_V, sample.voltage_V)
        self.trend.add(sample.time_s, sample.voltage_V)
        if math.isfinite(sample.voltage_V):
            self._recent.append((sample.time_s, sample.voltage_V, self.current_of(sample)))
        now = self._clock()
        if not self._arrivals or now - self._arrivals[-1][0] >= 0.25:
            self._arrivals.append((now, self.samples))
        self.link = "streaming"

    def event(self, kind: str, **fields) -> None:
        if kind == "disconnect":
            self.link = "LINK DOWN - reconnecting"
        elif kind == "reconnect":
            self.link = "reconnected"
        elif kind == "stop":
            self.ended = fields.get("ended_by", "")
            return
        text = fields.get("message") or fields.get("reason") or ""
        if kind == "gap":
            text = f"{duration(fields.get('duration_s', 0))} without data"
        self.events.append(f"{kind}: {text}" if text else kind)

    def close(self) -> None:
        pass

    # ------------------------------------------------------------------ numbers
    @property
    def rate_Hz(self) -> float:
        """Samples per wall-clock second over the last few seconds (0 when data stopped)."""
        if len(self._arrivals) < 2:
            return math.nan
        (t0, n0), (t1, n1) = self._arrivals[0], self._arrivals[-1]
        if self._clock() - t1 > max(3.0, 3 * (t1 - t0) / max(n1 - n0, 1)):
            return 0.0
        return (n1 - n0) / (t1 - t0) if t1 > t0 else math.nan

    def _window(self, window_s: float) -> list:
        recent = list(self._recent)       # one atomic copy: the pipeline thread appends
        if not recent:
            return []
        t_end = recent[-1][0]
        return [r for r in recent if r[0] >= t_end - window_s]

    def time_to_cutoff(self) -> tuple[float | None, str | None]:
        """Test time left until the cutoff [s] and how it was found: ``"model"`` (the
        battery model, :meth:`model_time_to_cutoff_s`) when one is known and can say,
        else ``"trend"`` (:meth:`trend_time_to_cutoff_s`); ``(None, None)`` when neither
        can."""
        if self.battery is not None:
            seconds = self.model_time_to_cutoff_s()
            if seconds is not None:
                return seconds, "model"
        seconds = self.trend_time_to_cutoff_s()
        return (seconds, "trend") if seconds is not None else (None, None)

    @property
    def charge_before_Ah(self) -> float | None:
        """Pack charge out before the test [Ah] by the battery model: the mean voltage and
        current of the first :data:`START_WINDOW_S` of test time read on the model
        (:func:`~dischargelab.acquire.remaining.charge_before_test_Ah`), less the charge
        logged meanwhile; 0 for a full pack, None without a model or data."""
        if self.battery is None or not self._start[0]:
            return None
        if self._charge_before is None:
            from .remaining import charge_before_test_Ah

            n, v, i, q = self._start
            self._charge_before = max(0.0, charge_before_test_Ah(self.battery, v / n, i / n)
                                      - q / n)
        return self._charge_before

    def model_time_to_cutoff_s(self, window_s: float = ETA_WINDOW_S) -> float | None:
        """Test time left [s] by the battery model: from the charge out so far (the
        charge before the test plus the logged Ah) at the mean current of the last
        ``window_s`` of test time (:mod:`dischargelab.acquire.remaining`); None without
        a model, a cutoff, a current, or when the model reads the pack at the cutoff.

        The model runs at most every :data:`MODEL_EVERY_S` of wall time; in between,
        the last answer is counted down by the test time since.
        """
        if self.battery is None or not self.cutoff_pack_V or self.last is None:
            return None
        now = self._clock()
        cached = self._model_eta
        if cached is not None and now - cached[0] < MODEL_EVERY_S:
            _, t_then, seconds = cached
            return None if seconds is None else max(0.0, seconds - (self.last.time_s - t_then))
        pts = [i for _, _, i in self._window(window_s) if i is not None and math.isfinite(i)]
        seconds = None
        if pts:
            from .remaining import model_time_to_cutoff_s

            seconds = model_time_to_cutoff_s(
                self.battery, charge_out_Ah=(self.charge_before_Ah or 0.0) + self.charge_Ah,
                current_A=sum(pts) / len(pts), cutoff_pack_V=self.cutoff_pack_V)
        self._model_eta = (now, self.last.time_s, seconds)
        return seconds

    def trend_time_to_cutoff_s(self, window_s: float = ETA_WINDOW_S) -> float | None:
        """Test time left until the pack reaches the cutoff at its present rate of fall [s].

        A straight line fitted (least squares) to the pack voltage over the last
        ``window_s`` of test time (at most :data:`RECENT_POINTS` samples) is
        extended to ``cutoff_pack_V``. A discharge curve bends down at its knee,
        so this is an upper estimate that shrinks as the knee approaches (hours
        too long on the flat middle of a LiPo curve); None when there is no cutoff,
        too little data, or the voltage is not falling.
        """
        if not self.cutoff_pack_V or len(self._recent) < 3:
            return None
        pts = [(t, v) for t, v, _ in self._window(window_s)]
        if len(pts) < 3:
            return None
        t_end = pts[-1][0]
        n = len(pts)
        mt = sum(t for t, _ in pts) / n
        mv = sum(v for _, v in pts) / n
        stt = sum((t - mt) ** 2 for t, _ in pts)
        if stt <= 0:
            return None
        slope = sum((t - mt) * (v - mv) for t, v in pts) / stt        # [V/s]
        if not slope < 0:
            return None
        v_now = mv + slope * (t_end - mt)
        return max(0.0, (v_now - self.cutoff_pack_V) / -slope)

    def summary(self) -> dict:
        """Numbers for the end-of-test summary."""
        last = self.last
        stats = self._stats()
        out = {
            "samples": self.samples,
            "duration_s": None if last is None else last.time_s,
            "first_voltage_V": None if last is None else self.first_voltage_V,
            "last_voltage_V": None if last is None else last.voltage_V,
            "min_voltage_V": None if last is None else self.min_voltage_V,
            "charge_Ah": self.charge_Ah if self._has_current() else None,
            "energy_Wh": self.energy_Wh if self._has_current() else None,
        }
        for key in ("frames_ok", "frames_lost", "frames_corrupt", "reconnects"):
            if key in stats:
                out[key] = stats[key]
        return out

    def _has_current(self) -> bool:
        return self.last is not None and self.current_of(self.last) is not None

    def status_line(self) -> str:
        """One plain line (for --quiet and logs)."""
        last = self.last
        if last is None:
            return f"waiting for data ({self.link})"
        stats = self._stats()
        cell = last.voltage_V / self.cells_series
        parts = [f"t={last.time_s:9.1f} s", f"V={last.voltage_V:7.3f} V ({cell:.3f} V/cell)"]
        current = self.current_of(last)
        if current is not None:
            parts.append(f"I={current:6.2f} A")
            parts.append(f"{self.charge_Ah:7.4f} Ah {self.energy_Wh:7.3f} Wh")
        if last.temperature_C is not None:
            parts.append(f"T={last.temperature_C:5.1f} C")
        parts.append(f"rate {self.rate_Hz:6.1f}/s")
        parts.append(f"lost {stats.get('frames_lost', 0)} corrupt {stats.get('frames_corrupt', 0)}")
        state = self.safety.pending if self.safety is not None else ""
        if self.link != "streaming":
            state = f"{self.link} {state}".strip()
        if state:
            parts.append(state)
        return "  ".join(parts)

    def render(self):
        """A rich renderable of the current state."""
        from rich.panel import Panel
        from rich.table import Table
        from rich.text import Text

        grid = Table.grid(padding=(0, 2))
        grid.add_column(style="bold", justify="right")
        grid.add_column()
        last = self.last
        stats = self._stats()
        if last is None:
            grid.add_row("status", Text(f"waiting for data ({self.link})", style="yellow"))
        else:
            cell = last.voltage_V / self.cells_series
            cut = ""
            if self.cutoff_pack_V:
                cut = f"   cutoff {self.cutoff_pack_V:.2f} V"
            low = self.cutoff_pack_V is not None and last.voltage_V <= self.cutoff_pack_V * 1.03
            grid.add_row("pack", Text(
                f"{last.voltage_V:8.3f} V   {self.cells_series} x {cell:.3f} V/cell   "
                f"min {self.min_voltage_V:.3f} V{cut}", style="bold red" if low else "bold green"))
            grid.add_row("elapsed", f"{duration(last.time_s)}   (test time)")
            current = self.current_of(last)
            if current is not None:
                how = "measured" if last.current_A is not None else "given"
                grid.add_row("current", f"{current:.3f} A ({how})   {self.charge_Ah:.4f} Ah   "
                                        f"{self.energy_Wh:.3f} Wh")
            else:
                grid.add_row("current", Text("unknown (give --current A for Ah and Wh)",
                                             style="dim"))
            left, how = self.time_to_cutoff()
            if left is not None:
                grid.add_row("to cutoff", f"{duration(left)}   ({how})")
            if last.temperature_C is not None:
                grid.add_row("temperature", f"{last.temperature_C:.1f} °C")
            if len(self.trend.values) > 1:
                grid.add_row("trend", f"{sparkline(self.trend.values)}  "
                                      f"{self.trend.values[0]:.2f} -> {last.voltage_V:.2f} V")
        grid.add_row("link", f"{self.rate_Hz:.1f} samples/s   ok {stats.get('frames_ok', 0)}   "
                             f"lost {stats.get('frames_lost', 0)}   corrupt "
                             f"{stats.get('frames_corrupt', 0)}   reconnects "
                             f"{stats.get('reconnects', 0)}")
        state = self.safety.pending if self.safety is not None else ""
        style = "bold red" if state or self.link.startswith("LINK") else "green"
        grid.add_row("state", Text(" | ".join(x for x in (self.link, state) if x), style=style))
        for text in list(self.events)[-2:]:
            grid.add_row("event", Text(text, style="yellow"))
        return Panel(grid, title=self.title or "dischargelab acquire", title_align="left",
                     subtitle="Ctrl-C stops", subtitle_align="right")


# ---------------------------------------------------------------------- plot window

def check_display() -> None:
    """Raise a one-line error when no window can be opened (no display, no GUI backend)."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                  or os.environ.get("WAYLAND_DISPLAY")):
        raise DischargelabError("--plot needs a graphical display (DISPLAY is not set); run "
                                "without --plot (the terminal view works over SSH) or use ssh -X")


class LivePlot:
    """Voltage-vs-time window updated from the main thread (``--plot``).

    Parameters
    ----------
    display : LiveDisplay
        Source of the data (its decimated trend).
    interactive : bool
        Open a window (needs a display and a GUI backend); False draws on an
        off-screen figure (for saving a picture).
    """

    def __init__(self, display: LiveDisplay, *, interactive: bool = True):
        if interactive:
            check_display()
        import matplotlib

        if interactive:
            backend = matplotlib.get_backend().lower()
            if backend in ("agg", "pdf", "svg", "ps", "cairo", "template"):
                for candidate in ("TkAgg", "QtAgg", "GTK3Agg"):
                    try:
                        matplotlib.use(candidate, force=True)
                        break
                    except Exception:
                        continue
                else:
                    raise DischargelabError("--plot needs an interactive matplotlib backend "
                                            "(Tk, Qt or GTK); none is installed")
        import matplotlib.pyplot as plt
        from matplotlib.figure import Figure

        self.display = display
        self.interactive = interactive
        self._plt = plt
        if interactive:
            plt.ion()
            self.figure = plt.figure("dischargelab acquire", figsize=(8, 4.5),
                                     layout="constrained")
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg

            self.figure = Figure(figsize=(8, 4.5), layout="constrained")
            FigureCanvasAgg(self.figure)
        self.ax = self.figure.add_subplot(1, 1, 1)
        (self.line,) = self.ax.plot([], [], lw=1.4, color="tab:blue", label="pack voltage")
        if display.cutoff_pack_V:
            self.ax.axhline(display.cutoff_pack_V, color="tab:red", ls="--", lw=1,
                            label=f"cutoff {display.cutoff_pack_V:.2f} V")
        self.ax.set_xlabel("time [s]")
        self.ax.set_ylabel("pack voltage [V]")
        self.ax.grid(True, alpha=0.3)
        self.ax.legend(loc="upper right")

    def update(self) -> None:
        """Redraw with the latest data (call a few times a second)."""
        t, v = list(self.display.trend.times), list(self.display.trend.values)
        if self.display.last is not None and (not t or self.display.last.time_s > t[-1]):
            t.append(self.display.last.time_s)
            v.append(self.display.last.voltage_V)
        n = min(len(t), len(v))
        self.line.set_data(t[:n], v[:n])
        if n:
            self.ax.relim()
            self.ax.autoscale_view()
            last = self.display.last
            self.ax.set_title(f"{last.voltage_V:.3f} V at {last.time_s:.0f} s", loc="left")
        if self.interactive:
            self.figure.canvas.draw_idle()
            self._plt.pause(0.001)
        else:
            self.figure.canvas.draw()

    def save(self, path) -> None:
        """Save the live figure atomically (:func:`dischargelab.atomic.save_figure`)."""
        from ..atomic import save_figure

        save_figure(self.figure, path, dpi=100)

    def close(self) -> None:
        if self.interactive:
            self._plt.close(self.figure)
