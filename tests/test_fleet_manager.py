"""The fleet manager (fleet_sim.sim.agents.fleet_manager): assigning orders, putting back the
order of an AGV that cannot carry it out, the charger queue, parking, admission; and, in whole
runs, idle AGVs parked, no order lost, Little's law on the order queue, admission never beyond
its limit and a large fleet that keeps delivering under it; work conservation: every reason
for not dispatching provoked and recorded, and over long runs with every incident on, no moment
at which an AGV stands Idle while an order waits without a recorded reason."""

from __future__ import annotations

import copy
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import simpy
import yaml

from fleet_sim.analysis.kpi_sums import run_kpis
from fleet_sim.analysis.tables import orders_table
from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.scenario import DispatchConfig
from fleet_sim.errors import SimulationError
from fleet_sim.model.kinematics import Motion
from fleet_sim.model.not_dispatched import NOT_DISPATCHED, NOT_DISPATCHED_END, NotDispatched
from fleet_sim.model.records import EventRecord, Order, Recorder
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.fleet_manager import FleetManager
from fleet_sim.sim.commands import CommandPath
from fleet_sim.sim.engine import RunOutput, build_simulation, simulate
from fleet_sim.sim.traffic.control import Traffic
from fleet_sim.sim.traffic.reactive import ReactivePolicy

from .conftest import LAYOUTS, make_scenario, write_yaml


@dataclass(eq=False)
class StubAgv:
    """An AGV as the fleet manager sees it (FleetAgv), standing at `node`."""

    id: int
    node: str
    fms_link: bool = True
    state: VehicleState = VehicleState.IDLE
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
    traffic = Traffic(env, layout, Motion(1.0, 0.5, 0.5, 0.3), recorder,
                      strategy=ReactivePolicy)
    commands = CommandPath.for_profile(env, None, 0.0, np.random.default_rng(0), recorder)
    return FleetManager(env, layout, traffic, config or DispatchConfig(), recorder, commands)


def spurs_data() -> dict[str, Any]:
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
    return data


@pytest.fixture(scope="module")
def spurs_layout(tmp_path_factory: pytest.TempPathFactory) -> Layout:
    """spurs_data as a layout."""
    return load_layout(write_yaml(tmp_path_factory.mktemp("spurs") / "spurs.yaml", spurs_data()))


def closed_pick_layout(folder: Path) -> Layout:
    """The spurs layout whose pickup only vehicle type `a` may serve."""
    data = spurs_data()
    for station in data["stations"]:
        if station["id"] == "PICK":
            station["allowed_types"] = ["a"]
    return load_layout(write_yaml(folder / "closed_pick.yaml", data))


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
    assert not fm.idle
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
    fm.cancel_charger_request(third, wait_3)
    fm.release_charger(spurs_layout.places["CHG_N"])
    assert not wait_3.triggered
    assert fm.charger_available() and [c.id for c in fm.chargers_free] == ["CHG_N"]


def test_a_charger_given_to_an_agv_that_gave_up_goes_back(spurs_layout: Layout) -> None:
    """An AGV that fails while its charger is given to it (or on its way to it over a slow
    command link) never comes: the charger goes back to the free ones."""
    fm = fleet_manager(spurs_layout)
    agv = StubAgv(0, "D")
    granted = fm.request_charger(agv)
    assert granted.triggered and [c.id for c in fm.chargers_free] == ["CHG_S"]
    fm.cancel_charger_request(agv, granted)
    assert sorted(c.id for c in fm.chargers_free) == ["CHG_N", "CHG_S"]

    env = simpy.Environment()  # the assign command takes its time on the CarriRo link
    recorder = Recorder(0.0, 3600.0)
    traffic = Traffic(env, spurs_layout, Motion(1.0, 0.5, 0.5, 0.3), recorder,
                      strategy=ReactivePolicy)
    commands = CommandPath.for_profile(env, "carriro-ad-plus", 0.0, np.random.default_rng(0),
                                       recorder)
    fm = FleetManager(env, spurs_layout, traffic, DispatchConfig(), recorder, commands)
    on_its_way = fm.request_charger(agv)
    assert [c.id for c in fm.chargers_free] == ["CHG_S"] and not on_its_way.triggered
    fm.cancel_charger_request(agv, on_its_way)
    env.run(until=10.0)
    assert not on_its_way.triggered
    assert sorted(c.id for c in fm.chargers_free) == ["CHG_N", "CHG_S"]
    assert not fm.charger_cancelled


def test_an_agv_failing_while_it_waits_for_a_charger_gives_it_up(spurs_layout: Layout) -> None:
    """Three AGVs at the charging threshold, two chargers: the one that waits fails (a
    scripted fault) while waiting; the chargers are all free again at the end."""
    scenario = make_scenario(
        duration_h=3, warmup_h=0, seed=3, dispatch={"park_idle": False},
        fleet={"size": 3, "vehicle": {"battery": {"initial_soc_pct": 32}}},
        demand={"rate_per_hour": 60}, incidents={"faults": [
            {"agv": 2, "at_s": 1000.0, "code": "E_999"}]})
    model = build_simulation(scenario, spurs_layout)
    model.env.run(until=scenario.duration_s)
    waits = [e for e in model.recorder.events if e.agv == 2 and e.time_s <= 1000.0
             and e.event == "not_dispatched" and e.detail == "waiting_for_charger"]
    assert waits, "AGV 2 was not waiting for a charger when it failed"
    held = [v.charger for v in model.vehicles if v.charger is not None]
    assert len(model.fleet.chargers_free) + len(held) == 2


def test_asking_for_a_charger_withdraws_the_agv_from_orders(spurs_layout: Layout) -> None:
    fm = fleet_manager(spurs_layout)
    agv = StubAgv(0, "D")
    fm.vehicle_idle(agv)
    assert list(fm.idle.values()) == [agv]
    fm.request_charger(agv)
    fm.submit(Order(0, 0.0, "PICK", "DROP"))
    assert not fm.idle and agv.orders == [] and len(fm.waiting) == 1


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
    assert all(not v.driver.held for v in run.vehicles)


def test_orders_are_never_lost(warehouse_layout: Layout) -> None:
    """Every order created is waiting, being served, or delivered at the end of a run."""
    scenario = make_scenario("warehouse.yaml", duration_h=2, warmup_h=0, seed=9,
                             fleet={"size": 6}, demand={"rate_per_hour": 200})
    model = build_simulation(scenario, warehouse_layout)
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


# ---- work conservation ---------------------------------------------------------------------


def test_an_idle_agv_that_cannot_take_a_waiting_order_gets_a_reason_on_changes_only(
        tiny_layout: Layout) -> None:
    fm = fleet_manager(tiny_layout)
    lost = StubAgv(0, "S1", fms_link=False)
    fm.status_changed(lost)  # Idle
    fm.vehicle_idle(lost)
    fm.env.run(until=10.0)
    assert lost.notes == []  # no order waits: nothing to explain
    fm.submit(Order(0, 10.0, "PICK", "DROP"))
    fm.env.run(until=20.0)
    fm.submit(Order(1, 20.0, "PICK", "DROP"))  # the reason goes on: not recorded again
    fm.env.run(until=30.0)
    assert lost.notes == [(NOT_DISPATCHED, "link_lost")]
    lost.fms_link = True
    fm.status_changed(lost)
    fm.link_restored()
    assert len(lost.orders) == 1 and len(fm.waiting) == 1
    lost.state = VehicleState.MOVING  # the AGV sets off with its order, in the same instant
    fm.status_changed(lost)
    fm.env.run(until=40.0)
    assert lost.notes[1:] == [(NOT_DISPATCHED_END, "link_lost")]


def test_an_idle_agv_with_orders_waiting_and_no_reason_stops_the_run(tiny_layout: Layout) -> None:
    """The invariant is checked in every run: an Idle AGV the fleet manager was told about,
    not offered for orders and held back by nothing, while an order waits, is a bug."""
    fm = fleet_manager(tiny_layout)
    forgotten = StubAgv(2, "S1")
    fm.status_changed(forgotten)
    fm.submit(Order(0, 0.0, "PICK", "DROP"))
    with pytest.raises(SimulationError, match=r"AGV 2 stands Idle at S1 while 1 orders wait"):
        fm.env.run(until=1.0)


def idle_unexplained_s(events: Sequence[EventRecord], queue_lengths: Sequence[tuple[float, int]],
                       end_s: float) -> tuple[float, float]:
    """An independent sweep over the run's records: (AGV-seconds Idle while an order waited
    with no not_dispatched reason open, AGV-seconds a reason was open while the AGV was not
    Idle or no order waited)."""
    changes: list[tuple[float, int, Any]] = [(t, i, n) for i, (t, n) in enumerate(queue_lengths)]
    changes += [(e.time_s, len(queue_lengths) + i, e) for i, e in enumerate(events)]
    changes.sort(key=lambda c: (c[0], c[1]))
    state: dict[int, str] = {}
    reason: dict[int, str | None] = {}
    queue = 0
    unexplained = stale = 0.0
    for k, (t, _, change) in enumerate(changes):
        if isinstance(change, int):
            queue = change
        elif change.event == NOT_DISPATCHED:
            reason[change.agv] = change.detail
        elif change.event == NOT_DISPATCHED_END:
            assert reason.get(change.agv) == change.detail, change
            reason[change.agv] = None
        else:
            state[change.agv] = change.to_state
        until = changes[k + 1][0] if k + 1 < len(changes) else end_s
        for agv, now in state.items():
            idle_waiting = now == "Idle" and queue > 0
            explained = reason.get(agv) is not None
            unexplained += (until - t) * (idle_waiting and not explained)
            stale += (until - t) * (explained and not idle_waiting)
    return unexplained, stale


def _recorded_reasons(events: Sequence[EventRecord]) -> set[str]:
    return {e.detail for e in events if e.event == NOT_DISPATCHED}


BATTERY_OFF = {"battery": "off"}
# one run per reason, each provoking it and nothing else (orders keep waiting in each)
REASON_RUNS: dict[NotDispatched, dict[str, Any]] = {
    # 3 AGVs start just above the 30 % threshold on a loop with 2 chargers: one waits
    NotDispatched.WAITING_FOR_CHARGER: {
        "duration_h": 3, "fleet": {"size": 3, "vehicle": {"battery": {"initial_soc_pct": 32}}},
        "demand": {"rate_per_hour": 90}},
    # charging off, just above P_050: the AGV soon may not move, and stands until E_201
    NotDispatched.BATTERY_LOW: {
        "duration_h": 2, "fleet": {"size": 1, "vehicle": {"battery": {"initial_soc_pct": 22}}},
        "charging": {"enabled": False}, "demand": {"rate_per_hour": 60}},
    # Req.Err.011: the FMS link lost for 5 minutes; the AGV waits at a tag (Idle)
    NotDispatched.LINK_LOST: {
        "duration_h": 1, "fleet": {"size": 1, "vehicle": BATTERY_OFF},
        "demand": {"rate_per_hour": 60},
        "incidents": {"link_losses": [{"agv": 0, "at_s": 600, "duration_s": 300}]}},
    # the fleet manager learns that an AGV is free at its next status poll, every 30 s
    NotDispatched.STATUS_POLL: {
        "duration_h": 1, "fleet": {"size": 2, "vehicle": BATTERY_OFF, "status_poll_s": 30},
        "demand": {"rate_per_hour": 90}},
    # every assign command takes its time over the CarriRo serial link (meanwhile the AGV
    # stands where it is: with park_idle it would set off for parking, Moving)
    NotDispatched.COMMAND_IN_TRANSIT: {
        "duration_h": 1, "fleet": {"size": 2, "vehicle": BATTERY_OFF,
                                   "command_profile": "carriro-ad-plus"},
        "dispatch": {"park_idle": False}, "demand": {"rate_per_hour": 90}},
    # admission: one AGV on the track at a time, the other two stand Idle in parking
    NotDispatched.ADMISSION_FULL: {
        "duration_h": 1, "fleet": {"size": 3, "vehicle": BATTERY_OFF},
        "dispatch": {"max_active_agvs": 1}, "demand": {"rate_per_hour": 90}},
    # two types, the pickup open to type a only (closed_pick_layout): b stands Idle
    NotDispatched.TYPE_NOT_ALLOWED: {
        "duration_h": 1, "fleet": {"vehicles": [
            {"type": "a", "count": 1, "vehicle": BATTERY_OFF},
            {"type": "b", "count": 1, "vehicle": BATTERY_OFF}]},
        "demand": {"rate_per_hour": 90}},
}


def test_every_reason_has_a_run_that_provokes_it() -> None:
    assert set(REASON_RUNS) == set(NotDispatched)


@pytest.mark.parametrize("reason", list(REASON_RUNS), ids=[r.value for r in REASON_RUNS])
def test_each_reason_for_not_dispatching_is_provoked_and_recorded(
        reason: NotDispatched, spurs_layout: Layout, tmp_path: Path) -> None:
    scenario = make_scenario(warmup_h=0, seed=3, **REASON_RUNS[reason])
    layout = spurs_layout  # the tiny loop with two chargers on spurs
    if reason is NotDispatched.TYPE_NOT_ALLOWED:
        layout = closed_pick_layout(tmp_path)
    run = simulate(scenario, layout)
    events = run.recorder.events
    assert _recorded_reasons(events) == {reason.value}
    figures = run_kpis(run)
    assert figures["idle_with_orders_waiting_pct"] > 0
    assert figures["idle_with_orders_waiting_pct_by_reason"][reason.value] == \
        pytest.approx(figures["idle_with_orders_waiting_pct"], abs=1e-5)
    assert idle_unexplained_s(events, run.recorder.queue_lengths, scenario.duration_s) == \
        pytest.approx((0.0, 0.0), abs=1e-6)
    unrecorded = [e for e in events if e.event not in (NOT_DISPATCHED, NOT_DISPATCHED_END)]
    assert idle_unexplained_s(unrecorded, run.recorder.queue_lengths,
                              scenario.duration_s)[0] > 0  # the check sees the idle time


def test_work_conservation_over_a_long_run_with_every_incident(spurs_layout: Layout) -> None:
    """24 h, 4 AGVs, 2 chargers, a status poll, the CarriRo command link, link losses, faults,
    free AGVs standing where they are: at every moment an AGV stands Idle while an order
    waits, a reason is open for it (the dispatch latency is zero: the poll and the command
    link are reasons), and a reason is open only then; the reasons add up to the KPI."""
    scenario = make_scenario(
        duration_h=24, warmup_h=1, seed=5,
        fleet={"size": 4, "status_poll_s": 5, "command_profile": "carriro-ad-plus"},
        dispatch={"park_idle": False}, demand={"rate_per_hour": 100},
        charging={"threshold_pct": 40},
        incidents={"link_loss_rate_per_h": 1.0, "link_loss_duration":
                   {"dist": "exponential", "mean_s": 60}, "mtbf_h": 10,
                   "transfer_failure_prob": 0.01, "cpu_reset": "operator"})
    run = simulate(scenario, spurs_layout)
    events = run.recorder.events
    assert _recorded_reasons(events) >= {"waiting_for_charger", "link_lost", "status_poll",
                                         "command_in_transit"}
    assert idle_unexplained_s(events, run.recorder.queue_lengths, scenario.duration_s) == \
        pytest.approx((0.0, 0.0), abs=1e-6)
    figures = run_kpis(run)
    by_reason = figures["idle_with_orders_waiting_pct_by_reason"]
    assert figures["idle_with_orders_waiting_pct"] > 0
    assert sum(by_reason.values()) == pytest.approx(figures["idle_with_orders_waiting_pct"],
                                                    abs=1e-4)


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
        for held in vehicle.driver.held + vehicle.driver.ahead:
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
