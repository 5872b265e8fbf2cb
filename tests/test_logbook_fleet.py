"""The logbook on a Dask cluster: the same events as in process, faults, interruptions."""

from __future__ import annotations

import functools
import shutil
import threading
from pathlib import Path

import pytest

pytest.importorskip("sqlalchemy")
pytest.importorskip("distributed")

from dask_cluster import Cluster
from dischargelab.errors import LogbookError
from dischargelab.fleet import DaskExecutor, InProcessExecutor, executor
from dischargelab.logbook import Logbook
from dischargelab.logbook.figures import pack_figures
from fleet_tasks import crash_on_file

CELL_C = "samsung30q_ageing_cellC"

#: Fields of an event that depend on when and where it was stored, not on the file.
STORAGE_FIELDS = ("id",)


@pytest.fixture(scope="module")
def packs(shared_data, tmp_path_factory) -> Path:
    """Three pack folders of cell C cycles, each copy changed (a trailing newline) so its
    hash differs: 36 files."""
    root = tmp_path_factory.mktemp("fleet") / "packs"
    files = sorted((shared_data / CELL_C).glob("DischargeCycle*.txt"))
    for k, pack in enumerate(("pack-a", "pack-b", "pack-c")):
        folder = root / pack
        folder.mkdir(parents=True)
        for f in files[k::6]:
            (folder / f.name).write_bytes(f.read_bytes() + b"\n" * (k + 1))
    return root


def stored(url: str) -> dict:
    """Every pack's events as stored, keyed by (pack, source, index), storage ids left out."""
    with Logbook(url) as lb:
        out = {}
        for name in lb.pack_names():
            for row in lb.events(name).to_dict()["events"]:
                key = (name, row["source"], row["idx"])
                assert key not in out, f"event stored twice: {key}"
                out[key] = {k: v for k, v in row.items() if k not in STORAGE_FIELDS}
        return out


def n_files(root: Path) -> int:
    return sum(1 for _ in root.rglob("*.txt"))


@pytest.fixture(scope="module")
def in_process(packs, tmp_path_factory) -> dict:
    url = str(tmp_path_factory.mktemp("inproc") / "lb.sqlite")
    with Logbook(url) as lb:
        result = lb.add(packs, pack_from="parent", recursive=True)
    assert len(result.added) == n_files(packs) and not result.rejected
    return stored(url)


@pytest.mark.slow
def test_local_cluster_stores_the_same_events_and_refits_and_reports_alike(
        packs, in_process, tmp_path):
    url = str(tmp_path / "lb.sqlite")
    code, out, err = run_cli("logbook", "add", packs, "--pack-from", "parent", "-r",
                             "--workers", "2", "--db", url)
    assert code == 0, err
    assert "running on 2 Dask worker(s)" in err
    assert stored(url) == in_process
    with Logbook(url) as lb, DaskExecutor(workers=2) as ex:
        fleet = lb.fleet(executor=ex)
        assert [r["name"] for r in fleet.rows] == [r["name"] for r in lb.fleet().rows]
        assert fleet.to_dict() == lb.fleet().to_dict()
        fitted = lb.fit_all(executor=ex, bootstrap=0)
        local = lb.fit_all(bootstrap=0)
    assert sorted(fitted) == ["pack-a", "pack-b", "pack-c"]
    for name, battery in fitted.items():
        assert battery.parameters.as_dict() == pytest.approx(
            local[name].parameters.as_dict(), rel=1e-9)


@pytest.mark.slow
def test_files_read_here_while_the_cluster_starts_are_stored_once_and_alike(
        packs, in_process, tmp_path):
    url = str(tmp_path / "lb.sqlite")
    total = n_files(packs)
    with executor(workers=2, background=True) as ex, Logbook(url) as lb:
        def progress(done, total, name):
            if ex.ran_here >= 3:
                ex.ready()              # the first files here, the rest on the workers
        result = lb.add(packs, pack_from="parent", recursive=True, executor=ex,
                        progress=progress)
        assert lb.stale() == []
        figures = {name: lb.health(name).to_dict() for name in lb.pack_names()}
    assert 1 <= ex.ran_here <= 3
    assert len(result.added) == total and not result.rejected and not result.skipped
    assert stored(url) == in_process
    with Logbook(str(tmp_path / "here.sqlite")) as lb:
        lb.add(packs, pack_from="parent", recursive=True)
        alike = {name: lb.health(name).to_dict() for name in lb.pack_names()}
    for health in (*figures.values(), *alike.values()):
        for event in health["events"]:
            event.pop("event_id")
    assert figures == alike


@pytest.mark.slow
def test_refits_build_each_packs_job_only_as_the_executor_asks(packs, tmp_path, monkeypatch):
    url = str(tmp_path / "lb.sqlite")
    with Logbook(url) as lb:
        lb.add(packs, pack_from="parent", recursive=True)
        lb.set_pack("no-full", label_capacity_Ah=3.0)   # a pack with nothing to fit
        built, seen, calls = [], [], []
        job = lb._job
        monkeypatch.setattr(lb, "_job", lambda name, *a: (built.append(name), job(name, *a))[1])

        class Watching(InProcessExecutor):
            def map_unordered(self, func, items, per_task=1):
                for item, outcome in super().map_unordered(func, items, per_task):
                    if func.__name__ == "fit_job":      # not the figures made after them
                        seen.append(len(built))     # jobs built when this one comes back
                    yield item, outcome

        fitted = lb.fit_all(executor=Watching(), bootstrap=0,
                            progress=lambda done, total, name: calls.append((done, total, name)))
        assert lb.stale() == []     # the new models' figures are stored
    # "no-full" (tried first, nothing to fit), then one job per result: never every
    # pack's file bytes at once (building them all first would read [4, 4, 4])
    assert seen == [2, 3, 4]
    assert sorted(fitted) == ["no-full", "pack-a", "pack-b", "pack-c"]
    assert "no full discharge" in fitted["no-full"]
    fits = [(d, t) for d, t, name in calls if not name.startswith("figures of")]
    assert fits[-1] == (4, 4) and [d for d, _ in fits] == [1, 2, 3, 4]
    assert [name for *_, name in calls[4:]] == [f"figures of pack-{x}" for x in "abc"]


def run_cli(*args):
    """The CLI in process, capturing its output (pytest's capsys is function-scoped)."""
    import contextlib
    import io

    from dischargelab.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            pytest.raises(SystemExit) as exc:
        main([str(a) for a in args])
    return exc.value.code, out.getvalue(), err.getvalue()


@pytest.mark.slow
def test_real_cluster_bytes_when_workers_cannot_see_and_a_worker_killed(packs, in_process,
                                                                       tmp_path):
    cluster = Cluster(workers=2)
    try:
        url = str(tmp_path / "lb.sqlite")
        with DaskExecutor(scheduler=cluster.address) as ex, Logbook(url) as lb:
            ex.client.wait_for_workers(2, timeout=60)
            ex.sees = lambda path: False          # as if the cluster were elsewhere
            sent = []
            killer = threading.Thread(target=cluster.kill, args=(cluster.workers[0],))

            def progress(done, total, name):
                sent.append(name)
                if len(sent) == 5:              # kill one worker mid-run
                    killer.start()

            result = lb.add(packs, pack_from="parent", recursive=True, executor=ex,
                            progress=progress)
            killer.join(timeout=30)
        assert cluster.workers[0].poll() is not None
        assert len(result.added) == n_files(packs) and not result.rejected
        assert stored(url) == in_process        # nothing lost, nothing twice
        # the same cluster through the command line, on a second database
        url2 = str(tmp_path / "lb2.sqlite")
        code, out, err = run_cli("logbook", "add", packs, "--pack-from", "parent", "-r",
                                 "--scheduler", cluster.address, "--db", url2)
        assert code == 0, err
        assert stored(url2) == in_process
    finally:
        cluster.stop()
    assert cluster.alive() == []


@pytest.mark.slow
def test_a_file_that_kills_workers_twice_is_rejected_and_the_rest_goes_in(packs, tmp_path):
    victim = sorted((packs / "pack-b").glob("*.txt"))[2].name

    class Crashing(DaskExecutor):
        def map_unordered(self, func, items, per_task=1):
            if func is pack_figures:     # the packs' figures after the files: no crash
                return super().map_unordered(func, items, per_task=per_task)
            assert per_task > 1          # the crashing file first fails with its batch
            return super().map_unordered(functools.partial(crash_on_file, func, victim), items,
                                         per_task=per_task)

    url = str(tmp_path / "lb.sqlite")
    with Crashing(workers=2) as ex, Logbook(url) as lb:
        result = lb.add(packs / "pack-b", pack="pack-b", executor=ex)
    assert [Path(p).name for p, _ in result.rejected] == [victim]
    assert "died twice" in result.rejected[0][1]
    assert len(result.added) == n_files(packs / "pack-b") - 1


def test_interrupted_add_keeps_whole_transactions_and_a_rerun_does_only_the_rest(
        packs, in_process, tmp_path):
    url = str(tmp_path / "lb.sqlite")
    folder = tmp_path / "pack-a"
    shutil.copytree(packs / "pack-a", folder)
    total = n_files(folder)

    def stop_after_seven(done, total, name):
        if done == 7:
            raise KeyboardInterrupt

    with Logbook(url) as lb:
        with pytest.raises(KeyboardInterrupt):
            lb.add(folder, pack="pack-a", executor=InProcessExecutor(),
                   progress=stop_after_seven)
    first = stored(url)
    assert len(first) == 7                       # what was summarised is kept, whole
    with Logbook(url) as lb:
        again = lb.add(folder, pack="pack-a")
    assert len(again.added) == total - 7 and len(again.skipped) == 7
    assert stored(url) == {k: v for k, v in in_process.items() if k[0] == "pack-a"}


def test_without_keeping_the_bytes_the_path_serves_until_the_file_changes(packs, tmp_path):
    folder = tmp_path / "pack-c"
    shutil.copytree(packs / "pack-c", folder)
    url = str(tmp_path / "lb.sqlite")
    kept = str(tmp_path / "kept.sqlite")
    with Logbook(url) as lb, Logbook(kept) as full:
        lean = lb.add(folder, pack="pack-c", keep_raw=False)
        full.add(folder, pack="pack-c")
        assert lean.added and stored(url) == stored(kept)
        lean_events = lb.health("pack-c").events   # the same health as with kept bytes
        assert [e.capacity_Ah for e in lean_events] == [
            e.capacity_Ah for e in full.health("pack-c").events]
        first = sorted(folder.glob("*.txt"))[0]
        from dischargelab.logbook.summarise import sha256_file

        digest = sha256_file(first)
        assert lb.raw(digest) == first.read_bytes()
        battery = lb.fit("pack-c", bootstrap=0)   # refits read the file at its path
        assert battery.capacity_Ah > 0
        first.write_bytes(first.read_bytes() + b"\n")
        with pytest.raises(LogbookError, match="no longer there as it was"):
            lb.raw(digest)
    assert (tmp_path / "lb.sqlite").stat().st_size < 0.5 * (tmp_path / "kept.sqlite").stat().st_size


def test_fleet_report_page_lists_packs_soonest_end_of_life_first(packs, tmp_path):
    import json

    url = str(tmp_path / "lb.sqlite")
    with Logbook(url) as lb:
        lb.add(packs, pack_from="parent", recursive=True)
        expected = lb.fleet()
    page = tmp_path / "fleet.html"
    code, out, err = run_cli("logbook", "report", "--fleet", "-o", page, "--within", "1000",
                             "--db", url, "--json")
    assert code == 0, err
    doc = json.loads(out)
    names = [p["name"] for p in doc["packs"]]
    assert names == [r["name"] for r in expected.rows] and sorted(names) == [
        "pack-a", "pack-b", "pack-c"]
    left = [p["efc_left"] for p in doc["packs"] if not p["observed"]]
    assert left == sorted(left)
    assert doc["retire_soon"] == expected.retire_soon(1000)
    html = page.read_text(encoding="utf-8")
    assert html.index("pack-a") > 0 and all(html.index(a) < html.index(b)
                                            for a, b in zip(names, names[1:]))
    assert html.count("<svg") == 6 and "<script" not in html and "http" not in html
    code, out, err = run_cli("logbook", "report", "--fleet", "-o", page, "--db", url)
    assert code == 2 and "already exists" in err and "--force" in err
    # every figure stored: --workers starts no cluster
    code, out, err = run_cli("logbook", "report", "--fleet", "-o", tmp_path / "again.html",
                             "--db", url, "--workers", "2")
    assert code == 0 and "no workers needed" in err and "running on" not in err, err
