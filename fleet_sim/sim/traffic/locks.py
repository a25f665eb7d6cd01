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
from simpy.events import PENDING, Event
from simpy.resources.resource import Request

from fleet_sim.sim.traffic.waking import Sleeper, at_once, process_now


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
    and most hops) and leaves the order of every other event unchanged."""

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


def grant(lock: Lock, claim: Claim) -> None:
    """Give `claim` the lock (it is among its users): at once if it is being made, else by
    scheduling it (its client waits on it), or, offered the lock by a `Released`, as that
    event has it scheduled or processed."""
    claim.usage_since = lock._env.now
    if claim.asking:
        claim.grant_at_once()
    else:
        offering = lock.offering
        if offering is None:
            claim.succeed()
        else:
            claim._ok = True
            claim._value = None
            offering.append(claim)
        if lock.watchers:  # a zone's queue may be empty now and have room left
            lock.changed()


class Released(Event):
    """SimPy's `Release` event, without what it does not need here: a lock is let go of at once
    (the claim leaves its users when it is given back, as SimPy's `_do_get` does), and the event,
    scheduled where SimPy schedules its `Release`, offers the lock to the claim waiting first
    when it is processed (SimPy's `_trigger_put`). Nobody waits on it. The claim it grants is
    scheduled when the offer is over, with the event id it would have had (nothing between
    takes one: `Lock.changed` sets alarms at ids reserved before), or, when it would be the
    next event processed (`at_once`) and is the only one granted, processed there and then."""

    def __init__(self, lock: Lock) -> None:
        self.env = lock._env
        self.callbacks = [self._offer]
        self._ok = True
        self._value = None
        self.lock = lock
        self.env.schedule(self)

    def _offer(self, _: Event) -> None:
        lock = self.lock
        granted: list[Claim] = []
        lock.offering = granted
        try:
            lock._trigger_put(self)
        finally:
            lock.offering = None
        if len(granted) == 1 and at_once(self.env):
            process_now(granted[0])
        else:
            for claim in granted:
                self.env.schedule(claim)


class FirstOf(Event):
    """`a | b` for two pending events (SimPy's `Condition` with `any_events`), without its
    bookkeeping: triggered (scheduled) when the first of them is processed, so it is processed
    where the `Condition` would be; its value is None (nobody reads it)."""

    def __init__(self, env: simpy.Environment, a: Event, b: Event) -> None:
        self.env = env
        self.callbacks = []
        self._value = PENDING
        self._a = a
        self._b = b
        check = self._check
        a.callbacks.append(check)
        b.callbacks.append(check)

    def _check(self, event: Event) -> None:
        if self._value is not PENDING:
            return
        self._ok = True
        self._value = None
        self.env.schedule(self)
        other = self._b if event is self._a else self._a
        callbacks = other.callbacks
        if callbacks:  # the other one no longer needs to tell it (SimPy removes it too)
            callbacks.remove(self._check)


class Lock(simpy.Resource):
    """An exclusive lock on a node or a corridor: a SimPy resource of capacity one."""

    QUIET_RELEASE = True
    """Let go of with nobody waiting, no `Released` event is scheduled: its only work, offering
    the lock to the first waiting claim, would find none at the time. (A claim queued later in
    the same instant is then offered the lock at the next release, where SimPy would have
    offered it at this one's place among the instant's events: the same grants at the same
    instants, in an order SimPy might not have taken.) False where a waiting claim may be
    refused for a reason other than room (a same-direction zone's direction), so a later offer
    can grant it."""

    offering: list[Claim] | None = None
    """While a `Released` offers the lock: the claims it granted (not scheduled yet)."""

    def __init__(self, env: simpy.Environment, key: LockKey) -> None:
        super().__init__(env, capacity=1)
        self.key = key
        self.watchers: list[Sleeper] = []
        """Blocked AGVs that may drive into what this lock guards: told when it may have
        become free (`changed`), until their wait is over."""
        self.holder_watchers: list[Sleeper] = []
        """Blocked AGVs holding this lock, which may give way: told when another AGV queues
        for it (`queued`), until their wait is over."""

    def changed(self) -> None:
        """The lock was let go of, given up by a waiting claim, or granted from its queue: it
        may be free now. Wake its watchers."""
        watchers = self.watchers
        if watchers:
            for sleeper in watchers:
                sleeper.changed()
            self.watchers = [s for s in watchers if s.alarm_s == s.alarm_s]  # (nan: over)

    def queued(self) -> None:
        """Another AGV queues for the lock: wake the blocked AGVs that hold it."""
        watchers = self.holder_watchers
        if watchers:
            for sleeper in watchers:
                sleeper.changed()
            self.holder_watchers = [s for s in watchers if s.alarm_s == s.alarm_s]

    def claim(self, client_id: int) -> Claim:
        """A claim of `client_id` on the lock: granted at once when the lock has room and nobody
        waits (built directly in the state SimPy's request and `grant_at_once` leave it in),
        else queued."""
        if self.put_queue or len(self.users) >= self._capacity:
            return Claim(self, client_id)
        claim = Claim.__new__(Claim)
        env = self._env
        claim.env = env
        claim.resource = self
        claim.proc = env.active_process
        claim.client_id = client_id
        claim.asking = False
        claim.usage_since = env._now
        claim._ok = True
        claim._value = None
        claim.callbacks = None  # type: ignore[assignment]  # SimPy's mark of "processed"
        self.users.append(claim)
        return claim

    def release(  # type: ignore[override]
            self, request: simpy.resources.resource.Request) -> Released | None:
        """Let go of `request` (one of the users): see `Released` and `QUIET_RELEASE`."""
        self.users.remove(request)
        if self.watchers:
            self.changed()
        if self.QUIET_RELEASE and not self.put_queue:
            return None
        return Released(self)

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
