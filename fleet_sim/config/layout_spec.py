"""The layout file as written: its nodes, segments, places, zones, traffic zones and LIF names,
each checked on its own (`fleet_sim.config.layout` checks them together as a graph). The file
format is described in docs/reference/layout-format.md."""

from __future__ import annotations

import re
from datetime import datetime
from typing import Annotated, Any, Final, Literal, NoReturn

from pydantic import AfterValidator, Field, Strict, field_validator

from fleet_sim.config.distributions import FixedTime, TimeDistribution
from userfiles.checking import Items, NonNegative, Positive, Problem, StrictModel, Text

NodeKind = Literal["tag", "junction", "station", "charger", "parking"]
Branch = Literal["auto", "straight", "left", "right"]

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


def checked_timestamp(text: str) -> str:
    """`text` if it is an ISO 8601 date and time in UTC (`is_timestamp`), else a Problem for
    the field being checked."""
    if not is_timestamp(text):
        raise Problem("", text, "an ISO 8601 date and time in UTC such as "
                                "2017-04-15T11:40:03.12Z")
    return text


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
        return checked_timestamp(text)


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


