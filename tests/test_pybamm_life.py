"""Lives simulated by PyBaMM with its degradation submodels (``tests/pybamm_life.py``):
the tests' capacities fade, the missions stay above the cutoff, and the log carries the
tests the truth names."""

import numpy as np
import pytest

pytest.importorskip("pybamm")


@pytest.mark.slow
def test_a_pybamm_life_fades_test_by_test_and_its_missions_stay_above_the_cutoff():
    from pybamm_life import PybammLifeSpec, ocv, pybamm_life

    spec = PybammLifeSpec(cycles=7, test_every=3, sample_hz=0.2, seed=2)
    life = pybamm_life(spec)
    capacity = np.array([q for _, _, q, _ in life.tests])
    assert capacity.size == 3
    # SEI, plating and loss of active material only take capacity away
    assert np.all(np.diff(capacity) < 0)
    assert capacity[-1] < 0.98 * capacity[0]
    assert life.cycles["mission_min_V"].min() > spec.cutoff_V
    # the lithium lost only grows, and the cell's own curve spans its voltage window
    assert np.all(np.diff(life.cycles["lli_pct"]) > 0)
    ends = ocv(spec, life.cycles.iloc[-1], [0.0, 1.0])
    assert ends[0] == pytest.approx(spec.cutoff_V, abs=0.02)
    assert ends[1] == pytest.approx(spec.test_cv_V, abs=0.02)
    # the logged tests hold the charge the truth names (C/5 to the cutoff)
    frame = life.frame
    for start, end, q, _ in life.tests:
        part = frame[(frame["time_s"] >= start) & (frame["time_s"] <= end)]
        logged = np.trapezoid(part["current_A"], part["time_s"]) / 3600.0
        assert logged == pytest.approx(q, rel=0.01)
        assert part["voltage_V"].iloc[-1] == pytest.approx(spec.cutoff_V, abs=0.02)
    # every mission discharge in the log ends above the cutoff
    missions = frame[frame["current_A"] > 1.0]
    assert missions["voltage_V"].min() > spec.cutoff_V
