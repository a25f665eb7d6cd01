"""The traffic policies by name (`traffic.policy`), as fleet_sim.sim.agents.dispatch.POLICIES
names the dispatch policies: each makes its policy for the `Traffic` it serves."""

from __future__ import annotations

from collections.abc import Callable

from fleet_sim.sim.traffic.avoiding import AvoidingPolicy
from fleet_sim.sim.traffic.control import Traffic
from fleet_sim.sim.traffic.policy import TrafficPolicy
from fleet_sim.sim.traffic.reactive import ReactivePolicy

POLICIES: dict[str, Callable[[Traffic], TrafficPolicy]] = {
    "reactive": ReactivePolicy,
    "avoiding": AvoidingPolicy,
}
