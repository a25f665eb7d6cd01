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
* How a hop is granted is the traffic policy's (`traffic.policy`, fleet_sim.sim.traffic.policy,
  looked up in fleet_sim.sim.traffic.policies.POLICIES): `reactive` queues for each part and
  finds and breaks wait-for cycles (fleet_sim.sim.traffic.reactive); `avoiding` grants only
  what keeps every AGV's plan finishable (fleet_sim.sim.traffic.avoiding). Escapes for a
  blocked AGV are fleet_sim.sim.traffic.escapes's.
* Mutex zones (the layout's `traffic_zones`, fleet_sim.sim.traffic.zones): at most N AGVs
  inside; an AGV takes the zone's lock (a `Gate`) before its first node in it.
* Same-direction zones (fleet_sim.sim.traffic.zones): AGVs inside all drive the aisle one
  way; an AGV takes the zone's lock (a `DirectionGate`) for the direction it enters by, and
  while it holds it with others, its routes and escapes keep off the aisle's hops the other
  way (alone, it may turn round).

The table itself (locks, holders, queues, claims, `version`) is fleet_sim.sim.traffic.table's
`Reservations`; `Traffic` owns one and adds routes, zone records and the drive's bookkeeping.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from typing import Any, cast

import simpy

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
from fleet_sim.sim.traffic.deadlock import (
    Escape,
    GentlestEscapeFirst,
    VictimChoice,
)
from fleet_sim.sim.traffic.locks import Claim
from fleet_sim.sim.traffic.policy import TrafficPolicy
from fleet_sim.sim.traffic.routing import Routes, SegmentCosts
from fleet_sim.sim.traffic.table import Reservations, TrafficClient
from fleet_sim.sim.traffic.waking import AlarmClock
from fleet_sim.sim.traffic.zones import DirectedClaim


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


class Traffic:
    """The reservation table: node and corridor locks, keyed by client."""

    def __init__(self, env: simpy.Environment, layout: Layout, motion: Motion,
                 recorder: Recorder, victim_choice: VictimChoice | None = None,
                 costs: RouteCosts | None = None, config: TrafficConfig | None = None, *,
                 strategy: Callable[[Traffic], TrafficPolicy]) -> None:
        self.env = env
        self.config = config if config is not None else TrafficConfig()
        """How long a blocked AGV waits before it looks again, gives way or replans."""
        self.layout = layout
        self.graph = layout.graph
        self.motion = motion
        self.routes = Routes(layout, motion)
        self.recorder = recorder
        self.victim_choice: VictimChoice = (victim_choice if victim_choice is not None
                                            else GentlestEscapeFirst())
        table = self.table = Reservations(env, layout)
        """What is held, by whom, and what is queued (the view the modules and policies get)."""
        self.clock = AlarmClock(env)
        """The run's alarms that mostly never ring: blocked AGVs' next looks, paused AGVs'
        E_101 timeouts (fleet_sim.sim.traffic.waking)."""
        self._share(table)
        self.next_nodes = {n: tuple(sorted(self.graph.successors(n))) for n in self.graph.nodes}
        """Node -> the nodes a segment leads to from it, sorted (escapes look in that order)."""
        self.blocks: dict[tuple[str, str], list[tuple[float, float]]] = {}
        """Scripted obstacles: segment (both directions) -> [(from_s, until_s)]."""
        self.known_blocks: dict[tuple[str, str], float] = {}
        """Blocks an AGV has reported: routes keep off them until they end."""
        self.motion_backend: MotionBackend | None = None
        """Moves the AGVs when set (`motion: sumo`); None: closed-form hops."""
        self._type_routes: dict[str, Routes] = {}
        """Vehicle type -> its routes (mixed fleets, layouts with `allowed_types`)."""
        self._client_routes: dict[int, Routes] = {}
        """Client id -> its type's routes; clients not listed use `routes`."""
        self.against_hops: dict[str, dict[int, frozenset[tuple[str, str]]]] = {
            z.id: {way: frozenset(hop for hop, d in z.hops.items() if d != way)
                   for way in (FORWARD, BACKWARD)}
            for z in layout.traffic_zones if z.kind == "same_direction"}
        """Same-direction zone id -> direction -> the aisle's hops the other way."""
        self.costs = costs if costs is not None else RouteCosts()
        self._weak: dict[tuple[str, str], float] = {
            (u, v): self.costs.weak_wifi_s for u, v, d in self.graph.edges(data=True)
            if self.costs.weak_wifi_s > 0 and d["rssi_dbm"] < self.costs.weak_rssi_dbm}
        """Weak-Wi-Fi segments and their extra route cost."""
        self.segment_costs = SegmentCosts(self._weak, self.costs.congestion_s, self.node_locks)
        """What costed routes add per segment, read from the node locks when searched."""
        self.zone_since: dict[int, dict[str, float]] = {}
        """Client id -> zone id -> when the client was given the zone it holds."""
        self.zone_entry: dict[int, dict[str, str]] = {}
        """Client id -> same-direction zone id -> the end node from which the client will
        drive in, while it holds the zone and is not inside yet."""
        self.open_waits: dict[int, tuple[float, str, int]] = {}
        """With moves recorded: client id -> the lock wait under way (since_s, lock,
        holder)."""
        self._take_modules(table)
        self.strategy: TrafficPolicy = strategy(self)
        """How hops are granted (`traffic.policy`, fleet_sim.sim.traffic.policies)."""

    def _share(self, table: Reservations) -> None:
        """The table's state and writes, under the names the drive and the policies use."""
        self.node_locks = table.node_locks
        self.junction_locks = table.junction_locks
        self.corridor_locks = table.corridor_locks
        self.zone_locks = table.zone_locks
        self.waiting = table.waiting
        self.clients = table.clients
        self.nodes_held = table.nodes
        self.corridors_held = table.corridors
        self.zones_held = table.zones
        self.request = table.request
        self.free = table.free
        self.withdraw = table.withdraw
        self.turned = table.turned
        self.entered_corridor = table.entered_corridor
        self.held_locks = table.held_locks
        self.corridors_of = table.corridors_of
        self.zones_of = table.zones_of
        self.holds_corridor = table.holds_corridor
        self.node_holder = table.node_holder
        self.holders = table.holders
        self.blocks_others = table.blocks_others
        self.past_m = table.past_m
        self.clearance_m = table.clearance_m
        self.start_waiting = table.start_waiting
        self.stop_waiting = table.stop_waiting

    def _take_modules(self, table: Reservations) -> None:
        """The allocation modules (fleet_sim.sim.traffic.allocation), in the order a queued
        request takes what a hop needs."""
        self.modules: tuple[AllocationModule, ...] = (
            CorridorModule(table), MutexZoneModule(table), SameDirectionModule(table),
            NodeModule(table))
        """What a hop needs, in the order a queued request takes it (allocation)."""
        self.active_modules = tuple(
            m for m in self.modules
            if m.name == "node" or (m.name == "corridor" and self.layout.corridors)
            or (m.name == "mutex" and self.layout.mutex_zones_at)
            or (m.name == "same_direction" and self.layout.direction_zones_at))
        """The modules this layout has resources for (the others never need anything)."""
        self.modules_before_node: tuple[AllocationModule, ...] = tuple(
            m for m in self.active_modules if m.name != "node")

    @property
    def version(self) -> int:
        """Changes of lock ownership and waits so far (`Reservations.version`)."""
        return self.table.version

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
        self.table.register(client)
        self.zone_since[client.id] = {}
        self.zone_entry[client.id] = {}

    def against(self, client_id: int | None) -> set[tuple[str, str]]:
        """The hops the client may not drive: along each same-direction zone it holds with
        other AGVs, the other way. Alone in one, it may turn round (and would get the turn at
        once)."""
        if client_id is None:
            return set()
        out: set[tuple[str, str]] = set()
        for zone_id, claim in self.zones_held[client_id].items():
            if isinstance(claim, DirectedClaim) and claim.triggered \
                    and any(cast(Claim, c).client_id != client_id
                            for c in self.zone_locks[zone_id].users):
                out |= self.against_hops[zone_id][claim.direction]
        return out

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
        against = self.against(client_id) if self.against_hops else None
        if against:  # on through a same-direction zone it holds with others, never back
            tries = [against | set(self.known_blocks), against] if self.known_blocks \
                else [against]
            for avoid in tries:
                forward = routes.route_costed(src, dest, self.segment_costs, frozenset(avoid)) \
                    if self.costs.active else routes.route_avoiding(src, dest, set(), avoid)
                if forward is not None:
                    return forward
        if self.costs.active:
            if self.known_blocks:
                around = routes.route_costed(src, dest, self.segment_costs,
                                             frozenset(self.known_blocks))
                if around is not None:
                    return around
            path = routes.route_costed(src, dest, self.segment_costs)
            assert path is not None  # the layout is strongly connected
            return path
        if self.known_blocks:
            around = routes.route_avoiding(src, dest, set(), set(self.known_blocks))
            if around is not None:
                return around
        return routes.route(src, dest)

    def entry_corridor(self, node: str, nxt: str | None) -> Corridor | None:
        """The corridor an AGV enters when it leaves `node` for `nxt`, if `node` is outside it."""
        if nxt is None:
            return None
        corridor = self.layout.corridor_of(node, nxt)
        if corridor is None or node in corridor.members:
            return None
        return corridor

    # ---- escapes and deadlocks --------------------------------------------------------------
    # ---- a hop's allocation (fleet_sim.sim.traffic.allocation) -------------------------------
    def needs(self, client_id: int, hop: Hop) -> list[tuple[AllocationModule, Need]]:
        return [(m, need) for m in self.active_modules for need in m.needs(client_id, hop)]

    def grant_now(self, client_id: int, needs: list[tuple[AllocationModule, Need]]) -> Claim:
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
                self.zone_since[client_id][need.zone_id] = now
            elif need.turn:  # avoiding: alone in the aisle, it turns round
                zone_id = need.zone_id
                held = self.zones_held[client_id][zone_id]
                claim = self.request(client_id, need.lock, direction=need.direction)
                self.record_zone(client_id, zone_id, held,
                                  self.zone_since[client_id].get(zone_id, now))
                self.turned(client_id, claim)
                self.zone_since[client_id][zone_id] = now
                self.clients[client_id].note(
                    "zone_turn", f"{zone_id} {DIRECTION_NAMES[need.direction]}")
                assert need.entry is not None
                self.note_entry(client_id, zone_id, need.entry)
            else:
                assert need.entry is not None
                self.request(client_id, need.lock, direction=need.direction)
                self.zone_since[client_id][need.zone_id] = now
                self.note_entry(client_id, need.zone_id, need.entry)
        assert node_claim is not None
        self.strategy.granted(client_id, node_claim.node)
        return node_claim

    def parking_at(self, node: str) -> Place | None:
        """The parking area whose access is `node`, if any."""
        for place in self.layout.parking:
            if place.nodes[0] == node:
                return place
        return None

    def close_wait(self, client: TrafficClient) -> None:
        opened = self.open_waits.pop(client.id, None)
        if opened is None:
            return
        since, lock, holder = opened
        self.recorder.moved(MoveRecord(client.id, "wait", since, self.env.now, client.node,
                                       lock, holder))

    def note_entry(self, client_id: int, zone_id: str, entry: str) -> None:
        """The client holds same-direction zone `zone_id` and will drive in from `entry` (if
        `entry` is an end of it, not inside)."""
        if entry not in self.layout.traffic_zone_by_id[zone_id].nodes:
            self.zone_entry[client_id][zone_id] = entry

    def zones_at(self, node: str) -> list[TrafficZone]:
        """The mutex zones and the same-direction zone that `node` lies inside."""
        zones = list(self.layout.mutex_zones_at.get(node, ()))
        aisle = self.layout.direction_zones_at.get(node)
        if aisle is not None:
            zones.append(aisle)
        return zones

    # ---- the policy's (fleet_sim.sim.traffic.policy) ---------------------------------------------
    def allocate(self, client: TrafficClient,
                 hop: Hop) -> Generator[simpy.Event, Any, Claim | None]:
        """Queue the client for the whole hop (its node, the corridors and zones it enters) as
        the policy grants it. Returns the node's claim once all are held; None if the client
        gave up waiting, what it took for the hop given back."""
        return (yield from self.strategy.allocate(client, hop))

    def try_allocate(self, client_id: int, hop: Hop) -> Claim | None:
        """Grant the whole hop now if the policy may, else nothing; never waits."""
        return self.strategy.try_allocate(client_id, hop)

    def reenter(self, client: TrafficClient,
                access: str) -> Generator[simpy.Event, Any, Claim | None]:
        """Back onto the track at `access` once the policy grants it (its corridor and zones
        with it). None: the wait was broken, what it took given back."""
        return (yield from self.strategy.reenter(client, access))

    def take_escape(self, client_id: int) -> Escape | None:
        """The escape chosen for the client, if any (it is then the client's to take)."""
        return self.strategy.take_escape(client_id)

    def escape_for(self, client: TrafficClient) -> Escape | None:
        """A way out for a blocked client."""
        return self.strategy.escape_for(client)

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
            self.zone_since[client_id][zone.id] = self.env.now
        claim = self.request(client_id, self.node_locks[node])
        if not claim.triggered:
            raise SimulationError(f"AGV {client_id} starts on node {node}, already occupied")
        self.strategy.placed(client_id, node)
        return claim

    def let_go(self, client_id: int) -> None:
        """The client left the track (its nodes given back): let go of its corridors and of
        the zones it is not inside."""
        for cid in list(self.corridors_held[client_id]):
            self._release_corridor(client_id, cid)
        self.release_left_zones(client_id)
        self.strategy.left(client_id)

    def check_hop(self, client_id: int, u: str, v: str) -> None:
        """The client is about to drive u -> v: it must hold the corridor it drives in."""
        corridor = self.layout.corridor_of(u, v)
        if corridor is not None and corridor.id not in self.corridors_held[client_id]:
            raise SimulationError(f"AGV {client_id} about to enter corridor {corridor.id} "
                                  f"({u} -> {v}) without holding it")

    def hopped(self, client_id: int, u: str, v: str, body: Sequence[str]) -> None:
        """The client drove u -> v; `body`: the nodes it still holds, oldest first (v last).
        Let go of the corridors and zones it has left."""
        self.strategy.hopped(client_id, v)
        corridor = self.layout.corridor_of(u, v)
        if corridor is not None:
            self.entered_corridor(client_id, corridor.id)
        if self.corridors_held[client_id]:
            self._release_left_corridors(client_id, body)
        if self.zones_held[client_id]:
            self.release_left_zones(client_id)

    def drop_pending(self, client_id: int) -> None:
        """A drive ended: give back the corridors and aisles reserved but not entered."""
        self._drop_pending_corridors(client_id)
        if self.zone_entry[client_id]:
            self.drop_pending_zones(client_id)

    def give_up(self, client_id: int) -> None:
        """The client gave up a hop and looks for another way: `drop_pending`, and the zones
        it is not inside."""
        self.drop_pending(client_id)
        if self.zones_held[client_id]:
            self.release_left_zones(client_id)

    def end_of_run(self, client_id: int) -> None:
        """The run ends: record the client's wait and zones under way, as far as they got."""
        self.close_wait(self.clients[client_id])
        if self.recorder.record_moves:
            since = self.zone_since[client_id]
            for zone_id, claim in self.zones_held[client_id].items():
                if claim.triggered and zone_id in since:
                    self.record_zone(client_id, zone_id, claim, since[zone_id])

    # ---- releasing ----------------------------------------------------------------------------
    def _release_corridor(self, client_id: int, cid: int) -> None:
        claim, _ = self.corridors_held[client_id][cid]
        self.free(client_id, claim)

    def _release_left_corridors(self, client_id: int, body: Sequence[str]) -> None:
        """Let go of corridors the client has entered and fully left, and of pending ones
        whose entry node it is no longer at or heading to."""
        corridors = self.corridors_held[client_id]
        if not corridors:
            return
        spots: set[str] | None = None  # made when needed (freeing corridors leaves it as is)
        for cid, (_, entry) in list(corridors.items()):
            corridor = self.layout.corridors[cid]
            if entry is not None:
                if spots is None:
                    spots = self.table.spots(client_id)
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
        for cid, (_, entry) in list(self.corridors_held[client_id].items()):
            if entry is not None:
                self._release_corridor(client_id, cid)

    def release_left_zones(self, client_id: int) -> None:
        """Let go of the zones in which the client holds no node, but for a same-direction
        zone it is about to drive into from a node it holds."""
        spots = self.table.spots(client_id)
        zones = self.layout.traffic_zone_by_id
        entries = self.zone_entry[client_id]
        for zone_id, claim in list(self.zones_held[client_id].items()):
            if not claim.triggered:
                continue
            if spots & zones[zone_id].nodes:
                entries.pop(zone_id, None)  # inside
                continue
            entry = entries.get(zone_id)
            if entry is not None and entry in spots:
                continue
            self._free_zone(client_id, zone_id, claim)

    def drop_pending_zones(self, client_id: int) -> None:
        """Let go of the same-direction zones the client holds but has not driven into."""
        entries = self.zone_entry[client_id]
        for zone_id in list(entries):
            claim = self.zones_held[client_id].get(zone_id)
            if claim is not None and claim.triggered:
                self._free_zone(client_id, zone_id, claim)
            else:
                del entries[zone_id]

    def _free_zone(self, client_id: int, zone_id: str, claim: Claim) -> None:
        self.zone_entry[client_id].pop(zone_id, None)
        self.free(client_id, claim)
        self.record_zone(client_id, zone_id, claim,
                          self.zone_since[client_id].pop(zone_id, self.env.now))

    def record_zone(self, client_id: int, zone_id: str, claim: Claim, since: float) -> None:
        """The client held zone `zone_id` from `since` until now (the replay's holders)."""
        now = self.env.now
        self.recorder.occupied("zone", zone_id, client_id, since, now)
        if self.recorder.record_moves:
            direction = claim.direction if isinstance(claim, DirectedClaim) else 0
            self.recorder.moved(MoveRecord(client_id, "zone", since, now, zone_id,
                                           DIRECTION_NAMES[direction]))
