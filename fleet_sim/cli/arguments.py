"""Argument types and the options several commands share.

Ranges and choices are declared where the argument is: `Number("hours", 0, MAX_DURATION_H)`,
`Integer("seed", 0)`, `choices=...`; the one-line refusal (``argument --hours: got 'nan';
expected a finite number of hours > 0 and <= 8760``) is written once, in those types. The text
of `--agvs` and `--set` is read by fleet_sim.config.overrides (`parse_agvs`, `parse_setting`),
which also applies them to the scenario: the command line only parses and hands over.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from fleet_sim.cli.registry import arg
from fleet_sim.config.overrides import SET, Agvs, parse_agvs, parse_setting
from fleet_sim.config.scenario import MAX_DURATION_H

T = TypeVar("T")


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


def argument_type(parse: Callable[[str], T]) -> Callable[[str], T]:
    """An argparse type of a parser of config/ that refuses with ValueError("got ...;
    expected ..."): the same words, after ``argument --flag: ``."""

    def checked(text: str) -> T:
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    checked.__name__ = parse.__name__
    return checked


HOURS = Number("hours", 0, MAX_DURATION_H)
WINDOW_HOURS = Number("hours", 0, MAX_DURATION_H, low_open=False)
SPEED = Number("metres per second", 0, 100)
SEED = Integer("seed", 0)
WORKERS = Integer("number of workers (0: one per core)", 0, 1024)
REPLICATIONS = Integer("number of replications", 2)  # the run limit is checked with the file
DASK_TIMEOUT = Number("seconds", 0, 86_400)
AGVS: Callable[[str], Agvs] = argument_type(parse_agvs)
"""A fleet size (N), or a mixed fleet's counts of some of its types (TYPE=N[,TYPE=N])."""
SETTING = argument_type(parse_setting)
"""`KEY=VALUE` of --set: a dotted scenario path and a YAML value."""


def timestamp(text: str) -> str:
    """An ISO 8601 UTC time for a LIF export, or `now`."""
    from datetime import UTC, datetime

    from fleet_sim.config.layout_spec import is_timestamp

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

SETTINGS = arg(SET, dest="settings", type=SETTING, action="append", default=[],
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
HOURS_ARG = arg("--hours", type=HOURS, help="run length in hours (overrides duration_h)")
SEED_ARG = arg("--seed", type=SEED, help="random seed (overrides seed)")
MAX_SPEED = arg("--max-speed", type=SPEED, default=None,
                help="vehicle top speed in m/s to check speed limits against")
SCHEMA_KINDS = ("layout", "scenario", "experiment", "profile", "lif", "factsheet")
