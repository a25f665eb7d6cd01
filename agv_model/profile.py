"""Vehicle profiles: one YAML file per vehicle type in `agv_model/profiles/`, loaded strictly.

A profile holds a vehicle's kinematics (the document's units: mm, mm/s, mm/s2), its battery (Wh,
W), its protocol name (`agv_model.protocols`) and its link settings (`agv_model.link`). A
profile names its source document by title (`document`, one of `DOCUMENTS`' titles; the
documents are not part of this repository). Each section carries a `source` mapping with one
entry per figure: a citation that starts with the document's tag (`DOCUMENTS`' keys) and names
the section, or text starting with `assumed` that says why. A figure without a source, a source
without a figure, an unknown key, a wrong type or an impossible value is an `InputError` naming
the file, the key, the value and what was expected (`ProfileFile` is the file as written,
`fleet-sim schema profile` its JSON Schema). A profile's name is its file name without `.yaml`.

A profile imported from a VDA 5050 factsheet (`fleet-sim profile import`) names the factsheet as
its document (``VDA 5050 factsheet: <file name>``) and cites it as ``VDA 5050 factsheet, <JSON
path> ...``; the figures a factsheet does not give are its base profile's, cited as ``assumed;
from base profile <name> (...)``.
"""

from __future__ import annotations

import types
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Final

from pydantic import Field, field_validator, model_validator

from agv_model.link import LinkSettings
from agv_model.protocols import names as protocol_names
from userfiles.checking import InputError, NonNegative, Positive, Problem, StrictModel, validate
from userfiles.reading import read_yaml

PROFILE_DIR: Final = Path(__file__).resolve().parent / "profiles"
ASSUMED: Final = "assumed"
DOCUMENTS: Final[Mapping[str, str]] = {
    "RSS-AGV-001": "RSS-AGV-001 core logic and state management, version 1.0.0",
    "CarriRo API v1.4": "CarriRo AD+ External Serial Interface API Reference, version 1.4",
    "KTM-02 commands": "KTM-02 command list, last update 2011-02-08",
    "TABO commands": "TABO robot command sheet",
    "AGV-3 protocol": "Grupp 3 AGV protokoll, revision 1.1",
}
"""The source documents: the tag a citation starts with -> the document's title, which a
profile's `document` names. The documents are not part of this repository; they are cited by
title and section (docs/background/spec-readings.md lists them)."""
FACTSHEET: Final = "VDA 5050 factsheet"
"""The tag of citations of a VDA 5050 factsheet, and of a `document` that is one
(``VDA 5050 factsheet: acme-tug.json``)."""


class Kinematics(StrictModel):
    max_speed_mmps: Positive
    accel_mmps2: Positive
    decel_mmps2: Positive
    turn_speed_mmps: Positive
    """Speed through branch turns and spins."""
    length_mm: Positive

    @model_validator(mode="after")
    def _turn_within_top_speed(self) -> Kinematics:
        if self.turn_speed_mmps > self.max_speed_mmps:
            raise Problem("turn_speed_mmps", self.turn_speed_mmps,
                          f"at most max_speed_mmps ({self.max_speed_mmps})")
        return self


class Battery(StrictModel):
    capacity_wh: Positive
    moving_w: NonNegative
    """Mean power drawn while driving."""
    idle_w: NonNegative
    """Mean power drawn while standing (Idle, Loading, Paused)."""
    charge_w: Positive
    """Power put into the battery while charging."""


def _check_sources(model: StrictModel, source: Mapping[str, str]) -> None:
    """Exactly one citation or `assumed ...` per figure of `model`'s section."""
    figures = tuple(n for n in type(model).model_fields if n != "source")
    for name, text in source.items():
        if name not in figures:
            raise Problem(f"source.{name}", text,
                          f"a figure of this section: {', '.join(figures)}")
        if not (text.startswith(ASSUMED) or any(text.startswith(tag) for tag in DOCUMENTS)
                or text.startswith(FACTSHEET)):
            raise Problem(f"source.{name}", text,
                          f"'{ASSUMED} ...' or a citation starting with one of "
                          f"{', '.join((*DOCUMENTS, FACTSHEET))}")
    for name in figures:
        if name not in source:
            raise Problem(f"source.{name}", None, "a citation or 'assumed ...' for this figure")


Sources = dict[str, str]
"""Figure name -> `assumed ...` or a citation starting with a document's tag."""


class KinematicsSection(Kinematics):
    """`kinematics` as written in a profile file: the figures and their sources."""

    source: Sources

    @model_validator(mode="after")
    def _sourced(self) -> KinematicsSection:
        _check_sources(self, self.source)
        return self


class BatterySection(Battery):
    """`battery` as written in a profile file: the figures and their sources."""

    source: Sources

    @model_validator(mode="after")
    def _sourced(self) -> BatterySection:
        _check_sources(self, self.source)
        return self


class LinkSection(LinkSettings):
    """`link` as written in a profile file: the settings and their sources."""

    source: Sources

    @model_validator(mode="after")
    def _sourced(self) -> LinkSection:
        _check_sources(self, self.source)
        return self


class ProfileFile(StrictModel):
    """A vehicle profile file (`agv_model/profiles/<name>.yaml`)."""

    title: Annotated[str, Field(min_length=1)]
    document: Annotated[str, Field(description=(
        "Which source document the vehicle comes from, by title: "
        + "; ".join(f"'{title}'" for title in DOCUMENTS.values())
        + f"; or '{FACTSHEET}: <file name>' for a profile imported from a factsheet."))]
    protocol: str | None
    """The wire protocol (agv_model.protocols); null: the document defines none."""
    kinematics: KinematicsSection
    battery: BatterySection
    link: LinkSection

    @field_validator("document")
    @classmethod
    def _known_document(cls, document: str) -> str:
        if document not in DOCUMENTS.values() and not (
                document.startswith(f"{FACTSHEET}: ") and len(document) > len(FACTSHEET) + 2):
            titles = ", ".join(repr(title) for title in DOCUMENTS.values())
            raise Problem("", document, f"a source document's title, one of {titles}; or "
                                        f"'{FACTSHEET}: <file name>'")
        return document

    @field_validator("protocol")
    @classmethod
    def _known_protocol(cls, protocol: str | None) -> str | None:
        if protocol is not None and protocol not in protocol_names():
            raise Problem("", protocol, f"null or one of {', '.join(protocol_names())}")
        return protocol


@dataclass(frozen=True)
class Profile:
    """A loaded profile: its figures, in plain models, and their sources by dotted key."""

    name: str
    title: str
    document: str
    protocol: str | None
    """None: the document defines no wire protocol (the generic RSS-AGV-001 vehicle)."""
    kinematics: Kinematics
    battery: Battery
    link: LinkSettings
    sources: Mapping[str, str]
    """Citation or `assumed ...` for every figure, by dotted key (`kinematics.length_mm`)."""


def parse_profile(name: str, data: object, file: str) -> Profile:
    """Build a profile from parsed YAML; `file` names it in errors."""
    written = validate(ProfileFile, data, file)
    sources = {f"{key}.{figure}": text
               for key, section in (("kinematics", written.kinematics),
                                    ("battery", written.battery), ("link", written.link))
               for figure, text in section.source.items()}
    return Profile(name, written.title, written.document, written.protocol,
                   Kinematics.model_validate(written.kinematics.model_dump(exclude={"source"})),
                   Battery.model_validate(written.battery.model_dump(exclude={"source"})),
                   LinkSettings.model_validate(written.link.model_dump(exclude={"source"})),
                   types.MappingProxyType(sources))


def read_profile(path: Path) -> Profile:
    """Load one profile file."""
    return parse_profile(path.stem, read_yaml(path), str(path))


def profile_names() -> tuple[str, ...]:
    """Names of the bundled profiles."""
    return tuple(sorted(p.stem for p in PROFILE_DIR.glob("*.yaml")))


def load_profile(name: str) -> Profile:
    """A bundled profile by name."""
    if name not in profile_names():
        raise InputError(str(PROFILE_DIR), "profile", name,
                           f"one of {', '.join(profile_names())}")
    return read_profile(PROFILE_DIR / f"{name}.yaml")


def load_profiles() -> dict[str, Profile]:
    return {name: load_profile(name) for name in profile_names()}


def profile_for(protocol: str) -> Profile:
    """The bundled profile of the vehicle that speaks `protocol`."""
    for profile in load_profiles().values():
        if profile.protocol == protocol:
            return profile
    raise InputError(str(PROFILE_DIR), "protocol", protocol,
                       f"a protocol of a bundled profile, one of {', '.join(protocol_names())}")
