"""VDMA LIF 1.0.0: fleet-sim's model of the format (fleet_sim.config.standards.lif), layouts
exported to it (lif_export) and imported from it (lif_import), and the `layout import|export`
commands."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from fleet_sim.cli import main
from fleet_sim.config.layout import layout_from_spec, load_layout
from fleet_sim.config.layout_spec import LayoutSpec
from fleet_sim.config.layout_yaml import layout_yaml
from fleet_sim.config.schemas import json_schema
from fleet_sim.config.standards.lif import LifFile, Trajectory, read_lif, trajectory_length_m
from fleet_sim.config.standards.lif_export import layout_to_lif, lif_json
from fleet_sim.config.standards.lif_import import Imported, import_lif
from fleet_sim.errors import InputError
from userfiles.checking import validate
from userfiles.reading import read_yaml

from .conftest import DATA, LAYOUTS

BUNDLED = sorted(LAYOUTS.glob("*.yaml"))
HALL3 = DATA / "hall3.lif.json"
RAW_HALL3: dict[str, Any] = json.loads(HALL3.read_text(encoding="utf-8"))


def spec_of(path: Path) -> LayoutSpec:
    return validate(LayoutSpec, read_yaml(path), str(path))


def export_import(spec: LayoutSpec, tmp: Path, **options: Any) -> Imported:
    """spec -> LIF file -> layout spec, through files as the commands do."""
    lif = tmp / "layout.lif.json"
    lif.write_text(lif_json(layout_to_lif(spec, **options)), encoding="utf-8")
    return import_lif(lif)


def write_json(path: Path, data: Any) -> Path:
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


# Round trips and what is written

@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.name)
def test_yaml_lif_yaml_is_exact_for_every_bundled_layout(path: Path, tmp_path: Path) -> None:
    before = load_layout(path)
    imported = export_import(before.spec, tmp_path)
    assert imported.spec == before.spec
    assert imported.notes == ()  # nothing of fleet-sim's own file is left out
    written = tmp_path / "back.yaml"
    written.write_text(layout_yaml(imported.spec, imported.comments()), encoding="utf-8")
    after = load_layout(written)  # and so is the layout file written from it
    assert after.spec == before.spec
    assert sorted(before.graph.edges(data=True)) == sorted(after.graph.edges(data=True))
    assert before.places == after.places


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.name)
def test_what_fleet_sim_writes_has_the_structure_lif_requires(path: Path) -> None:
    data = json.loads(lif_json(layout_to_lif(spec_of(path))))
    meta = data["metaInformation"]
    for key in ("projectIdentification", "creator", "exportTimestamp", "lifVersion"):
        assert isinstance(meta[key], str) and meta[key], key
    assert meta["lifVersion"] == "1.0.0"
    assert [layout["layoutId"] for layout in data["layouts"]] == [spec_of(path).name]
    layout = data["layouts"][0]
    assert isinstance(layout["layoutVersion"], str)
    for node in layout["nodes"]:
        assert isinstance(node["nodeId"], str) and isinstance(node["mapId"], str)
        assert {type(node["nodePosition"][k]) for k in ("x", "y")} == {float}
        assert node["vehicleTypeNodeProperties"]
        assert all(isinstance(p["vehicleTypeId"], str) for p in node["vehicleTypeNodeProperties"])
    node_ids = {node["nodeId"] for node in layout["nodes"]}
    assert len(node_ids) == len(layout["nodes"])
    assert len({edge["edgeId"] for edge in layout["edges"]}) == len(layout["edges"])
    for edge in layout["edges"]:
        assert {edge["startNodeId"], edge["endNodeId"]} <= node_ids
        for prop in edge["vehicleTypeEdgeProperties"]:
            assert isinstance(prop["vehicleTypeId"], str)
            assert prop["rotationAllowed"] is False and prop["maxSpeed"] > 0
    for station in layout["stations"]:
        assert station["stationId"] and set(station["interactionNodeIds"]) <= node_ids
    # and it is what fleet-sim's published schema of the format says
    schema = json_schema("lif")
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(data, schema, cls=jsonschema.Draft202012Validator)


def test_a_two_way_segment_is_two_edges_and_comes_back_as_one(tmp_path: Path) -> None:
    spec = spec_of(LAYOUTS / "tiny_loop.yaml")
    data = spec.model_dump(mode="json", by_alias=True)
    data["segments"][0] |= {"direction": "two_way", "length_m": 4.5, "speed_limit_mps": 0.6,
                            "branch": "left", "rssi_dbm": -71}
    data["segments"][4] |= {"speed_limit_mps": 1.0}  # explicit, equal to the default
    data["segments"].append({"from": "S3", "to": "P"})  # one-way, opposite P -> S3
    spec = validate(LayoutSpec, data, "t.yaml")
    layout_from_spec(spec, "t.yaml")
    edges = layout_to_lif(spec)["layouts"][0]["edges"]
    assert [(e["edgeId"], e.get("fleetSim")) for e in edges[:2]] == [
        ("SW-S1", {"length_m": 4.5, "speed_limit_mps": 0.6, "direction": "two_way",
                   "branch": "left", "rssi_dbm": -71.0}),
        ("S1-SW", {"length_m": 4.5, "speed_limit_mps": 0.6, "direction": "two_way",
                   "rssi_dbm": -71.0})]
    assert {e["vehicleTypeEdgeProperties"][0]["maxSpeed"] for e in edges[:2]} == {0.6}
    assert edges[5]["fleetSim"] == {"speed_limit_mps": 1.0}
    assert "fleetSim" not in edges[3]  # P -> S3 and S3 -> P stay two one-way segments
    assert export_import(spec, tmp_path).spec == spec


def test_lif_names_survive_both_ways(tmp_path: Path) -> None:
    data = spec_of(LAYOUTS / "tiny_loop.yaml").model_dump(mode="json", by_alias=True)
    data["lif"] = {"project": "Hall 9", "creator": "Planner", "layout_id": "H9-0",
                   "layout_version": "12", "level_id": "ground", "map_id": "slam-0",
                   "vehicle_type_id": "ACME.T12", "export_timestamp": "2025-01-02T03:04:05.06Z"}
    spec = validate(LayoutSpec, data, "t.yaml")
    lif = layout_to_lif(spec)
    meta, layout = lif["metaInformation"], lif["layouts"][0]
    assert (meta["projectIdentification"], meta["creator"], meta["exportTimestamp"]) == (
        "Hall 9", "Planner", "2025-01-02T03:04:05.06Z")
    assert (layout["layoutId"], layout["layoutName"], layout["layoutVersion"],
            layout["layoutLevelId"]) == ("H9-0", "tiny_loop", "12", "ground")
    assert {n["mapId"] for n in layout["nodes"]} == {"slam-0"}
    assert {p["vehicleTypeId"] for e in layout["edges"]
            for p in e["vehicleTypeEdgeProperties"]} == {"ACME.T12"}
    assert export_import(spec, tmp_path).spec == spec
    other = layout_to_lif(spec, timestamp="2026-02-03T04:05:06.07Z", vehicle_type="B.X")
    assert other["metaInformation"]["exportTimestamp"] == "2026-02-03T04:05:06.07Z"
    assert {p["vehicleTypeId"] for n in other["layouts"][0]["nodes"]
            for p in n["vehicleTypeNodeProperties"]} == {"B.X"}


def test_places_say_their_purpose_with_vda_5050_actions() -> None:
    layout = layout_to_lif(spec_of(LAYOUTS / "warehouse.yaml"))["layouts"][0]
    actions = {n["nodeId"]: [a["actionType"] for a in n["vehicleTypeNodeProperties"][0].get(
        "actions", [])] for n in layout["nodes"]}
    kinds = {s["stationId"]: s["fleetSim"]["kind"] for s in layout["stations"]}
    for station in layout["stations"]:
        expected = {"pickup": ["pick"], "dropoff": ["drop"],
                    "charger": ["startCharging", "stopCharging"], "parking": []}[
            kinds[station["stationId"]]]
        assert [actions[n] for n in station["interactionNodeIds"]] == [expected]
    assert sorted(set(kinds.values())) == ["charger", "dropoff", "parking", "pickup"]


# The bundled example and determinism

def test_the_bundled_lif_example_is_what_the_exporter_writes_today(tmp_path: Path,
                                                                   capsys: Any) -> None:
    out = tmp_path / "warehouse.lif.json"
    assert main(["layout", "export", str(LAYOUTS / "warehouse.yaml"), "--lif", str(out)]) == 0
    assert out.read_bytes() == (LAYOUTS / "warehouse.lif.json").read_bytes()
    again = tmp_path / "again.json"
    assert main(["layout", "export", str(LAYOUTS / "warehouse.yaml"), "--lif", str(again)]) == 0
    assert again.read_bytes() == out.read_bytes()
    assert "1970-01-01T00:00:00.00Z" in capsys.readouterr().out
    assert import_lif(LAYOUTS / "warehouse.lif.json").spec == spec_of(LAYOUTS / "warehouse.yaml")


def test_export_timestamp_now_and_given(tmp_path: Path) -> None:
    out = tmp_path / "x.json"
    tiny = str(LAYOUTS / "tiny_loop.yaml")
    assert main(["layout", "export", tiny, "--lif", str(out), "--timestamp", "now"]) == 0
    stamp = read_lif(out).metaInformation.exportTimestamp
    assert stamp != "1970-01-01T00:00:00.00Z" and stamp.endswith("Z") and len(stamp) == 23
    assert main(["layout", "export", tiny, "--lif", str(out), "--timestamp",
                 "2024-06-11T14:03:27.51Z"]) == 0
    assert read_lif(out).metaInformation.exportTimestamp == "2024-06-11T14:03:27.51Z"


# A hand-made file that uses what fleet_sim does not model

def test_a_hand_made_lif_with_optional_parts_is_read(tmp_path: Path) -> None:
    imported = import_lif(HALL3, layout_id="L0", vehicle_type="T1")
    spec = imported.spec
    assert spec.name == "hall3_ground"
    assert [n.id for n in spec.nodes] == ["N1", "N2", "N3", "N4", "N5", "N7"]  # N6: T2 only
    assert [(n.id, n.kind) for n in spec.nodes if n.kind != "tag"] == [
        ("N3", "station"), ("N4", "station"), ("N5", "charger")]
    segments = {(s.from_node, s.to_node): s for s in spec.segments}
    assert list(segments) == [("N1", "N2"), ("N2", "N3"), ("N3", "N4"), ("N4", "N1"),
                              ("N1", "N5"), ("N4", "N7")]
    assert [s.direction for s in segments.values()] == ["two_way", "one_way", "one_way",
                                                        "one_way", "two_way", "two_way"]
    assert [s.speed_limit_mps for s in segments.values()] == [1.2, 0.5, 0.8, None, 0.3, 0.5]
    # the curve N2 -> N3 (a quadratic Bezier) is the parabola x = 10 + 6t(1 - t), y = 6t
    assert segments["N2", "N3"].length_m == pytest.approx(_parabola_length(), abs=1e-5)
    assert [(s.id, s.kind, s.nodes) for s in spec.stations] == [
        ("PICK", "pickup", ("N3",)), ("DROP", "dropoff", ("N4",))]
    assert [(c.id, c.node) for c in spec.chargers] == [("CHG", "N5")]
    assert spec.parking == ()
    assert spec.lif.model_dump(exclude_defaults=True) == {
        "project": "Hall 3 retrofit", "creator": "Example Integrator GmbH",
        "export_timestamp": "2024-06-11T14:03:27.51Z", "layout_id": "L0",
        "layout_version": "4", "level_id": "ground", "map_id": "hall3_map_0",
        "vehicle_type_id": "T1"}
    dropped = {n.what for n in imported.notes if not n.kept}
    assert dropped >= {
        "layouts[1]", "metaInformation.integratorProjectNumber",
        "layouts[0].nodes[*].nodeName", "layouts[0].nodes[*].nodeDescription",
        "layouts[0].nodes[*].vehicleTypeNodeProperties[*]",
        "layouts[0].nodes[*].vehicleTypeNodeProperties[*].theta",
        "layouts[0].nodes[*].vehicleTypeNodeProperties[*].actions[*]",
        "layouts[0].nodes[*].vehicleTypeNodeProperties[*].actions[*].actionParameters",
        "layouts[0].edges[*].vehicleTypeEdgeProperties[*].loadRestriction",
        "layouts[0].edges[*].vehicleTypeEdgeProperties[*].maxHeight",
        "layouts[0].edges[*].vehicleTypeEdgeProperties[*].reentryAllowed",
        "layouts[0].edges[*].vehicleTypeEdgeProperties[*].vehicleOrientation",
        "layouts[0].edges[*].vehicleTypeEdgeProperties[*].rotationAtEndNodeAllowed",
        "layouts[0].edges[*].vehicleTypeEdgeProperties[*].actions",
        "layouts[0].edges[*].edgeName", "layouts[0].stations[*].stationHeight",
        "layouts[0].stations[*].stationPosition", "layouts[0].stations[*]"}
    why = {n.example: n.why for n in imported.notes}
    assert "no pick, drop or startCharging" in why["layouts[0].stations[3]"]  # BUFFER
    assert "belongs to PICK already" in why["layouts[0].stations[4]"]  # RACK on N3
    assert "another layout" in why["layouts[0].edges[11]"]  # N4 -> U1 upstairs
    assert "vehicle type T2" in why["layouts[0].edges[0].vehicleTypeEdgeProperties[1]"]
    # nothing but parking is missing for a complete layout
    with pytest.raises(InputError, match="at least one parking area"):
        layout_from_spec(spec, "hall3.yaml")


def _parabola_length() -> float:
    """Length of x = 10 + 6t(1 - t), y = 6t for t in [0, 1], by the midpoint rule on its
    speed (6 - 12t, 6), independent of the NURBS code."""
    steps = 20_000
    return sum(math.hypot(6 - 12 * (i + 0.5) / steps, 6) for i in range(steps)) / steps


def test_a_station_marked_as_parking_in_the_extension_completes_it(tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    data["layouts"][0]["stations"][3]["fleetSim"] = {"kind": "parking", "capacity": 2}
    imported = import_lif(write_json(tmp_path / "h.lif.json", data), "L0", "T1")
    assert [(p.id, p.node, p.capacity) for p in imported.spec.parking] == [("BUFFER", "N7", 2)]
    layout = layout_from_spec(imported.spec, "h.yaml")
    assert layout.graph.edges["N2", "N3"]["speed_limit_mps"] == 0.5


def test_lif_yaml_lif_keeps_what_the_layout_can_hold(tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    data["layouts"][0]["stations"][3]["fleetSim"] = {"kind": "parking", "capacity": 2}
    imported = import_lif(write_json(tmp_path / "h.lif.json", data), "L0", "T1")
    again = layout_to_lif(imported.spec)
    meta = again["metaInformation"]
    assert (meta["projectIdentification"], meta["creator"], meta["exportTimestamp"]) == (
        "Hall 3 retrofit", "Example Integrator GmbH", "2024-06-11T14:03:27.51Z")
    layout = again["layouts"][0]
    assert (layout["layoutId"], layout["layoutName"], layout["layoutVersion"],
            layout["layoutLevelId"]) == ("L0", "hall3_ground", "4", "ground")
    assert {n["mapId"] for n in layout["nodes"]} == {"hall3_map_0"}
    original = {(e["startNodeId"], e["endNodeId"]): e["vehicleTypeEdgeProperties"][0].get(
        "maxSpeed", 1.0) for e in data["layouts"][0]["edges"]
        if e["vehicleTypeEdgeProperties"][0]["vehicleTypeId"] == "T1" and e["endNodeId"] != "U1"}
    assert {(e["startNodeId"], e["endNodeId"]): e["vehicleTypeEdgeProperties"][0]["maxSpeed"]
            for e in layout["edges"]} == original
    assert {p["vehicleTypeId"] for e in layout["edges"]
            for p in e["vehicleTypeEdgeProperties"]} == {"T1"}


def test_one_layout_and_one_vehicle_type_are_chosen() -> None:
    with pytest.raises(InputError, match=r"layouts: got \['L0', 'L1'\]; expected one layout; "
                                         r"choose one with --layout-id L0 \(level ground, 7 "
                                         r"nodes\) or --layout-id L1 \(level mezzanine, 1 "
                                         r"node\)$"):
        import_lif(HALL3)
    with pytest.raises(InputError, match=r"layouts\[0\].nodes: got \['T1', 'T2'\]; expected one "
                                         "vehicle type; choose one with --vehicle-type T1 or "
                                         r"--vehicle-type T2 \(or every one with --all-types\)$"):
        import_lif(HALL3, layout_id="L0")
    with pytest.raises(InputError, match=r"got 'T9'; expected a vehicleTypeId the layout uses: "
                                         "T1, T2"):
        import_lif(HALL3, layout_id="L0", vehicle_type="T9")
    with pytest.raises(InputError, match=r"got 'L7'; expected the layoutId of one of its "
                                         "layouts: L0, L1"):
        import_lif(HALL3, layout_id="L7")
    upstairs = import_lif(HALL3, layout_id="L1")  # one vehicle type there
    assert [n.id for n in upstairs.spec.nodes] == ["U1"] and upstairs.spec.segments == ()


def test_opposite_edges_that_differ_stay_one_way(tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    data["layouts"][0]["edges"][1]["vehicleTypeEdgeProperties"][0]["maxSpeed"] = 1.1
    spec = import_lif(write_json(tmp_path / "h.lif.json", data), "L0", "T1").spec
    first = [(s.from_node, s.to_node, s.direction, s.speed_limit_mps) for s in spec.segments]
    assert first[:2] == [("N1", "N2", "one_way", 1.2), ("N2", "N1", "one_way", 1.1)]


def test_the_two_layout_refusal_is_one_line_naming_each_choice(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x.yaml"
    assert main(["layout", "import", str(HALL3), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (f"fleet-sim: error: {HALL3}: layouts: got ['L0', 'L1']; expected one layout; "
                   "choose one with --layout-id L0 (level ground, 7 nodes) or --layout-id L1 "
                   "(level mezzanine, 1 node)\n")
    assert not out.exists()


# Numbers written as texts (as six of the LIF document's own examples do with stationHeight)

def _hall3_with_text_numbers(tmp_path: Path) -> Path:
    data = copy.deepcopy(RAW_HALL3)
    ground = data["layouts"][0]
    ground["stations"][0]["stationHeight"] = "0.75"
    ground["nodes"][1]["nodePosition"]["x"] = str(ground["nodes"][1]["nodePosition"]["x"])
    for edge in ground["edges"][:2]:
        prop = edge["vehicleTypeEdgeProperties"][0]
        prop["maxSpeed"] = repr(prop["maxSpeed"])
    return write_json(tmp_path / "texts.lif.json", data)


def test_a_number_written_as_a_text_is_read_as_the_number_with_a_note(tmp_path: Path) -> None:
    path = _hall3_with_text_numbers(tmp_path)
    imported = import_lif(path, "L0", "T1")
    assert imported.spec == import_lif(HALL3, "L0", "T1").spec  # the numbers, used
    assert [(n.element, n.text, n.value) for n in imported.text_numbers] == [
        ("layouts[0].nodes[1].nodePosition.x", "10.0", 10.0),
        ("layouts[0].edges[0].vehicleTypeEdgeProperties[0].maxSpeed", "1.2", 1.2),
        ("layouts[0].edges[1].vehicleTypeEdgeProperties[0].maxSpeed", "1.2", 1.2),
        ("layouts[0].stations[0].stationHeight", "0.75", 0.75)]
    assert imported.warnings() == [
        f"{path}: layouts[0].nodes[1].nodePosition.x: got '10.0', a number written as a text; "
        "read as 10.0",
        f"{path}: layouts[0].edges[0].vehicleTypeEdgeProperties[0].maxSpeed: got '1.2', a "
        "number written as a text; read as 1.2 (and 1 more: "
        "layouts[*].edges[*].vehicleTypeEdgeProperties[*].maxSpeed)",
        f"{path}: layouts[0].stations[0].stationHeight: got '0.75', a number written as a text; "
        "read as 0.75"]
    assert "  - layouts[*].edges[*].vehicleTypeEdgeProperties[*].maxSpeed (2x, e.g. layouts[0]" \
           ".edges[0].vehicleTypeEdgeProperties[0].maxSpeed): numbers written as texts, read " \
           "as the numbers" in imported.comments()
    assert import_lif(HALL3, "L0", "T1").text_numbers == ()


def test_the_command_warns_of_each_text_number_on_stderr(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _hall3_with_text_numbers(tmp_path)
    out = tmp_path / "h.yaml"
    main(["layout", "import", str(path), "--out", str(out), "--layout-id", "L0",
          "--vehicle-type", "T1"])
    warnings = [line for line in capsys.readouterr().err.splitlines()
                if "written as a text" in line]
    assert warnings[-1] == (f"fleet-sim: warning: {path}: layouts[0].stations[0].stationHeight: "
                            "got '0.75', a number written as a text; read as 0.75")
    assert len(warnings) == 3
    assert "numbers written as texts, read as the numbers" in out.read_text(encoding="utf-8")


@pytest.mark.parametrize("text", ["0,75", " 0.75", "0.75 m", "NaN", "Infinity", "1e999", "",
                                  "0x10", "+1"])
def test_a_text_that_is_not_a_json_number_stays_refused(tmp_path: Path, text: str) -> None:
    data = copy.deepcopy(RAW_HALL3)
    data["layouts"][0]["stations"][0]["stationHeight"] = text
    with pytest.raises(InputError, match=r"layouts\[0\]\.stations\[0\]\.stationHeight: got "
                                         f"{re.escape(repr(text))}; expected a number$"):
        import_lif(write_json(tmp_path / "bad.lif.json", data), "L0", "T1")


def test_a_number_read_from_a_text_still_meets_the_range(tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    data["layouts"][0]["stations"][0]["stationHeight"] = "-0.5"
    with pytest.raises(InputError, match=r"layouts\[0\]\.stations\[0\]\.stationHeight: got "
                                         r"-0\.5; expected a number >= 0"):
        import_lif(write_json(tmp_path / "bad.lif.json", data), "L0", "T1")


def test_a_text_in_a_text_field_is_no_number_to_read(tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    data["layouts"][0]["layoutVersion"] = "2"  # a text field: stays the text, no note
    imported = import_lif(write_json(tmp_path / "v.lif.json", data), "L0", "T1")
    assert imported.text_numbers == () and imported.spec.lif.layout_version == "2"


def test_lif_2_is_refused_by_name(tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    data["metaInformation"]["lifVersion"] = "2.0.0"
    with pytest.raises(InputError, match=r"metaInformation.lifVersion: got '2.0.0'; expected "
                                         "LIF 1.x \\(LIF 2 is in development"):
        read_lif(write_json(tmp_path / "v2.lif.json", data))
    data["metaInformation"]["lifVersion"] = "0.11.0"  # the document's examples
    assert read_lif(write_json(tmp_path / "v0.lif.json", data)).layouts


def test_stations_mapid_and_requirement_type_may_be_missing_as_the_schema_allows(
        tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    del data["layouts"][1]["stations"]
    del data["layouts"][0]["nodes"][0]["mapId"]
    drop = data["layouts"][0]["nodes"][3]["vehicleTypeNodeProperties"][0]["actions"][0]
    assert drop["actionType"] == "drop" and "requirementType" not in drop
    lif = read_lif(write_json(tmp_path / "h.lif.json", data))
    assert lif.layouts[1].stations is None and lif.layouts[0].nodes[0].mapId is None


# Trajectories

def test_trajectory_length_is_the_curve_length() -> None:
    line = Trajectory.model_validate({"knotVector": [0, 0, 1, 1], "controlPoints": [
        {"x": 0, "y": 0}, {"x": 3, "y": 4}]})
    assert trajectory_length_m(line) == pytest.approx(5.0, abs=1e-12)
    quarter = Trajectory.model_validate({"degree": 2, "knotVector": [0, 0, 0, 1, 1, 1],
                                         "controlPoints": [{"x": 2, "y": 0},
                                                           {"x": 2, "y": 2,
                                                            "weight": math.sqrt(0.5)},
                                                           {"x": 0, "y": 2}]})
    assert trajectory_length_m(quarter) == pytest.approx(math.pi, rel=1e-5)  # r = 2
    polyline = Trajectory.model_validate({"knotVector": [0, 0, 0.5, 1, 1], "controlPoints": [
        {"x": 0, "y": 0}, {"x": 3, "y": 0}, {"x": 3, "y": 4}]})
    assert trajectory_length_m(polyline) == pytest.approx(7.0, abs=1e-9)


def test_a_trajectory_shorter_than_the_straight_line_is_not_believed(tmp_path: Path) -> None:
    data = copy.deepcopy(RAW_HALL3)
    traj = data["layouts"][0]["edges"][2]["vehicleTypeEdgeProperties"][0]["trajectory"]
    traj["controlPoints"] = [{"x": 10, "y": 0}, {"x": 10, "y": 1}, {"x": 10, "y": 2}]
    imported = import_lif(write_json(tmp_path / "h.lif.json", data), "L0", "T1")
    assert imported.spec.segments[1].length_m is None
    assert any("shorter than the straight line" in n.why for n in imported.notes)


# The commands

def test_layout_import_writes_the_layout_and_lists_what_it_left_out(tmp_path: Path,
                                                                      capsys: Any) -> None:
    out = tmp_path / "hall3.yaml"
    code = main(["layout", "import", str(HALL3), "--out", str(out), "--layout-id", "L0",
                 "--vehicle-type", "T1"])
    assert code == 1  # written, but it has no parking yet
    printed = capsys.readouterr()
    assert "fleet-sim: warning:" in printed.err and "parking" in printed.err
    assert "not kept     layouts[0].edges[*].vehicleTypeEdgeProperties[*].loadRestriction" \
        in printed.out
    text = out.read_text(encoding="utf-8")
    assert text.startswith("# Imported by `fleet-sim layout import` from ")
    assert "#   - layouts[0].nodes[*].nodeName" in text
    assert spec_of(out) == import_lif(HALL3, "L0", "T1").spec
    data = copy.deepcopy(RAW_HALL3)
    data["layouts"][0]["stations"][3]["fleetSim"] = {"kind": "parking"}
    complete = write_json(tmp_path / "complete.lif.json", data)
    assert main(["layout", "import", str(complete), "--out", str(out), "--layout-id", "L0",
                 "--vehicle-type", "T1"]) == 0
    assert main(["layout", str(out), "--png", str(tmp_path / "h.png")]) == 0


def test_layout_file_still_checks_and_a_file_named_import_too(tmp_path: Path,
                                                              capsys: Any,
                                                              monkeypatch: Any) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "import").write_text((LAYOUTS / "tiny_loop.yaml").read_text(encoding="utf-8"),
                                     encoding="utf-8")
    assert main(["layout", "./import", "--png", "t.png"]) == 0
    assert "layout 'tiny_loop' is valid" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_info:  # `layout import` is the command: needs --out
        main(["layout", "import", "x.lif.json"])
    assert exit_info.value.code == 2
    assert "--out" in capsys.readouterr().err


def test_schema_command_publishes_lif_and_factsheet(capsys: Any) -> None:
    for kind in ("lif", "factsheet"):
        assert main(["schema", kind]) == 0
        schema = json.loads(capsys.readouterr().out)
        assert schema["$id"] == f"fleet-sim/{kind}.schema.json"
        jsonschema.Draft202012Validator.check_schema(schema)
    assert LifFile.model_json_schema()["required"] == ["metaInformation", "layouts"]


def test_edge_ids_stay_unique_when_node_ids_hold_dashes(tmp_path: Path) -> None:
    data = spec_of(LAYOUTS / "tiny_loop.yaml").model_dump(mode="json", by_alias=True)
    data["nodes"] += [{"id": "S1-P", "x": 6, "y": 1}, {"id": "P-S3", "x": 10, "y": 1}]
    data["segments"] += [{"from": "S1", "to": "S1-P"}, {"from": "S1-P", "to": "S3"},
                         {"from": "S1", "to": "P-S3"}, {"from": "P-S3", "to": "S3"}]
    spec = validate(LayoutSpec, data, "t.yaml")
    layout_from_spec(spec, "t.yaml")
    edges = layout_to_lif(spec)["layouts"][0]["edges"]
    assert [(e["edgeId"], e["startNodeId"], e["endNodeId"]) for e in edges[-3:]] == [
        ("S1-P-S3", "S1-P", "S3"), ("S1-P-S3~2", "S1", "P-S3"), ("P-S3-S3", "P-S3", "S3")]
    assert export_import(spec, tmp_path).spec == spec


# Every vehicle type: allowed_types (mixed fleets)

def test_all_types_import_keeps_each_types_access_as_allowed_types(tmp_path: Path,
                                                                   capsys: Any) -> None:
    """hall3's L0: T1 drives the loop and the spurs, T2 only N1-N2 and its spur to N6. With
    every type imported, the shared edges are open to all, the rest to its type only, and
    the stations whose nodes only T1 may reach are T1's. Each type keeps its maxSpeed on the
    shared edges (T1 1.2 m/s both ways, T2 2.0 one way and no limit, so the default 1 m/s,
    the other): the highest is the segment's limit, the lower one a per-type limit. The
    speeds differ by direction for T2, so the pair stays two one-way segments."""
    imported = import_lif(HALL3, "L0", all_types=True)
    spec = imported.spec
    assert imported.vehicle_type == "T1" and spec.lif.vehicle_type_id == "T1"
    assert {(s.from_node, s.to_node): s.allowed_types for s in spec.segments} == {
        ("N1", "N2"): (), ("N2", "N1"): (), ("N2", "N3"): ("T1",), ("N3", "N4"): ("T1",),
        ("N4", "N1"): ("T1",), ("N1", "N5"): ("T1",), ("N4", "N7"): ("T1",),
        ("N2", "N6"): ("T2",)}
    assert [(s.from_node, s.to_node, s.speed_limit_mps, s.speed_limit_mps_by_type)
            for s in spec.segments][:2] == [("N1", "N2", 2.0, {"T1": 1.2}),
                                            ("N2", "N1", 1.2, {"T2": 1.0})]
    assert {s.id: s.allowed_types for s in spec.stations} == {"PICK": ("T1",), "DROP": ("T1",)}
    assert "N6" in [n.id for n in spec.nodes]  # T2's node, left out when importing T1 alone
    assert "N6" not in [n.id for n in import_lif(HALL3, "L0", "T1").spec.nodes]
    assert not any("a fleet_sim layout is for one vehicle type" in n.why
                   for n in imported.notes)
    def speed(segment: Any, vehicle_type: str | None = None) -> float:
        limit = segment.speed_limit_mps or 1.0  # hall3 has the default defaults
        return min(limit, segment.speed_limit_mps_by_type.get(vehicle_type, limit))

    for vehicle_type in ("T1", "T2"):  # each type's speed as when imported alone
        alone = {}
        for seg in import_lif(HALL3, "L0", vehicle_type).spec.segments:
            alone[seg.from_node, seg.to_node] = speed(seg)
            if seg.direction == "two_way":
                alone[seg.to_node, seg.from_node] = speed(seg)
        assert [speed(s, vehicle_type) for s in spec.segments[:2]] \
            == [alone[s.from_node, s.to_node] for s in spec.segments[:2]]
    # the main type names the file's type and chooses lengths; the speeds stay the same
    second = import_lif(HALL3, "L0", "T2", all_types=True).spec
    assert second.segments == spec.segments
    out = tmp_path / "hall3.yaml"
    assert main(["layout", "import", str(HALL3), "--out", str(out), "--layout-id", "L0",
                 "--all-types"]) == 1  # written; no parking yet
    assert spec_of(out) == spec
    capsys.readouterr()


def test_a_layout_with_allowed_types_exports_per_type_properties_and_comes_back(
        tmp_path: Path) -> None:
    """allowed_types on segments and stations are written as LIF's per-vehicle-type entries
    (an edge only for its types, a station's pick action only on its types' node entries),
    and `--all-types` reads them back to the same layout. Without allowed_types the export is
    for one type, as always."""
    data = read_yaml(LAYOUTS / "tiny_loop.yaml")
    data["segments"][0]["allowed_types"] = ["narrow"]
    data["segments"][5]["allowed_types"] = ["narrow", "wide"]
    data["stations"][0]["allowed_types"] = ["wide"]
    spec = validate(LayoutSpec, data, "t.yaml", "")
    lif = layout_to_lif(spec)
    layout = lif["layouts"][0]
    assert [p["vehicleTypeId"] for p in layout["edges"][0]["vehicleTypeEdgeProperties"]] == \
        ["narrow"]
    assert [p["vehicleTypeId"] for p in layout["edges"][1]["vehicleTypeEdgeProperties"]] == \
        ["fleet-sim", "narrow", "wide"]
    pick = next(n for n in layout["nodes"] if n["nodeId"] == "P")
    assert [(p["vehicleTypeId"], "actions" in p) for p in pick["vehicleTypeNodeProperties"]] \
        == [("fleet-sim", False), ("narrow", False), ("wide", True)]
    assert "allowed_types" not in json.dumps(layout["edges"])  # LIF's own fields carry it
    path = write_json(tmp_path / "t.lif.json", lif)
    assert import_lif(path, all_types=True).spec == spec
    with pytest.raises(InputError, match="one vehicle type; choose one with --vehicle-type "
                                         "fleet-sim or"):
        import_lif(path)
    plain = layout_to_lif(load_layout(LAYOUTS / "tiny_loop.yaml").spec)
    assert {p["vehicleTypeId"] for e in plain["layouts"][0]["edges"]
            for p in e["vehicleTypeEdgeProperties"]} == {"fleet-sim"}


def test_per_type_speed_limits_are_each_types_max_speed_and_come_back(tmp_path: Path) -> None:
    """speed_limit_mps_by_type is each type's maxSpeed on the edge; `--all-types` reads the
    layout back key for key: limits on one-way and two-way segments, under a default or an
    explicit segment limit, and on a segment where every type that may drive it has one."""
    data = read_yaml(LAYOUTS / "tiny_loop.yaml")
    data["segments"][1]["speed_limit_mps_by_type"] = {"heavy": 0.5}
    data["segments"][2] |= {"speed_limit_mps": 0.8, "speed_limit_mps_by_type": {"heavy": 0.3,
                                                                               "narrow": 0.6}}
    data["segments"][5] |= {"allowed_types": ["narrow", "heavy"],
                            "speed_limit_mps_by_type": {"heavy": 0.4, "narrow": 0.7}}
    data["nodes"].append({"id": "Y", "x": 20, "y": 4})
    data["segments"].append({"from": "E1", "to": "Y", "direction": "two_way",
                             "speed_limit_mps_by_type": {"narrow": 0.25}})
    spec = validate(LayoutSpec, data, "t.yaml", "")
    lif = layout_to_lif(spec)
    edges = {e["edgeId"]: {p["vehicleTypeId"]: p["maxSpeed"]
                           for p in e["vehicleTypeEdgeProperties"]}
             for e in lif["layouts"][0]["edges"]}
    assert edges["S1-P"] == {"fleet-sim": 1.0, "heavy": 0.5, "narrow": 1.0}
    assert edges["P-S3"] == {"fleet-sim": 0.8, "heavy": 0.3, "narrow": 0.6}
    assert edges["E1-NE"] == {"narrow": 0.7, "heavy": 0.4}
    assert edges["E1-Y"] == edges["Y-E1"] == {"fleet-sim": 1.0, "heavy": 1.0, "narrow": 0.25}
    assert edges["SW-S1"] == {"fleet-sim": 1.0, "heavy": 1.0, "narrow": 1.0}
    path = write_json(tmp_path / "t.lif.json", lif)
    imported = import_lif(path, all_types=True)
    assert imported.spec == spec
    assert imported.notes == ()
    written = tmp_path / "back.yaml"
    written.write_text(layout_yaml(imported.spec, imported.comments()), encoding="utf-8")
    assert spec_of(written) == spec
    assert "speed_limit_mps_by_type: {heavy: 0.3, narrow: 0.6}" in written.read_text("utf-8")
    heavy = import_lif(path, vehicle_type="heavy").spec  # one type: its own speed limits
    assert [(s.from_node, s.to_node, s.speed_limit_mps) for s in heavy.segments][1:3] == [
        ("S1", "P", 0.5), ("P", "S3", 0.3)]
    assert all(not s.speed_limit_mps_by_type for s in heavy.segments)


def test_a_foreign_file_gives_each_type_its_max_speed(tmp_path: Path) -> None:
    """Without fleet-sim's extension: the highest maxSpeed is the segment's limit and a type
    with a lower one gets it as its own; a type without maxSpeed has the default."""
    raw = copy.deepcopy(RAW_HALL3)
    edge = raw["layouts"][0]["edges"][0]
    edge["vehicleTypeEdgeProperties"][0]["maxSpeed"] = 2.5
    edge["vehicleTypeEdgeProperties"][1]["maxSpeed"] = 0.9
    spec = import_lif(write_json(tmp_path / "h.lif.json", raw), "L0", all_types=True).spec
    assert (spec.segments[0].speed_limit_mps, spec.segments[0].speed_limit_mps_by_type) \
        == (2.5, {"T2": 0.9})


def test_traffic_zones_of_every_kind_go_through_lif_exactly(tmp_path: Path) -> None:
    """Mutex, ban and same-direction zones ride in the layout's fleetSim extension (LIF has
    no field for them): export and import give the same layout, with nothing left out, and
    the layout file written from it loads to the same layout again. Before, they were lost."""
    data = read_yaml(DATA / "aisle_crossing.yaml")
    data["traffic_zones"] = [
        {"id": "AISLE", "kind": "same_direction", "nodes": ["B", "A1", "A2", "A3", "T"],
         "capacity": 3},
        {"id": "TOP", "kind": "mutex", "nodes": ["N4"], "segments": [["N4", "T"]],
         "capacity": 2},
        {"id": "EAST", "kind": "mutex", "nodes": ["E1", "E2"]},
        {"id": "DOCK", "kind": "ban", "nodes": ["D2"], "banned_types": ["wide", "tugger"]}]
    spec = validate(LayoutSpec, data, "zones.yaml", "")
    lif = layout_to_lif(spec)
    assert [z["kind"] for z in lif["layouts"][0]["fleetSim"]["traffic_zones"]] == \
        ["same_direction", "mutex", "mutex", "ban"]
    imported = export_import(spec, tmp_path)
    assert imported.spec == spec and imported.notes == ()
    written = tmp_path / "back.yaml"
    written.write_text(layout_yaml(imported.spec, imported.comments()), encoding="utf-8")
    after = load_layout(written)
    assert after.spec == spec
    assert after.traffic_zones == layout_from_spec(spec, "zones.yaml").traffic_zones
    assert lif_json(layout_to_lif(after.spec)) == lif_json(lif)  # and out again, the same bytes
