"""The analytic estimate on the tiny loop, where travel is known by hand (see test_engine: half
the loop takes 32.6267 s from standstill to standstill), and demand rates from a profile or a
trace worked out by hand; the bottleneck and critical fleet (admission `auto`) by hand on the
tiny loop, and what they are on the bundled sites."""

from __future__ import annotations

import math

import pytest

from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import load_layout_for, load_scenario
from fleet_sim.config.trace import TraceOrder
from fleet_sim.sim.estimate import analytic_estimate, bottleneck, demand_rates

from .conftest import ROOT, make_scenario
from .test_engine import HALF_LOOP_S


def test_analytic_estimate_is_the_hand_computed_cycle(tiny_layout: Layout) -> None:
    scenario = load_scenario(ROOT / "experiments" / "tiny_loop.yaml",
                             {"demand.rate_per_hour": 45, "warmup_h": 0.5, "duration_h": 4})
    estimate = analytic_estimate(scenario, tiny_layout)
    assert estimate.loaded_travel_s == pytest.approx(HALF_LOOP_S, abs=1e-9)
    assert estimate.empty_travel_s == pytest.approx(HALF_LOOP_S, abs=1e-9)
    assert estimate.handling_s == 50.0  # 20 s pick + 30 s drop
    assert estimate.cycle_s == pytest.approx(115.2533, abs=1e-4)
    assert estimate.capacity_per_agv_per_hour == pytest.approx(3600 / 115.2533, rel=1e-6)
    assert estimate.agvs == pytest.approx(45 * 115.2533 / 3600, rel=1e-6)  # 1.44
    assert estimate.minimum == 2
    half = analytic_estimate(scenario, tiny_layout, availability=0.5)
    assert half.agvs == pytest.approx(2 * 45 * 115.2533 / 3600, rel=1e-6)


def test_trace_flows_set_the_estimate(tiny_layout: Layout) -> None:
    scenario = make_scenario(duration_h=2, warmup_h=0,
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    # 3 orders in 2 h: 1.5 /h on average; 2 in the first hour, 1 in the second: peak 2 /h
    trace = [TraceOrder(100.0, "PICK", "DROP"), TraceOrder(200.0, "PICK", "DROP"),
             TraceOrder(4000.0, "PICK", "DROP")]
    estimate = analytic_estimate(scenario, tiny_layout, trace=trace)
    assert (estimate.demand_per_hour, estimate.peak_demand_per_hour) == (1.5, 2.0)
    assert estimate.cycle_s == pytest.approx(2 * HALF_LOOP_S + 50.0, abs=1e-9)
    assert estimate.agvs_at_peak == pytest.approx(2.0 * estimate.cycle_s / 3600, rel=1e-9)


def test_demand_rates_follow_the_time_of_day_profile() -> None:
    profile = [{"from_h": 0, "multiplier": 1.0}, {"from_h": 10, "multiplier": 2.0}]
    # from 08:00 for 4 h: 2 h at x1, 2 h at x2 -> 60 x 1.5 = 90 /h on average, 120 at the peak
    scenario = make_scenario(duration_h=4, warmup_h=0, start_h=8.0,
                             demand={"rate_per_hour": 60, "profile": profile})
    assert demand_rates(scenario) == pytest.approx((90.0, 120.0))
    # the warm-up (08:00-09:00) is not measured: 1 h at x1, 2 h at x2 -> 60 x 5/3 = 100 /h
    scenario = make_scenario(duration_h=4, warmup_h=1, start_h=8.0,
                             demand={"rate_per_hour": 60, "profile": profile})
    assert demand_rates(scenario) == pytest.approx((100.0, 120.0))


def test_the_bottleneck_is_the_station_that_holds_an_agv_longest(tiny_layout: Layout) -> None:
    """Tiny loop, one way round, 4 m between tags at 1 m/s, AGVs 1 m long with 0.5 m gaps: the
    drop-off D is held 30 s of handling plus, from the start of the hop before the hop into it
    (the driver's look-ahead takes it then), until the body has cleared it ((4 + 4 + 1.5) / 1
    s) per order; the pickup P less. The critical fleet is the cycle over D's 39.5 s, rounded
    up: 3 AGVs."""
    scenario = load_scenario(ROOT / "experiments" / "tiny_loop.yaml", {})
    neck = bottleneck(scenario, tiny_layout)
    assert neck.resource == "node D"
    assert neck.busy_s_per_order == pytest.approx(30 + (4 + 4 + 1.5) / 1.0, abs=1e-9)
    assert neck.cycle_s == pytest.approx(115.2533, abs=1e-4)
    assert neck.critical_fleet == 3  # 115.25 / 39.5 = 2.92
    assert neck.orders_per_hour == pytest.approx(3600 / 39.5)
    slower = load_scenario(ROOT / "experiments" / "tiny_loop.yaml",
                           {"fleet.vehicle.min_gap_m": 2.5})
    assert bottleneck(slower, tiny_layout).busy_s_per_order == pytest.approx(41.5)


def test_a_corridor_one_agv_at_a_time_is_the_warehouse_bottleneck() -> None:
    """The warehouse's stations sit in two-way aisles (corridors, one AGV at a time): the
    busiest is a corridor, and it, not any node, sets the critical fleet; the all one-way
    fulfilment centre has no corridor, and its critical fleet is hundreds of AGVs (246: the
    busiest node, held from the hop before it, 2.1 s per order)."""
    found = {}
    for name in ("warehouse_shift", "fulfilment_shift"):
        path = ROOT / "experiments" / f"{name}.yaml"
        scenario = load_scenario(path, {})
        found[name] = bottleneck(scenario, load_layout_for(scenario, path))
    warehouse = found["warehouse_shift"]
    assert warehouse.resource.startswith("corridor ")
    assert warehouse.critical_fleet == math.ceil(warehouse.cycle_s / warehouse.busy_s_per_order
                                                 - 1e-6)
    assert 15 <= warehouse.critical_fleet <= 25
    assert found["fulfilment_shift"].resource.startswith("node ")
    assert 200 < found["fulfilment_shift"].critical_fleet < 300
