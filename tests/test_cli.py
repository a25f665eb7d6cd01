"""The fleet-sim command as a user runs it: files written, summary printed, clear errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from .conftest import LAYOUTS, ROOT, write_yaml

KPI_KEYS = {"orders_created", "orders_completed", "throughput_per_hour", "lead_time_mean_s",
            "lead_time_p95_s", "agv_utilisation_pct", "blocked_time_pct", "deadlocks_detected",
            "distance_km"}


def fleet_sim(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "fleet_sim.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_run_writes_the_run_directory(tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = fleet_sim("run", "experiments/tiny_loop.yaml", "--agvs", "3", "--hours", "0.5",
                       "--seed", "5", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert {p.name for p in out.iterdir()} >= {"config.resolved.yaml", "kpis.json",
                                                "events.parquet", "orders.parquet"}
    figures = json.loads((out / "kpis.json").read_text())
    assert figures.keys() >= KPI_KEYS
    config = yaml.safe_load((out / "config.resolved.yaml").read_text())
    assert config["fleet"]["size"] == 3 and config["duration_h"] == 0.5 and config["seed"] == 5
    orders = pd.read_parquet(out / "orders.parquet")
    assert len(orders) == figures["orders_created"]
    events = pd.read_parquet(out / "events.parquet")
    assert list(events.columns) == ["time_s", "agv", "event", "from_state", "to_state", "node",
                                    "detail"]
    assert "throughput" in result.stdout and str(out) in result.stdout
    assert "simulated 0.50 of 0.50 h (100%)" in result.stderr  # progress


def test_default_run_directory_never_overwrites(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path / "s.yaml", {"name": "again", "layout": str(
        LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.2, "warmup_h": 0.0})
    for _ in range(2):
        assert fleet_sim("run", str(scenario), "--quiet", cwd=tmp_path).returncode == 0
    assert (tmp_path / "results" / "again" / "kpis.json").exists()
    assert (tmp_path / "results" / "again-2" / "kpis.json").exists()


def test_bad_input_is_one_clear_line(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path / "s.yaml", {"layout": str(LAYOUTS / "tiny_loop.yaml"),
                                                "fleet": {"size": 2, "colour": "red"}})
    result = fleet_sim("run", str(scenario))
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().count("\n") == 0
    assert f"{scenario}: fleet.colour: got 'red'; expected no such key" in result.stderr


def test_layout_command_checks_and_draws(tmp_path: Path) -> None:
    png = tmp_path / "wh.png"
    result = fleet_sim("layout", "layouts/warehouse.yaml", "--png", str(png))
    assert result.returncode == 0, result.stderr
    assert "186" in result.stdout and "6 pickup, 12 drop-off" in result.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    broken = tmp_path / "broken.yaml"
    broken.write_text((LAYOUTS / "tiny_loop.yaml").read_text().replace("{from: K, to: SW}",
                                                                       "{from: K, to: ZZ}"))
    result = fleet_sim("layout", str(broken))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "segments[11].to: got 'ZZ'; expected the id of a node" in result.stderr


def test_a_battery_that_runs_down_is_warned_at_the_start_and_recorded(tmp_path: Path) -> None:
    """The issue's trap (charging off, a draining battery, a long run): one warning line that
    names the settings and says when the AGVs stop; the run goes on and keeps the warning."""
    scenario = write_yaml(tmp_path / "s.yaml", {
        "name": "trap", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 6,
        "warmup_h": 0.5, "fleet": {"size": 1}, "demand": {"rate_per_hour": 15},
        "charging": {"enabled": False}})
    result = fleet_sim("run", str(scenario), "--quiet", "--out", str(tmp_path / "run"))
    assert result.returncode == 0, result.stderr
    (warning,) = [line for line in result.stderr.splitlines() if "warning" in line]
    assert warning.startswith("fleet-sim: warning: charging.enabled is false but the battery "
                              "drains (fleet.vehicle.battery): ")
    assert "stops taking orders after about 3.4 h working flat out" in warning
    assert "For no battery model set fleet.vehicle.battery: off" in warning
    figures = json.loads((tmp_path / "run" / "kpis.json").read_text())
    assert figures["setup_warnings"] == [warning.removeprefix("fleet-sim: warning: ")]
    assert "idle with orders waiting" in result.stdout


def test_a_sweep_warns_once_per_experiment_not_per_run(tmp_path: Path) -> None:
    scenario = write_yaml(tmp_path / "s.yaml", {
        "name": "trap", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 4,
        "warmup_h": 0.5, "demand": {"rate_per_hour": 10}, "charging": {"enabled": False}})
    experiment = write_yaml(tmp_path / "e.yaml", {
        "name": "trap", "scenario": str(scenario), "factors": {"fleet.size": [1, 2]},
        "replications": 2})
    result = fleet_sim("sweep", str(experiment), "--quiet", "--workers", "1",
                       "--out", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "charging.enabled is false" in warnings[0]
    summary = pd.read_parquet(tmp_path / "out" / "summary.parquet")
    assert len(summary) == 4 and (summary["setup_warnings"].str.len() > 0).all()


def test_agvs_of_a_mixed_fleet_name_the_types(tmp_path: Path) -> None:
    """--agvs TYPE=N sets that type's count (the others keep theirs); a plain number for a
    mixed fleet, a type for a one-type fleet or an unknown type is one clear line."""
    scenario = write_yaml(tmp_path / "mixed.yaml", {
        "name": "mixed", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.3,
        "warmup_h": 0.05, "fleet": {"vehicles": [{"type": "carrier", "count": 1},
                                                 {"type": "heavy", "count": 1}]}})
    out = tmp_path / "run"
    result = fleet_sim("run", str(scenario), "--agvs", "heavy=2", "--quiet", "--out", str(out))
    assert result.returncode == 0, result.stderr
    fleet = yaml.safe_load((out / "config.resolved.yaml").read_text())["fleet"]
    assert [(t["type"], t["count"]) for t in fleet["vehicles"]] == [("carrier", 1), ("heavy", 2)]
    for args, message in [
        (("run", str(scenario), "--agvs", "3"),
         "fleet-sim: error: --agvs: got 3; expected TYPE=N for a mixed fleet "
         "(fleet.vehicles: carrier, heavy), e.g. --agvs heavy=N"),
        (("run", str(scenario), "--agvs", "hevy=2"),
         "fleet-sim: error: --agvs: got 'hevy=2'; expected TYPE=N with TYPE a type of "
         "fleet.vehicles (carrier, heavy); did you mean heavy=2?"),
        (("run", "experiments/tiny_loop.yaml", "--agvs", "heavy=2"),
         "fleet-sim: error: --agvs: got 'heavy=2'; expected a number of AGVs "
         "(the scenario's fleet has one vehicle type)"),
        (("run", str(scenario), "--agvs", "heavy=0"), "number of heavy AGVs >= 1"),
    ]:
        result = fleet_sim(*args)
        assert result.returncode == 2, args
        assert message in result.stderr and result.stderr.strip().count("\n") == 0, \
            result.stderr


def test_help_lists_every_registered_command(capsys: pytest.CaptureFixture[str]) -> None:
    """`fleet-sim --help` is generated from the registrations: its usage line and its list
    name every command (replay and export were missing from the hand-kept list), and each
    group's help names its commands."""
    from fleet_sim.cli import REGISTRY, Group, main

    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    text = capsys.readouterr().out
    top = [name for name in REGISTRY if " " not in name]
    assert {"run", "replay", "export", "layout", "sweep", "size", "report"} <= set(top)
    assert "{" + ",".join(top) + "}" in text.splitlines()[1]
    listed = [line.split()[0] for line in text.splitlines() if line.startswith("    ")
              and line.split() and line.split()[0] in top]
    assert listed == top
    for name, entry in REGISTRY.items():
        if isinstance(entry, Group):
            with pytest.raises(SystemExit):
                main([name, "--help"])
            assert "{" + ",".join(entry.commands) + "}" in capsys.readouterr().out


def test_layout_file_is_layout_check_file(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The old form `layout FILE` runs `layout check`; `layout import|export` are commands."""
    from fleet_sim.cli import main

    outputs = []
    for argv in (["layout", str(LAYOUTS / "tiny_loop.yaml")],
                 ["layout", "check", str(LAYOUTS / "tiny_loop.yaml")]):
        assert main([*argv, "--png", str(tmp_path / "t.png")]) == 0
        outputs.append(capsys.readouterr().out)
    assert outputs[0] == outputs[1] and "layout 'tiny_loop' is valid" in outputs[0]
    with pytest.raises(SystemExit) as done:
        main(["layout", "export", str(LAYOUTS / "tiny_loop.yaml")])
    assert done.value.code == 2
    assert "the following arguments are required: --lif" in capsys.readouterr().err


def test_set_overrides_any_scenario_field(tmp_path: Path) -> None:
    """--set KEY=VALUE (repeated) sets dotted scenario fields, the value read as YAML; the
    resolved config holds them; --agvs still wins over a --set fleet.size."""
    from fleet_sim.cli import main

    out = tmp_path / "run"
    assert main(["run", "experiments/tiny_loop.yaml", "--quiet", "--out", str(out),
                 "--hours", "0.3", "--set", "demand.rate_per_hour=61.5",
                 "--set", "charging.enabled=false", "--set", "fleet.size=4",
                 "--agvs", "3"]) == 0
    config = yaml.safe_load((out / "config.resolved.yaml").read_text())
    assert config["demand"]["rate_per_hour"] == 61.5
    assert config["charging"]["enabled"] is False
    assert config["fleet"]["size"] == 3 and config["duration_h"] == 0.3


@pytest.mark.parametrize(("argv", "message"), [
    (["--set", "fleet.sise=3"],
     "fleet-sim: error: --set: fleet.sise: got 3; expected no such key here: did you mean "
     "'size'? (known keys: size, "),
    (["--set", "flet.size=3"],
     "fleet-sim: error: --set: flet: got {'size': 3}; expected no such key here: did you mean "
     "'fleet'?"),
    (["--set", "fleet.size=-1"],
     "fleet-sim: error: --set: fleet.size: got -1; expected an integer in [1, 2000]"),
    (["--set", "demand.rate_per_hour=[1"],
     "fleet-sim: error: argument --set: got 'demand.rate_per_hour=[1'; expected KEY=VALUE "
     "with VALUE in YAML"),
    (["--set", "fleet.size"],
     "fleet-sim: error: argument --set: got 'fleet.size'; expected KEY=VALUE with KEY a "
     "dotted scenario field"),
])
def test_a_bad_set_names_set_and_the_field(argv: list[str], message: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    from fleet_sim.cli import main

    try:
        code = main(["run", "experiments/tiny_loop.yaml", *argv])
    except SystemExit as exc:  # argparse refuses the argument itself
        code = int(str(exc.code))
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(message) and err.count("\n") == 1, err


def test_a_problem_of_the_file_still_names_the_file_with_set(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from fleet_sim.cli import main

    scenario = write_yaml(tmp_path / "s.yaml", {"layout": str(LAYOUTS / "tiny_loop.yaml"),
                                                "fleet": {"size": 0}})
    assert main(["run", str(scenario), "--set", "fleet.size=2"]) == 2
    assert capsys.readouterr().err.startswith(f"fleet-sim: error: {scenario}: fleet.size: got 0")


def test_set_on_an_experiment_is_an_override_of_every_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """sweep and size take --set as overrides of every run (recorded in the resolved
    experiment); a factor, seed or an invalid value is refused naming --set."""
    from fleet_sim.cli import experiment_for, main

    file = ROOT / "experiments" / "tiny_loop_sizing.yaml"
    experiment = experiment_for(file, [("demand.rate_per_hour", 30), ("charging.enabled", False)])
    assert experiment.spec.overrides["demand.rate_per_hour"] == 30
    assert all(dict(run.overrides)["charging.enabled"] is False for run in experiment.runs())
    assert experiment.scenario({"fleet.size": 2}).demand.rate_per_hour == 30
    for setting, message in [
        ("fleet.size=3", "--set: fleet.size: got 3; expected a field that is not a factor"),
        ("seed=3", "--set: seed: got 'seed'; expected another scenario field"),
        ("demand.rate_per_hour=-1", "--set: demand.rate_per_hour: got -1; expected a number"),
        ("demand.rate_per_houre=1", "--set: demand.rate_per_houre: got 1; expected no such key "
                                    "here: did you mean 'rate_per_hour'?"),
    ]:
        assert main(["sweep", str(file), "--set", setting, "--out", str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"fleet-sim: error: {message}"), err
    assert not (tmp_path / "runs").exists()


def test_admission_auto_keeps_the_critical_fleet_on_the_track_and_says_why(
        tmp_path: Path) -> None:
    """`--set dispatch.max_active_agvs=auto` with reactive traffic: the warehouse's critical
    fleet (20, its busiest corridor) is the limit; run_info.json says so and why; no more than
    20 of the 30 AGVs are ever admitted onto the track at once."""
    from fleet_sim.cli import main

    out = tmp_path / "run"
    assert main(["run", "experiments/warehouse_shift.yaml", "--quiet", "--out", str(out),
                 "--hours", "1", "--agvs", "30", "--set", "demand.rate_per_hour=300",
                 "--set", "dispatch.max_active_agvs=auto"]) == 0
    info = json.loads((out / "run_info.json").read_text())
    assert info["max_active_agvs"] == 20
    assert info["admission_basis"].startswith("corridor ")
    events = pd.read_parquet(out / "events.parquet")
    admitted = events.loc[events["event"] == "admitted", "detail"]
    counts = admitted.str.extract(r"^(\d+) of (\d+) on the track$").astype(int)
    assert len(counts) >= 20 and (counts[1] == 20).all() and counts[0].max() == 20
    config = yaml.safe_load((out / "config.resolved.yaml").read_text())
    assert config["dispatch"]["max_active_agvs"] == "auto"  # as written: derived per run
