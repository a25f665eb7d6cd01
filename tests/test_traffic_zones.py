"""Traffic zones of the layout: mutex zones (at most N AGVs inside, held by traffic control),
ban zones (some vehicle types never enter), same-direction zones (AGVs inside a two-way aisle
all drive it one way), their zone_wait_s KPI, their validation and drawing."""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
import simpy
import yaml

from fleet_sim.analysis.kpi_sums import compute_kpis
from fleet_sim.analysis.kpis import is_kpi_name
from fleet_sim.cli import main
from fleet_sim.config.layout import BACKWARD, FORWARD, load_layout
from fleet_sim.config.layout_spec import LayoutSpec
from fleet_sim.config.layout_yaml import layout_yaml
from fleet_sim.config.scenario import load_layout_for, load_scenario, parse_scenario
from fleet_sim.errors import InputError
from fleet_sim.model.records import OccupancySpell
from fleet_sim.report.layout_plot import ZONE_COLOUR, draw_layout, zone_rule
from fleet_sim.sim.engine import build_simulation
from fleet_sim.sim.traffic.locks import ZoneLock
from fleet_sim.sim.traffic.zones import ANY_DIRECTION, DirectedClaim, DirectionGate
from tests.conftest import DATA, LAYOUTS, ROOT
from tests.test_fleet_types import AISLE_NODES, aisle_layout
from tests.test_traffic import Client, make_traffic

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
    model = build_simulation(scenario, layout, record_occupancy=True)
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
    model = build_simulation(scenario, layout, record_occupancy=True)
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


def crossing_scenario(folder: Path, hours: float = 8, **fields: Any) -> dict[str, Any]:
    """Orders up the aisle (PICK1 -> DROP1), down it (PICK2 -> DROP2) and into its middle."""
    return {"name": "crossing", "layout": "crossing.yaml", "duration_h": hours,
            "warmup_h": 0.5, "seed": 5, "fleet": {"size": 6},
            "demand": {"rate_per_hour": 90, "flows": [
                {"from": "PICK1", "to": "DROP1"}, {"from": "PICK2", "to": "DROP2"},
                {"from": "PICK1", "to": "MID", "weight": 0.3},
                {"from": "PICK2", "to": "MID", "weight": 0.3}]},
            "charging": {"enabled": False}, **fields}


def run_crossing(folder: Path, zones: list[dict[str, Any]] | None = None) -> tuple[Any, Any]:
    crossing(folder, zones)
    scenario = parse_scenario(crossing_scenario(folder), "<test>", folder)
    layout = load_layout_for(scenario, "<test>")
    model = build_simulation(scenario, layout, record_occupancy=True)
    model.env.run(until=scenario.duration_s)
    return model, compute_kpis(model.recorder, scenario, layout.name)


Spell = tuple[float, float, int, int]


def aisle_spells(spells: list[OccupancySpell], aisle: list[str] = AISLE) -> list[Spell]:
    """Each AGV's stays inside `aisle`, from what it held and drove (not from the zone's
    lock), cut where it turns round: (start, end, agv, direction; +1 from the first node
    listed towards the last). An AGV is inside while it holds a node between the aisle's
    ends; it drives the way of its last hop along the aisle (before its first one, the way of
    that one)."""
    index = {n: i for i, n in enumerate(aisle)}
    inner = set(aisle[1:-1])
    holds: dict[int, list[tuple[float, float]]] = {}
    hops: dict[int, list[tuple[float, int]]] = {}
    for s in spells:
        if s.kind == "node" and s.key in inner:
            holds.setdefault(s.agv, []).append((s.start_s, s.end_s))
        elif s.kind == "segment":
            u, v = s.key.split(">")
            if u in index and v in index:
                hops.setdefault(s.agv, []).append((s.start_s, 1 if index[v] > index[u] else -1))
    out: list[Spell] = []
    for agv, spans in holds.items():
        stays: list[list[float]] = []
        for start, end in sorted(spans):
            if stays and start < stays[-1][1]:  # holds overlap all the way through a stay
                stays[-1][1] = max(stays[-1][1], end)
            else:
                stays.append([start, end])
        for start, end in stays:
            ways = sorted((t, d) for t, d in hops.get(agv, []) if start <= t < end)
            if not ways:  # a node taken as the run ended, not driven to yet
                continue
            since, way = start, ways[0][1]
            for t, d in ways[1:]:
                if d != way:  # it turns round here
                    out.append((since, t, agv, way))
                    since, way = t, d
            out.append((since, end, agv, way))
    return out


def still_held(model: Any) -> list[OccupancySpell]:
    """The nodes the AGVs held when the run ended (the recorder has them once let go)."""
    return [OccupancySpell("node", h.node, v.id, h.since_s, model.env.now)
            for v in model.vehicles for h in v.driver.held + v.driver.ahead]


def one_way_at_a_time(spells: list[Spell]) -> tuple[int, int]:
    """Fails if two AGVs are ever inside driving opposite ways; returns the most AGVs inside
    at once and how many times an AGV joined others inside."""
    most = shared = 0
    inside: dict[int, Spell] = {}
    for time_s, step, i in sorted([(p[0], 1, i) for i, p in enumerate(spells)]
                                  + [(p[1], -1, i) for i, p in enumerate(spells)]):
        if step < 0:  # at equal times, leaving sorts before entering
            del inside[i]
            continue
        inside[i] = spells[i]
        assert len({p[3] for p in inside.values()}) == 1, (time_s, inside)
        most = max(most, len({p[2] for p in inside.values()}))
        shared += len(inside) >= 2
    return most, shared


def test_a_same_direction_aisle_is_shared_one_way_at_a_time(tmp_path: Path) -> None:
    """8 hours, 6 AGVs, orders up and down a two-way aisle: never two AGVs inside driving it
    opposite ways (from their node holds and hops, not from the lock); AGVs do share it one
    way (two inside at once), turn round inside only when alone, and the zone makes AGVs
    wait."""
    model, figures = run_crossing(tmp_path)
    spells = aisle_spells(model.recorder.occupancy + still_held(model))
    most, shared = one_way_at_a_time(spells)
    up, down = sum(p[3] == 1 for p in spells), sum(p[3] == -1 for p in spells)
    assert up > 200 and down > 200
    assert most >= 2 and shared > 50
    turns = [p for p, q in itertools.pairwise(sorted(spells, key=lambda p: (p[2], p[0])))
             if p[2] == q[2] and p[1] == q[0] and p[3] != q[3]]
    assert len(turns) > 10  # alone, after a drop-off at MID, the next stop behind it
    assert figures["zone_wait_s"]["AISLE"] > 600
    assert figures["throughput_per_hour"] > 60


def test_without_the_zone_the_aisle_is_single_track(tmp_path: Path) -> None:
    """The same run with the aisle a plain two-way corridor: one AGV inside at a time (the
    zone is what lets them share it)."""
    model, figures = run_crossing(tmp_path, [])
    nodes = [s for s in model.recorder.occupancy if s.kind == "node"]
    assert most_inside(nodes, set(AISLE[1:-1])) == 1
    assert "zone_wait_s" not in figures


def test_the_gate_shares_one_way_queues_the_other_and_lets_a_turn_go_first() -> None:
    """The rule itself (fleet_sim.sim.traffic.zones.DirectionGate): one way shared; the other
    way waits, and so does every later AGV, in the order asked; a capacity; an AGV put inside
    takes the way of those inside; an AGV turning round inside goes before every waiter once
    alone."""
    env = simpy.Environment()
    gate = DirectionGate(env, ZoneLock("Z"), capacity=None)
    a = DirectedClaim(gate, 0, FORWARD)
    b = DirectedClaim(gate, 1, FORWARD)
    assert a.triggered and b.triggered and gate.direction == FORWARD
    c = DirectedClaim(gate, 2, BACKWARD)
    d = DirectedClaim(gate, 3, FORWARD)  # would fit, but asked after c
    assert not c.triggered and not d.triggered
    assert gate.blockers(2) == (0, 1) and gate.blockers(3) == (2,)
    assert not gate.admits(FORWARD) and not gate.admits(BACKWARD)
    turn = DirectedClaim(gate, 1, BACKWARD, turn=True)  # AGV 1 must drive back
    assert list(gate.put_queue) == [turn, c, d] and gate.blockers(1) == (0,)
    gate.release(a)
    env.run()
    assert turn.triggered and not c.triggered  # alone: it may turn, before c
    gate.release(b)  # its claim the old way, given back
    env.run()
    assert c.triggered and not d.triggered and gate.direction == BACKWARD
    small = DirectionGate(env, ZoneLock("S"), capacity=1)
    assert DirectedClaim(small, 0, FORWARD).triggered
    assert not DirectedClaim(small, 1, FORWARD).triggered and small.blockers(1) == (0,)
    placed = DirectedClaim(gate, 4, ANY_DIRECTION)
    assert placed.triggered is False  # d asked before it
    assert DirectedClaim(DirectionGate(env, ZoneLock("E"), None), 5, ANY_DIRECTION).direction \
        == FORWARD


def test_a_deadlock_in_front_of_the_aisle_is_found_through_every_holder(tmp_path: Path) -> None:
    """AGV 0 drives up the aisle and waits for T, where AGV 2 stands wanting to drive down; AGV
    1 drives up ahead of AGV 0 and is not waiting. AGV 2 waits for both holders; the cycle
    runs through the second one (AGV 0), which the first-holder walk of a plain lock would
    miss. It is counted and broken as any other: AGV 2 takes the loop instead."""
    layout = load_layout(crossing(tmp_path))
    traffic = make_traffic(layout)
    gate = traffic.zone_locks["AISLE"]
    clients = [Client(0, "A3", goal="N2", next_node="T"), Client(1, "A2", goal="N2"),
               Client(2, "T", goal="S4", next_node="A3")]
    for c in clients:
        traffic.register(c)
    for c, direction in ((clients[1], FORWARD), (clients[0], FORWARD)):
        assert traffic.request(c.id, gate, direction=direction).triggered
    for c in clients:
        assert traffic.request(c.id, traffic.node_locks[c.node]).triggered
    assert not traffic.request(0, traffic.node_locks["T"]).triggered
    traffic.start_waiting(0, traffic.node_locks["T"])
    assert not traffic.request(2, gate, direction=BACKWARD).triggered
    traffic.start_waiting(2, gate)
    assert gate.holder == 1  # the first holder is not in the cycle
    escape = traffic.strategy.resolve_deadlock(clients[2])
    assert traffic.recorder.deadlocks == 1
    assert clients[2].notes[0] == ("deadlock_detected", "agvs 2 0 waiting for zone AISLE T")
    assert escape is not None and escape.kind == "reroute"
    assert escape.path[:3] == ("T", "N2", "D1") and "A3" not in escape.path
    # AGV 0, inside, has no way back against its claim: its detours keep off the aisle down
    assert traffic.against(0) == {("T", "A3"), ("A3", "A2"), ("A2", "A1"), ("A1", "B")}
    assert traffic.escape_for(clients[0]) is None


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


def test_a_same_direction_zone_is_drawn_as_a_band_with_its_forward_arrow(tmp_path: Path) -> None:
    """On the layout PNG: the aisle in the zone's colour (a band, an arrow from the first node
    listed to the last, the id and rule); the same layout without the zone has none of it."""
    import matplotlib.image

    teal = np.array([int(ZONE_COLOUR["same_direction"][i:i + 2], 16) for i in (1, 3, 5)])

    def teal_pixels(png: Path) -> tuple[int, int]:
        image = (matplotlib.image.imread(png)[:, :, :3] * 255).round().astype(int)
        weight = 255 - teal  # how much teal over white each pixel is
        share = ((255 - image) * weight).sum(axis=2) / (weight * weight).sum()
        made = 255 - np.clip(share, 0, 1)[..., None] * weight
        teal_over_white = np.abs(image - made).max(axis=2) <= 12
        solid = int((teal_over_white & (share > 0.8)).sum())  # arrow and label
        tinted = int((teal_over_white & (share > 0.15) & (share < 0.4)).sum())  # the band
        return solid, tinted

    zoned = load_layout(crossing(tmp_path))
    assert zone_rule(zoned.traffic_zones[0]) == "same direction; forward B \u2192 T"
    solid, tinted = teal_pixels(draw_layout(zoned, tmp_path / "zoned.png"))
    assert solid > 150 and tinted > 1500, (solid, tinted)
    plain = teal_pixels(draw_layout(load_layout(crossing(tmp_path, [])), tmp_path / "plain.png"))
    assert plain[0] == 0 and plain[1] < 0.02 * tinted  # a few edges of other things


def test_the_bundled_same_direction_warehouse_keeps_every_aisle_one_way() -> None:
    """experiments/warehouse_same_direction.yaml (ten aisles same-direction only), its first
    3 hours: every aisle one way at a time, several of them shared."""
    scenario = load_scenario(ROOT / "experiments" / "warehouse_same_direction.yaml")
    scenario = scenario.model_copy(update={"duration_h": 3.0})
    layout = load_layout_for(scenario, "<test>")
    model = build_simulation(scenario, layout, record_occupancy=True)
    model.env.run(until=3 * 3600.0)
    occupancy = model.recorder.occupancy + still_held(model)
    shared_aisles = 0
    for zone in layout.traffic_zones:
        most, _ = one_way_at_a_time(aisle_spells(occupancy, list(zone.path)))
        shared_aisles += most >= 2
    assert shared_aisles >= 3
    figures = compute_kpis(model.recorder, scenario, layout.name)
    assert set(figures["zone_wait_s"]) == {f"AISLE{i:02d}" for i in range(1, 11)}
    assert figures["throughput_per_hour"] > 60


def test_the_published_layout_schema_knows_same_direction_zones(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema", "layout"]) == 0
    schema = json.loads(capsys.readouterr().out)
    zone = schema["$defs"]["TrafficZoneSpec"]
    assert zone["properties"]["kind"]["enum"] == ["mutex", "ban", "same_direction"]
    assert "same_direction" in zone["description"]
    data = yaml.safe_load((LAYOUTS / "warehouse_same_direction.yaml").read_text("utf-8"))
    jsonschema.validate(data, schema, cls=jsonschema.Draft202012Validator)
    data["traffic_zones"][0]["kind"] = "same_way"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(data, schema, cls=jsonschema.Draft202012Validator)


def test_agvs_put_inside_the_aisle_and_faults_keep_it_one_way(tmp_path: Path) -> None:
    """Two AGVs start inside the aisle (they take the zone the way of those inside), AGVs fail
    (two inside it: they hold it until taken off the track, and come back onto the track where
    they stood) and meet obstacles: still never two AGVs inside driving opposite ways."""
    crossing(tmp_path)
    raw = crossing_scenario(tmp_path, hours=4)
    raw["fleet"] = {"size": 6, "start_nodes": ["A1", "A3", "S2", "N4", "E1", "P1"]}
    raw["incidents"] = {"obstacle_rate_per_km": 3, "cpu_reset": "operator", "faults": [
        {"agv": i % 6, "at_s": 900 + 311 * i, "code": "E_999"} for i in range(24)]}
    scenario = parse_scenario(raw, "<test>", tmp_path)
    layout = load_layout_for(scenario, "<test>")
    model = build_simulation(scenario, layout, record_occupancy=True)
    model.env.run(until=scenario.duration_s)
    most, _ = one_way_at_a_time(aisle_spells(model.recorder.occupancy + still_held(model)))
    assert most >= 2
    inside = [e for e in model.recorder.events
              if e.event == "Event_Critical_Error" and e.node in AISLE[1:-1]]
    assert len(inside) >= 2
    figures = compute_kpis(model.recorder, scenario, layout.name)
    assert figures["throughput_per_hour"] > 50 and figures["zone_wait_s"]["AISLE"] > 0
