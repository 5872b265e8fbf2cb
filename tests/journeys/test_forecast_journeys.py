"""A new user's fresh packs: no end of life without a measured fade, and the health bar and
the forecast from one result. Real shared tester files and flights through the real CLI."""

from __future__ import annotations

import json
import re

import pytest

from cli_run import run
from shared_files import TESTER_FILES, TESTER_IDS

pytest.importorskip("sqlalchemy")


def fresh_pack(capsys, tmp_path, path):
    """Add ``path`` to a fresh logbook as pack P: (health JSON, health text, packs row)."""
    db = tmp_path / "fresh.sqlite"
    code, _, err = run(capsys, "logbook", "add", path, "--pack", "P", "--db", db)
    assert code == 0, err
    code, out, err = run(capsys, "logbook", "health", "P", "--db", db, "--json")
    assert code == 0, err
    health = json.loads(out)
    code, text, err = run(capsys, "logbook", "health", "P", "--db", db)
    assert code == 0, err
    code, out, err = run(capsys, "logbook", "packs", "--db", db, "--json")
    assert code == 0, err
    return health, text, json.loads(out)["rows"][0]


def check_no_end_of_life_soon(health, text, row):
    """No end of life inside 5x today's EFC; the words say no fade is measured yet and at
    about which EFC one could be; the list and the page read the same forecast."""
    fc, efc = health["forecast"], health["efc_now"]
    line = next(t for t in text.splitlines() if t.startswith("end of life"))
    assert "no fade measured yet" in line, line
    assert row["eol_efc"] is None and row["eol_efc_interval95"] in (None, [None, None])
    if fc is None:
        return
    assert fc["status"] == "no fade" and fc["eol_efc"] is None
    assert fc["eol_efc_interval95"] == [None, None]
    assert not fc["fade"]["measured"]
    need = fc["fade"]["efc_needed"]
    assert need is not None and need > 0
    if need > efc:
        assert re.search(rf"would show at about {need:.0f} EFC", line), line
    else:
        assert "would show by now" in line, line
    assert fc["message"] in line
    # the band drawn ahead of today is the trend the health bar reads, with no futures
    assert max(fc["band"]["efc"]) <= fc["last_efc"] + 1e-9


@pytest.mark.parametrize("name", TESTER_FILES, ids=TESTER_IDS)
def test_a_fresh_tester_file_gets_no_end_of_life_without_a_measured_fade(
        capsys, tmp_path, shared_data, name):
    health, text, row = fresh_pack(capsys, tmp_path, shared_data / name)
    check_no_end_of_life_soon(health, text, row)
    # the fleet report reads the same forecast and says why there is no end of life
    code, out, err = run(capsys, "logbook", "report", "--fleet", "--json", "--db",
                         tmp_path / "fresh.sqlite", "-o", tmp_path / "fleet.html")
    assert code == 0, err
    fleet = json.loads(out)["packs"][0]
    assert fleet["eol_efc"] is None and fleet["forecast_status"] == "no fade"
    assert fleet["forecast_note"].startswith("no fade measured yet")
    plot = tmp_path / "health.png"
    code, out, err = run(capsys, "logbook", "health", "P", "--db", tmp_path / "fresh.sqlite",
                         "--plot", plot)
    assert code == 0 and plot.stat().st_size > 10_000, err


def test_a_fresh_flight_set_gets_no_end_of_life_without_a_measured_fade(
        capsys, tmp_path, shared_data):
    health, text, row = fresh_pack(capsys, tmp_path, shared_data / "dji_m100_flights")
    assert health["forecast"] is not None and health["efc_now"] > 3
    check_no_end_of_life_soon(health, text, row)


def test_an_ageing_cell_gets_its_end_of_life_once_the_fade_is_measured(
        capsys, tmp_path, shared_data):
    """Cell C up to cycle 220: the fade is measured well outside the noise, the end of life
    is dated, lies below the health today, and the futures start from the trend that gives
    the health bar."""
    db = tmp_path / "c.sqlite"
    folder = shared_data / "samsung30q_ageing_cellC"
    files = [p for p in sorted(folder.glob("DischargeCycle*.txt"))
             if int(p.stem.replace("DischargeCycle", "")) <= 220]
    assert run(capsys, "logbook", "add", *files, "--pack", "C", "--db", db)[0] == 0
    code, out, _ = run(capsys, "logbook", "health", "C", "--db", db, "--json")
    health = json.loads(out)
    fc = health["forecast"]
    assert fc["status"] == "dated" and fc["fade"]["strong"]
    assert fc["fade"]["rate_interval95"][0] > 0
    assert fc["eol_efc"] > health["efc_now"]
    # the futures start where the capacity trend is at the last estimate
    band = fc["band"]
    at_last = band["efc"].index(max(e for e in band["efc"] if e <= fc["last_efc"]))
    trend = health["trend"]["capacity"]
    assert band["capacity_Ah"][at_last] == pytest.approx(trend["value"][-1], rel=2e-3)
    fraction = health["capacity_now_Ah"] / health["reference_capacity_Ah"]
    assert fraction > fc["eol"]
    code, text, _ = run(capsys, "logbook", "health", "C", "--db", db)
    assert f"forecast at {fc['eol_efc']:.0f} EFC" in text


@pytest.mark.slow
def test_the_pack_page_of_a_fresh_tester_file_says_no_fade_next_to_its_health_bar(
        capsys, tmp_path, shared_data):
    """TestFile.nda (1.7 EFC) on the pack page: a 100 % health bar and, where the end of life
    would be, "no fade measured yet" with the EFC a typical fade needs: both from the same
    stored health."""
    pytest.importorskip("starlette")
    from web_helpers import Browser, ServerProcess

    health, _, row = fresh_pack(capsys, tmp_path, shared_data / "cyclers/neware/TestFile.nda")
    need = health["forecast"]["fade"]["efc_needed"]
    server = ServerProcess(["serve", "--db", str(tmp_path / "fresh.sqlite"), "--port", "0"],
                           cwd=tmp_path)
    browser = Browser()
    try:
        browser.get(server.base + "/packs/P")
        browser.wait_for("window.__pack && window.__pack.loaded", what="the pack page")
        shown = browser.js("return window.__pack.data.health.forecast;")
        assert shown["status"] == "no fade" and shown["eol_efc"] is None
        assert browser.text("m-health") == f"Ah ({round(100 * row['capacity_fraction'])} %)"
        assert browser.text("m-eol") == "-"     # the pages' no-value mark (formatting.MISSING)
        assert browser.text("m-eol-iv") == ("no fade measured yet; a typical fade would show "
                                            f"at about {need:.0f} EFC")
        assert "End of life: no fade measured yet" in browser.text("health-note")
    finally:
        browser.quit()
        server.stop()
