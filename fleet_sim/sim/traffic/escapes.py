"""Ways out for a blocked AGV (escapes): another route whose first node is free, a circle
back round on one-way track, or a step back to a free neighbour; the traffic policies choose
among them (fleet_sim.sim.traffic.reactive, fleet_sim.sim.traffic.avoiding).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, cast

from fleet_sim.config.layout import Corridor
from fleet_sim.sim.traffic.deadlock import Escape
from fleet_sim.sim.traffic.locks import CorridorLock, Lock, NodeLock, ZoneLock
from fleet_sim.sim.traffic.table import TrafficClient
from fleet_sim.sim.traffic.zones import DirectedClaim, DirectionGate

if TYPE_CHECKING:
    from fleet_sim.sim.traffic.control import Traffic
    from fleet_sim.sim.traffic.routing import Routes

REROUTES_KEPT = 4096
"""Detours `escape_for` remembers by the lock waited for (forgotten all at once when full)."""
_UNKNOWN: Any = object()


class Escapes:
    """The escapes chosen for clients that have not taken them yet, and the search for them."""

    def __init__(self, traffic: Traffic) -> None:
        self.traffic = traffic
        self.table = traffic.table
        """What is held, by whom, and what is queued."""
        self.chosen: dict[int, Escape] = {}
        """Escapes chosen for clients that have not taken them yet."""
        self._reroutes: dict[tuple[Routes, str, str, Lock | None], list[str] | None] = {}
        """(routes, node, goal, lock waited for) -> the detour off that lock (`escape_for`
        asks it at every look of a blocked AGV; `Routes.route_avoiding` answers it from the
        sets to keep off, which cost more to make and hash than this key)."""

    def take_escape(self, client_id: int) -> Escape | None:
        """The escape chosen for the client, if any (it is then the client's to take)."""
        return self.chosen.pop(client_id, None)

    def other_way(self, client: TrafficClient, may_give_way: bool,
                  may_replan: bool) -> Escape | None:
        """Blocked long enough: another route if there is one; with someone queued behind,
        circulating rather than blocking them. The escape is kept for `take_escape`."""
        escape = self.another_route(client, may_give_way and self.table.blocks_others(client.id),
                                     may_replan)
        if escape is not None:
            self.chosen[client.id] = escape
        return escape

    def another_route(self, client: TrafficClient, give_way: bool,
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

    def escape_for(self, client: TrafficClient, must_free: Lock | None = None,
                   circulate: bool = True, backoff: bool = True) -> Escape | None:
        """A way out for a blocked AGV that lets go of `must_free` (a lock it holds that another
        AGV waits for): give up a corridor it has reserved but not entered, take another route
        whose first node is free, or back off to a free neighbour. `circulate`, `backoff`: False
        when the caller would not take that kind (it is then not looked for; looking changes
        nothing)."""
        client_id = client.id
        waited = self.table.waiting.get(client_id)
        node = client.node
        goal = client.goal
        inside: Corridor | None = None
        if must_free is not None and isinstance(must_free.key, CorridorLock):
            cid = must_free.key.corridor_id
            hold = self.table.corridors[client_id].get(cid)
            if hold is None or not hold[0].triggered or hold[1] is not None:
                return Escape("yield", (node,))
            inside = self.table.layout.corridors[cid]
        if must_free is not None and isinstance(must_free.key, ZoneLock):
            zone = self.table.layout.traffic_zone_by_id[must_free.key.zone_id]
            if not any(c.triggered and cast(Lock, c.resource).key in
                       {NodeLock(n) for n in zone.nodes}
                       for c in self.table.nodes[client_id]):
                return Escape("yield", (node,))  # holds the zone, not yet inside: give it up
        avoid_nodes: set[str] = set()
        avoid_edges = self.traffic.against(client_id) if self.traffic.against_hops else set()
        plain = not avoid_edges  # what to keep off follows from the lock waited for alone
        if waited is not None:
            key = waited.key
            if isinstance(key, NodeLock):
                avoid_nodes.add(key.node)
            elif isinstance(key, ZoneLock):
                avoid_nodes |= self.table.layout.traffic_zone_by_id[key.zone_id].nodes
            else:
                corridor = self.table.layout.corridors[key.corridor_id]
                avoid_nodes |= corridor.members
                avoid_edges |= corridor.segments
        routes = self.traffic.routes_of(client_id)
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
        for nxt in self.traffic.next_nodes[node]:
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
        routes = self.traffic.routes_of(client_id)
        for first in self.traffic.next_nodes[node]:
            if first in avoid_nodes or (node, first) in avoid_edges:
                continue
            if not routes.allows(node, first):
                continue
            if not self._free_to_enter(client_id, node, first):
                continue
            for second in self.traffic.next_nodes[first]:
                if second in avoid_nodes or (first, second) in avoid_edges or second == node:
                    continue
                if not routes.allows(first, second):
                    continue
                if self.table.layout.corridor_of(first, second) is not None \
                        or self.table.layout.direction_zone_of(first, second) is not None:
                    continue  # circulate on one-way track only
                back = self.traffic.route(second, goal, client_id)
                return Escape("circulate", (node, first, *back))
        return None

    def _free_to_enter(self, client_id: int, node: str, nxt: str) -> bool:
        if not self.table.node_locks[nxt].is_free:
            return False
        for zone in self.table.layout.mutex_zones_at.get(nxt, ()):
            if zone.id not in self.table.zones[client_id] \
                    and not self.table.zone_locks[zone.id].is_free:
                return False
        along = self.table.layout.direction_zone_of(node, nxt)
        if along is not None:
            zone, direction = along
            held = self.table.zones[client_id].get(zone.id)
            if held is not None and held.triggered:
                if cast(DirectedClaim, held).direction != direction:
                    return False
            elif not cast(DirectionGate, self.table.zone_locks[zone.id]).admits(direction):
                return False
        corridor = self.table.layout.corridor_of(node, nxt)
        if corridor is None or self.table.holds_corridor(client_id, corridor.id):
            return True
        return self.table.corridor_locks[corridor.id].is_free

