"""Health maths of the logbook without a database: summaries, capacity, EFC, outliers, forecast.

Truths are computed here from the raw files with numpy, or built by hand.
"""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

from dischargelab.errors import DataError
from dischargelab.fleet import InProcessExecutor
from dischargelab.logbook.forecast import (
    SPAN_SOON,
    Z_MEASURED,
    EolForecast,
    dating,
    efc_to_measure,
    fit_fade,
    forecast_eol,
    measure_fade,
)
from dischargelab.logbook.health import equivalent_full_cycles, pack_health
from dischargelab.logbook.outliers import flag_outliers, observed_crossing, value_today
from dischargelab.logbook.results import scale_parameters
from dischargelab.logbook.summarise import knee_ratio, step_resistance, summarise_source
from lvm_cut import lvm_cut

CELL_C = "samsung30q_ageing_cellC"


def stored(summary, source_id: int) -> list[dict]:
    """Summary events as the logbook returns them (ids, source name, resistance bounds)."""
    out = []
    for e in summary.events:
        row = dict(e, id=source_id * 10 + e["index"], source=summary.file_name)
        lo, hi = e["resistance_interval95"] or (None, None)
        row.update(resistance_low_ohm=lo, resistance_high_ohm=hi)
        out.append(row)
    return out


# --------------------------------------------------------------------------- summaries

def test_summary_is_small_serialisable_and_pure(shared_data, tmp_path):
    path = shared_data / CELL_C / "DischargeCycle100.txt"
    summary = summarise_source(path)
    again = summarise_source((path.name, path.read_bytes()))
    assert summary.to_dict() == again.to_dict()  # path or upload: the same summary
    assert pickle.loads(pickle.dumps(summary)).to_dict() == summary.to_dict()
    text = json.dumps(summary.to_dict())
    assert len(text) < 20_000  # numbers and a 101-point curve, never the 3,300 samples
    (event,) = summary.events
    assert event["cycle"] == 100 and event["kind"] == "discharge" and event["reaches_knee"]
    assert event["start_time"].startswith("2024-")
    with pytest.raises(DataError):
        summarise_source(tmp_path / "missing.txt")


def test_step_resistance_of_a_known_circuit():
    """A 20 mOhm pack on a stepping load; its open-circuit voltage falls 1 mV/s, which moves
    a 20 A step over 1 s by 1 mV / 20 A = 0.05 mOhm."""
    t = np.arange(200.0)
    current = np.where((t // 20) % 2 == 0, 10.0, 30.0)
    voltage = 16.0 - 0.001 * t - 0.020 * current
    r, (lo, hi) = step_resistance(t, voltage, current)
    assert r == pytest.approx(0.020, abs=0.00005 + 1e-12)
    assert lo <= r <= hi
    assert step_resistance(t, voltage, np.full(t.size, 10.0)) == (None, None)


def test_knee_ratio_tells_a_discharge_to_cutoff_from_one_stopped_early():
    q = np.linspace(0, 3.0, 400)
    v = 4.1 - 0.3 * q - 0.6 * np.exp((q - 3.0) / 0.05)  # falls 0.6 V over its last 5 %
    assert knee_ratio(q, v) > 4
    assert knee_ratio(q[:240], v[:240]) < 2


# --------------------------------------------------------------------------- health

def test_equivalent_full_cycles_count_unlogged_cycles():
    events = [{"discharged_Ah": 3.0, "cycle": 1}, {"discharged_Ah": 2.0, "cycle": 11},
              {"discharged_Ah": 2.0}]
    # 3 + 9 cycles of (3+2)/2 + 2, then 2 more Ah
    np.testing.assert_allclose(equivalent_full_cycles(events, 2.0),
                               [1.5, (3 + 22.5 + 2) / 2, (3 + 22.5 + 4) / 2])


def test_outliers_are_found_off_a_trend_and_not_at_its_ends():
    rng = np.random.default_rng(1)
    x = np.arange(40.0) * 10
    y = 3.0 - 0.001 * x - 2e-6 * x ** 2 + rng.normal(0, 0.003, x.size)
    y[17] += 0.05  # overcharged
    y[30] -= 0.05  # undercharged
    assert np.flatnonzero(flag_outliers(x, y)).tolist() == [17, 30]


def test_value_today_and_observed_crossing():
    x = np.arange(10.0)
    y = 2.0 - 0.1 * x
    assert value_today(x, y) == pytest.approx(2.0 - 0.9)
    at, (a, b) = observed_crossing(x, y, 1.45)
    assert at == pytest.approx(5.5) and (a, b) == (5.0, 6.0)
    assert observed_crossing(x, y, 1.05) is None  # only the last one is below


def test_partial_discharges_cut_at_60_percent_within_3_percent(shared_data, tmp_path):
    """Each 60 % cut against the full integral, measured on the previous full discharge."""
    cycles = [1, 10, 200, 210, 500, 510]
    events = []
    truth = {}
    for k, c in enumerate(cycles):
        path = shared_data / CELL_C / f"DischargeCycle{c:03d}.txt"
        if k % 2:  # every second one cut
            cut = tmp_path / path.name
            truth[path.name] = lvm_cut(path, cut, 0.6)
            path = cut
        events += stored(summarise_source(path), k)
    health, reference, _ = pack_health(events)
    partial = [h for h in health if not h.full]
    assert [h.source for h in partial] == [f"DischargeCycle{c:03d}.txt" for c in cycles[1::2]]
    for h in partial:
        assert h.capacity_Ah == pytest.approx(truth[h.source], rel=0.03)
        lo, hi = h.capacity_interval95
        assert lo < truth[h.source] < hi
    assert reference == pytest.approx(health[0].capacity_Ah)


@pytest.mark.parametrize("dated, down", [(True, 0.45), (False, 0.45), (True, 0.2)],
                         ids=["dated-3.8V", "undated-3.8V", "dated-4.08V"])
def test_partials_from_a_storage_charge_or_a_fresh_rest_within_3_percent(shared_data, tmp_path,
                                                                        dated, down):
    """A discharge from a storage charge (a rest near 3.8 V, or near 4.08 V, which a
    generic curve reads at 90 % and more: not full, since it delivered less than the full
    discharge after it) run to the cutoff, and one from a full charge whose rest still
    reads 40 mV high, against the full integral."""
    from lvm_cut import lvm_storage

    events, truth = [], {}
    for k, c in enumerate((1, 100, 200, 300)):
        events += stored(summarise_source(shared_data / CELL_C / f"DischargeCycle{c:03d}.txt"), k)
    for k, c in enumerate((110, 210, 310)):
        path = shared_data / CELL_C / f"DischargeCycle{c:03d}.txt"
        store = tmp_path / f"storage_{c}.txt"
        truth[store.name] = lvm_storage(path, store, down, dated)
        fresh = tmp_path / f"fresh_{c}.txt"
        truth[fresh.name] = lvm_cut(path, fresh, 0.6, dated)
        lines = fresh.read_text().splitlines(keepends=True)
        first = next(i for i, line in enumerate(lines) if line.startswith("X_Value")) + 1
        cols = lines[first].split("\t")
        cols[2] = f"{float(cols[2]) + 0.04:.6f}"
        lines[first] = "\t".join(cols)
        fresh.write_text("".join(lines))
        events += stored(summarise_source(store), 10 + k) + stored(summarise_source(fresh),
                                                                   20 + k)
    health, _, _ = pack_health(events)
    got = {h.source: h for h in health if h.source in truth}
    assert len(got) == 6
    for name, h in got.items():
        assert h.capacity_Ah == pytest.approx(truth[name], rel=0.03), name
        lo, hi = h.capacity_interval95
        assert lo < truth[name] < hi
    assert got["storage_110.txt"].soc_start == pytest.approx(1.0 - down, abs=0.03)
    assert not any(h.full for h in got.values())


@pytest.mark.parametrize("name, dated", [("storage_110.txt", True),
                                         ("DischargeCycle110.txt", False)],
                         ids=["dated-unnumbered", "undated-numbered"])
def test_a_storage_run_between_two_numbered_cycles(shared_data, tmp_path, name, dated):
    """Cycles 100 and 200 of cell C and, between them, a run from a storage charge 15 %
    down (dated without a cycle number, or numbered without a clock time), as a user adds
    them: the run sits between them, is not a full discharge and says so, the 99 cycles
    between the numbered ones still count, and the resistance's band stays positive."""
    from dischargelab.logbook import Logbook
    from dischargelab.logbook.health import NOT_FULL_NOTE
    from lvm_cut import lvm_storage

    folder = shared_data / CELL_C
    store = tmp_path / name
    truth = lvm_storage(folder / "DischargeCycle110.txt", store, 0.15, dated)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add([folder / "DischargeCycle100.txt", folder / "DischargeCycle200.txt", store],
               pack="C")
        health = lb.health("C")
    run = next(e for e in health.events if e.source == store.name)
    assert not run.full and run.notes[0].startswith(NOT_FULL_NOTE)
    assert run.capacity_Ah == pytest.approx(truth, rel=0.03)
    # placed between the two by its clock time, or by its number among numbered ones
    assert [e.source for e in health.events] == ["DischargeCycle100.txt", name,
                                                "DischargeCycle200.txt"]
    if dated:   # unnumbered: the 99 cycles between 100 and 200 count, the run one of them
        efc = [e.efc for e in health.events]
        per_cycle = 2.7 / health.reference_capacity_Ah
        assert efc[-1] - efc[0] == pytest.approx(100 * per_cycle, rel=0.05)
    assert health.today["resistance_interval95"][0] >= 0.0


def test_a_run_from_a_storage_charge_that_nothing_places_in_the_life(shared_data, tmp_path):
    """Runs of cycles 110, 310 and 510 from a charge 10 % down (rests 4.15-4.11 V, where
    an older cell rests full), in files with neither a clock time nor a cycle number,
    added after the full discharges: each is laid on the full discharges by its curve
    counted back from its end, taken back from full and measured within 3 %; the full
    discharges themselves all stay full."""
    from dischargelab.logbook.health import NOT_FULL_NOTE
    from lvm_cut import lvm_storage

    folder = shared_data / CELL_C
    events, truth = [], {}
    fulls = (1, 100, 200, 300, 400, 500, 600, 660)
    for k, c in enumerate(fulls):
        events += stored(summarise_source(folder / f"DischargeCycle{c:03d}.txt"), k)
    for k, c in enumerate((110, 310, 510)):
        store = tmp_path / f"run_{'abc'[k]}.txt"
        truth[store.name] = lvm_storage(folder / f"DischargeCycle{c:03d}.txt", store, 0.1,
                                        dated=False)
        events += stored(summarise_source(store), 20 + k)
    health, _, _ = pack_health(events)
    assert sum(h.full for h in health) == len(fulls)
    runs = [h for h in health if h.source in truth]
    assert len(runs) == 3
    for h in runs:
        assert not h.full and h.notes[0].startswith(NOT_FULL_NOTE), h.source
        assert h.capacity_Ah == pytest.approx(truth[h.source], rel=0.03), h.source
        lo, hi = h.capacity_interval95
        assert lo < truth[h.source] < hi


def test_partials_from_a_storage_charge_stopped_under_load(tmp_path):
    """Engine-made bench discharges of one cell at 1C (its slow polarisation relaxing over
    900 s, its curve 8 mV off the generic one and moving with age): full ones at 0, 100,
    200 and 300 EFC, and runs from a storage charge 45 % down (two hours' rest) stopped
    under load after half their charge, at 50, 150 and 250 EFC. Each rest is placed on the
    full discharges' open-circuit voltage with the drop the load settled to, as the pack's
    learned curve takes it: within 10 % of the full discharge at that age, inside the band
    (on the step resistance's drop: 16-19 % low, outside it)."""
    import synthetic_life as sl
    from dischargelab.logbook import Logbook

    spec = sl.LifeSpec(ocv_wiggle_V=0.008, season_C=0.0, resistance_growth_per_efc=2e-3,
                       lli_share=0.3, knee_efc=1e6)
    files, truth = [], {}
    for efc in (0, 100, 200, 300):
        files.append(tmp_path / f"full_{efc:03d}.csv")
        sl.bench_discharge(files[-1], spec, efc, current_A=3.0)
    for efc in (50, 150, 250):
        path = tmp_path / f"storage_{efc:03d}.csv"
        capacity = sl.capacity_at(spec, efc)
        truth[path.name] = sl.bench_discharge(path, spec, efc, current_A=3.0, down=0.45,
                                              stop_Ah=0.5 * 0.55 * capacity)
        files.append(path)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.set_pack("cell", cells=1, chemistry="li-ion")
        lb.add(files, pack="cell")
        health = lb.health("cell")
    runs = [e for e in health.events if e.source in truth]
    assert len(runs) == 3 and sum(e.full for e in health.events) == 4
    for e in runs:
        assert not e.full and e.capacity_Ah == pytest.approx(truth[e.source], rel=0.10)
        lo, hi = e.capacity_interval95
        assert lo < truth[e.source] < hi, e.source


# --------------------------------------------------------------------------- forecast

def test_forecast_of_a_straight_fade_centres_on_its_crossing():
    """A straight fade logged to 150 EFC that reaches 80 % at 300 EFC: chosen as a line, the
    crossing inside the interval (the median earlier: a knee may come), the band positive;
    a flat pack gets no finite median."""
    rng = np.random.default_rng(3)
    x = np.linspace(1, 150, 30)
    y = 3.0 - 0.002 * x + rng.normal(0, 0.005, x.size)
    fit = fit_fade(x, y)
    assert fit.family == "line" and fit.knee_efc is None
    ahead = forecast_eol(fit, 3.0, 2.4)
    lo, hi = ahead.interval95
    assert lo < 300 < hi and 0.75 * 300 < ahead.eol_efc <= 300
    assert np.all(ahead.low > 0) and ahead.efc[0] == pytest.approx(x[-1])
    flat = fit_fade(x, 3.0 + rng.normal(0, 0.005, x.size))
    assert forecast_eol(flat, 3.0, 1.5, paths=1000).eol_efc is None  # no fade to speak of


@pytest.mark.slow
def test_forecast_from_cycle_220_and_330_covers_the_observed_crossing(shared_data):
    """Cell C: forecast from the cycles up to 220 and 330, checked against the crossing the
    later cycles show (80 % of the first full discharge): covered, centre within 20 %."""
    from dischargelab.logbook.trend import smooth

    files = sorted((shared_data / CELL_C).glob("DischargeCycle*.txt"))
    events = []
    for k, path in enumerate(files):
        events += stored(summarise_source(path), k)
    everything, reference, _ = pack_health(events)
    threshold = 0.8 * reference
    usable = [h for h in everything if not h.outlier]
    seen = observed_crossing([h.efc for h in usable], [h.capacity_Ah for h in usable], threshold)
    assert seen is not None
    for upto in (220, 330):
        early = [h for h in usable if h.cycle <= upto]
        x, q = [h.efc for h in early], [h.capacity_Ah for h in early]
        lo95, hi95 = zip(*[h.capacity_interval95 for h in early])
        weights = smooth(x, q, lo95, hi95).weights
        ahead = forecast_eol(fit_fade(x, q, lo95, hi95, weights), reference, threshold)
        lo, hi = ahead.interval95
        assert lo <= seen[0] <= hi, upto
        assert ahead.eol_efc == pytest.approx(seen[0], rel=0.2), upto


def test_a_difference_between_kinds_of_estimate_is_never_fade():
    """Charges that read 5 % above the full discharges, each kind flat: no fade, though a
    line through all of them falls at many sigma; the same with a real fade in each kind
    is measured, and well outside the noise over more than SPAN_SOON EFC."""
    rng = np.random.default_rng(5)
    x = np.linspace(0.5, 3.0, 6)
    kinds = ["charge", "full"] * 3
    q = np.where(np.array(kinds) == "charge", 6.10, 5.81) + rng.normal(0, 0.003, x.size)
    tight = dict(low95=q - 0.01, high95=q + 0.01)
    flat = measure_fade(x, q, kinds=kinds, chemistry="li-ion", **tight)
    assert not flat.measured and abs(flat.z) < Z_MEASURED
    assert flat.efc_needed is not None and flat.efc_needed > x[-1]
    x = np.linspace(0.0, 60.0, 13)
    kinds = ["charge", "full"] * 6 + ["full"]
    q = np.where(np.array(kinds) == "charge", 6.10, 5.81) * (1 - 0.001 * x) \
        + rng.normal(0, 0.005, x.size)
    fading = measure_fade(x, q, q - 0.02, q + 0.02, kinds, chemistry="li-ion")
    assert fading.measured and fading.strong and fading.span_efc >= SPAN_SOON
    assert fading.interval95()[0] < 0.001 < fading.interval95()[1]


def test_efc_a_fade_needs_follows_the_slope_variance_of_evenly_spread_estimates():
    """Without a shared error the span is ``(12 z^2 sigma^2 / (rho r^2))^(1/3)``; a shared
    error that no span beats leaves it None."""
    rate, sigma, per_efc = 2.5e-4, 0.01, 2.0
    closed = (12 * Z_MEASURED ** 2 * sigma ** 2 / (per_efc * rate ** 2)) ** (1 / 3)
    assert efc_to_measure(rate, sigma, per_efc, 0.0) == pytest.approx(closed, rel=1e-6)
    assert efc_to_measure(rate, sigma, per_efc, 0.01) > closed
    assert efc_to_measure(rate, sigma, per_efc, 200.0) is None


def test_an_end_of_life_soon_needs_a_strong_fade():
    """A fade measured at 2.5 sigma gives no end of life whose interval reaches inside 5x
    today's EFC; one beyond it is given; an unmeasured fade gives none at all."""
    x = np.linspace(0.0, 10.0, 6)
    rng = np.random.default_rng(1)
    q = 3.0 * (1 - 0.002 * x) + rng.normal(0, 0.004, x.size)
    weak = measure_fade(x, q, q - 0.01, q + 0.01, ["full"] * x.size)
    weak.z, weak.span_efc = 2.5, 10.0
    grid = np.array([10.0, 100.0])
    soon = EolForecast(2.4, 30.0, [20.0, 80.0], grid, grid, grid, grid, 1.0)
    later = EolForecast(2.4, 300.0, [60.0, None], grid, grid, grid, grid, 1.0)
    assert dating(weak, soon, 10.0) == "uncertain"
    assert dating(weak, later, 10.0) == "dated"
    weak.z = 1.0
    assert dating(weak, later, 10.0) == "no fade"


def test_scaled_parameters_keep_the_curve_shape_in_state_of_charge():
    units = {"C_Ah": "Ah", "K_V_per_Ah": "V/Ah", "B_per_Ah": "1/Ah", "R_ohm": "ohm",
             "E0_V": "V"}
    values = {"C_Ah": 3.0, "K_V_per_Ah": 0.01, "B_per_Ah": 2.0, "R_ohm": 0.03, "E0_V": 3.7}
    out = scale_parameters(values, units, 0.8, 0.005)
    assert out == pytest.approx({"C_Ah": 2.4, "K_V_per_Ah": 0.0125, "B_per_Ah": 2.5,
                                 "R_ohm": 0.035, "E0_V": 3.7})
    assert scale_parameters(values, units, 1.0, -1.0)["R_ohm"] == 0.0


def test_in_process_executor_hands_back_exceptions():
    def task(x):
        if x == 2:
            raise DataError("bad item")
        return x * 10

    got = dict(InProcessExecutor().map_unordered(task, [1, 2, 3]))
    assert got[1] == 10 and got[3] == 30 and isinstance(got[2], DataError)


# --------------------------------------------------------------------------- LiHV prior

def test_lihv_curve_extends_the_lipo_curve_to_4_35_v():
    """The high-voltage LiPo curve: the LiPo curve below its top with its charge scaled by
    the extension's share, rising above it to the rest after a 4.35 V charge (as far below
    4.35 V as the LiPo curve's top is below 4.20 V), non-decreasing in state of charge."""
    from dischargelab.ocv import (
        CHARGE_CELL_V,
        GENERIC_OCV_V,
        LIHV_EXTRA_SHARE,
        LIHV_FULL_CELL_V,
        LIHV_OCV_V,
        OCV_SOC,
        charge_cell_V,
        generic_ocv,
    )

    relaxed = CHARGE_CELL_V["lipo"] - GENERIC_OCV_V["lipo"][0]
    assert LIHV_OCV_V[0] == pytest.approx(LIHV_FULL_CELL_V - relaxed, abs=1e-3)
    assert LIHV_OCV_V[-1] == pytest.approx(GENERIC_OCV_V["lipo"][-1], abs=1e-3)
    assert np.all(np.diff(LIHV_OCV_V) <= 0)
    assert 0.05 < LIHV_EXTRA_SHARE < 0.3
    # below the old top: the same voltage at the charge left scaled by (1 - share)
    soc = 0.5
    hv = np.interp(soc * (1 - LIHV_EXTRA_SHARE), OCV_SOC[::-1], LIHV_OCV_V[::-1])
    assert hv == pytest.approx(np.interp(soc, OCV_SOC[::-1], GENERIC_OCV_V["lipo"][::-1]),
                               abs=0.01)
    # chosen from the rest voltage, and only for LiPo
    assert generic_ocv("lipo", 4.32)[0] is LIHV_OCV_V
    assert generic_ocv(None, 4.32)[0] is LIHV_OCV_V
    assert generic_ocv("lipo", 4.19)[0] is GENERIC_OCV_V["lipo"]
    assert generic_ocv("li-ion", 4.32)[0] is GENERIC_OCV_V["li-ion"]
    # its charges end full at 4.35 V per cell, not at a LiPo's 4.20 V
    assert charge_cell_V("lipo", 4.32) == LIHV_FULL_CELL_V
    assert charge_cell_V(None, 4.32) == LIHV_FULL_CELL_V
    assert charge_cell_V("lipo", 4.19) == CHARGE_CELL_V["lipo"]
    assert charge_cell_V("li-ion", 4.32) == CHARGE_CELL_V["li-ion"]
    assert charge_cell_V("lifepo4") == CHARGE_CELL_V["lifepo4"]


def test_dji_hv_pack_reads_through_the_lihv_curve(shared_data):
    """A DJI Matrice 100 pack rests at 4.29-4.35 V per cell (a 4.35 V LiHV pack): its
    flights are read through the LiHV curve, whose rest before a flight from a pack not
    quite full no longer reads 100 %."""
    summary = summarise_source(shared_data / "dji_m100_flights"
                               / "derived_battery_20-01-12_tablet1_2020_01_12_12_08.csv")
    events = stored(summary, 1)
    health, _, _ = pack_health(events, cells=6, chemistry="lipo")
    flight = next(h for h in health if h.capacity_Ah is not None)
    assert any("LiHV" in n for n in flight.notes)
    # 25.836 V at rest = 4.306 V per cell: below the LiHV top, above the LiPo curve's
    assert 0.9 < flight.soc_start < 0.99
    assert flight.capacity_interval95[0] < flight.capacity_Ah < flight.capacity_interval95[1]


def test_cells_from_a_smart_battery_gauge():
    """The one count for which the idle voltage at a full gauge reading is a full cell's."""
    from dischargelab.flight.samples import cells_from_gauge

    current = np.array([0.8, 0.8, 18.0, 20.0, 0.9])
    # 26.1 V at 100 %: 6 x 4.35 V (LiHV), not 7 x 3.73 V; the loaded 24.2 V is left out
    assert cells_from_gauge([26.11, 26.10, 24.2, 22.0, 22.1], current, [100, 99, 97, 40, 39]) == 6
    # 4S LiFePO4 full at 13.4 V (3 x 4.47 V is too high for any lithium cell)
    assert cells_from_gauge([13.4, 13.4, 12.0, 12.5, 12.6], current, [98, 98, 90, 40, 39]) == 4
    # 16.75 V: 4 x 4.19 V (LiPo) or 5 x 3.35 V (LiFePO4): no answer
    assert cells_from_gauge([16.75, 16.74, 15.0, 14.0, 14.5], current,
                            [100, 99, 90, 40, 39]) is None
    # never full at idle: no answer
    assert cells_from_gauge([23.9, 23.9, 22.0, 21.0, 22.0], current, [67, 66, 50, 20, 19]) is None


def test_dji_pack_without_cells_is_6s_from_its_gauge(shared_data):
    """A DJI log added without --cells: 26.1 V is a 6S LiHV pack at its gauge's 100 %."""
    summary = summarise_source(shared_data / "dji_m100_flights"
                               / "derived_battery_19-12-17_tablet1_2019_12_17_18_49.csv")
    assert {e["cells"] for e in summary.events} == {6}
    health, _, _ = pack_health(stored(summary, 1))
    flight = next(h for h in health if h.capacity_Ah is not None)
    assert 5.0 < flight.capacity_Ah < 6.2          # the gauge's: 4.957 Ah over 89 %: 5.57 Ah
