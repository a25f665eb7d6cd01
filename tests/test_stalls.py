"""Stalls named for what they are (issue 33, item 7): a standstill behind AGVs waiting for a
charger is charging starvation, not a traffic gridlock; a fleet all in Error or Maintenance is
out of service; a wait-for cycle, or a standstill behind an AGV that nothing holds, stays a
gridlock. Each stall has its own KPIs, words and advice in the run summary, a sweep's or a
sizing search's lines and the report. Built on tests/data/charger_queue_loop.yaml (a loop with
one charger whose queue stands on the loop) and the bundled warehouse shift under fcfs (the
issue's finding: the whole fleet reaches the charging threshold together)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import pandas as pd
import yaml

from fleet_sim.analysis.kpi_sums import run_kpis
from fleet_sim.analysis.kpis import out_of_service, starved
from fleet_sim.analysis.run_summary import summary_text
from fleet_sim.config.layout import load_layout
from fleet_sim.model.records import Recorder
from fleet_sim.model.stalls import Held, Stall, StallMeter
from fleet_sim.report.console import kpi_table, stall_lines
from fleet_sim.report.content import Report
from fleet_sim.report.render import render_html
from fleet_sim.report.results_folder import ReportData
from fleet_sim.report.sections.charging import section_charging
from fleet_sim.report.stalls import stall_statements
from fleet_sim.sim.engine import simulate
from fleet_sim.sim.gridlock import chain_heads, held_up_off_traffic
from fleet_sim.sim.traffic.locks import Lock

from .conftest import LAYOUTS, ROOT, make_scenario

DATA = Path(__file__).parent / "data"
LOOP = DATA / "charger_queue_loop.yaml"
LOOP_FIELDS: dict[str, Any] = {
    "duration_h": 1.0, "warmup_h": 0.0, "seed": 1,
    "fleet": {"size": 3, "start_nodes": ["P", "B", "E"],
              "vehicle": {"battery": {"initial_soc_pct": 30.5}}},
    "demand": {"rate_per_hour": 120}, "dispatch": {"park_idle": False, "policy": "fcfs"},
    "traffic": {"gridlock_after_s": 120}}
LIMIT_AGVS = "Limit the AGVs on the floor"


def test_agvs_waiting_behind_the_charger_queue_are_starved_of_charging_not_gridlocked() -> None:
    """Three AGVs reach the threshold with their first order: one charges (about 1,000 s),
    the next stands at D waiting for the charger, the third waits behind it with its load.
    Nothing moves for far longer than gridlock_after_s (120 s) while orders wait: before issue
    33 this was 'gridlock at 0.09 h: agvs 2 at nodes E (nothing moving)'."""
    run = simulate(make_scenario(str(LOOP), **LOOP_FIELDS), load_layout(LOOP))
    figures = run_kpis(run)
    assert figures["gridlock_at_h"] is None and figures["gridlock_where"] is None
    assert not [e for e in run.recorder.events if e.event == "gridlock"]
    # orders waited while AGV 0 stood at D for the charger AGV 1 held, from its unloading
    # (about 300 s) until AGV 1's charge was complete (about 1,280 s)
    wait = [e for e in run.recorder.events if e.event == "not_dispatched"
            and e.detail == "waiting_for_charger"]
    assert wait and wait[0].node == "D"
    assert figures["charging_starvation_at_h"] == round(wait[0].time_s / 3600, 6)
    assert 0.2 < figures["charging_starvation_h"] < 0.35
    assert figures["charging_starvation_peak_agvs"] == 3
    assert figures["charging_starvation_worst"] == (
        "3 of 3 AGVs: 1 charging, 1 waiting for a charger or on the way to one, 1 at or below "
        "the 30 % threshold")
    assert starved(figures) and not out_of_service(figures)
    text = summary_text(figures)
    assert (f"CHARGING STARVATION for {figures['charging_starvation_h']:.2f} h from "
            f"{figures['charging_starvation_at_h']:.2f} h: orders waited, no AGV free to take "
            "them, while AGVs waited for a charger (at worst 3 of 3 AGVs: ") in text
    assert "more chargers, opportunity charging (charging.opportunity) or staggered " \
        "charge thresholds" in text
    assert "gridlock" not in text and LIMIT_AGVS not in text


def test_the_warehouse_shift_under_fcfs_is_starved_of_charging_not_gridlocked() -> None:
    """The issue's finding, one run of it: under fcfs every AGV drains at the same pace, all
    reach the 30 % threshold near 4.4 h, the four chargers take them one after another, and
    for half an hour orders wait while AGVs wait for a charger."""
    shift = yaml.safe_load((ROOT / "experiments" / "warehouse_shift.yaml").read_text())
    del shift["description"], shift["layout"]
    scenario = make_scenario("warehouse.yaml", **{
        **shift, "fleet": {"size": 10}, "dispatch": {"policy": "fcfs"}})
    figures = run_kpis(simulate(scenario, load_layout(LAYOUTS / "warehouse.yaml")))
    assert figures["gridlock_at_h"] is None
    assert figures["charging_starvation_h"] > 0.3
    assert 4.0 < figures["charging_starvation_at_h"] < 5.0
    assert figures["charging_starvation_peak_agvs"] >= 7  # of 10: the fleet charges together
    assert figures["out_of_service_h"] == 0.0 and figures["out_of_service_at_h"] is None
    assert "CHARGING STARVATION" in summary_text(figures)


def test_a_fleet_all_in_error_or_maintenance_is_out_of_service() -> None:
    """Both AGVs of the tiny loop fail at 600 s (E_101, scripted); an operator comes after 300
    s and each repair takes 600 s: from the first order after 600 s until 1,500 s orders wait
    with the whole fleet out of service."""
    scenario = make_scenario(
        duration_h=1.0, warmup_h=0.0, seed=2, fleet={"size": 2},
        demand={"rate_per_hour": 60}, dispatch={"park_idle": False},
        incidents={"faults": [{"agv": 0, "at_s": 600.0, "code": "E_101"},
                              {"agv": 1, "at_s": 600.0, "code": "E_101"}],
                   "operator_response": {"dist": "fixed", "mean_s": 300.0},
                   "repair": {"dist": "fixed", "mean_s": 600.0}})
    run = simulate(scenario, load_layout(LAYOUTS / "tiny_loop.yaml"))
    figures = run_kpis(run)
    back = min(e.time_s for e in run.recorder.events
               if e.from_state == "Maintenance" and e.to_state != "Maintenance")
    assert 1500.0 <= back < 1600.0  # 600 + 300 + 600, and the position estimation
    down_s = figures["out_of_service_at_h"] * 3600  # the first order after both failed
    assert 600.0 <= down_s < 700.0
    assert abs(figures["out_of_service_h"] - (back - down_s) / 3600) < 1e-5
    assert out_of_service(figures) and not starved(figures)
    assert figures["gridlock_at_h"] is None
    text = summary_text(figures)
    assert (f"OUT OF SERVICE for {figures['out_of_service_h']:.2f} h from 0.17 h: orders "
            "waited while every AGV was in Error, Maintenance or SafeMode.") in text
    assert "incidents.repair" in text and LIMIT_AGVS not in text
    assert "CHARGING STARVATION" not in text


class FakeLock:
    """A lock with a holder, as traffic's locks name their blockers."""

    def __init__(self, holder: int | None) -> None:
        self.holder = holder

    def blockers(self, client_id: int) -> tuple[int, ...]:
        return () if self.holder is None or self.holder == client_id else (self.holder,)


def locks(**held_by: int | None) -> dict[int, Lock]:
    """{waiting AGV: the lock it waits for, held by ...}: ``locks(a3=2)``."""
    return {int(k[1:]): cast(Lock, FakeLock(v)) for k, v in held_by.items()}


def test_a_standstill_is_a_gridlock_unless_every_chain_of_waits_ends_at_a_held_agv() -> None:
    waiting = locks(a3=2, a2=1, a5=4)  # 3 waits for 2, 2 for 1; 5 for 4
    assert chain_heads([3, 5], waiting) == {1, 4}
    assert chain_heads([3], {**waiting, **locks(a1=3)}) is None  # a cycle: traffic
    assert chain_heads([3], locks(a3=None)) is None  # a lock naming nobody: not explained
    recorder = Recorder(0.0, 3600.0)
    assert not held_up_off_traffic([3, 5], waiting, recorder)  # no meter: as before
    recorder.stalls = meter = StallMeter(6, 30.0)
    meter.charger_asked(10.0, 1)  # AGV 1 waits for a charger ...
    assert not held_up_off_traffic([3, 5], waiting, recorder)  # ... AGV 4 is held by nothing
    recorder.error(20.0, 4, "E_101", "Error")  # AGV 4 timed out paused: a jam's symptom
    meter.state_changed(20.0, 4, "Paused", "Error")
    assert meter.held(1) is Held.CHARGER and meter.held(4) is Held.DOWN
    assert not held_up_off_traffic([3, 5], waiting, recorder)
    meter.state_changed(300.0, 4, "Error", "Idle")  # repaired; a fault of its own this time
    recorder.error(400.0, 4, "E_999", "Fatal")
    meter.state_changed(400.0, 4, "Moving", "Error")
    assert held_up_off_traffic([3, 5], waiting, recorder)
    meter.state_changed(500.0, 4, "Error", "Maintenance")  # the fault stays until it is back
    assert held_up_off_traffic([3, 5], waiting, recorder)
    assert not held_up_off_traffic([3], {**waiting, **locks(a1=3)}, recorder)


def test_the_meter_joins_touching_spells_drops_empty_ones_and_keeps_the_worst() -> None:
    meter = StallMeter(3, 30.0)
    meter.orders_waiting(0.0, 2)
    meter.charger_asked(100.0, 0)
    meter.note(100.0, 0, "not_dispatched", "waiting_for_charger")  # starvation from 100 s
    meter.state_changed(150.0, 1, "Idle", "Charging")
    meter.soc(160.0, 2, 29.0)  # at its worst: all three held
    meter.orders_waiting(200.0, 0)
    meter.orders_waiting(200.0, 1)  # an empty queue for no time: one spell
    meter.note(300.0, 0, "not_dispatched_end", "waiting_for_charger")
    meter.note(300.0, 0, "not_dispatched", "waiting_for_charger")  # ended and began again
    meter.orders_waiting(400.0, 0)
    meter.orders_waiting(500.0, 1)
    meter.orders_waiting(500.0, 0)  # no length: no spell
    (spell,) = meter.spells[Stall.CHARGING_STARVATION]
    assert (spell.start_s, spell.end_s) == (100.0, 400.0)
    assert spell.held == ((Held.CHARGING, 1), (Held.CHARGER, 1), (Held.LOW, 1))
    assert meter.words(spell.held) == ("3 of 3 AGVs: 1 charging, 1 waiting for a charger or "
                                       "on the way to one, 1 at or below the 30 % threshold")
    # every AGV out of service: that, not starvation, even with one waiting for a charger
    meter.orders_waiting(600.0, 3)
    for agv in range(3):
        meter.state_changed(700.0, agv, "Idle", "Error")
    assert meter.stalled() is Stall.OUT_OF_SERVICE and meter.held(0) is Held.DOWN
    meter.state_changed(900.0, 2, "Maintenance", "Idle")
    assert meter.spells[Stall.OUT_OF_SERVICE][0].end_s == 900.0
    assert [(s.start_s, s.end_s) for s in meter.spells_to(Stall.CHARGING_STARVATION, 1000.0)
            ] == [(100.0, 400.0), (600.0, 700.0), (900.0, 1000.0)]  # the last still open
    meter.end(1000.0)
    assert meter.spells[Stall.CHARGING_STARVATION][-1].end_s == 1000.0


def stall_summary() -> pd.DataFrame:
    """A sweep summary: at 10 AGVs both runs starved, at 12 one of two; one run at 12 out of
    service; one run at 10 locked solid."""
    worst = "9 of 10 AGVs: 4 charging, 3 waiting for a charger or on the way to one, 2 at or " \
        "below the 30 % threshold"
    return pd.DataFrame({
        "run_id": ["a10", "b10", "a12", "b12"], "status": ["ok"] * 4,
        "fleet.size": [10, 10, 12, 12], "agvs": [10, 10, 12, 12],
        "throughput_per_hour": [90.0, 91.0, 92.0, 93.0],
        "lead_time_p95_s": [2100.0, 2000.0, 900.0, 950.0],
        "gridlock_at_h": [None, 5.5, None, None],
        "gridlock_where": [None, "agvs 3 5 at nodes M007 M008 (wait-for cycle)", None, None],
        "charging_starvation_h": [0.5, 0.6, 0.0, 0.2],
        "charging_starvation_at_h": [4.4, 4.5, None, 4.8],
        "charging_starvation_peak_agvs": [9, 8, None, 6],
        "charging_starvation_worst": [worst, "8 of 10 AGVs: ...", None, "6 of 12 AGVs: ..."],
        "out_of_service_h": [0.0, 0.0, 0.25, 0.0],
        "out_of_service_at_h": [None, None, 2.0, None],
        "orders_open_at_end": [0, 0, 0, 0]})


def test_sweeps_sizing_searches_and_reports_name_each_stall_with_its_own_advice(
        tmp_path: Path) -> None:
    summary = stall_summary()
    gridlock, starvation, down = stall_statements(summary)
    assert gridlock.startswith("WARNING: 1 of 4 finished runs locked solid") and \
        LIMIT_AGVS in gridlock
    assert starvation.startswith(
        "CHARGING STARVATION in 3 of 4 finished runs: orders waited, no AGV free to take them, "
        "while AGVs waited for a charger, 0.43 h per run on average (at most 0.60 h), first "
        "from 4.40 h; at worst 9 of 10 AGVs: 4 charging, 3 waiting for a charger or on the "
        "way to one, 2 at or below the 30 % threshold (run a10)")
    assert "more chargers, opportunity charging" in starvation and LIMIT_AGVS not in starvation
    assert down.startswith("OUT OF SERVICE in 1 of 4 finished runs: orders waited while every "
                           "AGV was in Error, Maintenance or SafeMode (the earliest a12 from "
                           "2.00 h, for 0.25 h)")
    assert "incidents.repair" in down and LIMIT_AGVS not in down
    assert stall_lines(summary) == [f"  {s}" for s in (gridlock, starvation, down)]
    assert stall_statements(summary.assign(gridlock_at_h=None, charging_starvation_h=0.0,
                                           out_of_service_h=0.0)) == []
    # the table that ends a sweep: a note per design point
    table = "\n".join(kpi_table(summary, ["fleet.size"], []))
    assert "GRIDLOCK in 1 of 2 runs; charging starvation in 2 of 2 runs (0.55 h each, mean)" \
        in table
    assert "charging starvation in 1 of 2 runs (0.20 h each, mean); out of service in 1 of " \
        "2 runs" in table
    # the report: under Charging, a row per design point with a starved run
    data = ReportData(tmp_path, {}, summary, ["fleet.size"], [], None, None, None)
    sec = section_charging(data, {}, {})
    assert sec.starvation is not None
    assert sec.starvation.rows == [["10", "2 of 2", "0.55", "4.40", "9 of 10"],
                                   ["12", "1 of 2", "0.10", "4.80", "6 of 12"]]
    page = " ".join(render_html(Report("t", "l", [starvation], [], [sec])).split())
    assert "Charging starvation:</strong> orders waited" in page
    assert "It is not a traffic gridlock." in page and LIMIT_AGVS not in page
