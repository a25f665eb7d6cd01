"""Sweeps: every run of an experiment in worker processes (or on a Dask cluster), resumable.

Results folder (``results/<experiment>`` by default)::

    experiment.yaml            the experiment file as given; experiment.resolved.yaml, resolved
    runs/<run id>/             one folder per run:
        spec.json              factors, replication, seed, overrides (written first)
        config.resolved.yaml   the run's scenario, every default written out
        events.parquet, orders.parquet, run_info.json    as `fleet-sim run` writes them
        node_waits.parquet     per node: AGV passes and seconds AGVs stood there waiting
        kpis.json              written last and atomically: its presence means "finished"
        error.json             instead of kpis.json when the run failed (type, message, trace)
    summary.parquet            one row per run: status, factors, replication, seed, every KPI
    stats.parquet              per design point: mean and 95 % CI of every KPI (analysis.stats)
    sweep.duckdb               DuckDB: table summary, stats; views orders, events, node_waits
                               over every run's Parquet files (with run_id)

Decisions, where the issue is silent:

* A run is finished when its kpis.json exists. The engine's files are written to
  ``runs/<id>/.partial`` and moved in, kpis.json last (``os.replace``), so a sweep killed at any
  moment leaves either a finished run or one that is run again; re-running a sweep skips
  finished runs and retries failed ones. A run folder whose spec.json differs from what the
  experiment now asks for (another master seed, other overrides) stops the sweep with an error
  rather than mixing two experiments in one folder.
* Failures: an exception inside a run is caught in the worker and written to error.json (status
  ``failed``). A worker process that dies (a segfault, ``os._exit``, the OOM killer) breaks the
  process pool; the pool is rebuilt, and the runs that were in flight are retried one at a time
  so the one that kills its worker is identified and recorded (status ``crashed``) while the
  others finish normally. On Dask, the scheduler retries a task whose worker died and gives up
  with KilledWorker after its allowed failures; that run is recorded as crashed.
* Runs start largest fleet first (longest first), which keeps every worker busy to the end.
* Worker processes start with the ``forkserver`` method where available (else ``spawn``): no
  state of the parent leaks into runs; the fork server imports the engine once, so workers
  start at once. A sizing search keeps one pool for all its batches.
* Congestion per node (node_waits.parquet): an AGV stands at a node between the end of one
  segment traversal and the start of the next. If it drives on with work to do (state Moving,
  or an order assigned while parked), the standing since it got that work (not the handling or
  idling before it, nor a park-in manoeuvre) is waiting for the way ahead. Summed over the
  measured window (after warm-up), per node, it equals the engine's blocked time. Needs the
  engine's occupancy trace, which the sweep turns on; it does not change the run.
* KPIs: every run's are summed as it runs (fleet_sim.analysis.kpis, as for `fleet-sim run`);
  the sweep adds ``wall_s``, the run's wall time including writing its files.
* Memory: a run streams its tables to Parquet as `fleet-sim run` does, but the occupancy
  trace that node_waits needs stays in memory (a record per node hold and segment
  traversal), and node_waits reads the columns it needs of events.parquet back once the run
  is over. A sweep run's memory therefore still grows with its simulated time, as every run's
  did before streaming; sweeps run shifts of hours, not years.
* One sweep or sizing search per results folder: it holds an exclusive ``fcntl.flock`` on
  ``<folder>/.fleet-sim.lock`` while it runs, and writes its pid, host and start time into it.
  flock (not a file created with O_EXCL) because the kernel releases it when the process
  dies, however it dies, so a lock can never be left stale; a lock file that still names a
  process which no longer holds it is taken over with a note. A second sweep or size into a
  busy folder stops with one line naming the folder and the owner's pid. Where fcntl does not
  exist (Windows) the owner's pid is checked instead. The file stays (emptied) after the run.
* summary.parquet and stats.parquet are rewritten at the end of every sweep and sizing search;
  one killed before its end leaves them behind its run folders. Readers go through
  `read_summary`, which compares the summary's (run, status) pairs with the run folders and
  rebuilds the summary from the folders (in memory: a reader never writes the folder) when
  they differ, so a report never counts 24 runs when 28 exist. A sweep or search ended by an
  exception (Ctrl-C included) still rewrites the tables on its way out.
* DuckDB views read the Parquet files by absolute path: the database works from any folder;
  after moving a results folder, run the sweep again (nothing is recomputed) to rebuild it.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import json
import math
import multiprocessing
import os
import shutil
import socket
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
import pandas as pd
import yaml

from fleet_sim.config.experiment import FLEET, Experiment, RunSpec, layout_for, load_trace_for
from fleet_sim.config.scenario import VEHICLE_TYPES
from fleet_sim.errors import FleetSimError, InputError, optional_import, require_extra
from fleet_sim.model.records import OccupancySpell
from fleet_sim.sim.motion import require_backend
from fleet_sim.study.progress import Progress

RunFn = Callable[[RunSpec, str], "RunResult"]
"""A function that executes one run into `runs_dir` (module level, so workers can import it)."""

OK, FAILED, CRASHED = "ok", "failed", "crashed"


@dataclass(frozen=True)
class RunResult:
    run_id: str
    status: str
    wall_s: float
    error: str = ""


class SweepError(FleetSimError):
    """The sweep cannot go on (such as a results folder holding another experiment)."""


class FolderBusy(SweepError):
    """Another sweep or sizing search is writing into the results folder."""


# ---- one sweep per folder ------------------------------------------------------------------

LOCK_FILE = ".fleet-sim.lock"

try:
    import fcntl
except ImportError:  # not POSIX
    fcntl = None  # type: ignore[assignment]


@contextmanager
def folder_lock(out_dir: Path, stream: IO[str] | None = None) -> Iterator[None]:
    """Hold the results folder for this process (see the module docstring), or raise
    FolderBusy naming the owner; `stream` gets the note when a stale lock is taken over."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / LOCK_FILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        owner = _lock_owner(fd)
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise _busy(out_dir, _lock_owner(fd) or owner) from None
        elif owner and owner.get("pid") != os.getpid() and pid_alive(int(owner["pid"])):
            raise _busy(out_dir, owner)
        if owner:
            print(f"fleet-sim: note: {out_dir}: taking over the lock of pid {owner.get('pid')} "
                  f"(host {owner.get('host')}, started {owner.get('started')}), which is no "
                  "longer running", file=stream or sys.stderr)
        os.ftruncate(fd, 0)
        mine = {"pid": os.getpid(), "host": socket.gethostname(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S")}
        os.pwrite(fd, (json.dumps(mine) + "\n").encode(), 0)
        try:
            yield
        finally:
            os.ftruncate(fd, 0)  # released: an empty lock file names no owner
    finally:
        os.close(fd)  # releases the flock


def _lock_owner(fd: int) -> dict[str, Any] | None:
    try:
        owner = json.loads(os.pread(fd, 4096, 0).decode() or "null")
    except (OSError, ValueError):
        return None
    return owner if isinstance(owner, dict) and "pid" in owner else None


def _busy(out_dir: Path, owner: dict[str, Any] | None) -> FolderBusy:
    who = (f"pid {owner.get('pid')} on {owner.get('host')}, started {owner.get('started')}"
           if owner else "pid unknown")
    return FolderBusy(f"{out_dir}: the results folder is in use by another sweep or size "
                      f"({who}); wait for it to finish or use --out for another folder")


# ---- one run, in a worker ------------------------------------------------------------------


def execute_run(spec: RunSpec, runs_dir: str) -> RunResult:
    """Run `spec` into ``runs_dir/<run id>``; never raises for a failing run."""
    from fleet_sim.analysis.tables import stream_run
    from fleet_sim.config.scenario import load_scenario

    start = time.perf_counter()
    run_dir = Path(runs_dir) / spec.run_id
    run_dir.mkdir(parents=True, exist_ok=True)
    if (run_dir / "kpis.json").exists():
        return RunResult(spec.run_id, OK, 0.0)
    for stale in ("error.json",):
        (run_dir / stale).unlink(missing_ok=True)
    info = {**spec.as_json(), "pid": os.getpid(), "host": socket.gethostname(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S")}
    _write_json_atomic(run_dir / "spec.json", info)
    partial = run_dir / ".partial"
    try:
        shutil.rmtree(partial, ignore_errors=True)
        scenario = load_scenario(spec.scenario_file, spec.override_dict())
        layout = layout_for(scenario, spec.scenario_file)
        run, figures = stream_run(scenario, layout, partial, load_trace_for(scenario, layout),
                                  record_occupancy=True)
        events = pd.read_parquet(partial / "events.parquet", columns=list(WORK_SPELL_COLUMNS))
        waits = node_waits(run.recorder.occupancy, events, scenario.warmup_s,
                           scenario.duration_s)
        waits.to_parquet(partial / "node_waits.parquet", index=False)
        wall = time.perf_counter() - start
        figures["wall_s"] = round(wall, 3)
        _write_json_atomic(partial / "kpis.json", figures)
        for item in sorted(partial.iterdir(), key=lambda p: p.name == "kpis.json"):
            os.replace(item, run_dir / item.name)  # kpis.json last: the run is finished
        partial.rmdir()
        return RunResult(spec.run_id, OK, wall)
    except Exception as exc:  # a failing run is recorded, never raised
        wall = time.perf_counter() - start
        message = str(exc) if isinstance(exc, FleetSimError | InputError) \
            else f"{type(exc).__name__}: {exc}"
        record_failure(run_dir, FAILED, message, traceback.format_exc(), wall)
        shutil.rmtree(partial, ignore_errors=True)
        return RunResult(spec.run_id, FAILED, wall, message)


def record_failure(run_dir: Path, status: str, message: str, trace: str, wall_s: float) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    _write_json_atomic(run_dir / "error.json", {"status": status, "error": message,
                                                "traceback": trace, "wall_s": round(wall_s, 3)})


def _write_json_atomic(path: Path, data: Any) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def node_waits(occupancy: Sequence[OccupancySpell], events: pd.DataFrame,
               start_s: float, end_s: float) -> pd.DataFrame:
    """Per node: AGV passes, and seconds AGVs with work to do stood there waiting for the way."""
    segs = pd.DataFrame([o for o in occupancy if o.kind == "segment"],
                        columns=["kind", "key", "agv", "start", "end"])
    if segs.empty:
        return pd.DataFrame({"node": pd.Series(dtype="string"),
                             "passes": pd.Series(dtype="int64"),
                             "wait_s": pd.Series(dtype="float64"),
                             "stops": pd.Series(dtype="int64")})
    segs["node"] = segs["key"].str.split(">").str[1]
    spells = _work_spells(events)
    passes: dict[str, int] = {}
    waits: dict[str, float] = {}
    stops: dict[str, int] = {}
    for agv, group in segs.sort_values(["agv", "start"]).groupby("agv", sort=False):
        ends = group["end"].to_numpy()
        starts = group["start"].to_numpy()
        nodes = group["node"].to_numpy()
        for node in nodes[(ends >= start_s) & (ends <= end_s)]:
            passes[node] = passes.get(node, 0) + 1
        # standing at nodes[i] from its arrival until the next departure (a wait still going
        # on at the end of the run is not counted, as the engine does not count it either)
        stand_from, stand_to = ends[:-1], starts[1:]
        sp_from, sp_to = spells.get(int(str(agv)), (np.empty(0), np.empty(0)))
        if len(sp_from) == 0:
            continue
        # the work spell the AGV departs in; it waited from the later of its arrival and the
        # spell's start (handling, idling or a park-in manoeuvre before that is not waiting)
        k = np.searchsorted(sp_from, stand_to, side="right") - 1
        kk = np.maximum(k, 0)
        valid = (k >= 0) & (sp_to[kk] >= stand_to - 1e-9)
        lo = np.clip(np.maximum(stand_from, sp_from[kk]), start_s, end_s)
        hi = np.clip(stand_to, start_s, end_s)
        for i in np.nonzero(valid & (hi - lo > 1e-9))[0]:
            node = nodes[i]
            waits[node] = waits.get(node, 0.0) + float(hi[i] - lo[i])
            stops[node] = stops.get(node, 0) + 1
    names = sorted(set(passes) | set(waits))
    return pd.DataFrame({
        "node": pd.Series(names, dtype="string"),
        "passes": pd.Series([passes.get(n, 0) for n in names], dtype="int64"),
        "wait_s": pd.Series([round(waits.get(n, 0.0), 6) for n in names], dtype="float64"),
        "stops": pd.Series([stops.get(n, 0) for n in names], dtype="int64"),
    })


WORK_SPELL_COLUMNS = ("time_s", "agv", "event", "from_state", "to_state")
"""The columns of events.parquet that node_waits reads."""


def _work_spells(events: pd.DataFrame) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Per AGV, the (start, end) spells in which it has somewhere to go: state Moving, or Idle
    with an order assigned (waiting to leave parking) until it moves."""
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    ordered = events.sort_values(["agv", "time_s"], kind="stable")
    for agv, group in ordered.groupby("agv", sort=False):
        starts: list[float] = []
        stops: list[float] = []
        open_at: float | None = None
        for t, event, before, after in zip(group["time_s"], group["event"], group["from_state"],
                                           group["to_state"], strict=True):
            committed = after == "Moving" or (event == "order_assigned" and after == "Idle")
            if committed and open_at is None:
                open_at = float(t)
            elif not committed and before != after and open_at is not None:
                starts.append(open_at)
                stops.append(float(t))
                open_at = None
        if open_at is not None:
            starts.append(open_at)
            stops.append(math.inf)
        out[int(str(agv))] = (np.array(starts, dtype=float), np.array(stops, dtype=float))
    return out


# ---- progress ------------------------------------------------------------------------------


@dataclass
class RunTally:
    """Counts runs as they finish and shows them through `progress`."""

    progress: Progress
    total: int
    done: int
    failed: int = 0

    def __call__(self, result: RunResult) -> None:
        self.done += 1
        if result.status != OK:
            self.failed += 1
            self.progress.note(f"run {result.run_id} {result.status}: {result.error}")
        self.progress.update(self.done, f"runs {self.done}/{self.total} done, "
                                        f"{self.failed} failed")


# ---- runners -------------------------------------------------------------------------------


PARENT_POLL_S = 0.5
"""How often a worker checks that the sweep process is still alive."""


def _process_start(pid: int) -> str | None:
    """The process's start time (field 22 of /proc/<pid>/stat), "Z" for a zombie, or None
    where /proc cannot tell (not Linux, no such process)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
    fields = stat[stat.rfind(")") + 2:].split()
    return "Z" if fields[0] in ("Z", "X") else fields[19]


def pid_alive(pid: int, start: str | None = None) -> bool:
    """True if process `pid` runs (and, given its /proc start time `start`, is that process)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    now = _process_start(pid)
    return now != "Z" and (start is None or now is None or now == start)


def _die_with(sweep_pid: int) -> None:
    """Worker initializer: end this worker when the sweep process `sweep_pid` is gone."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            libc = ctypes.CDLL(None, use_errno=True)
            pr_set_pdeathsig = 1
            libc.prctl(pr_set_pdeathsig, 9, 0, 0, 0)  # SIGKILL when the parent (fork server) dies
        except (OSError, AttributeError):
            pass
    start = _process_start(sweep_pid)
    if not pid_alive(sweep_pid, start):
        os._exit(1)

    def watch() -> None:
        while pid_alive(sweep_pid, start):
            time.sleep(PARENT_POLL_S)
        os._exit(1)  # the sweep is gone: no one would take this run's result

    threading.Thread(target=watch, name="fleet-sim-watch-sweep", daemon=True).start()


def _mp_context() -> Any:
    if "forkserver" in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["fleet_sim.study.sweep", "fleet_sim.sim.engine",
                                        "fleet_sim.analysis.kpis", "fleet_sim.analysis.tables"])
        return context
    return multiprocessing.get_context("spawn")


class LocalPool:
    """Worker processes on this machine, kept across batches of runs (the sizing search sends
    many small batches); a dying worker never sinks the sweep (see the module docstring)."""

    def __init__(self, workers: int, run_fn: RunFn = execute_run) -> None:
        self.workers = max(1, workers)
        self.run_fn = run_fn
        self.pool: cf.ProcessPoolExecutor | None = None

    def __enter__(self) -> LocalPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
            self.pool = None

    def _kill(self) -> None:
        if self.pool is not None:
            self.pool.shutdown(wait=False, cancel_futures=True)
            self.pool = None

    def run(self, specs: Sequence[RunSpec], runs_dir: Path,
            on_result: Callable[[RunResult], None]) -> list[RunResult]:
        pending: deque[RunSpec] = deque(specs)
        suspects: deque[RunSpec] = deque()
        results: list[RunResult] = []
        inflight: dict[cf.Future[RunResult], RunSpec] = {}
        isolated = False
        try:
            while pending or suspects or inflight:
                if self.pool is None:
                    self.pool = cf.ProcessPoolExecutor(max_workers=self.workers,
                                                       mp_context=_mp_context(),
                                                       initializer=_die_with,
                                                       initargs=(os.getpid(),))
                pool = self.pool
                if not inflight:
                    isolated = bool(suspects)
                    if isolated:
                        spec = suspects.popleft()
                        inflight[pool.submit(self.run_fn, spec, str(runs_dir))] = spec
                if not isolated:
                    while pending and len(inflight) < self.workers:
                        spec = pending.popleft()
                        inflight[pool.submit(self.run_fn, spec, str(runs_dir))] = spec
                done, _ = cf.wait(inflight, return_when=cf.FIRST_COMPLETED)
                broken = False
                for future in done:
                    spec = inflight.pop(future)
                    try:
                        result = future.result()
                    except cf.process.BrokenProcessPool:
                        broken = True
                        if not isolated:
                            suspects.append(spec)
                            continue
                        result = _crashed(spec, runs_dir)
                    except Exception as exc:  # the run function itself failed to report
                        result = _failed_outside(spec, runs_dir, FAILED,
                                                 f"{type(exc).__name__}: {exc}",
                                                 traceback.format_exc())
                    results.append(result)
                    on_result(result)
                if broken:
                    # every other run in flight was lost with the pool: retry each alone
                    suspects.extend(inflight.values())
                    inflight.clear()
                    self._kill()
        except BaseException:
            self._kill()  # interrupted: do not wait for runs in flight
            raise
        return results


def run_local(specs: Sequence[RunSpec], runs_dir: Path, workers: int,
              on_result: Callable[[RunResult], None], run_fn: RunFn = execute_run
              ) -> list[RunResult]:
    """Run `specs` in a pool of `workers` processes started for them."""
    with LocalPool(workers, run_fn) as pool:
        return pool.run(specs, runs_dir, on_result)


def _crashed(spec: RunSpec, runs_dir: Path) -> RunResult:
    message = ("the worker process running it died without a Python exception "
               "(killed, out of memory, or a crash in native code)")
    _failed_outside(spec, runs_dir, CRASHED, message, "")
    shutil.rmtree(runs_dir / spec.run_id / ".partial", ignore_errors=True)
    return RunResult(spec.run_id, CRASHED, 0.0, message)


def _failed_outside(spec: RunSpec, runs_dir: Path, status: str, message: str,
                    trace: str) -> RunResult:
    """Record a run that failed outside the run function (which may never have started)."""
    run_dir = runs_dir / spec.run_id
    run_dir.mkdir(parents=True, exist_ok=True)
    if not (run_dir / "spec.json").exists():
        _write_json_atomic(run_dir / "spec.json", spec.as_json())
    record_failure(run_dir, status, message, trace, 0.0)
    return RunResult(spec.run_id, status, 0.0, message)


def run_serial(specs: Sequence[RunSpec], runs_dir: Path, on_result: Callable[[RunResult], None],
               run_fn: RunFn = execute_run) -> list[RunResult]:
    """Run `specs` one after another in this process (benchmarks, debugging)."""
    results = []
    for spec in specs:
        result = run_fn(spec, str(runs_dir))
        results.append(result)
        on_result(result)
    return results


class DaskPool:
    """Runs on a Dask cluster: the scheduler at `scheduler`, or "local" for a LocalCluster of
    `workers` single-threaded worker processes on this machine. The results folder must be
    reachable by the workers at the same path (a shared file system on a real cluster)."""

    def __init__(self, scheduler: str, workers: int, run_fn: RunFn = execute_run) -> None:
        require_extra("dask.distributed", "cluster", "--scheduler")
        self.scheduler = scheduler
        self.workers = max(1, workers)
        self.run_fn = run_fn
        self.client: Any = None
        self.cluster: Any = None

    def __enter__(self) -> DaskPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None

    def _connect(self) -> Any:
        distributed: Any = optional_import("dask.distributed", "cluster", "--scheduler")
        Client, LocalCluster = distributed.Client, distributed.LocalCluster
        if self.client is None:
            address: Any = self.scheduler
            if self.scheduler == "local":
                self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1,
                                            processes=True, dashboard_address=None)
                address = self.cluster
            try:
                self.client = Client(address, timeout="20s")
            except OSError as exc:
                raise InputError("--scheduler", "address", self.scheduler,
                                 f"a reachable Dask scheduler ({exc})") from None
        return self.client

    def run(self, specs: Sequence[RunSpec], runs_dir: Path,
            on_result: Callable[[RunResult], None]) -> list[RunResult]:
        client = self._connect()
        as_completed = optional_import("dask.distributed", "cluster", "--scheduler").as_completed
        results: list[RunResult] = []
        stamp = time.time_ns()
        futures = {client.submit(self.run_fn, spec, str(runs_dir.resolve()), pure=False,
                                 key=f"fleet-sim-run-{spec.run_id}-{stamp}"): spec
                   for spec in specs}
        for future in as_completed(futures):
            spec = futures[future]
            try:
                result = future.result()
            except Exception as exc:
                if type(exc).__name__ == "KilledWorker":
                    result = _crashed(spec, runs_dir)
                else:
                    result = _failed_outside(spec, runs_dir, FAILED,
                                             f"{type(exc).__name__}: {exc}",
                                             "".join(traceback.format_exception(exc)))
            results.append(result)
            on_result(result)
        return results


# ---- the sweep -----------------------------------------------------------------------------


@dataclass
class SweepOutcome:
    out_dir: Path
    total: int
    skipped: int
    results: list[RunResult]

    @property
    def failed(self) -> list[RunResult]:
        return [r for r in self.results if r.status != OK]


def default_out(experiment: Experiment) -> Path:
    return Path("results") / experiment.name


def check_extras(experiment: Experiment, scheduler: str | None = None) -> None:
    """Before any run: the extras the experiment's runs need are installed (a SUMO backend in
    the scenario, its overrides or a `motion` factor; Dask for a scheduler), else one line."""
    first = dict(experiment.points[0]) if experiment.points else {}
    motions = {experiment.scenario(first).motion, *experiment.spec.factors.get("motion", ())}
    for motion in sorted(m for m in motions if isinstance(m, str)):
        require_backend(motion, f"{experiment.file}: motion: {motion}")
    if scheduler:
        require_extra("dask.distributed", "cluster", "--scheduler")


def prepare(experiment: Experiment, out_dir: Path) -> None:
    """Create the results folder and record the experiment in it."""
    (out_dir / "runs").mkdir(parents=True, exist_ok=True)
    shutil.copyfile(experiment.file, out_dir / "experiment.yaml")
    (out_dir / "experiment.resolved.yaml").write_text(
        yaml.safe_dump(experiment.resolved(), sort_keys=False, allow_unicode=True),
        encoding="utf-8")


def finished(spec: RunSpec, runs_dir: Path) -> bool:
    """True if the run's kpis.json exists; an error if the folder holds a different run."""
    run_dir = runs_dir / spec.run_id
    spec_file = run_dir / "spec.json"
    if spec_file.exists():
        try:
            recorded = json.loads(spec_file.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            recorded = None
        wanted = json.loads(json.dumps(spec.as_json(), default=str))
        if recorded is not None:
            for key in ("seed", "overrides", "scenario_file"):
                if recorded.get(key) != wanted[key]:
                    raise SweepError(
                        f"{run_dir}: this run was made with another {key} "
                        f"({recorded.get(key)!r}, now {wanted[key]!r}): the results folder "
                        "holds another experiment; use --out for a new folder or delete it")
    return (run_dir / "kpis.json").exists()


def execute(specs: Iterable[RunSpec], out_dir: Path, workers: int = 0,
            scheduler: str | None = None, quiet: bool = False,
            run_fn: RunFn = execute_run, stream: IO[str] | None = None,
            pool: LocalPool | DaskPool | None = None) -> SweepOutcome:
    """Run every spec not yet finished in `out_dir/runs`; workers=0 means one per core.
    `pool`: worker processes to reuse (else a pool is started for these runs)."""
    runs_dir = out_dir / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    specs = list(specs)
    todo = [s for s in specs if not finished(s, runs_dir)]
    todo.sort(key=lambda s: -_cost(s))
    workers = workers or os.cpu_count() or 1
    already = len(specs) - len(todo)
    with Progress(len(specs), already, stream=stream, quiet=quiet) as progress:
        if already:
            progress.note(f"{already} of {len(specs)} runs already finished: skipped")
        tally = RunTally(progress, len(specs), already)
        if not todo:
            results: list[RunResult] = []
        elif pool is not None:
            results = pool.run(todo, runs_dir, tally)
        elif scheduler:
            with DaskPool(scheduler, workers, run_fn) as dask_pool:
                results = dask_pool.run(todo, runs_dir, tally)
        else:
            results = run_local(todo, runs_dir, min(workers, len(todo)), tally, run_fn)
    return SweepOutcome(out_dir, len(specs), len(specs) - len(todo), results)


def _cost(spec: RunSpec) -> float:
    """A run's relative cost, for scheduling: its fleet size where a factor gives it (a mixed
    fleet: the counts its factors give)."""
    overrides = spec.override_dict()
    size = overrides.get(FLEET)
    if size is None:
        size = sum(v for k, v in overrides.items() if k.startswith(f"{VEHICLE_TYPES}.")
                   and k.endswith(".count") and isinstance(v, int)) or 1
    return float(size) if isinstance(size, (int, float)) else 1.0


def sweep(experiment: Experiment, out_dir: Path, workers: int = 0, scheduler: str | None = None,
          quiet: bool = False, run_fn: RunFn = execute_run,
          stream: IO[str] | None = None) -> SweepOutcome:
    """Run the experiment's design into `out_dir` and write its summary, statistics and DB."""
    check_extras(experiment, scheduler)
    with folder_lock(out_dir, stream), tables_written(experiment, out_dir):
        if experiment.spec.warmup.method != "fixed":
            from fleet_sim.study.warmup import largest_fleet, pilot_groups, settle_warmup

            n_workers = workers or os.cpu_count() or 1
            pilot_pool: LocalPool | DaskPool = DaskPool(scheduler, n_workers, run_fn) \
                if scheduler else LocalPool(n_workers, run_fn)
            with pilot_pool, Progress(stream=stream, quiet=quiet) as progress:
                experiment = settle_warmup(experiment, out_dir, pilot_groups(experiment),
                                           largest_fleet(experiment), pilot_pool, progress)
        prepare(experiment, out_dir)
        outcome = execute(experiment.runs(), out_dir, workers, scheduler, quiet, run_fn, stream)
    return outcome


@contextmanager
def tables_written(experiment: Experiment, out_dir: Path) -> Iterator[None]:
    """Write the summary tables when the block ends, also when an exception (Ctrl-C, a run
    function that fails to report) ends it, so the tables keep up with the runs finished."""
    try:
        yield
    except BaseException:
        with contextlib.suppress(Exception):  # the exception that ended the block matters more
            write_tables(experiment, out_dir)
        raise
    write_tables(experiment, out_dir)


# ---- tables --------------------------------------------------------------------------------


def collect_summary(out_dir: Path, factor_names: Sequence[str]) -> pd.DataFrame:
    """One row per run folder: status, factors, replication, seed, KPIs, runtime, error."""
    rows: list[dict[str, Any]] = []
    runs_dir = out_dir / "runs"
    for run_dir in sorted(p for p in runs_dir.iterdir() if p.is_dir()) if runs_dir.exists() \
            else []:
        spec_file = run_dir / "spec.json"
        if not spec_file.exists():
            continue
        spec = json.loads(spec_file.read_text(encoding="utf-8"))
        row: dict[str, Any] = {"run_id": spec["run_id"], "status": "incomplete",
                               "replication": spec["replication"], "seed": spec["seed"]}
        for name in factor_names:
            row[name] = spec["factors"].get(name)
        kpi_file, error_file = run_dir / "kpis.json", run_dir / "error.json"
        if kpi_file.exists():
            row["status"] = OK
            figures = json.loads(kpi_file.read_text(encoding="utf-8"))
            for key, value in figures.items():
                if isinstance(value, dict):  # errors_by_code -> errors_by_code.E_101, ...
                    row.update({f"{key}.{k}": v for k, v in value.items()})
                elif isinstance(value, list):  # setup_warnings: one line each
                    row[key] = "\n".join(str(v) for v in value)
                elif key not in row:
                    row[key] = value
            row["error"] = ""
        elif error_file.exists():
            error = json.loads(error_file.read_text(encoding="utf-8"))
            row["status"] = error.get("status", FAILED)
            row["error"] = error.get("error", "")
            row["wall_s"] = error.get("wall_s")
        rows.append(row)
    frame = pd.DataFrame(rows)
    counts = [c for c in frame.columns if c.startswith(("errors_by_code.", "warnings_by_code."))]
    frame[counts] = frame[counts].fillna(0)  # a code a run never raised: zero times
    if frame.empty:
        return pd.DataFrame({"run_id": pd.Series(dtype="string"),
                             "status": pd.Series(dtype="string")})
    for column in frame.columns:
        if frame[column].dtype == object:
            values = frame[column].dropna()
            if len(values) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                   for v in values):
                frame[column] = pd.to_numeric(frame[column])
            elif len(values) and all(isinstance(v, str) for v in values):
                frame[column] = frame[column].astype("string")
    return frame


def run_statuses(out_dir: Path) -> dict[str, str]:
    """Per run folder (with spec.json): its status as collect_summary gives it."""
    statuses: dict[str, str] = {}
    runs_dir = out_dir / "runs"
    for run_dir in runs_dir.iterdir() if runs_dir.exists() else []:
        if not (run_dir / "spec.json").exists():
            continue
        status = "incomplete"
        if (run_dir / "kpis.json").exists():
            status = OK
        elif (run_dir / "error.json").exists():
            try:
                error = json.loads((run_dir / "error.json").read_text(encoding="utf-8"))
                status = str(error.get("status", FAILED))
            except (OSError, json.JSONDecodeError):
                status = FAILED
        statuses[run_dir.name] = status
    return statuses


def read_summary(out_dir: Path, factor_names: Sequence[str]) -> tuple[pd.DataFrame, bool]:
    """The results folder's summary and whether it had to be rebuilt: summary.parquet if its
    runs and their statuses are those of the run folders, else one collected from them."""
    summary_file = out_dir / "summary.parquet"
    if summary_file.exists():
        summary = pd.read_parquet(summary_file)
        if {"run_id", "status"} <= set(summary.columns):
            recorded = dict(zip(summary["run_id"].astype(str), summary["status"].astype(str),
                                strict=True))
            if len(recorded) == len(summary) and recorded == run_statuses(out_dir):
                return summary, False
    return collect_summary(out_dir, factor_names), True


def write_tables(experiment: Experiment, out_dir: Path) -> pd.DataFrame:
    """summary.parquet, stats.parquet and sweep.duckdb from the run folders on disk."""
    from fleet_sim.analysis.stats import point_stats

    summary = collect_summary(out_dir, experiment.factor_names)
    summary.to_parquet(out_dir / "summary.parquet", index=False)
    stats = point_stats(summary, experiment.factor_names)
    stats.to_parquet(out_dir / "stats.parquet", index=False)
    write_duckdb(out_dir)
    return summary


def write_duckdb(out_dir: Path) -> Path:
    """sweep.duckdb: tables summary and stats, views over every run's Parquet tables."""
    import duckdb

    db_path = out_dir / "sweep.duckdb"
    tmp = out_dir / ".sweep.duckdb.tmp"
    tmp.unlink(missing_ok=True)
    runs = (out_dir / "runs").resolve()
    con = duckdb.connect(str(tmp))
    try:
        for table in ("summary", "stats"):
            source = (out_dir / f"{table}.parquet").resolve()
            if source.exists():
                con.execute(f"CREATE TABLE {table} AS SELECT * FROM read_parquet('{_sql(source)}')")
        for view in ("orders", "events", "node_waits"):
            if any(runs.glob(f"*/{view}.parquet")):
                pattern = _sql(runs / "*" / f"{view}.parquet")
                con.execute(
                    f"CREATE VIEW {view} AS SELECT regexp_extract(filename, "
                    f"'([^/]+)/{view}.parquet$', 1) AS run_id, * EXCLUDE (filename) "
                    f"FROM read_parquet('{pattern}', filename = true, union_by_name = true)")
    finally:
        con.close()
    os.replace(tmp, db_path)
    (out_dir / ".sweep.duckdb.tmp.wal").unlink(missing_ok=True)
    return db_path


def _sql(path: Path) -> str:
    return str(path).replace("'", "''")

