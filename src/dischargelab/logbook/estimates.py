"""Per-event estimates as a fuel gauge makes them: plain functions of arrays with units.

* **Relaxation** of a rest before its reading: :mod:`.relaxation`.
* **Open-circuit voltage.** :class:`OcvCurve`: the pack's own, learned from a slow
  full discharge (its loaded voltage plus the resistive drop, state of charge by
  coulomb counting), else a chemistry's generic curve (:mod:`dischargelab.ocv`).
  :func:`soc_reading` reads the state of charge of a rest voltage through it, with
  a standard deviation from the curve, the relaxation left, the idle current's
  drop and the temperature (the entropic change of the open-circuit voltage).
* **Counted charge.** :func:`counted_charge` integrates the current (trapezoids)
  and says how well the samples can count it: between two samples the current may
  have done anything within the change seen there (at least the event's typical
  sample-to-sample change), so each interval adds ``dt * max(|di|, typical) /
  sqrt(12)`` to the standard deviation. A take-off seen by two samples 167 s apart
  makes a mission uncountable; a charge's smooth current does not.
* **The error estimates share.** :func:`systematic_share`: what every capacity read
  through one curve shares (the curve's error, its drift as the cell ages), which many
  estimates do not average out.
* **Capacity between two rests.** :func:`capacity_between_rests`: the charge counted
  between the two readings divided by the change in state of charge they read.
  Small swings carry little information, as in a fuel gauge's learning rule
  (TI's Impedance Track updates its capacity only after enough passed charge):
  below :data:`MIN_SWING` no estimate, and the interval grows as the swing shrinks.
* **Resistance at reference conditions.** :func:`resistance_at_reference` moves a
  resistance measured at the cell's temperature to :data:`REFERENCE_TEMPERATURE_C`
  (Arrhenius, the prior activation of :mod:`dischargelab.models.thermal`) and,
  through the pack's model when it has one, to :data:`REFERENCE_SOC`.

References
----------
.. [1] Texas Instruments, "Theory and Implementation of Impedance Track Battery
   Fuel-Gauging Algorithm in bq20zxx Product Family", SLUA364B (2006-2009):
   chemical capacity ``Qmax = passed charge / |SOC1 - SOC2|`` from two relaxed
   open-circuit voltages, updated only after enough passed charge; resistance
   from the voltage under load.
.. [2] Texas Instruments, "Gauging: Achieving the Successful Learning Cycle",
   SLUA903 and "Impedance Track Gas Gauge for Novices", SLUA450 (relaxation
   before an OCV reading, depth of discharge needed for a capacity update).
.. [3] G. L. Plett, "Battery Management Systems, Vol. 1: Battery Modeling",
   Artech House (2015), ch. 2 (OCV from a slow discharge corrected for the
   resistive drop; diffusion relaxation) and Vol. 2 (2016), ch. 3-4 (SOC and
   capacity estimation, their uncertainty).
.. [4] V. Pop, H. J. Bergveld, P. H. L. Notten, P. P. L. Regtien, "State-of-the-art
   of battery state-of-charge determination", Meas. Sci. Technol. 16 (2005)
   R93-R110 (EMF from relaxation, extrapolated).
.. [5] M. Dubarry, C. Truchot, B. Y. Liaw, "Synthesize battery degradation modes via a
   diagnostic and prognostic model", J. Power Sources 219 (2012) 204-216; C. R. Birkl
   et al., "Degradation diagnostics for lithium ion cells", J. Power Sources 341 (2017)
   373-386 (an aged cell's open-circuit voltage curve under loss of lithium inventory
   and of active material: :data:`OCV_AGEING_SD`).
.. [6] A. Barai, W. D. Widanage, J. Marco, A. McGordon, P. Jennings, "A study of the open
   circuit voltage characterization technique and hysteresis assessment of lithium-ion
   cells", J. Power Sources 295 (2015) 99-107; M. A. Roscher, O. Bohlen, J. Vetter, "OCV
   hysteresis in Li-ion batteries including two-phase transition materials", Int. J.
   Electrochem. 2011, 984320 (the gap between the charge and discharge branches:
   :data:`HYSTERESIS_SD_CELL_V`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Standard deviation of one voltage sample per cell [V] (ADC noise and steps).
READING_SD_CELL_V = 0.002

#: Entropic temperature coefficient of the open-circuit voltage per cell [V/K]: its
#: size for NMC and LCO cells (0.1-0.4 mV/K, sign depending on the state of charge),
#: taken as an uncertainty away from the curve's temperature.
ENTROPIC_V_PER_K = 0.0003

#: Standard deviation of a generic chemistry curve per cell [V] (real packs differ by
#: tens of millivolts: :data:`dischargelab.ocv.GENERIC_OCV_V`).
PRIOR_CURVE_SD_CELL_V = 0.015

#: Standard deviation of a curve learned from the pack's own slow full discharge per
#: cell [V] (the resistive drop added back is known to about half of itself).
LEARNED_CURVE_SD_CELL_V = 0.005

#: Standard deviation per cell [V] of a rest after a charge read through a discharge
#: curve. A cell rests higher after a charge than after a discharge to the same state of
#: charge (open-circuit voltage hysteresis: a gap of 10-20 mV for NMC and LiCoO2 cells
#: over the middle of the charge, more for LiFePO4; Barai et al. 2015, Roscher et al.
#: 2011). The learned and the generic curves are discharge curves, and a charge that
#: stops short of full (a charger set to 4.0 V, a storage charge) leaves its rest on the
#: other branch; the gap is not measured per pack, so it is carried (in the reading and
#: in what every such reading shares, :func:`systematic_share`).
HYSTERESIS_SD_CELL_V = 0.010

#: State of charge after a charge that ends in a constant-voltage taper at the pack's
#: full voltage, and its standard deviation (full, as the charger defines it).
FULL_SOC = 1.0
FULL_SOC_SD = 0.01

#: Standard deviation of a capacity read through an open-circuit voltage curve, as a share
#: of the pack's fade since the curve was learned (a relative error per unit of fade). An
#: aged cell's curve against its own state of charge is not the fresh one: the two
#: bounding degradation modes are a curve that holds against the state of charge scaled
#: to today's capacity (loss of active material of both electrodes alike: no error) and a
#: curve that holds against the charge drawn from full (loss of lithium inventory, the
#: negative electrode limiting the end: the readings then give the fresh capacity, an
#: error of the whole fade, whatever the depth of the swing). Real cells age between the
#: two (Dubarry et al. 2012; Birkl et al. 2017); this share of the fade is the standard
#: deviation, and the error is shared by every estimate read through the curve.
OCV_AGEING_SD = 0.15

#: Smallest change in state of charge that gives a capacity (smaller swings carry too
#: little information: TI's gauges wait for far more).
MIN_SWING = 0.1

#: Largest standard deviation of one state-of-charge reading kept [-].
MAX_SOC_SD = 0.5

#: The counted charge is "resolved" when its standard deviation is at most this share.
RESOLVED_SHARE = 0.01

#: Reference conditions of ``resistance_ref_ohm``: temperature [degC] and state of charge.
REFERENCE_TEMPERATURE_C = 25.0
REFERENCE_SOC = 0.5

#: Relative standard deviation of the Arrhenius coefficient (the prior's, not the pack's).
BETA_RELATIVE_SD = 0.5

#: Load steps used for the resistance: at most this far apart [s] (so the open-circuit
#: voltage has not moved and the slow polarisation has not built up).
STEP_MAX_DT_S = 2.0

#: A load step counts when the current changes by at least this share of the event's
#: mean current (and :data:`STEP_MIN_A`).
STEP_MIN_FRACTION = 0.2

#: ... and by at least this much [A].
STEP_MIN_A = 0.2

#: Grid of a learned curve's states of charge.
CURVE_GRID = np.linspace(0.0, 1.0, 101)

Z95 = 1.959964


# --------------------------------------------------------------------------- OCV

@dataclass
class OcvCurve:
    """Open-circuit voltage per cell against state of charge.

    Attributes
    ----------
    soc : numpy.ndarray
        State of charge, ascending from 0 (empty) to 1 (full) [-].
    cell_V : numpy.ndarray
        Open-circuit voltage per cell there, non-decreasing [V].
    sd_V : float
        Standard deviation of the curve itself per cell [V].
    source : str
        Where it comes from (for notes).
    temperature_C : float or None
        Temperature it was measured at [degC].
    capacity_Ah : float or None
        Capacity its state of charge is scaled to [Ah] (the slow discharge's), None for a
        generic curve.
    spread_V : numpy.ndarray or None
        A further standard deviation at each ``soc`` [V per cell] (a chemistry not known:
        half the spread between the curves it may be), in quadrature with ``sd_V``.
    cells_spread_V : numpy.ndarray or None
        The spread of real cells' curves about a generic one at each ``soc`` [V per cell]
        (:data:`dischargelab.ocv.GENERIC_OCV_SPREAD_V`), in quadrature too: one offset
        for all of a pack's readings (its cells are alike), which does not average out
        over its events (:func:`systematic_share`).
    """

    soc: np.ndarray
    cell_V: np.ndarray
    sd_V: float
    source: str
    temperature_C: float | None = None
    capacity_Ah: float | None = None
    spread_V: np.ndarray | None = None
    cells_spread_V: np.ndarray | None = None

    def sd_at(self, soc: float, cells_alike: bool = True) -> float:
        """Standard deviation of the curve per cell at ``soc`` [V]; with ``cells_alike``
        False, without ``cells_spread_V`` (for what an offset common to the pack's
        readings cancels in)."""
        var = float(self.sd_V) ** 2
        if self.spread_V is not None:
            var += float(np.interp(soc, self.soc, self.spread_V)) ** 2
        if cells_alike:
            var += self.cells_sd_at(soc) ** 2
        return float(np.sqrt(var))

    def cells_sd_at(self, soc: float) -> float:
        """Real cells' spread about the curve per cell at ``soc`` [V] (0 without one)."""
        if self.cells_spread_V is None:
            return 0.0
        return float(np.interp(soc, self.soc, self.cells_spread_V))

    @classmethod
    def unknown(cls) -> OcvCurve:
        """A 4.2 V pack whose chemistry is not known (neither given nor read from a full
        discharge): the mean of the generic LiPo and Li-ion curves, half their difference
        carried as the curve's error at each state of charge (0.22 V apart at 30 %: a
        LiPo pouch's flat low end against an NMC cylinder's slope), with the Li-ion
        cells' own spread about theirs (:data:`dischargelab.ocv.GENERIC_OCV_SPREAD_V`)."""
        from ..ocv import GENERIC_OCV_SPREAD_V, OCV_SOC, generic_ocv

        lipo, _ = generic_ocv("lipo")
        li_ion, _ = generic_ocv("li-ion")
        mean = np.maximum.accumulate((0.5 * (lipo + li_ion))[::-1])
        return cls(soc=OCV_SOC[::-1].astype(float), cell_V=mean,
                   sd_V=PRIOR_CURVE_SD_CELL_V, spread_V=(0.5 * np.abs(lipo - li_ion))[::-1],
                   cells_spread_V=GENERIC_OCV_SPREAD_V["li-ion"][::-1].copy(),
                   source="the mean of the generic LiPo and Li-ion curves (chemistry not "
                          "known: give it to narrow the interval)", temperature_C=25.0)

    @classmethod
    def prior(cls, chemistry: str | None, rest_cell_V: float | None = None) -> OcvCurve:
        """The generic curve of a chemistry (:func:`dischargelab.ocv.generic_ocv`): a LiPo
        pack resting above 4.25 V per cell (``rest_cell_V``, its highest rest) gets the
        high-voltage (LiHV, 4.35 V) curve. Real cells' spread about it
        (:data:`dischargelab.ocv.GENERIC_OCV_SPREAD_V`) is carried as ``cells_spread_V``."""
        from ..ocv import GENERIC_OCV_SPREAD_V, OCV_SOC, check_chemistry, generic_ocv, is_lihv

        table, source = generic_ocv(chemistry, rest_cell_V)
        spread = None if is_lihv(chemistry, rest_cell_V) else \
            GENERIC_OCV_SPREAD_V.get(check_chemistry(chemistry))
        if spread is not None:
            source += (f" (other cells' curves scatter about it by "
                       f"{1000 * spread[1:-1].min():.0f}-{1000 * spread[1:-1].max():.0f} mV, "
                       "most near empty: carried in the interval; a slow full discharge of "
                       "the pack reads its own)")
        return cls(soc=OCV_SOC[::-1].astype(float), cell_V=table[::-1].copy(),
                   sd_V=PRIOR_CURVE_SD_CELL_V, source=source, temperature_C=25.0,
                   cells_spread_V=None if spread is None else spread[::-1].copy())

    @classmethod
    def from_discharge(cls, charge_Ah, voltage_V, current_A, *, cells: int,
                       resistance_ohm: float, rest_before_V: float | None = None,
                       temperature_C: float | None = None, source: str = "") -> OcvCurve:
        """The pack's curve from one slow full discharge.

        ``OCV = (V + R I) / cells`` at ``SOC = 1 - q / q_end`` (Plett 2015, ch. 2),
        with the rest voltage before the load (when given) at SOC 1, resampled on
        :data:`CURVE_GRID` and made non-decreasing.

        Parameters
        ----------
        charge_Ah, voltage_V, current_A : array_like
            The discharge's charge drawn [Ah], pack voltage [V] and current [A].
        cells : int
            Cells in series.
        resistance_ohm : float
            Pack resistance added back at each current [ohm].
        rest_before_V : float, optional
            Pack rest voltage before the load [V].
        """
        q = np.maximum.accumulate(np.asarray(charge_Ah, dtype=float))
        ocv = (np.asarray(voltage_V, dtype=float)
               + resistance_ohm * np.asarray(current_A, dtype=float)) / cells
        keep = np.concatenate(([True], np.diff(q) > 0))
        q, ocv = q[keep], ocv[keep]
        soc = 1.0 - q / q[-1]
        if rest_before_V is not None:
            soc = np.concatenate(([1.0], soc[soc < 1.0]))
            ocv = np.concatenate(([rest_before_V / cells], ocv[-soc.size + 1:]))
        order = np.argsort(soc)
        grid_v = np.interp(CURVE_GRID, soc[order], ocv[order])
        grid_v = np.maximum.accumulate(grid_v)
        return cls(soc=CURVE_GRID.copy(), cell_V=grid_v, sd_V=LEARNED_CURVE_SD_CELL_V,
                   source=source or "the pack's slow full discharge",
                   temperature_C=temperature_C, capacity_Ah=float(q[-1]))

    def soc_at(self, cell_V: float) -> float:
        """State of charge where the curve reads ``cell_V`` [V] (clipped to 0-1)."""
        return float(np.interp(cell_V, self.cell_V, self.soc))

    def voltage_at(self, soc) -> np.ndarray:
        """Open-circuit voltage per cell at ``soc`` [V]."""
        return np.interp(soc, self.soc, self.cell_V)

    def slope(self, soc: float, span: float = 0.05) -> float:
        """``dOCV/dSOC`` per cell around ``soc`` [V per unit SOC], over +-``span``."""
        lo, hi = max(0.0, soc - span), min(1.0, soc + span)
        if hi <= lo:
            return 0.0
        return float((self.voltage_at(hi) - self.voltage_at(lo)) / (hi - lo))


def soc_reading(curve: OcvCurve, reading: dict, cells: int, *,
                resistance_ohm: float | None = None,
                cells_alike: bool = True) -> tuple[float, float]:
    """State of charge of a rest reading and its standard deviation [-].

    Parameters
    ----------
    curve : OcvCurve
    reading : dict
        A rest reading (:func:`dischargelab.logbook.events.rest_reading`): pack
        ``relaxed_V`` and ``half95_V`` [V], the rest's ``current_A`` (idle draw,
        discharge positive) and ``temperature_C``.
    cells : int
        Cells in series.
    resistance_ohm : float, optional
        Pack resistance [ohm]: the idle draw's drop is added back (``V + R I``).
    cells_alike : bool
        False: without real cells' spread about a generic curve (``curve.cells_spread_V``,
        an offset the pack's readings share: :func:`cells_share`).

    Returns
    -------
    (soc, sd)
    """
    r = float(resistance_ohm or 0.0)
    idle = float(reading.get("current_A") or 0.0)
    cell_v = (float(reading["relaxed_V"]) + r * idle) / cells
    soc = curve.soc_at(cell_v)
    var = (curve.sd_at(soc, cells_alike) ** 2 + READING_SD_CELL_V ** 2
           + (float(reading.get("half95_V") or 0.0) / Z95 / cells) ** 2
           + (0.5 * r * abs(idle) / cells) ** 2)
    var += branch_sd_V(reading) ** 2
    temp = reading.get("temperature_C")
    if temp is not None and curve.temperature_C is not None:
        var += (ENTROPIC_V_PER_K * (float(temp) - curve.temperature_C)) ** 2
    slope = curve.slope(soc)
    sd = float(np.sqrt(var)) / slope if slope > 0 else MAX_SOC_SD
    return soc, float(min(sd, MAX_SOC_SD))


def branch_sd_V(reading: dict) -> float:
    """Per-cell standard deviation [V] a rest reading takes from the branch it rests on:
    :data:`HYSTERESIS_SD_CELL_V` after a charge, else 0."""
    return HYSTERESIS_SD_CELL_V if reading.get("after_charge") is not None else 0.0


# --------------------------------------------------------------------------- charge

def counted_charge(time_s, current_A, *, unresolved: bool = False, idle_A: float = 0.0
                   ) -> tuple[float, float]:
    """Charge through the samples [Ah] (discharge positive) and its standard deviation.

    Trapezoids. Each interval adds ``dt * s / sqrt(12)`` [As] to the standard deviation
    (independent intervals): a step of the current at a time uniform inside an interval
    is counted to that. ``s`` is the change seen across the interval, at least the
    typical change; when the samples do not follow the current (``unresolved``), every
    interval touching a loaded sample (``|i| > idle_A``) may hide a step across the
    whole range of the load's current, at least :data:`PEAK_FACTOR` times its mean (the
    samples may have missed every peak). A take-off between two samples 167 s apart:
    Monte Carlo of the CMU mission at random sample phase errs by 19-29 % (sd) at
    167-186 s; this rule gives 24-28 %, and covers the missions whose samples missed
    both take-off and landing (-41 %) within its 95 % interval.
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    if t.size < 2:
        return 0.0, 0.0
    dt = np.diff(t)
    di = np.abs(np.diff(i))
    q = float(np.sum(0.5 * (i[1:] + i[:-1]) * dt)) / 3600.0
    step = np.maximum(di, float(np.median(di)))
    if unresolved:
        loaded = np.abs(i) > idle_A
        touch = loaded[1:] | loaded[:-1]
        span = 0.0
        if loaded.any():
            span = max(float(np.ptp(np.concatenate(([0.0], i[loaded])))),
                       PEAK_FACTOR * float(np.mean(np.abs(i[loaded]))))
        step = np.where(touch, np.maximum(step, span), step)
    sd = float(np.sqrt(np.sum((dt * step) ** 2) / 12.0)) / 3600.0
    return q, sd


#: A flight's or a mission's peaks (take-off, climb) draw up to this many times its mean
#: current (CMU eVTOL: 54 W take-off and landing, 16 W cruise): what samples that do not
#: follow the current may have missed.
PEAK_FACTOR = 3.0

#: The samples follow the current when its typical change between two samples is at most
#: this share of its range over the event ...
UNRESOLVED_STEP_SHARE = 0.2

#: ... and, for a discharge, they are at most this far apart [s]: a flight's or a
#: mission's shortest phases (take-off, landing) last about a minute, and four samples
#: are needed to see one; samples farther apart can miss a whole phase while the ones
#: they catch look steady. A charger's current is smooth by design and is judged by its
#: samples alone.
RESOLVING_PERIOD_S = 15.0


def sampling_figures(time_s, current_A, *, charge: bool = False) -> dict:
    """How well the samples of one event follow and count its current.

    Parameters
    ----------
    time_s, current_A : array_like
        The event's samples (and one either side) [s, A].
    charge : bool
        The event is a charge (judged by its samples alone).

    Returns
    -------
    dict
        ``period_s`` (median sample interval), ``step_share`` (median change between two
        samples over the current's range), ``resolved`` (the samples follow the current:
        ``step_share`` at most :data:`UNRESOLVED_STEP_SHARE` and, for a discharge, a
        period of at most :data:`RESOLVING_PERIOD_S`), ``charge_Ah`` and ``charge_sd_Ah``
        (:func:`counted_charge`), ``countable`` (the standard deviation is at most
        :data:`RESOLVED_SHARE` of the charge).
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    if t.size < 3:
        return {"period_s": float(np.median(np.diff(t))) if t.size > 1 else None,
                "step_share": None, "resolved": False, "charge_Ah": 0.0,
                "charge_sd_Ah": 0.0, "countable": False}
    span = float(np.ptp(i))
    share = float(np.median(np.abs(np.diff(i)))) / span if span > 0 else 0.0
    period = float(np.median(np.diff(t)))
    resolved = share <= UNRESOLVED_STEP_SHARE and (charge or period <= RESOLVING_PERIOD_S)
    q, sd = counted_charge(t, i, unresolved=not resolved)
    return {"period_s": period, "step_share": share,
            "resolved": bool(resolved), "charge_Ah": q, "charge_sd_Ah": sd,
            "countable": bool(abs(q) > 0 and sd <= RESOLVED_SHARE * abs(q))}


#: Charges whose start :func:`charge_start_corrections` places need this many like
#: charges (the same current and sampling) among their :data:`PHASE_NEIGHBOURS` nearest
#: on each side, themselves included: the mean over uniform phases that gives the resistive
#: step is then known to ``g / sqrt(12 n)``, a tenth of the voltage one interval adds.
#: Like charges also start from the same rest voltage (a charge after a capacity test,
#: from empty, is not one of them).
PHASE_MIN_CHARGES = 8

#: Charges on each side whose starts give a charge's resistive step.
PHASE_NEIGHBOURS = 15

#: Two charges are alike when their currents, sample intervals and rest voltages before
#: them (the state of charge they start from) agree within this share.
PHASE_ALIKE = 0.03


def charge_start_corrections(starts: list) -> list:
    """Charge [Ah] to add to each charge's counted charge for where it started between
    the rest's last sample and its first.

    A charger steps its current up at a moment the samples do not see; the trapezoid
    from the rest's last sample (0 A) to the first one at the constant current ``I``
    counts ``I dt / 2`` whatever the moment, wrong by up to ``+-I dt / 2`` (+-4 % of a
    charge from 43 % to full sampled every 167 s). The voltage of the first sample says
    when: it lies above the rest's by the resistive step ``R I`` plus ``g f``, ``g`` the
    rise over one whole interval at the constant current and ``f`` the share of the
    interval that was charging. Over many like charges the moment is uniform in the
    interval (the log's clock does not know the charger's), so ``R I = mean(dV1) -
    mean(g) / 2`` over like charges (method of moments: what is added averages to zero
    over them, it only moves charge between them) and each charge's ``f = (dV1 - R I) /
    g``, clipped to 0-1; it adds ``I dt (f - 1/2)``. (A ramp of width ``w`` before the
    constant current changes nothing: the first samples past it have ``f`` uniform over
    ``w/2 .. 1 - w/2``.) A first sample caught inside the charger's ramp (below the
    constant current, the next one at it) lies within the ramp after the start: the
    interval before held little charge and the next one nearly all of ``I``.

    Parameters
    ----------
    starts : list of dict or None
        Per charge in the pack's order, :func:`dischargelab.logbook.events.charge_start`
        (None: no rest sample before it).

    Returns
    -------
    list of float or None
        The charge to add [Ah] (positive: more went in), None where it cannot be placed.
    """
    out: list = [None] * len(starts)
    ok = [s is not None and s["next_A"] > 0 and s["first_A"] >= 0 for s in starts]
    stepped = [o and abs(s["first_A"] - s["next_A"]) <= PHASE_ALIKE * s["next_A"]
               for o, s in zip(ok, starts)]
    for k, s in enumerate(starts):
        if not ok[k]:
            continue
        like = [j for j in range(max(0, k - PHASE_NEIGHBOURS),
                                 min(len(starts), k + PHASE_NEIGHBOURS + 1))
                if stepped[j] and _alike(starts[j], s)]
        if len(like) < PHASE_MIN_CHARGES:
            continue
        if stepped[k]:
            rise = np.array([starts[j]["first_V"] - starts[j]["rest_V"] for j in like])
            g = float(np.mean([starts[j]["next_V"] - starts[j]["first_V"] for j in like]))
            if g <= 0:
                continue
            f = float(np.clip((s["first_V"] - s["rest_V"] - (rise.mean() - g / 2)) / g,
                              0.0, 1.0))
            out[k] = s["first_A"] * s["interval_s"] * (f - 0.5) / 3600.0
        elif s["first_A"] < s["next_A"]:
            out[k] = (0.5 * s["next_A"] * s["next_interval_s"]
                      - 0.5 * s["first_A"] * (s["interval_s"] + s["next_interval_s"])) / 3600.0
    return out


def _alike(a: dict, b: dict) -> bool:
    return all(abs(a[key] - b[key]) <= PHASE_ALIKE * abs(b[key])
               for key in ("next_A", "interval_s", "next_interval_s", "rest_V"))


# --------------------------------------------------------------------------- capacity

def capacity_between_rests(charge_Ah: float, charge_sd_Ah: float, soc_start: float,
                           soc_start_sd: float, soc_end: float, soc_end_sd: float
                           ) -> tuple[float | None, list | None, str]:
    """Capacity [Ah] from the charge counted between two rests and their states of charge.

    ``C = Q / (SOC_start - SOC_end)`` (discharge positive: a charge has ``Q < 0`` and a
    rising state of charge). The 95 % interval is log-normal: the relative errors of
    the charge and of the swing add in quadrature.

    Returns
    -------
    (capacity, [low, high], how) or (None, None, one-line reason).

    References
    ----------
    TI SLUA364B (Qmax from two OCV readings and the passed charge).
    """
    swing = soc_start - soc_end
    if charge_Ah == 0 or swing == 0 or np.sign(swing) != np.sign(charge_Ah):
        return None, None, (f"the charge counted ({charge_Ah:+.3g} Ah) and the change in "
                            f"state of charge ({100 * swing:+.0f} %) disagree")
    if abs(swing) < MIN_SWING:
        return None, None, (f"a swing of {100 * abs(swing):.0f} % of charge is too small "
                            f"(at least {100 * MIN_SWING:.0f} %)")
    sd_swing = float(np.hypot(soc_start_sd, soc_end_sd))
    if abs(swing) - Z95 * sd_swing <= 0.2 * abs(swing):
        return None, None, (f"the rest voltages read the swing only to +-{100 * Z95 * sd_swing:.0f}"
                            f" % of charge ({100 * abs(swing):.0f} % swing)")
    cap = charge_Ah / swing
    rel = float(np.hypot(charge_sd_Ah / abs(charge_Ah), sd_swing / abs(swing)))
    return float(cap), [float(cap * np.exp(-Z95 * rel)), float(cap * np.exp(Z95 * rel))], \
        "rests before and after"


def systematic_share(curve: OcvCurve, soc_read: list[float], swing: float,
                     fade: float | None, branch_V: list[float] | None = None) -> float:
    """Relative standard deviation of a capacity between two rests that every estimate read
    through the same curve shares [-] (it does not average out over many events).

    The curve's own error at each reading not anchored full (``curve.sd_V`` through its
    slope) over the swing, and :data:`OCV_AGEING_SD` times the pack's ``fade`` since the
    curve was learned (the aged curve's drift, see there), in quadrature.

    Parameters
    ----------
    curve : OcvCurve
    soc_read : list of float
        The states of charge read through the curve (those read as full left out).
    swing : float
        Change in state of charge between the two rests [-].
    fade : float or None
        Capacity lost since the curve was learned, as a share of its capacity [-].
    branch_V : list of float, optional
        Per reading, the per-cell standard deviation of the branch it rests on
        (:func:`branch_sd_V`) [V]; none by default.
    """
    branch = branch_V or [0.0] * len(soc_read)
    var = sum((np.hypot(curve.sd_at(s), b) / max(curve.slope(s), 1e-6)) ** 2
              for s, b in zip(soc_read, branch))
    rel = np.sqrt(var) / max(abs(swing), 1e-9)
    return float(np.hypot(rel, OCV_AGEING_SD * max(0.0, fade or 0.0)))


def cells_share(curve: OcvCurve, soc_read: list[float], swing: float) -> float:
    """Relative standard deviation of a capacity between two rests from real cells' spread
    about a generic curve alone (``curve.cells_spread_V`` through its slope at each
    reading, over the swing; 0 for a curve without one) [-]. One offset for all of a
    pack's readings: it widens each estimate's interval but does not set one estimate
    apart from another (the trend adds it once, through :func:`systematic_share`)."""
    if curve.cells_spread_V is None:
        return 0.0
    var = sum((curve.cells_sd_at(s) / max(curve.slope(s), 1e-6)) ** 2 for s in soc_read)
    return float(np.sqrt(var) / max(abs(swing), 1e-9))


def log_sd(interval95) -> float:
    """Relative standard deviation of a log-normal 95 % interval ``[low, high]`` [-]."""
    lo, hi = interval95
    return float(np.log(hi / lo) / (2 * Z95))


def widen(capacity_Ah: float, interval95: list, extra_share: float) -> list:
    """A log-normal 95 % interval with ``extra_share`` (relative sd) added in quadrature."""
    rel = float(np.hypot(log_sd(interval95), extra_share))
    return [float(capacity_Ah * np.exp(-Z95 * rel)), float(capacity_Ah * np.exp(Z95 * rel))]


# --------------------------------------------------------------------------- resistance

def robust_sd(values, centre: float | None = None) -> float:
    """Standard deviation from the median absolute deviation about ``centre`` (default
    the median): ``1.4826 MAD``, a normal's sd, robust to a few wild values."""
    v = np.asarray(values, dtype=float)
    c = float(np.median(v)) if centre is None else centre
    return 1.4826 * float(np.median(np.abs(v - c)))


def sample_noise(x) -> float:
    """Sample noise from second differences (robust: MAD), same units as ``x``."""
    x = np.asarray(x, dtype=float)
    if x.size < 5:
        return 0.0
    return robust_sd(np.diff(x, 2)) / float(np.sqrt(6.0))


def step_resistance(time_s, voltage_V, current_A, rest: dict | None = None,
                    after: dict | None = None) -> tuple[float | None, list | None]:
    """Pack resistance from the load steps of one event [ohm], with its 95 % interval.

    Every change of current between two samples at most :data:`STEP_MAX_DT_S`
    apart, by at least :data:`STEP_MIN_FRACTION` of the mean current, gives
    ``R = -dV/dI``; so do the step from the rest sample before the load to the
    first loaded sample and the step from the last loaded sample to the rest after
    it. The resistance is the median of these (the DC resistance over about a
    second, series resistance plus the fastest polarisation; cf. the pulse
    resistance of the FreedomCAR Battery Test Manual's hybrid pulse power test, with
    a shorter pulse).

    95 % interval: from the sample noise of voltage and current (second differences),
    widened to the spread of the steps when there are three or more (standard error
    of the median, 1.2533 sd/sqrt(n), sd from the MAD).

    Returns
    -------
    (resistance_ohm, [low, high]) or (None, None) when no step qualifies.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    i = np.asarray(current_A, dtype=float)
    if t.size < 2:
        return None, None
    level = max(STEP_MIN_A, STEP_MIN_FRACTION * abs(float(np.mean(i))))
    di, dv, dt = np.diff(i), np.diff(v), np.diff(t)
    sel = (np.abs(di) >= level) & (dt <= STEP_MAX_DT_S)
    values = list(-dv[sel] / di[sel])
    steps = list(np.abs(di[sel]))
    if rest is not None and rest.get("voltage_V") is not None:
        gap = t[0] - float(rest.get("time_s", t[0]))
        d_i = i[0] - float(rest.get("current_A") or 0.0)
        if abs(d_i) >= level and gap <= STEP_MAX_DT_S:
            values.append((float(rest["voltage_V"]) - v[0]) / d_i)
            steps.append(abs(d_i))
    if after is not None and after.get("first_current_A") is not None:
        d_i = i[-1] - after["first_current_A"]
        if abs(d_i) >= level and after["first_gap_s"] <= STEP_MAX_DT_S:
            values.append((after["first_voltage_V"] - v[-1]) / d_i)
            steps.append(abs(d_i))
    arr = np.array([x for x in values if np.isfinite(x) and x > 0])
    if arr.size == 0:
        return None, None
    r = float(np.median(arr))
    sv, si = sample_noise(v), sample_noise(i)
    d_i = float(np.median(steps))
    half = 1.96 * np.sqrt(2.0 * sv ** 2 + 2.0 * (r * si) ** 2) / d_i / np.sqrt(arr.size)
    if arr.size >= 3:
        half = max(half, 1.96 * 1.2533 * robust_sd(arr, r) / np.sqrt(arr.size))
    return r, [max(0.0, r - half), r + half]


#: The regression resistance needs at least this many samples ...
REGRESSION_MIN_SAMPLES = 8

#: ... whose current varies by at least this share of its mean (between its 5th and 95th
#: percentiles: a cruise at a steady throttle with a few climbs is enough, the fit's
#: standard error says how well; MAVLink telemetry of a fixed wing every 4 s varies
#: its current by 9 % between the quartiles but 34 % between those percentiles).
REGRESSION_MIN_SPREAD = 0.1


def regression_resistance(time_s, voltage_V, current_A) -> tuple[float | None, list | None]:
    """Pack resistance [ohm] from how the voltage follows the current through an event.

    For logs too sparse for load steps (a DJI smart battery's record every ~12 s):
    least squares of ``V = a + b q + c q^2 - R I`` over the event (the open-circuit
    voltage locally quadratic in the charge drawn ``q``), 95 % interval from the
    coefficient's standard error. The resistance is that of the sample interval's
    time scale (series resistance plus the polarisation built in seconds), larger
    than a one-second step's.

    Returns
    -------
    (resistance_ohm, [low, high]) or (None, None): too few samples, too little
    variation of the current, or a non-positive fit.
    """
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(voltage_V, dtype=float)
    i = np.asarray(current_A, dtype=float)
    if t.size < REGRESSION_MIN_SAMPLES:
        return None, None
    mean = float(np.mean(i))
    if mean <= 0 or np.subtract(*np.percentile(i, [95, 5])) < REGRESSION_MIN_SPREAD * mean:
        return None, None
    q = np.concatenate(([0.0], np.cumsum(0.5 * (i[1:] + i[:-1]) * np.diff(t)))) / 3600.0
    design = np.column_stack([np.ones_like(q), q, q * q, -i])
    coef, *_ = np.linalg.lstsq(design, v, rcond=None)
    resid = v - design @ coef
    dof = t.size - design.shape[1]
    if dof < 2:
        return None, None
    s2 = float(resid @ resid) / dof
    cov = s2 * np.linalg.pinv(design.T @ design)
    r, se = float(coef[3]), float(np.sqrt(max(cov[3, 3], 0.0)))
    if not r > 0 or not np.isfinite(se) or se >= r:
        return None, None
    from scipy import stats

    half = float(stats.t.ppf(0.975, dof)) * se
    return r, [max(0.0, r - half), r + half]


#: The open-circuit drop resistance is read over this middle share of an event's charge
#: (away from the start's polarisation building up and the end's curve knee).
DROP_SPAN = (0.2, 0.8)

#: ... where the current is at least this share of the event's largest.
DROP_MIN_CURRENT_SHARE = 0.3

#: ... and only when the drop is at least this many times the curve's standard deviation
#: (a light load's drop is the curve's error, not the resistance's).
DROP_MIN_Z = 3.0


def drop_resistance(curve_points: dict, soc_start: float, soc_end: float, ocv: OcvCurve,
                    cells: int, direction: int) -> tuple[float | None, list | None]:
    """Pack resistance [ohm] from how far the loaded voltage lies from the open-circuit
    voltage through the middle of an event, for logs too sparse for load steps or a
    regression (the CMU eVTOL logs' one sample every 158-167 s).

    ``R = direction (OCV(soc) cells - V) / I`` at each point of the event's compact curve
    in :data:`DROP_SPAN` of its charge (current at least :data:`DROP_MIN_CURRENT_SHARE`
    of its largest), ``soc`` linear in the charge between the two rest readings
    ``soc_start`` and ``soc_end``; the median. ``direction`` +1 for a discharge, -1 for
    a charge. The resistance of minutes under load (series resistance and the
    polarisation built by then, Plett 2015 ch. 2): larger than a step's, and compared
    only with its own kind. 95 % interval: the curve's error and the points' spread.
    Real cells' spread about a generic curve (``cells_spread_V``) is left out of both:
    it shifts every drop of the pack alike and cancels in the resistance's rise, which is
    what these resistances are compared for.

    Returns
    -------
    (resistance_ohm, [low, high]) or (None, None) when no point qualifies or the drop is
    less than :data:`DROP_MIN_Z` times the curve's standard deviation.
    """
    q = np.asarray(curve_points.get("charge_Ah") or [], dtype=float)
    v = np.asarray(curve_points.get("voltage_V") or [], dtype=float)
    i = np.abs(np.asarray(curve_points.get("current_A") or [], dtype=float))
    if q.size < 3 or not q[-1] > 0 or v.size != q.size or i.size != q.size:
        return None, None
    share = q / q[-1]
    sel = (share >= DROP_SPAN[0]) & (share <= DROP_SPAN[1]) & \
        (i >= DROP_MIN_CURRENT_SHARE * i.max()) & (i > 0)
    if not sel.any():
        return None, None
    soc = soc_start + (soc_end - soc_start) * share[sel]
    drop = direction * (ocv.voltage_at(soc) * cells - v[sel])
    curve_sd = cells * ocv.sd_at(float(np.median(soc)), cells_alike=False)
    if not float(np.median(drop)) > DROP_MIN_Z * curve_sd:
        return None, None        # a drop the curve's own error could make (a small load)
    values = drop / i[sel]
    r = float(np.median(values))
    spread = robust_sd(values, r) if values.size >= 3 else 0.0
    half = 1.96 * float(np.hypot(curve_sd / float(np.median(i[sel])), spread))
    return r, [max(0.0, r - half), r + half]


def resistance_at_reference(resistance_ohm: float | None, interval95, temperature_C,
                            *, soc: float | None = None, model=None,
                            current_A: float | None = None
                            ) -> tuple[float | None, list | None, str]:
    """A resistance moved to :data:`REFERENCE_TEMPERATURE_C` and :data:`REFERENCE_SOC`.

    Temperature: ``R_ref = R / f(T)``, ``f`` the Arrhenius factor with the prior
    coefficient (:data:`dischargelab.models.thermal.BETA_PRIOR_K`), whose
    :data:`BETA_RELATIVE_SD` widens the interval the farther ``T`` is from the
    reference. State of charge: through the pack's model (the drop of ``current_A``
    at the reference state over the drop at ``soc``), when a model is given.

    Returns
    -------
    (R_ref [ohm], [low, high], how) or (None, None, reason).
    """
    from ..models.base import arrhenius
    from ..models.thermal import BETA_PRIOR_K

    if resistance_ohm is None:
        return None, None, "no resistance"
    lo, hi = interval95 if interval95 else (resistance_ohm, resistance_ohm)
    how = []
    factor, rel_sd = 1.0, 0.0
    if temperature_C is not None and np.isfinite(temperature_C):
        f = float(arrhenius(temperature_C, BETA_PRIOR_K, REFERENCE_TEMPERATURE_C))
        factor /= f
        rel_sd = abs(np.log(f)) * BETA_RELATIVE_SD
        how.append(f"from {temperature_C:.0f} degC")
    else:
        how.append("no temperature logged: not moved in temperature")
    if model is not None and soc is not None and current_A:
        ratio = _model_soc_ratio(model, soc, float(current_A))
        if ratio is not None:
            factor *= ratio
            how.append(f"from {100 * soc:.0f} % charge through the model")
    r = resistance_ohm * factor
    lo_r, hi_r = lo * factor, hi * factor
    half_lo = np.hypot(r - lo_r, Z95 * rel_sd * r)
    half_hi = np.hypot(hi_r - r, Z95 * rel_sd * r)
    return float(r), [float(max(0.0, r - half_lo)), float(r + half_hi)], "; ".join(how)


def _model_soc_ratio(model, soc: float, current_A: float) -> float | None:
    """Drop of ``current_A`` at the reference state of charge over the drop at ``soc``."""
    cap = float(model.capacity_Ah)
    q = np.array([(1.0 - REFERENCE_SOC) * cap, (1.0 - min(max(soc, 0.02), 1.0)) * cap])
    q = np.minimum(q, 0.98 * cap)
    with np.errstate(all="ignore"):
        rest = np.asarray(model.voltage(np.zeros(2), q), dtype=float)
        loaded = np.asarray(model.voltage(np.full(2, current_A), q), dtype=float)
    drop = rest - loaded
    if not np.all(np.isfinite(drop)) or np.any(drop <= 0):
        return None
    return float(drop[0] / drop[1])


__all__ = ["step_resistance", "sample_noise", "regression_resistance",
           "drop_resistance", "OcvCurve",
           "soc_reading",
           "counted_charge", "sampling_figures", "charge_start_corrections",
           "capacity_between_rests", "systematic_share", "cells_share", "branch_sd_V",
           "widen", "log_sd", "OCV_AGEING_SD",
           "resistance_at_reference", "MIN_SWING",
           "REFERENCE_TEMPERATURE_C", "REFERENCE_SOC", "FULL_SOC", "FULL_SOC_SD"]
