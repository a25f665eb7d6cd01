"""The fleet of a scenario (`fleet:`): how many AGVs of which vehicle, a mixed fleet's types
(each may take its figures from an agv_model profile), where they start, and what their
commands go over."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Final, Literal, NamedTuple

from pydantic import Field, PrivateAttr, ValidationInfo, field_validator, model_validator
from pydantic.config import JsonDict

from agv_model.link import LinkSettings
from agv_model.profile import Profile as AgvModelProfile
from agv_model.profile import load_profile, profile_names, read_profile
from fleet_sim.config.vehicle import VehicleProfile, vehicle_from_profile
from fleet_sim.errors import InputError
from userfiles.checking import Items, NonNegative, Problem, StrictModel, Text

MAX_FLEET_SIZE: Final = 2_000
"""Largest fleet: ten times the largest AGV fleets in service; beyond it a run takes hours."""

VEHICLE_TYPES: Final = "fleet.vehicles"
"""Where a mixed fleet's types are; an override enters one by its name:
``fleet.vehicles.<type>.count``."""


def type_count_path(vehicle_type: str) -> str:
    """The dotted path (override, factor) of a mixed fleet's count of `vehicle_type`."""
    return f"{VEHICLE_TYPES}.{vehicle_type}.count"


class CommandLink(NamedTuple):
    """What an AGV's commands go over: the protocol and link of an agv_model profile."""

    profile: str
    protocol: str | None
    """None: the generic RSS-AGV-001 vehicle, whose messages have no stated bytes."""
    link: LinkSettings


def _command_link(name: str, profile: AgvModelProfile) -> CommandLink:
    return CommandLink(name, profile.protocol, profile.link)


class VehicleType(StrictModel):
    """One type of a mixed fleet (`fleet.vehicles`): `count` AGVs of one vehicle profile."""

    type: Text
    """The type's name, as the layout's `allowed_types` and the KPIs (by_type.<type>) say it."""
    count: int = Field(ge=1, le=MAX_FLEET_SIZE)
    profile: Text | None = None
    """An agv_model vehicle profile that fills `vehicle` (fleet_sim.config.vehicle
    .vehicle_from_profile): a bundled one (rss-agv-001, carriro-ad-plus, ktm-02, tabo, agv-3)
    or a profile file, such as one `fleet-sim profile import` wrote from a VDA 5050
    factsheet, relative to the scenario file. Fields given under `vehicle` win over it."""
    vehicle: VehicleProfile = VehicleProfile()
    """The type's kinematics, body, station times and battery (as `fleet.vehicle`)."""
    _command_link: CommandLink | None = PrivateAttr(default=None)
    """The protocol and link of `profile` (none without one); not a key of the file."""

    @property
    def command_link(self) -> CommandLink | None:
        """The protocol and link the type's profile names; None without a profile."""
        return self._command_link

    @model_validator(mode="after")
    def _link_of_profile(self, info: ValidationInfo) -> VehicleType:
        if self.profile is not None:
            base_dir = (info.context or {}).get("base_dir", ".")
            self._command_link = _command_link(self.profile,
                                               _read_agv_profile(self.profile, base_dir))
        return self

    @model_validator(mode="before")
    @classmethod
    def _from_profile(cls, data: Any, info: ValidationInfo) -> Any:
        if not isinstance(data, dict) or not isinstance(data.get("profile"), str):
            return data
        given = data.get("vehicle", {})
        if not isinstance(given, dict):
            return data  # not a mapping: the field's own check names it
        base_dir = (info.context or {}).get("base_dir", ".")
        return {**data, "vehicle": _deep_merge(_profile_fields(data["profile"], base_dir),
                                               given)}


def _profile_fields(name: str, base_dir: str) -> dict[str, Any]:
    """The vehicle fields of profile `name` (bundled, or a file relative to `base_dir`)."""
    return vehicle_from_profile(_read_agv_profile(name, base_dir))


def _read_agv_profile(name: str, base_dir: str) -> AgvModelProfile:
    """Profile `name`: a bundled one, or a file relative to `base_dir`."""
    try:
        if name in profile_names():
            profile = load_profile(name)
        else:
            path = Path(name) if Path(name).is_absolute() else Path(base_dir) / name
            if path.suffix not in (".yaml", ".yml") or not path.is_file():
                raise Problem("profile", name,
                              f"a bundled profile ({', '.join(profile_names())}) or a profile "
                              f"file (.yaml; looked for {path})")
            profile = read_profile(path)
    except InputError as exc:
        raise Problem("profile", name, f"a valid profile file ({exc})") from None
    return profile


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def _off_schema(schema: JsonDict) -> None:
    """Publish ``false`` (YAML ``off``) beside the switch's words."""
    words = schema.pop("enum", None)
    schema.pop("type", None)
    schema["anyOf"] = [{"enum": words, "type": "string"}, {"const": False}]


class FleetConfig(StrictModel):
    size: int = Field(default=4, ge=1, le=MAX_FLEET_SIZE)
    """Number of AGVs; with `vehicles`, the sum of their counts (may be left out)."""
    vehicle: VehicleProfile = VehicleProfile()
    """The vehicle of a one-type fleet; not given with `vehicles`."""
    vehicles: Items[VehicleType] = ()
    """A mixed fleet: types of vehicle and how many of each (AGVs numbered type by type, in
    this order); empty: `size` AGVs of `vehicle`."""
    start_nodes: Items[Text] = ()
    """Where AGVs start, one node each; empty: inside the parking areas, filled in file order."""
    command_timing: Literal["auto", "off"] = Field(default="auto",
                                                   json_schema_extra=_off_schema)
    """auto: the fleet manager's commands to an AGV, its boot report and (granted hop by hop,
    `traffic.grants`) its route permissions take the time its type's profile's protocol and
    link take to carry them, for every type of `vehicles` that names a profile with a
    protocol (fleet_sim.sim.commands); other AGVs' take none. off (false): none take time."""
    command_profile: Text | None = None
    """A one-type fleet: the agv_model vehicle profile whose protocol and link carry every
    command (rss-agv-001, carriro-ad-plus, ktm-02, tabo, agv-3); none: commands take no time.
    A mixed fleet's types name their own (`vehicles[].profile`)."""
    status_poll_s: NonNegative = 0.0
    """The fleet manager polls each AGV this often and learns it is free at the next poll;
    0: AGVs report at once."""

    @field_validator("command_timing", mode="before")
    @classmethod
    def _timing_off(cls, value: Any) -> Any:
        """YAML reads `off` as false."""
        return "off" if value is False else value

    @model_validator(mode="before")
    @classmethod
    def _size_of_mix(cls, data: Any) -> Any:
        """With `vehicles`, `size` is the sum of the counts, and `vehicle` is each type's."""
        if not isinstance(data, dict) or not data.get("vehicles"):
            return data
        if "vehicle" in data:
            raise Problem("vehicle", "given", "no fleet.vehicle with fleet.vehicles (each type "
                                              "has its own vehicle or profile)")
        types = data["vehicles"]
        counts = [t.get("count") for t in types if isinstance(t, dict)] \
            if isinstance(types, list | tuple) else []
        if "size" not in data and counts and len(counts) == len(types) \
                and all(type(c) is int and c >= 1 for c in counts):
            return {**data, "size": sum(counts)}
        return data

    @property
    def agv_types(self) -> tuple[str, ...]:
        """The type of each AGV, in AGV order (one-type fleet: the vehicle's name)."""
        if not self.vehicles:
            return (self.vehicle.name,) * self.size
        return tuple(t.type for t in self.vehicles for _ in range(t.count))

    @property
    def agv_profiles(self) -> tuple[VehicleProfile, ...]:
        """The vehicle profile of each AGV, in AGV order."""
        if not self.vehicles:
            return (self.vehicle,) * self.size
        return tuple(t.vehicle for t in self.vehicles for _ in range(t.count))

    @property
    def type_profiles(self) -> dict[str, VehicleProfile]:
        """Type name -> its vehicle profile, in fleet order."""
        if not self.vehicles:
            return {self.vehicle.name: self.vehicle}
        return {t.type: t.vehicle for t in self.vehicles}

    @property
    def agv_command_links(self) -> tuple[CommandLink | None, ...]:
        """What each AGV's commands go over, in AGV order; None: they take no time.
        `command_profile`: its link for every AGV. Else, `command_timing: auto`: each type's
        profile's, if the profile has a protocol (the generic RSS-AGV-001 profile has none:
        its messages have no stated bytes, so they are timed only when named by
        command_profile)."""
        if self.command_profile is not None:
            name = self.command_profile
            return (_command_link(name, load_profile(name)),) * self.size
        if self.command_timing == "off" or not self.vehicles:
            return (None,) * self.size
        links = [t.command_link if t.command_link is not None
                 and t.command_link.protocol is not None else None for t in self.vehicles]
        return tuple(link for t, link in zip(self.vehicles, links, strict=True)
                     for _ in range(t.count))

    @property
    def max_speed_mps(self) -> float:
        """The fastest type's top speed (segment limits above it are refused)."""
        return max(p.max_speed_mps for p in self.type_profiles.values())

    @model_validator(mode="after")
    def _consistent(self) -> FleetConfig:
        if self.vehicles:
            total = sum(t.count for t in self.vehicles)
            if self.size != total:
                raise Problem("size", self.size, f"the sum of fleet.vehicles' counts ({total}); "
                              "leave fleet.size out with fleet.vehicles (to vary one type's "
                              "count: fleet.vehicles.<type>.count, e.g. "
                              f"{type_count_path(self.vehicles[-1].type)})")
            names = [t.type for t in self.vehicles]
            for i, name in enumerate(names):
                if name in names[:i]:
                    raise Problem(f"vehicles[{i}].type", name, "a type named once")
        if self.start_nodes and len(self.start_nodes) < self.size:
            raise Problem("start_nodes", list(self.start_nodes),
                          f"at least one start node per AGV ({self.size})")
        if self.command_profile is not None and self.command_profile not in profile_names():
            raise Problem("command_profile", self.command_profile,
                          f"one of {', '.join(profile_names())}")
        if self.command_profile is not None and self.vehicles:
            raise Problem("command_profile", self.command_profile,
                          "no command_profile with fleet.vehicles: each type's commands go "
                          "over its own profile's protocol and link (fleet.vehicles[].profile;"
                          " fleet.command_timing: off for commands that take no time)")
        if self.command_profile is not None and self.command_timing == "off":
            raise Problem("command_timing", "off",
                          "auto with fleet.command_profile (which times every command on its "
                          "link); leave command_profile out for commands that take no time")
        if len(set(self.start_nodes)) != len(self.start_nodes):
            raise Problem("start_nodes", list(self.start_nodes),
                          "distinct nodes (one AGV per node)")
        return self
