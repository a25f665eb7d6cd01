"""Pools of workers that execute runs: processes on this machine (`LocalPool`, kept across a
study's batches), a Dask cluster (`DaskPool`), or one run after another here (`run_serial`).
A worker that dies never sinks the study: the run it had is recorded as crashed.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import shutil
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from fleet_sim.config.experiment import RunSpec
from fleet_sim.errors import InputError, optional_import, require_extra
from fleet_sim.study.run_folder import CRASHED, FAILED, RunResult, record_failure
from fleet_sim.study.study_folder import SweepError, pid_alive, process_start
from fleet_sim.study.worker import RunFn, execute_run, machine_fault
from userfiles.writing import write_json_atomic

# ---- runners -------------------------------------------------------------------------------


DEFAULT_NO_WORKERS_TIMEOUT_S = 120.0
"""How long a study on a Dask cluster waits with no worker at all before it gives up."""
WORKER_POLL_S = 1.0
"""How often a study on a Dask cluster looks for workers while no run finishes."""

PARENT_POLL_S = 0.5
"""How often a worker checks that the sweep process is still alive."""


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
    start = process_start(sweep_pid)
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
        context.set_forkserver_preload(["fleet_sim.study.pools", "fleet_sim.sim.engine",
                                        "fleet_sim.analysis.kpi_sums",
                                        "fleet_sim.analysis.tables"])
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
