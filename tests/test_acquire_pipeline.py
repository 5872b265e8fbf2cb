"""Acquisition end to end: virtual logger on a pty -> pyserial -> pipeline -> log file."""

import threading

import numpy as np
import pytest

from dischargelab.acquire.arduino import ArduinoSource
from dischargelab.acquire.calibration import Calibration
from dischargelab.acquire.pipeline import Pipeline, ReconnectPolicy, Sample
from dischargelab.acquire.safety import SafetyLimits, SafetyMonitor
from dischargelab.acquire.sensors import ADC_REFERENCE_V, CURRENT_SENSORS, Thermistor
from dischargelab.acquire.virtual_device import VirtualDevice
from dischargelab.io.logfile import LogWriter, read_log

KE = 4.38
LSB_V = ADC_REFERENCE_V / 1024          # one ADC step at the pin [V]
WAIT_S = 90                              # generous: CI machines are slow and shared


class Collect:
    """Test consumer: keeps everything, sets ``reached`` when ``until(self)`` holds."""

    def __init__(self, until=None):
        self.samples: list[Sample] = []
        self.events: list[tuple[str, dict]] = []
        self.until = until
        self.reached = threading.Event()
        self.closed = False

    def _check(self):
        if self.until is not None and self.until(self):
            self.reached.set()

    def handle(self, sample):
        self.samples.append(sample)
        self._check()

    def event(self, kind, **fields):
        self.events.append((kind, fields))
        self._check()

    def close(self):
        self.closed = True

    def kinds(self):
        return [k for k, _ in self.events]


def run_until(source, consumers, collect, **kwargs) -> Pipeline:
    pipe = Pipeline(source, consumers + [collect], **kwargs).start()
    reached = collect.reached.wait(WAIT_S)
    pipe.close()
    assert reached, f"condition not reached; events {collect.events}, stats {pipe.stats}"
    return pipe


def measured(code, gain=KE, offset=0.0):
    return gain * (code + 0.5) * LSB_V + offset


def test_samples_arrive_calibrated_and_logged(tmp_path):
    rate = 5.0
    path = tmp_path / "run.csv"
    with VirtualDevice("zippy-1100-2s", speed=20, noise_mV=2.0, seed=3, keep_history=True,
                       divider_gain=KE) as dev:
        source = ArduinoSource(dev.port, rate_Hz=rate, calibration=Calibration(gain=KE))
        writer = LogWriter(path, {"port": dev.port, **source.info})
        col = Collect(until=lambda c: len(c.samples) >= 200)
        pipe = run_until(source, [writer], col)
    assert col.closed
    history = {f.index: f for f in dev.history}
    noise_V = KE * 4 * 0.002                         # 4 sigma of the pin noise, at the pack
    for s in col.samples:
        frame = history[round(s.time_s * rate)]
        assert frame.status == "sent" and frame.seq == s.seq
        assert s.voltage_V == pytest.approx(measured(frame.codes[0]), abs=1e-12)
        assert abs(s.voltage_V - frame.voltage_V) <= KE * LSB_V / 2 + noise_V
    times = np.array([s.time_s for s in col.samples])
    np.testing.assert_allclose(np.diff(times), 1 / rate)
    assert times[0] == 0.0
    stats = pipe.stats
    assert stats["frames_ok"] == len(col.samples) and stats["frames_lost"] == 0
    assert stats["frames_corrupt"] == 0 and stats["reconnects"] == 0
    # the file holds exactly what the consumers saw
    data, meta = read_log(path)
    assert len(data) == len(col.samples)
    np.testing.assert_allclose(data["voltage_V"], [s.voltage_V for s in col.samples], atol=5e-5)
    assert data["seq"].tolist() == [s.seq for s in col.samples]
    assert meta["firmware"].startswith("dischargelab-logger")
    assert meta["calibration"]["gain"] == KE
    assert [e["kind"] for e in meta["events"]] == ["stop"]


def test_calibration_gain_and_offset_are_applied():
    cal = Calibration(gain=4.0, offset_V=0.25)
    with VirtualDevice(speed=10, seed=4, keep_history=True) as dev:
        source = ArduinoSource(dev.port, rate_Hz=10, calibration=cal)
        col = Collect(until=lambda c: len(c.samples) >= 30)
        run_until(source, [], col)
    history = {f.index: f for f in dev.history}
    for s in col.samples:
        code = history[round(s.time_s * 10)].codes[0]
        assert s.voltage_V == pytest.approx(measured(code, 4.0, 0.25), abs=1e-12)


def test_current_and_temperature_channels():
    sensor = CURRENT_SENSORS["acs712-20a"]
    with VirtualDevice(current_A=2.5, speed=50, seed=5, keep_history=True, ambient_C=31.0,
                       noise_mV=2.0) as dev:
        source = ArduinoSource(dev.port, rate_Hz=2, calibration=KE, current_sensor=sensor,
                               thermistor=Thermistor())
        col = Collect(until=lambda c: len(c.samples) >= 60)
        run_until(source, [], col)
    assert source.info["channels"] == ["A0", "A1", "A2"]
    history = {f.index: f for f in dev.history}
    current_tol = (LSB_V / 2 + 4 * 0.002) / sensor.sensitivity_V_per_A
    for s in col.samples:
        frame = history[round(s.time_s * 2)]
        assert s.current_A == pytest.approx(frame.current_A, abs=current_tol)
        # NTC near 30 degC: about 0.1 K per ADC step; allow 4 noise sigma + half a step
        assert s.temperature_C == pytest.approx(frame.temperature_C, abs=0.35)


def test_corruption_and_drops_are_counted_never_accepted():
    rate = 100.0
    with VirtualDevice(speed=1, seed=6, keep_history=True, corrupt=0.05,
                       drop_bytes=0.003) as dev:
        source = ArduinoSource(dev.port, rate_Hz=rate, calibration=KE)
        col = Collect(until=lambda c: len(c.samples) >= 400)
        pipe = run_until(source, [], col)
    history = {f.index: f for f in dev.history}
    last = round(col.samples[-1].time_s * rate)
    for s in col.samples:
        frame = history[round(s.time_s * rate)]
        assert frame.status == "sent", "a damaged frame was accepted"
        assert s.voltage_V == pytest.approx(measured(frame.codes[0]), abs=1e-12)
    damaged = sum(1 for k in range(last + 1) if history[k].status != "sent")
    stats = pipe.stats
    assert damaged > 5
    assert stats["frames_corrupt"] >= damaged * 0.5
    assert stats["frames_lost"] == last + 1 - len(col.samples) >= damaged


@pytest.mark.parametrize("mode", ["close", "silent"])
def test_disconnect_is_survived_and_recorded(tmp_path, mode):
    path = tmp_path / "run.csv"
    with VirtualDevice(speed=1, seed=7, disconnect_after_s=1.0, disconnect_for_s=2.5,
                       disconnect_mode=mode) as dev:
        source = ArduinoSource(dev.port, rate_Hz=20, calibration=KE, stall_timeout_s=1.2)
        writer = LogWriter(path, {})

        def resumed(c):
            if "gap" not in c.kinds():
                return False
            t_gap = dict(c.events)["gap"]["end_time_s"]
            return sum(s.time_s >= t_gap for s in c.samples) >= 20

        col = Collect(until=resumed)
        run_until(source, [writer], col, reconnect=ReconnectPolicy(first_delay_s=0.1,
                                                                     max_delay_s=0.5))
    kinds = [k for k in col.kinds() if k in ("disconnect", "reconnect", "gap")]
    assert kinds == ["disconnect", "reconnect", "gap"]
    assert source.stats["reconnects"] == 1
    gap = dict(col.events)["gap"]
    assert gap["duration_s"] >= 2.0                    # the device was away 2.5 s (+ detection)
    times = np.array([s.time_s for s in col.samples])
    assert np.all(np.diff(times) > 0)
    data, meta = read_log(path)
    assert [e["kind"] for e in meta["events"] if e["kind"] != "stop"] == kinds
    assert len(data) == len(col.samples)


def test_cutoff_stops_the_test_switches_the_load_off_and_is_recorded(tmp_path):
    path = tmp_path / "run.csv"
    limits = SafetyLimits.for_chemistry("lipo", 2)     # 6.0 V pack
    with VirtualDevice("zippy-1100-2s", current_A=4.0, speed=250, seed=8, relay=True,
                       keep_history=True) as dev:
        source = ArduinoSource(dev.port, rate_Hz=2, calibration=KE, switch_load=True)
        writer = LogWriter(path, {"cutoff_pack_V": limits.cutoff_pack_V})
        col = Collect()
        pipe = Pipeline(source, [writer, col])
        safety = SafetyMonitor(limits, lambda kind, msg, f: pipe.request_stop(kind, msg,
                                                                              kind=kind, **f))
        pipe.add(safety)
        pipe.start()
        assert pipe.wait(WAIT_S), "the cutoff did not end the test"
        pipe.close()
        assert dev.load_switched_off.wait(10), "the load relay was not opened"
        assert not dev.load_on
    assert pipe.ended_by == "cutoff" and pipe.exit_status == 3
    v = np.array([s.voltage_V for s in col.samples])
    below = v <= limits.cutoff_pack_V
    first = next(k for k in range(len(v) - 2) if below[k:k + 3].all())
    trip = dict(col.events)["cutoff"]
    assert trip["time_s"] == col.samples[first + 2].time_s      # third consecutive sample
    data, meta = read_log(path)
    kinds = [e["kind"] for e in meta["events"]]
    assert kinds[0] == "cutoff" and "stop" in kinds
    cutoff_event = meta["events"][0]
    assert cutoff_event["voltage_V"] <= limits.cutoff_pack_V
    assert len(data) >= first + 3


def test_pipeline_consumer_error_stops_and_reports(tmp_path):
    class Broken(Collect):
        def handle(self, sample):
            raise OSError("disk full")

    with VirtualDevice(speed=5) as dev:
        source = ArduinoSource(dev.port, rate_Hz=5, calibration=KE)
        pipe = Pipeline(source, [Broken()]).start()
        assert pipe.wait(WAIT_S)
        pipe.close()
    assert pipe.ended_by == "error" and "disk full" in pipe.end_message
    assert not source.streaming


def test_unanswered_port_gives_one_clear_error(tmp_path):
    import os
    import tty

    from dischargelab.acquire.pipeline import SourceDisconnected

    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        with pytest.raises(SourceDisconnected, match="no answer from a dischargelab logger"):
            ArduinoSource(os.ttyname(slave), calibration=KE, connect_timeout_s=0.5)
    finally:
        os.close(master)
        os.close(slave)
    with pytest.raises(SourceDisconnected, match="cannot open serial port"):
        ArduinoSource(str(tmp_path / "nope"), calibration=KE)


@pytest.mark.parametrize("name", ["shepherd", "shepherd-thermal", "ecm"])
def test_virtual_device_runs_any_model_family(name):
    from dischargelab.model import Battery, CellParameters
    from dischargelab.models import FAMILIES

    fam = FAMILIES[name]
    battery = Battery(CellParameters(fam.defaults()), model=name, cells_series=2)
    dev = VirtualDevice(battery, current_A=3.0, speed=60.0, thermistor=Thermistor())
    dev._discharging = True   # the load is on (no relay): what START does
    dev._advance(0.0)
    dev._advance(1.0)   # one minute of the model at 3 A: it heats the cell and uses charge
    assert dev.charge_Ah == pytest.approx(3.0 / 60.0)
    assert dev.temperature_C > dev.ambient_C
    assert 0 < dev.pack_voltage_V() < 2 * 4.5
