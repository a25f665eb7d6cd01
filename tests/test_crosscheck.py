"""The closed form against SUMO on small cases (each run in its own process).

Tolerances, and why:
* One AGV on the tiny loop: only segment timing differs. SUMO drives the same trapezoids
  (ballistic update, sigma 0), but it sees each stop and start on its 0.1 s step grid and
  Krauss eases into a stop rather than braking at a constant rate to the very end. With two
  stops per cycle that costs about 0.15 s in 121 s: each delivery cycle must agree within
  0.3 % (0.36 s), throughput exactly.
* Two AGVs: they now also interact, and SUMO keeps a time headway (tau 1 s) behind the AGV
  ahead where the closed form only keeps the node locks' gap; queue orders can change. Lead
  times within 3 %, throughput within 1 order/h, distance within 1 %.
"""

from __future__ import annotations

import statistics
from pathlib import Path

import pytest

from fleet_sim.study.crosscheck import crosscheck, table

from .conftest import LAYOUTS, ROOT, write_yaml

CYCLE_S = 121.2533  # tests/test_engine.py: D->P + pick + P->D + drop, by hand


def test_one_agv_on_the_tiny_loop_agrees_closely(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path / "one.yaml", {
        "name": "one_agv", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.75,
        "warmup_h": 0.1, "fleet": {"size": 1}, "demand": {"rate_per_hour": 60}})
    results = crosscheck(scenario, {})
    base, sumo = results["closed_form"], results["sumo"]
    assert base["throughput_per_hour"] == sumo["throughput_per_hour"]
    gaps = {motion: [b - a for a, b in zip(r["delivered_s"][2:], r["delivered_s"][3:],
                                             strict=False)]
            for motion, r in results.items()}
    assert statistics.median(gaps["closed_form"]) == pytest.approx(CYCLE_S, abs=1e-3)
    assert len(gaps["sumo"]) >= 15
    for gap in gaps["sumo"]:
        assert gap == pytest.approx(CYCLE_S, rel=0.003)
    for key in ("lead_time_mean_s", "lead_time_p95_s"):
        assert sumo[key] == pytest.approx(base[key], rel=0.01)
    assert sumo["distance_km"] == pytest.approx(base["distance_km"], rel=0.001)


def test_two_agvs_on_the_tiny_loop_agree_within_a_looser_tolerance() -> None:
    results = crosscheck(ROOT / "experiments" / "tiny_loop.yaml", {"duration_h": 1.0})
    base, sumo = results["closed_form"], results["sumo"]
    assert base["agvs"] == sumo["agvs"] == 2
    assert sumo["throughput_per_hour"] == pytest.approx(base["throughput_per_hour"], abs=1.0)
    for key in ("lead_time_mean_s", "lead_time_p95_s"):
        assert sumo[key] == pytest.approx(base[key], rel=0.03)
    assert sumo["distance_km"] == pytest.approx(base["distance_km"], rel=0.01)
    text = table(results)
    assert "sumo vs closed_form" in text and "throughput /h" in text


def test_crosscheck_command_prints_the_table() -> None:
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "crosscheck",
                             "experiments/tiny_loop.yaml", "--agvs", "1", "--hours", "0.2"],
                            cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("tiny_loop: 1 AGVs, 0.2 h")
    assert [line.split()[0] for line in lines[2:5]] == ["closed_form", "sumo", "sumo"]


def test_crosscheck_command_names_bad_input() -> None:
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "crosscheck",
                             "experiments/tiny_loop.yaml", "--agvs", "0"],
                            cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 2
    assert "argument --agvs: got '0'; expected an integer number of AGVs >= 1" in result.stderr
