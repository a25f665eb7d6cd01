"""A generated corpus of bad inputs ("no garbage in").

Every case is a bad layout, scenario, experiment, order trace, vehicle profile, LIF file, VDA
5050 factsheet or CLI argument.
Each must end in one InputError (or, through the CLI, exit status 2 and one line on stderr) that
names the file or the argument, never a traceback, and within a few seconds (a hang or an alias
bomb fails the test). Most cases go through the loaders in-process; a representative sample goes
through the real `fleet-sim` command in a subprocess.
"""

from __future__ import annotations

import copy
import json
import os
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any

import pytest
import yaml

from agv_model.profile import read_profile
from fleet_sim.config.experiment import load_experiment
from fleet_sim.config.layout import load_layout
from fleet_sim.config.layout_spec import LayoutSpec
from fleet_sim.config.scenario import load_layout_for, load_scenario
from fleet_sim.config.standards.factsheet_profile import import_factsheet
from fleet_sim.config.standards.lif_export import layout_to_lif
from fleet_sim.config.standards.lif_import import import_lif
from fleet_sim.config.trace import load_trace
from fleet_sim.errors import InputError
from userfiles.checking import validate
from userfiles.reading import MAX_FILE_BYTES

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "layouts" / "tiny_loop.yaml"
PROFILE = ROOT / "agv_model" / "profiles" / "tabo.yaml"
FACTSHEET = ROOT / "tests" / "data" / "tugger.factsheet.json"
FILE_NAMES = {"trace": "orders.csv", "lif": "x.lif.json", "factsheet": "factsheet.json"}
CASE_SECONDS = 10

NAN, INF = float("nan"), float("inf")
BAD_NUMBERS: list[Any] = [NAN, INF, -INF, 1e308, -1, "many", True, [1]]


def _scenario() -> dict[str, Any]:
    return {"name": "bad", "layout": str(LAYOUT), "duration_h": 1, "warmup_h": 0.1,
            "seed": 1, "fleet": {"size": 2}, "demand": {"rate_per_hour": 40}}


def _layout() -> dict[str, Any]:
    data = yaml.safe_load(LAYOUT.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def _experiment(scenario: Path) -> dict[str, Any]:
    return {"name": "bad", "scenario": str(scenario), "factors": {"fleet.size": [1, 2]},
            "replications": 2}


def _profile() -> dict[str, Any]:
    data = yaml.safe_load(PROFILE.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def _lif() -> dict[str, Any]:
    """The tiny loop as fleet-sim exports it: a valid LIF file (nodes[2] is a pickup)."""
    return layout_to_lif(validate(LayoutSpec, _layout(), str(LAYOUT)))


def _factsheet() -> dict[str, Any]:
    data = json.loads(FACTSHEET.read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def _json(data: Any) -> bytes:
    return json.dumps(data).encode()


def _set(data: dict[str, Any], dotted: str, value: Any) -> dict[str, Any]:
    keys = dotted.split(".")
    target: Any = data
    for key in keys[:-1]:
        target = target[int(key)] if isinstance(target, list) else target.setdefault(key, {})
    if isinstance(target, list):
        target[int(keys[-1])] = value
    else:
        target[keys[-1]] = value
    return data


def _alias_bomb() -> bytes:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    return ("\n".join(lines) + "\n").encode()


# Raw files that are not YAML (or not text): the same for every kind of YAML file.
RAW: dict[str, bytes] = {
    "binary": bytes(range(256)) * 4,
    "latin1": "name: caf\xe9\nnodes: []\n".encode("latin-1"),
    "nul": b"name: x\x00y\n",
    "control": b"name: x\x07y\n",
    "alias_bomb": _alias_bomb(),
    "recursive_alias": b"a: &x [1, *x]\n",
    "deep_nesting": b"[" * 50_000 + b"]" * 50_000 + b"\n",
    "deep_mapping": b"a: {" * 50_000 + b"}" * 50_000 + b"\n",
    "duplicate_keys": b"name: one\nlayout: x.yaml\nname: two\n",
    "truncated": b"name: x\nnodes: [\n  {id: A, x: 0\n",
    "tab_indent": b"name: x\n\tnodes: []\n",
    "empty": b"",
    "top_level_list": b"- 1\n- 2\n",
    "top_level_text": b"just some words\n",
    "two_documents": b"name: x\n---\nname: y\n",
}


# Raw files that are not JSON objects: the same for LIF files and factsheets.
RAW_JSON: dict[str, bytes] = {
    "binary": bytes(range(256)) * 4,
    "latin1": '{"name": "caf\xe9"}'.encode("latin-1"),
    "nul": b'{"name": "x\x00y"}',
    "empty": b"",
    "truncated": b'{"metaInformation": {"creator": ',
    "nan": b'{"x": NaN}',
    "infinity": b'{"x": -Infinity}',
    "duplicate_keys": b'{"version": "2.1.0", "layouts": [], "layouts": []}',
    "deep_nesting": b"[" * 50_000 + b"]" * 50_000,
    "top_level_list": b"[1, 2]",
    "top_level_text": b'"just words"',
    "yaml_not_json": b"name: x\nnodes: []\n",
    "trailing_garbage": b"{} and more",
}


def _drop(data: dict[str, Any], dotted: str) -> dict[str, Any]:
    keys = dotted.split(".")
    target: Any = data
    for key in keys[:-1]:
        target = target[int(key)] if isinstance(target, list) else target[key]
    del target[keys[-1]]
    return data


NODE = "layouts.0.nodes.3"
EDGE = "layouts.0.edges.0"
EDGE_TYPE = f"{EDGE}.vehicleTypeEdgeProperties.0"
# (case id, change to the valid LIF file)
LIF_CASES: list[tuple[str, Callable[[dict[str, Any]], dict[str, Any]]]] = [
    ("x-text", lambda d: _set(d, f"{NODE}.nodePosition.x", "abc")),
    ("x-bool", lambda d: _set(d, f"{NODE}.nodePosition.x", True)),
    ("x-huge", lambda d: _set(d, f"{NODE}.nodePosition.x", 1e400)),
    ("position-null", lambda d: _set(d, f"{NODE}.nodePosition", None)),
    ("position-missing", lambda d: _drop(d, f"{NODE}.nodePosition")),
    ("node-id-number", lambda d: _set(d, f"{NODE}.nodeId", 12)),
    ("node-id-twice", lambda d: _set(d, f"{NODE}.nodeId", "SW")),
    ("no-vehicle-types", lambda d: _set(d, f"{NODE}.vehicleTypeNodeProperties", [])),
    ("type-twice", lambda d: _set(d, f"{NODE}.vehicleTypeNodeProperties",
                                  [{"vehicleTypeId": "A"}, {"vehicleTypeId": "A"}])),
    ("theta-beyond-pi", lambda d: _set(d, f"{NODE}.vehicleTypeNodeProperties.0.theta", 4)),
    ("blocking-type", lambda d: _set(
        d, "layouts.0.nodes.2.vehicleTypeNodeProperties.0.actions.0.blockingType", "MAYBE")),
    ("edge-to-nowhere", lambda d: _set(d, f"{EDGE}.endNodeId", "ZZ")),
    ("edge-without-start", lambda d: _drop(d, f"{EDGE}.startNodeId")),
    ("max-speed-zero", lambda d: _set(d, f"{EDGE_TYPE}.maxSpeed", 0)),
    ("max-speed-negative", lambda d: _set(d, f"{EDGE_TYPE}.maxSpeed", -1)),
    ("max-speed-text", lambda d: _set(d, f"{EDGE_TYPE}.maxSpeed", "fast")),
    ("rotation-allowed-missing", lambda d: _drop(d, f"{EDGE_TYPE}.rotationAllowed")),
    ("rotation-at-start", lambda d: _set(d, f"{EDGE_TYPE}.rotationAtStartNodeAllowed", "LEFT")),
    ("knots-miscounted", lambda d: _set(d, f"{EDGE_TYPE}.trajectory", {
        "degree": 2, "knotVector": [0, 1], "controlPoints": [{"x": 0, "y": 0}]})),
    ("knot-beyond-one", lambda d: _set(d, f"{EDGE_TYPE}.trajectory", {
        "knotVector": [0, 0, 2, 2], "controlPoints": [{"x": 0, "y": 0}, {"x": 4, "y": 0}]})),
    ("station-without-nodes", lambda d: _set(d, "layouts.0.stations.0.interactionNodeIds", [])),
    ("station-at-nowhere", lambda d: _set(d, "layouts.0.stations.0.interactionNodeIds", ["ZZ"])),
    ("station-height", lambda d: _set(d, "layouts.0.stations.0.stationHeight", -1)),
    ("station-height-text-negative", lambda d: _set(d, "layouts.0.stations.0.stationHeight",
                                                    "-1")),  # read as -1, then refused
    ("station-height-comma", lambda d: _set(d, "layouts.0.stations.0.stationHeight", "0,5")),
    ("max-speed-text-zero", lambda d: _set(d, f"{EDGE_TYPE}.maxSpeed", "0")),
    ("position-text-nan", lambda d: _set(d, f"{NODE}.nodePosition.x", "NaN")),
    ("lif-2", lambda d: _set(d, "metaInformation.lifVersion", "2.0.0")),
    ("lif-version-text", lambda d: _set(d, "metaInformation.lifVersion", "one")),
    ("timestamp", lambda d: _set(d, "metaInformation.exportTimestamp", "yesterday")),
    ("no-meta", lambda d: _drop(d, "metaInformation")),
    ("layouts-text", lambda d: _set(d, "layouts", "none")),
    ("no-layouts", lambda d: _set(d, "layouts", [])),
    ("extension-length", lambda d: _set(d, f"{EDGE}.fleetSim", {"length_m": -1})),
    ("extension-unknown-key", lambda d: _set(d, f"{EDGE}.fleetSim", {"colour": "red"})),
    ("extension-kind", lambda d: _set(d, "layouts.0.stations.0.fleetSim.kind", "bakery")),
    ("extension-power-of-a-pickup", lambda d: _set(d, "layouts.0.stations.0.fleetSim.power_kw",
                                                   3)),
    ("extension-handling", lambda d: _set(d, "layouts.0.stations.0.fleetSim.handling",
                                          {"dist": "fixed", "mean_s": -5})),
]
FACTSHEET_CASES: list[tuple[str, Callable[[dict[str, Any]], dict[str, Any]]]] = [
    ("speed-text", lambda d: _set(d, "physicalParameters.speedMax", "fast")),
    ("speed-negative", lambda d: _set(d, "physicalParameters.speedMax", -1)),
    ("speed-zero", lambda d: _set(d, "physicalParameters.speedMax", 0)),
    ("speed-bool", lambda d: _set(d, "physicalParameters.speedMax", True)),
    ("speed-huge", lambda d: _set(d, "physicalParameters.speedMax", 1e400)),
    ("speed-min-above-max", lambda d: _set(d, "physicalParameters.speedMin", 5)),
    ("no-length", lambda d: _drop(d, "physicalParameters.length")),
    ("no-type", lambda d: _drop(d, "typeSpecification")),
    ("agv-class", lambda d: _set(d, "typeSpecification.agvClass", "SPACESHIP")),
    ("version-3", lambda d: _set(d, "version", "3.0.0")),
    ("header-negative", lambda d: _set(d, "headerId", -1)),
    ("pick-time", lambda d: _set(d, "loadSpecification.loadSets.0.pickTime", -3)),
    ("order-nodes", lambda d: (d["protocolLimits"]["maxArrayLens"].update(
        {"order.nodes": 2.5}), d)[1]),
    ("wheel-diameter", lambda d: _set(d, "agvGeometry.wheelDefinitions.0.diameter", 0)),
    ("timing-missing", lambda d: _drop(d, "protocolLimits.timing.minOrderInterval")),
]


def _changes(*changes: Any) -> dict[str, Any]:
    return {"variants": {"v": {"layout_changes": list(changes)}}}


# What-if variants on the tiny loop (SW -> S1 -> P -> S3 -> SE ... -> NW -> K -> SW).
VARIANT_CASES: list[tuple[str, dict[str, Any]]] = [
    ("unknown-kind", _changes({"one_wya": ["SW", "S1"]})),
    ("two-kinds", _changes({"one_way": ["SW", "S1"], "two_way": ["S1", "P"]})),
    ("not-a-mapping", _changes("one_way SW S1")),
    ("not-a-list", {"variants": {"v": {"layout_changes": {"one_way": ["SW", "S1"]}}}}),
    ("missing-node", _changes({"one_way": ["SW", "ZZ"]})),
    ("not-a-segment", _changes({"two_way": ["SW", "SE"]})),
    ("chain-of-one", _changes({"one_way": ["SW"]})),
    ("dead-end", _changes({"close_segment": ["SW", "S1"]})),
    ("turned-hop", _changes({"one_way": ["S1", "SW"]})),
    ("conflict", _changes({"two_way": ["SW", "S1"]}, {"one_way": ["S1", "SW"]})),
    ("close-a-station-node", _changes({"close_node": "P"})),
    ("closed-then-used", _changes({"close_node": "S1"}, {"two_way": ["SW", "S1"]})),
    ("speed-nan", _changes({"speed_limit": {"chain": ["SW", "S1"], "speed_mps": NAN}})),
    ("speed-zero", _changes({"speed_limit": {"chain": ["SW", "S1"], "speed_mps": 0}})),
    ("parking-too-small", _changes({"parking_capacity": {"id": "PARK", "capacity": 1}})),
    ("remove-the-only-pickup", _changes({"remove_station": "PICK"})),
    ("handling-not-a-distribution",
     _changes({"station_handling": {"id": "DROP", "handling": 5}})),
    ("unknown-station", _changes({"station_handling": {"id": "NOPE",
                                                       "handling": {"mean_s": 5}}})),
    ("charger-on-a-station", _changes({"add_charger": {"id": "C", "node": "P"}})),
    ("variant-named-baseline", {"variants": {"baseline": {}}}),
    ("variant-name-path", {"variants": {"../x": {}}}),
    ("baseline-unknown", {"variants": {"a": {}}, "baseline": "b"}),
    ("override-seed", {"variants": {"v": {"overrides": {"seed": 3}}}}),
    ("override-a-factor", {"variants": {"v": {"overrides": {"fleet.size": 3}}}}),
    ("override-bad-value", {"variants": {"v": {"overrides": {"demand.rate_per_hour": NAN}}}}),
    ("layout-missing", {"variants": {"v": {"layout": "nowhere.yaml"}}}),
    ("unknown-key", {"variants": {"v": {"layout_change": []}}}),
]


def _optimise(**changes: Any) -> dict[str, Any]:
    """An experiment's optimise section on the tiny loop, with `changes` to it."""
    section: dict[str, Any] = {
        "decisions": {"fleet.size": {"min": 1, "max": 3, "price_per_unit": 100}},
        "layout_decisions": {"handling": {"as_it_is": {}, "fast": {"price": 30, "changes": [
            {"station_handling": {"id": "PICK", "handling": {"mean_s": 2}}}]}}},
        "tolerance": {"lead_time_p95_s": 60}}
    section.update(changes)
    return {"targets": [{"kpi": "lead_time_p95_s", "at_most": 600}], "optimise": section}


_SLOW = {"as_it_is": {}, "slow": {"changes": [
    {"speed_limit": {"chain": ["SW", "S1"], "speed_mps": 0.5}}]}}
# Decisions and costs (fleet-sim optimise): each refused in one line, naming optimise...
OPTIMISE_CASES: list[tuple[str, dict[str, Any]]] = [
    ("key-the-scenario-lacks", _optimise(decisions={"fleet.sise": {"min": 1, "max": 2}})),
    ("level-the-scenario-refuses", _optimise(decisions={"dispatch.policy": {
        "levels": [{"level": "nearest_idle"}, {"level": "whenever"}]}})),
    ("range-and-levels", _optimise(decisions={"fleet.size": {"min": 1, "max": 2,
                                                             "levels": [{"level": 1}]}})),
    ("range-reversed", _optimise(decisions={"fleet.size": {"min": 3, "max": 1}})),
    ("range-half", _optimise(decisions={"fleet.size": {"min": 1}})),
    ("price-nan", _optimise(decisions={"fleet.size": {"min": 1, "max": 2,
                                                      "price_per_unit": NAN}})),
    ("price-negative", _optimise(decisions={"fleet.size": {"min": 1, "max": 2,
                                                           "price_per_unit": -5}})),
    ("price-inf", _optimise(decisions={"fleet.size": {"min": 1, "max": 2,
                                                      "yearly_per_unit": INF}})),
    ("option-price-text", _optimise(layout_decisions={"handling": {
        "as_it_is": {}, "fast": {"price": "cheap"}}})),
    ("horizon-negative", _optimise(horizon_years=-1)),
    ("levels-repeated", _optimise(decisions={"dispatch.policy": {
        "levels": [{"level": "nearest_idle"}, {"level": "nearest_idle"}]}})),
    ("decision-is-seed", _optimise(decisions={"seed": {"min": 1, "max": 2}})),
    ("decision-is-layout", _optimise(decisions={"layout": {"levels": [{"level": "x.yaml"}]}})),
    ("no-decisions", _optimise(decisions={}, layout_decisions={})),
    ("one-option-group", _optimise(layout_decisions={"handling": {"fast": {}}})),
    ("option-change-unknown-node", _optimise(layout_decisions={"g": {
        "as_it_is": {}, "x": {"changes": [{"one_way": ["SW", "ZZ"]}]}}})),
    ("groups-conflict", _optimise(layout_decisions={"a": _SLOW, "b": _SLOW})),
    ("tolerance-missing", _optimise(tolerance={})),
    ("tolerance-zero", _optimise(tolerance={"lead_time_p95_s": 0})),
    ("tolerance-not-a-target", _optimise(tolerance={"lead_time_p95_s": 60,
                                                     "lead_time_p59_s": 5})),
    ("relax-tighter", _optimise(relax={"lead_time_p95_s": [500]})),
    ("confidence-one", _optimise(confidence=1)),
    ("replications-reversed", _optimise(min_replications=10, max_replications=5)),
    ("assume-without-a-count", _optimise(decisions={}, more_agvs_never_worse=True)),
    ("space-over-the-design-limit", _optimise(decisions={
        "fleet.size": {"min": 1, "max": 200}, "demand.rate_per_hour": {"min": 10, "max": 200}})),
    ("space-over-the-run-limit", _optimise(decisions={
        "fleet.size": {"min": 1, "max": 100}, "demand.rate_per_hour": {"min": 10, "max": 29}})),
    ("unknown-key", _optimise(budget=5)),
]


@dataclass(frozen=True)
class Case:
    id: str
    kind: str  # layout, scenario, experiment, trace, profile, lif, factsheet
    content: Callable[[Path], bytes]
    """The file's bytes, given the folder the case is written in."""


def _yaml(data: Any) -> bytes:
    return yaml.safe_dump(data, sort_keys=False).encode()


def _cases() -> Iterator[Case]:
    for kind in ("layout", "scenario", "experiment", "profile"):
        for name, raw in RAW.items():
            yield Case(f"{kind}-{name}", kind, lambda _d, raw=raw: raw)
    scenario_fields = ["duration_h", "warmup_h", "seed", "fleet.size", "demand.rate_per_hour",
                       "start_h", "charging.threshold_pct"]
    for field in scenario_fields:
        for i, value in enumerate(BAD_NUMBERS):
            yield Case(f"scenario-{field}-{i}-{value!r}", "scenario",
                       lambda _d, f=field, v=value: _yaml(_set(_scenario(), f, v)))
    for field, value in [("duration_h", 8761), ("demand.rate_per_hour", 100_001),
                         ("fleet.size", 2001), ("fleet.size", 0), ("unknown_key", 1),
                         ("fleet.vehicle.max_speed_mps", NAN), ("fleet.start_nodes", ["ZZ"]),
                         ("layout", "missing.yaml"), ("layout", str(ROOT / "layouts")),
                         ("fleet.vehicle.battery", True), ("fleet.vehicle.battery", "on"),
                         ("fleet.vehicle.battery", "empty"), ("fleet.vehicle.battery", 0),
                         ("fleet.vehicle.battery", [1]),
                         ("fleet.vehicle.battery", {"capacity_wh": 0}),
                         ("fleet.vehicle.battery", {"idle_w": NAN}),
                         ("fleet.vehicle.battery", {"switch": "off"}),
                         ("fleet.vehicles", [{"type": "a", "count": 1}]),
                         ("fleet.vehicles", [{"type": "a", "count": 2, "profile": "nowhere"}]),
                         ("fleet.vehicles", [{"type": "a", "count": 1},
                                             {"type": "a", "count": 1}]),
                         ("fleet.vehicles", [{"type": "a", "count": 2, "speed": 1}]),
                         ("fleet.vehicles", [{"type": "a", "count": 2.5}]),
                         ("fleet.vehicles", "many"),
                         ("fleet.vehicle.length_m", 1e6), ("fleet.vehicle.length_m", 44),
                         ("fleet.vehicle.min_gap_m", 44),
                         ("fleet.vehicles", [{"type": "a", "count": 1},
                                             {"type": "b", "count": 1,
                                              "vehicle": {"length_m": 1e6}}]),
                         ("demand.flows", [{"stops": ["PICK", "DROP", "PICK"]}]),
                         ("demand.flows", [{"stops": ["PICK", "DROP"] * 11}]),
                         ("demand.flows", [{"stops": ["PICK", "PICK", "DROP", "DROP"]}]),
                         ("demand.flows", [{"stops": ["PICK", "DROP", "ZZ", "DROP"]}]),
                         ("demand.flows", [{"from": "PICK", "stops": ["PICK", "DROP"]}]),
                         ("demand.flows", [{"from": "PICK"}]),
                         ("demand.flows", [{"stops": "PICK>DROP"}]),
                         ("fleet.command_timing", "sometimes"), ("fleet.command_timing", True),
                         ("traffic.grants", "always"),
                         ("rules.agv_ahead", "maybe"), ("rules.lds_stop_m", -1),
                         ("rules.lds_clear_m", NAN), ("incidents.cpu_reset", "reset"),
                         ("fleet", {"size": 2, "command_profile": "ktm-02",
                                    "command_timing": False}),
                         ("fleet", {"vehicles": [{"type": "a", "count": 2,
                                                  "profile": "ktm-02"}],
                                    "command_profile": "ktm-02"})]:
        yield Case(f"scenario-{field}-{value!r}", "scenario",
                   lambda _d, f=field, v=value: _yaml(_set(_scenario(), f, v)))
    for field, value in [("nodes.0.x", NAN), ("nodes.0.x", INF), ("nodes.0.y", "north"),
                         ("segments.0.length_m", -1), ("segments.0.to", "ZZ"),
                         ("segments.0.speed_limit_mps", 0), ("nodes.1.id", "SW"),
                         ("parking.0.capacity", 1e308), ("parking.0.capacity", 0),
                         ("defaults.speed_limit_mps", NAN), ("stations.0.nodes", []),
                         ("segments.0.allowed_types", "narrow"),
                         ("traffic_zones", [{"id": "Z", "kind": "mutex", "nodes": ["ZZ"]}]),
                         ("traffic_zones", [{"id": "Z", "kind": "mutex", "nodes": ["SW"],
                                             "capacity": 0}]),
                         ("traffic_zones", [{"id": "Z", "kind": "ban", "nodes": ["SW"]}]),
                         ("stations.0.allowed_types", [["a"]]),
                         ("nodes", "none")]:
        yield Case(f"layout-{field}-{value!r}", "layout",
                   lambda _d, f=field, v=value: _yaml(_set(_layout(), f, v)))
    many_levels = {"fleet.size": list(range(1, 101)),
                   "demand.rate_per_hour": list(range(1, 51))}
    for field, value in [("replications", 0), ("replications", 1001), ("replications", NAN),
                         ("replications", "three"), ("name", "../x"), ("name", ".."),
                         ("name", "/abs"), ("factors", many_levels),
                         ("factors.fleet\\.size", None), ("design", "random"),
                         ("master_seed", -1), ("sizing", {"max_agvs": 1e308}),
                         ("sizing", {"max_agvs": 5000}), ("scenario", "nowhere.yaml")]:
        def experiment(folder: Path, f: str = field, v: Any = value) -> bytes:
            scenario = folder / "base.yaml"
            scenario.write_bytes(_yaml(_scenario()))
            data = _experiment(scenario)
            if f == "factors.fleet\\.size":
                data["factors"] = {"fleet.size": [0, 2]}
            else:
                _set(data, f, v)
            return _yaml(data)
        yield Case(f"experiment-{field}-{value!r}"[:80], "experiment", experiment)
    for name, extra in VARIANT_CASES:
        yield Case(f"experiment-variants-{name}", "experiment",
                   lambda d, e=extra: _yaml({**_experiment(_write_base(d)), **e}))
    for name, extra in OPTIMISE_CASES:
        yield Case(f"experiment-optimise-{name}", "experiment",
                   lambda d, e=extra: _yaml({**{k: v for k, v in _experiment(
                       _write_base(d)).items() if k != "factors"}, **e}))
    yield Case("experiment-optimise-with-factors", "experiment",
               lambda d: _yaml({**_experiment(_write_base(d)), **_optimise()}))
    yield Case("experiment-lhs-samples", "experiment", lambda d: _yaml({
        **_experiment(_write_base(d)), "design": "latin_hypercube", "samples": 10_001,
        "factors": {"demand.rate_per_hour": {"min": 10, "max": 50}}}))
    for field, value in [("kinematics.max_speed_mmps", NAN), ("kinematics.accel_mmps2", -1),
                         ("battery.capacity_wh", INF), ("battery.moving_w", "lots"),
                         ("protocol", "smoke-signals")]:
        yield Case(f"profile-{field}-{value!r}", "profile",
                   lambda _d, f=field, v=value: _yaml(_set(_profile(), f, v)))
    header = b"time_s,pickup,dropoff\n"
    latin1 = "time_s,pickup,dropoff\n1,P\xc9,DROP\n".encode("latin-1")
    for name, raw in [("binary", bytes(range(256))), ("latin1", latin1),
                      ("empty", b""), ("no_header", b"1,PICK,DROP\n"),
                      ("time_nan", header + b"nan,PICK,DROP\n"),
                      ("time_inf", header + b"inf,PICK,DROP\n"),
                      ("time_huge", header + b"1e309,PICK,DROP\n"),
                      ("time_negative", header + b"-5,PICK,DROP\n"),
                      ("time_text", header + b"soon,PICK,DROP\n"),
                      ("unknown_station", header + b"1,NOWHERE,DROP\n"),
                      ("short_row", header + b"1,PICK\n"),
                      ("nul", header + b"1,PI\x00CK,DROP\n"),
                      ("stops_odd", b"time_s,stops\n1,PICK>DROP>PICK\n"),
                      ("stops_wrong_kind", b"time_s,stops\n1,PICK>DROP>DROP>PICK\n"),
                      ("stops_unknown", b"time_s,stops\n1,PICK>DROP>PICK>NOWHERE\n"),
                      ("stops_too_many", b"time_s,stops\n1," + b">".join([b"PICK>DROP"] * 11)
                       + b"\n"),
                      ("stops_time_nan", b"time_s,stops\nnan,PICK>DROP>PICK>DROP\n"),
                      ("stops_pickup_differs", header[:-1] + b",stops\n1,DROP,DROP,"
                       b"PICK>DROP>PICK>DROP\n"),
                      ("stops_empty_plain_row", b"time_s,stops\n1,\n"),
                      ("stops_no_time", b"stops\nPICK>DROP\n")]:
        yield Case(f"trace-{name}", "trace", lambda _d, raw=raw: raw)
    for kind in ("lif", "factsheet"):
        for name, raw in RAW_JSON.items():
            yield Case(f"{kind}-{name}", kind, lambda _d, raw=raw: raw)
    for name, change in LIF_CASES:
        yield Case(f"lif-{name}", "lif", lambda _d, c=change: _json(c(copy.deepcopy(_lif()))))
    for name, change in FACTSHEET_CASES:
        yield Case(f"factsheet-{name}", "factsheet",
                   lambda _d, c=change: _json(c(_factsheet())))


def _write_base(folder: Path) -> Path:
    scenario = folder / "base.yaml"
    scenario.write_bytes(_yaml(_scenario()))
    return scenario


CASES = list(_cases())


class _Timeout(Exception):
    pass


def _load(kind: str, path: Path) -> None:
    if kind == "layout":
        load_layout(path)
    elif kind == "scenario":
        scenario = load_scenario(path)
        load_layout_for(scenario, str(path))
    elif kind == "experiment":
        load_experiment(path)
    elif kind == "profile":
        read_profile(path)
    elif kind == "lif":
        import_lif(path)
    elif kind == "factsheet":
        import_factsheet(path)
    else:
        load_trace(path, load_layout(LAYOUT))


def test_the_corpus_is_large() -> None:
    assert len(CASES) >= 100
    assert len({c.id for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_one_named_error(case: Case, tmp_path: Path) -> None:
    path = tmp_path / FILE_NAMES.get(case.kind, f"{case.kind}.yaml")
    path.write_bytes(case.content(tmp_path))

    def expire(_signum: int, _frame: FrameType | None) -> None:
        raise _Timeout(f"{case.id} took more than {CASE_SECONDS} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(CASE_SECONDS)
    try:
        with pytest.raises(InputError) as info:
            _load(case.kind, path)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    message = str(info.value)
    assert "\n" not in message, message
    assert message.startswith(str(tmp_path)) or message.startswith(str(ROOT)), message
    assert "; expected " in message, message
    if case.id.startswith("experiment-variants-"):
        assert ": variants." in message or ": baseline: " in message, message


def test_the_valid_lif_and_factsheet_the_cases_change_are_read(tmp_path: Path) -> None:
    path = tmp_path / "x.lif.json"
    path.write_bytes(_json(_lif()))
    assert import_lif(path).spec.name == "tiny_loop"
    assert import_factsheet(FACTSHEET).title == "T12 tugger (Example Motion)"


def test_a_malformed_lif_names_the_json_path(tmp_path: Path) -> None:
    path = tmp_path / "x.lif.json"
    path.write_bytes(_json(_set(_lif(), f"{NODE}.nodePosition.x", "abc")))
    with pytest.raises(InputError) as info:
        import_lif(path)
    assert str(info.value) == (f"{path}: layouts[0].nodes[3].nodePosition.x: got 'abc'; "
                               "expected a number")
    path.write_bytes(_json(_set(_lif(), f"{EDGE}.endNodeId", "ZZ")))
    with pytest.raises(InputError, match=r"x.lif.json: layouts\[0\].edges\[0\].endNodeId: got "
                                         r"'ZZ'; expected the nodeId of a node in the file"):
        import_lif(path)
    path.write_bytes(b'{"metaInformation": {},\n "layouts": [}')
    with pytest.raises(InputError, match=r"x.lif.json: line 2 column 14: got 'Expecting value'; "
                                         "expected valid JSON"):
        import_lif(path)


def test_a_file_over_the_size_cap_is_refused_unread(tmp_path: Path) -> None:
    big = tmp_path / "layout.yaml"
    with big.open("wb") as handle:
        handle.truncate(MAX_FILE_BYTES + 10)
    with pytest.raises(InputError, match=r"layout.yaml: file: .*at most 20 MB"):
        load_layout(big)
    csv = tmp_path / "orders.csv"
    big.rename(csv)
    with pytest.raises(InputError, match=r"orders.csv: file: .*at most 20 MB"):
        load_trace(csv, load_layout(LAYOUT))


def test_duplicate_keys_name_the_key_and_both_lines(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("layout: x.yaml\nfleet:\n  size: 2\n  size: 3\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"line 4: got 'size'; .*already on line 3"):
        load_scenario(path)


def test_merge_keys_may_override_what_they_bring(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(f"layout: {LAYOUT}\nfleet:\n  <<: {{size: 2}}\n  size: 3\n",
                    encoding="utf-8")
    assert load_scenario(path).fleet.size == 3


# The real command, a representative sample (each start costs ~2 s; the argument checks of the
# other values are the same functions): (arguments, what the one line must contain).
def _cli_cases(tmp: Path) -> list[tuple[list[str], str]]:
    scenario = str(ROOT / "experiments" / "tiny_loop.yaml")
    experiment = str(ROOT / "experiments" / "tiny_loop_sizing.yaml")
    a_file = tmp / "a_file"
    a_file.write_text("x", encoding="utf-8")
    dup = tmp / "dup.yaml"
    dup.write_text(f"name: dup\nlayout: {LAYOUT}\nseed: 1\nseed: 2\n", encoding="utf-8")
    binary = tmp / "binary.yaml"
    binary.write_bytes(RAW["binary"])
    bomb = tmp / "bomb.yaml"
    bomb.write_bytes(RAW["alias_bomb"])
    long_agv = tmp / "long.yaml"
    long_agv.write_bytes(_yaml(_set(_scenario(), "fleet.vehicle.length_m", 1e6)))
    bad_lif = tmp / "bad.lif.json"
    bad_lif.write_bytes(_json(_set(_lif(), f"{NODE}.nodePosition.x", "abc")))
    bad_factsheet = tmp / "bad.factsheet.json"
    bad_factsheet.write_bytes(_json(_set(_factsheet(), "physicalParameters.speedMax", -1)))
    return [
        (["layout", "import", str(bad_lif), "--out", str(tmp / "x.yaml")],
         f"{bad_lif}: layouts[0].nodes[3].nodePosition.x: got 'abc'; expected a number"),
        (["profile", "import", str(bad_factsheet), "--out", str(tmp / "p.yaml")],
         "physicalParameters.speedMax: got -1; expected a number > 0"),
        (["layout", "export", str(LAYOUT), "--lif", str(tmp / "x.json"), "--timestamp", "noon"],
         "argument --timestamp: got 'noon'; expected an ISO 8601"),
        (["run", scenario, "--hours", "nan"], "argument --hours: got 'nan'; expected a finite"),
        (["run", scenario, "--hours", "0.05"], "--hours: duration_h: got 0.05"),
        (["run", scenario, "--agvs", "0"], "argument --agvs: got '0'"),
        (["run", scenario, "--out", str(a_file)], "--out: out: got"),
        (["run", str(dup)], "already on line 3"),
        (["run", str(long_agv)], f"{long_agv}: fleet.vehicle.length_m: got 1000000.0; expected a "
                                 "vehicle that fits the track of layout tiny_loop: at most 43.5 m"),
        (["layout", str(LAYOUT), "--max-speed", "nan"], "argument --max-speed: got 'nan'"),
        (["layout", str(LAYOUT), "--png", str(tmp)], "--png: png: got"),
        (["layout", str(binary)], "not UTF-8 text"),
        (["sweep", experiment, "--workers", "-3"], "argument --workers: got '-3'"),
    ]


def test_the_command_refuses_bad_input_in_one_line(tmp_path: Path) -> None:
    for argv, expected in _cli_cases(tmp_path):
        result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", *argv], cwd=tmp_path,
                                capture_output=True, text=True, timeout=60, check=False,
                                env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert result.returncode == 2, (argv, result.stderr)
        lines = result.stderr.splitlines()
        assert len(lines) == 1, (argv, result.stderr)
        assert "Traceback" not in result.stderr
        assert lines[0].startswith("fleet-sim: error: ") and expected in lines[0], (argv, lines)
        assert not (tmp_path / "results").exists() or argv[0] == "layout", argv


def test_agvs_that_cannot_reach_a_charger_are_named(tmp_path: Path) -> None:
    from fleet_sim.config.scenario import agvs_without_charger, parse_scenario

    layout = load_layout(LAYOUT)  # no charger at all
    on = parse_scenario(_scenario(), "s.yaml")
    assert agvs_without_charger(on, layout) == [0, 1]
    off = parse_scenario(_set(_scenario(), "charging.enabled", False), "s.yaml")
    assert agvs_without_charger(off, layout) == []
    scenario = tmp_path / "s.yaml"
    scenario.write_bytes(_yaml(_set(_scenario(), "duration_h", 0.2)))
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "run", str(scenario),
                             "--quiet", "--out", str(tmp_path / "out")],
                            cwd=tmp_path, capture_output=True, text=True, timeout=120,
                            check=False, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 0, result.stderr
    warning = [line for line in result.stderr.splitlines() if "warning" in line]
    assert warning == ["fleet-sim: warning: charging is on but the layout has no charger: "
                       "AGV 0, 1 (2 of 2) will run down and stop with E_201: from 90 % to the "
                       "charging threshold 30 %, where they stop taking orders, in about 2.9 h "
                       "working flat out or 28.8 h idle, then E_201 at 10 % 9.6 h later"]


def test_a_layout_with_a_charger_warns_no_one() -> None:
    from fleet_sim.config.scenario import agvs_without_charger, load_layout_for

    scenario = load_scenario(ROOT / "experiments" / "warehouse_shift.yaml")
    layout = load_layout_for(scenario, "warehouse_shift.yaml")
    assert agvs_without_charger(scenario, layout) == []


@pytest.mark.parametrize(("name", "folder"), [
    ("warehouse", "warehouse"), ("../x", ".._x"), ("/tmp/x", "_tmp_x"), ("..", "__"),
    (".", "_"), ("", "scenario"), ("a b\x00", "a_b_")])
def test_a_scenario_name_never_leaves_results(name: str, folder: str) -> None:
    from fleet_sim.config.scenario import folder_name

    assert folder_name(name) == folder
