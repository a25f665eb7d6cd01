"""Checks of the model itself: hand-computed timing, conservation laws, traffic invariants,
deadlocks, dispatch policies, determinism."""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from pathlib import Path

import pytest

from fleet_sim.analysis.kpis import run_kpis
from fleet_sim.analysis.tables import orders_table, write_run
from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.trace import TraceOrder
from fleet_sim.sim.engine import build_model, simulate

from .conftest import DATA, make_scenario, write_yaml

A = 0.5  # P_002 / P_003: 500 mm/s2


def trapezoid_s(length_m: float, v0: float, v1: float, vmax: float = 1.0) -> float:
    """By hand: accelerate from v0 to vmax, cruise, brake to v1 (long enough to cruise)."""
    d_acc = (vmax**2 - v0**2) / (2 * A)
    d_dec = (vmax**2 - v1**2) / (2 * A)
    assert d_acc + d_dec <= length_m
    return (vmax - v0) / A + (vmax - v1) / A + (length_m - d_acc - d_dec) / vmax


# The tiny loop has tags every 4 m and a 90-degree left turn at each corner. A turn is driven at
# 0.3 m/s (Req.Nav.005) over the first 1.0 m after the corner (layout turn_length_m), so an AGV
# slows to 0.3 m/s before each corner and speeds up again 1 m after it.
TURN = 0.3
INTO_CORNER = trapezoid_s(4, 1.0, TURN)  # 1.0 m/s -> 0.3 m/s at the corner
OUT_OF_CORNER = 1.0 / TURN + trapezoid_s(3, TURN, 1.0)  # curve, then back up to 1.0 m/s
START = trapezoid_s(4, 0.0, 1.0)
STOP = trapezoid_s(4, 1.0, 0.0)
# P -> D: start, into SE, out of SE, into NE, out of NE, stop at D. D -> P is the mirror image.
HALF_LOOP_S = START + INTO_CORNER + OUT_OF_CORNER + INTO_CORNER + OUT_OF_CORNER + STOP
# K -> P after leaving parking: K->SW (start, slow for the corner), out of SW, stop at P.
K_TO_P_S = trapezoid_s(4, 0.0, TURN) + OUT_OF_CORNER + STOP
# L_Approach 1.5 s + L_Handshake 1.0 s + L_Transfer (the station's handling) + L_Verify 0.5 s
SUB_STATES_S = 1.5 + 1.0 + 0.5
PICK_S, DROP_S = 20.0 + SUB_STATES_S, 30.0 + SUB_STATES_S


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


def test_throughput_equals_completed_orders_over_time(warehouse_layout: Layout) -> None:
    scenario = make_scenario("warehouse.yaml", duration_h=3, warmup_h=0.5, seed=3,
                             fleet={"size": 8}, demand={"rate_per_hour": 60})
    run = simulate(scenario, warehouse_layout)
    orders = orders_table(run.recorder)
    figures = run_kpis(run)
    done = orders["delivered_s"].between(1800.0, 3 * 3600.0)
    assert done.sum() > 50
    assert figures["throughput_per_hour"] == pytest.approx(done.sum() / 2.5, rel=1e-9)
    assert figures["orders_completed"] == int(orders["delivered_s"].notna().sum())
    lead = orders.loc[done, "delivered_s"] - orders.loc[done, "created_s"]
    assert figures["lead_time_mean_s"] == pytest.approx(lead.mean(), rel=1e-6)
    # every AGV's time in states adds up to the window
    shares = sum(v for k, v in figures.items() if k.startswith("state_"))
    assert shares == pytest.approx(100.0, abs=1e-4)  # each share is rounded to 1e-6


def test_littles_law_on_the_order_queue(tiny_layout: Layout) -> None:
    """Time-average number of orders waiting = arrival rate x mean wait, within sampling error."""
    scenario = make_scenario(duration_h=40, warmup_h=1, seed=11, fleet={"size": 2},
                             demand={"rate_per_hour": 45})
    run = simulate(scenario, tiny_layout)
    orders = orders_table(run.recorder)
    figures = run_kpis(run)
    start, end = 3600.0, 40 * 3600.0
    arrived = orders[orders["created_s"].between(start, end)]
    rate = len(arrived) / (end - start)
    wait = (arrived["assigned_s"].fillna(end) - arrived["created_s"]).mean()
    assert figures["order_queue_mean"] > 0.2  # a queue worth checking
    assert figures["order_queue_mean"] == pytest.approx(rate * wait, rel=0.05)


def test_no_two_agvs_share_a_node_or_segment(warehouse_layout: Layout) -> None:
    """Invariant over a long random run: node holds and segment traversals never overlap."""
    scenario = make_scenario("warehouse.yaml", duration_h=3, warmup_h=0.0, seed=5,
                             fleet={"size": 20}, demand={"rate_per_hour": 150})
    run = simulate(scenario, warehouse_layout, record_occupancy=True)
    spans: dict[tuple[str, str], list[tuple[float, float, int]]] = defaultdict(list)
    for spell in run.recorder.occupancy:
        assert spell.end_s >= spell.start_s
        key = spell.key
        if spell.kind == "segment":  # one physical segment, whichever way it is driven
            key = "|".join(sorted(key.split(">")))
        spans[(spell.kind, key)].append((spell.start_s, spell.end_s, spell.agv))
    assert sum(1 for kind, _ in spans if kind == "segment") > 100
    assert len(run.recorder.occupancy) > 10_000
    for (kind, key), items in spans.items():
        items.sort()
        for (a0, a1, agv_a), (b0, b1, agv_b) in itertools.pairwise(items):
            assert b0 >= a1 - 1e-9, f"{kind} {key}: AGV {agv_a} [{a0}, {a1}] overlaps " \
                                    f"AGV {agv_b} [{b0}, {b1}]"


def test_gap_to_the_agv_ahead_is_kept(tmp_path: Path) -> None:
    """On a loop with tags every 1 m, an AGV lets go of a node only once its body and the
    minimum gap (1.2 + 0.6 m) have cleared it; so the next AGV never comes closer."""
    ring = [(x, 0) for x in range(4)] + [(4, y) for y in range(4)] + \
        [(x, 4) for x in range(4, 0, -1)] + [(0, y) for y in range(4, 0, -1)]
    ids = [f"T{i:02d}" for i in range(len(ring))]
    kinds = {2: "station", 10: "station", 14: "parking"}
    layout_file = write_yaml(tmp_path / "dense.yaml", {
        "name": "dense",
        "nodes": [{"id": n, "x": x, "y": y, "kind": kinds.get(i, "tag")}
                  for i, (n, (x, y)) in enumerate(zip(ids, ring, strict=True))],
        "segments": [{"from": a, "to": b} for a, b in zip(ids, ids[1:] + ids[:1], strict=True)],
        "stations": [{"id": "PICK", "kind": "pickup", "nodes": ["T02"]},
                     {"id": "DROP", "kind": "dropoff", "nodes": ["T10"]}],
        "parking": [{"id": "PARK", "node": "T14", "capacity": 3}],
    })
    scenario = make_scenario(str(layout_file), duration_h=1, warmup_h=0.0, seed=2,
                             fleet={"size": 3, "vehicle": {"length_m": 1.2, "min_gap_m": 0.6}},
                             demand={"rate_per_hour": 120})
    run = simulate(scenario, load_layout(layout_file), record_occupancy=True)
    hops: dict[int, list[tuple[float, float, str, str]]] = defaultdict(list)
    for spell in run.recorder.occupancy:
        if spell.kind == "segment":
            u, v = spell.key.split(">")
            hops[spell.agv].append((spell.start_s, spell.end_s, u, v))
    parked = {(e.agv, e.time_s) for e in run.recorder.events
              if e.event == "Event_Arrived_Parking"}
    checked = 0
    for kind, node, agv, t0, t1 in run.recorder.occupancy:
        if kind != "node" or (agv, t1) in parked:
            continue  # into a parking bay, off the track
        driven = [h for h in hops[agv] if t0 <= h[0] and h[1] <= t1 + 1e-9]
        leaving = [h for h in driven if h[2] == node]
        if not leaving:
            continue  # it parked or stopped there; nothing to clear
        past = sum(1.0 for h in driven if h[0] >= leaving[0][0])
        assert past >= 1.8 - 1e-9, f"AGV {agv} let go of {node} only {past} m past it"
        checked += 1
    assert checked > 200


def test_deadlock_built_on_purpose_is_detected_and_resolved() -> None:
    layout = load_layout(DATA / "deadlock_ring.yaml")
    scenario = make_scenario(str(DATA / "deadlock_ring.yaml"), duration_h=1, warmup_h=0,
                             fleet={"size": 4, "start_nodes": ["N0", "N1", "N2", "N3"]},
                             demand={"rate_per_hour": 0}, dispatch={"park_idle": False})
    model = build_model(scenario, layout)
    goals = {0: "N2", 1: "N3", 2: "N0", 3: "N1"}  # each two nodes ahead: all wait on the next
    drives = []
    for vehicle in model.vehicles:
        vehicle.process = model.env.process(vehicle.drive(goals[vehicle.id]))
        drives.append(vehicle.process)
    model.env.run(until=600)
    assert model.recorder.deadlocks >= 1
    names = [e.event for e in model.recorder.events]
    assert "deadlock_detected" in names and "deadlock_resolved" in names
    assert all(not p.is_alive for p in drives), "an AGV is still stuck"
    assert {v.id: v.node for v in model.vehicles} == goals


def test_deadlock_layout_under_orders_keeps_delivering() -> None:
    layout = load_layout(DATA / "deadlock_ring.yaml")
    scenario = make_scenario(str(DATA / "deadlock_ring.yaml"), duration_h=4, warmup_h=0,
                             seed=4, fleet={"size": 4, "start_nodes": ["N0", "N1", "N2", "N3"]},
                             demand={"rate_per_hour": 200}, dispatch={"park_idle": False})
    run = simulate(scenario, layout)
    delivered = [o for o in run.recorder.orders if o.delivered_s is not None]
    last_hour = [o for o in delivered if o.delivered_s is not None and o.delivered_s > 3 * 3600]
    assert len(delivered) > 100
    assert last_hour, "deliveries stopped: the fleet is stuck"


@pytest.mark.parametrize("policy,expected_agv", [("nearest_idle", 1), ("fcfs", 0)])
def test_dispatch_policies(tiny_layout: Layout, policy: str, expected_agv: int) -> None:
    """AGV 0 stands at N1 (far from the pickup), AGV 1 at S1 (4 m before it). Both become idle
    at the same moment; AGV 0 first."""
    scenario = make_scenario(duration_h=0.1, warmup_h=0, fleet={"size": 2,
                             "start_nodes": ["N1", "S1"]}, dispatch={"policy": policy,
                             "park_idle": False}, demand={"kind": "trace", "trace_csv": "x.csv"})
    run = simulate(scenario, tiny_layout, [TraceOrder(60.0, "PICK", "DROP")])
    assert run.recorder.orders[0].agv == expected_agv


def test_idle_agvs_go_to_parking(warehouse_layout: Layout) -> None:
    scenario = make_scenario("warehouse.yaml", duration_h=0.5, warmup_h=0,
                             fleet={"size": 3, "start_nodes": ["M010", "M030", "A05_12"]},
                             demand={"rate_per_hour": 0})
    run = simulate(scenario, warehouse_layout)
    parked = [e for e in run.recorder.events if e.event == "Event_Arrived_Parking"]
    assert sorted(e.agv for e in parked) == [0, 1, 2]
    assert all(v.parked_in is not None for v in run.vehicles)
    assert all(not v.held for v in run.vehicles)


def test_poisson_demand_rate_and_time_of_day_profile(tiny_layout: Layout) -> None:
    """Arrivals follow rate x multiplier: 30/h from 00:00, 90/h from 02:00 (x3)."""
    scenario = make_scenario(duration_h=4, warmup_h=0, seed=8, fleet={"size": 1},
                             demand={"rate_per_hour": 30, "profile": [
                                 {"from_h": 0, "multiplier": 1.0},
                                 {"from_h": 2, "multiplier": 3.0}]})
    model = build_model(scenario, tiny_layout)
    model.env.run(until=4 * 3600)
    times = [o.created_s for o in model.recorder.orders]
    low = sum(1 for t in times if t < 7200)
    high = len(times) - low
    # Poisson counts: 60 and 180 expected; 4 standard deviations either side
    assert abs(low - 60) < 4 * math.sqrt(60)
    assert abs(high - 180) < 4 * math.sqrt(180)


def test_trace_replay_creates_orders_at_their_times(tiny_layout: Layout) -> None:
    scenario = make_scenario(duration_h=0.5, warmup_h=0, fleet={"size": 2},
                             demand={"kind": "trace", "trace_csv": "x.csv"})
    trace = [TraceOrder(t, "PICK", "DROP") for t in (10.0, 10.0, 250.5, 900.0)]
    run = simulate(scenario, tiny_layout, trace)
    assert [o.created_s for o in run.recorder.orders] == [10.0, 10.0, 250.5, 900.0]


def test_same_seed_same_bytes_other_seed_other_results(tmp_path: Path,
                                                        warehouse_layout: Layout) -> None:
    def run_to(folder: str, seed: int) -> Path:
        scenario = make_scenario("warehouse.yaml", duration_h=1.5, warmup_h=0.25, seed=seed,
                                 fleet={"size": 10}, demand={"rate_per_hour": 100})
        out = tmp_path / folder
        run = simulate(scenario, warehouse_layout)
        write_run(run, out, run_kpis(run))
        return out

    a, b, c = run_to("a", 21), run_to("b", 21), run_to("c", 22)
    for name in ("events.parquet", "orders.parquet", "kpis.json", "config.resolved.yaml"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "orders.parquet").read_bytes() != (c / "orders.parquet").read_bytes()


def test_orders_are_never_lost(warehouse_layout: Layout) -> None:
    """Every order created is waiting, being served, or delivered at the end of a run."""
    scenario = make_scenario("warehouse.yaml", duration_h=2, warmup_h=0, seed=9,
                             fleet={"size": 6}, demand={"rate_per_hour": 200})
    model = build_model(scenario, warehouse_layout)
    model.env.run(until=2 * 3600)
    waiting = {o.id for o in model.fleet.waiting}
    serving = {v.order.id for v in model.vehicles if v.order is not None}
    delivered = {o.id for o in model.recorder.orders if o.delivered_s is not None}
    assert waiting | serving | delivered == {o.id for o in model.recorder.orders}
    assert not waiting & serving and not serving & delivered and not waiting & delivered


def test_giving_way_keeps_the_main_loop_flowing(warehouse_layout: Layout) -> None:
    """25 busy AGVs queue on the loop for busy aisles and full sidings. Without the give-way rule
    (and without re-planning) they lock the loop solid within the first hour; with it, AGVs that
    block others circulate and the warehouse keeps delivering."""
    def deliveries_after_first_hour(give_way_after_s: float) -> tuple[int, int]:
        scenario = make_scenario("warehouse.yaml", duration_h=3, warmup_h=0, seed=7,
                                 fleet={"size": 25}, demand={"rate_per_hour": 187.5},
                                 charging={"enabled": False},
                                 traffic={"give_way_after_s": give_way_after_s,
                                          "replan_after_s": 1e9})
        run = simulate(scenario, warehouse_layout)
        late = sum(1 for o in run.recorder.orders
                   if o.delivered_s is not None and o.delivered_s > 3600)
        return late, sum(1 for e in run.recorder.events if e.event == "circulate")

    assert deliveries_after_first_hour(1e9) == (0, 0)
    late, circulated = deliveries_after_first_hour(10.0)
    assert late > 250 and circulated > 100
