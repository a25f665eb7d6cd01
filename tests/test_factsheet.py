"""VDA 5050 2.1.0 factsheets: fleet-sim's model of the format
(fleet_sim.config.standards.factsheet) and the vehicle profiles made of them
(fleet_sim.config.standards.factsheet_profile, `fleet-sim profile import`)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from agv_model.profile import (
    DOCUMENTS,
    FACTSHEET,
    PROFILE_DIR,
    ProfileFile,
    load_profile,
    read_profile,
)
from fleet_sim.cli import main
from fleet_sim.config.schemas import json_schema
from fleet_sim.config.standards.factsheet import read_factsheet
from fleet_sim.config.standards.factsheet_profile import import_factsheet
from fleet_sim.config.vehicle import kinematics_m
from fleet_sim.errors import InputError
from userfiles.checking import validate
from userfiles.reading import read_yaml

from .conftest import DATA

TUGGER = DATA / "tugger.factsheet.json"
RAW: dict[str, Any] = json.loads(TUGGER.read_text(encoding="utf-8"))
REQUIRED_ONLY: dict[str, Any] = {
    "version": "2.1.0", "manufacturer": "Plain", "serialNumber": "1",
    "typeSpecification": {"seriesName": "P1", "agvKinematic": "OMNI", "agvClass": "CARRIER",
                          "maxLoadMass": 0, "localizationTypes": [], "navigationTypes": []},
    "physicalParameters": {"speedMin": 0, "speedMax": 0.2, "accelerationMax": 0.3,
                           "decelerationMax": 0.3, "heightMax": 0.4, "width": 0.5,
                           "length": 0.8},
    "protocolLimits": {"maxStringLens": {}, "maxArrayLens": {},
                       "timing": {"minOrderInterval": 1, "minStateInterval": 1}},
    "protocolFeatures": {"optionalParameters": [], "agvActions": []},
    "agvGeometry": {}, "loadSpecification": {}}


def write_json(path: Path, data: Any) -> Path:
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def test_a_factsheet_becomes_a_profile_that_loads(tmp_path: Path, capsys: Any) -> None:
    out = tmp_path / "t12.yaml"
    assert main(["profile", "import", str(TUGGER), "--out", str(out)]) == 0
    profile = read_profile(out)
    k = profile.kinematics
    metres = kinematics_m(k)  # the one conversion of a profile's mm to the vehicle's metres
    assert (metres["max_speed_mps"], metres["accel_mps2"], metres["decel_mps2"],
            metres["length_m"]) == (1.2, 0.4, 0.6, 1.35)
    assert profile.title == "T12 tugger (Example Motion)"
    assert profile.document == f"{FACTSHEET}: tugger.factsheet.json"
    assert profile.protocol is None
    assert profile.sources["kinematics.max_speed_mmps"] == \
        f"{FACTSHEET}, physicalParameters.speedMax 1.2 m/s"
    # what a factsheet lacks is the base profile's, and said to be assumed
    base = load_profile("rss-agv-001")
    assert k.turn_speed_mmps == base.kinematics.turn_speed_mmps
    assert (profile.battery, profile.link) == (base.battery, base.link)
    for key in ("kinematics.turn_speed_mmps", "battery.capacity_wh", "link.baud"):
        assert profile.sources[key].startswith("assumed; from base profile rss-agv-001 (")
    printed = capsys.readouterr().out
    assert "loadSpecification.loadSets[0].pickTime = 12: a station's handling time" in printed
    text = out.read_text(encoding="utf-8")
    assert text.startswith("# Imported by `fleet-sim profile import` from tugger.factsheet.json")
    for unused in ("typeSpecification.agvKinematic = DIFF", "physicalParameters.width = 0.7",
                   "loadSpecification.loadSets[0].dropTime = 9.5", "protocolLimits = {...}",
                   "agvGeometry = {...}", "vehicleConfig = {...}",
                   "loadSpecification.loadSets[0].agvSpeedLimit = 0.8",
                   "exampleMotionServiceInterval: not a VDA 5050 2.1.0 factsheet key"):
        assert f"#   - {unused}" in text, unused
    again = tmp_path / "again.yaml"
    assert main(["profile", "import", str(TUGGER), "--out", str(again)]) == 0
    assert again.read_bytes() == out.read_bytes()


def test_the_base_profile_can_be_chosen_and_the_turn_speed_is_capped(tmp_path: Path) -> None:
    carriro = import_factsheet(TUGGER, "carriro-ad-plus")
    assert carriro.data["battery"]["capacity_wh"] == load_profile(
        "carriro-ad-plus").battery.capacity_wh
    assert carriro.data["link"]["baud"] == 19200
    slow = import_factsheet(write_json(tmp_path / "slow.json", REQUIRED_ONLY))
    kinematics = slow.data["kinematics"]
    assert kinematics["max_speed_mmps"] == 200 and kinematics["turn_speed_mmps"] == 200
    assert "capped at physicalParameters.speedMax" in kinematics["source"]["turn_speed_mmps"]
    from_file = import_factsheet(TUGGER, str(PROFILE_DIR / "tabo.yaml"))
    assert from_file.base == "tabo"
    with pytest.raises(InputError, match=r"--base: base: got 'nobody'; expected the name of a "
                                         "bundled profile"):
        import_factsheet(TUGGER, "nobody")


def test_a_factsheet_with_only_the_required_parts_uses_everything_but_width_and_height(
        tmp_path: Path) -> None:
    imported = import_factsheet(write_json(tmp_path / "plain.json", REQUIRED_ONLY))
    assert [line.split(" =")[0] for line in imported.not_used] == [
        "typeSpecification.agvKinematic", "typeSpecification.agvClass",
        "typeSpecification.maxLoadMass", "typeSpecification.localizationTypes",
        "typeSpecification.navigationTypes", "physicalParameters.speedMin",
        "physicalParameters.heightMax", "physicalParameters.width", "protocolLimits",
        "protocolFeatures", "agvGeometry"]
    written = tmp_path / "plain.yaml"
    written.write_text(imported.text(), encoding="utf-8")
    assert read_profile(written).kinematics.length_mm == 800


def test_the_published_schema_takes_the_factsheets_fleet_sim_takes() -> None:
    schema = json_schema("factsheet")
    jsonschema.Draft202012Validator.check_schema(schema)
    for good in (RAW, REQUIRED_ONLY):
        jsonschema.validate(good, schema, cls=jsonschema.Draft202012Validator)
    bad = copy.deepcopy(RAW)
    bad["physicalParameters"]["speedMax"] = 0
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema, cls=jsonschema.Draft202012Validator)


@pytest.mark.parametrize(("change", "message"), [
    (lambda d: d.update(version="3.0.0"),
     "version: got '3.0.0'; expected a VDA 5050 2.x factsheet"),
    (lambda d: d["physicalParameters"].update(speedMin=2.0),
     "physicalParameters.speedMin: got 2.0; expected at most speedMax (1.2)"),
    (lambda d: d["protocolLimits"]["maxArrayLens"].update({"order.nodes": -1}),
     "protocolLimits.maxArrayLens.order.nodes: got -1; expected an integer in [0, 4294967295]"),
    (lambda d: d["agvGeometry"]["envelopes2d"][0].update(set=5),
     "agvGeometry.envelopes2d[0].set: got 5; expected a text"),
    (lambda d: d.update(timestamp="noon"),
     "timestamp: got 'noon'; expected an ISO 8601 date and time"),
])
def test_a_bad_factsheet_is_named_by_its_json_path(change: Any, message: str,
                                                   tmp_path: Path) -> None:
    data = copy.deepcopy(RAW)
    change(data)
    path = write_json(tmp_path / "f.json", data)
    with pytest.raises(InputError) as info:
        read_factsheet(path)
    assert str(info.value).startswith(f"{path}: {message}")


def test_a_profile_names_a_factsheet_as_its_document_or_a_spec() -> None:
    data = read_yaml(PROFILE_DIR / "tabo.yaml")
    for document in (f"{FACTSHEET}: a.json", DOCUMENTS["TABO commands"]):
        assert validate(ProfileFile, {**data, "document": document}, "p.yaml").document == \
            document
    for document in (f"{FACTSHEET}: ", "acme.pdf"):
        with pytest.raises(InputError,
                           match=r"p.yaml: document: got .*; expected a source document's title"):
            validate(ProfileFile, {**data, "document": document}, "p.yaml")


def test_the_written_profile_holds_exactly_the_figures_made() -> None:
    imported = import_factsheet(TUGGER)
    assert yaml.safe_load(imported.text()) == imported.data
    assert "max_speed_mmps: 1200\n" in imported.text()  # written as a planner writes it
