"""Dispatch policies as strategy objects, and as the fleet manager uses them."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from fleet_sim.config.layout import Layout
from fleet_sim.config.trace import TraceOrder
from fleet_sim.sim.agents.dispatch import POLICIES, FirstComeFirstServed, NearestIdle
from fleet_sim.sim.engine import build_simulation, simulate

from .conftest import make_scenario


@dataclass(frozen=True)
class Agv:
    id: int
    dispatch_node: str


TIMES = {("X", "P"): 30.0, ("Y", "P"): 10.0, ("Z", "P"): 10.0}


def travel(src: str, dest: str) -> float:
    return TIMES[(src, dest)]


def test_nearest_idle_takes_the_shortest_trip_then_the_lowest_id() -> None:
    ready = [Agv(4, "X"), Agv(7, "Z"), Agv(2, "Y")]
    assert NearestIdle().choose(ready, "P", travel) == Agv(2, "Y")
    assert NearestIdle().choose([Agv(4, "X"), Agv(7, "Z")], "P", travel) == Agv(7, "Z")


def test_fcfs_takes_the_agv_idle_longest() -> None:
    ready = [Agv(4, "X"), Agv(7, "Z"), Agv(2, "Y")]
    assert FirstComeFirstServed().choose(ready, "P", travel) == Agv(4, "X")


def test_the_scenario_names_the_policy(tiny_layout: Layout) -> None:
    assert set(POLICIES) == {"nearest_idle", "fcfs"}
    scenario = make_scenario(duration_h=0.1, warmup_h=0, dispatch={"policy": "fcfs"},
                             demand={"rate_per_hour": 0})
    assert isinstance(build_simulation(scenario, tiny_layout).fleet.policy, FirstComeFirstServed)


@pytest.mark.parametrize("policy,expected_agv", [("nearest_idle", 1), ("fcfs", 0)])
def test_dispatch_policies_in_a_run(tiny_layout: Layout, policy: str, expected_agv: int) -> None:
    """AGV 0 stands at N1 (far from the pickup), AGV 1 at S1 (4 m before it). Both become idle
    at the same moment; AGV 0 first."""
    scenario = make_scenario(duration_h=0.1, warmup_h=0, fleet={"size": 2,
                             "start_nodes": ["N1", "S1"]}, dispatch={"policy": policy,
                             "park_idle": False}, demand={"kind": "trace", "trace_csv": "x.csv"})
    run = simulate(scenario, tiny_layout, [TraceOrder(60.0, "PICK", "DROP")])
    assert run.recorder.orders[0].agv == expected_agv
