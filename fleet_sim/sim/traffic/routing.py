"""Routes and hop kinematics on a layout: what traffic control asks about the track.

Routes follow the shortest free-flow travel time (length / min(limit, VEL_MAX)), a vehicle
type's own (its top speed, its segment speed limits); route costs (`route_costed`) add seconds
per segment. Detours and costed routes are an A* search on plain adjacency lists, guided by the
free-flow table; detours and hop times are cached. Both matter because traffic asks for them on
the engine's hot path, each time an AGV is blocked or drives a hop. A costed route is searched
by the same A*, reading the node locks' occupancy in its loop (docs/background/engine.md,
"Congestion-aware routes"; tests/test_routing_costs.py).

`Routes` holds no locks and no clock; it only needs the layout and the vehicle's motion limits
(the fleet sizing estimate uses it too). A costed search is handed the node locks' occupancy
to read (`SegmentCosts`).

The choices where the issues were silent: docs/background/decisions/sim.md.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sized
from dataclasses import dataclass
from typing import Any, Protocol, cast

import networkx as nx

from fleet_sim.config.layout import Layout
from fleet_sim.model.kinematics import Motion, Piece, stop_entry_speed, traverse

Detour = tuple[str, str, frozenset[str], frozenset[tuple[str, str]]]
Weight = str | Callable[[str, str, dict[str, Any]], float | None]
NO_EDGES: frozenset[tuple[str, str]] = frozenset()
_UNKNOWN = object()
"""A detour not asked for yet (a cached detour may be None: there is none)."""
DETOUR_CACHE_SIZE = 2048
"""Detours remembered per vehicle type: the most recently asked (a few KB each; a 27-day run
asked 818 distinct ones, a year would ask more)."""


class Occupancy(Protocol):
    """A node's lock as a costed route sees it: the claims holding it and those queued."""

    @property
    def users(self) -> Sized: ...

    @property
    def put_queue(self) -> Sized: ...


@dataclass(frozen=True)
class SegmentCosts:
    """What a costed route adds to a segment's free-flow time, in seconds (never negative):
    the segment's own cost, if it has one, plus `per_agv_s` for each AGV on or queued for the
    node it leads to, read from that node's lock when the route is searched."""

    fixed_s: Mapping[tuple[str, str], float]
    """Segment u -> v -> its own cost (weak Wi-Fi); segments not listed add nothing."""
    per_agv_s: float
    """Seconds per AGV on or queued for the node (0: congestion costs nothing)."""
    locks: Mapping[str, Occupancy]
    """Node -> its lock."""

    def extra_s(self, u: str, v: str) -> float:
        """The seconds added to segment u -> v now: the definition, which `Routes._a_star`
        works out in its loop without the call."""
        cost = self.fixed_s.get((u, v), 0.0)
        if self.per_agv_s > 0:
            lock = self.locks[v]
            cost += self.per_agv_s * (len(lock.users) + len(lock.put_queue))
        return cost


class Routes:
    """Route tables, detours and the hop kinematics cache of one layout and vehicle type."""

    def __init__(self, layout: Layout, motion: Motion, vehicle_type: str | None = None) -> None:
        self.layout = layout
        self.graph = layout.graph
        self.motion = motion
        self.vehicle_type = vehicle_type
        """None: every segment, the graph's `free_time_s`. A type (mixed fleets, layouts
        with `allowed_types` or `speed_limit_mps_by_type`): only the segments open to it, at
        its own top speed and its type's speed limits."""
        self.weight: Weight = "free_time_s"
        """The edge weight of routes (networkx: an attribute name or a function)."""
        self._reverse_weight: Weight = "free_time_s"
        self._times: dict[tuple[str, str], float] = {}
        if vehicle_type is None:
            for _, _, data in self.graph.edges(data=True):
                data["free_time_s"] = data["length_m"] / min(data["speed_limit_mps"],
                                                             motion.max_speed_mps)
        else:
            times = {(u, v): data["length_m"] / self._limit(data)
                     for u, v, data in layout.type_graph(vehicle_type).edges(data=True)}
            self._times = times
            self.weight = self._type_weight
            self._reverse_weight = self._type_weight_reversed
        self._to_dest: dict[str, tuple[dict[str, float], dict[str, str]]] = {}
        self._pieces: dict[tuple[str | None, str, str], tuple[Piece, ...]] = {}
        self._stop_entry: dict[tuple[str, str, str], float] = {}
        self._detours: OrderedDict[Detour, list[str] | None] = OrderedDict()
        self._hops: dict[tuple[str | None, str, str, float, float], tuple[float, float]] = {}
        self.edge: dict[tuple[str, str], dict[str, Any]] = {
            (u, v): d for u, v, d in self.graph.edges(data=True)}
        """Segment u -> v's attributes (length_m, speed_limit_mps, rssi_dbm...)."""
        self.length_m: dict[tuple[str, str], float] = {
            key: data["length_m"] for key, data in self.edge.items()}
        """Segment u -> v's length."""
        self._succ: dict[str, tuple[tuple[str, float], ...]] = {
            u: tuple((v, d["free_time_s"]) for v, d in self.graph.succ[u].items())
            for u in self.graph.nodes} if vehicle_type is None else {
            u: tuple((v, self._times[(u, v)]) for v in self.graph.succ[u] if (u, v) in self._times)
            for u in self.graph.nodes}
        """Successors and free-flow hop times, in the graph's order (A* of the detours); for a
        vehicle type only the segments open to it, at its own speed."""

    def _limit(self, data: dict[str, Any]) -> float:
        """The speed an AGV of this type may drive a segment at (its attributes `data`): the
        least of its top speed, the segment's limit and the segment's limit for its type."""
        limit: float = data["speed_limit_mps"]
        if self.vehicle_type is not None:
            limit = min(limit, data["speed_limit_mps_by_type"].get(self.vehicle_type, limit))
        return min(limit, self.motion.max_speed_mps)

    def _type_weight(self, u: str, v: str, _data: dict[str, Any]) -> float | None:
        """Free-flow time of u -> v for this type; None (closed) off its segments."""
        return self._times.get((u, v))

    def _type_weight_reversed(self, u: str, v: str, _data: dict[str, Any]) -> float | None:
        """The same on the reversed graph, whose edge u -> v is the segment v -> u."""
        return self._times.get((v, u))

    def allows(self, u: str, v: str) -> bool:
        """May an AGV of this type drive u -> v?"""
        if self.vehicle_type is None:
            return True
        return (u, v) in self._times

    # ---- routes ---------------------------------------------------------------------------
    def _table(self, dest: str) -> tuple[dict[str, float], dict[str, str]]:
        table = self._to_dest.get(dest)
        if table is None:
            # predecessors, not paths: no path list per node (twice as quick on the
            # fulfilment centre); the first predecessor is the one a path would go through
            pred, dist = nx.dijkstra_predecessor_and_distance(
                self.graph.reverse(copy=False), dest, weight=self._reverse_weight)
            table = (dist, {n: p[0] for n, p in pred.items() if p})
            self._to_dest[dest] = table
        return table

    def travel_time_s(self, src: str, dest: str) -> float:
        """Free-flow travel time from src to dest (cached per destination)."""
        if self.vehicle_type is None:
            return self._table(dest)[0][src]
        return self._table(dest)[0].get(src, math.inf)  # no way there for this type

    def route(self, src: str, dest: str) -> list[str]:
        """Nodes from src to dest by shortest free-flow travel time, src included."""
        next_hop = self._table(dest)[1]
        path = [src]
        node = src
        while node != dest:
            node = next_hop[node]
            path.append(node)
        return path

    def route_avoiding(self, src: str, dest: str, avoid: set[str],
                       avoid_edges: set[tuple[str, str]] | None = None) -> list[str] | None:
        """Shortest route that keeps off `avoid` nodes and edges (cached per question)."""
        if dest in avoid or src in avoid:
            return None
        key = (src, dest, frozenset(avoid), frozenset(avoid_edges or ()))
        detours = self._detours
        found = detours.get(key, _UNKNOWN)
        if found is not _UNKNOWN:
            detours.move_to_end(key)
            return cast(list[str] | None, found)
        path = self._a_star(src, dest, key[2], key[3])
        detours[key] = path
        if len(detours) > DETOUR_CACHE_SIZE:
            detours.popitem(last=False)  # the least recently asked
        return path

    def route_costed(self, src: str, dest: str, costs: SegmentCosts,
                     avoid_edges: frozenset[tuple[str, str]] = NO_EDGES) -> list[str] | None:
        """Cheapest route by free-flow time plus `costs` per segment, off `avoid_edges`."""
        return self._a_star(src, dest, frozenset(), avoid_edges, costs)

    def _a_star(self, src: str, dest: str, avoid: frozenset[str],
                avoid_edges: frozenset[tuple[str, str]],
                costs: SegmentCosts | None = None) -> list[str] | None:
        """Shortest route from src to dest off `avoid` and `avoid_edges` (None if there is
        none), by free-flow time plus `costs`. The heuristic, the free-flow time to dest on the
        whole layout, is consistent, so the first time dest leaves the queue its route is the
        cheapest. A segment's extra cost (`SegmentCosts.extra_s`) is worked out in the loop,
        not by a call per segment, and added as (g + t) + extra, where it is not 0.0 (x + 0.0
        is x): the same sums, so the same routes, ties included, as with the call."""
        to_dest = self._table(dest)[0]
        if src not in to_dest:
            return None
        succ = self._succ
        fixed: Mapping[tuple[str, str], float] = costs.fixed_s if costs is not None else {}
        per_agv_s = costs.per_agv_s if costs is not None else 0.0
        locks = costs.locks if costs is not None else {}
        best = {src: 0.0}
        parent: dict[str, str] = {}
        done: set[str] = set()
        tie = itertools.count()
        push, pop, inf = heapq.heappush, heapq.heappop, math.inf
        queue = [(to_dest[src], next(tie), 0.0, src)]
        while queue:
            _, _, g, u = pop(queue)
            if u in done:
                continue
            if u == dest:
                path = [u]
                while u != src:
                    u = parent[u]
                    path.append(u)
                return path[::-1]
            done.add(u)
            for v, t in succ[u]:
                if v in done or (avoid and v in avoid) or (avoid_edges and (u, v) in avoid_edges):
                    continue
                h = to_dest.get(v)
                if h is None:
                    continue  # dest cannot be reached from v at all
                cost = g + t
                if fixed:
                    extra = fixed.get((u, v), 0.0)
                    if per_agv_s > 0:
                        lock = locks[v]
                        extra += per_agv_s * (len(lock.users) + len(lock.put_queue))
                    cost = cost + extra
                elif per_agv_s > 0:
                    lock = locks[v]
                    agvs = len(lock.users) + len(lock.put_queue)
                    if agvs:
                        cost = cost + per_agv_s * agvs
                if cost < best.get(v, inf):
                    best[v] = cost
                    parent[v] = u
                    push(queue, (cost + h, next(tie), cost, v))
        return None

    # ---- kinematics per hop ---------------------------------------------------------------
    def pieces(self, prev: str | None, u: str, v: str) -> tuple[Piece, ...]:
        """The stretch u -> v for an AGV that came from prev: a turn curve first if it turns."""
        key = (prev, u, v)
        found = self._pieces.get(key)
        if found is None:
            data = self.graph.edges[u, v]
            length = data["length_m"]
            limit = self._limit(data)
            turn = self.layout.turn(prev, u, v)
            curve = min(self.layout.turn_length_m, length)
            if turn in ("left", "right") and curve > 0:
                turn_limit = min(limit, self.motion.turn_speed_mps)
                found = ((curve, turn_limit), (length - curve, limit)) if length > curve \
                    else ((length, turn_limit),)
            else:
                found = ((length, limit),)
            self._pieces[key] = found
        return found

    def pass_speed_mps(self, u: str, v: str, w: str) -> float:
        """Highest speed at v for an AGV on u -> v that goes on to w and may have to stop at w."""
        key = (u, v, w)
        found = self._stop_entry.get(key)
        if found is None:
            if self.layout.turn(u, v, w) == "reverse":
                found = 0.0
            else:
                found = stop_entry_speed(self.pieces(u, v, w), self.motion.decel_mps2)
            self._stop_entry[key] = found
        return found

    def hop(self, prev: str | None, u: str, v: str, v_in: float,
            v_end_max: float) -> tuple[float, float]:
        """(time_s, v_end) for u -> v, closed form."""
        key = (prev, u, v, v_in, v_end_max)
        found = self._hops.get(key)
        if found is None:
            found = traverse(self.pieces(prev, u, v), v_in, v_end_max,
                             self.motion.accel_mps2, self.motion.decel_mps2)
            self._hops[key] = found
        return found
