"""Layout files -> a validated networkx graph of nodes (RFID tags, junctions, stations, chargers,
parking) and segments (magnetic-tape paths between them).

The file format is described in docs/reference/layout-format.md. Every problem found while
loading names the file, the element (``segments[12].to``), the bad value and what was expected.

Modelling decisions written down here because the engine relies on them:

* A station's capacity is its number of docking nodes: one AGV per node at a time, as everywhere.
* A parking area is an off-track buffer of ``capacity`` AGVs reached through its access node: an
  AGV inside holds no node, so parked AGVs never block traffic.
* Two-way segments form *corridors*: maximal chains of two-way segments between junctions (nodes
  that also have one-way segments or meet three or more two-way segments). An AGV must hold a
  corridor before it enters it (single-track rule), which rules out head-on deadlocks by
  construction. A dead-end spur to a charger is a corridor too. A corridor covered by a
  same_direction traffic zone is not one: the zone's rule (AGVs inside all drive it one way)
  takes the place of the single-track rule.
* The turn an AGV makes at a node comes from the geometry of its incoming and outgoing segments
  (left, right, straight, reverse); a segment's ``branch`` key overrides it for AGVs entering it.
* A segment's ``speed_limit_mps_by_type`` (type -> m/s) only lowers its speed limit for the
  types named: an AGV drives it at the least of its top speed, the segment's limit and its
  type's limit there (`Layout.speed_limit_mps`). A limit at or above the segment's own says
  nothing and is refused, as is one for a type the segment's ``allowed_types`` shut out. The
  names are not checked against a fleet here (a layout serves many scenarios); a mixed fleet
  whose layout names a type it lacks is warned (fleet_sim.config.scenario.setup_warnings).
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any, Final, Literal, NoReturn

import networkx as nx
import yaml
from pydantic import AfterValidator, Field, Strict, field_validator

from fleet_sim.config.distributions import FixedTime, TimeDistribution
from fleet_sim.errors import InputError
from userfiles.checking import Items, NonNegative, Positive, Problem, StrictModel, Text, validate
from userfiles.reading import read_yaml
from userfiles.writing import comment_lines, tidy_numbers

NodeKind = Literal["tag", "junction", "station", "charger", "parking"]
Branch = Literal["auto", "straight", "left", "right"]
Turn = Literal["straight", "left", "right", "reverse"]

STRAIGHT_WITHIN_DEG = 30.0
"""Heading changes smaller than this are driven straight (no branch speed limit)."""
REVERSE_BEYOND_DEG = 150.0
"""Heading changes larger than this are a reversal: the AGV must stop at the node first."""


Marker = Literal["speed_low", "speed_mid", "speed_high", "location", "spin", "pause"]
MARKER_SPEED_MPS = {"speed_low": 0.2, "speed_mid": 0.5, "speed_high": 1.0}
"""RSS-AGV-001 5.3: TYPE_SPD 0x01/0x02/0x03 set the speed to 0.2/0.5/1.0 m/s."""


class NodeSpec(StrictModel):
    id: Text
    x: float
    """Metres."""
    y: float
    """Metres."""
    kind: NodeKind = "tag"
    marker: Marker | None = None
    """RFID marker action (RSS-AGV-001 5.3): speed tags, location correction, spin, pause."""


class TypeLimits(dict[str, float]):
    """Vehicle type -> speed limit (m/s) of one segment: a read-only, hashable mapping, so a
    layout spec stays hashable like every config (lists are tuples there)."""

    def __hash__(self) -> int:  # type: ignore[override]
        return hash(tuple(sorted(self.items())))

    def __reduce__(self) -> tuple[type[TypeLimits], tuple[dict[str, float]]]:
        return TypeLimits, (dict(self),)  # pickle and copy without item assignment

    def _read_only(self, *_: Any, **__: Any) -> NoReturn:
        raise TypeError("a segment's per-type speed limits are read-only")

    __setitem__ = __delitem__ = _read_only
    clear = pop = popitem = setdefault = update = _read_only


SpeedLimitsByType = Annotated[dict[Text, Positive], AfterValidator(TypeLimits)]


class SegmentSpec(StrictModel):
    from_node: Text = Field(alias="from")
    to_node: Text = Field(alias="to")
    length_m: Positive | None = None
    """Default: the straight distance between the two nodes."""
    speed_limit_mps: Positive | None = None
    """Default: defaults.speed_limit_mps."""
    direction: Literal["one_way", "two_way"] = "one_way"
    branch: Branch = "auto"
    rssi_dbm: float | None = None
    """Wi-Fi signal on the segment; default: its zone's, else defaults.rssi_dbm."""
    allowed_types: Items[Text] = ()
    """Vehicle types (the scenario's fleet.vehicles[].type, or a one-type fleet's
    vehicle.name) that may drive the segment; empty: every type."""
    speed_limit_mps_by_type: SpeedLimitsByType = Field(default={}, validate_default=True)
    """Lower speed limits for some vehicle types (type -> m/s), such as a heavy tugger in a
    narrow aisle: an AGV of a named type drives the segment at most at its type's limit, the
    others at speed_limit_mps. Each below the segment's speed limit; with allowed_types,
    only types among them."""


class StationSpec(StrictModel):
    id: Text
    kind: Literal["pickup", "dropoff"]
    nodes: Items[Text]
    handling: TimeDistribution = FixedTime(mean_s=20.0)
    allowed_types: Items[Text] = ()
    """Vehicle types that may serve the station; empty: every type. An order goes only to an
    AGV whose type may serve both its stations."""


class ChargerSpec(StrictModel):
    id: Text
    node: Text
    power_kw: Positive = 3.0
    docking_s: NonNegative = 30.0


class ParkingSpec(StrictModel):
    id: Text
    node: Text
    capacity: int = Field(default=1, ge=1)


class LayoutDefaults(StrictModel):
    speed_limit_mps: Positive = 1.0
    turn_length_m: NonNegative = 1.0
    """Length of the curve after a branch node, driven at the vehicle's turn speed (assumed)."""
    rssi_dbm: float = -55.0
    """Assumed: good Wi-Fi coverage where nothing else is said."""


class ZoneSpec(StrictModel):
    """An area of the floor (x_min, y_min, x_max, y_max in metres) whose segments (by their
    midpoint) get their own Wi-Fi signal or obstacle rate."""

    id: Text
    area_m: Annotated[tuple[float, float, float, float], Strict(False)]
    rssi_dbm: float | None = None
    obstacle_rate_per_km: NonNegative | None = None
    obstacle_duration: TimeDistribution | None = None


TrafficZoneKind = Literal["mutex", "ban", "same_direction"]


class TrafficZoneSpec(StrictModel):
    """A traffic zone (FlexSim's control areas, openTCS blocks, Open-RMF mutex groups): a set
    of nodes, given as `nodes` and/or `segments` (a segment adds both its ends).

    * ``mutex``: at most `capacity` AGVs inside at once (an AGV is inside while it holds a
      node of the zone); an AGV asks traffic for the zone before it takes its first node in
      it and waits outside when the zone is full.
    * ``ban``: AGVs of `banned_types` never enter: their routes keep off every segment into
      the zone, and they serve no station inside it.
    * ``same_direction`` (openTCS's "same direction only" block): a two-way aisle, its `nodes`
      listed in order from one end to the other. Several AGVs may be inside at once if they
      all drive it the same way: forward (from the first node listed towards the last) or
      backward; one that wants the other way waits before the aisle's end until no AGV drives
      it the other way. The end nodes are its gates (an AGV passing an end is not inside);
      the aisle's single-track rule gives way to the zone's. `capacity`: the most AGVs inside
      at once (default: no limit but one AGV per node)."""

    id: Text
    kind: TrafficZoneKind
    nodes: Items[Text] = ()
    """same_direction: the aisle's nodes in order, its two ends included."""
    segments: Items[Annotated[tuple[Text, Text], Strict(False)]] = ()
    """[from, to] pairs of the layout's segments (not for same_direction)."""
    capacity: int | None = Field(default=None, ge=1)
    """mutex: the most AGVs inside at once (default 1); same_direction: the same (default:
    no limit)."""
    banned_types: Items[Text] = ()
    """ban: the vehicle types that may not enter."""


EPOCH_TIMESTAMP: Final = "1970-01-01T00:00:00.00Z"
"""The LIF export timestamp when neither the layout nor --timestamp gives one: a fixed value,
so that exporting the same layout twice gives the same bytes."""
LIF_CREATOR: Final = "fleet-sim"
LIF_VEHICLE_TYPE: Final = "fleet-sim"


def is_timestamp(text: str) -> bool:
    """Whether `text` is an ISO 8601 date and time with its time zone (LIF wants UTC: ``Z``)."""
    if not re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?(Z|[+-]\d\d:\d\d)", text):
        return False
    try:
        datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return False
    return True


class LifInfo(StrictModel):
    """How the layout is named in a VDMA LIF file (`fleet-sim layout export --lif`); `fleet-sim
    layout import` writes the values of the file it read, where they differ from these
    defaults, so that a layout exported again keeps them."""

    project: Text | None = None
    """metaInformation.projectIdentification; default: the layout's name."""
    creator: Text = LIF_CREATOR
    """metaInformation.creator."""
    export_timestamp: Text = EPOCH_TIMESTAMP
    """metaInformation.exportTimestamp (ISO 8601, UTC); `--timestamp` overrides it."""
    layout_id: Text | None = None
    """layoutId; default: the layout's name."""
    layout_version: Text = "1"
    level_id: Text | None = None
    """layoutLevelId: the floor or level; default: none."""
    map_id: Text | None = None
    """Every node's mapId; default: the layout id."""
    vehicle_type_id: Text = LIF_VEHICLE_TYPE
    """The vehicleTypeId the nodes and edges are written for (VDMA suggests
    manufacturer.seriesName of the vehicle's VDA 5050 factsheet)."""

    @field_validator("export_timestamp")
    @classmethod
    def _iso_8601(cls, text: str) -> str:
        if not is_timestamp(text):
            raise Problem("", text, "an ISO 8601 date and time in UTC such as "
                                    "2017-04-15T11:40:03.12Z")
        return text


class LayoutSpec(StrictModel):
    """A layout file: the nodes and segments of the track and the places on it."""

    name: Text
    nodes: Items[NodeSpec]
    segments: Items[SegmentSpec]
    stations: Items[StationSpec]
    parking: Items[ParkingSpec]
    chargers: Items[ChargerSpec] = ()
    description: Text = ""
    defaults: LayoutDefaults = LayoutDefaults()
    zones: Items[ZoneSpec] = ()
    lif: LifInfo = LifInfo()
    """Names and ids for LIF export (`fleet-sim layout export --lif`)."""
    traffic_zones: Items[TrafficZoneSpec] = ()
    """Mutex and ban zones enforced by traffic control (`zones` are Wi-Fi and obstacle
    areas)."""


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
        self.traffic_zones = [_traffic_zone(z) for z in spec.traffic_zones]
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
    graph = _build_graph(spec, file, max_speed_mps)
    _check_places(spec, file, graph)
    _check_traffic_zones(spec, file, graph)
    _check_connectivity(spec, file, graph)
    corridors = _find_corridors(graph)
    if any(z.kind == "same_direction" for z in spec.traffic_zones):
        corridors = _check_aisles(spec, file, graph, corridors)
    return Layout(spec, file, graph, corridors)


def _traffic_zone(spec: TrafficZoneSpec) -> TrafficZone:
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
        hops = _traffic_zone(zone).hops
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


def layout_yaml(spec: LayoutSpec, comments: Sequence[str] = ()) -> str:
    """The layout file of `spec`, one line per node, segment and place as the bundled layouts
    are written, `comments` as its first lines; loading it gives `spec` back."""
    lines = [comment_lines(comments).rstrip("\n")] if comments else []
    lines.append(_flow({"name": spec.name}))
    if spec.description:
        lines.append(_flow({"description": spec.description}))
    lines.append(_flow({"defaults": spec.defaults.model_dump(mode="json")}))
    sections: list[tuple[str, list[dict[str, Any]]]] = [
        ("nodes", [{"id": n.id, "x": n.x, "y": n.y, "kind": n.kind}
                   | ({"marker": n.marker} if n.marker is not None else {}) for n in spec.nodes]),
        ("segments", [s.model_dump(mode="json", by_alias=True, exclude_defaults=True)
                      for s in spec.segments]),
        ("stations", [{"id": s.id, "kind": s.kind, "nodes": list(s.nodes),
                       "handling": s.handling.model_dump(mode="json")}
                      | ({"allowed_types": list(s.allowed_types)} if s.allowed_types else {})
                      for s in spec.stations]),
        ("chargers", [c.model_dump(mode="json") for c in spec.chargers]),
        ("parking", [p.model_dump(mode="json") for p in spec.parking]),
        ("zones", [z.model_dump(mode="json", exclude_none=True) for z in spec.zones]),
        ("traffic_zones", [z.model_dump(mode="json", exclude_defaults=True)
                           for z in spec.traffic_zones]),
    ]
    for key, items in sections:
        if items or key in ("nodes", "segments", "stations", "parking"):
            lines.append(f"{key}:" if items else f"{key}: []")
            lines += [f"- {_flow(item)}" for item in items]
    lif = spec.lif.model_dump(mode="json", exclude_defaults=True)
    if lif:
        lines.append(_flow({"lif": lif}))
    return "\n".join(lines) + "\n"


def _flow(data: dict[str, Any]) -> str:
    """One mapping on one line (a top-level key's value in flow style)."""
    if len(data) == 1:
        (key, value), = data.items()
        if not isinstance(value, dict | list):
            return yaml.safe_dump(tidy_numbers(data), sort_keys=False, allow_unicode=True,
                                  width=1 << 30).rstrip("\n")
        return f"{key}: {_flow_value(value)}"
    return _flow_value(data)


def _flow_value(value: Any) -> str:
    text = yaml.safe_dump(tidy_numbers(value), default_flow_style=True, sort_keys=False,
                          allow_unicode=True, width=1 << 30)
    return text.rstrip("\n").removesuffix("\n...").rstrip("\n")

