"""A scenario with a command's settings and flags: `--set KEY=VALUE`, `--agvs`, `--hours`,
`--seed`, applied here, in config/, so that the command line only parses and hands over (as
desmod applies user overrides in its config module).

`load_scenario(file, sets, agvs=, hours=, seed=)` reads and parses the file's YAML once
(`fleet_sim.config.scenario.scenario_data`) and checks it in up to three steps, each on a copy
of that data, so that every problem names what brought it (`scenario_of` does the same with
YAML already parsed, such as a loaded scenario's `resolved(scenario)`):

1. the file with `--hours` and `--seed`: a problem of the file alone names the file; a warm-up
   the `--hours` run cannot hold names `--hours`;
2. with the `--set` settings too: a problem they bring names `--set` and the field (a problem
   of another file, a profile a setting names, names that file);
3. with `--agvs` too, which needs step 2's fleet (a mixed fleet's types): a plain number for a
   mixed fleet, types for a one-type fleet, or a type the fleet does not have is refused naming
   `--agvs`.

The settings come first and the flags after them, so `--agvs 3` wins over `--set fleet.size=4`.
Paths set this way are relative to the scenario file, as in the file.

The text of a flag (`parse_agvs`, `parse_setting`) is checked before any file is read; a bad
one raises ValueError with the words ``got '...'; expected ...``, which the command line shows
after ``argument --agvs: ``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from fleet_sim.config.scenario import Scenario, scenario_data, scenario_with
from fleet_sim.config.scenario_fleet import MAX_FLEET_SIZE, type_count_path
from fleet_sim.errors import InputError
from userfiles.checking import closest

SET = "--set"
"""The flag a problem of the settings is named by."""

Agvs = int | dict[str, int]
"""`--agvs`: a fleet size, or a mixed fleet's counts of some of its types."""

SETTING_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z0-9_][A-Za-z0-9_-]*)*")


def load_scenario(file: str | Path,
                  sets: Mapping[str, object] | Iterable[tuple[str, object]] = (), *,
                  agvs: Agvs | None = None, hours: float | None = None,
                  seed: int | None = None) -> Scenario:
    """The scenario of `file` with the `--set` settings, then `--agvs`, `--hours` and `--seed`
    (the module's docstring: which step names which problem)."""
    path = Path(file)
    return scenario_of(scenario_data(path), str(path), path.parent, sets, agvs=agvs,
                       hours=hours, seed=seed)


def scenario_of(data: dict[str, Any], file: str, base_dir: str | Path,
                sets: Mapping[str, object] | Iterable[tuple[str, object]] = (), *,
                agvs: Agvs | None = None, hours: float | None = None,
                seed: int | None = None) -> Scenario:
    """`load_scenario` of parsed YAML: a file's `data` (named `file` in errors, its folder
    `base_dir`), or a loaded scenario's (`resolved(scenario)`); `data` is left as it is."""
    settings = dict(sets)
    flags = flag_overrides(hours, seed)
    scenario = _with_hours(data, flags, file, base_dir, hours)
    if settings:
        try:
            scenario = scenario_with(data, {**settings, **flags}, file, base_dir)
        except InputError as exc:
            if exc.file != file:
                raise
            raise InputError(SET, exc.element, exc.value, exc.expected) from None
    if agvs is None:
        return scenario
    return _with_hours(data, {**settings, **fleet_overrides(agvs, scenario), **flags}, file,
                       base_dir, hours)


def flag_overrides(hours: float | None, seed: int | None) -> dict[str, object]:
    """The overrides of `--hours` and `--seed`, those given."""
    overrides: dict[str, object] = {}
    if hours is not None:
        overrides["duration_h"] = hours
    if seed is not None:
        overrides["seed"] = seed
    return overrides


def fleet_overrides(agvs: Agvs, scenario: Scenario) -> dict[str, object]:
    """The overrides of `--agvs`: fleet.size, or each named type's count of a mixed fleet. A
    plain number for a mixed fleet, types for a one-type fleet, or a type the fleet does not
    have is refused naming --agvs."""
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


def _with_hours(data: dict[str, Any], overrides: dict[str, object], file: str,
                base_dir: str | Path, hours: float | None) -> Scenario:
    """The scenario with the overrides; a warm-up the --hours run cannot hold names --hours."""
    try:
        return scenario_with(data, overrides, file, base_dir)
    except InputError as exc:
        if hours is not None and exc.element == "warmup_h":
            raise InputError("--hours", "duration_h", hours,
                             f"a run longer than the scenario's warm-up ({exc.value} h in "
                             f"{file})") from None
        raise


# --- the text of the flags, before any file is read -----------------------------------------

def parse_agvs(text: str) -> Agvs:
    """`--agvs`: a fleet size (N), or a mixed fleet's counts of some of its types
    (TYPE=N[,TYPE=N])."""
    if "=" not in text:
        return count_of(text, "number of AGVs")
    counts: dict[str, int] = {}
    for part in text.split(","):
        name, _, number = part.partition("=")
        name = name.strip()
        if not name or name in counts:
            raise ValueError(f"got {text!r}; expected N, or TYPE=N[,TYPE=N] with each type once")
        counts[name] = count_of(number.strip(), f"number of {name} AGVs")
    return counts


def count_of(text: str, what: str) -> int:
    """A number of AGVs in [1, MAX_FLEET_SIZE]."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= MAX_FLEET_SIZE:
        raise ValueError(f"got {text!r}; expected an integer {what} >= 1 and <= {MAX_FLEET_SIZE}")
    return value


def parse_setting(text: str) -> tuple[str, object]:
    """`--set KEY=VALUE`: a dotted scenario path and a YAML value."""
    import yaml

    key, equals, value = text.partition("=")
    key = key.strip()
    if not equals or not SETTING_KEY.fullmatch(key):
        raise ValueError(f"got {text!r}; expected KEY=VALUE with KEY a dotted scenario field "
                         "such as fleet.size and VALUE in YAML")
    try:
        return key, yaml.safe_load(value)
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise ValueError(f"got {text!r}; expected KEY=VALUE with VALUE in YAML "
                         f"({problem})") from None
