"""A pack's figures are computed once per change, stored, and read back as computed.

The stored figures must equal what the result objects give when computed from the rows
(health, fleet row, pack, model curves); every kind of write makes only the packs it
changed stale; a new figures version (an upgrade) makes every pack stale; pages read what
is stored and say ``recomputing``; a pack whose figures cannot be made says why.
"""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("sqlalchemy")

from dischargelab.errors import DataError, LogbookError
from dischargelab.logbook import Logbook, figures
from dischargelab.logbook.fleet_report import pack_summary
from dischargelab.logbook.results import DEFAULT_EOL, build_health

CELL_C = "samsung30q_ageing_cellC"
A_CYCLES = (1, 50, 100, 150, 200, 250, 300, 350)
B_CYCLES = (400, 450, 500, 550, 600)


def cell_c(shared_data: Path, cycles) -> list[Path]:
    return [shared_data / CELL_C / f"DischargeCycle{c:03d}.txt" for c in cycles]


@pytest.fixture
def counting(monkeypatch):
    """The packs whose figures are computed, in order."""
    seen: list[str] = []
    compute = figures.pack_figures

    def pack_figures(job):
        seen.append(job["row"]["name"])
        return compute(job)

    monkeypatch.setattr(figures, "pack_figures", pack_figures)
    return seen


def computed_now(lb: Logbook, name: str) -> tuple:
    """Health and fleet row computed from the stored rows, not read from the figures."""
    row, events, model = lb._pack_data(name)
    return (build_health(row, events, model, DEFAULT_EOL).to_dict(),
            pack_summary((row, events, model, DEFAULT_EOL)))


def computed_at(lb: Logbook) -> dict:
    from sqlalchemy import select

    from dischargelab.logbook import schema

    with lb._read() as conn:
        return dict(conn.execute(select(schema.pack_figures.c.pack_id,
                                        schema.pack_figures.c.pack_version)).all())


@pytest.mark.slow
def test_each_write_recomputes_only_the_pack_it_changed_and_reads_compute_nothing(
        tmp_path, shared_data, counting):
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(cell_c(shared_data, A_CYCLES), pack="A")
        lb.add(cell_c(shared_data, B_CYCLES), pack="B")
        assert counting == ["A", "B"] and lb.stale() == []
        for name in ("A", "B"):         # what is read is what the rows give now
            health, fleet = computed_now(lb, name)
            assert lb.health(name).to_dict() == health
            assert lb.figures(name).health == health
            assert next(r for r in lb.fleet().rows if r["name"] == name) == fleet
            row = next(r for r in lb.packs().rows if r["name"] == name)
            assert row == {k: fleet[k] for k in figures.ROW_KEYS} | {"recomputing": False}
            pack = lb.pack(name)
            assert pack.capacity_Ah == pytest.approx(fleet["capacity_Ah"])
            assert pack.health.to_dict() == health
        assert counting == ["A", "B"]     # reading computed nothing
        versions = computed_at(lb)

        lb.set_pack("A", label_capacity_Ah=3.0)                  # settings
        assert counting[2:] == ["A"]
        assert lb.health("A").reference == "label capacity"
        lb.add(cell_c(shared_data, [650]), pack="B")              # events
        assert counting[3:] == ["B"]
        assert lb.add(cell_c(shared_data, [650]), pack="B").added == []
        assert counting[4:] == []                                 # nothing new: nothing done
        after = computed_at(lb)
        assert all(after[k] == versions[k] + 1 for k in versions)

        assert lb.figures("A").model is None
        lb.fit("A", bootstrap=0)                                  # a model
        assert counting[4:] == ["A"]
        model = lb.figures("A").model
        assert [c["c_rate"] for c in model["curves"]] == list(figures.CURVE_C_RATES)
        assert "scaled to its health today" in model["note"]
        assert lb.health("A", eol=0.7).forecast.eol == 0.7         # another eol: computed
        assert counting[5:] == []


def test_a_new_figures_version_makes_every_pack_stale_and_pages_say_so(
        tmp_path, shared_data, counting, monkeypatch):
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(cell_c(shared_data, A_CYCLES[:4]), pack="A")
        lb.add(cell_c(shared_data, B_CYCLES[:3]), pack="B")
        before = lb.packs().rows
        monkeypatch.setattr(figures, "FIGURES_VERSION", figures.FIGURES_VERSION + 1)
        assert lb.stale() == ["A", "B"]
        # a page answers at once from what is stored, and says it is being recomputed
        rows = lb.packs(recompute=False).rows
        assert [r["recomputing"] for r in rows] == [True, True]
        assert [{k: r[k] for k in figures.ROW_KEYS} for r in rows] == \
            [{k: r[k] for k in figures.ROW_KEYS} for r in before]
        page = lb.figures("A", recompute=False)
        assert page.recomputing and page.health["pack"] == "A"
        assert counting == ["A", "B"]
        assert lb.refresh() == ["A", "B"] and lb.stale() == []
        assert counting == ["A", "B", "A", "B"]
        assert not lb.figures("A", recompute=False).recomputing
        # a pack whose figures were never computed: its name and events, being recomputed
        lb.add(cell_c(shared_data, [600, 650]), pack="C", refresh=False)
        row = next(r for r in lb.packs(recompute=False).rows if r["name"] == "C")
        assert row["events"] == 2 and row["recomputing"] and row["efc"] is None
        page = lb.figures("C", recompute=False)
        assert page.recomputing and page.summary is None and page.health is None
        assert counting == ["A", "B", "A", "B"]


def test_a_pack_whose_figures_cannot_be_made_says_why_once(tmp_path, shared_data, monkeypatch):
    compute = figures.pack_figures
    tried = []

    def pack_figures(job):
        tried.append(job["row"]["name"])
        if job["row"]["name"] == "odd":
            raise DataError("the events of this pack contradict each other")
        return compute(job)

    monkeypatch.setattr(figures, "pack_figures", pack_figures)
    with Logbook(tmp_path / "lb.sqlite") as lb:
        lb.add(cell_c(shared_data, A_CYCLES[:3]), pack="odd")
        lb.add(cell_c(shared_data, B_CYCLES[:3]), pack="fine")
        rows = {r["name"]: r for r in lb.packs().rows}
        assert rows["odd"]["error"] == "the events of this pack contradict each other"
        assert rows["odd"]["efc"] is None and "error" not in rows["fine"]
        with pytest.raises(LogbookError, match="its figures cannot be computed: the events"):
            lb.health("odd")
        assert lb.fleet().failed == [("odd", "the events of this pack contradict each other")]
        assert tried == ["odd", "fine"]           # stored with its reason: not tried again
