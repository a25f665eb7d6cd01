"""Run functions for sweep tests; module level so worker processes can import them."""

from __future__ import annotations

import json
import os
from pathlib import Path

from fleet_sim.config.experiment import RunSpec
from fleet_sim.study.run_folder import RunResult
from fleet_sim.study.worker import execute_run

CRASH = "fleet.size=2__r01"
FAIL = "fleet.size=3__r00"
MISNAMED = "fleet.size=9__r00"


def flaky_run(spec: RunSpec, runs_dir: str) -> RunResult:
    """Kills its worker process on run CRASH, raises on run FAIL, else runs normally."""
    if spec.run_id == CRASH:
        os._exit(3)  # like a segfault or the OOM killer: no Python exception, no clean-up
    if spec.run_id == FAIL:
        raise RuntimeError("boom: a bug in the run function")
    return execute_run(spec, runs_dir)


def recordless_run(spec: RunSpec, runs_dir: str) -> RunResult:
    """Says run FAIL went well but leaves nothing on disk (a record lost); the rest run."""
    if spec.run_id == FAIL:
        return RunResult(spec.run_id, "ok", 0.0)
    return execute_run(spec, runs_dir)


def misnamed_run(spec: RunSpec, runs_dir: str) -> RunResult:
    """Runs normally, then leaves run FAIL's spec.json naming another run (a folder copied
    by hand, say): the summary files the run under that name, and FAIL has no row."""
    result = execute_run(spec, runs_dir)
    if spec.run_id == FAIL:
        path = Path(runs_dir) / spec.run_id / "spec.json"
        path.write_text(json.dumps({**json.loads(path.read_text(encoding="utf-8")),
                                    "run_id": MISNAMED}), encoding="utf-8")
    return result
