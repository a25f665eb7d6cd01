"""Run functions for sweep tests; module level so worker processes can import them."""

from __future__ import annotations

import os

from fleet_sim.config.experiment import RunSpec
from fleet_sim.study.runner import RunResult, execute_run

CRASH = "fleet.size=2__r01"
FAIL = "fleet.size=3__r00"


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
