"""Journeys: what the report, the terminal and the pages state is what was done.

Each test runs the command line as a user does (a subprocess, the shared data) and checks
the statement against the result it describes: the battery file's own record of the data
its fit saw, its model family and its interval method; one number for one quantity
wherever it is shown.
"""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import pytest

import dischargelab as dl
from cli_run import command as cli
from dischargelab.formatting import interval, pack_text

COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
CELL_C = "samsung30q_ageing_cellC"
CYCLES = (1, 100, 200, 300)




def cards(page: str) -> list[tuple[str, str, str]]:
    """The report's headline cards as (label, value, note)."""
    found = re.findall(r'<div class="card"><div class="l">(.*?)</div><div class="v">(.*?)'
                       r'</div><div class="l">(.*?)</div></div>', page)
    return [tuple(html.unescape(x) for x in card) for card in found]


def footer(page: str) -> str:
    return html.unescape(re.search(r"<footer>(.*?)</footer>", page, re.S).group(1))


def fitted_names(battery_file: Path) -> set[str]:
    """The files the battery file records its fit saw."""
    extra = dl.load(str(battery_file)).extra
    return {Path(s["source"]).name for s in extra["source"]}


@pytest.mark.slow
def test_demo_headline_is_a_held_out_validation_named_with_the_model_used(tmp_path):
    out = tmp_path / "demo"
    cli("demo", "--out", out)
    page = (out / "report.html").read_text(encoding="utf-8")
    battery = dl.load(str(out / "battery.json"))
    seen = fitted_names(out / "battery.json")
    assert "Q30_S001_1C.csv" not in seen and seen == {"Q30_S001_C10.csv", "Q30_S001_4C.csv"}
    labels = [c[0] for c in cards(page)]
    validation = [c for c in cards(page) if "validation" in c[0]]
    # the one validation card is held-out data: 1C, which the fit did not see
    assert len(validation) == 1
    label, value, note = validation[0]
    assert label.startswith("held-out validation")
    assert "Q30_S001_1C.csv" in note and "not in the fit" in note
    assert not any(name in note for name in seen)
    assert re.fullmatch(r"\d+\.\d %", value)
    assert not any("fit check" in x for x in labels)
    # the headline names the model family and the interval method of battery.json
    n_boot = len(battery.extra["bootstrap"]["samples"])
    model = [c for c in cards(page) if c[0] == "model"]
    assert len(model) == 1 and model[0][1] == battery.model
    assert battery.family.title in model[0][2] and f"{n_boot} bootstrap refits" in model[0][2]
    # the footer and the facts name the family, the data and the interval method used
    text = footer(page)
    assert battery.family.title in text and f"'{battery.model}'" in text
    assert f"{n_boot} bootstrap refits" in text
    for name in seen:
        assert name in text
    assert "Q30_S001_1C.csv" not in text
    if battery.model != "shepherd":
        assert "eq. (6) of" not in text.replace("extends eq. (6) of", "")


@pytest.fixture(scope="module")
def ecm_fit(shared_data, tmp_path_factory) -> Path:
    """An ``ecm`` fit with bootstrap refits on the Samsung 30Q 1C and 4C runs."""
    folder = tmp_path_factory.mktemp("ecm")
    runs = shared_data / "samsung30q_S001"
    cli("fit", runs / "Q30_S001_1C.csv", runs / "Q30_S001_4C.csv", "--columns", COLUMNS,
        "--model", "ecm", "--bootstrap", 12, "-o", folder / "ecm.json")
    return folder / "ecm.json"


@pytest.mark.slow
def test_report_of_an_ecm_bootstrap_fit_says_so_and_tells_validation_from_fit_check(
        ecm_fit, shared_data, tmp_path):
    runs = shared_data / "samsung30q_S001"
    out = tmp_path / "report.html"
    done = cli("report", ecm_fit, "--validate", runs / "Q30_S001_3C.csv", "--validate",
               runs / "Q30_S001_1C.csv", "--columns", COLUMNS, "--cutoff", 2.5, "-o", out)
    page = out.read_text(encoding="utf-8")
    battery = dl.load(str(ecm_fit))
    assert battery.model == "ecm"
    text = footer(page)
    assert battery.family.title in text and "'ecm'" in text
    assert "12 bootstrap refits" in text
    assert "modified Shepherd" not in text and "sampling the fit" not in text
    # the terminal says the same
    assert battery.family.title in done.stdout and "12 bootstrap refits" in done.stdout
    # 3C was not fitted: a validation; 1C was: a fit check, never called a validation
    by_label = {c[0]: c for c in cards(page)}
    held = [c for k, c in by_label.items() if k.startswith("held-out validation")]
    check = [c for k, c in by_label.items() if k.startswith("fit check")]
    assert len(held) == 1 and "Q30_S001_3C.csv" in held[0][2] and "1C" not in held[0][2]
    assert by_label["model"][1] == "ecm" and "12 bootstrap refits" in by_label["model"][2]
    assert len(check) == 1 and "Q30_S001_1C.csv" in check[0][2]
    assert ">Validation against measured discharges<" not in page


@pytest.mark.slow
def test_endurance_header_and_warning_name_one_extrapolation_ratio(shared_data, tmp_path):
    runs = shared_data / "samsung30q_S001"
    cell = tmp_path / "cell-1C.json"
    cli("fit", runs / "Q30_S001_1C.csv", "--columns", COLUMNS, "--bootstrap", 0, "-o", cell)
    args = ("endurance", cell, "fixed-wing-survey", "--cells", 4, "--parallel", 2,
            "--cutoff", 3.0, "--draws", 50)
    printed = cli(*args).stdout
    ratios = set(re.findall(r"extrapolation(?: ratio)? \(?(x\d+\.\d)", printed))
    warnings = [line for line in printed.splitlines() if line.startswith("warning: extrapol")]
    assert warnings, printed      # the survey flies far outside the one fitted rate
    assert len(ratios) == 1, printed
    # the number is the mission's, the one its interval was widened with
    result = json.loads(cli(*args, "--json").stdout)
    ratio = result["uncertainty"]["model_error"]["extrapolation_ratio"]
    assert ratios == {f"x{ratio:.1f}"}
    assert all(f"x{ratio:.1f}" in w for w in result["warnings"] if w.startswith("extrapol"))


@pytest.fixture(scope="module")
def logbook(shared_data, tmp_path_factory) -> Path:
    db = tmp_path_factory.mktemp("logbook") / "logbook.sqlite"
    cli("logbook", "add", *[shared_data / CELL_C / f"DischargeCycle{c:03d}.txt"
                            for c in CYCLES], "--pack", "cell C", "--db", db)
    return db


def terminal_row(printed: str, name: str) -> list[str]:
    """A row of a rich table printed by the CLI, split into its cells."""
    line = next(x for x in printed.splitlines() if x.strip("│┃ ").startswith(name))
    return [cell.strip() for cell in line.strip().strip("│┃").split("│")]


@pytest.mark.slow
def test_pack_list_terminal_json_and_page_write_efc_and_intervals_alike(logbook):
    printed = cli("logbook", "packs", "--db", logbook).stdout
    row = terminal_row(printed, "cell C")
    data = json.loads(cli("logbook", "packs", "--db", logbook, "--json").stdout)["rows"][0]
    text = pack_text(data)
    # the terminal writes what the JSON's text says, at the page's decimals (EFC to 0.1)
    assert data["text"] == text
    assert row[2] == text["efc"] and re.fullmatch(r"\d+\.\d", row[2])
    assert row[4] == text["capacity_interval95"] and row[8] == text["eol_efc_interval95"]

    from web_helpers import Browser, ServerProcess

    server = ServerProcess(["serve", "--db", str(logbook), "--port", "0"])
    try:
        api = server.get_json("/api/packs")["rows"][0]
        assert api["text"] == text
        browser = Browser()
        try:
            browser.get(server.base + "/")
            browser.wait_for("window.__packs && window.__packs.loaded && "
                             "!window.__packs.rows.some(r => r.recomputing)", 120, "the list")
            cells = browser.js("return [...document.querySelector('#packs tbody tr').cells]"
                               ".map(c => c.textContent.trim());")
            assert cells[2] == row[2] and cells[7] == row[8]
            browser.get(server.base + "/packs/cell%20C")
            browser.wait_for("window.__pack && window.__pack.loaded", 120, "the pack page")
            assert browser.text("m-efc") == row[2]
            # an open interval: the page's helper writes what the terminal writes
            for pair in ([10, None], [None, 25.4], [3.2, 447.6], None):
                shown = browser.js("return DL.interval(arguments[0], 0);", pair)
                assert shown == interval(pair, 0)
            assert interval([10, None], 0) == "10 - open"
        finally:
            browser.quit()
    finally:
        server.stop()
