"""The live bench page in headless Chromium: a virtual-logger discharge, every sample shown.

The server runs ``dischargelab serve --demo``: the page's Start opens a virtual logger on a
pseudo-terminal that the acquisition reads through real pyserial, logs to a file and feeds
the page. The page must update at the logger's rate and hold exactly what the log file holds.
"""

import time

import numpy as np
import pytest

from dischargelab.io.logfile import read_log
from web_helpers import CSP_PROBE, Browser, ServerProcess, plot_state

RATE_HZ = 10.0            # logger rate; time compression 1, so 10 samples per wall second
WATCH_S = 15.0            # the watched window (the acceptance measured 30 s)
MAX_STALL_MS = 1500       # a page that shows nothing new for longer has fallen behind


@pytest.fixture
def demo_server(tmp_path):
    server = ServerProcess(["serve", "--demo", "--port", "0", "--runs", str(tmp_path / "runs"),
                            "--db", str(tmp_path / "logbook.sqlite")])
    server.runs = tmp_path / "runs"
    yield server
    server.stop()


@pytest.fixture
def browser():
    b = Browser()
    yield b
    b.quit()


def page_data(browser) -> dict:
    return browser.js("const L = window.__live; return {n: L.n, t: L.t, v: L.v, i: L.i, "
                      "seq: L.seq, missing: L.missing, gaps: L.gaps, snapshots: L.snapshots, "
                      "updates: L.updates, now: performance.now()};")


def start_from_the_page(browser, **settings) -> None:
    browser.wait_for("window.__live && window.__live.status && window.__live.status.can_start",
                     what="the Start button to be enabled")
    for name, value in settings.items():
        browser.js("const f = document.querySelector('#start-form [name=' + arguments[0] + ']');"
                   "f.value = arguments[1];", name, str(value))
    browser.driver.find_element("id", "start").click()
    browser.wait_for("window.__live.n.length > 0", 30, "the first samples")


def compare_with_log(data: dict, log_path) -> None:
    log, meta = read_log(log_path)
    n = np.array(data["n"])
    assert data["missing"] == 0 and data["gaps"] == 0
    np.testing.assert_array_equal(n, np.arange(len(n)))       # every sample, in order
    assert len(log) == len(n), (len(log), len(n))              # nothing more in the file
    np.testing.assert_allclose(np.array(data["t"], float), log["time_s"], rtol=0, atol=6e-5)
    np.testing.assert_allclose(np.array(data["v"], float), log["voltage_V"], rtol=0, atol=6e-5)
    np.testing.assert_allclose(np.array(data["i"], float), log["current_A"], rtol=0, atol=6e-5)
    np.testing.assert_array_equal(np.array(data["seq"]), log["seq"].to_numpy(int))
    # no gap in the test itself: one sample every 1/rate of test time
    np.testing.assert_allclose(np.diff(log["time_s"]), 1 / RATE_HZ, atol=1e-3)


@pytest.mark.slow
def test_live_page_keeps_up_and_holds_every_logged_sample(demo_server, browser):
    browser.driver.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument",
                                   {"source": CSP_PROBE})
    browser.get(demo_server.base + "/live")
    start_from_the_page(browser, rate_Hz=RATE_HZ, speed=1, c_rate=1)
    page_t0 = browser.js("return performance.now();")
    deadline = time.monotonic() + WATCH_S
    while time.monotonic() < deadline:          # the page is left alone, as a viewer would
        time.sleep(1.0)
        assert demo_server.alive
    data = page_data(browser)
    stamps = np.array([u for u in data["updates"] if page_t0 <= u <= page_t0 + WATCH_S * 1000])
    bins = np.arange(page_t0, page_t0 + WATCH_S * 1000 + 1, 1000)
    per_second = np.histogram(stamps, bins=bins)[0]
    # the page follows the logger: one update per sample as a rule, and no stall; a loaded
    # two-core machine may hold one draw back for a few hundred ms (the samples then arrive
    # together), which is not a page falling behind
    gaps = np.diff(stamps)
    assert abs(np.median(gaps) - 1000 / RATE_HZ) < 0.2 * 1000 / RATE_HZ, np.median(gaps)
    assert len(stamps) >= WATCH_S * RATE_HZ * 0.8, len(stamps)
    assert gaps.max() < MAX_STALL_MS, gaps.max()
    received = len(data["n"])
    assert received >= WATCH_S * RATE_HZ * 0.9, received
    print(f"\nlive page: {len(stamps) / WATCH_S:.1f} updates/s (slowest second "
          f"{per_second.min()}), {received} samples, missing {data['missing']}")

    # a reload gets the history, then carries on live
    browser.driver.refresh()
    browser.wait_for(f"window.__live && window.__live.n.length > {received + 20}", 30,
                     "the history and new samples after a reload")
    assert browser.js("return window.__live.snapshots;") == 1

    # zoomed into the first samples, the view stays put while samples keep arriving;
    # a double click shows the whole run again, up to the newest sample
    from selenium.webdriver.common.action_chains import ActionChains

    over = browser.driver.find_element("css selector", "#plot-voltage .u-over")
    width = plot_state(browser, "plot-voltage")["over"][0]
    ActionChains(browser.driver).move_to_element_with_offset(over, -width // 2 + 5, 0) \
        .click_and_hold().move_by_offset(width // 4, 0).release().perform()
    zoomed = plot_state(browser, "plot-voltage")
    assert zoomed["zoomed"]
    browser.wait_for(f"window.__live.n.length > {len(zoomed['xs']) + 10}", 30, "more samples")
    time.sleep(0.3)                              # a draw after them
    later = plot_state(browser, "plot-voltage")
    assert later["x"] == zoomed["x"] and len(later["xs"]) > len(zoomed["xs"])
    ActionChains(browser.driver).double_click(over).perform()
    whole = plot_state(browser, "plot-voltage")
    # (a sample may arrive between the reset and the next draw)
    assert not whole["zoomed"] and whole["x"][1] >= whole["xs"][-1] - 2 / RATE_HZ
    assert browser.js("return window.__csp;") == []
    browser.driver.find_element("id", "stop").click()
    browser.wait_for("window.__live.status && window.__live.status.ended_by === 'user'", 30,
                     "the stop")
    state = demo_server.get_json("/api/live")
    time.sleep(0.5)                              # the last samples and the end state
    data = page_data(browser)
    assert data["n"][-1] == state["samples"] - 1
    assert "/" not in state["info"]["out"]      # the log's name, not where the server keeps it
    compare_with_log(data, demo_server.runs / state["info"]["out"])
    assert "stopped from the web page" in browser.text("message")


def test_start_settings_are_checked_like_the_command_line(demo_server, browser):
    browser.get(demo_server.base + "/live")
    browser.wait_for("window.__live && window.__live.status && window.__live.status.can_start")
    status, body = demo_server.request("POST", "/api/live/start", b'{"debounce": 0}',
                                       {"Content-Type": "application/json"})
    assert status == 400 and "debounce must be between 1 and 1000" in body["error"]
    status, body = demo_server.request("POST", "/api/live/start", b'{"chemistry": "nimh"}',
                                       {"Content-Type": "application/json"})
    assert status == 400 and "unknown chemistry 'nimh'" in body["error"]
    status, body = demo_server.request("POST", "/api/live/stop", b"{}")
    assert status == 409 and body["error"] == "no test is running"
    # a cutoff above the pack's voltage: refused by the acquisition before any test runs
    browser.js("document.querySelector('#start-form [name=cutoff_cell_V]').value = '4.4';")
    browser.driver.find_element("id", "start").click()
    message = browser.wait_for("document.getElementById('message').textContent", 30,
                               "the refusal")
    assert "at or below the cutoff" in message
    # a fast run to the cutoff: the page ends with the cutoff, as the command line does
    browser.js("document.querySelector('#start-form [name=cutoff_cell_V]').value = '';")
    start_from_the_page(browser, rate_Hz=2, speed=300, c_rate=2)
    # the demo knows its battery model: the time to cutoff is the model's
    browser.wait_for("window.__live.status && window.__live.status.time_to_cutoff_method === "
                     "'model'", 20, "the model's time to cutoff")
    assert browser.text("m-eta-method") == "(model)"
    browser.wait_for("window.__live.status && window.__live.status.ended_by === 'cutoff'", 60,
                     "the cutoff")
    assert "CUTOFF" in browser.text("message")
    assert browser.text("state").startswith("ended: cutoff")
    kinds = browser.js("return window.__live.events.map(e => e.kind);")
    assert "cutoff" in kinds
    assert demo_server.alive


@pytest.mark.slow
def test_acquire_serve_shows_the_command_lines_test_and_stops_it(tmp_path, browser):
    from dischargelab.acquire.virtual_device import VirtualDevice

    log_path = tmp_path / "run.csv"
    with VirtualDevice("zippy-1100-2s", speed=1, seed=21, current_A=1.1) as dev:
        acq = ServerProcess(["acquire", "--port", dev.port, "--out", str(log_path), "--ke",
                             "4.38", "--current", "1.1", "--cells", "2", "--rate", "5",
                             "--quiet", "--serve", "--serve-port", "0",
                             "--battery-model", "zippy-1100-2s"])
        try:
            browser.get(acq.url)
            browser.wait_for("window.__live && window.__live.n.length >= 25", 30,
                             "5 s of samples")
            assert browser.js("return window.__live.status.mode;") == "watch"
            browser.wait_for("window.__live.status.time_to_cutoff_method === 'model'", 10,
                             "the model's time to cutoff (--battery-model)")
            assert browser.js("return document.getElementById('start').disabled;")
            browser.driver.find_element("id", "stop").click()
            assert acq.proc.wait(30) == 0                  # stopped like Ctrl-C: status 0
            data = page_data(browser)
        finally:
            acq.stop()
    assert "stopped from the web page" in "\n".join(acq.lines)
    log, _ = read_log(log_path)
    n = np.array(data["n"])
    assert data["missing"] == 0
    np.testing.assert_array_equal(n, np.arange(len(n)))
    # the page may miss only the very last samples, sent while the server was closing
    assert len(log) - 3 <= len(n) <= len(log)
    np.testing.assert_allclose(np.array(data["v"], float), log["voltage_V"][:len(n)], atol=6e-5)
    np.testing.assert_allclose(np.array(data["i"], float), log["current_A"][:len(n)], atol=6e-5)
