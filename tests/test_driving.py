"""Driving under traffic control (fleet_sim.sim.agents.driving): hop times and the look-ahead,
locks let go only once the body and the gap have cleared them, no two AGVs on one node or
segment, deadlocks escaped, giving way."""

from __future__ import annotations

import itertools
from collections import defaultdict
from pathlib import Path

import pytest

from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.sim.engine import build_simulation, simulate

from .conftest import DATA, make_scenario, trapezoid_s, write_yaml


def segment_spans(occupancy: list[tuple[str, str, int, float, float]],
                  agv: int) -> dict[str, tuple[float, float]]:
    return {key: (t0, t1) for kind, key, who, t0, t1 in occupancy
            if kind == "segment" and who == agv}


def test_look_ahead_passes_a_node_at_speed_or_brakes_before_a_held_one(
        tiny_layout: Layout) -> None:
    """AGV 0 drives SW -> S1 -> P -> S3 (4 m hops, straight). With P free it takes P while at
    SW and passes S1 at 1.0 m/s: 2 s to reach 1.0 m/s over 1 m, then 3 m at 1.0 m/s = 5 s.
    With P held by AGV 1 it must be able to stop at S1: 2 s up, 2 m at 1.0 m/s, 2 s down = 6 s."""
    def sw_to_s1_s(start_nodes: list[str]) -> tuple[float, float]:
        scenario = make_scenario(duration_h=0.1, warmup_h=0, demand={"rate_per_hour": 0},
                                 fleet={"size": len(start_nodes), "start_nodes": start_nodes},
                                 dispatch={"park_idle": False})
        model = build_simulation(scenario, tiny_layout, record_occupancy=True)
        agv = model.vehicles[0]
        agv.process = model.env.process(agv.drive("S3"))
        model.env.run(until=30)
        return segment_spans(model.recorder.occupancy, 0)["SW>S1"]

    assert sw_to_s1_s(["SW"]) == (0.0, trapezoid_s(4, 0.0, 1.0)) == (0.0, 5.0)
    assert sw_to_s1_s(["SW", "P"]) == (0.0, trapezoid_s(4, 0.0, 0.0)) == (0.0, 6.0)


def test_a_whole_drive_with_a_turn_by_hand(tiny_layout: Layout) -> None:
    """K -> SW -> S1 -> P: up to 1.0 m/s and down to 0.3 m/s at the SW corner, 1 m of curve at
    0.3 m/s, back up to 1.0 m/s and a stop at P (8 m from SW)."""
    scenario = make_scenario(duration_h=0.1, warmup_h=0, demand={"rate_per_hour": 0},
                             fleet={"size": 1, "start_nodes": ["K"]},
                             dispatch={"park_idle": False})
    model = build_simulation(scenario, tiny_layout, record_occupancy=True)
    agv = model.vehicles[0]
    drive = model.env.process(agv.drive("P"))
    agv.process = drive
    model.env.run(until=60)
    assert not drive.is_alive and agv.node == "P" and agv.speed_mps == 0.0
    into_corner = trapezoid_s(4, 0.0, 0.3)  # 2 s up + 1.4 s down + 2.09 m at 1.0 m/s = 5.49 s
    out_and_stop = 1.0 / 0.3 + trapezoid_s(7, 0.3, 0.0)  # 3.3333 s + (1.4 + 2 + 5.09) s
    spans = segment_spans(model.recorder.occupancy, 0)
    assert spans["K>SW"][0] == 0.0
    assert spans["K>SW"][1] == pytest.approx(5.49, abs=1e-9)
    assert into_corner == pytest.approx(5.49, abs=1e-9)
    assert spans["S1>P"][1] == pytest.approx(into_corner + out_and_stop, abs=1e-9)
    assert into_corner + out_and_stop == pytest.approx(17.3133, abs=1e-4)


def test_no_two_agvs_share_a_node_or_segment(warehouse_layout: Layout) -> None:
    """Invariant over a long random run: node holds and segment traversals never overlap."""
    scenario = make_scenario("warehouse.yaml", duration_h=3, warmup_h=0.0, seed=5,
                             fleet={"size": 20}, demand={"rate_per_hour": 150})
    run = simulate(scenario, warehouse_layout, record_occupancy=True)
    spans: dict[tuple[str, str], list[tuple[float, float, int]]] = defaultdict(list)
    for kind, key, agv, t0, t1 in run.recorder.occupancy:
        assert t1 >= t0
        if kind == "segment":  # one physical segment, whichever way it is driven
            key = "|".join(sorted(key.split(">")))
        spans[(kind, key)].append((t0, t1, agv))
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
    for kind, key, agv, t0, t1 in run.recorder.occupancy:
        if kind == "segment":
            u, v = key.split(">")
            hops[agv].append((t0, t1, u, v))
    parked = {(e.agv, e.time_s) for e in run.recorder.events if e.event == "Event_Arrived_Parking"}
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
    model = build_simulation(scenario, layout)
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


def test_giving_way_keeps_the_main_loop_flowing(warehouse_layout: Layout) -> None:
    """25 busy AGVs queue on the loop for busy aisles and full sidings. Without the give-way rule
    (and without re-planning) they lock the loop solid within the first hour; with it, AGVs that
    block others circulate and the warehouse keeps delivering."""
    def deliveries_after_first_hour(give_way_after_s: float) -> tuple[int, int]:
        scenario = make_scenario("warehouse.yaml", duration_h=3, warmup_h=0, seed=7,
                                 fleet={"size": 25}, demand={"rate_per_hour": 187.5},
                                 charging={"enabled": False},
                                 rules={"agv_ahead": "held_back"},  # no E_101 behind AGVs
                                 traffic={"give_way_after_s": give_way_after_s,
                                          "replan_after_s": 1e9})
        run = simulate(scenario, warehouse_layout)
        late = sum(1 for o in run.recorder.orders
                   if o.delivered_s is not None and o.delivered_s > 3600)
        return late, sum(1 for e in run.recorder.events if e.event == "circulate")

    assert deliveries_after_first_hour(1e9) == (0, 0)
    late, circulated = deliveries_after_first_hour(10.0)
    assert late > 250 and circulated > 100


def test_an_agv_whose_re_entry_wait_is_broken_waits_again_and_never_shares_a_node(
        tiny_layout: Layout) -> None:
    """An AGV off the track waits to come back on at P, held by another AGV. Traffic breaks its
    wait (as it does to the AGV it picks to break a wait-for cycle): it must let go, wait again
    and come on only once P is free, holding P's lock, with no claim left behind."""
    from fleet_sim.sim.traffic.deadlock import DeadlockVictim, Escape

    scenario = make_scenario(duration_h=0.1, warmup_h=0, demand={"rate_per_hour": 0},
                             fleet={"size": 2, "start_nodes": ["S1", "P"]},
                             dispatch={"park_idle": False})
    model = build_simulation(scenario, tiny_layout)
    env, traffic = model.env, model.traffic
    comer, holder = model.vehicles
    comer.driver.leave_track()
    comer.process = env.process(comer.driver.reenter_track("P"))
    env.run(until=5)
    assert traffic.waiting[comer.id].key == traffic.node_locks["P"].key
    traffic.strategy.escapes.chosen[comer.id] = Escape("yield", (comer.node,))
    comer.driver.on_deadlock_victim(DeadlockVictim(Escape("yield", (comer.node,))))
    env.run(until=20)
    assert comer.process.is_alive and not comer.driver.held  # still waiting, P not taken
    assert traffic.node_locks["P"].holder == holder.id
    assert comer.id not in traffic.strategy.escapes.chosen
    holder.process = env.process(holder.drive("S3"))
    env.run(until=120)
    assert not comer.process.is_alive
    assert comer.node == "P" and traffic.node_locks["P"].holder == comer.id
    assert [h.node for h in comer.driver.held] == ["P"]
    assert comer.id not in traffic.waiting
