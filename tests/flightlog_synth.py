"""Write small synthetic flight logs (binary DataFlash, ULog) with known battery data.

The byte layouts follow the published formats: ArduPilot DataFlash (0xA3 0x95,
message id, payload; ``FMT`` messages define the others) and PX4 ULog (16-byte
header, then ``F`` format, ``A`` subscription and ``D`` data messages).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

# ----------------------------------------------------------------------------- DataFlash

_DF_STRUCT = {"b": "b", "B": "B", "h": "h", "H": "H", "i": "i", "I": "I", "f": "f", "d": "d",
              "n": "4s", "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I",
              "L": "i", "M": "B", "q": "q", "Q": "Q"}
_DF_HEAD = b"\xa3\x95"

#: name -> (id, format, columns) of the messages the writer knows.
DF_MESSAGES = {
    "FMT": (128, "BBnNZ", "Type,Length,Name,Format,Columns"),
    "PARM": (129, "QNf", "TimeUS,Name,Value"),
    "GPS": (130, "QBIH", "TimeUS,Status,GMS,GWk"),
    "BAT": (131, "QBfffffcfB", "TimeUS,Inst,Volt,VoltR,Curr,CurrTot,EnrgTot,Temp,Res,RemPct"),
    "BCL": (132, "QBfHHHHHHHHHHHH", "TimeUS,Instance,Volt,V1,V2,V3,V4,V5,V6,V7,V8,V9,V10,V11,V12"),
    "EV": (133, "QB", "TimeUS,Id"),
    "ARM": (134, "QBIBB", "TimeUS,ArmState,ArmChecks,Forced,Method"),
    "IMU": (135, "QBffffffIIfBB", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T,GH,AH"),
}


def _df_struct(fmt: str) -> struct.Struct:
    return struct.Struct("<" + "".join(_DF_STRUCT[c] for c in fmt))


class DataFlashWriter:
    """Collect DataFlash messages in memory; :meth:`save` writes them."""

    def __init__(self):
        self.parts: list[bytes] = []
        self._packers = {}
        for name, (msg_id, fmt, columns) in DF_MESSAGES.items():
            packer = _df_struct(fmt)
            self._packers[name] = (msg_id, packer)
            self.parts.append(self._fmt(msg_id, name, fmt, columns, packer.size + 3))

    def _fmt(self, msg_id, name, fmt, columns, length) -> bytes:
        _, packer = 128, _df_struct("BBnNZ")
        return _DF_HEAD + bytes([128]) + packer.pack(msg_id, length, name.encode(), fmt.encode(),
                                                     columns.encode())

    def add(self, name: str, *values) -> None:
        msg_id, packer = self._packers[name]
        values = [v.encode() if isinstance(v, str) else v for v in values]
        self.parts.append(_DF_HEAD + bytes([msg_id]) + packer.pack(*values))

    def bytes(self) -> bytes:
        return b"".join(self.parts)

    def save(self, path) -> Path:
        path = Path(path)
        path.write_bytes(self.bytes())
        return path


def dataflash_flights(path, *, rate_Hz=10.0, idle_A=0.3) -> dict:
    """A binary DataFlash log: two batteries, BCL cells, two armed flights, a 0 V end.

    Battery 0 (4S, 5000 mAh): 0.3 A idle, 20 A in flight 1 (10-70 s) and 30 A
    in flight 2 (100-160 s); voltage falls with the charge drawn. Battery 1:
    half the current. One record has a NaN current, the last one 0 V.

    Returns the expected figures.
    """
    w = DataFlashWriter()
    w.add("PARM", 0, "BATT_CAPACITY", 5000.0)
    w.add("PARM", 0, "BATT2_CAPACITY", 2200.0)
    t = np.arange(0.0, 180.0 + 1e-9, 1.0 / rate_Hz)
    current = np.full(t.size, idle_A)
    current[(t >= 10.0) & (t <= 70.0)] = 20.0
    current[(t >= 100.0) & (t <= 160.0)] = 30.0
    events = {10.0: ("ARM", 1), 70.0: ("ARM", 0), 100.0: ("EV", 10), 160.0: ("EV", 11)}
    charge_mAh = {0: 0.0, 1: 0.0}
    nan_index = int(np.searchsorted(t, 40.0))
    for k, tk in enumerate(t):
        us = int(round((tk + 5.0) * 1e6))
        if k % int(rate_Hz) == 0:
            w.add("GPS", us, 3, int(tk * 1000), 2200)
        for when, (kind, state) in events.items():
            if abs(tk - when) < 0.5 / rate_Hz:
                if kind == "ARM":
                    w.add("ARM", us, state, 0, 0, 0)
                else:
                    w.add("EV", us, state)
        for inst, share in ((0, 1.0), (1, 0.5)):
            amps = current[k] * share
            if k:
                charge_mAh[inst] += 0.5 * (current[k - 1] + current[k]) * share / rate_Hz / 3.6
            volts = 16.6 - 0.02 * amps - 0.0004 * charge_mAh[inst] * (1 + inst)
            if k == t.size - 1:
                volts = 0.0
            logged_amps = float("nan") if (k == nan_index and inst == 0) else amps
            w.add("BAT", us, inst, volts, volts + 0.02 * amps, logged_amps, charge_mAh[inst],
                  charge_mAh[inst] * 0.015, 2500, 0.02, 80)
            if inst == 0:
                cell = max(int(round(volts / 4 * 1000)), 5)
                w.add("BCL", us, 0, volts, cell, cell + 5, cell - 5, cell, 0xFFFF, 0xFFFF, 0xFFFF,
                      0xFFFF, 0xFFFF, 0xFFFF, 0xFFFF, 0xFFFF)
    w.save(path)
    return {"flights": [(10.0, 70.0), (100.0, 160.0)], "idle_A": idle_A, "cells": 4,
            "capacity_mAh": {0: 5000.0, 1: 2200.0}, "rows": t.size,
            "charge_mAh": {0: 20.0 * 60 / 3.6 + 30.0 * 60 / 3.6}}


# ----------------------------------------------------------------------------- ULog

_ULOG_TYPES = {"uint64_t": "Q", "int64_t": "q", "uint32_t": "I", "int32_t": "i", "uint16_t": "H",
               "int16_t": "h", "uint8_t": "B", "int8_t": "b", "float": "f", "double": "d",
               "bool": "?", "char": "c"}


class ULogWriter:
    """Build a minimal ULog file (version 1): formats, subscriptions, data."""

    def __init__(self, start_us: int = 1_000_000):
        self.body: list[bytes] = []
        self.header = b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", start_us)
        self.definitions: list[bytes] = []
        self.formats: dict[str, tuple[list[tuple[str, str]], struct.Struct]] = {}
        self.ids: dict[tuple[str, int], int] = {}
        self._info("sys_name", "char[4]", b"PX4 ")

    @staticmethod
    def _message(kind: str, payload: bytes) -> bytes:
        return struct.pack("<HB", len(payload), ord(kind)) + payload

    def _info(self, key: str, type_name: str, value: bytes) -> None:
        text = f"{type_name} {key}".encode()
        self.definitions.append(self._message("I", bytes([len(text)]) + text + value))

    def define(self, name: str, fields: list[tuple[str, str]]) -> None:
        """``fields``: [(type, name)], ``timestamp`` (uint64_t) first, no trailing padding."""
        text = f"{name}:" + "".join(f"{t} {n};" for t, n in fields)
        self.definitions.append(self._message("F", text.encode()))
        layout = "<"
        for type_name, _ in fields:
            base, _, count = type_name.partition("[")
            layout += (count.rstrip("]") if count else "") + _ULOG_TYPES[base]
        self.formats[name] = (fields, struct.Struct(layout))

    def add(self, name: str, multi_id: int, values: list) -> None:
        key = (name, multi_id)
        if key not in self.ids:
            msg_id = len(self.ids)
            self.ids[key] = msg_id
            self.body.append(self._message("A", struct.pack("<BH", multi_id, msg_id)
                                           + name.encode()))
        packer = self.formats[name][1]
        flat = []
        for v in values:
            flat.extend(v if isinstance(v, (list, tuple)) else [v])
        self.body.append(self._message("D", struct.pack("<H", self.ids[key]) + packer.pack(*flat)))

    def bytes(self) -> bytes:
        return self.header + b"".join(self.definitions) + b"".join(self.body)

    def save(self, path) -> Path:
        path = Path(path)
        path.write_bytes(self.bytes())
        return path


BATTERY_FIELDS = [("uint64_t", "timestamp"), ("float", "voltage_v"), ("float", "current_a"),
                  ("float", "discharged_mah"), ("float", "remaining"), ("float", "temperature"),
                  ("uint8_t", "cell_count"), ("uint8_t", "connected")]


def ulog_battery(path, *, current_a=None, n=40, rate_Hz=2.0, topic="battery_status") -> Path:
    """A ULog with one battery in ``topic``; ``current_a`` overrides every current."""
    w = ULogWriter()
    fields = BATTERY_FIELDS if topic == "battery_status" else [
        ("uint64_t", "timestamp"), ("float", "bus_voltage_v"), ("float", "bus_current_a"),
        ("float", "power_w")]
    w.define(topic, fields)
    w.define("vehicle_status", [("uint64_t", "timestamp"), ("uint8_t", "arming_state")])
    charge = 0.0
    for k in range(n):
        t_us = 1_000_000 + int(k * 1e6 / rate_Hz)
        amps = 10.0 if 5 <= k < n - 5 else 0.2
        charge += amps / rate_Hz / 3.6
        amps_logged = amps if current_a is None else current_a
        volts = 16.4 - 0.03 * amps - 0.0005 * charge
        if topic == "battery_status":
            w.add(topic, 0, [t_us, volts, amps_logged, charge, 0.9, 0.0, 4, 1])
        else:
            w.add(topic, 0, [t_us, volts, amps_logged, volts * amps_logged])
        if k % 2 == 0:
            w.add("vehicle_status", 0, [t_us, 2 if 5 <= k < n - 5 else 1])
    return w.save(path)


__all__ = ["DataFlashWriter", "dataflash_flights", "ULogWriter", "ulog_battery"]
