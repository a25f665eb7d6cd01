"""The fleet manager (fleet_sim.sim.agents.fleet_manager): assigning orders, putting back the
order of an AGV that cannot carry it out, the charger queue, parking, admission; and, in whole
runs, idle AGVs parked, no order lost, Little's law on the order queue, admission never beyond
its limit and a large fleet that keeps delivering under it."""

from __future__ import annotations

import copy
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import pytest
import simpy
import yaml

from fleet_sim.analysis.kpis import run_kpis
from fleet_sim.analysis.tables import orders_table
from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.scenario import DispatchConfig
from fleet_sim.model.kinematics import Motion
from fleet_sim.model.records import Order, Recorder
from fleet_sim.sim.agents.fleet_manager import FleetManager
from fleet_sim.sim.commands import CommandPath
from fleet_sim.sim.engine import RunOutput, build_model, simulate
from fleet_sim.sim.traffic.control import Traffic

from .conftest import LAYOUTS, make_scenario, write_yaml


@dataclass(eq=False)
class StubAgv:
    """An AGV as the fleet manager sees it (FleetAgv), standing at `node`."""

    id: int
    node: str
    fms_link: bool = True
    in_parking: bool = False
    notes: list[tuple[str, str]] = field(default_factory=list)
    orders: list[Order] = field(default_factory=list)

    @property
    def dispatch_node(self) -> str:
        return self.node

    def note(self, event: str, detail: str = "") -> None:
        self.notes.append((event, detail))

    def assign(self, order: Order) -> None:
        self.orders.append(order)


def fleet_manager(layout: Layout, config: DispatchConfig | None = None) -> FleetManager:
    env = simpy.Environment()
    recorder = Recorder(0.0, 3600.0)
    traffic = Traffic(env, layout, Motion(1.0, 0.5, 0.5, 0.3), recorder)
    commands = CommandPath(env, None, 0.0, np.random.default_rng(0), recorder)
    return FleetManager(env, layout, traffic, config or DispatchConfig(), recorder, commands)


@pytest.fixture(scope="module")
def spurs_layout(tmp_path_factory: pytest.TempPathFactory) -> Layout:
    """The tiny loop with two chargers and a second parking area, each on a 4 m two-way spur:
    CN north of N1, CS south of S3, and a one-place parking Q north of D (PARK is K, west)."""
    data = copy.deepcopy(yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text()))
    data["nodes"] += [{"id": "CN", "x": 4, "y": 12, "kind": "charger"},
                      {"id": "CS", "x": 12, "y": -4, "kind": "charger"},
                      {"id": "Q", "x": 8, "y": 12, "kind": "parking"}]
    data["segments"] += [{"from": "N1", "to": "CN", "direction": "two_way"},
                         {"from": "S3", "to": "CS", "direction": "two_way"},
                         {"from": "D", "to": "Q", "direction": "two_way"}]
    data["chargers"] = [{"id": "CHG_N", "node": "CN", "power_kw": 1.0},
                        {"id": "CHG_S", "node": "CS", "power_kw": 1.0}]
    data["parking"].append({"id": "PARK2", "node": "Q", "capacity": 1})
    path = write_yaml(tmp_path_factory.mktemp("spurs") / "spurs.yaml", data)
    return load_layout(path)


def test_an_idle_agv_gets_the_oldest_order_at_once(tiny_layout: Layout) -> None:
    fm = fleet_manager(tiny_layout)
    first, second = Order(0, 0.0, "PICK", "DROP"), Order(1, 0.0, "PICK", "DROP")
    fm.submit(first)
    fm.submit(second)
    assert list(fm.waiting) == [first, second]
    agv = StubAgv(3, "S1")
    fm.vehicle_idle(agv)
    assert agv.orders == [first] and list(fm.waiting) == [second]
    assert (first.agv, first.assigned_s, first.pickup_node, first.dropoff_node) == \
        (3, 0.0, "P", "D")
    assert fm.idle == []
    assert fm.recorder.queue_lengths == [(0.0, 0), (0.0, 1), (0.0, 2), (0.0, 1)]


def test_an_agv_without_the_fms_link_gets_no_order(tiny_layout: Layout) -> None:
    fm = fleet_manager(tiny_layout)
    fm.submit(Order(0, 0.0, "PICK", "DROP"))
    lost = StubAgv(0, "S1", fms_link=False)
    fm.vehicle_idle(lost)
    assert lost.orders == [] and len(fm.waiting) == 1
    heard = StubAgv(1, "NW")
    fm.vehicle_idle(heard)
    assert len(heard.orders) == 1 and not fm.waiting


def test_requeue_puts_the_order_back_at_the_front_unassigned(tiny_layout: Layout) -> None:
    fm = fleet_manager(tiny_layout)
    first, second = Order(0, 0.0, "PICK", "DROP"), Order(1, 0.0, "PICK", "DROP")
    fm.submit(first)
    fm.submit(second)
    broken = StubAgv(0, "S1")
    fm.vehicle_idle(broken)
    assert fm.bound_for["P"] == 1 and fm.bound_for["D"] == 1
    fm.requeue(broken, first)
    assert list(fm.waiting) == [first, second]
    assert (first.agv, first.assigned_s, first.pickup_node, first.dropoff_node) == \
        (None, None, None, None)
    assert first.reassigned == 1
    assert fm.bound_for["P"] == 0 and fm.bound_for["D"] == 0
    assert broken.notes == [("order_reassigned", "order 0")]
    other = StubAgv(1, "NW")
    fm.vehicle_idle(other)
    assert other.orders == [first]  # the put-back order before the younger one


def test_order_failed_records_the_code_and_frees_the_dropoff(tiny_layout: Layout) -> None:
    fm = fleet_manager(tiny_layout)
    order = Order(0, 0.0, "PICK", "DROP")
    fm.submit(order)
    fm.vehicle_idle(StubAgv(0, "S1"))
    order.picked_s = 10.0
    fm.left_station("P")  # loaded: the AGV has left the pickup
    fm.env.run(until=50.0)
    fm.order_failed(order, "E_102")
    assert (order.failed_s, order.failure) == (50.0, "E_102")
    assert fm.bound_for["P"] == 0 and fm.bound_for["D"] == 0


def test_chargers_nearest_free_first_then_first_come_first_served(spurs_layout: Layout) -> None:
    fm = fleet_manager(spurs_layout)
    at_d, at_p = StubAgv(0, "D"), StubAgv(1, "P")
    got_d, got_p = fm.request_charger(at_d), fm.request_charger(at_p)
    # D -> N1 -> CN is 8 m; P -> S3 -> CS is 8 m; the other way round, most of the loop
    assert (got_d.value.id, got_p.value.id) == ("CHG_N", "CHG_S")
    assert not fm.charger_available()
    second, third = StubAgv(2, "N3"), StubAgv(3, "S1")
    wait_2, wait_3 = fm.request_charger(second), fm.request_charger(third)
    assert not wait_2.triggered and not wait_3.triggered
    fm.release_charger(spurs_layout.places["CHG_S"])
    assert wait_2.triggered and wait_2.value.id == "CHG_S" and not wait_3.triggered
    fm.cancel_charger_request(third)
    fm.release_charger(spurs_layout.places["CHG_N"])
    assert not wait_3.triggered
    assert fm.charger_available() and [c.id for c in fm.chargers_free] == ["CHG_N"]


def test_asking_for_a_charger_withdraws_the_agv_from_orders(spurs_layout: Layout) -> None:
    fm = fleet_manager(spurs_layout)
    agv = StubAgv(0, "D")
    fm.vehicle_idle(agv)
    assert fm.idle == [agv]
    fm.request_charger(agv)
    fm.submit(Order(0, 0.0, "PICK", "DROP"))
    assert fm.idle == [] and agv.orders == [] and len(fm.waiting) == 1


def test_parking_nearest_with_room(spurs_layout: Layout) -> None:
    fm = fleet_manager(spurs_layout)

    def park(agv: int, node: str) -> str | None:
        place = fm.reserve_parking(StubAgv(agv, node))
        return None if place is None else place.id

    # from N3: Q (PARK2) is 8 m away, K (PARK) 16 m; from NW, K is 4 m away
    assert park(0, "NW") == "PARK"
    assert park(1, "N3") == "PARK2"
    assert park(2, "N3") == "PARK"  # PARK2 holds one
    assert fm.parking_free == {"PARK": 2, "PARK2": 0}
    assert park(3, "E1") == "PARK"
    assert park(4, "E1") == "PARK"
    assert park(5, "E1") is None  # 4 + 1 places, all taken
    fm.release_parking(spurs_layout.places["PARK2"])
    assert park(5, "E1") == "PARK2"


def test_idle_agvs_go_to_parking(warehouse_layout: Layout) -> None:
    scenario = make_scenario("warehouse.yaml", duration_h=0.5, warmup_h=0,
                             fleet={"size": 3, "start_nodes": ["M010", "M030", "A05_12"]},
                             demand={"rate_per_hour": 0})
    run = simulate(scenario, warehouse_layout)
    parked = [e for e in run.recorder.events if e.event == "Event_Arrived_Parking"]
    assert sorted(e.agv for e in parked) == [0, 1, 2]
    assert all(v.parked_in is not None for v in run.vehicles)
    assert all(not v.held for v in run.vehicles)


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


# ---- admission (dispatch.max_active_agvs) ----------------------------------------------------


def test_admission_gives_parked_agvs_work_only_while_there_is_room(spurs_layout: Layout) -> None:
    fm = fleet_manager(spurs_layout, DispatchConfig(max_active_agvs=1))
    out, parked = StubAgv(0, "K", in_parking=True), StubAgv(1, "K", in_parking=True)
    fm.vehicle_idle(out)
    fm.vehicle_idle(parked)
    first, second = Order(0, 0.0, "PICK", "DROP"), Order(1, 0.0, "PICK", "DROP")
    fm.submit(first)
    fm.submit(second)
    assert out.orders == [first] and parked.orders == []  # one admission, taken by AGV 0
    assert fm.admitted == {0} and list(fm.waiting) == [second]
    assert out.notes == [("admitted", "1 of 1 on the track")]
    out.in_parking = False  # AGV 0 drives off, delivers, and offers itself on the track
    fm.vehicle_idle(out)
    assert out.orders == [first, second]  # on the track already: no admission needed
    out.in_parking = True
    fm.parked(out)  # AGV 0 is back in parking: its admission is free
    assert fm.admitted == set()
    fm.submit(third := Order(2, 0.0, "PICK", "DROP"))
    assert parked.orders == [third] and fm.admitted == {1}


def test_a_freed_admission_goes_to_a_charger_before_an_order(spurs_layout: Layout) -> None:
    fm = fleet_manager(spurs_layout, DispatchConfig(max_active_agvs=1))
    busy = StubAgv(0, "D")
    fm.on_track_at_start(busy)
    waiting_idle, low = StubAgv(1, "K", in_parking=True), StubAgv(2, "K", in_parking=True)
    fm.vehicle_idle(waiting_idle)
    fm.submit(order := Order(0, 0.0, "PICK", "DROP"))
    charger = fm.request_charger(low)
    assert not charger.triggered and waiting_idle.orders == []  # AGV 0 holds the admission
    busy.in_parking = True
    fm.parked(busy)
    assert charger.triggered and fm.admitted == {2}  # the battery first
    assert waiting_idle.orders == [] and list(fm.waiting) == [order]


def on_track_at_most(run: RunOutput) -> int:
    """The most AGVs on the track at once, from the node holds the run recorded (an AGV on the
    track always holds its node; in parking, none): independent of the admission bookkeeping."""
    spans: dict[int, list[tuple[float, float]]] = {}
    for spell in run.recorder.occupancy:
        if spell.kind == "node":
            spans.setdefault(spell.agv, []).append((spell.start_s, spell.end_s))
    for vehicle in run.vehicles:  # holds still open at the end
        for held in vehicle.held + vehicle.ahead:
            spans.setdefault(vehicle.id, []).append((held.since_s, run.scenario.duration_s))
    changes: list[tuple[float, int]] = []
    for agv_spans in spans.values():  # each AGV's union of holds: +1 when it starts, -1 at end
        agv_spans.sort()
        start, end = agv_spans[0]
        for a, b in agv_spans[1:]:
            if a > end:
                changes += [(start, 1), (end, -1)]
                start = a
            end = max(end, b)
        changes += [(start, 1), (end, -1)]
    most = now = 0
    for _, step in sorted(changes):  # at one instant, leaving (-1) before entering (+1)
        now += step
        most = max(most, now)
    return most


def test_admission_never_admits_beyond_its_limit(warehouse_layout: Layout) -> None:
    lulls = [{"from_h": h / 2, "multiplier": 0.05 if h % 2 else 1.0} for h in range(6)]
    scenario = make_scenario("warehouse.yaml", duration_h=3, warmup_h=0.5, seed=5,
                             fleet={"size": 40},  # busy half-hours and lulls: AGVs come and go
                             demand={"rate_per_hour": 150, "profile": lulls},
                             dispatch={"max_active_agvs": 12},
                             charging={"threshold_pct": 60})  # charging trips too
    run = simulate(scenario, warehouse_layout, record_occupancy=True)
    assert on_track_at_most(run) == 12  # the limit binds, and is never passed
    admitted = Counter(e.agv for e in run.recorder.events if e.event == "admitted")
    assert sum(admitted.values()) > 12  # admissions freed in parking were handed out again
    assert any(e.event == "Event_Go_Charge" for e in run.recorder.events)
    unlimited = simulate(scenario.model_copy(update={"dispatch": DispatchConfig()}),
                         warehouse_layout, record_occupancy=True)
    assert on_track_at_most(unlimited) > 12  # without the rule, more AGVs go out


def test_150_agvs_on_the_warehouse_deliver_in_every_hour_under_admission(
        warehouse_layout: Layout) -> None:
    """Without admission, 100 busy AGVs lock the warehouse's loop solid in the first hour
    (bench/admission.py); with the loop's working load admitted, 150 keep delivering."""
    scenario = make_scenario("warehouse.yaml", duration_h=3.5, warmup_h=0.5, seed=3,
                             fleet={"size": 150}, demand={"rate_per_hour": 300},
                             dispatch={"max_active_agvs": 20})
    run = simulate(scenario, warehouse_layout)
    per_hour = Counter(int((o.delivered_s - 1800.0) // 3600) for o in run.recorder.orders
                       if o.delivered_s is not None and o.delivered_s >= 1800.0)
    assert all(per_hour[h] >= 120 for h in range(3)), per_hour  # the plateau is ~170/h
