"""The model-family interface: every battery model is one subclass of :class:`Family`.

A family declares its parameters (name with unit, bounds, default, whether it
enters the terminal voltage linearly), its states and how they evolve, and
computes the cell terminal voltage and its analytic Jacobian. Fitting,
simulation, missions, uncertainty draws, validation and the report only talk to
this interface, so a new model family is one new file in this package.

Sign convention: discharge current positive; ``charge_Ah`` is the charge taken
out of the cell since full charge [Ah]; everything here is per cell.

States
------
Each state has a *kind* that tells the time-stepping engine how to advance it
over a step of constant current ``i`` and length ``dt``:

* ``"charge"``: ``dq/dt = i / 3600`` [Ah/s] (exact).
* ``"lowpass"``: ``dx/dt = (i - x) / tau`` with ``tau`` [s] a parameter; the
  exact solution ``x = i + (x0 - i) exp(-dt / tau)`` is used.
* ``"thermal"``: lumped thermal mass, ``C_th dT/dt = i (U_ocv - V) - (T - T_amb) / R_th``
  (heat from the overpotential times the current, Newton cooling), advanced by
  the engine with the exact exponential solution for the step's mean heat
  (predictor-corrector), stable for any thermal time constant.

References
----------
.. [1] O. Tremblay, L.-A. Dessaint, "Experimental validation of a battery dynamic
   model for EV applications", World Electric Vehicle Journal 3 (2009).
.. [2] D. Bernardi, E. Pawlikowski, J. Newman, "A general energy balance for
   battery systems", J. Electrochem. Soc. 132 (1985) 5-12 (irreversible heat).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Kelvin offset of the Celsius scale.
ZERO_CELSIUS_K = 273.15

#: Reference temperature of the temperature-dependent parameters [degC].
REFERENCE_TEMPERATURE_C = 25.0

STATE_KINDS = ("charge", "lowpass", "thermal")


@dataclass(frozen=True)
class Parameter:
    """One model parameter (per cell).

    Attributes
    ----------
    name : str
        Canonical name with its unit, e.g. ``"R_ohm"``.
    unit : str
        Unit for display, e.g. ``"ohm"``.
    lower, upper : float
        Default bounds of the fit.
    default : float
        Value used when the data cannot determine it (priors, presets).
    linear : bool
        True when the terminal voltage is linear in this parameter for fixed
        values of the others (variable projection eliminates it).
    description : str
        One line for tables and reports.
    fit : bool
        False for parameters that are held at their default unless a fit asks
        for them (e.g. thermal coefficients from isothermal data).
    limit_note : str
        When set, a fitted value at a bound is a physical limit (an effect the
        data do not need, e.g. no diffusion lag), reported as a note with this
        text rather than as a bound problem.
    """

    name: str
    unit: str
    lower: float
    upper: float
    default: float
    linear: bool = False
    description: str = ""
    fit: bool = True
    limit_note: str = ""


@dataclass(frozen=True)
class State:
    """One state variable of a family (see the module docstring for the kinds)."""

    name: str
    unit: str
    kind: str
    tau: str | None = None  # parameter holding the time constant of a lowpass state [s]
    tau_scale: float = 1.0  # the state's time constant is ``tau_scale`` times that parameter

    def time_constant(self, p):
        """Time constant [s] of a lowpass state under parameters ``p`` (scalar or draws)."""
        return np.asarray(p[self.tau], dtype=float) * self.tau_scale

    def __post_init__(self):
        if self.kind not in STATE_KINDS:
            raise ValueError(f"state kind must be one of {STATE_KINDS}, got {self.kind!r}")


@dataclass
class Samples:
    """Cell-level samples the fit evaluates the model on (all curves stacked).

    Rest points (the voltage before each load step) are appended as samples with
    ``current = 0`` and ``charge = 0``; ``is_rest`` marks them. ``first`` marks
    the first load sample of each curve (where filtered states restart).
    """

    voltage: np.ndarray      # [V] per cell
    current: np.ndarray      # [A] per cell, discharge positive
    charge: np.ndarray       # [Ah] per cell
    time: np.ndarray         # [s] from each curve's load start
    temperature: np.ndarray  # [degC] logged cell temperature, or the ambient where not logged
    weight: np.ndarray       # sqrt weights per sample
    curve: np.ndarray        # curve index per sample
    is_rest: np.ndarray
    n_curves: int
    has_temperature: bool = False
    ambient_C: float = REFERENCE_TEMPERATURE_C
    _cache: dict = field(default_factory=dict, repr=False)

    @property
    def q_max(self) -> float:
        """Largest discharged charge in the data [Ah per cell]."""
        return float(self.charge.max())


def arrhenius(temperature_C, beta_K, reference_C=REFERENCE_TEMPERATURE_C):
    """Arrhenius factor ``exp(beta (1/T - 1/T_ref))`` [-] for temperatures in degC.

    ``beta = E_a / R_gas`` [K]; the factor is 1 at the reference temperature and
    falls as the cell warms (resistances and polarisation shrink).
    """
    t = np.asarray(temperature_C, dtype=float) + ZERO_CELSIUS_K
    return np.exp(beta_K * (1.0 / t - 1.0 / (reference_C + ZERO_CELSIUS_K)))


def arrhenius_dbeta(temperature_C, reference_C=REFERENCE_TEMPERATURE_C):
    """``d ln(arrhenius) / d beta`` [1/K] = ``1/T - 1/T_ref``."""
    t = np.asarray(temperature_C, dtype=float) + ZERO_CELSIUS_K
    return 1.0 / t - 1.0 / (reference_C + ZERO_CELSIUS_K)


def lowpass_samples(time_s, current_A, first, tau_s):
    """First-order lowpass of a sampled current and its derivative with respect to tau.

    Zero-order hold between samples (the current of sample ``k`` is held from
    ``t[k-1]`` to ``t[k]``), the state restarting at 0 at each ``first`` sample
    (a curve's load start, after rest).

    Parameters
    ----------
    time_s, current_A : numpy.ndarray
        Sample times [s] and currents [A].
    first : numpy.ndarray of bool
        Samples where a new curve starts (state reset to 0 before it).
    tau_s : float
        Time constant [s] (> 0).

    Returns
    -------
    x, dx_dtau : numpy.ndarray
        Filtered current [A] and its sensitivity [A/s].
    """
    t = np.asarray(time_s, dtype=float)
    i = np.asarray(current_A, dtype=float)
    n = t.size
    dt = np.empty(n)
    dt[0] = 0.0
    dt[1:] = np.diff(t)
    dt[first] = np.maximum(t[first], 0.0)  # from load start (t = 0) to the first sample
    dt = np.maximum(dt, 0.0)
    a = np.exp(-dt / tau_s)
    da = a * dt / tau_s**2
    x = np.empty(n)
    s = np.empty(n)
    starts = np.flatnonzero(first)
    if starts.size == 0 or starts[0] != 0:
        starts = np.r_[0, starts]
    bounds = np.r_[starts, n]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        _recursion(a[lo:hi], da[lo:hi], i[lo:hi], x[lo:hi], s[lo:hi])
    return x, s


#: Filtered currents kept per ``Samples`` (one entry per time constant evaluated).
_FILTER_CACHE_ENTRIES = 24


def filtered_samples(data: Samples, tau_s):
    """Lowpass-filtered current [A] and its sensitivity to ``tau_s`` [A/s] at every sample
    of ``data`` (:func:`lowpass_samples` over the load samples of each curve, restarting
    at each curve's load start; rest samples 0), cached on ``data`` per time constant."""
    cache = data._cache.setdefault("lowpass", {})
    source = data._cache.get("lowpass_source")
    if source is None or source[0] is not data.time or source[1] is not data.current:
        cache.clear()
        data._cache["lowpass_source"] = (data.time, data.current)
    key = float(tau_s)
    if key not in cache:
        load = np.flatnonzero(~np.asarray(data.is_rest, bool))
        curve = np.asarray(data.curve)[load]
        first = np.ones(load.size, bool)
        first[1:] = curve[1:] != curve[:-1]
        x = np.zeros(data.current.size)
        s = np.zeros(data.current.size)
        if load.size:
            x[load], s[load] = lowpass_samples(data.time[load], data.current[load], first, key)
        if len(cache) >= _FILTER_CACHE_ENTRIES:
            cache.pop(next(iter(cache)))
        cache[key] = (x, s)
    return cache[key]


def _recursion(a, da, i, x, s):
    """x_k = a_k x_{k-1} + (1 - a_k) i_k ; s_k = a_k s_{k-1} + da_k (x_{k-1} - i_k); x_-1 = 0.

    Uniformly sampled segments use scipy's IIR filter (one C loop); irregular ones a
    log-depth parallel prefix scan of the affine recursion (stable: 0 < a <= 1).
    """
    n = a.size
    if n == 0:
        return
    if n > 2 and np.ptp(a[1:]) <= 1e-12 * max(a[1], 1e-300) and abs(a[0] - a[1]) <= 1e-12:
        from scipy.signal import lfilter

        alpha = float(a[1])
        x[:] = lfilter([1.0 - alpha], [1.0, -alpha], i)
        prev = np.r_[0.0, x[:-1]]
        s[:] = lfilter([1.0], [1.0, -alpha], da * (prev - i))
        return
    x[:] = affine_scan(a, (1.0 - a) * i)
    prev = np.r_[0.0, x[:-1]]
    s[:] = affine_scan(a, da * (prev - i))


def affine_scan(a, b):
    """All ``y_k = a_k y_{k-1} + b_k`` with ``y_-1 = 0`` (Hillis-Steele scan, log2(n) passes).

    Composition of the affine maps ``y -> a y + b`` is associative, so after pass
    ``d`` each entry holds the composition of the last ``2^d`` maps.
    """
    mul = np.array(a, dtype=float)
    add = np.array(b, dtype=float)
    step = 1
    while step < mul.size:
        add[step:] = mul[step:] * add[:-step] + add[step:]
        mul[step:] = mul[step:] * mul[:-step]
        step *= 2
    return add


class Family:
    """Base class of a model family (subclass once per family, register in ``models``).

    Subclasses set :attr:`name`, :attr:`version`, :attr:`parameters`,
    :attr:`states` and implement :meth:`voltage`, :meth:`fit_voltage`,
    :meth:`jacobian` and :meth:`guess`. Parameter values are passed as a mapping
    ``{name: value}``; values may be numpy arrays (one entry per parameter draw)
    and every method broadcasts over them.
    """

    name: str = ""
    version: int = 1
    #: Best grid starts refined by the solver (more where the cost has local minima).
    n_best: int = 1
    #: Capacities, as multiples of the searched solution's, whose cost is evaluated before
    #: the refinement (the other parameters held); the lowest local minima among them are
    #: refined too, and the best result kept (empty: none). For a family whose cost has
    #: minima in ``C_Ah`` narrower than its grid's steps.
    capacity_scan: tuple[float, ...] = ()
    title: str = ""
    description: str = ""
    parameters: tuple[Parameter, ...] = ()
    states: tuple[State, ...] = (State("charge_Ah", "Ah", "charge"),)
    #: Parameters shown in plot titles and short summaries.
    headline: tuple[str, ...] = ()
    #: Parameters that together shape the open-circuit voltage curve (a free-form OCV):
    #: reports draw the curve and keep these numbers folded away.
    ocv_parameters: tuple[str, ...] = ()
    #: True when what sets the family apart is a logged temperature: without one it
    #: reduces to another family, and ``model="auto"`` does not try it.
    needs_temperature: bool = False
    #: False for a family that ``model="auto"`` does not compare on several rates (where
    #: it would only repeat another family's fit).
    several_rates_candidate: bool = True
    #: Simpler forms of the family that ``model="auto"`` also fits to several rates,
    #: keeping whichever form has the smaller held-out error
    #: (:func:`dischargelab.fit.auto.fit_auto`): ``{what is left out: {parameter: value
    #: that makes its effect absent}}``. For a term that several rates can still confuse
    #: with another (a slow RC pair with the open-circuit voltage's curvature at a slow
    #: rate), whose fit then extrapolates worse than the family without it.
    several_rates_variants: dict = {}
    #: Growth with ln(extrapolation ratio) of the relative error of a time to cutoff
    #: predicted from a fit to ONE rate, for a sloped discharge curve
    #: (:func:`dischargelab.uncertainty.extrapolation_growth`; calibrated by
    #: ``benchmarks/accuracy.py``).
    one_rate_growth: float = 2.0
    #: Parameters that one constant current cannot show, held at the value that makes
    #: their effect absent when the fit has one steady rate
    #: (:func:`dischargelab.fit.family.one_steady_rate`), unless the caller fixes or
    #: bounds them.
    steady_fixed: dict = {}
    #: Of the ``steady_fixed`` parameters, those whose effect a fast run shows although a
    #: slow steady one cannot: held at this prior instead, in a second fit that keeps the
    #: ``steady_prior_carries`` parameters at the values of the fit without it (the fit
    #: notes say so, with :attr:`steady_prior_note`).
    steady_prior: dict = {}
    steady_prior_carries: tuple = ()
    steady_prior_note: str = ""
    #: Parameters a battery file of an older :attr:`version` lacks: ``{version: {new
    #: parameter: the parameter it equalled in files of that version and older}}``
    #: (:meth:`dischargelab.model.Battery.from_dict` copies its value and covariance).
    upgrades: dict = {}

    # ---- parameters -------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in the family's canonical order."""
        return tuple(p.name for p in self.parameters)

    def parameter(self, name: str) -> Parameter:
        """The :class:`Parameter` called ``name``."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def linear_names(self) -> tuple[str, ...]:
        """Parameters that enter the voltage linearly."""
        return tuple(p.name for p in self.parameters if p.linear)

    def defaults(self) -> dict[str, float]:
        """Default value of every parameter."""
        return {p.name: p.default for p in self.parameters}

    @property
    def thermal(self) -> bool:
        """True when the family has a temperature state."""
        return any(s.kind == "thermal" for s in self.states)

    # ---- physics ----------------------------------------------------------------
    def initial_state(self, p, *, charge_Ah=0.0, temperature_C=REFERENCE_TEMPERATURE_C) -> dict:
        """State at rest with ``charge_Ah`` removed [Ah] at ``temperature_C`` [degC]."""
        shape = np.broadcast(*[np.asarray(v) for v in p.values()],
                             np.asarray(charge_Ah), np.asarray(temperature_C)).shape
        out = {}
        for s in self.states:
            if s.kind == "charge":
                value = charge_Ah
            elif s.kind == "thermal":
                value = temperature_C
            else:
                value = 0.0
            out[s.name] = np.broadcast_to(np.asarray(value, dtype=float), shape).copy()
        return out

    def voltage(self, p, state: dict, current_A):
        """Cell terminal voltage [V] at ``state`` under ``current_A`` [A]."""
        raise NotImplementedError

    def open_circuit_voltage(self, p, state: dict):
        """Equilibrium voltage [V] used for the irreversible heat (default: V at i = 0
        with every lowpass state at 0)."""
        calm = {s.name: (0.0 * state[s.name] if s.kind == "lowpass" else state[s.name])
                for s in self.states}
        return self.voltage(p, calm, 0.0)

    def capacity_Ah(self, p, state: dict):
        """Charge [Ah] at which the model ends (voltage diverges or the cell is empty)."""
        return p["C_Ah"]

    def temperature_C(self, state: dict, ambient_C):
        """Cell temperature [degC] in ``state`` (the ambient for isothermal families)."""
        return state.get("temperature_C", ambient_C)

    def heat_W(self, p, state: dict, current_A):
        """Irreversible heat [W] = current x overpotential."""
        return current_A * (self.open_circuit_voltage(p, state) - self.voltage(p, state,
                                                                                current_A))

    # ---- fitting ------------------------------------------------------------------
    def fit_voltage(self, p, data: Samples):
        """Cell voltage [V] at every sample of ``data``."""
        raise NotImplementedError

    def jacobian(self, p, data: Samples, names=None) -> np.ndarray:
        """Analytic ``dV/dp`` at every sample, shape (n, len(names)), in ``names`` order
        (default: every parameter in family order)."""
        raise NotImplementedError

    def guess(self, data: Samples) -> dict[str, float]:
        """Starting values from the data (the others start at their defaults)."""
        return self.defaults()

    def start_grid(self, data: Samples, free_nonlinear) -> dict[str, list[float]]:
        """Candidate starting values per free nonlinear parameter (a grid is searched)."""
        return {}

    def fit_bounds(self, data: Samples) -> dict[str, tuple[float, float]]:
        """Bounds that depend on the data (e.g. capacity above the discharged charge)."""
        return {}

    def fit_fixed(self, data: Samples) -> dict[str, float]:
        """Parameters this family holds fixed for these data (with :meth:`fit_notes`)."""
        return {p.name: p.default for p in self.parameters if not p.fit}

    def fit_notes(self, data: Samples, fixed: dict) -> list[str]:
        """Notes on what :meth:`fit_fixed` held for these data and why (``fixed``: every
        value the fit holds)."""
        return []

    # ---- file format ------------------------------------------------------------------
    def describe(self) -> dict:
        """Name, version, description and the parameter table (for ``models``)."""
        return {
            "name": self.name, "version": self.version, "title": self.title,
            "description": self.description,
            "parameters": [{"name": p.name, "unit": p.unit, "lower": p.lower, "upper": p.upper,
                            "default": p.default, "linear": p.linear,
                            "description": p.description} for p in self.parameters],
            "states": [{"name": s.name, "unit": s.unit, "kind": s.kind} for s in self.states],
        }


#: Heat capacity [J/K] of a thermal family fitted without a logged temperature: the
#: cell stays at the ambient (1 MJ/K: 10 W for an hour warms it by 0.04 K).
HELD_AT_AMBIENT_HEAT_CAPACITY = 1e6

#: Smallest logged temperature rise [K] from which the heat capacity is fitted;
#: below it only the thermal resistance is (the heat capacity keeps its value).
MIN_HEATING_K = 2.0


#: Thermal resistance [K/W] the regression of :func:`fit_lumped_thermal` returns when the
#: logged temperature shows no cooling (an adiabatic cell over the fitted runs): a limit,
#: not a measurement (the fit says so).
MAX_THERMAL_RESISTANCE = 1e4


def fit_lumped_thermal(family: Family, p, data: Samples):
    """Heat capacity [J/K] and thermal resistance [K/W] from the logged cell temperature.

    Integral form of the lumped energy balance over each curve (no derivative
    of a noisy temperature is taken)::

        T(t) - T(0) = (1/C_th) int Q dt - 1/(R_th C_th) int (T - T_amb) dt

    with ``Q`` the irreversible heat of the fitted electrical model along each run as
    the model itself runs it (Bernardi et al. 1985): its filtered currents (RC pairs, a
    building polarisation) rise from 0 at the load start, as the engine integrates them, not
    at their steady values (an RC pair of 40 minutes carries 40 % of its steady drop
    after 20). Read at the steady values, the heat of an ``ecm`` fitted to 1C + 3C of
    a pouch cell was several times too large early in each run: the heat capacity
    came out 332 J/K instead of 44 J/K, and the simulated cell warmed 14 K instead of
    41 K at 3C. ``T_amb`` is the temperature of the cell at rest before the load (its
    first sample). A linear least-squares fit in ``1/C_th`` and ``1/(R_th C_th)``
    over the curves that heat by :data:`MIN_HEATING_K` or more. When none does,
    the log still says that the cell hardly heats: ``C_th`` keeps its value in
    ``p`` and only ``1/(R_th C_th)`` is fitted, so that the model does not
    predict a heating the log does not show (None when that fit finds no cooling:
    the ambient drifted more than the cell heated).

    Returns
    -------
    dict or None
        ``{"Cth_J_per_K", "Rth_K_per_W", "rmse_K", "heat_capacity_fitted"}``; None
        without a logged temperature or when it cannot be used.
    """
    if not data.has_temperature:
        return None
    rows = {True: ([], []), False: ([], [])}
    lowpass = {s.name: filtered_samples(data, float(s.time_constant(p)))[0]
               for s in family.states
               if s.kind == "lowpass"}
    for k in range(data.n_curves):
        sel = (data.curve == k) & ~data.is_rest
        t, temp = data.time[sel], data.temperature[sel]
        if t.size < 10:
            continue
        state = {s.name: (data.charge[sel] if s.kind == "charge" else
                          temp if s.kind == "thermal" else lowpass[s.name][sel])
                 for s in family.states}
        heat = family.heat_W(p, state, data.current[sel])
        heat = np.where(np.isfinite(heat), heat, 0.0)
        dt = np.diff(t)
        x1 = np.r_[0.0, np.cumsum(0.5 * (heat[1:] + heat[:-1]) * dt)]
        excess = temp - temp[0]
        x2 = np.r_[0.0, np.cumsum(0.5 * (excess[1:] + excess[:-1]) * dt)]
        xs, ys = rows[bool(np.ptp(temp) >= MIN_HEATING_K)]
        xs.append(np.column_stack([x1, -x2]))
        ys.append(excess)
    from scipy.optimize import nnls

    if rows[True][0]:
        x, y = np.vstack(rows[True][0]), np.concatenate(rows[True][1])
        coef, _ = nnls(x, y)
        a, b = coef
        if a > 0:
            rmse = float(np.sqrt(np.mean((x @ coef - y) ** 2)))
            return {"Cth_J_per_K": float(1.0 / a),
                    "Rth_K_per_W": float(min(a / b if b > 0 else MAX_THERMAL_RESISTANCE,
                                             MAX_THERMAL_RESISTANCE)), "rmse_K": rmse,
                    "heat_capacity_fitted": True}
    if not rows[False][0]:
        return None
    x, y = np.vstack(rows[False][0]), np.concatenate(rows[False][1])
    cth = float(p["Cth_J_per_K"])
    target = y - x[:, 0] / cth  # = -b x2, b = 1/(R_th C_th) >= 0
    den = float(x[:, 1] @ x[:, 1])
    if den <= 0:
        return None
    b = float(x[:, 1] @ target) / den
    if not b > 0:  # no cooling seen: the log's drift, not the cell, sets the temperature
        return None
    rmse = float(np.sqrt(np.mean((x[:, 0] / cth + b * x[:, 1] - y) ** 2)))
    return {"Cth_J_per_K": cth, "Rth_K_per_W": float(min(1.0 / (b * cth),
                                                         MAX_THERMAL_RESISTANCE)),
            "rmse_K": rmse, "heat_capacity_fitted": False}
