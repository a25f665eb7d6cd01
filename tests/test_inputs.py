"""One validation system for every file a user writes: one InputError naming file, element,
value and expectation; no NaN, infinity or absurd value gets through; the published JSON Schemas
agree with the bundled files."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from agv_model.profile import PROFILE_DIR, read_profile
from fleet_sim.cli import main
from fleet_sim.config.experiment import load_experiment
from fleet_sim.config.layout import load_layout
from fleet_sim.config.layout_spec import SegmentSpec
from fleet_sim.config.scenario import load_scenario
from fleet_sim.config.schemas import json_schema
from fleet_sim.config.trace import load_trace
from userfiles.checking import InputError, validate
from userfiles.reading import read_yaml

from .conftest import LAYOUTS, ROOT, write_yaml


def _yaml(path: Path) -> Any:
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def _is_experiment(data: dict[str, Any]) -> bool:
    return "scenario" in data and ("factors" in data or "variants" in data or "optimise" in data)


def bundled() -> list[tuple[str, Path]]:
    files = [("layout", p) for p in sorted(LAYOUTS.glob("*.yaml"))]
    files += [("experiment" if _is_experiment(_yaml(p)) else "scenario", p)
              for p in sorted((ROOT / "experiments").glob("*.yaml"))]
    files += [("profile", p) for p in sorted(PROFILE_DIR.glob("*.yaml"))]
    files += [("lif", p) for p in sorted(LAYOUTS.glob("*.lif.json"))]
    return files


BUNDLED = bundled()


def test_every_kind_of_bundled_file_is_there() -> None:
    assert {kind for kind, _ in BUNDLED} == {"layout", "scenario", "experiment", "profile",
                                             "lif"}


@pytest.mark.parametrize(("kind", "path"), BUNDLED, ids=[f"{k}:{p.name}" for k, p in BUNDLED])
def test_bundled_files_validate_against_the_published_schema(kind: str, path: Path) -> None:
    schema = json_schema(kind)
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(_yaml(path), schema, cls=jsonschema.Draft202012Validator)


@pytest.mark.parametrize(("kind", "path", "change"), [
    ("layout", LAYOUTS / "tiny_loop.yaml", lambda d: d["segments"][0].update(length_m=-1)),
    ("layout", LAYOUTS / "tiny_loop.yaml", lambda d: d["nodes"][0].update(colour="red")),
    ("layout", LAYOUTS / "tiny_loop.yaml", lambda d: d["stations"][0].update(
        handling={"dist": "fixed", "mean_s": 20, "sd_s": 3})),
    ("scenario", ROOT / "experiments" / "tiny_loop.yaml", lambda d: d.update(
        fleet={"size": 0})),
    ("scenario", ROOT / "experiments" / "tiny_loop.yaml", lambda d: d.update(
        rules={"bat_low_pct": 120})),
    ("experiment", ROOT / "experiments" / "warehouse_sizing.yaml", lambda d: d.update(
        replications=0)),
    ("profile", PROFILE_DIR / "tabo.yaml", lambda d: d["link"].update(parity="E")),
    ("profile", PROFILE_DIR / "tabo.yaml", lambda d: d["kinematics"].pop("source")),
    ("lif", LAYOUTS / "warehouse.lif.json", lambda d: d["layouts"][0]["nodes"][3][
        "nodePosition"].update(x="abc")),
    ("lif", LAYOUTS / "warehouse.lif.json", lambda d: d["layouts"][0]["edges"][0][
        "vehicleTypeEdgeProperties"].clear()),
    ("lif", LAYOUTS / "warehouse.lif.json", lambda d: d["layouts"][0]["edges"][0].update(
        fleetSim={"direction": "sideways"})),
])
def test_a_bad_value_fails_the_schema_as_it_fails_the_loader(kind: str, path: Path,
                                                             change: Any) -> None:
    data = copy.deepcopy(_yaml(path))
    change(data)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(data, json_schema(kind), cls=jsonschema.Draft202012Validator)


def test_schema_says_what_each_key_means_and_hides_internal_ones() -> None:
    scenario = json_schema("scenario")
    assert "KPIs count from the end of the warm-up" in scenario["properties"]["warmup_h"][
        "description"]
    assert "_base_dir" not in json.dumps(scenario) and "base_dir" not in scenario["properties"]
    segment = json_schema("layout")["$defs"]["SegmentSpec"]
    assert {"from", "to"} <= set(segment["properties"]) and "from_node" not in segment[
        "properties"]


def test_schema_command_prints_or_writes_the_schema(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema", "layout"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == json_schema("layout")
    out = tmp_path / "profile.schema.json"
    assert main(["schema", "profile", "--out", str(out)]) == 0
    assert json.loads(out.read_text(encoding="utf-8")) == json_schema("profile")
    assert main(["schema", "profile", "--out", str(tmp_path / "no" / "such" / "dir.json")]) == 2
    assert "--out: out: got" in capsys.readouterr().err


# ---- non-finite and absurd numbers ------------------------------------------------------------

def _set(data: dict[str, Any], dotted: str, value: Any) -> None:
    """Set `a.b[2].c` in parsed YAML."""
    target: Any = data
    parts = dotted.replace("[", ".[").split(".")
    for i, part in enumerate(parts):
        key: Any = int(part[1:-1]) if part.startswith("[") else part
        if i == len(parts) - 1:
            target[key] = value
        else:
            if isinstance(key, str) and not isinstance(target.get(key), dict | list):
                target[key] = {}  # absent, or a switch such as battery: off
            target = target[key]


def _load(kind: str, path: Path) -> None:
    if kind == "layout":
        load_layout(path)
    elif kind == "scenario":
        load_scenario(path)
    elif kind == "experiment":
        load_experiment(path)
    else:
        read_profile(path)


SOURCES = {"layout": LAYOUTS / "tiny_loop.yaml", "scenario": ROOT / "experiments" /
           "tiny_loop.yaml", "experiment": ROOT / "experiments" / "tiny_loop_sizing.yaml",
           "profile": PROFILE_DIR / "carriro-ad-plus.yaml"}

FIELDS = [
    # (kind, element, an absurd value beyond a bound or None where the field has none)
    ("layout", "nodes[3].x", None),
    ("layout", "segments[2].length_m", -1e308),
    ("layout", "defaults.speed_limit_mps", -1e308),
    ("layout", "stations[0].handling.mean_s", -1e308),
    ("layout", "chargers[0].power_kw", -1e308),
    ("scenario", "duration_h", -1e308),
    ("scenario", "fleet.vehicle.accel_mps2", -1e308),
    ("scenario", "fleet.vehicle.battery.initial_soc_pct", 1e308),
    ("scenario", "demand.rate_per_hour", -1e308),
    ("scenario", "rules.safe_mode_rssi_dbm", None),
    ("scenario", "incidents.transfer_failure_prob", 1e308),
    ("scenario", "incidents.repair.high_s", -1e308),
    ("scenario", "sumo.step_length_s", 1e308),
    ("experiment", "sizing.agv_availability", 1e308),
    ("experiment", "targets[0].at_least", None),
    ("profile", "kinematics.max_speed_mmps", -1e308),
    ("profile", "battery.capacity_wh", -1e308),
    ("profile", "link.latency_s", -1e308),
    ("profile", "link.jitter.mean_s", -1e308),
]
CASES = [(kind, element, value) for kind, element, absurd in FIELDS
         for value in (math.nan, math.inf, -math.inf, absurd) if value is not None]


@pytest.mark.parametrize(("kind", "element", "value"), CASES,
                         ids=[f"{k}:{e}={v}" for k, e, v in CASES])
def test_non_finite_or_absurd_numbers_are_one_input_error(tmp_path: Path, kind: str,
                                                          element: str, value: float) -> None:
    data = _yaml(SOURCES[kind])
    if kind == "layout":
        data["chargers"] = [{"id": "CH", "node": "K"}]  # a charger to break (K is parking)
    if element.startswith("incidents.repair"):
        data["incidents"] = {"repair": {"dist": "triangular", "low_s": 1, "mode_s": 2,
                                        "high_s": 3}}
    if kind == "experiment":
        data["scenario"] = str(ROOT / "experiments" / "tiny_loop.yaml")
    _set(data, element, value)
    path = write_yaml(tmp_path / SOURCES[kind].name, data)
    with pytest.raises(InputError) as info:
        _load(kind, path)
    error = info.value
    assert (error.file, error.element) == (str(path), element)
    if math.isnan(value):
        assert math.isnan(float(error.value))  # type: ignore[arg-type]
    else:
        assert error.value == value
    assert error.expected == ("a finite number" if not math.isfinite(value)
                              else error.expected)
    assert error.expected.startswith(("a finite number", "a number >", "a number in",
                                      "a number <"))
    assert str(error).startswith(f"{path}: {element}: got ")


def test_trace_rows_refuse_nan(tmp_path: Path) -> None:
    layout = load_layout(LAYOUTS / "tiny_loop.yaml")
    trace = tmp_path / "orders.csv"
    trace.write_text("time_s,pickup,dropoff\n10,PICK,DROP\nnan,PICK,DROP\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"orders.csv: row 3.time_s: got 'nan'; expected a "
                                         r"finite number$"):
        load_trace(trace, layout)


# ---- the formatter ----------------------------------------------------------------------------

@pytest.mark.parametrize(("data", "element", "value", "expected"), [
    ({"from": "A"}, "to", None, "a value for required key 'to'"),
    ({"from": "A", "to": "B", "length_m": True}, "length_m", True, "a number"),
    ({"from": "A", "to": "B", "length_m": [3]}, "length_m", [3], "a number"),
    ({"from": "A", "to": "B", "length_m": "3"}, "length_m", "3", "a number"),
    ({"from": "A", "to": "B", "direction": "both"}, "direction", "both",
     "one of 'one_way', 'two_way'"),
    ({"from": "A", "to": "B", "from_node": "C"}, "from_node", "C",
     "no such key here: did you mean 'from'? (known keys: from, to, length_m, speed_limit_mps, "
     "direction, branch, rssi_dbm, allowed_types, speed_limit_mps_by_type)"),
    (["A", "B"], "top level", ["A", "B"], "a mapping"),
])
def test_formatter_speaks_the_files_language(data: Any, element: str, value: object,
                                             expected: str) -> None:
    with pytest.raises(InputError) as info:
        validate(SegmentSpec, data, "f.yaml")
    assert (info.value.element, info.value.value, info.value.expected) == (
        element, value, expected)


def test_a_number_may_name_a_node() -> None:
    segment = validate(SegmentSpec, {"from": 12, "to": "B"}, "f.yaml")
    assert segment.from_node == "12"


def test_read_yaml_names_the_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nnodes: [\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"bad.yaml: line 3: got .*; expected valid YAML"):
        read_yaml(bad)


def test_input_error_survives_pickling() -> None:
    import pickle

    error = InputError("f.yaml", "fleet.size", 0, "an integer >= 1")
    again = pickle.loads(pickle.dumps(error))
    assert (again.file, again.element, again.value, again.expected) == (
        "f.yaml", "fleet.size", 0, "an integer >= 1")
    assert str(again) == str(error)


@pytest.mark.parametrize(("kind", "edit", "message"), [
    ("scenario", lambda d: d["fleet"].update(sise=2),
     "fleet.sise: got 2; expected no such key here: did you mean 'size'? (known keys: size,"),
    ("scenario", lambda d: d.update(duration=2),
     "duration: got 2; expected no such key here: did you mean 'duration_h'?"),
    ("experiment", lambda d: d.update(replication=2),
     "replication: got 2; expected no such key here: did you mean 'replications'?"),
    ("layout", lambda d: d["segments"][0].update(lenght_m=4),
     "segments[0].lenght_m: got 4; expected no such key here: did you mean 'length_m'?"),
    ("scenario", lambda d: d["fleet"].update(colour="red"),  # nothing close: no guess
     "fleet.colour: got 'red'; expected no such key here (known keys: size,"),
])
def test_an_unknown_key_gets_did_you_mean(tmp_path: Path, kind: str, edit: Any,
                                          message: str) -> None:
    """An unknown key in a scenario, experiment or layout file names the key meant, where one
    is close (difflib), before the list of known keys."""
    source = {"scenario": ROOT / "experiments" / "tiny_loop.yaml",
              "experiment": ROOT / "experiments" / "tiny_loop_sizing.yaml",
              "layout": LAYOUTS / "tiny_loop.yaml"}[kind]
    data = _yaml(source)
    if kind == "scenario":
        data["layout"] = str(LAYOUTS / "tiny_loop.yaml")
        data.setdefault("fleet", {})
    if kind == "experiment":
        data["scenario"] = str(ROOT / "experiments" / "tiny_loop.yaml")
    edit(data)
    path = write_yaml(tmp_path / f"{kind}.yaml", data)
    load = {"scenario": load_scenario, "experiment": load_experiment, "layout": load_layout}
    with pytest.raises(InputError) as info:
        load[kind](path)
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


def test_did_you_mean_offers_only_a_close_key() -> None:
    """A key the word begins or that begins it, or difflib's ratio >= 0.65; nothing for a
    word that merely shares a suffix (`sd_s` is not `mode_s`)."""
    from userfiles.checking import closest

    assert closest("from_node", ["from", "to", "length_m"]) == "from"
    assert closest("rate", ["rate_per_hour", "kind"]) == "rate_per_hour"
    assert closest("sise", ["size", "vehicle"]) == "size"
    assert closest("sd_s", ["dist", "low_s", "mode_s", "high_s"]) is None
    assert closest("top_speed_kmh", ["max_speed_mmps", "turn_speed_mmps"]) is None
    assert closest("colour", ["size", "vehicle", "vehicles"]) is None


def test_more_aliases_than_allowed_are_refused_before_anything_is_built(tmp_path: Path) -> None:
    """An alias is counted in the composed document (libyaml's parser composes in C): 1,000
    are read, the 1,001st is refused, naming the line of the node it refers to."""
    from userfiles.reading import MAX_YAML_ALIASES

    for count, refused in ((MAX_YAML_ALIASES, False), (MAX_YAML_ALIASES + 1, True)):
        path = tmp_path / f"aliases{count}.yaml"
        path.write_text("a: &a 1\nb:\n" + "".join("  - *a\n" for _ in range(count)), "utf-8")
        if refused:
            with pytest.raises(InputError, match=rf"line 1: got 'alias number {count} \(of the "
                                                 r"node on this line\)'; expected at most"):
                read_yaml(path)
        else:
            assert read_yaml(path)["b"] == [1] * count
