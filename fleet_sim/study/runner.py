"""Executing runs: one run in a worker, pools of workers (processes here, or a Dask cluster),
and the lock that keeps one study per results folder. Sweep, size and compare decide which runs
to make; this module makes them and never decides.

A run's folder (``<results>/runs/<run id>/``)::

    spec.json              factors, replication, seed, overrides (written first)
    config.resolved.yaml   the run's scenario, every default written out
    events.parquet, orders.parquet, run_info.json    as `fleet-sim run` writes them
    node_waits.parquet     per node: AGV passes and seconds AGVs stood there waiting
                           (fleet_sim.analysis.congestion)
    kpis.json              the run's KPIs
    manifest.json          written last: each file's size and SHA-256 (a finished run)
    error.json             instead of the manifest when the run failed (type, message, trace)

Decisions, where the issues are silent:

* A run is finished when its manifest exists and checks out (`run_problem`): every file it
  lists is there with its size and SHA-256, and kpis.json holds KPIs. The engine's files are
  written to ``runs/<id>/.partial`` (each atomically: userfiles.writing) and moved in,
  the manifest last (``os.replace``), so a study killed at any moment leaves either a
  finished run or one that is run again; re-running skips finished runs, retries failed ones
  and makes again, with one line naming it and what was wrong, a run whose files were
  damaged, truncated or removed since, the manifest included: a run's spec.json says the
  manifest checks it (``checked_by``), so a run without one is not finished (a run of an
  older fleet_sim, whose spec.json does not say so, is trusted if its kpis.json holds KPIs
  and its Parquet files open), or whose spec.json names another run (the summary would file
  it under that run's name). Checking costs a read of the run's files (SHA-256 runs at
  several hundred MB/s; a warehouse shift's run is 1-3 MB).
* The temporaries a killed study left (``.*.tmp``, ``.partial``) are removed by the next study
  that takes the folder. A run that finishes after its study stopped (a Dask worker that
  outlived a lost scheduler) sees that the folder's lock no longer names its study and
  writes nothing. A run folder whose spec.json differs from what the experiment
  now asks for (another master seed, other overrides) stops the study with an error rather
  than mixing two experiments in one folder.
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
* KPIs: every run's are summed as it runs (fleet_sim.analysis.kpis, as for `fleet-sim run`);
  the runner adds ``wall_s``, the run's wall time including writing its files.
* Memory: a run streams its tables to Parquet as `fleet-sim run` does, but the occupancy
  trace that node waits need stays in memory (a record per node hold and segment
  traversal), and node_waits reads the columns it needs of events.parquet back once the run
  is over. A study run's memory therefore still grows with its simulated time; studies run
  shifts of hours, not years.
* One study per results folder: a sweep, size or compare holds an exclusive ``fcntl.flock`` on
  ``<folder>/.fleet-sim.lock`` while it runs, and writes its pid, host and start time into it.
  flock (not a file created with O_EXCL) because the kernel releases it when the process
  dies, however it dies, so a lock can never be left stale; a lock file that still names a
  process which no longer holds it is taken over with a note. A second study into a busy
  folder stops with one line naming the folder and the owner's pid. Where fcntl does not
  exist (Windows) the owner's pid is checked instead. The file stays (emptied) after the run.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import errno
import hashlib
import json
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

import pandas as pd
import yaml

from fleet_sim.analysis.congestion import WORK_SPELL_COLUMNS, node_waits
from fleet_sim.config.experiment import FLEET, Experiment, RunSpec, load_trace_for, run_layout
from fleet_sim.config.scenario import VEHICLE_TYPES
from fleet_sim.errors import FleetSimError, InputError, optional_import, require_extra
from fleet_sim.sim.motion import require_backend
from fleet_sim.study.progress import Progress
from userfiles.writing import (
    atomic_path,
    clean_temporaries,
    copy_atomic,
    write_json_atomic,
    write_text_atomic,
)

RunFn = Callable[[RunSpec, str], "RunResult"]
"""A function that executes one run into `runs_dir` (module level, so workers can import it)."""

OK, FAILED, CRASHED, DAMAGED = "ok", "failed", "crashed", "damaged"


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
        clean_temporaries(out_dir)  # what a killed study left half-written
        try:
            yield
        finally:
            os.ftruncate(fd, 0)  # released: an empty lock file names no owner
    finally:
        os.close(fd)  # releases the flock


def study_running(out_dir: Path) -> bool:
    """Is a study (sweep, size, compare) writing into `out_dir` now? Asked of the lock itself:
    a shared lock cannot be had while a study holds the exclusive one."""
    path = out_dir / LOCK_FILE
    if not path.exists():
        return False
    if fcntl is None:
        owner = study_owner(out_dir)
        return owner is not None and pid_alive(int(json.loads(owner).get("pid", 0)))
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # releases the shared lock if it was had
    return False


PLAN_FILE = "plan.json"
"""What the study in a results folder set out to do: its kind and the runs it planned."""


def write_plan(out_dir: Path, study: str, run_ids: Sequence[str] | None) -> None:
    """Record the runs a study plans (None: a search that decides as it goes), so a report
    on an unfinished study can say how many of how many have finished."""
    write_json_atomic(out_dir / PLAN_FILE, {"study": study, "runs": None if run_ids is None
                                            else list(run_ids)})


def read_plan(out_dir: Path) -> dict[str, Any] | None:
    try:
        plan = json.loads((out_dir / PLAN_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return plan if isinstance(plan, dict) else None


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
    owner = study_owner(Path(runs_dir).parent)
    run_dir.mkdir(parents=True, exist_ok=True)
    if (run_dir / MANIFEST).exists() and run_problem(run_dir) is None:
        return RunResult(spec.run_id, OK, 0.0)
    for stale in (MANIFEST, "kpis.json", "error.json"):  # a damaged run is made again
        (run_dir / stale).unlink(missing_ok=True)
    info = {**spec.as_json(), "pid": os.getpid(), "host": socket.gethostname(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S"), CHECKED_BY: MANIFEST,
            MODEL_KEY: MODEL_VERSION}
    write_json_atomic(run_dir / "spec.json", info)
    partial = run_dir / ".partial"
    try:
        shutil.rmtree(partial, ignore_errors=True)
        scenario = load_scenario(spec.scenario_file, spec.override_dict())
        layout = run_layout(scenario, spec)
        run, figures = stream_run(scenario, layout, partial, load_trace_for(scenario, layout),
                                  record_occupancy=True)
        events = pd.read_parquet(partial / "events.parquet", columns=list(WORK_SPELL_COLUMNS))
        waits = node_waits(run.recorder.occupancy, events, scenario.warmup_s,
                           scenario.duration_s)
        with atomic_path(partial / "node_waits.parquet") as tmp:
            waits.to_parquet(tmp, index=False)
        wall = time.perf_counter() - start
        figures["wall_s"] = round(wall, 3)
        write_json_atomic(partial / "kpis.json", figures)
        write_manifest(partial)
        if owner is not None and study_owner(Path(runs_dir).parent) != owner:
            # the study that asked for this run has stopped (a Dask worker outliving its
            # sweep): its folder is no longer this run's to write
            shutil.rmtree(partial, ignore_errors=True)
            return RunResult(spec.run_id, FAILED, wall, "the study stopped before this run "
                             "finished; not written")
        for item in sorted(partial.iterdir(), key=lambda p: p.name == MANIFEST):
            os.replace(item, run_dir / item.name)  # the manifest last: the run is finished
        partial.rmdir()
        return RunResult(spec.run_id, OK, wall)
    except Exception as exc:  # a failing run is recorded, never raised
        wall = time.perf_counter() - start
        message = str(exc) if isinstance(exc, FleetSimError | InputError) \
            else f"{type(exc).__name__}: {exc}"
        shutil.rmtree(partial, ignore_errors=True)
        if machine_fault(exc):
            raise  # not this run's fault: every run would fail so; the study stops
        with contextlib.suppress(OSError):  # a full disk may not take the record either
            record_failure(run_dir, FAILED, message, traceback.format_exc(), wall)
        return RunResult(spec.run_id, FAILED, wall, message)


MACHINE_FAULTS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES,
                            errno.EPERM})
"""Errors of the machine, not of a run: a full disk, a read-only or forbidden folder. A run
that meets one stops the study with one line (every other run would meet it too)."""


def machine_fault(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno in MACHINE_FAULTS


# ---- is a finished run what it says it is? -------------------------------------------------

MANIFEST = "manifest.json"
"""Written last into a finished run's folder: each file's size and SHA-256."""
CHECKED_BY = "checked_by"
"""The key of spec.json that says the run is finished only with its manifest (absent in the
runs of an older fleet_sim, which wrote none)."""
MODEL_VERSION = "2026-11-28"
"""The model that made a run, in spec.json: changed whenever a change moves the results of runs
with the same settings (new defaults, a fix in the engine). A finished run of another model
(or of an older fleet_sim, which did not say) is made again, with one line naming it, so a
resumed study never mixes runs of two models. Last changed by issue 33 (the AGV ahead paused
by its LDS, E_999 as a reboot, commands timed on each type's protocol)."""
MODEL_KEY = "model_version"
CHECKED_ASIDE = ("spec.json", "error.json", MANIFEST)
"""Files of a run folder the manifest does not cover (written before, or instead of, it)."""
HASH_CHUNK = 1 << 20


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(HASH_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def write_manifest(run_dir: Path) -> None:
    """The manifest of the run's files in `run_dir` (everything but spec.json and error.json)."""
    files = {p.name: {"size_bytes": p.stat().st_size, "sha256": file_sha256(p)}
             for p in sorted(run_dir.iterdir())
             if p.is_file() and not p.name.startswith(".") and p.name not in CHECKED_ASIDE}
    write_json_atomic(run_dir / MANIFEST, {"files": files})


def run_problem(run_dir: Path) -> str | None:
    """What is wrong with a run folder that looks finished (it has a manifest or a
    kpis.json), in a few words; None when every file it should hold is there, whole and
    readable. A run of an older fleet_sim (kpis.json, no manifest) is checked by reading:
    its kpis.json must hold KPIs and every Parquet file must open."""
    spec, spec_problem = _read_json(run_dir / "spec.json", "run_id",
                                    "does not say which run this is")
    if spec_problem is not None:  # the summary could not place the run: it would vanish
        return spec_problem
    if spec["run_id"] != run_dir.name:  # the summary would file it under another run's name
        return f"spec.json names another run ({spec['run_id']})"
    if spec.get(MODEL_KEY) != MODEL_VERSION:
        return (f"it was made by another version of the model ({spec.get(MODEL_KEY) or 'older'}"
                f", now {MODEL_VERSION})")
    manifest_file = run_dir / MANIFEST
    if not manifest_file.exists() and spec.get(CHECKED_BY) == MANIFEST:
        return f"{MANIFEST} is missing"
    if manifest_file.exists():
        try:
            manifest = json.loads(manifest_file.read_text(encoding="utf-8"))
            files = manifest["files"]
            assert isinstance(files, dict)
        except (OSError, ValueError, KeyError, AssertionError, TypeError):
            return f"{MANIFEST} is damaged"
        for name, entry in sorted(files.items()):
            path = run_dir / name
            if not path.is_file():
                return f"{name} is missing"
            try:
                size = path.stat().st_size
                if size != entry.get("size_bytes"):
                    return (f"{name} has {size} bytes where {entry.get('size_bytes')} were "
                            "written")
                if file_sha256(path) != entry.get("sha256"):
                    return f"{name} is damaged (its content changed since it was written)"
            except OSError as exc:
                return f"{name} cannot be read ({exc.strerror or exc})"
        if "kpis.json" not in files:
            return "kpis.json is missing"
    return _kpis_problem(run_dir) or (None if manifest_file.exists()
                                      else _tables_problem(run_dir))


def _kpis_problem(run_dir: Path) -> str | None:
    return _read_json(run_dir / "kpis.json", "throughput_per_hour", "holds no KPIs")[1]


def _read_json(path: Path, key: str, without_key: str) -> tuple[dict[str, Any], str | None]:
    """A run's JSON file that must be an object holding `key`, and what is wrong with it:
    None when nothing is (when something is, the object is empty)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}, f"{path.name} is missing"
    except (OSError, ValueError):
        return {}, f"{path.name} is damaged (not JSON)"
    if not isinstance(data, dict) or key not in data:
        return {}, f"{path.name} {without_key}"
    return data, None


def _tables_problem(run_dir: Path) -> str | None:
    import pyarrow.parquet as pq

    for path in sorted(run_dir.glob("*.parquet")):
        try:
            pq.read_metadata(path)
        except Exception as exc:  # pyarrow raises its own errors for a damaged file
            return f"{path.name} is damaged ({type(exc).__name__})"
    return None


def study_owner(out_dir: Path) -> str | None:
    """Who holds the results folder now (the lock file's content), or None when nobody
    does (a run made outside a study)."""
    try:
        text = (out_dir / LOCK_FILE).read_text(encoding="utf-8").strip()
    except OSError:
        return None
    return text or None


def record_failure(run_dir: Path, status: str, message: str, trace: str, wall_s: float) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(run_dir / "error.json", {"status": status, "error": message,
                                                "traceback": trace, "wall_s": round(wall_s, 3)})





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


DEFAULT_NO_WORKERS_TIMEOUT_S = 120.0
"""How long a study on a Dask cluster waits with no worker at all before it gives up."""
WORKER_POLL_S = 1.0
"""How often a study on a Dask cluster looks for workers while no run finishes."""

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
        context.set_forkserver_preload(["fleet_sim.study.runner", "fleet_sim.sim.engine",
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
                        if machine_fault(exc):
                            raise
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


def make_pool(scheduler: str | None, workers: int, run_fn: RunFn = execute_run,
              dask_timeout_s: float = DEFAULT_NO_WORKERS_TIMEOUT_S) -> LocalPool | DaskPool:
    """Workers kept for a whole study: on the Dask cluster `scheduler`, else processes here
    (workers=0: one per core)."""
    n_workers = workers or os.cpu_count() or 1
    return DaskPool(scheduler, n_workers, run_fn, dask_timeout_s) if scheduler \
        else LocalPool(n_workers, run_fn)


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
        write_json_atomic(run_dir / "spec.json", spec.as_json())
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

    def __init__(self, scheduler: str, workers: int, run_fn: RunFn = execute_run,
                 no_workers_timeout_s: float = DEFAULT_NO_WORKERS_TIMEOUT_S) -> None:
        require_extra("dask.distributed", "cluster", "--scheduler")
        self.scheduler = scheduler
        self.workers = max(1, workers)
        self.run_fn = run_fn
        self.no_workers_timeout_s = no_workers_timeout_s
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
        distributed: Any = optional_import("dask.distributed", "cluster", "--scheduler")
        results: list[RunResult] = []
        stamp = time.time_ns()
        futures = {client.submit(self.run_fn, spec, str(runs_dir.resolve()), pure=False,
                                 key=f"fleet-sim-run-{spec.run_id}-{stamp}"): spec
                   for spec in specs}
        for future in self._as_completed(client, distributed, list(futures)):
            spec = futures[future]
            try:
                result = future.result()
            except Exception as exc:
                if machine_fault(exc):
                    raise
                if type(exc).__name__ == "KilledWorker":
                    result = _crashed(spec, runs_dir)
                else:
                    result = _failed_outside(spec, runs_dir, FAILED,
                                             f"{type(exc).__name__}: {exc}",
                                             "".join(traceback.format_exception(exc)))
            results.append(result)
            on_result(result)
        return results

    def _as_completed(self, client: Any, distributed: Any, futures: list[Any]
                      ) -> Iterator[Any]:
        """The futures as they finish; SweepError when the cluster has had no worker for
        `no_workers_timeout_s` (a cluster that lost every worker would leave the runs waiting
        for ever) or the scheduler is gone."""
        pending = set(futures)
        alone_since: float | None = None
        while pending:
            try:
                done, pending = distributed.wait(list(pending), timeout=WORKER_POLL_S,
                                                 return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = set()
            except OSError as exc:  # the scheduler is gone
                raise SweepError(f"Dask scheduler {self.scheduler}: lost ({exc}); the runs "
                                 "finished so far are kept, run the study again to go "
                                 "on") from None
            yield from (f for f in futures if f in done)
            if done:
                alone_since = None
                continue
            try:
                workers = len(client.scheduler_info().get("workers", {}))
            except OSError:
                workers = 0
            if workers:
                alone_since = None
            elif alone_since is None:
                alone_since = time.monotonic()
            elif time.monotonic() - alone_since >= self.no_workers_timeout_s:
                raise SweepError(
                    f"Dask cluster {self.scheduler}: no worker for "
                    f"{self.no_workers_timeout_s:g} s (--dask-timeout) with {len(pending)} "
                    "runs waiting; the runs finished so far are kept, run the study again "
                    "to go on")


# ---- a batch of runs ------------------------------------------------------------------


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
    copy_atomic(experiment.file, out_dir / "experiment.yaml")
    write_text_atomic(out_dir / "experiment.resolved.yaml",
                      yaml.safe_dump(experiment.resolved(), sort_keys=False,
                                     allow_unicode=True))


def finished(spec: RunSpec, runs_dir: Path) -> tuple[bool, str | None]:
    """Whether the run finished and checks out, and, for one that looks finished but does not
    (`run_problem`), what is wrong with it; an error if the folder holds a different run."""
    run_dir = runs_dir / spec.run_id
    spec_file = run_dir / "spec.json"
    if spec_file.exists():
        try:
            recorded = json.loads(spec_file.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            recorded = None
        wanted = json.loads(json.dumps(spec.as_json(), default=str))
        if recorded is not None:
            for key in ("seed", "overrides", "scenario_file", "layout_changes"):
                if recorded.get(key) != wanted.get(key):
                    raise SweepError(
                        f"{run_dir}: this run was made with another {key} "
                        f"({recorded.get(key)!r}, now {wanted.get(key)!r}): the results folder "
                        "holds another experiment; use --out for a new folder or delete it")
    if not ((run_dir / MANIFEST).exists() or (run_dir / "kpis.json").exists()):
        return False, None
    problem = run_problem(run_dir)
    return problem is None, problem


def execute(specs: Iterable[RunSpec], out_dir: Path, workers: int = 0,
            scheduler: str | None = None, quiet: bool = False,
            run_fn: RunFn = execute_run, stream: IO[str] | None = None,
            pool: LocalPool | DaskPool | None = None,
            dask_timeout_s: float = DEFAULT_NO_WORKERS_TIMEOUT_S) -> SweepOutcome:
    """Run every spec not yet finished in `out_dir/runs`; workers=0 means one per core.
    `pool`: worker processes to reuse (else a pool is started for these runs)."""
    runs_dir = out_dir / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)
    specs = list(specs)
    checked = {s.run_id: finished(s, runs_dir) for s in specs}
    damaged = {run: problem for run, (_, problem) in checked.items() if problem is not None}
    todo = [s for s in specs if not checked[s.run_id][0]]
    todo.sort(key=lambda s: -_cost(s))
    workers = workers or os.cpu_count() or 1
    already = len(specs) - len(todo)
    with Progress(len(specs), already, stream=stream, quiet=quiet) as progress:
        for run_id, problem in damaged.items():
            progress.note(f"run {run_id}: {problem}; it is run again")
        if already:
            progress.note(f"{already} of {len(specs)} runs already finished: skipped")
        tally = RunTally(progress, len(specs), already)
        if not todo:
            results: list[RunResult] = []
        elif pool is not None:
            results = pool.run(todo, runs_dir, tally)
        elif scheduler:
            with DaskPool(scheduler, workers, run_fn, dask_timeout_s) as dask_pool:
                results = dask_pool.run(todo, runs_dir, tally)
        else:
            results = run_local(todo, runs_dir, min(workers, len(todo)), tally, run_fn)
    unrecorded = [s.run_id for s in specs if not (runs_dir / s.run_id / "spec.json").is_file()]
    if unrecorded:  # the summary would hold fewer runs than were planned, without a word
        raise SweepError(
            f"{len(unrecorded)} of the {len(specs)} runs asked for left no record in "
            f"{runs_dir} ({', '.join(unrecorded[:3])}{' ...' if len(unrecorded) > 3 else ''}): "
            "run the study again to make them")
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


