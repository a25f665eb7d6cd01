"""Multi-stop orders (fleet_sim.config.chains): chains of stops from flows and traces, driven
stop by stop, timed by hand on the tiny loop, given back after an unloaded failure, and the
plain order unchanged."""

from __future__ import annotations

import copy
from collections import Counter
from pathlib import Path

import pytest
import yaml

from fleet_sim.analysis.tables import ORDER_COLUMNS, STOPS_COLUMN, events_table, orders_table
from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.scenario import check_against_layout, parse_scenario, resolved
from fleet_sim.config.trace import TraceOrder, load_trace
from fleet_sim.errors import InputError
from fleet_sim.sim.engine import simulate
from fleet_sim.sim.estimate import Estimate, analytic_estimate

from .conftest import DROP_S, HALF_LOOP_S, K_TO_P_S, LAYOUTS, PICK_S, make_scenario
from .test_demand import arrivals

CHAIN = ("A", "B", "C", "D")


def four_station_loop(folder: Path, a_types: tuple[str, ...] = ()) -> Path:
    """The tiny loop with pickups A (at N3) and C (at S3), dropoffs B (at S1) and D (at N1),
    fixed handling times; `a_types`: the only vehicle types station A admits."""
    data = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text(encoding="utf-8"))
    data["name"] = "four_stations"
    kinds = {"S1": "station", "S3": "station", "N3": "station", "N1": "station"}
    data["nodes"] = [{**n, "kind": kinds.get(n["id"], n.get("kind", "tag"))}
                     for n in data["nodes"] if n["id"] not in ("P", "D")] + [
        {"id": "P", "x": 8, "y": 0}, {"id": "D", "x": 8, "y": 8}]
    data["stations"] = [
        {"id": "A", "kind": "pickup", "nodes": ["N3"], "handling": {"dist": "fixed", "mean_s": 10},
         **({"allowed_types": list(a_types)} if a_types else {})},
        {"id": "B", "kind": "dropoff", "nodes": ["S1"], "handling": {"dist": "fixed",
                                                                      "mean_s": 11}},
        {"id": "C", "kind": "pickup", "nodes": ["S3"], "handling": {"dist": "fixed", "mean_s": 12}},
        {"id": "D", "kind": "dropoff", "nodes": ["N1"], "handling": {"dist": "fixed",
                                                                      "mean_s": 13}},
    ]
    path = folder / "four.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def arrivals_at_stops(run_events: list[tuple[str, str, str]]) -> list[tuple[str, str]]:
    return [(node, detail.split()[-1]) for event, node, detail in run_events
            if event in ("Event_Arrived_Pickup", "Event_Arrived_Dropoff")]


def test_a_four_stop_chain_is_driven_stop_by_stop_in_order(tmp_path: Path) -> None:
    """A at N3, B at S1, C at S3, D at N1: on the one-way loop the AGV passes S1 and S3 on its
    way to A, yet it stops at A, B, C, D in chain order, loaded only from each pickup to the
    dropoff after it, with Loading/Unloading sub-states at every stop."""
    layout = load_layout(four_station_loop(tmp_path))
    scenario = make_scenario("four.yaml", tmp_path, duration_h=0.2, warmup_h=0,
                             fleet={"size": 1}, dispatch={"park_idle": False},
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    run = simulate(scenario, layout, [TraceOrder(10.0, "A", "D", CHAIN)])
    table = events_table(run.recorder)
    rows = list(zip(table["event"], table["node"], table["detail"], strict=True))
    assert arrivals_at_stops(rows) == [("N3", "A"), ("S1", "B"), ("S3", "C"), ("N1", "D")]
    states = [(e, f, t) for e, f, t, d in zip(table["event"], table["from_state"],
                                              table["to_state"], table["detail"], strict=True)
              if e.startswith("Event_") and "order 0" in d]
    assert [s[0] for s in states] == [
        "Event_Transport_Order", "Event_Arrived_Pickup", "Event_Load_Complete",
        "Event_Arrived_Dropoff", "Event_Next_Stop", "Event_Arrived_Pickup",
        "Event_Load_Complete", "Event_Arrived_Dropoff", "Event_Unload_Complete"]
    assert ("Event_Next_Stop", "Unloading", "Moving") in states
    assert Counter(e for e in table["event"] if e in ("L_Transfer", "U_Transfer")) == \
        {"L_Transfer": 2, "U_Transfer": 2}
    order = run.recorder.orders[0]
    assert order.delivered_s is not None and order.stops_done == 4
    # first pickup and last dropoff timestamps; the columns name the chain's ends
    first_pick = table[table["event"] == "Event_Arrived_Pickup"]["time_s"].iloc[0]
    last_drop = table[table["event"] == "Event_Arrived_Dropoff"]["time_s"].iloc[-1]
    assert order.pickup_arrival_s == first_pick and order.dropoff_arrival_s == last_drop
    frame = orders_table(run.recorder)
    assert list(frame.columns) == [*ORDER_COLUMNS, STOPS_COLUMN]
    assert frame.loc[0, STOPS_COLUMN] == "A>B>C>D"
    assert (frame.loc[0, "pickup"], frame.loc[0, "dropoff"]) == ("A", "D")


def test_chain_lead_time_is_the_hand_computed_sum(tiny_layout: Layout) -> None:
    """PICK>DROP>PICK>DROP with one AGV on the tiny loop: out of parking to P, pick, half a
    loop to D, drop, half a loop back to P, pick, half a loop to D, drop."""
    scenario = make_scenario(duration_h=0.2, warmup_h=0.0, fleet={"size": 1},
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    chain = ("PICK", "DROP", "PICK", "DROP")
    run = simulate(scenario, tiny_layout, [TraceOrder(100.0, "PICK", "DROP", chain)])
    order = run.recorder.orders[0]
    expected = K_TO_P_S + 3 * HALF_LOOP_S + 2 * (PICK_S + DROP_S)
    assert expected == pytest.approx(227.1933, abs=1e-4)  # 17.3133 + 3 x 32.6267 + 2 x 56
    assert order.delivered_s is not None
    assert order.delivered_s - order.created_s == pytest.approx(expected, abs=1e-9)
    assert order.pickup_arrival_s == pytest.approx(100.0 + K_TO_P_S, abs=1e-9)
    assert order.picked_s == pytest.approx(100.0 + K_TO_P_S + PICK_S, abs=1e-9)
    assert order.dropoff_arrival_s == pytest.approx(order.delivered_s - DROP_S, abs=1e-9)
    frame = orders_table(run.recorder)
    assert frame.loc[0, "lead_time_s"] == pytest.approx(expected, abs=1e-9)


def test_a_two_stop_chain_is_the_plain_order(tiny_layout: Layout) -> None:
    """A flow `stops: [PICK, DROP]` gives the very run of `from: PICK, to: DROP`."""
    def tables(flow: dict[str, object]) -> tuple[bytes, bytes]:
        scenario = make_scenario(duration_h=0.5, warmup_h=0, fleet={"size": 2},
                                 demand={"rate_per_hour": 50, "flows": [flow]})
        run = simulate(scenario, tiny_layout)
        return (events_table(run.recorder).to_json().encode(),
                orders_table(run.recorder).to_json().encode())

    plain = tables({"from": "PICK", "to": "DROP"})
    assert plain == tables({"stops": ["PICK", "DROP"]})
    assert b"stops" not in plain[1]


def test_flows_generate_chains_at_their_rate(warehouse_layout: Layout) -> None:
    """Weights 1 : 3 between a 4-stop chain and a plain flow: a quarter of the orders are
    chains, within 4 standard deviations, each with a handling time per stop."""
    chain = ("PICK01", "DROP01", "PICK02", "DROP07")
    orders = arrivals(warehouse_layout, 10 * 3600, layout_file="warehouse.yaml",
                      rate_per_hour=3600, flows=[
                          {"stops": list(chain), "weight": 1.0},
                          {"from": "PICK01", "to": "DROP01", "weight": 3.0}])
    chains = [o for o in orders if o.stops]
    assert all(o.stops == chain and (o.pickup, o.dropoff) == ("PICK01", "DROP07")
               and len(o.stop_handling_s) == 4 for o in chains)
    assert all(not o.stops and (o.pickup, o.dropoff) == ("PICK01", "DROP01")
               for o in orders if not o.stops)
    n = len(orders)
    assert abs(n - 36_000) < 4 * (36_000 ** 0.5)
    assert abs(len(chains) / n - 0.25) < 4 * (0.25 * 0.75 / n) ** 0.5


def test_trace_chains_are_read(tmp_path: Path, tiny_layout: Layout) -> None:
    """One row per order: a `stops` cell makes a chain (pickup/dropoff cells empty or its
    ends), an empty one a plain order."""
    path = tmp_path / "orders.csv"
    path.write_text("time_s,pickup,dropoff,stops\n"
                    "5,PICK,DROP,\n"
                    "1,,,PICK>DROP>PICK>DROP\n"
                    "3,PICK,DROP, PICK > DROP \n", encoding="utf-8")
    assert load_trace(path, tiny_layout) == [
        TraceOrder(1.0, "PICK", "DROP", ("PICK", "DROP", "PICK", "DROP")),
        TraceOrder(3.0, "PICK", "DROP", ("PICK", "DROP")),
        TraceOrder(5.0, "PICK", "DROP")]
    path.write_text("time_s,stops\n2,PICK>DROP>PICK>DROP>PICK>DROP\n", encoding="utf-8")
    assert [len(o.stops) for o in load_trace(path, tiny_layout)] == [6]


def test_a_bad_chain_is_one_clear_line(tmp_path: Path, tiny_layout: Layout) -> None:
    path = tmp_path / "orders.csv"
    path.write_text("time_s,stops\n1,PICK>DROP>DROP>PICK\n", encoding="utf-8")
    with pytest.raises(InputError) as info:
        load_trace(path, tiny_layout)
    assert str(info.value) == (
        f"{path}: row 2.stops[2]: got 'DROP'; expected a pickup station of layout tiny_loop "
        "(PICK); stops alternate pickup, dropoff, starting with a pickup")
    scenario = make_scenario(demand={"flows": [{"stops": ["PICK", "DROP", "PICK", "NOPE"]}]})
    with pytest.raises(InputError, match=r"demand.flows\[0\].stops\[3\]: got 'NOPE'; expected "
                                         r"a dropoff station of layout tiny_loop \(DROP\)"):
        check_against_layout(scenario, tiny_layout, "s.yaml")


def test_the_resolved_config_writes_chains_and_reloads_to_the_same_scenario() -> None:
    scenario = make_scenario(demand={"flows": [
        {"stops": ["PICK", "DROP", "PICK", "DROP"], "weight": 2},
        {"from": "PICK", "to": "DROP"}]})
    plain = resolved(scenario)
    assert plain["demand"]["flows"] == [
        {"weight": 2.0, "stops": ["PICK", "DROP", "PICK", "DROP"]},
        {"from": "PICK", "to": "DROP", "weight": 1.0}]
    again = parse_scenario(copy.deepcopy(plain), "resolved.yaml", LAYOUTS)
    assert again.demand == scenario.demand


def test_an_agv_that_fails_between_stops_gives_the_rest_of_the_chain_back(
        tmp_path: Path) -> None:
    """A scripted fault while the AGV drives empty from B to C: the order goes back to the
    queue with stops C and D (reassigned once); the other AGV serves them, A and B are not
    visited again; the order keeps its first pickup's timestamps. A fault while loaded (from A
    to B) loses the order."""
    layout = load_layout(four_station_loop(tmp_path))

    def run(fault_s: float | None) -> tuple[list[tuple[int, str]], object]:
        faults = [] if fault_s is None else [{"agv": 0, "at_s": fault_s}]
        scenario = make_scenario("four.yaml", tmp_path, duration_h=0.3, warmup_h=0,
                                 fleet={"size": 2}, incidents={"faults": faults},
                                 demand={"kind": "trace", "trace_csv": "unused.csv"})
        result = simulate(scenario, layout, [TraceOrder(10.0, "A", "D", CHAIN)])
        table = events_table(result.recorder)
        stops = [(int(a), d.split()[-1]) for e, a, d in zip(
            table["event"], table["agv"], table["detail"], strict=True)
            if e in ("Event_Arrived_Pickup", "Event_Arrived_Dropoff")]
        return stops, result.recorder.orders[0]

    clean, _ = run(None)
    assert clean == [(0, "A"), (0, "B"), (0, "C"), (0, "D")]
    scenario = make_scenario("four.yaml", tmp_path, duration_h=0.3, warmup_h=0,
                             fleet={"size": 2},
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    table = events_table(simulate(scenario, layout, [TraceOrder(10.0, "A", "D", CHAIN)])
                         .recorder)
    next_stop = float(table[table["event"] == "Event_Next_Stop"]["time_s"].iloc[0])
    first_load = float(table[table["event"] == "Event_Load_Complete"]["time_s"].iloc[0])

    stops, order = run(next_stop + 1.0)
    assert stops == [(0, "A"), (0, "B"), (1, "C"), (1, "D")]
    assert order.reassigned == 1 and order.delivered_s is not None  # type: ignore[attr-defined]
    assert order.agv == 1 and order.pickup_node == "N3"  # type: ignore[attr-defined]

    stops, order = run(first_load + 1.0)
    assert stops == [(0, "A")]
    assert order.failure == "E_999" and order.delivered_s is None  # type: ignore[attr-defined]


def test_only_a_type_that_may_serve_every_stop_gets_a_chain(tmp_path: Path) -> None:
    """Station A admits type `wide` only: the chain A>B>C>D goes to the wide AGV even when the
    narrow one stands nearer; a flow whose chain no type may serve is refused when read."""
    layout = load_layout(four_station_loop(tmp_path, ("wide",)))
    fleet = {"vehicles": [{"type": "narrow", "count": 1}, {"type": "wide", "count": 1}],
             "start_nodes": ["E1", "SW"]}
    scenario = make_scenario("four.yaml", tmp_path, duration_h=0.2, warmup_h=0, fleet=fleet,
                             dispatch={"park_idle": False},
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    run = simulate(scenario, layout, [TraceOrder(10.0, "A", "D", CHAIN),
                                      TraceOrder(10.0, "C", "B")])
    served = {o.stops or (o.pickup, o.dropoff): o.agv for o in run.recorder.orders}
    assert served == {CHAIN: 1, ("C", "B"): 0}
    narrow = make_scenario("four.yaml", tmp_path, fleet={
        "vehicles": [{"type": "narrow", "count": 1}]},
        demand={"flows": [{"stops": list(CHAIN)}]})
    with pytest.raises(InputError, match=r"demand.flows\[0\].stops: got 'A -> B -> C -> D'; "
                                         r"expected stops that one vehicle type"):
        check_against_layout(narrow, layout, "s.yaml")


def test_the_analytic_estimate_counts_every_leg_and_stop_of_a_chain(
        tiny_layout: Layout) -> None:
    """PICK>DROP>PICK>DROP on the tiny loop is two plain orders' work: twice the loaded travel,
    twice the empty travel (one leg inside the chain, one to the next order), twice the
    handling; so one AGV carries half as many chains as plain orders."""
    def estimate(flow: dict[str, object]) -> Estimate:
        return analytic_estimate(make_scenario(demand={"flows": [flow]}), tiny_layout)

    plain = estimate({"from": "PICK", "to": "DROP"})
    chain = estimate({"stops": ["PICK", "DROP", "PICK", "DROP"]})
    assert chain.loaded_travel_s == pytest.approx(2 * plain.loaded_travel_s, abs=1e-9)
    assert chain.empty_travel_s == pytest.approx(2 * plain.empty_travel_s, abs=1e-9)
    assert chain.handling_s == pytest.approx(2 * plain.handling_s, abs=1e-9) == 100.0
    assert chain.capacity_per_agv_per_hour == pytest.approx(
        plain.capacity_per_agv_per_hour / 2, abs=1e-9)
