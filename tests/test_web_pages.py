"""The pack list and pack page in headless Chromium, on a real logbook database.

A SQLite logbook is built in the test's folder from cell C's ageing files (read in place
from ../shared/data) and a synthetic 2S discharge made here; ``dischargelab serve --db``
runs on it in a subprocess (127.0.0.1, a free port, stopped by its process id). Every
number a page shows is compared with what :class:`dischargelab.Logbook` reads from the
same database, formatted as the page formats it.
"""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sqlalchemy")
pytest.importorskip("starlette")

import dischargelab as dl
from dischargelab.engine import Step
from dischargelab.formatting import MISSING, interval, number, pack_text
from dischargelab.simulate import simulate
from web_helpers import CSP_PROBE, Browser, ServerProcess, multipart, plot_state

CELL_C = "samsung30q_ageing_cellC"
#: Cycles of cell C in the logbook (cycle 300 was overcharged; the rest span its fade).
CYCLES = (1, 100, 200, 300, 400, 500)
#: The cell C file uploaded through the page.
UPLOADED_CYCLE = 600
#: --max-upload of the test servers [MB] (a cell C file is ~200 kB).
MAX_UPLOAD_MB = 1.0
MISSION = "paper-table5"


def cell_c(shared_data: Path, cycle: int) -> Path:
    return shared_data / CELL_C / f"DischargeCycle{cycle:03d}.txt"


def synthetic_discharge(path: Path, capacity_scale: float = 1.0) -> Path:
    """A 2S LiPo bench log (time_s, voltage_V, current_A): 60 s at rest, then 1.1 A to
    3.0 V per cell, simulated on the zippy-1100-2s preset, sampled every 2 s, its time
    axis (so its charge) scaled by ``capacity_scale``."""
    bat = dl.load("zippy-1100-2s")
    sim = simulate(bat, [Step("rest", 0.0, 60.0), Step("current", 1.1)], cutoff_cell_V=3.0,
                   points_per_step=400)
    t = np.arange(0.0, float(sim.time_s[-1]), 2.0)
    v = np.interp(t, sim.time_s, sim.voltage_V)
    i = np.interp(t, sim.time_s, sim.current_A)
    rows = [f"{a * capacity_scale:.1f},{b:.4f},{c:.3f}" for a, b, c in zip(t, v, i)]
    path.write_text("time_s,voltage_V,current_A\n" + "\n".join(rows) + "\n")
    return path


def num(value, digits: int) -> str:
    """What the pages write for a number: the one formatter's (DL.num is its twin)."""
    return number(value, digits)


def list_row(row: dict) -> list[str]:
    """A row of the pack list as every view writes it, from ``Logbook.packs()``."""
    text = pack_text(row)
    return [row["name"], str(row["events"]), text["efc"], text["capacity_Ah"],
            text["capacity_fraction"], text["resistance_ohm"], text["eol_efc"],
            text["eol_efc_interval95"]]


def content(path: Path) -> str:
    """Digest of everything stored in a SQLite database (its write-ahead log included)."""
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        return hashlib.sha256("\n".join(conn.iterdump()).encode()).hexdigest()
    finally:
        conn.close()


@pytest.fixture(scope="module")
def template_db(tmp_path_factory, shared_data) -> Path:
    """The logbook every test copies: pack 'cell C' (six cycles), pack 'zippy 2S' (one
    synthetic discharge); no model fitted."""
    folder = tmp_path_factory.mktemp("logbook")
    path = folder / "template.sqlite"
    with dl.Logbook(str(path)) as lb:
        added = lb.add([cell_c(shared_data, c) for c in CYCLES], pack="cell C")
        assert added.events == len(CYCLES) and not added.rejected
        added = lb.add([synthetic_discharge(folder / "zippy-2s-001.csv")], pack="zippy 2S")
        assert added.events == 1 and not added.rejected
    return path


@pytest.fixture
def db(template_db, tmp_path) -> Path:
    path = tmp_path / "logbook.sqlite"
    shutil.copyfile(template_db, path)
    return path


@pytest.fixture
def server(db, tmp_path):
    srv = ServerProcess(["serve", "--db", str(db), "--port", "0",
                         "--max-upload", str(MAX_UPLOAD_MB)], cwd=tmp_path)
    yield srv
    srv.stop()


@pytest.fixture
def browser():
    b = Browser()
    yield b
    b.quit()


def page_rows(browser) -> list[list[str]]:
    return browser.js("return [...document.querySelectorAll('#packs tbody tr')].map("
                      "r => [...r.cells].map(c => c.textContent.trim()));")


def open_list(browser, server) -> list[list[str]]:
    """The list's rows once every pack's stored figures are current (the server recomputes
    stale ones in the background and the page looks again until then)."""
    browser.get(server.base + "/")
    browser.wait_for("window.__packs && window.__packs.loaded && "
                     "!window.__packs.rows.some(r => r.recomputing)", 120, "the pack list")
    return page_rows(browser)


def test_pack_list_shows_the_databases_numbers(server, browser, db):
    rows = open_list(browser, server)
    with dl.Logbook(str(db)) as lb:
        expected = lb.packs().to_dict()["rows"]
    assert [r["name"] for r in expected] == ["cell C", "zippy 2S"]
    assert rows == [list_row(r) for r in expected]
    assert expected[0]["eol_efc"] is not None and expected[1]["eol_efc"] is None
    assert rows[0][2] != MISSING and rows[1][6] == MISSING
    assert browser.text("count") == "2 packs"
    fill = browser.js("const f = document.querySelector('#packs .bar > span'); return f."
                      "getBoundingClientRect().width / f.parentNode.getBoundingClientRect().width;")
    assert fill == pytest.approx(round(expected[0]["capacity_fraction"] * 100) / 100, abs=0.005)
    href = browser.js("return document.querySelector('#packs tbody a').getAttribute('href');")
    assert href == "/packs/cell%20C"


@pytest.mark.slow
def test_pack_page_reads_without_writing_then_refits_and_flies(server, browser, db):
    before = content(db)
    browser.get(server.base + "/packs/cell%20C")
    browser.wait_for("window.__pack && window.__pack.loaded", what="the pack page")
    with dl.Logbook(str(db)) as lb:
        pack = lb.pack("cell C")
        summary, health = pack.to_dict(), lb.health("cell C").to_dict()
        assert not pack.fitted
    # the numbers stored, as the page formats them
    assert browser.text("m-capacity") == num(summary["capacity_Ah"], 3)
    fraction = summary["capacity_Ah"] / summary["reference_capacity_Ah"]
    assert browser.text("m-health") == f"Ah ({num(fraction * 100, 0)} %)"
    assert browser.text("m-reference") == num(summary["reference_capacity_Ah"], 3)
    assert browser.text("m-efc") == num(summary["efc"], 1)
    assert browser.text("m-resistance") == num(summary["resistance_ohm"] * 1000, 1)
    fc = health["forecast"]
    assert browser.text("m-eol") == num(fc["eol_efc"], 0)
    lo, hi = fc["eol_efc_interval95"]
    assert browser.text("m-eol-iv") == f"EFC (95 %: {interval([lo, hi], 0)})"
    assert browser.text("pack-summary") == f"{len(CYCLES)} events"
    events = browser.js("return [...document.querySelectorAll('#events tbody tr')].map("
                        "r => [...r.cells].map(c => c.textContent));")
    assert [(e[0], e[2], e[4], e[7]) for e in events] == [
        (e["source"], e["kind"], num(e["capacity_Ah"], 3), num(e["efc"], 1))
        for e in reversed(health["events"])]
    assert [e[0] for e in events[::-1]] == [f"DischargeCycle{c:03d}.txt" for c in CYCLES]
    band = browser.js("return window.__pack.data.health.forecast.band;")
    assert len(band["efc"]) == len(band["lo"]) == len(band["hi"]) > 10
    # no model stored: the page says so, flying is off, and the GET wrote nothing
    assert browser.js("return window.__pack.data.model;") is None
    assert browser.js("return window.__pack.data.model_note;") == "no model fitted yet — Refit"
    assert browser.js("return document.getElementById('fly').disabled;")
    status, body = server.request("POST", "/api/packs/cell%20C/endurance",
                                  b'{"mission": "%s"}' % MISSION.encode(),
                                  {"Content-Type": "application/json"})
    assert status == 409 and "no fitted model yet" in body["error"]
    assert content(db) == before
    with dl.Logbook(str(db)) as lb:
        assert not lb.pack("cell C").fitted

    # the refit is the explicit POST; then the curves and the endurance use the stored model
    browser.driver.find_element("id", "refit").click()
    browser.wait_for("window.__pack.data.model && window.__pack.data.model.curves", 120,
                     "the refitted model")
    assert browser.text("fit-result") == "model refitted"
    assert content(db) != before
    with dl.Logbook(str(db)) as lb:
        assert lb.pack("cell C").fitted
        expected = dl.endurance(lb.pack("cell C"), MISSION).to_dict()
    model = browser.js("return window.__pack.data.model;")
    assert [c["c_rate"] for c in model["curves"]] == [0.5, 1.0, 2.0]
    assert "scaled to its health today" in browser.text("model-note")
    assert browser.js("return document.getElementById('mission').value;") == MISSION
    browser.driver.find_element("id", "fly").click()
    result = browser.wait_for("window.__endurance", 60, "the endurance result")
    assert result["flight_time_s"] == pytest.approx(expected["flight_time_s"], rel=1e-9)
    assert any("scaled to its health today" in n for n in result["notes"])
    assert result["source"] == MISSION                  # a name, not a path on the server
    # the paper's 50 A take-off on 4S1P of these 3 Ah cells: the page says it cannot fly
    cannot = expected["cannot_deliver"]
    assert result["cannot_deliver"] == cannot and cannot["phase"] == "takeoff"
    assert cannot["message"].startswith("the pack cannot deliver the 50 A of 'takeoff'")
    row = browser.js("const r = document.querySelector('#endurance-result tr.cannot');"
                     "return r && [r.cells[0].textContent, r.cells[1].textContent];")
    assert row == ["Cannot fly", cannot["message"]]


@pytest.mark.slow
def test_uploads_through_the_form_and_the_api_appear_in_the_list(server, browser, db,
                                                                  shared_data, tmp_path):
    open_list(browser, server)
    uploaded = cell_c(shared_data, UPLOADED_CYCLE)
    browser.driver.find_element("id", "upload-pack").send_keys("cell C")
    browser.driver.find_element("id", "upload-file").send_keys(str(uploaded))
    browser.driver.find_element("id", "upload-button").click()
    browser.wait_for("window.__packs.rows.some(r => r.name === 'cell C' && r.events === "
                     f"{len(CYCLES) + 1} && !r.recomputing)", 120,
                     "the uploaded event in the list, its figures recomputed")
    assert browser.text("upload-result") == f"{uploaded.name}: added, 1 events"
    with dl.Logbook(str(db)) as lb:
        expected = lb.packs().to_dict()["rows"]
        sources = [e["source"] for e in lb.health("cell C").to_dict()["events"]]
    assert page_rows(browser) == [list_row(r) for r in expected]
    assert uploaded.name in sources

    # the API: multipart `file` and `pack`, a new pack; the page lists it on reload
    log = synthetic_discharge(tmp_path / "spare-001.csv", capacity_scale=0.97)
    body, ctype = multipart({"pack": "zippy spare"}, {"file": (log.name, log.read_bytes())})
    status, data = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
    assert status == 200 and data["added"] == [log.name] and data["events"] == 1
    status, data = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
    assert status == 200 and data["skipped"] == [log.name] and data["added"] == []
    rows = open_list(browser, server)
    with dl.Logbook(str(db)) as lb:
        expected = lb.packs().to_dict()["rows"]
    assert [r["name"] for r in expected] == ["cell C", "zippy 2S", "zippy spare"]
    assert rows == [list_row(r) for r in expected]


def strings(value):
    """Every string in a JSON answer (keys and values)."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield k
            yield from strings(v)
    elif isinstance(value, list):
        for v in value:
            yield from strings(v)
    elif isinstance(value, str):
        yield value


def test_answers_carry_what_the_page_shows_and_no_server_path(server, db):
    detail = server.get_json("/api/packs/cell%20C")
    assert set(detail) == {"name", "summary", "health", "model", "model_note", "recomputing",
                           "error"}
    assert detail["recomputing"] is False and detail["error"] is None
    assert [e["source"] for e in detail["health"]["events"]] == [
        f"DischargeCycle{c:03d}.txt" for c in CYCLES]
    for answer in (detail, server.get_json("/api/packs"), server.get_json("/api/missions"),
                   server.get_json("/api/live")):
        for text in strings(answer):
            assert str(db.parent) not in text and not text.startswith("/"), text


def test_bad_requests_get_a_clear_4xx_and_the_server_stays_up(server, db, tmp_path):
    packs = server.get_json("/api/packs")
    before = content(db)

    def refused(method, path, body=None, headers=None, status=400, words=""):
        got, data = server.request(method, path, body, headers)
        assert got == status, (path, got, data)
        assert isinstance(data, dict) and set(data) == {"error"}, data
        line = data["error"]
        assert line and "\n" not in line and "Traceback" not in line and words in line, line
        assert server.alive and server.get_json("/api/packs") == packs
        return line

    garbage = bytes(range(256)) * 64
    body, ctype = multipart({"pack": "cell C"}, {"file": ("garbage.bin", garbage)})
    line = refused("POST", "/api/upload", body, {"Content-Type": ctype}, 422, "garbage.bin: ")
    assert len(line) < 300
    text = b"time_s;volts\nnot,a,log\n" * 10
    body, ctype = multipart({"pack": "cell C"}, {"file": ("notes.csv", text)})
    refused("POST", "/api/upload", body, {"Content-Type": ctype}, 422, "notes.csv: ")
    big = b"0" * int((MAX_UPLOAD_MB + 0.1) * 1024 * 1024)
    body, ctype = multipart({"pack": "cell C"}, {"file": ("big.csv", big)})
    refused("POST", "/api/upload", body, {"Content-Type": ctype}, 413, "over the limit")
    refused("POST", "/api/upload", b"x=1", {"Content-Type": "application/x-www-form-urlencoded"},
            400, "multipart/form-data")
    for path in ("/static/../../../etc/passwd", "/static/%2e%2e%2f%2e%2e%2fetc%2fpasswd",
                 "/static/%252e%252e%252fpyproject.toml", "/packs/..%2f..%2fetc%2fpasswd",
                 "/api/packs/%2e%2e%2fcell%20C", "/api/packs/%252e%252e"):
        refused("GET", path, words="path")
    refused("GET", "/api/packs/no%20such%20pack", status=404,
            words="no pack named 'no such pack' in the logbook")
    refused("POST", "/api/packs/no%20such%20pack/fit", b"{}",
            {"Content-Type": "application/json"}, 404, "no pack named")
    refused("POST", "/api/packs/cell%20C/endurance", b'{"mission": "to-the-moon"}',
            {"Content-Type": "application/json"}, 400, "unknown mission 'to-the-moon'")
    assert content(db) == before                  # nothing refused reached the database


@pytest.mark.slow
def test_unknown_pack_and_garbage_upload_on_the_pages(server, browser, tmp_path):
    browser.get(server.base + "/packs/no%20such%20pack")
    browser.wait_for("window.__pack && window.__pack.loaded", what="the pack page")
    assert browser.js("return window.__pack.status;") == 404
    assert browser.text("message") == "no pack named 'no such pack' in the logbook"
    open_list(browser, server)
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(bytes(range(256)) * 8)
    browser.driver.find_element("id", "upload-pack").send_keys("cell C")
    browser.driver.find_element("id", "upload-file").send_keys(str(garbage))
    browser.driver.find_element("id", "upload-button").click()
    message = browser.wait_for("document.getElementById('message').textContent", 30,
                               "the refusal")
    assert message.startswith("garbage.bin: ") and "\n" not in message
    assert server.alive and len(server.get_json("/api/packs")["rows"]) == 2


def test_pack_page_plots_zoom_pan_and_read_out(server, browser, db):
    """The capacity plot (uPlot): hovering a point reads its EFC and capacity; a drag zooms
    in, the y axis fits what is left; the wheel zooms, shift + drag pans, a double click
    shows everything again; the Content-Security-Policy reports nothing."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    from selenium.webdriver.common.keys import Keys

    browser.driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument",
                                   {"source": CSP_PROBE})
    browser.get(server.base + "/packs/cell%20C")
    browser.wait_for("window.__pack && window.__pack.loaded", what="the pack page")
    with dl.Logbook(str(db)) as lb:
        events = [e for e in lb.health("cell C").to_dict()["events"] if e["capacity_Ah"]]
    over = browser.driver.find_element("css selector", "#plot-capacity .u-over")
    full = plot_state(browser, "plot-capacity")
    assert full["zoomed"] is False
    efc = [e["efc"] for e in events]
    assert full["x"][0] < min(efc) < max(efc) < full["x"][1]
    width, height = full["over"]
    capacity = full["labels"].index("full")  # the capacity tests' series, named by kind

    def at(x_value, y_value) -> tuple[int, int]:
        """Offset from the plot area's centre of a data point [CSS px]."""
        px, py = browser.js("const u = document.getElementById('plot-capacity').__dlPlot.u; "
                            "return [u.valToPos(arguments[0], 'x'), "
                            "u.valToPos(arguments[1], 'y')];", x_value, y_value)
        return round(px - width / 2), round(py - height / 2)

    # before any hover the legend reads each series' last value; hovering reads the point
    # under the cursor
    read_legend = ("[...document.querySelectorAll('#plot-capacity .u-legend .u-series "
                   ".u-value')].map(v => v.textContent)")
    idle = browser.js(f"return {read_legend};")
    last_full = [e for e in events if e["kind"] == "full" and not e.get("outlier")][-1]
    assert float(idle[capacity]) == pytest.approx(last_full["capacity_Ah"], abs=0.001)
    event = events[2]
    ActionChains(browser.driver).move_to_element_with_offset(over, *at(
        event["efc"], event["capacity_Ah"])).perform()
    legend = browser.wait_for(f"(() => {{ const l = {read_legend}; return Math.abs("
                              f"parseFloat(l[{capacity}]) - {event['capacity_Ah']}) < 0.001 "
                              f"&& l; }})()", 5, "a read-out")
    pixel = (full["x"][1] - full["x"][0]) / width        # the cursor moves by whole pixels
    assert float(legend[0]) == pytest.approx(event["efc"], abs=max(0.5, 1.5 * pixel))

    # drag across the first half: zoom in, and the y axis fits the points left in view
    ActionChains(browser.driver).move_to_element_with_offset(over, -width // 2 + 5, 0) \
        .click_and_hold().move_by_offset(width // 2 - 10, 0).release().perform()
    zoomed = plot_state(browser, "plot-capacity")
    assert zoomed["zoomed"]
    assert zoomed["x"][1] - zoomed["x"][0] < 0.6 * (full["x"][1] - full["x"][0])
    shown = [e["capacity_Ah"] for e in events
             if zoomed["x"][0] <= e["efc"] <= zoomed["x"][1]]
    assert shown and len(shown) < len(events)
    assert zoomed["y"][0] <= min(shown) and max(shown) <= zoomed["y"][1]

    # shift + drag pans (same span, moved), the wheel zooms in at the cursor
    span = zoomed["x"][1] - zoomed["x"][0]
    ActionChains(browser.driver).move_to_element_with_offset(over, 0, 0).key_down(Keys.SHIFT) \
        .click_and_hold().move_by_offset(-width // 4, 0).release().key_up(Keys.SHIFT).perform()
    panned = plot_state(browser, "plot-capacity")
    assert panned["x"][1] - panned["x"][0] == pytest.approx(span, rel=1e-6)
    assert panned["x"][0] > zoomed["x"][0]
    ActionChains(browser.driver).scroll_from_origin(ScrollOrigin.from_element(over), 0, -120) \
        .perform()
    browser.wait_for("(() => { const u = document.getElementById('plot-capacity').__dlPlot.u; "
                     f"return u.scales.x.max - u.scales.x.min < {span * 0.95}; }})()", 5,
                     "the wheel's zoom")

    # a double click shows everything again
    ActionChains(browser.driver).double_click(over).perform()
    again = plot_state(browser, "plot-capacity")
    assert again["x"] == pytest.approx(full["x"]) and not again["zoomed"]
    assert browser.js("return window.__csp;") == []
