"""A layout spec as a graph: the segments built into a networkx graph (lengths, limits, zones'
signal and obstacle rates), the places and traffic zones checked against it, every node
reachable, and the single-track corridors found."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Final

import networkx as nx

from fleet_sim.config.layout_spec import LayoutSpec, TrafficZoneKind, TrafficZoneSpec
from fleet_sim.errors import InputError

FORWARD: Final = 1
"""A same_direction zone driven from its first node listed towards its last."""
BACKWARD: Final = -1
"""... and from its last node towards its first."""


@dataclass(frozen=True)
class TrafficZone:
    """A traffic zone as the engine sees it (TrafficZoneSpec, its nodes resolved)."""

    id: str
    kind: TrafficZoneKind
    nodes: frozenset[str]
    """The nodes inside: an AGV holding one of them is in the zone (same_direction: the
    aisle's nodes between its two ends)."""
    capacity: int | None
    """The most AGVs inside at once (mutex: 1 if not given); None: no limit."""
    banned_types: frozenset[str]
    path: tuple[str, ...] = ()
    """same_direction: the aisle's nodes in order, its ends included (forward: first to
    last)."""

    @property
    def hops(self) -> dict[tuple[str, str], int]:
        """same_direction: every hop along the aisle and its direction."""
        out: dict[tuple[str, str], int] = {}
        for a, b in itertools.pairwise(self.path):
            out[(a, b)] = FORWARD
            out[(b, a)] = BACKWARD
        return out


@dataclass(frozen=True)
class Corridor:
    """A chain of two-way segments that one AGV at a time may occupy."""

    id: int
    members: frozenset[str]
    """Nodes inside the corridor (its junction ends are not members)."""
    segments: frozenset[tuple[str, str]]
    """Both directions of every segment in the corridor."""




def checked_graph(spec: LayoutSpec, file: str, max_speed_mps: float | None = None
                  ) -> tuple[nx.DiGraph, list[Corridor]]:
    """The graph of `spec`, checked, and its corridors. `max_speed_mps` is the fleet's top
    speed, if known."""
    graph = _build_graph(spec, file, max_speed_mps)
    _check_places(spec, file, graph)
    _check_traffic_zones(spec, file, graph)
    _check_connectivity(spec, file, graph)
    corridors = _find_corridors(graph)
    if any(z.kind == "same_direction" for z in spec.traffic_zones):
        corridors = _check_aisles(spec, file, graph, corridors)
    return graph, corridors


def traffic_zone(spec: TrafficZoneSpec) -> TrafficZone:
    if spec.kind == "same_direction":
        return TrafficZone(spec.id, spec.kind, frozenset(spec.nodes[1:-1]), spec.capacity,
                           frozenset(), tuple(spec.nodes))
    nodes = frozenset(spec.nodes) | {n for seg in spec.segments for n in seg}
    capacity = spec.capacity if spec.capacity is not None or spec.kind != "mutex" else 1
    return TrafficZone(spec.id, spec.kind, nodes, capacity, frozenset(spec.banned_types))


def _build_graph(spec: LayoutSpec, file: str, max_speed_mps: float | None) -> nx.DiGraph:
    graph = nx.DiGraph()
    first_index: dict[str, int] = {}
    for i, node in enumerate(spec.nodes):
        if node.id in first_index:
            raise InputError(file, f"nodes[{i}].id", node.id,
                             f"a unique node id (nodes[{first_index[node.id]}] has it already)")
        first_index[node.id] = i
        graph.add_node(node.id, x=node.x, y=node.y, kind=node.kind, index=i)
    for i, seg in enumerate(spec.segments):
        where = f"segments[{i}]"
        for key, node_id in (("from", seg.from_node), ("to", seg.to_node)):
            if node_id not in first_index:
                raise InputError(file, f"{where}.{key}", node_id, "the id of a node in `nodes`")
        if seg.from_node == seg.to_node:
            raise InputError(file, f"{where}.to", seg.to_node,
                             f"a node other than its `from` ({seg.from_node})")
        a = spec.nodes[first_index[seg.from_node]]
        b = spec.nodes[first_index[seg.to_node]]
        straight_m = math.hypot(b.x - a.x, b.y - a.y)
        length = seg.length_m if seg.length_m is not None else straight_m
        if length <= 0:
            what = "length_m" if seg.length_m is not None else "length_m (from the coordinates)"
            raise InputError(file, f"{where}.{what}", length, "a length > 0 m")
        if length < straight_m - 1e-6:
            raise InputError(file, f"{where}.length_m", length,
                             f"at least the straight distance {straight_m:.3f} m between "
                             f"{seg.from_node} and {seg.to_node}")
        limit = seg.speed_limit_mps if seg.speed_limit_mps is not None \
            else spec.defaults.speed_limit_mps
        if max_speed_mps is not None and limit > max_speed_mps + 1e-9:
            raise InputError(file, f"{where}.speed_limit_mps", limit,
                             f"at most the vehicle's maximum speed {max_speed_mps} m/s")
        for name, type_limit in seg.speed_limit_mps_by_type.items():
            at = f"{where}.speed_limit_mps_by_type.{name}"
            if seg.allowed_types and name not in seg.allowed_types:
                raise InputError(file, at, name, "a type of the segment's allowed_types ("
                                 f"{', '.join(seg.allowed_types)}): other types may not "
                                 "drive it")
            if type_limit >= limit:
                raise InputError(file, at, type_limit,
                                 f"a limit below the segment's speed limit {limit:g} m/s (a "
                                 "type's limit lowers it for that type; raise "
                                 "speed_limit_mps to let the other types drive faster)")
        ends = [(seg.from_node, seg.to_node)]
        if seg.direction == "two_way":
            ends.append((seg.to_node, seg.from_node))
        for u, v in ends:
            if graph.has_edge(u, v):
                other = graph.edges[u, v]["index"]
                raise InputError(file, where, f"{seg.from_node} -> {seg.to_node}",
                                 f"one segment per pair of nodes (segments[{other}] already "
                                 f"joins {u} -> {v})")
            branch = seg.branch if (u, v) == (seg.from_node, seg.to_node) else "auto"
            graph.add_edge(u, v, length_m=length, speed_limit_mps=limit,
                           two_way=seg.direction == "two_way", branch=branch, index=i,
                           rssi_dbm=seg.rssi_dbm, obstacle_rate_per_km=None,
                           obstacle_duration=None, allowed_types=frozenset(seg.allowed_types),
                           speed_limit_mps_by_type=seg.speed_limit_mps_by_type)
    _apply_zones(spec, file, graph)
    for node in spec.nodes:
        if graph.out_degree(node.id) == 0:
            raise InputError(file, f"nodes[{first_index[node.id]}]", node.id,
                             "a node with a way out (no segment leaves it)")
    return graph


def _apply_zones(spec: LayoutSpec, file: str, graph: nx.DiGraph) -> None:
    """Segments take their zone's signal and obstacle rate (the first zone holding their
    midpoint); a segment's own rssi_dbm wins; the layout default fills the rest."""
    for i, spec_zone in enumerate(spec.zones):
        x0, y0, x1, y1 = spec_zone.area_m
        if x0 >= x1 or y0 >= y1:
            raise InputError(file, f"zones[{i}].area_m", list(spec_zone.area_m),
                             "[x_min, y_min, x_max, y_max] with x_min < x_max, y_min < y_max")
    for u, v, data in graph.edges(data=True):
        mx = (graph.nodes[u]["x"] + graph.nodes[v]["x"]) / 2
        my = (graph.nodes[u]["y"] + graph.nodes[v]["y"]) / 2
        zone = next((z for z in spec.zones
                     if z.area_m[0] <= mx <= z.area_m[2] and z.area_m[1] <= my <= z.area_m[3]),
                    None)
        if data["rssi_dbm"] is None:
            data["rssi_dbm"] = zone.rssi_dbm if zone is not None and zone.rssi_dbm is not None \
                else spec.defaults.rssi_dbm
        if zone is not None:
            data["obstacle_rate_per_km"] = zone.obstacle_rate_per_km
            data["obstacle_duration"] = zone.obstacle_duration


def _check_traffic_zones(spec: LayoutSpec, file: str, graph: nx.DiGraph) -> None:
    seen: dict[str, int] = {}
    for i, zone in enumerate(spec.traffic_zones):
        where = f"traffic_zones[{i}]"
        if zone.id in seen:
            raise InputError(file, f"{where}.id", zone.id,
                             f"a unique id (traffic_zones[{seen[zone.id]}] has it)")
        seen[zone.id] = i
        if not zone.nodes and not zone.segments:
            raise InputError(file, where, zone.id, "a zone with nodes or segments")
        for j, node in enumerate(zone.nodes):
            if node not in graph:
                raise InputError(file, f"{where}.nodes[{j}]", node, "the id of a node in `nodes`")
        for j, (u, v) in enumerate(zone.segments):
            if not graph.has_edge(u, v):
                raise InputError(file, f"{where}.segments[{j}]", f"{u} -> {v}",
                                 "a segment of the layout ([from, to])")
        if zone.kind == "ban" and not zone.banned_types:
            raise InputError(file, f"{where}.banned_types", [],
                             "at least one vehicle type for a ban zone")
        if zone.kind == "mutex" and zone.banned_types:
            raise InputError(file, f"{where}.banned_types", list(zone.banned_types),
                             "none for a mutex zone (a ban zone bans types)")
        if zone.kind == "ban" and zone.capacity is not None:
            raise InputError(file, f"{where}.capacity", zone.capacity,
                             "no capacity for a ban zone (a mutex zone has one)")
        parking = {p.node for p in spec.parking}
        inside = (set(zone.nodes) | {n for seg in zone.segments for n in seg}) & parking
        if zone.kind == "mutex" and inside:
            raise InputError(file, f"{where}.nodes", sorted(inside)[0],
                             "no parking access node in a mutex zone (parked AGVs hold no "
                             "node and would not count)")
        if zone.kind == "same_direction":
            _check_aisle(zone, where, file, graph, parking)


def _check_aisle(zone: TrafficZoneSpec, where: str, file: str, graph: nx.DiGraph,
                 parking: set[str]) -> None:
    """A same_direction zone is one two-way aisle, its nodes listed in order, entered and
    left at its two ends only (its way round: `_check_aisles`)."""
    if zone.banned_types:
        raise InputError(file, f"{where}.banned_types", list(zone.banned_types),
                         "none for a same_direction zone (a ban zone bans types)")
    if zone.segments:
        raise InputError(file, f"{where}.segments", [list(s) for s in zone.segments],
                         "no segments for a same_direction zone: list the aisle's nodes in "
                         "order under `nodes` (the order says which way is forward)")
    nodes = zone.nodes
    if len(nodes) < 3:
        raise InputError(file, f"{where}.nodes", list(nodes),
                         "at least 3 nodes in order along the aisle (its two ends and the "
                         "nodes between them)")
    first: dict[str, int] = {}
    for j, node in enumerate(nodes):
        if node in first:
            raise InputError(file, f"{where}.nodes[{j}]", node,
                             f"each node once (nodes[{first[node]}] is {node} already)")
        first[node] = j
    for j in range(1, len(nodes)):
        a, b = nodes[j - 1], nodes[j]
        if not (graph.has_edge(a, b) and graph.has_edge(b, a)):
            raise InputError(file, f"{where}.nodes[{j}]", b,
                             f"a node joined to nodes[{j - 1}] ({a}) by a two-way segment "
                             "(a same_direction zone is a two-way aisle, its nodes listed "
                             "in order)")
    for j in range(1, len(nodes) - 1):
        node = nodes[j]
        chain = {nodes[j - 1], nodes[j + 1]}
        others = sorted((set(graph.successors(node)) | set(graph.predecessors(node))) - chain)
        if others:
            raise InputError(file, f"{where}.nodes[{j}]", node,
                             f"a node joined only to its neighbours in the list (a segment "
                             f"joins it to {others[0]}: a same_direction zone is entered "
                             "and left at its two ends only)")
        if node in parking:
            raise InputError(file, f"{where}.nodes[{j}]", node,
                             "no parking access node inside a same_direction zone (parked "
                             "AGVs hold no node and would not count)")


def _check_aisles(spec: LayoutSpec, file: str, graph: nx.DiGraph,
                  corridors: list[Corridor]) -> list[Corridor]:
    """A same_direction zone has a way round outside it and covers whole single-track
    corridors, whose place it takes: the corridors it covers are left out (the others
    numbered again)."""
    covered: set[tuple[str, str]] = set()
    for i, zone in enumerate(spec.traffic_zones):
        if zone.kind != "same_direction":
            continue
        nodes = zone.nodes
        outside = graph.subgraph(n for n in graph.nodes if n not in set(nodes[1:-1]))
        for a, b in ((nodes[-1], nodes[0]), (nodes[0], nodes[-1])):
            if not nx.has_path(outside, a, b):
                raise InputError(file, f"traffic_zones[{i}].nodes", list(nodes),
                                 f"an aisle with a way round: no path outside the zone "
                                 f"leads from its end {a} back to its other end {b}, so an "
                                 "AGV that drove through it could not come back without "
                                 "turning round inside")
        hops = traffic_zone(zone).hops
        for corridor in corridors:
            inside = corridor.segments & hops.keys()
            if inside and inside != corridor.segments:
                u, v = sorted(corridor.segments - hops.keys())[0]
                raise InputError(file, f"traffic_zones[{i}].nodes", list(zone.nodes),
                                 f"the whole two-way aisle: its segment {u} -> {v} goes on "
                                 "beyond the zone's end (a same_direction zone takes the "
                                 "place of the aisle's single-track rule, so it must start "
                                 "and end where the aisle does)")
        covered |= hops.keys()
    kept = [c for c in corridors if not c.segments <= covered]
    return [replace(c, id=i) for i, c in enumerate(kept)]


def _check_places(spec: LayoutSpec, file: str, graph: nx.DiGraph) -> None:
    owner: dict[str, str] = {}
    seen_ids: dict[str, str] = {}

    def claim(where: str, place_id: str, node: str, kind: str) -> None:
        if node not in graph:
            raise InputError(file, where, node, "the id of a node in `nodes`")
        if node in owner:
            raise InputError(file, where, node, f"a node not already used by {owner[node]}")
        owner[node] = place_id
        actual = graph.nodes[node]["kind"]
        if actual != kind:
            raise InputError(file, where, node, f"a node of kind {kind!r} (it is {actual!r})")

    def unique(where: str, place_id: str) -> None:
        if place_id in seen_ids:
            raise InputError(file, where, place_id, f"a unique id ({seen_ids[place_id]} has it)")
        seen_ids[place_id] = where

    for i, st in enumerate(spec.stations):
        unique(f"stations[{i}].id", st.id)
        if not st.nodes:
            raise InputError(file, f"stations[{i}].nodes", [], "at least one docking node")
        for j, node in enumerate(st.nodes):
            claim(f"stations[{i}].nodes[{j}]", st.id, node, "station")
    for i, ch in enumerate(spec.chargers):
        unique(f"chargers[{i}].id", ch.id)
        claim(f"chargers[{i}].node", ch.id, ch.node, "charger")
    for i, pk in enumerate(spec.parking):
        unique(f"parking[{i}].id", pk.id)
        claim(f"parking[{i}].node", pk.id, pk.node, "parking")
    kinds = {st.kind for st in spec.stations}
    for needed in ("pickup", "dropoff"):
        if needed not in kinds:
            raise InputError(file, "stations", f"no {needed} station",
                             "at least one pickup and one dropoff station")
    if not spec.parking:
        raise InputError(file, "parking", [], "at least one parking area for idle AGVs")
    for spec_node in spec.nodes:
        if spec_node.kind in ("station", "charger", "parking") and spec_node.id not in owner:
            raise InputError(file, f"nodes[{graph.nodes[spec_node.id]['index']}].kind",
                             spec_node.kind, f"a node listed under {spec_node.kind}s "
                             f"(node {spec_node.id} is not)")


def _check_connectivity(spec: LayoutSpec, file: str, graph: nx.DiGraph) -> None:
    """Every node must be reachable from every other one: an AGV can get anywhere and back."""
    components = list(nx.strongly_connected_components(graph))
    if len(components) == 1:
        return
    anchor = spec.stations[0].nodes[0]
    main = next(c for c in components if anchor in c)
    places: list[tuple[str, str, Iterable[str]]] = []
    places += [(f"stations[{i}] ({s.id})", s.id, s.nodes) for i, s in enumerate(spec.stations)]
    places += [(f"chargers[{i}] ({c.id})", c.id, (c.node,)) for i, c in enumerate(spec.chargers)]
    places += [(f"parking[{i}] ({p.id})", p.id, (p.node,)) for i, p in enumerate(spec.parking)]
    for where, _, nodes in places:
        for node in nodes:
            if node not in main:
                raise InputError(file, where, node, _reach_problem(graph, node, anchor))
    for spec_node in spec.nodes:
        if spec_node.id not in main:
            raise InputError(file, f"nodes[{graph.nodes[spec_node.id]['index']}]", spec_node.id,
                             _reach_problem(graph, spec_node.id, anchor))


def _reach_problem(graph: nx.DiGraph, node: str, anchor: str) -> str:
    if not nx.has_path(graph, anchor, node):
        return f"a node AGVs can reach (no path from {anchor} leads to it)"
    return f"a node AGVs can leave (no path from it leads back to {anchor})"


def _find_corridors(graph: nx.DiGraph) -> list[Corridor]:
    two_way = nx.Graph()
    for u, v, data in graph.edges(data=True):
        if data["two_way"]:
            two_way.add_edge(u, v)
    junctions = {
        n for n in two_way.nodes
        if two_way.degree(n) >= 3
        or any(not graph.edges[n, w]["two_way"] for w in graph.successors(n))
        or any(not graph.edges[w, n]["two_way"] for w in graph.predecessors(n))
    }
    inner = two_way.subgraph(n for n in two_way.nodes if n not in junctions)
    corridors: list[Corridor] = []
    assigned: set[frozenset[str]] = set()
    for comp in sorted(nx.connected_components(inner), key=lambda c: min(c)):
        segs: set[tuple[str, str]] = set()
        for n in comp:
            for w in two_way.neighbors(n):
                segs.add((n, w))
                segs.add((w, n))
                assigned.add(frozenset((n, w)))
        corridors.append(Corridor(len(corridors), frozenset(comp), frozenset(segs)))
    for u, v in sorted(two_way.edges, key=lambda e: tuple(sorted(e))):
        if frozenset((u, v)) not in assigned:  # a two-way segment directly between junctions
            corridors.append(Corridor(len(corridors), frozenset(), frozenset({(u, v), (v, u)})))
    return corridors

