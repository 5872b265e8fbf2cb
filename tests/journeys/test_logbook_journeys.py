"""A flight counted once however many files hold it, events in date order, and a tester's
file split by its own steps: the shared DJI flights and tester files through the real CLI."""

from __future__ import annotations

import json
from datetime import datetime

import numpy as np
import pytest

from cli_run import run
from shared_files import TESTER_FILES, TESTER_IDS

pytest.importorskip("sqlalchemy")

DJI = "dji_m100_flights"


def add(capsys, db, *paths, extra=()):
    code, out, err = run(capsys, "logbook", "add", *paths, "--pack", "P", "--db", db,
                         "--json", *extra)
    assert code == 0, err
    return json.loads(out)


def health(capsys, db):
    code, out, err = run(capsys, "logbook", "health", "P", "--db", db, "--json")
    assert code == 0, err
    return json.loads(out)


def stored_events(capsys, db):
    code, out, err = run(capsys, "logbook", "events", "P", "--db", db, "--json")
    assert code == 0, err
    return json.loads(out)["events"]


def flights_and_efc(capsys, db):
    h = health(capsys, db)
    return sum(1 for e in h["events"] if e["kind"] == "flight"), h["efc_now"], h


def check_same_as_raw(capsys, tmp_path, folder_db, copies):
    raw_db = tmp_path / "raw.sqlite"
    add(capsys, raw_db, *RAW_LOGS)
    n_raw, efc_raw, _ = flights_and_efc(capsys, raw_db)
    n_all, efc_all, h = flights_and_efc(capsys, folder_db)
    assert n_all == n_raw and n_raw >= 5
    assert abs(efc_all / efc_raw - 1.0) <= 0.05
    # every export is named as skipped, with the raw log kept in its place
    assert sorted(c["file"] for c in copies) == sorted(
        p.name.replace("raw_", "derived_battery_").replace(".txt", ".csv") for p in RAW_LOGS)
    for c in copies:
        kept = c["file"].replace("derived_battery_", "raw_").replace(".csv", ".txt")
        assert kept in c["reason"] and "kept" in c["reason"]
    return h


RAW_LOGS: list = []


@pytest.fixture
def raw_logs(shared_data):
    RAW_LOGS[:] = sorted((shared_data / DJI).glob("raw_*.txt"))
    assert len(RAW_LOGS) == 5
    return RAW_LOGS


def test_the_dji_folder_as_it_is_counts_each_flight_once(capsys, tmp_path, shared_data,
                                                          raw_logs):
    db = tmp_path / "folder.sqlite"
    result = add(capsys, db, shared_data / DJI)
    h = check_same_as_raw(capsys, tmp_path, db, result["copies"])
    # the CLI's words name each skipped file and the file kept
    code, out, err = run(capsys, "logbook", "add", shared_data / DJI, "--pack", "P",
                         "--db", tmp_path / "words.sqlite")
    assert code == 0, err
    for c in result["copies"]:
        assert f"{c['file']}: skipped: " in out
    # events in date order: the life order and the stored dates agree
    starts = [datetime.fromisoformat(e["start"]) for e in h["events"]]
    assert len(starts) == len(h["events"]) and starts == sorted(starts)
    assert starts[0].date().isoformat() == "2019-11-28"
    listed = stored_events(capsys, db)
    assert [e["start_time"] for e in listed] == sorted(e["start_time"] for e in listed)
    for e in listed:
        day = e["source"].split("_")[-5:-2]          # ..._2019_11_28_18_28.txt
        assert e["start_time"].startswith("-".join(day))


def test_exports_added_in_a_later_run_are_skipped_as_copies(capsys, tmp_path, shared_data,
                                                             raw_logs):
    db = tmp_path / "later.sqlite"
    first = add(capsys, db, *raw_logs)
    assert len(first["added"]) == 5 and not first["copies"]
    exports = sorted((shared_data / DJI).glob("derived_*.csv"))
    second = add(capsys, db, *exports)
    assert second["added"] == [] and second["events"] == 0
    check_same_as_raw(capsys, tmp_path, db, second["copies"])
    # the other way round: the exports first, then the raw logs, keeps the exports
    db2 = tmp_path / "exports_first.sqlite"
    add(capsys, db2, *exports)
    again = add(capsys, db2, *raw_logs)
    assert again["added"] == [] and len(again["copies"]) == 5
    n2, efc2, _ = flights_and_efc(capsys, db2)
    n1, efc1, _ = flights_and_efc(capsys, db)
    assert n2 == n1 and efc2 == pytest.approx(efc1, rel=1e-6)


@pytest.mark.slow
def test_the_dji_folder_on_dask_workers_counts_each_flight_once(capsys, tmp_path,
                                                                shared_data, raw_logs):
    db = tmp_path / "dask.sqlite"
    result = add(capsys, db, shared_data / DJI, extra=("--workers", "2"))
    check_same_as_raw(capsys, tmp_path, db, result["copies"])


def steps_as_runs(path):
    """The tester's steps as events: consecutive steps of one kind are one, with the charge
    its records move."""
    from dischargelab.io.cyclers import read_tester

    runs = []
    for step in read_tester(path).steps:
        if runs and runs[-1][0] == step["kind"]:
            runs[-1][1] += step["charge_Ah"]
        else:
            runs.append([step["kind"], step["charge_Ah"]])
    return runs


def check_events_are_the_steps(capsys, db, runs):
    events = [e for e in stored_events(capsys, db) if e["kind"] != "gap"]
    assert [e["kind"] for e in events] == [kind for kind, _ in runs]
    for e, (kind, moved) in zip(events, runs):
        if kind == "discharge" and moved > 0:
            assert e["discharged_Ah"] == pytest.approx(moved, rel=0.01)


@pytest.mark.parametrize("name", TESTER_FILES, ids=TESTER_IDS)
def test_a_tester_file_gets_the_testers_own_steps_as_events(capsys, tmp_path, shared_data,
                                                            name):
    db = tmp_path / "tester.sqlite"
    result = add(capsys, db, shared_data / name)
    assert len(result["added"]) == 1, result
    check_events_are_the_steps(capsys, db, steps_as_runs(shared_data / name))


def arbin_like_cell(path, capacity_Ah=3.179e-3, cycles=4, seed=7, noise_A=2e-6):
    """An Arbin CSV export of a small full cell at C/10 (0.32 mA): charge CC, CV, rest,
    discharge, rest; logged every second for a minute after each step starts, then every
    10 minutes (as a tester logging by voltage change does on a flat curve)."""
    rng = np.random.default_rng(seed)
    rate = capacity_Ah / 10.0
    rows, state = [], {"t": 0.0, "soc": 0.0, "qc": 0.0, "qd": 0.0}

    def ocv(soc):
        return 3.0 + 1.2 * soc - 0.15 * np.exp(-20.0 * soc)

    def step(number, cycle, current, duration, stop):
        elapsed = 0.0
        for _ in range(10_000):
            if elapsed >= duration:
                break
            dt = min(1.0 if elapsed < 60 else 600.0, duration - elapsed)
            elapsed += dt
            state["t"] += dt
            state["soc"] -= current * dt / 3600 / capacity_Ah
            state["qd" if current > 0 else "qc"] += abs(current) * dt / 3600
            v = ocv(min(max(state["soc"], 0.0), 1.0)) - 40.0 * current
            rows.append((len(rows) + 1, state["t"], elapsed, number, cycle,
                         -current + rng.normal(0, noise_A), v + rng.normal(0, 2e-4),
                         state["qc"], state["qd"]))
            if stop(state["soc"]):
                break

    never = lambda soc: False  # noqa: E731
    for cycle in range(1, cycles + 1):
        step(1, cycle, 0.0, 3600, never)
        step(2, cycle, -rate, 12 * 3600, lambda soc: soc >= 0.97)
        step(3, cycle, -0.05 * rate, 3 * 3600, lambda soc: soc >= 1.0)
        step(4, cycle, 0.0, 1800, never)
        step(5, cycle, rate, 12 * 3600, lambda soc: soc <= 0.0)
        step(6, cycle, 0.0, 1800, never)
    lines = ["Data_Point,Test_Time,Step_Time,Step_Index,Cycle_Index,Current,Voltage,"
             "Charge_Capacity,Discharge_Capacity"]
    lines += [",".join(f"{x:.9g}" for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_small_full_cell_in_milliamperes_is_not_split_into_noise(capsys, tmp_path):
    path = arbin_like_cell(tmp_path / "small_cell_Channel_1.csv")
    db = tmp_path / "small.sqlite"
    result = add(capsys, db, path)
    assert len(result["added"]) == 1, result
    runs = steps_as_runs(path)
    assert sum(1 for kind, _ in runs if kind == "discharge") == 4
    check_events_are_the_steps(capsys, db, runs)
    discharges = [e for e in stored_events(capsys, db) if e["kind"] == "discharge"]
    assert len(discharges) == 4
    for e in discharges:
        assert e["discharged_Ah"] == pytest.approx(3.179e-3, rel=0.02)


@pytest.mark.parametrize("capacity_Ah", [3.179e-3, 3.179e-5])
def test_a_small_full_cell_without_step_numbers_gives_its_loads_as_events(capsys, tmp_path,
                                                                          capacity_Ah):
    """The same small cell's records without the tester's step and cycle numbers (time,
    voltage and current in mA only, discharge positive), in mA and in uA: the discharges
    and charges come from the current, at the cell's own scale, and the sparse records of
    a long step are neither gaps nor noise events."""
    # the tester's current noise in proportion to its range (2 uA on 0.3 mA)
    tester = arbin_like_cell(tmp_path / "small_cell_Channel_1.csv", capacity_Ah=capacity_Ah,
                             noise_A=2e-6 * capacity_Ah / 3.179e-3)
    table = np.genfromtxt(tester, delimiter=",", names=True)
    path = tmp_path / "small_cell_records.csv"
    lines = ["time_s,voltage_V,current_mA"] + [
        f"{t:.1f},{v:.6f},{-1e3 * i:.9g}"
        for t, v, i in zip(table["Test_Time"], table["Voltage"], table["Current"])]
    path.write_text("\n".join(lines) + "\n")
    db = tmp_path / "records.sqlite"
    result = add(capsys, db, path)
    assert len(result["added"]) == 1, result
    events = stored_events(capsys, db)
    loads = [e["kind"] for e in events if e["kind"] in ("discharge", "charge")]
    assert loads == ["charge", "discharge"] * 4
    assert not [e for e in events if e["kind"] == "gap"]
    for e in (e for e in events if e["kind"] == "discharge"):
        assert e["discharged_Ah"] == pytest.approx(capacity_Ah, rel=0.02)


def telemetry_pack(capsys, tmp_path, shared_data):
    """A pack of two MAVLink telemetry logs: its logbook and its `logbook packs` row."""
    db = tmp_path / "lb.sqlite"
    tlogs = shared_data / "flight_logs" / "mavlink_tlog"
    add(capsys, db, tlogs / "thayer_rural.tlog", tlogs / "olivieri_20211202-132614.tlog")
    code, out, err = run(capsys, "logbook", "packs", "--db", db, "--json")
    assert code == 0, err
    return db, json.loads(out)["rows"][0]


def test_one_efc_rendering_in_every_view(capsys, tmp_path, shared_data):
    """Two telemetry logs of a pack: the EFC of `logbook packs` is the one the health
    lines give for capacity today (it read "EFC 0" beside "0.5" in the list)."""
    db, row = telemetry_pack(capsys, tmp_path, shared_data)
    code, text, err = run(capsys, "logbook", "health", "P", "--db", db)
    assert code == 0, err
    shown = row["text"]["efc"]
    assert 0 < row["efc"] < 5
    assert f"capacity today (EFC {shown})" in text


def test_flight_time_carries_the_capacity_band(capsys, tmp_path, shared_data):
    """A pack known only from two telemetry logs: its capacity today is known to about
    +-50 %, and the flight time's band says so (it gave +-3 % from the model error
    alone, as if the capacity were certain)."""
    db, row = telemetry_pack(capsys, tmp_path, shared_data)
    lo_c, hi_c = row["capacity_interval95"]
    code, out, err = run(capsys, "endurance", "--pack", "P", "multirotor-hover", "--db", db,
                         "--json")
    assert code == 0, err
    doc = json.loads(out)
    band = doc["uncertainty"]["endurance_s"]
    lo_t, hi_t = band["low"], band["high"]
    # the flight runs to the reserve: its time scales with the capacity
    assert hi_t / lo_t >= 0.7 * hi_c / lo_c
    assert lo_t < doc["flight_time_s"] < hi_t
    assert "parameters" in doc["uncertainty"]["interval_includes"]


def test_capacity_today_holds_the_latest_test(capsys, tmp_path):
    """The example set's three capacity tests of one ageing cell (1, 330 and 664 cycles,
    all at 3 A): the last one, 33 % below the first, is a capacity test like the others
    (it was taken for a mission at a high rate), and capacity today's band holds it."""
    from dischargelab.examples import copy_examples

    copy_examples(tmp_path / "ex")
    db = tmp_path / "lb.sqlite"
    add(capsys, db, tmp_path / "ex" / "ageing")
    h = health(capsys, db)
    last = max((e for e in h["events"] if e.get("capacity_Ah")), key=lambda e: e["efc"])
    assert last["source"] in [s["source"] for s in h["capacity_from"]]
    lo, hi = h["capacity_now_interval95"]
    assert lo <= last["capacity_Ah"] <= hi
    assert abs(h["capacity_now_Ah"] / last["capacity_Ah"] - 1) < 0.05
