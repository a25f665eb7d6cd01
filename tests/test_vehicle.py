"""The AGV's day (fleet_sim.sim.agents.vehicle): an order's states and Loading/Unloading
sub-states, lead and cycle times against hand computation, the trip to a charger."""

from __future__ import annotations

import copy
import itertools
import math
from pathlib import Path

import pytest
import yaml

from fleet_sim.analysis.kpi_sums import run_kpis
from fleet_sim.analysis.tables import events_table, orders_table
from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.scenario import setup_warnings
from fleet_sim.config.trace import TraceOrder
from fleet_sim.sim.engine import simulate

from .conftest import (
    DROP_S,
    HALF_LOOP_S,
    K_TO_P_S,
    LAYOUTS,
    PICK_S,
    TURN_MPS,
    make_scenario,
    trapezoid_s,
    write_yaml,
)

TURN = TURN_MPS


def test_single_agv_lead_time_matches_hand_computation(tiny_layout: Layout) -> None:
    scenario = make_scenario(duration_h=0.2, warmup_h=0.0, fleet={"size": 1},
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    run = simulate(scenario, tiny_layout, [TraceOrder(100.0, "PICK", "DROP")])
    order = run.recorder.orders[0]
    assert order.delivered_s is not None
    expected = K_TO_P_S + PICK_S + HALF_LOOP_S + DROP_S
    assert expected == pytest.approx(105.94, abs=1e-9)  # 17.3133 + 23 + 32.6267 + 33
    assert order.delivered_s - order.created_s == pytest.approx(expected, abs=1e-9)
    assert order.pickup_arrival_s == pytest.approx(100.0 + K_TO_P_S, abs=1e-9)


def test_single_agv_steady_cycle_time(tiny_layout: Layout) -> None:
    """With orders always waiting, one AGV delivers every D->P + pick + P->D + drop seconds."""
    scenario = make_scenario(duration_h=0.5, warmup_h=0.0, fleet={"size": 1},
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    trace = [TraceOrder(0.0, "PICK", "DROP")] * 12
    run = simulate(scenario, tiny_layout, trace)
    delivered = sorted(o.delivered_s for o in run.recorder.orders if o.delivered_s is not None)
    gaps = [b - a for a, b in itertools.pairwise(delivered)]
    assert len(gaps) >= 8
    cycle = 2 * HALF_LOOP_S + PICK_S + DROP_S
    assert cycle == pytest.approx(121.2533, abs=1e-4)
    for gap in gaps:
        assert gap == pytest.approx(cycle, abs=1e-9)


def test_an_order_walks_the_states_and_sub_states_in_order(tiny_layout: Layout) -> None:
    """Idle -> Moving -> Loading (L_Approach 1.5 s, L_Handshake 1.0 s, L_Transfer 20 s,
    L_Verify 0.5 s) -> Moving -> Unloading (the same with 30 s) -> Idle, at hand-computed
    times; the handling times are the stations' fixed 20 s and 30 s."""
    scenario = make_scenario(duration_h=0.1, warmup_h=0.0, fleet={"size": 1},
                             dispatch={"park_idle": False},
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    run = simulate(scenario, tiny_layout, [TraceOrder(100.0, "PICK", "DROP")])
    table = events_table(run.recorder)
    rows = table[(table["time_s"] >= 100.0) & (table["agv"] == 0)]
    seen = list(zip(rows["event"], rows["from_state"], rows["to_state"], strict=True))
    assert seen == [
        ("order_assigned", "Idle", "Idle"),
        ("Event_Transport_Order", "Idle", "Moving"),
        ("Event_Arrived_Pickup", "Moving", "Loading"),
        ("L_Approach", "Loading", "Loading"),
        ("L_Handshake", "Loading", "Loading"),
        ("L_Transfer", "Loading", "Loading"),
        ("L_Verify", "Loading", "Loading"),
        ("Event_Load_Complete", "Loading", "Moving"),
        ("Event_Arrived_Dropoff", "Moving", "Unloading"),
        ("U_Approach", "Unloading", "Unloading"),
        ("U_Handshake", "Unloading", "Unloading"),
        ("U_Transfer", "Unloading", "Unloading"),
        ("U_Verify", "Unloading", "Unloading"),
        ("Event_Unload_Complete", "Unloading", "Idle"),
    ]
    at_pickup = 100.0 + K_TO_P_S
    at_dropoff = at_pickup + PICK_S + HALF_LOOP_S
    expected_s = [100.0, 100.0, at_pickup,
                  at_pickup, at_pickup + 1.5, at_pickup + 2.5, at_pickup + 22.5, at_pickup + 23.0,
                  at_dropoff,
                  at_dropoff, at_dropoff + 1.5, at_dropoff + 2.5, at_dropoff + 32.5,
                  at_dropoff + 33.0]
    assert list(rows["time_s"]) == pytest.approx(expected_s, abs=1e-9)
    assert list(rows["node"])[2:] == ["P"] * 6 + ["D"] * 6


def test_the_trip_to_the_charger_is_moving_with_its_purpose(tmp_path: Path) -> None:
    """An AGV starting at N3 with 25 % (below the 30 % threshold) asks for the charger after
    booting (5 s) and drives N3 -> D -> N1 -> C, a right turn at N1 onto a 4 m spur: up to
    1.0 m/s, down to 0.3 m/s at N1, 1 m of curve, then 3 m to a stop. It is Moving all the way,
    Charging from its arrival."""
    data = copy.deepcopy(yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text()))
    data["nodes"].append({"id": "C", "x": 4, "y": 12, "kind": "charger"})
    data["segments"].append({"from": "N1", "to": "C", "direction": "two_way"})
    data["chargers"] = [{"id": "CHG", "node": "C", "power_kw": 1.0, "docking_s": 10}]
    layout_file = write_yaml(tmp_path / "tiny.yaml", data)
    scenario = make_scenario(str(layout_file), duration_h=0.05, warmup_h=0.0,
                             fleet={"size": 1, "start_nodes": ["N3"],
                                    "vehicle": {"battery": {"initial_soc_pct": 25.0}}},
                             demand={"rate_per_hour": 0}, dispatch={"park_idle": False})
    run = simulate(scenario, load_layout(layout_file))
    table = events_table(run.recorder)
    rows = table[table["from_state"] != table["to_state"]]
    seen = list(zip(rows["event"], rows["from_state"], rows["to_state"], rows["node"],
                    strict=True))
    assert seen[:4] == [("Event_Power_On", "", "Booting", "N3"),
                        ("Event_Init_Complete", "Booting", "Idle", "N3"),
                        ("Event_Go_Charge", "Idle", "Moving", "N3"),
                        ("Event_Arrived_Charger", "Moving", "Charging", "C")]
    assert rows["detail"].iloc[2].startswith("to_charger CHG")
    trip_s = trapezoid_s(8, 0.0, TURN) + 1.0 / TURN + trapezoid_s(3, TURN, 0.0)
    assert trip_s == pytest.approx(17.3133, abs=1e-4)  # 9.49 + 3.3333 + 4.49
    assert list(rows["time_s"])[:4] == pytest.approx([0.0, 5.0, 5.0, 5.0 + trip_s], abs=1e-9)


# ---- the battery switch: "no battery" and "charging off" ------------------------------------

ISSUE_13 = {"duration_h": 300, "warmup_h": 0.5, "seed": 1, "demand": {"rate_per_hour": 15},
            "charging": {"enabled": False}}
"""The tiny loop, one AGV, 15 orders/h (about half its capacity), charging off."""


def test_without_a_battery_one_agv_keeps_up_with_its_demand_for_300_h(
        tiny_layout: Layout) -> None:
    """`fleet.vehicle.battery: off`: throughput equals the arrival rate within sampling error,
    Little's law holds on the order queue, no AGV ever stands Idle while an order waits."""
    scenario = make_scenario(**ISSUE_13, fleet={"size": 1, "vehicle": {"battery": "off"}})
    run = simulate(scenario, tiny_layout)
    figures = run_kpis(run)
    window_h = 300 - 0.5
    # Poisson arrivals: 3 standard deviations of the count is 3 sqrt(15 x 299.5) = 201 orders
    assert abs(figures["throughput_per_hour"] - 15.0) < 3 * math.sqrt(15 * window_h) / window_h
    assert figures["throughput_per_hour"] * window_h == pytest.approx(
        figures["demand_per_hour"] * window_h, abs=3)  # delivered = created, but the last few
    assert figures["orders_open_at_end"] <= 2
    orders = orders_table(run.recorder)
    start, end = 0.5 * 3600, 300 * 3600
    arrived = orders[orders["created_s"].between(start, end)]
    rate = len(arrived) / (end - start)
    wait = (arrived["assigned_s"].fillna(end) - arrived["created_s"]).mean()
    assert figures["order_queue_mean"] > 0.1
    assert figures["order_queue_mean"] == pytest.approx(rate * wait, rel=0.03)  # Little
    assert figures["idle_with_orders_waiting_pct"] == 0.0
    assert figures["errors_by_code"] == {} and figures["charges"] == 0
    assert run.recorder.soc_samples == []  # no battery, no SOC curve
    assert run.vehicles[0].soc_pct == 100.0


def test_charging_off_with_a_draining_battery_runs_down_and_says_why(
        tiny_layout: Layout) -> None:
    """The issue's trap, now explained: with charging off the AGV stops taking orders at
    P_050 and stands Idle until E_201; every such hour is recorded as battery_low."""
    scenario = make_scenario(**{**ISSUE_13, "duration_h": 100}, fleet={"size": 1})
    run = simulate(scenario, tiny_layout)
    figures = run_kpis(run)
    assert figures["throughput_per_hour"] < 0.75 * figures["demand_per_hour"]
    assert figures["errors_by_code"]["E_201"] >= 5
    assert figures["idle_with_orders_waiting_pct"] > 40
    assert figures["idle_with_orders_waiting_pct_by_reason"]["battery_low"] == \
        figures["idle_with_orders_waiting_pct"]
    assert [w.kind for w in setup_warnings(scenario, tiny_layout)] == ["charging_off"]
    # it withdrew at P_050 (20 %), not lower: no order was handed to it and given back
    assert figures["orders_reassigned"] == 0


def test_scheduled_charging_calls_need_charging_and_a_battery(tiny_layout: Layout) -> None:
    """A charging schedule with charging off, or without a battery, calls no one (a call that
    could never be answered left the AGV turning back from each parking trip, forever, at
    one instant: the run never ended)."""
    for fleet, charging in [({"size": 1}, {"enabled": False, "schedule_h": [0.05]}),
                            ({"size": 1, "vehicle": {"battery": "off"}}, {"schedule_h": [0.05]})]:
        scenario = make_scenario(duration_h=1, warmup_h=0, fleet=fleet, charging=charging,
                                 demand={"rate_per_hour": 20})
        run = simulate(scenario, tiny_layout)
        assert not any(v.charge_due for v in run.vehicles)
        assert not [e for e in run.recorder.events if e.event == "Event_Stop"]
        assert sum(o.delivered_s is not None for o in run.recorder.orders) >= 10
