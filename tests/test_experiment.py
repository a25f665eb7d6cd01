"""Experiment files: validation, factor expansion, seeds."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fleet_sim.config.experiment import (
    experiment_warnings,
    load_experiment,
    replication_seed,
    run_id,
)
from fleet_sim.errors import InputError

from .conftest import LAYOUTS, ROOT, write_yaml

TINY = str(ROOT / "experiments" / "tiny_loop.yaml")


def experiment_file(tmp_path: Path, **fields: Any) -> Path:
    data: dict[str, Any] = {"name": "t", "scenario": TINY,
                            "overrides": {"duration_h": 0.5, "warmup_h": 0.1},
                            "factors": {"fleet.size": [1, 2]}, "replications": 2,
                            "master_seed": 7, **fields}
    return write_yaml(tmp_path / "exp.yaml", data)


def test_full_factorial_expands_every_combination_last_factor_fastest(tmp_path: Path) -> None:
    exp = load_experiment(experiment_file(
        tmp_path, factors={"fleet.size": [1, 2, 3], "demand.rate_per_hour": [20, 40]},
        replications=3))
    points = [dict(p) for p in exp.points]
    assert points == [{"fleet.size": n, "demand.rate_per_hour": r}
                      for n in (1, 2, 3) for r in (20, 40)]
    runs = exp.runs()
    assert len(runs) == 6 * 3
    assert len({r.run_id for r in runs}) == len(runs)
    first = runs[0]
    assert first.run_id == "demand.rate_per_hour=20__fleet.size=1__r00"
    assert first.override_dict() == {"duration_h": 0.5, "warmup_h": 0.1, "fleet.size": 1,
                                     "demand.rate_per_hour": 20, "seed": first.seed}


def test_seeds_common_across_levels_distinct_across_replications(tmp_path: Path) -> None:
    exp = load_experiment(experiment_file(tmp_path, replications=4))
    by_rep: dict[int, set[int]] = {}
    for run in exp.runs():
        by_rep.setdefault(run.replication, set()).add(run.seed)
    assert all(len(seeds) == 1 for seeds in by_rep.values())  # same seed at every level
    seeds = [next(iter(by_rep[r])) for r in range(4)]
    assert len(set(seeds)) == 4
    # replication r's seed is the r-th child of SeedSequence(master_seed).spawn(n)
    children = np.random.SeedSequence(7).spawn(4)
    assert seeds == [int(c.generate_state(1, np.uint32)[0]) for c in children]
    assert replication_seed(7, 9) == int(
        np.random.SeedSequence(7).spawn(10)[9].generate_state(1, np.uint32)[0])


def test_latin_hypercube_uses_each_stratum_once(tmp_path: Path) -> None:
    path = experiment_file(tmp_path, design="latin_hypercube", samples=8, factors={
        "demand.rate_per_hour": {"min": 20, "max": 60},
        "fleet.size": {"min": 1, "max": 4, "integer": True},
        "dispatch.policy": ["nearest_idle", "fcfs"]})
    exp = load_experiment(path)
    points = [dict(p) for p in exp.points]
    assert len(points) == 8
    rates = sorted(p["demand.rate_per_hour"] for p in points)
    assert [int((r - 20) / 40 * 8) for r in rates] == list(range(8))  # one per stratum
    sizes = [p["fleet.size"] for p in points]
    assert all(isinstance(s, int) for s in sizes)
    assert sorted(sizes) == [1, 1, 2, 2, 3, 3, 4, 4]
    assert sorted(p["dispatch.policy"] for p in points) == ["fcfs"] * 4 + ["nearest_idle"] * 4
    assert [dict(p) for p in load_experiment(path).points] == points  # same seed, same design


@pytest.mark.parametrize(("fields", "element", "expected"), [
    ({"replicatons": 3}, "replicatons", "no such key here"),
    ({"factors": {"fleet.sise": [1, 2]}}, "factors.fleet.sise[0]", "fleet.sise"),
    ({"factors": {"fleet.size": [1, "two"]}}, "factors.fleet.size[1]", "an integer"),
    ({"factors": {"fleet.size": [1, 9]}}, "design point (fleet.size=9)", "parking capacity"),
    ({"factors": {"seed": [1, 2]}}, "factors.seed", "master_seed"),
    ({"factors": {"fleet.size": {"min": 1, "max": 3}}}, "factors.fleet.size", "latin_hypercube"),
    ({"targets": [{"kpi": "lead_time_p95_s"}]}, "targets[0]", "exactly one of"),
    ({"scenario": "missing.yaml"}, "scenario", "an existing scenario file"),
    ({"overrides": {"warmup_h": 5}}, "overrides", "shorter than duration_h"),
])
def test_bad_experiment_names_file_element_and_value(tmp_path: Path, fields: dict[str, Any],
                                                     element: str, expected: str) -> None:
    path = experiment_file(tmp_path, **fields)
    with pytest.raises(InputError) as info:
        load_experiment(path)
    assert info.value.file == str(path)
    assert info.value.element == element
    assert expected in info.value.expected


def test_run_ids_are_stable_and_readable() -> None:
    assert run_id({"fleet.size": 8}, 3) == "fleet.size=8__r03"
    assert run_id({"b": 0.5, "a": "x y"}, 0) == "a=x-y__b=0.5__r00"
    long = run_id({f"factor_{i}.value": i for i in range(12)}, 1)
    assert long.startswith("p") and long.endswith("__r01") and len(long) < 40


def test_cli_bad_experiment_is_one_line_and_exit_2(tmp_path: Path) -> None:
    path = experiment_file(tmp_path, factors={"fleet.sise": [1]})
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "sweep", str(path)],
                            capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert "factors.fleet.sise" in lines[0] and str(path) in lines[0]


def test_setup_warnings_once_per_experiment_with_their_design_points(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path / "s.yaml", {
        "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 6, "warmup_h": 0.5})
    experiment = load_experiment(write_yaml(tmp_path / "e.yaml", {
        "name": "traps", "scenario": str(scenario),
        "factors": {"fleet.size": [1, 2, 3], "charging.enabled": [True, False]}}))
    warnings = experiment_warnings(experiment)
    assert len(warnings) == 2
    assert warnings[0].startswith("charging is on but the layout has no charger: AGV 0 (1 of 1)")
    assert warnings[0].endswith(" (in 3 of 6 design points)")
    assert warnings[1].startswith("charging.enabled is false but the battery drains")
    assert warnings[1].endswith(" (in 3 of 6 design points)")
    off = load_experiment(write_yaml(tmp_path / "off.yaml", {
        "name": "off", "scenario": str(scenario), "overrides": {"fleet.vehicle.battery": False},
        "factors": {"charging.enabled": [True, False]}}))
    assert experiment_warnings(off) == []
