"""The `fleet-sim` command: one registration per command, no logic.

Each command is one function decorated with `@command(name, help, *arguments)`: its name, the
line `fleet-sim --help` shows, and its arguments declared as data (`arg(...)`, `one_of(...)`).
The parser, the command list in `--help` and its usage line are generated from these
registrations (`build_parser`), so a new command is one decorated function and nothing else. A
command of a group is registered as "GROUP NAME" (`layout import`), after `group(...)`.

Ranges and choices are declared where the argument is: `Number("hours", 0, MAX_DURATION_H)`,
`Integer("seed", 0)`, `choices=...`; the one-line refusal (``argument --hours: got 'nan';
expected a finite number of hours > 0 and <= 8760``) is written once, in those types.

What the commands print when they finish is worded in fleet_sim.report.console.

Decisions, where the issues are silent:

* argparse, not click: argparse's messages (``argument --hours: ...``, ``the following
  arguments are required: ...``) are the ones users, the README and the tests know, and the
  declarative part click would bring is the small registry below.
* A group may name a default command: `fleet-sim layout FILE` is `fleet-sim layout check FILE`
  (the older form, kept). A first word that is not one of the group's commands is the default
  command's first argument, so a layout file named `import` is checked when written as a path
  (`./import`).
* Bad input (a layout, scenario, experiment, trace or profile file, or an argument) ends in one
  line naming the file or the argument, the element, the value and what was expected, and exit
  status 2; never a traceback. `fleet-sim schema KIND` prints the JSON Schema of a file kind.
* `--set KEY=VALUE` (run, sweep, size; repeated) sets any dotted scenario field, the value read
  as YAML (`--set demand.rate_per_hour=60`, `--set 'charging.enabled=false'`), checked like the
  file: a problem the file has alone names the file, one the settings bring names `--set` and
  the field. Paths set this way are relative to the scenario file, as in the file. The flags
  `--agvs`, `--hours` and `--seed` are applied after the settings.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import tempfile
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fleet_sim.config.scenario import MAX_DURATION_H, MAX_FLEET_SIZE
from fleet_sim.errors import FleetSimError, InputError

if typing.TYPE_CHECKING:
    from fleet_sim.config.experiment import Experiment
    from fleet_sim.config.scenario import Scenario

Handler = Callable[[argparse.Namespace], int]


# --- the registry ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Arg:
    """One argument as argparse's `add_argument` takes it."""

    flags: tuple[str, ...]
    options: dict[str, typing.Any]


def arg(*flags: str, **options: typing.Any) -> Arg:
    return Arg(flags, options)


@dataclass(frozen=True)
class OneOf:
    """Arguments of which at most one (exactly one if `required`) may be given."""

    args: tuple[Arg, ...]
    required: bool = False


def one_of(*args: Arg, required: bool = False) -> OneOf:
    return OneOf(args, required)


@dataclass(frozen=True)
class Command:
    name: str
    """The words that call it: `run`, or `layout import` for a command of a group."""
    help: str
    arguments: tuple[Arg | OneOf, ...]
    handle: Handler
    description: str | None = None
    epilog: str | None = None


@dataclass
class Group:
    """Commands under one word (`layout check|import|export`); `default` runs when the next
    word is none of them."""

    name: str
    help: str
    default: str | None = None
    commands: list[str] = field(default_factory=list)


DESCRIPTION = ("Discrete-event AGV fleet simulator: how many AGVs a layout needs, and why. "
               "`fleet-sim COMMAND --help` for a command's arguments.")

REGISTRY: dict[str, Command | Group] = {}
"""Every command and group by its name, in the order `--help` lists them."""


def command(name: str, help: str, *arguments: Arg | OneOf, description: str | None = None,
            epilog: str | None = None) -> Callable[[Handler], Handler]:
    """Register the decorated function as the command `name` (one registration per command)."""

    def register(handle: Handler) -> Handler:
        words = name.split()
        if len(words) == 2:
            parent = REGISTRY[words[0]]
            assert isinstance(parent, Group), f"{words[0]} is not a group"
            parent.commands.append(words[1])
        REGISTRY[name] = Command(name, help, arguments, handle, description, epilog)
        return handle

    return register


def group(name: str, help: str, default: str | None = None) -> None:
    REGISTRY[name] = Group(name, help, default)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``fleet-sim: error: argument --hours: got 'nan'; expected
    ...`` and exit 2, without the usage block (``--help`` still shows it)."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, f"fleet-sim: error: {message}\n")


def _add(parser: argparse.ArgumentParser, item: Arg | OneOf) -> None:
    if isinstance(item, OneOf):
        exclusive = parser.add_mutually_exclusive_group(required=item.required)
        for member in item.args:
            exclusive.add_argument(*member.flags, **member.options)
    else:
        parser.add_argument(*item.flags, **item.options)


def build_parser() -> argparse.ArgumentParser:
    """The whole command line, from the registrations."""
    parser = _Parser(prog="fleet-sim", description=DESCRIPTION)
    top = parser.add_subparsers(required=True)
    groups: dict[str, typing.Any] = {}
    for name, entry in REGISTRY.items():
        words = name.split()
        subparsers = groups[words[0]] if len(words) == 2 else top
        if isinstance(entry, Group):
            grp = subparsers.add_parser(entry.name, help=entry.help, description=entry.help)
            groups[entry.name] = grp.add_subparsers(required=True)
            continue
        sub = subparsers.add_parser(words[-1], help=entry.help,
                                    description=entry.description or entry.help,
                                    epilog=entry.epilog)
        for item in entry.arguments:
            _add(sub, item)
        sub.set_defaults(handle=entry.handle)
    return parser


def _with_default_commands(argv: list[str]) -> list[str]:
    """`layout FILE ...` -> `layout check FILE ...`: a group's default command when the word
    after the group is none of its commands (nor a request for help)."""
    if not argv:
        return argv
    entry = REGISTRY.get(argv[0])
    if isinstance(entry, Group) and entry.default is not None and (
            len(argv) == 1 or argv[1] not in (*entry.commands, "-h", "--help")):
        return [argv[0], entry.default, *argv[1:]]
    return argv


def main(argv: Sequence[str] | None = None) -> int:
    argv = _with_default_commands(list(sys.argv[1:] if argv is None else argv))
    args = build_parser().parse_args(argv)
    try:
        handle: Handler = args.handle
        return handle(args)
    except (FleetSimError, InputError) as exc:
        print(f"fleet-sim: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fleet-sim: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError as exc:
        if stdout_closed():  # output piped into `head` and the like: nothing more to say
            sys.stderr.close()
            return 0
        print(f"fleet-sim: error: {fault_text(exc)}", file=sys.stderr)
        return 1
    except OSError as exc:  # a full disk, a read-only folder, a worker pool that cannot start
        print(f"fleet-sim: error: {fault_text(exc)}", file=sys.stderr)
        return 1


def stdout_closed() -> bool:
    """Has the reader of standard output gone away (a pipe into `head`)? Asked of the pipe
    itself (poll reports an error on a pipe with no reader), so a broken pipe to a worker
    process is never mistaken for it."""
    import select

    try:
        fd = sys.stdout.fileno()
    except (OSError, ValueError):
        return True
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & (select.POLLERR | select.POLLHUP) for _, events in poller.poll(0))


def fault_text(exc: OSError) -> str:
    """One line for an error of the machine (not of the input): the path or resource, the
    cause and its errno name, and that finished work is kept."""
    import errno

    where = exc.filename if exc.filename is not None else "fleet-sim"
    cause = exc.strerror or str(exc) or type(exc).__name__
    code = f" ({errno.errorcode.get(exc.errno, exc.errno)})" if exc.errno else ""
    return f"{where}: {cause}{code}; what had finished is kept"


# --- argument types: ranges declared where the argument is ----------------------------------

@dataclass(frozen=True)
class Number:
    """A finite number of `what` in (low, high] (or [low, high] if not `low_open`)."""

    what: str
    low: float
    high: float
    low_open: bool = True

    def __call__(self, text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or not (value > self.low if self.low_open
                                            else value >= self.low) or value > self.high:
            raise argparse.ArgumentTypeError(
                f"got {text!r}; expected a finite number of {self.what} "
                f"{'>' if self.low_open else '>='} {self.low:g} and <= {self.high:g}")
        return value


@dataclass(frozen=True)
class Integer:
    """An integer `what` in [low, high] (no upper bound if `high` is None)."""

    what: str
    low: int
    high: int | None = None

    def __call__(self, text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = self.low - 1
        if value < self.low or (self.high is not None and value > self.high):
            upper = f" and <= {self.high}" if self.high is not None else ""
            raise argparse.ArgumentTypeError(
                f"got {text!r}; expected an integer {self.what} >= {self.low}{upper}")
        return value


HOURS = Number("hours", 0, MAX_DURATION_H)
WINDOW_HOURS = Number("hours", 0, MAX_DURATION_H, low_open=False)
SPEED = Number("metres per second", 0, 100)
SEED = Integer("seed", 0)
WORKERS = Integer("number of workers (0: one per core)", 0, 1024)
REPLICATIONS = Integer("number of replications", 2)  # the run limit is checked with the file
DASK_TIMEOUT = Number("seconds", 0, 86_400)
AGV_COUNT = Integer("number of AGVs", 1, MAX_FLEET_SIZE)


def agvs(text: str) -> int | dict[str, int]:
    """A fleet size (N), or a mixed fleet's counts of some of its types (TYPE=N[,TYPE=N])."""
    if "=" not in text:
        return AGV_COUNT(text)
    counts: dict[str, int] = {}
    for part in text.split(","):
        name, _, number = part.partition("=")
        name = name.strip()
        if not name or name in counts:
            raise argparse.ArgumentTypeError(
                f"got {text!r}; expected N, or TYPE=N[,TYPE=N] with each type once")
        counts[name] = Integer(f"number of {name} AGVs", 1, MAX_FLEET_SIZE)(number.strip())
    return counts


SETTING_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z0-9_][A-Za-z0-9_-]*)*")


def setting(text: str) -> tuple[str, object]:
    """`KEY=VALUE` of --set: a dotted scenario path and a YAML value."""
    import yaml

    key, equals, value = text.partition("=")
    key = key.strip()
    if not equals or not SETTING_KEY.fullmatch(key):
        raise argparse.ArgumentTypeError(
            f"got {text!r}; expected KEY=VALUE with KEY a dotted scenario field such as "
            "fleet.size and VALUE in YAML")
    try:
        return key, yaml.safe_load(value)
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise argparse.ArgumentTypeError(
            f"got {text!r}; expected KEY=VALUE with VALUE in YAML ({problem})") from None


def timestamp(text: str) -> str:
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


def identifier(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError(f"got {text!r}; expected a non-empty id")
    return text


# --- options several commands share ---------------------------------------------------------

SET = "--set"
SETTINGS = arg(SET, dest="settings", type=setting, action="append", default=[],
               metavar="KEY=VALUE",
               help="set a scenario field for this command, the value in YAML "
                    "(--set demand.rate_per_hour=60); repeat for several")
QUIET = arg("--quiet", action="store_true", help="no progress display")
RUNNER = (
    arg("--workers", type=WORKERS, default=0, help="worker processes (default: one per core)"),
    arg("--scheduler", metavar="ADDRESS",
        help="run on the Dask cluster at ADDRESS (tcp://host:8786), or 'local' for a local Dask "
             "cluster of --workers processes"),
    arg("--dask-timeout", type=DASK_TIMEOUT, default=120.0, metavar="SECONDS",
        help="with --scheduler: give up when the cluster has had no worker for this long "
             "(default 120; finished runs are kept)"),
    arg("--out", type=Path, help="results folder (default: results/<experiment name>)"),
    QUIET,
    SETTINGS,
)
MAX_SPEED = arg("--max-speed", type=SPEED, default=None,
                help="vehicle top speed in m/s to check speed limits against")
SCHEMA_KINDS = ("layout", "scenario", "experiment", "profile", "lif", "factsheet")


# --- the commands ---------------------------------------------------------------------------

@command(
    "run", "run one scenario and write its run directory",
    arg("scenario", type=Path, help="scenario YAML file"),
    arg("--agvs", type=agvs, help="fleet size (overrides fleet.size); a mixed fleet: "
        "TYPE=N[,TYPE=N] (overrides those types' counts)"),
    arg("--hours", type=HOURS, help="run length in hours (overrides duration_h)"),
    arg("--seed", type=SEED, help="random seed (overrides seed)"),
    arg("--out", type=Path, help="run directory (default: results/<scenario name>)"),
    QUIET,
    arg("--replay", action="store_true",
        help="also record every AGV's motion (moves.parquet) and write replay.html"),
    SETTINGS)
def _run(args: argparse.Namespace) -> int:
    from fleet_sim.analysis.tables import stream_run
    from fleet_sim.config.scenario import folder_name, load_layout_for
    from fleet_sim.config.trace import load_trace
    from fleet_sim.report.console import replay_line, run_lines
    from fleet_sim.study.progress import Progress

    scenario = scenario_for(args.scenario, args.settings, args.agvs, args.hours, args.seed)
    if args.replay and scenario.motion != "closed_form":
        raise InputError(str(args.scenario), "motion", scenario.motion,
                         "closed_form with --replay: a replay draws the closed-form speed "
                         "profile; with SUMO moving the AGVs their positions between nodes are "
                         "not recorded")
    layout = load_layout_for(scenario, str(args.scenario))  # bad input: no results folder
    out = args.out or _fresh_dir(Path("results") / folder_name(scenario.name))
    _check_out_dir(out, "--out" if args.out else "results folder")
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
    print(f"replay: {page.resolve()}  ({megabytes(page)})")
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
            _check_out_dir(args.out, "--out")
        else:
            _check_out_file(args.out, "--out")
    written = export(args.source, args.format, args.out,
                     note=lambda text: print(f"  {text}", file=sys.stderr, flush=True))
    print(export_lines(written))
    return 0


group("layout", "check a layout file and draw it to PNG (`layout FILE` is `layout check "
      "FILE`); `layout import` / `layout export` read and write VDMA LIF files",
      default="check")


@command(
    "layout check", "check a layout file and draw it to PNG (the default: `fleet-sim layout "
    "FILE`)",
    arg("layout", type=Path, help="layout YAML file"),
    arg("--png", type=Path, help="where to draw it (default: results/<name>.png)"),
    arg("--labels", action="store_true",
        help="write every node's id on the drawing, to find an aisle's nodes"),
    MAX_SPEED,
    arg("--sumo", type=Path, metavar="DIR",
        help="also export it as a SUMO network (plain XML, net.xml, vType) to DIR"))
def _layout(args: argparse.Namespace) -> int:
    from fleet_sim.config.layout import load_layout
    from fleet_sim.report.console import layout_lines
    from fleet_sim.report.layout_plot import draw_layout

    if args.png is not None:
        _check_out_file(args.png, "--png")
    layout = load_layout(args.layout, max_speed_mps=args.max_speed)
    print(layout_lines(args.layout, layout))
    png = args.png or Path("results") / f"{layout.name}.png"
    _check_out_file(png, "--png" if args.png else "results folder")
    draw_layout(layout, png, labels=args.labels)
    print(f"  drawing      {png}")
    if args.sumo is not None:
        from fleet_sim.sim.motion.sumo_network import export

        network = export(layout, args.sumo)
        print(f"  SUMO network {network.net_file} (+ plain .nod/.edg/.con.xml, "
              f"{network.vtype_file.name})")
    return 0


@command(
    "layout import", "read a VDMA LIF 1.0.0 file and write a fleet_sim layout",
    arg("lif", type=Path, metavar="FILE.lif.json", help="LIF file"),
    arg("--out", type=Path, required=True, help="layout YAML file to write"),
    arg("--layout-id", type=identifier, metavar="ID",
        help="which layout of the file (needed if it has several)"),
    arg("--vehicle-type", type=identifier, metavar="ID",
        help="which vehicleTypeId's nodes, edges and speeds (needed if the layout is for "
             "several)"),
    arg("--all-types", action="store_true",
        help="import every vehicle type: segments and stations open to some types only get "
             "allowed_types (--vehicle-type: the type whose speeds and lengths are kept)"),
    description="Read a VDMA LIF 1.0.0 file and write a fleet_sim layout; what the layout "
                "cannot hold is listed.")
def _layout_import(args: argparse.Namespace) -> int:
    """LIF -> layout file. The layout is written even if it does not check as a graph yet (a
    LIF without parking, say): the planner completes it; the problem is named, exit status 1."""
    from fleet_sim.config.layout import layout_from_spec, layout_yaml
    from fleet_sim.config.layout_lif import import_lif
    from fleet_sim.report.console import lif_import_lines

    _check_out_file(args.out, "--out")
    imported = import_lif(args.lif, args.layout_id, args.vehicle_type, args.all_types)
    for line in imported.warnings():
        print(f"fleet-sim: warning: {line}", file=sys.stderr)
    _write(args.out, layout_yaml(imported.spec, imported.comments()), "--out")
    print(lif_import_lines(args.lif, args.out, imported))
    try:
        layout_from_spec(imported.spec, str(args.out))
    except InputError as exc:
        print(f"fleet-sim: warning: {exc} (written; complete the layout and check it with "
              "`fleet-sim layout`)", file=sys.stderr)
        return 1
    return 0


@command(
    "layout export", "write a fleet_sim layout as a VDMA LIF 1.0.0 file",
    arg("layout", type=Path, metavar="NAME.yaml", help="layout YAML file"),
    arg("--lif", type=Path, required=True, metavar="FILE.json", help="LIF file to write"),
    arg("--timestamp", type=timestamp, metavar="ISO|now",
        help="exportTimestamp (default: the layout's lif.export_timestamp, else "
             "1970-01-01T00:00:00.00Z, so the same layout gives the same file)"),
    arg("--vehicle-type", type=identifier, metavar="ID",
        help="vehicleTypeId to write (default: the layout's lif.vehicle_type_id, else "
             "fleet-sim)"),
    MAX_SPEED,
    description="Write a fleet_sim layout as a VDMA LIF 1.0.0 file.")
def _layout_export(args: argparse.Namespace) -> int:
    from fleet_sim.config.layout import load_layout
    from fleet_sim.config.layout_lif import layout_to_lif, lif_json
    from fleet_sim.report.console import lif_export_lines

    _check_out_file(args.lif, "--lif")
    layout = load_layout(args.layout, max_speed_mps=args.max_speed)
    data = layout_to_lif(layout.spec, args.timestamp, args.vehicle_type)
    _write(args.lif, lif_json(data), "--lif")
    print(lif_export_lines(args.layout, args.lif, layout.name, data, args.timestamp is not None))
    return 0


@command(
    "crosscheck", "run a scenario with the closed-form and the SUMO motion backends and "
    "compare the KPIs (each run in its own process)",
    arg("scenario", type=Path, help="scenario YAML file"),
    arg("--agvs", type=agvs, nargs="+", metavar="N",
        help="fleet sizes to compare (default: the scenario's); a mixed fleet: TYPE=N[,TYPE=N] "
             "each"),
    arg("--hours", type=HOURS, help="run length in hours (overrides duration_h)"),
    arg("--seed", type=SEED, help="random seed (overrides seed)"))
def _crosscheck(args: argparse.Namespace) -> int:
    """One table per fleet size: KPIs and wall time of each backend, and SUMO's difference."""
    from fleet_sim.config.scenario import load_layout_for
    from fleet_sim.study.crosscheck import crosscheck, table

    # bad input fails here, before any run
    scenario = scenario_for(args.scenario, [], None, args.hours, args.seed)
    base = _flag_overrides(None, args.hours, args.seed, scenario)
    load_layout_for(scenario, str(args.scenario))
    for size in args.agvs or [None]:
        overrides = base if size is None else {**base, **fleet_overrides(size, scenario)}
        fleet = scenario.fleet
        text = _fleet_text(size) if size is not None else _fleet_text(
            {t.type: t.count for t in fleet.vehicles} if fleet.vehicles else fleet.size)
        print(f"{scenario.name}: {text}, {scenario.duration_h:g} h "
              f"(warm-up {scenario.warmup_h:g} h), seed {scenario.seed}", flush=True)
        print(table(crosscheck(args.scenario, overrides)), flush=True)
        print()
    return 0


@command(
    "emulate", "serve a virtual vehicle on a pseudo-terminal",
    arg("protocol", help="carriro, ktm02, tabo or agv3"),
    arg("--profile", help="vehicle profile (default: the one for the protocol)"),
    arg("--seed", type=SEED, help="seed of the link jitter"))
def _emulate(args: argparse.Namespace) -> int:
    """Print the pty path first, answer until Ctrl-C or SIGTERM, exit 0."""
    from agv_model.emulate import EmulateError, choose_profile, serve

    try:
        return serve(choose_profile(args.protocol, args.profile), seed=args.seed)
    except EmulateError as exc:
        raise FleetSimError(str(exc)) from None


@command("sweep", "run every run of an experiment (resumable)",
         arg("experiment", type=Path, help="experiment YAML file"), *RUNNER)
def _sweep(args: argparse.Namespace) -> int:
    from fleet_sim.report.console import sweep_header, sweep_lines
    from fleet_sim.study.runner import default_out
    from fleet_sim.study.sweep import sweep

    experiment = experiment_for(args.experiment, args.settings)
    out = args.out or default_out(experiment)
    print(sweep_header(experiment, len(experiment.runs()), args.workers, args.scheduler))
    outcome = sweep(experiment, out, args.workers, args.scheduler, args.quiet,
                    dask_timeout_s=args.dask_timeout)
    print(sweep_lines(experiment, outcome, out))
    return 1 if outcome.failed else 0


@command("size", "smallest fleet that meets the experiment's targets",
         arg("experiment", type=Path, help="experiment YAML file"), *RUNNER)
def _size(args: argparse.Namespace) -> int:
    from fleet_sim.report.console import size_header, size_lines
    from fleet_sim.study.runner import default_out
    from fleet_sim.study.sizing import size_fleet

    experiment = experiment_for(args.experiment, args.settings)
    out = args.out or default_out(experiment)
    print(size_header(experiment))
    results = size_fleet(experiment, out, args.workers, args.scheduler, args.quiet,
                         dask_timeout_s=args.dask_timeout)
    print(size_lines(results, out))
    return 0


@command("optimise", "cheapest design (fleet, chargers, policies, layout changes) that meets "
         "the experiment's targets, with a guarantee (resumable)",
         arg("experiment", type=Path, help="experiment YAML file with an optimise section"),
         *RUNNER)
def _optimise(args: argparse.Namespace) -> int:
    import time

    from fleet_sim.config.decisions import design_space
    from fleet_sim.report.console import optimise_header, optimise_lines
    from fleet_sim.study.optimise import optimise
    from fleet_sim.study.runner import default_out

    experiment = experiment_for(args.experiment, args.settings)
    space = design_space(experiment)  # refuses a file without an optimise section
    out = args.out or default_out(experiment)
    print(optimise_header(experiment, space))
    start = time.perf_counter()
    outcome = optimise(experiment, out, args.workers, args.scheduler, args.quiet,
                       dask_timeout_s=args.dask_timeout, space=space)
    print(optimise_lines(outcome, time.perf_counter() - start))
    return 1 if outcome.runs_failed else 0


@command("compare", "every variant against the baseline: paired differences with common random "
         "numbers, replications added until decided, the best variant selected (resumable)",
         arg("experiment", type=Path, help="experiment YAML file with variants"), *RUNNER,
         arg("--max-replications", type=REPLICATIONS, metavar="N",
             help="replication limit (default: the file's compare.max_replications)"))
def _compare(args: argparse.Namespace) -> int:
    import time

    from fleet_sim.study.compare import check_compare, compare, table_lines
    from fleet_sim.study.runner import default_out

    experiment = experiment_for(args.experiment, args.settings)
    check_compare(experiment, args.max_replications)
    out = args.out or default_out(experiment)
    print(f"compare {experiment.name}: {', '.join(experiment.variant_names[1:])} against "
          f"{experiment.baseline_name}, {max(1, len(experiment.points))} design point(s)")
    start = time.perf_counter()
    outcome = compare(experiment, out, args.workers, args.scheduler, args.quiet,
                      args.max_replications, dask_timeout_s=args.dask_timeout)
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


@command("schema", "print the JSON Schema of a file kind, for editors",
         arg("kind", choices=SCHEMA_KINDS, help="which file"),
         arg("--out", type=Path, help="write it to this file instead"))
def _schema(args: argparse.Namespace) -> int:
    import json

    from fleet_sim.config.schemas import json_schema

    text = json.dumps(json_schema(args.kind), indent=2, ensure_ascii=False) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    _write(args.out, text, "--out")
    print(f"{args.kind} schema: {args.out}")
    return 0


group("profile", "vehicle profiles: `profile import` makes one of a VDA 5050 factsheet")


@command(
    "profile import", "make a vehicle profile of a VDA 5050 2.1.0 factsheet",
    arg("factsheet", type=Path, metavar="FACTSHEET.json", help="factsheet file"),
    arg("--out", type=Path, required=True, help="profile YAML file to write"),
    arg("--base", default="rss-agv-001", metavar="PROFILE",
        help="bundled profile name or profile file giving the figures a factsheet lacks: turn "
             "speed, battery, link (default: rss-agv-001)"),
    description="Make a vehicle profile of a VDA 5050 2.1.0 factsheet: speeds, accelerations "
                "and length from the factsheet, the rest from a base profile; what is not used "
                "is listed.")
def _profile_import(args: argparse.Namespace) -> int:
    from fleet_sim.config.profile_factsheet import import_factsheet
    from fleet_sim.report.console import profile_import_lines

    _check_out_file(args.out, "--out")
    imported = import_factsheet(args.factsheet, args.base)
    _write(args.out, imported.text(), "--out")
    print(profile_import_lines(args.factsheet, args.out, imported))
    return 0


# --- helpers the commands share -------------------------------------------------------------

def scenario_for(file: Path, settings: Sequence[tuple[str, object]],
                 agvs: int | dict[str, int] | None, hours: float | None,
                 seed: int | None) -> Scenario:
    """The scenario of `file` with the --set settings, then --agvs, --hours and --seed. A
    problem of the file alone names the file; one a setting brings names --set and the field;
    one of a flag names the flag."""
    from fleet_sim.config.scenario import load_scenario

    sets = dict(settings)
    plain = _flag_overrides(None, hours, seed, None)
    scenario = _load_with_hours(file, plain, hours)
    if sets:
        try:
            scenario = load_scenario(file, {**sets, **plain})
        except InputError as exc:
            if exc.file != str(file):
                raise
            raise InputError(SET, exc.element, exc.value, exc.expected) from None
    if agvs is None:
        return scenario
    return _load_with_hours(file,
                            {**sets, **_flag_overrides(agvs, hours, seed, scenario)}, hours)


def experiment_for(file: Path, settings: Sequence[tuple[str, object]]) -> Experiment:
    """The experiment of `file` with the --set settings in every run; its targets checked and
    its setup warnings printed."""
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.targets import check_targets_known

    experiment = load_experiment(file, dict(settings), SET)
    check_targets_known(experiment)
    _warn_experiment(experiment)
    return experiment


def _flag_overrides(agvs: int | dict[str, int] | None, hours: float | None, seed: int | None,
                    scenario: Scenario | None) -> dict[str, object]:
    overrides: dict[str, object] = {}
    if agvs is not None:
        assert scenario is not None
        overrides |= fleet_overrides(agvs, scenario)
    if hours is not None:
        overrides["duration_h"] = hours
    if seed is not None:
        overrides["seed"] = seed
    return overrides


def fleet_overrides(agvs: int | dict[str, int], scenario: Scenario) -> dict[str, object]:
    """The overrides of --agvs: fleet.size, or each named type's count of a mixed fleet. A
    plain number for a mixed fleet, types for a one-type fleet, or a type the fleet does not
    have is refused naming --agvs."""
    from agv_model.inputs import closest
    from fleet_sim.config.scenario import type_count_path

    fleet = scenario.fleet
    if isinstance(agvs, int):
        if fleet.vehicles:
            types = [t.type for t in fleet.vehicles]
            raise InputError("--agvs", "", agvs, "TYPE=N for a mixed fleet (fleet."
                             f"vehicles: {', '.join(types)}), e.g. --agvs {types[-1]}=N; "
                             f"several: --agvs {types[0]}=N,{types[-1]}=M")
        return {"fleet.size": agvs}
    text = ",".join(f"{t}={n}" for t, n in agvs.items())
    if not fleet.vehicles:
        raise InputError("--agvs", "", text,
                         "a number of AGVs (the scenario's fleet has one vehicle type)")
    types = [t.type for t in fleet.vehicles]
    for name, count in agvs.items():
        if name not in types:
            close = closest(name, types)
            hint = f"; did you mean {close}={count}?" if close is not None else ""
            raise InputError("--agvs", "", text, f"TYPE=N with TYPE a type of fleet.vehicles "
                             f"({', '.join(types)}){hint}")
    return {type_count_path(name): n for name, n in agvs.items()}


def _fleet_text(agvs: int | dict[str, int]) -> str:
    if isinstance(agvs, int):
        return f"{agvs} AGVs"
    return " + ".join(f"{n} {name}" for name, n in agvs.items())


def _load_with_hours(file: Path, overrides: dict[str, object],
                     hours: float | None) -> Scenario:
    """The scenario with the overrides; a warm-up the --hours run cannot hold names --hours."""
    from fleet_sim.config.scenario import load_scenario

    try:
        return load_scenario(file, overrides)
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


def _write(path: Path, text: str, argument: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(argument, argument.lstrip("-"), str(path),
                         f"a writable file ({exc.strerror})") from None


def _warn_setup(scenario: Scenario, layout: typing.Any) -> None:
    """One warning line on stderr per battery or charging trap of the scenario (AGVs that
    cannot reach a charger, a draining battery with charging off): the run goes on."""
    from fleet_sim.config.scenario import setup_warnings

    for warning in setup_warnings(scenario, layout):
        print(f"fleet-sim: warning: {warning.text}", file=sys.stderr)


def _warn_experiment(experiment: Experiment) -> None:
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


if __name__ == "__main__":
    sys.exit(main())
