"""The registry of the `fleet-sim` command: one registration per command, and the parser and
`main` generated from the registrations.

Each command is one function decorated with `@command(name, help, *arguments)`: its name, the
line `fleet-sim --help` shows, and its arguments declared as data (`arg(...)`, `one_of(...)`).
The parser, the command list in `--help` and its usage line are generated from these
registrations (`build_parser`), so a new command is one decorated function and nothing else. A
command of a group is registered as "GROUP NAME" (`layout import`), after `group(...)`. The
reference page of the commands (docs/reference/commands.md) is generated from the same parser
(tools/docs_hook.py).

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import argparse
import sys
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from fleet_sim.errors import FleetSimError, InputError

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

