"""Logging a test: calibrate, acquire, virtual-device, demo-acquire."""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import click

from ..errors import DischargelabError
from ..formatting import duration
from .common import (
    battery_input,
    err,
    force_option,
    guard_outputs,
    json_option,
    load_battery_arg,
    out,
    print_json,
    print_json_line,
    table,
)

# --- calibration and load commands ---

def _read_pairs_interactively() -> list[tuple[float, float]]:
    """Ask for REAL,MEASURED pairs on stdin until an empty line or end of input."""
    from ..acquire.calibration import parse_pair

    err.print("Type one point per line as MULTIMETER_V,LOGGER_V (e.g. 11.88,2.71); "
              "an empty line ends.", markup=False)
    pairs: list[tuple[float, float]] = []
    while True:
        try:
            text = click.prompt(f"point {len(pairs) + 1}", default="", show_default=False,
                                err=True)
        except click.exceptions.Abort:
            break
        if not text.strip():
            break
        try:
            pairs.append(parse_pair(text, len(pairs) + 1))
        except DischargelabError as exc:
            err.print(f"  {exc}; try again", markup=False)
    return pairs


@click.command("calibrate")
@click.option("--pair", "pairs", multiple=True, metavar="REAL,MEASURED",
              help="Multimeter reading and logger reading of one voltage [V] (repeat).")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False),
              help="CSV of points: two columns (multimeter, logger) or named real_V,measured_V.")
@click.option("--divider", default="", metavar="NAME",
              help="Name of the divider (stored; selects rows of a CSV 'divider' column).")
@click.option("--meter-percent", default=0.8, show_default=True, type=click.FloatRange(0),
              help="Multimeter accuracy, percent of reading (paper: Minipa ET-1002).")
@click.option("--meter-digits", default=5, show_default=True, type=click.IntRange(0),
              help="Multimeter accuracy, digits.")
@click.option("--meter-resolution", default=0.01, show_default=True,
              type=click.FloatRange(0, min_open=True), metavar="V",
              help="Multimeter resolution on the range used [V].")
@click.option("--adc-bits", default=10, show_default=True, type=click.IntRange(1, 32),
              help="Logger ADC bits (Arduino Uno: 10).")
@click.option("--adc-reference", default=5.0, show_default=True,
              type=click.FloatRange(0, min_open=True), metavar="V",
              help="Logger ADC reference [V].")
@click.option("--offset", type=click.Choice(["auto", "yes", "no"]), default="auto",
              show_default=True, help="Fit an offset: only if significant (auto), always, never.")
@click.option("--alpha", default=0.05, show_default=True, type=click.FloatRange(0, 1,
              min_open=True, max_open=True), help="Significance level of the offset tests.")
@click.option("-o", "--output", type=click.Path(dir_okay=False),
              help="Write the calibration file (JSON) for 'acquire --calibration'.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False),
              help="Save a plot of Ke per point, the fit and the linear range (PNG, PDF).")
@force_option
@json_option
def calibrate_cmd(pairs, csv_path, divider, meter_percent, meter_digits, meter_resolution,
                  adc_bits, adc_reference, offset, alpha, output, plot_path, force, as_json):
    """Find the logger's scale factor Ke = V_real / V_measured (paper eq. 7).

    Give pairs of (multimeter reading, logger reading) taken with packs at
    several voltages. The command fits Ke through the origin, adds an offset only
    if it is significant (F-test and a chi-square test against the meter's stated
    accuracy), lists the residual of every point, flags points outside the linear
    range of the front end and prints the voltage resolution (ADC step x Ke).

    \b
    Examples:
      dischargelab calibrate --pair 15.33,3.51 --pair 13.16,3.01 --pair 11.88,2.71 \\
          --pair 11.26,2.57 --pair 7.67,1.74 --divider 3.3k -o cal.json
      dischargelab calibrate --csv points.csv --divider 2.7k --plot ke.png --json
      dischargelab calibrate -o cal.json          (type the points at the prompt)
      dischargelab acquire --calibration cal.json ...
    """
    from ..acquire.calibration import MeterAccuracy, fit_calibration, parse_pair, read_points_csv

    if csv_path and pairs:
        raise DischargelabError("give the points either with --pair or with --csv, not both")
    guard_outputs([output, plot_path], [csv_path], force, figures=[plot_path])
    if csv_path:
        real, measured = read_points_csv(csv_path, divider or None)
    elif pairs:
        parsed = [parse_pair(text, i) for i, text in enumerate(pairs, start=1)]
        real, measured = [p[0] for p in parsed], [p[1] for p in parsed]
    else:
        parsed = _read_pairs_interactively()
        if not parsed:
            raise DischargelabError("no calibration points given; use --pair REAL,MEASURED, "
                                    "--csv FILE or type them at the prompt")
        real, measured = [p[0] for p in parsed], [p[1] for p in parsed]
    meter = MeterAccuracy(meter_percent, meter_digits, meter_resolution)
    result = fit_calibration(real, measured, divider=divider, meter=meter, adc_bits=adc_bits,
                             adc_reference_V=adc_reference, alpha=alpha, offset=offset)
    if output:
        result.calibration.save(output)
    if plot_path:
        from ..errors import require
        from ..plot import save

        require("matplotlib", "plot").use("Agg")
        ax = result.plot()
        ax.figure.tight_layout()
        save(ax, plot_path, dpi=120)
    if as_json:
        data = result.to_dict()
        data["output"] = output
        data["plot"] = plot_path
        print_json(data)
        return
    rows = [[f"{p.real_V:g}", f"{p.measured_V:g}", f"{p.ke:.4f}", f"{p.predicted_V:.3f}",
             f"{p.residual_V * 1000:+.0f}",
             "" if math.isnan(p.loo_residual_V) else f"{p.loo_residual_V * 1000:+.0f}",
             f"{p.bound_V * 1000:.0f}", p.status] for p in result.points]
    title = f"Calibration points{' (' + divider + ')' if divider else ''}"
    out.print(table(title, ["meter V", "logger V", "Ke", "fit V", "resid mV", "LOO mV",
                            "bound mV", "status"], rows))
    out.print(result.report(), markup=False)
    if output:
        out.print(f"calibration written to {output}; use it with: dischargelab acquire "
                  f"--calibration {output}", markup=False)


# --- acquisition commands ---

_ACQ_STATUS_HELP = ("exit status: 0 stopped by the user or --duration, 3 cutoff reached, "
                    "4 over-temperature, 5 link lost (--give-up-after), 6 internal error, "
                    "2 bad input")


def _source_choices() -> list[str]:
    from ..acquire.sources import SOURCE_KINDS

    return list(SOURCE_KINDS)


def _acquire_summary_rows(result) -> list[list]:
    s = result.summary

    def num(key, fmt):
        value = s.get(key)
        return "-" if value is None else format(value, fmt)

    rows = [["ended by", result.ended_by], ["message", result.message or "-"],
            ["samples", s.get("samples", 0)], ["rows in file", s.get("rows_written", 0)],
            ["test time", duration(s.get("duration_s"))],
            ["first voltage (V)", num("first_voltage_V", ".3f")],
            ["last voltage (V)", num("last_voltage_V", ".3f")],
            ["min voltage (V)", num("min_voltage_V", ".3f")],
            ["charge (Ah)", num("charge_Ah", ".4f")], ["energy (Wh)", num("energy_Wh", ".3f")]]
    for key in ("frames_ok", "frames_lost", "frames_corrupt", "reconnects"):
        if key in result.stats:
            rows.append([key.replace("_", " "), result.stats[key]])
    rows.append(["load at the end", {"switched off": "switched off by dischargelab",
                                     "not switched off": "NOT switched off (switch it off)",
                                     "not driven": "not driven by dischargelab"}
                 [result.load_state]])
    rows.append(["data file", str(result.out)])
    from rich.markup import escape

    return [[escape(str(key)), escape(str(value))] for key, value in rows]


#: What the end-of-test alarm says about the load, by ``AcquireResult.load_state``.
_LOAD_LINES = {
    "switched off": "load switched off, test stopped",
    "not switched off": "test stopped, but the load could NOT be switched off: switch it off "
                        "by hand NOW",
    "not driven": "test stopped; dischargelab does not drive this load (no --switch-load "
                  "relay): switch it off by hand NOW",
}


def _report_acquisition(result, as_json: bool) -> None:
    if result.ended_by in ("cutoff", "over-temperature", "link-lost"):
        err.print(f"\a\n*** {result.message or result.ended_by} ***\n*** "
                  f"{_LOAD_LINES[result.load_state]}; event recorded in {result.out} ***",
                  style="bold red", markup=False)
    if result.error:
        err.print(f"error during the test: {result.error}", markup=False)
    if as_json:
        print_json(result.to_dict())
    else:
        out.print(table("Acquisition summary", ["", "value"], _acquire_summary_rows(result)))


@click.command("acquire", epilog=_ACQ_STATUS_HELP)
@click.option("--port", required=True, metavar="PORT",
              help="Serial port of the logger (/dev/ttyACM0, COM3, a virtual device's path).")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Log file to create (dischargelab log CSV); never overwritten without --force.")
@click.option("--source", "source_kind", default="arduino", show_default=True,
              type=click.Choice(_source_choices()), help="Kind of instrument on --port.")
@click.option("--cells", type=click.IntRange(1, 24), metavar="N",
              help="Cells in series (default: inferred from the first voltage, with a warning).")
@click.option("--chemistry", type=click.Choice(["lipo", "li-ion", "lifepo4"]), default="lipo",
              show_default=True, help="Sets the per-cell cutoff (3.0 / 2.5 / 2.5 V).")
@click.option("--cutoff-cell", type=click.FloatRange(0.5, 4.5), metavar="V",
              help="Per-cell cutoff voltage [V], overriding the chemistry preset.")
@click.option("--max-temp", type=float, default=60.0, show_default=True, metavar="C",
              help="Over-temperature limit [degC] (needs a temperature sensor).")
@click.option("--debounce", type=click.IntRange(1, 1000), default=3, show_default=True,
              metavar="N", help="Consecutive samples beyond a limit before it trips.")
@click.option("--rate", "rate_Hz", type=click.FloatRange(min=0.0003, min_open=False),
              default=1.0, show_default=True, metavar="HZ", help="Sample rate [Hz].")
@click.option("--calibration", "calibration_path", type=click.Path(dir_okay=False),
              help="Calibration file from 'dischargelab calibrate' (Ke and offset).")
@click.option("--ke", type=click.FloatRange(min=0, min_open=True), metavar="X",
              help="Divider gain Ke = V_real / V_measured (paper eq. 7; 4.38 for its 3.3 kOhm "
                   "divider).")
@click.option("--current", "current_A", type=click.FloatRange(min=0, min_open=True),
              metavar="A", help="Known constant discharge current [A] (for Ah and Wh; the "
                                "EBC load's set current).")
@click.option("--current-sensor", metavar="NAME",
              help="Current sensor on A1: acs712-5a, acs712-20a, acs712-30a or "
                   "shunt:V_PER_A[:ZERO_V].")
@click.option("--thermistor", is_flag=True,
              help="10 kOhm NTC (B 3950) on A2 with a 10 kOhm resistor to 5 V.")
@click.option("--switch-load", is_flag=True,
              help="Close the load relay (pin D7) at start; it is opened at any end.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0, min_open=True),
              metavar="S", help="Stop after this much test time [s].")
@click.option("--plot", is_flag=True, help="Also open a live plot window (needs a display).")
@click.option("--live/--no-live", default=True, show_default=True,
              help="Terminal panel; --no-live prints a line every --every seconds.")
@click.option("--quiet", is_flag=True, help="Same as --no-live.")
@click.option("--every", "every_s", type=click.FloatRange(min=0.1), default=10.0,
              show_default=True, metavar="S", help="Seconds between lines without the panel.")
@click.option("--force", is_flag=True, help="Overwrite an existing --out file.")
@click.option("--logview", "logview_path", type=click.Path(dir_okay=False), metavar="FILE",
              help="Also write LogView OpenFormat lines to FILE (or a serial port).")
@click.option("--baud", type=click.IntRange(1200), metavar="BAUD",
              help="Serial baud rate (default: the source's own, 115200 for the Arduino).")
@click.option("--parity", type=click.Choice(["N", "E", "O"]), default=None,
              help="Serial parity (default: the source's own; the EBC-A loads are documented "
                   "with E by most sources, O by some: try O if no status frame arrives).")
@click.option("--give-up-after", "give_up_s", type=click.FloatRange(min=0, min_open=True),
              metavar="S", help="End the test if the link stays down this long [s] "
                                "(default: keep reconnecting until stopped).")
@click.option("--battery-model", "battery_model", metavar="PRESET|FILE",
              help="Model of the pack on test (preset or battery file): the time to cutoff "
                   "is run through it from the charge taken out at the recent mean current, "
                   "instead of the voltage trend's straight line.")
@click.option("--serve", is_flag=True,
              help="Also show the test on a live web page (extra web; the address is printed).")
@click.option("--serve-port", type=click.IntRange(0, 65535), default=8050, show_default=True,
              metavar="PORT", help="TCP port of the live page (0 picks a free one).")
@click.option("--serve-host", default="127.0.0.1", show_default=True, metavar="ADDR",
              help="Address of the live page; anything but loopback needs --serve-token.")
@click.option("--serve-token", is_flag=False, flag_value="auto", default=None,
              metavar="[TOKEN]", help="Require this token on the live page (alone: a random one).")
@json_option
def acquire_cmd(port, out_path, source_kind, cells, chemistry, cutoff_cell, max_temp, debounce,
                rate_Hz, calibration_path, ke, current_A, current_sensor, thermistor,
                switch_load, duration_s, plot, live, quiet, every_s, force, logview_path, baud,
                parity, give_up_s, battery_model, serve, serve_port, serve_host, serve_token,
                as_json):
    """Log a discharge test from a serial instrument, with live view and safety cutoff.

    The producer/consumer program of the paper (section 3.2): samples are
    calibrated, written to a crash-safe log file (fsync every 0.5 s), shown live
    and checked against the cutoff; on a cutoff the load is switched off (when
    dischargelab drives it: --switch-load relay or an electronic load; otherwise
    you are told to switch it off), the event is recorded and the command exits
    with status 3. Ctrl-C stops cleanly.

    \b
    Examples:
      dischargelab acquire --port /dev/ttyACM0 --out run.csv --cells 3 --ke 4.38 --current 2
      dischargelab acquire --port COM3 --out run.csv --calibration cal.json --rate 2 --plot
      dischargelab acquire --port /dev/ttyACM0 --out run.csv --ke 4.38 --current-sensor \\
          acs712-20a --thermistor --chemistry lifepo4 --cells 4 --quiet --every 30
      dischargelab acquire --source ebc-a20 --port /dev/ttyUSB0 --out run.csv --cells 2 \\
          --current 1.7
      dischargelab acquire --port /dev/ttyACM0 --out run.csv --ke 4.38 --current 2 --serve
      dischargelab acquire --port /dev/ttyACM0 --out run.csv --ke 4.38 --current 2 \\
          --battery-model pack3.json --serve
    """
    from ..acquire.acquisition import AcquireSettings, prepare_acquisition
    from ..acquire.sensors import Thermistor
    from ..acquire.sensors import current_sensor as make_current_sensor

    if calibration_path and ke is not None:
        raise DischargelabError("give either --calibration or --ke, not both")
    if plot:
        from ..acquire.live import check_display

        check_display()                    # before the port is opened or a file created
    from ..acquire.logview import is_serial_target

    logview_file = logview_path if logview_path and not is_serial_target(logview_path) else None
    guard_outputs([out_path, logview_file], [calibration_path], force)
    model = None
    if battery_model:
        from ..model import load_battery

        model = load_battery(battery_model)
    calibration = None
    if calibration_path:
        from ..acquire.calibration import load_calibration

        calibration = load_calibration(calibration_path)
    elif ke is not None:
        from ..acquire.calibration import Calibration

        calibration = Calibration(gain=ke)
    settings = AcquireSettings(
        port=port, out=Path(out_path), source=source_kind, cells=cells, chemistry=chemistry,
        cutoff_cell_V=cutoff_cell, max_temperature_C=max_temp, debounce_samples=debounce,
        rate_Hz=rate_Hz, calibration=calibration, current_A=current_A,
        current_sensor=make_current_sensor(current_sensor) if current_sensor else None,
        thermistor=Thermistor() if thermistor else None, baudrate=baud, parity=parity,
        switch_load=switch_load, duration_s=duration_s, force=force, logview=logview_path,
        give_up_after_s=give_up_s, battery_model=model)
    web = _live_page_server(serve_host, serve_port, serve_token) if serve else None
    acquisition = prepare_acquisition(settings)
    console = err if as_json else out
    if web is not None:
        web.app_state("bench").attach(acquisition)
        web.start()
        console.print(f"live page: listening on {web.listening.page('live')}", markup=False)
    view = "live" if live and not quiet and console.is_terminal else "lines"
    result = acquisition.run(view=view, console=console, every_s=every_s, plot=plot)
    if web is not None:
        web.app_state("bench").finished(result)
        time.sleep(1.0)                    # the page gets the end of the test
        web.stop()
    _report_acquisition(result, as_json)
    sys.exit(result.exit_status)


def _live_page_server(host, port, token):
    """The live page's server, bound (a busy port fails here, before the test starts)."""
    from ..web.bench import LiveBench
    from ..web.server import build_server, is_loopback

    if not is_loopback(host) and not token:
        raise DischargelabError(f"--serve-host {host} lets other machines see the test: add "
                                "--serve-token (or keep the default 127.0.0.1)")
    return build_server(host=host, port=port, token=token, live=LiveBench())


@click.command("virtual-device")
@click.option("--battery", default="zippy-1100-2s", show_default=True, metavar="PRESET|FILE",
              help="Battery preset or battery file driving the simulated pack.")
@click.option("--cells", type=click.IntRange(1, 24), metavar="N",
              help="Cells in series (default: the battery's).")
@click.option("--current", "current_A", type=click.FloatRange(min=0), metavar="A",
              help="Load current [A] (default 1C).")
@click.option("--rate", "rate_Hz", type=click.FloatRange(min=0.0003), default=1.0,
              show_default=True, metavar="HZ", help="Sample rate at power-up (the host sets it).")
@click.option("--speed", type=click.FloatRange(min=0, min_open=True), default=1.0,
              show_default=True, metavar="X", help="Battery seconds per wall second.")
@click.option("--ke", "divider_gain", type=click.FloatRange(min=0, min_open=True), default=4.38,
              show_default=True, metavar="X", help="Divider gain of the simulated front end.")
@click.option("--noise-mV", "noise_mV", type=click.FloatRange(min=0), default=2.0,
              show_default=True, metavar="MV", help="RMS noise at the ADC pin [mV].")
@click.option("--drop-bytes", type=click.FloatRange(0, 1, max_open=True), default=0.0,
              show_default=True, metavar="P", help="Probability of losing each sample byte.")
@click.option("--corrupt", type=click.FloatRange(0, 1), default=0.0, show_default=True,
              metavar="P", help="Probability of flipping 1-3 bits in a sample frame.")
@click.option("--disconnect-after", type=click.FloatRange(min=0), metavar="S",
              help="Simulate an unplugged cable this many seconds after START.")
@click.option("--disconnect-for", type=click.FloatRange(min=0), default=2.0, show_default=True,
              metavar="S", help="How long the disconnect lasts.")
@click.option("--disconnect-mode", type=click.Choice(["close", "silent"]), default="close",
              show_default=True, help="close: the port vanishes and returns reset; silent: the "
                                      "board stops answering.")
@click.option("--baud", type=click.IntRange(min=0), default=0, show_default=True, metavar="BAUD",
              help="Pace output like a UART at this baud rate (0 = unpaced).")
@click.option("--relay", is_flag=True, help="Model a load relay switched by the host.")
@click.option("--link", type=click.Path(dir_okay=False), metavar="PATH",
              help="Create the port symlink here (default: a temporary directory).")
@click.option("--record", type=click.Path(dir_okay=False), metavar="FILE",
              help="Write every produced frame and its fate to this CSV.")
@click.option("--seed", type=int, default=0, show_default=True, help="Noise and fault seed.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0, min_open=True),
              metavar="S", help="Exit after this many wall seconds (default: until Ctrl-C).")
@force_option
@click.option("--json", "as_json", is_flag=True,
              help="JSON Lines on stdout: one object when the port is ready (event "
                   "'started'), one with the summary when the device stops ('stopped').")
def virtual_device_cmd(battery, cells, current_A, rate_Hz, speed, divider_gain, noise_mV,
                       drop_bytes, corrupt, disconnect_after, disconnect_for, disconnect_mode,
                       baud, relay, link, record, seed, duration_s, force, as_json):
    """Run a virtual Arduino logger on a pseudo-terminal, driven by the battery model.

    Prints the port path, then answers the host like the firmware until Ctrl-C.

    \b
    Examples:
      dischargelab virtual-device --battery zippy-1100-2s --speed 60
      dischargelab virtual-device --link /tmp/ttyDLAB --corrupt 0.01 --drop-bytes 0.001
      dischargelab virtual-device --disconnect-after 10 --disconnect-for 3 --record sent.csv
    and in another terminal:
      dischargelab acquire --port /tmp/ttyDLAB --out run.csv --ke 4.38 --current 1.1
    """
    import signal
    import time as _time

    from ..acquire.virtual_device import VirtualDevice

    guard_outputs([record], battery_input(battery), force)
    device = VirtualDevice(load_battery_arg(battery), cells_series=cells, current_A=current_A,
                           rate_Hz=rate_Hz, speed=speed, divider_gain=divider_gain,
                           noise_mV=noise_mV, drop_bytes=drop_bytes, corrupt=corrupt,
                           disconnect_after_s=disconnect_after, disconnect_for_s=disconnect_for,
                           disconnect_mode=disconnect_mode, baudrate=baud or None, seed=seed,
                           link=link, record=record, relay=relay)
    port = device.start()
    info = {"event": "started", "port": port, "battery": device.battery.name, "cells_series":
            device.battery.cells_series, "current_A": device.current_A, "speed": speed,
            "divider_gain": divider_gain}
    if as_json:
        print_json_line(info)
    else:
        out.print(port, markup=False)
        err.print(f"virtual logger: {device.battery.name} ({device.battery.cells_series}S), "
                  f"{device.current_A:g} A, x{speed:g}, Ke {divider_gain:g}; "
                  f"connect with: dischargelab acquire --port {port} --ke {divider_gain:g} "
                  f"--current {device.current_A:g} --out run.csv   (Ctrl-C stops)",
                  markup=False)
    sys.stdout.flush()

    def _term(signum, frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _term)
    end = None if duration_s is None else _time.monotonic() + duration_s
    try:
        while end is None or _time.monotonic() < end:
            _time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        device.stop()
    summary = device.summary()
    if as_json:
        print_json_line({"event": "stopped", **summary})
    else:
        err.print(table("Virtual logger stopped", ["", "value"], _device_summary_rows(summary)))


def _device_summary_rows(summary: dict) -> list[list]:
    """Rows of the virtual device's summary (see ``VirtualDevice.summary``)."""
    frames = summary["frames"]
    lost = {k: v for k, v in frames.items() if k not in ("produced", "sent") and v}
    rows = [["battery", f"{summary['battery']} ({summary['cells_series']}S), "
                        f"{summary['current_A']:g} A, x{summary['speed']:g}"],
            ["battery time", duration(summary["battery_time_s"])],
            ["charge drawn (Ah)", f"{summary['charge_Ah']:.4f}"],
            ["frames produced", frames.get("produced", 0)],
            ["frames sent intact", frames.get("sent", 0)]]
    rows += [[f"frames {key.replace('-', ' ')}", value] for key, value in lost.items()]
    rows += [["disconnects", summary["disconnects"]], ["commands received", summary["commands"]]]
    return rows


@click.command("demo-acquire")
@click.option("--out", "out_dir", default="demo-out", show_default=True,
              type=click.Path(file_okay=False), help="Folder for the log, record and plot.")
@click.option("--battery", default="zippy-1100-2s", show_default=True, metavar="PRESET|FILE",
              help="Battery driving the virtual logger.")
@click.option("--seconds", "wall_seconds", type=click.FloatRange(min=5), default=45.0,
              show_default=True, metavar="S", help="Wall-clock length of the discharge.")
@click.option("--seed", type=int, default=1, show_default=True, help="Noise seed.")
@click.option("--live/--no-live", default=True, show_default=True, help="Terminal panel.")
@force_option
@json_option
def demo_acquire_cmd(out_dir, battery, wall_seconds, seed, live, force, as_json):
    """A complete simulated test: virtual logger -> acquisition -> cutoff -> fit.

    A preset pack is discharged at 1C by a virtual logger on a pseudo-terminal
    (time compressed to about --seconds), logged through the real serial path
    until the cutoff trips, and the logged curve is fitted; the fitted
    coefficients are printed next to the true ones.

    \b
    Examples:
      dischargelab demo-acquire
      dischargelab demo-acquire --battery zippy-1100-2s --seconds 30 --out /tmp/demo
    """
    from ..acquire.demo import check_acquire_demo, run_acquire_demo

    check_acquire_demo(out_dir, force)
    console = err if as_json else out
    view = "live" if live and console.is_terminal else "lines"
    summary = run_acquire_demo(out_dir, battery=load_battery_arg(battery),
                               wall_seconds=wall_seconds, seed=seed, view=view,
                               console=console, force=force)
    if as_json:
        print_json(summary)
        return
    out.print(f"ended by {summary['ended_by']}: {summary['message']}", markup=False)
    rows = [[r["parameter"], f"{r['true']:.5g}", f"{r['fitted']:.5g}",
             "fixed" if r["fixed"] else ("-" if r["stderr"] is None else f"{r['stderr']:.2g}")]
            for r in summary["parameters"]]
    rows.append(["E0 - R*i (cell)", f"{summary['E0_minus_Ri_true_V']:.5g}",
                 f"{summary['E0_minus_Ri_fitted_V']:.5g}", ""])
    out.print(table(f"Fitted vs true coefficients ({summary['battery']}, per cell)",
                    ["parameter", "true", "fitted", "stderr"], rows))
    out.print(f"fit RMSE {summary['rmse_V'] * 1000:.1f} mV per cell; logged "
              f"{summary['samples']} samples, lost {summary['stats'].get('frames_lost', 0)}, "
              f"corrupt {summary['stats'].get('frames_corrupt', 0)}", markup=False)
    for w in summary["warnings"]:
        out.print(f"warning: {w}", markup=False)
    out.print(f"files: {summary['log']}, {summary['device_record']}, {summary['plot']}",
              markup=False)


COMMANDS = [calibrate_cmd, acquire_cmd, virtual_device_cmd, demo_acquire_cmd]
