"""Order arrivals (fleet_sim.sim.demand): Poisson thinning under a time-of-day profile, flows
by weight, trace replay, and common random numbers across fleet sizes and policies."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import simpy

from fleet_sim.config.layout import Layout
from fleet_sim.config.trace import TraceOrder
from fleet_sim.model.records import Order
from fleet_sim.sim.demand import Demand, resolved_flows
from fleet_sim.sim.engine import build_simulation, simulate

from .conftest import make_scenario


def arrivals(layout: Layout, until_s: float, start_h: float = 0.0, seed: int = 1,
             layout_file: str = "tiny_loop.yaml", **demand: object) -> list[Order]:
    """Orders a Demand alone creates up to `until_s`."""
    config = make_scenario(layout_file, demand=demand).demand
    env = simpy.Environment()
    orders: list[Order] = []
    arrival_seed, handling_seed = np.random.SeedSequence(seed).spawn(2)
    Demand(env, layout, config, start_h, orders.append, np.random.default_rng(arrival_seed),
           np.random.default_rng(handling_seed)).start()
    env.run(until=until_s)
    return orders


def test_without_flows_every_pickup_goes_to_every_dropoff(tiny_layout: Layout,
                                                         warehouse_layout: Layout) -> None:
    tiny = make_scenario().demand
    assert resolved_flows(tiny, tiny_layout) == [("PICK", "DROP", 1.0)]
    flows = resolved_flows(make_scenario("warehouse.yaml").demand, warehouse_layout)
    assert len(flows) == 6 * 12 == len(set(flows))
    assert {f[0] for f in flows} == {f"PICK{i:02d}" for i in range(1, 7)}
    assert {f[1] for f in flows} == {f"DROP{i:02d}" for i in range(1, 13)}
    assert {f[2] for f in flows} == {1.0}


def test_poisson_demand_rate_and_time_of_day_profile(tiny_layout: Layout) -> None:
    """Arrivals follow rate x multiplier: 30/h from 00:00, 90/h from 02:00 (x3)."""
    scenario = make_scenario(duration_h=4, warmup_h=0, seed=8, fleet={"size": 1},
                             demand={"rate_per_hour": 30, "profile": [
                                 {"from_h": 0, "multiplier": 1.0},
                                 {"from_h": 2, "multiplier": 3.0}]})
    model = build_simulation(scenario, tiny_layout)
    model.env.run(until=4 * 3600)
    times = [o.created_s for o in model.recorder.orders]
    low = sum(1 for t in times if t < 7200)
    high = len(times) - low
    # Poisson counts: 60 and 180 expected; 4 standard deviations either side
    assert abs(low - 60) < 4 * math.sqrt(60)
    assert abs(high - 180) < 4 * math.sqrt(180)


def test_a_zero_multiplier_hour_gets_no_order_and_the_profile_follows_the_clock(
        tiny_layout: Layout) -> None:
    """Profile by clock hour: 1 from 00:00, 0 from 01:00, 2 from 02:00, repeating daily. From
    a 00:00 start, the second simulated hour is empty; from a 01:00 start, the first."""
    profile = [{"from_h": 0, "multiplier": 1.0}, {"from_h": 1, "multiplier": 0.0},
               {"from_h": 2, "multiplier": 2.0}]
    at_midnight = [o.created_s for o in arrivals(tiny_layout, 3 * 3600, rate_per_hour=600,
                                                 profile=profile)]
    hours = Counter(int(t // 3600) for t in at_midnight)
    assert hours[1] == 0
    assert abs(hours[0] - 600) < 4 * math.sqrt(600)
    assert abs(hours[2] - 1200) < 4 * math.sqrt(1200)
    at_one = [o.created_s for o in arrivals(tiny_layout, 3 * 3600, start_h=1.0,
                                            rate_per_hour=600, profile=profile)]
    hours = Counter(int(t // 3600) for t in at_one)
    assert hours[0] == 0 and hours[1] > 1000 and hours[2] > 400
    # 23:00 start: 23:00-24:00 is the 2x period, then the day starts over at 1x
    late = Counter(int(o.created_s // 3600) for o in arrivals(
        tiny_layout, 3 * 3600, start_h=23.0, rate_per_hour=600, profile=profile))
    assert late[0] > 1000 and 400 < late[1] < 800 and late[2] == 0


def test_flows_are_chosen_by_weight(warehouse_layout: Layout) -> None:
    """Weights 3 : 1 give 75 % and 25 % of the orders, within 4 standard deviations."""
    orders = arrivals(warehouse_layout, 10 * 3600, layout_file="warehouse.yaml",
                      rate_per_hour=3600, flows=[
                          {"from": "PICK01", "to": "DROP01", "weight": 3.0},
                          {"from": "PICK02", "to": "DROP07", "weight": 1.0}])
    pairs = Counter((o.pickup, o.dropoff) for o in orders)
    assert set(pairs) == {("PICK01", "DROP01"), ("PICK02", "DROP07")}
    n = len(orders)
    assert abs(n - 36_000) < 4 * math.sqrt(36_000)
    share = pairs[("PICK01", "DROP01")] / n
    assert abs(share - 0.75) < 4 * math.sqrt(0.75 * 0.25 / n)


def test_trace_replay_creates_orders_at_their_times(tiny_layout: Layout) -> None:
    scenario = make_scenario(duration_h=0.5, warmup_h=0, fleet={"size": 2},
                             demand={"kind": "trace", "trace_csv": "x.csv"})
    trace = [TraceOrder(t, "PICK", "DROP") for t in (10.0, 10.0, 250.5, 900.0)]
    run = simulate(scenario, tiny_layout, trace)
    assert [o.created_s for o in run.recorder.orders] == [10.0, 10.0, 250.5, 900.0]


def test_common_random_numbers_across_fleet_sizes_and_policies(
        warehouse_layout: Layout) -> None:
    """Runs that differ only in fleet size or dispatch policy see the same orders, with the
    same (random, triangular) handling times; another seed sees other orders."""
    def orders(seed: int, size: int, policy: str) -> list[tuple[float, str, str, float, float]]:
        scenario = make_scenario("warehouse.yaml", duration_h=1, warmup_h=0, seed=seed,
                                 fleet={"size": size}, dispatch={"policy": policy},
                                 demand={"rate_per_hour": 120})
        model = build_simulation(scenario, warehouse_layout)
        model.env.run(until=3600)
        return [(o.created_s, o.pickup, o.dropoff, o.pickup_handling_s, o.dropoff_handling_s)
                for o in model.recorder.orders]

    base = orders(5, 3, "nearest_idle")
    assert len(base) > 80
    assert len({o[3] for o in base}) == len(base)  # handling times really are drawn
    assert all(15.0 <= o[3] <= 35.0 for o in base)
    assert orders(5, 12, "nearest_idle") == base
    assert orders(5, 3, "fcfs") == base
    assert orders(6, 3, "nearest_idle")[:5] != base[:5]
