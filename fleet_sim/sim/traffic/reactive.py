"""The reactive traffic policy (`traffic.policy: reactive`, the default): an AGV queues for
each part of a hop in turn, and wait-for cycles are found and broken.

A wait-for cycle is looked for when an AGV starts waiting, the only change that can close one
(an AGV waits for one lock at a time, and a lock passed on goes to an AGV that thereby stops
waiting), and again every `deadlock_check_s` only for the AGVs a cycle was found for
(`Reservations.suspects`): walking every blocked AGV's whole chain every check period would
cost (queue length)^2 per period in a long queue. A blocked AGV that sees the same
`Reservations.version` as at its last look has nothing new to find. An AGV blocked
`give_way_after_s` with another queued behind it gives way (circulates), which keeps loops
flowing; blocked `replan_after_s`, it takes another route if there is one.

A blocked AGV sleeps on its claim and looks again every `deadlock_check_s` from the start of
its wait, but is woken only for the looks that can find something new
(fleet_sim.sim.traffic.waking): the first past each threshold of its wait, every one while it
is a suspect, and, past a threshold, the first after a way out may have opened (a lock it
could drive into let go of) or another AGV queued for what it holds.

The choices where the issues were silent: docs/background/decisions/sim.md.
"""

from __future__ import annotations

import math
from collections.abc import Generator
from typing import TYPE_CHECKING, Any, cast

import simpy

from fleet_sim.errors import SimulationError
from fleet_sim.sim.traffic.allocation import DIRECTION_NAMES, Hop, Need
from fleet_sim.sim.traffic.deadlock import DeadlockVictim, Escape, find_cycle
from fleet_sim.sim.traffic.escapes import Escapes
from fleet_sim.sim.traffic.locks import Claim, Lock, ZoneLock
from fleet_sim.sim.traffic.table import TrafficClient
from fleet_sim.sim.traffic.waking import LOOK_AGAIN, Relay, Sleeper

if TYPE_CHECKING:
    from fleet_sim.sim.traffic.control import Traffic


class ReactivePolicy:
    """Queue for each part of a hop; find and break wait-for cycles (`TrafficPolicy`)."""

    name = "reactive"

    def __init__(self, traffic: Traffic) -> None:
        self.traffic = traffic
        self.table = traffic.table
        """What is held, by whom, and what is queued."""
        self.escapes = Escapes(traffic)
        self.alarms = traffic.clock
        """The thresholds of blocked AGVs' waits, and suspects' next looks."""

    def placed(self, client_id: int, node: str) -> None:
        """Nothing to do: reactive traffic keeps no plans."""

    def hopped(self, client_id: int, node: str) -> None:
        """Nothing to do: reactive traffic keeps no plans."""

    def left(self, client_id: int) -> None:
        """Nothing to do: reactive traffic keeps no plans."""

    def granted(self, client_id: int, node: str) -> None:
        """Nothing to do: reactive traffic keeps no plans."""

    def take_escape(self, client_id: int) -> Escape | None:
        return self.escapes.take_escape(client_id)

    def escape_for(self, client: TrafficClient) -> Escape | None:
        return self.escapes.escape_for(client)

    def allocate(self, client: TrafficClient,
                 hop: Hop) -> Generator[simpy.Event, Any, Claim | None]:
        """Queue the client for the whole hop: its parts are taken in the modules' order,
        waiting for each. Returns the node's claim once all are held; None if the client gave
        up waiting (deadlock victim, or blocked long with another way at hand), what it took
        for the hop given back (see fleet_sim.sim.traffic.allocation)."""
        client_id = client.id
        needs = self.traffic.needs(client_id, hop)
        taken: list[Claim] = []
        for m, need in needs:
            if m.name == "corridor":
                claim = self.table.request(client_id, need.lock, entry=need.entry)
                if not (yield from self.wait(client, need.lock, claim)):
                    self.table.free_all(client_id, taken)
                    return None
                taken.append(claim)
            elif m.name == "mutex":
                claim = self.table.request(client_id, need.lock)
                if not (yield from self._wait_zone(client, need.zone_id, need.lock, claim)):
                    self.table.free_all(client_id, taken)
                    self.traffic.release_left_zones(client_id)
                    return None
            elif m.name == "same_direction":
                if not (yield from self._take_direction(client, need)):
                    self.table.free_all(client_id, taken)
                    self.traffic.drop_pending_zones(client_id)
                    self.traffic.release_left_zones(client_id)
                    return None
            else:
                claim = self.table.request(client_id, need.lock)
                if not (yield from self.wait(client, need.lock, claim)):
                    self.table.free_all(client_id, taken)
                    self.traffic.release_left_zones(client_id)
                    return None
                return claim
        raise SimulationError(f"AGV {client_id}: a hop to {hop.node} without its node")

    def wait(self, client: TrafficClient, lock: Lock, claim: Claim,
             may_escape: bool = True) -> Generator[simpy.Event, Any, bool]:
        """Wait for `claim`. Returns True once held; False if the client gave up (deadlock
        victim, or blocked for long with another route at hand) and the claim was withdrawn.
        Any other interrupt (a fault) withdraws or frees the claim and passes on."""
        if claim.triggered:
            return True
        env = self.table.env
        config = self.traffic.config
        table = self.table
        suspects = self.table.suspects
        client_id = client.id
        start = env.now
        self.table.start_waiting(client_id, lock)
        client.began_waiting(lock)
        self.traffic.recorder.wait_began(client_id, start,
                                 lock.key.zone_id if isinstance(lock.key, ZoneLock) else None)
        if self.traffic.recorder.record_moves:
            holder = lock.holder
            self.traffic.open_waits[client_id] = (start, str(lock.key),
                                                  -1 if holder is None else holder)
        looked_at: tuple[int, bool, bool] | None = None
        give_way_after_s = config.give_way_after_s
        replan_after_s = config.replan_after_s
        sleeping = table.sleeping
        sleeper = sleeping[client_id] = Sleeper(cast(simpy.Process, env.active_process),
                                                self.alarms, start, config.deadlock_check_s)
        try:
            while True:
                waited = env.now - start
                now_seen = (table.version, waited >= give_way_after_s, waited >= replan_after_s)
                sleeper.looked_s = env.now  # (woken at a look time, or at the start)
                if may_escape and now_seen != looked_at:  # nothing changed, nothing to look at
                    looked_at = now_seen
                    # (resolve_deadlock looks only for a suspect, other_way only once the AGV
                    # may give way or replan: the calls are left out otherwise)
                    if (client_id in suspects and self.resolve_deadlock(client) is not None) \
                            or ((now_seen[1] or now_seen[2]) and self.escapes.other_way(
                                client, now_seen[1], now_seen[2]) is not None):
                        self.table.withdraw(client_id, claim)
                        return False
                if may_escape:
                    sleeper.sleep()
                    self._watch(client, sleeper, start, now_seen[1] or now_seen[2])
                relay = sleeper.claim = Relay(env, claim)
                sleeper.awake = False
                try:
                    yield relay
                except simpy.Interrupt as interrupt:
                    relay.drop()
                    if interrupt.cause is LOOK_AGAIN:
                        if claim.triggered:  # granted in the same instant
                            return True
                        continue
                    if not isinstance(interrupt.cause, DeadlockVictim):
                        # a fault: let go and pass it on
                        if claim.triggered:
                            self.table.free(client_id, claim)
                        else:
                            self.table.withdraw(client_id, claim)
                        raise
                    if claim.triggered:
                        self.escapes.take_escape(client_id)  # the way is open after all
                        return True
                    self.table.withdraw(client_id, claim)
                    return False
                finally:
                    sleeper.awake = True  # changes and timers until it sleeps pass it by
                if claim.triggered:
                    return True
        finally:
            sleeper.over()
            del sleeping[client_id]
            self.table.stop_waiting(client_id)
            self.traffic.recorder.blocked(start, env.now, client_id)
            self.traffic.close_wait(client)

    def _watch(self, client: TrafficClient, sleeper: Sleeper, start_s: float,
               long: bool) -> None:
        """When a blocked AGV looks again, besides being granted its claim: at its first look
        time (`Sleeper`) past a threshold of its wait (`give_way_after_s`, `replan_after_s`);
        a suspect of a wait-for cycle, at its next; blocked long, at the next after a lock its
        way out depends on may have become free (the ways into the nodes after its own, the
        zones it holds) or another AGV queued for what it holds (it may give way)."""
        config = self.traffic.config
        now = self.table.env.now
        due = [sleeper.first_look_waited(t)
               for t in (config.give_way_after_s, config.replan_after_s) if now - start_s < t]
        if client.id in self.table.suspects:
            due.append(sleeper.next_look())
        alarm_s = min(due, default=math.inf)
        if alarm_s < math.inf and (alarm_s < sleeper.alarm_s or sleeper.alarm_s <= now):
            self.alarms.set(sleeper, alarm_s, sleeper.eid)
        if long and not sleeper.watching:  # (what it holds and where it stands stay put)
            sleeper.watching = True
            for lock in self._way_out_locks(client):
                lock.watchers.append(sleeper)
            nodes, others = self.table.held_locks(client.id)
            for lock in nodes + others:
                lock.holder_watchers.append(sleeper)
            for zone_lock in self.table.zones_of(client.id).values():  # others may leave it,
                lock = cast(Lock, zone_lock.resource)  # and the hops the other way open up
                lock.watchers.append(sleeper)

    def _way_out_locks(self, client: TrafficClient) -> list[Lock]:
        """The locks whose freeing may open a way out for a client blocked at its node: those
        of entering each next node (the node, its mutex zones, the corridor or same-direction
        zone of the segment)."""
        table = self.table
        layout = table.layout
        node = client.node
        waited = table.waiting.get(client.id)
        locks: list[Lock] = []
        for nxt in self.traffic.next_nodes[node]:
            lock = table.node_locks[nxt]
            if lock is waited:
                continue  # the way it waits for: no way out through it
            locks.append(lock)
            locks.extend(table.zone_locks[z.id] for z in layout.mutex_zones_at.get(nxt, ()))
            along = layout.direction_zone_of(node, nxt)
            if along is not None:
                locks.append(table.zone_locks[along[0].id])
            corridor = layout.corridor_of(node, nxt)
            if corridor is not None:
                locks.append(table.corridor_locks[corridor.id])
        return locks

    def _wait_zone(self, client: TrafficClient, zone_id: str, gate: Lock, claim: Claim,
                   may_escape: bool = True) -> Generator[simpy.Event, Any, bool]:
        """`wait` for a zone, its waiting time counted for the zone."""
        start = self.table.env.now
        ok = yield from self.wait(client, gate, claim, may_escape)
        if start < self.table.env.now:
            self.traffic.recorder.zone_waited(zone_id, start, self.table.env.now)
        if ok:
            self.traffic.zone_since[client.id][zone_id] = self.table.env.now
        return ok

    def _take_direction(self, client: TrafficClient,
                        need: Need) -> Generator[simpy.Event, Any, bool]:
        """Hold a same-direction zone for `need.direction` before driving along it from
        `need.entry`: by asking (waiting outside, or, holding it the other way, turning once
        alone inside). False if the client gave up waiting."""
        client_id = client.id
        zone_id = need.zone_id
        assert need.entry is not None
        held = self.table.zones[client_id].get(zone_id)
        since = self.traffic.zone_since[client_id].get(zone_id, self.table.env.now)
        claim = self.table.request(client_id, need.lock, direction=need.direction)
        if not (yield from self._wait_zone(client, zone_id, need.lock, claim)):
            return False
        if held is not None:  # a turn inside: the claim it held ends here
            self.traffic.record_zone(client_id, zone_id, held, since)
            self.table.turned(client_id, claim)
            client.note("zone_turn", f"{zone_id} {DIRECTION_NAMES[need.direction]}")
        self.traffic.note_entry(client_id, zone_id, need.entry)
        return True

    def resolve_deadlock(self, client: TrafficClient) -> Escape | None:
        """Look for a wait-for cycle through `client` and resolve it. Returns the escape when
        the client itself must move; another victim is interrupted with `DeadlockVictim`."""
        if client.id not in self.table.suspects:
            return None  # no cycle closed through it since it last looked
        cycle = find_cycle(client.id, self.table.waiting)
        if cycle is None:
            self.table.suspects.discard(client.id)
            return None
        members = [self.table.clients[m] for m in cycle]
        if any(m.id in self.escapes.chosen or m.failing for m in members):
            return None  # already being resolved
        new = self.table.cycles.is_new(cycle, self.table.waiting)
        names = " ".join(str(m) for m in cycle)
        if new:
            locks = " ".join(str(self.table.waiting[m].key) for m in cycle)
            self.traffic.recorder.deadlocks += 1
            client.note("deadlock_detected", f"agvs {names} waiting for {locks}")
        # Member i holds the lock that member i-1 waits for; its escape must let go of it.
        options = [(m.id, self.escapes.escape_for(m, self.table.waiting[cycle[i - 1]]))
                   for i, m in enumerate(members)]
        chosen = self.traffic.victim_choice.choose(options)
        if chosen is None:
            if new:
                client.note("deadlock_unresolved", f"agvs {names}: no free way out yet")
            return None
        victim_id, escape = chosen
        victim = self.table.clients[victim_id]
        victim.note("deadlock_resolved", f"{escape.kind} via {' '.join(escape.path)}")
        self.escapes.chosen[victim_id] = escape
        if victim is client:
            return escape
        victim.on_deadlock_victim(DeadlockVictim(escape))
        return None

    def reenter(self, client: TrafficClient,
                access: str) -> Generator[simpy.Event, Any, Claim | None]:
        """Back onto the track at `access` once it (its corridor and zones) is free. None: the
        wait was broken (the client chosen to break a wait-for cycle), what it took given
        back."""
        client_id = client.id
        corridor = self.table.layout.corridor_at(access)
        taken: list[Claim] = []
        if corridor is not None:
            lock = self.table.corridor_locks[corridor.id]
            claim = self.table.request(client_id, lock)
            if not (yield from self.wait(client, lock, claim, may_escape=False)):
                return None
            taken.append(claim)
        for zone in self.traffic.zones_at(access):
            gate = self.table.zone_locks[zone.id]
            if not (yield from self._wait_zone(client, zone.id, gate,
                                               self.table.request(client_id, gate), False)):
                self.table.free_all(client_id, taken)
                self.traffic.release_left_zones(client_id)  # holding no node, it is inside none
                return None
        lock = self.table.node_locks[access]
        claim = self.table.request(client_id, lock)
        if not (yield from self.wait(client, lock, claim, may_escape=False)):
            self.table.free_all(client_id, taken)
            self.traffic.release_left_zones(client_id)
            return None
        return claim

    def try_allocate(self, client_id: int, hop: Hop) -> Claim | None:
        """Grant the whole hop now (its node, the corridors and zones it enters) if every
        module may allocate its part, else nothing; never waits. Returns the node's claim."""
        for module in self.traffic.modules_before_node:
            if module.needs(client_id, hop):
                break
        else:  # the node alone (`grant_now`, shortened)
            node = hop.node
            lock = self.table.node_locks[node]
            if lock.users or lock.put_queue:
                return None
            claim = lock.claim(client_id)
            claim.node = node
            self.table.nodes[client_id].add(claim)
            self.table.version += 1
            return claim
        needs = self.traffic.needs(client_id, hop)
        for m, need in needs:
            if not m.may_allocate(client_id, need):
                return None
        return self.traffic.grant_now(client_id, needs)

