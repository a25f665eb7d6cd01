"""The project's own model of the VDA 5050 2.1.0 factsheet: the JSON document in which a vehicle
type describes itself "for planning, dimensioning and simulation" (VDA 5050 6.15): speeds,
accelerations, size, load handling, protocol limits and features.

Written from the VDA 5050 2.1.0 document (section 6.15.1) and its JSON schema
(``json_schemas/factsheet.schema`` at tag 2.1.0 of the VDA5050/VDA5050 repository); nothing of
either is copied here. Field names, types and required fields are the format's; `fleet-sim
schema factsheet` publishes this model's JSON Schema. `factsheet_profile` turns a factsheet into
a vehicle profile.

The choices where the format is silent or disagrees with itself:
docs/background/decisions/config.md.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

from pydantic import ConfigDict, Field, Strict, field_validator, model_validator

from fleet_sim.config.layout_spec import is_timestamp
from userfiles.checking import NonNegative, Positive, Problem, StrictModel, validate
from userfiles.reading import read_json

T = TypeVar("T")

List = Annotated[tuple[T, ...], Strict(False)]
UInt32 = Annotated[int, Field(ge=0, le=2**32 - 1)]


class FactsheetModel(StrictModel):
    """Base of the factsheet models: strict types and ranges; keys the format does not name are
    kept and reported as not used."""

    model_config = ConfigDict(extra="allow")


class TypeSpecification(FactsheetModel):
    seriesName: str
    seriesDescription: str | None = None
    agvKinematic: Literal["DIFF", "OMNI", "THREEWHEEL"]
    agvClass: Literal["FORKLIFT", "CONVEYOR", "TUGGER", "CARRIER"]
    maxLoadMass: NonNegative
    """kg."""
    localizationTypes: List[str]
    navigationTypes: List[str]


class PhysicalParameters(FactsheetModel):
    speedMin: NonNegative
    """m/s: the slowest controlled continuous speed."""
    speedMax: Positive
    """m/s."""
    angularSpeedMin: NonNegative | None = None
    """rad/s (in the document, not the schema)."""
    angularSpeedMax: NonNegative | None = None
    """rad/s (in the document, not the schema)."""
    accelerationMax: Positive
    """m/s2, with maximum load."""
    decelerationMax: Positive
    """m/s2, with maximum load."""
    heightMin: NonNegative | None = None
    """m."""
    heightMax: Positive
    """m."""
    width: Positive
    """m."""
    length: Positive
    """m."""

    @model_validator(mode="after")
    def _min_within_max(self) -> PhysicalParameters:
        if self.speedMin > self.speedMax:
            raise Problem("speedMin", self.speedMin, f"at most speedMax ({self.speedMax})")
        return self


class MaxStringLens(FactsheetModel):
    msgLen: UInt32 | None = None
    topicSerialLen: UInt32 | None = None
    topicElemLen: UInt32 | None = None
    idLen: UInt32 | None = None
    idNumericalOnly: bool | None = None
    enumLen: UInt32 | None = None
    loadIdLen: UInt32 | None = None


class MaxArrayLens(FactsheetModel):
    order_nodes: UInt32 | None = Field(default=None, alias="order.nodes")
    order_edges: UInt32 | None = Field(default=None, alias="order.edges")
    node_actions: UInt32 | None = Field(default=None, alias="node.actions")
    edge_actions: UInt32 | None = Field(default=None, alias="edge.actions")
    actions_parameters: UInt32 | None = Field(default=None, alias="actions.actionsParameters")
    instant_actions: UInt32 | None = Field(default=None, alias="instantActions")
    knot_vector: UInt32 | None = Field(default=None, alias="trajectory.knotVector")
    control_points: UInt32 | None = Field(default=None, alias="trajectory.controlPoints")
    node_states: UInt32 | None = Field(default=None, alias="state.nodeStates")
    edge_states: UInt32 | None = Field(default=None, alias="state.edgeStates")
    loads: UInt32 | None = Field(default=None, alias="state.loads")
    action_states: UInt32 | None = Field(default=None, alias="state.actionStates")
    errors: UInt32 | None = Field(default=None, alias="state.errors")
    information: UInt32 | None = Field(default=None, alias="state.information")
    error_references: UInt32 | None = Field(default=None, alias="error.errorReferences")
    info_references: UInt32 | None = Field(default=None, alias="information.infoReferences")


class Timing(FactsheetModel):
    minOrderInterval: NonNegative
    """s."""
    minStateInterval: NonNegative
    """s."""
    defaultStateInterval: NonNegative | None = None
    visualizationInterval: NonNegative | None = None


class ProtocolLimits(FactsheetModel):
    maxStringLens: MaxStringLens
    maxArrayLens: MaxArrayLens
    timing: Timing


class OptionalParameter(FactsheetModel):
    parameter: str
    support: Literal["SUPPORTED", "REQUIRED"]
    description: str | None = None


class ActionParameterSpec(FactsheetModel):
    key: str
    valueDataType: Literal["BOOL", "NUMBER", "INTEGER", "FLOAT", "STRING", "OBJECT", "ARRAY"]
    description: str | None = None
    isOptional: bool | None = None


class AgvAction(FactsheetModel):
    actionType: str
    actionDescription: str | None = None
    actionScopes: List[Literal["INSTANT", "NODE", "EDGE"]]
    actionParameters: List[ActionParameterSpec] | None = None
    resultDescription: str | None = None
    blockingTypes: List[Literal["NONE", "SOFT", "HARD"]] | None = None


class ProtocolFeatures(FactsheetModel):
    optionalParameters: List[OptionalParameter]
    agvActions: List[AgvAction]


class WheelPosition(FactsheetModel):
    x: float
    y: float
    theta: float | None = None


class WheelDefinition(FactsheetModel):
    type: Literal["DRIVE", "CASTER", "FIXED", "MECANUM"]
    isActiveDriven: bool
    isActiveSteered: bool
    position: WheelPosition
    diameter: Positive
    width: Positive
    centerDisplacement: float | None = None
    constraints: str | None = None


class PolygonPoint(FactsheetModel):
    x: float
    y: float


class Envelope2d(FactsheetModel):
    set_name: str = Field(alias="set")
    polygonPoints: List[PolygonPoint]
    description: str | None = None


class Envelope3d(FactsheetModel):
    set_name: str = Field(alias="set")
    format: str
    data: dict[str, Any] | None = None
    url: str | None = None
    description: str | int | None = None
    """Text in the document, an integer in the schema."""


class AgvGeometry(FactsheetModel):
    wheelDefinitions: List[WheelDefinition] | None = None
    envelopes2d: List[Envelope2d] | None = None
    envelopes3d: List[Envelope3d] | None = None


class BoundingBoxReference(FactsheetModel):
    x: float
    y: float
    z: float
    theta: float | None = None


class LoadDimensions(FactsheetModel):
    length: Positive
    width: Positive
    height: Positive | None = None


class LoadSet(FactsheetModel):
    setName: str
    loadType: str
    loadPositions: List[str] | None = None
    boundingBoxReference: BoundingBoxReference | None = None
    loadDimensions: LoadDimensions | None = None
    maxWeight: NonNegative | None = None
    """kg."""
    minLoadhandlingHeight: float | None = None
    maxLoadhandlingHeight: float | None = None
    minLoadhandlingDepth: float | None = None
    maxLoadhandlingDepth: float | None = None
    minLoadhandlingTilt: float | None = None
    maxLoadhandlingTilt: float | None = None
    agvSpeedLimit: Positive | None = None
    """m/s with this load."""
    agvAccelerationLimit: Positive | None = None
    agvDecelerationLimit: Positive | None = None
    pickTime: NonNegative | None = None
    """s, approximately."""
    dropTime: NonNegative | None = None
    """s, approximately."""
    description: str | None = None


class LoadSpecification(FactsheetModel):
    loadPositions: List[str] | None = None
    loadSets: List[LoadSet] | None = None


class VersionInfo(FactsheetModel):
    key: str
    value: str


class Network(FactsheetModel):
    dnsServers: List[str] | None = None
    ntpServers: List[str] | None = None
    localIpAddress: str | None = None
    netmask: str | None = None
    defaultGateway: str | None = None


class VehicleConfig(FactsheetModel):
    versions: List[VersionInfo] | None = None
    network: Network | None = None


class Factsheet(FactsheetModel):
    """A VDA 5050 factsheet: one vehicle type series."""

    headerId: UInt32 | None = None
    timestamp: str | None = None
    """ISO 8601, UTC."""
    version: str
    """The VDA 5050 version, [Major].[Minor].[Patch]."""
    manufacturer: str
    serialNumber: str
    typeSpecification: TypeSpecification
    physicalParameters: PhysicalParameters
    protocolLimits: ProtocolLimits
    protocolFeatures: ProtocolFeatures
    agvGeometry: AgvGeometry
    loadSpecification: LoadSpecification
    vehicleConfig: VehicleConfig | None = None

    @field_validator("timestamp")
    @classmethod
    def _iso_8601(cls, text: str | None) -> str | None:
        if text is not None and not is_timestamp(text):
            raise Problem("", text, "an ISO 8601 date and time in UTC such as "
                                    "2017-04-15T11:40:03.12Z")
        return text

    @field_validator("version")
    @classmethod
    def _version_two(cls, text: str) -> str:
        found = re.fullmatch(r"(\d+)\.(\d+)\.(\d+)", text)
        if found is None:
            raise Problem("", text, "a version [Major].[Minor].[Patch] such as 2.1.0")
        if found.group(1) != "2":
            raise Problem("", text, "a VDA 5050 2.x factsheet (fleet-sim reads 2.1.0's)")
        return text


def read_factsheet(path: Path) -> Factsheet:
    """Read and check one factsheet; every problem is one InputError naming the JSON path."""
    return validate(Factsheet, read_json(path), str(path))
