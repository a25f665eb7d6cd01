"""KPIs of a tiny hand-made run, worked out by hand in the comments; the catalogue; and the same
KPI values from `fleet-sim run` and from a sweep."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
import yaml

from fleet_sim.analysis.kpi_sums import compute_kpis
from fleet_sim.analysis.kpis import (
    CATALOGUE,
    NOTE_FIELDS,
    NOTE_MEANINGS,
    RUN_FIELDS,
    kpi_names,
    kpi_value,
    target_value,
)
from fleet_sim.config.experiment import load_experiment
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.model.records import Order, Recorder
from fleet_sim.study.run_folder import OK
from fleet_sim.study.worker import execute_run

from .conftest import LAYOUTS, ROOT, make_scenario, write_yaml

# The run: 2 AGVs, 1 h, warm-up 0.25 h, so the window is [900 s, 3600 s] = 0.75 h and
# 2 x 2700 = 5400 AGV-seconds.
START_S, END_S = 900.0, 3600.0


def record_orders(rec: Recorder, orders: list[Order]) -> None:
    """Create the orders, then finish the delivered and failed ones in the order they finished,
    as a run does."""
    for order in orders:
        rec.order_created(order)
    done = [o for o in orders if o.delivered_s is not None or o.failed_s is not None]
    for order in sorted(done, key=lambda o: o.delivered_s or o.failed_s or 0.0):
        rec.order_finished(order)


def hand_made_recorder() -> Recorder:
    rec = Recorder(START_S, END_S)
    record_orders(rec, [
        Order(1, 100.0, "PICK", "DROP", agv=0, assigned_s=200.0, delivered_s=1000.0),
        Order(2, 1000.0, "PICK", "DROP", agv=0, assigned_s=1200.0, delivered_s=2000.0),
        Order(3, 1500.0, "PICK", "DROP", agv=1, assigned_s=1600.0, delivered_s=3000.0),
        Order(4, 3000.0, "PICK", "DROP", agv=1, assigned_s=3300.0, failed_s=3400.0,
              failure="E_102"),
        Order(5, 3500.0, "PICK", "DROP"),  # never assigned
        Order(6, 500.0, "PICK", "DROP", agv=1, assigned_s=600.0, delivered_s=800.0,
              reassigned=1),  # all in the warm-up
    ])
    for event in [(0.0, 0, "boot", "Booting", "Idle"), (0.0, 1, "boot", "Booting", "Idle"),
                  (500.0, 1, "not_dispatched", "Idle", "Idle", "status_poll"),
                  (800.0, 0, "not_dispatched", "Idle", "Idle", "link_lost"),
                  (1100.0, 0, "not_dispatched", "Idle", "Idle", "waiting_for_charger"),
                  (1200.0, 0, "go", "Idle", "Moving"),
                  (1200.0, 0, "not_dispatched_end", "Moving", "Moving", "waiting_for_charger"),
                  (1500.0, 0, "order_assigned", "Idle", "Idle"),  # no change of state
                  (1800.0, 1, "fault", "Idle", "Error"),
                  (1800.0, 1, "not_dispatched_end", "Error", "Error", "status_poll"),
                  (2000.0, 0, "arrived", "Moving", "Idle"),
                  (2000.0, 0, "not_dispatched", "Idle", "Idle", "battery_low"),
                  (2400.0, 1, "manual", "Error", "Maintenance"),
                  (2700.0, 0, "not_dispatched_end", "Idle", "Idle", "battery_low"),
                  (3000.0, 1, "auto", "Maintenance", "Idle")]:
        rec.event(*event[:5], node="P", detail=event[5] if len(event) > 5 else "")
    for time_s, waiting in [(0.0, 0), (500.0, 3), (900.0, 2), (1800.0, 1), (2700.0, 0)]:
        rec.queue_length(time_s, waiting)
    rec.blocked_s = 270.0
    rec.distance_m = 12_345.0
    rec.deadlocks = 2
    rec.charge_wait(100.0, 160.0)
    rec.charge_wait(2000.0, 2020.0)
    rec.error(1800.0, 1, "E_999", "Fatal")
    rec.error(2500.0, 0, "E_101", "Error")
    rec.error(2600.0, 0, "E_101", "Error")
    rec.warnings = Counter({"E_002": 3})
    rec.obstacle_pauses, rec.comm_losses, rec.agv_obstacle_pauses = 4, 1, 3
    rec.commands_sent, rec.command_retries = 7, 1
    # state of charge at state changes: AGV 0 falls 10 points inside the window, rises, then
    # falls 10 over 2500-4000 s (1100 of its 1500 s inside); AGV 1 falls 20 in the warm-up,
    # then 10 over 600-1800 s (900 of 1200 s inside)
    for time_s, agv, soc in [(0.0, 0, 100.0), (0.0, 1, 100.0), (600.0, 1, 80.0),
                             (1200.0, 0, 100.0), (1800.0, 1, 70.0), (2000.0, 0, 90.0),
                             (2500.0, 0, 95.0), (4000.0, 0, 85.0)]:
        rec.soc(time_s, agv, soc)
    return rec


def hand_made_figures(**changes: Any) -> dict[str, Any]:
    scenario = make_scenario(name="hand", seed=3, duration_h=1.0, warmup_h=0.25,
                             fleet={"size": 2}, **changes)
    return compute_kpis(hand_made_recorder(), scenario, "tiny_loop")


def test_every_kpi_of_a_hand_made_run() -> None:
    figures = hand_made_figures()
    assert figures == {
        "scenario": "hand", "layout": "tiny_loop", "agvs": 2, "seed": 3, "duration_h": 1.0,
        "warmup_h": 0.25, "setup_warnings": [],
        "orders_created": 6,
        "orders_completed": 4,  # orders 1, 2, 3 and 6 (delivered in the warm-up)
        "throughput_per_hour": 4.0,  # orders 1, 2, 3 in 0.75 h
        "lead_time_mean_s": 1133.333333,  # (900 + 1000 + 1500) / 3
        "lead_time_p95_s": 1450.0,  # 1000 + 0.9 x (1500 - 1000)
        # busy in the window: 100 + 800 + 1400 + 100 (order 4 until it failed) = 2400 of 5400
        "agv_utilisation_pct": 44.444444,
        "blocked_time_pct": 5.0,  # 270 of 5400
        "deadlocks_detected": 2,
        "distance_km": 12.345,
        "order_wait_mean_s": 160.0,  # (100 + 200 + 100 + 300 + 100) / 5; order 5 waits on
        "order_wait_incl_unassigned_mean_s": 150.0,  # (800 + order 5: 3600 - 3500) / 6
        "order_queue_mean": 1.0,  # (2 x 900 + 1 x 900 + 0 x 900) / 2700
        # AGV 0: Idle 300 + 1600, Moving 800; AGV 1: Idle 900 + 600, Error 600, Maint. 600
        "state_booting_pct": 0.0, "state_idle_pct": 62.962963, "state_moving_pct": 14.814815,
        "state_loading_pct": 0.0, "state_unloading_pct": 0.0, "state_charging_pct": 0.0,
        "state_paused_pct": 0.0, "state_error_pct": 11.111111,
        "state_maintenance_pct": 11.111111, "state_safe_mode_pct": 0.0,
        "availability_pct": 77.777778,  # 1 - 1200 / 5400
        # orders wait in [900, 2700]; Idle meanwhile: AGV 0 [900, 1200] + [2000, 2700], AGV 1
        # [900, 1800]: 1900 of 5400
        "idle_with_orders_waiting_pct": 35.185185,
        "idle_with_orders_waiting_pct_by_reason": {
            "waiting_for_charger": 1.851852,  # AGV 0 [1100, 1200]
            "battery_low": 12.962963,  # AGV 0 [2000, 2700]: the queue is empty from 2700
            "link_lost": 3.703704,  # AGV 0 [900, 1100] (opened in the warm-up)
            "status_poll": 16.666667,  # AGV 1 [900, 1800]
            "command_in_transit": 0.0, "type_not_allowed": 0.0,
            "admission_full": 0.0},
        "orders_failed": 1, "orders_reassigned": 1,
        "charges": 2, "charging_queue_wait_mean_s": 40.0,  # (60 + 20) / 2
        "charger_waits_open_at_end": 0,
        "commands_sent": 7, "command_retries": 1, "obstacle_pauses": 4, "comm_losses": 1,
        "agv_obstacle_pauses": 3,
        "errors_by_code": {"E_101": 2, "E_999": 1}, "warnings_by_code": {"E_002": 3},
        "demand_per_hour": 5.333333,  # orders 2, 3, 4, 5 created in 0.75 h
        "throughput_pct_of_demand": 75.0,  # 4 of 5.33 per hour
        "orders_open_at_end": 1,  # order 5 (order 4 failed: not open)
        "open_order_age_mean_s": 100.0, "open_order_age_p95_s": 100.0,  # 3600 - 3500
        "open_order_age_max_s": 100.0, "orders_unassigned_at_end": 1,
        "gridlock_at_h": None, "gridlock_where": None,
        # no StallMeter on a hand-made recorder: the stalls are not measured
        "charging_starvation_h": None, "charging_starvation_at_h": None,
        "charging_starvation_peak_agvs": None, "charging_starvation_worst": None,
        "out_of_service_h": None, "out_of_service_at_h": None,
        # (10 + 10 x 1100/1500 + 10 x 900/1200) % of 960 Wh
        "energy_used_kwh": pytest.approx((10 + 10 * 1100 / 1500 + 7.5) / 100 * 0.96),
    }


def test_spells_open_at_the_end_count_to_the_end() -> None:
    """The hand-made run, but at the end (3600 s) AGV 0 still waits for a lock since 3000 s,
    for zone Z's gate, AGV 1 for a node since 500 s (in the warm-up), and AGV 1 for a charger
    since 3300 s; orders 7 (assigned, not delivered) and 8 (never assigned) are open."""
    rec = hand_made_recorder()
    rec.zone_wait_s = {"Z": 40.0}
    record_orders(rec, [Order(7, 2600.0, "PICK", "DROP", agv=0, assigned_s=3000.0),
                        Order(8, 3240.0, "PICK", "DROP")])
    rec.wait_began(0, 3000.0, "Z")
    rec.wait_began(1, 500.0)
    rec.charger_asked(1, 3300.0)
    rec.wait_began(0, 3100.0)  # a later wait of AGV 0 (the one before it ended) ...
    rec.blocked(3000.0, 3100.0, 0)  # ... its end is counted once, as a closed wait
    rec.wait_began(0, 3100.0, "Z")
    rec.end_of_run()
    rec.blocked(3100.0, 3600.0, 0)  # a wait closed after the end (garbage collection): no
    scenario = make_scenario(name="hand", seed=3, duration_h=1.0, warmup_h=0.25,
                             fleet={"size": 2})
    figures = compute_kpis(rec, scenario, "tiny_loop")
    # 270 before + 100 (3000-3100) + 500 (3100-3600, open) + 2700 (AGV 1: 900-3600, open)
    assert figures["blocked_time_pct"] == round(100 * 3570 / 5400, 6)
    assert figures["zone_wait_s"] == {"Z": 540.0}  # 40 + 500 still open
    assert figures["charging_queue_wait_mean_s"] == 126.666667  # (60 + 20 + 300 open) / 3
    assert figures["charger_waits_open_at_end"] == 1 and figures["charges"] == 2
    assert figures["orders_open_at_end"] == 3  # orders 5, 7 and 8
    assert figures["open_order_age_max_s"] == 1000.0  # order 7: 3600 - 2600
    assert figures["open_order_age_mean_s"] == round((100 + 1000 + 360) / 3, 6)
    assert figures["open_order_age_p95_s"] == 936.0  # 360 + 0.9 x (1000 - 360)
    assert figures["orders_unassigned_at_end"] == 2  # 5 and 8
    # assigned: 800 over 5, and order 7 400; never assigned: 100 and 360 -> 1660 / 8
    assert figures["order_wait_mean_s"] == 200.0
    assert figures["order_wait_incl_unassigned_mean_s"] == 207.5
    # lead time targets: held against the open orders' age of the same statistic
    assert figures["lead_time_p95_s"] == 1450.0
    assert target_value(figures, "lead_time_p95_s") == 1450.0  # above the open ages' 936
    assert target_value(figures, "lead_time_mean_s") == figures["lead_time_mean_s"]
    assert target_value({**figures, "open_order_age_mean_s": 5000.0},
                        "lead_time_mean_s") == 5000.0
    assert target_value(figures, "throughput_per_hour") == 4.0  # other KPIs as they are


def test_throughput_pct_of_demand_uses_the_rounded_throughput() -> None:
    rec = Recorder(0.0, 3600.0)
    # 3 orders created in 1 h, 2 delivered: 2/3 of demand
    record_orders(rec, [Order(i, 10.0 * i, "PICK", "DROP", assigned_s=10.0 * i,
                              delivered_s=20.0 * i if i < 2 else None) for i in range(3)])
    scenario = make_scenario(duration_h=1.0, warmup_h=0.0, fleet={"size": 1})
    figures = compute_kpis(rec, scenario, "tiny_loop")
    assert figures["demand_per_hour"] == 3.0
    assert figures["throughput_pct_of_demand"] == 66.666667
    # 9 orders created in 3 h, 7 delivered: 2.333333 /h of 3 /h, 77.777767 % (not 77.777778)
    rec = Recorder(0.0, 3 * 3600.0)
    record_orders(rec, [Order(i, 1.0, "PICK", "DROP", delivered_s=2.0) for i in range(7)]
                  + [Order(i, 3.0, "PICK", "DROP") for i in (7, 8)])
    scenario = make_scenario(duration_h=3.0, warmup_h=0.0, fleet={"size": 1})
    figures = compute_kpis(rec, scenario, "tiny_loop")
    assert figures["throughput_per_hour"] == 2.333333 and figures["demand_per_hour"] == 3.0
    assert figures["throughput_pct_of_demand"] == 77.777767


def test_no_orders_no_demand_no_ratio() -> None:
    scenario = make_scenario(duration_h=1.0, warmup_h=0.0, fleet={"size": 1})
    figures = compute_kpis(Recorder(0.0, 3600.0), scenario, "tiny_loop")
    assert figures["demand_per_hour"] == 0.0 and figures["throughput_pct_of_demand"] is None
    assert figures["lead_time_mean_s"] is None and figures["order_wait_mean_s"] is None
    assert figures["charging_queue_wait_mean_s"] is None
    assert figures["state_booting_pct"] == 0.0 and figures["availability_pct"] == 100.0


def test_catalogue_names_every_kpi_a_run_reports_once() -> None:
    figures = hand_made_figures()
    reported = {k for k in figures if k not in RUN_FIELDS + NOTE_FIELDS
                and not isinstance(figures[k], dict)}
    names = [k.name for k in CATALOGUE]
    assert len(names) == len(set(names))
    assert reported <= kpi_names()
    assert kpi_names() - reported == {
        "wall_s", "errors_by_code.E_101", "errors_by_code.E_102", "errors_by_code.E_201",
        "errors_by_code.E_202", "errors_by_code.E_301", "errors_by_code.E_999",
        "warnings_by_code.E_001", "warnings_by_code.E_002",
        *(f"idle_with_orders_waiting_pct_by_reason.{r}" for r in NotDispatched)}
    assert not set(RUN_FIELDS + NOTE_FIELDS) & kpi_names()
    assert set(NOTE_MEANINGS) == set(NOTE_FIELDS)  # an export says what each note is
    assert all(k.unit and k.meaning for k in CATALOGUE)


def test_kpi_value_reads_per_code_counts() -> None:
    figures = hand_made_figures()
    assert kpi_value(figures, "errors_by_code.E_101") == 2
    assert kpi_value(figures, "errors_by_code.E_202") == 0  # never raised: zero times
    assert kpi_value(figures, "warnings_by_code.E_002") == 3
    assert kpi_value(figures, "throughput_pct_of_demand") == 75.0
    assert kpi_value(figures, "lead_time_p95_s") == 1450.0
    assert kpi_value(figures, "idle_with_orders_waiting_pct_by_reason.link_lost") == 3.703704
    assert kpi_value({}, "lead_time_p95_s") is None


def test_run_and_sweep_report_the_same_kpis(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path / "s.yaml", {
        "name": "same", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 1.5,
        "warmup_h": 0.25, "fleet": {"size": 2}, "demand": {"rate_per_hour": 45}})
    experiment = load_experiment(write_yaml(tmp_path / "e.yaml", {
        "name": "same", "scenario": str(scenario), "factors": {"fleet.size": [2]},
        "replications": 1, "master_seed": 5}))
    (spec,) = experiment.runs()
    assert execute_run(spec, str(tmp_path / "runs")).status == OK
    swept = json.loads((tmp_path / "runs" / spec.run_id / "kpis.json").read_text())
    assert swept.pop("wall_s") >= 0
    result = subprocess.run(
        [sys.executable, "-m", "fleet_sim.cli", "run", str(scenario), "--seed", str(spec.seed),
         "--out", str(tmp_path / "run"), "--quiet"],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    ran = json.loads((tmp_path / "run" / "kpis.json").read_text())
    assert ran["orders_completed"] > 50 and ran["throughput_pct_of_demand"] is not None
    assert ran == swept
    assert f"throughput / demand         {ran['throughput_pct_of_demand']:,.1f} %" \
        in result.stdout



# ---- Idle while orders waited: streamed against the whole run -------------------------------

Spells = list[tuple[float, float]]


def _overlap(a: Spells, b: Spells) -> Spells:
    out: Spells = []
    i = j = 0
    while i < len(a) and j < len(b):
        lo, hi = max(a[i][0], b[j][0]), min(a[i][1], b[j][1])
        if hi > lo:
            out.append((lo, hi))
        if a[i][1] < b[j][1]:
            i += 1
        else:
            j += 1
    return out


def whole_run_idle_waiting(rec: Recorder, start: float,
                           end: float) -> tuple[float, dict[NotDispatched, float]]:
    """The reference: the computation over the whole run's lists that the KPI had before it
    was streamed (every Idle spell, waiting spell and reason spell at once)."""
    waiting: Spells = []
    lengths = list(rec.queue_lengths)
    for (t0, value), (t1, _) in zip(lengths, [*lengths[1:], (end, 0)], strict=False):
        a, b = max(t0, start), min(t1, end)
        if value > 0 and b > a:
            if waiting and waiting[-1][1] == a:
                waiting[-1] = (waiting[-1][0], b)
            else:
                waiting.append((a, b))
    since: dict[int, float] = {}
    idle: dict[int, Spells] = {}
    open_: dict[int, tuple[NotDispatched, float]] = {}
    reasons: dict[int, dict[NotDispatched, Spells]] = {}
    for e in rec.events:
        if e.event in ("not_dispatched", "not_dispatched_end") and e.agv in open_:
            reason, t = open_.pop(e.agv)
            reasons.setdefault(e.agv, {}).setdefault(reason, []).append((t, e.time_s))
        if e.event == "not_dispatched":
            open_[e.agv] = (NotDispatched(e.detail), e.time_s)
        if e.from_state != e.to_state:
            if e.agv in since:
                idle.setdefault(e.agv, []).append((since.pop(e.agv), e.time_s))
            if e.to_state == "Idle":
                since[e.agv] = e.time_s
    for agv, t in since.items():
        idle.setdefault(agv, []).append((t, end))
    for agv, (reason, t) in open_.items():
        reasons.setdefault(agv, {}).setdefault(reason, []).append((t, end))
    total = 0.0
    by_reason = dict.fromkeys(NotDispatched, 0.0)
    for agv, spells in idle.items():
        idle_waiting = _overlap(spells, waiting)
        total += sum(b - a for a, b in idle_waiting)
        for reason, held in reasons.get(agv, {}).items():
            by_reason[reason] += sum(b - a for a, b in _overlap(held, idle_waiting))
    return total, by_reason


def test_idle_while_waiting_streamed_in_small_batches_is_the_whole_run_figure(
        tmp_path: Path) -> None:
    """Two runs (charging and incidents; a mixed fleet held back by admission), their events
    and queue lengths handed over in batches of 7 and 5,000 rows: the very seconds of the
    whole-run computation, to the last bit, and the matched spells let go."""
    from fleet_sim.analysis.kpi_sums import KpiSums
    from fleet_sim.config.layout import load_layout
    from fleet_sim.sim.engine import build_simulation

    from .test_tables import eventful, feature_rich

    data = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text())
    data["nodes"].append({"id": "C", "x": 4, "y": 12, "kind": "charger"})
    data["segments"].append({"from": "N1", "to": "C", "direction": "two_way"})
    data["chargers"] = [{"id": "CHG", "node": "C", "power_kw": 1.0, "docking_s": 10}]
    charger_loop = write_yaml(tmp_path / "tiny_charger.yaml", data)
    runs = [(eventful(charger_loop, seed=9), load_layout(charger_loop)),
            feature_rich(tmp_path)]
    seen: set[NotDispatched] = set()
    for scenario, layout in runs:
        whole = build_simulation(scenario, layout)
        whole.env.run(until=scenario.duration_s)
        expected = whole_run_idle_waiting(whole.recorder, scenario.warmup_s,
                                          scenario.duration_s)
        assert expected[0] > 0
        seen |= {r for r, s in expected[1].items() if s > 0}
        for batch_rows in (7, 5000):
            sums = KpiSums(scenario.warmup_s, scenario.duration_s)
            model = build_simulation(scenario, layout, sink=sums, batch_rows=batch_rows)
            model.env.run(until=scenario.duration_s)
            model.recorder.finish()
            assert sums.idle_waiting.seconds() == expected
            assert len(sums.idle_waiting.waiting) < 200  # matched spells are let go
    assert {NotDispatched.WAITING_FOR_CHARGER, NotDispatched.ADMISSION_FULL} <= seen
