"""Scenario files: defaults from RSS-AGV-001 7.1, strict keys, resolved config, cross-checks."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel, ValidationError

from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import (
    Scenario,
    VehicleProfile,
    battery_hours,
    load_layout_for,
    load_scenario,
    resolved,
    setup_warnings,
)
from fleet_sim.config.trace import load_trace
from fleet_sim.config.vehicle import BatteryProfile
from fleet_sim.errors import InputError

from .conftest import LAYOUTS, ROOT, write_yaml


def test_vehicle_defaults_are_the_specs_parameters() -> None:
    profile = VehicleProfile()
    assert profile.max_speed_mps == 1.0  # P_001 VEL_MAX 1000 mm/s
    assert profile.accel_mps2 == 0.5  # P_002 VEL_ACC 500 mm/s2
    assert profile.decel_mps2 == 0.5  # P_003 VEL_DEC 500 mm/s2
    assert profile.turn_speed_mps == 0.3  # P_004 TURN_SPEED 300 mm/s, Req.Nav.005
    assert profile.min_gap_m == 0.5  # P_006 OBS_STOP_DIST 500 mm


def test_bundled_scenarios_load() -> None:
    from fleet_sim.config.experiment import load_experiment

    for path in sorted((ROOT / "experiments").glob("*.yaml")):
        if "scenario" in (yaml.safe_load(path.read_text(encoding="utf-8")) or {}):
            load_experiment(path)  # an experiment file
            continue
        scenario = load_scenario(path)
        load_layout_for(scenario, str(path))


def test_config_is_frozen() -> None:
    scenario = load_scenario(ROOT / "experiments" / "tiny_loop.yaml")
    with pytest.raises(ValidationError, match="frozen"):
        scenario.seed = 3  # type: ignore[misc]
    assert hash(scenario) == hash(load_scenario(ROOT / "experiments" / "tiny_loop.yaml"))


def test_resolved_config_writes_every_default_and_reloads(tmp_path: Path) -> None:
    scenario = load_scenario(ROOT / "experiments" / "tiny_loop.yaml")
    plain = resolved(scenario)
    assert plain["fleet"]["vehicle"]["turn_speed_mps"] == 0.3
    assert plain["dispatch"]["policy"] == "nearest_idle"
    assert plain["traffic"]["replan_after_s"] == 30.0
    assert plain["dispatch"]["max_active_agvs"] is None  # admission off: the spec's behaviour
    assert "_base_dir" not in plain
    assert plain["layout"] == str((LAYOUTS / "tiny_loop.yaml").resolve())  # runs from anywhere
    again = load_scenario(write_yaml(tmp_path / "again.yaml", plain))
    assert resolved(again) == plain
    assert again.model_copy(update={"layout": scenario.layout}).model_dump() == \
        scenario.model_dump()
    assert again.path(again.layout) == scenario.path(scenario.layout).resolve()


def test_overrides_copy_without_touching_the_original() -> None:
    scenario = load_scenario(ROOT / "experiments" / "tiny_loop.yaml")
    bigger = scenario.model_copy(update={"fleet": scenario.fleet.model_copy(update={"size": 5})})
    assert (scenario.fleet.size, bigger.fleet.size) == (2, 5)
    assert bigger.base_dir == scenario.base_dir and bigger.rules is scenario.rules


def test_overrides_by_dotted_key() -> None:
    scenario = load_scenario(ROOT / "experiments" / "tiny_loop.yaml",
                             {"fleet.size": 3, "demand.rate_per_hour": 12.5})
    assert scenario.fleet.size == 3 and scenario.demand.rate_per_hour == 12.5


@pytest.mark.parametrize("data,element,expected", [
    ({"layout": "x.yaml", "fleet": {"sise": 3}}, "fleet.sise", "no such key"),
    ({"layout": "x.yaml", "fleet": {"size": 0}}, "fleet.size", "an integer in [1, 2000]"),
    ({"layout": "x.yaml", "fleet": {"size": "many"}}, "fleet.size", "an integer"),
    ({"layout": "x.yaml", "duration_h": 1, "warmup_h": 2}, "warmup_h", "shorter than"),
    ({"layout": "x.yaml", "dispatch": {"policy": "random"}}, "dispatch.policy",
     "one of 'nearest_idle', 'fcfs'"),
    ({"layout": "x.yaml", "demand": {"profile": [{"from_h": 3, "multiplier": 1}]}},
     "demand.profile", "the first at 0"),
    ({"layout": "x.yaml", "fleet": {"vehicle": {"accel_mps2": -1}}},
     "fleet.vehicle.accel_mps2", "a number > 0"),
    ({"fleet": {"size": 2}}, "layout", "required key"),
    ({"layout": "x.yaml", "traffic": {"congestion_cost_s": -1}}, "traffic.congestion_cost_s",
     "a number in [0, 3600]"),
    ({"layout": "x.yaml", "traffic": {"weak_wifi_cost_s": 1e9}}, "traffic.weak_wifi_cost_s",
     "a number in [0, 3600]"),
    ({"layout": "x.yaml", "dispatch": {"max_active_agvs": 0}}, "dispatch.max_active_agvs",
     "an integer in [1, 2000], or auto"),
    ({"layout": "x.yaml", "dispatch": {"max_active_agvs": 2.5}}, "dispatch.max_active_agvs",
     "an integer in [1, 2000], or auto"),
    ({"layout": "x.yaml", "dispatch": {"max_active_agvs": "automatic"}},
     "dispatch.max_active_agvs", "an integer in [1, 2000], or auto"),
    ({"layout": "x.yaml", "fleet": {"size": 3, "start_nodes": ["A", "B", "C"]},
      "dispatch": {"max_active_agvs": 2}}, "dispatch.max_active_agvs",
     "at least fleet.size (3) when the AGVs start on the track"),
])
def test_bad_scenarios(tmp_path: Path, data: dict[str, object], element: str,
                       expected: str) -> None:
    path = write_yaml(tmp_path / "s.yaml", data)
    with pytest.raises(InputError) as info:
        load_scenario(path)
    assert str(info.value).startswith(f"{path}: {element}: got ")
    assert expected in str(info.value)


def test_scenario_checked_against_its_layout(tmp_path: Path) -> None:
    path = write_yaml(tmp_path / "s.yaml", {
        "layout": str(LAYOUTS / "tiny_loop.yaml"),
        "demand": {"flows": [{"from": "PICK", "to": "NOWHERE"}]}})
    with pytest.raises(InputError, match=r"demand.flows\[0\].to: got 'NOWHERE'; expected a "
                                         r"dropoff station of layout tiny_loop \(DROP\)"):
        load_layout_for(load_scenario(path), str(path))
    too_many = write_yaml(tmp_path / "t.yaml", {"layout": str(LAYOUTS / "tiny_loop.yaml"),
                                                "fleet": {"size": 9}})
    with pytest.raises(InputError, match=r"fleet\.size: got 9; expected at most the parking"):
        load_layout_for(load_scenario(too_many), str(too_many))
    missing = write_yaml(tmp_path / "u.yaml", {"layout": "nope.yaml"})
    with pytest.raises(InputError, match=r"layout: got 'nope\.yaml'; expected an existing layout"):
        load_layout_for(load_scenario(missing), str(missing))


def test_trace_csv_errors_name_the_line(tmp_path: Path) -> None:
    layout = load_layout_for(load_scenario(ROOT / "experiments" / "tiny_loop.yaml"), "s")
    good = tmp_path / "ok.csv"
    good.write_text("time_s,pickup,dropoff,note\n30,PICK,DROP,a\n5,PICK,DROP,b\n")
    assert [o.time_s for o in load_trace(good, layout)] == [5.0, 30.0]
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,pickup,dropoff\n30,PICK,DROP\nsoon,PICK,DROP\n")
    with pytest.raises(InputError, match=r"bad.csv: row 3.time_s: got 'soon'; expected a number"):
        load_trace(bad, layout)
    endless = tmp_path / "endless.csv"
    endless.write_text("time_s,pickup,dropoff\n30,PICK,DROP\ninf,PICK,DROP\n")
    with pytest.raises(InputError, match=r"endless.csv: row 3.time_s: got 'inf'; expected a "
                                         r"finite number"):
        load_trace(endless, layout)
    early = tmp_path / "early.csv"
    early.write_text("time_s,pickup,dropoff\n-5,PICK,DROP\n")
    with pytest.raises(InputError, match=r"row 2.time_s: got '-5'; expected a number >= 0"):
        load_trace(early, layout)
    wrong = tmp_path / "wrong.csv"
    wrong.write_text("time_s,pickup,dropoff\n30,DROP,DROP\n")
    with pytest.raises(InputError, match=r"row 2.pickup: got 'DROP'; expected a pickup"):
        load_trace(wrong, layout)
    header = tmp_path / "header.csv"
    header.write_text("t,pickup,dropoff\n")
    with pytest.raises(InputError, match=r"header: got 't,pickup,dropoff'; expected columns"):
        load_trace(header, layout)


def test_scenario_type_is_a_pydantic_model() -> None:
    assert issubclass(Scenario, BaseModel)
    text = yaml.safe_dump(resolved(load_scenario(ROOT / "experiments" / "warehouse_shift.yaml")))
    assert "rate_per_hour: 90" in text


def test_an_experiment_file_is_not_a_scenario() -> None:
    with pytest.raises(InputError, match=r"expected a scenario file; run experiments with "
                                         r"`fleet-sim sweep`"):
        load_scenario(ROOT / "experiments" / "warehouse_sizing.yaml")


def test_known_keys_do_not_list_internal_ones(tmp_path: Path) -> None:
    path = write_yaml(tmp_path / "s.yaml", {"layout": "x.yaml", "colour": "red"})
    with pytest.raises(InputError) as info:
        load_scenario(path)
    assert "_base_dir" not in str(info.value)
    assert "known keys: layout, name, description, duration_h" in str(info.value)
    internal = write_yaml(tmp_path / "t.yaml", {"layout": "x.yaml", "_base_dir": "/etc"})
    with pytest.raises(InputError, match=r"_base_dir: got '/etc'; expected no such key"):
        load_scenario(internal)


# ---- the battery switch and the battery traps ----------------------------------------------


@pytest.mark.parametrize("off", ["off", "false", "null", "'off'"])
def test_battery_off_is_written_out_and_reloads(tmp_path: Path, off: str) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(f"layout: {LAYOUTS / 'tiny_loop.yaml'}\nfleet:\n  vehicle:\n"
                    f"    battery: {off}\n", encoding="utf-8")
    scenario = load_scenario(path)
    assert scenario.fleet.vehicle.battery is None
    plain = resolved(scenario)
    assert plain["fleet"]["vehicle"]["battery"] is None
    again = load_scenario(write_yaml(tmp_path / "again.yaml", plain))
    assert again.fleet.vehicle.battery is None and resolved(again) == plain
    assert load_scenario(ROOT / "experiments" / "warehouse_shift.yaml").fleet.vehicle.battery \
        == BatteryProfile()  # left out: the default battery


def test_the_schema_publishes_the_battery_switch() -> None:
    import jsonschema

    from fleet_sim.config.schemas import json_schema

    schema = json_schema("scenario")
    base = {"layout": "x.yaml"}
    for good in (False, None, {"idle_w": 5}):
        jsonschema.validate({**base, "fleet": {"vehicle": {"battery": good}}}, schema)
    for bad in (True, "on", 3, {"idle_w": -1}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate({**base, "fleet": {"vehicle": {"battery": bad}}}, schema)


def test_battery_hours_by_hand() -> None:
    vehicle = VehicleProfile()  # 960 Wh; 0.04 / 0.06 Wh/m at 1.0 m/s; idle 20 W; handling 100 W
    # 90 % -> 20 %: 672 Wh. Flat out: 20 W + 0.05 Wh/m x 3600 m/h = 200 W -> 3.36 h; idle 33.6 h
    assert battery_hours(vehicle, 90, 20) == pytest.approx((3.36, 33.6))
    slow = vehicle.model_copy(update={"max_speed_mps": 0.25})  # driving 65 W < handling 100 W
    assert battery_hours(slow, 90, 20).busy_h == pytest.approx(6.72)
    assert battery_hours(vehicle, 15, 20) == (0.0, 0.0)  # there already
    idle_free = vehicle.model_copy(update={"battery": BatteryProfile(idle_w=0)})
    assert battery_hours(idle_free, 90, 20).idle_h == math.inf
    assert battery_hours(vehicle.model_copy(update={"battery": None}), 90, 20) == \
        (math.inf, math.inf)


def _tiny(tmp_path: Path, **fields: object) -> tuple[Scenario, Layout]:
    path = write_yaml(tmp_path / "s.yaml", {"layout": str(LAYOUTS / "tiny_loop.yaml"),
                                            "fleet": {"size": 1}, **fields})
    scenario = load_scenario(path)
    return scenario, load_layout_for(scenario, str(path))


def test_charging_off_with_a_draining_battery_is_warned_with_its_run_down_time(
        tmp_path: Path) -> None:
    """The issue's scenario: one AGV, charging off, 100 h."""
    scenario, layout = _tiny(tmp_path, duration_h=100, charging={"enabled": False},
                             demand={"rate_per_hour": 15})
    (warning,) = setup_warnings(scenario, layout)
    assert warning.kind == "charging_off"
    assert warning.text == (
        "charging.enabled is false but the battery drains (fleet.vehicle.battery): from 90 % "
        "an AGV runs down to 20 % (P_050) and stops taking orders after about 3.4 h working "
        "flat out or 33.6 h idle, then stands until E_201 at 10 % 4.8 h later; the run is "
        "100 h. For no battery model set fleet.vehicle.battery: off")
    # a run too short to run the battery down, or no battery model: nothing to say
    short, _ = _tiny(tmp_path, duration_h=3, charging={"enabled": False})
    assert setup_warnings(short, layout) == []
    off, _ = _tiny(tmp_path, duration_h=100, charging={"enabled": False},
                   fleet={"size": 1, "vehicle": {"battery": "off"}})
    assert setup_warnings(off, layout) == []
    on_off, _ = _tiny(tmp_path, duration_h=100, fleet={"size": 1, "vehicle": {"battery": None}})
    assert setup_warnings(on_off, layout) == []  # charging on, but nothing to charge


def test_charging_on_without_a_charger_says_when_the_agvs_stop(tmp_path: Path) -> None:
    scenario, layout = _tiny(tmp_path, duration_h=1)
    (warning,) = setup_warnings(scenario, layout)
    # 90 % -> 30 % (the charging threshold): 576 Wh, 2.88 h at 200 W, 28.8 h at 20 W;
    # 30 % -> 10 % standing in the charger queue: 192 Wh at 20 W, 9.6 h
    assert (warning.kind, warning.text) == ("no_charger", (
        "charging is on but the layout has no charger: AGV 0 (1 of 1) will run down and stop "
        "with E_201: from 90 % to the charging threshold 30 %, where they stop taking orders, "
        "in about 2.9 h working flat out or 28.8 h idle, then E_201 at 10 % 9.6 h later"))


@pytest.mark.parametrize(("name", "hours"), [("tiny_loop", 100), ("warehouse_shift", 24)])
def test_bundled_scenarios_stay_meaningful_on_long_runs(name: str, hours: float) -> None:
    """A planner's --hours far beyond the shift: no silent run-down (no battery on the tiny
    loop; chargers in the warehouse), the demand is met, AGVs hardly ever stand Idle while
    orders wait, and when they do the reasons account for it."""
    from fleet_sim.analysis.kpi_sums import run_kpis
    from fleet_sim.sim.engine import simulate

    path = ROOT / "experiments" / f"{name}.yaml"
    scenario = load_scenario(path, {"duration_h": hours})
    layout = load_layout_for(scenario, str(path))
    assert setup_warnings(scenario, layout) == []
    figures = run_kpis(simulate(scenario, layout))
    assert figures["throughput_pct_of_demand"] >= 98
    assert "E_201" not in figures["errors_by_code"]
    assert figures["idle_with_orders_waiting_pct"] < 0.5
    assert sum(figures["idle_with_orders_waiting_pct_by_reason"].values()) == pytest.approx(
        figures["idle_with_orders_waiting_pct"], abs=1e-4)


# A vehicle must fit the track it drives (check_against_layout)

def _one_long_agv(tmp_path: Path, length_m: float, **fleet: object) -> Path:
    return write_yaml(tmp_path / "long.yaml", {
        "name": "long", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.5,
        "warmup_h": 0.0, "seed": 1, "demand": {"rate_per_hour": 40},
        "fleet": {"size": 1, "vehicle": {"battery": "off", "length_m": length_m}, **fleet}})


def test_a_vehicle_fits_the_loop_up_to_the_limit_the_simulation_shows(tmp_path: Path) -> None:
    """The tiny loop is 48 m, tags every 4 m: coming back to the pickup P, an AGV has driven
    44 m since it left it; with min_gap_m 0.5 m a 43.5 m vehicle clears P, a 44 m one does
    not (it would wait for its own tail for ever: no order delivered, no deadlock seen)."""
    from fleet_sim.sim.engine import simulate

    fits = _one_long_agv(tmp_path, 43.5)
    scenario = load_scenario(fits)
    run = simulate(scenario, load_layout_for(scenario, str(fits)))
    assert sum(o.delivered_s is not None for o in run.recorder.orders) >= 10
    too_long = _one_long_agv(tmp_path, 44.0)
    with pytest.raises(InputError) as info:
        load_layout_for(load_scenario(too_long), str(too_long))
    assert str(info.value) == (
        f"{too_long}: fleet.vehicle.length_m: got 44.0; expected a vehicle that fits the track "
        "of layout tiny_loop: at most 43.5 m (an AGV coming back to pickup PICK, node P, has "
        "driven at most 44 m since it left it, and its length plus min_gap_m 0.5 m must be "
        "clear of it)")


def test_the_vehicle_too_long_of_a_mixed_fleet_is_named(tmp_path: Path) -> None:
    path = write_yaml(tmp_path / "mixed.yaml", {
        "name": "mixed", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.5,
        "warmup_h": 0.0, "seed": 1, "demand": {"rate_per_hour": 40},
        "fleet": {"vehicles": [{"type": "short", "count": 1},
                               {"type": "tugger", "count": 1,
                                "vehicle": {"length_m": 1e6, "min_gap_m": 1.0}}]}})
    with pytest.raises(InputError, match=r"mixed.yaml: fleet.vehicles\[1\].vehicle.length_m: "
                                         r"got 1000000.0; expected a vehicle that fits the track "
                                         r"of layout tiny_loop: at most 43 m \("):
        load_layout_for(load_scenario(path), str(path))


def test_a_dead_end_spur_must_hold_the_vehicle(tmp_path: Path) -> None:
    """A drop-off at the end of a two-way spur: the AGV turns back on it, so the spur must be
    longer than the vehicle plus its gap (the way back in is from the spur's other end)."""
    layout = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text(encoding="utf-8"))
    assert layout["nodes"][8]["id"] == "D"
    del layout["nodes"][8]["kind"]  # D becomes a tag; the drop-off moves to X, 3 m north
    layout["nodes"].append({"id": "X", "x": 8, "y": 11, "kind": "station"})
    layout["segments"].append({"from": "D", "to": "X", "direction": "two_way"})
    layout["stations"][1]["nodes"] = ["X"]
    layout_file = write_yaml(tmp_path / "spur.yaml", layout)

    def scenario(length_m: float) -> Path:
        return write_yaml(tmp_path / f"s{length_m}.yaml", {
            "name": "spur", "layout": str(layout_file), "duration_h": 0.5, "warmup_h": 0.0,
            "seed": 1, "demand": {"rate_per_hour": 40},
            "fleet": {"size": 1, "vehicle": {"battery": "off", "length_m": length_m}}})

    fits = scenario(2.5)  # 2.5 + 0.5 = the spur's 3 m
    load_layout_for(load_scenario(fits), str(fits))
    too_long = scenario(2.6)
    with pytest.raises(InputError, match=r"got 2.6; expected a vehicle that fits the track of "
                                         r"layout tiny_loop: at most 2.5 m \(an AGV coming back "
                                         r"to dropoff DROP, node X, has driven at most 3 m"):
        load_layout_for(load_scenario(too_long), str(too_long))
