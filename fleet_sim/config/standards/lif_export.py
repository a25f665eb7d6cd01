"""A fleet_sim layout as a VDMA LIF 1.0.0 file: `fleet-sim layout export --lif`.

LIF's own fields carry what LIF can say (node positions, directed edges with maxSpeed, stations
with their interaction nodes, a place's purpose as the VDA 5050 action on its nodes); the
extension key ``fleetSim`` carries the rest, so that `fleet-sim layout import` of an exported
file gives the layout back exactly. The mapping is tabled in docs/reference/standards.md; the
choices where the format was silent: docs/background/decisions/config.md.
"""

from __future__ import annotations

import json
from typing import Any, Final

from fleet_sim.config.layout_spec import LayoutSpec, LifInfo, NodeKind
from fleet_sim.config.standards.lif import (
    ACTIONS,
    EXTENSION_KEY,
    LIF_VERSION,
    LifFile,
    PlaceKind,
)

BLOCKING: Final = "HARD"
"""Blocking type of a place's actions: the AGV stands still and does nothing else meanwhile."""
REQUIREMENT: Final = "CONDITIONAL"
"""Requirement type: an AGV passing the node does not always pick, drop or charge there."""

_Actions = dict[str, list[dict[str, Any]]]
"""nodeId -> the actions of the place on it."""


def layout_to_lif(spec: LayoutSpec, timestamp: str | None = None,
                  vehicle_type: str | None = None) -> dict[str, Any]:
    """The LIF file of one layout, as JSON data (checked against `LifFile`). `timestamp`
    overrides ``lif.export_timestamp``, `vehicle_type` overrides ``lif.vehicle_type_id``."""
    info = spec.lif
    layout_id = info.layout_id or spec.name
    types = export_types(spec, vehicle_type or info.vehicle_type_id)
    place_kind, actions, stations = _stations(spec)
    nodes = _nodes(spec, types, info.map_id or layout_id, place_kind, actions)
    layout = _layout(spec, info, layout_id)
    layout |= {"nodes": nodes, "edges": _edges(spec, types), "stations": stations}
    layout[EXTENSION_KEY] = _layout_extension(spec)
    data = {"metaInformation": {"projectIdentification": info.project or spec.name,
                                "creator": info.creator,
                                "exportTimestamp": timestamp or info.export_timestamp,
                                "lifVersion": LIF_VERSION},
            "layouts": [layout]}
    LifFile.model_validate(data)  # what fleet-sim writes is LIF as this model reads it
    return data


def _stations(spec: LayoutSpec) -> tuple[dict[str, NodeKind], _Actions, list[dict[str, Any]]]:
    """The LIF stations of the layout's places, the node kind each place gives its nodes, and
    the actions that say each place's purpose."""
    position = {n.id: (n.x, n.y) for n in spec.nodes}
    place_kind: dict[str, NodeKind] = {}
    actions: _Actions = {}
    stations: list[dict[str, Any]] = []

    def place(place_id: str, kind: PlaceKind, nodes: tuple[str, ...],
              extension: dict[str, Any]) -> None:
        for node in nodes:
            place_kind[node] = "parking" if kind == "parking" else \
                "charger" if kind == "charger" else "station"
            actions[node] = [{"actionType": a, "requirementType": REQUIREMENT,
                              "blockingType": BLOCKING} for a in ACTIONS.get(kind, ())]
        xs = [position[n][0] for n in nodes]
        ys = [position[n][1] for n in nodes]
        stations.append({"stationId": place_id, "interactionNodeIds": list(nodes),
                         "stationPosition": {"x": sum(xs) / len(xs), "y": sum(ys) / len(ys)},
                         EXTENSION_KEY: {"kind": kind, **extension}})

    for st in spec.stations:
        place(st.id, st.kind, st.nodes, {"handling": st.handling.model_dump(mode="json")})
    for ch in spec.chargers:
        place(ch.id, "charger", (ch.node,), {"power_kw": ch.power_kw, "docking_s": ch.docking_s})
    for pk in spec.parking:
        place(pk.id, "parking", (pk.node,), {"capacity": pk.capacity})
    return place_kind, actions, stations


def _nodes(spec: LayoutSpec, types: tuple[str, ...], map_id: str,
           place_kind: dict[str, NodeKind], actions: _Actions) -> list[dict[str, Any]]:
    """The LIF nodes: one property entry per type (a station's actions only for the types it
    serves), the node's kind and marker in the extension where the places do not tell it."""
    station_types = {n: st.allowed_types for st in spec.stations if st.allowed_types
                     for n in st.nodes}
    nodes = []
    for n in spec.nodes:
        props: list[dict[str, Any]] = []
        for t in types:
            prop: dict[str, Any] = {"vehicleTypeId": t}
            if actions.get(n.id) and t in station_types.get(n.id, (t,)):
                prop["actions"] = actions[n.id]
            props.append(prop)
        node: dict[str, Any] = {"nodeId": n.id, "mapId": map_id,
                                "nodePosition": {"x": n.x, "y": n.y},
                                "vehicleTypeNodeProperties": props}
        extension: dict[str, Any] = {}
        if n.kind != place_kind.get(n.id, "tag"):
            extension["kind"] = n.kind
        if n.marker is not None:
            extension["marker"] = n.marker
        if extension:
            node[EXTENSION_KEY] = extension
        nodes.append(node)
    return nodes


def _edges(spec: LayoutSpec, types: tuple[str, ...]) -> list[dict[str, Any]]:
    """The LIF edges: one per direction a segment is driven (a two-way segment: u->v, then
    v->u right after it), each type's maxSpeed its limit on the segment."""
    edges: list[dict[str, Any]] = []
    edge_ids: set[str] = set()

    def edge(start: str, end: str, limit: float, extension: dict[str, Any],
             allowed: tuple[str, ...], by_type: dict[str, float]) -> None:
        edge_id = f"{start}-{end}"
        n = 2
        while edge_id in edge_ids:  # ids that contain "-" can meet: A-B + C and A + B-C
            edge_id, n = f"{start}-{end}~{n}", n + 1
        edge_ids.add(edge_id)
        data: dict[str, Any] = {
            "edgeId": edge_id, "startNodeId": start, "endNodeId": end,
            "vehicleTypeEdgeProperties": [{"vehicleTypeId": t, "rotationAllowed": False,
                                           "maxSpeed": by_type.get(t, limit)}
                                          for t in allowed or types]}
        if extension:
            data[EXTENSION_KEY] = extension
        edges.append(data)

    for seg in spec.segments:
        limit = seg.speed_limit_mps if seg.speed_limit_mps is not None \
            else spec.defaults.speed_limit_mps
        extension = seg.model_dump(mode="json", exclude_defaults=True,
                                   exclude={"from_node", "to_node", "allowed_types"})
        by_type = dict(seg.speed_limit_mps_by_type)
        edge(seg.from_node, seg.to_node, limit, extension, seg.allowed_types, by_type)
        if seg.direction == "two_way":
            edge(seg.to_node, seg.from_node, limit,
                 {k: v for k, v in extension.items() if k != "branch"}, seg.allowed_types,
                 by_type)
    return edges


def _layout(spec: LayoutSpec, info: LifInfo, layout_id: str) -> dict[str, Any]:
    """The LIF layout's names: id, name, version, level and description."""
    layout: dict[str, Any] = {"layoutId": layout_id, "layoutName": spec.name,
                              "layoutVersion": info.layout_version}
    if info.level_id is not None:
        layout["layoutLevelId"] = info.level_id
    if spec.description:
        layout["layoutDescription"] = spec.description
    return layout


def _layout_extension(spec: LayoutSpec) -> dict[str, Any]:
    """The layout's ``fleetSim`` extension: its defaults, zones and traffic zones."""
    extension: dict[str, Any] = {"defaults": spec.defaults.model_dump(mode="json")}
    if spec.zones:
        extension["zones"] = [z.model_dump(mode="json", exclude_none=True) for z in spec.zones]
    if spec.traffic_zones:
        extension["traffic_zones"] = [
            z.model_dump(mode="json", exclude_defaults=True) for z in spec.traffic_zones]
    return extension


def export_types(spec: LayoutSpec, type_id: str) -> tuple[str, ...]:
    """The vehicle types an export writes: `type_id`, then every type the layout's segments
    and stations name in `allowed_types`, then in `speed_limit_mps_by_type` (first seen
    first). A segment or station with `allowed_types` is written for those types only (a
    station: its pick or drop action only on their entries of its nodes); the rest for every
    type. An edge's maxSpeed for a type is the segment's limit for it. A layout without
    allowed_types and per-type limits is written for `type_id` alone."""
    named: dict[str, None] = {type_id: None}
    for allowed in [s.allowed_types for s in spec.segments] \
            + [s.allowed_types for s in spec.stations] \
            + [tuple(s.speed_limit_mps_by_type) for s in spec.segments]:
        for t in allowed:
            named.setdefault(t)
    return tuple(named)


def lif_json(data: dict[str, Any]) -> str:
    """The text of a LIF file: 2-space indented JSON, UTF-8, keys in the format's order."""
    return json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False) + "\n"
