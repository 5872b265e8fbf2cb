"""Time to cutoff of a running test: the battery model's when one is known, else the trend.

The acceptance runs a virtual logger (the model drives a pseudo-terminal read through real
pyserial, with ADC quantisation and noise) through the acquisition and compares the live
estimate at mid-test with the time the run really took to reach its cutoff.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from rich.console import Console

import dischargelab as dl
from dischargelab.acquire.acquisition import AcquireSettings, prepare_acquisition
from dischargelab.acquire.calibration import Calibration
from dischargelab.acquire.live import LiveDisplay
from dischargelab.acquire.pipeline import Sample
from dischargelab.acquire.remaining import model_time_to_cutoff_s
from dischargelab.acquire.sensors import CURRENT_SENSORS, Thermistor
from dischargelab.acquire.virtual_device import VirtualDevice
from dischargelab.simulate import simulate_current

PRESET = "zippy-1100-2s"
CUTOFF_PACK_V = 6.0          # 2 x 3.0 V (the LiPo preset's cutoff)


def simulated_samples(battery, current_A, *, every_s=5.0, charge_before_Ah=0.0):
    """Samples of a constant-current discharge on the model itself (exact voltages)."""
    sim = simulate_current(battery, current_A, cutoff_pack_V=CUTOFF_PACK_V,
                           initial_charge_Ah=charge_before_Ah, points=2000)
    import numpy as np

    t = np.arange(0.0, sim.time_to_cutoff_s, every_s)
    v = np.interp(t, sim.time_s, sim.voltage_V)
    return [Sample(float(a), float(b), current_A, None, k) for k, (a, b) in enumerate(zip(t, v))
            ], sim.time_to_cutoff_s


def test_model_estimate_on_the_models_own_discharge_and_the_trend_without_one():
    bat = dl.load(PRESET)
    current = bat.capacity_Ah
    samples, total = simulated_samples(bat, current)
    with_model = LiveDisplay(cells_series=2, cutoff_pack_V=CUTOFF_PACK_V, battery=bat,
                             clock=iter(range(10**6)).__next__)
    without = LiveDisplay(cells_series=2, cutoff_pack_V=CUTOFF_PACK_V)
    half = len(samples) // 2
    for s in samples[:half]:
        with_model.handle(s)
        without.handle(s)
    left = total - samples[half - 1].time_s
    seconds, how = with_model.time_to_cutoff()
    assert how == "model" and seconds == pytest.approx(left, rel=0.01)
    assert with_model.charge_before_Ah == pytest.approx(0.0, abs=0.005)
    seconds, how = without.time_to_cutoff()
    assert how == "trend" and seconds > 2 * left        # the flat middle: far too long
    console = Console(record=True, width=120)
    console.print(with_model.render())
    text = console.export_text()
    assert "to cutoff" in text and "(model)" in text


def test_a_pack_started_part_discharged_is_read_on_the_model():
    bat = dl.load(PRESET)
    samples, total = simulated_samples(bat, 1.0, charge_before_Ah=0.4)
    display = LiveDisplay(cells_series=2, cutoff_pack_V=CUTOFF_PACK_V, battery=bat,
                          clock=iter(range(10**6)).__next__)
    half = len(samples) // 2
    for s in samples[:half]:
        display.handle(s)
    assert display.charge_before_Ah == pytest.approx(0.4, abs=0.01)
    seconds, how = display.time_to_cutoff()
    assert how == "model"
    assert seconds == pytest.approx(total - samples[half - 1].time_s, rel=0.02)


def test_no_current_or_a_model_below_the_cutoff_falls_back_to_the_trend():
    bat = dl.load(PRESET)
    display = LiveDisplay(cells_series=2, cutoff_pack_V=CUTOFF_PACK_V, battery=bat)
    for k in range(200):                      # no current known: the model cannot say
        display.handle(Sample(10.0 * k, 7.4 - 0.001 * k, None, None, k))
    assert display.time_to_cutoff()[1] == "trend"
    assert model_time_to_cutoff_s(bat, charge_out_Ah=bat.capacity_Ah, current_A=1.0,
                                  cutoff_pack_V=CUTOFF_PACK_V) is None
    assert model_time_to_cutoff_s(bat, charge_out_Ah=0.2, current_A=0.0,
                                  cutoff_pack_V=CUTOFF_PACK_V) is None
    assert model_time_to_cutoff_s(bat, charge_out_Ah=0.2, current_A=1.0,
                                  cutoff_pack_V=7.5) is None      # model already below it
    four = LiveDisplay(cells_series=4, cutoff_pack_V=12.0, battery=bat)
    assert four.battery.cells_series == 4                         # the bench's pack


def test_the_live_page_status_says_how_it_was_found():
    from dischargelab.web.live import LiveHub

    bat = dl.load(PRESET)
    samples, _ = simulated_samples(bat, 1.0)

    async def scenario():
        hub = LiveHub()
        hub.begin({}, cells_series=2, cutoff_pack_V=CUTOFF_PACK_V, current_given_A=None,
                  battery=bat)
        for s in samples[:100]:
            hub.handle(s)
        model = hub.status()
        hub.begin({}, cells_series=2, cutoff_pack_V=CUTOFF_PACK_V)
        for s in samples[:100]:
            hub.handle(s)
        return model, hub.status()

    model, trend = asyncio.run(scenario())
    assert model["time_to_cutoff_method"] == "model" and model["time_to_cutoff_s"] > 0
    assert trend["time_to_cutoff_method"] == "trend"


def run_virtual(tmp_path: Path, *, battery: str, cells: int, chemistry: str,
                charge_before_Ah: float = 0.0, speed: float = 600, seed: int = 1):
    """A 1C virtual-logger discharge to the cutoff; returns the estimates seen every
    quarter second, ``[(test time, seconds, method)]``, and the test time at the end."""
    bat = dl.load(battery)
    out = tmp_path / "run.csv"
    seen = []
    with VirtualDevice(bat, current_A=bat.capacity_Ah, rate_Hz=1.0, speed=speed,
                       divider_gain=4.38, seed=seed) as dev:
        dev.charge_Ah = charge_before_Ah
        acq = prepare_acquisition(AcquireSettings(
            port=dev.port, out=out, cells=cells, chemistry=chemistry, rate_Hz=1.0,
            calibration=Calibration(gain=4.38, divider="virtual"),
            current_sensor=CURRENT_SENSORS["acs712-20a"], thermistor=Thermistor(),
            battery_model=bat))

        def watch(a):
            if a.display.last is not None:
                seen.append((a.display.last.time_s, *a.display.time_to_cutoff(),
                             a.display.trend_time_to_cutoff_s()))

        result = acq.run(view="none", on_tick=watch)
    assert result.ended_by == "cutoff", result.message
    return seen, result.summary["duration_s"]


def at_mid(seen, end):
    t, seconds, how, trend = min(seen, key=lambda r: abs(r[0] - end / 2))
    return end - t, seconds, how, trend


@pytest.mark.slow
def test_model_estimate_at_mid_test_within_10_percent_on_a_virtual_logger(tmp_path):
    seen, end = run_virtual(tmp_path, battery=PRESET, cells=2, chemistry="lipo")
    actual, seconds, how, trend = at_mid(seen, end)
    print(f"\nmid-test: {actual:.0f} s left; model {seconds:.0f} s, trend {trend:.0f} s")
    assert how == "model"
    assert seconds == pytest.approx(actual, rel=0.10)
    assert abs(trend - actual) > abs(seconds - actual)
    assert all(r[2] == "model" for r in seen if 0.1 * end < r[0] < 0.9 * end)


@pytest.mark.slow
def test_model_estimate_of_a_part_discharged_pack_on_a_virtual_logger(tmp_path):
    seen, end = run_virtual(tmp_path, battery=PRESET, cells=2, chemistry="lipo",
                            charge_before_Ah=0.4, seed=3)
    actual, seconds, how, _ = at_mid(seen, end)
    print(f"\nmid-test (0.4 Ah out before): {actual:.0f} s left; model {seconds:.0f} s")
    assert how == "model" and seconds == pytest.approx(actual, rel=0.10)
