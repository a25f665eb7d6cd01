"""fleet_sim.config.overrides: a scenario with a command's settings and flags, its file read
once, every problem named by what brought it (the command line's messages are tested in
test_cli.py and test_bad_inputs.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import fleet_sim.config.scenario as scenario_module
from fleet_sim.config.overrides import load_scenario, parse_agvs, parse_setting, scenario_of
from fleet_sim.config.scenario import resolved
from fleet_sim.errors import InputError

from .conftest import LAYOUTS, write_yaml

MIXED = {"name": "mixed", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.5,
         "warmup_h": 0.1, "fleet": {"vehicles": [{"type": "carrier", "count": 1},
                                                 {"type": "heavy", "count": 1}]}}


def test_the_file_is_read_once_with_settings_and_every_flag(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    file = write_yaml(tmp_path / "mixed.yaml", MIXED)
    reads: list[Path] = []
    read_yaml = scenario_module.read_yaml

    def counted(path: Path) -> Any:
        reads.append(path)
        return read_yaml(path)

    monkeypatch.setattr(scenario_module, "read_yaml", counted)
    scenario = load_scenario(file, [("demand.rate_per_hour", 30)], agvs={"heavy": 3},
                             hours=0.4, seed=7)
    assert reads == [file]
    assert scenario.demand.rate_per_hour == 30 and scenario.duration_h == 0.4
    assert scenario.seed == 7
    assert [(t.type, t.count) for t in scenario.fleet.vehicles] == [("carrier", 1), ("heavy", 3)]


def test_each_problem_names_what_brought_it(tmp_path: Path) -> None:
    file = write_yaml(tmp_path / "mixed.yaml", MIXED)
    cases: list[tuple[dict[str, Any], str, str]] = [
        ({"sets": {"fleet.vehicles.heavy.count": 0}}, "--set", "fleet.vehicles[1].count"),
        ({"hours": 0.05}, "--hours", "duration_h"),
        ({"agvs": 3}, "--agvs", ""),
        ({"agvs": {"hevy": 2}}, "--agvs", ""),
    ]
    for arguments, named, element in cases:
        with pytest.raises(InputError) as error:
            load_scenario(file, **arguments)
        assert (error.value.file, error.value.element) == (named, element), arguments
    broken = write_yaml(tmp_path / "broken.yaml", {**MIXED, "warmup_h": -1})
    with pytest.raises(InputError) as error:  # the file's own problem, whatever the settings
        load_scenario(broken, {"warmup_h": 0.1})
    assert error.value.file == str(broken)


def test_a_loaded_scenarios_resolved_config_takes_the_same_overrides(tmp_path: Path) -> None:
    scenario = load_scenario(write_yaml(tmp_path / "mixed.yaml", MIXED))
    again = scenario_of(resolved(scenario), "<scenario mixed>", scenario.base_dir,
                        agvs={"carrier": 2}, seed=3)
    assert [t.count for t in again.fleet.vehicles] == [2, 1] and again.seed == 3


@pytest.mark.parametrize(("text", "value"), [("3", 3), ("heavy=2, carrier=1",
                                                         {"heavy": 2, "carrier": 1})])
def test_agvs_text(text: str, value: object) -> None:
    assert parse_agvs(text) == value


@pytest.mark.parametrize(("text", "message"), [
    ("0", "got '0'; expected an integer number of AGVs >= 1 and <= 2000"),
    ("a=1,a=2", "got 'a=1,a=2'; expected N, or TYPE=N[,TYPE=N] with each type once"),
    ("a=x", "got 'x'; expected an integer number of a AGVs >= 1 and <= 2000"),
])
def test_bad_agvs_text(text: str, message: str) -> None:
    with pytest.raises(ValueError, match="^" + message.replace("[", r"\[").replace("]", r"\]")):
        parse_agvs(text)


def test_setting_text() -> None:
    assert parse_setting("demand.rate_per_hour=60") == ("demand.rate_per_hour", 60)
    with pytest.raises(ValueError, match="KEY a dotted scenario field"):
        parse_setting("fleet.size")
