"""Routes and hop kinematics on a layout: what traffic control asks about the track.

* Routes follow the shortest free-flow travel time (length / min(limit, VEL_MAX)), from
  per-destination tables computed once (Dijkstra on the reversed graph).
* Detours (`route_avoiding`) keep off given nodes and segments; they are computed when an AGV is
  blocked and cached by (source, destination, what to avoid).
* Each hop's pieces (a branch curve at the turn speed, then the rest of the segment) and the
  highest speed from which an AGV can still stop at the node after are cached per (prev, u, v).

`Routes` holds no locks and no clock; it only needs the layout and the vehicle's motion limits
(the fleet sizing estimate uses it too).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import networkx as nx

from fleet_sim.config.layout import Layout
from fleet_sim.model.kinematics import Motion, Piece, stop_entry_speed, traverse

Detour = tuple[str, str, frozenset[str], frozenset[tuple[str, str]]]
Weight = str | Callable[[str, str, dict[str, Any]], float | None]


class Routes:
    """Route tables, detours and the hop kinematics cache of one layout and vehicle type."""

    def __init__(self, layout: Layout, motion: Motion, vehicle_type: str | None = None) -> None:
        self.layout = layout
        self.graph = layout.graph
        self.motion = motion
        self.vehicle_type = vehicle_type
        """None: every segment, the graph's `free_time_s`. A type (mixed fleets, layouts
        with `allowed_types`): only the segments open to it, at its own top speed."""
        self.weight: Weight = "free_time_s"
        """The edge weight of routes (networkx: an attribute name or a function)."""
        self._reverse_weight: Weight = "free_time_s"
        self._times: dict[tuple[str, str], float] = {}
        if vehicle_type is None:
            for _, _, data in self.graph.edges(data=True):
                data["free_time_s"] = data["length_m"] / min(data["speed_limit_mps"],
                                                             motion.max_speed_mps)
        else:
            times = {(u, v): data["length_m"] / min(data["speed_limit_mps"],
                                                    motion.max_speed_mps)
                     for u, v, data in layout.type_graph(vehicle_type).edges(data=True)}
            self._times = times
            self.weight = self._type_weight
            self._reverse_weight = self._type_weight_reversed
        self._to_dest: dict[str, tuple[dict[str, float], dict[str, str]]] = {}
        self._pieces: dict[tuple[str | None, str, str], tuple[Piece, ...]] = {}
        self._stop_entry: dict[tuple[str, str, str], float] = {}
        self._detours: dict[Detour, list[str] | None] = {}

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
            dist, paths = nx.single_source_dijkstra(self.graph.reverse(copy=False), dest,
                                                    weight=self._reverse_weight)
            next_hop = {n: p[-2] for n, p in paths.items() if len(p) > 1}
            table = (dist, next_hop)
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
        if key in self._detours:
            return self._detours[key]
        view = nx.restricted_view(self.graph, list(avoid), list(avoid_edges or ()))
        try:
            path: list[str] | None = list(nx.shortest_path(view, src, dest, weight=self.weight))
        except nx.NetworkXNoPath:
            path = None
        self._detours[key] = path
        return path

    # ---- kinematics per hop ---------------------------------------------------------------
    def pieces(self, prev: str | None, u: str, v: str) -> tuple[Piece, ...]:
        """The stretch u -> v for an AGV that came from prev: a turn curve first if it turns."""
        key = (prev, u, v)
        found = self._pieces.get(key)
        if found is None:
            data = self.graph.edges[u, v]
            length = data["length_m"]
            limit = min(data["speed_limit_mps"], self.motion.max_speed_mps)
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
        return traverse(self.pieces(prev, u, v), v_in, v_end_max,
                        self.motion.accel_mps2, self.motion.decel_mps2)
