"""Battery testers' files: every shared file reads, its first full discharge matches the
tester's own capacity counter, steps carry the tester's numbers, and exports with other
column names, units and sheet splits read the same."""

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import dischargelab as dl
from cli_run import run
from dischargelab.errors import DataError, MissingExtraError
from dischargelab.io import read_discharge, read_discharges
from dischargelab.io.cyclers import (
    detect_tester,
    fit_steps,
    full_discharges,
    read_tester,
)

#: file -> (format, the step number of its first full discharge, that discharge's mean
#: current [A]); from the data README and the testers' own step tables.
FILES = {
    "neware/TestFile.nda": ("neware-nda", 7, 3.0),
    "neware/test_2.ndax": ("neware-ndax", 4, 7.92e-5),
    "biologic/jdb11-1_c3_gcpl_5cycles_2V-3p8V_C-24_data_C09.mpr": ("biologic-mpr", 4, 8.88e-5),
    "arbin/arbin_example.res": ("arbin-res", 3, 8.65e-5),
    "arbin/20160805_test001_45_cc_01.res": ("arbin-res", 9, 1.52e-4),
    "arbin/bs542_004_gr_li_50ua_50mv_1v_191020_Channel_11.xlsx": ("arbin-xlsx", 4, 5.0e-5),
    "arbin/arbin_example.csv": ("arbin-text", 3, 3.42),
    "maccor/maccor_001.txt": ("maccor-text", 7, 0.5),
}

#: The acceptance: charge counted from the current within 0.1 % of the tester's counter.
CAPACITY_TOLERANCE = 1e-3


def _needs_mdbtools(name: str) -> None:
    if name.endswith(".res") and shutil.which("mdb-export") is None:
        if os.environ.get("CI"):
            pytest.fail("mdbtools is required in CI (make mdbtools: apt-get install mdbtools)")
        pytest.skip("mdbtools not installed (apt-get install mdbtools)")


@pytest.fixture(scope="module")
def cyclers(shared_data):
    return shared_data / "cyclers"


@pytest.mark.parametrize("name", sorted(FILES))
def test_every_tester_file_reads_and_its_first_full_discharge_matches_the_tester(cyclers,
                                                                                 name):
    _needs_mdbtools(name)
    fmt, number, current = FILES[name]
    tester = read_tester(cyclers / name)
    assert tester.meta["format"] == fmt
    first = full_discharges(tester.steps)[0]
    assert first["number"] == number
    assert first["mean_current_A"] == pytest.approx(current, rel=0.02)
    assert first["tester_Ah"] > 0
    assert abs(first["charge_Ah"] / first["tester_Ah"] - 1) < CAPACITY_TOLERANCE
    # the discharge read_discharge gives by default is that step, discharge positive
    frame, meta = read_discharge(cyclers / name)
    assert meta["segment"] == number and meta["step"]["kind"] == "discharge"
    assert frame["current_A"].median() > 0
    assert frame["time_s"].iloc[0] == 0 and np.all(np.diff(frame["time_s"]) > 0)
    assert meta["cycle"] == first["cycle"]
    assert set(frame["step_index"]) == {first["step"]}


def test_steps_carry_the_testers_numbers_and_kinds(cyclers):
    tester = read_tester(cyclers / "maccor/maccor_001.txt")
    kinds = [s["kind"] for s in tester.steps[:8]]
    assert kinds == ["rest", "discharge", "rest", "charge", "charge", "rest", "discharge",
                     "rest"]
    assert [s["mode"] for s in tester.steps[3:5]] == ["CC", "CV"]
    assert [s["step"] for s in tester.steps] == list(range(1, 25))
    assert "state column" in tester.meta["sign_source"]
    # the current is unsigned in the file: the state gives charge its sign
    assert tester.steps[3]["mean_current_A"] == pytest.approx(-1.5, rel=1e-3)
    assert fit_steps(tester.steps)[0] == [7, 12, 17, 22]
    whole, meta = read_discharge(cyclers / "maccor/maccor_001.txt", segment="none")
    assert whole["cycle_index"].dtype.kind == "i" and whole["step_index"].dtype.kind == "i"
    assert len(meta["steps"]) == 24 and meta["segment"] is None
    assert [s["number"] for s in meta["segments"]] == [2, 7, 12, 17, 22]
    assert (whole["current_A"] < 0).any() and (whole["current_A"] > 0).any()


def test_a_step_is_read_by_its_number_and_a_charge_step_is_refused(cyclers):
    d = dl.read(cyclers / "maccor/maccor_001.txt", segment=12)
    assert d.mean_current_A == pytest.approx(2.5, rel=1e-3)
    assert d.rest_voltage_V == pytest.approx(4.173, abs=0.002)
    assert d.meta["starts_full"] is True
    with pytest.raises(DataError, match="is not a discharge.*2, 7, 12, 17, 22"):
        read_discharge(cyclers / "maccor/maccor_001.txt", segment=4)
    with pytest.raises(DataError, match="24 steps"):
        read_discharge(cyclers / "maccor/maccor_001.txt", segment=30)
    with pytest.raises(DataError, match="not a battery tester file"):
        read_discharges(cyclers.parent / "samsung30q_S001/Q30_S001_1C.csv", steps=[2],
                        columns="time_s=0,current_A=1,voltage_V=2")


def test_neware_sign_cycles_and_ndax_step_times(cyclers):
    nda = read_tester(cyclers / "neware/TestFile.nda")
    assert [s["cycle"] for s in nda.steps] == [1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3]
    assert "temperature_C" in nda.frame and nda.meta["start_time"].startswith("2024-05-27")
    ndax = read_tester(cyclers / "neware/test_2.ndax")
    assert np.all(np.diff(ndax.frame["time_s"]) >= 0)
    assert any("interpolation" in n for n in ndax.meta["notes"])
    assert len(fit_steps(ndax.steps)[0]) == 7     # one per rate of the rate test


def test_biologic_set_point_current_is_used_and_said(cyclers):
    d = dl.read(cyclers / "biologic/jdb11-1_c3_gcpl_5cycles_2V-3p8V_C-24_data_C09.mpr")
    assert any("set point control/V/mA" in n for n in d.meta["notes"])
    assert d.charge_Ah == pytest.approx(0.853e-3, rel=2e-3)


def test_arbin_res_records_out_of_order_are_put_in_order(cyclers):
    _needs_mdbtools(".res")
    tester = read_tester(cyclers / "arbin/arbin_example.res")
    assert any("Data_Point order" in n for n in tester.meta["notes"])
    assert [s["number"] for s in full_discharges(tester.steps)] == [3, 7, 11, 15]


# ----------------------------------------------------------------------------- held out

def test_newer_arbin_export_names_and_units_read_the_same(cyclers, tmp_path):
    """MITS Pro 8 style headers ("Test Time (s)", "Current (mA)"...), mA and mAh units."""
    source = pd.read_csv(cyclers / "arbin/arbin_example.csv")
    newer = pd.DataFrame({
        "Date Time": pd.to_datetime(source["DateTime"], unit="s").dt.strftime(
            "%m/%d/%Y %H:%M:%S"),
        "Test Time (s)": source["Test_Time"], "Step Time (s)": source["Step_Time"],
        "Cycle Index": source["Cycle_Index"], "Step Index": source["Step_Index"],
        "Current (mA)": source["Current"] * 1000, "Voltage (V)": source["Voltage"],
        "Charge Capacity (mAh)": source["Charge_Capacity"] * 1000,
        "Discharge Capacity (mAh)": source["Discharge_Capacity"] * 1000,
        "Aux_Temperature_1 (C)": source["Temperature"]})
    path = tmp_path / "channel_5.csv"
    newer.to_csv(path, index=False)
    assert detect_tester(path) == "text"
    old, new = read_tester(cyclers / "arbin/arbin_example.csv"), read_tester(path)
    assert new.meta["format"] == "tester-text"
    assert [s["kind"] for s in new.steps] == [s["kind"] for s in old.steps]
    for a, b in zip(full_discharges(old.steps), full_discharges(new.steps)):
        assert b["charge_Ah"] == pytest.approx(a["charge_Ah"], rel=1e-9)
        assert b["tester_Ah"] == pytest.approx(a["tester_Ah"], rel=1e-9)
    assert new.frame["temperature_C"].iloc[5] == pytest.approx(source["Temperature"].iloc[5])


def test_maccor_export_with_seconds_and_comma_separation_reads_the_same(cyclers, tmp_path):
    text = (cyclers / "maccor/maccor_001.txt").read_text()
    lines = text.splitlines()
    head = 3   # preamble lines before the header
    table = pd.read_csv(cyclers / "maccor/maccor_001.txt", sep="\t", skiprows=head)
    days = table["TestTime"].str.extract(r"(\d+)d\s+(\d+):(\d+):([\d.]+)").astype(float)
    seconds = days[0] * 86400 + days[1] * 3600 + days[2] * 60 + days[3]
    other = pd.DataFrame({"Rec#": table["Rec#"], "Cyc#": table["Cyc#"], "Step": table["Step"],
                          "Test (Sec)": seconds, "Amp-hr": table["Amp-hr"],
                          "Amps": table["Amps"], "Volts": table["Volts"],
                          "State": table["State"]})
    path = tmp_path / "maccor_export.csv"
    path.write_text("\n".join(lines[:head]) + "\n" + other.to_csv(index=False))
    tester = read_tester(path)
    assert tester.meta["format"] == "maccor-text"
    step = tester.step(7)
    assert step["charge_Ah"] == pytest.approx(4.544, rel=1e-3)
    assert abs(step["charge_Ah"] / step["tester_Ah"] - 1) < CAPACITY_TOLERANCE


def test_workbook_split_over_sheets_reads_as_one(cyclers, tmp_path):
    pytest.importorskip("openpyxl")
    book = pd.read_excel(cyclers / "arbin/bs542_004_gr_li_50ua_50mv_1v_191020_Channel_11.xlsx",
                         sheet_name="Channel_11_1")
    path = tmp_path / "split.xlsx"
    with pd.ExcelWriter(path, engine="openpyxl") as writer:
        book.iloc[:2000].to_excel(writer, sheet_name="Channel_11_1", index=False)
        book.iloc[2000:].to_excel(writer, sheet_name="Channel_11_2", index=False)
        pd.DataFrame({"Cycle_Index": [1], "Charge_Time(s)": [1.0]}).to_excel(
            writer, sheet_name="Statistics_11", index=False)
    tester = read_tester(path)
    assert len(tester.frame) == len(book)
    whole = read_tester(cyclers / "arbin/bs542_004_gr_li_50ua_50mv_1v_191020_Channel_11.xlsx")
    assert [s["charge_Ah"] for s in tester.steps] == pytest.approx(
        [s["charge_Ah"] for s in whole.steps], rel=1e-12)


# ----------------------------------------------------------------------------- errors

def test_unreadable_files_name_the_reader_and_its_version(cyclers, tmp_path):
    nda = tmp_path / "damaged.nda"
    nda.write_bytes(b"NEWARE" + np.random.default_rng(3).integers(0, 256, 4000,
                                                                 dtype=np.uint8).tobytes())
    with pytest.raises(DataError) as info:
        read_tester(nda)
    assert "NewareNDA" in str(info.value) and "\n" not in str(info.value)
    mpr = tmp_path / "cut.mpr"
    mpr.write_bytes((cyclers / "biologic/jdb11-1_c3_gcpl_5cycles_2V-3p8V_C-24_data_C09.mpr")
                    .read_bytes()[:5000])
    with pytest.raises(DataError) as info:
        read_tester(mpr)
    assert "galvani" in str(info.value) and "\n" not in str(info.value)


def test_missing_mdbtools_names_the_debian_package(cyclers, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(MissingExtraError, match="apt-get install mdbtools"):
        read_tester(cyclers / "arbin/arbin_example.res")


# ----------------------------------------------------------------------------- commands

def test_steps_command_and_step_option(cyclers, capsys, tmp_path):
    code, out, err = run(capsys, "steps", cyclers / "neware/TestFile.nda", "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["fit_steps"] == [7] and len(doc["steps"]) == 11
    code, out, err = run(capsys, "validate", "zippy-1100-2s", cyclers / "maccor/maccor_001.txt",
                         "--step", "99", "--cutoff", "2.6")
    assert code == 2 and "24 steps" in err
    code, out, err = run(capsys, "fit", cyclers.parent / "samsung30q_S001/Q30_S001_1C.csv",
                         "--columns", "time_s=0,current_A=1,voltage_V=2", "--step", "2")
    assert code == 2 and "not a battery tester file" in err


@pytest.mark.parametrize("name", sorted(FILES))
def test_logbook_makes_one_event_per_step_of_its_kind(cyclers, name):
    """Each tester step becomes an event of its kind (a charge's constant-current and
    constant-voltage steps, or two rests in a row, one event), whatever the current's size
    (coin cells at tens of microamps); a discharge keeps its cycle and its charge."""
    from dischargelab.logbook.summarise import summarise_source

    _needs_mdbtools(name)
    steps = read_tester(cyclers / name).steps
    expected: list[list] = []
    for step in steps:
        if expected and expected[-1][0] == step["kind"]:
            expected[-1][1].append(step)
        else:
            expected.append([step["kind"], [step]])
    events = [e for e in summarise_source(cyclers / name, keep_raw=False).events
              if e["kind"] != "gap"]
    assert [e["kind"] for e in events] == [kind for kind, _ in expected]
    for event, (kind, group) in zip(events, expected):
        if kind == "discharge":
            assert event["cycle"] == group[0]["cycle"]
            # the event counts from the sample before it to the one after (a short pulse
            # differs by a few per cent from the step's own rows)
            assert event["discharged_Ah"] == pytest.approx(
                sum(s["charge_Ah"] for s in group), rel=0.05)


@pytest.mark.slow
def test_fit_on_lithium_cells_validates_on_their_other_steps(cyclers):
    """Maccor LG M50 at 0 degC: fitted at 0.5 and 10 A, checked at 2.5 and 5 A; Neware
    cell: fitted on its full discharge (cycle 2), checked on cycle 1 from a partial charge."""
    maccor = cyclers / "maccor/maccor_001.txt"
    runs = [dl.read(maccor, segment=n) for n in (7, 22)]
    fit = dl.fit(runs, bootstrap=0)
    cases = dl.validate(fit.battery, [dl.read(maccor, segment=n) for n in (12, 17)],
                        cutoff=2.6)
    errors = [c.summary["endurance_error_s"] / c.summary["endurance_measured_s"]
              for c in cases]
    assert all(abs(e) < 0.05 for e in errors), errors
    assert not any(c.summary["in_fit"] for c in cases)

    neware = dl.fit(cyclers / "neware/TestFile.nda", bootstrap=0)
    assert any("step 7 used" in n for n in neware.notes)
    cases = dl.validate(neware.battery, cyclers / "neware/TestFile.nda", cutoff=2.6)
    held_out = [c for c in cases if not c.summary["in_fit"]]
    assert [c.summary["file"].endswith("step 2") for c in held_out] == [True]
    error = held_out[0].summary["endurance_error_s"] / held_out[0].summary["endurance_measured_s"]
    # a discharge from a partial charge, one rate fitted: shepherd-dynamic (auto) +5.7 %
    # with the polarisation read from the load step (R 26 mOhm, Rp 23 mOhm), +15.7 % when
    # its polarisation at full charge was the knee's K (8 mOhm); shepherd-thermal +7.7 %
    # (see docs/accuracy.md)
    assert abs(error) < 0.15, error


def test_ec_lab_text_export_with_decimal_commas_reads_like_the_mpr(cyclers, tmp_path):
    """An EC-Lab .mpt: a long settings header, tab separated, decimal commas, I measured."""
    from galvani import BioLogic

    mpr = cyclers / "biologic/jdb11-1_c3_gcpl_5cycles_2V-3p8V_C-24_data_C09.mpr"
    data = BioLogic.MPRfile(str(mpr)).data
    table = pd.DataFrame({"Ns": data["Ns"], "time/s": data["time/s"], "Ewe/V": data["Ewe/V"],
                          "<I>/mA": data["control/V/mA"], "cycle number": data["half cycle"] // 2,
                          "Q charge/discharge/mA.h": data["Q charge/discharge/mA.h"],
                          "Temperature/°C": 24.5})
    header = ["EC-Lab ASCII FILE", "Nb header lines : 120"] + \
        [f"setting {k} : {k},5" for k in range(117)]
    body = table.to_csv(sep="\t", index=False, float_format="%.7g").replace(".", ",")
    path = tmp_path / "gcpl.mpt"
    path.write_text("\n".join(header) + "\n" + body, encoding="latin-1")
    assert detect_tester(path) == "text"
    text, binary = read_tester(path), read_tester(mpr)
    first_text, first_binary = full_discharges(text.steps)[0], full_discharges(binary.steps)[0]
    assert first_text["number"] == first_binary["number"]
    assert first_text["charge_Ah"] == pytest.approx(first_binary["charge_Ah"], rel=1e-5)
    assert "voltage trend" in text.meta["sign_source"]
    assert text.frame["temperature_C"].iloc[0] == pytest.approx(24.5)   # Latin-1's degree


def _clock(seconds) -> list[str]:
    s = np.asarray(seconds, dtype=float)
    return [f"{int(x // 3600):02d}:{int(x % 3600 // 60):02d}:{x % 60:06.3f}" for x in s]


def _neware_layouts(tester, pause_s: float) -> dict[str, pd.DataFrame]:
    """The records of ``tester`` in Neware BTS record exports (a step time that restarts
    every step, mA, discharge negative), the clock ``pause_s`` late from step 4 on."""
    f = tester.frame
    runs = np.concatenate(([0], np.cumsum(np.diff(f["step_index"].to_numpy()) != 0)))
    start = pd.Series(runs).map(f.groupby(runs)["time_s"].first()).to_numpy()
    step_s = f["time_s"].to_numpy() - start
    late = np.where(runs >= 3, pause_s, 0.0)
    real = (pd.Timestamp(tester.meta["start_time"])
            + pd.to_timedelta(f["time_s"] + late, unit="s")).dt.strftime("%Y-%m-%d %H:%M:%S")
    current_mA = -f["current_A"] * 1000
    state = np.where(f["current_A"] > 1e-6, "CC_DChg",
                     np.where(f["current_A"] < -1e-6, "CCCV_Chg", "Rest"))
    return {
        "bts": pd.DataFrame({"Cycle ID": f["cycle_index"], "Step ID": f["step_index"],
                             "Record ID": np.arange(1, len(f) + 1),
                             "Time(h:min:s.ms)": _clock(step_s), "Voltage(V)": f["voltage_V"],
                             "Current(mA)": current_mA, "Realtime": real}),
        "relative": pd.DataFrame({"Record Index": np.arange(1, len(f) + 1), "Status": state,
                                  "Cycle": f["cycle_index"], "Step": f["step_index"],
                                  "Relative Time(h:min:s.ms)": _clock(step_s),
                                  "Absolute Time": real, "Cur(mA)": current_mA,
                                  "Voltage(V)": f["voltage_V"]}),
        "no clock": pd.DataFrame({"Cycle ID": f["cycle_index"], "Step ID": f["step_index"],
                                  "Time(h:min:s.ms)": _clock(step_s),
                                  "Voltage(V)": f["voltage_V"], "Current(mA)": current_mA}),
        "digatron": pd.DataFrame({"Step": f["step_index"],
                                  "Status": np.select([f["current_A"] > 1e-6,
                                                       f["current_A"] < -1e-6],
                                                      ["DCH", "CHA"], "PAU"),
                                  "Prog Time": _clock(f["time_s"] + late),
                                  "Step Time": _clock(step_s), "Cycle": f["cycle_index"],
                                  "Voltage": f["voltage_V"],
                                  "Current": np.abs(f["current_A"])}),
        "hours": pd.DataFrame({"Date and Time": real, "Cycle Number": f["cycle_index"],
                               "Step Type": f["step_index"],
                               "Run Time (h)": (f["time_s"] + late) / 3600,
                               "Current (A)": -f["current_A"],
                               "Potential (V)": f["voltage_V"]}),
    }


@pytest.mark.parametrize("layout", ["bts", "relative", "no clock", "digatron", "hours"])
def test_exports_with_a_step_time_or_a_clock_only_read_the_same_steps(cyclers, tmp_path,
                                                                      layout):
    """Neware BTS exports carry the step's time (``Time(h:min:s.ms)``, restarting every
    step) and a date-time, no test time: the test time is added up over the steps, a pause
    the clock shows kept; a numbered ``Step Type`` is the step; Digatron's program time,
    its unsigned current and its ``DCH``/``CHA``/``PAU`` states."""
    from dischargelab.logbook.summarise import summarise_source

    source = cyclers / "neware/TestFile.nda"
    original = read_tester(source)
    pause_s = 3600.0
    path = tmp_path / f"{layout.replace(' ', '_')}.csv"
    _neware_layouts(original, pause_s)[layout].to_csv(path, index=False)
    assert detect_tester(path) == "text"
    tester = read_tester(path)
    assert [s["kind"] for s in tester.steps] == [s["kind"] for s in original.steps]
    assert [s["charge_Ah"] for s in tester.steps] == pytest.approx(
        [s["charge_Ah"] for s in original.steps], rel=CAPACITY_TOLERANCE, abs=1e-9)
    gap = tester.steps[3]["start_s"] - tester.steps[2]["end_s"]
    if layout == "no clock":
        assert gap < 1.0 and any("not known" in n for n in tester.meta["notes"])
    else:
        assert gap == pytest.approx(pause_s, abs=2.0)
    events = [e["kind"] for e in summarise_source(source, keep_raw=False).events]
    assert [e["kind"] for e in summarise_source(path, keep_raw=False).events] == events


def test_a_chinese_export_in_gb18030_reads_the_same_steps(cyclers, tmp_path):
    """A Chinese tester's export: headers in Chinese with full-width brackets, state words
    (恒流放电 / 恒流恒压充电 / 搁置), a step time and an absolute time, GB 18030 bytes."""
    original = read_tester(cyclers / "neware/TestFile.nda")
    bts = _neware_layouts(original, 0.0)["relative"]
    words = {"CC_DChg": "恒流放电", "CCCV_Chg": "恒流恒压充电", "Rest": "搁置"}
    table = pd.DataFrame({"记录序号": bts["Record Index"], "循环号": bts["Cycle"],
                          "工步号": bts["Step"], "工步类型": bts["Status"].map(words),
                          "时间（h:min:s.ms）": bts["Relative Time(h:min:s.ms)"],
                          "绝对时间": bts["Absolute Time"], "电流（mA）": bts["Cur(mA)"],
                          "电压（V）": bts["Voltage(V)"]})
    path = tmp_path / "chinese_export.csv"
    path.write_bytes(table.to_csv(index=False).encode("gb18030"))
    assert detect_tester(path) == "text"
    tester = read_tester(path)
    assert "the state column" in tester.meta["sign_source"]
    assert [s["kind"] for s in tester.steps] == [s["kind"] for s in original.steps]
    assert [s["charge_Ah"] for s in tester.steps] == pytest.approx(
        [s["charge_Ah"] for s in original.steps], rel=CAPACITY_TOLERANCE, abs=1e-9)
    assert tester.meta["start_time"] == original.meta["start_time"]


def test_an_excel_97_workbook_says_to_save_it_as_xlsx(capsys, tmp_path):
    """Landt's and older Neware exports are .xls (an OLE2 file): one line says what to do,
    from the tester reader, the discharge reader and the logbook."""
    path = tmp_path / "landt.xls"
    path.write_bytes(b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1" + bytes(range(256)) * 8)
    with pytest.raises(DataError, match="save it as .xlsx or CSV"):
        read_tester(path)
    code, out, err = run(capsys, "fit", path)
    assert code == 2 and "Excel 97-2003 workbook" in err and "Traceback" not in err
    code, out, err = run(capsys, "steps", path)
    assert code == 2 and "Excel 97-2003 workbook" in err


def _arbin_layouts(source: pd.DataFrame) -> dict[str, str]:
    """The shared Arbin CSV's records as other testers' text exports write them."""
    clock = pd.to_datetime(source["DateTime"], unit="s")
    hours = source["Test_Time"] // 3600
    rest = source["Test_Time"] - 3600 * hours
    total = [f"{int(h):02d}:{int(s // 60):02d}:{s % 60:06.3f}" for h, s in zip(hours, rest)]
    pec = pd.DataFrame({
        "Test": 25205, "Cell": 1, "Step": source["Step_Index"], "Cycle": source["Cycle_Index"],
        "Total Time (Hours in hh:mm:ss.xxx)": total, "Step Time (Seconds)": source["Step_Time"],
        "Real Time": clock.dt.strftime("%m/%d/%Y %H:%M:%S"), "Voltage (V)": source["Voltage"],
        "Current (A)": source["Current"],
        "Charge Capacity (mAh)": source["Charge_Capacity"] * 1000,
        "Discharge Capacity (mAh)": source["Discharge_Capacity"] * 1000})
    novonix = pd.DataFrame({
        "Date and Time": clock.dt.strftime("%Y-%m-%d %I:%M:%S %p"),
        "Cycle Number": source["Cycle_Index"], "Step Number": source["Step_Index"],
        "Run Time (h)": source["Test_Time"] / 3600, "Current (A)": source["Current"],
        "Potential (V)": source["Voltage"]})
    quoted = "\n".join(['"[Summary]"', '"Cell: 1"'] + [
        f'"{line}"' for line in novonix.to_csv(index=False).splitlines()])
    ec_lab = pd.DataFrame({"Ns": source["Step_Index"], "time/s": source["Test_Time"],
                           "Ewe/V": 0.01 * np.sin(np.arange(len(source))),
                           "Ewe-Ece/V": source["Voltage"], "I/mA": source["Current"] * 1e3,
                           "cycle number": source["Cycle_Index"]})
    mpt = ("EC-Lab ASCII FILE\nNb header lines : 4\nAcquisition started on : "
           f"{clock.iloc[0]:%m/%d/%Y %H:%M:%S}\n\n" + ec_lab.to_csv(sep="\t", index=False))
    state = np.where(source["Current"] > 0.01, "Charge",
                     np.where(source["Current"] < -0.01, "Discharge", "Pause"))
    basytec = pd.DataFrame({"~Time[h]": source["Test_Time"] / 3600, "DataSet": source.index + 1,
                            "Date": clock.dt.strftime("%d.%m.%Y"),
                            "Time": clock.dt.strftime("%H:%M:%S"),
                            "t-Step[h]": source["Step_Time"] / 3600, "Line": source["Step_Index"],
                            "Command": state, "U[V]": source["Voltage"], "I[A]": source["Current"],
                            "Cyc-Count": source["Cycle_Index"], "T1[°C]": source["Temperature"]})
    return {"pec.csv": "Test Name:,cells\nStart Time:,07/02/2017 14:39:13\n\n"
                       + pec.to_csv(index=False),
            "novonix.csv": quoted, "eclab.mpt": mpt,
            "basytec.txt": "~Resultfile from Basytec Battery Test System\n~Name of Test: cells\n~\n"
                           + basytec.to_csv(sep="\t", index=False)}


@pytest.mark.parametrize("name", ["pec.csv", "novonix.csv", "eclab.mpt", "basytec.txt"])
def test_other_testers_text_exports_read_the_same_steps(cyclers, tmp_path, name):
    """PEC (a ``Test`` number column, time as ``Hours in hh:mm:ss.xxx``), Novonix (every
    line wrapped in quotes), EC-Lab with a reference electrode (``Ewe`` against the
    reference beside the cell's ``Ewe-Ece``) and BaSyTec (``~`` before its header, its
    program's ``Line`` a step, a day-first ``Date`` beside a ``Time``) read the steps of the
    same records."""
    source = pd.read_csv(cyclers / "arbin/arbin_example.csv")
    original = read_tester(cyclers / "arbin/arbin_example.csv")
    path = tmp_path / name
    path.write_text(_arbin_layouts(source)[name])
    assert detect_tester(path) == "text"
    tester = read_tester(path)
    assert tester.meta["format"] == {"pec.csv": "pec-text", "novonix.csv": "novonix-text",
                                     "eclab.mpt": "ec-lab-text",
                                     "basytec.txt": "basytec-text"}[name]
    assert [s["kind"] for s in tester.steps] == [s["kind"] for s in original.steps]
    assert [s["charge_Ah"] for s in tester.steps] == pytest.approx(
        [s["charge_Ah"] for s in original.steps], rel=CAPACITY_TOLERANCE, abs=1e-9)
    assert tester.frame["voltage_V"].to_numpy() == pytest.approx(source["Voltage"].to_numpy())
    if name == "pec.csv":
        assert tester.meta["column_map"]["time_s"].startswith("Total Time")
    assert tester.meta["start_time"] == original.meta["start_time"]


def test_empty_step_columns_and_blank_states_read_with_a_note(cyclers, capsys, tmp_path):
    """An Arbin CSV whose Step_Index and Cycle_Index are empty (as some converters write
    them) and a Maccor export with a blank State cell read; nothing crashes."""
    source = pd.read_csv(cyclers / "arbin/arbin_example.csv")
    path = tmp_path / "blank_steps.csv"
    source.assign(Step_Index=np.nan, Cycle_Index=np.nan).to_csv(path, index=False)
    tester = read_tester(path)
    assert any("'Step_Index' is empty" in n for n in tester.meta["notes"])
    code, out, err = run(capsys, "steps", path)
    assert code == 0 and "Traceback" not in err
    lines = (cyclers / "maccor/maccor_001.txt").read_text().splitlines()
    header = lines[3].split("\t")
    state = header.index("State")
    fields = lines[10].split("\t")
    fields[state] = ""
    lines[10] = "\t".join(fields)
    maccor = tmp_path / "maccor_blank_state.txt"
    maccor.write_text("\n".join(lines) + "\n")
    assert read_tester(maccor).step(7)["charge_Ah"] == pytest.approx(4.544, rel=1e-3)


def test_a_time_that_does_not_advance_or_a_clock_without_a_date_is_not_taken(cyclers,
                                                                                tmp_path):
    """A constant column read as the time stops the reader with one line; a date-time
    column holding only the clock gives no start date (it would be the day of reading)."""
    source = pd.read_csv(cyclers / "arbin/arbin_example.csv")
    frozen = tmp_path / "frozen.csv"
    source.assign(Test_Time=12.0).drop(columns=["DateTime"]).to_csv(frozen, index=False)
    with pytest.raises(DataError, match="stays at 12 s over all .* it is not a time"):
        read_tester(frozen)
    clock = pd.to_datetime(source["DateTime"], unit="s")
    clock_only = tmp_path / "clock_only.csv"
    table = source.assign(DateTime=clock.dt.strftime("%H:%M:%S")).to_csv(index=False)
    clock_only.write_text(table)
    assert "start_time" not in read_tester(clock_only).meta
    clock_only.write_text(f"Date of Test:,{clock.iloc[0]:%m/%d/%Y}\n" + table)   # its day
    assert read_tester(clock_only).meta["start_time"] == f"{clock.iloc[0]:%Y-%m-%dT%H:%M:%S}"


def test_pulses_are_not_full_discharges(tmp_path):
    """Ten-second pulses that each end near the others are not runs to the lower limit."""
    rows = []
    for pulse in range(4):
        rows += [(1 + 3 * pulse, -0.5, 3.40 + 0.001 * k) for k in range(12)]   # charge
        rows += [(2 + 3 * pulse, 0.5, 3.43 - 0.002 * k) for k in range(10)]    # pulse
        rows += [(3 + 3 * pulse, 0.0, 3.42)] * 10                             # rest
    rows = [(float(t), 1, *row) for t, row in enumerate(rows)]
    path = tmp_path / "pulses.csv"
    pd.DataFrame(rows, columns=["Test_Time", "Cycle_Index", "Step_Index", "Current",
                                "Voltage"]).to_csv(path, index=False)
    tester = read_tester(path)
    assert sum(s["kind"] == "discharge" for s in tester.steps) == 4
    assert full_discharges(tester.steps) == []


def test_a_folder_takes_ec_lab_text_and_maccor_numbered_files(cyclers, capsys, tmp_path):
    """``logbook add FOLDER`` tries EC-Lab's .mpt and Maccor's .001, .002 files, and says
    which files it did not try."""
    from dischargelab.logbook.ingest import list_files

    folder = tmp_path / "tests"
    folder.mkdir()
    for name in ("run.mpt", "run.001", "run.017", "landt.xls", "photo.png", "README.md",
                 ".hidden"):
        (folder / name).write_text("x")
    files, _, not_tried = list_files([folder], pack="p", pack_from=None, recursive=False)
    assert sorted(f.name for f, _ in files) == ["run.001", "run.017", "run.mpt"]
    assert sorted(Path(p).name for p in not_tried) == ["landt.xls", "photo.png"]
    code, out, err = run(capsys, "logbook", "add", folder, "--pack", "p", "--db",
                         tmp_path / "lb.sqlite")
    assert "not tried: 2 file(s) in the folders whose type is not a data file's (.xls x1, "\
        ".png x1)" in out + err and "Traceback" not in err


def test_ec_lab_mean_current_over_each_interval_is_counted_over_it(tmp_path):
    """EC-Lab's ``<I>`` is the mean over the interval before each record (its ``Q``
    counter sums them): a step's first record, written a moment after the switch, holds a
    part of the step's current. Counted over the intervals, the steps match the counter;
    trapezoids over the records miss 5-6 % here."""
    t = np.r_[0.0, 10.0, 10.0006, 20.0, 30.0, 40.0, 40.0006, 50.0, 60.0, 70.0]
    mean_mA = np.r_[0.0, 0.0, -0.019, -0.030, -0.030, -0.030, 0.021, 0.030, 0.030, 0.030]
    q = np.cumsum(np.r_[0.0, np.diff(t)] * mean_mA) / 3600.0   # mAh
    table = pd.DataFrame({"Ns": [0, 0, 1, 1, 1, 1, 2, 2, 2, 2], "time/s": t,
                          "Ewe/V": np.linspace(3.4, 3.0, t.size), "<I>/mA": mean_mA,
                          "cycle number": 0, "(Q-Qo)/mA.h": q})
    path = tmp_path / "gcpl.mpt"
    path.write_text("EC-Lab ASCII FILE\nNb header lines : 3\n\n"
                    + table.to_csv(sep="\t", index=False))
    tester = read_tester(path)
    assert [s["kind"] for s in tester.steps] == ["rest", "charge", "discharge"]
    assert [s["rows"] for s in tester.steps] == [2, 4, 4]
    for step, (a, b) in zip(tester.steps[1:], ((1, 5), (5, 9))):
        assert step["charge_Ah"] == pytest.approx(abs(q[b] - q[a]) / 1000, rel=1e-4)
    assert any("mean current over the interval" in n for n in tester.meta["notes"])
