"""Journeys: a user who installed the wheel has the example set, and the guide's first
commands give true answers on it.

From an empty folder: ``dischargelab examples DIR``, then the commands the getting-started
page runs (fit, validate, endurance, a flight log, a tester file, a logbook), each through
the command line as a user runs it, each answer checked against the copied file itself
(charge counted from its samples, the tester's and the log's own counters, the energy the
cell gave), not against a number written here.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

import dischargelab as dl
from cli_run import command
from dischargelab.examples import EXAMPLE_COLUMNS, example_files

pytestmark = pytest.mark.slow


def cli(*args, cwd, ok=True, timeout=600):
    """``python -m dischargelab ARGS`` in ``cwd`` as a user runs it (its own logbook)."""
    return command(*args, cwd=cwd, env={"DISCHARGELAB_DB": str(Path(cwd) / "default.db")},
                   check=ok, timeout=timeout)


def bench(path: Path) -> dict[str, np.ndarray]:
    """A bench file's own samples (no header: time, current (discharge negative), voltage)."""
    raw = np.loadtxt(path, delimiter=",", usecols=(0, 1, 2), encoding="utf-8-sig")
    return {"t": raw[:, 0], "i": -raw[:, 1], "v": raw[:, 2]}


def counted_Ah(run) -> float:
    on = run["i"] > 0.01
    return float(np.trapezoid(np.where(on, run["i"], 0.0), run["t"]) / 3600)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """An empty folder the example set is copied into, as the guide starts."""
    home = tmp_path_factory.mktemp("user") / "try-me"
    done = cli("examples", home, cwd=home.parent)
    for name in example_files():
        assert (home / name).is_file(), name
        assert str(home / name) in done.stdout, name          # it says what it wrote
    assert "dischargelab fit bench/" in done.stdout          # and what to try next
    return home


def test_examples_copies_the_set_and_never_replaces_a_users_file(folder, tmp_path):
    shipped = example_files()
    for name, source in shipped.items():
        assert (folder / name).read_bytes() == source.read_bytes(), name
    # the wheel's set is small and carries each file's licence
    assert sum(p.stat().st_size for p in shipped.values()) < 6e6
    assert {n.split("/")[0] for n in shipped if n.endswith("LICENSE")} == \
        {"bench", "flight", "tester", "ageing"}
    # copying again is harmless; a changed file is kept unless --force
    again = cli("examples", folder, cwd=tmp_path)
    assert "wrote 0 files" in again.stdout
    mine = folder / "mission" / "survey.toml"
    mine.write_text(mine.read_text() + "\n# my edit\n")
    refused = cli("examples", folder, cwd=tmp_path, ok=False)
    assert refused.returncode == 2
    assert len(refused.stderr.strip().splitlines()) == 1 and "--force" in refused.stderr
    assert "my edit" in mine.read_text()
    forced = cli("examples", folder, "--force", cwd=tmp_path)
    assert str(mine) in forced.stdout and "my edit" not in mine.read_text()
    # a file where the folder should be: one line, nothing written
    blocker = tmp_path / "blocked"
    blocker.write_text("x")
    assert cli("examples", blocker, cwd=tmp_path, ok=False).returncode == 2


def test_the_library_gives_the_paths(tmp_path):
    from dischargelab.examples import copy_examples

    result = copy_examples(tmp_path / "set")
    assert set(result.files) == set(example_files())
    assert len(result.written) == len(result.files)
    run = dl.read(result["bench/Q30_S001_1C.csv"], columns=EXAMPLE_COLUMNS)
    assert run.charge_Ah == pytest.approx(counted_Ah(bench(result["bench/Q30_S001_1C.csv"])),
                                          rel=0.01)
    assert copy_examples(tmp_path / "set").written == []


def test_fit_validate_and_endurance_on_the_bench_files(folder):
    c10, c1, c4 = (bench(folder / "bench" / f"Q30_S001_{r}.csv") for r in ("C10", "1C", "4C"))
    cli("fit", "bench/Q30_S001_C10.csv", "bench/Q30_S001_4C.csv", "--columns", EXAMPLE_COLUMNS,
        "-o", "cell.json", cwd=folder)
    # the capacity is the charge the slow run drew to 2.5 V (within 3 %)
    capacity = dl.load(folder / "cell.json").capacity_Ah
    assert capacity == pytest.approx(counted_Ah(c10), rel=0.03)

    # the 1C run the fit did not see: its time to 2.5 V within 3 %, called validation
    done = cli("validate", "cell.json", "bench/Q30_S001_1C.csv", "--columns", EXAMPLE_COLUMNS,
               "--cutoff", "2.5", "--json", cwd=folder)
    case = json.loads(done.stdout)["files"][0]
    below = np.flatnonzero((c1["v"] < 2.5) & (c1["i"] > 0.01))
    start = c1["t"][np.flatnonzero(c1["i"] > 0.01)[0]]
    measured = (c1["t"][below[0]] if below.size else c1["t"][-1]) - start
    assert case["endurance_measured_s"] == pytest.approx(measured, rel=0.01)
    assert abs(case["endurance_predicted_s"] / measured - 1) < 0.03
    assert case["in_fit"] is False

    # the survey mission on a 4S2P pack: endurance as the energy the cells give allows
    done = cli("endurance", "cell.json", "mission/survey.toml", "--cells", 4, "--parallel", 2,
               "--draws", 20, "--json", cwd=folder)
    flight = json.loads(done.stdout)
    assert (flight["cells_series"], flight["strings_parallel"]) == (4, 2)
    assert flight["capacity_Ah"] == pytest.approx(2 * capacity, rel=0.01)
    assert flight["completed"] and flight["soc_end_pct"] >= flight["reserve_pct"]
    energy_Wh = 8 * float(np.trapezoid(c4["v"] * np.clip(c4["i"], 0, None), c4["t"]) / 3600)
    survey_W = flight["energy_used_Wh"] * 3600 / flight["flight_time_s"]
    allowed_s = (1 - flight["reserve_pct"] / 100) * energy_Wh * 3600 / survey_W
    # between the 4C energy (a lower bound) and 1.3 times it (the takeoff draws more)
    assert 0.8 * allowed_s < flight["endurance_s"] < 1.6 * allowed_s


def test_the_flight_log_carries_current(folder):
    done = cli("flight", "flight/esc_status_log.ulg", "--json", cwd=folder)
    report = json.loads(done.stdout)
    assert report["cells_series"] == 6
    flight = report["flights"][0]
    cli("convert", "flight/esc_status_log.ulg", "-o", "flight.csv", cwd=folder)
    with open(folder / "flight.csv", encoding="utf-8") as handle:
        rows = list(csv.DictReader(line for line in handle if not line.startswith("#")))
    current = np.array([float(r["current_A"]) for r in rows])
    counter = np.array([float(r["log_discharged_mAh"]) for r in rows])
    assert flight["peak_current_A"] == pytest.approx(current.max(), rel=1e-6)
    # the charge counted from the current agrees with the log's own counter (within 3 %)
    assert flight["charge_Ah"] * 1000 == pytest.approx(counter[-1] - counter[0], rel=0.03)
    assert 0 < flight["resistance_ohm"] < 0.2


def test_the_tester_file_and_the_ageing_cell(folder):
    done = cli("steps", "tester/arbin_example.csv", "--json", cwd=folder)
    steps = json.loads(done.stdout)
    assert steps["fit_steps"], steps["fit_steps_reason"]
    for number in steps["fit_steps"]:
        step = next(s for s in steps["steps"] if s["number"] == number)
        assert step["kind"] == "discharge" and step["mean_current_A"] > 0
        # the charge counted from the records agrees with the tester's own counter
        assert step["charge_Ah"] == pytest.approx(step["tester_Ah"], rel=0.001)
    run = dl.read(folder / "tester" / "arbin_example.csv")
    assert run.mean_current_A > 0                                   # discharge positive
    assert run.charge_Ah == pytest.approx(
        steps["steps"][steps["fit_steps"][0] - 1]["tester_Ah"], rel=0.01)

    # a fit of the tester file answers (a model or one line), never a crash
    fitted = cli("fit", "tester/arbin_example.csv", "-o", "lfp.json", cwd=folder, ok=False)
    assert fitted.returncode in (0, 2) and "Traceback" not in fitted.stderr, fitted.stderr

    cli("logbook", "add", "ageing", "--pack", "cell-C", "--db", "packs.db", cwd=folder)
    health = json.loads(cli("logbook", "health", "cell-C", "--db", "packs.db", "--json",
                            cwd=folder).stdout)
    capacities = [e["capacity_Ah"] for e in health["events"] if e.get("full")]
    assert len(capacities) == 3 and capacities == sorted(capacities, reverse=True)
    first = np.loadtxt(folder / "ageing" / "DischargeCycle001.txt", skiprows=_header_lines(
        folder / "ageing" / "DischargeCycle001.txt"), usecols=(0, 1))
    drawn = counted_Ah({"t": first[:, 0], "i": -first[:, 1]})
    assert capacities[0] == pytest.approx(drawn, rel=0.01)


def _header_lines(path: Path) -> int:
    """Lines up to and including the LabVIEW header's ``X_Value`` line."""
    with open(path, encoding="utf-8", errors="replace") as handle:
        for k, line in enumerate(handle):
            if line.startswith("X_Value"):
                return k + 1
    return 0
