"""One run, in a worker: `execute_run` makes a run's folder (fleet_sim.study.run_folder)
from its spec; a failing run is recorded in it, never raised, but for a fault of the machine
(a full disk, a folder that cannot be written), which stops the study.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import socket
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from fleet_sim.analysis.congestion import WORK_SPELL_COLUMNS, node_waits
from fleet_sim.config.experiment import RunSpec, load_trace_for, run_layout
from fleet_sim.errors import FleetSimError, InputError
from fleet_sim.study.run_folder import (
    CHECKED_BY,
    FAILED,
    MANIFEST,
    MODEL_KEY,
    MODEL_VERSION,
    OK,
    RunResult,
    record_failure,
    run_problem,
    write_manifest,
)
from fleet_sim.study.study_folder import study_owner
from userfiles.writing import atomic_path, write_json_atomic

RunFn = Callable[[RunSpec, str], RunResult]
"""A function that executes one run into `runs_dir` (module level, so workers can import it)."""


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
