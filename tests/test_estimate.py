"""The analytic estimate on the tiny loop, where travel is known by hand (see test_engine: half
the loop takes 32.6267 s from standstill to standstill), and demand rates from a profile or a
trace worked out by hand."""

from __future__ import annotations

import pytest

from fleet_sim.analysis.estimate import analytic_estimate, demand_rates
from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import load_scenario
from fleet_sim.config.trace import TraceOrder

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
