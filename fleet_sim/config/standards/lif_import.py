"""A fleet_sim layout as a VDMA LIF 1.0.0 file and back: `fleet-sim layout export --lif` and
`fleet-sim layout import`. The mapping, and what is dropped on the way in, is tabled in
docs/reference/standards.md; the decisions it rests on are these.

* Export writes what LIF can say in LIF's own fields (node positions, directed edges with
  maxSpeed, stations with their interaction nodes, the purpose of a place as the VDA 5050 action
  on its nodes: ``pick``, ``drop``, ``startCharging``/``stopCharging``) and everything else in
  the extension key ``fleetSim`` (layout defaults, zones and traffic zones; a node's kind where
  the places do not tell it and its RFID marker; a segment's explicit length, explicit speed
  limit, two-way direction, branch and Wi-Fi signal; a place's kind, handling time, charger
  power and docking time, parking capacity). So a LIF reader that ignores extensions still
  gets a graph it can route on, and `import` of an exported file gives the layout back
  exactly.
* A two-way segment is two LIF edges (u->v, then v->u right after it), both marked two-way in
  the extension; import merges them back into one segment. In a file without fleet-sim's
  extension, an opposite pair of edges with the same length and speed limit is one path driven
  both ways, so it becomes one two-way segment (a single-track corridor); any other edge is a
  one-way segment.
* LIF's fields win over the extension where both speak: an edge's maxSpeed is its speed limit
  (the extension only says whether the layout gave it or took the default); a station's
  interaction nodes are its nodes.
* A segment's length: the extension's `length_m`, else the length of the edge's trajectory
  (NURBS) for the vehicle type, else none (the straight distance).
* fleet_sim layouts describe one vehicle type. Import takes the one the file uses, or the one
  named (`--vehicle-type`); nodes and edges not open to it are left out and reported, as are the
  properties for other types. Of a multi-layout file (levels of a building, say) one layout is
  taken (`--layout-id`); without it the refusal names each layout with the option that
  chooses it (its level and size beside it), since a fleet_sim layout is one plane.
* Mixed fleets: `--all-types` (``all_types=True``) imports every vehicle type of the layout.
  A node or edge open to any type is kept; a segment open to some types only gets those as its
  `allowed_types`, and so does a pickup or drop-off station whose interaction nodes are not
  open to every type (the types open on all of them). Each type keeps its own maxSpeed (the
  speed it would have if imported alone): the highest is the segment's `speed_limit_mps`, a
  lower one the type's `speed_limit_mps_by_type` (`_speeds`). A segment has one length: the
  main type's (`--vehicle-type`, else the file's first type) where it has an entry, else the
  first type's that has one; another type's different trajectory is reported. An opposite
  pair of edges becomes one two-way segment only if the same types may drive both at the same
  speeds. Chargers and parking areas have no `allowed_types`: one not open to every type is
  kept and reported.
* Per-type speed limits are exported as each type's maxSpeed on the edge (the types they name
  are written like those of `allowed_types`); the edge's extension repeats them, so that the
  import knows the segment's own limit even where every type on the edge has a lower one.
* A foreign station's purpose comes from the actions on its interaction nodes, as LIF 8.3.13.1
  says: pick -> pickup, drop -> drop-off, startCharging -> one charger per node. A station with
  none of them cannot be placed and is reported; so are handling times (fleet_sim's default) and
  charger figures (defaults) that LIF does not carry, and parking, which LIF has no action for.
* Nothing is dropped silently: each optional LIF field the import has no place for, and each key
  LIF does not name, is counted in `Imported.notes` (LIF 8.1.1 asks an importer to warn), and the
  command prints them and writes them at the top of the layout file.
"""

from __future__ import annotations

import json
import math
import shlex
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

from pydantic import BaseModel

from fleet_sim.config.layout import LayoutDefaults, LayoutSpec, NodeKind
from fleet_sim.config.lif import (
    EXTENSION_KEY,
    LIF_VERSION,
    Edge,
    EdgeExtension,
    Layout,
    LifFile,
    LifModel,
    Node,
    TextNumber,
    VehicleTypeEdgeProperty,
    VehicleTypeNodeProperty,
    read_lif_noting,
    text_number_warnings,
    trajectory_length_m,
)
from fleet_sim.errors import InputError
from userfiles.checking import validate

PlaceKind = Literal["pickup", "dropoff", "charger", "parking"]
ACTIONS: Final[dict[str, tuple[str, ...]]] = {
    "pickup": ("pick",), "dropoff": ("drop",), "charger": ("startCharging", "stopCharging")}
"""The VDA 5050 actions that say what a place is for (LIF 8.3.13.1)."""
BLOCKING: Final = "HARD"
"""Blocking type of those actions: the AGV stands still and does nothing else meanwhile."""
REQUIREMENT: Final = "CONDITIONAL"
"""Requirement type: an AGV passing the node does not always pick, drop or charge there."""
LENGTH_DIGITS: Final = 6
"""A trajectory's length is kept to the micrometre."""


# Export

def layout_to_lif(spec: LayoutSpec, timestamp: str | None = None,
                  vehicle_type: str | None = None) -> dict[str, Any]:
    """The LIF file of one layout, as JSON data (checked against `LifFile`). `timestamp`
    overrides ``lif.export_timestamp``, `vehicle_type` overrides ``lif.vehicle_type_id``."""
    info = spec.lif
    layout_id = info.layout_id or spec.name
    map_id = info.map_id or layout_id
    type_id = vehicle_type or info.vehicle_type_id
    types = export_types(spec, type_id)
    station_types = {n: st.allowed_types for st in spec.stations if st.allowed_types
                     for n in st.nodes}
    position = {n.id: (n.x, n.y) for n in spec.nodes}
    place_kind: dict[str, NodeKind] = {}
    actions: dict[str, list[dict[str, Any]]] = {}
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

    layout: dict[str, Any] = {"layoutId": layout_id, "layoutName": spec.name,
                              "layoutVersion": info.layout_version}
    if info.level_id is not None:
        layout["layoutLevelId"] = info.level_id
    if spec.description:
        layout["layoutDescription"] = spec.description
    layout |= {"nodes": nodes, "edges": edges, "stations": stations}
    layout[EXTENSION_KEY] = {"defaults": spec.defaults.model_dump(mode="json")}
    if spec.zones:
        layout[EXTENSION_KEY]["zones"] = [z.model_dump(mode="json", exclude_none=True)
                                          for z in spec.zones]
    if spec.traffic_zones:
        layout[EXTENSION_KEY]["traffic_zones"] = [
            z.model_dump(mode="json", exclude_defaults=True) for z in spec.traffic_zones]
    data = {"metaInformation": {"projectIdentification": info.project or spec.name,
                                "creator": info.creator,
                                "exportTimestamp": timestamp or info.export_timestamp,
                                "lifVersion": LIF_VERSION},
            "layouts": [layout]}
    LifFile.model_validate(data)  # what fleet-sim writes is LIF as this model reads it
    return data


def export_types(spec: LayoutSpec, type_id: str) -> tuple[str, ...]:
    """The vehicle types an export writes: `type_id`, then every type the layout's segments
    and stations name in `allowed_types`, then in `speed_limit_mps_by_type` (first seen
    first). A segment or station with `allowed_types` is written for those types only (a
    station: its pick or drop action only on their entries of its nodes); the rest for every
    type. An edge's maxSpeed for a type is the segment's limit for it. A layout without
    allowed_types and per-type limits is written for `type_id` alone, as always."""
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


# Import

@dataclass(frozen=True)
class Note:
    """Something of the LIF file the layout does not keep (or reads in a way worth saying)."""

    what: str
    """The JSON path, with [*] for every item of a list: ``layouts[0].nodes[*].nodeName``."""
    why: str
    count: int
    example: str
    """The JSON path of the first one."""
    kept: bool = False
    """True: read, but as `why` says; False: not kept."""

    def line(self) -> str:
        if self.count > 1:
            return f"{self.what} ({self.count}x, e.g. {self.example}): {self.why}"
        if self.example != self.what:
            return f"{self.what} ({self.example}): {self.why}"
        return f"{self.what}: {self.why}"


@dataclass
class _Notes:
    found: dict[tuple[str, str, bool], list[Any]] = field(default_factory=dict)

    def add(self, what: str, example: str, why: str, kept: bool = False) -> None:
        entry = self.found.setdefault((what, why, kept), [0, example])
        entry[0] += 1

    def notes(self) -> tuple[Note, ...]:
        return tuple(Note(what, why, count, example, kept)
                     for (what, why, kept), (count, example) in self.found.items())


@dataclass(frozen=True)
class Imported:
    """A layout read from a LIF file, and what of the file it does not keep."""

    spec: LayoutSpec
    file: str
    lif_version: str
    layout_id: str
    vehicle_type: str
    notes: tuple[Note, ...]
    text_numbers: tuple[TextNumber, ...] = ()
    """Numbers the file writes as texts, read as numbers (`warnings` tells them)."""

    def warnings(self) -> list[str]:
        """The lines the command prints on stderr: each kind of text number, once."""
        return text_number_warnings(self.file, self.text_numbers)

    def comments(self) -> list[str]:
        """The first lines of the layout file written from it."""
        lines = [f"Imported by `fleet-sim layout import` from {self.file}: LIF {self.lif_version}"
                 f", layout {self.layout_id}, vehicle type {self.vehicle_type}."]
        dropped = [n for n in self.notes if not n.kept]
        read_as = [n for n in self.notes if n.kept]
        if dropped:
            lines.append("Not kept (no place for it in a fleet_sim layout):")
            lines += [f"  - {n.line()}" for n in dropped]
        if read_as:
            lines.append("Read as:")
            lines += [f"  - {n.line()}" for n in read_as]
        if not dropped:
            lines.append("Nothing of the file was left out.")
        return lines


def import_lif(path: Path, layout_id: str | None = None,
               vehicle_type: str | None = None, all_types: bool = False) -> Imported:
    """Read a LIF file and turn one of its layouts into a layout spec (not yet checked as a
    graph: `layout_from_spec` does that). `all_types`: every vehicle type, as allowed_types
    (see the module docstring); `vehicle_type` is then the main one."""
    lif, text_numbers = read_lif_noting(path)
    return lif_to_layout(lif, str(path), layout_id, vehicle_type, all_types, text_numbers)


def lif_to_layout(lif: LifFile, file: str, layout_id: str | None = None,
                  vehicle_type: str | None = None, all_types: bool = False,
                  text_numbers: tuple[TextNumber, ...] = ()) -> Imported:
    notes = _Notes()
    for number in text_numbers:
        notes.add(number.pattern, number.element, "numbers written as texts, read as the "
                  "numbers", kept=True)
    index = _choose_layout(lif, file, layout_id)
    layout = lif.layouts[index]
    at = f"layouts[{index}]"
    for i, other in enumerate(lif.layouts):
        if i != index:
            notes.add(f"layouts[{i}]", f"layouts[{i}]", f"layout {other.layoutId} not imported "
                      "(one layout per fleet_sim layout file; --layout-id chooses)")
    types: tuple[str, ...] | None = None
    if all_types:
        types = _vehicle_types(layout)
        type_id = _choose_vehicle_type(layout, file, at, vehicle_type) \
            if vehicle_type is not None else types[0] if types else \
            _choose_vehicle_type(layout, file, at, None)
        types = (type_id, *(t for t in types if t != type_id))
    else:
        type_id = _choose_vehicle_type(layout, file, at, vehicle_type)
    for what, example in _extra_keys(lif, "", ""):
        notes.add(what, example, "not a LIF 1.0.0 key")
    kept = _open_nodes(layout, type_id, at, notes) if types is None \
        else _open_nodes_any(layout, types, at, notes)
    claimed, places = _places(layout, kept, at, notes)
    if types is not None:
        _place_types(layout, places, types, at, notes)
    spec_nodes, map_ids = _node_entries(kept, claimed, at, notes)
    extension = layout.fleetSim
    defaults = extension.defaults if extension is not None and extension.defaults is not None \
        else LayoutDefaults()
    segments = _segments(layout.edges, kept, type_id, extension is not None, at, notes,
                         defaults, types)

    name = layout.layoutName if layout.layoutName is not None else layout.layoutId
    meta = lif.metaInformation
    lif_info: dict[str, Any] = {
        "project": meta.projectIdentification if meta.projectIdentification != name else None,
        "creator": meta.creator, "export_timestamp": meta.exportTimestamp,
        "layout_id": layout.layoutId if layout.layoutId != name else None,
        "layout_version": layout.layoutVersion, "level_id": layout.layoutLevelId,
        "vehicle_type_id": type_id}
    if len(map_ids) > 1:
        notes.add(f"{at}.nodes[*].mapId", f"{at}.nodes", f"nodes on {len(map_ids)} maps "
                  f"({', '.join(map_ids)}): a fleet_sim layout is one plane; mapId "
                  f"{map_ids[0]} kept")
    if map_ids and map_ids[0] != layout.layoutId:
        lif_info["map_id"] = map_ids[0]
    if meta.lifVersion != LIF_VERSION:
        notes.add("metaInformation.lifVersion", "metaInformation.lifVersion",
                  f"{meta.lifVersion}: an export writes {LIF_VERSION}", kept=True)
    data: dict[str, Any] = {"name": name}
    if layout.layoutDescription:
        data["description"] = layout.layoutDescription
    if extension is not None and extension.defaults is not None:
        data["defaults"] = extension.defaults.model_dump(mode="json")
    if extension is not None and extension.zones:
        data["zones"] = [z.model_dump(mode="json", exclude_none=True) for z in extension.zones]
    if extension is not None and extension.traffic_zones:
        data["traffic_zones"] = [z.model_dump(mode="json", exclude_defaults=True)
                                 for z in extension.traffic_zones]
    data |= {"nodes": spec_nodes, "segments": segments, **places,
             "lif": {k: v for k, v in lif_info.items() if v is not None}}
    spec = validate(LayoutSpec, data, file, at)
    return Imported(spec, file, meta.lifVersion, layout.layoutId, type_id, notes.notes(),
                    text_numbers)


_OpenNodes = dict[str, tuple[str, Node, VehicleTypeNodeProperty]]
"""nodeId -> (JSON path of its entry for the vehicle type, node, entry), in file order."""


def _open_nodes(layout: Layout, type_id: str, at: str, notes: _Notes) -> _OpenNodes:
    """The nodes open to the vehicle type."""
    kept: _OpenNodes = {}
    for j, node in enumerate(layout.nodes):
        where = f"{at}.nodes[{j}]"
        k, prop = _entry(node.vehicleTypeNodeProperties, type_id, notes,
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


def _vehicle_types(layout: Layout) -> tuple[str, ...]:
    """The vehicleTypeIds of a layout's nodes and edges, in file order."""
    types: dict[str, None] = {}
    for node in layout.nodes:
        for prop in node.vehicleTypeNodeProperties:
            types.setdefault(prop.vehicleTypeId)
    for edge in layout.edges:
        for eprop in edge.vehicleTypeEdgeProperties:
            types.setdefault(eprop.vehicleTypeId)
    return tuple(types)


def _main_entry(entries: tuple[Any, ...], types: tuple[str, ...]) -> tuple[int, Any]:
    """The index and entry of the first of `types` (main type first) that has one."""
    for type_id in types:
        for k, entry in enumerate(entries):
            if entry.vehicleTypeId == type_id:
                return k, entry
    return -1, None


def _open_nodes_any(layout: Layout, types: tuple[str, ...], at: str,
                    notes: _Notes) -> _OpenNodes:
    """The nodes open to any of `types` (all types), with the main type's entry if it has
    one."""
    kept: _OpenNodes = {}
    for j, node in enumerate(layout.nodes):
        where = f"{at}.nodes[{j}]"
        k, prop = _main_entry(node.vehicleTypeNodeProperties, types)
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


def _place_types(layout: Layout, places: dict[str, list[dict[str, Any]]],
                 types: tuple[str, ...], at: str, notes: _Notes) -> None:
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


def _places(layout: Layout, kept: _OpenNodes, at: str, notes: _Notes
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


def _node_entries(kept: _OpenNodes, claimed: dict[str, tuple[str, PlaceKind]], at: str,
                  notes: _Notes) -> tuple[list[dict[str, Any]], list[str]]:
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


def _choose_layout(lif: LifFile, file: str, layout_id: str | None) -> int:
    ids = [layout.layoutId for layout in lif.layouts]
    if not ids:
        raise InputError(file, "layouts", [], "at least one layout")
    if layout_id is not None:
        if layout_id not in ids:
            raise InputError(file, "layouts", layout_id,
                             f"the layoutId of one of its layouts: {', '.join(ids) or 'none'}")
        return ids.index(layout_id)
    if len(ids) != 1:
        choices = " or ".join(f"--layout-id {shlex.quote(layout.layoutId)} ({_size(layout)})"
                              for layout in lif.layouts)
        raise InputError(file, "layouts", ids, f"one layout; choose one with {choices}")
    return 0


def _size(layout: Layout) -> str:
    """``level 1, 12 nodes``: what tells one layout of a file from another."""
    nodes = len(layout.nodes)
    level = f"level {layout.layoutLevelId}, " if layout.layoutLevelId else ""
    return f"{level}{nodes} node{'' if nodes == 1 else 's'}"


def _choose_vehicle_type(layout: Layout, file: str, at: str, vehicle_type: str | None) -> str:
    types = _vehicle_types(layout)
    if vehicle_type is not None:
        if vehicle_type not in types:
            raise InputError(file, f"{at}.nodes", vehicle_type,
                             f"a vehicleTypeId the layout uses: {', '.join(types) or 'none'}")
        return vehicle_type
    if len(types) != 1:
        choices = " or ".join(f"--vehicle-type {shlex.quote(t)}" for t in types)
        raise InputError(file, f"{at}.nodes", list(types),
                         f"one vehicle type; choose one with {choices} (or every one with "
                         "--all-types)" if types else "a vehicle type (no node names one)")
    return next(iter(types))


def _entry(entries: tuple[Any, ...], type_id: str, notes: _Notes, pattern: str,
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


def _place_kind(extension_kind: PlaceKind | None, props: list[VehicleTypeNodeProperty],
                notes: _Notes, where: str, pattern: str) -> PlaceKind | None:
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


@dataclass
class _Hop:
    where: str
    edge: Edge
    prop: VehicleTypeEdgeProperty
    ext: EdgeExtension | None
    length_m: float | None
    speed_limit_mps: float | None
    allowed_types: tuple[str, ...] = ()
    """With every vehicle type imported: the types that may drive it, if not all."""
    speed_limits_by_type: dict[str, float] = field(default_factory=dict)
    """With every vehicle type imported: the types whose maxSpeed is below the segment's."""


def _segments(edges: tuple[Edge, ...], kept: _OpenNodes, type_id: str, ours: bool, at: str,
              notes: _Notes, defaults: LayoutDefaults,
              types: tuple[str, ...] | None = None) -> list[dict[str, Any]]:
    """The segments; `types`: every vehicle type (main first), kept as allowed_types."""
    pattern = f"{at}.edges[*]"
    hops: list[_Hop] = []
    seen: dict[tuple[str, str], str] = {}
    for j, edge in enumerate(edges):
        where = f"{at}.edges[{j}]"
        if types is None:
            k, prop = _entry(edge.vehicleTypeEdgeProperties, type_id, notes,
                             f"{pattern}.vehicleTypeEdgeProperties", where)
        else:
            k, prop = _main_entry(edge.vehicleTypeEdgeProperties, types)
        if prop is None:
            notes.add(pattern, where, f"edge not open to vehicle type {type_id}" if types is None
                      else "edge open to no vehicle type")
            continue
        if edge.startNodeId not in kept or edge.endNodeId not in kept:
            notes.add(pattern, where, "edge to or from a node not imported (not open to the "
                      "vehicle type or in another layout)")
            continue
        if edge.startNodeId == edge.endNodeId:
            notes.add(pattern, where, "edge from a node to itself: no segment in fleet_sim")
            continue
        pair = (edge.startNodeId, edge.endNodeId)
        if pair in seen:
            notes.add(pattern, where, f"a second edge {pair[0]} -> {pair[1]} ({seen[pair]} "
                      "kept): fleet_sim has one segment per direction between two nodes")
            continue
        seen[pair] = where
        _note_edge_fields(edge, prop, where, f"{where}.vehicleTypeEdgeProperties[{k}]",
                          pattern, notes)
        allowed: tuple[str, ...] = ()
        prop_at = f"{where}.vehicleTypeEdgeProperties[{k}]"
        if types is None:
            speed = _speed(edge.fleetSim, prop, defaults, prop_at, pattern, notes)
            by_type: dict[str, float] = {}
        else:
            allowed = _edge_types(edge, prop, types, where, pattern, notes)
            speed, by_type = _speeds(edge, types, defaults, where, pattern, notes)
        hops.append(_Hop(where, edge, prop, edge.fleetSim,
                         _length(edge, prop, kept, prop_at, pattern, notes), speed, allowed,
                         by_type))
    by_pair = {(h.edge.startNodeId, h.edge.endNodeId): h for h in hops}
    merged: set[int] = set()
    segments: list[dict[str, Any]] = []
    for hop in hops:
        if id(hop) in merged:
            continue
        partner = by_pair.get((hop.edge.endNodeId, hop.edge.startNodeId))
        two_way = hop.ext.direction == "two_way" if ours and hop.ext is not None else not ours
        if partner is not None and id(partner) not in merged and two_way and (
                not ours or (partner.ext is not None and partner.ext.direction == "two_way")):
            same = (partner.length_m, partner.speed_limit_mps, partner.allowed_types,
                    partner.speed_limits_by_type) \
                == (hop.length_m, hop.speed_limit_mps, hop.allowed_types,
                    hop.speed_limits_by_type) \
                and (partner.ext.rssi_dbm if partner.ext else None) == (
                    hop.ext.rssi_dbm if hop.ext else None)
            if same:
                merged.add(id(partner))
                segments.append(_segment(hop, "two_way"))
                if not ours:
                    notes.add(pattern, f"{hop.where} + {partner.where}", "an opposite pair of "
                              "edges with the same length and speed: one two-way segment "
                              "(a single-track corridor)", kept=True)
                continue
        if ours and hop.ext is not None and hop.ext.direction == "two_way":
            notes.add(pattern, hop.where, "two-way in fleetSim, but no matching opposite edge: "
                      "read as one-way", kept=True)
        segments.append(_segment(hop, "one_way"))
    return segments


def _segment(hop: _Hop, direction: str) -> dict[str, Any]:
    data: dict[str, Any] = {"from": hop.edge.startNodeId, "to": hop.edge.endNodeId}
    if hop.length_m is not None:
        data["length_m"] = hop.length_m
    if hop.speed_limit_mps is not None:
        data["speed_limit_mps"] = hop.speed_limit_mps
    if hop.speed_limits_by_type:
        data["speed_limit_mps_by_type"] = hop.speed_limits_by_type
    if direction == "two_way":
        data["direction"] = "two_way"
    if hop.ext is not None and hop.ext.branch != "auto":
        data["branch"] = hop.ext.branch
    if hop.ext is not None and hop.ext.rssi_dbm is not None:
        data["rssi_dbm"] = hop.ext.rssi_dbm
    if hop.allowed_types:
        data["allowed_types"] = list(hop.allowed_types)
    return data


def _edge_types(edge: Edge, prop: VehicleTypeEdgeProperty, types: tuple[str, ...], where: str,
                pattern: str, notes: _Notes) -> tuple[str, ...]:
    """The types that may drive an edge, if not every type (else ()); another type's different
    trajectory is reported (a segment has one length; each type's maxSpeed is kept:
    `_speeds`)."""
    entries = edge.vehicleTypeEdgeProperties
    open_to = {e.vehicleTypeId for e in entries}
    for k, entry in enumerate(entries):
        if entry is prop:
            continue
        at = f"{where}.vehicleTypeEdgeProperties[{k}]"
        if entry.trajectory is not None and entry.trajectory != prop.trajectory:
            notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].trajectory", f"{at}.trajectory",
                      f"trajectory of another vehicle type: the segment keeps type "
                      f"{prop.vehicleTypeId}'s length")
    allowed = tuple(t for t in types if t in open_to)
    return () if len(allowed) == len(types) else allowed


def _length(edge: Edge, prop: VehicleTypeEdgeProperty, kept: _OpenNodes, prop_at: str,
            pattern: str, notes: _Notes) -> float | None:
    if edge.fleetSim is not None and edge.fleetSim.length_m is not None:
        if prop.trajectory is not None:
            notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].trajectory", f"{prop_at}.trajectory",
                      "fleetSim length_m is the segment's length")
        return edge.fleetSim.length_m
    if prop.trajectory is None:
        return None
    length = round(trajectory_length_m(prop.trajectory), LENGTH_DIGITS)
    a, b = kept[edge.startNodeId][1].nodePosition, kept[edge.endNodeId][1].nodePosition
    straight = math.hypot(b.x - a.x, b.y - a.y)
    if length < straight - 1e-6:
        notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].trajectory", f"{prop_at}.trajectory",
                  "trajectory shorter than the straight line between its nodes: the straight "
                  "distance is the length")
        return None
    notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].trajectory", f"{prop_at}.trajectory",
              "the length of the curve is the segment's length_m (its shape is not kept)",
              kept=True)
    return length


def _speed(ext: EdgeExtension | None, prop: VehicleTypeEdgeProperty, defaults: LayoutDefaults,
           prop_at: str, pattern: str, notes: _Notes) -> float | None:
    """maxSpeed wins; the extension says whether the layout gave it or took the default."""
    explicit = ext.speed_limit_mps if ext is not None else None
    if prop.maxSpeed is None:
        if ext is None:
            notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].maxSpeed",
                      f"{prop_at}.maxSpeed", "no maxSpeed (no "
                      f"limit): defaults.speed_limit_mps ({defaults.speed_limit_mps:g} m/s) "
                      "applies", kept=True)
        return explicit
    if explicit is not None and prop.maxSpeed == explicit:
        return explicit
    return None if prop.maxSpeed == defaults.speed_limit_mps else prop.maxSpeed


def _speeds(edge: Edge, types: tuple[str, ...], defaults: LayoutDefaults, where: str,
            pattern: str, notes: _Notes) -> tuple[float | None, dict[str, float]]:
    """With every vehicle type: the segment's speed limit (given as `_speed` gives it) and
    the types' lower limits. Each type keeps the speed it would have if imported alone: its
    maxSpeed, else (no limit in LIF) the extension's speed_limit_mps or
    defaults.speed_limit_mps. The segment's limit is the highest of them (or, where
    fleet-sim's extension lists per-type limits, at least the layout's own limit, which every
    type on the edge may have below it); a type below it gets its own as its limit."""
    ext = edge.fleetSim
    explicit = ext.speed_limit_mps if ext is not None else None
    fallback = explicit if explicit is not None else defaults.speed_limit_mps
    speeds: dict[str, float] = {}
    for k, entry in enumerate(edge.vehicleTypeEdgeProperties):
        if entry.maxSpeed is not None:
            speeds[entry.vehicleTypeId] = entry.maxSpeed
            continue
        speeds[entry.vehicleTypeId] = fallback
        if ext is None:
            notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].maxSpeed",
                      f"{where}.vehicleTypeEdgeProperties[{k}].maxSpeed", "no maxSpeed (no "
                      f"limit): defaults.speed_limit_mps ({defaults.speed_limit_mps:g} m/s) "
                      "applies", kept=True)
    top = max(speeds.values())
    listed = ext.speed_limit_mps_by_type if ext is not None else None
    if listed:
        top = max(top, fallback)
    limit = explicit if explicit is not None and explicit == top else \
        None if top == defaults.speed_limit_mps else top
    order = [*(listed or ()), *types]
    lower = sorted((t for t, v in speeds.items() if v < top), key=order.index)
    return limit, {t: speeds[t] for t in lower}


_NOT_MODELLED: Final = {
    "vehicleOrientation": "fleet_sim does not model the vehicle's orientation",
    "orientationType": "fleet_sim does not model the vehicle's orientation",
    "rotationAtStartNodeAllowed": "fleet_sim does not model rotation on the spot",
    "rotationAtEndNodeAllowed": "fleet_sim does not model rotation on the spot",
    "maxRotationSpeed": "fleet_sim does not model rotation on the spot",
    "minHeight": "fleet_sim does not model heights",
    "maxHeight": "fleet_sim does not model heights",
    "loadRestriction": "fleet_sim lets loaded and empty AGVs use every segment",
    "actions": "fleet_sim does not model actions on edges",
    "reentryAllowed": "fleet_sim does not model re-entry into automatic mode",
}


def _note_edge_fields(edge: Edge, prop: VehicleTypeEdgeProperty, where: str, prop_at: str,
                      pattern: str, notes: _Notes) -> None:
    for key in ("edgeName", "edgeDescription"):
        if getattr(edge, key) is not None:
            notes.add(f"{pattern}.{key}", f"{where}.{key}",
                      "for display only; fleet_sim segments have no names")
    if prop.rotationAllowed:
        notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].rotationAllowed",
                  f"{prop_at}.rotationAllowed", "fleet_sim does not model rotation on an edge")
    for key, why in _NOT_MODELLED.items():
        if getattr(prop, key) is not None:
            notes.add(f"{pattern}.vehicleTypeEdgeProperties[*].{key}", f"{prop_at}.{key}", why)


def _extra_keys(model: BaseModel, path: str, pattern: str) -> Iterator[tuple[str, str]]:
    """(pattern, path) of every key LIF does not name, anywhere in `model`."""
    for key in model.model_extra or {}:
        yield _dot(pattern, key), _dot(path, key)
    for name in type(model).model_fields:
        value = getattr(model, name)
        if isinstance(value, LifModel):
            yield from _extra_keys(value, _dot(path, name), _dot(pattern, name))
        elif isinstance(value, tuple):
            for i, item in enumerate(value):
                if isinstance(item, LifModel):
                    keep = name == "layouts"
                    yield from _extra_keys(item, f"{_dot(path, name)}[{i}]",
                                           f"{_dot(pattern, name)}[{i if keep else '*'}]")


def _dot(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key
