"""The commands of many runs and their results: `sweep`, `size`, `optimise`, `compare`, `report`,
`export`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TypedDict

from fleet_sim.cli.arguments import REPLICATIONS, RUNNER
from fleet_sim.cli.registry import arg, command, one_of
from fleet_sim.cli.shared import check_out_dir, check_out_file, experiment_for


@command("sweep", "run every run of an experiment (resumable)",
         arg("experiment", type=Path, help="experiment YAML file"), *RUNNER)
def _sweep(args: argparse.Namespace) -> int:
    from fleet_sim import api
    from fleet_sim.report.console import sweep_header, sweep_lines
    from fleet_sim.study.runner import default_out

    experiment = experiment_for(args.experiment, args.settings)
    out = args.out or default_out(experiment)
    print(sweep_header(experiment, len(experiment.runs()), args.workers, args.scheduler))
    result = api.sweep(experiment, out=out, **_runner(args))
    print(sweep_lines(experiment, result.outcome, out))
    return 1 if result.outcome.failed else 0


class Runner(TypedDict):
    """The runner's options of a study command, as the API takes them."""

    workers: int
    scheduler: str | None
    dask_timeout: float
    progress: bool


def _runner(args: argparse.Namespace) -> Runner:
    return Runner(workers=args.workers, scheduler=args.scheduler,
                  dask_timeout=args.dask_timeout, progress=not args.quiet)


@command("size", "smallest fleet that meets the experiment's targets",
         arg("experiment", type=Path, help="experiment YAML file"), *RUNNER)
def _size(args: argparse.Namespace) -> int:
    from fleet_sim import api
    from fleet_sim.report.console import size_header, size_lines
    from fleet_sim.study.runner import default_out

    experiment = experiment_for(args.experiment, args.settings)
    out = args.out or default_out(experiment)
    print(size_header(experiment))
    result = api.size(experiment, out=out, **_runner(args))
    print(size_lines(result.groups, out))
    return 0


@command("optimise", "cheapest design (fleet, chargers, policies, layout changes) that meets "
         "the experiment's targets, with a guarantee (resumable)",
         arg("experiment", type=Path, help="experiment YAML file with an optimise section"),
         *RUNNER)
def _optimise(args: argparse.Namespace) -> int:
    import time

    from fleet_sim import api
    from fleet_sim.config.decisions import design_space
    from fleet_sim.report.console import optimise_header, optimise_lines
    from fleet_sim.study.runner import default_out

    experiment = experiment_for(args.experiment, args.settings)
    space = design_space(experiment)  # refuses a file without an optimise section
    out = args.out or default_out(experiment)
    print(optimise_header(experiment, space))
    start = time.perf_counter()
    result = api.optimise(experiment, out=out, **_runner(args))
    print(optimise_lines(result.outcome, time.perf_counter() - start))
    return 1 if result.outcome.runs_failed else 0


@command("compare", "every variant against the baseline: paired differences with common random "
         "numbers, replications added until decided, the best variant selected (resumable)",
         arg("experiment", type=Path, help="experiment YAML file with variants"), *RUNNER,
         arg("--max-replications", type=REPLICATIONS, metavar="N",
             help="replication limit (default: the file's compare.max_replications)"))
def _compare(args: argparse.Namespace) -> int:
    import time

    from fleet_sim import api
    from fleet_sim.study.compare import check_compare, table_lines
    from fleet_sim.study.runner import default_out

    experiment = experiment_for(args.experiment, args.settings)
    check_compare(experiment, args.max_replications)
    out = args.out or default_out(experiment)
    print(f"compare {experiment.name}: {', '.join(experiment.variant_names[1:])} against "
          f"{experiment.baseline_name}, {max(1, len(experiment.points))} design point(s)")
    start = time.perf_counter()
    outcome = api.compare(experiment, out=out, max_replications=args.max_replications,
                          **_runner(args)).outcome
    print(f"  {outcome.runs_made} runs made, {outcome.runs_skipped} already finished, "
          f"{len(outcome.failed)} failed; {time.perf_counter() - start:.0f} s")
    print("\n".join(table_lines(outcome)))
    print(f"  comparison   {out / 'compare.json'}  (`fleet-sim report {out}` for the report)")
    return 1 if outcome.failed else 0


@command("report", "HTML and PDF report of a results folder (of sweep, size, compare, optimise)",
         arg("results", type=Path, help="results folder of `sweep`, `size`, `compare` or "
             "`optimise`"),
         arg("--no-pdf", action="store_true", help="write the HTML report only"))
def _report(args: argparse.Namespace) -> int:
    from fleet_sim.report.console import report_lines
    from fleet_sim.report.render import write_report

    print(report_lines(*write_report(args.results, pdf=not args.no_pdf)))
    return 0


@command(
    "export", "a run's or a sweep's tables as CSV files or a workbook",
    arg("source", type=Path, help="run directory, or sweep/sizing results folder"),
    one_of(arg("--csv", dest="format", action="store_const", const="csv",
               help="one CSV file per table, in SOURCE/export/"),
           arg("--xlsx", dest="format", action="store_const", const="xlsx",
               help="one Excel workbook, SOURCE/export.xlsx, a sheet per table"),
           required=True),
    arg("--out", type=Path, help="where instead: a folder for --csv, a .xlsx file for --xlsx"))
def _export(args: argparse.Namespace) -> int:
    from fleet_sim.report.console import export_lines
    from fleet_sim.report.export import export

    if args.out is not None:
        if args.format == "csv":
            check_out_dir(args.out, "--out")
        else:
            check_out_file(args.out, "--out")
    written = export(args.source, args.format, args.out,
                     note=lambda text: print(f"  {text}", file=sys.stderr, flush=True))
    print(export_lines(written))
    return 0
