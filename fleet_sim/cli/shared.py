"""What the commands share: the experiment of a file with its settings, checks of an output
path before any work, and warnings printed on standard error."""

from __future__ import annotations

import sys
import typing
from collections.abc import Sequence
from pathlib import Path

from fleet_sim.config.overrides import SET
from fleet_sim.errors import InputError
from userfiles.writing import check_out_dir as check_out_dir

if typing.TYPE_CHECKING:
    from fleet_sim.config.experiment import Experiment
    from fleet_sim.config.scenario import Scenario


def experiment_for(file: Path, settings: Sequence[tuple[str, object]]) -> Experiment:
    """The experiment of `file` with the --set settings in every run; its targets checked and
    its setup warnings printed."""
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.targets import check_targets_known

    experiment = load_experiment(file, dict(settings), SET)
    check_targets_known(experiment)
    warn_experiment(experiment)
    return experiment


def check_out_file(out: Path, argument: str) -> None:
    """Refuse, before any work, an output file path that is a directory or cannot be written."""
    if out.is_dir():
        raise InputError(argument, argument.lstrip("-"), str(out),
                         "a file path (it is an existing directory)")
    check_out_dir(out.parent, argument, f"{argument.lstrip('-')} folder")


def write(path: Path, text: str, argument: str) -> None:
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(argument, argument.lstrip("-"), str(path),
                         f"a writable file ({exc.strerror})") from None


def warn_setup(scenario: Scenario, layout: typing.Any) -> None:
    """One warning line on stderr per battery or charging trap of the scenario (AGVs that
    cannot reach a charger, a draining battery with charging off): the run goes on."""
    from fleet_sim.config.scenario import setup_warnings

    for warning in setup_warnings(scenario, layout):
        print(f"fleet-sim: warning: {warning.text}", file=sys.stderr)


def warn_experiment(experiment: Experiment) -> None:
    """The setup warnings of an experiment's design points, each kind once."""
    from fleet_sim.config.experiment import experiment_warnings

    for text in experiment_warnings(experiment):
        print(f"fleet-sim: warning: {text}", file=sys.stderr)


def fresh_dir(base: Path) -> Path:
    """`base`, or `base-2`, `base-3`... so that a default run never overwrites an earlier one."""
    if not base.exists():
        return base
    n = 2
    while Path(f"{base}-{n}").exists():
        n += 1
    return Path(f"{base}-{n}")
