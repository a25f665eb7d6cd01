"""Mutex zones: the locks traffic control hands out for a layout's `traffic_zones`.

A mutex zone of capacity N admits at most N AGVs at once. Its lock is a `Gate`: a `Lock` (the
same reservation table, the same claims, the same waits) whose SimPy capacity is N. An AGV asks
`Traffic` for the zone before it takes its first node in it, standing outside, and lets go once
it holds no node in it any more (fleet_sim.sim.agents.driving). Ban zones need no lock: a
banned type's routes keep off them (fleet_sim.config.layout.Layout.type_graph).

Deadlocks: a zone of capacity 1 is one lock with one holder, so a wait-for cycle through it is
found and broken like any other (its waiters keep off the zone's nodes when they look for
another way). For a zone of capacity N > 1 the wait-for graph follows the AGV that entered
first (`Lock.holder`): a cycle through a later entrant is not seen. It is rare (every AGV
inside must wait for an AGV waiting outside) and the other rules (give way, replan) still
apply; the zone's waits show in `zone_wait_s.<zone>`.
"""

from __future__ import annotations

import simpy

from fleet_sim.sim.traffic.locks import Lock, ZoneLock


class Gate(Lock):
    """A zone's lock: up to `capacity` holders at once, in the order they asked."""

    def __init__(self, env: simpy.Environment, key: ZoneLock, capacity: int) -> None:
        simpy.Resource.__init__(self, env, capacity=capacity)
        self.key = key

    @property
    def is_free(self) -> bool:
        """Room for one more, and nobody waiting before."""
        return len(self.users) < self.capacity and not self.put_queue
