"""Vehicle profiles: one YAML file per vehicle type in `agv_model/profiles/`, loaded strictly.

A profile holds a vehicle's kinematics (the document's units: mm, mm/s, mm/s2), its battery
(Wh, W), its protocol name (`agv_model.protocols`) and its link settings (`agv_model.link`).
Each section carries a `source` mapping with one entry per figure: a citation that starts with
the document's tag (`DOCUMENTS`) and names the section, or text starting with `assumed` that
says why. A figure without a source, a source without a figure, an unknown key, a wrong type or
an impossible value is a `ProfileError` naming the file, the key, the value and what was
expected. A profile's name is its file name without `.yaml`.
"""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import yaml

from agv_model.link import Jitter, LinkSettings, LinkSettingsError
from agv_model.protocols import names as protocol_names

PROFILE_DIR: Final = Path(__file__).resolve().parent / "profiles"
ASSUMED: Final = "assumed"
DOCUMENTS: Final[Mapping[str, str]] = {
    "RSS-AGV-001": "rss-agv-001-core-logic.ja.md",
    "CarriRo API v1.4": "carriro-ad-plus-serial-api-v1.4.ja.md",
    "KTM-02 commands": "ktm-02-commands.ja.md",
    "TABO commands": "tabo-commands.ja.tsv",
    "AGV-3 protocol": "agv-3-protocol.sv.md",
}


class ProfileError(ValueError):
    """A profile file holds something the loader cannot use."""

    def __init__(self, file: str, key: str, value: object, expected: str) -> None:
        self.file = file
        self.key = key
        self.value = value
        self.expected = expected
        super().__init__(f"{file}: {key}: got {value!r}; expected {expected}")


@dataclass(frozen=True)
class Kinematics:
    max_speed_mmps: float
    accel_mmps2: float
    decel_mmps2: float
    turn_speed_mmps: float
    """Speed through branch turns and spins."""
    length_mm: float

    @property
    def max_speed_mps(self) -> float:
        return self.max_speed_mmps / 1000

    @property
    def accel_mps2(self) -> float:
        return self.accel_mmps2 / 1000

    @property
    def decel_mps2(self) -> float:
        return self.decel_mmps2 / 1000

    @property
    def turn_speed_mps(self) -> float:
        return self.turn_speed_mmps / 1000

    @property
    def length_m(self) -> float:
        return self.length_mm / 1000


@dataclass(frozen=True)
class Battery:
    capacity_wh: float
    moving_w: float
    """Mean power drawn while driving."""
    idle_w: float
    """Mean power drawn while standing (Idle, Loading, Paused)."""
    charge_w: float
    """Power put into the battery while charging."""


@dataclass(frozen=True)
class Profile:
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


_POSITIVE: Final = {"max_speed_mmps", "accel_mmps2", "decel_mmps2", "turn_speed_mmps",
                    "length_mm", "capacity_wh", "charge_w"}
_TOP_KEYS: Final = ("title", "document", "protocol", "kinematics", "battery", "link")


def _mapping(file: str, key: str, value: object) -> dict[str, Any]:
    if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
        raise ProfileError(file, key, value, "a mapping with text keys")
    return value


def _unknown(file: str, key: str, data: Mapping[str, Any], allowed: tuple[str, ...]) -> None:
    for name, value in data.items():
        if name not in allowed:
            raise ProfileError(file, f"{key}.{name}" if key else name, value,
                               f"one of the keys {', '.join(allowed)}")
    for name in allowed:
        if name not in data:
            raise ProfileError(file, f"{key}.{name}" if key else name, None,
                               "a value (the key is missing)")


def _number(file: str, key: str, value: object, *, whole: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ProfileError(file, key, value, "a whole number" if whole else "a number")
    if whole and not isinstance(value, int):
        raise ProfileError(file, key, value, "a whole number")
    return value


def _sources(file: str, key: str, data: Mapping[str, Any],
             figures: tuple[str, ...]) -> dict[str, str]:
    """Check a section's `source` mapping: exactly one citation or `assumed` per figure."""
    source = _mapping(file, f"{key}.source", data.get("source"))
    for name, text in source.items():
        if name not in figures:
            raise ProfileError(file, f"{key}.source.{name}", text,
                               f"a figure of {key}: {', '.join(figures)}")
        cites = isinstance(text, str) and any(text.startswith(tag) for tag in DOCUMENTS)
        if not cites and not (isinstance(text, str) and text.startswith(ASSUMED)):
            raise ProfileError(file, f"{key}.source.{name}", text,
                               f"'{ASSUMED} ...' or a citation starting with one of "
                               f"{', '.join(DOCUMENTS)}")
    for name in figures:
        if name not in source:
            raise ProfileError(file, f"{key}.source.{name}", None,
                               "a citation or 'assumed ...' for this figure")
    return {f"{key}.{name}": text for name, text in source.items()}


def _figures(file: str, key: str, data: Mapping[str, Any], cls: type[Any]) -> dict[str, float]:
    fields = tuple(f.name for f in dataclasses.fields(cls))
    _unknown(file, key, data, (*fields, "source"))
    values: dict[str, float] = {}
    for name in fields:
        value = _number(file, f"{key}.{name}", data[name])
        if value < 0 or (name in _POSITIVE and value == 0):
            raise ProfileError(file, f"{key}.{name}", value,
                               "a number > 0" if name in _POSITIVE else "a number >= 0")
        values[name] = float(value)
    return values


def _kinematics(file: str, data: Mapping[str, Any]) -> Kinematics:
    kinematics = Kinematics(**_figures(file, "kinematics", data, Kinematics))
    if kinematics.turn_speed_mmps > kinematics.max_speed_mmps:
        raise ProfileError(file, "kinematics.turn_speed_mmps", kinematics.turn_speed_mmps,
                           f"at most max_speed_mmps ({kinematics.max_speed_mmps})")
    return kinematics


_LINK_KEYS: Final = tuple(f.name for f in dataclasses.fields(LinkSettings))
_JITTER_KEYS: Final = tuple(f.name for f in dataclasses.fields(Jitter))


def _link(file: str, data: Mapping[str, Any]) -> LinkSettings:
    _unknown(file, "link", data, (*_LINK_KEYS, "source"))
    jitter = _mapping(file, "link.jitter", data["jitter"])
    for name, value in jitter.items():
        if name not in _JITTER_KEYS:
            raise ProfileError(file, f"link.jitter.{name}", value,
                               f"one of the keys {', '.join(_JITTER_KEYS)}")
    settings = {k: data[k] for k in _LINK_KEYS if k != "jitter"}
    try:
        return LinkSettings(**settings, jitter=Jitter(**jitter))
    except LinkSettingsError as exc:
        where = "link.jitter" if exc.setting in _JITTER_KEYS else "link"
        raise ProfileError(file, f"{where}.{exc.setting}", exc.value, exc.expected) from None


def parse_profile(name: str, data: object, file: str) -> Profile:
    """Build a profile from parsed YAML; `file` names it in errors."""
    top = _mapping(file, "profile", data)
    _unknown(file, "", top, _TOP_KEYS)
    for key in ("title", "document"):
        if not isinstance(top[key], str) or not top[key]:
            raise ProfileError(file, key, top[key], "a non-empty text")
    protocol = top["protocol"]
    if protocol is not None and protocol not in protocol_names():
        raise ProfileError(file, "protocol", protocol,
                           f"null or one of {', '.join(protocol_names())}")
    if top["document"] not in DOCUMENTS.values():
        raise ProfileError(file, "document", top["document"],
                           f"one of {', '.join(DOCUMENTS.values())}")
    sections = {key: _mapping(file, key, top[key]) for key in ("kinematics", "battery", "link")}
    kinematics = _kinematics(file, sections["kinematics"])
    battery = Battery(**_figures(file, "battery", sections["battery"], Battery))
    link = _link(file, sections["link"])
    sources: dict[str, str] = {}
    for key, section in sections.items():
        figures = _LINK_KEYS if key == "link" else tuple(
            f.name for f in dataclasses.fields(Kinematics if key == "kinematics" else Battery))
        sources.update(_sources(file, key, section, figures))
    return Profile(name, top["title"], top["document"], protocol, kinematics, battery, link,
                   types.MappingProxyType(sources))


def read_profile(path: Path) -> Profile:
    """Load one profile file."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ProfileError(str(path), "file", str(path),
                           f"a readable profile file ({exc.strerror})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ProfileError(str(path), "file", type(exc).__name__, f"valid YAML: {exc}") from None
    return parse_profile(path.stem, data, str(path))


def profile_names() -> tuple[str, ...]:
    """Names of the bundled profiles."""
    return tuple(sorted(p.stem for p in PROFILE_DIR.glob("*.yaml")))


def load_profile(name: str) -> Profile:
    """A bundled profile by name."""
    if name not in profile_names():
        raise ProfileError(str(PROFILE_DIR), "profile", name,
                           f"one of {', '.join(profile_names())}")
    return read_profile(PROFILE_DIR / f"{name}.yaml")


def load_profiles() -> dict[str, Profile]:
    return {name: load_profile(name) for name in profile_names()}


def profile_for(protocol: str) -> Profile:
    """The bundled profile of the vehicle that speaks `protocol`."""
    for profile in load_profiles().values():
        if profile.protocol == protocol:
            return profile
    raise ProfileError(str(PROFILE_DIR), "protocol", protocol,
                       f"a protocol of a bundled profile, one of {', '.join(protocol_names())}")
