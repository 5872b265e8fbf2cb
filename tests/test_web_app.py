"""The web server's safety rules and the live hub's no-silent-drop promise (no browser)."""

import asyncio
import socket
import subprocess
import sys
import time

import pytest

from dischargelab.acquire.pipeline import Sample
from dischargelab.errors import DischargelabError
from dischargelab.web.guard import path_problem
from dischargelab.web.limits import Limits
from dischargelab.web.live import RING_EVENTS, LiveHub
from dischargelab.web.server import Server, build_server, check_bind
from web_helpers import ThreadServer, multipart


@pytest.fixture
def server(tmp_path):
    srv = ThreadServer(db=str(tmp_path / "logbook.sqlite"), limits=Limits(max_upload_bytes=50_000))
    yield srv
    srv.server.stop()


@pytest.mark.parametrize("path", [
    "/static/../../etc/passwd", "/static/..%2f..%2fetc%2fpasswd",
    "/static/%2e%2e%2f%2e%2e%2fetc%2fpasswd", "/%2e%2e/%2e%2e/etc/passwd",
    "/static/%252e%252e%252f%252e%252e%252fetc%252fpasswd", "/static/%25252e%25252e%25252fx",
    "/static/..\\..\\pyproject.toml", "/static/%5c..%5cpyproject.toml", "/packs/..",
    "/api/packs/%2e%2e", "/static/app.css%00.png",
])
def test_path_traversal_is_refused_in_every_encoding(server, path):
    status, data, _ = server.request("GET", path)
    assert status == 400, (status, data)
    assert "path" in data["error"]
    assert server.alive()


def test_path_problem_decodes_repeatedly():
    assert path_problem("/static/app.css") is None
    assert path_problem("/packs/pack%20one") is None
    assert path_problem("/a/%2525252e%2525252e/b")


def test_only_the_apps_own_files_are_served(server):
    status, body, _ = server.request("GET", "/static/app.css")
    assert status == 200 and "font" in body
    for path in ("/static/pyproject.toml", "/static/live.html", "/static/__init__.py",
                 "/static/", "/nothing-here", "/api/nothing"):
        status, data, _ = server.request("GET", path)
        assert status == 404 and data["error"], path
    status, data, _ = server.request("DELETE", "/api/live")
    assert status == 405 and "DELETE is not allowed" in data["error"]
    assert server.alive()


def test_bad_uploads_get_a_clear_4xx(server):
    body, ctype = multipart({"pack": "p1"}, {"file": ("run.csv", b"x" * 60_000)})
    status, data, _ = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
    assert status == 413 and "over the limit of 50000 bytes" in data["error"]
    status, data, _ = server.request("POST", "/api/upload", b"just bytes",
                                     {"Content-Type": "text/plain"})
    assert status == 400 and "multipart/form-data" in data["error"]
    status, data, _ = server.request(
        "POST", "/api/upload", b"--b\r\nContent-Disposition: form-data; name=\"file\"\r\n\r\nx",
        {"Content-Type": "multipart/form-data; boundary=b"})
    assert status == 400
    body, ctype = multipart({}, {"file": ("run.csv", b"time_s,voltage_V\n0,4\n")})
    status, data, _ = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
    assert status == 400 and "'pack'" in data["error"]
    body, ctype = multipart({"pack": "p1"}, {})
    status, data, _ = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
    assert status == 400 and "'file'" in data["error"]
    body, ctype = multipart({"pack": "a/b"}, {"file": ("run.csv", b"1,2\n")})
    status, data, _ = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
    assert status == 400 and "pack name" in data["error"]
    assert server.alive()


def _upload_until(server, body, ctype, done, timeout_s=10):
    """POST ``body`` to /api/upload every 0.1 s until ``done(status)`` or ``timeout_s`` [s]
    has passed; returns the last status and JSON answer."""
    deadline = time.monotonic() + timeout_s
    while True:
        status, data, _ = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
        if done(status) or time.monotonic() > deadline:
            return status, data
        time.sleep(0.1)


def test_uploads_beyond_two_at_once_are_told_to_try_again(server):
    MAX_CONCURRENT_UPLOADS = Limits().max_uploads
    csv = b"time_s,current_A,voltage_V\n" + b"".join(
        b"%d,1.0,%.3f\n" % (k, 4.1 - 0.001 * k) for k in range(600))
    body, ctype = multipart({"pack": "p1"}, {"file": ("run.csv", csv)})
    held = []
    for _ in range(MAX_CONCURRENT_UPLOADS):     # uploads that send half their body and wait
        sock = socket.create_connection((server.host, server.port), timeout=20)
        sock.sendall(b"POST /api/upload HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                     b"Content-Type: " + ctype.encode() + b"\r\n"
                     b"Content-Length: %d\r\n\r\n" % len(body) + body[: len(body) // 2])
        held.append(sock)
    try:
        # a third is refused once the server has started reading both
        status, data = _upload_until(server, body, ctype, lambda status: status == 503)
        assert status == 503 and "try again" in data["error"], (status, data)
        held[0].sendall(body[len(body) // 2:])  # one finishes: its answer is a stored file
        reply = held[0].recv(65536)
        assert reply.startswith(b"HTTP/1.1 200"), reply[:200]
    finally:
        for sock in held:
            sock.close()
    # the abandoned upload frees its place: the next one is read
    status, data = _upload_until(server, body, ctype, lambda status: status != 503)
    assert status == 200 and data["skipped"], (status, data)   # the first one stored it
    assert server.alive()


def test_other_sites_and_other_host_names_are_refused(server):
    status, data, _ = server.request("POST", "/api/live/stop", b"{}",
                                     {"Origin": "http://evil.example"})
    assert status == 403 and "another site" in data["error"]
    status, data, _ = server.request("GET", "/api/live", headers={"Host": "evil.example:80"})
    assert status == 421
    status, data, _ = server.request("POST", "/api/live/start", b"[1, 2]",
                                     {"Content-Type": "application/json"})
    assert status == 409 or status == 400
    assert server.alive()


def test_behind_a_proxy_the_public_name_is_answered(tmp_path):
    srv = ThreadServer(db=str(tmp_path / "lb.sqlite"), public_hosts=["dl.example.org"])
    try:
        status, data, _ = srv.request("GET", "/api/live", headers={"Host": "dl.example.org"})
        assert status == 200 and "active" in data
        status, data, _ = srv.request("POST", "/api/live/stop", b"{}", {
            "Host": "dl.example.org", "Origin": "https://dl.example.org"})
        assert status == 409 and "no test is running" in data["error"]   # past the guard
        status, data, _ = srv.request("POST", "/api/live/stop", b"{}", {
            "Host": "dl.example.org", "Origin": "https://evil.example"})
        assert status == 403
        status, data, _ = srv.request("GET", "/api/live", headers={"Host": "evil.example"})
        assert status == 421
    finally:
        srv.server.stop()


def test_listening_beyond_loopback_needs_a_token():
    with pytest.raises(DischargelabError, match="give it a token"):
        check_bind("0.0.0.0", None)
    with pytest.raises(DischargelabError, match="give it a token"):
        build_server(host="0.0.0.0", port=0)
    check_bind("0.0.0.0", "a-long-secret.token")
    check_bind("127.0.0.1", None)
    check_bind("::1", None)
    for bad in ("short", "has;semicolon-in-it", "has space in it", "euro-\u20ac-token-x"):
        with pytest.raises(DischargelabError, match="the token must be 12-200 letters"):
            check_bind("0.0.0.0", bad)


@pytest.mark.parametrize("file_name", ["..", ".", "a\x01b.csv", "\u00e9" * 200 + ".csv",
                                       "C:\\logs\\..\\run.csv"])
def test_upload_names_no_file_system_takes_are_made_safe(server, file_name):
    body, ctype = multipart({"pack": "p1"}, {"file": (file_name, b"not a log at all\n")})
    status, data, _ = server.request("POST", "/api/upload", body, {"Content-Type": ctype})
    assert status == 422 and "has a header but no data rows" in data["error"], (status, data)
    assert server.alive()


def test_demo_start_settings_refuse_infinities_and_server_files(tmp_path):
    from dischargelab.errors import DataError
    from dischargelab.web.bench import DemoBench, parse_demo_settings

    for settings in ({"cells": 1e400}, {"debounce": float("inf")}, {"c_rate": float("nan")}):
        with pytest.raises(DataError, match="must be a"):
            parse_demo_settings(settings)
    bench = DemoBench(tmp_path / "runs")
    with pytest.raises(DataError, match="battery must be one of the presets"):
        bench.start({"battery": str(tmp_path / "battery.json")})
    assert not bench.running


def test_a_token_is_needed_on_every_request_when_given(tmp_path):
    srv = ThreadServer(db=str(tmp_path / "lb.sqlite"), token="s3cret-token")
    try:
        status, data, _ = srv.request("GET", "/api/live")
        assert status == 401 and "token" in data["error"]
        status, data, _ = srv.request("GET", "/api/live",
                                      headers={"Authorization": "Bearer wrong"})
        assert status == 401
        status, data, _ = srv.request("GET", "/api/live",
                                      headers={"Authorization": "Bearer s3cret-token"})
        assert status == 200
        status, _, cookie = srv.request("GET", "/live?token=s3cret-token")
        assert status == 200 and "dl_token=s3cret-token" in cookie and "HttpOnly" in cookie
        status, data, _ = srv.request("GET", "/api/live",
                                      headers={"Cookie": "dl_token=s3cret-token"})
        assert status == 200
    finally:
        srv.server.stop()


def test_a_busy_port_is_one_clear_line(tmp_path):
    first = ThreadServer(db=str(tmp_path / "lb.sqlite"))
    try:
        with pytest.raises(DischargelabError, match=f"port {first.port} on 127.0.0.1 is in use"):
            Server(object(), "127.0.0.1", first.port)
    finally:
        first.server.stop()


# ---------------------------------------------------------------------- live hub

def _samples(n, start=0):
    return [Sample(time_s=0.1 * k, voltage_V=8.0 - 1e-4 * k, current_A=1.0, seq=k)
            for k in range(start, start + n)]


def test_hub_never_waits_for_a_subscriber_and_resyncs_one_that_fell_behind():
    async def scenario():
        hub = LiveHub(ring_samples=1000, subscriber_samples=50)
        hub.begin({"out": "x.csv"}, cells_series=2, cutoff_pack_V=6.0)
        sub = hub.subscribe(asyncio.get_running_loop())
        kind, snap = hub.take(sub)
        assert kind == "snapshot" and snap["samples"] == []
        t0 = time.perf_counter()
        for s in _samples(40):
            hub.handle(s)
        kind, got = hub.take(sub)
        assert kind == "samples" and [r[0] for r in got["samples"]] == list(range(40))
        for s in _samples(300, 40):          # the page reads nothing: its queue overflows
            hub.handle(s)
        elapsed = time.perf_counter() - t0
        kind, got = hub.take(sub)            # resync: the whole ring, nothing missing
        assert kind == "snapshot"
        assert [r[0] for r in got["samples"]] == list(range(340))
        assert got["samples"][-1][9] == 339 and got["samples"][1][3] == pytest.approx(
            (8.0 - 1e-4) / 2)
        assert hub.take(sub) is None
        hub.handle(_samples(1, 340)[0])
        kind, got = hub.take(sub)
        assert kind == "samples" and got["samples"][0][0] == 340
        assert elapsed < 10.0                # a hang, not a timing: 340 samples, no reader
        hub.unsubscribe(sub)
        assert hub.subscribers == 0

    asyncio.run(scenario())


def test_hub_resyncs_a_subscriber_whose_events_pile_up():
    async def scenario():
        hub = LiveHub(ring_samples=1000, subscriber_samples=50)
        hub.begin({})
        sub = hub.subscribe(asyncio.get_running_loop())
        hub.take(sub)
        for k in range(RING_EVENTS + 5):     # a noisy link, a page that reads nothing
            hub.event("gap", frames=k)
        assert len(sub.events) <= RING_EVENTS
        kind, got = hub.take(sub)
        assert kind == "snapshot" and len(got["events"]) == RING_EVENTS
        assert got["events"][-1]["frames"] == RING_EVENTS + 4

    asyncio.run(scenario())


def test_hub_history_is_bounded_and_says_where_it_starts():
    async def scenario():
        hub = LiveHub(ring_samples=100, subscriber_samples=10)
        hub.begin({})
        for s in _samples(250):
            hub.handle(s)
        sub = hub.subscribe(asyncio.get_running_loop())
        kind, snap = hub.take(sub)
        assert snap["first_n"] == 150 and len(snap["samples"]) == 100

    asyncio.run(scenario())


def test_importing_dischargelab_does_not_import_the_web_stack():
    code = ("import sys, dischargelab; bad = [m for m in sys.modules if m.split('.')[0] in "
            "('starlette', 'uvicorn', 'python_multipart', 'multipart', 'anyio', "
            "'dischargelab.web')]; print(bad); assert not bad")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_limits_refuse_nonsense_in_one_line():
    from dischargelab.errors import DataError

    assert Limits().header_timeout_s == 10.0 and Limits().max_uploads == 2
    for bad, words in (({"header_timeout_s": 0}, "header_timeout_s must be a positive"),
                       ({"body_min_rate_Bps": float("nan")}, "bytes/s"),
                       ({"max_connections": 0}, "max_connections must be a whole number >= 1"),
                       ({"read_threads": 2.5}, "read_threads must be a whole number"),
                       ({"max_uploads": True}, "max_uploads must be a whole number")):
        with pytest.raises(DataError, match=words):
            Limits(**bad)


def test_the_open_file_limit_is_raised_to_fit_the_connections_or_said():
    code = ("import resource; from dischargelab.web.server import open_files_for\n"
            "from dischargelab.errors import DischargelabError\n"
            "resource.setrlimit(resource.RLIMIT_NOFILE, (200, 400))\n"
            "open_files_for(300)\n"
            "assert resource.getrlimit(resource.RLIMIT_NOFILE)[0] == 364\n"
            "try:\n    open_files_for(1000)\nexcept DischargelabError as exc:\n"
            "    print(exc)\nelse:\n    raise SystemExit('not refused')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert "1000 connections need 1064 open files, and this system allows 400" in done.stdout
    assert "lower max_connections to 336" in done.stdout and "ulimit -n" in done.stdout
