"""The Python API (fleet_sim.api): the same runs and messages as the command, KPIs as dicts,
tables as DataFrames; `import fleet_sim` stays light; the tutorial page's code runs."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

import fleet_sim
from fleet_sim.analysis.tables import ORDER_COLUMNS
from fleet_sim.config.experiment import load_experiment
from fleet_sim.config.scenario import load_scenario
from tests.conftest import ROOT, write_yaml

TINY = ROOT / "experiments" / "tiny_loop.yaml"
SIZING = ROOT / "experiments" / "tiny_loop_sizing.yaml"
DESIGN = ROOT / "experiments" / "tiny_loop_design.yaml"
EVENT_COLUMNS = ["time_s", "agv", "event", "from_state", "to_state", "node", "detail"]


def test_import_fleet_sim_is_light_and_offers_the_api() -> None:
    """`import fleet_sim` loads neither pandas nor the simulation; the names come on use."""
    code = ("import sys, fleet_sim; heavy = {'pandas', 'simpy', 'fleet_sim.api'} & "
            "set(sys.modules); assert not heavy, heavy; "
            "assert callable(fleet_sim.run) and 'pandas' in sys.modules; "
            "assert fleet_sim.InputError.__module__ == 'userfiles.checking'")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
    assert {"run", "sweep", "size", "compare", "optimise", "InputError"} <= set(dir(fleet_sim))
    with pytest.raises(AttributeError, match="no attribute 'walk'"):
        fleet_sim.walk  # noqa: B018


def test_run_gives_the_kpis_and_tables_of_the_command(tmp_path: Path) -> None:
    """The same run through the command and the API: kpis.json equal to the result's KPIs,
    the tables equal to the run directory's."""
    from fleet_sim.cli import main

    args = ["--hours", "0.5", "--agvs", "3", "--seed", "4"]
    assert main(["run", str(TINY), *args, "--out", str(tmp_path / "cli"), "--quiet"]) == 0
    result = fleet_sim.run(TINY, agvs=3, hours=0.5, seed=4)
    assert result.kpis == json.loads((tmp_path / "cli" / "kpis.json").read_text())
    assert result.kpis["agvs"] == 3 and result.kpis["duration_h"] == 0.5
    assert result.run_dir is None and result.scenario.fleet.size == 3
    pd.testing.assert_frame_equal(result.orders, pd.read_parquet(tmp_path / "cli" /
                                                                 "orders.parquet"))
    assert list(result.orders.columns) == list(ORDER_COLUMNS)
    assert list(result.events.columns) == EVENT_COLUMNS
    assert len(result.orders) == result.kpis["orders_created"] > 0


def test_run_keeps_its_run_directory_and_takes_a_loaded_scenario(tmp_path: Path) -> None:
    """With `out` the run directory is written and kept; a loaded Scenario with overrides runs
    as its file with the same overrides."""
    on_disk = fleet_sim.run(TINY, hours=0.5, set={"demand.rate_per_hour": 30},
                            out=tmp_path / "r")
    assert on_disk.run_dir == tmp_path / "r"
    assert json.loads((tmp_path / "r" / "kpis.json").read_text()) == on_disk.kpis
    loaded = fleet_sim.run(load_scenario(TINY), hours=0.5, set=[("demand.rate_per_hour", 30)])
    assert loaded.kpis == on_disk.kpis
    assert loaded.scenario.demand.rate_per_hour == on_disk.scenario.demand.rate_per_hour == 30


def _cli_message(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    from fleet_sim.cli import main

    capsys.readouterr()
    assert main(["run", str(TINY), *args]) == 2
    line: str = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("fleet-sim: error: ")
    return line.removeprefix("fleet-sim: error: ")


@pytest.mark.parametrize(("cli", "api"), [
    (["--set", "fleet.colour=red"], {"set": {"fleet.colour": "red"}}),
    (["--agvs", "heavy=2"], {"agvs": {"heavy": 2}}),
    (["--hours", "0.05"], {"hours": 0.05}),
    (["--set", "warmup_h=2"], {"set": {"warmup_h": 2}}),
])
def test_bad_input_raises_input_error_with_the_commands_message(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, cli: list[str],
        api: dict[str, Any]) -> None:
    expected = _cli_message(capsys, *cli, "--out", str(tmp_path / "cli"))
    with pytest.raises(fleet_sim.InputError) as caught:
        fleet_sim.run(TINY, **api)
    assert str(caught.value) == expected
    assert capsys.readouterr() == ("", "")  # the API prints nothing


def test_a_bad_file_names_the_file(tmp_path: Path) -> None:
    bad = write_yaml(tmp_path / "s.yaml", {"layout": str(ROOT / "layouts" / "tiny_loop.yaml"),
                                           "fleet": {"size": 1, "colour": "red"}})
    with pytest.raises(fleet_sim.InputError, match=re.escape(f"{bad}: fleet.colour: got")):
        fleet_sim.run(bad)
    with pytest.raises(fleet_sim.InputError, match="an experiment file"):
        fleet_sim.run(SIZING)


def test_size_finds_the_hand_computed_fleet(tmp_path: Path) -> None:
    """The tiny loop at 45 orders/h: one AGV carries about 31 orders/h, two keep up."""
    result = fleet_sim.size(SIZING, out=tmp_path / "size", workers=2)
    assert result.recommended == 2
    assert result.statements[0].startswith("2 AGVs meet every target")
    assert result.document["groups"][0]["recommended"] == 2
    assert {"run_id", "status", "fleet.size", "throughput_per_hour"} <= set(result.summary)
    assert {"fleet.size", "kpi", "mean", "half_width"} <= set(result.stats)
    assert result.database.is_file()


def test_sweep_with_settings_and_a_loaded_experiment(tmp_path: Path) -> None:
    """`set` reaches every run; a loaded Experiment sweeps as its file; a second sweep into the
    same folder makes no run again."""
    result = fleet_sim.sweep(SIZING, out=tmp_path / "w", workers=2,
                             set={"duration_h": 1, "demand.rate_per_hour": 20})
    assert len(result.summary) == 9 and result.failed == []
    assert result.experiment.scenario({"fleet.size": 1}).demand.rate_per_hour == 20
    assert set(result.summary["duration_h"]) == {1}
    again = fleet_sim.sweep(load_experiment(SIZING), out=tmp_path / "w", workers=2,
                            set={"duration_h": 1, "demand.rate_per_hour": 20})
    assert again.outcome.skipped == 9
    pd.testing.assert_frame_equal(again.summary, result.summary)
    with pytest.raises(fleet_sim.InputError, match=r"^--set: fleet.size: "):
        fleet_sim.sweep(SIZING, out=tmp_path / "x", set={"fleet.size": 3})


def test_compare_tables_its_paired_differences(tmp_path: Path) -> None:
    experiment = write_yaml(tmp_path / "cmp.yaml", {
        "name": "cmp", "scenario": str(TINY), "master_seed": 5,
        "overrides": {"duration_h": 0.75, "warmup_h": 0.1, "demand.rate_per_hour": 40},
        "variants": {"slow_drop": {"layout_changes": [{"station_handling": {
            "id": "DROP", "handling": {"dist": "fixed", "mean_s": 90}}}]}},
        "compare": {"kpis": ["lead_time_mean_s"], "min_replications": 3,
                    "max_replications": 4}})
    result = fleet_sim.compare(experiment, out=tmp_path / "c", workers=2)
    assert list(result.comparisons["variant"]) == ["slow_drop"]
    assert {"kpi", "difference", "ci_low", "ci_high", "verdict"} <= set(result.comparisons)
    assert result.comparisons["difference"].iloc[0] > 0  # a slower drop-off: longer lead times
    assert result.document == json.loads((tmp_path / "c" / "compare.json").read_text())
    assert "variant" in result.summary
    with pytest.raises(fleet_sim.InputError, match="at least one variant"):
        fleet_sim.compare(SIZING, out=tmp_path / "d")


def test_optimise_finds_the_hand_computed_design(tmp_path: Path) -> None:
    """One AGV with fast handling (130 k) beats two AGVs (200 k) at 33 orders/h."""
    result = fleet_sim.optimise(DESIGN, out=tmp_path / "o", workers=2)
    assert result.answer is not None and result.answer["design"] == "fleet.size=1, handling=fast"
    assert result.answer["price"] == 130
    assert {"label", "price", "verdict"} <= set(result.designs)
    assert result.statement == result.document["statement"]
    with pytest.raises(fleet_sim.InputError, match="optimise"):
        fleet_sim.optimise(SIZING, out=tmp_path / "p")


# --- the tutorial page -----------------------------------------------------------------------

TUTORIAL = ROOT / "docs" / "tutorial" / "python.md"
CODE = re.compile(r"^```python\n(.*?)^```", re.MULTILINE | re.DOTALL)


def test_the_python_tutorial_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every ```python block of docs/tutorial/python.md, in order, in one namespace, from a
    folder holding the bundled experiments and layouts (as the repository's root)."""
    blocks = CODE.findall(TUTORIAL.read_text(encoding="utf-8"))
    assert len(blocks) >= 5
    for folder in ("experiments", "layouts"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict[str, Any] = {"__name__": "__tutorial__"}
    for i, block in enumerate(blocks):
        exec(compile(block, f"{TUTORIAL.name} block {i + 1}", "exec"), namespace)
    assert os.path.isdir(tmp_path / "results")
