"""kill -9 of a running logger: the file is readable, nothing corrupt, at most ~1 s missing."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from dischargelab.acquire.sensors import adc_to_volts
from dischargelab.acquire.virtual_device import VirtualDevice
from dischargelab.io.logfile import read_log

KE = 4.38
RATE_HZ = 50.0


def rows_in(path) -> int:
    try:
        return max(0, path.read_text().count("\n") - 3)
    except FileNotFoundError:
        return 0


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_kill_minus_nine_loses_at_most_one_second(tmp_path, seed):
    rng = np.random.default_rng(seed)
    out = tmp_path / "run.csv"
    with VirtualDevice("zippy-1100-2s", speed=1, seed=seed, keep_history=True) as dev:
        logger = subprocess.Popen(
            [sys.executable, "-m", "dischargelab", "acquire", "--port", dev.port, "--out",
             str(out), "--ke", str(KE), "--cells", "2", "--rate", str(RATE_HZ), "--quiet",
             "--every", "1000"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            deadline = time.monotonic() + 90
            while rows_in(out) < 20:                  # logging for real
                assert logger.poll() is None, logger.stderr.read().decode()
                assert time.monotonic() < deadline, "the logger never started writing"
                time.sleep(0.05)
            time.sleep(float(rng.uniform(0.5, 3.0)))  # a random moment of the test
            killed_at = time.monotonic()              # CLOCK_MONOTONIC: same as the device's
            os.kill(logger.pid, signal.SIGKILL)
            logger.wait(30)
        finally:
            if logger.poll() is None:
                logger.kill()
        assert logger.returncode == -signal.SIGKILL
        history = list(dev.history)

    data, meta = read_log(out)
    assert meta["dropped"]["malformed"] == 0          # no corrupt row; a cut last line is fine
    sent = {f.index: f for f in history}
    index = np.rint(data["time_s"].to_numpy() * RATE_HZ).astype(int)
    assert np.all(np.diff(index) >= 1)
    for k, v, seq in zip(index, data["voltage_V"], data["seq"]):
        frame = sent[int(k)]
        assert frame.seq == seq
        assert v == pytest.approx(KE * float(adc_to_volts(frame.codes[0])), abs=5e-5)
    # every frame the device sent more than 1 s before the kill is in the file
    before = [f.index for f in history if f.status == "sent" and f.wall_time < killed_at - 1.0]
    missing = sorted(set(before) - set(index.tolist()))
    assert not missing, f"{len(missing)} samples missing from more than 1 s before the kill"
    assert len(before) >= 20


def _interruptible() -> None:
    """In the logger's process: Ctrl-C's default, as at a terminal. A suite started in the
    background by a shell (``make test &``) has SIGINT ignored, every child inherits that,
    and Python then installs no Ctrl-C handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_stops_cleanly_with_summary(tmp_path, signum):
    out = tmp_path / "run.csv"
    with VirtualDevice("zippy-1100-2s", speed=1, seed=3, relay=True) as dev:
        logger = subprocess.Popen(
            [sys.executable, "-m", "dischargelab", "acquire", "--port", dev.port, "--out",
             str(out), "--ke", str(KE), "--cells", "2", "--rate", "20", "--quiet",
             "--switch-load"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            preexec_fn=_interruptible)
        deadline = time.monotonic() + 90
        while rows_in(out) < 10:
            assert logger.poll() is None, logger.stderr.read()
            assert time.monotonic() < deadline, "the logger never started writing"
            time.sleep(0.05)
        logger.send_signal(signum)
        stdout, stderr = logger.communicate(timeout=60)
        assert dev.load_switched_off.is_set()          # the relay was opened on the way out
    assert logger.returncode == 0, stderr
    assert "Acquisition summary" in stdout and "user" in stdout
    data, meta = read_log(out)
    assert meta["dropped"] == {"partial_last_line": 0, "malformed": 0}
    kinds = [e["kind"] for e in meta["events"]]
    assert kinds[-2:] == ["user-stop", "stop"]
    assert meta["events"][-1]["frames_ok"] == len(data)
