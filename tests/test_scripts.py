"""Every example script and every benchmark runs (quick settings) and prints its result."""

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((REPO / "examples").glob("*.py"))

#: benchmark -> (quick arguments, text the output must contain)
BENCHMARKS = {
    "fit_speed.py": (["--repeats", "1", "--large-rows", "50000", "--families", "shepherd"],
                     "speed-up"),
    "fit_latency.py": (["--repeats", "1", "--bootstrap", "10"], "x the baseline"),
    "slow_to_fast.py": (["--cells", "none", "--logs", "none", "--bootstrap", "5"],
                        "endurance error"),
    "accuracy.py": (["--sets", "enertech", "--families", "auto", "--bootstrap", "5"],
                    "endurance error"),
    "one_rate_errors.py": (["--cells", "enertech", "--families", "shepherd", "--no-two-rate"],
                           "leave one cell out"),
    "next_test.py": (["--cells", "enertech"], "Predicted within a factor"),
    "step_polarisation.py": (["--cells", "enertech"], "best alpha"),
    "two_rate_residuals.py": (["--cases", "nca/shepherd"], "time-to-cutoff error"),
    "mission_speed.py": (["--repeats", "1"], "Table 5"),
    "io_read_speed.py": (["--repeats", "1", "--rows", "20000"], "ms"),
    "acquire_throughput.py": (["--seconds", "5"], "corrupt"),
    "calibration_table1.py": ([], "Target: 3.3 kOhm Ke = 4.38 +/- 0.01 -> 4.380"),
    "flightlog_read_speed.py": (["--mb", "2", "--blackbox-mb", "2.5", "--unfiltered-mb", "1"],
                                "peak RSS MB"),
    "logbook.py": (["--copies", "20"], "95 % interval holds truth"),
    "forecast.py": (["--lives", "2", "--skip-cell-c"], "Calibration of the end-of-life interval"),
    "fleet.py": (["--packs", "1", "--repeats", "1", "--no-formats"], "the whole command"),
    "server_load.py": (["--readers", "4", "--seconds", "3", "--idle", "10", "--uploads", "2",
                        "--cell-c", "3"], "uploads stored exactly once"),
    # needs Debian's chromium and chromium-driver (make browser), as the web page tests do
    "web_plot_speed.py": (["--points", "2000", "--repeats", "3"], "next draws, median"),
    "tester_files.py": ([], "tester's counter"),
    "logbook_pages.py": (["--sizes", "2,3", "--requests", "3", "--workers", "1"], "goals at 3"),
    "health_from_use.py": (["--skip", "cmu", "synthetic", "cellc"], "full-enough flights"),
    "cmu_rewindow.py": ([], "re-windowed"),
    "health_matrix.py": (["--only", "generic curve", "--cycles", "11", "--cache", "{tmp}"],
                         "band holds"),
    "fade_span.py": (["--skip-cmu"], "EFC"),
    "unseen_fade.py": (["--cells", "VAH27", "--cache", "{tmp}"], "fade the charges miss"),
    "partial_flights.py": (["--flights", "2", "--chemistries", "lipo"], "read as discharges"),
    # with PyBaMM (the `virtual` extra) a short life; without it, says it is skipped
    "pybamm_ocv_drift.py": (["--only", "25 degC", "--cycles", "6", "--cache", "{tmp}"],
                            "open-circuit curve with age"),
    # with PyBaMM the published cells too; without it the measured cell only
    "ocv_spread.py": ([], "Deviation from the generic Li-ion curve"),
    # needs Debian's lua5.3 (make lua), as the on-board script tests do
    "onboard.py": (["--quick", "--skip-real"], "largest |DL_TREM - time left|"),
    # needs the `virtual` extra (PyBaMM) to regenerate tests/data/virtual; here its usage only
    "virtual_cells.py": (["--help"], "usage"),
}


def run(args, timeout=300):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)


@pytest.mark.slow      # `make docs` runs every example too (the gallery)
@pytest.mark.parametrize("script", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_example_runs(script, tmp_path):
    done = run([script, "--out", tmp_path])
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip()
    produced = [p for p in tmp_path.iterdir() if p.suffix in (".png", ".html")]
    assert produced and all(p.stat().st_size > 10_000 for p in produced)


def test_every_benchmark_is_listed():
    assert {p.name for p in (REPO / "benchmarks").glob("[!_]*.py")} == set(BENCHMARKS)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(BENCHMARKS))
def test_benchmark_runs(name, shared_data, tmp_path):
    args, expected = BENCHMARKS[name]
    done = run([REPO / "benchmarks" / name, *(a.replace("{tmp}", str(tmp_path)) for a in args)])
    assert done.returncode == 0, done.stderr[-2000:]
    assert expected in done.stdout
