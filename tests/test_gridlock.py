"""A run that locks solid (issue 20): the gridlock is named (event, gridlock_at_h, summary
warning), the KPIs count the waits still open at the end as the replay's lock waits do, and the
run still exits 0 with its tables. Built on tests/data/gridlock_ring.yaml, a one-way ring of
four tags with four AGVs and no way round, which locks for certain within seconds."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd

from fleet_sim.analysis.kpi_sums import run_kpis
from fleet_sim.analysis.kpis import gridlocked, target_value
from fleet_sim.analysis.run_summary import summary_text
from fleet_sim.config.layout import load_layout
from fleet_sim.model.records import MoveRecord
from fleet_sim.report.sections.runs import open_orders_line
from fleet_sim.report.stalls import gridlock_statement
from fleet_sim.sim.engine import build_simulation, simulate

from .conftest import ROOT, make_scenario, write_yaml

DATA = Path(__file__).parent / "data"
RING = DATA / "gridlock_ring.yaml"
RING_FIELDS = {"duration_h": 1.0, "warmup_h": 0.1, "seed": 3,
               "fleet": {"size": 4, "start_nodes": ["N0", "N1", "N2", "N3"]},
               "demand": {"rate_per_hour": 120}, "dispatch": {"park_idle": False},
               "charging": {"enabled": False}, "traffic": {"gridlock_after_s": 120},
               "rules": {"agv_ahead": "held_back"}}
"""The locked ring, its AGVs held out of each other's LDS range (under the default reading
each would raise E_101 after 5 minutes paused: tests/test_stalls.py)."""


def wait_share_pct(moves: list[MoveRecord], agvs: int, start_s: float, end_s: float) -> float:
    """The share of AGV time after the warm-up covered by the replay's lock waits."""
    covered = sum(max(0.0, min(m.end_s, end_s) - max(m.start_s, start_s))
                  for m in moves if m.kind == "wait")
    return 100.0 * covered / (agvs * (end_s - start_s))


def test_a_locked_run_counts_its_open_waits_names_the_gridlock_and_shows_open_orders() -> None:
    scenario = make_scenario(str(RING), **RING_FIELDS)
    run = simulate(scenario, load_layout(RING), record_moves=True)
    figures = run_kpis(run)
    share = wait_share_pct(run.recorder.moves, 4, scenario.warmup_s, scenario.duration_s)
    assert share > 90.0  # the AGVs stand waiting nearly all the time ...
    assert abs(figures["blocked_time_pct"] - share) <= 0.1  # ... and the KPI says so
    states = sum(v for k, v in figures.items() if k.startswith("state_"))
    assert abs(states - 100.0) < 1e-4
    # nothing is ever delivered: every order is open, its age counted to the end
    assert figures["orders_completed"] == 0 and figures["lead_time_p95_s"] is None
    assert figures["orders_open_at_end"] == figures["orders_created"] > 100
    ages = sorted(scenario.duration_s - o.created_s for o in run.recorder.orders)
    assert figures["open_order_age_max_s"] == round(ages[-1], 6)
    assert abs(figures["open_order_age_mean_s"] - sum(ages) / len(ages)) < 1e-5
    assert figures["orders_unassigned_at_end"] == figures["orders_created"] - 4
    # the gridlock: early, named, with its event
    gridlock = run.recorder.gridlock
    assert gridlock is not None and figures["gridlock_at_h"] == round(gridlock.since_s / 3600, 6)
    assert figures["gridlock_at_h"] < 0.05 and gridlocked(figures)
    (event,) = [e for e in run.recorder.events if e.event == "gridlock"]
    assert gridlock.since_s + 120 <= event.time_s <= gridlock.since_s + 120 + 12 + 1e-9
    assert all(node in event.detail for node in gridlock.nodes)
    text = summary_text(figures)
    assert f"WARNING: gridlock at {figures['gridlock_at_h']:.2f} h: agvs" in text
    assert "dispatch.max_active_agvs" in text
    assert f"open at the end             {figures['orders_open_at_end']} orders" in text
    # a lead-time target cannot be met on no deliveries: it is judged by the open orders' age
    assert target_value(figures, "lead_time_p95_s") == figures["open_order_age_p95_s"] > 1000


def test_an_unresolvable_cycle_is_named_with_its_members_and_nodes() -> None:
    """Each AGV sent two nodes ahead: all four wait for the next one's node, no escape."""
    scenario = make_scenario(str(RING), **{**RING_FIELDS, "demand": {"rate_per_hour": 0}})
    model = build_simulation(scenario, load_layout(RING))
    goals = {0: "N2", 1: "N3", 2: "N0", 3: "N1"}
    for vehicle in model.vehicles:
        vehicle.process = model.env.process(vehicle.drive(goals[vehicle.id]))
    model.env.run(until=600)
    gridlock = model.recorder.gridlock
    assert gridlock is not None and gridlock.kind == "cycle"
    assert sorted(gridlock.agvs) == [0, 1, 2, 3]
    at = {v.id: v.node for v in model.vehicles}
    assert list(gridlock.nodes) == [at[agv] for agv in gridlock.agvs]
    assert sorted(gridlock.nodes) == ["N0", "N1", "N2", "N3"]
    # locked when the last member began waiting: all start at once, at the first step
    assert gridlock.since_s == max(since for since, _ in model.recorder.open_waits.values())
    assert gridlock.since_s < 10.0
    assert "(wait-for cycle)" in gridlock.where()


def test_a_run_that_keeps_moving_records_no_gridlock() -> None:
    scenario = make_scenario(duration_h=1.0, warmup_h=0.1, fleet={"size": 2},
                             demand={"rate_per_hour": 45})
    figures = run_kpis(simulate(scenario, load_layout(ROOT / "layouts" / "tiny_loop.yaml")))
    assert figures["gridlock_at_h"] is None and figures["gridlock_where"] is None
    assert not gridlocked(figures) and "WARNING" not in summary_text(figures)


def test_fleet_sim_run_of_a_locked_layout_exits_0_with_its_tables(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path / "ring.yaml", {"name": "ring", "layout": str(RING),
                                                   **RING_FIELDS})
    out = tmp_path / "run"
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "run", str(scenario),
                             "--out", str(out), "--quiet"],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    figures = json.loads((out / "kpis.json").read_text(encoding="utf-8"))
    assert "WARNING: gridlock at" in result.stdout and figures["gridlock_at_h"] is not None
    events = pd.read_parquet(out / "events.parquet")
    assert (events["event"] == "gridlock").sum() == 1
    assert len(pd.read_parquet(out / "orders.parquet")) == figures["orders_created"]
    # a sweep summary row of it: the report flags it and shows the open orders
    summary = pd.DataFrame([{"run_id": "ring__r00", "status": "ok", **{
        k: v for k, v in figures.items() if not isinstance(v, (dict, list))}},
        {"run_id": "fine__r00", "status": "ok", "gridlock_at_h": None,
         "orders_open_at_end": 0, "open_order_age_max_s": None}])
    statement = gridlock_statement(summary)
    assert statement is not None and statement.startswith("WARNING: 1 of 2 finished runs")
    assert "ring__r00" in statement
    assert f"at most {figures['orders_open_at_end']}" in open_orders_line(summary)
    assert gridlock_statement(summary.iloc[1:]) is None and open_orders_line(summary[1:]) == ""


def test_a_lead_time_target_is_not_met_by_a_fleet_that_leaves_a_backlog() -> None:
    """Four replications deliver fast (p95 500 s) but leave orders open 5,000 s at p95: the
    p95 target of 900 s fails; with young open orders (300 s) it is met."""
    from fleet_sim.analysis.stats import check_targets
    from fleet_sim.config.experiment import Target

    target = Target(kpi="lead_time_p95_s", at_most=900.0)
    rows = [{"run_id": f"r{i}", "status": "ok", "fleet.size": 4,
             "lead_time_p95_s": 500.0 + i, "open_order_age_p95_s": 5000.0 + i}
            for i in range(4)]
    (backlog,) = check_targets(pd.DataFrame(rows), ["fleet.size"], [target])
    assert backlog.decision == "fails" and backlog.interval.mean > 5000
    young = pd.DataFrame([{**r, "open_order_age_p95_s": 300.0} for r in rows])
    (fine,) = check_targets(young, ["fleet.size"], [target])
    assert fine.decision == "meets" and abs(fine.interval.mean - 501.5) < 1e-9
