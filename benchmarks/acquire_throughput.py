"""Acquisition throughput at the full 115200-baud link rate, and the logger's CPU load.

A virtual logger (``dischargelab virtual-device``) paced at the link's real
byte rate (115200 baud, 10 bits per byte = 11520 bytes/s) streams one-channel
SAMPLE frames (11 bytes) at the highest rate the link carries (1046 Hz after
Timer1 quantisation), with a few injected faults (bit flips, dropped bytes).
The real logger (``python -m dischargelab acquire``) runs as a separate process
over pyserial on the pty for ``--seconds`` (default 600 s), writing the log file
with fsync. Afterwards every logged row is checked against the device's record
of what it sent: a row whose codes differ from the intact frame with the same
sample index is a corrupt frame accepted (must be 0).

CPU: user + system time of the logger process (``os.wait4``) divided by its
wall-clock time, in % of one core; includes start-up and the fsync'ing writer.
Target: under 15 %.

Usage::

    python benchmarks/acquire_throughput.py                # 10 minutes
    python benchmarks/acquire_throughput.py --seconds 30   # quick run
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from dischargelab.acquire import protocol as proto
from dischargelab.acquire.sensors import adc_to_volts
from dischargelab.io.logfile import read_log

KE = 4.38


def wait_for(path: Path, timeout_s: float) -> None:
    end = time.monotonic() + timeout_s
    while not path.exists():
        if time.monotonic() > end:
            raise SystemExit(f"{path} did not appear within {timeout_s} s")
        time.sleep(0.05)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="logging time [s]")
    parser.add_argument("--baud", type=int, default=115200)
    parser.add_argument("--corrupt", type=float, default=0.001,
                        help="probability of bit flips per frame")
    parser.add_argument("--drop-bytes", type=float, default=0.0001,
                        help="probability of losing each byte")
    parser.add_argument("--keep", help="keep the files in this folder")
    args = parser.parse_args()

    n_channels = 1
    link_rate = proto.max_frame_rate_Hz(n_channels, args.baud)
    rate = int(link_rate)                       # highest whole rate the link carries
    period_us = proto.quantize_period_us(round(1e6 / rate))
    frame_bytes = proto.sample_frame_bytes(n_channels)
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="dlab-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    port, record, log = work / "tty", work / "record.csv", work / "run.csv"
    for p in (port, record, log):
        if p.exists() or p.is_symlink():
            p.unlink()
    python = sys.executable
    device = subprocess.Popen(
        [python, "-m", "dischargelab", "virtual-device", "--battery", "zippy-1100-2s",
         "--speed", "1", "--baud", str(args.baud), "--link", str(port), "--record", str(record),
         "--corrupt", str(args.corrupt), "--drop-bytes", str(args.drop_bytes), "--seed", "7",
         "--duration", str(args.seconds + 60)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(port, 30)
        started = time.monotonic()
        logger = subprocess.Popen(
            [python, "-m", "dischargelab", "acquire", "--port", str(port), "--out", str(log),
             "--ke", str(KE), "--cells", "2", "--current", "1.1", "--rate", str(rate),
             "--duration", str(args.seconds), "--quiet", "--every", "60", "--json"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        _, status, usage = os.wait4(logger.pid, 0)
        wall = time.monotonic() - started
        summary = json.loads(logger.stdout.read() or "{}")
        cpu_s = usage.ru_utime + usage.ru_stime
    finally:
        device.terminate()
        device.wait(30)

    rec = pd.read_csv(record)
    data, meta = read_log(log)
    produced = len(rec)
    # only what the device produced while the logger was listening (up to its last row)
    idx = np.rint(data["time_s"].to_numpy() / (period_us / 1e6)).astype(np.int64)
    last = int(idx.max()) if len(idx) else -1
    window = rec[rec["index"] <= last]
    by_status = window["status"].value_counts().to_dict()
    intact = window[window["status"] == "sent"].set_index("index")
    codes = intact["codes"].astype(int)
    expected_V = np.round(KE * adc_to_volts(codes.to_numpy()), 4)
    expected = pd.Series(expected_V, index=intact.index)
    logged = pd.Series(data["voltage_V"].to_numpy(), index=idx)
    matched = logged.index.isin(expected.index)
    wrong = int((~matched).sum())
    wrong += int((np.abs(logged[matched].to_numpy() - expected[logged.index[matched]].to_numpy())
                  > 5e-5).sum())
    stats = summary.get("stats", {})
    received = len(data)
    duration = float(data["time_s"].iloc[-1]) if received else 0.0
    rows = [
        ("link", f"{args.baud} baud = {args.baud / 10:.0f} B/s; frame {frame_bytes} B; "
                 f"max {link_rate:.1f} frames/s"),
        ("requested rate", f"{rate} Hz -> {1e6 / period_us:.2f} Hz (Timer1 period {period_us} us)"),
        ("logging time", f"{duration:.1f} s test time, {wall:.1f} s wall (logger process)"),
        ("frames produced by device", f"{len(window)} (of {produced} in the whole device run)"),
        ("  sent intact", str(by_status.get("sent", 0))),
        ("  sent with flipped bits", str(by_status.get("corrupted", 0))),
        ("  sent with dropped bytes", str(by_status.get("bytes-dropped", 0))),
        ("  not sent (device buffer full)", str(by_status.get("overflow", 0))),
        ("frames received (rows in log)", str(received)),
        ("frames lost (host seq gaps)", str(stats.get("frames_lost", "?"))),
        ("frames rejected as corrupt", str(stats.get("frames_corrupt", "?"))),
        ("corrupt frames accepted", f"{wrong}  (must be 0)"),
        ("received frame rate",
         f"{received / max(duration, 1e-9):.1f} frames/s "
         f"({received * frame_bytes / max(duration, 1e-9) / (args.baud / 10) * 100:.1f} %"
         " of the link)"),
        ("logger CPU", f"{cpu_s:.1f} s over {wall:.1f} s = {cpu_s / wall * 100:.1f} % of one core"
                       f" (target < 15 %)"),
        ("logger exit status", str(os.waitstatus_to_exitcode(status))),
    ]
    print(f"# acquire_throughput  {dt.datetime.now().isoformat(timespec='seconds')}  "
          f"{platform.node()}  {platform.processor() or platform.machine()}  "
          f"{os.cpu_count()} cores  Python {platform.python_version()}")
    width = max(len(k) for k, _ in rows)
    print(f"| {'quantity'.ljust(width)} | value |")
    print(f"|{'-' * (width + 2)}|-------|")
    for key, value in rows:
        print(f"| {key.ljust(width)} | {value} |")
    if wrong:
        sys.exit(1)


if __name__ == "__main__":
    main()
