"""Replay battery readings through a generated ArduPilot script in a real Lua 5.3, with the
stand-in of the bindings (``ardupilot_standin.lua``); shared by the tests and the benchmark."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

STANDIN = Path(__file__).with_name("ardupilot_standin.lua")


def lua() -> str | None:
    """The Lua 5.3 interpreter, or None."""
    return shutil.which("lua5.3")


@dataclass
class Replay:
    floats: dict = field(default_factory=dict)   # name -> (times_s, values)
    texts: list = field(default_factory=list)    # (time_s, severity, text)
    max_instructions: int = 0
    heap_kb: float = 0.0
    calls: int = 0

    def series(self, name: str):
        t, v = self.floats.get(name, ([], []))
        return np.asarray(t, dtype=float), np.asarray(v, dtype=float)


def _field(x) -> str:
    if x is None:
        return "nil"
    if isinstance(x, bool):
        return "1" if x else "0"
    return repr(float(x))


def replay(script_text: str, rows, timeout_s: float = 600.0, params: dict | None = None
           ) -> Replay:
    """Run ``script_text`` on ``rows`` ``(time_ms, armed, voltage, current, consumed_mAh)``,
    with parameter values ``params`` (``{"DL_RESERVE": 60}``)."""
    exe = lua()
    if exe is None:
        raise RuntimeError("lua5.3 is not installed (make lua)")
    with tempfile.TemporaryDirectory() as tmp:
        script = os.path.join(tmp, "battery.lua")
        samples = os.path.join(tmp, "samples.txt")
        Path(script).write_text(script_text)
        with open(samples, "w") as fh:
            for t, armed, v, c, q in rows:
                fh.write(f"{int(t)} {_field(bool(armed))} {_field(v)} {_field(c)} {_field(q)}\n")
        env = dict(os.environ, STANDIN_PARAMS=",".join(f"{k}={v}" for k, v in
                                                        (params or {}).items()))
        proc = subprocess.run([exe, str(STANDIN), script, samples], capture_output=True,
                              text=True, timeout=timeout_s, check=False, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"lua5.3 failed: {proc.stderr.strip()}")
    out = Replay()
    for line in proc.stdout.splitlines():
        kind, _, rest = line.partition(" ")
        if kind == "F":
            t, name, value = rest.split(" ")
            ts, vs = out.floats.setdefault(name, ([], []))
            ts.append(int(t) / 1000.0)
            vs.append(float(value))
        elif kind == "T":
            t, sev, text = rest.split(" ", 2)
            out.texts.append((int(t) / 1000.0, int(sev), text))
        elif kind == "I":
            out.max_instructions = int(rest)
        elif kind == "H":
            out.heap_kb = float(rest)
        elif kind == "N":
            out.calls = int(rest)
    return out


def flight_rows(samples, counter: bool = False) -> list[tuple]:
    """Battery-monitor readings of a logged flight (a ``FlightAnalysis.samples`` frame):
    armed while in flight, consumed charge integrated from the current, or with ``counter``
    the log's own consumed-charge counter as it was logged (from its first value)."""
    t = samples["time_s"].to_numpy(dtype=float)
    v = samples["voltage_V"].to_numpy(dtype=float)
    i = samples["current_A"].to_numpy(dtype=float)
    armed = samples["in_flight"].to_numpy(dtype=bool)
    used = np.concatenate([[0.0], np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t))]) / 3.6
    if counter:
        logged = samples["log_discharged_mAh"].ffill().bfill().to_numpy(dtype=float)
        used = logged - logged[0]
    return [(int(round(tk * 1000)), bool(a), float(vk), float(ik), float(qk))
            for tk, a, vk, ik, qk in zip(t - t[0], armed, v, i, used)]


def against_python_replay(script_text: str, analysis,
                          counter: bool = False) -> tuple[float, Replay]:
    """Largest |DL_TREM - the Python replay's time left at the recent load| over a logged
    flight's replay moments, in % of the flight's time to cutoff as the Python replay sees
    it at its first moment."""
    samples = analysis.samples
    t0 = float(samples["time_s"].iloc[0])
    rep = replay(script_text, flight_rows(samples, counter))
    ts, trem = rep.series("DL_TREM")
    rows = analysis.replay.dropna(subset=["model_s"])
    if rows.empty or ts.size == 0:
        raise RuntimeError("nothing to compare: no replay moment or no DL_TREM sent")
    start = float(samples["time_s"][samples["in_flight"]].iloc[0])
    total = float(rows["time_s"].iloc[0]) - start + float(rows["model_s"].iloc[0])
    worst = 0.0
    for time_s, model_s in zip(rows["time_s"], rows["model_s"]):
        k = int(np.argmin(np.abs(ts + t0 - time_s)))
        worst = max(worst, abs(float(trem[k]) - float(model_s)) / total * 100.0)
    return worst, rep
