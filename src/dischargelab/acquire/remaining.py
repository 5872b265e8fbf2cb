"""Time left until a running discharge reaches its cutoff, from a battery model.

The model is run (:func:`dischargelab.simulate.simulate_current`, the one engine) from the
charge already taken out to the cutoff at the recent mean current. The charge taken out is
what the logger counted since the test started plus what the pack had given before it,
read once from the first voltage with the model (:func:`dischargelab.ocv.model_charge_at_rest`;
0 for a full pack). On the flat middle of a discharge this holds where a straight line
through the recent voltages does not: the knee is in the model, not in the recent slope.
"""

from __future__ import annotations

import math

from ..errors import SimulationError
from ..ocv import model_charge_at_rest
from ..simulate import simulate_current


def for_pack(battery, cells_series: int):
    """``battery`` with the bench's cells in series (the model's cell, the pack on test)."""
    if battery is None or battery.cells_series == int(cells_series):
        return battery
    return battery.with_pack(cells_series=int(cells_series))


def charge_before_test_Ah(battery, voltage_V: float, current_A: float | None) -> float:
    """Pack charge [Ah] the model says was out at the first sample (``voltage_V`` [V]
    at ``current_A`` [A]; None = at rest); 0 for a full pack."""
    if not math.isfinite(voltage_V):
        return 0.0
    current = current_A if current_A is not None and math.isfinite(current_A) else 0.0
    try:
        return model_charge_at_rest(battery, float(voltage_V), max(0.0, float(current)))
    except SimulationError:
        return 0.0


def model_time_to_cutoff_s(battery, *, charge_out_Ah: float, current_A: float,
                           cutoff_pack_V: float) -> float | None:
    """Seconds until ``battery`` reaches ``cutoff_pack_V`` [V] at ``current_A`` [A, pack]
    with ``charge_out_Ah`` [Ah, pack] already taken out.

    None when the model cannot say: no discharge current, the charge at or beyond the
    model's capacity, or the model reading the pack at or below the cutoff already (it
    disagrees with the pack, which is still above it).
    """
    if not (current_A > 0 and math.isfinite(charge_out_Ah) and cutoff_pack_V):
        return None
    charge = max(0.0, float(charge_out_Ah))
    if charge >= battery.capacity_Ah:
        return None
    try:
        sim = simulate_current(battery, float(current_A), cutoff_pack_V=float(cutoff_pack_V),
                               initial_charge_Ah=charge)
    except SimulationError:
        return None
    seconds = float(sim.time_to_cutoff_s)
    return seconds if math.isfinite(seconds) else None


__all__ = ["for_pack", "charge_before_test_Ah", "model_time_to_cutoff_s"]
