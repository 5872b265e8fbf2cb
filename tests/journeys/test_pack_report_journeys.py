"""Journeys: a logbook pack's report, and one duration written one way everywhere.

The command line runs as a user runs it (a subprocess, the shared data). ``report --pack``
reads the pack's model as of today without writing anything to the logbook (every row of
every table compared before and after) and flies the mission with the pack's own cells,
chemistry and cutoff. A flight time reads the same in the terminal, the JSON, the HTML
report, the server's answer and the pack page.
"""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import pytest

import dischargelab as dl
from cli_run import command as cli
from cli_run import stored_rows
from dischargelab.cell import CUTOFF_CELL_VOLTAGE_V
from dischargelab.formatting import duration, mission_text

pytest.importorskip("sqlalchemy")

CELL_C = "samsung30q_ageing_cellC"
CYCLES = (1, 100, 200, 300)
FLIGHTS = "flight_logs/ina3221_fpv_4s"
#: A bundled mission written for a 4S LiFePO4 pack (cutoff 2.5 V per cell).
HOVER = "multirotor-hover"








def facts(page: str) -> dict[str, str]:
    """The report's label / value rows (every facts table) as a dict."""
    rows = re.findall(r"<tr><td>(.*?)</td><td>(.*?)</td></tr>", page)
    return {html.unescape(k): html.unescape(v) for k, v in rows}


def card(page: str, label: str) -> str:
    found = re.search(r'<div class="card"><div class="l">' + re.escape(label)
                      + r'</div><div class="v">(.*?)</div>', page)
    assert found, label
    return html.unescape(found.group(1))


def terminal_value(printed: str, name: str) -> str:
    """The value cell of a row of a two-column rich table printed by the CLI."""
    line = next(x for x in printed.splitlines() if x.strip("│┃ ").startswith(name))
    return line.strip().strip("│┃").split("│")[1].strip()


@pytest.fixture(scope="module")
def logbook(shared_data, tmp_path_factory) -> Path:
    """Cell C's bench discharges (full ones: a model is fitted to them) and a 4S FPV
    pack's flights (no full discharge: its chemistry's model at today's figures)."""
    db = tmp_path_factory.mktemp("logbook") / "logbook.sqlite"
    cli("logbook", "add", *[shared_data / CELL_C / f"DischargeCycle{c:03d}.txt"
                            for c in CYCLES], "--pack", "cell C", "--db", db)
    cli("logbook", "add", *sorted((shared_data / FLIGHTS).glob("*.csv")), "--pack", "fpv",
        "--db", db)
    return db


@pytest.mark.slow
def test_report_of_a_pack_writes_nothing_and_flies_the_packs_identity(logbook, tmp_path):
    before = stored_rows(logbook)
    out = tmp_path / "cell-c.html"
    args = ("report", "--pack", "cell C", "--db", logbook, "--mission", "fixed-wing-survey",
            "--cells", 4, "--parallel", 2, "--draws", 0)
    printed = cli(*args, "-o", out).stdout
    data = json.loads(cli(*args, "-o", tmp_path / "again.html", "--json").stdout)
    # the model was fitted in memory to the latest full discharge: nothing stored
    assert stored_rows(logbook) == before
    with dl.Logbook(str(logbook), create=False) as lb:
        pack = lb.pack("cell C", store=False)
        assert not pack.fitted
        expected = dl.endurance(pack, "fixed-wing-survey", draws=0, cells_series=4,
                                strings_parallel=2).to_dict()
    assert stored_rows(logbook) == before
    flown = data["mission"]
    assert data["pack"] == "cell C"
    for key in ("cells_series", "strings_parallel", "chemistry", "cutoff_cell_V"):
        assert flown[key] == expected[key], key
    # a li-ion cell: the mission's lifepo4 [battery] default does not change it
    assert flown["chemistry"] == "li-ion"
    assert any("pack 'cell C' is li-ion; flying li-ion" in w for w in flown["warnings"])
    assert flown["flight_time_s"] == pytest.approx(expected["flight_time_s"], rel=1e-9)
    page = out.read_text(encoding="utf-8")
    assert card(page, "pack as flown") == "4S2P"
    assert "logbook pack 'cell C'" in facts(page)["logbook pack today"]
    assert "scaled to its health today" in facts(page)["logbook pack today"]
    assert "pack: logbook pack 'cell C'" in printed

    # a 4S LiPo pack that only flies: its cells and its chemistry's cutoff, not the
    # mission's 2.5 V LiFePO4 default
    data = json.loads(cli("report", "--pack", "fpv", "--db", logbook, "--mission", HOVER,
                          "--draws", 0, "-o", tmp_path / "fpv.html", "--json").stdout)
    assert stored_rows(logbook) == before
    with dl.Logbook(str(logbook), create=False) as lb:
        expected = dl.endurance(lb.pack("fpv", store=False), HOVER, draws=0).to_dict()
    flown = data["mission"]
    for key in ("cells_series", "strings_parallel", "chemistry", "cutoff_cell_V"):
        assert flown[key] == expected[key], key
    assert flown["cells_series"] == 4 and flown["chemistry"] == "lipo"
    assert flown["cutoff_cell_V"] == CUTOFF_CELL_VOLTAGE_V["lipo"] != 2.5


def test_report_of_a_pack_says_in_one_line_what_is_missing(tmp_path):
    db = tmp_path / "lb.sqlite"
    with dl.Logbook(str(db)) as lb:
        lb.set_pack("bare", chemistry="lipo")
        lb.set_pack("zippy-a", label_capacity_Ah=2.2, chemistry="lipo", cells=3)
    before = stored_rows(db)
    out = tmp_path / "r.html"
    cases = [(("--pack", "nope"), ["no pack named 'nope'", "'bare'", "'zippy-a'",
                                   "logbook packs"]),
             (("--pack", "bare"), ["pack 'bare' has no model yet", "logbook add",
                                   "--capacity AH"]),
             (("hacker-4100-4s-lifepo4", "--pack", "bare"), ["not both"])]
    for args, said in cases:
        done = cli("report", *args, "--db", db, "-o", out, check=False)
        assert done.returncode == 2, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
        for text in said:
            assert text in lines[0], (text, lines[0])
        assert not out.exists()
    assert stored_rows(db) == before


@pytest.mark.slow
def test_a_flight_time_reads_alike_in_terminal_json_report_and_page(logbook, tmp_path):
    pytest.importorskip("starlette")
    from web_helpers import Browser, ServerProcess

    args = ("--pack", "fpv", "--db", logbook)
    printed = cli("endurance", *args, HOVER, "--draws", 0).stdout
    result = json.loads(cli("endurance", *args, HOVER, "--draws", 0, "--json").stdout)
    text = result["text"]
    assert text == mission_text(result)
    shown = text["flight_time_s"]
    assert shown == duration(result["flight_time_s"])
    assert re.fullmatch(r"\d+ min \d\d s", shown), shown
    # the terminal
    assert f"flight time {shown}  " in printed
    assert terminal_value(printed, "flight as planned") == shown
    assert terminal_value(printed, "reserve reached at") == text["reserve_time_s"]
    # the report
    out = tmp_path / "fpv.html"
    reported = cli("report", *args, "--mission", HOVER, "--draws", 0, "-o", out).stdout
    page = out.read_text(encoding="utf-8")
    assert facts(page)["flight time as planned"] == shown
    assert facts(page)["reserve reached at"] == text["reserve_time_s"]
    assert card(page, "endurance") == text["endurance_s"]
    assert f"flight time {shown}  " in reported

    server = ServerProcess(["serve", "--db", str(logbook), "--port", "0"], cwd=tmp_path,
                           env={"PYTHONPATH": str(Path(dl.__file__).parents[1])})
    try:
        status, answer = server.request("POST", "/api/packs/fpv/endurance",
                                         json.dumps({"mission": HOVER}).encode(),
                                         {"Content-Type": "application/json"})
        assert status == 200, answer
        assert answer["text"]["flight_time_s"] == shown
        assert answer["text"]["endurance_s"] == text["endurance_s"]
        browser = Browser()
        try:
            browser.get(server.base + "/packs/fpv")
            browser.wait_for("window.__pack && window.__pack.loaded", 120, "the pack page")
            browser.js("document.getElementById('mission').value = arguments[0];", HOVER)
            browser.driver.find_element("id", "fly").click()
            browser.wait_for("window.__endurance", 120, "the endurance result")
            rows = dict(browser.js(
                "return [...document.querySelectorAll('#endurance-result tr')]"
                ".map(r => [r.cells[0].textContent, r.cells[1].textContent]);"))
            assert rows["Flight time"] == shown
            assert rows["Endurance to cutoff"] == text["endurance_s"]
            # the pages' own writer of a duration (the live page's) is the twin
            values = [0, 0.4, 0.5, 2.5, 59.49, 59.5, 60.49999999999999, 4168.7, 7199.49,
                      7199.5, 7229.9, 7230, 186300, -65, -0.4, None, float("nan")]
            for signed in (False, True):
                written = browser.js("return arguments[0].map(v => DL.duration("
                                     "v === 'nan' ? NaN : v, arguments[1]));",
                                     ["nan" if v != v else v for v in values], signed)
                assert written == [duration(v, signed=signed) for v in values]
        finally:
            browser.quit()
    finally:
        server.stop()
