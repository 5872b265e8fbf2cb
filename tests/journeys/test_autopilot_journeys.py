"""Journeys: the autopilot files a user writes from a logbook pack or a preset.

The command line runs as a user runs it (a subprocess, the shared data): reading a pack's
model for its autopilot settings changes nothing stored in the logbook, the settings say
which load they were computed at, and the on-board script from a preset runs in Lua 5.3.
"""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
from pathlib import Path

import pytest

import dischargelab as dl
from cli_run import command as cli
from cli_run import stored_rows

CELL_C = "samsung30q_ageing_cellC"
FLIGHTS = "flight_logs/ina3221_fpv_4s"






def test_autopilot_params_from_a_pack_leaves_the_logbook_unchanged(tmp_path, shared_data):
    db = tmp_path / "lb.sqlite"
    files = [shared_data / CELL_C / f"DischargeCycle{n:03d}.txt" for n in (1, 660, 664)]
    cli("logbook", "add", *files, "--pack", "C", "--chemistry", "li-ion", "--cells", "1",
        "--db", db)
    before = stored_rows(db)
    out = json.loads(cli("autopilot-params", "--pack", "C", "--db", db, "--firmware",
                         "ardupilot", "--cutoff", "2.5", "--json").stdout)
    assert stored_rows(db) == before                    # no model, no figure stored
    derivation = out["derivation"]
    assert derivation["BATT_CAPACITY"].startswith("today's capacity estimate")
    assert "1C of today's capacity estimate" in " ".join(out["notes"])   # no flights logged
    assert 0 < out["parameters"]["BATT_SOC1_C3"] <= 0.5
    assert "worst difference" in derivation["BATT_SOC1_C1"]


def test_a_flying_pack_reserves_at_its_flights_current(tmp_path, shared_data):
    db = tmp_path / "lb.sqlite"
    flights = sorted((shared_data / FLIGHTS).glob("*.csv"))
    cli("logbook", "add", *flights, "--pack", "fpv", "--db", db)
    before = stored_rows(db)
    with dl.Logbook(db) as lb:
        typical, count = lb.flight_current("fpv")
    target = tmp_path / "fpv.param"
    cli("autopilot-params", "--pack", "fpv", "--db", db, "--firmware", "ardupilot",
        "-o", target)
    assert stored_rows(db) == before
    text = target.read_text()
    amps = f"{typical:.3g} A"
    assert f"load {amps}: the median mean current of the pack's {count} logged flight" in text
    assert f"when 120 s of flight at {amps} remain" in text
    assert all(len(line) <= 100 for line in text.splitlines())
    assert "BATT_CAPACITY [mAh]: today's capacity estimate" in text


def test_autopilot_script_from_a_preset_runs_in_lua(tmp_path):
    lua = shutil.which("lua5.3")
    if lua is None:
        if os.environ.get("CI"):
            pytest.fail("lua5.3 not found (make lua installs it)")
        pytest.skip("lua5.3 not found (make lua installs it)")
    from ardupilot_replay import replay
    from dischargelab.onboard import flight_samples
    from dischargelab.simulate import simulate_current

    target = tmp_path / "battery.lua"
    cli("autopilot-script", "nanotech-1700-2s", "--cells", "4", "--cutoff", "3.3",
        "--reserve-s", "90", "-o", target)
    text = target.read_text()
    assert "SCR_ENABLE = 1" in text and "4S1P" in text
    pack = dl.load_battery("nanotech-1700-2s").with_pack(4)
    sim = simulate_current(pack, 5.1, cutoff_cell_V=3.3)     # 3C to the cutoff
    rep = replay(text, flight_samples(sim, rest_s=5.0))
    total = sim.time_to_cutoff_s
    times, trem = rep.series("DL_TREM")
    half = trem[abs(times - 5.0 - 0.5 * total).argmin()]
    assert abs(half - 0.5 * total) / total < 0.02
    assert any("90 s" in t[2] or "s of flight left" in t[2] for t in rep.texts)
    assert rep.max_instructions <= 10_000 and rep.heap_kb <= 40.0


def need_lua() -> None:
    if shutil.which("lua5.3") is None:
        if os.environ.get("CI"):
            pytest.fail("lua5.3 not found (make lua installs it)")
        pytest.skip("lua5.3 not found (make lua installs it)")


@pytest.mark.slow
def test_autopilot_script_from_a_fitted_battery_file_runs_in_lua(tmp_path):
    """Fit a cell from the bundled 1C discharge, write its script for a 4S2P pack, fly it."""
    need_lua()
    from ardupilot_replay import replay
    from dischargelab.onboard import flight_samples
    from dischargelab.simulate import simulate_current

    data = Path(dl.__file__).parent / "data" / "samsung30q"
    cell = tmp_path / "cell.json"
    cli("fit", data / "Q30_S001_1C.csv", "--columns",
        "time_s=0,current_A=1,voltage_V=2,temperature_C=4", "-o", cell)
    target = tmp_path / "q30.lua"
    shown = cli("autopilot-script", cell, "--cells", "4", "--parallel", "2", "--cutoff", "3.0",
                "-o", target).stdout
    assert "4S2P" in shown and "script written to" in shown
    pack = dl.load_battery(cell).with_pack(4, 2)
    sim = simulate_current(pack, 2.0 * pack.rated_capacity_Ah, cutoff_cell_V=3.0)
    rep = replay(target.read_text(), flight_samples(sim, rest_s=5.0))
    total = sim.time_to_cutoff_s
    times, trem = rep.series("DL_TREM")
    for f in (0.25, 0.5, 0.75, 0.9):
        sent = trem[abs(times - 5.0 - f * total).argmin()]
        assert abs(sent - (1 - f) * total) / total < 0.02, (f, sent, total)
    assert rep.max_instructions <= 10_000 and rep.heap_kb <= 40.0


def test_autopilot_script_from_a_pack_leaves_the_logbook_unchanged(tmp_path, shared_data):
    db = tmp_path / "lb.sqlite"
    files = [shared_data / CELL_C / f"DischargeCycle{n:03d}.txt" for n in (1, 660, 664)]
    cli("logbook", "add", *files, "--pack", "C", "--chemistry", "li-ion", "--cells", "1",
        "--db", db)
    before = stored_rows(db)
    target = tmp_path / "C.lua"
    cli("autopilot-script", "--pack", "C", "--db", db, "--cells", "4", "--cutoff", "3.0",
        "-o", target)
    assert stored_rows(db) == before
    header = target.read_text().split("\nlocal ", 1)[0]
    assert "health today" in header and "4S1P" in header
    assert all(len(line) <= 100 for line in header.splitlines())


def test_the_pack_page_offers_the_parameters_and_the_script_without_writing(tmp_path,
                                                                            shared_data):
    pytest.importorskip("starlette")
    from web_helpers import ServerProcess

    db = tmp_path / "lb.sqlite"
    flights = sorted((shared_data / FLIGHTS).glob("*.csv"))
    cli("logbook", "add", *flights, "--pack", "fpv", "--chemistry", "lipo", "--db", db)
    server = ServerProcess(["serve", "--db", str(db), "--port", "0"], cwd=tmp_path)
    try:
        server.get_json("/api/packs/fpv")               # the stored figures, as a visit reads
        before = stored_rows(db)
        status, lua = server.request("GET", "/api/packs/fpv/autopilot/ardupilot.lua",
                                     timeout_s=300)
        assert status == 200 and 'gcs:send_named_float("DL_TREM"' in lua
        status, param = server.request("GET", "/api/packs/fpv/autopilot/ardupilot.param",
                                       timeout_s=300)
        assert status == 200 and "BATT_CAPACITY" in param and "logged flight" in param
        status, body = server.request("GET", "/api/packs/fpv/autopilot/px4.exe")
        assert status == 404 and "ardupilot.lua" in str(body)
        assert stored_rows(db) == before                # nothing fitted or stored
    finally:
        server.stop()
    page = (Path(dl.__file__).parent / "web" / "static" / "pack.html").read_text()
    assert 'id="dl-lua"' in page and 'id="dl-param"' in page


def test_endurance_from_a_pack_leaves_the_logbook_unchanged(tmp_path):
    """`endurance --pack` on a pack with capacity tests, no model yet and figures from an
    older release: nothing stored (the stale figures were redone and stored), and the second
    run answers as the first (the first fitted and stored a model, and
    the second, flying the stored model with figures redone around it, differed by 2 %)."""
    from dischargelab.examples import copy_examples

    copy_examples(tmp_path / "ex")
    db = tmp_path / "lb.sqlite"
    cli("logbook", "add", tmp_path / "ex" / "ageing", "--pack", "C", "--db", db)
    with sqlite3.connect(db) as conn:  # figures stored by an older release: stale
        conn.execute("UPDATE pack_figures SET figures_version = '1/0.0.0'")
    before = stored_rows(db)
    runs = [json.loads(cli("endurance", "--pack", "C", "multirotor-hover", "--cells", "4",
                           "--db", db, "--json").stdout) for _ in range(2)]
    assert stored_rows(db) == before
    assert runs[0]["flight_time_s"] == runs[1]["flight_time_s"]
    assert runs[0]["uncertainty"]["endurance_s"] == runs[1]["uncertainty"]["endurance_s"]
