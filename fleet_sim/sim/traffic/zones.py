"""Traffic zones: the locks traffic control hands out for a layout's `traffic_zones`.

Mutex zones. A mutex zone of capacity N admits at most N AGVs at once. Its lock is a `Gate`: a
`Lock` (the same reservation table, the same claims, the same waits) whose SimPy capacity is N.
An AGV asks `Traffic` for the zone before it takes its first node in it, standing outside, and
lets go once it holds no node in it any more (`Traffic.release_left_zones`). Ban zones need no
lock: a banned type's routes keep off them (fleet_sim.config.layout.Layout.type_graph).

Same-direction zones (openTCS's "same direction only" blocks). The zone is a two-way aisle, its
nodes listed in order; its lock is a `DirectionGate`, whose claims carry a direction (FORWARD:
from the first node listed towards the last; BACKWARD). Decisions:

* The direction of a pass is the direction of the hop by which the AGV enters the aisle: it
  asks for the zone with that direction before it takes the end node from which it drives in
  (as it would take a single-track corridor: waiting there, it would block the way out). Every
  hop along the aisle is checked against the AGV's claim: it never drives the other way on the
  claim it holds.
* A claim is granted when no other AGV holds the zone in the other direction and the zone has
  room (`capacity`, default no limit but one AGV per node), in the order asked (first come,
  first served): one that wants the other direction is not overtaken by later AGVs going the
  way the AGVs inside go, so it waits for the AGVs inside to leave, not for a gap in a stream.
* Turning round inside. An AGV alone in the zone may turn round (after a drop-off in the
  aisle, its next stop behind it): it asks for the other direction ahead of every waiting AGV
  and, being alone, gets it at once. With other AGVs in the zone it drives on: while it holds
  the zone with others, its routes, detours and escapes keep off the aisle's hops the other way
  (Traffic.against), so it leaves by the far end, and the layout check makes sure a way round
  leads back (fleet_sim.config.layout). (Should it have to drive back all the same, its type
  having no way round, it waits inside until it is alone.) An AGV put on the track inside the
  aisle (a start node, back from a repair) takes the zone in the direction of the AGVs inside
  (forward if none).
* Deadlocks: a claim waits for every AGV holding the zone the other way (all of them must
  leave), else, when the zone is full, for the AGV that entered first, else for the AGV asking
  before it (first come, first served). `blockers` names them, and the wait-for graph follows
  each (fleet_sim.sim.traffic.deadlock.find_cycle), so a cycle through any of them is found and
  broken like any other.

Deadlocks through a mutex zone: a zone of capacity 1 is one lock with one holder, so a wait-for
cycle through it is found and broken like any other (its waiters keep off the zone's nodes when
they look for another way). For a zone of capacity N > 1 the wait-for graph follows the AGV that
entered first (`Lock.holder`): a cycle through a later entrant is not seen. It is rare (every AGV
inside must wait for an AGV waiting outside) and the other rules (give way, replan) still apply;
the zone's waits show in `zone_wait_s.<zone>`.
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
