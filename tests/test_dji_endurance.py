"""A battery fitted from the DJI M100 flights (K near 0): missions end in bounded time."""

import json
import time

import pytest

from dischargelab.cli import main
from dischargelab.mission import bundled_missions


@pytest.fixture(scope="module", params=["shepherd", "auto"])
def dji_battery(request, shared_data, tmp_path_factory):
    files = sorted((shared_data / "dji_m100_flights").glob("derived_battery_*.csv"))
    out = tmp_path_factory.mktemp("dji") / f"dji-{request.param}.json"
    with pytest.raises(SystemExit) as exc:
        main(["fit", str(files[1]), "--cells", "6", "--model", request.param,
              "--bootstrap", "20", "-o", str(out), "--quiet"])
    assert exc.value.code == 0
    return out


@pytest.mark.parametrize("mission", sorted(bundled_missions()))
def test_endurance_on_a_dji_fitted_battery_returns_quickly(dji_battery, mission, capsys):
    start = time.perf_counter()
    with pytest.raises(SystemExit) as exc:
        main(["endurance", str(dji_battery), mission, "--json"])
    elapsed = time.perf_counter() - start
    captured = capsys.readouterr()
    assert elapsed < 30.0  # a hang, not a timing: each mission takes about 1 s here
    if exc.value.code == 0:
        doc = json.loads(captured.out)
        assert doc["endurance_s"] is None or doc["endurance_s"] > 0
    else:  # the model cannot fly it: one clear line, no traceback
        assert exc.value.code == 2
        assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
