"""Fleet sizing on the tiny loop, where the answer is known by hand (see test_engine): one AGV
needs 2 x 32.6267 s of travel + 20 s pick + 30 s drop = 115.2533 s per order, so it carries
31.2 orders/h; at 45 orders/h one AGV cannot keep up and two can."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from fleet_sim.config.experiment import load_experiment
from fleet_sim.study.sizing import RunBudget, SizingLimit, size_fleet

from .conftest import ROOT, write_yaml

EXPERIMENT = ROOT / "experiments" / "tiny_loop_sizing.yaml"


def test_size_search_finds_the_known_answer(tmp_path: Path) -> None:
    experiment = load_experiment(EXPERIMENT)
    out = tmp_path / "sizing"
    stream = io.StringIO()
    (result,) = size_fleet(experiment, out, workers=2, stream=stream)
    assert result.recommended == 2
    assert result.evaluations[2].verdict == "meets"
    assert result.evaluations[1].verdict == "fails"  # and one AGV is shown to fail
    assert set(result.evaluations) == {1, 2}  # started at the estimate: no blind grid
    # sequential stopping: a clear case takes the minimum, two replications
    assert result.evaluations[1].replications == experiment.spec.sizing.min_replications
    through = result.evaluations[1].checks[0]
    assert through.interval.high < 98 * 31.3 / 45  # one AGV carries ~31 of 45 orders/h
    document = json.loads((out / "sizing.json").read_text())
    (group,) = document["groups"]
    assert group["recommended"] == 2
    assert group["estimate"]["cycle_s"] == pytest.approx(115.2533, abs=1e-4)
    assert group["statement"].startswith("2 AGVs meet every target with 95 % confidence")
    runs = {p.name for p in (out / "runs").iterdir()}
    assert {f"fleet.size=1__r{r:02d}" for r in range(2)} <= runs
    assert "fleet.size=1__r02" not in runs
    assert not any(name.startswith("fleet.size=3") for name in runs)
    # every run the search asked for is in the summary, and it says so
    assert stream.getvalue().rstrip().endswith(
        f"all {len(runs)} planned runs are in the summary ({len(runs)} finished)")


def variant(tmp_path: Path, source: Path, name: str, **changes: Any) -> Path:
    """The experiment file `source` with `changes` to its top-level keys (sizing merged)."""
    data = yaml.safe_load(source.read_text(encoding="utf-8"))
    data["scenario"] = str((source.parent / data["scenario"]).resolve())
    sizing = {**data.get("sizing", {}), **changes.pop("sizing", {})}
    data.update({**changes, "sizing": sizing})
    return write_yaml(tmp_path / f"{name}.yaml", data)


@pytest.mark.parametrize("source,changes,cap", [
    (EXPERIMENT, {}, 8),
    (ROOT / "experiments" / "warehouse_sizing.yaml",  # shortened: 2-hour shifts, one demand
     {"overrides": {"warmup_h": 0.25, "duration_h": 2.0}, "warmup": {"method": "fixed"},
      "factors": {"fleet.size": list(range(6, 15)), "demand.rate_per_hour": [90]}}, 6),
])
def test_sequential_stopping_recommends_what_fixed_replications_do(
        tmp_path: Path, source: Path, changes: dict[str, Any], cap: int) -> None:
    """The same seeds, the same searches: `cap` replications at every fleet size looked at,
    against as few as decide it (2, then 2 more at a time, up to `cap`)."""
    out = tmp_path / "out"  # shared: the sequential search reuses the fixed one's runs
    fixed_file = variant(tmp_path, source, "fixed", replications=cap,
                         sizing={"stopping": "fixed", "max_replications": cap}, **changes)
    sequential_file = variant(tmp_path, source, "sequential", replications=cap,
                              sizing={"stopping": "sequential", "max_replications": cap},
                              **changes)
    fixed = size_fleet(load_experiment(fixed_file), out, workers=2, quiet=True)
    sequential = size_fleet(load_experiment(sequential_file), out, workers=2, quiet=True)
    assert [g.recommended for g in sequential] == [g.recommended for g in fixed]
    assert all(g.recommended is not None for g in fixed)
    assert sum(g.runs() for g in sequential) < sum(g.runs() for g in fixed)
    document = json.loads((out / "sizing.json").read_text())
    assert document["stopping"] == "sequential" and document["runs"] == \
        sum(g.runs() for g in sequential)


def test_search_stops_at_the_run_limit_and_keeps_what_it_decided(tmp_path: Path) -> None:
    """With room for 4 runs, the search evaluates its first fleet size (3 replications) and
    stops before asking for 3 more: sizing.json and the runs done stay."""
    data = yaml.safe_load(EXPERIMENT.read_text())
    data["scenario"] = str(EXPERIMENT.parent / data["scenario"])
    data["overrides"]["duration_h"] = 1.5
    data.setdefault("sizing", {})["stopping"] = "fixed"  # 3 replications per size
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


# A mixed fleet: one type's count is searched, the others keep theirs

def mixed_experiment(tmp_path: Path, **sizing: Any) -> Path:
    """The tiny loop at 50 orders/h with one carrier (1 m/s, ~29 orders/h alone) and a number
    of slower heavy AGVs (0.8 m/s) to find: one heavy AGV beside it keeps up only with p95
    lead times of about 500 s, two bring them to about 250 s."""
    scenario = {"name": "mixed_loop", "layout": str(ROOT / "layouts" / "tiny_loop.yaml"),
                "fleet": {"vehicles": [
                    {"type": "carrier", "count": 1, "vehicle": {"battery": "off"}},
                    {"type": "heavy", "count": 1,
                     "vehicle": {"battery": "off", "max_speed_mps": 0.8, "length_m": 1.4}}]},
                "demand": {"rate_per_hour": 50}}
    write_yaml(tmp_path / "mixed_loop.yaml", scenario)
    data = {"name": "mixed_sizing", "scenario": "mixed_loop.yaml",
            "overrides": {"duration_h": 3, "warmup_h": 0.5}, "master_seed": 7,
            "targets": [{"kpi": "lead_time_p95_s", "at_most": 450}],
            "sizing": {"min_agvs": 1, "max_agvs": 3, "stopping": "fixed", **sizing},
            "replications": 3}
    return write_yaml(tmp_path / "mixed_sizing.yaml", data)


def test_sizing_a_mixed_fleet_varies_one_type_and_keeps_the_others(tmp_path: Path) -> None:
    experiment = load_experiment(mixed_experiment(tmp_path, vary_type="heavy"))
    assert experiment.fleet_factor == "fleet.vehicles.heavy.count"
    out = tmp_path / "sizing"
    stream = io.StringIO()
    (result,) = size_fleet(experiment, out, workers=2, stream=stream)
    assert result.recommended == 2
    assert result.evaluations[1].verdict != "meets"
    assert set(result.evaluations) == {1, 2}  # from the estimate (2 AGVs) less the carrier
    assert result.statement().startswith("2 heavy AGVs (beside 1 carrier) meet every target")
    document = json.loads((out / "sizing.json").read_text())
    (group,) = document["groups"]
    assert (group["vary_type"], group["beside"], group["recommended"]) == \
        ("heavy", {"carrier": 1}, 2)
    runs = sorted((out / "runs").iterdir())
    assert [p.name for p in runs] == [f"fleet.vehicles.heavy.count={n}__r{r:02d}"
                                      for n in (1, 2) for r in range(3)]
    for run in runs:  # the carrier count never changes; the heavy count is the run's
        fleet = yaml.safe_load((run / "config.resolved.yaml").read_text())["fleet"]
        counts = {t["type"]: t["count"] for t in fleet["vehicles"]}
        assert counts == {"carrier": 1, "heavy": int(run.name.split("=")[1][0])}, run.name
        kpis = json.loads((run / "kpis.json").read_text())
        assert kpis["by_type"]["carrier.agvs"] == 1


@pytest.mark.parametrize(("sizing", "factors", "message"), [
    ({}, {}, r"sizing.vary_type: got None; expected the vehicle type whose count the search "
             r"varies, .*fleet mixes carrier, heavy; for example sizing: \{vary_type: heavy\}"),
    ({"vary_type": "hevy"}, {}, r"sizing.vary_type: got 'hevy'; expected a type of the base "
                                r"scenario's fleet.vehicles \(carrier, heavy\)"),
    ({"vary_type": "heavy"}, {"fleet.size": [3, 4]},
     r"factors.fleet.size\[0\].*fleet.vehicles.<type>.count"),
])
def test_a_mixed_fleet_sizing_names_what_to_write(tmp_path: Path, sizing: dict[str, Any],
                                                  factors: dict[str, Any], message: str) -> None:
    from fleet_sim.errors import InputError

    path = mixed_experiment(tmp_path, **sizing)
    if factors:
        data = yaml.safe_load(path.read_text())
        write_yaml(path, {**data, "factors": factors})
    with pytest.raises(InputError, match=message):
        size_fleet(load_experiment(path), tmp_path / "out", workers=1, quiet=True)


def test_vary_type_needs_a_mixed_fleet(tmp_path: Path) -> None:
    from fleet_sim.errors import InputError

    data = yaml.safe_load(EXPERIMENT.read_text())
    data["scenario"] = str(EXPERIMENT.parent / data["scenario"])
    data["sizing"]["vary_type"] = "heavy"
    with pytest.raises(InputError, match=r"sizing.vary_type: got 'heavy'; expected no "
                                         r"vary_type with a one-type fleet"):
        load_experiment(write_yaml(tmp_path / "vary.yaml", data))
