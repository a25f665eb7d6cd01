"""The project's own model of VDMA's Layout Interchange Format (LIF) 1.0.0: JSON files in which
integrators hand over track layouts (nodes, edges, stations, per-vehicle-type properties).

Written from the published specification (LIF.md, "Version 1.0.0 - September 2023") and its
JSON schema (``json_schemas/LIF.schema``) in the Intralogistics-2X-LIF/Layout-Interchange-Format
repository; nothing of either is copied here. Field names, types, required fields and ranges are
the format's. `fleet-sim schema lif` publishes this model's JSON Schema.

The choices where the format is silent or disagrees with itself:
docs/background/decisions/config.md. In short: fleet-sim reads what the document or the schema
allows and writes what both require; keys LIF does not name are kept and reported, not refused.
"""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Final, Literal, TypeVar

from pydantic import ConfigDict, Field, Strict, ValidationError, field_validator, model_validator

from fleet_sim.config.distributions import TimeDistribution
from fleet_sim.config.layout_spec import (
    Branch,
    LayoutDefaults,
    Marker,
    NodeKind,
    SpeedLimitsByType,
    TrafficZoneSpec,
    ZoneSpec,
    checked_timestamp,
)
from userfiles.checking import NonNegative, Positive, Problem, StrictModel, validate
from userfiles.reading import read_json

T = TypeVar("T")

LIF_VERSION: Final = "1.0.0"
"""The version fleet-sim writes."""
EXTENSION_KEY: Final = "fleetSim"
"""fleet-sim's extension key on layouts, nodes, edges and stations."""
PlaceKind = Literal["pickup", "dropoff", "charger", "parking"]
"""What a fleet_sim place is, as the station extension's `kind` says it."""
ACTIONS: Final[dict[str, tuple[str, ...]]] = {
    "pickup": ("pick",), "dropoff": ("drop",), "charger": ("startCharging", "stopCharging")}
"""The VDA 5050 actions that say what a place is for (LIF 8.3.13.1)."""

Angle = Annotated[float, Field(ge=-math.pi, le=math.pi)]
"""Radians in [-pi, pi]."""
List = Annotated[tuple[T, ...], Strict(False)]
"""A JSON array (a tuple in the model)."""
NonEmpty = Annotated[tuple[T, ...], Strict(False), Field(min_length=1)]
"""A JSON array the document says must not be empty."""
Knot = Annotated[float, Field(ge=0, le=1)]


class LifModel(StrictModel):
    """Base of the LIF models: strict types and ranges, but keys LIF does not name are kept
    (the format allows extension); the importer reports them as not used."""

    model_config = ConfigDict(extra="allow")


# fleet-sim's extension: what a fleet_sim layout says that LIF cannot (strict, like every file
# fleet-sim writes; its keys are the layout file's).

class LayoutExtension(StrictModel):
    """On a layout: the layout file's defaults, zones and traffic zones."""

    defaults: LayoutDefaults | None = None
    zones: List[ZoneSpec] = ()
    traffic_zones: List[TrafficZoneSpec] = ()


class NodeExtension(StrictModel):
    """On a node: what its kind and RFID marker are, where the stations do not say it."""

    kind: NodeKind | None = None
    marker: Marker | None = None


class EdgeExtension(StrictModel):
    """On an edge: the segment's keys that LIF has no field for. An edge of a two-way segment
    says ``direction: two_way``, and so does its opposite edge."""

    direction: Literal["one_way", "two_way"] = "one_way"
    length_m: Positive | None = None
    speed_limit_mps: Positive | None = None
    """Given when the layout file gives it (maxSpeed holds the limit in either case)."""
    speed_limit_mps_by_type: SpeedLimitsByType | None = None
    """The segment's lower limits for some types, as the layout gives them; each type's
    maxSpeed holds its limit (and wins). Written so that import knows the segment's own limit
    even when every type on the edge has a lower one."""
    branch: Branch = "auto"
    rssi_dbm: float | None = None


class StationExtension(StrictModel):
    """On a station: what kind of place it is in fleet_sim and the figures LIF has no field
    for (handling time; charger power and docking time; parking capacity)."""

    kind: Literal["pickup", "dropoff", "charger", "parking"]
    handling: TimeDistribution | None = None
    power_kw: Positive | None = None
    docking_s: NonNegative | None = None
    capacity: int | None = Field(default=None, ge=1)

    @model_validator(mode="after")
    def _figures_of_its_kind(self) -> StationExtension:
        allowed = {"pickup": {"handling"}, "dropoff": {"handling"},
                   "charger": {"power_kw", "docking_s"}, "parking": {"capacity"}}[self.kind]
        for key in ("handling", "power_kw", "docking_s", "capacity"):
            if key not in allowed and getattr(self, key) is not None:
                raise Problem(key, getattr(self, key),
                              f"no {key} for a {self.kind} (it takes {', '.join(sorted(allowed))})")
        return self


# The format.

class MetaInformation(LifModel):
    projectIdentification: str
    """Human-readable name of the project."""
    creator: str
    exportTimestamp: str
    """ISO 8601 in UTC, e.g. 2017-04-15T11:40:03.12Z."""
    lifVersion: str
    """[Major].[Minor].[Patch]."""

    @field_validator("exportTimestamp")
    @classmethod
    def _iso_8601(cls, text: str) -> str:
        return checked_timestamp(text)

    @field_validator("lifVersion")
    @classmethod
    def _version_one(cls, text: str) -> str:
        found = re.fullmatch(r"(\d+)\.(\d+)\.(\d+)", text)
        if found is None:
            raise Problem("", text, "a version [Major].[Minor].[Patch] such as 1.0.0")
        if int(found.group(1)) > 1:
            raise Problem("", text, "LIF 1.x (LIF 2 is in development; fleet-sim reads and "
                                    "writes LIF 1.0.0)")
        return text


class NodePosition(LifModel):
    x: float
    """Metres from the global origin."""
    y: float
    """Metres from the global origin."""


class ActionParameter(LifModel):
    key: str
    value: str


class Action(LifModel):
    """A VDA 5050 action a master control may add to an order on this node or edge."""

    actionType: str
    actionDescription: str | None = None
    requirementType: Literal["REQUIRED", "CONDITIONAL", "OPTIONAL"] | None = None
    blockingType: Literal["NONE", "SOFT", "HARD"]
    actionParameters: List[ActionParameter] | None = None


class VehicleTypeNodeProperty(LifModel):
    vehicleTypeId: str
    theta: Angle | None = None
    """Radians: orientation of the vehicle on the node."""
    actions: List[Action] | None = None


class Node(LifModel):
    nodeId: str
    nodeName: str | None = None
    nodeDescription: str | None = None
    mapId: str | None = None
    nodePosition: NodePosition
    vehicleTypeNodeProperties: NonEmpty[VehicleTypeNodeProperty]
    fleetSim: NodeExtension | None = None


class LoadRestriction(LifModel):
    unloaded: bool
    loaded: bool
    loadSetNames: List[str] | None = None


class ControlPoint(LifModel):
    x: float
    y: float
    weight: Positive | None = None
    """Default 1.0."""


class Trajectory(LifModel):
    """A NURBS curve from the start node to the end node."""

    degree: Annotated[float, Field(ge=1)] | None = None
    """Default 1; a whole number."""
    knotVector: List[Knot]
    controlPoints: NonEmpty[ControlPoint]

    @model_validator(mode="after")
    def _knots_fit(self) -> Trajectory:
        degree = self.degree if self.degree is not None else 1.0
        if not degree.is_integer():
            raise Problem("degree", degree, "a whole number >= 1")
        expected = len(self.controlPoints) + int(degree) + 1
        if len(self.knotVector) != expected:
            raise Problem("knotVector", list(self.knotVector),
                          f"{expected} knots (len(controlPoints) + degree + 1)")
        for i in range(1, len(self.knotVector)):
            if self.knotVector[i] < self.knotVector[i - 1]:
                raise Problem(f"knotVector[{i}]", self.knotVector[i],
                              f"a knot >= the one before it ({self.knotVector[i - 1]})")
        if self.knotVector[int(degree)] >= self.knotVector[-int(degree) - 1]:
            raise Problem("knotVector", list(self.knotVector),
                          "knots that leave the curve a parameter range of non-zero length")
        return self


class VehicleTypeEdgeProperty(LifModel):
    vehicleTypeId: str
    vehicleOrientation: float | None = None
    """Radians."""
    orientationType: Literal["GLOBAL", "TANGENTIAL"] | None = None
    rotationAllowed: bool
    rotationAtStartNodeAllowed: Literal["NONE", "CCW", "CW", "BOTH"] | None = None
    rotationAtEndNodeAllowed: Literal["NONE", "CCW", "CW", "BOTH"] | None = None
    maxSpeed: Positive | None = None
    """Metres per second; none: no limit."""
    maxRotationSpeed: NonNegative | None = None
    """Radians per second."""
    minHeight: NonNegative | None = None
    maxHeight: NonNegative | None = None
    loadRestriction: LoadRestriction | None = None
    actions: List[Action] | None = None
    trajectory: Trajectory | None = None
    reentryAllowed: bool | None = None


class Edge(LifModel):
    edgeId: str
    edgeName: str | None = None
    edgeDescription: str | None = None
    startNodeId: str
    endNodeId: str
    vehicleTypeEdgeProperties: NonEmpty[VehicleTypeEdgeProperty]
    fleetSim: EdgeExtension | None = None


class StationPosition(LifModel):
    x: float
    y: float
    theta: Angle | None = None


class Station(LifModel):
    stationId: str
    interactionNodeIds: NonEmpty[str]
    stationName: str | None = None
    stationDescription: str | None = None
    stationHeight: NonNegative | None = None
    """Metres."""
    stationPosition: StationPosition | None = None
    """For display only."""
    fleetSim: StationExtension | None = None


class Layout(LifModel):
    layoutId: str
    layoutName: str | None = None
    layoutVersion: str
    layoutLevelId: str | None = None
    layoutDescription: str | None = None
    nodes: List[Node]
    edges: List[Edge]
    stations: List[Station] | None = None
    fleetSim: LayoutExtension | None = None


class LifFile(LifModel):
    """A LIF file: meta information and one or more layouts (levels or parts of a facility)."""

    metaInformation: MetaInformation
    layouts: List[Layout]

    @model_validator(mode="after")
    def _ids_and_references(self) -> LifFile:
        layout_at: dict[str, str] = {}
        node_at: dict[str, str] = {}
        edge_at: dict[str, str] = {}
        station_at: dict[str, str] = {}

        def unique(seen: dict[str, str], key: str, where: str, what: str) -> None:
            if key in seen:
                raise Problem(where, key, f"a {what} unique in the file ({seen[key]} has it)")
            seen[key] = where.rsplit(".", 1)[0]

        for i, layout in enumerate(self.layouts):
            unique(layout_at, layout.layoutId, f"layouts[{i}].layoutId", "layoutId")
            for j, node in enumerate(layout.nodes):
                where = f"layouts[{i}].nodes[{j}]"
                unique(node_at, node.nodeId, f"{where}.nodeId", "nodeId")
                _one_entry_per_type(node.vehicleTypeNodeProperties,
                                    f"{where}.vehicleTypeNodeProperties")
        for i, layout in enumerate(self.layouts):
            own = {node.nodeId for node in layout.nodes}
            for j, edge in enumerate(layout.edges):
                where = f"layouts[{i}].edges[{j}]"
                unique(edge_at, edge.edgeId, f"{where}.edgeId", "edgeId")
                if edge.startNodeId not in own:
                    raise Problem(f"{where}.startNodeId", edge.startNodeId,
                                  f"the nodeId of a node of this layout ({layout.layoutId})")
                if edge.endNodeId not in node_at:
                    raise Problem(f"{where}.endNodeId", edge.endNodeId,
                                  "the nodeId of a node in the file")
                _one_entry_per_type(edge.vehicleTypeEdgeProperties,
                                    f"{where}.vehicleTypeEdgeProperties")
            for j, station in enumerate(layout.stations or ()):
                where = f"layouts[{i}].stations[{j}]"
                unique(station_at, station.stationId, f"{where}.stationId", "stationId")
                for k, node_id in enumerate(station.interactionNodeIds):
                    if node_id not in node_at:
                        raise Problem(f"{where}.interactionNodeIds[{k}]", node_id,
                                      "the nodeId of a node in the file")
        return self


def _one_entry_per_type(entries: Sequence[VehicleTypeNodeProperty | VehicleTypeEdgeProperty],
                        where: str) -> None:
    seen: dict[str, int] = {}
    for k, entry in enumerate(entries):
        if entry.vehicleTypeId in seen:
            raise Problem(f"{where}[{k}].vehicleTypeId", entry.vehicleTypeId,
                          f"one entry per vehicle type ({where}[{seen[entry.vehicleTypeId]}] "
                          "is for it already)")
        seen[entry.vehicleTypeId] = k


@dataclass(frozen=True)
class TextNumber:
    """A number the file writes as a text, read as the number."""

    element: str
    """Its JSON path: ``layouts[0].stations[0].stationHeight``."""
    text: str
    value: float

    @property
    def pattern(self) -> str:
        """The path with [*] for every list index: ``layouts[*].stations[*].stationHeight``."""
        return re.sub(r"\[\d+\]", "[*]", self.element)


def text_number_warnings(file: str, numbers: Sequence[TextNumber]) -> list[str]:
    """One line per kind of element (its first one named, the others counted)."""
    first: dict[str, tuple[TextNumber, int]] = {}
    for number in numbers:
        seen, count = first.get(number.pattern, (number, 0))
        first[number.pattern] = (seen, count + 1)
    return [f"{file}: {n.element}: got {n.text!r}, a number written as a text; read as "
            f"{n.value!r}" + (f" (and {count - 1} more: {pattern})" if count > 1 else "")
            for pattern, (n, count) in first.items()]


_JSON_NUMBER: Final = re.compile(r"-?(?:0|[1-9]\d*)(?:\.\d+)?(?:[eE][+-]?\d+)?")
_MAX_PASSES: Final = 20
"""Validation passes reading text numbers (a pass finds every such number that pydantic reaches;
one inside a model whose other fields were wrong shows on the next)."""


def read_lif(path: Path) -> LifFile:
    """Read and check one LIF file; every problem is one InputError naming the JSON path.
    Numbers written as texts are read silently: `read_lif_noting` tells them."""
    return read_lif_noting(path)[0]


def read_lif_noting(path: Path) -> tuple[LifFile, tuple[TextNumber, ...]]:
    """`read_lif`, and the numbers the file writes as texts (read as numbers)."""
    return lif_from_data(read_json(path), str(path))


def lif_from_data(data: Any, file: str) -> tuple[LifFile, tuple[TextNumber, ...]]:
    """Check parsed JSON as a LIF file: validate; where pydantic finds a text in a number's
    place and the text is a JSON number, put the number there, note it, and validate again."""
    data = copy.deepcopy(data)
    numbers: list[TextNumber] = []
    for _ in range(_MAX_PASSES):
        try:
            return LifFile.model_validate(data), tuple(numbers)
        except ValidationError as exc:
            found = [n for n in map(_text_number, exc.errors()) if n is not None]
            if not found or not all(_put(data, loc, number) for loc, number in found):
                break
            numbers += [number for _, number in found]
    return validate(LifFile, data, file), tuple(numbers)


def _text_number(error: Any) -> tuple[tuple[int | str, ...], TextNumber] | None:
    text = error.get("input")
    if error["type"] not in ("float_type", "int_type") or not isinstance(text, str) \
            or _JSON_NUMBER.fullmatch(text) is None:
        return None
    value = float(text)
    if not math.isfinite(value) or (error["type"] == "int_type" and not value.is_integer()):
        return None
    loc = tuple(error["loc"])
    element = "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in loc).lstrip(".")
    return loc, TextNumber(element, text, value)


def _put(data: Any, loc: tuple[int | str, ...], number: TextNumber) -> bool:
    """Set the number at `loc`, if `loc` is a path in the data (not a union's branch)."""
    *parents, last = loc
    for key in parents:
        in_dict = isinstance(data, dict) and isinstance(key, str) and key in data
        in_list = isinstance(data, list) and isinstance(key, int) and 0 <= key < len(data)
        if not (in_dict or in_list):
            return False
        data = data[key]
    value = int(number.value) if number.text.lstrip("-").isdigit() else number.value
    if isinstance(data, dict) and isinstance(last, str) and data.get(last) == number.text:
        data[last] = value
        return True
    if isinstance(data, list) and isinstance(last, int) and 0 <= last < len(data) \
            and data[last] == number.text:
        data[last] = value
        return True
    return False


def trajectory_length_m(trajectory: Trajectory, chords_per_span: int = 128) -> float:
    """Length of a trajectory's NURBS curve: chord sums with n and 2n chords per knot span,
    extrapolated (Richardson: the chord sum's error falls with the square of the chord), good
    to about 1e-9 of the length on a quarter circle."""
    coarse = _chord_sum(trajectory, chords_per_span)
    fine = _chord_sum(trajectory, 2 * chords_per_span)
    return (4 * fine - coarse) / 3


def _chord_sum(trajectory: Trajectory, chords_per_span: int) -> float:
    degree = int(trajectory.degree or 1)
    knots = trajectory.knotVector
    points = [(p.x, p.y, p.weight if p.weight is not None else 1.0)
              for p in trajectory.controlPoints]
    total = 0.0
    for span in range(degree, len(points)):
        low, high = knots[span], knots[span + 1]
        if high <= low:
            continue
        previous = _nurbs_point(degree, knots, points, span, low)
        for step in range(1, chords_per_span + 1):
            point = _nurbs_point(degree, knots, points, span,
                                 low + (high - low) * step / chords_per_span)
            total += math.hypot(point[0] - previous[0], point[1] - previous[1])
            previous = point
    return total


def _nurbs_point(degree: int, knots: tuple[float, ...], points: list[tuple[float, float, float]],
                 span: int, u: float) -> tuple[float, float]:
    """De Boor's algorithm in homogeneous coordinates, on knot span `span`."""
    d = [(points[j][0] * points[j][2], points[j][1] * points[j][2], points[j][2])
         for j in range(span - degree, span + 1)]
    for r in range(1, degree + 1):
        for j in range(degree, r - 1, -1):
            i = span - degree + j
            denominator = knots[i + degree - r + 1] - knots[i]
            alpha = 0.0 if denominator == 0 else (u - knots[i]) / denominator
            d[j] = tuple((1 - alpha) * a + alpha * b  # type: ignore[assignment]
                         for a, b in zip(d[j - 1], d[j], strict=True))
    x, y, w = d[degree]
    return x / w, y / w

