"""Pack list and pack page latency of `dischargelab serve` at 10, 100 and 1,000 packs.

A SQLite logbook is built once and grown: ten distinct packs are added from the cell C
cycle files of ../shared/data (each a different set of :data:`EVENTS_PER_PACK` cycles
spread over the cell's life, its model fitted and stored), then copied in the database
under new names (each copy's files under hashes of their own, its events and its model
row copied) until the logbook holds the number of packs asked; every pack's figures are
then computed for real by ``Logbook.refresh`` on a local Dask cluster, as ``logbook add``
does after a write. At each size a real server process (``dischargelab serve`` on
127.0.0.1, a port of its own) is started and two requests are timed from the client over
the loopback, one after the other, from sending to the last byte received:

* ``GET /api/packs``, the pack list (every pack's row);
* ``GET /api/packs/NAME``, what a pack page shows (its health with the forecast band,
  events, model curves), for packs drawn at random.

Goals: the list <= 50 ms and a pack page <= 100 ms at 1,000 packs (median).

Usage: python benchmarks/logbook_pages.py [--sizes 10,100,1000] [--requests N]
       [--workers N] [--keep DIR]
"""

from __future__ import annotations

import argparse
import hashlib
import http.client
import os
import random
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import machine_line, shared_data

CELL_C = shared_data() / "samsung30q_ageing_cellC"
#: Events of each distinct pack (cycles spread over the life, a different set each).
EVENTS_PER_PACK = 8
DISTINCT_PACKS = 10
#: Goals of issue 24 [ms] (median).
GOAL_LIST_MS, GOAL_PAGE_MS = 50.0, 100.0


def distinct_packs(lb, packs: int, folder: Path) -> None:
    """Add ``packs`` packs of real files, each a different set of cycles (copies changed by
    trailing newlines, so each pack's files have hashes of their own), and fit them."""
    files = sorted(CELL_C.glob("DischargeCycle*.txt"))
    step = len(files) // EVENTS_PER_PACK
    for k in range(packs):
        name = f"pack-{k + 1:04d}"
        (folder / name).mkdir(parents=True)
        for f in files[k % step::step][:EVENTS_PER_PACK]:
            (folder / name / f.name).write_bytes(f.read_bytes() + b"\n" * (k + 1))
        lb.add(folder / name, pack=name, refresh=False)
        lb.fit(name, bootstrap=0)


def copy_packs(lb, total: int) -> None:
    """Copy the distinct packs' rows under new names until the logbook holds ``total``."""
    from sqlalchemy import select

    from dischargelab.logbook import schema

    names = lb.pack_names()
    originals = names[:DISTINCT_PACKS]
    p, s, e, m = schema.packs, schema.sources, schema.events, schema.models
    with schema.writing(lb._engine) as conn:
        rows = {r.name: r._asdict() for r in conn.execute(select(p))}
        for k in range(len(names), total):
            original = rows[originals[k % len(originals)]]
            name = f"pack-{k + 1:04d}"
            pid = conn.execute(p.insert().values(name=name, created_at=schema.now_iso(),
                                                 version=1).returning(p.c.id)).scalar_one()
            event_ids = {}
            for src in conn.execute(select(s).where(s.c.pack_id == original["id"])).mappings():
                sha = hashlib.sha256(f"{src['sha256']}:{name}".encode()).hexdigest()
                new_src = conn.execute(s.insert().values(
                    {**{c: src[c] for c in src if c != "id"}, "sha256": sha, "pack_id": pid})
                    .returning(s.c.id)).scalar_one()
                for ev in conn.execute(select(e).where(e.c.source_id == src["id"])).mappings():
                    event_ids[ev["id"]] = conn.execute(e.insert().values(
                        {**{c: ev[c] for c in ev if c != "id"}, "source_id": new_src,
                         "pack_id": pid}).returning(e.c.id)).scalar_one()
            for model in conn.execute(select(m).where(m.c.pack_id == original["id"])).mappings():
                conn.execute(m.insert().values(
                    {**{c: model[c] for c in model if c != "id"}, "pack_id": pid,
                     "reference_event_id": event_ids.get(model["reference_event_id"])}))


class Server:
    """``dischargelab serve --db DB --port 0`` on 127.0.0.1, ended by its process id."""

    def __init__(self, db: Path):
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "dischargelab", "serve", "--db", str(db), "--port", "0"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"}, start_new_session=True)
        found = threading.Event()
        self.port = None

        def pump():
            for line in self.proc.stdout:
                match = re.search(r"listening on http://127\.0\.0\.1:(\d+)/", line)
                if match and self.port is None:
                    self.port = int(match.group(1))
                    found.set()
            found.set()

        threading.Thread(target=pump, daemon=True).start()
        if not found.wait(120) or self.port is None:
            self.stop()
            raise SystemExit("the server did not start")

    def get(self, path: str) -> tuple[float, int]:
        """Seconds from sending the request to its last byte, and the body's size."""
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=60)
        start = time.perf_counter()
        conn.request("GET", path)
        response = conn.getresponse()
        body = response.read()
        elapsed = time.perf_counter() - start
        conn.close()
        if response.status != 200:
            raise SystemExit(f"GET {path}: {response.status} {body[:200]!r}")
        if b'"recomputing":true' in body.replace(b" ", b""):
            raise SystemExit(f"GET {path}: figures still being recomputed")
        return elapsed, len(body)

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(30)


def timings(server: Server, paths: list[str]) -> tuple[list[float], int]:
    server.get(paths[0])                           # the first request opens the logbook
    times, size = [], 0
    for path in paths:
        elapsed, size = server.get(path)
        times.append(1000 * elapsed)
    return times, size


def summary(times: list[float]) -> str:
    ordered = sorted(times)
    p95 = ordered[min(len(ordered) - 1, int(round(0.95 * (len(ordered) - 1))))]
    return f"{statistics.median(times):.1f} | {p95:.1f} | {max(times):.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,100,1000", help="pack counts, growing")
    parser.add_argument("--requests", type=int, default=30, help="timed requests of each kind")
    parser.add_argument("--workers", type=int, default=2,
                        help="Dask workers computing the figures (1: in this process)")
    parser.add_argument("--keep", type=Path, help="keep the logbook in this folder")
    opts = parser.parse_args()
    from dischargelab.fleet import executor
    from dischargelab.logbook import Logbook

    sizes = sorted(int(x) for x in opts.sizes.split(","))
    work = Path(opts.keep or tempfile.mkdtemp(prefix="dischargelab-pages-"))
    db = work / "logbook.sqlite"
    db.unlink(missing_ok=True)
    rng = random.Random(0)
    rows = []
    with Logbook(db) as lb, executor(workers=opts.workers) as ex:
        distinct_packs(lb, min(DISTINCT_PACKS, sizes[0]), work / "files")
        for size in sizes:
            copy_packs(lb, size)
            start = time.perf_counter()
            done = lb.refresh(executor=ex)
            build = time.perf_counter() - start
            assert lb.stale() == [] and len(lb.pack_names()) == size
            names = lb.pack_names()
            server = Server(db)
            try:
                load = os.getloadavg()[0]
                list_times, list_size = timings(server, ["/api/packs"] * opts.requests)
                pages = [f"/api/packs/{rng.choice(names)}" for _ in range(opts.requests)]
                page_times, page_size = timings(server, pages)
            finally:
                server.stop()
            rows.append((size, len(done), build, list_times, list_size, page_times, page_size,
                         load, os.getloadavg()[0]))
    print(f"Pack list and pack page latency, `dischargelab serve` on 127.0.0.1, SQLite; "
          f"{opts.requests} requests of each, one after the other; packs of "
          f"{EVENTS_PER_PACK} cell C events with a fitted model")
    print("| packs | figures computed (packs, s) | GET /api/packs: median | p95 | max [ms] | "
          "size [kB] | GET /api/packs/NAME: median | p95 | max [ms] | size [kB] | "
          "load average |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for size, n, build, lt, ls, pt, ps, l0, l1 in rows:
        print(f"| {size:,} | {n} in {build:.0f} s | {summary(lt)} | {ls / 1e3:.0f} | "
              f"{summary(pt)} | {ps / 1e3:.0f} | {l0:.1f}-{l1:.1f} |")
    last = rows[-1]
    print(f"goals at {last[0]:,} packs (median): list <= {GOAL_LIST_MS:.0f} ms: "
          f"{statistics.median(last[3]):.1f} ms; page <= {GOAL_PAGE_MS:.0f} ms: "
          f"{statistics.median(last[5]):.1f} ms")
    print(machine_line(), f"; load average at the end {os.getloadavg()[0]:.2f}")
    if opts.keep is None:
        shutil.rmtree(work)


if __name__ == "__main__":
    start = time.perf_counter()
    main()
    print(f"benchmark took {time.perf_counter() - start:.0f} s")
