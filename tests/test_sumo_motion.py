"""`motion: sumo`: every bundled scenario runs, runs repeat, faults and obstacles work, libsumo
stays out of closed-form runs, and bad settings are named. Every SUMO run here is in its own
process (fleet_sim.study.crosscheck.run_isolated), as libsumo requires."""

from __future__ import annotations

import subprocess
import sys

import pytest

from fleet_sim.errors import InputError
from fleet_sim.study.crosscheck import run_isolated

from .conftest import ROOT, make_scenario


@pytest.mark.parametrize("name", ["tiny_loop", "warehouse_shift", "warehouse_incidents"])
def test_every_bundled_scenario_runs_with_sumo(name: str) -> None:
    figures = run_isolated(ROOT / "experiments" / f"{name}.yaml",
                           {"motion": "sumo", "duration_h": 0.3, "warmup_h": 0.05})
    assert figures["motion"] == "sumo"
    assert figures["orders_completed"] > 0
    assert figures["distance_km"] > 0
    # no faster than the handling alone: triangular lows 15 s and 10 s (tiny loop: 20 and 30 s)
    # plus 3 s of sub-states at each end
    assert figures["lead_time_mean_s"] > 15 + 10 + 2 * 3


def test_same_seed_same_run_under_sumo() -> None:
    overrides = {"motion": "sumo", "duration_h": 0.25, "warmup_h": 0.0, "fleet.size": 3}
    first = run_isolated(ROOT / "experiments" / "tiny_loop.yaml", overrides)
    second = run_isolated(ROOT / "experiments" / "tiny_loop.yaml", overrides)
    assert first["delivered_s"] == second["delivered_s"]
    assert first["blocked_time_pct"] == second["blocked_time_pct"]


def test_a_fault_while_driving_is_recovered_under_sumo() -> None:
    """AGV 0 fails on the loop; the operator takes it off, repairs it, and it goes back to
    work: SUMO removes the vehicle and inserts it again where it comes back."""
    figures = run_isolated(ROOT / "experiments" / "tiny_loop.yaml", {
        "motion": "sumo", "duration_h": 1.0, "warmup_h": 0.0, "fleet.size": 2,
        "incidents.faults": [{"agv": 0, "at_s": 130.0, "code": "E_999"}],
        "incidents.obstacle_rate_per_km": 20.0, "incidents.line_loss_per_km": 5.0})
    assert figures["errors_by_code"].get("E_999") == 1
    assert figures["obstacle_pauses"] > 0
    assert figures["orders_completed"] >= 20


def _python(code: str) -> subprocess.CompletedProcess[str]:
    """Run `code` in a fresh interpreter (libsumo: one simulation per process); it must pass."""
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                            text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    return result


def test_closed_form_runs_never_load_libsumo() -> None:
    code = ("import sys\n"
            "from tests.conftest import make_scenario, LAYOUTS\n"
            "from fleet_sim.config.layout import load_layout\n"
            "from fleet_sim.sim.engine import simulate\n"
            "simulate(make_scenario(duration_h=0.1, warmup_h=0.0),"
            " load_layout(LAYOUTS / 'tiny_loop.yaml'))\n"
            "print('libsumo' in sys.modules)\n")
    result = _python(code)
    assert result.stdout.strip() == "False"


def test_one_sumo_simulation_per_process() -> None:
    code = ("from tests.conftest import make_scenario, LAYOUTS\n"
            "from fleet_sim.config.layout import load_layout\n"
            "from fleet_sim.sim.engine import build_model\n"
            "from fleet_sim.errors import SimulationError\n"
            "layout = load_layout(LAYOUTS / 'tiny_loop.yaml')\n"
            "scenario = make_scenario(duration_h=0.1, warmup_h=0.0, motion='sumo')\n"
            "first = build_model(scenario, layout)\n"
            "try:\n"
            "    build_model(scenario, layout)\n"
            "except SimulationError as exc:\n"
            "    print('refused:', exc)\n"
            "first.close()\n"
            "build_model(scenario, layout).close()\n"
            "print('again ok')\n")
    result = _python(code)
    assert "refused: a SUMO simulation is already running" in result.stdout
    assert "again ok" in result.stdout


@pytest.mark.parametrize(("fields", "element", "expected"), [
    ({"motion": "microscopic"}, "motion", "closed_form"),
    ({"motion": "sumo", "sumo": {"step_length_s": 0}}, "sumo.step_length_s",
     "a number in (0, 1]"),
    ({"motion": "sumo", "sumo": {"tau_s": 0.05, "step_length_s": 0.1}}, "sumo.tau_s",
     "a headway >= step_length_s"),
    ({"motion": "sumo", "sumo": {"step": 1}}, "sumo.step", ""),
])
def test_bad_motion_settings_are_named(fields: dict[str, object], element: str,
                                       expected: str) -> None:
    with pytest.raises(InputError) as info:
        make_scenario(**fields)
    assert info.value.file == "<test scenario>"
    assert info.value.element == element
    assert expected in info.value.expected
