"""The fault suite: faults of the machine and of files on disk, each made for real (a small
tmpfs that fills, a tmpfs mounted read-only, a user who may not write, files damaged on disk,
a reader racing a writer, a Dask cluster that loses its workers). Each asserts what a planner
is promised: never exit 0 with missing or wrong results, never a traceback, one line naming
the path and the cause, and a resume whose results equal an undisturbed study's.

Mounting needs root (these machines and CI run tests as root); without it those cases skip
with the reason.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from .conftest import ROOT, write_yaml

TINY = str(ROOT / "experiments" / "tiny_loop.yaml")
FLEET_SIM = [sys.executable, "-m", "fleet_sim.cli"]
KPI_IGNORED = ("wall_s", "error")
"""Columns of a summary that differ between two runs of the same study by nature."""


def experiment_file(folder: Path, name: str = "faults", duration_h: float = 1.5,
                    sizes: tuple[int, ...] = (1, 2), replications: int = 2) -> Path:
    return write_yaml(folder / f"{name}.yaml", {
        "name": name, "scenario": TINY,
        "overrides": {"duration_h": duration_h, "warmup_h": 0.25, "demand.rate_per_hour": 45},
        "factors": {"fleet.size": list(sizes)}, "replications": replications,
        "master_seed": 5,
        "targets": [{"kpi": "throughput_pct_of_demand", "at_least": 98}]})


def fleet_sim(*args: str | Path, cwd: Path, user: str | None = None,
              timeout: float = 300) -> subprocess.CompletedProcess[str]:
    command = [*FLEET_SIM, *map(str, args)]
    if user is not None:
        command = ["setpriv", f"--reuid={user}", f"--regid={user}", "--clear-groups",
                   *command]
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})


def assert_one_line_error(result: subprocess.CompletedProcess[str], *words: str) -> str:
    """Non-zero exit, no traceback, the last line of stderr names the fault."""
    assert result.returncode != 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith("fleet-sim: error: "), result.stderr
    for word in words:
        assert word in line, line
    return line


def summary_kpis(out: Path) -> pd.DataFrame:
    summary = pd.read_parquet(out / "summary.parquet")
    keep = [c for c in summary.columns if c not in KPI_IGNORED]
    return summary[keep].sort_values("run_id").reset_index(drop=True)


@pytest.fixture(scope="module")
def undisturbed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference: the fault suite's study, swept on a healthy disk."""
    folder = tmp_path_factory.mktemp("undisturbed")
    result = fleet_sim("sweep", experiment_file(folder), "--out", folder / "out",
                       "--workers", "2", "--quiet", cwd=folder)
    assert result.returncode == 0, result.stderr
    return folder / "out"


@pytest.fixture()
def mount(tmp_path: Path) -> Iterator[Any]:
    """mount(size_kb, read_only=False) -> a folder on a fresh tmpfs of that size."""
    mounted: list[Path] = []

    def make(size_kb: int, read_only: bool = False) -> Path:
        point = tmp_path / f"disk{len(mounted)}"
        point.mkdir()
        options = f"size={size_kb}k" + (",ro" if read_only else "")
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(point)],
                              capture_output=True, text=True)
        if done.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip()}): needs root")
        mounted.append(point)
        return point

    yield make
    for point in mounted:
        subprocess.run(["umount", "-l", str(point)], capture_output=True)


def remount(point: Path, size_kb: int) -> None:
    subprocess.run(["mount", "-o", f"remount,size={size_kb}k", str(point)], check=True)


# ---- a full disk ---------------------------------------------------------------------------


def test_run_on_a_full_disk_says_so_and_leaves_no_table_under_its_name(mount: Any) -> None:
    disk = mount(160)
    result = fleet_sim("run", TINY, "--hours", "60", "--out", disk / "run", cwd=disk.parent)
    assert_one_line_error(result, "No space left on device", "ENOSPC")
    left = sorted(p.name for p in (disk / "run").iterdir()) if (disk / "run").exists() else []
    assert [n for n in left if n.endswith(".parquet") or n == "kpis.json"] == [], left


def test_a_sweep_on_a_full_disk_stops_with_one_line_and_resumes_to_the_same_results(
        mount: Any, undisturbed: Path) -> None:
    disk = mount(700)
    experiment = experiment_file(disk.parent, name="faults")
    out = disk / "out"
    result = fleet_sim("sweep", experiment, "--out", out, "--workers", "2", "--quiet",
                       cwd=disk.parent)
    assert_one_line_error(result, "No space left on device", "ENOSPC")
    # nothing under a final name that is not whole: every run that looks finished checks
    # out, and a database, if there is one, holds its tables
    from fleet_sim.study.run_folder import MANIFEST, run_problem

    for run_dir in (out / "runs").iterdir():
        if (run_dir / MANIFEST).exists() or (run_dir / "kpis.json").exists():
            assert run_problem(run_dir) is None, run_dir
    if (out / "sweep.duckdb").exists():
        import duckdb

        con = duckdb.connect(str(out / "sweep.duckdb"), read_only=True)
        assert con.execute("SELECT count(*) FROM summary").fetchone() is not None
        con.close()
    remount(disk, 8192)
    again = fleet_sim("sweep", experiment, "--out", out, "--workers", "2", "--quiet",
                      cwd=disk.parent)
    assert again.returncode == 0, again.stderr
    assert list(disk.rglob("*.tmp")) == [] and list(disk.rglob(".partial")) == []
    pd.testing.assert_frame_equal(summary_kpis(out), summary_kpis(undisturbed))
    import duckdb

    con = duckdb.connect(str(out / "sweep.duckdb"), read_only=True)
    assert con.execute("SELECT count(*) FROM summary").fetchone() == (4,)
    con.close()


# ---- damaged runs --------------------------------------------------------------------------


def _damage(run_dir: Path, how: str) -> str:
    """Damage a finished run as the audit found them; returns the words the message must
    hold."""
    if how == "empty kpis":
        (run_dir / "kpis.json").write_text("{}", encoding="utf-8")
        return "kpis.json"
    if how == "truncated kpis":
        text = (run_dir / "kpis.json").read_text(encoding="utf-8")
        (run_dir / "kpis.json").write_text(text[: len(text) // 2], encoding="utf-8")
        return "kpis.json"
    if how == "missing file":
        (run_dir / "orders.parquet").unlink()
        return "orders.parquet is missing"
    if how == "damaged parquet":
        path = run_dir / "events.parquet"
        data = bytearray(path.read_bytes())
        middle = len(data) // 2
        data[middle:middle + 64] = bytes(64)
        path.write_bytes(bytes(data))
        return "events.parquet is damaged"
    raise AssertionError(how)


@pytest.mark.parametrize("how", ["empty kpis", "truncated kpis", "missing file",
                                 "damaged parquet"])
def test_a_damaged_finished_run_is_named_and_made_again(tmp_path: Path, undisturbed: Path,
                                                        how: str) -> None:
    out = tmp_path / "out"
    shutil.copytree(undisturbed, out)
    victim = sorted((out / "runs").iterdir())[1]
    words = _damage(victim, how)
    # report and export say which run and what to do, never a traceback
    report = fleet_sim("report", out, "--no-pdf", cwd=tmp_path)
    assert report.returncode == 0 and "Traceback" not in report.stderr, report.stderr
    page = (out / "report.html").read_text(encoding="utf-8")
    assert victim.name in page and "damaged" in page and "3 of 4 runs finished" in page
    export = fleet_sim("export", out, "--csv", cwd=tmp_path)
    assert_one_line_error(export, victim.name, words)
    # the resume names the run and what was wrong, makes it again, and the summary is the
    # undisturbed one (the statistics use all four replications)
    experiment = experiment_file(tmp_path)
    again = fleet_sim("sweep", experiment, "--out", out, "--workers", "1", cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert f"run {victim.name}: {words}" in again.stderr + again.stdout
    assert "3 of 4 runs already finished" in again.stderr + again.stdout
    pd.testing.assert_frame_equal(summary_kpis(out), summary_kpis(undisturbed))
    stats, reference = (pd.read_parquet(o / "stats.parquet") for o in (out, undisturbed))
    stats, reference = (s[s["kpi"] != "wall_s"].reset_index(drop=True)
                        for s in (stats, reference))
    pd.testing.assert_frame_equal(stats, reference)  # every replication counted again


def test_deleting_any_file_of_a_finished_run_makes_the_resume_make_it_again(
        tmp_path: Path, undisturbed: Path) -> None:
    """Each file of a finished run deleted in turn (spec.json included: that run used to
    vanish from the summary with exit 0; manifest.json included: that run used to be kept
    unchecked): the resume names the run and the missing file in one line, makes it again,
    and the summary is the undisturbed one."""
    names = sorted(p.name for p in sorted((undisturbed / "runs").iterdir())[1].iterdir()
                   if p.is_file())
    assert {"spec.json", "kpis.json", "manifest.json", "events.parquet"} <= set(names)
    experiment = experiment_file(tmp_path)
    for name in names:
        out = tmp_path / f"out_{name}"
        shutil.copytree(undisturbed, out)
        victim = sorted((out / "runs").iterdir())[1]
        (victim / name).unlink()
        again = fleet_sim("sweep", experiment, "--out", out, "--workers", "1", cwd=tmp_path)
        assert again.returncode == 0, (name, again.stderr)
        named = [line for line in again.stderr.splitlines() if victim.name in line]
        assert [line.strip() for line in named] == \
            [f"run {victim.name}: {name} is missing; it is run again"], (name, again.stderr)
        assert "1 runs made, 3 already finished" in again.stdout, (name, again.stdout)
        pd.testing.assert_frame_equal(summary_kpis(out), summary_kpis(undisturbed))


def test_orphan_temporaries_are_gone_after_a_resume(tmp_path: Path, undisturbed: Path) -> None:
    out = tmp_path / "out"
    shutil.copytree(undisturbed, out)
    run_dir = sorted((out / "runs").iterdir())[0]
    orphans = [run_dir / ".error.json.4242.tmp", out / ".summary.parquet.4242.tmp",
               run_dir / ".partial" / "events.parquet"]
    for orphan in orphans:
        orphan.parent.mkdir(exist_ok=True)
        orphan.write_text("left by a killed process", encoding="utf-8")
    again = fleet_sim("sweep", experiment_file(tmp_path), "--out", out, "--quiet",
                      cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert not any(o.exists() for o in orphans)
    assert not (run_dir / ".partial").exists()


# ---- folders that cannot be written --------------------------------------------------------


def test_a_read_only_results_folder_gives_one_line(tmp_path: Path, mount: Any,
                                                   undisturbed: Path) -> None:
    disk = mount(4096)
    shutil.copytree(undisturbed, disk / "out")
    for name in ("report.html", "report.pdf", "export"):
        assert not (disk / "out" / name).exists()
    subprocess.run(["mount", "-o", "remount,ro", str(disk)], check=True)
    experiment = experiment_file(tmp_path, sizes=(1, 2, 3))  # one more level: runs to make
    for args in (["sweep", experiment, "--out", disk / "out", "--quiet"],
                 ["size", experiment, "--out", disk / "out", "--quiet"],
                 ["report", disk / "out", "--no-pdf"],
                 ["export", disk / "out", "--xlsx"]):
        result = fleet_sim(*args, cwd=tmp_path)
        assert_one_line_error(result, str(disk / "out"))
    # everything finished is still there, unchanged
    assert sorted(p.name for p in (disk / "out" / "runs").iterdir()) == \
        sorted(p.name for p in (undisturbed / "runs").iterdir())


def test_a_user_who_may_not_write_the_folder_gets_one_line(undisturbed: Path) -> None:
    """Another user (nobody) resumes a sweep in a folder owned by root: one line naming the
    folder with EACCES, and the runs finished so far untouched."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to run as another user")
    import tempfile

    place = Path(tempfile.mkdtemp(prefix="fleet-sim-faults-", dir="/tmp"))
    try:
        place.chmod(0o755)
        out = place / "out"
        shutil.copytree(undisturbed, out)
        experiment = experiment_file(place, sizes=(1, 2, 3))
        experiment.chmod(0o644)
        result = fleet_sim("sweep", experiment, "--out", out, "--workers", "2", "--quiet",
                           cwd=place, user="65534")
        if "fleet-sim" not in result.stderr:
            pytest.skip(f"another user cannot run the project's Python here: {result.stderr}")
        line = assert_one_line_error(result, "Permission denied", "EACCES")
        assert str(out) in line
        assert sorted(p.name for p in (out / "runs").iterdir()) == \
            sorted(p.name for p in (undisturbed / "runs").iterdir())
    finally:
        shutil.rmtree(place, ignore_errors=True)


# ---- readers racing writers ----------------------------------------------------------------


def test_a_reader_never_sees_a_torn_summary(tmp_path: Path, undisturbed: Path) -> None:
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.results import write_tables

    out = tmp_path / "out"
    shutil.copytree(undisturbed, out)
    experiment = load_experiment(experiment_file(tmp_path))
    stop = threading.Event()
    reads = torn = 0

    def read() -> None:
        nonlocal reads, torn
        while not stop.is_set():
            try:
                frame = pd.read_parquet(out / "summary.parquet")
                assert len(frame) == 4
            except Exception:
                torn += 1
            reads += 1

    reader = threading.Thread(target=read)
    reader.start()
    try:
        for _ in range(15):
            write_tables(experiment, out)
    finally:
        stop.set()
        reader.join()
    assert reads > 15 and torn == 0


# ---- pipes ---------------------------------------------------------------------------------


def test_a_closed_standard_output_ends_quietly(tmp_path: Path) -> None:
    command = " ".join([*FLEET_SIM, "schema", "scenario"]) + " | head -c 10 >/dev/null"
    result = subprocess.run(["bash", "-o", "pipefail", "-c", command], capture_output=True,
                            text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    assert result.stderr == ""


# ---- Dask ----------------------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_dask_cluster_that_loses_every_worker_fails_after_the_timeout(
        tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = str(Path(sys.executable).parent / "dask")
    scheduler = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port",
                                  str(port), "--no-dashboard"], cwd=tmp_path,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                 start_new_session=True)
    worker = subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--nworkers", "1",
                               "--no-dashboard"], cwd=tmp_path, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    out = tmp_path / "out"
    try:
        experiment = experiment_file(tmp_path, duration_h=30, sizes=(1, 2), replications=2)
        sweep = subprocess.Popen([*FLEET_SIM, "sweep", str(experiment), "--out", str(out),
                                  "--scheduler", address, "--dask-timeout", "5", "--quiet"],
                                 cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True)
        deadline = time.monotonic() + 120
        while not list(out.glob("runs/*/spec.json")):  # the worker has started a run
            assert sweep.poll() is None and time.monotonic() < deadline, sweep.communicate()
            time.sleep(0.2)
        os.killpg(worker.pid, signal.SIGKILL)  # every worker lost
        started = time.monotonic()
        _, stderr = sweep.communicate(timeout=120)
        waited = time.monotonic() - started
    finally:
        for proc in (worker, scheduler):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert sweep.returncode != 0 and "Traceback" not in stderr, stderr
    line = stderr.strip().splitlines()[-1]
    assert line.startswith("fleet-sim: error: ") and "no worker for 5 s" in line, line
    assert "--dask-timeout" in line
    assert 4 <= waited < 60
    # the summary the sweep left holds no run that is not whole
    summary = pd.read_parquet(out / "summary.parquet")
    assert set(summary["status"]) <= {"ok", "incomplete", "failed", "crashed"}


def test_a_run_that_outlives_its_study_writes_nothing(tmp_path: Path) -> None:
    """A worker still running when its study has stopped (a lost Dask scheduler): the folder's
    lock no longer names its study when it finishes, so it leaves no finished run."""
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.run_folder import MANIFEST
    from fleet_sim.study.study_folder import LOCK_FILE

    experiment = load_experiment(experiment_file(tmp_path, duration_h=40, sizes=(2,),
                                                 replications=1))
    out = tmp_path / "out"
    (out / "runs").mkdir(parents=True)
    (out / LOCK_FILE).write_text(json.dumps({"pid": 1, "host": "h", "started": "t"}) + "\n")
    (spec,) = experiment.runs()
    code = ("import sys, pickle; from fleet_sim.study.worker import execute_run; "
            "spec = pickle.loads(bytes.fromhex(sys.argv[1])); "
            "print(execute_run(spec, sys.argv[2]).status)")
    import pickle

    worker = subprocess.Popen([sys.executable, "-c", code, pickle.dumps(spec).hex(),
                               str(out / "runs")], stdout=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (out / "runs" / spec.run_id / "spec.json").exists():
        assert worker.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    (out / LOCK_FILE).write_text("")  # the study stops: its lock is released
    stdout, _ = worker.communicate(timeout=120)
    assert stdout.strip() == "failed"
    run_dir = out / "runs" / spec.run_id
    assert not (run_dir / MANIFEST).exists() and not (run_dir / "kpis.json").exists()
    assert not (run_dir / ".partial").exists()


def test_a_run_made_by_another_version_of_the_model_is_made_again(
        tmp_path: Path, undisturbed: Path) -> None:
    """A results folder from before a change that moves results (issue 33's new defaults):
    resuming it must not mix old runs with new ones. Each stale run is named in one line and
    made again; the summary is the undisturbed one."""
    from fleet_sim.study.run_folder import MODEL_KEY, MODEL_VERSION

    out = tmp_path / "out"
    shutil.copytree(undisturbed, out)
    runs = sorted((out / "runs").iterdir())
    for run_dir, version in ((runs[0], None), (runs[2], "2026-11-01")):
        spec = json.loads((run_dir / "spec.json").read_text(encoding="utf-8"))
        assert spec[MODEL_KEY] == MODEL_VERSION
        if version is None:
            del spec[MODEL_KEY]  # an older fleet_sim said nothing
        else:
            spec[MODEL_KEY] = version
        (run_dir / "spec.json").write_text(json.dumps(spec), encoding="utf-8")
    again = fleet_sim("sweep", experiment_file(tmp_path), "--out", out, "--workers", "1",
                      cwd=tmp_path)
    assert again.returncode == 0, again.stderr
    assert (f"run {runs[0].name}: it was made by another version of the model (older, now "
            f"{MODEL_VERSION}); it is run again") in again.stderr
    assert f"run {runs[2].name}: it was made by another version of the model (2026-11-01" \
        in again.stderr
    assert "2 runs made, 2 already finished" in again.stdout
    pd.testing.assert_frame_equal(summary_kpis(out), summary_kpis(undisturbed))
