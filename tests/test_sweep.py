"""Sweeps: seeding, paired streams, crashing runs, resume after a kill, Dask, DuckDB."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import duckdb
import pandas as pd
import pytest

from fleet_sim.analysis.congestion import node_waits
from fleet_sim.config.experiment import Experiment, load_experiment
from fleet_sim.study.run_folder import CRASHED, FAILED, OK
from fleet_sim.study.study_folder import SweepError
from fleet_sim.study.sweep import sweep
from fleet_sim.study.worker import execute_run

from . import sweep_helpers
from .conftest import ROOT, write_yaml

TINY = str(ROOT / "experiments" / "tiny_loop.yaml")


def tiny_experiment(tmp_path: Path, name: str = "tiny", **fields: Any) -> Experiment:
    data: dict[str, Any] = {"name": name, "scenario": TINY,
                            "overrides": {"duration_h": 1.5, "warmup_h": 0.25,
                                          "demand.rate_per_hour": 45},
                            "factors": {"fleet.size": [1, 2, 3]}, "replications": 2,
                            "master_seed": 11,
                            "targets": [{"kpi": "throughput_pct_of_demand", "at_least": 98}],
                            **fields}
    return load_experiment(write_yaml(tmp_path / f"{name}.yaml", data))


def kpis(run_dir: Path) -> dict[str, Any]:
    figures = json.loads((run_dir / "kpis.json").read_text())
    figures.pop("wall_s")
    return figures



def sweep_command(experiment: Path, out: Path, workers: int) -> list[str]:
    return [sys.executable, "-m", "fleet_sim.cli", "sweep", str(experiment), "--out", str(out),
            "--workers", str(workers)]


def start_sweep(command: list[str], cwd: Path) -> subprocess.Popen[bytes]:
    """A real `fleet-sim sweep` in the background, in a session of its own (for kill tests)."""
    return subprocess.Popen(command, cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)

def test_same_seed_same_results(tmp_path: Path) -> None:
    spec = tiny_experiment(tmp_path).runs()[3]
    for out in ("a", "b"):
        assert execute_run(spec, str(tmp_path / out)).status == OK
    first, second = tmp_path / "a" / spec.run_id, tmp_path / "b" / spec.run_id
    assert kpis(first) == kpis(second)
    for table in ("orders.parquet", "events.parquet", "node_waits.parquet"):
        assert (first / table).read_bytes() == (second / table).read_bytes()


def test_replications_share_order_streams_across_fleet_sizes(tmp_path: Path) -> None:
    exp = tiny_experiment(tmp_path)
    runs = {(r.factor_dict()["fleet.size"], r.replication): r for r in exp.runs()}
    orders = {}
    for key in ((1, 0), (3, 0), (3, 1)):
        execute_run(runs[key], str(tmp_path))
        frame = pd.read_parquet(tmp_path / runs[key].run_id / "orders.parquet")
        orders[key] = frame[["created_s", "pickup", "dropoff", "pickup_handling_s"]]
    # same replication: the same orders at the same times, whatever the fleet
    pd.testing.assert_frame_equal(orders[(1, 0)], orders[(3, 0)])
    # another replication: other orders
    assert not orders[(3, 0)]["created_s"].equals(orders[(3, 1)]["created_s"])
    assert kpis(tmp_path / runs[(1, 0)].run_id)["throughput_per_hour"] < \
        kpis(tmp_path / runs[(3, 0)].run_id)["throughput_per_hour"]


def test_a_planned_run_that_left_no_record_is_not_passed_over(tmp_path: Path) -> None:
    """Every run asked for is accounted for: one that reports success but left nothing on
    disk ends the sweep with an error naming it (the summary would hold 5 of 6 runs), and
    the next sweep makes it."""
    exp = tiny_experiment(tmp_path)
    out = tmp_path / "out"
    with pytest.raises(SweepError, match=f"1 of the 6 runs asked for left no record .*"
                                         f"{sweep_helpers.FAIL}.*run the study again"):
        sweep(exp, out, workers=2, run_fn=sweep_helpers.recordless_run, quiet=True)
    outcome = sweep(exp, out, workers=2, quiet=True)
    assert outcome.total == 6 and outcome.skipped == 5
    assert len(pd.read_parquet(out / "summary.parquet")) == 6


def test_a_planned_run_missing_from_the_summary_ends_the_sweep_naming_it(
        tmp_path: Path) -> None:
    """Every planned run accounted for at the end: run FAIL finishes but its spec.json names
    another run, so the summary files it under that name and has no row for FAIL; the sweep
    ends with an error naming FAIL instead of exit 0 with 5 of its 6 runs, and keeps the
    tables and every run folder. Run again, it makes FAIL again with a line naming it."""
    exp = tiny_experiment(tmp_path)
    out = tmp_path / "out"
    with pytest.raises(SweepError, match=r"summary.parquet: 1 of the 6 planned runs is not "
                                         r"in the summary as finished or failed with a "
                                         rf"reason: {sweep_helpers.FAIL} \(no row\); the "
                                         "tables and every run folder are kept"):
        sweep(exp, out, workers=2, run_fn=sweep_helpers.misnamed_run, quiet=True)
    summary = pd.read_parquet(out / "summary.parquet")
    assert sweep_helpers.FAIL not in set(summary["run_id"])
    assert sweep_helpers.MISNAMED in set(summary["run_id"])
    assert len(list((out / "runs").glob("*/kpis.json"))) == 6
    stream = io.StringIO()
    again = sweep(exp, out, workers=2, stream=stream)
    assert again.skipped == 5 and [r.run_id for r in again.results] == [sweep_helpers.FAIL]
    assert f"run {sweep_helpers.FAIL}: spec.json names another run " \
           f"({sweep_helpers.MISNAMED}); it is run again" in stream.getvalue()
    assert "all 6 planned runs are in the summary (6 finished)" in stream.getvalue()
    summary = pd.read_parquet(out / "summary.parquet")
    assert sorted(summary["run_id"]) == sorted(s.run_id for s in exp.runs())


def test_the_sweep_command_exits_non_zero_when_its_summary_lacks_a_planned_run(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """The summary writer loses a row (a bug of the gather step): `fleet-sim sweep` names
    the run in one line and exits 2, never 0 with fewer runs than it planned."""
    from fleet_sim.cli import main
    from fleet_sim.study import results

    tiny_experiment(tmp_path, factors={"fleet.size": [1, 2]}, replications=1)
    gather = results.collect_summary
    monkeypatch.setattr(results, "collect_summary",
                        lambda *args, **kwargs: gather(*args, **kwargs).iloc[1:])
    code = main(["sweep", str(tmp_path / "tiny.yaml"), "--out", str(tmp_path / "out"),
                 "--workers", "2"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("fleet-sim: error: ") and \
        "1 of the 2 planned runs is not in the summary" in last and \
        "fleet.size=1__r00 (no row)" in last, err
    assert (tmp_path / "out" / "runs" / "fleet.size=1__r00" / "kpis.json").is_file()


def test_failing_and_crashing_runs_are_recorded_and_resume_completes(tmp_path: Path) -> None:
    exp = tiny_experiment(tmp_path)
    out = tmp_path / "out"
    stream = io.StringIO()
    outcome = sweep(exp, out, workers=2, run_fn=sweep_helpers.flaky_run, stream=stream)
    status = {r.run_id: r.status for r in outcome.results}
    assert status[sweep_helpers.CRASH] == CRASHED
    assert status[sweep_helpers.FAIL] == FAILED
    assert sum(s == OK for s in status.values()) == 4  # every other run finished
    error = json.loads((out / "runs" / sweep_helpers.FAIL / "error.json").read_text())
    assert "boom" in error["error"] and "RuntimeError" in error["traceback"]
    crash = json.loads((out / "runs" / sweep_helpers.CRASH / "error.json").read_text())
    assert crash["status"] == CRASHED and "died" in crash["error"]
    summary = pd.read_parquet(out / "summary.parquet").set_index("run_id")
    assert len(summary) == 6
    assert summary.loc[sweep_helpers.CRASH, "status"] == CRASHED
    assert "1 failed" in stream.getvalue() and "runs 6/6 done, 2 failed" in stream.getvalue()
    assert stream.getvalue().rstrip().endswith(
        "all 6 planned runs are in the summary (4 finished, 2 failed)")
    finished = {p: p.stat().st_mtime_ns for p in (out / "runs").glob("*/kpis.json")}
    assert len(finished) == 4

    stream = io.StringIO()
    again = sweep(exp, out, workers=2, stream=stream)
    assert "all 6 planned runs are in the summary (6 finished)" in stream.getvalue()
    assert again.skipped == 4 and {r.run_id for r in again.results} == {
        sweep_helpers.CRASH, sweep_helpers.FAIL}
    assert all(r.status == OK for r in again.results)
    assert {p: p.stat().st_mtime_ns for p in finished} == finished  # never recomputed
    summary = pd.read_parquet(out / "summary.parquet")
    assert (summary["status"] == OK).all() and len(summary) == 6
    assert not (out / "runs" / sweep_helpers.FAIL / "error.json").exists()


def test_sweep_killed_midway_resumes_without_losing_runs(tmp_path: Path) -> None:
    path = write_yaml(tmp_path / "long.yaml", {
        "name": "long", "scenario": TINY,
        "overrides": {"duration_h": 10, "warmup_h": 0.5, "demand.rate_per_hour": 45},
        "factors": {"fleet.size": [2, 3, 4]}, "replications": 5, "master_seed": 3})
    out = tmp_path / "out"
    command = sweep_command(path, out, workers=2)
    proc = start_sweep(command, tmp_path)
    deadline = time.monotonic() + 120
    try:
        while len(list(out.glob("runs/*/kpis.json"))) < 3:
            assert proc.poll() is None, "the sweep ended before it could be interrupted"
            assert time.monotonic() < deadline
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the sweep and its workers, mid-run
        proc.wait()
    finished = {p: (p.stat().st_mtime_ns, p.read_bytes())
                for p in out.glob("runs/*/kpis.json")}
    assert 3 <= len(finished) < 15
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert f"{len(finished)} of 15 runs already finished" in result.stderr
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in finished} == finished
    summary = pd.read_parquet(out / "summary.parquet")
    assert len(summary) == 15 and (summary["status"] == OK).all()
    assert not list(out.glob("runs/*/.partial"))
    for run_dir in out.glob("runs/*"):  # every run complete, whenever it finished
        assert {"config.resolved.yaml", "events.parquet", "orders.parquet", "spec.json",
                "node_waits.parquet", "run_info.json"} <= {p.name for p in run_dir.iterdir()}


def test_dask_cluster_gives_the_same_results_and_duckdb_queries_them(tmp_path: Path) -> None:
    distributed = pytest.importorskip("dask.distributed")
    exp = tiny_experiment(tmp_path, factors={"fleet.size": [1, 2]})
    local = sweep(exp, tmp_path / "local", workers=2, quiet=True)
    assert len(local.results) == 4
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    try:
        remote = sweep(exp, tmp_path / "dask", scheduler=cluster.scheduler_address, quiet=True)
    finally:
        cluster.close()
    assert sorted(r.status for r in remote.results) == [OK] * 4
    for spec in exp.runs():
        assert kpis(tmp_path / "local" / "runs" / spec.run_id) == \
            kpis(tmp_path / "dask" / "runs" / spec.run_id)
    con = duckdb.connect(str(tmp_path / "dask" / "sweep.duckdb"), read_only=True)
    try:
        rows = con.execute(
            'SELECT s."fleet.size", count(*), sum(o.delivered_s IS NOT NULL) FROM orders o '
            "JOIN summary s USING (run_id) GROUP BY 1 ORDER BY 1").fetchall()
        summary = pd.read_parquet(tmp_path / "dask" / "summary.parquet")
        by_size = summary.groupby("fleet.size")[["orders_created", "orders_completed"]].sum()
        assert rows == [(n, int(by_size.loc[n, "orders_created"]),
                         int(by_size.loc[n, "orders_completed"])) for n in (1, 2)]
        events = con.execute("SELECT count(DISTINCT run_id) FROM events").fetchone()
        assert events == (4,)
        stats = con.execute("SELECT n FROM stats WHERE kpi = 'throughput_per_hour'").fetchall()
        assert stats == [(2,), (2,)]
    finally:
        con.close()


def test_node_waits_add_up_to_the_engine_blocked_time(tmp_path: Path) -> None:
    from fleet_sim.analysis.tables import events_table
    from fleet_sim.config.experiment import layout_for
    from fleet_sim.config.scenario import load_scenario
    from fleet_sim.sim.engine import simulate

    scenario = load_scenario(TINY, {"fleet.size": 3, "duration_h": 3, "warmup_h": 0.5,
                                    "demand.rate_per_hour": 45, "seed": 5})
    run = simulate(scenario, layout_for(scenario, TINY), record_occupancy=True)
    waits = node_waits(run.recorder.occupancy, events_table(run.recorder), scenario.warmup_s,
                       scenario.duration_s)
    assert run.recorder.blocked_s > 100  # a run with traffic worth checking
    assert waits["wait_s"].sum() == pytest.approx(run.recorder.blocked_s, rel=1e-3)
    assert set(waits["node"]) <= set(run.layout.graph.nodes)
    assert waits.loc[waits["node"] == "P", "passes"].item() > 0


def test_results_folder_of_another_experiment_is_refused(tmp_path: Path) -> None:
    from fleet_sim.study.study_folder import SweepError

    out = tmp_path / "out"
    sweep(tiny_experiment(tmp_path, factors={"fleet.size": [1]}, replications=1), out,
          workers=1, quiet=True)
    other = tiny_experiment(tmp_path, factors={"fleet.size": [1]}, replications=1,
                            master_seed=12)
    with pytest.raises(SweepError, match="another seed"):
        sweep(other, out, workers=1, quiet=True)


def _group_members(pgid: int) -> list[int]:
    """Pids of the live (not zombie) processes in process group `pgid`, from /proc."""
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2:].split()
        if fields[0] not in ("Z", "X") and int(fields[2]) == pgid:
            members.append(int(entry.name))
    return members


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_workers_die_with_a_killed_sweep_and_the_folder_resumes(tmp_path: Path) -> None:
    path = write_yaml(tmp_path / "long.yaml", {
        "name": "long", "scenario": TINY,
        "overrides": {"duration_h": 40, "warmup_h": 0.5, "demand.rate_per_hour": 45},
        "factors": {"fleet.size": [2, 3]}, "replications": 2, "master_seed": 3})
    out = tmp_path / "out"
    command = sweep_command(path, out, workers=2)
    proc = start_sweep(command, tmp_path)
    deadline = time.monotonic() + 120
    try:
        while not list(out.glob("runs/*/spec.json")):  # a worker has started a run
            assert proc.poll() is None, "the sweep ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
        assert len(_group_members(proc.pid)) >= 3  # the sweep, the fork server, workers
        proc.kill()  # SIGKILL to the sweep process alone: its children get no signal
        proc.wait()
        deadline = time.monotonic() + 10
        while _group_members(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        left = _group_members(proc.pid)
        assert not left, f"processes of the killed sweep still running: {left}"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    finished = {p: (p.stat().st_mtime_ns, p.read_bytes())
                for p in out.glob("runs/*/kpis.json")}
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in finished} == finished
    summary = pd.read_parquet(out / "summary.parquet")
    assert len(summary) == 4 and (summary["status"] == OK).all()
    assert not list(out.glob("runs/*/.partial"))


def test_a_second_sweep_into_a_busy_folder_is_refused(tmp_path: Path) -> None:
    path = write_yaml(tmp_path / "long.yaml", {
        "name": "long", "scenario": TINY,
        "overrides": {"duration_h": 300, "warmup_h": 0.5, "demand.rate_per_hour": 45},
        "factors": {"fleet.size": [2, 3]}, "replications": 2, "master_seed": 3,
        "targets": [{"kpi": "throughput_pct_of_demand", "at_least": 98}]})
    out = tmp_path / "out"
    command = sweep_command(path, out, workers=1)
    first = start_sweep(command, tmp_path)
    try:
        deadline = time.monotonic() + 120
        while not list(out.glob("runs/*/spec.json")):
            assert first.poll() is None and time.monotonic() < deadline
            time.sleep(0.02)
        for second in (command, [*command[:3], "size", *command[4:]]):
            result = subprocess.run(second, cwd=tmp_path, capture_output=True, text=True,
                                    timeout=120)
            assert result.returncode == 2
            (line,) = result.stderr.splitlines()
            assert str(out) in line and f"pid {first.pid}" in line and "in use" in line
        assert first.poll() is None  # the first sweep goes on
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()


def test_a_stale_lock_is_taken_over(tmp_path: Path) -> None:
    from fleet_sim.study.study_folder import LOCK_FILE

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": dead.pid, "host": "h", "started": "t"}))
    stream = io.StringIO()
    outcome = sweep(tiny_experiment(tmp_path, factors={"fleet.size": [1]}, replications=1), out,
                    workers=1, stream=stream)
    assert [r.status for r in outcome.results] == [OK]
    assert f"taking over the lock of pid {dead.pid}" in stream.getvalue()
    assert (out / LOCK_FILE).read_text() == ""  # released


def test_a_summary_behind_its_run_folders_is_rebuilt_for_the_report(tmp_path: Path) -> None:
    from fleet_sim.report.results_folder import load
    from fleet_sim.report.sections.runs import section_runs
    from fleet_sim.study.results import read_summary

    out = tmp_path / "out"
    sweep(tiny_experiment(tmp_path, factors={"fleet.size": [1, 2]}, replications=1), out,
          workers=2, quiet=True)
    assert len(pd.read_parquet(out / "summary.parquet")) == 2
    assert not read_summary(out, ["fleet.size"])[1]  # up to date: read as written
    # runs added later (as `size` adds them, killed before it rewrote the summary)
    bigger = tiny_experiment(tmp_path, factors={"fleet.size": [1, 2, 3]}, replications=1)
    added = [s for s in bigger.runs() if s.factor_dict()["fleet.size"] == 3]
    for spec in added:
        assert execute_run(spec, str(out / "runs")).status == OK
    summary, rebuilt = read_summary(out, ["fleet.size"])
    assert rebuilt and len(summary) == 3 and (summary["status"] == OK).all()
    data = load(out)
    assert sorted(data.summary["run_id"]) == sorted(p.name for p in (out / "runs").iterdir())
    runs = section_runs(data)
    assert (runs.runs, runs.finished, runs.failed) == (3, 3, 0)


def test_an_interrupted_sweep_still_writes_its_summary(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    from fleet_sim.study import sweep as sweep_module

    exp = tiny_experiment(tmp_path, factors={"fleet.size": [1, 2]}, replications=1)
    out = tmp_path / "out"

    def one_run_then_ctrl_c(specs: Any, out_dir: Path, *args: Any, **kwargs: Any) -> Any:
        execute_run(next(iter(specs)), str(out_dir / "runs"))
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "execute", one_run_then_ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        sweep(exp, out, workers=1, quiet=True)
    summary = pd.read_parquet(out / "summary.parquet")
    assert list(summary["status"]) == [OK]


def test_a_sweep_ends_with_a_kpi_table_that_flags_gridlock_and_open_orders(
        tmp_path: Path) -> None:
    """`fleet-sim sweep` on the one-way ring of tests/data/gridlock_ring.yaml: one AGV
    circulates, four lock solid. Without targets the table shows throughput and p95 lead time
    (names and units from the KPI catalogue), mean and 95 % interval as the summary gives
    them; the four-AGV row says GRIDLOCK and the orders left open."""
    from fleet_sim.analysis.paired import number_text
    from fleet_sim.analysis.stats import mean_ci

    ring = Path(__file__).parent / "data" / "gridlock_ring.yaml"
    scenario = write_yaml(tmp_path / "ring.yaml", {
        "name": "ring", "layout": str(ring), "duration_h": 0.5, "warmup_h": 0.1, "seed": 3,
        "fleet": {"size": 4, "start_nodes": ["N0", "N1", "N2", "N3"]},
        "demand": {"rate_per_hour": 120}, "dispatch": {"park_idle": False},
        "charging": {"enabled": False}, "traffic": {"gridlock_after_s": 120},
        "rules": {"agv_ahead": "held_back"}})  # (else E_101 behind AGVs breaks the ring up)
    experiment = write_yaml(tmp_path / "e.yaml", {
        "name": "ring", "scenario": str(scenario), "factors": {"fleet.size": [1, 4]},
        "replications": 2, "master_seed": 4})
    out = tmp_path / "out"
    result = subprocess.run(sweep_command(experiment, out, 2), cwd=ROOT, capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.rstrip("\n").splitlines()
    title = lines.index("  KPIs per design point: mean ± half-width of the 95 % interval over "
                        "the runs")
    header, one, four = lines[title + 1:]  # the table ends the output
    assert header.split() == ["fleet.size", "runs", "throughput", "[orders/h]", "p95", "lead",
                              "time", "[s]", "note"]
    summary = pd.read_parquet(out / "summary.parquet")
    small = summary[summary["fleet.size"] == 1]
    thr = mean_ci(small["throughput_per_hour"].to_numpy(dtype=float))
    assert one.split()[:2] == ["1", "2"]
    assert f"{number_text(thr.mean)} ± {number_text(thr.half_width)}" in one
    assert "GRIDLOCK" not in one
    open_one = small["orders_open_at_end"].mean()
    assert (f"{open_one:.1f} orders open at the end (mean)" in one) == (open_one > 0)
    big = summary[summary["fleet.size"] == 4]
    assert big["gridlock_at_h"].notna().all()
    assert four.split()[:5] == ["4", "2", "0", "±", "0"]  # nothing delivered: no p95 either
    assert "n/a" in four
    assert four.endswith(f"GRIDLOCK in 2 of 2 runs; {big['orders_open_at_end'].mean():.1f} "
                         "orders open at the end (mean)")


def test_the_kpi_table_shows_the_targets_kpis_and_says_where_runs_failed() -> None:
    from fleet_sim.report.console import kpi_table

    summary = pd.DataFrame({
        "run_id": ["a", "b", "c", "d"], "status": ["ok", "ok", "ok", "failed"],
        "demand.rate_per_hour": [30, 30, 60, 60], "replication": [0, 1, 0, 1],
        "throughput_pct_of_demand": [90.0, 100.0, 80.0, None],
        "lead_time_p95_s": [100.0, 200.0, 300.0, None],
        "throughput_per_hour": [27.0, 30.0, 48.0, None]})
    lines = kpi_table(summary, ["demand.rate_per_hour"], ["throughput_pct_of_demand"])
    header, thirty, sixty = lines[2:]
    assert header.split() == ["demand.rate_per_hour", "runs", "throughput", "[%", "of",
                              "demand]", "note"]
    # 95 +- t(1) * 7.07 / sqrt(2) = 95 +- 63.5; one run: its value, no interval
    assert thirty.split() == ["30", "2", "95", "±", "63.5"]
    assert sixty.split()[:3] == ["60", "1", "80"]
    assert sixty.endswith("1 run failed")
