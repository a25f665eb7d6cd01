"""A vehicle profile from a VDA 5050 factsheet (`fleet-sim profile import`).

The profile is written as every profile is (`agv_model.profile.ProfileFile`: figures in mm,
mm/s, mm/s2, Wh, W, each with its source), so it loads and checks like a bundled one.

The figures come from the factsheet where it has them (top speed, acceleration, deceleration,
length) and from a base profile where not; what is taken from where, and why:
docs/background/decisions/config.md.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import yaml
from pydantic import BaseModel

from agv_model.profile import ASSUMED, FACTSHEET, PROFILE_DIR, ProfileFile, profile_names
from fleet_sim.config.standards.factsheet import Factsheet, FactsheetModel, read_factsheet
from fleet_sim.config.vehicle import mm
from fleet_sim.errors import InputError
from userfiles.checking import validate
from userfiles.reading import read_yaml
from userfiles.writing import comment_lines, tidy_numbers

DEFAULT_BASE: Final = "rss-agv-001"

_NOT_USED: Final[dict[str, str]] = {
    "typeSpecification.seriesDescription": "free text (the title names the series)",
    "typeSpecification.agvKinematic": "fleet_sim drives along the track; the kinematics type "
                                      "does not change the timing model",
    "typeSpecification.agvClass": "fleet_sim does not model the kind of load handling",
    "typeSpecification.maxLoadMass": "fleet_sim does not model load mass",
    "typeSpecification.localizationTypes": "fleet_sim does not model localisation",
    "typeSpecification.navigationTypes": "fleet_sim's AGVs follow the layout's segments",
    "physicalParameters.speedMin": "fleet_sim has no minimum speed",
    "physicalParameters.angularSpeedMin": "fleet_sim does not model rotation on the spot",
    "physicalParameters.angularSpeedMax": "fleet_sim does not model rotation on the spot "
                                          "(a spin takes the scenario's spin_s)",
    "physicalParameters.heightMin": "fleet_sim does not model heights",
    "physicalParameters.heightMax": "fleet_sim does not model heights",
    "physicalParameters.width": "fleet_sim models an AGV by its length on the track",
    "protocolLimits": "VDA 5050 message limits; fleet_sim does not exchange VDA 5050 messages",
    "protocolFeatures": "VDA 5050 actions and optional parameters; not simulated",
    "agvGeometry": "wheels and envelopes; fleet_sim models an AGV by its length",
    "loadSpecification.loadPositions": "fleet_sim does not model load handling devices",
    "vehicleConfig": "software versions and network settings",
}
_LOAD_SET: Final[dict[str, str]] = {
    "pickTime": "a station's handling time in fleet_sim: put it in the layout "
                "(stations[].handling)",
    "dropTime": "a station's handling time in fleet_sim: put it in the layout "
                "(stations[].handling)",
    "agvSpeedLimit": "fleet_sim drives loaded and empty at the same top speed",
    "agvAccelerationLimit": "fleet_sim drives loaded and empty with the same acceleration",
    "agvDecelerationLimit": "fleet_sim drives loaded and empty with the same deceleration",
}


@dataclass(frozen=True)
class ImportedProfile:
    """A profile made from a factsheet: the file's data, its first comment lines and what of
    the factsheet it does not use."""

    data: dict[str, Any]
    title: str
    base: str
    not_used: tuple[str, ...]
    """``<JSON path> = <value>: <reason>``, one per line."""
    comments: tuple[str, ...]

    def text(self) -> str:
        """The profile file."""
        head = comment_lines(self.comments)
        body = yaml.safe_dump(tidy_numbers(self.data), sort_keys=False, allow_unicode=True,
                              width=100, default_flow_style=False)
        return head + body


def import_factsheet(path: Path, base: str = DEFAULT_BASE) -> ImportedProfile:
    """Read a factsheet and make a profile of it on the figures of `base` (a bundled profile's
    name or a profile file)."""
    return factsheet_to_profile(read_factsheet(path), path.name, base, str(path))


def factsheet_to_profile(sheet: Factsheet, file_name: str, base: str = DEFAULT_BASE,
                         file: str | None = None) -> ImportedProfile:
    base_file, base_name = _base_file(base)
    written = validate(ProfileFile, read_yaml(base_file), str(base_file))
    physical = sheet.physicalParameters
    speed_mmps = mm(physical.speedMax)
    turn_mmps = min(written.kinematics.turn_speed_mmps, speed_mmps)
    turn_source = _from_base(base_name, written.kinematics.source["turn_speed_mmps"])
    if turn_mmps < written.kinematics.turn_speed_mmps:
        turn_source = (f"{ASSUMED}; base profile {base_name}'s turn speed "
                       f"{written.kinematics.turn_speed_mmps:g} mm/s capped at "
                       "physicalParameters.speedMax")
    kinematics = {
        "max_speed_mmps": speed_mmps,
        "accel_mmps2": mm(physical.accelerationMax),
        "decel_mmps2": mm(physical.decelerationMax),
        "turn_speed_mmps": turn_mmps,
        "length_mm": mm(physical.length),
        "source": {
            "max_speed_mmps": _cite("physicalParameters.speedMax", physical.speedMax, "m/s"),
            "accel_mmps2": _cite("physicalParameters.accelerationMax", physical.accelerationMax,
                                 "m/s2, with maximum load"),
            "decel_mmps2": _cite("physicalParameters.decelerationMax", physical.decelerationMax,
                                 "m/s2, with maximum load"),
            "turn_speed_mmps": turn_source,
            "length_mm": _cite("physicalParameters.length", physical.length, "m"),
        },
    }
    sections = {}
    for key in ("battery", "link"):
        section = getattr(written, key)
        dumped = section.model_dump(mode="json", exclude={"source"})
        if key == "link":
            dumped["jitter"] = section.jitter.model_dump(mode="json", exclude_defaults=True)
        dumped["source"] = {figure: _from_base(base_name, text)
                            for figure, text in section.source.items()}
        sections[key] = dumped
    series = sheet.typeSpecification.seriesName
    title = f"{series} ({sheet.manufacturer})"
    data = {"title": title, "document": f"{FACTSHEET}: {file_name}", "protocol": None,
            "kinematics": kinematics, **sections}
    validate(ProfileFile, data, file or file_name)  # what is written loads as a profile
    not_used = tuple(_not_used(sheet))
    comments = (
        f"Imported by `fleet-sim profile import` from {file_name}: VDA 5050 {sheet.version} "
        f"factsheet of {series} by {sheet.manufacturer} (serial number "
        f"{sheet.serialNumber}).",
        f"From the factsheet: max_speed_mmps, accel_mmps2, decel_mmps2, length_mm. From base "
        f"profile {base_name} (assumed for this vehicle): turn_speed_mmps, battery, link.",
        "protocol null: VDA 5050 is JSON over MQTT, not a protocol agv_model speaks; the base "
        "link stands for the radio hop.",
        *(("Not used (no place in a fleet_sim profile):",
           *(f"  - {line}" for line in not_used)) if not_used else ()),
    )
    return ImportedProfile(data, title, base_name, not_used, comments)


def _base_file(base: str) -> tuple[Path, str]:
    if base in profile_names():
        return PROFILE_DIR / f"{base}.yaml", base
    path = Path(base)
    if path.suffix in (".yaml", ".yml") and path.is_file():
        return path, path.stem
    raise InputError("--base", "base", base, "the name of a bundled profile ("
                     f"{', '.join(profile_names())}) or a profile file (.yaml)")


def _cite(path: str, value: float, unit: str) -> str:
    return f"{FACTSHEET}, {path} {value:g} {unit}"


def _from_base(base: str, source: str) -> str:
    return f"{ASSUMED}; from base profile {base} ({source})"


def _not_used(sheet: Factsheet) -> Iterator[str]:
    for path, why in _NOT_USED.items():
        value = _at(sheet, path)
        if value is not None:
            yield f"{path} = {_show(value)}: {why}"
    for i, load_set in enumerate(sheet.loadSpecification.loadSets or ()):
        where = f"loadSpecification.loadSets[{i}]"
        for key, why in _LOAD_SET.items():
            value = getattr(load_set, key)
            if value is not None:
                yield f"{where}.{key} = {value:g}: {why}"
        rest = [k for k in type(load_set).model_fields
                if k not in _LOAD_SET and getattr(load_set, k) is not None]
        if rest:
            yield (f"{where} ({load_set.setName}, {load_set.loadType}): "
                   f"{', '.join(rest)}: fleet_sim does not model load handling")
    for path in _extra_keys(sheet, ""):
        yield f"{path}: not a VDA 5050 2.1.0 factsheet key"


def _at(model: BaseModel, dotted: str) -> Any:
    value: Any = model
    for key in dotted.split("."):
        value = getattr(value, key, None)
        if value is None:
            return None
    return value


def _show(value: Any) -> str:
    if isinstance(value, BaseModel):
        return "{...}"
    if isinstance(value, tuple):
        return "[" + ", ".join(str(v) for v in value) + "]" if all(
            isinstance(v, str) for v in value) else f"[{len(value)} items]"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _extra_keys(model: BaseModel, path: str) -> Iterator[str]:
    for key in model.model_extra or {}:
        yield f"{path}.{key}" if path else key
    for name, info in type(model).model_fields.items():
        value = getattr(model, name)
        here = f"{path}.{info.alias or name}" if path else (info.alias or name)
        if isinstance(value, FactsheetModel):
            yield from _extra_keys(value, here)
        elif isinstance(value, tuple):
            for i, item in enumerate(value):
                if isinstance(item, FactsheetModel):
                    yield from _extra_keys(item, f"{here}[{i}]")

