"""LIF import, nodes and places: the nodes open to the vehicle type(s), and the fleet_sim
stations, chargers and parking areas made of LIF stations by the actions on their nodes
(LIF 8.3.13.1)."""

from __future__ import annotations

from typing import Any

from fleet_sim.config.layout_spec import NodeKind
from fleet_sim.config.standards.lif import (
    ACTIONS,
    EXTENSION_KEY,
    Layout,
    Node,
    PlaceKind,
    VehicleTypeNodeProperty,
)
from fleet_sim.config.standards.lif_notes import Notes

OpenNodes = dict[str, tuple[str, Node, VehicleTypeNodeProperty]]
"""nodeId -> (JSON path of its entry for the vehicle type, node, entry), in file order."""


def open_nodes(layout: Layout, type_id: str, at: str, notes: Notes) -> OpenNodes:
    """The nodes open to the vehicle type."""
    kept: OpenNodes = {}
    for j, node in enumerate(layout.nodes):
        where = f"{at}.nodes[{j}]"
        k, prop = type_entry(node.vehicleTypeNodeProperties, type_id, notes,
                         f"{at}.nodes[*].vehicleTypeNodeProperties", where)
        if prop is None:
            notes.add(f"{at}.nodes[*]", where, f"node not open to vehicle type {type_id}")
            continue
        kept[node.nodeId] = (f"{where}.vehicleTypeNodeProperties[{k}]", node, prop)
        for key in ("nodeName", "nodeDescription"):
            if getattr(node, key) is not None:
                notes.add(f"{at}.nodes[*].{key}", f"{where}.{key}",
                          "for display only; fleet_sim nodes have only an id")
        if prop.theta is not None:
            notes.add(f"{at}.nodes[*].vehicleTypeNodeProperties[*].theta",
                      f"{kept[node.nodeId][0]}.theta",
                      "fleet_sim does not model the vehicle's orientation on a node")
    return kept


def vehicle_types(layout: Layout) -> tuple[str, ...]:
    """The vehicleTypeIds of a layout's nodes and edges, in file order."""
    types: dict[str, None] = {}
    for node in layout.nodes:
        for prop in node.vehicleTypeNodeProperties:
            types.setdefault(prop.vehicleTypeId)
    for edge in layout.edges:
        for eprop in edge.vehicleTypeEdgeProperties:
            types.setdefault(eprop.vehicleTypeId)
    return tuple(types)


def main_type_entry(entries: tuple[Any, ...], types: tuple[str, ...]) -> tuple[int, Any]:
    """The index and entry of the first of `types` (main type first) that has one."""
    for type_id in types:
        for k, entry in enumerate(entries):
            if entry.vehicleTypeId == type_id:
                return k, entry
    return -1, None


def type_entry(entries: tuple[Any, ...], type_id: str, notes: Notes, pattern: str,
           where: str) -> tuple[int, Any]:
    """The index and entry of `entries` (vehicleType...Properties) for `type_id`, or (-1,
    None); the entries of other types are noted."""
    found: tuple[int, Any] = (-1, None)
    key = pattern.rsplit(".", 1)[1]
    for k, entry in enumerate(entries):
        if entry.vehicleTypeId == type_id:
            found = (k, entry)
        else:
            notes.add(f"{pattern}[*]", f"{where}.{key}[{k}]",
                      f"properties for vehicle type {entry.vehicleTypeId}: a fleet_sim layout "
                      "is for one vehicle type (--vehicle-type chooses)")
    return found


def open_nodes_any(layout: Layout, types: tuple[str, ...], at: str,
                    notes: Notes) -> OpenNodes:
    """The nodes open to any of `types` (all types), with the main type's entry if it has
    one."""
    kept: OpenNodes = {}
    for j, node in enumerate(layout.nodes):
        where = f"{at}.nodes[{j}]"
        k, prop = main_type_entry(node.vehicleTypeNodeProperties, types)
        if prop is None:
            notes.add(f"{at}.nodes[*]", where, "node open to no vehicle type")
            continue
        kept[node.nodeId] = (f"{where}.vehicleTypeNodeProperties[{k}]", node, prop)
        for key in ("nodeName", "nodeDescription"):
            if getattr(node, key) is not None:
                notes.add(f"{at}.nodes[*].{key}", f"{where}.{key}",
                          "for display only; fleet_sim nodes have only an id")
        for entry in node.vehicleTypeNodeProperties:
            if entry.theta is not None:
                notes.add(f"{at}.nodes[*].vehicleTypeNodeProperties[*].theta",
                          f"{kept[node.nodeId][0]}.theta",
                          "fleet_sim does not model the vehicle's orientation on a node")
    return kept


def place_types(layout: Layout, places: dict[str, list[dict[str, Any]]],
                 types: tuple[str, ...], at: str, notes: Notes) -> None:
    """`allowed_types` of the pickup and drop-off stations whose nodes are not open to every
    type; chargers and parking areas not open to every type are reported."""
    node_types = {n.nodeId: {p.vehicleTypeId: {a.actionType for a in p.actions or ()}
                             for p in n.vehicleTypeNodeProperties} for n in layout.nodes}

    def open_to(nodes: list[str], action: str | None = None) -> list[str]:
        """Types open on every node; for a station, of those that carry its purpose's action
        on a node where some type does, only the ones that carry it there."""
        def serves(t: str, n: str) -> bool:
            entries = node_types[n]
            if t not in entries:
                return False
            return action is None or action in entries[t] \
                or not any(action in acts for acts in entries.values())
        return [t for t in types if all(serves(t, n) for n in nodes)]

    for entry in places["stations"]:
        allowed = open_to(entry["nodes"], ACTIONS[entry["kind"]][0])
        if len(allowed) < len(types):
            entry["allowed_types"] = allowed
    for kind, what in (("chargers", "charger"), ("parking", "parking area")):
        for entry in places[kind]:
            allowed = open_to([entry["node"]])
            if len(allowed) < len(types):
                notes.add(f"{at}.stations[*]", entry["id"], f"a {what} open to "
                          f"{', '.join(allowed)} only: kept for every type (fleet_sim "
                          "chargers and parking areas have no allowed_types)", kept=True)


def places_of(layout: Layout, kept: OpenNodes, at: str, notes: Notes
            ) -> tuple[dict[str, tuple[str, PlaceKind]], dict[str, list[dict[str, Any]]]]:
    """The stations, chargers and parking areas of the layout's LIF stations, and which place
    each of their nodes belongs to."""
    claimed: dict[str, tuple[str, PlaceKind]] = {}
    places: dict[str, list[dict[str, Any]]] = {"stations": [], "chargers": [], "parking": []}
    pattern = f"{at}.stations[*]"
    for k, st in enumerate(layout.stations or ()):
        where = f"{at}.stations[{k}]"
        nodes = [n for n in st.interactionNodeIds if n in kept]
        if len(nodes) < len(st.interactionNodeIds):
            notes.add(f"{pattern}.interactionNodeIds[*]", f"{where}.interactionNodeIds",
                      "interaction node not imported (not open to the vehicle type or in "
                      "another layout)")
        if not nodes:
            notes.add(pattern, where, f"station {st.stationId} left out: none of its nodes is "
                      "imported")
            continue
        ext = st.fleetSim
        kind = _place_kind(ext.kind if ext is not None else None,
                           [kept[n][2] for n in nodes], notes, where, pattern)
        if kind is None:
            continue
        taken = [n for n in nodes if n in claimed]
        if taken:
            notes.add(pattern, where, f"station {st.stationId} left out: node {taken[0]} "
                      f"belongs to {claimed[taken[0]][0]} already (one place per node)")
            continue
        for n in nodes:
            claimed[n] = (st.stationId, kind)
        for key in ("stationName", "stationDescription", "stationHeight"):
            if getattr(st, key) is not None:
                notes.add(f"{pattern}.{key}", f"{where}.{key}",
                          "fleet_sim places have only an id" if key != "stationHeight"
                          else "fleet_sim does not model heights")
        if st.stationPosition is not None and ext is None:
            notes.add(f"{pattern}.stationPosition", f"{where}.stationPosition",
                      "for display only; fleet_sim places sit on their nodes")
        if kind in ("pickup", "dropoff"):
            entry: dict[str, Any] = {"id": st.stationId, "kind": kind, "nodes": nodes}
            if ext is not None and ext.handling is not None:
                entry["handling"] = ext.handling.model_dump(mode="json")
            else:
                notes.add(pattern, where, "handling time: fleet_sim's default (fixed 20 s); "
                          "LIF has none", kept=True)
            places["stations"].append(entry)
        elif kind == "charger":
            if ext is None:
                notes.add(pattern, where, "charger power and docking time: fleet_sim's "
                          "defaults (3 kW, 30 s); LIF has none", kept=True)
            for m, n in enumerate(nodes):
                entry = {"id": st.stationId if len(nodes) == 1 else f"{st.stationId}_{m + 1}",
                         "node": n}
                if ext is not None and ext.power_kw is not None:
                    entry["power_kw"] = ext.power_kw
                if ext is not None and ext.docking_s is not None:
                    entry["docking_s"] = ext.docking_s
                places["chargers"].append(entry)
        else:
            if len(nodes) > 1:
                notes.add(f"{pattern}.interactionNodeIds[*]", where, "a parking area has one "
                          f"access node; {nodes[0]} kept")
            entry = {"id": st.stationId, "node": nodes[0]}
            if ext is not None and ext.capacity is not None:
                entry["capacity"] = ext.capacity
            places["parking"].append(entry)
    return claimed, places


def _place_kind(extension_kind: PlaceKind | None, props: list[VehicleTypeNodeProperty],
                notes: Notes, where: str, pattern: str) -> PlaceKind | None:
    if extension_kind is not None:
        return extension_kind
    offered = {a.actionType for p in props for a in (p.actions or ())}
    purposes: tuple[PlaceKind, ...] = ("pickup", "dropoff", "charger")
    kinds = [k for k in purposes if ACTIONS[k][0] in offered]
    if not kinds:
        notes.add(pattern, where, "station left out: no pick, drop or startCharging action on "
                  "its nodes says what it is for (fleet_sim needs pickup, drop-off, charger or "
                  "parking)")
        return None
    if len(kinds) > 1:
        notes.add(pattern, where, f"station offers {' and '.join(kinds)}: read as {kinds[0]} "
                  "(a fleet_sim place has one kind)", kept=True)
    return kinds[0]



def node_entries(kept: OpenNodes, claimed: dict[str, tuple[str, PlaceKind]], at: str,
                  notes: Notes) -> tuple[list[dict[str, Any]], list[str]]:
    """The layout's nodes (kind from their place, else the extension, else tag; marker) and
    the maps they are on; actions that say no place's purpose are noted."""
    entries: list[dict[str, Any]] = []
    map_ids: dict[str, None] = {}
    for node_id, (prop_at, node, prop) in kept.items():
        where = prop_at.rsplit(".", 1)[0]
        place_kind = claimed[node_id][1] if node_id in claimed else None
        kind: NodeKind = "tag"
        if place_kind in ("pickup", "dropoff"):
            kind = "station"
        elif place_kind == "charger":
            kind = "charger"
        elif place_kind == "parking":
            kind = "parking"
        ext = node.fleetSim
        if place_kind is None and ext is not None and ext.kind is not None:
            if ext.kind in ("tag", "junction"):
                kind = ext.kind
            else:
                notes.add(f"{at}.nodes[*].{EXTENSION_KEY}.kind", f"{where}.{EXTENSION_KEY}.kind",
                          f"kind {ext.kind} without its place: read as a tag", kept=True)
        entry: dict[str, Any] = {"id": node_id, "x": node.nodePosition.x,
                                 "y": node.nodePosition.y, "kind": kind}
        if ext is not None and ext.marker is not None:
            entry["marker"] = ext.marker
        entries.append(entry)
        if node.mapId is not None:
            map_ids.setdefault(node.mapId)
        used = ACTIONS.get(place_kind or "", ())
        for a, action in enumerate(prop.actions or ()):
            action_at = f"{prop_at}.actions[{a}]"
            if action.actionType not in used:
                notes.add(f"{at}.nodes[*].vehicleTypeNodeProperties[*].actions[*]", action_at,
                          f"action {action.actionType}: fleet_sim does not model it here")
            elif action.actionParameters:
                notes.add(f"{at}.nodes[*].vehicleTypeNodeProperties[*].actions[*]"
                          ".actionParameters", action_at, "action parameters not modelled")
    return entries, list(map_ids)
