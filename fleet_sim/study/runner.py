"""Executing a study's runs: the runs of the study not yet finished (a finished one is
skipped, a damaged one made again), on a pool of workers (fleet_sim.study.pools), with their
progress and a check that each left its record. Sweep, size and compare decide which runs to
make; this module makes them and never decides.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import yaml

from fleet_sim.config.experiment import FLEET, Experiment, RunSpec
from fleet_sim.config.scenario import VEHICLE_TYPES
from fleet_sim.errors import require_extra
from fleet_sim.sim.sumo import require_backend
from fleet_sim.study.pools import DEFAULT_NO_WORKERS_TIMEOUT_S, DaskPool, LocalPool, run_local
from fleet_sim.study.progress import Progress
from fleet_sim.study.run_folder import MANIFEST, OK, RunResult, run_problem
from fleet_sim.study.study_folder import SweepError
from fleet_sim.study.worker import RunFn, execute_run
from userfiles.writing import copy_atomic, write_text_atomic

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
