"""The browser server under a team's load: readers, uploads and idle half-open connections.

A logbook of 10 packs is built from ../shared/data (Samsung 30Q cell C's ageing files but
eight, the DJI M100 flights, the K2 LFP and 30Q rate tests, the Enertech LCO curves, the
PX4, Betaflight, ArduPilot and INA3221 flight logs). The real command ``dischargelab serve``
runs on it in a separate process (127.0.0.1, a free port). Then, at once, for --seconds:

- --readers clients read the API as the pages do, each one request after the other on a
  kept-alive connection: ``GET /api/packs`` and ``GET /api/packs/NAME`` in turn, NAME
  cycling through the packs (``--mix light`` reads the server's own answers instead:
  a page, a script and ``/api/missions``, to show the server apart from the logbook);
- the eight held-out cell C files are uploaded to "cell C", one every seconds/8, each
  sent again after a 503 until it is taken;
- --idle connections each send half a request line and wait; when the server closes one,
  another opens at once, so that --idle are held all along;
- once a second a new connection asks for the pack list page (``GET /``): the latency of
  a request made during the idle connections.

Printed: requests done and failed (an error status, a time-out of --request-timeout, a
closed connection), latency p50/p99 per request kind and over all, each upload's result and
how many times its file is stored, how long the server let an idle connection live, and the
server's resident memory (RSS) growth over the run (sampled every 0.2 s from
/proc/PID/status, against the RSS after one warm-up request of each kind and one upload
of a small file to "K2 LFP", once the server is idle). To tell the
server from the logbook, the same reads are also timed in this process on one thread
(``compute alone``): what each request costs before any waiting.

Usage: python benchmarks/server_load.py [--readers 64] [--seconds 20] [--idle 200]
       [--mix api|light] [--db PATH] [--cell-c N]
"""

from __future__ import annotations

import argparse
import http.client
import itertools
import json
import os
import selectors
import shutil
import socket
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT / "tests"))

from _machine import machine_line, shared_data, table  # noqa: E402
from web_helpers import ServerProcess, multipart  # noqa: E402

SHARED = shared_data()
CELL_C = SHARED / "samsung30q_ageing_cellC"
#: Cycles of cell C held out of the logbook and uploaded during the run.
UPLOADED = (600, 610, 620, 630, 640, 650, 660, 664)
#: A file uploaded before the run (to pack "K2 LFP"), so that its imports are not counted.
WARM_UPLOAD = ROOT / "tests" / "data" / "k2_lfp26650_20C_excerpt.lvm"
#: Pause before an upload answered 503 is sent again [s].
RETRY_S = 0.5
#: Half a request line: what an idle client sends before it stops.
HALF_LINE = b"GET /api/pac"
#: Longest the run waits for the requests still open at its end [s].
DRAIN_S = 300.0


def build_logbook(path: Path, cell_c_files: int | None = None) -> list[str]:
    """The 10-pack logbook (see the module docstring); returns the pack names."""
    from dischargelab.logbook import Logbook

    flights = SHARED / "flight_logs"
    held = {f"DischargeCycle{c:03d}.txt" for c in UPLOADED}
    cell_c = [p for p in sorted(CELL_C.glob("DischargeCycle*.txt")) if p.name not in held]
    if cell_c_files:
        cell_c = cell_c[:: max(1, len(cell_c) // cell_c_files)][:cell_c_files]
    enertech = SHARED / "enertech_lco"
    with Logbook(path) as lb:
        lb.set_pack("cell C", chemistry="li-ion", cells=1)
        lb.add(cell_c, pack="cell C")
        lb.set_pack("M100 6S", label_capacity_Ah=5.7, chemistry="lipo", cells=6)
        lb.add(sorted((SHARED / "dji_m100_flights").glob("derived_battery_*.csv")),
               pack="M100 6S")
        lb.set_pack("K2 LFP", chemistry="lifepo4", cells=1)
        lb.add(sorted((SHARED / "k2_lfp26650").glob("K2_*.txt")), pack="K2 LFP")
        lb.set_pack("30Q S001", chemistry="li-ion", cells=1)
        lb.add(sorted((SHARED / "samsung30q_S001").glob("Q30_*.csv")), pack="30Q S001",
               columns={"time_s": 0, "current_A": 1, "voltage_V": 2, "temperature_C": 4})
        for rate, amps in (("0.1C", 0.228), ("0.5C", 1.14), ("1C", 2.28), ("2C", 4.56)):
            lb.add(enertech / f"{rate}_discharge_U.txt", pack="Enertech LCO", current_A=amps)
        lb.set_pack("FPV 4S", chemistry="lipo", cells=4)
        lb.add(sorted((flights / "ina3221_fpv_4s").glob("*.csv")), pack="FPV 4S")
        lb.add(flights / "pyulog_sample" / "sample_log_small.ulg", pack="PX4 sample")
        lb.add(flights / "px4_ulog_rs" / "esc_status_log.ulg", pack="PX4 ESC")
        lb.add(flights / "betaflight_diatone" / "btfl_001.bbl", pack="Diatone")
        lb.add(flights / "ardupilot_loganalyzer" / "mechanical_fail.log", pack="ArduPilot")
        packs = lb.pack_names()
        empty = [name for name in packs if not lb.events(name).to_dict().get("events")]
    if len(packs) != 10 or empty:
        raise SystemExit(f"the logbook should hold 10 packs with events; got {packs} "
                         f"(empty: {empty}); is {SHARED} the shared data folder?")
    return packs


def compute_alone(db: Path, packs: list[str]) -> dict:
    """Seconds per read, in this process on one thread (the web layer's own calls)."""
    from dischargelab.web.limits import Limits
    from dischargelab.web.packs import PackPages
    from dischargelab.web.work import Workers

    pages = PackPages(str(db), limits=Limits(), workers=Workers(Limits()))
    try:
        t0 = time.perf_counter()
        pages.logbook().packs().to_dict()
        t_list = time.perf_counter() - t0
        per_pack = []
        for name in packs:
            t0 = time.perf_counter()
            pages._pack_detail(name)
            per_pack.append(time.perf_counter() - t0)
    finally:
        pages.close()
        pages.workers.close()
    return {"list": t_list, "pack_mean": statistics.mean(per_pack), "pack_max": max(per_pack)}


def cpu_s(pid: int) -> float:
    """CPU time a process has used so far [s] (user + system)."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def wait_idle(pid: int, bound_s: float = 300.0) -> None:
    """Until the process uses under 2 % of a core for a second (work it started in the
    background, such as recomputing figures after an upload, has ended)."""
    deadline = time.monotonic() + bound_s
    last = cpu_s(pid)
    while time.monotonic() < deadline:
        time.sleep(1.0)
        now = cpu_s(pid)
        if now - last < 0.02:
            return
        last = now


def rss_MB(pid: int) -> float:
    with open(f"/proc/{pid}/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


class Clock:
    """The run's end time and a stop flag shared by every thread."""

    def __init__(self, seconds: float):
        self.start = time.monotonic()
        self.end = self.start + seconds
        self.stop = threading.Event()

    def running(self) -> bool:
        return time.monotonic() < self.end and not self.stop.is_set()


def reader(host, port, paths, clock: Clock, timeout_s: float, out: list) -> None:
    """One client: requests one after the other on a kept-alive connection."""
    conn = None
    for kind, path in paths:
        if not clock.running():
            break
        t0 = time.perf_counter()
        try:
            if conn is None:
                conn = http.client.HTTPConnection(host, port, timeout=timeout_s)
            conn.request("GET", path)
            resp = conn.getresponse()
            resp.read()
            ok = resp.status == 200
            detail = str(resp.status)
            if resp.getheader("connection", "").lower() == "close":
                conn.close()
                conn = None
        except (OSError, http.client.HTTPException) as exc:
            ok, detail = False, type(exc).__name__
            if conn is not None:
                conn.close()
            conn = None
        out.append((kind, time.perf_counter() - t0, ok, detail))
    if conn is not None:
        conn.close()


def upload(host, port, path: Path, at_s: float, clock: Clock, timeout_s: float,
           out: dict) -> None:
    """Send one file to "cell C" at ``at_s`` after the start, again after each 503."""
    body, ctype = multipart({"pack": "cell C"}, {"file": (path.name, path.read_bytes())})
    time.sleep(max(0.0, clock.start + at_s - time.monotonic()))
    tries, t0 = 0, time.perf_counter()
    while True:
        tries += 1
        try:
            conn = http.client.HTTPConnection(host, port, timeout=timeout_s)
            conn.request("POST", "/api/upload", body, {"Content-Type": ctype})
            resp = conn.getresponse()
            status, data = resp.status, resp.read()
            conn.close()
        except (OSError, http.client.HTTPException) as exc:
            status, data = 0, type(exc).__name__.encode()
        if status != 503 or time.monotonic() > clock.end + DRAIN_S:
            break
        time.sleep(RETRY_S)
    try:
        answer = json.loads(data)
    except ValueError:
        answer = {"error": data[:200].decode("utf-8", "replace")}
    out[path.name] = {"status": status, "tries": tries, "seconds": time.perf_counter() - t0,
                      "added": answer.get("added", []), "error": answer.get("error")}


def hold_idle(host, port, count: int, clock: Clock, out: dict) -> None:
    """Keep ``count`` half-open connections until the run ends; reopen those the server
    closes, and record how long each lived."""
    sel = selectors.DefaultSelector()

    def open_one():
        try:
            sock = socket.create_connection((host, port), timeout=10)
            sock.sendall(HALF_LINE)
            sock.setblocking(False)
            sel.register(sock, selectors.EVENT_READ, time.monotonic())
            out["opened"] += 1
        except OSError:
            out["failed_to_open"] += 1

    for _ in range(count):
        open_one()
    out["held_at_start"] = len(sel.get_map())
    while clock.running():
        for key, _ in sel.select(timeout=0.1):
            sock = key.fileobj
            try:
                data = sock.recv(4096)
            except OSError:
                data = b""
            if data.startswith(b"HTTP/1.1 408"):
                out["answered_408"] += 1
            sel.unregister(sock)
            sock.close()
            out["lived_s"].append(time.monotonic() - key.data)
            if clock.running():
                open_one()
        out["least_held"] = min(out["least_held"], len(sel.get_map()))
    for key in list(sel.get_map().values()):
        sel.unregister(key.fileobj)
        key.fileobj.close()


def probe(host, port, clock: Clock, timeout_s: float, out: list) -> None:
    """Once a second, a new connection asks for the pack list page."""
    while clock.running():
        t0 = time.perf_counter()
        try:
            conn = http.client.HTTPConnection(host, port, timeout=timeout_s)
            conn.request("GET", "/")
            resp = conn.getresponse()
            resp.read()
            conn.close()
            out.append((time.perf_counter() - t0, resp.status == 200))
        except (OSError, http.client.HTTPException):
            out.append((time.perf_counter() - t0, False))
        time.sleep(max(0.0, 1.0 - (time.perf_counter() - t0)))


def sample_rss(pid: int, clock: Clock, out: list) -> None:
    while not clock.stop.is_set():
        try:
            out.append(rss_MB(pid))
        except OSError:
            return
        time.sleep(0.2)


def reads_for(mix: str, packs: list[str], offset: int):
    """The endless request sequence of one reader: (kind, path)."""
    from urllib.parse import quote

    if mix == "light":
        cycle = [("page", "/"), ("script", "/static/common.js"), ("missions", "/api/missions")]
    else:
        names = packs[offset % len(packs):] + packs[:offset % len(packs)]
        cycle = []
        for name in names:
            cycle += [("/api/packs", "/api/packs"),
                      ("/api/packs/NAME", f"/api/packs/{quote(name, safe='')}")]
    return itertools.cycle(cycle)


def pct(values, q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100.0 * (len(ordered) - 1))))]


def stored_times(db: Path, names: list[str]) -> dict:
    """How many times each file name is stored in the logbook (its sources)."""
    import sqlite3

    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        return {name: con.execute("SELECT COUNT(*) FROM sources WHERE file_name = ?",
                                  (name,)).fetchone()[0] for name in names}
    finally:
        con.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--readers", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--idle", type=int, default=200)
    parser.add_argument("--uploads", type=int, default=len(UPLOADED))
    parser.add_argument("--mix", choices=("api", "light"), default="api")
    parser.add_argument("--request-timeout", type=float, default=60.0,
                        help="a request not answered within this is a failure [s]")
    parser.add_argument("--db", type=Path, help="use (a copy of) this logbook instead")
    parser.add_argument("--cell-c", type=int, default=None,
                        help="cell C files in the logbook (default: all but the uploaded)")
    parser.add_argument("--serve-args", default="", help="more options for the server")
    args = parser.parse_args()

    work = Path(tempfile.mkdtemp(prefix="dl-server-load-"))
    server = None
    try:
        db = work / "logbook.sqlite"
        t0 = time.perf_counter()
        if args.db:
            shutil.copy(args.db, db)
            from dischargelab.logbook import Logbook

            with Logbook(db) as lb:
                packs = lb.pack_names()
        else:
            packs = build_logbook(db, args.cell_c)
        print(f"logbook: {len(packs)} packs ({', '.join(packs)}), built in "
              f"{time.perf_counter() - t0:.0f} s")
        alone = compute_alone(db, packs) if args.mix == "api" else None
        server = ServerProcess(["serve", "--db", str(db), "--port", "0",
                                *args.serve_args.split()])
        host, port, pid = server.host, server.port, server.proc.pid
        # warm-up: each kind of request once (the first imports the readers and the
        # physics), so that the memory growth is the run's, not the imports'
        warm = [path for _, path in itertools.islice(reads_for("api", packs, 0), 2)]
        warm += [path for _, path in itertools.islice(reads_for("light", packs, 0), 3)]
        for path in warm:
            status, _ = server.request("GET", path, timeout_s=DRAIN_S)
            assert status == 200, (path, status)
        body, ctype = multipart({"pack": "K2 LFP"}, {"file": (WARM_UPLOAD.name,
                                                              WARM_UPLOAD.read_bytes())})
        status, _ = server.request("POST", "/api/upload", body, {"Content-Type": ctype},
                                   timeout_s=DRAIN_S)
        assert status == 200, status
        wait_idle(pid)
        base_rss = rss_MB(pid)

        clock = Clock(args.seconds)
        results: list = []
        uploads: dict = {}
        idle = {"opened": 0, "failed_to_open": 0, "answered_408": 0, "lived_s": [],
                "least_held": args.idle, "held_at_start": 0}
        probes: list = []
        rss: list = []
        files = [CELL_C / f"DischargeCycle{c:03d}.txt" for c in UPLOADED[:args.uploads]]
        threads = [threading.Thread(target=sample_rss, args=(pid, clock, rss), daemon=True),
                   threading.Thread(target=hold_idle, args=(host, port, args.idle, clock, idle),
                                    daemon=True)]
        threads += [threading.Thread(target=reader, daemon=True, args=(
            host, port, reads_for(args.mix, packs, k), clock, args.request_timeout, results))
            for k in range(args.readers)]
        spacing = args.seconds / max(1, len(files))
        threads += [threading.Thread(target=upload, daemon=True, args=(
            host, port, path, k * spacing, clock, args.request_timeout, uploads))
            for k, path in enumerate(files)]
        threads.append(threading.Thread(target=probe, daemon=True,
                                        args=(host, port, clock, args.request_timeout, probes)))
        for th in threads:
            th.start()
        time.sleep(args.seconds)
        for th in threads[1:]:
            th.join(max(0.0, clock.end + DRAIN_S - time.monotonic()))
        clock.stop.set()
        threads[0].join(5)
        alive = server.alive
        load = os.getloadavg()
        server.stop()
        server = None

        done = list(results)
        failed = [r for r in done if not r[2]]
        rows = []
        for kind in sorted({r[0] for r in done}):
            lat = [r[1] for r in done if r[0] == kind]
            rows.append([kind, len(lat), sum(1 for r in done if r[0] == kind and not r[2]),
                         f"{pct(lat, 50):.3f}", f"{pct(lat, 99):.3f}", f"{max(lat):.3f}"])
        lat = [r[1] for r in done]
        rows.append(["all", len(lat), len(failed), f"{pct(lat, 50):.3f}", f"{pct(lat, 99):.3f}",
                     f"{max(lat) if lat else float('nan'):.3f}"])
        table(f"Reads: {args.readers} readers for {args.seconds:g} s, mix {args.mix!r} "
              f"({len(packs)} packs)", ["request", "done", "failed", "p50 [s]", "p99 [s]",
                                        "max [s]"], rows)
        if failed:
            kinds = {}
            for r in failed:
                kinds[r[3]] = kinds.get(r[3], 0) + 1
            print("failures: " + ", ".join(f"{k} x{v}" for k, v in sorted(kinds.items())))

        times = stored_times(db, [p.name for p in files])
        table(f"Uploads to 'cell C' (one every {spacing:.1f} s, sent again after each 503)",
              ["file", "status", "tries", "seconds", "stored (times)"],
              [[name, u["status"], u["tries"], f"{u['seconds']:.2f}", times.get(name)]
               for name, u in sorted(uploads.items())])
        once = sum(1 for name in times if times[name] == 1)
        lived = idle["lived_s"]
        probe_lat = [p[0] for p in probes]
        table("Acceptance", ["figure", "measured", "goal"], [
            ["failed requests", f"{len(failed)} of {len(done)}", "0"],
            ["p50 / p99 latency, all reads [s]", f"{pct(lat, 50):.3f} / {pct(lat, 99):.3f}",
             "p99 <= 2"],
            ["uploads stored exactly once", f"{once} of {len(files)}", f"{len(files)}"],
            ["request during the idle connections: max [s]",
             f"{max(probe_lat) if probe_lat else float('nan'):.3f} "
             f"({sum(1 for p in probes if p[1])} of {len(probes)} answered)", "<= 2"],
            ["idle connections held (least / asked)", f"{idle['least_held']} / {args.idle}",
             ""],
            ["idle connections closed by the server", f"{len(lived)} (408: "
             f"{idle['answered_408']}), lived median {pct(lived, 50):.1f} s", "header time-out"],
            ["server RSS growth: peak / end [MB]",
             f"{max(rss) - base_rss:.1f} / {rss[-1] - base_rss:.1f} (base {base_rss:.0f})",
             "<= 100"],
            ["server alive at the end", "yes" if alive else "NO", "yes"],
        ])
        if alone:
            print(f"\ncompute alone (this process, one thread): /api/packs {alone['list']:.3f} s;"
                  f" /api/packs/NAME mean {alone['pack_mean']:.3f} s, slowest "
                  f"{alone['pack_max']:.3f} s")
        print(f"\nload average during the run: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
        print(machine_line())
    finally:
        if server is not None:
            server.stop()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
