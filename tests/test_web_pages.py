"""The pack list and pack page in headless Chromium, and the upload form.

The pages are fed through the logbook API of the agreed contract (``Logbook.packs``,
``pack``, ``health``, ``events``, ``add_bytes``). Until the logbook package is available in
this tree the tests run against :class:`ContractLogbook`, an in-memory logbook with that
interface and fixed numbers, so they check that every number on the page is the one the
API returned.
"""

import pytest

import dischargelab as dl
from dischargelab.errors import DataError
from web_helpers import Browser, ThreadServer


class _Table:
    def __init__(self, data):
        self.data = data

    def to_dict(self):
        return self.data


class _Pack:
    def __init__(self, name, reference):
        self.name, self.reference_capacity_Ah = name, reference

    def to_battery(self):
        return dl.load("zippy-1100-2s")

    battery = to_battery


class ContractLogbook:
    """In-memory logbook with the contract's interface (see the module docstring)."""

    def __init__(self):
        self.rows = [
            {"name": "zippy-a", "events": 3, "efc": 41.5, "capacity_Ah": 1.032,
             "capacity_fraction": 0.938, "resistance_ohm": 0.0412, "eol_efc": 212.0,
             "eol_efc_interval95": [160.0, 290.0]},
            {"name": "zippy-b", "events": 1, "efc": 7.0, "capacity_Ah": 1.087,
             "capacity_fraction": 0.988, "resistance_ohm": None, "eol_efc": None,
             "eol_efc_interval95": None},
        ]
        self.health_events = {"zippy-a": [
            {"source": "a1.csv", "start": "2026-01-02T10:00:00", "kind": "full",
             "discharged_Ah": 1.08, "capacity_Ah": 1.081, "capacity_interval95": [1.07, 1.09],
             "resistance_ohm": 0.038, "efc": 1.0, "outlier": False},
            {"source": "a2.csv", "start": "2026-02-02T10:00:00", "kind": "full",
             "discharged_Ah": 1.05, "capacity_Ah": 1.055, "capacity_interval95": [1.04, 1.07],
             "resistance_ohm": 0.040, "efc": 20.0, "outlier": False},
            {"source": "a3.csv", "start": "2026-03-02T10:00:00", "kind": "flight",
             "discharged_Ah": 0.71, "capacity_Ah": 1.032, "capacity_interval95": [1.0, 1.06],
             "resistance_ohm": 0.0412, "efc": 41.5, "outlier": False}],
            "zippy-b": []}

    def packs(self):
        return _Table({"rows": self.rows})

    def pack(self, name):
        return _Pack(name, 1.1)

    def events(self, name):
        return _Table({"pack": name, "rows": self.health_events[name]})

    def health(self, name, eol=0.8):
        forecast = ({"threshold_Ah": 0.88, "eol_efc": 212.0, "eol_efc_interval95": [160.0, 290.0]}
                    if name == "zippy-a" else None)
        return _Table({"pack": name, "events": self.health_events[name], "forecast": forecast})

    def add_bytes(self, file_name, data, pack):
        if not data.startswith(b"time_s,"):
            raise DataError(f"{file_name}: not a discharge log (no time_s column)")
        self.rows.append({"name": pack, "events": 1, "efc": 1.0, "capacity_Ah": 1.1,
                          "capacity_fraction": 1.0, "resistance_ohm": None, "eol_efc": None,
                          "eol_efc_interval95": None})
        self.health_events[pack] = []
        return _Table({"added": [file_name], "skipped": [], "rejected": [], "events": 1})


@pytest.fixture
def pages_server():
    srv = ThreadServer(db=None)
    srv.server.app_state("packs")._logbook = ContractLogbook()
    yield srv
    srv.server.stop()


@pytest.fixture
def browser():
    b = Browser()
    yield b
    b.quit()


def test_pack_list_shows_the_logbooks_numbers(pages_server, browser):
    browser.get(f"http://127.0.0.1:{pages_server.port}/")
    browser.wait_for("window.__packs && window.__packs.loaded")
    rows = browser.js("return [...document.querySelectorAll('#packs tbody tr')].map("
                      "r => [...r.cells].map(c => c.textContent.trim()));")
    assert rows[0][:4] == ["zippy-a", "3", "41.5", "1.032"]
    assert rows[0][4].startswith("94 %") and rows[0][5] == "41.2" and rows[0][6] == "212"
    assert rows[0][7] == "160 – 290"
    assert rows[1][:4] == ["zippy-b", "1", "7.0", "1.087"] and rows[1][6] == "–"


def test_pack_page_shows_health_events_and_model(pages_server, browser):
    browser.get(f"http://127.0.0.1:{pages_server.port}/packs/zippy-a")
    browser.wait_for("window.__pack && window.__pack.loaded")
    assert browser.text("m-capacity") == "1.032" and browser.text("m-efc") == "41.5"
    assert browser.text("m-eol") == "212" and "160–290" in browser.text("m-eol-iv")
    cells = browser.js("return [...document.querySelectorAll('#events tbody tr')].map("
                       "r => r.cells[0].textContent + ' ' + r.cells[4].textContent);")
    assert cells == ["a3.csv 1.032", "a2.csv 1.055", "a1.csv 1.081"]
    curves = browser.js("return window.__pack.data.model.curves.length;")
    assert curves == 3
    mission = browser.js("return document.getElementById('mission').value;")
    browser.driver.find_element("id", "fly").click()
    result = browser.wait_for("window.__endurance", 60, "the endurance result")
    expected = dl.endurance(dl.load("zippy-1100-2s"), mission).to_dict()
    assert result["flight_time_s"] == pytest.approx(expected["flight_time_s"], rel=1e-9)


def test_unknown_pack_is_a_404_on_the_page_and_the_api(pages_server, browser):
    status, data, _ = pages_server.request("GET", "/api/packs/nope")
    assert status == 404 and data["error"] == "no pack named 'nope' in the logbook"
    browser.get(f"http://127.0.0.1:{pages_server.port}/packs/nope")
    browser.wait_for("window.__pack && window.__pack.loaded")
    assert "no pack named 'nope'" in browser.text("message")


def test_an_upload_appears_in_the_list_and_garbage_is_refused(pages_server, browser, tmp_path):
    log = tmp_path / "new-run.csv"
    log.write_text("time_s,voltage_V,current_A\n0,8.2,1.1\n1,8.1,1.1\n")
    browser.get(f"http://127.0.0.1:{pages_server.port}/")
    browser.wait_for("window.__packs && window.__packs.loaded")
    browser.driver.find_element("id", "upload-pack").send_keys("zippy-new")
    browser.driver.find_element("id", "upload-file").send_keys(str(log))
    browser.driver.find_element("id", "upload-button").click()
    browser.wait_for("window.__packs.rows.some(r => r.name === 'zippy-new')", 20, "the new pack")
    assert "new-run.csv: added" in browser.text("upload-result")
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(bytes(range(256)) * 8)
    browser.driver.find_element("id", "upload-file").send_keys(str(garbage))
    browser.driver.find_element("id", "upload-button").click()
    message = browser.wait_for("document.getElementById('message').textContent", 20, "refusal")
    assert "garbage.bin: not a discharge log" in message
    assert pages_server.alive()
