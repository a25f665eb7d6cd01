"""Targets are checked against the KPI catalogue before anything runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from fleet_sim.config.experiment import load_experiment
from fleet_sim.errors import InputError
from fleet_sim.study.targets import check_targets_known

from .conftest import ROOT, write_yaml

TINY = str(ROOT / "experiments" / "tiny_loop.yaml")


def experiment_file(tmp_path: Path, targets: list[dict[str, Any]]) -> Path:
    return write_yaml(tmp_path / "exp.yaml", {
        "name": "typo", "scenario": TINY, "overrides": {"duration_h": 0.5, "warmup_h": 0.1},
        "factors": {"fleet.size": [1, 2]}, "replications": 2, "targets": targets})


def test_known_kpis_pass_and_a_misspelt_one_is_named(tmp_path: Path) -> None:
    good = [{"kpi": "throughput_pct_of_demand", "at_least": 98},
            {"kpi": "errors_by_code.E_101", "at_most": 0},
            {"kpi": "lead_time_p95_s", "at_most": 600}]
    check_targets_known(load_experiment(experiment_file(tmp_path, good)))
    bad = [*good, {"kpi": "lead_time_p59_s", "at_most": 600}]
    path = experiment_file(tmp_path, bad)
    with pytest.raises(InputError) as caught:
        check_targets_known(load_experiment(path))
    assert (caught.value.file, caught.value.element, caught.value.value) == (
        str(path), "targets[3].kpi", "lead_time_p59_s")
    assert "(closest: lead_time_p95_s)" in caught.value.expected


@pytest.mark.parametrize("name", ["seed", "agvs", "errors_by_code", "errors_by_code.E_123"])
def test_run_fields_and_unflattened_or_unknown_codes_are_no_kpis(tmp_path: Path,
                                                                 name: str) -> None:
    path = experiment_file(tmp_path, [{"kpi": name, "at_least": 1}])
    with pytest.raises(InputError, match=r"targets\[0\]\.kpi"):
        check_targets_known(load_experiment(path))


@pytest.mark.parametrize("command", ["sweep", "size"])
def test_unknown_kpi_stops_the_command_before_any_run(tmp_path: Path, command: str) -> None:
    path = experiment_file(tmp_path, [{"kpi": "throughput_pct_of_demnd", "at_least": 98}])
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", command, str(path),
                             "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                            timeout=600)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert lines[0].startswith(f"fleet-sim: error: {path}: targets[0].kpi: got "
                               "'throughput_pct_of_demnd'; expected one of the KPIs (closest: "
                               "throughput_pct_of_demand): ")
    assert result.stdout == "" and not out.exists()
