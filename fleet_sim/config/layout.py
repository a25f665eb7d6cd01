"""Layout files -> a validated networkx graph of nodes (RFID tags, junctions, stations, chargers,
parking) and segments (magnetic-tape paths between them).

The file format is described in docs/reference/layout-format.md. Every problem found while
loading names the file, the element (``segments[12].to``), the bad value and what was expected.

Two-way segments form single-track corridors, which an AGV holds before it enters, so no two
AGVs meet head-on. What else the engine relies on, and why: docs/background/decisions/config.md.
"""


from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import networkx as nx

from fleet_sim.config.distributions import TimeDistribution
from fleet_sim.config.layout_graph import BACKWARD as BACKWARD
from fleet_sim.config.layout_graph import FORWARD as FORWARD
from fleet_sim.config.layout_graph import Corridor as Corridor
from fleet_sim.config.layout_graph import TrafficZone as TrafficZone
from fleet_sim.config.layout_graph import checked_graph, traffic_zone
from fleet_sim.config.layout_spec import LayoutSpec, TypeLimits
from userfiles.checking import validate
from userfiles.reading import read_yaml

Turn = Literal["straight", "left", "right", "reverse"]

STRAIGHT_WITHIN_DEG = 30.0
"""Heading changes smaller than this are driven straight (no branch speed limit)."""
REVERSE_BEYOND_DEG = 150.0
"""Heading changes larger than this are a reversal: the AGV must stop at the node first."""


@dataclass(frozen=True)
class Place:
    """A station, charger or parking area as the engine sees it."""

    id: str
    kind: Literal["pickup", "dropoff", "charger", "parking"]
    nodes: tuple[str, ...]
    capacity: int
    handling: TimeDistribution | None = None
    power_kw: float = 0.0
    docking_s: float = 0.0
    allowed_types: frozenset[str] = frozenset()
    """Types that may serve a station; empty: every type."""
    banned_types: frozenset[str] = frozenset()
    """Types banned from the station's nodes by a ban zone."""

    def serves(self, vehicle_type: str) -> bool:
        return (not self.allowed_types or vehicle_type in self.allowed_types) \
            and vehicle_type not in self.banned_types


class Layout:
    """A loaded, validated layout: the graph plus its places and corridors."""

    def __init__(self, spec: LayoutSpec, file: str, graph: nx.DiGraph,
                 corridors: list[Corridor]) -> None:
        self.spec = spec
        self.file = file
        self.name = spec.name
        self.graph = graph
        self.corridors = corridors
        self._corridor_of: dict[tuple[str, str], Corridor] = {
            seg: c for c in corridors for seg in c.segments
        }
        self._corridor_at: dict[str, Corridor] = {n: c for c in corridors for n in c.members}
        places: list[Place] = []
        for s in spec.stations:
            places.append(Place(s.id, s.kind, s.nodes, len(s.nodes), handling=s.handling,
                                allowed_types=frozenset(s.allowed_types)))
        for c in spec.chargers:
            places.append(Place(c.id, "charger", (c.node,), 1, power_kw=c.power_kw,
                                docking_s=c.docking_s))
        for p in spec.parking:
            places.append(Place(p.id, "parking", (p.node,), p.capacity))
        self.places: dict[str, Place] = {p.id: p for p in places}
        self.pickups = [p for p in places if p.kind == "pickup"]
        self.dropoffs = [p for p in places if p.kind == "dropoff"]
        self.chargers = [p for p in places if p.kind == "charger"]
        self.parking = [p for p in places if p.kind == "parking"]
        self.turn_length_m = spec.defaults.turn_length_m
        self.markers = {n.id: n.marker for n in spec.nodes if n.marker is not None}
        self.traffic_zones = [traffic_zone(z) for z in spec.traffic_zones]
        self.traffic_zone_by_id = {z.id: z for z in self.traffic_zones}
        self.mutex_zones_at: dict[str, tuple[TrafficZone, ...]] = {}
        """Node -> the mutex zones it lies in."""
        self.direction_zones_at: dict[str, TrafficZone] = {}
        """Node -> the same_direction zone it lies inside (not at an end of)."""
        self._direction_hops: dict[tuple[str, str], tuple[TrafficZone, int]] = {}
        for zone in self.traffic_zones:
            if zone.kind == "mutex":
                for node in sorted(zone.nodes):
                    self.mutex_zones_at[node] = (*self.mutex_zones_at.get(node, ()), zone)
            elif zone.kind == "same_direction":
                self.direction_zones_at.update(dict.fromkeys(zone.nodes, zone))
                self._direction_hops.update({hop: (zone, d) for hop, d in zone.hops.items()})
        self._banned_at: dict[str, frozenset[str]] = {}
        for zone in self.traffic_zones:
            if zone.kind == "ban":
                for node in zone.nodes:
                    self._banned_at[node] = self._banned_at.get(node, frozenset()) \
                        | zone.banned_types
        if self._banned_at:
            self.places = {pid: replace(p, banned_types=frozenset().union(
                *(self._banned_at.get(n, frozenset()) for n in p.nodes)))
                for pid, p in self.places.items()}
            self.pickups = [self.places[p.id] for p in self.pickups]
            self.dropoffs = [self.places[p.id] for p in self.dropoffs]

    def corridor_of(self, u: str, v: str) -> Corridor | None:
        return self._corridor_of.get((u, v))

    def direction_zone_of(self, u: str, v: str) -> tuple[TrafficZone, int] | None:
        """The same_direction zone whose aisle the hop u -> v drives along, and the hop's
        direction (FORWARD or BACKWARD), if any."""
        return self._direction_hops.get((u, v))

    def corridor_at(self, node: str) -> Corridor | None:
        """The corridor that `node` lies inside (not at the junction end of), if any."""
        return self._corridor_at.get(node)

    def position(self, node: str) -> tuple[float, float]:
        data = self.graph.nodes[node]
        return float(data["x"]), float(data["y"])

    def turn(self, prev: str | None, node: str, nxt: str) -> Turn:
        """The turn an AGV arriving at `node` from `prev` makes to leave towards `nxt`."""
        forced = self.graph.edges[node, nxt]["branch"]
        if forced != "auto":
            return forced  # type: ignore[no-any-return]
        if prev is None:
            return "straight"
        if prev == nxt:
            return "reverse"
        ax, ay = self.position(prev)
        bx, by = self.position(node)
        cx, cy = self.position(nxt)
        h1 = math.atan2(by - ay, bx - ax)
        h2 = math.atan2(cy - by, cx - bx)
        diff = math.degrees((h2 - h1 + math.pi) % (2 * math.pi) - math.pi)
        if abs(diff) < STRAIGHT_WITHIN_DEG:
            return "straight"
        if abs(diff) > REVERSE_BEYOND_DEG:
            return "reverse"
        return "left" if diff > 0 else "right"

    @property
    def restricts_types(self) -> bool:
        """Some segment or station is open to some vehicle types only."""
        return any(s.allowed_types for s in self.spec.segments) \
            or any(s.allowed_types for s in self.spec.stations) or bool(self._banned_at)

    def type_graph(self, vehicle_type: str) -> nx.DiGraph:
        """The track an AGV of `vehicle_type` may drive: a view without the segments closed
        to it (segments' `allowed_types`)."""
        def allowed(u: str, v: str) -> bool:
            if vehicle_type in self._banned_at.get(v, ()):
                return False  # a ban zone: no way in
            types: frozenset[str] = self.graph.edges[u, v]["allowed_types"]
            return not types or vehicle_type in types
        return nx.subgraph_view(self.graph, filter_edge=allowed)

    @property
    def speed_limited_types(self) -> frozenset[str]:
        """The vehicle types some segment gives a speed limit of their own."""
        return frozenset(name for s in self.spec.segments for name in s.speed_limit_mps_by_type)

    def speed_limit_mps(self, u: str, v: str, vehicle_type: str | None = None) -> float:
        """Segment u -> v's speed limit, for AGVs of `vehicle_type` (None: the segment's
        own, for every type)."""
        data = self.graph.edges[u, v]
        limit: float = data["speed_limit_mps"]
        if vehicle_type is None:
            return limit
        limits: TypeLimits = data["speed_limit_mps_by_type"]
        return min(limit, limits.get(vehicle_type, limit))

    @property
    def total_length_m(self) -> float:
        """Length of tape, counting a two-way segment once."""
        seen: set[frozenset[str]] = set()
        total = 0.0
        for u, v, data in self.graph.edges(data=True):
            key = frozenset((u, v))
            if key not in seen:
                seen.add(key)
                total += data["length_m"]
        return total


def load_layout(path: str | Path, max_speed_mps: float | None = None) -> Layout:
    """Load and validate a layout file. `max_speed_mps` is the fleet's top speed, if known."""
    path = Path(path)
    file = str(path)
    spec = validate(LayoutSpec, read_yaml(path), file)
    return layout_from_spec(spec, file, max_speed_mps)




def layout_from_spec(spec: LayoutSpec, file: str, max_speed_mps: float | None = None) -> Layout:
    """The layout of a spec read from `file` (named in errors), checked as a graph."""
    graph, corridors = checked_graph(spec, file, max_speed_mps)
    return Layout(spec, file, graph, corridors)
