"""What an experiment and a design space (fleet_sim.config.decisions) share below them: the
limits of one experiment, run ids and seeds, levels in words, the check of a dotted scenario
path, and the layouts runs drive on (read once per process, changes applied once).

fleet_sim.config.experiment re-exports each of these names, so its users import them from
there; they live here so that the decisions module needs nothing of the experiment
module at run time.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import Any, Final

import numpy as np

from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.layout_changes import Change, ChangeSite, changed_layout
from fleet_sim.config.scenario import Scenario
from fleet_sim.config.scenario_checks import check_against_layout
from fleet_sim.errors import InputError

MAX_REPLICATIONS: Final = 1_000
"""Most replications of one design point: intervals stop narrowing usefully long before."""
MAX_RUNS: Final = 10_000
"""Most runs of one experiment (design points x replications): a day or more of computing."""

VARIANT_PREFIX: Final = "v="
"""Run ids of a named variant start with ``v=<name>__``; the base scenario's have no prefix."""


def replication_seed(master_seed: int, replication: int) -> int:
    """The scenario seed of replication `replication`: the same at every factor level."""
    child = np.random.SeedSequence(master_seed, spawn_key=(replication,))
    return int(child.generate_state(1, np.uint32)[0])


def variant_run_id(variant: str, factors: Mapping[str, Any], replication: int) -> str:
    """A named variant's run id: the base scenario's, prefixed ``v=<variant>__``."""
    return f"{VARIANT_PREFIX}{variant}__{run_id(factors, replication)}"


def run_id(factors: Mapping[str, Any], replication: int) -> str:
    """A readable, stable folder name for a run, from its factor values and replication."""
    parts = [f"{path}={_fmt(value)}" for path, value in sorted(factors.items())]
    text = "__".join([*parts, f"r{replication:02d}"])
    text = re.sub(r"[^A-Za-z0-9_.=+-]", "-", text)
    if len(text) > 120:
        import hashlib
        digest = hashlib.sha1(text.encode()).hexdigest()[:12]
        text = f"p{digest}__r{replication:02d}"
    return text


def level_text(value: Any) -> str:
    """A factor level as the experiment file would write it: `null` for no value (a pandas
    column of levels holds it as NaN), whole numbers without a decimal point."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "null"
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return _fmt(value)


def point_text(point: Mapping[str, Any]) -> str:
    """A design point for messages and captions: `fleet.size=50, dispatch.max_active_agvs=null`."""
    return ", ".join(f"{k}={level_text(v)}" for k, v in point.items())


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (list, tuple, dict)):
        return re.sub(r"\s+", "", str(value))
    return str(value)


def check_path(file: str, element: str, key: str) -> None:
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z0-9_][A-Za-z0-9_-]*)*", key):
        raise InputError(file, element, key, "a dotted scenario path such as fleet.size")
    if key == "seed":
        raise InputError(file, element, key, "another scenario field (seeds come from "
                                             "master_seed and the replication)")


@lru_cache(maxsize=8)
def cached_layout(path: str, max_speed_mps: float) -> Layout:
    """Layouts are read once per process (a sweep builds many scenarios on one layout)."""
    return load_layout(path, max_speed_mps=max_speed_mps)


def layout_for(scenario: Scenario, scenario_file: str) -> Layout:
    """The scenario's layout (cached), checked against the scenario."""
    layout_path = scenario.path(scenario.layout)
    if not layout_path.exists():
        raise InputError(scenario_file, "layout", scenario.layout,
                         f"an existing layout file (looked for {layout_path})")
    layout = cached_layout(str(layout_path.resolve()), scenario.fleet.max_speed_mps)
    check_against_layout(scenario, layout, scenario_file)
    return layout


@lru_cache(maxsize=16)
def _cached_changed_layout(path: str, max_speed_mps: float, changes: tuple[Change, ...],
                           site: ChangeSite) -> Layout:
    """A layout with a variant's changes, made once per process (a comparison builds many
    scenarios on one changed layout)."""
    return changed_layout(cached_layout(path, max_speed_mps), changes, site, max_speed_mps)


def changed_layout_for(scenario: Scenario, scenario_file: str, changes: Sequence[Change],
                       site: ChangeSite) -> Layout:
    """The scenario's layout (cached) with `changes` applied, checked against the scenario;
    a problem is a refusal naming the experiment file, the variant and the change."""
    layout_path = scenario.path(scenario.layout)
    if not layout_path.exists():
        raise InputError(scenario_file, "layout", scenario.layout,
                         f"an existing layout file (looked for {layout_path})")
    path, speed = str(layout_path.resolve()), scenario.fleet.max_speed_mps
    layout = _cached_changed_layout(path, speed, tuple(changes), site)

    def check(candidate: Layout) -> None:
        check_against_layout(scenario, candidate, scenario_file)

    try:
        check(layout)
    except InputError:  # the same again, to blame the change that made the scenario not fit
        changed_layout(cached_layout(path, speed), changes, site, speed, check)
        raise
    return layout
