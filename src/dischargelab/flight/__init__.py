"""Flight logs in: fit a battery model from flights, replay what the pack did in the air.

Two entry points:

* :func:`flight_curves` turns the flights of a log into fit curves
  (:class:`~dischargelab.fit.Curve`) for a pack that did not start full and did
  not reach its cutoff. The charge already taken out before each flight comes
  from the pack's rest voltage before take-off through an open-circuit voltage
  (OCV) curve: the battery model's own when one is given, else the generic
  per-chemistry table :data:`GENERIC_OCV_V` (a prior), times the label capacity:
  ``initial_charge_Ah = (1 - SOC) * capacity_Ah``. :func:`fit_flights` (what
  ``dischargelab.fit`` runs for a :class:`FlightCurves`) fits them together; when
  the flights do not reach the knee of the OCV curve, the capacity ``C_Ah`` is
  held within :data:`CAPACITY_TOLERANCE` of the label and the OCV outside the
  flown range is held at the prior. Both say so in their notes.
* :func:`analyse_flight` reports, per flight: duration, charge and energy,
  rest and loaded voltages, sag at the peak current, the internal resistance
  through the flight (regression of voltage on current over short windows) next
  to the log's own estimate, and the charge left at landing. With a battery
  model it flies the logged current through the engine
  (:func:`dischargelab.engine.run`, a ``profile`` step) from the charge at
  take-off, compares the voltage, and replays the remaining flight time every
  :data:`REPLAY_EVERY_S` seconds: the model from the state at that moment at the
  recent load, next to the autopilots' own charge-counting estimates and, when
  the logged voltage reached the cutoff, the true value.

Sign convention: discharge current positive; charges are pack charges [Ah]
taken out of the pack since full unless a name says ``cell``. Times are log
times [s] unless a name says otherwise.


Modules: :mod:`.samples` (flights as samples, rest voltages), :mod:`.fitting`
(models from flights), :mod:`.analysis` (what each flight did), :mod:`.replay`
(the model flown through the log, remaining time); the OCV prior is
:mod:`dischargelab.ocv`.

References
----------
.. [1] The open-circuit voltage curves and their sources: :mod:`dischargelab.ocv`.
.. [2] PX4 parameter reference: BAT1_V_EMPTY, BAT1_V_CHARGED [V per cell],
   BAT1_R_INTERNAL [ohm per cell]; uORB ``battery_status.time_remaining_s``
   ("time remaining until the battery is empty under the previous averaged load").
.. [3] ArduPilot parameter reference: BATT_CAPACITY [mAh]; DataFlash ``CURR.CurrTot`` /
   ``BAT.CurrTot`` [mAh consumed].
"""

from __future__ import annotations

from ..ocv import (
    CHARGE_CELL_V,
    DEFAULT_CHEMISTRY,
    GENERIC_OCV_V,
    OCV_SOC,
    OCV_SOURCE,
    check_chemistry,
    model_charge_at_rest,
    ocv_from_soc,
    soc_from_rest_voltage,
    soc_per_10mV,
)
from .analysis import FlightAnalysis, FlightReport, analyse_flight, resistance_windows
from .fitting import CAPACITY_TOLERANCE, FlightCurves, fit_flights, flight_curves, steady_current
from .replay import REPLAY_EVERY_S
from .samples import (
    FlightSamples,
    RestVoltage,
    cells_from_gauge,
    flight_samples,
    infer_cells,
    resample,
)

__all__ = ["GENERIC_OCV_V", "OCV_SOC", "OCV_SOURCE", "CHARGE_CELL_V", "DEFAULT_CHEMISTRY",
           "CAPACITY_TOLERANCE", "REPLAY_EVERY_S", "FlightCurves", "FlightReport",
           "FlightAnalysis", "FlightSamples", "RestVoltage", "flight_curves", "fit_flights",
           "analyse_flight", "flight_samples", "resample", "steady_current", "check_chemistry",
           "soc_from_rest_voltage", "soc_per_10mV", "ocv_from_soc", "resistance_windows",
           "infer_cells", "cells_from_gauge", "model_charge_at_rest"]
