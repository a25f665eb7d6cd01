"""LIF import, edges: the segments of the edges open to the vehicle type(s), an opposite pair
of edges merged into one two-way segment, each segment's length and speed limits."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Final

from fleet_sim.config.layout_spec import LayoutDefaults
from fleet_sim.config.standards.lif import (
    Edge,
    EdgeExtension,
    VehicleTypeEdgeProperty,
    trajectory_length_m,
)
from fleet_sim.config.standards.lif_import_nodes import OpenNodes, main_type_entry, type_entry
from fleet_sim.config.standards.lif_notes import Notes

LENGTH_DIGITS: Final = 6
"""A trajectory's length is kept to the micrometre."""


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


def segments_of(edges: tuple[Edge, ...], kept: OpenNodes, type_id: str, ours: bool, at: str,
              notes: Notes, defaults: LayoutDefaults,
              types: tuple[str, ...] | None = None) -> list[dict[str, Any]]:
    """The segments; `types`: every vehicle type (main first), kept as allowed_types."""
    pattern = f"{at}.edges[*]"
    hops: list[_Hop] = []
    seen: dict[tuple[str, str], str] = {}
    for j, edge in enumerate(edges):
        where = f"{at}.edges[{j}]"
        if types is None:
            k, prop = type_entry(edge.vehicleTypeEdgeProperties, type_id, notes,
                             f"{pattern}.vehicleTypeEdgeProperties", where)
        else:
            k, prop = main_type_entry(edge.vehicleTypeEdgeProperties, types)
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
                pattern: str, notes: Notes) -> tuple[str, ...]:
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


def _length(edge: Edge, prop: VehicleTypeEdgeProperty, kept: OpenNodes, prop_at: str,
            pattern: str, notes: Notes) -> float | None:
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
           prop_at: str, pattern: str, notes: Notes) -> float | None:
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
            pattern: str, notes: Notes) -> tuple[float | None, dict[str, float]]:
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
                      pattern: str, notes: Notes) -> None:
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
