"""Mixed fleets: vehicle types from profiles, per-type routes and speeds, segments and stations
open to some types only, dispatch by type, and the per-type KPIs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from agv_model.profile import load_profile
from fleet_sim.analysis.kpi_sums import compute_kpis
from fleet_sim.analysis.kpis import is_kpi_name, kpi_value
from fleet_sim.config.layout import load_layout
from fleet_sim.config.scenario import (
    check_against_layout,
    load_layout_for,
    load_scenario,
    parse_scenario,
    resolved,
)
from fleet_sim.config.standards.factsheet_profile import import_factsheet
from fleet_sim.config.trace import TraceOrder
from fleet_sim.errors import InputError
from fleet_sim.sim.engine import build_simulation, simulate
from tests.conftest import DATA, LAYOUTS

AISLE_NODES = {"A1", "Q", "A3"}


def aisle_layout(folder: Path) -> Path:
    """The tiny loop with a side aisle under its south side (S1 -> A1 -> Q -> A3 -> S3) that
    only type `narrow` may drive, and a pickup station PICK2 at Q that only `narrow` serves."""
    data: dict[str, Any] = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text("utf-8"))
    data["name"] = "aisle_loop"
    data["nodes"] += [{"id": "A1", "x": 4, "y": -4}, {"id": "Q", "x": 8, "y": -4,
                                                      "kind": "station"},
                      {"id": "A3", "x": 12, "y": -4}]
    data["segments"] += [{"from": a, "to": b, "allowed_types": ["narrow"]}
                         for a, b in (("S1", "A1"), ("A1", "Q"), ("Q", "A3"), ("A3", "S3"))]
    data["stations"].append({"id": "PICK2", "kind": "pickup", "nodes": ["Q"],
                             "handling": {"dist": "fixed", "mean_s": 10},
                             "allowed_types": ["narrow"]})
    path = folder / "aisle_loop.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def mixed(folder: Path, **fields: Any) -> dict[str, Any]:
    aisle_layout(folder)
    return {"name": "mixed", "layout": "aisle_loop.yaml", "duration_h": 4, "warmup_h": 0.2,
            "seed": 3,
            "fleet": {"vehicles": [{"type": "narrow", "count": 2},
                                   {"type": "wide", "count": 2,
                                    "vehicle": {"max_speed_mps": 0.5, "length_m": 1.5}}]},
            "demand": {"rate_per_hour": 50,
                       "flows": [{"from": "PICK", "to": "DROP"}, {"from": "PICK2", "to": "DROP"}]},
            "charging": {"enabled": False}, **fields}


def run_mixed(folder: Path, **fields: Any) -> Any:
    scenario = parse_scenario(mixed(folder, **fields), "<test>", folder)
    layout = load_layout_for(scenario, "<test>")
    model = build_simulation(scenario, layout, record_occupancy=True)
    model.env.run(until=scenario.duration_s)
    return scenario, layout, model


def test_a_type_never_enters_an_aisle_closed_to_it(tmp_path: Path) -> None:
    _, _, model = run_mixed(tmp_path)
    wide = {2, 3}
    for spell in model.recorder.occupancy:
        if spell.agv in wide:
            nodes = set(spell.key.split(">"))
            assert not nodes & AISLE_NODES, spell
    for event in model.recorder.events:
        if event.agv in wide:
            assert event.node not in AISLE_NODES, event
    orders = model.recorder.orders
    at_pick2 = [o for o in orders if o.pickup == "PICK2" and o.delivered_s is not None]
    assert len(at_pick2) > 20  # the aisle is used, by the narrow type only
    assert {o.agv for o in at_pick2} <= {0, 1}
    assert any(o.agv in wide for o in orders if o.delivered_s is not None)  # wide AGVs work


def test_each_type_drives_at_its_own_top_speed(tmp_path: Path) -> None:
    _, layout, model = run_mixed(tmp_path)
    fastest = {0: 1.0, 1: 1.0, 2: 0.5, 3: 0.5}
    hops = 0
    for spell in model.recorder.occupancy:
        if spell.kind != "segment":
            continue
        u, v = spell.key.split(">")
        length = layout.graph.edges[u, v]["length_m"]
        assert spell.end_s - spell.start_s >= length / fastest[spell.agv] - 1e-9, spell
        hops += 1
    assert hops > 1000
    wide_spells = [s for s in model.recorder.occupancy if s.kind == "segment" and s.agv >= 2]
    assert min(s.end_s - s.start_s for s in wide_spells) > 4 / 1.0  # never at 1 m/s


def test_kpis_per_type_add_up(tmp_path: Path) -> None:
    scenario, layout, model = run_mixed(tmp_path)
    figures = compute_kpis(model.recorder, scenario, layout.name)
    by_type = figures["by_type"]
    assert list(by_type)[:2] == ["narrow.agvs", "narrow.orders_completed"]
    assert by_type["narrow.agvs"] + by_type["wide.agvs"] == figures["agvs"] == 4
    assert by_type["narrow.orders_completed"] + by_type["wide.orders_completed"] \
        == figures["orders_completed"]
    assert by_type["narrow.throughput_per_hour"] + by_type["wide.throughput_per_hour"] \
        == pytest.approx(figures["throughput_per_hour"], abs=1e-5)
    utilisation = (by_type["narrow.agv_utilisation_pct"] + by_type["wide.agv_utilisation_pct"]) / 2
    assert utilisation == pytest.approx(figures["agv_utilisation_pct"], abs=1e-4)
    assert kpi_value(figures, "by_type.wide.throughput_per_hour") \
        == by_type["wide.throughput_per_hour"]
    assert is_kpi_name("by_type.wide.throughput_per_hour")
    assert not is_kpi_name("by_type.wide.speed")


def test_an_idle_agv_of_the_wrong_type_is_recorded_not_dispatched(tmp_path: Path) -> None:
    _, _, model = run_mixed(tmp_path)
    passed = [e for e in model.recorder.events
              if e.event == "not_dispatched" and e.detail == "type_not_allowed"]
    assert passed and {e.agv for e in passed} <= {2, 3}
    for e in passed:  # every order waiting then was one the AGV's type may not serve
        waiting = [o for o in model.recorder.orders if o.created_s <= e.time_s
                   and (o.assigned_s is None or o.assigned_s > e.time_s)]
        assert waiting and {o.pickup for o in waiting} == {"PICK2"}


def test_an_order_no_type_may_serve_fails_when_created(tmp_path: Path) -> None:
    data = mixed(tmp_path, demand={"kind": "trace", "trace_csv": "orders.csv"})
    data["fleet"] = {"vehicles": [{"type": "wide", "count": 2}]}
    scenario = parse_scenario(data, "<test>", tmp_path)
    layout = load_layout(tmp_path / "aisle_loop.yaml")
    model = build_simulation(scenario, layout, [TraceOrder(10.0, "PICK2", "DROP"),
                                           TraceOrder(20.0, "PICK", "DROP")])
    model.env.run(until=600)
    lost, served = model.recorder.orders
    assert (lost.failed_s, lost.failure, lost.agv) == (10.0, "type_not_allowed", None)
    assert served.delivered_s is not None


def test_a_flow_no_type_may_serve_is_refused(tmp_path: Path) -> None:
    data = mixed(tmp_path)
    data["fleet"] = {"vehicles": [{"type": "wide", "count": 2}, {"type": "odd", "count": 1}]}
    scenario = parse_scenario(data, "<test>", tmp_path)
    with pytest.raises(InputError, match=r"demand.flows\[1\]: got 'PICK2 -> DROP'"):
        load_layout_for(scenario, "<test>")


def test_a_type_cut_off_from_parking_is_refused(tmp_path: Path) -> None:
    scenario = parse_scenario(mixed(tmp_path), "<test>", tmp_path)
    layout = load_layout(tmp_path / "aisle_loop.yaml")
    spec = layout.spec.model_copy(update={"segments": tuple(
        s.model_copy(update={"allowed_types": ("narrow",)}) if s.from_node == "NW" else s
        for s in layout.spec.segments)})
    from fleet_sim.config.layout import layout_from_spec
    closed = layout_from_spec(spec, "<layout>")
    with pytest.raises(InputError, match=r"fleet.vehicles\[1\].type: got 'wide'.*parking PARK"):
        check_against_layout(scenario, closed, "<test>")


def test_a_profile_fills_the_vehicle_and_the_resolved_config_reloads(tmp_path: Path) -> None:
    imported = import_factsheet(DATA / "tugger.factsheet.json")
    (tmp_path / "profiles").mkdir()
    (tmp_path / "profiles" / "tugger.yaml").write_text(imported.text(), encoding="utf-8")
    data = mixed(tmp_path)
    data["fleet"]["vehicles"][1] = {"type": "tugger", "count": 1,
                                    "profile": "profiles/tugger.yaml",
                                    "vehicle": {"min_gap_m": 0.8, "battery": {"idle_w": 5}}}
    data["fleet"]["vehicles"].append({"type": "carriro", "count": 1,
                                      "profile": "carriro-ad-plus"})
    path = tmp_path / "mixed.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    scenario = load_scenario(path)
    tugger = scenario.fleet.type_profiles["tugger"]
    kin = imported.data["kinematics"]
    assert tugger.max_speed_mps == kin["max_speed_mmps"] / 1000
    assert tugger.length_m == kin["length_mm"] / 1000
    assert tugger.min_gap_m == 0.8 and tugger.battery.idle_w == 5  # the vehicle's own win
    carriro = load_profile("carriro-ad-plus")
    bridged = scenario.fleet.type_profiles["carriro"].battery
    per_m = carriro.battery.moving_w / (carriro.kinematics.max_speed_mmps / 1000 * 3600)
    assert bridged.drive_wh_per_m == pytest.approx(per_m)
    assert bridged.drive_loaded_wh_per_m == pytest.approx(1.5 * per_m)
    assert bridged.capacity_wh == carriro.battery.capacity_wh
    assert scenario.fleet.size == 4
    assert scenario.fleet.agv_types == ("narrow", "narrow", "tugger", "carriro")
    plain = resolved(scenario)
    assert "size" not in plain["fleet"] and "vehicle" not in plain["fleet"]
    elsewhere = tmp_path / "results"
    elsewhere.mkdir()
    again = elsewhere / "config.resolved.yaml"
    again.write_text(yaml.safe_dump(plain, sort_keys=False), encoding="utf-8")
    assert resolved(load_scenario(again)) == plain  # the profile named by absolute path
    assert load_scenario(again).fleet.agv_profiles == scenario.fleet.agv_profiles


def test_a_one_type_fleet_is_written_and_reported_as_before(tmp_path: Path) -> None:
    scenario = parse_scenario({"layout": "tiny_loop.yaml", "duration_h": 0.5, "warmup_h": 0.1,
                               "fleet": {"size": 2}}, "<test>", LAYOUTS)
    assert "vehicles" not in resolved(scenario)["fleet"]
    run = simulate(scenario, load_layout(LAYOUTS / "tiny_loop.yaml"))
    assert "by_type" not in compute_kpis(run.recorder, scenario, "tiny_loop")


@pytest.mark.parametrize(("fleet", "message"), [
    ({"size": 3, "vehicles": [{"type": "a", "count": 2}]},
     r"fleet.size: got 3; expected the sum of fleet.vehicles' counts \(2\)"),
    ({"vehicle": {"max_speed_mps": 1}, "vehicles": [{"type": "a", "count": 2}]},
     r"fleet.vehicle: .*no fleet.vehicle with fleet.vehicles"),
    ({"vehicles": [{"type": "a", "count": 1}, {"type": "a", "count": 1}]},
     r"fleet.vehicles\[1\].type: got 'a'; expected a type named once"),
    ({"vehicles": [{"type": "a", "count": 1, "profile": "nowhere"}]},
     r"fleet.vehicles\[0\].profile: got 'nowhere'; expected a bundled profile"),
    ({"vehicles": [{"type": "a", "count": 0}]}, r"fleet.vehicles\[0\].count"),
])
def test_bad_fleets_are_named(fleet: dict[str, Any], message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_scenario({"layout": "tiny_loop.yaml", "fleet": fleet}, "<test>", LAYOUTS)


# Per-type speed limits on segments (speed_limit_mps_by_type)

SLOW_AISLE = (("SE", "E1"), ("E1", "NE"))
BYPASS = (("SE", "X1"), ("X1", "X2"), ("X2", "NE"))


def limited_layout(folder: Path, limits: dict[tuple[str, str], dict[str, float]],
                   bypass: bool = False) -> Path:
    """The tiny loop with per-type speed limits on some segments; `bypass`: a 16 m detour
    east of its 8 m east side (SE -> X1 -> X2 -> NE)."""
    data: dict[str, Any] = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text("utf-8"))
    data["name"] = "limited_loop"
    for seg in data["segments"]:
        if (seg["from"], seg["to"]) in limits:
            seg["speed_limit_mps_by_type"] = limits[seg["from"], seg["to"]]
    if bypass:
        data["nodes"] += [{"id": "X1", "x": 20, "y": 0}, {"id": "X2", "x": 20, "y": 8}]
        data["segments"] += [{"from": a, "to": b} for a, b in BYPASS]
    path = folder / "limited_loop.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def run_limited(folder: Path, limits: dict[tuple[str, str], dict[str, float]],
                bypass: bool = False) -> Any:
    limited_layout(folder, limits, bypass)
    data = {"name": "limited", "layout": "limited_loop.yaml", "duration_h": 2,
            "warmup_h": 0.2, "seed": 5,
            "fleet": {"vehicles": [{"type": "carrier", "count": 2},
                                   {"type": "heavy", "count": 2}]},
            "demand": {"rate_per_hour": 60}, "charging": {"enabled": False}}
    scenario = parse_scenario(data, "<test>", folder)
    layout = load_layout_for(scenario, "<test>")
    model = build_simulation(scenario, layout, record_occupancy=True)
    model.env.run(until=scenario.duration_s)
    return scenario, layout, model


def segment_times(model: Any, agvs: set[int], segment: tuple[str, str]) -> list[float]:
    key = ">".join(segment)
    return [s.end_s - s.start_s for s in model.recorder.occupancy
            if s.kind == "segment" and s.key == key and s.agv in agvs]


def test_a_type_never_drives_a_segment_faster_than_its_limit_there(tmp_path: Path) -> None:
    """heavy may drive the south side past the pickup at 0.4 m/s only; carrier AGVs (the same
    top speed, 1 m/s) drive it faster. Traversal times are the recorded segment spells."""
    south = (("P", "S3"), ("S3", "SE"))
    _, layout, model = run_limited(tmp_path, {seg: {"heavy": 0.4} for seg in south})
    heavy, carrier = {2, 3}, {0, 1}
    for seg in south:
        length = layout.graph.edges[seg]["length_m"]
        slow = segment_times(model, heavy, seg)
        fast = segment_times(model, carrier, seg)
        assert len(slow) > 20 and len(fast) > 20
        assert min(slow) >= length / 0.4 - 1e-9, seg
        assert min(fast) < length / 0.4 - 1.0, seg  # never held to heavy's limit
    elsewhere = segment_times(model, heavy, ("N3", "D"))  # no limit of its own: top speed
    assert min(elsewhere) < 4 / 0.4 - 1.0
    assert layout.speed_limit_mps("P", "S3", "heavy") == 0.4
    assert layout.speed_limit_mps("P", "S3", "carrier") == 1.0
    assert layout.speed_limit_mps("P", "S3") == 1.0


def test_a_type_slowed_on_a_segment_routes_around_it(tmp_path: Path) -> None:
    """The east side is 8 m, the bypass 16 m. heavy's limit of 0.2 m/s on the east side
    makes the bypass quicker for heavy only: heavy AGVs take it, carrier AGVs keep to the
    east side. Without the limit both types take the east side."""
    from fleet_sim.model.kinematics import Motion
    from fleet_sim.sim.traffic.routing import Routes

    _, layout, model = run_limited(tmp_path, {seg: {"heavy": 0.2} for seg in SLOW_AISLE},
                                   bypass=True)
    motion = Motion(1.0, 0.5, 0.5, 0.3)
    assert Routes(layout, motion, "heavy").route("S3", "N3") == ["S3", "SE", "X1", "X2", "NE",
                                                                  "N3"]
    assert Routes(layout, motion, "carrier").route("S3", "N3") == ["S3", "SE", "E1", "NE",
                                                                    "N3"]
    heavy, carrier = {2, 3}, {0, 1}
    assert len(segment_times(model, heavy, BYPASS[1])) > 20
    assert segment_times(model, heavy, SLOW_AISLE[0]) == []
    assert len(segment_times(model, carrier, SLOW_AISLE[0])) > 20
    assert segment_times(model, carrier, BYPASS[1]) == []
    _, _, plain = run_limited(tmp_path, {}, bypass=True)
    assert len(segment_times(plain, heavy, SLOW_AISLE[0])) > 20
    assert segment_times(plain, heavy | carrier, BYPASS[1]) == []


def test_a_one_type_fleet_named_in_a_limit_drives_at_it(tmp_path: Path) -> None:
    """A one-type fleet's vehicle.name is a type too; a layout whose limits name only other
    types runs exactly as without them."""
    limited_layout(tmp_path, {("P", "S3"): {"rss-agv-001": 0.25}})
    data = {"layout": "limited_loop.yaml", "duration_h": 0.5, "warmup_h": 0.1,
            "fleet": {"size": 1}, "charging": {"enabled": False}}
    scenario = parse_scenario(data, "<test>", tmp_path)
    model = build_simulation(scenario, load_layout_for(scenario, "<test>"), record_occupancy=True)
    model.env.run(until=scenario.duration_s)
    assert min(segment_times(model, {0}, ("P", "S3"))) >= 4 / 0.25 - 1e-9
    limited_layout(tmp_path, {("P", "S3"): {"heavy": 0.25}})
    other = simulate(scenario, load_layout_for(scenario, "<test>"))
    plain = simulate(scenario.model_copy(update={"layout": str(LAYOUTS / "tiny_loop.yaml")}),
                     load_layout(LAYOUTS / "tiny_loop.yaml"))
    assert other.recorder.orders == plain.recorder.orders
    assert other.recorder.events == plain.recorder.events


@pytest.mark.parametrize(("limits", "message"), [
    ({"heavy": 1.0}, r"segments\[1\].speed_limit_mps_by_type.heavy: got 1.0; expected a limit "
                     r"below the segment's speed limit 1 m/s"),
    ({"heavy": 0}, r"segments\[1\].speed_limit_mps_by_type.heavy"),
    ({"heavy": ".nan"}, r"segments\[1\].speed_limit_mps_by_type.heavy"),
    ({"heavy": "fast"}, r"segments\[1\].speed_limit_mps_by_type.heavy: got 'fast'"),
])
def test_bad_type_limits_are_named(tmp_path: Path, limits: dict[str, Any], message: str) -> None:
    path = limited_layout(tmp_path, {("S1", "P"): limits})
    path.write_text(path.read_text("utf-8").replace("'.nan'", ".nan"), encoding="utf-8")
    with pytest.raises(InputError, match=message) as caught:
        load_layout(path)
    assert str(path) in str(caught.value)


def test_a_type_limit_must_name_an_allowed_type_and_unknown_types_are_warned(
        tmp_path: Path) -> None:
    from fleet_sim.config.scenario import setup_warnings

    aisle_layout(tmp_path)
    path = tmp_path / "aisle_loop.yaml"
    data = yaml.safe_load(path.read_text("utf-8"))
    data["segments"][-1]["speed_limit_mps_by_type"] = {"wide": 0.5}
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(InputError, match=r"segments\[15\].speed_limit_mps_by_type.wide: got "
                                         r"'wide'; expected a type of the segment's "
                                         r"allowed_types \(narrow\)"):
        load_layout(path)
    data["segments"][-1]["speed_limit_mps_by_type"] = {"narow": 0.5}
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    with pytest.raises(InputError, match="allowed_types"):
        load_layout(path)
    data["segments"][-1]["allowed_types"] = []
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    scenario = parse_scenario(mixed(tmp_path), "<test>", tmp_path)
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    warnings = [w for w in setup_warnings(scenario, load_layout_for(scenario, "<test>"))
                if w.kind == "unknown_type_limit"]
    assert len(warnings) == 1
    assert "segments[15].speed_limit_mps_by_type names vehicle type 'narow', not a type of " \
           "the fleet (narrow, wide)" in warnings[0].text


def test_the_layout_schema_publishes_per_type_limits() -> None:
    from fleet_sim.config.schemas import json_schema

    field = json_schema("layout")["$defs"]["SegmentSpec"]["properties"]["speed_limit_mps_by_type"]
    assert field["type"] == "object" and field["default"] == {}
    assert field["additionalProperties"] == {"exclusiveMinimum": 0, "type": "number"}
