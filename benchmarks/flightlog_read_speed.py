"""Reading speed and peak memory of the flight-log readers on ~100 MB logs.

Builds, in a temporary folder, large logs of every format from real records
or with the formats' own byte layouts:

* ArduPilot text DataFlash: the body of the real ``mechanical_fail.log``
  repeated with the GPS time moved on (one arm-to-disarm flight per copy);
* ArduPilot binary DataFlash: written with ``tests/flightlog_synth.py``, BAT at
  10 Hz among IMU messages at 400 Hz (the usual share of battery records);
* PX4 ULog: written the same way, battery_status at 10 Hz among a 400 Hz topic;
* in-flight logger CSV: the real INA3221 ``29.csv`` repeated with the time moved on;
* Betaflight blackbox: the real ``btfl_001.bbl`` repeated (three logs per copy),
  ``--blackbox-mb`` in size, because orangebox decodes every frame in Python.

Each file is read by ``read_flight_log`` in a fresh Python process, which
reports its wall-clock time and its own peak resident memory
(``resource.getrusage``). For text DataFlash the same process also times
pymavlink's reader on every message (no type filter) on a smaller file, to
show what the type filter buys.

Goal: a 100 MB log reads in under 30 s with memory bounded well below the
machine's. Usage: python benchmarks/flightlog_read_speed.py [--mb 100]
[--blackbox-mb 10] [--unfiltered-mb 10]
"""

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))

from _machine import machine_line, shared_data  # noqa: E402
from flightlog_synth import DataFlashWriter, ULogWriter  # noqa: E402

LOGS = shared_data() / "flight_logs"
MB = 1_000_000

_CHILD = r"""
import json, resource, sys, time
from dischargelab.io.flightlog import read_flight_log
start = time.perf_counter()
log = read_flight_log(sys.argv[1])
elapsed = time.perf_counter() - start
rows = sum(b.rows for b in log.batteries)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"seconds": elapsed, "rows": rows, "flights": len(log.spans),
                  "peak_MB": peak}))
"""

_CHILD_UNFILTERED = r"""
import json, resource, sys, time
from pymavlink import DFReader
start = time.perf_counter()
reader = DFReader.DFReader_text(sys.argv[1])
count = 0
while reader.recv_msg() is not None:
    count += 1
elapsed = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"seconds": elapsed, "rows": count, "flights": None, "peak_MB": peak}))
"""


def measure(path: Path, child: str = _CHILD) -> dict:
    done = subprocess.run([sys.executable, "-c", child, str(path)], capture_output=True,
                          text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def text_dataflash(path: Path, size_mb: float) -> Path:
    """Repeat the real text log's records, moving the GPS clock on by 200 s per copy."""
    lines = (LOGS / "ardupilot_loganalyzer" / "mechanical_fail.log").read_text(
        encoding="utf-8", errors="replace").splitlines()
    first_data = next(k for k, line in enumerate(lines) if line.startswith(("EV,", "GPS,")))
    head, body = lines[:first_data], lines[first_data:]
    with open(path, "w", encoding="utf-8", newline="\r\n") as out:
        out.write("\n".join(head) + "\n")
        copy = 0
        while out.tell() < size_mb * MB:
            shift_ms = copy * 200_000
            for line in body:
                if line.startswith("GPS,"):
                    parts = line.split(", ")
                    parts[2] = str(int(parts[2]) + shift_ms)
                    line = ", ".join(parts)
                out.write(line + "\n")
            copy += 1
    return path


def binary_dataflash(path: Path, size_mb: float) -> Path:
    """BAT at 10 Hz, GPS at 5 Hz, IMU at 400 Hz; arm at 10 s, disarm 10 s before the end."""
    seconds = int(size_mb * MB / (400 * 50 + 10 * 48 + 5 * 19)) + 1
    with open(path, "wb") as out:
        w = DataFlashWriter()
        w.add("PARM", 0, "BATT_CAPACITY", 10000.0)
        out.write(w.bytes())
        for second in range(seconds):
            w.parts = []
            if second in (10, seconds - 10):
                w.add("EV", second * 1_000_000, 10 if second == 10 else 11)
            flying = 10 <= second < seconds - 10
            for k in range(400):
                us = second * 1_000_000 + k * 2500
                w.add("IMU", us, 0, 0.01, 0.02, 0.03, 0.1, 0.2, -9.8, 0, 0, 40.0, 1, 1)
                if k % 40 == 0:
                    amps = 25.0 if flying else 0.4
                    w.add("BAT", us, 0, 16.0 - 0.02 * amps, 16.0, amps, second * 7.0,
                          second * 0.1, 2500, 0.02, 80)
                if k % 80 == 0:
                    w.add("GPS", us, 3, us // 1000, 2200)
            out.write(w.bytes())
    return path


def ulog(path: Path, size_mb: float) -> Path:
    """battery_status at 10 Hz among a 400 Hz sensor topic; armed after 10 s."""
    w = ULogWriter()
    w.define("battery_status", [("uint64_t", "timestamp"), ("float", "voltage_v"),
                                ("float", "current_a"), ("float", "discharged_mah"),
                                ("float", "remaining"), ("float", "temperature"),
                                ("uint8_t", "cell_count"), ("uint8_t", "connected")])
    w.define("sensor_combined", [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"),
                                 ("float[3]", "accelerometer_m_s2"), ("uint32_t", "gyro_dt")])
    w.define("vehicle_status", [("uint64_t", "timestamp"), ("uint8_t", "arming_state")])
    per_second = 400 * 45 + 10 * 35 + 14
    seconds = int(size_mb * MB / per_second) + 1
    with open(path, "wb") as out:
        out.write(w.bytes())
        for second in range(seconds):
            w.header, w.definitions, w.body = b"", [], []
            w.add("vehicle_status", 0, [second * 1_000_000 + 1, 2 if second >= 10 else 1])
            for k in range(400):
                us = second * 1_000_000 + k * 2500 + 2
                w.add("sensor_combined", 0, [us, [0.01, 0.02, 0.03], [0.1, 0.2, -9.8], 2500])
                if k % 40 == 0:
                    amps = 25.0 if second >= 10 else 0.4
                    w.add("battery_status", 0, [us, 16.0 - 0.02 * amps, amps, second * 7.0,
                                                0.8, 25.0, 4, 1])
            out.write(b"".join(w.body))
    return path


def inflight_csv(path: Path, size_mb: float) -> Path:
    data = np.genfromtxt(LOGS / "ina3221_fpv_4s" / "29.csv", delimiter=",")[:-1, :8]
    span = data[-1, 0] - data[0, 0] + 67.0
    with open(path, "w", encoding="utf-8") as out:
        copy = 0
        while out.tell() < size_mb * MB:
            block = data.copy()
            block[:, 0] += copy * span
            np.savetxt(out, block, delimiter=",", fmt="%.0f,%.2f,%.2f,%.2f,%.2f,%.2f,%.2f,%.2f",
                       newline=",\n")
            copy += 1
    return path


def blackbox(path: Path, size_mb: float) -> Path:
    data = (LOGS / "betaflight_diatone" / "btfl_001.bbl").read_bytes()
    copies = max(1, int(round(size_mb * MB / len(data))))
    path.write_bytes(data * copies)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mb", type=float, default=100.0, help="size of the large logs [MB]")
    parser.add_argument("--blackbox-mb", type=float, default=10.0)
    parser.add_argument("--unfiltered-mb", type=float, default=10.0)
    args = parser.parse_args()
    cases = [("ArduPilot text DataFlash", text_dataflash, "log", args.mb),
             ("ArduPilot binary DataFlash", binary_dataflash, "bin", args.mb),
             ("PX4 ULog", ulog, "ulg", args.mb),
             ("in-flight logger CSV (INA3221)", inflight_csv, "csv", args.mb),
             ("Betaflight blackbox", blackbox, "bbl", args.blackbox_mb)]
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for label, build, suffix, size in cases:
            path = build(Path(folder) / f"big.{suffix}", size)
            result = measure(path)
            rows.append((label, path.stat().st_size / MB, result))
            path.unlink()
        path = text_dataflash(Path(folder) / "unfiltered.log", args.unfiltered_mb)
        rows.append(("  same, pymavlink on every message", path.stat().st_size / MB,
                     measure(path, _CHILD_UNFILTERED)))
        rows.append(("  same, read_flight_log", path.stat().st_size / MB, measure(path)))
    print(f"{'log':<36} {'MB':>7} {'rows':>10} {'flights':>8} {'read s':>8} {'MB/s':>7} "
          f"{'peak RSS MB':>12}")
    for label, size, r in rows:
        flights = "" if r["flights"] is None else str(r["flights"])
        print(f"{label:<36} {size:7.1f} {r['rows']:10d} {flights:>8} {r['seconds']:8.2f} "
              f"{size / r['seconds']:7.1f} {r['peak_MB']:12.0f}")
    print("rows: battery samples kept (for 'every message': DataFlash messages decoded)")
    print(machine_line())


if __name__ == "__main__":
    main()
