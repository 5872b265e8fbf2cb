"""Simulate a battery under a load: constant current, constant power, or a profile of steps.

Loads are given as data (PyBaMM-style experiment steps)::

    simulate(battery, [Step("current", 20.0, 60.0, "climb"), Step("power", 250.0, None, "cruise")],
             cutoff_cell_V=3.0)

Sign convention: current and power are positive on discharge; all arrays are
pack-level (pack current, pack voltage, pack charge). A step without a duration
runs until the cutoff. The time to cutoff is found by root finding on the
closed-form model (constant current) or by event location on the charge ODE
(constant power), never by scanning a grid.

Constant power: at each instant the cell current solves ``V(i, q) * i = P`` with
``V = a(q) - b(q) * i`` (eq. 6 is linear in i), i.e.
``i = (a - sqrt(a**2 - 4*b*P)) / (2*b)``, the low-current branch. When
``a**2 < 4*b*P`` the battery cannot deliver the power ("power limit").

References
----------
.. [1] paper eq. (6) and Figs 5, 7, 10 (see ``../shared/paper``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from .errors import SimulationError
from .model import Battery, load_battery

STEP_KINDS = ("current", "power", "rest")

#: Points per simulated step on the output curve.
POINTS_PER_STEP = 200


@dataclass(frozen=True)
class Step:
    """One load step.

    Parameters
    ----------
    kind : {"current", "power", "rest"}
    value : float
        Pack current [A] or pack electric power [W] (discharge positive); ignored for rest.
    duration_s : float or None
        Duration [s]; None runs until the cutoff (not allowed for rest).
    name : str
        Label (flight phase name, ...).
    """

    kind: str
    value: float = 0.0
    duration_s: float | None = None
    name: str = ""

    def __post_init__(self):
        if self.kind not in STEP_KINDS:
            raise SimulationError(f"step kind must be one of {', '.join(STEP_KINDS)}, "
                                  f"got {self.kind!r}")
        if not np.isfinite(self.value) or (self.kind != "rest" and self.value < 0):
            raise SimulationError(f"step {self.name or self.kind!r}: load must be a finite "
                                  f"value >= 0 (discharge positive), got {self.value}")
        if self.duration_s is None and self.kind == "rest":
            raise SimulationError("a rest step needs a duration")
        if self.duration_s is not None and not (self.duration_s >= 0 and
                                                np.isfinite(self.duration_s)):
            raise SimulationError(f"step {self.name or self.kind!r}: duration must be >= 0 s, "
                                  f"got {self.duration_s}")

    def describe(self) -> str:
        """Human-readable step, e.g. 'discharge at 20 A for 60 s'."""
        if self.kind == "rest":
            load = "rest"
        elif self.kind == "current":
            load = f"discharge at {self.value:g} A"
        else:
            load = f"hold {self.value:g} W"
        until = "until cutoff" if self.duration_s is None else f"for {self.duration_s:g} s"
        return f"{load} {until}"


@dataclass
class SimulationResult:
    """Pack-level time series of a simulation and its summary numbers.

    Arrays: ``time_s``, ``current_A``, ``voltage_V``, ``power_W``, ``charge_Ah``,
    ``energy_Wh`` (cumulative), ``step`` (index into ``steps``).
    Scalars: ``time_to_cutoff_s`` (NaN when the profile ended first),
    ``capacity_Ah`` and ``energy_Wh_total`` delivered, ``ended_by`` in
    {"cutoff", "power limit", "end"}.
    """

    time_s: np.ndarray
    current_A: np.ndarray
    voltage_V: np.ndarray
    power_W: np.ndarray
    charge_Ah: np.ndarray
    energy_Wh: np.ndarray
    step: np.ndarray
    steps: list[Step]
    cutoff_pack_V: float
    ended_by: str
    battery: Battery = field(repr=False)
    initial_charge_Ah: float = 0.0

    @property
    def duration_s(self) -> float:
        """Simulated time [s]."""
        return float(self.time_s[-1])

    @property
    def time_to_cutoff_s(self) -> float:
        """Time at which the cutoff (or power limit) was reached [s]; NaN if never."""
        return self.duration_s if self.ended_by != "end" else float("nan")

    @property
    def capacity_Ah(self) -> float:
        """Charge delivered during the simulation [Ah]."""
        return float(self.charge_Ah[-1] - self.initial_charge_Ah)

    @property
    def energy_Wh_total(self) -> float:
        """Energy delivered during the simulation [Wh]."""
        return float(self.energy_Wh[-1])

    def to_pandas(self):
        """Time series as a DataFrame with canonical column names."""
        import pandas as pd

        names = [s.name or s.kind for s in self.steps]
        return pd.DataFrame({
            "time_s": self.time_s, "current_A": self.current_A, "voltage_V": self.voltage_V,
            "power_W": self.power_W, "charge_Ah": self.charge_Ah, "energy_Wh": self.energy_Wh,
            "step": [names[k] for k in self.step],
        })

    def to_dict(self) -> dict:
        """Summary for JSON output (the ``predict --json`` keys plus ``ended_by``)."""
        out = {}
        if len(self.steps) == 1 and self.steps[0].kind == "current":
            out["current_A"] = self.steps[0].value
        elif len(self.steps) == 1 and self.steps[0].kind == "power":
            out["power_W"] = self.steps[0].value
        out.update({
            "cutoff_V": self.cutoff_pack_V / self.battery.cells_series,
            "cutoff_pack_V": self.cutoff_pack_V,
            "time_to_cutoff_s": self.time_to_cutoff_s,
            "capacity_Ah": self.capacity_Ah,
            "energy_Wh": self.energy_Wh_total,
            "ended_by": self.ended_by,
            "cells_series": self.battery.cells_series,
            "strings_parallel": self.battery.strings_parallel,
        })
        return out

    def plot(self, ax=None, x: str = "time", **kwargs):
        """Voltage against time (``x="time"``) or charge (``x="charge"``); returns the Axes."""
        from .plot import plot_simulation

        return plot_simulation(self, ax=ax, x=x, **kwargs)


def _cutoff_pack(battery: Battery, cutoff_cell_V, cutoff_pack_V) -> float:
    if (cutoff_cell_V is None) == (cutoff_pack_V is None):
        raise SimulationError("give exactly one cutoff: per cell (cutoff_cell_V / --cutoff) "
                              "or per pack (cutoff_pack_V / --cutoff-pack)")
    value = cutoff_pack_V if cutoff_pack_V is not None else cutoff_cell_V * battery.cells_series
    if not np.isfinite(value) or value <= 0:
        raise SimulationError(f"cutoff voltage must be a positive number, got {value}")
    return float(value)


def linear_in_current(battery: Battery):
    """Pack voltage as a line in the current: returns ``a_b(q_pack) -> (a, b)``.

    Eq. (6) with ``i_f = i`` is linear in the current, so at pack charge ``Q`` [Ah]
    the pack voltage is ``V = a(Q) - b(Q) * I`` with ``a`` [V] and ``b`` [ohm]
    vectorised over ``Q`` (and over parameter samples).
    """
    p = battery.strings_parallel
    s = battery.cells_series
    prm = battery.parameters
    C = prm.C_Ah

    def a_b(q_pack):
        q = np.asarray(q_pack, dtype=float) / p
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            gain = C / (C - q)
            a = prm.E0_V - prm.K_V_per_Ah * gain * q + prm.A_V * np.exp(-prm.B_per_Ah * q)
            b = prm.R_ohm + prm.K_V_per_Ah * gain
        # pack level: V = s*(a - b*i/p)
        return s * a, s * b / p

    return a_b


def power_current(a, b, power_W):
    """Low-current root of (a - b*i)*i = P; NaN where the power cannot be delivered."""
    disc = a * a - 4.0 * b * power_W
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.sqrt(np.where(disc >= 0, disc, np.nan))
        # numerically stable form of (a - root) / (2b)
        i = 2.0 * power_W / (a + root)
    return i


def simulate(battery, steps, *, cutoff_cell_V: float | None = None,
             cutoff_pack_V: float | None = None, initial_charge_Ah: float = 0.0,
             points_per_step: int = POINTS_PER_STEP) -> SimulationResult:
    """Run load steps one after another until the profile ends or the cutoff is reached.

    Parameters
    ----------
    battery : Battery, preset name or battery-file path
    steps : sequence of Step
    cutoff_cell_V, cutoff_pack_V : float
        Cutoff voltage per cell or per pack [V]; give exactly one.
    initial_charge_Ah : float
        Pack charge already removed at the start [Ah] (0 = full).
    points_per_step : int
        Output samples per step (the time to cutoff does not depend on it).

    Returns
    -------
    SimulationResult

    Raises
    ------
    SimulationError
        Cutoff at or above the starting voltage, charge beyond the capacity, bad steps.
    """
    battery = load_battery(battery)
    steps = list(steps)
    if not steps:
        raise SimulationError("no load steps to simulate")
    for st in steps:
        if not isinstance(st, Step):
            raise SimulationError(f"steps must be Step objects, got {type(st).__name__}")
    cutoff = _cutoff_pack(battery, cutoff_cell_V, cutoff_pack_V)
    q_max = battery.capacity_Ah
    if not 0 <= initial_charge_Ah < q_max:
        raise SimulationError(f"initial charge removed {initial_charge_Ah:g} Ah must be in "
                              f"[0, {q_max:g}) Ah (the model capacity C x parallel strings)")
    a_b = linear_in_current(battery)
    first_load = next((st for st in steps if st.kind != "rest"), None)
    if first_load is not None:
        v0 = _start_voltage(a_b, first_load, initial_charge_Ah)
        if not v0 > cutoff:
            raise SimulationError(
                f"cutoff {cutoff / battery.cells_series:.3f} V/cell ({cutoff:.3f} V pack) is not "
                f"below the starting voltage {v0 / battery.cells_series:.3f} V/cell under "
                f"'{first_load.describe()}'; lower the cutoff or check --cells / --cutoff-pack")

    pieces = []
    t0, q0, e0 = 0.0, float(initial_charge_Ah), 0.0
    ended_by = "end"
    for k, st in enumerate(steps):
        piece, ended = _run_step(st, a_b, cutoff, t0, q0, q_max, points_per_step)
        piece["energy_Wh"] = e0 + _cumulative_energy(piece["time_s"], piece["power_W"])
        piece["step"] = np.full(piece["time_s"].size, k)
        pieces.append(piece)
        t0, q0, e0 = piece["time_s"][-1], piece["charge_Ah"][-1], piece["energy_Wh"][-1]
        if ended:
            ended_by = ended
            break
    cat = {key: np.concatenate([p[key] for p in pieces]) for key in pieces[0]}
    return SimulationResult(
        time_s=cat["time_s"], current_A=cat["current_A"], voltage_V=cat["voltage_V"],
        power_W=cat["power_W"], charge_Ah=cat["charge_Ah"], energy_Wh=cat["energy_Wh"],
        step=cat["step"].astype(int), steps=steps, cutoff_pack_V=cutoff, ended_by=ended_by,
        battery=battery, initial_charge_Ah=float(initial_charge_Ah),
    )


def _start_voltage(a_b, step: Step, q0: float) -> float:
    a, b = a_b(q0)
    if step.kind == "current":
        return float(a - b * step.value)
    i = power_current(a, b, step.value)
    if not np.isfinite(i):
        raise SimulationError(f"the battery cannot deliver {step.value:g} W: its maximum power "
                              f"at the start is {a * a / (4 * b):.1f} W; lower the power")
    return float(a - b * i)


def _cumulative_energy(t, p):
    e = np.zeros_like(t)
    if t.size > 1:
        np.cumsum(0.5 * (p[1:] + p[:-1]) * np.diff(t), out=e[1:])
    return e / 3600.0


def _run_step(st: Step, a_b, cutoff, t0, q0, q_max, n):
    if st.kind == "power":
        return _run_power(st, a_b, cutoff, t0, q0, q_max, n)
    current = 0.0 if st.kind == "rest" else float(st.value)
    return _run_current(st, current, a_b, cutoff, t0, q0, q_max, n)


def _pack_voltage(a_b, current, q):
    a, b = a_b(q)
    return a - b * current


def _run_current(st, current, a_b, cutoff, t0, q0, q_max, n):
    """Constant current: q(t) = q0 + i t / 3600, cutoff by Brent's method on the closed form."""
    ended = None
    duration = st.duration_s
    q_limit = q_max * (1.0 - 1e-12)
    if _pack_voltage(a_b, current, q0) <= cutoff:
        ended = "cutoff"
        duration = 0.0
    elif current > 0:
        q_end = q_limit if duration is None else min(q0 + current * duration / 3600.0, q_limit)
        if duration is None or _pack_voltage(a_b, current, q_end) <= cutoff:
            q_cut = brentq(lambda q: _pack_voltage(a_b, current, q) - cutoff, q0, q_limit,
                           xtol=1e-12, rtol=1e-12)
            duration = (q_cut - q0) * 3600.0 / current
            ended = "cutoff"
    t = np.linspace(0.0, duration, max(n, 2))
    q = q0 + current * t / 3600.0
    if ended:
        q[-1] = q0 + current * duration / 3600.0
    v = _pack_voltage(a_b, current, q)
    if ended:
        v[-1] = cutoff  # exact at the root
    return {"time_s": t0 + t, "current_A": np.full(t.size, current), "voltage_V": v,
            "power_W": v * current, "charge_Ah": q}, ended


def _run_power(st, a_b, cutoff, t0, q0, q_max, n):
    """Constant power: integrate dq/dt = i(q)/3600 with events at the cutoff and power limit."""
    power = float(st.value)

    def current_at(q):
        a, b = a_b(q)
        return power_current(a, b, power)

    def rhs(_t, y):
        i = current_at(y[0])
        return [i / 3600.0 if np.isfinite(i) else 0.0]

    def cutoff_event(_t, y):
        i = current_at(y[0])
        if not np.isfinite(i):
            return -1.0
        return float(_pack_voltage(a_b, i, y[0]) - cutoff)

    def limit_event(_t, y):
        a, b = a_b(y[0])
        return float(a * a - 4.0 * b * power)

    cutoff_event.terminal = True
    cutoff_event.direction = -1
    limit_event.terminal = True
    limit_event.direction = -1

    if not np.isfinite(current_at(q0)):
        return _single_point(t0, q0, 0.0, a_b), "power limit"
    if cutoff_event(0, [q0]) <= 0:
        return _single_point(t0, q0, current_at(q0), a_b), "cutoff"
    if power == 0:
        duration = st.duration_s
        t = np.linspace(0.0, duration, max(n, 2))
        v = _pack_voltage(a_b, 0.0, np.full(t.size, q0))
        return {"time_s": t0 + t, "current_A": np.zeros(t.size), "voltage_V": v,
                "power_W": np.zeros(t.size), "charge_Ah": np.full(t.size, q0)}, None
    # upper time bound: the charge left at the smallest possible current (P / a_max)
    t_end = st.duration_s
    if t_end is None:
        a0, _ = a_b(q0)
        t_end = (q_max - q0) * 3600.0 * max(a0, 1e-9) / power * 1.01 + 1.0
    sol = solve_ivp(rhs, (0.0, t_end), [q0], method="RK45", dense_output=True,
                    events=(cutoff_event, limit_event), rtol=1e-9, atol=1e-12,
                    max_step=max(t_end / 50.0, 1e-3))
    if sol.status == -1:
        raise SimulationError(f"constant-power integration failed: {sol.message}")
    ended = None
    duration = sol.t[-1]
    if sol.t_events[0].size:
        ended, duration = "cutoff", float(sol.t_events[0][0])
    if sol.t_events[1].size and (ended is None or sol.t_events[1][0] < duration):
        ended, duration = "power limit", float(sol.t_events[1][0])
    if st.duration_s is None and ended is None:
        raise SimulationError("constant-power step did not reach the cutoff; check the cutoff")
    t = np.linspace(0.0, duration, max(n, 2))
    q = sol.sol(t)[0]
    i = current_at(q)
    if ended == "power limit":
        # at the limit the discriminant is zero: i = a / (2b)
        a, b = a_b(q[-1])
        i[-1] = a / (2.0 * b)
    v = _pack_voltage(a_b, i, q)
    if ended == "cutoff":
        v[-1] = cutoff
    return {"time_s": t0 + t, "current_A": i, "voltage_V": v, "power_W": v * i,
            "charge_Ah": q}, ended


def _single_point(t0, q0, current, a_b):
    v = _pack_voltage(a_b, current, q0)
    return {"time_s": np.array([t0]), "current_A": np.array([current]),
            "voltage_V": np.array([v]), "power_W": np.array([v * current]),
            "charge_Ah": np.array([q0])}


def simulate_current(battery, current_A: float, *, cutoff_cell_V: float | None = None,
                     cutoff_pack_V: float | None = None, initial_charge_Ah: float = 0.0,
                     points: int = POINTS_PER_STEP) -> SimulationResult:
    """Constant-current discharge [A, pack] until the cutoff (paper Figs 5, 7, 10)."""
    if not current_A > 0:
        raise SimulationError(f"discharge current must be > 0 A, got {current_A}")
    return simulate(battery, [Step("current", float(current_A))], cutoff_cell_V=cutoff_cell_V,
                    cutoff_pack_V=cutoff_pack_V, initial_charge_Ah=initial_charge_Ah,
                    points_per_step=points)


def simulate_power(battery, power_W: float, *, cutoff_cell_V: float | None = None,
                   cutoff_pack_V: float | None = None, initial_charge_Ah: float = 0.0,
                   points: int = POINTS_PER_STEP) -> SimulationResult:
    """Constant-power discharge [W, pack] until the cutoff or the power limit."""
    if not power_W > 0:
        raise SimulationError(f"discharge power must be > 0 W, got {power_W}")
    return simulate(battery, [Step("power", float(power_W))], cutoff_cell_V=cutoff_cell_V,
                    cutoff_pack_V=cutoff_pack_V, initial_charge_Ah=initial_charge_Ah,
                    points_per_step=points)


def curve_family(battery, currents_A=None, *, powers_W=None, cutoff_cell_V=None,
                 cutoff_pack_V=None) -> list[SimulationResult]:
    """Constant-current (or constant-power) discharges at several loads (paper Figs 5, 7, 10)."""
    battery = load_battery(battery)
    if (currents_A is None) == (powers_W is None):
        raise SimulationError("give either currents or powers for a curve family")
    kw = dict(cutoff_cell_V=cutoff_cell_V, cutoff_pack_V=cutoff_pack_V)
    if currents_A is not None:
        return [simulate_current(battery, i, **kw) for i in currents_A]
    return [simulate_power(battery, p, **kw) for p in powers_W]
