"""Traffic zones of the layout: mutex zones (at most N AGVs inside, held by traffic control),
ban zones (some vehicle types never enter), same-direction zones (AGVs inside a two-way aisle
all drive it one way), their zone_wait_s KPI, their validation and drawing."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import pytest
import yaml

from fleet_sim.analysis.kpis import compute_kpis, is_kpi_name
from fleet_sim.config.layout import BACKWARD, FORWARD, LayoutSpec, layout_yaml, load_layout
from fleet_sim.config.scenario import load_layout_for, parse_scenario
from fleet_sim.errors import InputError
from fleet_sim.model.records import OccupancySpell
from fleet_sim.report.layout_plot import draw_layout
from fleet_sim.sim.engine import build_model
from tests.conftest import DATA, LAYOUTS
from tests.test_fleet_types import AISLE_NODES, aisle_layout

EAST = ["S3", "SE", "E1", "NE"]


def zoned_loop(folder: Path, capacity: int) -> Path:
    data: dict[str, Any] = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text("utf-8"))
    data["traffic_zones"] = [{"id": "EAST", "kind": "mutex", "nodes": EAST[:2],
                              "segments": [["SE", "E1"], ["E1", "NE"]], "capacity": capacity}]
    path = folder / "zoned.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def most_inside(spells: list[OccupancySpell], nodes: set[str]) -> int:
    """The most AGVs holding a node of `nodes` at one time."""
    changes = sorted([(s.start_s, 1, s.agv) for s in spells if s.key in nodes]
                     + [(s.end_s, -1, s.agv) for s in spells if s.key in nodes])
    holds: dict[int, int] = {}
    most = 0
    for _, step, agv in changes:  # at equal times, leaving (-1) sorts before entering
        holds[agv] = holds.get(agv, 0) + step
        most = max(most, sum(1 for n in holds.values() if n > 0))
    return most


def run_loop(folder: Path, capacity: int) -> tuple[Any, dict[str, Any]]:
    zoned_loop(folder, capacity)
    scenario = parse_scenario({"layout": "zoned.yaml", "duration_h": 8, "warmup_h": 0.5,
                               "seed": 5, "fleet": {"size": 4},
                               "demand": {"rate_per_hour": 60},
                               "charging": {"enabled": False}}, "<test>", folder)
    layout = load_layout_for(scenario, "<test>")
    model = build_model(scenario, layout, record_occupancy=True)
    model.env.run(until=scenario.duration_s)
    return model, compute_kpis(model.recorder, scenario, layout.name)


def test_a_mutex_zone_of_capacity_one_never_holds_two_agvs(tmp_path: Path) -> None:
    model, figures = run_loop(tmp_path, 1)
    nodes = [s for s in model.recorder.occupancy if s.kind == "node"]
    assert most_inside(nodes, set(EAST)) == 1
    zone = sorted((s.start_s, s.end_s) for s in model.recorder.occupancy if s.kind == "zone")
    assert len(zone) > 300
    assert all(end <= nxt for (_, end), (nxt, _) in itertools.pairwise(zone))
    assert figures["zone_wait_s"]["EAST"] > 60  # the zone made AGVs wait
    assert figures["throughput_per_hour"] > 40


def test_a_mutex_zone_of_capacity_two_holds_two_and_never_three(tmp_path: Path) -> None:
    model, figures = run_loop(tmp_path, 2)
    nodes = [s for s in model.recorder.occupancy if s.kind == "node"]
    assert most_inside(nodes, set(EAST)) == 2
    assert figures["zone_wait_s"]["EAST"] < run_loop(tmp_path, 1)[1]["zone_wait_s"]["EAST"]
    assert is_kpi_name("zone_wait_s.EAST")


def test_a_banned_type_never_enters_a_ban_zone(tmp_path: Path) -> None:
    path = aisle_layout(tmp_path)
    data = yaml.safe_load(path.read_text("utf-8"))
    for item in data["segments"] + data["stations"]:
        item.pop("allowed_types", None)
    data["traffic_zones"] = [{"id": "AISLE", "kind": "ban", "nodes": sorted(AISLE_NODES),
                              "banned_types": ["wide"]}]
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    scenario = parse_scenario({
        "layout": "aisle_loop.yaml", "duration_h": 4, "warmup_h": 0.2, "seed": 3,
        "fleet": {"vehicles": [{"type": "narrow", "count": 2}, {"type": "wide", "count": 2}]},
        "demand": {"rate_per_hour": 50, "flows": [{"from": "PICK", "to": "DROP"},
                                                  {"from": "PICK2", "to": "DROP"}]},
        "charging": {"enabled": False}}, "<test>", tmp_path)
    layout = load_layout_for(scenario, "<test>")
    model = build_model(scenario, layout, record_occupancy=True)
    model.env.run(until=scenario.duration_s)
    for spell in model.recorder.occupancy:
        if spell.agv in (2, 3):
            assert not set(spell.key.split(">")) & AISLE_NODES, spell
    served = [o for o in model.recorder.orders if o.pickup == "PICK2" and o.delivered_s]
    assert len(served) > 20 and {o.agv for o in served} <= {0, 1}


def test_traffic_zones_are_written_back_and_drawn(tmp_path: Path) -> None:
    layout = load_layout(zoned_loop(tmp_path, 2))
    again = tmp_path / "again.yaml"
    again.write_text(layout_yaml(layout.spec), encoding="utf-8")
    assert load_layout(again).spec == layout.spec
    assert isinstance(layout.spec, LayoutSpec)
    png = draw_layout(layout, tmp_path / "zoned.png")
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize(("zone", "message"), [
    ({"id": "Z", "kind": "mutex", "nodes": ["ZZ"]}, r"traffic_zones\[0\].nodes\[0\]: got 'ZZ'"),
    ({"id": "Z", "kind": "mutex", "segments": [["SW", "NW"]]},
     r"traffic_zones\[0\].segments\[0\]: got 'SW -> NW'"),
    ({"id": "Z", "kind": "mutex", "nodes": ["SW"], "capacity": 0}, r"traffic_zones\[0\].capacity"),
    ({"id": "Z", "kind": "ban", "nodes": ["SW"]}, r"traffic_zones\[0\].banned_types: got \[\]"),
    ({"id": "Z", "kind": "mutex", "nodes": ["K"]}, r"traffic_zones\[0\].nodes: got 'K'"),
    ({"id": "Z", "kind": "one_way_only", "nodes": ["SW"]}, r"traffic_zones\[0\].kind"),
    ({"id": "Z", "kind": "mutex"}, r"traffic_zones\[0\]: got 'Z'; expected a zone with nodes"),
])
def test_bad_traffic_zones_are_named(tmp_path: Path, zone: dict[str, Any], message: str) -> None:
    data: dict[str, Any] = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text("utf-8"))
    data["traffic_zones"] = [zone]
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(InputError, match=message):
        load_layout(path)


# ---- same-direction zones ----------------------------------------------------------------------

AISLE = ["B", "A1", "A2", "A3", "T"]
"""The aisle of tests/data/aisle_crossing.yaml, from the bottom of the loop to its top."""


def crossing(folder: Path, zones: list[dict[str, Any]] | None = None) -> Path:
    """tests/data/aisle_crossing.yaml with `zones` (default: the aisle same-direction)."""
    data: dict[str, Any] = yaml.safe_load((DATA / "aisle_crossing.yaml").read_text("utf-8"))
    data["traffic_zones"] = zones if zones is not None else [
        {"id": "AISLE", "kind": "same_direction", "nodes": AISLE}]
    path = folder / "crossing.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


@pytest.mark.parametrize(("zone", "message"), [
    ({"nodes": AISLE, "segments": [["B", "A1"]]},
     r"traffic_zones\[0\].segments: got \[\['B', 'A1'\]\]; expected no segments for a "
     r"same_direction zone: list the aisle's nodes in order under `nodes`"),
    ({"nodes": ["B", "A1"]}, r"traffic_zones\[0\].nodes: got \['B', 'A1'\]; expected at least "
                             r"3 nodes in order along the aisle"),
    ({"nodes": ["B", "A2", "A1", "A3", "T"]},
     r"traffic_zones\[0\].nodes\[1\]: got 'A2'; expected a node joined to nodes\[0\] \(B\) by "
     r"a two-way segment"),
    ({"nodes": ["S2", "B", "A1", "A2"]},
     r"traffic_zones\[0\].nodes\[1\]: got 'B'; expected a node joined to nodes\[0\] \(S2\) by "
     r"a two-way segment"),
    ({"nodes": ["B", "A1", "A2", "A1", "B"]},
     r"traffic_zones\[0\].nodes\[3\]: got 'A1'; expected each node once"),
    ({"nodes": ["A1", "A2", "A3", "T"]},
     r"traffic_zones\[0\].nodes: got \['A1', 'A2', 'A3', 'T'\]; expected the whole two-way "
     r"aisle: its segment A1 -> B goes on beyond the zone's end"),
    ({"nodes": AISLE, "banned_types": ["wide"]},
     r"traffic_zones\[0\].banned_types: got \['wide'\]; expected none for a same_direction"),
    ({"nodes": AISLE, "capacity": 0}, r"traffic_zones\[0\].capacity"),
])
def test_bad_same_direction_zones_are_named(tmp_path: Path, zone: dict[str, Any],
                                            message: str) -> None:
    path = crossing(tmp_path, [{"id": "Z", "kind": "same_direction", **zone}])
    with pytest.raises(InputError, match=message) as raised:
        load_layout(path)
    assert str(raised.value).startswith(str(path))


def test_a_same_direction_zone_is_an_aisle_entered_at_its_ends_with_a_way_round(
        tmp_path: Path) -> None:
    data: dict[str, Any] = yaml.safe_load((DATA / "aisle_crossing.yaml").read_text("utf-8"))
    zone = {"id": "Z", "kind": "same_direction", "nodes": AISLE}
    side = {**data, "traffic_zones": [zone],
            "nodes": [*data["nodes"], {"id": "X", "x": 14, "y": 6}],
            "segments": [*data["segments"], {"from": "A2", "to": "X", "direction": "two_way"}]}
    path = tmp_path / "side.yaml"
    path.write_text(yaml.safe_dump(side, sort_keys=False), encoding="utf-8")
    with pytest.raises(InputError, match=r"traffic_zones\[0\].nodes\[2\]: got 'A2'; expected a "
                                         r"node joined only to its neighbours in the list \(a "
                                         r"segment joins it to X"):
        load_layout(path)
    # the loop's top side bypasses T: from T the only way on is down the aisle
    top = [s for s in data["segments"] if (s["from"], s["to"]) != ("T", "N2")]
    cut = {**data, "traffic_zones": [zone],
           "segments": [*top, {"from": "N4", "to": "N2", "length_m": 9}]}
    path.write_text(yaml.safe_dump(cut, sort_keys=False), encoding="utf-8")
    with pytest.raises(InputError, match=r"traffic_zones\[0\].nodes: got \['B', 'A1', 'A2', "
                                         r"'A3', 'T'\]; expected an aisle with a way round: no "
                                         r"path outside the zone leads from its end T back"):
        load_layout(path)


def test_a_same_direction_zone_lifts_the_single_track_rule_of_its_aisle_only(
        tmp_path: Path) -> None:
    plain = load_layout(DATA / "aisle_crossing.yaml")
    zoned = load_layout(crossing(tmp_path))
    assert [c.id for c in plain.corridors] == [0] and zoned.corridors == []
    assert zoned.direction_zone_of("A1", "A2") == (zoned.traffic_zones[0], FORWARD)
    assert zoned.direction_zone_of("T", "A3") == (zoned.traffic_zones[0], BACKWARD)
    assert zoned.direction_zone_of("S2", "B") is None
    assert zoned.traffic_zones[0].nodes == {"A1", "A2", "A3"}  # its ends are its gates
    again = tmp_path / "again.yaml"
    again.write_text(layout_yaml(zoned.spec), encoding="utf-8")
    assert load_layout(again).spec == zoned.spec
