"""The same flights in other bytes, recognised by content; dates from file names."""

from __future__ import annotations

from datetime import datetime, timedelta

import pytest

from dischargelab.logbook import duplicates
from dischargelab.logbook.summarise import name_clock, summarise_source

STEM = "19-11-28_waddle1_2019_11_28_18_28"


@pytest.fixture(scope="module")
def both(shared_data):
    folder = shared_data / "dji_m100_flights"
    raw = summarise_source(folder / f"raw_{STEM}.txt", keep_raw=False)
    csv = summarise_source(folder / f"derived_battery_{STEM}.csv", keep_raw=False)
    other = summarise_source(folder / "raw_20-01-12_tablet1_2020_01_12_12_08.txt",
                             keep_raw=False)
    return raw, csv, other


def test_a_raw_log_and_its_export_hold_the_same_flights(both):
    raw, csv, other = both
    assert raw.sha256 != csv.sha256 and raw.format != csv.format
    mine, theirs = duplicates.content(raw.events), duplicates.content(csv.events)
    assert len(mine) == 7
    assert duplicates.same_content(mine, theirs)
    assert not duplicates.same_content(mine, duplicates.content(other.events))
    # one flight less, or the flights of one file against a part of them, are not a copy
    assert not duplicates.same_content(mine[:-1], theirs)
    assert duplicates.richness(sum(e["samples"] for e in mine), raw.size_bytes) \
        > duplicates.richness(sum(e["samples"] for e in theirs), csv.size_bytes)


def shifted(event, **change):
    out = dict(event)
    for key, value in change.items():
        out[key] = value
    return out


def test_what_tells_two_flights_apart(both):
    raw, _, _ = both
    e = duplicates.content(raw.events)[0]
    start = datetime.fromisoformat(e["start_time"])
    later = lambda s: (start + timedelta(seconds=s)).isoformat()  # noqa: E731
    assert duplicates.same_event(e, shifted(e))
    # a whole time-zone offset is one clock written in local time and in UTC
    assert duplicates.same_event(e, shifted(e, start_time=later(13 * 3600)))
    assert duplicates.same_event(e, shifted(e, start_time=later(5.5 * 3600 + 30)))
    # another time of day, another cycle, another charge, another length: another flight
    assert not duplicates.same_event(e, shifted(e, start_time=later(37 * 60)))
    assert not duplicates.same_event(shifted(e, cycle=3), shifted(e, cycle=4))
    assert not duplicates.same_event(e, shifted(e, discharged_Ah=e["discharged_Ah"] * 1.02))
    assert not duplicates.same_event(e, shifted(e, duration_s=e["duration_s"] * 1.05))
    assert not duplicates.same_event(e, shifted(e, samples=e["samples"] + 5))
    assert not duplicates.same_event(e, shifted(e, kind="discharge"))
    # an undated copy of a dated file is still the same flight
    assert duplicates.same_event(e, shifted(e, start_time=None))


def test_a_run_from_storage_is_not_an_older_cells_full_discharge(shared_data, tmp_path):
    """Cycle 510 of cell C run from a storage charge 15 % down moves, undated and
    unnumbered, the charge of cycle 660's full discharge (0.1 %) over as long at the same
    current; its energy is 0.6 % less."""
    from lvm_cut import lvm_storage

    folder = shared_data / "samsung30q_ageing_cellC"
    store = tmp_path / "storage.txt"
    lvm_storage(folder / "DischargeCycle510.txt", store, 0.15, dated=False)
    mine = duplicates.content(summarise_source(store, keep_raw=False).events)
    full = duplicates.content(summarise_source(folder / "DischargeCycle660.txt",
                                               keep_raw=False).events)
    assert mine[0]["discharged_Ah"] == pytest.approx(full[0]["discharged_Ah"], rel=0.002)
    assert not duplicates.same_content(mine, full)


@pytest.mark.parametrize("name, expected", [
    ("raw_20-01-21_tab3_2020_01_21_20_55.txt", datetime(2020, 1, 21, 20, 55)),
    ("flight-20240501-134502.csv", datetime(2024, 5, 1, 13, 45, 2)),
    ("log_2024-05-01.csv", datetime(2024, 5, 1)),
    ("20160805_test001_45_cc_01.res", datetime(2016, 8, 5)),
    ("DischargeCycle042.txt", None),
    ("Q30_S001_C10.csv", None),
    ("pack_20231399.csv", None),                      # not a date
])
def test_the_date_and_time_in_a_file_name(name, expected):
    assert name_clock(name) == expected


def test_flights_of_an_undated_log_are_dated_by_its_name(both):
    raw, csv, _ = both
    starts = [e["start_time"] for e in raw.events]
    assert all(s.startswith("2019-11-28T") for s in starts) and starts == sorted(starts)
    assert [e["start_time"] for e in csv.events] == starts
    assert any("file name" in note for note in raw.notes)
