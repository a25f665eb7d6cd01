"""A scenario checked against its layout: the stations, nodes and segments it names exist, the
fleet fits the parking and the track, and every vehicle type can reach what it must."""

from __future__ import annotations

from typing import TYPE_CHECKING

import networkx as nx

from fleet_sim.config.chains import check_chain
from fleet_sim.config.layout import Layout, Place, load_layout
from fleet_sim.errors import InputError

if TYPE_CHECKING:
    from fleet_sim.config.scenario import Scenario


def load_layout_for(scenario: Scenario, scenario_file: str) -> Layout:
    """Load the scenario's layout and check the scenario against it."""
    layout_path = scenario.path(scenario.layout)
    if not layout_path.exists():
        raise InputError(scenario_file, "layout", scenario.layout,
                         f"an existing layout file (looked for {layout_path})")
    layout = load_layout(layout_path, max_speed_mps=scenario.fleet.max_speed_mps)
    check_against_layout(scenario, layout, scenario_file)
    return layout


def check_against_layout(scenario: Scenario, layout: Layout, file: str) -> None:
    for i, flow in enumerate(scenario.demand.flows):
        if flow.stops:
            check_chain(flow.stops, layout, file, f"demand.flows[{i}].stops")
            continue
        for key, station, kind in (("from", flow.from_station, "pickup"),
                                   ("to", flow.to_station, "dropoff")):
            assert station is not None
            place = layout.places.get(station)
            if place is None or place.kind != kind:
                names = ", ".join(p.id for p in layout.places.values() if p.kind == kind)
                raise InputError(file, f"demand.flows[{i}].{key}", station,
                                 f"a {kind} station of layout {layout.name} ({names})")
    for i, node in enumerate(scenario.fleet.start_nodes):
        if node not in layout.graph:
            raise InputError(file, f"fleet.start_nodes[{i}]", node,
                             f"a node of layout {layout.name}")
    for i, block in enumerate(scenario.incidents.blocks):
        if not layout.graph.has_edge(block.from_node, block.to_node):
            raise InputError(file, f"incidents.blocks[{i}]",
                             f"{block.from_node} -> {block.to_node}",
                             f"a segment of layout {layout.name}")
    numbered = [("link_losses", i, x.agv) for i, x in enumerate(scenario.incidents.link_losses)]
    numbered += [("faults", i, x.agv) for i, x in enumerate(scenario.incidents.faults)]
    for key, i, agv in numbered:
        if not 0 <= agv < scenario.fleet.size:
            raise InputError(file, f"incidents.{key}[{i}].agv", agv,
                             f"an AGV number from 0 to {scenario.fleet.size - 1}")
    if not scenario.fleet.start_nodes:
        room = sum(p.capacity for p in layout.parking)
        if scenario.fleet.size > room:
            raise InputError(file, "fleet.size", scenario.fleet.size,
                             f"at most the parking capacity of layout {layout.name} ({room}), "
                             "or fleet.start_nodes for the rest")
    _check_types(scenario, layout, file)
    _check_vehicles_fit(scenario, layout, file)


def _check_vehicles_fit(scenario: Scenario, layout: Layout, file: str) -> None:
    """Every vehicle type fits the track it drives: an AGV coming back to a place it serves
    (station, charger, parking) must have left it behind, that is have driven at least its
    `length_m` + `min_gap_m` since (the stretch it holds behind itself,
    fleet_sim.sim.agents.driving). Else it waits for itself there for ever: a vehicle longer
    than the whole loop ran with no order delivered and no deadlock reported.

    Refused only where it is certain on the layout's shortest ways: for a place's node x, the
    way back in is from one of x's predecessors u, reached from x after at least d(x, u) m
    (shortest path, the type's own track); a type is refused when every such u is nearer than
    its length plus gap. So the limit on the tiny loop (48 m, tags every 4 m) is 44 m of
    length plus gap, which the simulation bears out (43.5 m runs, 44.5 m stands still). The
    search goes no further from x than that length plus gap, so it costs next to nothing for
    real vehicles."""
    fleet = scenario.fleet
    for i, (name, profile) in enumerate(fleet.type_profiles.items()):
        clear_m = profile.length_m + profile.min_gap_m
        graph = layout.type_graph(name) if layout.restricts_types else layout.graph
        places = [p for p in layout.places.values()
                  if p.kind == "parking" or (p.kind == "charger" and scenario.charging.enabled)
                  or (p.kind in ("pickup", "dropoff") and p.serves(name))]
        tightest: tuple[float, Place, str] | None = None
        for place in places:
            for node in place.nodes:
                ways_in = [u for u in graph.predecessors(node) if u != node]
                if not ways_in:
                    continue
                near = nx.single_source_dijkstra_path_length(graph, node, cutoff=clear_m,
                                                             weight="length_m")
                if not all(u in near and near[u] < clear_m - 1e-9 for u in ways_in):
                    continue
                room_m = max(near[u] for u in ways_in)
                if tightest is None or room_m < tightest[0]:
                    tightest = (room_m, place, node)
        if tightest is not None:
            room_m, place, node = tightest
            where = f"fleet.vehicles[{i}].vehicle.length_m" if fleet.vehicles \
                else "fleet.vehicle.length_m"
            raise InputError(file, where, profile.length_m,
                             f"a vehicle that fits the track of layout {layout.name}: at most "
                             f"{max(room_m - profile.min_gap_m, 0.0):g} m (an AGV coming back "
                             f"to {place.kind} {place.id}, node {node}, has driven at most "
                             f"{room_m:g} m since it left it, and its length plus min_gap_m "
                             f"{profile.min_gap_m:g} m must be clear of it)")


def _check_types(scenario: Scenario, layout: Layout, file: str) -> None:
    """Where the layout closes segments or stations to some vehicle types: every type can
    drive between all parking areas, chargers (charging on), its AGVs' start nodes and the
    stations it may serve; and every flow has a type that may serve both its stations."""
    if not layout.restricts_types:
        return
    fleet = scenario.fleet
    starts = agv_start_nodes(scenario, layout)
    for i, name in enumerate(fleet.type_profiles):
        where = f"fleet.vehicles[{i}].type" if fleet.vehicles else "fleet.vehicle.name"
        must = [(f"parking {p.id}", p.nodes[0]) for p in layout.parking]
        if scenario.charging.enabled:
            must += [(f"charger {c.id}", c.nodes[0]) for c in layout.chargers]
        must += [(f"station {p.id}", n) for p in layout.pickups + layout.dropoffs
                 if p.serves(name) for n in p.nodes]
        must += [(f"the start of AGV {agv}", node) for agv, (node, kind)
                 in enumerate(zip(starts, fleet.agv_types, strict=False)) if kind == name]
        graph = layout.type_graph(name)
        anchor = must[0][1]
        both_ways = (nx.descendants(graph, anchor) | {anchor}) \
            & (nx.ancestors(graph, anchor) | {anchor})
        for what, node in must:
            if node not in both_ways:
                raise InputError(file, where, name,
                                 f"a vehicle type that can drive to and from {what} (node "
                                 f"{node}) and parking {layout.parking[0].id} on layout "
                                 f"{layout.name}; the segments' allowed_types cut it off")
    names = tuple(fleet.type_profiles)
    for i, flow in enumerate(scenario.demand.flows):
        if flow.stops:
            if not chain_serving_types(layout, flow.stops, names):
                raise InputError(file, f"demand.flows[{i}].stops", " -> ".join(flow.stops),
                                 "stops that one vehicle type of the fleet "
                                 f"({', '.join(names)}) may serve all of (stations' "
                                 "allowed_types)")
            continue
        assert flow.from_station is not None and flow.to_station is not None
        if not serving_types(layout, flow.from_station, flow.to_station, names):
            raise InputError(file, f"demand.flows[{i}]", f"{flow.from_station} -> "
                             f"{flow.to_station}", "stations that one vehicle type of the "
                             f"fleet ({', '.join(names)}) may serve both of (stations' "
                             "allowed_types)")
    if not scenario.demand.flows and not any(
            serving_types(layout, p.id, d.id, names)
            for p in layout.pickups for d in layout.dropoffs):
        raise InputError(file, "demand.flows", [], "flows, or a pickup and a dropoff station "
                         f"that one vehicle type of the fleet ({', '.join(names)}) may serve")


def serving_types(layout: Layout, pickup: str, dropoff: str,
                  types: tuple[str, ...]) -> tuple[str, ...]:
    """The types among `types` that may serve both stations."""
    a, b = layout.places[pickup], layout.places[dropoff]
    return tuple(t for t in types if a.serves(t) and b.serves(t))


def chain_serving_types(layout: Layout, stops: tuple[str, ...],
                        types: tuple[str, ...]) -> tuple[str, ...]:
    """The types among `types` that may serve every stop of a chain."""
    places = [layout.places[s] for s in stops]
    return tuple(t for t in types if all(p.serves(t) for p in places))


def agv_start_nodes(scenario: Scenario, layout: Layout) -> list[str]:
    """The node each AGV starts on, in AGV order, as the engine places them: the scenario's
    start nodes, else the parking areas' slots in file order."""
    if scenario.fleet.start_nodes:
        return list(scenario.fleet.start_nodes[:scenario.fleet.size])
    slots = [p.nodes[0] for p in layout.parking for _ in range(p.capacity)]
    return slots[:scenario.fleet.size]


def agvs_without_charger(scenario: Scenario, layout: Layout) -> list[int]:
    """The AGVs (numbers) that cannot drive to any charger from their start, if charging is on;
    empty when charging is off or there is no battery model."""
    if not scenario.charging.enabled:
        return []
    chargers = {n for c in layout.chargers for n in c.nodes}
    stranded: list[int] = []
    reach: dict[str, bool] = {}
    profiles = scenario.fleet.agv_profiles
    for agv, node in enumerate(agv_start_nodes(scenario, layout)):
        if profiles[agv].battery is None:
            continue
        if node not in reach:
            reach[node] = node in layout.graph and bool(
                chargers & (nx.descendants(layout.graph, node) | {node}))
        if not reach[node]:
            stranded.append(agv)
    return stranded
