"""What-if variants in experiment files: overrides, another layout, layout changes, their
refusals, seeds and run ids (fleet_sim.config.experiment, fleet_sim.config.layout_changes)."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from fleet_sim.analysis.tables import stream_run
from fleet_sim.config.experiment import (
    BASE_VARIANT,
    Experiment,
    experiment_warnings,
    load_experiment,
    run_id,
    run_layout,
)
from fleet_sim.config.layout import Layout
from fleet_sim.config.layout_changes import SEGMENT_FIELDS
from fleet_sim.config.scenario import load_scenario
from fleet_sim.config.schemas import json_schema
from fleet_sim.errors import InputError

from .conftest import LAYOUTS, ROOT, write_yaml

SHIFT = str(ROOT / "experiments" / "warehouse_shift.yaml")
AISLE_3 = ["M007", "A03_04", "D11", "A03_12", "A03_16", "D03", "A03_24", "A03_28", "A03_32",
           "A03_36", "M051"]
"""The third two-way aisle of layouts/warehouse.yaml, from the south main road to the north."""


def whatif(tmp_path: Path, variants: dict[str, Any], **fields: Any) -> Path:
    data: dict[str, Any] = {"name": "whatif", "scenario": SHIFT,
                            "overrides": {"duration_h": 0.5, "warmup_h": 0.1},
                            "factors": {"fleet.size": [4, 6]}, "replications": 3,
                            "master_seed": 11, "variants": variants, **fields}
    return write_yaml(tmp_path / "whatif.yaml", data)


def changes(tmp_path: Path, *edits: dict[str, Any]) -> Experiment:
    return load_experiment(whatif(tmp_path, {"v": {"layout_changes": list(edits)}}))


def edges(layout: Layout) -> dict[tuple[str, str], dict[str, Any]]:
    """What the layout says about each hop (and its place in the file: `index`); not what
    the engine caches on the graph of a layout it ran on (free_time_s)."""
    return {(u, v): {k: data.get(k) for k in (*SEGMENT_FIELDS, "index")}
            for u, v, data in layout.graph.edges(data=True)}


# ---- resolved layouts ----------------------------------------------------------------------


def test_a_no_op_speed_limit_resolves_to_the_base_layout(tmp_path: Path) -> None:
    exp = changes(tmp_path, {"speed_limit": {"chain": ["M003", "M004", "M005", "M006"],
                                             "speed_mps": 1.0}})
    resolved = exp.variant_layout("v")
    assert resolved.layout is not resolved.baseline  # the changes were applied ...
    assert resolved.diff.empty  # ... and changed nothing
    assert edges(resolved.layout) == edges(resolved.baseline)  # segment order kept, too
    assert dict(resolved.layout.graph.nodes(data=True)) == \
        dict(resolved.baseline.graph.nodes(data=True))
    assert resolved.layout.places == resolved.baseline.places
    assert resolved.layout.corridors == resolved.baseline.corridors
    slower = changes(tmp_path, {"speed_limit": {"chain": ["M003", "M004", "M005", "M006"],
                                                "speed_mps": 0.8}}).variant_layout("v")
    assert slower.diff.changed_segments == (("M003", "M004"), ("M004", "M005"),
                                            ("M005", "M006"))
    assert slower.layout.speed_limit_mps("M004", "M005") == 0.8


def test_a_no_op_variant_runs_byte_identical_tables(tmp_path: Path) -> None:
    """The variant's run (its layout from run_layout, as a worker gets it) writes the same
    bytes as the baseline's run with the same seed; a real change does not."""
    exp = load_experiment(whatif(tmp_path, {
        "same": {"layout_changes": [{"speed_limit": {"chain": AISLE_3, "speed_mps": 1.0}}]},
        "slow": {"layout_changes": [{"speed_limit": {"chain": AISLE_3, "speed_mps": 0.3}}]}},
        overrides={"duration_h": 0.4, "warmup_h": 0.05}, factors={"fleet.size": [6]}))
    tables: dict[str, dict[str, bytes]] = {}
    for variant in (BASE_VARIANT, "same", "slow"):
        spec = exp.variant_runs(variant, [0])[0]
        scenario = load_scenario(spec.scenario_file, spec.override_dict())
        out = tmp_path / variant
        stream_run(scenario, run_layout(scenario, spec), out)
        tables[variant] = {name: (out / name).read_bytes()
                           for name in ("orders.parquet", "events.parquet")}
    assert tables["same"] == tables[BASE_VARIANT]
    assert tables["slow"]["events.parquet"] != tables[BASE_VARIANT]["events.parquet"]


def test_one_way_makes_exactly_the_named_segments_one_way(tmp_path: Path) -> None:
    exp = changes(tmp_path, {"one_way": AISLE_3})
    resolved = exp.variant_layout("v")
    base, new = edges(resolved.baseline), edges(resolved.layout)
    hops = list(itertools.pairwise(AISLE_3))
    for a, b in hops:
        assert base[(a, b)]["two_way"] and (b, a) in base  # two-way in the bundled layout
        assert (a, b) in new and not new[(a, b)]["two_way"]
        assert (b, a) not in new
    named = set(hops) | {(b, a) for a, b in hops}
    assert {k: v for k, v in base.items() if k not in named} == \
        {k: v for k, v in new.items() if k not in named}  # every other segment unchanged
    assert resolved.diff.changed_segments == tuple(sorted(hops))
    assert resolved.diff.removed_segments == tuple(sorted((b, a) for a, b in hops))
    assert resolved.diff.changed_nodes == ()
    # the aisle is no longer a single-track corridor; the other nine still are
    assert len(resolved.layout.corridors) == len(resolved.baseline.corridors) - 1
    assert resolved.layout.corridor_of("A03_12", "A03_16") is None


def test_one_way_turns_a_one_way_segment_and_two_way_opens_the_way_back(
        tmp_path: Path) -> None:
    loop = ["M030", "K1b", "PARK1", "K1a", "M026"]  # the parking loop, driven the other way
    turned = changes(tmp_path, {"one_way": loop},
                     {"two_way": ["M026", "M027"]}).variant_layout("v")
    new = edges(turned.layout)
    hops = list(itertools.pairwise(loop))
    for a, b in hops:
        assert (a, b) in new and (b, a) not in new and not new[(a, b)]["two_way"]
    assert new[("M026", "M027")]["two_way"] and new[("M027", "M026")]["two_way"]
    assert set(turned.diff.removed_segments) == {(b, a) for a, b in hops}
    assert set(turned.diff.changed_segments) == {*hops, ("M026", "M027"), ("M027", "M026")}


def test_places_are_added_moved_removed_and_changed(tmp_path: Path) -> None:
    exp = changes(
        tmp_path,
        {"add_node": {"id": "C05", "x": -4, "y": 0, "kind": "charger"}},
        {"add_segment": {"from": "M067", "to": "C05", "direction": "two_way"}},
        {"add_charger": {"id": "CHG05", "node": "C05", "power_kw": 4.5}},
        {"remove_charger": "CHG04"}, {"close_node": "C04"},
        {"move_parking": {"id": "PARK2", "node": "K2a"}},
        {"station_handling": {"id": "DROP03", "handling": {"dist": "fixed", "mean_s": 60}}},
        {"parking_capacity": {"id": "PARK1", "capacity": 20}},
        {"add_station": {"id": "DROP13", "kind": "dropoff", "nodes": ["A05_28"]}})
    resolved = exp.variant_layout("v")
    layout = resolved.layout
    assert sorted(c.id for c in layout.chargers) == ["CHG01", "CHG02", "CHG03", "CHG05"]
    assert layout.places["CHG05"].power_kw == 4.5 and layout.places["CHG05"].nodes == ("C05",)
    assert "C04" not in layout.graph
    assert layout.places["PARK2"].nodes == ("K2a",)
    assert layout.graph.nodes["K2a"]["kind"] == "parking"
    assert layout.graph.nodes["PARK2"]["kind"] == "tag"  # the node the parking area left
    handling = layout.places["DROP03"].handling
    assert handling is not None and handling.expected_s == 60
    assert layout.places["PARK1"].capacity == 20
    assert layout.places["DROP13"].kind == "dropoff"
    diff = resolved.diff
    assert diff.changed_places == ("CHG05", "DROP03", "DROP13", "PARK1", "PARK2")
    assert diff.removed_places == ("CHG04",)
    assert diff.removed_nodes == ("C04",)
    assert {"C05", "K2a", "PARK2", "D03", "A05_28", "PARK1"} <= set(diff.changed_nodes)
    assert set(diff.removed_segments) == {("M060", "C04"), ("C04", "M060")}


def test_run_layout_gives_the_worker_the_changed_layout_cached(tmp_path: Path) -> None:
    exp = changes(tmp_path, {"close_segment": ["A03_16", "D03"]})
    base_spec, variant_spec = exp.runs()[0], exp.variant_runs("v")[0]
    scenario = load_scenario(variant_spec.scenario_file, variant_spec.override_dict())
    layout = run_layout(scenario, variant_spec)
    assert not layout.graph.has_edge("A03_16", "D03")
    assert run_layout(scenario, variant_spec) is layout  # once per process
    base = run_layout(load_scenario(base_spec.scenario_file, base_spec.override_dict()),
                      base_spec)
    assert base.graph.has_edge("A03_16", "D03")
    assert variant_spec.as_json()["layout_changes"] == [{"close_segment": ["A03_16", "D03"]}]
    assert "variant" not in base_spec.as_json()  # the base scenario's spec.json as before


# ---- seeds and run ids ---------------------------------------------------------------------


def test_variant_runs_share_the_baselines_seeds_and_prefix_its_run_ids(tmp_path: Path) -> None:
    exp = load_experiment(whatif(tmp_path, {
        "aisle3": {"layout_changes": [{"one_way": AISLE_3}]},
        "busy": {"overrides": {"demand.rate_per_hour": 108}}}))
    assert exp.baseline_name == BASE_VARIANT
    assert exp.variant_names == [BASE_VARIANT, "aisle3", "busy"]
    base = exp.variant_runs(BASE_VARIANT)
    assert base == exp.runs()  # the base scenario's runs are the sweep's, unchanged
    assert [r.run_id for r in base] == [run_id({"fleet.size": n}, r)
                                        for n in (4, 6) for r in range(3)]
    assert base[1].run_id == "fleet.size=4__r01"
    for name in ("aisle3", "busy"):
        runs = exp.variant_runs(name)
        assert [r.seed for r in runs] == [r.seed for r in base]
        assert [r.run_id for r in runs] == [f"v={name}__{r.run_id}" for r in base]
        assert [r.point for r in runs] == [r.point for r in base]
        assert all(r.variant == name for r in runs)
    busy = exp.variant_runs("busy", [5])[0]
    assert busy.run_id == "v=busy__fleet.size=4__r05"
    assert busy.seed == exp.run({"fleet.size": 4}, 5).seed
    assert busy.override_dict() == {"duration_h": 0.5, "warmup_h": 0.1,
                                    "demand.rate_per_hour": 108, "fleet.size": 4,
                                    "seed": busy.seed}


def test_a_named_baseline_keeps_its_prefix(tmp_path: Path) -> None:
    exp = load_experiment(whatif(tmp_path, {
        "now": {}, "aisle3": {"layout_changes": [{"one_way": AISLE_3}]}},
        baseline="aisle3"))
    assert exp.baseline_name == "aisle3"
    assert exp.variant_names == ["aisle3", "now"]
    assert exp.variant_runs("aisle3")[0].run_id == "v=aisle3__fleet.size=4__r00"
    diff = exp.variant_layout("now").diff  # against the named baseline's layout
    assert {("M007", "A03_04"), ("A03_04", "M007")} <= set(diff.changed_segments)
    assert diff.removed_segments == ()


# ---- layout files: a factor, an override, a variant's own ----------------------------------


def test_layout_is_a_factor_with_files_relative_to_the_experiment(tmp_path: Path) -> None:
    (tmp_path / "layouts").mkdir()
    (tmp_path / "studies").mkdir()
    copy = tmp_path / "layouts" / "w.yaml"
    copy.write_bytes((LAYOUTS / "warehouse.yaml").read_bytes())
    wifi = str(LAYOUTS / "warehouse_wifi.yaml")
    path = write_yaml(tmp_path / "studies" / "e.yaml", {
        "name": "layouts", "scenario": SHIFT, "overrides": {"duration_h": 0.5, "warmup_h": 0.1},
        "factors": {"layout": ["../layouts/w.yaml", wifi]}, "replications": 1})
    exp = load_experiment(path)
    first, second = exp.runs()
    assert first.run_id == "layout=..-layouts-w.yaml__r00"  # the level as written
    assert first.factor_dict() == {"layout": "../layouts/w.yaml"}
    assert first.override_dict()["layout"] == str(copy.resolve())
    assert second.override_dict()["layout"] == wifi
    assert first.seed == second.seed
    scenario = exp.scenario(dict(exp.points[0]))
    assert scenario.path(scenario.layout) == copy.resolve()
    bad = write_yaml(tmp_path / "studies" / "bad.yaml", {
        "name": "layouts", "scenario": SHIFT, "factors": {"layout": ["w.yaml"]}})
    with pytest.raises(InputError) as info:
        load_experiment(bad)
    assert info.value.element == "factors.layout[0]"
    assert "an existing layout file" in info.value.expected


def test_layout_changes_apply_to_every_level_of_a_layout_factor(tmp_path: Path) -> None:
    levels = [str(LAYOUTS / "warehouse.yaml"), str(LAYOUTS / "warehouse_wifi.yaml")]
    exp = load_experiment(whatif(tmp_path, {"aisle3": {"layout_changes": [{"one_way": AISLE_3}]}},
                                 factors={"layout": levels}))
    for level in levels:
        resolved = exp.variant_layout("aisle3", {"layout": level})
        assert Path(resolved.layout.file) == Path(level)
        assert ("M007", "A03_04") in resolved.diff.changed_segments
        assert len(resolved.diff.removed_segments) == len(AISLE_3) - 1
    own = whatif(tmp_path, {"v": {"layout": levels[1]}}, factors={"layout": levels})
    with pytest.raises(InputError, match="layout is a factor"):
        load_experiment(own)


def test_a_variant_may_bring_its_own_layout_file(tmp_path: Path) -> None:
    (tmp_path / "wifi.yaml").write_bytes((LAYOUTS / "warehouse_wifi.yaml").read_bytes())
    exp = load_experiment(whatif(tmp_path, {"wifi": {"layout": "wifi.yaml"}}))
    run = exp.variant_runs("wifi")[0]
    assert run.override_dict()["layout"] == str((tmp_path / "wifi.yaml").resolve())
    assert exp.resolved()["variants"]["wifi"]["layout"] == str((tmp_path / "wifi.yaml")
                                                               .resolve())


# ---- refusals ------------------------------------------------------------------------------


REFUSED = [
    # (variants, element, value, words in expected)
    ({"v": {"layout_changes": [{"one_way": ["M007", "A03_99"]}]}},
     "variants.v.layout_changes[0] (one_way)", "A03_99", "did you mean A03_36"),
    ({"v": {"layout_changes": [{"one_way": ["M007", "M051"]}]}},
     "variants.v.layout_changes[0] (one_way)", "M007 -> M051", "joined by a segment"),
    ({"v": {"layout_changes": [{"speed_limit": {"chain": AISLE_3[:3], "speed_mps": 0.5}},
                               {"one_way": AISLE_3[1:4]},
                               {"two_way": ["A03_04", "D11"]}]}},
     "variants.v.layout_changes[2] (two_way)", "A03_04 -> D11",
     "layout_changes[1] (one_way) changes the direction of segment"),
    ({"v": {"layout_changes": [{"close_segment": ["A03_12", "A03_16"]},
                               {"speed_limit": {"chain": ["A03_16", "A03_12"],
                                                "speed_mps": 0.5}}]}},
     "variants.v.layout_changes[1] (speed_limit)", "A03_16 -> A03_12",
     "layout_changes[0] (close_segment) changes the whole segment"),
    ({"v": {"layout_changes": [{"one_way": ["A03_16", "D03"]}, {"one_way": ["A03_24", "D03"]}]}},
     "variants.v.layout_changes[1] (one_way)", "D03", "a node with a way out"),
    ({"v": {"layout_changes": [{"close_segment": ["M007", "A03_04"]},
                               {"close_segment": ["A03_36", "M051"]}]}},
     "variants.v.layout_changes[1] (close_segment)", "D03", "a node AGVs can reach"),
    ({"v": {"layout_changes": [{"one_way": ["M004", "M003"]}]}},
     "variants.v.layout_changes[0] (one_way)", "P02", "a node AGVs can reach"),
    ({"v": {"layout_changes": [{"close_node": "C01"}]}},
     "variants.v.layout_changes[0] (close_node)", "C01", "CHG01 does"),
    ({"v": {"layout_changes": [{"remove_station": "DROP99"}]}},
     "variants.v.layout_changes[0] (remove_station)", "DROP99", "the id of a station"),
    ({"v": {"layout_changes": [{"add_charger": {"id": "PARK1", "node": "M067"}}]}},
     "variants.v.layout_changes[0] (add_charger)", "PARK1", "an id no station"),
    ({"v": {"layout_changes": [{"parking_capacity": {"id": "PARK1", "capacity": 2}},
                               {"parking_capacity": {"id": "PARK2", "capacity": 2}}]}},
     "variants.v.layout_changes[1] (parking_capacity)", 6, "parking capacity"),
    ({"v": {"layout_changes": [{"remove_station": "DROP03"},
                               {"remove_station": "DROP03"}]}},
     "variants.v.layout_changes[1] (remove_station)", "DROP03", "the id of a station"),
    ({"v": {"layout_changes": [{"speed_limit": {"chain": ["M003", "M004"], "speed_mps": 3}}]}},
     "variants.v.layout_changes[0] (speed_limit)", 3.0, "the vehicle's maximum speed"),
    ({"v": {"layout_changes": [{"one_wya": ["M007", "A03_04"]}]}},
     "variants.v.layout_changes[0]", "one_wya", "did you mean one_way"),
    ({"v": {"layout_changes": [{"speed_limit": {"chain": ["M003", "M004"], "speed": 1}}]}},
     "variants.v.layout_changes[0].speed_limit.speed_mps", None, "required key 'speed_mps'"),
    ({"v": {"overrides": {"fleet.size": 9}}}, "variants.v.overrides.fleet.size", 9,
     "not a factor"),
    ({"v": {"overrides": {"seed": 9}}}, "variants.v.overrides.seed", "seed", "master_seed"),
    ({"v": {"overrides": {"layout": "x.yaml"}}}, "variants.v.overrides.layout", "x.yaml",
     "variants.v.layout"),
    ({"v": {"layout": "nowhere.yaml"}}, "variants.v.layout", "nowhere.yaml",
     "an existing layout file"),
    ({"v": {"overrides": {"demand.rate_per_hour": -1}}},
     "variants.v.overrides.demand.rate_per_hour", -1, "a number in [0, 100000]"),
    ({"v": {"overrides": {"fleet.vehicle.max_speed_mps": 0.5}}},
     "variants.v at design point (fleet.size=4)", 1.0, "at most the vehicle's maximum speed"),
    ({"baseline": {}}, "variants.baseline", "baseline", "the base scenario"),
    ({"a/b": {}}, "variants.a/b", "a/b", "variant name"),
    ({"v": {"layout_changez": []}}, "variants.v.layout_changez", [], "no such key"),
    ({f"v{i}": {} for i in range(100)} | {"v100": {}}, "variants", {f"v{i}": {} for i in
                                                                   range(101)},
     "at most 100 items"),
]


@pytest.mark.parametrize(("variants", "element", "value", "expected"), REFUSED,
                         ids=[r[1] + "-" + str(r[3])[:20] for r in REFUSED])
def test_a_refused_variant_names_the_file_variant_change_and_element(
        tmp_path: Path, variants: dict[str, Any], element: str, value: Any,
        expected: str) -> None:
    path = whatif(tmp_path, variants)
    with pytest.raises(InputError) as info:
        load_experiment(path)
    assert info.value.file == str(path)
    assert info.value.element == element
    assert info.value.value == value
    assert expected in info.value.expected
    assert "\n" not in str(info.value)


def test_variants_count_towards_the_most_runs_of_an_experiment(tmp_path: Path) -> None:
    path = whatif(tmp_path, {f"v{i}": {} for i in range(40)}, replications=200,
                  factors={"fleet.size": [4, 5]})
    with pytest.raises(InputError) as info:
        load_experiment(path)
    assert info.value.element == "variants"
    assert info.value.value == "41 variants x 2 design points x 200 replications"


def test_baseline_must_name_a_variant(tmp_path: Path) -> None:
    path = whatif(tmp_path, {"a": {}}, baseline="b")
    with pytest.raises(InputError) as info:
        load_experiment(path)
    assert (info.value.element, info.value.value) == ("baseline", "b")
    assert "baseline, a" in info.value.expected


def test_a_refused_change_through_the_cli_is_one_line_and_exit_2(tmp_path: Path) -> None:
    path = whatif(tmp_path, {"aisle3": {"layout_changes": [
        {"one_way": AISLE_3}, {"close_node": "A03_99"}]}})
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "sweep", str(path),
                             "--out", str(tmp_path / "out")],
                            capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert f"{path}: variants.aisle3.layout_changes[1] (close_node): got 'A03_99'" in lines[0]
    assert not (tmp_path / "out" / "runs").exists()


# ---- the schema ----------------------------------------------------------------------------


def test_the_experiment_schema_knows_variants_and_every_change_kind() -> None:
    schema = json_schema("experiment")
    assert {"variants", "baseline"} <= set(schema["properties"])
    text = json.dumps(schema)
    for kind in ("one_way", "two_way", "close_segment", "close_node", "speed_limit",
                 "add_charger", "move_station", "remove_parking", "station_handling",
                 "parking_capacity"):
        assert f'"{kind}"' in text
    variant = schema["$defs"]["VariantSpec"]
    assert variant["additionalProperties"] is False
    assert set(variant["properties"]) == {"description", "overrides", "layout",
                                          "layout_changes"}


def test_a_whatif_file_validates_against_the_schema_and_a_bad_change_fails_it(
        tmp_path: Path) -> None:
    import jsonschema
    import yaml

    schema = json_schema("experiment")
    jsonschema.Draft202012Validator.check_schema(schema)
    path = whatif(tmp_path, {"aisle3": {"layout_changes": [
        {"one_way": AISLE_3}, {"speed_limit": {"chain": AISLE_3[:3], "speed_mps": 0.5}},
        {"station_handling": {"id": "DROP03", "handling": {"dist": "fixed", "mean_s": 40}}}]},
        "busy": {"overrides": {"demand.rate_per_hour": 108}}}, baseline="busy")
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    jsonschema.validate(data, schema, cls=jsonschema.Draft202012Validator)
    load_experiment(path)  # the loader agrees
    data["variants"]["aisle3"]["layout_changes"].append({"one_wya": ["M007", "A03_04"]})
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(data, schema, cls=jsonschema.Draft202012Validator)


def test_the_docs_example_loads_and_its_messages_are_todays(tmp_path: Path) -> None:
    """docs/whatif.md: its experiment file loads (paths made absolute), and each error line
    it quotes is what fleet-sim says today for the change it describes."""
    import re

    import yaml

    text = (ROOT / "docs" / "whatif.md").read_text(encoding="utf-8")
    block = re.search(r"```yaml\n(.*?)```", text, re.S)
    assert block is not None
    data = yaml.safe_load(block.group(1))
    data["scenario"] = SHIFT
    data["variants"]["wifi_hall"]["layout"] = str(LAYOUTS / "warehouse_wifi.yaml")
    exp = load_experiment(write_yaml(tmp_path / "whatif.yaml", data))
    assert exp.variant_names == ["baseline", "aisle3_one_way", "fifth_charger",
                                 "opportunity_charging", "more_demand", "wifi_hall"]
    assert exp.variant_layout("fifth_charger").diff.changed_places == ("CHG05",)
    quoted = re.findall(r"^whatif\.yaml: .*$", text, re.M)
    cases = [("aisle3", [{"one_way": ["M007", "A03_99"]}]),
             ("v", [{"close_segment": ["M007", "A03_04"]},
                    {"close_segment": ["A03_36", "M051"]}]),
             ("v", [{"speed_limit": {"chain": AISLE_3[:3], "speed_mps": 0.5}},
                    {"one_way": AISLE_3[1:4]}, {"two_way": ["A03_04", "D11"]}]),
             ("v", [{"parking_capacity": {"id": "PARK1", "capacity": 2}},
                    {"parking_capacity": {"id": "PARK2", "capacity": 2}}])]
    said = []
    for name, edits in cases:
        path = write_yaml(tmp_path / "whatif.yaml", {
            "name": "w", "scenario": SHIFT, "factors": {"fleet.size": [12, 14]},
            "variants": {name: {"layout_changes": edits}}})
        with pytest.raises(InputError) as info:
            load_experiment(path)
        said.append(str(info.value).replace(f"{tmp_path}/", ""))
    assert said == quoted


def test_setup_warnings_are_said_per_variant(tmp_path: Path) -> None:
    """A variant that removes every charger while charging is on is warned of, the base
    scenario (four chargers) is not."""
    exp = load_experiment(whatif(tmp_path, {"no_chargers": {"layout_changes": [
        {"remove_charger": f"CHG0{i}"} for i in range(1, 5)]}}))
    assert not any("no charger" in w for w in experiment_warnings(exp))
    warned = experiment_warnings(exp, "no_chargers")
    assert any(w.startswith("charging is on but the layout has no charger") for w in warned)
