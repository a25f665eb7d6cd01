"""The `fleet-sim` command: one registration per command, no logic.

The registry and `main` are in `registry`; the commands, one decorated function each, are in a
module per group, imported here in the order `fleet-sim --help` lists them:

* `run`: run, replay (one run);
* `study`: sweep, size, optimise, compare, report, export (many runs and their results);
* `layout`: layout check|import|export, profile import, schema (the files a planner writes);
* `motion`: crosscheck, emulate (the vehicle's motion).

Argument types and the options several commands share are in `arguments`, what the commands
share beyond parsing in `shared`. A scenario with `--set`, `--agvs`, `--hours` and `--seed` is
made in fleet_sim.config.overrides (`load_scenario`): the command line only parses and hands
over. What the commands print when they finish is worded in fleet_sim.report.console.
"""

# The command modules register in the order they are imported: the order of `--help`.
from fleet_sim.cli import run

# isort: split
from fleet_sim.cli import study

# isort: split
from fleet_sim.cli import layout

# isort: split
from fleet_sim.cli import motion

# isort: split
from fleet_sim.cli.registry import REGISTRY, Command, Group, OneOf, build_parser, main
from fleet_sim.cli.shared import experiment_for

__all__ = ["REGISTRY", "Command", "Group", "OneOf", "build_parser", "experiment_for", "layout",
           "main", "motion", "run", "study"]
