"""Layout files: the bundled layouts, validation messages, corridors and turns."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import networkx as nx
import pytest
import yaml

from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.errors import InputError

from .conftest import LAYOUTS, write_yaml


def test_bundled_warehouse_is_realistic(warehouse_layout: Layout) -> None:
    g = warehouse_layout.graph
    assert g.number_of_nodes() >= 150
    assert len(warehouse_layout.pickups) >= 6
    assert len(warehouse_layout.dropoffs) >= 10
    assert len(warehouse_layout.chargers) >= 4
    assert warehouse_layout.parking
    one_way = nx.DiGraph([(u, v) for u, v, d in g.edges(data=True) if not d["two_way"]])
    loop = max(nx.simple_cycles(one_way, length_bound=80), key=len)
    assert len(loop) >= 60, "a one-way main loop"
    aisles = [c for c in warehouse_layout.corridors if len(c.members) >= 5]
    assert len(aisles) >= 8, "two-way aisles"
    assert nx.is_strongly_connected(g)


def test_bundled_distribution_centre_is_large() -> None:
    layout = load_layout(LAYOUTS / "distribution_centre.yaml")
    assert layout.graph.number_of_nodes() >= 600
    assert nx.is_strongly_connected(layout.graph)


def test_tiny_loop(tiny_layout: Layout) -> None:
    assert [p.id for p in tiny_layout.pickups] == ["PICK"]
    assert [p.id for p in tiny_layout.dropoffs] == ["DROP"]
    assert tiny_layout.total_length_m == pytest.approx(48.0)


def test_length_defaults_to_straight_distance(tiny_layout: Layout) -> None:
    assert tiny_layout.graph.edges["SW", "S1"]["length_m"] == pytest.approx(4.0)


def test_turns_come_from_geometry(tiny_layout: Layout) -> None:
    assert tiny_layout.turn("S3", "SE", "E1") == "left"
    assert tiny_layout.turn("SW", "S1", "P") == "straight"
    assert tiny_layout.turn(None, "SW", "S1") == "straight"


def test_turn_right_and_reverse(warehouse_layout: Layout) -> None:
    # bottom side runs east; the pickup siding leaves it to the south: a right turn
    assert warehouse_layout.turn("M000", "M001", "Q01") == "right"
    # the west side runs south; its charger spurs point west: a right turn in, a reversal out
    assert warehouse_layout.turn("M065", "M066", "C01") == "right"
    assert warehouse_layout.turn("M066", "C01", "M066") == "reverse"


def test_corridors_are_the_two_way_chains(warehouse_layout: Layout) -> None:
    aisle = warehouse_layout.corridor_at("A01_04")
    assert aisle is not None
    assert {"A01_04", "A01_36", "D01"} <= aisle.members
    assert warehouse_layout.corridor_of("M003", "A01_04") is aisle
    assert warehouse_layout.corridor_of("M000", "M001") is None
    spur = warehouse_layout.corridor_at("C01")
    assert spur is not None and spur.members == {"C01"}


def _tiny() -> dict[str, Any]:
    data = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text())
    assert isinstance(data, dict)
    return data


def _mutate(path: Path, change: Any) -> Path:
    data = copy.deepcopy(_tiny())
    change(data)
    return write_yaml(path, data)


CASES = [
    ("unknown node", lambda d: d["segments"][0].update({"to": "NOPE"}),
     "segments[0].to", "'NOPE'", "the id of a node"),
    ("duplicate id", lambda d: d["nodes"][1].update({"id": "SW"}),
     "nodes[1].id", "'SW'", "a unique node id"),
    ("zero length", lambda d: d["segments"][2].update({"length_m": 0}),
     "segments[2].length_m", "0", "a number > 0"),
    ("negative length", lambda d: d["segments"][2].update({"length_m": -3}),
     "segments[2].length_m", "-3", "a number > 0"),
    ("shorter than the straight line", lambda d: d["segments"][2].update({"length_m": 2}),
     "segments[2].length_m", "2", "at least the straight distance"),
    ("no way out", lambda d: d["segments"].pop(3),
     "nodes[3]", "'S3'", "a node with a way out"),
    ("unreachable station", lambda d: (d["nodes"].append(
        {"id": "X", "x": 30, "y": 0, "kind": "station"}), d["segments"].append(
        {"from": "X", "to": "SE"}), d["stations"].append(
        {"id": "DROP2", "kind": "dropoff", "nodes": ["X"]})),
     "stations[2] (DROP2)", "'X'", "a node AGVs can reach"),
    ("unknown key", lambda d: d["segments"][0].update({"speed": 2}),
     "segments[0].speed", "2", "no such key"),
    ("wrong type", lambda d: d["nodes"][0].update({"x": "west"}),
     "nodes[0].x", "'west'", "a number"),
    ("station on a tag", lambda d: d["stations"][0].update({"nodes": ["S1"]}),
     "stations[0].nodes[0]", "'S1'", "a node of kind 'station'"),
    ("bad distribution", lambda d: d["stations"][0].update(
        {"handling": {"dist": "uniform", "low_s": 5}}),
     "stations[0].handling.high_s", "None", "a value for required key 'high_s'"),
    ("parameter the distribution does not take", lambda d: d["stations"][0].update(
        {"handling": {"dist": "fixed", "mean_s": 5, "sd_s": 1}}),
     "stations[0].handling.sd_s", "1", "no such key for dist 'fixed' (known keys: dist, mean_s)"),
    ("unknown distribution", lambda d: d["stations"][0].update(
        {"handling": {"dist": "gamma", "mean_s": 5}}),
     "stations[0].handling.dist", "'gamma'", "one of 'fixed', 'uniform', 'triangular'"),
    ("zone area of three numbers", lambda d: d.update(
        {"zones": [{"id": "Z", "area_m": [0, 0, 4]}]}),
     "zones[0].area_m", "[0, 0, 4]", "a list of 4 items"),
    ("a bool for a number", lambda d: d["nodes"][0].update({"y": True}),
     "nodes[0].y", "True", "a number"),
    ("no parking", lambda d: d.update({"parking": []}),
     "parking", "[]", "at least one parking area"),
    ("same pair twice", lambda d: d["segments"].append({"from": "SW", "to": "S1"}),
     "segments[12]", "'SW -> S1'", "one segment per pair of nodes"),
]


@pytest.mark.parametrize("name,change,element,value,expected", CASES, ids=[c[0] for c in CASES])
def test_validation_names_file_element_value_and_expectation(
        tmp_path: Path, name: str, change: Any, element: str, value: str, expected: str) -> None:
    path = _mutate(tmp_path / "bad.yaml", change)
    with pytest.raises(InputError) as info:
        load_layout(path)
    message = str(info.value)
    assert message.startswith(str(path))
    assert f": {element}: " in message, message
    assert f"got {value}" in message, message
    assert expected in message, message


def test_speed_limit_above_vehicle_maximum(tmp_path: Path) -> None:
    path = _mutate(tmp_path / "fast.yaml", lambda d: d["segments"][5].update(
        {"speed_limit_mps": 1.5}))
    load_layout(path)  # fine without a vehicle to compare with
    with pytest.raises(InputError, match=r"segments\[5\].speed_limit_mps: got 1.5; expected at "
                                         r"most the vehicle's maximum speed 1.0"):
        load_layout(path, max_speed_mps=1.0)


def test_charger_that_no_agv_can_leave(tmp_path: Path) -> None:
    def change(d: dict[str, Any]) -> None:
        d["nodes"].append({"id": "CH", "x": 8, "y": 4, "kind": "charger"})
        d["segments"].append({"from": "P", "to": "CH"})
        d["chargers"] = [{"id": "CHG", "node": "CH"}]
    with pytest.raises(InputError, match=r"nodes\[12\]: got 'CH'; expected a node with a way out"):
        load_layout(_mutate(tmp_path / "trap.yaml", change))


def test_missing_file_and_bad_yaml(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="expected an existing file"):
        load_layout(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("nodes: [\n")
    with pytest.raises(InputError, match="expected valid YAML"):
        load_layout(bad)
