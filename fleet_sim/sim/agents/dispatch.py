"""Dispatch policies: which idle AGV gets the order at the head of the queue.

A policy is an object handed to the fleet manager (like Ciw's routing and deadlock strategies);
scenario `dispatch.policy` names one of `POLICIES`. Both bundled policies serve orders oldest
first; they differ only in the AGV they pick among those ready (idle, with an FMS link), which
the fleet manager lists in the order they offered themselves.

* ``nearest_idle``: the shortest free-flow travel time from where the AGV is committed to
  (`dispatch_node`) to the order's pickup; ties: lowest AGV id.
* ``fcfs``: the AGV that has been idle longest, wherever it is.

Mixed fleets: the fleet manager hands a policy only the AGVs whose type may serve the order,
and `travel_of` gives each AGV's travel time on its own type's routes (its segments, its
speed); without it every AGV uses `travel_time_s`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol, TypeVar


class Candidate(Protocol):
    """What a dispatch policy knows of an AGV."""

    @property
    def id(self) -> int: ...

    @property
    def dispatch_node(self) -> str:
        """The node the AGV is committed to: where travel to the pickup is measured from."""
        ...


AgvT = TypeVar("AgvT", bound=Candidate)
TravelTime = Callable[[str, str], float]
"""Free-flow travel time in seconds from one node to another."""


TravelOf = Callable[[Candidate], TravelTime]
"""The travel time function of one AGV's vehicle type (mixed fleets)."""


class DispatchPolicy(Protocol):
    def choose(self, ready: Sequence[AgvT], pickup_node: str,
               travel_time_s: TravelTime, travel_of: TravelOf | None = None) -> AgvT:
        """One of `ready` (never empty, in the order the AGVs became idle)."""
        ...


class NearestIdle:
    """The idle AGV with the shortest free-flow travel time to the pickup."""

    def choose(self, ready: Sequence[AgvT], pickup_node: str,
               travel_time_s: TravelTime, travel_of: TravelOf | None = None) -> AgvT:
        if travel_of is not None:
            return min(ready, key=lambda agv: (travel_of(agv)(agv.dispatch_node, pickup_node),
                                               agv.id))
        return min(ready, key=lambda agv: (travel_time_s(agv.dispatch_node, pickup_node), agv.id))


class FirstComeFirstServed:
    """The AGV idle longest."""

    def choose(self, ready: Sequence[AgvT], pickup_node: str,
               travel_time_s: TravelTime, travel_of: TravelOf | None = None) -> AgvT:
        return ready[0]


POLICIES: dict[str, Callable[[], DispatchPolicy]] = {
    "nearest_idle": NearestIdle,
    "fcfs": FirstComeFirstServed,
}
"""Scenario `dispatch.policy` name -> the policy."""
