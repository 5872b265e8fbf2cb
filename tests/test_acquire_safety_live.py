"""Safety monitor (debounce, never skipped), live view numbers and rendering, source factory."""

import math

import pytest
from rich.console import Console

from dischargelab.acquire.live import LiveDisplay, LivePlot, Trend, sparkline
from dischargelab.acquire.pipeline import Sample
from dischargelab.acquire.safety import SafetyLimits, SafetyMonitor, infer_cells
from dischargelab.acquire.sources import SOURCE_KINDS, open_source, register_source
from dischargelab.errors import DataError
from dischargelab.model import CUTOFF_CELL_VOLTAGE_V


def monitor(limits):
    trips = []
    return SafetyMonitor(limits, lambda kind, msg, fields: trips.append((kind, msg, fields))), trips


def feed(mon, voltages, temps=None):
    temps = temps or [None] * len(voltages)
    for k, (v, t) in enumerate(zip(voltages, temps)):
        mon.handle(Sample(float(k), v, None, t, k))


def test_chemistry_presets_and_override():
    for chem, cell in CUTOFF_CELL_VOLTAGE_V.items():
        assert SafetyLimits.for_chemistry(chem, 4).cutoff_pack_V == pytest.approx(4 * cell)
    assert SafetyLimits.for_chemistry("lipo", 3, cutoff_cell_V=3.3).cutoff_pack_V == \
        pytest.approx(9.9)
    with pytest.raises(DataError, match="unknown chemistry"):
        SafetyLimits.for_chemistry("nimh", 3)


def test_one_noisy_sample_does_not_stop_the_test():
    mon, trips = monitor(SafetyLimits.for_chemistry("lipo", 2))       # 6.0 V
    feed(mon, [7.0, 5.9, 7.0, 5.9, 5.9, 7.0, 6.5])
    assert trips == [] and mon.tripped is None


def test_sustained_cutoff_trips_once_on_the_nth_sample():
    mon, trips = monitor(SafetyLimits.for_chemistry("lipo", 2, debounce_samples=3))
    feed(mon, [7.0, 6.2, 5.99, 5.98, 5.97, 5.5, 5.0])
    assert len(trips) == 1
    kind, message, fields = trips[0]
    assert kind == "cutoff" and "CUTOFF" in message
    assert fields["time_s"] == 4.0 and fields["samples_below"] == 3


def test_invalid_voltage_counts_as_below():
    mon, trips = monitor(SafetyLimits.for_chemistry("lipo", 2, debounce_samples=2))
    feed(mon, [7.0, math.nan, math.nan])
    assert [t[0] for t in trips] == ["cutoff"]


def test_over_temperature_only_with_a_sensor():
    mon, trips = monitor(SafetyLimits.for_chemistry("li-ion", 1, max_temperature_C=60))
    feed(mon, [4.0] * 4)                                      # no sensor: nothing
    feed(mon, [4.0] * 5, [59.0, 61.0, 62.0, 63.0, 64.0])
    assert [t[0] for t in trips] == ["over-temperature"]
    assert trips[0][2]["temperature_C"] == 63.0


@pytest.mark.parametrize("volts, chem, cells", [
    (16.8, "lipo", 4), (13.3, "lipo", 4), (12.6, "lipo", 3), (9.7, "lipo", 3),
    (8.4, "lipo", 2), (14.6, "lifepo4", 4), (13.2, "lifepo4", 4), (4.1, "li-ion", 1)])
def test_infer_cells(volts, chem, cells):
    assert infer_cells(volts, chem) == cells


def test_live_display_integrates_charge_and_energy():
    display = LiveDisplay(cells_series=2, cutoff_pack_V=6.0, current_given_A=2.0)
    for k in range(3601):
        display.handle(Sample(float(k), 8.0 - k / 3600, None, None, k))
    assert display.charge_Ah == pytest.approx(2.0)
    assert display.energy_Wh == pytest.approx(2.0 * 7.5, rel=1e-6)     # mean voltage 7.5 V
    assert len(display.trend.values) < 2 * display.trend.points
    line = display.status_line()
    assert "V/cell" in line and "2.0000 Ah" in line
    console = Console(record=True, width=120)
    console.print(display.render())
    text = console.export_text()
    assert "3.500 V/cell" in text and "Ah" in text and "cutoff 6.00 V" in text
    display.event("disconnect", reason="cable")
    assert "LINK DOWN" in display.status_line()


def test_measured_current_wins_over_given():
    display = LiveDisplay(current_given_A=5.0)
    display.handle(Sample(0.0, 4.0, 1.0, 30.0, 0))
    display.handle(Sample(3600.0, 4.0, 1.0, 30.0, 1))
    assert display.charge_Ah == pytest.approx(1.0)


def test_sparkline_and_trend():
    assert sparkline([1, 2, 3, 4, 5, 6, 7, 8]) == "▁▂▃▄▅▆▇█"
    assert len(set(sparkline([2.0] * 5))) == 1          # flat: one mid-height bar
    assert len(sparkline(range(1000), width=30)) == 30
    trend = Trend(points=10)
    for k in range(10000):
        trend.add(float(k), float(k))
    assert trend.times[0] == 0.0 and trend.times[-1] > 9000 and len(trend.times) < 20


def test_live_plot_draws(tmp_path):
    display = LiveDisplay(cells_series=2, cutoff_pack_V=6.0)
    for k in range(500):
        display.handle(Sample(k * 7.0, 8.4 - 2.3 * (k / 500) ** 3, None, None, k))
    plot = LivePlot(display, interactive=False)
    plot.update()
    path = tmp_path / "live.png"
    plot.save(path)
    x, y = plot.line.get_data()
    assert len(x) == len(y) > 100 and max(x) == pytest.approx(499 * 7.0)
    assert path.stat().st_size > 10_000


def test_source_factory():
    assert list(SOURCE_KINDS)[0] == "arduino"
    with pytest.raises(DataError, match="unknown source"):
        open_source("nope", "/dev/null")
    with pytest.raises(DataError, match="--ke"):
        open_source("arduino", "/dev/null")
    register_source("test-kind", __name__, "_fake_opener", "for tests")
    try:
        assert open_source("test-kind", "PORT", rate_Hz=3) == ("PORT", 3)
    finally:
        SOURCE_KINDS.pop("test-kind")


def _fake_opener(port, rate_Hz=None, **_):
    return port, rate_Hz
