"""Lock keys and locks: what the reservation table (fleet_sim.sim.traffic.control.Traffic) hands
out.

A lock is a SimPy resource of capacity one (`Lock`), named by a typed key: `NodeLock(node)` for a
node, `CorridorLock(corridor_id)` for a single-track corridor. A `Claim` is a request for a lock
that knows which client (AGV) made it. The key's `str` is the name the run's events show
("M011", "corridor 3"); nothing parses it back.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import simpy
from simpy.resources.resource import Request


@dataclass(frozen=True, slots=True)
class NodeLock:
    """The lock on one node: one AGV per node."""

    node: str

    def __str__(self) -> str:
        return self.node


@dataclass(frozen=True, slots=True)
class CorridorLock:
    """The lock on one single-track corridor (fleet_sim.config.layout.Corridor)."""

    corridor_id: int

    def __str__(self) -> str:
        return f"corridor {self.corridor_id}"


@dataclass(frozen=True, slots=True)
class ZoneLock:
    """The lock on one mutex or same-direction zone (fleet_sim.sim.traffic.zones)."""

    zone_id: str

    def __str__(self) -> str:
        return f"zone {self.zone_id}"


LockKey = NodeLock | CorridorLock | ZoneLock


class Claim(Request):
    """A request for a lock that knows which client made it.

    A claim granted the moment it is made is not scheduled as a SimPy event: nobody can be
    waiting on a claim that is being made, and processing it would do nothing (SimPy's
    `_trigger_get` finds no release queued). It is marked granted and processed at once
    (`grant_at_once`), which saves one event per lock taken without waiting (the look-ahead
    and most hops) and leaves the order of every other event as it was."""

    node = ""
    """For a node lock: the node (set by traffic control when it makes the claim)."""

    def __init__(self, resource: Lock, client_id: int) -> None:
        self.client_id = client_id
        self.asking = True
        super().__init__(resource)
        self.asking = False

    def grant_at_once(self) -> None:
        """Granted while being made: triggered and processed, never scheduled."""
        self._ok = True
        self._value = None
        self.callbacks = None  # type: ignore[assignment]  # SimPy's mark of "processed"


def grant(lock: simpy.Resource, claim: Claim) -> None:
    """Give `claim` the lock (it is among its users): at once if it is being made, else by
    scheduling it (its client waits on it)."""
    claim.usage_since = lock._env.now
    if claim.asking:
        claim.grant_at_once()
    else:
        claim.succeed()


class Lock(simpy.Resource):
    """An exclusive lock on a node or a corridor: a SimPy resource of capacity one."""

    def __init__(self, env: simpy.Environment, key: LockKey) -> None:
        super().__init__(env, capacity=1)
        self.key = key

    def _do_put(self, event: Claim) -> None:  # type: ignore[override]  # only Claims here
        if len(self.users) < self.capacity:
            self.users.append(event)
            grant(self, event)

    @property
    def holder(self) -> int | None:
        """The client holding the lock, if any."""
        if not self.users:
            return None
        claim = cast(Claim, self.users[0])
        return claim.client_id

    @property
    def is_free(self) -> bool:
        """Nobody holds it and nobody waits for it."""
        return not self.users and not self.put_queue

    def blockers(self, client_id: int) -> tuple[int, ...]:
        """The clients that `client_id`, waiting for this lock, waits for: its holder (a
        same-direction zone may name several, fleet_sim.sim.traffic.zones)."""
        holder = self.holder
        return () if holder is None or holder == client_id else (holder,)
