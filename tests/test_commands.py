"""The fleet manager's commands cost the real link's time (issue 4 item 6)."""

from __future__ import annotations

import itertools

import pytest

from agv_model.fleet_commands import CommandTiming
from fleet_sim.analysis.kpis import run_kpis
from fleet_sim.config.layout import Layout
from fleet_sim.config.trace import TraceOrder
from fleet_sim.errors import InputError
from fleet_sim.sim.engine import simulate

from .conftest import DROP_S, HALF_LOOP_S, K_TO_P_S, PICK_S, make_scenario

ONE_ORDER = [TraceOrder(100.0, "PICK", "DROP")]


def lead_time(layout: Layout, **fleet: object) -> float:
    scenario = make_scenario(duration_h=0.2, warmup_h=0.0, fleet={"size": 1, **fleet},
                             demand={"kind": "trace", "trace_csv": "x.csv"})
    order = simulate(scenario, layout, ONE_ORDER).recorder.orders[0]
    assert order.delivered_s is not None
    return order.delivered_s - order.created_s


@pytest.mark.parametrize("profile", ["carriro-ad-plus", "ktm-02", "agv-3"])
def test_an_assignment_costs_one_assign_round_trip(tiny_layout: Layout, profile: str) -> None:
    hand = K_TO_P_S + PICK_S + HALF_LOOP_S + DROP_S
    assert lead_time(tiny_layout) == pytest.approx(hand, abs=1e-9)
    assign_s = CommandTiming.for_profile(profile).round_trip_s("assign")
    assert assign_s > 0.005
    assert lead_time(tiny_layout, command_profile=profile) == pytest.approx(hand + assign_s,
                                                                            abs=1e-9)


def test_status_polling_delays_what_the_fleet_manager_knows(tiny_layout: Layout) -> None:
    """One AGV with orders always waiting: each new order reaches it only after the next poll
    has shown it free, then one assign round trip."""
    timing = CommandTiming.for_profile("carriro-ad-plus")
    poll_s = 20.0
    scenario = make_scenario(duration_h=1.0, warmup_h=0.0,
                             fleet={"size": 1, "command_profile": "carriro-ad-plus",
                                    "status_poll_s": poll_s},
                             demand={"kind": "trace", "trace_csv": "x.csv"})
    run = simulate(scenario, tiny_layout, [TraceOrder(0.0, "PICK", "DROP")] * 12)
    done = sorted(o.delivered_s for o in run.recorder.orders if o.delivered_s is not None)
    gaps = [b - a for a, b in itertools.pairwise(done)]
    assert len(gaps) >= 5
    cycle = 2 * HALF_LOOP_S + PICK_S + DROP_S
    least = cycle + timing.reply_s("status") + timing.round_trip_s("assign")
    for gap in gaps:
        assert least - 1e-9 <= gap <= least + poll_s + 1e-9
    assert sum(gaps) / len(gaps) > least + 1.0  # waiting for polls costs time on average
    figures = run_kpis(run)
    assert figures["commands_sent"] == len(run.recorder.orders)  # one assign each, no retries
    assert figures["command_retries"] == 0


def test_polling_period_shows_in_lead_times(tiny_layout: Layout) -> None:
    def mean_lead(poll_s: float) -> float:
        scenario = make_scenario(duration_h=6, warmup_h=0.5, seed=4, fleet={
            "size": 2, "command_profile": "rss-agv-001", "status_poll_s": poll_s},
            demand={"rate_per_hour": 45})
        run = simulate(scenario, tiny_layout)
        value = run_kpis(run)["lead_time_mean_s"]
        assert isinstance(value, float)
        return value

    assert mean_lead(0.0) < mean_lead(10.0) < mean_lead(60.0)


def test_unknown_command_profile_is_an_input_error() -> None:
    with pytest.raises(InputError, match=r"fleet.command_profile: got 'carrot'; expected one "
                                         r"of .*carriro-ad-plus"):
        make_scenario(fleet={"command_profile": "carrot"})
