"""Fleet sizing on the tiny loop, where the answer is known by hand (see test_engine): one AGV
needs 2 x 32.6267 s of travel + 20 s pick + 30 s drop = 115.2533 s per order, so it carries
31.2 orders/h; at 45 orders/h one AGV cannot keep up and two can."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from fleet_sim.config.experiment import load_experiment
from fleet_sim.study.sizing import RunBudget, SizingLimit, size_fleet

from .conftest import ROOT, write_yaml

EXPERIMENT = ROOT / "experiments" / "tiny_loop_sizing.yaml"


def test_size_search_finds_the_known_answer(tmp_path: Path) -> None:
    experiment = load_experiment(EXPERIMENT)
    out = tmp_path / "sizing"
    (result,) = size_fleet(experiment, out, workers=2, quiet=True)
    assert result.recommended == 2
    assert result.evaluations[2].verdict == "meets"
    assert result.evaluations[1].verdict == "fails"  # and one AGV is shown to fail
    assert set(result.evaluations) == {1, 2}  # started at the estimate: no blind grid
    assert result.evaluations[1].replications == experiment.spec.replications  # clear: no more
    through = result.evaluations[1].checks[0]
    assert through.interval.high < 98 * 31.3 / 45  # one AGV carries ~31 of 45 orders/h
    document = json.loads((out / "sizing.json").read_text())
    (group,) = document["groups"]
    assert group["recommended"] == 2
    assert group["estimate"]["cycle_s"] == pytest.approx(115.2533, abs=1e-4)
    assert group["statement"].startswith("2 AGVs meet every target with 95 % confidence")
    runs = {p.name for p in (out / "runs").iterdir()}
    assert {f"fleet.size=1__r{r:02d}" for r in range(3)} <= runs
    assert not any(name.startswith("fleet.size=3") for name in runs)


def test_search_stops_at_the_run_limit_and_keeps_what_it_decided(tmp_path: Path) -> None:
    """With room for 4 runs, the search evaluates its first fleet size (3 replications) and
    stops before asking for 3 more: sizing.json and the runs done stay."""
    data = yaml.safe_load(EXPERIMENT.read_text())
    data["scenario"] = str(EXPERIMENT.parent / data["scenario"])
    data["overrides"]["duration_h"] = 1.5
    experiment = load_experiment(write_yaml(tmp_path / "e.yaml", data))
    out = tmp_path / "sizing"
    with pytest.raises(SizingLimit, match="needs more than 4 runs, the limit of one experiment"):
        size_fleet(experiment, out, workers=1, quiet=True, max_runs=4)
    document = json.loads((out / "sizing.json").read_text())
    assert document["max_runs"] == 4 and document["runs_used"] == 3
    (group,) = document["groups"]
    assert group["stopped"] and group["recommended"] is None
    assert len(group["evaluations"]) == 1 and group["evaluations"][0]["replications"] == 3
    assert group["statement"].startswith("no answer (")
    finished = [p for p in (out / "runs").iterdir() if (p / "kpis.json").exists()]
    assert len(finished) == 3 == len(list((out / "runs").iterdir()))


def test_run_budget_counts_each_run_once() -> None:
    experiment = load_experiment(EXPERIMENT)
    runs = [experiment.run({"fleet.size": 2}, r) for r in range(3)]
    budget = RunBudget(4)
    budget.take(runs)
    budget.take(runs[:2])  # reused runs cost nothing
    with pytest.raises(SizingLimit, match="used 3 and asked for 2 more"):
        budget.take([experiment.run({"fleet.size": 3}, r) for r in range(2)])
    assert len(budget.used) == 3
    budget.take([experiment.run({"fleet.size": 3}, 0)])
    assert len(budget.used) == 4
