"""The `fleet-sim` command.

Bad input (a layout, scenario, experiment, trace or profile file) ends in one line naming the
file, the element, the value and what was expected, and exit status 2; never a traceback.
`fleet-sim schema KIND` prints the JSON Schema of a file kind, for editors that check YAML as it
is typed.
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


def _agvs(text: str) -> int:
    return _integer(text, "number of AGVs", 1, MAX_FLEET_SIZE)


def _seed(text: str) -> int:
    return _integer(text, "seed", 0)


def _speed(text: str) -> float:
    return _number(text, "metres per second", 0, 100)


def _workers(text: str) -> int:
    return _integer(text, "number of workers (0: one per core)", 0, 1024)


def main(argv: Sequence[str] | None = None) -> int:
    parser = _Parser(prog="fleet-sim", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="run one scenario and write its run directory")
    run.add_argument("scenario", type=Path, help="scenario YAML file")
    run.add_argument("--agvs", type=_agvs, help="fleet size (overrides fleet.size)")
    run.add_argument("--hours", type=_hours, help="run length in hours (overrides duration_h)")
    run.add_argument("--seed", type=_seed, help="random seed (overrides seed)")
    run.add_argument("--out", type=Path, help="run directory (default: results/<scenario name>)")
    run.add_argument("--quiet", action="store_true", help="no progress display")

    lay = sub.add_parser("layout", help="check a layout file and draw it to PNG")
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
                       help="fleet sizes to compare (default: the scenario's)")
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

    rep = sub.add_parser("report", help="HTML and PDF report of a sweep or sizing results folder")
    rep.add_argument("results", type=Path, help="results folder of `sweep` or `size`")
    rep.add_argument("--no-pdf", action="store_true", help="write the HTML report only")

    schema = sub.add_parser("schema", help="print the JSON Schema of a file kind, for editors")
    schema.add_argument("kind", choices=SCHEMA_KINDS, help="which file")
    schema.add_argument("--out", type=Path, help="write it to this file instead")

    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            return _run(args)
        if args.command == "emulate":
            return _emulate(args)
        if args.command == "sweep":
            return _sweep(args)
        if args.command == "size":
            return _size(args)
        if args.command == "report":
            return _report(args)
        if args.command == "crosscheck":
            return _crosscheck(args)
        if args.command == "schema":
            return _schema(args)
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
        overrides["fleet.size"] = args.agvs
    if args.hours is not None:
        overrides["duration_h"] = args.hours
    if args.seed is not None:
        overrides["seed"] = args.seed
    scenario = _load_with_hours(load_scenario, args.scenario, overrides, args.hours)
    out = args.out or _fresh_dir(Path("results") / folder_name(scenario.name))
    _check_out_dir(out, "--out" if args.out else "results folder")
    layout = load_layout_for(scenario, str(args.scenario))
    _warn_unreachable_chargers(scenario, layout)
    trace = []
    if scenario.demand.kind == "trace":
        assert scenario.demand.trace_csv is not None
        trace = load_trace(scenario.path(scenario.demand.trace_csv), layout)
    with Progress(scenario.duration_s, quiet=args.quiet, plain_lines=4) as progress:
        def simulated(now_s: float, end_s: float) -> None:
            progress.update(now_s, f"simulated {now_s / 3600:.2f} of {end_s / 3600:.2f} h "
                                   f"({now_s / end_s:.0%})")

        run, figures = stream_run(scenario, layout, out, trace, progress=simulated)
    print(summary_text(figures))
    print(f"  run directory               {out}  ({run.wall_s:.1f} s wall, "
          f"{run.sim_events:,} events)")
    return 0


SCHEMA_KINDS = ("layout", "scenario", "experiment", "profile")


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


def _warn_unreachable_chargers(scenario: typing.Any, layout: typing.Any) -> None:
    """One warning line on stderr if charging is on and some AGVs cannot reach a charger."""
    from fleet_sim.config.scenario import agvs_without_charger

    stranded = agvs_without_charger(scenario, layout)
    if not stranded:
        return
    shown = ", ".join(str(a) for a in stranded[:20]) + (", ..." if len(stranded) > 20 else "")
    why = "the layout has no charger" if not layout.chargers else "no charger is reachable " \
        "from their start nodes"
    print(f"fleet-sim: warning: charging is on but {why}: AGV {shown} "
          f"({len(stranded)} of {scenario.fleet.size}) will run down and stop with E_201",
          file=sys.stderr)


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
    from fleet_sim.study.sweep import default_out, sweep
    from fleet_sim.study.targets import check_targets_known

    _check_workers(args)
    experiment = load_experiment(args.experiment)
    check_targets_known(experiment)
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
    from fleet_sim.study.sizing import size_fleet
    from fleet_sim.study.sweep import default_out
    from fleet_sim.study.targets import check_targets_known

    _check_workers(args)
    experiment = load_experiment(args.experiment)
    check_targets_known(experiment)
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
    for size in args.agvs or [scenario.fleet.size]:
        if size < 1:
            raise InputError("--agvs", "fleet.size", size, "an integer >= 1")
        overrides = {**base, "fleet.size": size}
        print(f"{scenario.name}: {size} AGVs, {scenario.duration_h:g} h "
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
