"""Traffic zones: the locks traffic control hands out for a layout's `traffic_zones`.

Mutex zones. A mutex zone of capacity N admits at most N AGVs at once. Its lock is a `Gate`: a
`Lock` (the same reservation table, the same claims, the same waits) whose SimPy capacity is N.
An AGV asks `Traffic` for the zone before it takes its first node in it, standing outside, and
lets go once it holds no node in it any more (`Traffic.release_left_zones`). Ban zones need no
lock: a banned type's routes keep off them (fleet_sim.config.layout.Layout.type_graph).

Same-direction zones (openTCS's "same direction only" blocks). The zone is a two-way aisle, its
nodes listed in order; its lock is a `DirectionGate`, whose claims carry a direction (FORWARD:
from the first node listed towards the last; BACKWARD). An AGV takes it for the direction of
the hop by which it enters the aisle, before it takes the end node from which it drives in;
claims are granted first come, first served, and `blockers` names whom a claim waits for, so
the wait-for graph follows them (fleet_sim.sim.traffic.deadlock.find_cycle).

The choices where the issues were silent (directions, turning round inside, deadlocks through
a zone): docs/background/decisions/sim.md.
"""

from __future__ import annotations

import sys
from typing import cast

import simpy

from fleet_sim.sim.traffic.locks import Claim, Lock, ZoneLock, grant

ANY_DIRECTION = 0
"""A claim for a same-direction zone by an AGV put on the track inside it: it takes the
direction of the AGVs inside (FORWARD if none)."""


class Gate(Lock):
    """A zone's lock: up to `capacity` holders at once, in the order they asked."""

    def __init__(self, env: simpy.Environment, key: ZoneLock, capacity: int) -> None:
        simpy.Resource.__init__(self, env, capacity=capacity)
        self.key = key
        self.watchers = []
        self.holder_watchers = []

    @property
    def is_free(self) -> bool:
        """Room for one more, and nobody waiting before."""
        return len(self.users) < self.capacity and not self.put_queue


class DirectedClaim(Claim):
    """A claim on a same-direction zone, for one direction (FORWARD, BACKWARD or
    ANY_DIRECTION until granted). `turn`: its client holds the zone the other way already."""

    def __init__(self, resource: DirectionGate, client_id: int, direction: int,
                 turn: bool = False) -> None:
        self.direction = direction
        self.turn = turn
        super().__init__(resource, client_id)


class _TurnsFirst(list[DirectedClaim]):
    """The waiting claims in the order asked, but an AGV turning inside before all."""

    def append(self, claim: DirectedClaim) -> None:
        if claim.turn:
            self.insert(sum(1 for c in self if c.turn), claim)
        else:
            super().append(claim)


class DirectionGate(Gate):
    """A same-direction zone's lock: holders all in one direction, up to `capacity` (None:
    no limit), granted in the order asked (turns first)."""

    PutQueue = _TurnsFirst
    QUIET_RELEASE = False

    def __init__(self, env: simpy.Environment, key: ZoneLock, capacity: int | None) -> None:
        super().__init__(env, key, capacity if capacity is not None else sys.maxsize)

    def _claims(self) -> list[DirectedClaim]:
        return cast(list[DirectedClaim], self.users)

    @property
    def direction(self) -> int:
        """The direction of the AGVs holding the zone; 0 when nobody does."""
        users = self._claims()
        return users[0].direction if users else 0

    def _grantable(self, claim: DirectedClaim) -> bool:
        others = [c for c in self._claims() if c.client_id != claim.client_id]
        if claim.turn:
            return not others
        if len(others) >= self.capacity:
            return False
        return claim.direction == ANY_DIRECTION \
            or all(c.direction == claim.direction for c in others)

    def _do_put(self, event: simpy.resources.resource.Request) -> None:
        claim = cast(DirectedClaim, event)
        if self._grantable(claim):
            if claim.direction == ANY_DIRECTION:
                claim.direction = self.direction or 1
            self.users.append(claim)
            grant(self, claim)

    def admits(self, direction: int) -> bool:
        """A claim for `direction` would be granted now (nobody waits before it)."""
        return not self.put_queue and len(self.users) < self.capacity \
            and all(c.direction == direction for c in self._claims())

    @property
    def is_free(self) -> bool:
        return not self.put_queue and len(self.users) < self.capacity

    def blockers(self, client_id: int) -> tuple[int, ...]:
        """Whom a waiting claim of `client_id` waits for: every holder the other way (all must
        leave); else, the zone being full, the first holder; else the claim asked before."""
        queue = cast(list[DirectedClaim], self.put_queue)
        mine = next((c for c in queue if c.client_id == client_id), None)
        if mine is None:
            return super().blockers(client_id)
        others = [c for c in self._claims() if c.client_id != client_id]
        if mine.turn:
            return tuple(c.client_id for c in others)
        against = tuple(c.client_id for c in others if c.direction != mine.direction
                        and mine.direction != ANY_DIRECTION)
        if against:
            return against
        if len(others) >= self.capacity:
            return (others[0].client_id,)
        at = queue.index(mine)
        return (queue[at - 1].client_id,) if at > 0 else ()
