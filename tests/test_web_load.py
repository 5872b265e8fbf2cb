"""The server holds slow, idle and many clients: time-outs, caps, uploads under load.

Each test runs the real ``dischargelab serve`` in a subprocess on 127.0.0.1 (a free port),
ended by its process id. They check what is answered and what is stored, not how fast:
every wait has a bound so that nothing hangs, and timings are never asserted.
"""

from __future__ import annotations

import hashlib
import socket
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("sqlalchemy")
pytest.importorskip("starlette")

import dischargelab as dl
from web_helpers import ServerProcess, multipart, raw_request

#: Head and body time-outs of the test servers [s] (short, so the tests are short).
HEAD_S = 1.0
BODY_S = 1.0
#: Longest any socket operation of a test may wait [s] (a hang bound, not a timing).
WAIT_S = 60.0
CELL_C = "samsung30q_ageing_cellC"


def cell_c(shared_data: Path, cycle: int) -> Path:
    return shared_data / CELL_C / f"DischargeCycle{cycle:03d}.txt"


def half_open(server, data: bytes = b"GET /api/pac", source: str = "127.0.0.1"):
    """A connection that sends ``data`` (half a request line) and waits."""
    sock = socket.create_connection((server.host, server.port), timeout=WAIT_S,
                                    source_address=(source, 0))
    if data:
        sock.sendall(data)
    return sock


def read_all(sock) -> bytes:
    """Everything the server sends until it closes the connection (bounded by WAIT_S)."""
    chunks = []
    while True:
        try:
            chunk = sock.recv(65536)
        except ConnectionResetError:
            break
        if not chunk:
            break
        chunks.append(chunk)
    sock.close()
    return b"".join(chunks)


def vm(pid: int, key: str) -> float:
    """``VmRSS`` / ``VmHWM`` of a process [MB]."""
    with open(f"/proc/{pid}/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024.0
    raise AssertionError(f"no {key} in /proc/{pid}/status")


@pytest.fixture(scope="module")
def timed_server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("timeouts")
    srv = ServerProcess(["serve", "--db", str(folder / "logbook.sqlite"), "--port", "0",
                         "--header-timeout", str(HEAD_S), "--body-timeout", str(BODY_S),
                         "--max-upload", "64"], cwd=folder)
    yield srv
    srv.stop()


def test_idle_and_half_sent_connections_are_closed_after_the_head_timeout(timed_server):
    silent = [half_open(timed_server, b"") for _ in range(10)]
    half = [half_open(timed_server) for _ in range(10)]
    # a request made while they are held is answered
    status, data = timed_server.request("GET", "/api/missions", timeout_s=WAIT_S)
    assert status == 200 and "paper-table5" in data["missions"]
    for sock in silent:                       # nothing sent: closed without an answer
        assert read_all(sock) == b""
    for sock in half:                         # half a request: 408 and closed
        answer = read_all(sock)
        assert answer.startswith(b"HTTP/1.1 408 "), answer[:80]
        assert b"connection: close" in answer.lower()
        assert b'"the request head did not arrive within 1 s' in answer
    # a kept-alive connection whose next request stops half way is closed the same way
    sock = half_open(timed_server, b"GET /api/missions HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
                                   b"GET /api/miss")
    answer = read_all(sock)
    assert answer.startswith(b"HTTP/1.1 200 ") and b"HTTP/1.1 408 " in answer
    assert timed_server.alive


def test_a_body_slower_than_the_minimum_rate_is_cut_off(timed_server):
    # an upload whose body comes a byte at a time: 408, the connection closed
    sock = half_open(timed_server, b"POST /api/upload HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                   b"Content-Type: multipart/form-data; boundary=b\r\n"
                                   b"Content-Length: 100000\r\n\r\n--b\r\n")
    answer = b""
    try:
        for _ in range(int(WAIT_S / 0.1)):
            sock.sendall(b"x")
            time.sleep(0.1)
    except OSError:                            # the server has closed it
        pass
    answer = read_all(sock)
    assert answer.startswith(b"HTTP/1.1 408 "), answer[:80]
    assert b"the request body came slower than 500 bytes/s" in answer
    assert b"connection: close" in answer.lower()
    # a JSON body that stops half way
    sock = half_open(timed_server, b"POST /api/live/start HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                                   b"Content-Type: application/json\r\n"
                                   b"Content-Length: 40\r\n\r\n{\"speed\":")
    answer = read_all(sock)
    assert answer.startswith(b"HTTP/1.1 408 "), answer[:80]
    # the upload places they held are free again: a real upload is read and stored
    body, ctype = multipart({"pack": "p"}, {"file": ("run.csv", b"time_s,current_A,voltage_V\n"
                                                    + b"".join(b"%d,1.0,%.3f\n" % (k, 4.1 - k / 1e3)
                                                               for k in range(300)))})
    status, data = timed_server.request("POST", "/api/upload", body, {"Content-Type": ctype},
                                        timeout_s=WAIT_S)
    assert status == 200 and data["added"] == ["run.csv"], (status, data)
    assert timed_server.alive


def test_an_upload_is_streamed_not_held_in_memory(timed_server):
    pid = timed_server.proc.pid
    size = 48 * 1024 * 1024
    body, ctype = multipart({"pack": "a/b"}, {"file": ("big.csv", b"1,2,3\n" * (size // 6))})
    timed_server.request("GET", "/api/missions")
    with open(f"/proc/{pid}/clear_refs", "w", encoding="ascii") as fh:
        fh.write("5")                          # the peak RSS starts again from now
    before = vm(pid, "VmRSS")
    status, data = timed_server.request("POST", "/api/upload", body, {"Content-Type": ctype},
                                        timeout_s=WAIT_S)
    growth = vm(pid, "VmHWM") - before
    assert status == 400 and "pack name" in data["error"]   # read whole, refused at the end
    # the body held once would be 48 MB; streamed to a file it is a few chunks
    assert growth < 16, f"the server grew by {growth:.1f} MB while receiving 48 MB"


def test_connection_caps_answer_and_free_up(tmp_path):
    srv = ServerProcess(["serve", "--db", str(tmp_path / "logbook.sqlite"), "--port", "0",
                         "--max-connections", "30", "--max-per-client", "20"], cwd=tmp_path)
    held = []
    try:
        held += [half_open(srv) for _ in range(20)]
        answer = read_all(half_open(srv))       # the 21st from 127.0.0.1
        assert answer.startswith(b"HTTP/1.1 429 ") and b"this address holds" in answer
        held += [half_open(srv, source="127.0.0.2") for _ in range(10)]
        answer = read_all(half_open(srv, source="127.0.0.2"))   # the 31st in all
        assert answer.startswith(b"HTTP/1.1 503 ") and b"maximum of 30 connections" in answer
        for sock in held[:5]:
            sock.close()
        deadline = time.monotonic() + WAIT_S    # the server sees the closes, then answers
        while True:
            status, _, _ = raw_request(srv.host, srv.port, "GET", "/api/missions",
                                       timeout_s=WAIT_S)
            if status == 200 or time.monotonic() > deadline:
                break
            time.sleep(0.1)
        assert status == 200
    finally:
        for sock in held:
            sock.close()
        srv.stop()


@pytest.mark.slow
def test_readers_uploads_and_idle_connections_together(tmp_path, shared_data):
    """32 readers, 4 uploads (each sent again after a 503) and 100 half-open connections,
    held for a few head time-outs: every read answered, each upload stored once, the idle
    connections closed, a request made meanwhile answered."""
    db = tmp_path / "logbook.sqlite"
    with dl.Logbook(str(db)) as lb:
        assert lb.add([cell_c(shared_data, c) for c in (1, 200, 400)], pack="cell C").events
        assert lb.add(Path(__file__).parent / "data" / "k2_lfp26650_20C_excerpt.lvm",
                      pack="K2").events
    srv = ServerProcess(["serve", "--db", str(db), "--port", "0", "--header-timeout",
                         str(HEAD_S), "--body-timeout", "5"], cwd=tmp_path)
    uploads = [cell_c(shared_data, c) for c in (500, 550, 600, 650)]
    stop = threading.Event()
    reads, answers, idle_closed = [], {}, []

    def reader(k):
        paths = ["/api/packs", "/api/packs/cell%20C", "/", "/api/packs/K2"]
        while not stop.is_set():
            path = paths[k % len(paths)]
            k += 1
            try:
                status, _, _ = raw_request(srv.host, srv.port, "GET", path, timeout_s=WAIT_S)
            except OSError as exc:
                status = repr(exc)
            reads.append((path, status))

    def upload(path):
        body, ctype = multipart({"pack": "cell C"}, {"file": (path.name, path.read_bytes())})
        deadline = time.monotonic() + WAIT_S
        while True:
            status, data, _ = raw_request(srv.host, srv.port, "POST", "/api/upload", body,
                                          {"Content-Type": ctype}, timeout_s=WAIT_S)
            if status != 503 or time.monotonic() > deadline:
                answers[path.name] = (status, data)
                return
            time.sleep(0.2)

    def idle():
        socks = [half_open(srv) for _ in range(100)]
        idle_closed.extend(read_all(s)[:12] for s in socks)

    threads = [threading.Thread(target=idle)]
    threads += [threading.Thread(target=reader, args=(k,)) for k in range(32)]
    threads += [threading.Thread(target=upload, args=(p,)) for p in uploads]
    try:
        for th in threads:
            th.start()
        time.sleep(0.5)
        status, _ = srv.request("GET", "/api/missions", timeout_s=WAIT_S)   # meanwhile
        assert status == 200
        for th in threads[:1] + threads[33:]:   # the idle ones closed, the uploads done
            th.join(WAIT_S * 2)
        stop.set()
        for th in threads[1:33]:
            th.join(WAIT_S * 2)
        assert not any(th.is_alive() for th in threads)
        assert srv.alive
    finally:
        stop.set()
        srv.stop()
    assert len(idle_closed) == 100 and set(idle_closed) == {b"HTTP/1.1 408"}
    assert reads and all(status == 200 for _, status in reads), \
        [r for r in reads if r[1] != 200][:5]
    for path in uploads:
        status, data = answers[path.name]
        assert status == 200 and data["added"] == [path.name], (status, data)
    with dl.Logbook(str(db)) as lb:
        names = [e["source"] for e in lb.events("cell C").to_dict()["events"]]
        for path in uploads:
            assert names.count(path.name) == 1
            assert lb.raw(hashlib.sha256(path.read_bytes()).hexdigest()) == path.read_bytes()
