"""Sweeps: every run of an experiment's design (each design point times each replication),
in worker processes or on a Dask cluster (fleet_sim.study.runner), resumable, then the summary
tables (fleet_sim.study.results).

Results folder (``results/<experiment>`` by default)::

    experiment.yaml            the experiment file as given; experiment.resolved.yaml, resolved
    runs/<run id>/             one folder per run (fleet_sim.study.runner)
    pilot/, warmup.json        the warm-up's pilot runs and estimate (fleet_sim.study.warmup)
    summary.parquet, stats.parquet, sweep.duckdb     (fleet_sim.study.results)
"""

from __future__ import annotations

from pathlib import Path
from typing import IO

from fleet_sim.config.experiment import Experiment
from fleet_sim.study.pools import DEFAULT_NO_WORKERS_TIMEOUT_S, make_pool
from fleet_sim.study.progress import Progress
from fleet_sim.study.results import tables_written
from fleet_sim.study.runner import SweepOutcome, check_extras, execute, prepare
from fleet_sim.study.study_folder import folder_lock, write_plan
from fleet_sim.study.warmup import largest_fleet, pilot_groups, settle_warmup
from fleet_sim.study.worker import RunFn, execute_run


def sweep(experiment: Experiment, out_dir: Path, workers: int = 0, scheduler: str | None = None,
          quiet: bool = False, run_fn: RunFn = execute_run,
          stream: IO[str] | None = None,
          dask_timeout_s: float = DEFAULT_NO_WORKERS_TIMEOUT_S) -> SweepOutcome:
    """Run the experiment's design into `out_dir` and write its summary, statistics and DB."""
    check_extras(experiment, scheduler)
    with folder_lock(out_dir, stream), \
            tables_written(experiment, out_dir, stream=stream, quiet=quiet) as plan:
        if experiment.spec.warmup.method != "fixed":
            with make_pool(scheduler, workers, run_fn, dask_timeout_s) as pilot_pool, \
                    Progress(stream=stream, quiet=quiet) as progress:
                experiment = settle_warmup(experiment, out_dir, pilot_groups(experiment),
                                           largest_fleet(experiment), pilot_pool, progress)
        prepare(experiment, out_dir)
        write_plan(out_dir, "sweep", [spec.run_id for spec in experiment.runs()])
        plan.add(spec.run_id for spec in experiment.runs())
        outcome = execute(experiment.runs(), out_dir, workers, scheduler, quiet, run_fn, stream,
                          dask_timeout_s=dask_timeout_s)
    return outcome


