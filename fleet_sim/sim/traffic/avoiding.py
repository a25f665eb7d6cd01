"""The deadlock-avoiding traffic policy (`traffic.policy: avoiding`): every AGV on the track
declares a plan that ends in parking, and a hop is granted only when every part of it is free
and the grant keeps every plan finishable (fleet_sim.sim.traffic.avoidance has the scheme and
its proof). A blocked AGV waits for a wake (a lock let go of, or the held-back AGVs woken), not
in a lock's queue; blocked `replan_after_s`, it takes another route as a new plan the check
accepts, or none.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import TYPE_CHECKING, Any, cast

import simpy
from simpy.events import Timeout

from fleet_sim.sim.traffic.allocation import AllocationModule, Hop, Need
from fleet_sim.sim.traffic.avoidance import Plans
from fleet_sim.sim.traffic.deadlock import Escape, find_cycle
from fleet_sim.sim.traffic.escapes import Escapes
from fleet_sim.sim.traffic.locks import Claim, FirstOf, Lock, ZoneLock
from fleet_sim.sim.traffic.table import TrafficClient

if TYPE_CHECKING:
    from fleet_sim.sim.traffic.control import Traffic


class AvoidingPolicy:
    """Grant a hop only if the state stays safe with it (`TrafficPolicy`)."""

    name = "avoiding"

    def __init__(self, traffic: Traffic) -> None:
        self.traffic = traffic
        self.table = traffic.table
        """What is held, by whom, and what is queued."""
        self.escapes = Escapes(traffic)
        self.plans = Plans(traffic.table, traffic.routes)
        """Every AGV's plan and the safety checks."""
        self._wakes: dict[Lock, simpy.Event] = {}
        """Lock -> the event that wakes the AGVs waiting for it to be let go of."""
        self._wake_all: simpy.Event | None = None
        """The event that wakes the AGVs held back by the safety check."""
        self._held_back: set[int] = set()
        """The AGVs on the track the safety check holds back; while there are any, no AGV
        comes back onto the track (it would only add to the queue)."""
        traffic.table.on_free.append(self._woken)

    def placed(self, client_id: int, node: str) -> None:
        """Placed on the track at the start: its plan is to drive off (unchecked)."""
        plans = self.plans
        plans.declare(client_id, plans.exit_route(self.traffic.routes_of(client_id), node))

    def hopped(self, client_id: int, node: str) -> None:
        self.plans.advance(client_id, node)

    def left(self, client_id: int) -> None:
        self.plans.clear(client_id)
        self._wake_held_back()

    def granted(self, client_id: int, node: str) -> None:
        self.plans.took(client_id, node)

    def take_escape(self, client_id: int) -> Escape | None:
        return self.escapes.take_escape(client_id)

    def escape_for(self, client: TrafficClient) -> Escape | None:
        return self.escapes.escape_for(client)

    def try_allocate(self, client_id: int, hop: Hop) -> Claim | None:
        """Grant the whole hop now if every module may allocate its part and the grant keeps
        the state safe, else nothing; never waits. Returns the node's claim."""
        traffic = self.traffic
        needs = traffic.needs(client_id, hop)
        for m, need in needs:
            if not m.may_allocate(client_id, need):
                return None
        if not self.plans.may_grant(
                client_id, [(need.lock, need.direction) for _, need in needs], hop.node):
            return None
        return traffic.grant_now(client_id, needs)

    def declare(self, client: TrafficClient, goal: str, via: str | None = None) -> bool:
        """Make the route from where the client stands to `goal`, and on to the nearest
        parking access, its plan if the state stays safe with it; False: refused, the plan in
        force stays. `via`: the node it is on its way to and holds (stopped mid-hop by a
        reset), which the route goes through first."""
        route = self.traffic.route
        path = route(client.node, goal, client.id) if via is None \
            else [client.node, *route(via, goal, client.id)]
        return self._declare_path(client.id, path)

    def _declare_path(self, client_id: int, path: list[str]) -> bool:
        """`path` (to the goal), and on to the parking access nearest its end, as the client's
        plan if the state stays safe with it."""
        plans = self.plans
        path = path + plans.exit_route(self.traffic.routes_of(client_id), path[-1])[1:]  # cached
        if not plans.may_declare(client_id, path):
            return False
        plans.declare(client_id, path)
        self._wake_held_back()
        return True

    def plan_step(self, client_id: int, ahead: int) -> str | None:
        """the node `ahead` hops further along the client's plan, if any."""
        return self.plans.step(client_id, ahead)

    def _woken(self, lock: Lock) -> None:
        """`lock` was let go of: wake who waits for it, and who the safety check held back."""
        event = self._wakes.pop(lock, None)
        if event is not None:
            event.succeed()
        self._wake_held_back()

    def _wake_held_back(self) -> None:
        event = self._wake_all
        if event is not None:
            self._wake_all = None
            event.succeed()

    def _wake_on(self, lock: Lock | None) -> simpy.Event:
        if lock is None:
            if self._wake_all is None:
                self._wake_all = self.table.env.event()
            return self._wake_all
        event = self._wakes.get(lock)
        if event is None:
            event = self._wakes[lock] = self.table.env.event()
        return event

    def allocate(self, client: TrafficClient, hop: Hop,
                 needs_of: Callable[[], list[tuple[AllocationModule, Need]]] | None = None
                 ) -> Generator[simpy.Event, Any, Claim | None]:
        """wait until every part of the hop is free and the grant keeps the state
        safe, then take it all at once. The wait is recorded like any lock wait (for the one
        not free, or, held back by the check, for the hop's node); a wait-for cycle, which the
        check should make impossible, is still looked for and recorded. `needs_of`: what the
        hop needs, if not the modules' answer (back onto the track)."""
        plans = self.plans
        env = self.table.env
        client_id = client.id
        start: float | None = None
        zone_wait: str | None = None
        retry: Timeout | None = None
        retry_until = 0.0
        config = self.traffic.config
        look: Timeout | None = None
        try:
            while True:
                needs = self.traffic.needs(client_id, hop) if needs_of is None else needs_of()
                blocker: Lock | None = None
                for m, need in needs:
                    if not (m.may_allocate(client_id, need) or (need.turn and all(
                            cast(Claim, c).client_id == client_id for c in need.lock.users))):
                        blocker = need.lock
                        break
                if blocker is None and (needs_of is None or not self._held_back) \
                        and plans.may_grant(
                            client_id, [(need.lock, need.direction) for _, need in needs],
                            hop.node, waits=True):
                    self._held_back.discard(client_id)
                    granted = self.traffic.grant_now(client_id, needs)
                    self._wake_held_back()
                    return granted
                if blocker is None and needs_of is None:
                    self._held_back.add(client_id)
                shown = blocker if blocker is not None else self.table.node_locks[hop.node]
                if start is None:
                    start = env.now
                    zone_wait = self._wait_began(client_id, shown)
                if self.table.waiting.get(client_id) is not shown:
                    self._waits_for(client, shown)
                wake = self._wake_on(blocker)
                if needs_of is None:  # driving: blocked long, another way (checked as a plan)
                    waited = env.now - start + 1e-9
                    if waited >= config.replan_after_s and self._replan_safely(client):
                        return None
                    long = waited >= config.give_way_after_s
                    if look is None or look.processed:  # from give_way_after_s on, it looks
                        # (and asks for the grant) again every deadlock_check_s
                        look = Timeout(env, config.deadlock_check_s if long
                                       else config.give_way_after_s - waited + 1e-9)
                    wake = FirstOf(env, wake, look)
                retry_at = plans.retry_at(client_id) if blocker is None else None
                if retry_at is not None and retry_at > env.now:
                    # walked and refused a moment ago: asked again at every wake, walked
                    # again from `retry_at` on, so it is woken then too
                    if retry is None or retry_until != retry_at:
                        retry, retry_until = Timeout(env, retry_at - env.now), retry_at
                    if not retry.processed:
                        wake = FirstOf(env, wake, retry)
                yield wake
        finally:
            if client_id in self._held_back:
                self._held_back.discard(client_id)
                self._wake_held_back()
            if start is not None:
                self.table.stop_waiting(client_id)
                self.traffic.recorder.blocked(start, env.now, client_id)
                self.traffic.close_wait(client)
                if zone_wait is not None and start < env.now:
                    self.traffic.recorder.zone_waited(zone_wait, start, env.now)

    def _wait_began(self, client_id: int, shown: Lock) -> str | None:
        """Record the start of a wait like any lock wait, for `shown`; the zone it is for,
        if a zone."""
        zone_wait = shown.key.zone_id if isinstance(shown.key, ZoneLock) else None
        recorder = self.traffic.recorder
        recorder.wait_began(client_id, self.table.env.now, zone_wait)
        if recorder.record_moves:
            holder = shown.holder
            self.traffic.open_waits[client_id] = (self.table.env.now, str(shown.key),
                                                  -1 if holder is None else holder)
        return zone_wait

    def _waits_for(self, client: TrafficClient, shown: Lock) -> None:
        """The client now waits for `shown` (a wait-for cycle it closes is recorded)."""
        if client.id in self.table.waiting:
            self.table.stop_waiting(client.id)
        self.table.start_waiting(client.id, shown)
        client.began_waiting(shown)
        self._record_cycle(client)

    def _replan_safely(self, client: TrafficClient) -> bool:
        """Avoiding, blocked `replan_after_s`: another route to the goal whose first node is
        free, as reactive traffic's `other_way` finds it, taken as the plan if the state stays
        safe with it. True: the plan changed, the hop waited for is given up. (No giving way:
        `blocks_others` sees who queues on a lock, and AGVs waiting under this policy do not
        queue on locks.)"""
        escape = self.escapes.another_route(client, False, True) \
            if client.goal is not None else None
        if escape is None or not self._declare_path(client.id, list(escape.path)):
            return False
        client.note(escape.kind, escape.brief())
        return True

    def _record_cycle(self, client: TrafficClient) -> None:
        """record a wait-for cycle through the client, if one closed (none should)."""
        if client.id not in self.table.suspects:
            return
        cycle = find_cycle(client.id, self.table.waiting)
        if cycle is None or not self.table.cycles.is_new(cycle, self.table.waiting):
            return
        self.traffic.recorder.deadlocks += 1
        names = " ".join(str(m) for m in cycle)
        locks = " ".join(str(self.table.waiting[m].key) for m in cycle)
        client.note("deadlock_detected", f"agvs {names} waiting for {locks}")

    def reenter(self, client: TrafficClient,
                access: str) -> Generator[simpy.Event, Any, Claim]:
        """back onto the track at `access` with the plan of driving off again there
        (it holds nothing, so that plan closes no cycle), once the access and its corridor and
        zones are free and the grant keeps the state safe."""
        plans = self.plans
        client_id = client.id
        path = plans.path.get(client_id)
        if path is None or path[0] != access or plans.at[client_id] != 0:
            plans.declare(client_id, plans.exit_route(self.traffic.routes_of(client_id), access))
        modules = {m.name: m for m in self.traffic.modules}

        def needs_of() -> list[tuple[AllocationModule, Need]]:
            out: list[tuple[AllocationModule, Need]] = []
            corridor = self.table.layout.corridor_at(access)
            if corridor is not None:
                out.append((modules["corridor"], Need(self.table.corridor_locks[corridor.id])))
            out += [(modules["mutex"], Need(self.table.zone_locks[z.id]))
                    for z in self.traffic.zones_at(access)]
            out.append((modules["node"], Need(self.table.node_locks[access])))
            return out

        claim = yield from self.allocate(client, Hop(access, access), needs_of)
        assert claim is not None
        return claim

