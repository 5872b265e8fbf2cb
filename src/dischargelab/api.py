"""The public Python API: read, fit, load, predict, endurance, validate.

::

    import dischargelab as dl
    runs = [dl.read(p, columns="time_s=0,current_A=1,voltage_V=2,temperature_C=4")
            for p in ("c10.csv", "1c.csv", "4c.csv")]
    fit = dl.fit(runs)                       # model picked by evidence
    fit.predict(current=6.0, cutoff=2.5).to_dict()["time_to_cutoff_s"]
    fit.save("cell.json"); cell = dl.load("cell.json")
    dl.endurance(dl.load("hacker-4100-4s-lifepo4"), "paper-table5").plot()

The command line is this API plus printing; both use the same defaults.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .autopilot import autopilot_params  # noqa: F401  (public: dl.autopilot_params)
from .discharge import Discharge
from .errors import DataError
from .model import Battery, load_battery
from .onboard import autopilot_script  # noqa: F401  (public: dl.autopilot_script)

#: Bootstrap refits stored by :func:`fit` (the draws of every later interval).
DEFAULT_BOOTSTRAP = 100


def read(path: str | Path, **options: Any) -> Discharge:
    """Read one discharge from a file; the format is detected from the content.

    Parameters
    ----------
    path : str or path-like
        CSV/TSV/LabVIEW/DJI/dischargelab log, a flight log (ArduPilot, PX4 ULog,
        blackbox, MAVLink .tlog, in-flight CSV) or a battery tester's file (Neware,
        BioLogic, Arbin, Maccor: one discharge step, ``segment=N`` picks step N).
    **options
        Reader options of :func:`dischargelab.io.read_discharge` (``columns``,
        ``current_A`` [A] for files without a current, ``sign``, ``units``,
        ``segment``, ...).

    Returns
    -------
    Discharge
    """
    from .io import read_discharge

    frame, meta = read_discharge(path, **options)
    return Discharge.from_frame(frame, meta, name=Path(path).name)


def fit(discharges: Discharge | str | Path | Sequence[Discharge | str | Path], *,
        model: str = "auto", cells: int | None = None, parallel: int = 1,
        bootstrap: int = DEFAULT_BOOTSTRAP, fixed: dict | None = None,
        bounds: dict | None = None, e0: float | None = None, paper_mode: bool = False,
        use_rest: bool = True, seed: int = 0, cooling: str | None = "still-air",
        chemistry: str | None = None):
    """Fit a battery model to one or several discharges (shared parameters).

    Parameters
    ----------
    discharges : Discharge, path, or a sequence of them, or FlightCurves
        Measurements of the same cell or pack at one or several currents, or the
        flights of one pack from :func:`dischargelab.flight.flight_curves` (fitted by
        :func:`dischargelab.flight.fit_flights`: each flight from its own initial
        charge, the capacity held near the label when the flights do not reach the knee).
        A battery tester's file (Neware, BioLogic, Arbin, Maccor) given by path gives
        the first full discharge at each of its rates (the result's notes say which
        steps); choose others with ``dl.read(path, segment=N)``.
    model : str
        ``"auto"`` (by evidence; ``"ecm"`` for flights), ``"shepherd"``,
        ``"shepherd-thermal"``, ``"shepherd-dynamic"`` or ``"ecm"``.
    cells : int, optional
        Cells in series of the measured pack (default 1; for flights the log's count).
    parallel : int
        Strings in parallel of the measured pack.
    bootstrap : int
        Moving-block bootstrap refits kept for intervals (0: covariance only).
    fixed : dict, optional
        Parameters held fixed ``{name: value}`` (per cell, SI units in the name).
    bounds : dict, optional
        ``{name: (low, high)}`` bounds.
    e0 : float, optional
        Known E0 per cell [V] (shorthand for ``fixed={"E0_V": e0}``).
    paper_mode : bool
        Reproduce the paper's fit (``shepherd``, E0 given, current scale fitted).
    use_rest : bool
        Use the rest voltage before the load as a data point.
    seed : int
        Seed of the bootstrap.
    cooling : {"still-air", "airflow"} or None
        Cooling of the cells for the thermal prior of a thermal model fitted without a
        logged temperature (its self-heating is simulated; None: held at the ambient).
        Flights always use ``"airflow"``.
    chemistry : {"lipo", "li-ion", "lifepo4"}, optional
        For that thermal prior; default from the full cell's voltage.

    Returns
    -------
    dischargelab.fit.FitResult
        ``.parameters``, ``.ci95``, ``.warnings``, ``.predict(...)``, ``.save(path)``,
        ``.report()``, ``.to_dict()``, ``.plot()``.
    """
    from .fit import fit_battery
    from .flight import FlightCurves

    fixed = dict(fixed or {})
    if e0 is not None:
        fixed["E0_V"] = float(e0)
    if isinstance(discharges, FlightCurves):
        return _fit_flights(discharges, model=model, cells=cells, parallel=parallel,
                            bootstrap=bootstrap, fixed=fixed, bounds=bounds, use_rest=use_rest,
                            seed=seed)
    from .io.cyclers import used_steps_note

    items = discharges if isinstance(discharges, (list, tuple)) else [discharges]
    if not items:
        raise DataError("no discharges to fit")
    runs = [run for d in items for run in _as_discharges(d, "fit")]
    cells = 1 if cells is None else cells
    result = fit_battery([run.to_curve() for run in runs], cells_series=cells,
                         strings_parallel=parallel, fixed=fixed, bounds=bounds,
                         paper_mode=paper_mode, use_rest=use_rest, bootstrap=bootstrap,
                         seed=seed, model=model, cooling=cooling, chemistry=chemistry)
    result.notes.extend(used_steps_note([run.meta for run in runs]))
    return result


def _fit_flights(flights, *, model, cells, parallel, bootstrap, fixed, bounds, use_rest, seed):
    """``fit`` for :class:`dischargelab.flight.FlightCurves` (flights of one pack)."""
    from .flight import fit_flights

    return fit_flights(flights, model=model, strings_parallel=parallel, cells=cells,
                       fixed=fixed, bounds=bounds, bootstrap=bootstrap, seed=seed,
                       use_rest=use_rest)


def load(source: str | Path | Battery) -> Battery:
    """A battery from a battery file or a preset name.

    Parameters
    ----------
    source : str, path-like or Battery
        Battery file written by :func:`fit` / ``dischargelab fit -o``, or a preset
        name (``dischargelab presets``).

    Returns
    -------
    Battery
        Immutable: ``with_pack(...)`` and ``dataclasses.replace`` return copies, so a
        preset is never changed by its users.
    """
    return load_battery(source)  # a logbook pack gives its model at today's health


def predict(battery: Battery | str | Path, *, current: float | None = None,
            c_rate: float | None = None, power: float | None = None,
            cutoff: float | None = None, cutoff_pack: float | None = None, soc: float = 100.0,
            ambient: float | None = None, interval: bool = True):
    """Constant-current or constant-power discharge until the cutoff, with its 95 % interval.

    Parameters
    ----------
    battery : Battery, preset name, battery-file path or logbook pack
        See :func:`load`.
    current : float, optional
        Constant pack current [A].
    c_rate : float, optional
        Current as a multiple of the rated pack capacity [1/h].
    power : float, optional
        Constant pack power [W]. Give exactly one of current, c_rate, power.
    cutoff, cutoff_pack : float, optional
        Cutoff per cell or per pack [V]; default the chemistry's usual cutoff.
    soc : float
        State of charge at the start [%] (100 = full).
    ambient : float, optional
        Ambient temperature [degC] (thermal families; default the fitted data's).
    interval : bool
        Add the 95 % interval (parameter draws plus model error).

    Returns
    -------
    dischargelab.predict.Prediction
    """
    from .predict import predict as predict_battery

    return predict_battery(load(battery), current=current, c_rate=c_rate, power=power,
                           cutoff=cutoff, cutoff_pack=cutoff_pack, soc=soc, ambient=ambient,
                           interval=interval)


def endurance(battery: Battery | str | Path | None, mission: str | Path, *,
              draws: int | None = None, seed: int = 0, **options: Any):
    """Fly a mission (TOML file or bundled mission name) and return its result.

    Parameters
    ----------
    battery : Battery, preset name, battery-file path or logbook pack (see :func:`load`)
        None: the battery the mission's ``[battery] source`` names. The battery's cells,
        chemistry and cutoff are kept; the mission's ``[battery]`` table fills in only
        what it does not say (:mod:`dischargelab.identity`).
    mission : str or path-like
        Mission file, or a bundled mission's name (``"paper-table5"``, ...).
    draws : int, optional
        Parameter draws for the 95 % interval (default: every stored bootstrap refit).
    seed : int
        Seed of the draws.
    **options
        ``cutoff_cell_V``, ``reserve_pct`` ... as :func:`dischargelab.mission.load_mission`.

    Returns
    -------
    dischargelab.mission.MissionResult
    """
    from .mission import load_mission, run_mission

    mis = load_mission(mission, battery=None if battery is None else load(battery), **options)
    bat = mis.battery
    if draws is None:
        boot = bat.extra.get("bootstrap") or {}
        draws = len(boot.get("samples", [])) or (100 if bat.covariance is not None else 0)
    return run_mission(mis, draws=draws, seed=seed)


def validate(battery: Battery | str | Path,
             discharges: Discharge | str | Path | Sequence[Discharge | str | Path], *,
             cutoff: float | None = None, low_timer_s: float | None = None):
    """Compare predictions with measured discharges (endurance, voltage, interval coverage).

    Parameters
    ----------
    battery : Battery, preset name, battery-file path or logbook pack (see :func:`load`)
    discharges : Discharge, path, or a sequence of them
    cutoff : float, optional
        Cutoff per cell [V]; default the chemistry's usual cutoff.
    low_timer_s : float, optional
        The cutoff is reached when the voltage stays under it this long [s]; default
        10 s under a varying current (peaks dip under it early), 0 under a constant one.

    Returns
    -------
    list of dischargelab.validate.ValidationCase
    """
    from .predict import default_cutoff
    from .validate import compare_discharge, input_warnings

    bat = load(battery)
    cut = default_cutoff(bat, cutoff)["cutoff_cell_V"]
    items = discharges if isinstance(discharges, (list, tuple)) else [discharges]
    out, loaded = [], []
    for d in items:
        for dis in _as_discharges(d, "all"):
            frame, meta = dis.to_pandas(), dict(dis.meta)
            loaded.append((frame, meta))
            out.append(compare_discharge(bat, frame, meta, cut, low_timer_s=low_timer_s))
    input_warnings(bat, loaded, out, cut)
    return out


def _as_discharges(item, choose: str) -> list[Discharge]:
    """A Discharge, or the discharges of a file (several steps of a tester's file)."""
    if isinstance(item, Discharge):
        return [item]
    if isinstance(item, (str, Path)):
        from .io import read_discharges

        name = Path(item).name
        return [Discharge.from_frame(frame, meta, name=f"{name} step {meta['step']['number']}"
                                     if isinstance(meta.get("step"), dict) else name)
                for frame, meta in read_discharges(item, choose=choose)]
    raise DataError(f"expected a Discharge or a file path, got {type(item).__name__}")
