"""`motion: sumo`: every bundled scenario runs, runs repeat, faults and obstacles work, libsumo
stays out of closed-form runs, and bad settings are named. Every SUMO run here is in its own
process (fleet_sim.study.crosscheck.run_isolated), as libsumo requires."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
            "from fleet_sim.sim.engine import build_simulation\n"
            "from fleet_sim.errors import SimulationError\n"
            "layout = load_layout(LAYOUTS / 'tiny_loop.yaml')\n"
            "scenario = make_scenario(duration_h=0.1, warmup_h=0.0, motion='sumo')\n"
            "first = build_simulation(scenario, layout)\n"
            "try:\n"
            "    build_simulation(scenario, layout)\n"
            "except SimulationError as exc:\n"
            "    print('refused:', exc)\n"
            "first.close()\n"
            "build_simulation(scenario, layout).close()\n"
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


MIXED_RUN = """
import json, sys
from fleet_sim.config.scenario import load_scenario, load_layout_for
from fleet_sim.sim.engine import build_simulation
scenario = load_scenario(sys.argv[1])
layout = load_layout_for(scenario, sys.argv[1])
model = build_simulation(scenario, layout, record_occupancy=True)
model.env.run(until=scenario.duration_s)
sumo = model.motion_backend.sumo
types = {vid: sumo.vehicle.getTypeID(vid) for vid in sumo.vehicle.getIDList()}
print(json.dumps({
    "spells": [[s.agv, s.key, s.end_s - s.start_s] for s in model.recorder.occupancy
               if s.kind == "segment"],
    "vtypes": {t: [sumo.vehicletype.getMaxSpeed(t), sumo.vehicletype.getLength(t),
                   sumo.vehicletype.getVehicleClass(t)] for t in set(types.values())},
    "types": types,
    "delivered": sum(o.delivered_s is not None for o in model.recorder.orders)}))
model.close()
"""


def test_a_mixed_fleet_runs_under_sumo_each_type_at_its_own_speed(tmp_path: Path) -> None:
    """carrier (1 m/s) and heavy (0.5 m/s, 1.5 m long) on the tiny loop under SUMO, with a
    limit of 0.4 m/s for carrier past the pickup (P -> S3): each AGV is its type's SUMO vType,
    heavy never beats its top speed anywhere, carrier drives faster than heavy can elsewhere
    but keeps to its own limit on P -> S3 (SUMO's class speed limit)."""
    import yaml

    layout = yaml.safe_load((ROOT / "layouts" / "tiny_loop.yaml").read_text("utf-8"))
    layout["segments"][2]["speed_limit_mps_by_type"] = {"carrier": 0.4}
    (tmp_path / "limited.yaml").write_text(yaml.safe_dump(layout), encoding="utf-8")
    scenario = {"name": "mixed_sumo", "layout": "limited.yaml", "motion": "sumo",
                "duration_h": 0.5, "warmup_h": 0.05, "seed": 4,
                "fleet": {"vehicles": [
                    {"type": "carrier", "count": 2, "vehicle": {"battery": "off"}},
                    {"type": "heavy", "count": 1, "vehicle": {
                        "battery": "off", "max_speed_mps": 0.5, "length_m": 1.5}}]},
                "demand": {"rate_per_hour": 60}}
    path = tmp_path / "mixed_sumo.yaml"
    path.write_text(yaml.safe_dump(scenario), encoding="utf-8")
    result = subprocess.run([sys.executable, "-c", MIXED_RUN, str(path)], cwd=ROOT,
                            capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr
    got = json.loads(result.stdout.strip().splitlines()[-1])
    assert got["vtypes"] == {"agv0_carrier": [1.0, 1.0, "custom1"],
                             "agv1_heavy": [0.5, 1.5, "custom2"]}
    assert {vid: t for vid, t in got["types"].items()} == {
        vid: "agv1_heavy" if vid == "agv2" else "agv0_carrier" for vid in got["types"]}
    assert got["delivered"] > 10
    step = 0.1  # SUMO's step: a hop ends in the step the AGV gets there
    lengths = {f"{s['from']}>{s['to']}": 4.0 for s in layout["segments"]}
    fastest = {"carrier": [], "heavy": []}
    for agv, key, seconds in got["spells"]:
        kind = "heavy" if agv == 2 else "carrier"
        top = 0.5 if kind == "heavy" else (0.4 if key == "P>S3" else 1.0)
        assert seconds >= lengths[key] / top - step, (agv, key, seconds)
        fastest[kind].append(seconds)
    assert min(fastest["carrier"]) < 4.0 / 0.5 - 1.0  # carrier is not held to heavy's speed
    on_limited = [s for a, k, s in got["spells"] if a < 2 and k == "P>S3"]
    assert on_limited and min(on_limited) >= 4.0 / 0.4 - step
