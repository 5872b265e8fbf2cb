"""Journeys: a battery tester's file fitted and used with no chemistry given.

The runs of a tester's file stop at its lower voltage limit: the battery file records that
cutoff, and the commands that need one use it (they asked for a cutoff the user had not
thought of, although every fitted run said it); the battery takes one name for the steps
of one file, and a figure's title keeps inside the figure.
"""

from __future__ import annotations

import json

from cli_run import run

MACCOR = "cyclers/maccor/maccor_001.txt"


def test_a_tester_file_fitted_without_chemistry_keeps_its_cutoff(capsys, tmp_path,
                                                                 shared_data):
    cell = tmp_path / "cell.json"
    code, out, err = run(capsys, "fit", shared_data / MACCOR, "--model", "shepherd",
                         "--bootstrap", "0", "-o", cell)
    assert code == 0, err
    doc = json.loads(cell.read_text())
    assert doc["name"] == "maccor_001 steps 7, 12, 17, 22"
    assert doc["tested_cutoff_cell_V"] == 2.5
    code, out, err = run(capsys, "curves", cell, "--currents", "1,5", "--json")
    assert code == 0, err
    assert "cutoff 2.5 V/cell, where every fitted run stopped" in err
    ends = [c["cutoff_pack_V"] for c in json.loads(out)]
    assert ends and all(abs(v - 2.5) < 1e-9 for v in ends)


def test_runs_label_groups_the_steps_of_one_file():
    from dischargelab.formatting import runs_label

    assert runs_label(["m step 7", "m step 12", "a.csv"]) == "m steps 7, 12, a.csv"
    assert runs_label(["m step 7"]) == "m step 7"
    assert runs_label(["C10", "1C"]) == "C10, 1C"
