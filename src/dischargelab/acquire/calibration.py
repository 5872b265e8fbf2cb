"""Voltage calibration of the divider + voltage-follower front end (paper 3.3).

The logger measures a scaled-down pack voltage; the scaling factor is found by
comparing the logger's reading with a reference multimeter (paper eq. 7)::

    Ke = V_real / V_measured

:func:`fit_calibration` fits that gain through the origin to several
(multimeter, logger) pairs, decides whether an offset is warranted, reports
residuals per point, and finds where the front end stops being linear (the
paper's 2.7 kOhm divider drives the op-amp out of its linear region near 15 V,
Table 1). The result is a :class:`Calibration` stored as a small JSON file that
``dischargelab acquire --calibration cal.json`` applies to every sample.

Statistics used (all stated in the report):

* Gain: weighted least squares through the origin, weights ``1/sigma_i**2``
  where ``sigma_i`` combines the reference meter's stated accuracy (taken as a
  uniform distribution, sigma = limit / sqrt(3), GUM type B) and the ADC
  quantisation (sigma = Ke * step / sqrt(12)).
* Offset: nested models ``V = Ke*x`` versus ``V = a*x + b`` on the linear
  points. Two tests: the F-test (noise estimated from the scatter of the
  points) and a likelihood-ratio chi-square test with the known measurement
  uncertainty. An offset is adopted only when both reject "no offset" at
  ``alpha``: an offset smaller than what the reference meter can resolve cannot
  be told apart from the meter's own error.
* Linear range: the largest set of lowest-voltage points that a single gain
  fits within the worst-case error bound (meter limit + one ADC step +
  two standard errors of the prediction). Points above it are outside the
  linear range. Inside it, leave-one-out residuals flag isolated outliers.

References
----------
.. [1] "Measuring battery discharge characteristics for accurate UAV endurance
   estimation", section 3.3, eq. (7) and Table 1 (see ``../shared/paper``).
.. [2] JCGM 100:2008 (GUM), 4.3.7: rectangular distribution for a stated
   accuracy limit.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..errors import DataError
from ..jsonfile import read_json, write_json

#: Arduino Uno ADC: 10 bits over a 5 V reference (paper 3.3).
DEFAULT_ADC_BITS = 10
DEFAULT_ADC_REFERENCE_V = 5.0

#: Identifier written into every calibration file.
FILE_FORMAT = "dischargelab-calibration"
FILE_VERSION = 1


def adc_step_V(bits: int = DEFAULT_ADC_BITS, reference_V: float = DEFAULT_ADC_REFERENCE_V) -> float:
    """Voltage of one ADC count [V]: ``reference_V / 2**bits`` (5 V / 1024 = 4.883 mV)."""
    if bits < 1 or reference_V <= 0:
        raise DataError(f"ADC needs bits >= 1 and a positive reference, got {bits} bits, "
                        f"{reference_V} V")
    return float(reference_V) / 2 ** int(bits)


@dataclass(frozen=True)
class MeterAccuracy:
    """Stated accuracy of the reference multimeter: ``±(percent % of reading + digits)``.

    Defaults are the paper's Minipa ET-1002 on its 20 V range: resolution 10 mV,
    precision ±0.8 % + 5 digits (paper 3.3).
    """

    percent: float = 0.8
    digits: int = 5
    resolution_V: float = 0.01

    def limit_V(self, reading_V):
        """Worst-case error of a reading [V]."""
        return np.abs(np.asarray(reading_V, dtype=float)) * self.percent / 100.0 \
            + self.digits * self.resolution_V

    def sigma_V(self, reading_V):
        """Standard uncertainty [V]: the limit as a rectangular distribution (limit / sqrt 3)."""
        return self.limit_V(reading_V) / math.sqrt(3.0)

    def describe(self) -> str:
        return f"±({self.percent:g} % + {self.digits} digits of {self.resolution_V * 1000:g} mV)"


@dataclass(frozen=True)
class Calibration:
    """Scale a logger reading to the real pack voltage: ``V = gain * measured + offset_V``.

    Attributes
    ----------
    gain : float
        Ke = V_real / V_measured [-] (paper eq. 7).
    offset_V : float
        Additive offset [V]; 0 unless the calibration found a significant one.
    divider : str
        Name of the divider / front end the points were taken with (e.g. "3.3k").
    created : str
        ISO 8601 date and time of the calibration.
    valid_range_V : tuple of float or None
        Lowest and highest real voltage [V] where the front end was shown linear.
    adc_step_V : float
        One ADC count at the logger input [V] (5 V / 1024).
    points : tuple of dict
        The calibration points and their residuals, as stored in the file.
    extra : dict
        Everything else kept in the file (tests, meter accuracy, ...).
    """

    gain: float
    offset_V: float = 0.0
    divider: str = ""
    created: str = ""
    valid_range_V: tuple[float, float] | None = None
    adc_step_V: float = DEFAULT_ADC_REFERENCE_V / 2 ** DEFAULT_ADC_BITS
    points: tuple = ()
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        if not (math.isfinite(self.gain) and self.gain > 0):
            raise DataError(f"calibration gain must be a positive number, got {self.gain!r}")
        if not math.isfinite(self.offset_V):
            raise DataError(f"calibration offset must be finite, got {self.offset_V!r}")

    def apply(self, measured_V):
        """Real pack voltage [V] from the logger's reading [V] (float in, float out)."""
        value = self.gain * np.asarray(measured_V, dtype=float) + self.offset_V
        return float(value) if np.ndim(value) == 0 else value

    @property
    def resolution_V(self) -> float:
        """Voltage resolution at the pack [V]: one ADC step times the gain."""
        return self.gain * self.adc_step_V

    def in_valid_range(self, voltage_V: float) -> bool:
        """True if a real voltage [V] lies inside the range the calibration covered."""
        if self.valid_range_V is None:
            return True
        low, high = self.valid_range_V
        return low <= voltage_V <= high

    def to_dict(self) -> dict:
        """JSON-ready dictionary (the calibration file)."""
        out = dict(self.extra)
        out.update({
            "format": FILE_FORMAT,
            "version": FILE_VERSION,
            "gain": float(self.gain),
            "offset_V": float(self.offset_V),
            "divider": self.divider,
            "created": self.created,
            "valid_range_V": None if self.valid_range_V is None
            else [float(v) for v in self.valid_range_V],
            "adc_step_V": float(self.adc_step_V),
            "resolution_V": float(self.resolution_V),
            "points": [dict(p) for p in self.points],
        })
        return out

    @classmethod
    def from_dict(cls, data: dict, source: str = "calibration") -> Calibration:
        """Inverse of :meth:`to_dict`; raises :class:`DataError` on a malformed file."""
        if not isinstance(data, dict) or "gain" not in data:
            raise DataError(f"{source}: not a calibration file (no 'gain'); create one with "
                            "'dischargelab calibrate ... -o cal.json'")
        if data.get("format", FILE_FORMAT) != FILE_FORMAT:
            raise DataError(f"{source}: format is {data.get('format')!r}, expected {FILE_FORMAT!r}")
        try:
            gain = float(data["gain"])
            offset = float(data.get("offset_V", 0.0))
            rng = data.get("valid_range_V")
            valid = None if rng is None else (float(rng[0]), float(rng[1]))
            step = float(data.get("adc_step_V", adc_step_V()))
        except (TypeError, ValueError, IndexError):
            raise DataError(f"{source}: gain, offset_V, valid_range_V and adc_step_V must be "
                            "numbers") from None
        known = {"format", "version", "gain", "offset_V", "divider", "created", "valid_range_V",
                 "adc_step_V", "resolution_V", "points"}
        return cls(gain=gain, offset_V=offset, divider=str(data.get("divider", "")),
                   created=str(data.get("created", "")), valid_range_V=valid, adc_step_V=step,
                   points=tuple(data.get("points", ())),
                   extra={k: v for k, v in data.items() if k not in known})

    def save(self, path) -> Path:
        """Write the calibration file (JSON, atomically); returns the path."""
        return write_json(path, self.to_dict())


def load_calibration(path) -> Calibration:
    """Read a calibration file written by :meth:`Calibration.save`."""
    data = read_json(path, f"calibration file {str(path)!r} not found; create one with "
                           "'dischargelab calibrate --pair REAL,MEASURED ... -o cal.json'")
    return Calibration.from_dict(data, source=str(path))


# --------------------------------------------------------------------------- fitting

@dataclass(frozen=True)
class PointResult:
    """One calibration point after the fit (voltages in V)."""

    real_V: float
    measured_V: float
    ke: float                  # this point's own V_real / V_measured (eq. 7)
    predicted_V: float         # calibration applied to measured_V
    residual_V: float          # real - predicted
    loo_residual_V: float      # residual when the gain is fitted without this point
    bound_V: float             # worst-case error bound used for the decision
    status: str                # "linear", "outlier" or "non-linear"

    def to_dict(self) -> dict:
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class OffsetTest:
    """Nested-model comparison ``V = Ke*x`` (1 parameter) vs ``V = a*x + b`` (2)."""

    n_points: int
    gain_only: float
    gain_with_offset: float
    offset_V: float
    f_statistic: float
    f_p_value: float
    chi2_statistic: float
    chi2_p_value: float
    max_model_difference_V: float
    alpha: float
    adopted: bool
    reason: str

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class CalibrationFit:
    """Everything :func:`fit_calibration` found; ``.calibration`` is what gets stored."""

    calibration: Calibration
    points: tuple[PointResult, ...]
    gain_stderr: float
    offset_test: OffsetTest | None
    linear_up_to_V: float
    nonlinear_from_V: float | None
    clip_estimate_V: float | None
    meter: MeterAccuracy
    warnings: tuple[str, ...] = ()

    @property
    def nonlinear_points(self) -> list[PointResult]:
        return [p for p in self.points if p.status == "non-linear"]

    def to_dict(self) -> dict:
        """The ``calibrate --json`` dictionary."""
        cal = self.calibration
        return {
            "gain": cal.gain,
            "gain_stderr": self.gain_stderr,
            "offset_V": cal.offset_V,
            "divider": cal.divider,
            "valid_range_V": list(cal.valid_range_V) if cal.valid_range_V else None,
            "linear_up_to_V": self.linear_up_to_V,
            "nonlinear_from_V": self.nonlinear_from_V,
            "clip_estimate_V": self.clip_estimate_V,
            "adc_step_V": cal.adc_step_V,
            "resolution_V": cal.resolution_V,
            "meter": {"percent": self.meter.percent, "digits": self.meter.digits,
                      "resolution_V": self.meter.resolution_V},
            "offset_test": None if self.offset_test is None else self.offset_test.to_dict(),
            "points": [p.to_dict() for p in self.points],
            "warnings": list(self.warnings),
        }

    def plot(self, ax=None):
        """Ke of every point against the multimeter voltage, with the fitted Ke and the
        error bound of each point (in Ke units); returns the Axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4.2))
        cal = self.calibration
        colours = {"linear": "tab:blue", "outlier": "tab:orange", "non-linear": "tab:red"}
        for status, colour in colours.items():
            pts = [p for p in self.points if p.status == status]
            if pts:
                ax.errorbar([p.real_V for p in pts], [p.ke for p in pts],
                            yerr=[p.bound_V / p.measured_V for p in pts], fmt="o",
                            color=colour, capsize=3, label=f"{status} points")
        v = np.linspace(min(p.real_V for p in self.points), max(p.real_V for p in self.points))
        x = (v - cal.offset_V) / cal.gain
        ax.plot(v, v / x, color="k", lw=1,
                label=f"fit: Ke = {cal.gain:.4f}" + (f", offset {cal.offset_V:+.3f} V"
                                                     if cal.offset_V else ""))
        if cal.valid_range_V:
            ax.axvspan(*cal.valid_range_V, color="tab:green", alpha=0.08, label="linear range")
        ax.set_xlabel("multimeter voltage [V]")
        ax.set_ylabel("Ke = V_real / V_measured [-]")
        title = "Calibration (paper eq. 7)"
        ax.set_title(title + (f", divider {cal.divider}" if cal.divider else ""))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        return ax

    def report(self) -> str:
        """Plain-text summary (what the command prints above the table)."""
        cal = self.calibration
        lines = [f"Ke = {cal.gain:.4f} ± {self.gain_stderr:.4f} (paper eq. 7, fitted through the "
                 f"origin on {sum(p.status == 'linear' for p in self.points)} points)"]
        if cal.offset_V:
            lines.append(f"offset = {cal.offset_V:+.4f} V (significant, see test below)")
        t = self.offset_test
        if t is not None:
            lines.append(
                f"offset test (V = a*x + b vs V = Ke*x, n = {t.n_points}): "
                f"F = {t.f_statistic:.3g}, p = {t.f_p_value:.3g}; "
                f"chi2 with the meter's stated accuracy = "
                f"{t.chi2_statistic:.3g}, p = {t.chi2_p_value:.3g} -> "
                f"{'offset adopted' if t.adopted else 'no offset'} ({t.reason})")
        bad = self.nonlinear_points
        if bad:
            where = ", ".join(f"{p.real_V:g} V" for p in bad)
            lines.append(f"outside the linear range: {where} (Ke "
                         + ", ".join(f"{p.ke:.3f}" for p in bad)
                         + f" vs {cal.gain:.3f}); linear up to {self.linear_up_to_V:g} V, "
                         f"non-linear from {self.nonlinear_from_V:g} V")
            if self.clip_estimate_V is not None:
                lines.append(f"the flagged readings sit at the same level "
                             f"({min(p.measured_V for p in bad):g}-"
                             f"{max(p.measured_V for p in bad):g} V): the output clips; "
                             f"linearity ends near {self.clip_estimate_V:.1f} V")
        elif all(p.status == "linear" for p in self.points):
            lines.append(f"all points linear within the meter accuracy {self.meter.describe()}; "
                         f"valid range {cal.valid_range_V[0]:g}-{cal.valid_range_V[1]:g} V")
        else:
            lines.append(f"linear range {cal.valid_range_V[0]:g}-{cal.valid_range_V[1]:g} V "
                         f"within the meter accuracy {self.meter.describe()}")
        lines.append(f"resolution: ADC step {cal.adc_step_V * 1000:.3f} mV x Ke "
                     f"= {cal.resolution_V * 1000:.2f} mV")
        lines.extend(f"warning: {w}" for w in self.warnings)
        return "\n".join(lines)


def _gain_fit(x, y, w):
    """Weighted least-squares gain through the origin and its standard error."""
    sxx = float(np.sum(w * x * x))
    gain = float(np.sum(w * x * y)) / sxx
    return gain, 1.0 / math.sqrt(sxx)


def _line_fit(x, y, w):
    """Weighted least-squares line ``a*x + b``; returns (a, b, weighted RSS)."""
    sw = np.sqrt(w)
    design = np.column_stack([x, np.ones_like(x)]) * sw[:, None]
    coef, *_ = np.linalg.lstsq(design, y * sw, rcond=None)
    rss = float(np.sum((y * sw - design @ coef) ** 2))
    return float(coef[0]), float(coef[1]), rss


def validate_points(real_V, measured_V) -> tuple[np.ndarray, np.ndarray]:
    """Check calibration pairs; one clear :class:`DataError` for anything unusable."""
    try:
        real = np.asarray(real_V, dtype=float).ravel()
        measured = np.asarray(measured_V, dtype=float).ravel()
    except (TypeError, ValueError):
        raise DataError("calibration points must be numbers (REAL,MEASURED in volts)") from None
    if real.size != measured.size:
        raise DataError(f"got {real.size} multimeter readings but {measured.size} measured ones")
    if real.size < 2:
        raise DataError(f"need at least 2 calibration points to fit Ke and check linearity, "
                        f"got {real.size}; add more with --pair REAL,MEASURED")
    for i, (r, m) in enumerate(zip(real, measured), start=1):
        if not (math.isfinite(r) and math.isfinite(m)):
            raise DataError(f"point {i}: readings must be finite numbers, got {r}, {m}")
        if m == 0:
            raise DataError(f"point {i}: measured voltage is 0 V, so Ke = V_real / V_measured "
                            "is undefined; check the logger wiring")
        if r < 0 or m < 0:
            raise DataError(f"point {i}: negative voltage ({r:g} V, {m:g} V); give the pack "
                            "voltage with the probes the right way round")
        if r == 0:
            raise DataError(f"point {i}: multimeter reading is 0 V; calibrate with a battery "
                            "connected")
    if np.ptp(measured) == 0 and real.size > 1 and np.ptp(real) > 0:
        raise DataError("all measured readings are equal while the multimeter readings differ: "
                        "the logger input is stuck or saturated")
    return real, measured


def fit_calibration(real_V, measured_V, *, divider: str = "", meter: MeterAccuracy | None = None,
                    adc_bits: int = DEFAULT_ADC_BITS,
                    adc_reference_V: float = DEFAULT_ADC_REFERENCE_V, alpha: float = 0.05,
                    offset: str = "auto", created: str | None = None) -> CalibrationFit:
    """Fit Ke (and an offset if significant), report residuals and the linear range.

    Parameters
    ----------
    real_V, measured_V : array_like
        Reference multimeter readings [V] and the logger's readings [V] of the
        same voltages (at least 2 pairs).
    divider : str
        Name stored with the calibration (e.g. ``"3.3k"``).
    meter : MeterAccuracy, optional
        Stated accuracy of the multimeter; default the paper's ±(0.8 % + 5 digits).
    adc_bits, adc_reference_V : int, float
        ADC of the logger (10 bits, 5 V on an Arduino Uno).
    alpha : float
        Significance level of the offset tests.
    offset : {"auto", "yes", "no"}
        ``"auto"``: adopt an offset only if both tests reject "no offset".
    created : str, optional
        ISO 8601 time stamp; default now (UTC).

    Returns
    -------
    CalibrationFit

    References
    ----------
    .. [1] paper section 3.3, eq. (7), Table 1.
    """
    from scipy import stats

    if offset not in ("auto", "yes", "no"):
        raise DataError(f"offset must be 'auto', 'yes' or 'no', got {offset!r}")
    if not 0 < alpha < 1:
        raise DataError(f"alpha must be between 0 and 1, got {alpha}")
    meter = meter or MeterAccuracy()
    real, measured = validate_points(real_V, measured_V)
    step = adc_step_V(adc_bits, adc_reference_V)
    order = np.argsort(real, kind="stable")
    real, measured = real[order], measured[order]
    n = real.size
    ke_points = real / measured

    def sigma(gain):
        return np.sqrt(meter.sigma_V(real) ** 2 + (gain * step) ** 2 / 12.0)

    def bounds(gain, gain_se):
        # worst-case bound: meter limit + one ADC step at the pack + 2 SE of the prediction
        return meter.limit_V(real) + gain * step + 2.0 * gain_se * measured

    def consistent(idx):
        """One gain fitted to the points ``idx``: do all of them lie within the bound?"""
        idx = list(idx)
        x, y = measured[idx], real[idx]
        g0 = float(np.median(y / x))
        g, se = _gain_fit(x, y, 1.0 / sigma(g0)[idx] ** 2)
        return bool(np.all(np.abs(y - g * x) <= bounds(g, se)[idx]))

    # Grow the set from the lowest voltage up. A point that does not fit is an isolated
    # outlier if the point after it fits again, otherwise the linear range ends there.
    warnings: list[str] = []
    included: list[int] = [0, 1]
    outliers: list[int] = []
    first_nonlinear = n
    if not consistent(included):
        warnings.append("the two lowest points disagree by more than the meter accuracy; "
                        "all points are used, check the readings")
        included = list(range(n))
    else:
        i = 2
        while i < n:
            if consistent(included + [i]):
                included.append(i)
            elif i + 1 < n and consistent(included + [i + 1]):
                outliers.append(i)
            else:
                first_nonlinear = i
                break
            i += 1
    n_linear = len(included)
    if outliers:
        warnings.append("isolated point(s) at " + ", ".join(f"{real[i]:g} V" for i in outliers)
                        + " disagree with their neighbours and were left out; repeat them")

    x_lin, y_lin = measured[included], real[included]
    g0 = float(np.median(y_lin / x_lin))
    w_lin = 1.0 / sigma(g0)[included] ** 2
    gain, gain_se = _gain_fit(x_lin, y_lin, w_lin)

    # Leave-one-out residuals of the points in the fit (information for the user).
    # Points outside the fit get their plain residual (the fit never saw them).
    loo = np.full(n, np.nan)
    for i in range(n):
        keep = [j for j in included if j != i]
        if len(keep) >= 2:
            g_i, _ = _gain_fit(measured[keep], real[keep], 1.0 / sigma(g0)[keep] ** 2)
            loo[i] = real[i] - g_i * measured[i]

    # Offset: nested models on the linear points.
    offset_test = None
    offset_V = 0.0
    if n_linear >= 3 and np.ptp(x_lin) > 0:
        a, b, rss_line = _line_fit(x_lin, y_lin, w_lin)
        rss_gain = float(np.sum(w_lin * (y_lin - gain * x_lin) ** 2))
        dof = n_linear - 2
        drop = max(rss_gain - rss_line, 0.0)
        if rss_line > 0:
            f_stat = drop / (rss_line / dof)
            f_p = float(stats.f.sf(f_stat, 1, dof))
        else:
            f_stat, f_p = math.inf, 0.0
        chi2_stat = drop  # weights are 1/sigma^2 of the known uncertainty
        chi2_p = float(stats.chi2.sf(chi2_stat, 1))
        diff = float(np.max(np.abs((a * x_lin + b) - gain * x_lin)))
        if offset == "yes":
            adopted, reason = True, "requested"
        elif offset == "no":
            adopted, reason = False, "not requested"
        elif f_p < alpha and chi2_p < alpha:
            adopted, reason = True, f"both p < {alpha:g}"
        elif f_p < alpha:
            adopted = False
            reason = (f"the offset model differs by at most {diff * 1000:.0f} mV, within the "
                      "reference meter's accuracy (chi2 test not significant)")
        else:
            adopted, reason = False, f"F-test p >= {alpha:g}"
        offset_test = OffsetTest(n_linear, gain, a, b, f_stat, f_p, chi2_stat, chi2_p, diff,
                                 alpha, adopted, reason)
        if adopted:
            gain, offset_V = a, b
            # standard error of the slope of the weighted line
            sxx = float(np.sum(w_lin * (x_lin - np.average(x_lin, weights=w_lin)) ** 2))
            gain_se = 1.0 / math.sqrt(sxx)
    elif offset == "yes":
        raise DataError("an offset needs at least 3 linear calibration points at different "
                        "voltages")
    else:
        warnings.append("fewer than 3 linear points: the offset cannot be tested")

    predicted = gain * measured + offset_V
    residual = real - predicted
    bound = bounds(gain, gain_se)
    status = ["linear" if i in included else "outlier" if i in outliers else "non-linear"
              for i in range(n)]

    points = tuple(PointResult(float(real[i]), float(measured[i]), float(ke_points[i]),
                               float(predicted[i]), float(residual[i]), float(loo[i]),
                               float(bound[i]), status[i]) for i in range(n))
    linear_up_to = float(real[included[-1]])
    nonlinear_from = float(real[first_nonlinear]) if first_nonlinear < n else None
    clip = None
    top = list(range(first_nonlinear, n))
    if len(top) >= 2 and np.ptp(real[top]) > 0:
        # readings that stop rising while the real voltage rises: the output clips
        slope = np.ptp(measured[top]) / np.ptp(real[top])
        if slope < 0.25 / gain:
            clip = float(gain * np.min(measured[top]) + offset_V)
    valid = (float(real[included[0]]), linear_up_to)
    if created is None:
        created = datetime.now(UTC).replace(microsecond=0).isoformat()
    calibration = Calibration(
        gain=float(gain), offset_V=float(offset_V), divider=str(divider), created=created,
        valid_range_V=valid, adc_step_V=step,
        points=tuple(p.to_dict() for p in points),
        extra={"gain_stderr": gain_se,
               "meter": {"percent": meter.percent, "digits": meter.digits,
                         "resolution_V": meter.resolution_V},
               "offset_test": None if offset_test is None else offset_test.to_dict(),
               "nonlinear_from_V": nonlinear_from,
               "method": "weighted least squares through the origin (paper eq. 7); "
                         "offset by nested F and chi2 tests; linear range by the largest "
                         "consistent set of lowest points"},
    )
    return CalibrationFit(calibration, points, float(gain_se), offset_test, linear_up_to,
                          nonlinear_from, clip, meter, tuple(warnings))


# --------------------------------------------------------------------------- input

def parse_pair(text: str, index: int | None = None) -> tuple[float, float]:
    """Parse ``"REAL,MEASURED"`` (also ``;``, tab or space separated) into floats."""
    where = f"pair {index}" if index is not None else "pair"
    parts = [p for p in text.replace(";", ",").replace("\t", ",").replace(" ", ",").split(",")
             if p.strip()]
    if len(parts) != 2:
        raise DataError(f"{where}: expected REAL,MEASURED (two numbers in volts), got {text!r}")
    try:
        return float(parts[0]), float(parts[1])
    except ValueError:
        raise DataError(f"{where}: {text!r} is not two numbers; write e.g. 11.88,2.71") from None


def read_points_csv(path, divider: str | None = None) -> tuple[list[float], list[float]]:
    """Calibration pairs from a CSV file.

    The file has two columns (multimeter reading, logger reading) with or
    without a header; lines starting with ``#`` are comments. With a header,
    columns named ``real_V`` / ``measured_V`` (or containing "real"/"multimeter"
    and "measured"/"logger") are used wherever they are; a ``divider`` column
    selects the rows of one divider when ``divider`` is given.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"calibration CSV {str(path)!r} not found")
    with path.open(newline="", encoding="utf-8-sig") as fh:
        rows = list(csv.reader(line for line in fh
                               if line.strip() and not line.lstrip().startswith("#")))
    if not rows:
        raise DataError(f"{path}: no calibration points")

    def is_number(text):
        try:
            float(text)
            return True
        except ValueError:
            return False

    header = None
    if not all(is_number(c) for c in rows[0][:2]):
        header = [c.strip().lower() for c in rows[0]]
        rows = rows[1:]
    real_col, meas_col, div_col = 0, 1, None
    if header:
        def find(*keys):
            for i, name in enumerate(header):
                if any(k in name for k in keys):
                    return i
            return None
        r = find("real", "multimeter", "reference")
        m = find("measured", "logger", "arduino")
        if r is None or m is None:
            raise DataError(f"{path}: header {header} has no real/measured columns; name them "
                            "real_V,measured_V or drop the header")
        real_col, meas_col, div_col = r, m, find("divider", "resistor")
    real, measured = [], []
    for lineno, row in enumerate(rows, start=2 if header else 1):
        if div_col is not None and divider and row[div_col].strip() != divider:
            continue
        try:
            real.append(float(row[real_col]))
            measured.append(float(row[meas_col]))
        except (ValueError, IndexError):
            raise DataError(f"{path}: row {lineno} is not two numbers: {row}") from None
    if div_col is not None and divider and not real:
        names = sorted({row[div_col].strip() for row in rows if len(row) > div_col})
        raise DataError(f"{path}: no rows for divider {divider!r}; the file has {names}")
    if div_col is not None and not divider:
        names = sorted({row[div_col].strip() for row in rows if len(row) > div_col})
        if len(names) > 1:
            raise DataError(f"{path}: points of several dividers {names}; choose one with "
                            "--divider NAME")
    return real, measured


__all__ = [
    "Calibration", "CalibrationFit", "MeterAccuracy", "OffsetTest", "PointResult",
    "adc_step_V", "fit_calibration", "load_calibration", "parse_pair", "read_points_csv",
    "validate_points", "DEFAULT_ADC_BITS", "DEFAULT_ADC_REFERENCE_V",
]
