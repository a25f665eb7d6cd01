"""The reservation table: every node, corridor and zone lock, who holds each, who waits for
which, and each client's claims (granted or waiting).

This is the narrow view the allocation modules (fleet_sim.sim.traffic.allocation), the
avoiding policy's plans (fleet_sim.sim.traffic.avoidance) and the traffic policies
(fleet_sim.sim.traffic.policy) are handed, as openTCS's Scheduler modules are handed the
allocation state rather than the Scheduler: what is held, by whom, and what is queued, and the
table's own writes (ask, give back, withdraw). Routes, escapes, zone records and the drive's
bookkeeping stay with `fleet_sim.sim.traffic.control.Traffic`, which owns one table.

`version` counts changes of lock ownership and waits: a blocked AGV that sees the same count as
at its last look has nothing new to find.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Protocol, cast

import simpy

from fleet_sim.config.layout import Layout
from fleet_sim.errors import SimulationError
from fleet_sim.sim.traffic.deadlock import DeadlockVictim, KnownCycles, find_cycle
from fleet_sim.sim.traffic.locks import Claim, CorridorLock, Lock, NodeLock, ZoneLock
from fleet_sim.sim.traffic.waking import Sleeper
from fleet_sim.sim.traffic.zones import ANY_DIRECTION, DirectedClaim, DirectionGate, Gate

CorridorHold = tuple[Claim, str | None]
"""A corridor claim and the node from which the client will enter it (None once inside)."""


class TrafficClient(Protocol):
    """What traffic control knows of an AGV (openTCS: a Scheduler client)."""

    @property
    def id(self) -> int: ...

    @property
    def node(self) -> str:
        """The node the AGV stands on (or last passed)."""
        ...

    @property
    def goal(self) -> str | None:
        """Where the AGV is driving to, if anywhere."""
        ...

    @property
    def next_node(self) -> str | None:
        """The node it drives to next, if it is driving."""
        ...

    @property
    def failing(self) -> bool:
        """A fault is on its way: the AGV is about to let go of everything."""
        ...

    def note(self, event: str, detail: str = "") -> None:
        """Record an event about the AGV that changes no state (deadlock_detected...)."""

    def on_deadlock_victim(self, cause: DeadlockVictim) -> None:
        """The AGV was chosen to break a wait-for cycle: stop waiting and take `cause.escape`."""

    def began_waiting(self, lock: Lock) -> None:
        """Traffic makes the AGV wait for `lock` (the AGV ahead may now be in its LDS's
        range: fleet_sim.sim.agents.lds)."""

    @property
    def clear_m(self) -> float:
        """How far past a node the AGV drives before it lets go of it (its length plus the
        minimum gap)."""
        ...

    def past_m(self) -> dict[str, float]:
        """Node -> how far the AGV has driven past it, for the nodes behind it it holds."""
        ...


class Reservations:
    """The locks, their holders and queues, and each client's claims."""

    def __init__(self, env: simpy.Environment, layout: Layout) -> None:
        self.env = env
        self.layout = layout
        graph = layout.graph
        self.node_locks = {n: Lock(env, NodeLock(n)) for n in graph.nodes}
        self.junction_locks = frozenset(self.node_locks[n] for n in graph.nodes
                                        if graph.in_degree(n) >= 2)
        """The locks of the nodes more than one segment leads into (where AGVs cross or merge;
        the avoiding policy's walk keeps out of them, fleet_sim.sim.traffic.avoidance)."""
        self.corridor_locks = {c.id: Lock(env, CorridorLock(c.id)) for c in layout.corridors}
        self.zone_locks: dict[str, Gate] = {}
        """Mutex and same-direction zone id -> its lock."""
        for z in layout.traffic_zones:
            if z.kind == "mutex":
                self.zone_locks[z.id] = Gate(env, ZoneLock(z.id), z.capacity or 1)
            elif z.kind == "same_direction":
                self.zone_locks[z.id] = DirectionGate(env, ZoneLock(z.id), z.capacity)
        self.waiting: dict[int, Lock] = {}
        """Client id -> the lock it waits for."""
        self.version = 0
        self.clients: dict[int, TrafficClient] = {}
        self.nodes: dict[int, set[Claim]] = {}
        """Client id -> its node claims (granted or waiting)."""
        self.corridors: dict[int, dict[int, CorridorHold]] = {}
        """Client id -> corridor id -> its corridor claims, in the order it asked for them."""
        self.zones: dict[int, dict[str, Claim]] = {}
        """Client id -> zone id -> its zone claims (granted or waiting)."""
        self.sleeping: dict[int, Sleeper] = {}
        """Client id -> its wait, while it sleeps (fleet_sim.sim.traffic.reactive)."""
        self.suspects: set[int] = set()
        """Clients found in a wait-for cycle that may still stand: they look again while they
        wait; nobody else needs to (fleet_sim.sim.traffic.reactive)."""
        self.cycles = KnownCycles()
        """The wait-for cycles recorded so far (each is recorded once)."""
        self.on_free: list[Callable[[Lock], None]] = []
        """Called with each lock a client gives back (the avoiding policy wakes its waiters)."""

    def register(self, client: TrafficClient) -> None:
        self.clients[client.id] = client
        self.nodes[client.id] = set()
        self.corridors[client.id] = {}
        self.zones[client.id] = {}

    def request(self, client_id: int, lock: Lock, entry: str | None = None,
                direction: int = ANY_DIRECTION) -> Claim:
        """Ask for `lock`: the claim is granted (`triggered`) at once if the lock is free, else
        when the client's turn comes. `entry`: for a corridor, the node from which the client
        will enter it (None: it is inside already). `direction`: for a same-direction zone,
        the way the client will drive it; a client holding the zone the other way asks to
        turn (`turned` once granted)."""
        key = lock.key
        if isinstance(lock, DirectionGate):
            assert isinstance(key, ZoneLock)
            held = self.zones[client_id].get(key.zone_id)
            turn = held is not None and held.triggered
            claim: Claim = DirectedClaim(lock, client_id, direction, turn)
            if not turn:
                self.zones[client_id][key.zone_id] = claim
            self.version += 1
            if lock.holder_watchers and not claim.triggered:
                lock.queued()
            return claim
        claim = lock.claim(client_id)
        if isinstance(key, NodeLock):
            claim.node = key.node
            self.nodes[client_id].add(claim)
        elif isinstance(key, ZoneLock):
            self.zones[client_id][key.zone_id] = claim
        else:
            self.corridors[client_id][key.corridor_id] = (claim, entry)
        self.version += 1
        if lock.holder_watchers and not claim.triggered:
            lock.queued()
        return claim

    def held_locks(self, client_id: int) -> tuple[list[Lock], list[Lock]]:
        """The node locks and the corridor and zone locks the client holds (granted)."""
        nodes = [cast(Lock, c.resource) for c in self.nodes[client_id] if c.triggered]
        others = [cast(Lock, c.resource) for c, _ in self.corridors[client_id].values()
                  if c.triggered]
        others += [cast(Lock, c.resource) for c in self.zones[client_id].values()
                   if c.triggered]
        return nodes, others

    def start_waiting(self, client_id: int, lock: Lock) -> None:
        """The client waits for `lock`; a wait-for cycle it closes makes its members suspects."""
        self.waiting[client_id] = lock
        self.version += 1
        cycle = find_cycle(client_id, self.waiting)
        if cycle is not None:
            self.suspects.update(cycle)
            for member in cycle:  # suspects now: they look again at their next look time
                sleeper = self.sleeping.get(member)
                if sleeper is not None:
                    sleeper.changed()

    def stop_waiting(self, client_id: int) -> None:
        del self.waiting[client_id]
        self.suspects.discard(client_id)
        self.version += 1

    def spots(self, client_id: int) -> set[str]:
        """The nodes the client holds (stands on, drives to, or has not cleared yet)."""
        return {c.node for c in self.nodes[client_id] if c.triggered}

    def past_m(self, client_id: int) -> dict[str, float]:
        """How far the client has driven past each node behind it (`TrafficClient.past_m`)."""
        return self.clients[client_id].past_m()

    def clearance_m(self, client_id: int) -> float:
        """How far past a node the client lets go of it (`TrafficClient.clear_m`)."""
        return self.clients[client_id].clear_m

    def free(self, client_id: int, claim: Claim) -> None:
        """Give back a lock the client holds."""
        lock: Lock = claim.resource  # type: ignore[assignment]  # a Claim's is a Lock
        if claim.client_id != client_id or claim not in lock.users:
            raise SimulationError(f"AGV {client_id} cannot free {lock.key}: it does not hold "
                                  f"it (holder: {lock.holder})")
        lock.release(claim)
        if type(lock.key) is NodeLock:  # `_forget`, for a node
            self.nodes[client_id].discard(claim)
            self.version += 1
        else:
            self._forget(client_id, lock, claim)
        for freed in self.on_free:
            freed(lock)

    def free_all(self, client_id: int, claims: list[Claim]) -> None:
        """Give back each of `claims` (all held by the client)."""
        for claim in claims:
            self.free(client_id, claim)

    def withdraw(self, client_id: int, claim: Claim) -> None:
        """Stop waiting for a claim not yet granted."""
        lock = cast(Lock, claim.resource)
        if claim.client_id != client_id or claim.triggered:
            raise SimulationError(f"AGV {client_id} cannot withdraw its claim on {lock.key}: "
                                  "it is not its own waiting claim")
        claim.cancel()
        self._forget(client_id, lock, claim)
        if lock.watchers:
            lock.changed()

    def _forget(self, client_id: int, lock: Lock, claim: Claim) -> None:
        key = lock.key
        if isinstance(key, NodeLock):
            self.nodes[client_id].discard(claim)
        elif isinstance(key, ZoneLock):
            if self.zones[client_id].get(key.zone_id) is claim:
                del self.zones[client_id][key.zone_id]
        else:
            hold = self.corridors[client_id].get(key.corridor_id)
            if hold is not None and hold[0] is claim:
                del self.corridors[client_id][key.corridor_id]
        self.version += 1

    def turned(self, client_id: int, claim: Claim) -> None:
        """A turn the client asked for inside a same-direction zone is granted: its claim the
        old way is given back, the new one is the client's claim on the zone."""
        key = cast(Lock, claim.resource).key
        assert isinstance(key, ZoneLock) and claim.triggered
        self.free(client_id, self.zones[client_id][key.zone_id])
        self.zones[client_id][key.zone_id] = claim

    def entered_corridor(self, client_id: int, corridor_id: int) -> None:
        """The client has driven into a corridor it reserved."""
        claim, _ = self.corridors[client_id][corridor_id]
        self.corridors[client_id][corridor_id] = (claim, None)

    def corridors_of(self, client_id: int) -> Mapping[int, CorridorHold]:
        """The client's corridor claims (corridor id -> claim, entry node), oldest first."""
        return self.corridors[client_id]

    def zones_of(self, client_id: int) -> Mapping[str, Claim]:
        """The client's zone claims (zone id -> claim)."""
        return self.zones[client_id]

    def holds_corridor(self, client_id: int, corridor_id: int) -> bool:
        hold = self.corridors[client_id].get(corridor_id)
        return hold is not None and hold[0].triggered

    def node_holder(self, client_id: int) -> tuple[TrafficClient, str] | None:
        """The client holding the node `client_id` waits for, and that node (None: it waits
        for no node, or for a free one)."""
        lock = self.waiting.get(client_id)
        if lock is None or not isinstance(lock.key, NodeLock):
            return None
        holder = lock.holder
        if holder is None or holder == client_id:
            return None
        return self.clients[holder], lock.key.node

    def holders(self) -> Iterator[tuple[str, int]]:
        """(node, client id) for every held node lock (for invariant checks)."""
        for node, lock in self.node_locks.items():
            holder = lock.holder
            if holder is not None:
                yield node, holder

    def blocks_others(self, client_id: int) -> bool:
        """True if another AGV waits for a node, corridor or zone that the client holds."""
        for claim in self.nodes[client_id]:
            if claim.triggered and claim.resource.put_queue:
                return True
        for claim, _ in self.corridors[client_id].values():
            if claim.triggered and claim.resource.put_queue:
                return True
        for claim in self.zones[client_id].values():
            if claim.triggered and claim.resource.put_queue:
                return True
        return False
