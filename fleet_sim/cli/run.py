"""The commands of one run: `run` (a scenario, its run directory) and `replay` (a run's offline
page).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fleet_sim.cli.arguments import AGVS, HOURS_ARG, QUIET, SEED_ARG, SETTINGS, WINDOW_HOURS
from fleet_sim.cli.registry import arg, command
from fleet_sim.cli.shared import check_out_dir, fresh_dir, warn_setup


@command(
    "run", "run one scenario and write its run directory",
    arg("scenario", type=Path, help="scenario YAML file"),
    arg("--agvs", type=AGVS, help="fleet size (overrides fleet.size); a mixed fleet: "
        "TYPE=N[,TYPE=N] (overrides those types' counts)"),
    HOURS_ARG,
    SEED_ARG,
    arg("--out", type=Path, help="run directory (default: results/<scenario name>)"),
    QUIET,
    arg("--replay", action="store_true",
        help="also record every AGV's motion (moves.parquet) and write replay.html"),
    SETTINGS)
def _run(args: argparse.Namespace) -> int:
    from fleet_sim.api import check_replay, simulate_into
    from fleet_sim.config.overrides import load_scenario
    from fleet_sim.config.scenario import folder_name, load_layout_for
    from fleet_sim.report.console import replay_line, run_lines

    scenario = load_scenario(args.scenario, args.settings, agvs=args.agvs, hours=args.hours,
                             seed=args.seed)
    check_replay(scenario, str(args.scenario), args.replay)
    layout = load_layout_for(scenario, str(args.scenario))  # bad input: no results folder
    out = args.out or fresh_dir(Path("results") / folder_name(scenario.name))
    check_out_dir(out, "--out" if args.out else "results folder")
    warn_setup(scenario, layout)
    run, figures = simulate_into(scenario, layout, out, replay=args.replay, quiet=args.quiet)
    print(run_lines(figures, out, run.wall_s, run.sim_events))
    if args.replay:  # moves.parquet was streamed with the other tables
        from fleet_sim.report.replay import write_replay

        del run
        if not args.quiet:
            print("  writing replay.html", file=sys.stderr, flush=True)
        print(replay_line(write_replay(out)))
    return 0


@command(
    "replay", "write RUN_DIR/replay.html: the floor, every AGV moving, its timeline and the "
    "order lead times, in one offline page",
    arg("run_dir", type=Path, help="run directory (of `fleet-sim run`, or a sweep's "
        "runs/<run>)"),
    arg("--from", dest="from_h", type=WINDOW_HOURS, metavar="H",
        help="start of the window, hours since the start of the run (default 0)"),
    arg("--to", dest="to_h", type=WINDOW_HOURS, metavar="H",
        help="end of the window, hours since the start (default: the end)"),
    QUIET)
def _replay(args: argparse.Namespace) -> int:
    from fleet_sim.analysis.replay import MOVES_FILE
    from fleet_sim.report.console import megabytes
    from fleet_sim.report.replay import check_window, write_replay
    from fleet_sim.study.progress import Progress

    run_dir: Path = args.run_dir
    check_window(run_dir, args.from_h, args.to_h)  # bad input fails before any work
    check_out_dir(run_dir, "run_dir", "run directory")
    again = not (run_dir / MOVES_FILE).is_file()
    with Progress(1.0, quiet=args.quiet, plain_lines=4) as progress:
        if again:
            progress.note(f"{run_dir} has no {MOVES_FILE}: simulating the run again from its "
                          "config.resolved.yaml (same seed, same run)")

        def simulated(now_s: float, end_s: float) -> None:
            progress.update(now_s / end_s, f"re-simulated {now_s / 3600:.2f} of "
                                           f"{end_s / 3600:.2f} h ({now_s / end_s:.0%})")

        page = write_replay(run_dir, args.from_h, args.to_h, progress=simulated,
                            writing=lambda: progress.note(f"writing {run_dir / 'replay.html'}"))
    print(f"replay: {page.resolve()}  ({megabytes(page)})")
    return 0
