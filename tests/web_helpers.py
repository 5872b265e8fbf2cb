"""Helpers of the web tests: a server in a subprocess, raw HTTP requests, headless Chromium.

The server is ``python -m dischargelab serve ...`` on 127.0.0.1 with port 0 (a free port,
read from the line it prints), stopped by its process id at teardown. The browser is Debian's
Chromium driven by Selenium through Debian's chromedriver (same package version, nothing
downloaded). Outside CI a missing browser skips the test; in CI (env CI set) it fails.
"""

from __future__ import annotations

import http.client
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--disable-dev-shm-usage",
                  "--window-size=1280,1000", "--hide-scrollbars"]
#: Longest a server may take to print its address [s].
START_TIMEOUT_S = 60


def _missing(what: str):
    if os.environ.get("CI"):
        pytest.fail(f"{what} is required in CI (make browser installs it)")
    pytest.skip(f"{what} not installed (make browser installs it)")


class ServerProcess:
    """``dischargelab serve`` (or another command printing ``listening on URL``) in a
    subprocess, with its address; :meth:`stop` ends it by its pid."""

    def __init__(self, args: list[str], env: dict | None = None, cwd=None):
        full_env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
        self.proc = subprocess.Popen([sys.executable, "-m", "dischargelab", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     env=full_env, cwd=cwd, start_new_session=True)
        self.lines: list[str] = []
        self.url = None
        found = threading.Event()

        def pump():
            for line in self.proc.stdout:
                self.lines.append(line.rstrip("\n"))
                match = re.search(r"listening on (http://\S+)", line)
                if match and self.url is None:
                    self.url = match.group(1)
                    found.set()
            found.set()

        self._reader = threading.Thread(target=pump, daemon=True)
        self._reader.start()
        if not found.wait(START_TIMEOUT_S) or self.url is None:
            self.stop()
            raise AssertionError("server did not start:\n" + "\n".join(self.lines))
        match = re.match(r"http://([^/:]+|\[[^\]]+\]):(\d+)/", self.url)
        self.host, self.port = match.group(1), int(match.group(2))
        self.base = f"http://{self.host}:{self.port}"

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self, timeout_s: float = 15) -> None:
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout_s)
            except ProcessLookupError:
                pass
        self._reader.join(5)

    def request(self, method: str, path: str, body: bytes | None = None,
                headers: dict | None = None, timeout_s: float = 30) -> tuple[int, dict | str]:
        """Send ``path`` exactly as given (no client-side normalisation of ``..``)."""
        status, data, _ = raw_request(self.host, self.port, method, path, body, headers,
                                      timeout_s)
        return status, data

    def get_json(self, path: str):
        status, data = self.request("GET", path)
        assert status == 200, (status, data)
        return data


def raw_request(host, port, method, path, body=None, headers=None, timeout_s=30.0):
    """Send ``path`` exactly as given (no client-side normalisation of ``..``); returns
    (status, JSON or text, the set-cookie header)."""
    conn = http.client.HTTPConnection(host, port, timeout=timeout_s)
    try:
        conn.putrequest(method, path, skip_accept_encoding=True,
                        skip_host="Host" in (headers or {}))
        for key, value in {"Content-Length": str(len(body or b"")), **(headers or {})}.items():
            conn.putheader(key, value)
        conn.endheaders()
        if body:
            conn.send(body)
        resp = conn.getresponse()
        raw = resp.read()
        cookie = resp.getheader("set-cookie")
    finally:
        conn.close()
    try:
        return resp.status, json.loads(raw), cookie
    except ValueError:
        return resp.status, raw.decode("utf-8", "replace"), cookie


def multipart(fields: dict, files: dict, boundary: str = "dlboundary7f3a") -> tuple[bytes, str]:
    """A multipart/form-data body: ``fields`` name -> text, ``files`` name -> (file name, bytes)."""
    out = []
    for name, value in fields.items():
        out.append(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n'
                   f"{value}\r\n".encode())
    for name, (file_name, data) in files.items():
        out.append(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"; '
                   f'filename="{file_name}"\r\nContent-Type: application/octet-stream\r\n\r\n'
                   .encode() + data + b"\r\n")
    out.append(f"--{boundary}--\r\n".encode())
    return b"".join(out), f"multipart/form-data; boundary={boundary}"


class Browser:
    """Headless Chromium through Selenium; :meth:`quit` ends it and removes its profile."""

    def __init__(self, width: int = 1280, height: int = 1000):
        if not Path(CHROMIUM).exists():
            _missing("chromium")
        if not Path(CHROMEDRIVER).exists():
            _missing("chromedriver (Debian package chromium-driver)")
        try:
            from selenium import webdriver
            from selenium.webdriver.chrome.service import Service
        except ImportError:
            _missing("selenium (extra test)")
        self.profile = tempfile.mkdtemp(prefix="dl-chromium-")
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for flag in CHROMIUM_FLAGS:
            options.add_argument(flag)
        options.add_argument(f"--window-size={width},{height}")
        options.add_argument(f"--user-data-dir={self.profile}")
        self.driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
        self.driver.set_page_load_timeout(30)
        self.driver.set_script_timeout(30)

    def get(self, url: str) -> None:
        self.driver.get(url)

    def js(self, script: str, *args):
        return self.driver.execute_script(script, *args)

    def wait_for(self, script: str, timeout_s: float = 20, what: str = "condition"):
        """Poll a JavaScript expression until it is truthy; returns its value."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            value = self.js(f"return ({script});")
            if value:
                return value
            time.sleep(0.1)
        raise AssertionError(f"timed out after {timeout_s} s waiting for {what}: {script}")

    def text(self, element_id: str) -> str:
        return self.js("return document.getElementById(arguments[0]).textContent;", element_id)

    def screenshot(self, path, height: int | None = None) -> None:
        if height:
            self.driver.set_window_size(1280, height)
        self.driver.save_screenshot(str(path))

    def quit(self) -> None:
        try:
            self.driver.quit()
        finally:
            shutil.rmtree(self.profile, ignore_errors=True)


class ThreadServer:
    """A server in a thread of the test process on a free loopback port."""

    def __init__(self, **options):
        from dischargelab.web.server import build_server

        self.server = build_server(port=0, **options).start()
        self.host, self.port = "127.0.0.1", self.server.listening.port

    def request(self, method, path, body=None, headers=None):
        return raw_request(self.host, self.port, method, path, body, headers, 20)

    def alive(self) -> bool:
        status, data, _ = self.request("GET", "/api/live")
        return status == 200 and "active" in data


#: Collects the page's Content-Security-Policy violations from its first script on.
CSP_PROBE = ("window.__csp = []; document.addEventListener('securitypolicyviolation', "
             "e => window.__csp.push(e.violatedDirective + ' ' + e.blockedURI));")


def plot_state(browser, element_id: str) -> dict:
    """The chart's x and y ranges, the data it holds and its legend's read-outs."""
    return browser.js(
        "const p = document.getElementById(arguments[0]).__dlPlot, u = p.u; return {"
        "x: [u.scales.x.min, u.scales.x.max], y: [u.scales.y.min, u.scales.y.max], "
        "xs: u.data[0], labels: u.series.map(s => s.label), zoomed: p.zoomed, "
        "legend: [...u.root.querySelectorAll('.u-legend .u-series')].map("
        "r => r.querySelector('.u-value').textContent), "
        "over: [u.over.clientWidth, u.over.clientHeight]};", element_id)
