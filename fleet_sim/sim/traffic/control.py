"""Traffic control: the one reservation table of node and corridor locks, and what it tells the
AGVs about routes, escapes and deadlocks.

Like openTCS's Scheduler, `Traffic` owns every allocation: its clients (the AGVs' drivers,
anything that satisfies `TrafficClient`) ask it once per hop for the hop's whole set
(`allocate(client, hop)`, queued; `try_allocate`, all or nothing now), each kind of resource
answering through its module whether it may allocate (fleet_sim.sim.traffic.allocation);
traffic waits for the claims, gives back what a given-up request took, and lets go of
corridors and zones the client has left. Clients give back node claims (`free`). A client
cannot free what it does not hold. Nobody else writes or reads locks; traffic never reads a
client's own bookkeeping, only what `TrafficClient` declares and what it is told (`hopped`).

Rules (see docs/background/engine.md for why):

* One AGV per node. An AGV holds the node it stands on, the node it drives to, and the nodes
  behind it until its body and the minimum gap have cleared them. It reserves the node after the
  next one on the fly (look-ahead) so it can pass through without stopping; when that node is
  taken it brakes to stop at the next node. On a segment there is therefore one AGV at a time,
  in order, at least the minimum gap behind the one ahead: no overtaking and no overlap.
* Corridors (chains of two-way segments) are single-track: an AGV takes the corridor lock before
  it takes the node from which it enters the corridor, so two AGVs never meet head-on.
* Routes follow the shortest free-flow travel time (fleet_sim.sim.traffic.routing), unless the
  planner gives routes a cost (`RouteCosts`, scenario `traffic.congestion_cost_s` and
  `traffic.weak_wifi_cost_s`, both 0 by default, the spec's shortest routes): seconds added per
  AGV standing on or queued for the node a segment leads to, at the moment the route is planned,
  and per segment whose Wi-Fi signal is weak (below `rules.weak_rssi_dbm`, E_002), where the
  link may drop. Dispatching still measures free-flow travel times.
* A wait-for cycle is looked for whenever an AGV starts waiting (fleet_sim.sim.traffic.deadlock),
  and, while a cycle it was found in may still stand, every `deadlock_check_s` while it waits. A
  cycle is recorded and resolved by the `DeadlockPolicy` handed to `Traffic`: one member takes
  another route or backs off.
* Why only then: an AGV waits for one lock at a time, so the wait-for graph has at most one edge
  out of each AGV, and a lock passed on goes to an AGV that thereby stops waiting. The only
  change that can close a cycle is therefore an AGV starting to wait, and the cycle then runs
  through it. AGVs that no cycle was found for do not walk their wait chains again while they
  wait (`_suspects`): before, every blocked AGV walked its whole chain every `deadlock_check_s`
  when anything had changed anywhere, which in a long queue cost (queue length)^2 per check
  period, the largest cost of a congested run with 200 AGVs.
* Mutex zones (the layout's `traffic_zones`, fleet_sim.sim.traffic.zones): at most N AGVs
  inside; an AGV takes the zone's lock (a `Gate`) before its first node in it.
* Same-direction zones (fleet_sim.sim.traffic.zones): AGVs inside all drive the aisle one
  way; an AGV takes the zone's lock (a `DirectionGate`) for the direction it enters by, and
  while it holds it with others, its routes and escapes keep off the aisle's hops the other
  way (alone, it may turn round).
* Giving way: an AGV that has waited `give_way_after_s` for a corridor or a side track while
  another AGV queues behind it drives on and comes back round (circulates) instead of blocking
  the main loop. This keeps loops flowing, which avoids most deadlocks by construction.

`version` counts changes of lock ownership and waits: a blocked AGV that sees the same count as
at its last look has nothing new to find.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Generator, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, cast

import simpy
from simpy.events import Timeout

from fleet_sim.config.layout import BACKWARD, FORWARD, Corridor, Layout, Place, TrafficZone
from fleet_sim.config.scenario import TrafficConfig
from fleet_sim.errors import SimulationError
from fleet_sim.model.kinematics import Motion, MotionBackend
from fleet_sim.model.records import MoveRecord, Recorder
from fleet_sim.sim.traffic.allocation import (
    DIRECTION_NAMES,
    AllocationModule,
    CorridorModule,
    Hop,
    MutexZoneModule,
    Need,
    NodeModule,
    SameDirectionModule,
)
from fleet_sim.sim.traffic.avoidance import Plans
from fleet_sim.sim.traffic.deadlock import (
    DeadlockPolicy,
    DeadlockVictim,
    Escape,
    GentlestEscapeFirst,
    KnownCycles,
    find_cycle,
)
from fleet_sim.sim.traffic.locks import Claim, CorridorLock, FirstOf, Lock, NodeLock, ZoneLock
from fleet_sim.sim.traffic.routing import Routes
from fleet_sim.sim.traffic.zones import ANY_DIRECTION, DirectedClaim, DirectionGate, Gate

REROUTES_KEPT = 4096
"""Detours `escape_for` remembers by the lock waited for (forgotten all at once when full)."""
_UNKNOWN: Any = object()


@dataclass(frozen=True)
class RouteCosts:
    """Extra route cost per segment (seconds); all zero: shortest free-flow routes."""

    congestion_s: float = 0.0
    """Per AGV on or queued for the node the segment leads to, when the route is planned."""
    weak_wifi_s: float = 0.0
    """Per segment with a Wi-Fi signal below `weak_rssi_dbm`."""
    weak_rssi_dbm: float = -70.0

    @property
    def active(self) -> bool:
        return self.congestion_s > 0 or self.weak_wifi_s > 0


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


class Traffic:
    """The reservation table: node and corridor locks, keyed by client."""

    def __init__(self, env: simpy.Environment, layout: Layout, motion: Motion,
                 recorder: Recorder, policy: DeadlockPolicy | None = None,
                 costs: RouteCosts | None = None, config: TrafficConfig | None = None) -> None:
        self.env = env
        self.config = config if config is not None else TrafficConfig()
        """How long a blocked AGV waits before it looks again, gives way or replans."""
        self.layout = layout
        self.graph = layout.graph
        self.motion = motion
        self.routes = Routes(layout, motion)
        self.recorder = recorder
        self.policy: DeadlockPolicy = policy if policy is not None else GentlestEscapeFirst()
        self.node_locks = {n: Lock(env, NodeLock(n)) for n in self.graph.nodes}
        self.junction_locks = frozenset(self.node_locks[n] for n in self.graph.nodes
                                        if self.graph.in_degree(n) >= 2)
        """The locks of the nodes more than one segment leads into (where AGVs cross or merge;
        the avoiding policy's walk keeps out of them, fleet_sim.sim.traffic.avoidance)."""
        self._next_nodes = {n: tuple(sorted(self.graph.successors(n))) for n in self.graph.nodes}
        """Node -> the nodes a segment leads to from it, sorted (escapes look in that order)."""
        self._reroutes: dict[tuple[Routes, str, str, Lock | None], list[str] | None] = {}
        """(routes, node, goal, lock waited for) -> the detour off that lock (`escape_for`
        asks it at every look of a blocked AGV; `Routes.route_avoiding` answers it from the
        sets to keep off, which cost more to make and hash than this key)."""
        self.corridor_locks = {c.id: Lock(env, CorridorLock(c.id)) for c in layout.corridors}
        self.waiting: dict[int, Lock] = {}
        """Client id -> the lock it waits for."""
        self.blocks: dict[tuple[str, str], list[tuple[float, float]]] = {}
        """Scripted obstacles: segment (both directions) -> [(from_s, until_s)]."""
        self.known_blocks: dict[tuple[str, str], float] = {}
        """Blocks an AGV has reported: routes keep off them until they end."""
        self.version = 0
        self.motion_backend: MotionBackend | None = None
        """Moves the AGVs when set (`motion: sumo`); None: closed-form hops."""
        self._clients: dict[int, TrafficClient] = {}
        self._nodes: dict[int, set[Claim]] = {}
        """Client id -> its node claims (granted or waiting)."""
        self._corridors: dict[int, dict[int, CorridorHold]] = {}
        """Client id -> corridor id -> its corridor claims, in the order it asked for them."""
        self._escapes: dict[int, Escape] = {}
        """Escapes chosen for clients that have not taken them yet."""
        self._cycles = KnownCycles()
        self._type_routes: dict[str, Routes] = {}
        """Vehicle type -> its routes (mixed fleets, layouts with `allowed_types`)."""
        self._client_routes: dict[int, Routes] = {}
        """Client id -> its type's routes; clients not listed use `routes`."""
        self.zone_locks: dict[str, Gate] = {}
        """Mutex and same-direction zone id -> its lock."""
        for z in layout.traffic_zones:
            if z.kind == "mutex":
                self.zone_locks[z.id] = Gate(env, ZoneLock(z.id), z.capacity or 1)
            elif z.kind == "same_direction":
                self.zone_locks[z.id] = DirectionGate(env, ZoneLock(z.id), z.capacity)
        self._against_hops: dict[str, dict[int, frozenset[tuple[str, str]]]] = {
            z.id: {way: frozenset(hop for hop, d in z.hops.items() if d != way)
                   for way in (FORWARD, BACKWARD)}
            for z in layout.traffic_zones if z.kind == "same_direction"}
        """Same-direction zone id -> direction -> the aisle's hops the other way."""
        self._zones: dict[int, dict[str, Claim]] = {}
        """Client id -> zone id -> its zone claims (granted or waiting)."""
        self.costs = costs if costs is not None else RouteCosts()
        self._weak: dict[tuple[str, str], float] = {
            (u, v): self.costs.weak_wifi_s for u, v, d in self.graph.edges(data=True)
            if self.costs.weak_wifi_s > 0 and d["rssi_dbm"] < self.costs.weak_rssi_dbm}
        """Weak-Wi-Fi segments and their extra route cost."""
        self._suspects: set[int] = set()
        """Clients found in a wait-for cycle that may still stand: they look again while they
        wait; nobody else needs to (see the module docstring)."""
        self._zone_since: dict[int, dict[str, float]] = {}
        """Client id -> zone id -> when the client was given the zone it holds."""
        self._zone_entry: dict[int, dict[str, str]] = {}
        """Client id -> same-direction zone id -> the end node from which the client will
        drive in, while it holds the zone and is not inside yet."""
        self._open_waits: dict[int, tuple[float, str, int]] = {}
        """With moves recorded: client id -> the lock wait under way (since_s, lock,
        holder)."""
        self.modules: tuple[AllocationModule, ...] = (
            CorridorModule(self), MutexZoneModule(self), SameDirectionModule(self),
            NodeModule(self))
        """What a hop needs, in the order a queued request takes it (allocation)."""
        self._active_modules = tuple(
            m for m in self.modules
            if m.name == "node" or (m.name == "corridor" and layout.corridors)
            or (m.name == "mutex" and layout.mutex_zones_at)
            or (m.name == "same_direction" and layout.direction_zones_at))
        """The modules this layout has resources for (the others never need anything)."""
        self._modules_before_node: tuple[AllocationModule, ...] = tuple(
            m for m in self._active_modules if m.name != "node")
        self.plans: Plans | None = Plans(self) if self.config.policy == "avoiding" else None
        """`traffic.policy: avoiding`: every AGV's plan and the safety checks (None:
        reactive)."""
        self._wakes: dict[Lock, simpy.Event] = {}
        """Avoiding: lock -> the event that wakes the AGVs waiting for it to be let go of."""
        self._wake_all: simpy.Event | None = None
        self._held_back: set[int] = set()
        """Avoiding: the AGVs on the track the safety check holds back; while there are any,
        no AGV comes back onto the track (it would only add to the queue)."""
        """Avoiding: the event that wakes the AGVs held back by the safety check."""

    @property
    def zone_ids(self) -> tuple[str, ...]:
        """The mutex and same-direction zones traffic hands out, in the layout's order."""
        return tuple(self.zone_locks)

    # ---- vehicle types ----------------------------------------------------------------------
    def add_vehicle_type(self, name: str, motion: Motion) -> None:
        """Route AGVs of type `name` on the segments open to it, at its own top speed."""
        self._type_routes[name] = Routes(self.layout, motion, name)

    def assign_type(self, client_id: int, name: str) -> None:
        """Client `client_id` is an AGV of type `name` (added with `add_vehicle_type`)."""
        self._client_routes[client_id] = self._type_routes[name]

    def routes_of(self, client_id: int | None) -> Routes:
        """The routes and hop kinematics of a client's vehicle type."""
        if client_id is None:
            return self.routes
        return self._client_routes.get(client_id, self.routes)

    # ---- clients and the table --------------------------------------------------------------
    def register(self, client: TrafficClient) -> None:
        self._clients[client.id] = client
        self._nodes[client.id] = set()
        self._corridors[client.id] = {}
        self._zones[client.id] = {}
        self._zone_since[client.id] = {}
        self._zone_entry[client.id] = {}

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
            held = self._zones[client_id].get(key.zone_id)
            turn = held is not None and held.triggered
            claim: Claim = DirectedClaim(lock, client_id, direction, turn)
            if not turn:
                self._zones[client_id][key.zone_id] = claim
            self.version += 1
            return claim
        claim = lock.claim(client_id)
        if isinstance(key, NodeLock):
            claim.node = key.node
            self._nodes[client_id].add(claim)
        elif isinstance(key, ZoneLock):
            self._zones[client_id][key.zone_id] = claim
        else:
            self._corridors[client_id][key.corridor_id] = (claim, entry)
        self.version += 1
        return claim

    def held_locks(self, client_id: int) -> tuple[list[Lock], list[Lock]]:
        """The node locks and the corridor and zone locks the client holds (granted)."""
        nodes = [cast(Lock, c.resource) for c in self._nodes[client_id] if c.triggered]
        others = [cast(Lock, c.resource) for c, _ in self._corridors[client_id].values()
                  if c.triggered]
        others += [cast(Lock, c.resource) for c in self._zones[client_id].values()
                   if c.triggered]
        return nodes, others

    def past_m(self, client_id: int) -> dict[str, float]:
        """How far the client has driven past each node behind it (`TrafficClient.past_m`)."""
        return self._clients[client_id].past_m()

    def clearance_m(self, client_id: int) -> float:
        """How far past a node the client lets go of it (`TrafficClient.clear_m`)."""
        return self._clients[client_id].clear_m

    def free(self, client_id: int, claim: Claim) -> None:
        """Give back a lock the client holds."""
        lock: Lock = claim.resource  # type: ignore[assignment]  # a Claim's is a Lock
        if claim.client_id != client_id or claim not in lock.users:
            raise SimulationError(f"AGV {client_id} cannot free {lock.key}: it does not hold "
                                  f"it (holder: {lock.holder})")
        lock.release(claim)
        if type(lock.key) is NodeLock:  # `_forget`, for a node
            self._nodes[client_id].discard(claim)
            self.version += 1
        else:
            self._forget(client_id, lock, claim)
        if self.plans is not None:
            self._woken(lock)

    def withdraw(self, client_id: int, claim: Claim) -> None:
        """Stop waiting for a claim not yet granted."""
        lock = cast(Lock, claim.resource)
        if claim.client_id != client_id or claim.triggered:
            raise SimulationError(f"AGV {client_id} cannot withdraw its claim on {lock.key}: "
                                  "it is not its own waiting claim")
        claim.cancel()
        self._forget(client_id, lock, claim)

    def _forget(self, client_id: int, lock: Lock, claim: Claim) -> None:
        key = lock.key
        if isinstance(key, NodeLock):
            self._nodes[client_id].discard(claim)
        elif isinstance(key, ZoneLock):
            if self._zones[client_id].get(key.zone_id) is claim:
                del self._zones[client_id][key.zone_id]
        else:
            hold = self._corridors[client_id].get(key.corridor_id)
            if hold is not None and hold[0] is claim:
                del self._corridors[client_id][key.corridor_id]
        self.version += 1

    def turned(self, client_id: int, claim: Claim) -> None:
        """A turn the client asked for inside a same-direction zone is granted: its claim the
        old way is given back, the new one is the client's claim on the zone."""
        key = cast(Lock, claim.resource).key
        assert isinstance(key, ZoneLock) and claim.triggered
        self.free(client_id, self._zones[client_id][key.zone_id])
        self._zones[client_id][key.zone_id] = claim

    def entered_corridor(self, client_id: int, corridor_id: int) -> None:
        """The client has driven into a corridor it reserved."""
        claim, _ = self._corridors[client_id][corridor_id]
        self._corridors[client_id][corridor_id] = (claim, None)

    def corridors_of(self, client_id: int) -> Mapping[int, CorridorHold]:
        """The client's corridor claims (corridor id -> claim, entry node), oldest first."""
        return self._corridors[client_id]

    def zones_of(self, client_id: int) -> Mapping[str, Claim]:
        """The client's zone claims (zone id -> claim)."""
        return self._zones[client_id]

    def against(self, client_id: int | None) -> set[tuple[str, str]]:
        """The hops the client may not drive: along each same-direction zone it holds with
        other AGVs, the other way. Alone in one, it may turn round (and would get the turn at
        once)."""
        if client_id is None:
            return set()
        out: set[tuple[str, str]] = set()
        for zone_id, claim in self._zones[client_id].items():
            if isinstance(claim, DirectedClaim) and claim.triggered \
                    and any(cast(Claim, c).client_id != client_id
                            for c in self.zone_locks[zone_id].users):
                out |= self._against_hops[zone_id][claim.direction]
        return out

    def holds_corridor(self, client_id: int, corridor_id: int) -> bool:
        hold = self._corridors[client_id].get(corridor_id)
        return hold is not None and hold[0].triggered

    def start_waiting(self, client_id: int, lock: Lock) -> None:
        self.waiting[client_id] = lock
        self.version += 1
        cycle = find_cycle(client_id, self.waiting)
        if cycle is not None:
            self._suspects.update(cycle)

    def stop_waiting(self, client_id: int) -> None:
        del self.waiting[client_id]
        self._suspects.discard(client_id)
        self.version += 1

    def node_holder(self, client_id: int) -> tuple[TrafficClient, str] | None:
        """The client holding the node `client_id` waits for, and that node (None: it waits
        for no node, or for a free one)."""
        lock = self.waiting.get(client_id)
        if lock is None or not isinstance(lock.key, NodeLock):
            return None
        holder = lock.holder
        if holder is None or holder == client_id:
            return None
        return self._clients[holder], lock.key.node

    def holders(self) -> Iterator[tuple[str, int]]:
        """(node, client id) for every held node lock (for invariant checks)."""
        for node, lock in self.node_locks.items():
            holder = lock.holder
            if holder is not None:
                yield node, holder

    # ---- routes -----------------------------------------------------------------------------
    def travel_time_s(self, src: str, dest: str, client_id: int | None = None) -> float:
        """Free-flow travel time from src to dest (for client `client_id`'s vehicle type)."""
        return self.routes_of(client_id).travel_time_s(src, dest)

    def block(self, u: str, v: str, from_s: float, until_s: float) -> None:
        for key in ((u, v), (v, u)):
            self.blocks.setdefault(key, []).append((from_s, until_s))

    def blocked_until(self, u: str, v: str, now_s: float) -> float | None:
        """End of the scripted block on u -> v in force now, if any; reported to routing."""
        for start, end in self.blocks.get((u, v), ()):
            if start <= now_s < end:
                self.known_blocks[(u, v)] = end
                self.known_blocks[(v, u)] = end
                return end
        return None

    def route(self, src: str, dest: str, client_id: int | None = None) -> list[str]:
        """Nodes from src to dest by shortest free-flow travel time (plus the route costs, if
        any), src included; around segments reported blocked when there is a way round (for
        client `client_id`'s vehicle type)."""
        routes = self.routes_of(client_id)
        if self.known_blocks:
            now = self.env.now
            self.known_blocks = {k: t for k, t in self.known_blocks.items() if t > now}
        against = self.against(client_id) if self._against_hops else None
        if against:  # on through a same-direction zone it holds with others, never back
            tries = [against | set(self.known_blocks), against] if self.known_blocks \
                else [against]
            for avoid in tries:
                forward = routes.route_costed(src, dest, self._extra_cost, frozenset(avoid)) \
                    if self.costs.active else routes.route_avoiding(src, dest, set(), avoid)
                if forward is not None:
                    return forward
        if self.costs.active:
            if self.known_blocks:
                around = routes.route_costed(src, dest, self._extra_cost,
                                             frozenset(self.known_blocks))
                if around is not None:
                    return around
            path = routes.route_costed(src, dest, self._extra_cost)
            assert path is not None  # the layout is strongly connected
            return path
        if self.known_blocks:
            around = routes.route_avoiding(src, dest, set(), set(self.known_blocks))
            if around is not None:
                return around
        return routes.route(src, dest)

    def _extra_cost(self, u: str, v: str) -> float:
        cost = self._weak.get((u, v), 0.0)
        if self.costs.congestion_s > 0:
            lock = self.node_locks[v]
            cost += self.costs.congestion_s * (len(lock.users) + len(lock.put_queue))
        return cost

    def entry_corridor(self, node: str, nxt: str | None) -> Corridor | None:
        """The corridor an AGV enters when it leaves `node` for `nxt`, if `node` is outside it."""
        if nxt is None:
            return None
        corridor = self.layout.corridor_of(node, nxt)
        if corridor is None or node in corridor.members:
            return None
        return corridor

    # ---- escapes and deadlocks --------------------------------------------------------------
    def take_escape(self, client_id: int) -> Escape | None:
        """The escape chosen for the client, if any (it is then the client's to take)."""
        return self._escapes.pop(client_id, None)

    def other_way(self, client: TrafficClient, may_give_way: bool,
                  may_replan: bool) -> Escape | None:
        """Blocked long enough: another route if there is one; with someone queued behind,
        circulating rather than blocking them. The escape is kept for `take_escape`."""
        escape = self._another_route(client, may_give_way and self.blocks_others(client.id),
                                     may_replan)
        if escape is not None:
            self._escapes[client.id] = escape
        return escape

    def _another_route(self, client: TrafficClient, give_way: bool,
                       may_replan: bool) -> Escape | None:
        """Blocked long (`other_way`, `_replan_safely`): a route whose first node is free, or,
        giving way, a circle; the other escapes are not looked for."""
        if not (give_way or may_replan):
            return None
        escape = self.escape_for(client, circulate=give_way, backoff=False)
        if escape is None or not (escape.kind == "reroute"
                                  or (give_way and escape.kind == "circulate")):
            return None
        return escape

    def resolve_deadlock(self, client: TrafficClient) -> Escape | None:
        """Look for a wait-for cycle through `client` and resolve it. Returns the escape when
        the client itself must move; another victim is interrupted with `DeadlockVictim`."""
        if client.id not in self._suspects:
            return None  # no cycle closed through it since it last looked
        cycle = find_cycle(client.id, self.waiting)
        if cycle is None:
            self._suspects.discard(client.id)
            return None
        members = [self._clients[m] for m in cycle]
        if any(m.id in self._escapes or m.failing for m in members):
            return None  # already being resolved
        new = self._cycles.is_new(cycle, self.waiting)
        names = " ".join(str(m) for m in cycle)
        if new:
            locks = " ".join(str(self.waiting[m].key) for m in cycle)
            self.recorder.deadlocks += 1
            client.note("deadlock_detected", f"agvs {names} waiting for {locks}")
        # Member i holds the lock that member i-1 waits for; its escape must let go of it.
        options = [(m.id, self.escape_for(m, self.waiting[cycle[i - 1]]))
                   for i, m in enumerate(members)]
        chosen = self.policy.choose(options)
        if chosen is None:
            if new:
                client.note("deadlock_unresolved", f"agvs {names}: no free way out yet")
            return None
        victim_id, escape = chosen
        victim = self._clients[victim_id]
        victim.note("deadlock_resolved", f"{escape.kind} via {' '.join(escape.path)}")
        self._escapes[victim_id] = escape
        if victim is client:
            return escape
        victim.on_deadlock_victim(DeadlockVictim(escape))
        return None

    def escape_for(self, client: TrafficClient, must_free: Lock | None = None,
                   circulate: bool = True, backoff: bool = True) -> Escape | None:
        """A way out for a blocked AGV that lets go of `must_free` (a lock it holds that another
        AGV waits for): give up a corridor it has reserved but not entered, take another route
        whose first node is free, or back off to a free neighbour. `circulate`, `backoff`: False
        when the caller would not take that kind (it is then not looked for; looking changes
        nothing)."""
        client_id = client.id
        waited = self.waiting.get(client_id)
        node = client.node
        goal = client.goal
        inside: Corridor | None = None
        if must_free is not None and isinstance(must_free.key, CorridorLock):
            cid = must_free.key.corridor_id
            hold = self._corridors[client_id].get(cid)
            if hold is None or not hold[0].triggered or hold[1] is not None:
                return Escape("yield", (node,))
            inside = self.layout.corridors[cid]
        if must_free is not None and isinstance(must_free.key, ZoneLock):
            zone = self.layout.traffic_zone_by_id[must_free.key.zone_id]
            if not any(c.triggered and cast(Lock, c.resource).key in
                       {NodeLock(n) for n in zone.nodes} for c in self._nodes[client_id]):
                return Escape("yield", (node,))  # holds the zone, not yet inside: give it up
        avoid_nodes: set[str] = set()
        avoid_edges = self.against(client_id) if self._against_hops else set()
        plain = not avoid_edges  # what to keep off follows from the lock waited for alone
        if waited is not None:
            key = waited.key
            if isinstance(key, NodeLock):
                avoid_nodes.add(key.node)
            elif isinstance(key, ZoneLock):
                avoid_nodes |= self.layout.traffic_zone_by_id[key.zone_id].nodes
            else:
                corridor = self.layout.corridors[key.corridor_id]
                avoid_nodes |= corridor.members
                avoid_edges |= corridor.segments
        routes = self.routes_of(client_id)
        if goal is not None and (avoid_nodes or avoid_edges):
            if plain:  # the same question as route_avoiding's, asked by the lock waited for
                known = (routes, node, goal, waited)
                path = self._reroutes.get(known, _UNKNOWN)
                if path is _UNKNOWN:
                    path = routes.route_avoiding(node, goal, avoid_nodes, avoid_edges)
                    if len(self._reroutes) >= REROUTES_KEPT:
                        self._reroutes.clear()
                    self._reroutes[known] = path
            else:
                path = routes.route_avoiding(node, goal, avoid_nodes, avoid_edges)
            if path is not None and len(path) > 1 \
                    and self._free_to_enter(client_id, node, path[1]) \
                    and (inside is None or any(n not in inside.members for n in path[1:])):
                return Escape("reroute", tuple(path))
        if circulate and goal is not None and inside is None and (avoid_nodes or avoid_edges):
            circle = self._circulate(client_id, node, goal, avoid_nodes, avoid_edges)
            if circle is not None:
                return circle
        if not backoff:
            return None
        for nxt in self._next_nodes[node]:
            if nxt in avoid_nodes or (node, nxt) in avoid_edges or nxt == client.next_node:
                continue
            if inside is not None and nxt in inside.members:
                continue
            if not routes.allows(node, nxt):
                continue
            if self._free_to_enter(client_id, node, nxt):
                return Escape("backoff", (node, nxt))
        return None

    def _circulate(self, client_id: int, node: str, goal: str, avoid_nodes: set[str],
                   avoid_edges: set[tuple[str, str]]) -> Escape | None:
        """Drive on two hops past what blocks the way (a busy corridor, a full siding) and come
        back round by the usual route: a loop's answer to waiting in everyone's way."""
        routes = self.routes_of(client_id)
        for first in self._next_nodes[node]:
            if first in avoid_nodes or (node, first) in avoid_edges:
                continue
            if not routes.allows(node, first):
                continue
            if not self._free_to_enter(client_id, node, first):
                continue
            for second in self._next_nodes[first]:
                if second in avoid_nodes or (first, second) in avoid_edges or second == node:
                    continue
                if not routes.allows(first, second):
                    continue
                if self.layout.corridor_of(first, second) is not None \
                        or self.layout.direction_zone_of(first, second) is not None:
                    continue  # circulate on one-way track only
                back = self.route(second, goal, client_id)
                return Escape("circulate", (node, first, *back))
        return None

    def blocks_others(self, client_id: int) -> bool:
        """True if another AGV waits for a node or corridor that the client holds."""
        for claim in self._nodes[client_id]:
            if claim.triggered and claim.resource.put_queue:
                return True
        for claim, _ in self._corridors[client_id].values():
            if claim.triggered and claim.resource.put_queue:
                return True
        for claim in self._zones[client_id].values():
            if claim.triggered and claim.resource.put_queue:
                return True
        return False

    def _free_to_enter(self, client_id: int, node: str, nxt: str) -> bool:
        if not self.node_locks[nxt].is_free:
            return False
        for zone in self.layout.mutex_zones_at.get(nxt, ()):
            if zone.id not in self._zones[client_id] and not self.zone_locks[zone.id].is_free:
                return False
        along = self.layout.direction_zone_of(node, nxt)
        if along is not None:
            zone, direction = along
            held = self._zones[client_id].get(zone.id)
            if held is not None and held.triggered:
                if cast(DirectedClaim, held).direction != direction:
                    return False
            elif not cast(DirectionGate, self.zone_locks[zone.id]).admits(direction):
                return False
        corridor = self.layout.corridor_of(node, nxt)
        if corridor is None or self.holds_corridor(client_id, corridor.id):
            return True
        return self.corridor_locks[corridor.id].is_free

    # ---- a hop's allocation (fleet_sim.sim.traffic.allocation) -------------------------------
    def _needs(self, client_id: int, hop: Hop) -> list[tuple[AllocationModule, Need]]:
        return [(m, need) for m in self._active_modules for need in m.needs(client_id, hop)]

    def try_allocate(self, client_id: int, hop: Hop) -> Claim | None:
        """Grant the whole hop now (its node, the corridors and zones it enters) if every
        module may allocate its part (and, avoiding deadlocks, if the grant keeps the state
        safe), else nothing; never waits. Returns the node's claim."""
        if self.plans is None:
            for module in self._modules_before_node:
                if module.needs(client_id, hop):
                    break
            else:  # the node alone (`_grant_now`, shortened)
                node = hop.node
                lock = self.node_locks[node]
                if lock.users or lock.put_queue:
                    return None
                claim = lock.claim(client_id)
                claim.node = node
                self._nodes[client_id].add(claim)
                self.version += 1
                return claim
        needs = self._needs(client_id, hop)
        for m, need in needs:
            if not m.may_allocate(client_id, need):
                return None
        if self.plans is not None and not self.plans.may_grant(
                client_id, [(need.lock, need.direction) for _, need in needs], hop.node):
            return None
        return self._grant_now(client_id, needs)

    def _grant_now(self, client_id: int, needs: list[tuple[AllocationModule, Need]]) -> Claim:
        """Grant every part of a hop at once (each may be allocated)."""
        now = self.env.now
        node_claim: Claim | None = None
        for m, need in needs:  # granted at once (never scheduled): their order is unseen
            kind = m.name
            if kind == "node":
                node_claim = self.request(client_id, need.lock)
            elif kind == "corridor":
                self.request(client_id, need.lock, entry=need.entry)
            elif kind == "mutex":
                self.request(client_id, need.lock)
                self._zone_since[client_id][need.zone_id] = now
            elif need.turn:  # avoiding: alone in the aisle, it turns round
                zone_id = need.zone_id
                held = self._zones[client_id][zone_id]
                claim = self.request(client_id, need.lock, direction=need.direction)
                self._record_zone(client_id, zone_id, held,
                                  self._zone_since[client_id].get(zone_id, now))
                self.turned(client_id, claim)
                self._zone_since[client_id][zone_id] = now
                self._clients[client_id].note(
                    "zone_turn", f"{zone_id} {DIRECTION_NAMES[need.direction]}")
                assert need.entry is not None
                self._note_entry(client_id, zone_id, need.entry)
            else:
                assert need.entry is not None
                self.request(client_id, need.lock, direction=need.direction)
                self._zone_since[client_id][need.zone_id] = now
                self._note_entry(client_id, need.zone_id, need.entry)
        assert node_claim is not None
        if self.plans is not None:
            self.plans.took(client_id, node_claim.node)
        return node_claim

    def allocate(self, client: TrafficClient,
                 hop: Hop) -> Generator[simpy.Event, Any, Claim | None]:
        """Queue the client for the whole hop: its parts are taken in the modules' order,
        waiting for each. Returns the node's claim once all are held; None if the client gave
        up waiting (deadlock victim, or blocked long with another way at hand), what it took
        for the hop given back (see fleet_sim.sim.traffic.allocation)."""
        if self.plans is not None:
            return (yield from self._allocate_safely(client, hop))
        client_id = client.id
        needs = self._needs(client_id, hop)
        taken: list[Claim] = []
        for m, need in needs:
            if m.name == "corridor":
                claim = self.request(client_id, need.lock, entry=need.entry)
                if not (yield from self.wait(client, need.lock, claim)):
                    self._free_all(client_id, taken)
                    return None
                taken.append(claim)
            elif m.name == "mutex":
                claim = self.request(client_id, need.lock)
                if not (yield from self._wait_zone(client, need.zone_id, need.lock, claim)):
                    self._free_all(client_id, taken)
                    self.release_left_zones(client_id)
                    return None
            elif m.name == "same_direction":
                if not (yield from self._take_direction(client, need)):
                    self._free_all(client_id, taken)
                    self._drop_pending_zones(client_id)
                    self.release_left_zones(client_id)
                    return None
            else:
                claim = self.request(client_id, need.lock)
                if not (yield from self.wait(client, need.lock, claim)):
                    self._free_all(client_id, taken)
                    self.release_left_zones(client_id)
                    return None
                return claim
        raise SimulationError(f"AGV {client_id}: a hop to {hop.node} without its node")

    # ---- avoiding deadlocks (traffic.policy: avoiding, fleet_sim.sim.traffic.avoidance) -------
    def declare(self, client: TrafficClient, goal: str) -> bool:
        """Make the route from where the client stands to `goal`, and on to the nearest
        parking access, its plan if the state stays safe with it; False: refused, the old plan
        stays in force."""
        return self._declare_path(client.id, self.route(client.node, goal, client.id))

    def _declare_path(self, client_id: int, path: list[str]) -> bool:
        """`path` (to the goal), and on to the parking access nearest its end, as the client's
        plan if the state stays safe with it."""
        plans = self.plans
        assert plans is not None
        path = path + plans.exit_route(self.routes_of(client_id), path[-1])[1:]  # cached
        if not plans.may_declare(client_id, path):
            return False
        plans.declare(client_id, path)
        self._wake_held_back()
        return True

    def parking_at(self, node: str) -> Place | None:
        """The parking area whose access is `node`, if any."""
        for place in self.layout.parking:
            if place.nodes[0] == node:
                return place
        return None

    def plan_step(self, client_id: int, ahead: int) -> str | None:
        """Avoiding: the node `ahead` hops further along the client's plan, if any."""
        assert self.plans is not None
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
                self._wake_all = self.env.event()
            return self._wake_all
        event = self._wakes.get(lock)
        if event is None:
            event = self._wakes[lock] = self.env.event()
        return event

    def _allocate_safely(self, client: TrafficClient, hop: Hop,
                         needs_of: Callable[[], list[tuple[AllocationModule, Need]]] | None
                         = None) -> Generator[simpy.Event, Any, Claim | None]:
        """Avoiding: wait until every part of the hop is free and the grant keeps the state
        safe, then take it all at once. The wait is recorded like any lock wait (for the one
        not free, or, held back by the check, for the hop's node); a wait-for cycle, which the
        check should make impossible, is still looked for and recorded. `needs_of`: what the
        hop needs, if not the modules' answer (back onto the track)."""
        plans = self.plans
        assert plans is not None
        env = self.env
        client_id = client.id
        start: float | None = None
        zone_wait: str | None = None
        retry: Timeout | None = None
        retry_until = 0.0
        config = self.config
        look: Timeout | None = None
        try:
            while True:
                needs = self._needs(client_id, hop) if needs_of is None else needs_of()
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
                    granted = self._grant_now(client_id, needs)
                    self._wake_held_back()
                    return granted
                if blocker is None and needs_of is None:
                    self._held_back.add(client_id)
                shown = blocker if blocker is not None else self.node_locks[hop.node]
                if start is None:
                    start = env.now
                    if isinstance(shown.key, ZoneLock):
                        zone_wait = shown.key.zone_id
                    self.recorder.wait_began(client_id, start, zone_wait)
                    if self.recorder.record_moves:
                        holder = shown.holder
                        self._open_waits[client_id] = (start, str(shown.key),
                                                       -1 if holder is None else holder)
                if self.waiting.get(client_id) is not shown:
                    if client_id in self.waiting:
                        self.stop_waiting(client_id)
                    self.start_waiting(client_id, shown)
                    client.began_waiting(shown)
                    self._record_cycle(client)
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
                self.stop_waiting(client_id)
                self.recorder.blocked(start, env.now, client_id)
                self._close_wait(client)
                if zone_wait is not None and start < env.now:
                    self.recorder.zone_waited(zone_wait, start, env.now)

    def _replan_safely(self, client: TrafficClient) -> bool:
        """Avoiding, blocked `replan_after_s`: another route to the goal whose first node is
        free, as reactive traffic's `other_way` finds it, taken as the plan if the state stays
        safe with it. True: the plan changed, the hop waited for is given up. (No giving way:
        `blocks_others` sees who queues on a lock, and AGVs waiting under this policy do not
        queue on locks.)"""
        escape = self._another_route(client, False, True) if client.goal is not None else None
        if escape is None or not self._declare_path(client.id, list(escape.path)):
            return False
        client.note(escape.kind, escape.brief())
        return True

    def _record_cycle(self, client: TrafficClient) -> None:
        """Avoiding: record a wait-for cycle through the client, if one closed (none should)."""
        if client.id not in self._suspects:
            return
        cycle = find_cycle(client.id, self.waiting)
        if cycle is None or not self._cycles.is_new(cycle, self.waiting):
            return
        self.recorder.deadlocks += 1
        names = " ".join(str(m) for m in cycle)
        locks = " ".join(str(self.waiting[m].key) for m in cycle)
        client.note("deadlock_detected", f"agvs {names} waiting for {locks}")

    def _reenter_safely(self, client: TrafficClient,
                        access: str) -> Generator[simpy.Event, Any, Claim]:
        """Avoiding: back onto the track at `access` with the plan of driving off again there
        (it holds nothing, so that plan closes no cycle), once the access and its corridor and
        zones are free and the grant keeps the state safe."""
        plans = self.plans
        assert plans is not None
        client_id = client.id
        path = plans.path.get(client_id)
        if path is None or path[0] != access or plans.at[client_id] != 0:
            plans.declare(client_id, plans.exit_route(self.routes_of(client_id), access))
        modules = {m.name: m for m in self.modules}

        def needs_of() -> list[tuple[AllocationModule, Need]]:
            out: list[tuple[AllocationModule, Need]] = []
            corridor = self.layout.corridor_at(access)
            if corridor is not None:
                out.append((modules["corridor"], Need(self.corridor_locks[corridor.id])))
            out += [(modules["mutex"], Need(self.zone_locks[z.id])) for z in self.zones_at(access)]
            out.append((modules["node"], Need(self.node_locks[access])))
            return out

        claim = yield from self._allocate_safely(client, Hop(access, access), needs_of)
        assert claim is not None
        return claim

    def _free_all(self, client_id: int, claims: list[Claim]) -> None:
        for claim in claims:
            self.free(client_id, claim)

    def wait(self, client: TrafficClient, lock: Lock, claim: Claim,
             may_escape: bool = True) -> Generator[simpy.Event, Any, bool]:
        """Wait for `claim`. Returns True once held; False if the client gave up (deadlock
        victim, or blocked for long with another route at hand) and the claim was withdrawn.
        Any other interrupt (a fault) withdraws or frees the claim and passes on."""
        if claim.triggered:
            return True
        env = self.env
        config = self.config
        client_id = client.id
        start = env.now
        self.start_waiting(client_id, lock)
        client.began_waiting(lock)
        self.recorder.wait_began(client_id, start,
                                 lock.key.zone_id if isinstance(lock.key, ZoneLock) else None)
        if self.recorder.record_moves:
            holder = lock.holder
            self._open_waits[client_id] = (start, str(lock.key), -1 if holder is None else holder)
        looked_at: tuple[int, bool, bool] | None = None
        give_way_after_s = config.give_way_after_s
        replan_after_s = config.replan_after_s
        check_s = config.deadlock_check_s
        try:
            while True:
                waited = env.now - start
                now_seen = (self.version, waited >= give_way_after_s, waited >= replan_after_s)
                if may_escape and now_seen != looked_at:  # nothing changed, nothing to look at
                    looked_at = now_seen
                    # (resolve_deadlock looks only for a suspect, other_way only once the AGV
                    # may give way or replan: the calls are left out otherwise)
                    if (client_id in self._suspects and self.resolve_deadlock(client) is not None) \
                            or ((now_seen[1] or now_seen[2])
                                and self.other_way(client, now_seen[1], now_seen[2]) is not None):
                        self.withdraw(client_id, claim)
                        return False
                try:
                    yield FirstOf(env, claim, Timeout(env, check_s))
                except simpy.Interrupt as interrupt:
                    if not isinstance(interrupt.cause, DeadlockVictim):
                        # a fault: let go and pass it on
                        if claim.triggered:
                            self.free(client_id, claim)
                        else:
                            self.withdraw(client_id, claim)
                        raise
                    if claim.triggered:
                        self.take_escape(client_id)  # the way is open after all
                        return True
                    self.withdraw(client_id, claim)
                    return False
                if claim.triggered:
                    return True
        finally:
            self.stop_waiting(client_id)
            self.recorder.blocked(start, env.now, client_id)
            self._close_wait(client)

    def _close_wait(self, client: TrafficClient) -> None:
        opened = self._open_waits.pop(client.id, None)
        if opened is None:
            return
        since, lock, holder = opened
        self.recorder.moved(MoveRecord(client.id, "wait", since, self.env.now, client.node,
                                       lock, holder))

    def _wait_zone(self, client: TrafficClient, zone_id: str, gate: Lock, claim: Claim,
                   may_escape: bool = True) -> Generator[simpy.Event, Any, bool]:
        """`wait` for a zone, its waiting time counted for the zone."""
        start = self.env.now
        ok = yield from self.wait(client, gate, claim, may_escape)
        if start < self.env.now:
            self.recorder.zone_waited(zone_id, start, self.env.now)
        if ok:
            self._zone_since[client.id][zone_id] = self.env.now
        return ok

    def _take_direction(self, client: TrafficClient,
                        need: Need) -> Generator[simpy.Event, Any, bool]:
        """Hold a same-direction zone for `need.direction` before driving along it from
        `need.entry`: by asking (waiting outside, or, holding it the other way, turning once
        alone inside). False if the client gave up waiting."""
        client_id = client.id
        zone_id = need.zone_id
        assert need.entry is not None
        held = self._zones[client_id].get(zone_id)
        since = self._zone_since[client_id].get(zone_id, self.env.now)
        claim = self.request(client_id, need.lock, direction=need.direction)
        if not (yield from self._wait_zone(client, zone_id, need.lock, claim)):
            return False
        if held is not None:  # a turn inside: the old claim ends here
            self._record_zone(client_id, zone_id, held, since)
            self.turned(client_id, claim)
            client.note("zone_turn", f"{zone_id} {DIRECTION_NAMES[need.direction]}")
        self._note_entry(client_id, zone_id, need.entry)
        return True

    def _note_entry(self, client_id: int, zone_id: str, entry: str) -> None:
        """The client holds same-direction zone `zone_id` and will drive in from `entry` (if
        `entry` is an end of it, not inside)."""
        if entry not in self.layout.traffic_zone_by_id[zone_id].nodes:
            self._zone_entry[client_id][zone_id] = entry

    def zones_at(self, node: str) -> list[TrafficZone]:
        """The mutex zones and the same-direction zone that `node` lies inside."""
        zones = list(self.layout.mutex_zones_at.get(node, ()))
        aisle = self.layout.direction_zones_at.get(node)
        if aisle is not None:
            zones.append(aisle)
        return zones

    # ---- on and off the track -----------------------------------------------------------------
    def place(self, client_id: int, node: str) -> Claim:
        """Put the client on `node` at the start (its corridor and zones with it)."""
        corridor = self.layout.corridor_at(node)
        if corridor is not None:
            claim = self.request(client_id, self.corridor_locks[corridor.id])
            if not claim.triggered:
                raise SimulationError(f"AGV {client_id} starts in corridor {corridor.id}, "
                                      "which another AGV already occupies")
        for zone in self.zones_at(node):
            if not self.request(client_id, self.zone_locks[zone.id]).triggered:
                raise SimulationError(f"AGV {client_id} starts on node {node} in zone "
                                      f"{zone.id}, which is full")
            self._zone_since[client_id][zone.id] = self.env.now
        claim = self.request(client_id, self.node_locks[node])
        if not claim.triggered:
            raise SimulationError(f"AGV {client_id} starts on node {node}, already occupied")
        if self.plans is not None:
            self.plans.declare(client_id, self.plans.exit_route(self.routes_of(client_id), node))
        return claim

    def reenter(self, client: TrafficClient,
                access: str) -> Generator[simpy.Event, Any, Claim | None]:
        """Back onto the track at `access` once it (its corridor and zones) is free. None: the
        wait was broken (the client chosen to break a wait-for cycle), what it took given
        back."""
        client_id = client.id
        if self.plans is not None:
            return (yield from self._reenter_safely(client, access))
        corridor = self.layout.corridor_at(access)
        taken: list[Claim] = []
        if corridor is not None:
            lock = self.corridor_locks[corridor.id]
            claim = self.request(client_id, lock)
            if not (yield from self.wait(client, lock, claim, may_escape=False)):
                return None
            taken.append(claim)
        for zone in self.zones_at(access):
            gate = self.zone_locks[zone.id]
            if not (yield from self._wait_zone(client, zone.id, gate,
                                               self.request(client_id, gate), False)):
                self._free_all(client_id, taken)
                self.release_left_zones(client_id)  # holding no node, it is inside none
                return None
        lock = self.node_locks[access]
        claim = self.request(client_id, lock)
        if not (yield from self.wait(client, lock, claim, may_escape=False)):
            self._free_all(client_id, taken)
            self.release_left_zones(client_id)
            return None
        return claim

    def let_go(self, client_id: int) -> None:
        """The client left the track (its nodes given back): let go of its corridors and of
        the zones it is not inside."""
        for cid in list(self._corridors[client_id]):
            self._release_corridor(client_id, cid)
        self.release_left_zones(client_id)
        if self.plans is not None:
            self.plans.clear(client_id)
            self._wake_held_back()

    def check_hop(self, client_id: int, u: str, v: str) -> None:
        """The client is about to drive u -> v: it must hold the corridor it drives in."""
        corridor = self.layout.corridor_of(u, v)
        if corridor is not None and corridor.id not in self._corridors[client_id]:
            raise SimulationError(f"AGV {client_id} about to enter corridor {corridor.id} "
                                  f"({u} -> {v}) without holding it")

    def hopped(self, client_id: int, u: str, v: str, body: Sequence[str]) -> None:
        """The client drove u -> v; `body`: the nodes it still holds, oldest first (v last).
        Let go of the corridors and zones it has left."""
        if self.plans is not None:
            self.plans.advance(client_id, v)
        corridor = self.layout.corridor_of(u, v)
        if corridor is not None:
            self.entered_corridor(client_id, corridor.id)
        if self._corridors[client_id]:
            self._release_left_corridors(client_id, body)
        if self._zones[client_id]:
            self.release_left_zones(client_id)

    def drop_pending(self, client_id: int) -> None:
        """A drive ended: give back the corridors and aisles reserved but not entered."""
        self._drop_pending_corridors(client_id)
        if self._zone_entry[client_id]:
            self._drop_pending_zones(client_id)

    def give_up(self, client_id: int) -> None:
        """The client gave up a hop and looks for another way: `drop_pending`, and the zones
        it is not inside."""
        self.drop_pending(client_id)
        if self._zones[client_id]:
            self.release_left_zones(client_id)

    def end_of_run(self, client_id: int) -> None:
        """The run ends: record the client's wait and zones under way, as far as they got."""
        self._close_wait(self._clients[client_id])
        if self.recorder.record_moves:
            since = self._zone_since[client_id]
            for zone_id, claim in self._zones[client_id].items():
                if claim.triggered and zone_id in since:
                    self._record_zone(client_id, zone_id, claim, since[zone_id])

    # ---- releasing ----------------------------------------------------------------------------
    def _spots(self, client_id: int) -> set[str]:
        """The nodes the client holds (stands on, drives to, or has not cleared yet)."""
        return {c.node for c in self._nodes[client_id] if c.triggered}

    def _release_corridor(self, client_id: int, cid: int) -> None:
        claim, _ = self._corridors[client_id][cid]
        self.free(client_id, claim)

    def _release_left_corridors(self, client_id: int, body: Sequence[str]) -> None:
        """Let go of corridors the client has entered and fully left, and of pending ones
        whose entry node it is no longer at or heading to."""
        corridors = self._corridors[client_id]
        if not corridors:
            return
        spots: set[str] | None = None  # made when needed (freeing corridors leaves it as is)
        for cid, (_, entry) in list(corridors.items()):
            corridor = self.layout.corridors[cid]
            if entry is not None:
                if spots is None:
                    spots = self._spots(client_id)
                if entry not in spots:
                    self._release_corridor(client_id, cid)
                continue
            if not corridor.members.isdisjoint(body):
                continue
            segments = corridor.segments
            for hop in itertools.pairwise(body):
                if hop in segments:
                    break
            else:
                self._release_corridor(client_id, cid)

    def _drop_pending_corridors(self, client_id: int) -> None:
        for cid, (_, entry) in list(self._corridors[client_id].items()):
            if entry is not None:
                self._release_corridor(client_id, cid)

    def release_left_zones(self, client_id: int) -> None:
        """Let go of the zones in which the client holds no node, but for a same-direction
        zone it is about to drive into from a node it holds."""
        spots = self._spots(client_id)
        zones = self.layout.traffic_zone_by_id
        entries = self._zone_entry[client_id]
        for zone_id, claim in list(self._zones[client_id].items()):
            if not claim.triggered:
                continue
            if spots & zones[zone_id].nodes:
                entries.pop(zone_id, None)  # inside
                continue
            entry = entries.get(zone_id)
            if entry is not None and entry in spots:
                continue
            self._free_zone(client_id, zone_id, claim)

    def _drop_pending_zones(self, client_id: int) -> None:
        """Let go of the same-direction zones the client holds but has not driven into."""
        entries = self._zone_entry[client_id]
        for zone_id in list(entries):
            claim = self._zones[client_id].get(zone_id)
            if claim is not None and claim.triggered:
                self._free_zone(client_id, zone_id, claim)
            else:
                del entries[zone_id]

    def _free_zone(self, client_id: int, zone_id: str, claim: Claim) -> None:
        self._zone_entry[client_id].pop(zone_id, None)
        self.free(client_id, claim)
        self._record_zone(client_id, zone_id, claim,
                          self._zone_since[client_id].pop(zone_id, self.env.now))

    def _record_zone(self, client_id: int, zone_id: str, claim: Claim, since: float) -> None:
        """The client held zone `zone_id` from `since` until now (the replay's holders)."""
        now = self.env.now
        self.recorder.occupied("zone", zone_id, client_id, since, now)
        if self.recorder.record_moves:
            direction = claim.direction if isinstance(claim, DirectedClaim) else 0
            self.recorder.moved(MoveRecord(client_id, "zone", since, now, zone_id,
                                           DIRECTION_NAMES[direction]))
