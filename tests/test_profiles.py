"""Vehicle profiles: the five bundled files load, carry the documents' figures, and the loader
rejects what it cannot use with the file, the key, the value and what it expected."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest
import yaml
from pydantic import ValidationError

from agv_model.link import Link
from agv_model.profile import (
    ASSUMED,
    DOCUMENTS,
    PROFILE_DIR,
    Profile,
    load_profile,
    load_profiles,
    profile_for,
    profile_names,
    read_profile,
)
from agv_model.protocols import Command
from userfiles.checking import InputError

NAMES = ("agv-3", "carriro-ad-plus", "ktm-02", "rss-agv-001", "tabo")
FIGURES_PER_PROFILE = 5 + 4 + 9  # kinematics, battery, link


def test_all_five_profiles_load() -> None:
    assert profile_names() == NAMES
    profiles = load_profiles()
    assert {name: p.protocol for name, p in profiles.items()} == {
        "agv-3": "agv3", "carriro-ad-plus": "carriro", "ktm-02": "ktm02", "rss-agv-001": None,
        "tabo": "tabo"}
    for profile in profiles.values():
        assert profile.document in DOCUMENTS.values()
    # each names its document by title, never by a file name (the documents are not in the repo)
    assert {name: p.document for name, p in profiles.items()} == {
        "agv-3": DOCUMENTS["AGV-3 protocol"], "carriro-ad-plus": DOCUMENTS["CarriRo API v1.4"],
        "ktm-02": DOCUMENTS["KTM-02 commands"], "rss-agv-001": DOCUMENTS["RSS-AGV-001"],
        "tabo": DOCUMENTS["TABO commands"]}


def test_generic_profile_carries_rss_agv_001_7_1_defaults() -> None:
    generic = load_profile("rss-agv-001")
    k = generic.kinematics
    assert (k.max_speed_mmps, k.accel_mmps2, k.decel_mmps2, k.turn_speed_mmps) == (
        1000, 500, 500, 300)
    for key, param in (("max_speed_mmps", "P_001"), ("accel_mmps2", "P_002"),
                       ("decel_mmps2", "P_003"), ("turn_speed_mmps", "P_004")):
        assert generic.sources[f"kinematics.{key}"].startswith(f"RSS-AGV-001 7.1 {param}")


def test_carriro_profile_carries_the_interface_settings() -> None:
    carriro = load_profile("carriro-ad-plus")
    link = carriro.link
    assert (link.baud, link.data_bits, link.parity, link.stop_bits) == (19200, 8, "even", 1)
    assert link.host_gap_s == 0.010 and link.bits_per_char == 11
    assert carriro.kinematics.max_speed_mmps == pytest.approx(3.0 / 3.6 * 1000, abs=1e-3)
    for key in ("baud", "data_bits", "parity", "stop_bits"):
        assert "インターフェイス仕様" in carriro.sources[f"link.{key}"]
    assert carriro.sources["link.host_gap_s"].startswith("CarriRo API v1.4, 処理")


def test_documented_figures_of_the_other_vehicles() -> None:
    assert load_profile("agv-3").link.reply_timeout_s == 0.25
    assert load_profile("agv-3").sources["link.reply_timeout_s"].startswith(
        "AGV-3 protocol, Syntax")
    assert load_profile("tabo").kinematics.max_speed_mmps == 410
    assert load_profile("tabo").sources["kinematics.max_speed_mmps"].startswith("TABO commands")


@pytest.mark.parametrize("name", NAMES)
def test_every_figure_cites_a_document_or_says_assumed(name: str) -> None:
    profile = load_profile(name)
    assert len(profile.sources) == FIGURES_PER_PROFILE
    for key, text in profile.sources.items():
        assert text.startswith(ASSUMED) or any(text.startswith(tag) for tag in DOCUMENTS), key
    # a figure from another vehicle's document would be a mistake
    own = {tag for tag, title in DOCUMENTS.items() if title == profile.document}
    for text in profile.sources.values():
        cited = {tag for tag in DOCUMENTS if text.startswith(tag)}
        assert cited <= own


@pytest.mark.parametrize("name", [n for n in NAMES if n != "rss-agv-001"])
def test_each_profile_link_drives_its_protocol(name: str) -> None:
    profile = load_profile(name)
    assert profile.protocol is not None
    link = Link(profile.protocol, profile.link)
    assert profile_for(profile.protocol) == profile
    hello = {"carriro": b"comm?\n", "ktm02": Command("RequestStatusCmd"), "tabo": b"GBI\n",
             "agv3": b"*IDN?\r\n"}[profile.protocol]
    exchange = link.exchange(hello)
    assert exchange.reply and not exchange.timed_out


def test_profiles_are_frozen() -> None:
    profile = load_profile("tabo")
    with pytest.raises(ValidationError, match="frozen"):
        profile.kinematics.max_speed_mmps = 1.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        profile.title = "another"  # type: ignore[misc]
    with pytest.raises(TypeError):
        profile.sources["link.baud"] = "assumed"  # type: ignore[index]


def broken(tmp_path: Path, change: Any, name: str = "carriro-ad-plus") -> Path:
    """A copy of a bundled profile, changed by `change(data)`."""
    data = yaml.safe_load((PROFILE_DIR / f"{name}.yaml").read_text(encoding="utf-8"))
    change(data)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True), encoding="utf-8")
    return path


def test_a_copy_loads_like_the_original(tmp_path: Path) -> None:
    copied = read_profile(broken(tmp_path, lambda d: None))
    original = load_profile("carriro-ad-plus")
    assert dataclasses.replace(copied, sources={}) == dataclasses.replace(original, sources={})
    assert (copied.kinematics, copied.link) == (original.kinematics, original.link)
    assert dict(copied.sources) == dict(original.sources)


def test_unknown_key_names_file_key_value_and_expectation(tmp_path: Path) -> None:
    path = broken(tmp_path, lambda d: d["kinematics"].update(top_speed_kmh=6))
    with pytest.raises(InputError) as info:
        read_profile(path)
    message = str(info.value)
    assert message == (f"{path}: kinematics.top_speed_kmh: got 6; expected no such key here "
                       "(known keys: max_speed_mmps, accel_mmps2, decel_mmps2, turn_speed_mmps, "
                       "length_mm, source)")
    assert (info.value.file, info.value.element, info.value.value) == (
        str(path), "kinematics.top_speed_kmh", 6)


def setter(section: str, key: str, value: Any) -> Any:
    def change(data: dict[str, Any]) -> None:
        target = data
        for part in section.split(".") if section else ():
            target = target[part]
        target[key] = value
    return change


def deleter(section: str, key: str) -> Any:
    def change(data: dict[str, Any]) -> None:
        target = data
        for part in section.split("."):
            target = target[part]
        del target[key]
    return change


@pytest.mark.parametrize(("change", "key", "expected"), [
    (setter("", "colour", "red"), "colour", "no such key here (known keys: title, document"),
    (setter("link.jitter", "spread_s", 0.1), "link.jitter.spread_s",
     "no such key here: did you mean 'sd_s'? (known keys: distribution"),
    (setter("link", "baud", 0), "link.baud", "an integer > 0"),
    (setter("link", "baud", 1e400), "link.baud", "an integer"),
    (setter("link", "parity", "E"), "link.parity", "one of 'none', 'even'"),
    (setter("link.jitter", "distribution", "gauss"), "link.jitter.distribution", "one of 'none'"),
    (setter("link", "latency_s", float("nan")), "link.latency_s", "a finite number"),
    (setter("battery", "idle_w", float("inf")), "battery.idle_w", "a finite number"),
    (setter("", "title", ""), "title", "a non-empty text"),
    (setter("kinematics", "max_speed_mmps", "fast"), "kinematics.max_speed_mmps", "a number"),
    (setter("kinematics", "length_mm", 0), "kinematics.length_mm", "a number > 0"),
    (setter("battery", "idle_w", -1), "battery.idle_w", "a number >= 0"),
    (setter("kinematics", "turn_speed_mmps", 900), "kinematics.turn_speed_mmps", "at most"),
    (setter("", "protocol", "modbus"), "protocol", "null or one of carriro"),
    (setter("", "document", "brochure.pdf"), "document",
     "a source document's title, one of 'RSS-AGV-001 core logic"),
    (setter("", "document", "RSS-AGV-001"), "document", "a source document's title"),
    (deleter("battery", "charge_w"), "battery.charge_w", "a value for required key 'charge_w'"),
    (deleter("link.source", "baud"), "link.source.baud", "a citation or 'assumed ...'"),
    (setter("link.source", "baud", "the brochure"), "link.source.baud", "'assumed ...' or a"),
    (setter("link.source", "speed", "assumed"), "link.source.speed", "a figure of this section"),
])
def test_bad_profiles_are_rejected(tmp_path: Path, change: Any, key: str,
                                   expected: str) -> None:
    path = broken(tmp_path, change)
    with pytest.raises(InputError) as info:
        read_profile(path)
    assert info.value.element == key
    assert str(info.value).startswith(f"{path}: {key}: got ")
    assert info.value.expected.startswith(expected)


def test_bad_yaml_and_missing_files(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("title: [unclosed\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"bad.yaml: line 2: got .*; expected valid YAML"):
        read_profile(bad)
    with pytest.raises(InputError, match=r"missing.yaml: file: got .*; expected an existing file"):
        read_profile(tmp_path / "missing.yaml")
    with pytest.raises(InputError, match="got 'nope'; expected one of agv-3, carriro-ad-plus"):
        load_profile("nope")


def test_profile_for_an_unbundled_protocol() -> None:
    with pytest.raises(InputError, match="got 'modbus'"):
        profile_for("modbus")


def test_profile_type() -> None:
    assert all(isinstance(p, Profile) for p in load_profiles().values())
