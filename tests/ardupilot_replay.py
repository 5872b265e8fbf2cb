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
