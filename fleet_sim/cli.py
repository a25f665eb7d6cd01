"""The `fleet-sim` command.

Bad input (a layout, scenario, experiment, trace or profile file) ends in one line naming the
file, the element, the value and what was expected, and exit status 2; never a traceback.
`fleet-sim schema KIND` prints the JSON Schema of a file kind, for editors that check YAML as it
is typed.

`fleet-sim layout import|export` (VDMA LIF files) are parsed as commands of their own: `layout
FILE` keeps working as it always has, and a layout file actually named `import` or `export` is
still checked when written as a path (`./import`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import typing
from collections.abc import Sequence
from pathlib import Path

from fleet_sim.config.scenario import MAX_DURATION_H, MAX_FLEET_SIZE
from fleet_sim.errors import FleetSimError, InputError

MAX_WARNINGS = 4


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``fleet-sim: error: argument --hours: got 'nan'; expected
    ...`` and exit 2, without the usage block (``--help`` still shows it)."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, f"fleet-sim: error: {message}\n")


def _number(text: str, what: str, low: float, high: float, low_open: bool = True) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or not (value > low if low_open else value >= low) \
            or value > high:
        raise argparse.ArgumentTypeError(f"got {text!r}; expected a finite number of {what} "
                                         f"{'>' if low_open else '>='} {low:g} and <= {high:g}")
    return value


def _integer(text: str, what: str, low: int, high: int | None = None) -> int:
    try:
        value = int(text)
    except ValueError:
        value = low - 1
    if value < low or (high is not None and value > high):
        upper = f" and <= {high}" if high is not None else ""
        raise argparse.ArgumentTypeError(f"got {text!r}; expected an integer {what} >= {low}"
                                         f"{upper}")
    return value


def _hours(text: str) -> float:
    return _number(text, "hours", 0, MAX_DURATION_H)


def _agvs(text: str) -> int | dict[str, int]:
    """A fleet size (N), or a mixed fleet's counts of some of its types (TYPE=N[,TYPE=N])."""
    if "=" not in text:
        return _integer(text, "number of AGVs", 1, MAX_FLEET_SIZE)
    counts: dict[str, int] = {}
    for part in text.split(","):
        name, _, number = part.partition("=")
        name = name.strip()
        if not name or name in counts:
            raise argparse.ArgumentTypeError(
                f"got {text!r}; expected N, or TYPE=N[,TYPE=N] with each type once")
        counts[name] = _integer(number.strip(), f"number of {name} AGVs", 1, MAX_FLEET_SIZE)
    return counts


def _fleet_overrides(agvs: int | dict[str, int], scenario_file: Path) -> dict[str, object]:
    """The overrides of --agvs: fleet.size, or each named type's count of a mixed fleet. A
    plain number for a mixed fleet, or types for a one-type fleet, is refused by name."""
    from fleet_sim.config.scenario import load_scenario, type_count_path

    fleet = load_scenario(scenario_file).fleet
    if isinstance(agvs, int):
        if fleet.vehicles:
            types = [t.type for t in fleet.vehicles]
            raise InputError("--agvs", "fleet.vehicles", agvs, "TYPE=N for a mixed fleet (fleet."
                             f"vehicles: {', '.join(types)}), e.g. --agvs {types[-1]}=N; "
                             f"several: --agvs {types[0]}=N,{types[-1]}=M")
        return {"fleet.size": agvs}
    if not fleet.vehicles:
        raise InputError("--agvs", "fleet.size", ",".join(f"{t}={n}" for t, n in agvs.items()),
                         "a number of AGVs (the scenario's fleet has one vehicle type)")
    return {type_count_path(name): n for name, n in agvs.items()}


def _fleet_text(agvs: int | dict[str, int]) -> str:
    if isinstance(agvs, int):
        return f"{agvs} AGVs"
    return " + ".join(f"{n} {name}" for name, n in agvs.items())


def _seed(text: str) -> int:
    return _integer(text, "seed", 0)


def _speed(text: str) -> float:
    return _number(text, "metres per second", 0, 100)


def _window_hours(text: str) -> float:
    return _number(text, "hours", 0, MAX_DURATION_H, low_open=False)


def _workers(text: str) -> int:
    return _integer(text, "number of workers (0: one per core)", 0, 1024)


def _timestamp(text: str) -> str:
    """An ISO 8601 UTC time for a LIF export, or `now`."""
    from datetime import UTC, datetime

    from fleet_sim.config.layout import is_timestamp

    if text == "now":
        now = datetime.now(UTC)
        return now.strftime("%Y-%m-%dT%H:%M:%S.") + f"{now.microsecond // 10_000:02d}Z"
    if not is_timestamp(text):
        raise argparse.ArgumentTypeError(f"got {text!r}; expected an ISO 8601 date and time in "
                                         "UTC such as 2017-04-15T11:40:03.12Z, or now")
    return text


def _identifier(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError(f"got {text!r}; expected a non-empty id")
    return text


LAYOUT_COMMANDS = {"import": "layout-import", "export": "layout-export"}
"""`fleet-sim layout import|export ...` -> the internal command that parses it."""


def main(argv: Sequence[str] | None = None) -> int:
    parser = _Parser(prog="fleet-sim", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(
        dest="command", required=True,
        metavar="{run,layout,crosscheck,emulate,sweep,size,compare,report,schema,profile}")

    run = sub.add_parser("run", help="run one scenario and write its run directory")
    run.add_argument("scenario", type=Path, help="scenario YAML file")
    run.add_argument("--agvs", type=_agvs, help="fleet size (overrides fleet.size); a mixed "
                     "fleet: TYPE=N[,TYPE=N] (overrides those types' counts)")
    run.add_argument("--hours", type=_hours, help="run length in hours (overrides duration_h)")
    run.add_argument("--seed", type=_seed, help="random seed (overrides seed)")
    run.add_argument("--out", type=Path, help="run directory (default: results/<scenario name>)")
    run.add_argument("--quiet", action="store_true", help="no progress display")
    run.add_argument("--replay", action="store_true",
                     help="also record every AGV's motion (moves.parquet) and write replay.html")

    rpl = sub.add_parser("replay", help="write RUN_DIR/replay.html: the floor, every AGV moving, "
                         "its timeline and the order lead times, in one offline page")
    rpl.add_argument("run_dir", type=Path, help="run directory (of `fleet-sim run`, or a "
                     "sweep's runs/<run>)")
    rpl.add_argument("--from", dest="from_h", type=_window_hours, metavar="H",
                     help="start of the window, hours since the start of the run (default 0)")
    rpl.add_argument("--to", dest="to_h", type=_window_hours, metavar="H",
                     help="end of the window, hours since the start (default: the end)")
    rpl.add_argument("--quiet", action="store_true", help="no progress display")

    exp = sub.add_parser("export", help="a run's or a sweep's tables as CSV files or a workbook")
    exp.add_argument("source", type=Path, help="run directory, or sweep/sizing results folder")
    form = exp.add_mutually_exclusive_group(required=True)
    form.add_argument("--csv", dest="format", action="store_const", const="csv",
                      help="one CSV file per table, in SOURCE/export/")
    form.add_argument("--xlsx", dest="format", action="store_const", const="xlsx",
                      help="one Excel workbook, SOURCE/export.xlsx, a sheet per table")
    exp.add_argument("--out", type=Path,
                     help="where instead: a folder for --csv, a .xlsx file for --xlsx")

    lay = sub.add_parser("layout", help="check a layout file and draw it to PNG; `layout "
                         "import` / `layout export` read and write VDMA LIF files",
                         epilog="fleet-sim layout import FILE.lif.json --out NAME.yaml; "
                                "fleet-sim layout export NAME.yaml --lif FILE.json "
                                "(see their --help)")
    lay.add_argument("layout", type=Path, help="layout YAML file")
    lay.add_argument("--png", type=Path, help="where to draw it (default: results/<name>.png)")
    lay.add_argument("--max-speed", type=_speed, default=None,
                     help="vehicle top speed in m/s to check speed limits against")
    lay.add_argument("--sumo", type=Path, metavar="DIR",
                     help="also export it as a SUMO network (plain XML, net.xml, vType) to DIR")

    cross = sub.add_parser("crosscheck", help="run a scenario with the closed-form and the SUMO "
                           "motion backends and compare the KPIs (each run in its own process)")
    cross.add_argument("scenario", type=Path, help="scenario YAML file")
    cross.add_argument("--agvs", type=_agvs, nargs="+", metavar="N",
                       help="fleet sizes to compare (default: the scenario's); a mixed fleet: "
                            "TYPE=N[,TYPE=N] each")
    cross.add_argument("--hours", type=_hours, help="run length in hours (overrides duration_h)")
    cross.add_argument("--seed", type=_seed, help="random seed (overrides seed)")

    emu = sub.add_parser("emulate", help="serve a virtual vehicle on a pseudo-terminal")
    emu.add_argument("protocol", help="carriro, ktm02, tabo or agv3")
    emu.add_argument("--profile", help="vehicle profile (default: the one for the protocol)")
    emu.add_argument("--seed", type=_seed, help="seed of the link jitter")
    swp = sub.add_parser("sweep", help="run every run of an experiment (resumable)")
    swp.add_argument("experiment", type=Path, help="experiment YAML file")
    _runner_options(swp)

    size = sub.add_parser("size", help="smallest fleet that meets the experiment's targets")
    size.add_argument("experiment", type=Path, help="experiment YAML file")
    _runner_options(size)

    _add_compare(sub)

    rep = sub.add_parser("report", help="HTML and PDF report of a sweep, sizing or compare "
                         "results folder")
    rep.add_argument("results", type=Path, help="results folder of `sweep`, `size` or `compare`")
    rep.add_argument("--no-pdf", action="store_true", help="write the HTML report only")

    schema = sub.add_parser("schema", help="print the JSON Schema of a file kind, for editors")
    schema.add_argument("kind", choices=SCHEMA_KINDS, help="which file")
    schema.add_argument("--out", type=Path, help="write it to this file instead")

    # `layout import` and `layout export`: no help= keeps them out of the command list
    imp = sub.add_parser("layout-import", prog="fleet-sim layout import",
                         description="Read a VDMA LIF 1.0.0 file and write a fleet_sim layout; "
                                     "what the layout cannot hold is listed.")
    imp.add_argument("lif", type=Path, metavar="FILE.lif.json", help="LIF file")
    imp.add_argument("--out", type=Path, required=True, help="layout YAML file to write")
    imp.add_argument("--layout-id", type=_identifier, metavar="ID",
                     help="which layout of the file (needed if it has several)")
    imp.add_argument("--vehicle-type", type=_identifier, metavar="ID",
                     help="which vehicleTypeId's nodes, edges and speeds (needed if the "
                          "layout is for several)")
    imp.add_argument("--all-types", action="store_true",
                     help="import every vehicle type: segments and stations open to some "
                          "types only get allowed_types (--vehicle-type: the type whose "
                          "speeds and lengths are kept)")
    exp = sub.add_parser("layout-export", prog="fleet-sim layout export",
                         description="Write a fleet_sim layout as a VDMA LIF 1.0.0 file.")
    exp.add_argument("layout", type=Path, metavar="NAME.yaml", help="layout YAML file")
    exp.add_argument("--lif", type=Path, required=True, metavar="FILE.json",
                     help="LIF file to write")
    exp.add_argument("--timestamp", type=_timestamp, metavar="ISO|now",
                     help="exportTimestamp (default: the layout's lif.export_timestamp, else "
                          "1970-01-01T00:00:00.00Z, so the same layout gives the same file)")
    exp.add_argument("--vehicle-type", type=_identifier, metavar="ID",
                     help="vehicleTypeId to write (default: the layout's lif.vehicle_type_id, "
                          "else fleet-sim)")
    exp.add_argument("--max-speed", type=_speed, default=None,
                     help="vehicle top speed in m/s to check speed limits against")

    prof = sub.add_parser("profile", help="vehicle profiles: `profile import` makes one of a "
                          "VDA 5050 factsheet")
    prof_sub = prof.add_subparsers(dest="profile_command", required=True, metavar="{import}")
    fact = prof_sub.add_parser("import", help="make a vehicle profile of a VDA 5050 2.1.0 "
                               "factsheet", description="Make a vehicle profile of a VDA 5050 "
                               "2.1.0 factsheet: speeds, accelerations and length from the "
                               "factsheet, the rest from a base profile; what is not used is "
                               "listed.")
    fact.add_argument("factsheet", type=Path, metavar="FACTSHEET.json", help="factsheet file")
    fact.add_argument("--out", type=Path, required=True, help="profile YAML file to write")
    fact.add_argument("--base", default="rss-agv-001", metavar="PROFILE",
                      help="bundled profile name or profile file giving the figures a "
                           "factsheet lacks: turn speed, battery, link (default: rss-agv-001)")

    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) >= 2 and argv[0] == "layout" and argv[1] in LAYOUT_COMMANDS:
        argv = [LAYOUT_COMMANDS[argv[1]], *argv[2:]]
    elif argv and argv[0] in LAYOUT_COMMANDS.values():
        parser.error(f"argument command: invalid choice: {argv[0]!r} (use: layout "
                     f"{argv[0].removeprefix('layout-')})")
    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            return _run(args)
        if args.command == "replay":
            return _replay(args)
        if args.command == "export":
            return _export(args)
        if args.command == "emulate":
            return _emulate(args)
        if args.command == "sweep":
            return _sweep(args)
        if args.command == "size":
            return _size(args)
        if args.command == "compare":
            return _compare(args)
        if args.command == "report":
            return _report(args)
        if args.command == "crosscheck":
            return _crosscheck(args)
        if args.command == "schema":
            return _schema(args)
        if args.command == "layout-import":
            return _layout_import(args)
        if args.command == "layout-export":
            return _layout_export(args)
        if args.command == "profile":
            return _profile_import(args)
        return _layout(args)
    except (FleetSimError, InputError) as exc:
        print(f"fleet-sim: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fleet-sim: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and the like
        sys.stderr.close()
        return 0


def _run(args: argparse.Namespace) -> int:
    from fleet_sim.analysis.kpis import summary_text
    from fleet_sim.analysis.tables import stream_run
    from fleet_sim.config.scenario import folder_name, load_layout_for, load_scenario
    from fleet_sim.config.trace import load_trace
    from fleet_sim.study.progress import Progress

    overrides: dict[str, object] = {}
    if args.agvs is not None:
        overrides |= _fleet_overrides(args.agvs, args.scenario)
    if args.hours is not None:
        overrides["duration_h"] = args.hours
    if args.seed is not None:
        overrides["seed"] = args.seed
    scenario = _load_with_hours(load_scenario, args.scenario, overrides, args.hours)
    if args.replay and scenario.motion != "closed_form":
        raise InputError(str(args.scenario), "motion", scenario.motion,
                         "closed_form with --replay: a replay draws the closed-form speed "
                         "profile; with SUMO moving the AGVs their positions between nodes are "
                         "not recorded")
    out = args.out or _fresh_dir(Path("results") / folder_name(scenario.name))
    _check_out_dir(out, "--out" if args.out else "results folder")
    layout = load_layout_for(scenario, str(args.scenario))
    _warn_setup(scenario, layout)
    trace = []
    if scenario.demand.kind == "trace":
        assert scenario.demand.trace_csv is not None
        trace = load_trace(scenario.path(scenario.demand.trace_csv), layout)
    with Progress(scenario.duration_s, quiet=args.quiet, plain_lines=4) as progress:
        def simulated(now_s: float, end_s: float) -> None:
            progress.update(now_s, f"simulated {now_s / 3600:.2f} of {end_s / 3600:.2f} h "
                                   f"({now_s / end_s:.0%})")

        run, figures = stream_run(scenario, layout, out, trace, progress=simulated,
                                  record_moves=args.replay)
    print(summary_text(figures))
    print(f"  run directory               {out}  ({run.wall_s:.1f} s wall, "
          f"{run.sim_events:,} events)")
    if args.replay:  # moves.parquet was streamed with the other tables
        from fleet_sim.report.replay import write_replay

        del run
        if not args.quiet:
            print("  writing replay.html", file=sys.stderr, flush=True)
        page = write_replay(out)
        print(f"  replay                      {page}  ({_megabytes(page)})")
    return 0


def _megabytes(path: Path) -> str:
    return f"{path.stat().st_size / 1e6:.1f} MB"


def _replay(args: argparse.Namespace) -> int:
    from fleet_sim.analysis.replay import MOVES_FILE
    from fleet_sim.report.replay import check_window, write_replay
    from fleet_sim.study.progress import Progress

    run_dir: Path = args.run_dir
    check_window(run_dir, args.from_h, args.to_h)  # bad input fails before any work
    _check_out_dir(run_dir, "run_dir", "run directory")
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
    print(f"replay: {page.resolve()}  ({_megabytes(page)})")
    return 0


def _export(args: argparse.Namespace) -> int:
    from fleet_sim.report.export import export

    if args.out is not None:
        if args.format == "csv":
            _check_out_dir(args.out, "--out")
        else:
            _check_out_file(args.out, "--out")
    written = export(args.source, args.format, args.out,
                     note=lambda text: print(f"  {text}", file=sys.stderr, flush=True))
    for item in written:
        print(f"{item.table:8s} {item.rows:>10,} rows  {item.path}")
    return 0


SCHEMA_KINDS = ("layout", "scenario", "experiment", "profile", "lif", "factsheet")


def _schema(args: argparse.Namespace) -> int:
    from fleet_sim.config.schemas import json_schema

    text = json.dumps(json_schema(args.kind), indent=2, ensure_ascii=False) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    try:
        args.out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError("--out", "out", str(args.out), f"a writable file ({exc.strerror})") \
            from None
    print(f"{args.kind} schema: {args.out}")
    return 0


def _load_with_hours(load: typing.Callable[..., typing.Any], file: Path,
                     overrides: dict[str, object], hours: float | None) -> typing.Any:
    """The scenario with the overrides; a warm-up the --hours run cannot hold names --hours."""
    try:
        return load(file, overrides)
    except InputError as exc:
        if hours is not None and exc.element == "warmup_h":
            raise InputError("--hours", "duration_h", hours,
                             f"a run longer than the scenario's warm-up ({exc.value} h in "
                             f"{file})") from None
        raise


def _check_out_dir(out: Path, argument: str, element: str = "out") -> None:
    """Refuse, before any work, a run or results directory that cannot be written: an existing
    file in its place, or a place where it cannot be made or written (tried: the directory is
    made and a probe file written and removed)."""
    if out.exists() and not out.is_dir():
        raise InputError(argument, element, str(out), "a directory (or a new path), not a file")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise InputError(argument, element, str(out),
                         f"a writable directory ({exc.strerror or exc})") from None


def _check_out_file(out: Path, argument: str) -> None:
    """Refuse, before any work, an output file path that is a directory or cannot be written."""
    if out.is_dir():
        raise InputError(argument, argument.lstrip("-"), str(out),
                         "a file path (it is an existing directory)")
    _check_out_dir(out.parent, argument, f"{argument.lstrip('-')} folder")


def _warn_setup(scenario: typing.Any, layout: typing.Any) -> None:
    """One warning line on stderr per battery or charging trap of the scenario (AGVs that
    cannot reach a charger, a draining battery with charging off): the run goes on."""
    from fleet_sim.config.scenario import setup_warnings

    for warning in setup_warnings(scenario, layout):
        print(f"fleet-sim: warning: {warning.text}", file=sys.stderr)


def _warn_experiment(experiment: typing.Any) -> None:
    """The setup warnings of an experiment's design points, each kind once."""
    from fleet_sim.config.experiment import experiment_warnings

    for text in experiment_warnings(experiment):
        print(f"fleet-sim: warning: {text}", file=sys.stderr)


def _fresh_dir(base: Path) -> Path:
    """`base`, or `base-2`, `base-3`... so that a default run never overwrites an earlier one."""
    if not base.exists():
        return base
    n = 2
    while Path(f"{base}-{n}").exists():
        n += 1
    return Path(f"{base}-{n}")


def _runner_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--workers", type=_workers, default=0,
                        help="worker processes (default: one per core)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run on the Dask cluster at ADDRESS (tcp://host:8786), or 'local' "
                             "for a local Dask cluster of --workers processes")
    parser.add_argument("--out", type=Path,
                        help="results folder (default: results/<experiment name>)")
    parser.add_argument("--quiet", action="store_true", help="no progress display")


def _check_workers(args: argparse.Namespace) -> None:
    if args.workers < 0:
        raise InputError("--workers", "workers", args.workers, "an integer >= 0 (0: one per core)")


def _sweep(args: argparse.Namespace) -> int:
    from fleet_sim.analysis.stats import check_targets
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.runner import default_out
    from fleet_sim.study.sweep import sweep
    from fleet_sim.study.targets import check_targets_known

    _check_workers(args)
    experiment = load_experiment(args.experiment)
    check_targets_known(experiment)
    _warn_experiment(experiment)
    out = args.out or default_out(experiment)
    runs = experiment.runs()
    where = f"Dask cluster {args.scheduler}" if args.scheduler else \
        f"{args.workers or 'one per core'} worker processes"
    print(f"sweep {experiment.name}: {len(experiment.points)} design points x "
          f"{experiment.spec.replications} replications = {len(runs)} runs on {where}")
    outcome = sweep(experiment, out, args.workers, args.scheduler, args.quiet)
    import pandas as pd

    summary = pd.read_parquet(out / "summary.parquet")
    done = int((summary["status"] == "ok").sum()) if len(summary) else 0
    print(f"  {len(outcome.results)} runs made, {outcome.skipped} already finished; "
          f"{done} finished in all, {len(outcome.failed)} failed in this sweep")
    for failure in outcome.failed:
        print(f"  failed: {failure.run_id} ({failure.status}): {failure.error}")
    warnings = [w for w in (c.warning() for c in check_targets(
        summary, experiment.factor_names, experiment.spec.targets)) if w]
    for warning in warnings[:MAX_WARNINGS]:
        print(f"  warning: {warning}")
    if len(warnings) > MAX_WARNINGS:
        print(f"  ... and {len(warnings) - MAX_WARNINGS} more intervals too wide to decide "
              "(all in the report); `fleet-sim size` adds replications where it matters")
    print(f"  summary      {out / 'summary.parquet'}  (one row per run)")
    print(f"  statistics   {out / 'stats.parquet'}  (mean and 95 % CI per design point)")
    print(f"  SQL          {out / 'sweep.duckdb'}  (tables summary, stats; views orders, "
          "events, node_waits)")
    return 1 if outcome.failed else 0


def _size(args: argparse.Namespace) -> int:
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.runner import default_out
    from fleet_sim.study.sizing import size_fleet
    from fleet_sim.study.targets import check_targets_known

    _check_workers(args)
    experiment = load_experiment(args.experiment)
    check_targets_known(experiment)
    _warn_experiment(experiment)
    out = args.out or default_out(experiment)
    print(f"size {experiment.name}: targets "
          + ", ".join(t.describe() for t in experiment.spec.targets))
    results = size_fleet(experiment, out, args.workers, args.scheduler, args.quiet)
    for result in results:
        est = result.estimate
        print(f"  analytic estimate: {est.agvs:.2f} AGVs at the mean demand, "
              f"{est.agvs_at_peak:.2f} at the peak ({est.cycle_s:.1f} s per order: "
              f"{est.empty_travel_s:.1f} s empty + {est.loaded_travel_s:.1f} s loaded travel + "
              f"{est.handling_s:.1f} s handling; {est.demand_per_hour:.1f} orders/h)")
        print(f"  simulation: {result.statement()}")
    print(f"  sizing       {out / 'sizing.json'}")
    return 0


def _add_compare(sub: typing.Any) -> None:
    cmp = sub.add_parser("compare", help="every variant against the baseline: paired "
                         "differences with common random numbers, replications added until "
                         "decided, the best variant selected (resumable)")
    cmp.add_argument("experiment", type=Path, help="experiment YAML file with variants")
    _runner_options(cmp)
    cmp.add_argument("--max-replications", type=lambda t: _integer(t, "number of replications", 2),
                     metavar="N", help="replication limit (default: the file's "
                                       "compare.max_replications)")


def _compare(args: argparse.Namespace) -> int:
    import time

    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.compare import check_compare, compare, table_lines
    from fleet_sim.study.runner import default_out

    _check_workers(args)
    experiment = load_experiment(args.experiment)
    check_compare(experiment, args.max_replications)
    _warn_experiment(experiment)
    out = args.out or default_out(experiment)
    print(f"compare {experiment.name}: {', '.join(experiment.variant_names[1:])} against "
          f"{experiment.baseline_name}, {max(1, len(experiment.points))} design point(s)")
    start = time.perf_counter()
    outcome = compare(experiment, out, args.workers, args.scheduler, args.quiet,
                      args.max_replications)
    print(f"  {outcome.runs_made} runs made, {outcome.runs_skipped} already finished, "
          f"{len(outcome.failed)} failed; {time.perf_counter() - start:.0f} s")
    for line in table_lines(outcome):
        print(line)
    print(f"  comparison   {out / 'compare.json'}  (`fleet-sim report {out}` for the report)")
    return 1 if outcome.failed else 0


def _report(args: argparse.Namespace) -> int:
    from fleet_sim.report.render import write_report

    html, pdf = write_report(args.results, pdf=not args.no_pdf)
    print(f"report: {html.resolve()}")
    if pdf is not None:
        print(f"        {pdf.resolve()}")
    return 0


def _layout(args: argparse.Namespace) -> int:
    from fleet_sim.config.layout import load_layout
    from fleet_sim.report.layout_plot import draw_layout

    if args.png is not None:
        _check_out_file(args.png, "--png")
    layout = load_layout(args.layout, max_speed_mps=args.max_speed)
    kinds: dict[str, int] = {}
    for _, data in layout.graph.nodes(data=True):
        kinds[data["kind"]] = kinds.get(data["kind"], 0) + 1
    print(f"{args.layout}: layout {layout.name!r} is valid")
    print(f"  nodes        {layout.graph.number_of_nodes()} "
          f"({', '.join(f'{n} {k}' for k, n in sorted(kinds.items()))})")
    print(f"  segments     {layout.graph.number_of_edges()} directed, "
          f"{layout.total_length_m:.0f} m of track, {len(layout.corridors)} two-way corridors")
    print(f"  stations     {len(layout.pickups)} pickup, {len(layout.dropoffs)} drop-off")
    print(f"  chargers     {len(layout.chargers)}")
    print(f"  parking      {len(layout.parking)} areas, "
          f"{sum(p.capacity for p in layout.parking)} AGVs")
    png = args.png or Path("results") / f"{layout.name}.png"
    _check_out_file(png, "--png" if args.png else "results folder")
    draw_layout(layout, png)
    print(f"  drawing      {png}")
    if args.sumo is not None:
        from fleet_sim.sim.motion.sumo_network import export

        network = export(layout, args.sumo)
        print(f"  SUMO network {network.net_file} (+ plain .nod/.edg/.con.xml, "
              f"{network.vtype_file.name})")
    return 0


def _layout_import(args: argparse.Namespace) -> int:
    """LIF -> layout file. The layout is written even if it does not check as a graph yet (a
    LIF without parking, say): the planner completes it; the problem is named, exit status 1."""
    from fleet_sim.config.layout import layout_from_spec, layout_yaml
    from fleet_sim.config.layout_lif import import_lif

    _check_out_file(args.out, "--out")
    imported = import_lif(args.lif, args.layout_id, args.vehicle_type, args.all_types)
    _write(args.out, layout_yaml(imported.spec, imported.comments()), "--out")
    spec = imported.spec
    print(f"{args.lif}: LIF {imported.lif_version} layout {imported.layout_id!r}, vehicle type "
          f"{imported.vehicle_type!r} -> {args.out}")
    print(f"  nodes        {len(spec.nodes)}")
    print(f"  segments     {len(spec.segments)} "
          f"({sum(s.direction == 'two_way' for s in spec.segments)} two-way)")
    print(f"  places       {len(spec.stations)} stations, {len(spec.chargers)} chargers, "
          f"{len(spec.parking)} parking")
    for note in imported.notes:
        print(f"  {'read as ' if note.kept else 'not kept'}     {note.line()}")
    try:
        layout_from_spec(spec, str(args.out))
    except InputError as exc:
        print(f"fleet-sim: warning: {exc} (written; complete the layout and check it with "
              "`fleet-sim layout`)", file=sys.stderr)
        return 1
    return 0


def _layout_export(args: argparse.Namespace) -> int:
    from fleet_sim.config.layout import load_layout
    from fleet_sim.config.layout_lif import layout_to_lif, lif_json

    _check_out_file(args.lif, "--lif")
    layout = load_layout(args.layout, max_speed_mps=args.max_speed)
    data = layout_to_lif(layout.spec, args.timestamp, args.vehicle_type)
    _write(args.lif, lif_json(data), "--lif")
    lif_layout = data["layouts"][0]
    print(f"{args.layout}: layout {layout.name!r} -> {args.lif} (LIF "
          f"{data['metaInformation']['lifVersion']})")
    print(f"  nodes        {len(lif_layout['nodes'])}")
    print(f"  edges        {len(lif_layout['edges'])} (a two-way segment is two edges)")
    print(f"  stations     {len(lif_layout['stations'])} (pickup, drop-off, chargers, parking)")
    print(f"  exported at  {data['metaInformation']['exportTimestamp']}"
          + ("" if args.timestamp else " (--timestamp now for the current time)"))
    print("  fleetSim     handling times, charger power, parking capacity, markers, Wi-Fi, "
          "zones and explicit lengths are in the extension key fleetSim")
    return 0


def _profile_import(args: argparse.Namespace) -> int:
    from fleet_sim.config.profile_factsheet import import_factsheet

    _check_out_file(args.out, "--out")
    imported = import_factsheet(args.factsheet, args.base)
    _write(args.out, imported.text(), "--out")
    print(f"{args.factsheet}: {imported.title} -> {args.out} (profile "
          f"{args.out.stem!r})")
    print("  from the factsheet   top speed, acceleration, deceleration, length")
    print(f"  from {imported.base:<15} turn speed, battery, link (assumed for this vehicle)")
    for line in imported.not_used:
        print(f"  not used             {line}")
    return 0


def _write(path: Path, text: str, argument: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(argument, argument.lstrip("-"), str(path),
                         f"a writable file ({exc.strerror})") from None


def _crosscheck(args: argparse.Namespace) -> int:
    """One table per fleet size: KPIs and wall time of each backend, and SUMO's difference."""
    from fleet_sim.config.scenario import load_layout_for, load_scenario
    from fleet_sim.study.crosscheck import crosscheck, table

    base: dict[str, object] = {}
    if args.hours is not None:
        base["duration_h"] = args.hours
    if args.seed is not None:
        base["seed"] = args.seed
    # bad input fails here, before any run
    scenario = _load_with_hours(load_scenario, args.scenario, base, args.hours)
    load_layout_for(scenario, str(args.scenario))
    for size in args.agvs or [None]:
        overrides = base if size is None else {**base, **_fleet_overrides(size, args.scenario)}
        fleet = scenario.fleet
        text = _fleet_text(size) if size is not None else _fleet_text(
            {t.type: t.count for t in fleet.vehicles} if fleet.vehicles else fleet.size)
        print(f"{scenario.name}: {text}, {scenario.duration_h:g} h "
              f"(warm-up {scenario.warmup_h:g} h), seed {scenario.seed}", flush=True)
        print(table(crosscheck(args.scenario, overrides)), flush=True)
        print()
    return 0


def _emulate(args: argparse.Namespace) -> int:
    """Print the pty path first, answer until Ctrl-C or SIGTERM, exit 0."""
    from agv_model.emulate import EmulateError, choose_profile, serve

    try:
        return serve(choose_profile(args.protocol, args.profile), seed=args.seed)
    except EmulateError as exc:
        raise FleetSimError(str(exc)) from None


if __name__ == "__main__":
    sys.exit(main())
