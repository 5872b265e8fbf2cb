"""HTML report: self-contained, complete, and rendered by a real browser (headless Chromium)."""

import base64
import io
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from dischargelab.cli import main as cli_main
from dischargelab.mission import load_mission, run_mission
from dischargelab.report import build_report, write_report
from dischargelab.validate import compare_files

REPO = Path(__file__).resolve().parents[1]
MISSIONS = REPO / "src" / "dischargelab" / "data" / "missions"

COLUMNS = "time_s=0,current_A=1,voltage_V=2,temperature_C=4"
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--no-first-run", "--disable-sync",
                  "--hide-scrollbars"]


def chromium() -> str:
    """Path of the Chromium binary; CI must have it, a developer machine may not."""
    for name in ("/usr/bin/chromium", "chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    if os.environ.get("CI"):
        pytest.fail("headless Chromium is required in CI (apt-get install chromium)")
    pytest.skip("Chromium not installed (apt-get install chromium)")


def embedded_pngs(page: str) -> list[bytes]:
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([^"]+)"', page)]


@pytest.fixture(scope="module")
def fitted(shared_data, tmp_path_factory):
    """Battery fitted to the Samsung 30Q 1C and 4C files (they stay reachable for the report)."""
    from dischargelab.fit import Curve, fit_battery
    from dischargelab.io import read_discharge

    folder = shared_data / "samsung30q_S001"
    curves = [Curve.from_frame(*read_discharge(folder / f"Q30_S001_{r}.csv", columns=COLUMNS))
              for r in ("1C", "4C")]
    battery = fit_battery(curves).battery
    path = battery.save(tmp_path_factory.mktemp("battery") / "q30.json")
    return battery, path, folder


@pytest.fixture(scope="module")
def full_report(fitted, tmp_path_factory):
    battery, path, folder = fitted
    mission = load_mission(MISSIONS / "fixed-wing-survey.toml", battery=path, cutoff_cell_V=3.0)
    mission = mission.with_battery(mission.battery.with_pack(4, 2))
    result = run_mission(mission, draws=200, seed=0)
    cases = compare_files(path, [folder / f"Q30_S001_{r}.csv" for r in ("2C", "3C")],
                          cutoff_cell_V=3.0, columns=COLUMNS)
    out = tmp_path_factory.mktemp("report") / "report.html"
    write_report(out, path, mission_result=result, validation=cases)
    return out, result, cases


def test_report_is_self_contained_and_complete(full_report):
    path, result, cases = full_report
    page = path.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>")
    # nothing is loaded from elsewhere: no scripts, stylesheets, fonts or remote images
    assert "<script" not in page and "<link" not in page and "@import" not in page
    assert not re.search(r'(src|href)="(?!data:)', page)
    assert "http://" not in page and "https://" not in page
    for section in ("Battery model", "Fit to the measured discharge", "Simulated discharges",
                    "Mission", "Validation against measured discharges"):
        assert f">{section}<" in page
    assert page.count("<table") >= 6
    # the four figures (fit, family, mission, validation) are real PNGs
    pngs = embedded_pngs(page)
    assert len(pngs) == 4
    from PIL import Image

    for data in pngs:
        assert data.startswith(b"\x89PNG\r\n\x1a\n")
        width, height = Image.open(io.BytesIO(data)).size
        assert width > 600 and height > 400
    # numbers in the page are the numbers of the results
    e = result.uncertainty["endurance_s"]
    assert e["low"] <= result.endurance_s <= e["high"]
    for case in cases:
        assert f"{case.summary['endurance_error_pct']:+.2f}" in page
    assert "Q30_S001_3C.csv" in page


def test_report_renders_in_chromium(full_report, tmp_path):
    """Chromium decodes every image and shows every table; the screenshot is a real page."""
    browser = chromium()
    path, _, _ = full_report
    page = path.read_text(encoding="utf-8")
    probe = ("<script>window.addEventListener('load',function(){var r=[];"
             "for(var i=0;i<document.images.length;i++){var m=document.images[i];"
             "r.push(m.complete+':'+m.naturalWidth+'x'+m.naturalHeight);}"
             "var p=document.createElement('pre');p.id='probe';"
             "p.textContent=r.join(' ')+' tables='+document.querySelectorAll('table').length+"
             "' h2='+document.querySelectorAll('h2').length;document.body.appendChild(p);});"
             "</script>")
    probed = tmp_path / "probed.html"
    probed.write_text(page.replace("</body>", probe + "</body>"), encoding="utf-8")
    profile = tmp_path / "profile"
    dom = subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                          "--virtual-time-budget=10000", "--dump-dom", probed.as_uri()],
                         capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0, dom.stderr[-2000:]
    match = re.search(r'<pre id="probe">([^<]*)</pre>', dom.stdout)
    assert match, "the page did not finish loading in Chromium"
    fields = match.group(1).split()
    images = [f for f in fields if ":" in f]
    assert len(images) == 4
    for item in images:
        complete, size = item.split(":")
        width, height = (int(x) for x in size.split("x"))
        assert complete == "true" and width > 600 and height > 400
    assert int(fields[-2].split("=")[1]) >= 6 and int(fields[-1].split("=")[1]) == 5
    shot = tmp_path / "report.png"
    done = subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                           "--window-size=1100,1400", f"--screenshot={shot}", path.as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and shot.exists(), done.stderr[-2000:]
    from PIL import Image

    image = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert image.shape == (1400, 1100)
    assert image.std() > 20                       # text and plots, not a blank page


def page_width_overflow(page: Path, width: int, tmp_path: Path) -> dict:
    """Load ``page`` in Chromium with a viewport ``width`` CSS px wide (a phone's width
    through device emulation): the document's scrollWidth and clientWidth, how many boxes
    reach past the right edge, and a screenshot of the first screen."""
    from web_helpers import Browser

    browser = Browser()
    try:
        browser.driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
            "width": width, "height": 900, "deviceScaleFactor": 1, "mobile": width < 600})
        browser.get(page.as_uri())
        browser.wait_for("document.readyState === 'complete'", what="the report")
        got = browser.js(
            "const e = document.documentElement; return {scroll: e.scrollWidth, client: "
            "e.clientWidth, wide: [...document.querySelectorAll('body *')].filter(x => "
            "x.getBoundingClientRect().right > e.clientWidth + 1).length};")
        got["shot"] = tmp_path / f"{page.stem}-{width}.png"
        browser.driver.save_screenshot(str(got["shot"]))
        return got
    finally:
        browser.quit()


@pytest.fixture(scope="module")
def ecm_report(tmp_path_factory):
    """The report of an ecm fit (18 open-circuit-voltage parameters) with a mission."""
    import dischargelab as dl
    from dischargelab.demo import demo_data_dir

    folder = tmp_path_factory.mktemp("ecm")
    fit = dl.fit([dl.read(demo_data_dir() / "Q30_S001_1C.csv", columns=COLUMNS)],
                 model="ecm", bootstrap=10)
    path = fit.save(folder / "ecm.json")
    mission = load_mission("multirotor-hover", battery=path, cutoff_cell_V=3.0)
    result = run_mission(mission.with_battery(mission.battery.with_pack(4, 1)), draws=20,
                         seed=0)
    return write_report(folder / "ecm.html", path, mission_result=result), fit


def test_ecm_report_plots_the_ocv_and_folds_its_numbers(ecm_report):
    path, fit = ecm_report
    page = path.read_text(encoding="utf-8")
    assert "open-circuit voltage curve" in page             # the figure's alt text
    folded = re.search(r"<details><summary>([^<]*)</summary>(.*?)</details>", page, re.S)
    assert folded and "18 parameters" in folded.group(1)
    ocv_names = [n for n in fit.parameters if n.startswith("ocv_d")]
    assert len(ocv_names) == 18
    # each drop is in the folded table, none in the main one
    assert all(f">{n}<" in folded.group(2) for n in ocv_names)
    main_table = page[page.index(">Battery model<"):page.index("<details>")]
    assert not any(f">{n}<" in main_table for n in ocv_names)
    assert ">U_full_V<" in main_table and ">R0_ohm<" in main_table
    assert len(embedded_pngs(page)) == 4        # OCV, fit, family, mission


@pytest.mark.slow
@pytest.mark.parametrize("width", [1280, 390])
def test_report_fits_the_screen_width(ecm_report, full_report, width, tmp_path):
    """No horizontal scroll bar on a laptop or a phone: the summary rows wrap, the tables
    become cards on a phone, the figures shrink."""
    for page in (ecm_report[0], full_report[0]):
        got = page_width_overflow(page, width, tmp_path)
        assert got["client"] == pytest.approx(width, abs=20), got   # scroll bars hidden
        assert got["scroll"] <= got["client"] and got["wide"] == 0, (page.name, got)
        from PIL import Image

        image = np.asarray(Image.open(got["shot"]).convert("L"), dtype=float)
        assert image.std() > 20


def test_preset_report_skips_the_fit_with_a_note(tmp_path):
    mission = load_mission(MISSIONS / "paper-table5.toml")
    page = build_report("hacker-4100-4s-lifepo4", mission_result=run_mission(mission, draws=100))
    assert "fit plot skipped" in page
    assert "(model error only)" in page            # presets carry no parameter draws
    assert "paper Table 4" in page
    assert len(embedded_pngs(page)) == 2           # family and mission


def test_unreachable_fit_sources_are_noted(fitted, tmp_path):
    battery, path, _ = fitted
    data = json.loads(path.read_text())
    for entry in data["source"]:
        entry["source"] = str(tmp_path / "moved" / "file.csv")
    moved = tmp_path / "moved.json"
    moved.write_text(json.dumps(data))
    page = build_report(moved)
    assert "source file not readable here" in page and "fit plot skipped" in page


def test_cli_report(fitted, tmp_path, capsys):
    _, path, folder = fitted
    out = tmp_path / "r.html"
    with pytest.raises(SystemExit) as info:
        cli_main(["report", str(path), "--mission", str(MISSIONS / "multirotor-hover.toml"),
                  "--validate", str(folder / "Q30_S001_3C.csv"), "--cutoff", "3.0",
                  "--columns", COLUMNS, "--cells", "4", "--parallel", "2", "--draws", "50",
                  "-o", str(out), "--json"])
    assert info.value.code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["report"] == str(out) and out.stat().st_size == summary["bytes"]
    assert summary["validation"][0]["file"].endswith("Q30_S001_3C.csv")
    assert summary["mission"]["ended_by"] in ("reserve", "cutoff")
    with pytest.raises(SystemExit) as info:
        cli_main(["report", str(path), "-o", str(tmp_path / "r.pdf")])
    assert info.value.code == 2
    assert ".html" in capsys.readouterr().err


def test_one_rate_report_names_the_next_test(bundled_data):
    """A battery fitted on one rate: the report says which run would narrow its
    predictions, and to about what."""
    import dischargelab as dl

    fit = dl.fit(dl.read(bundled_data / "Q30_S001_1C.csv", columns=COLUMNS), bootstrap=0)
    page = build_report(fit.battery)
    assert "next test: fitted on one rate" in page
    assert f"one more run at {fit.next_test['current_A']:.3g} A" in page
