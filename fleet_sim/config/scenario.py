"""Scenario files -> one typed, frozen, validated config.

Every key has a default written here, with its source: RSS-AGV-001 section 7.1 where the spec
gives a figure, "assumed" where it does not. Unknown keys are errors. The resolved config (every
default written out) is `resolved(scenario)`, saved with each run.

The resolved config names its files by absolute path, so it reruns from any folder. The
choices where the issues were silent: docs/background/decisions/config.md.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any, Final, Literal

from pydantic import Field, PrivateAttr, ValidationInfo, model_validator

from agv_model.profile import profile_names
from fleet_sim.config.scenario_checks import agv_start_nodes as agv_start_nodes
from fleet_sim.config.scenario_checks import agvs_without_charger as agvs_without_charger
from fleet_sim.config.scenario_checks import check_against_layout as check_against_layout
from fleet_sim.config.scenario_checks import load_layout_for as load_layout_for
from fleet_sim.config.scenario_demand import DemandConfig as DemandConfig
from fleet_sim.config.scenario_fleet import MAX_FLEET_SIZE as MAX_FLEET_SIZE
from fleet_sim.config.scenario_fleet import VEHICLE_TYPES as VEHICLE_TYPES
from fleet_sim.config.scenario_fleet import CommandLink as CommandLink
from fleet_sim.config.scenario_fleet import FleetConfig
from fleet_sim.config.scenario_fleet import type_count_path as type_count_path
from fleet_sim.config.scenario_incidents import IncidentsConfig as IncidentsConfig
from fleet_sim.config.scenario_policies import ChargingConfig as ChargingConfig
from fleet_sim.config.scenario_policies import DispatchConfig as DispatchConfig
from fleet_sim.config.scenario_policies import TrafficConfig as TrafficConfig
from fleet_sim.config.scenario_rules import Rules as Rules
from fleet_sim.config.scenario_warnings import battery_hours as battery_hours
from fleet_sim.config.scenario_warnings import setup_warnings as setup_warnings
from fleet_sim.config.vehicle import VehicleProfile as VehicleProfile
from fleet_sim.errors import InputError
from userfiles.checking import HourOfDay, NonNegative, Problem, StrictModel, Text, validate
from userfiles.reading import read_yaml

MAX_DURATION_H: Final = 8760.0
"""Longest run: one year of operation; a longer run tells nothing more and runs for days."""
FOLDER_NAME: Final = "letters, digits, '_', '.', '-', not '.' or '..' (it names the results folder)"
"""What a scenario or experiment name may be: it becomes a folder under results/, so no path."""


def is_folder_name(name: str) -> bool:
    """True if `name` can name a folder under results/ without leaving it."""
    return bool(re.fullmatch(r"[A-Za-z0-9_.-]+", name)) and name not in (".", "..")


def folder_name(name: str) -> str:
    """`name` as one folder name under results/: unsafe characters become '_'."""
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", name)
    return safe if is_folder_name(safe) else safe.replace(".", "_") or "scenario"


class SumoConfig(StrictModel):
    """Settings of the SUMO motion backend (used when `motion` is ``sumo``)."""

    step_length_s: float = Field(default=0.1, gt=0, le=1.0)
    """SUMO's time step; SUMO and SimPy advance together in steps of this length."""
    tau_s: float = 1.0
    """Krauss time headway (assumed): at 1 m/s the following gap is min_gap_m + 1.0 m,
    P_005's 1.5 m detection distance."""

    @model_validator(mode="after")
    def _headway_at_least_a_step(self) -> SumoConfig:
        if self.tau_s < self.step_length_s:
            raise Problem("tau_s", self.tau_s,
                          f"a headway >= step_length_s ({self.step_length_s} s)")
        return self


class Scenario(StrictModel):
    """A scenario file: one run's layout, fleet, demand, policies, rules and incidents."""

    layout: Text
    """Layout file, relative to the scenario file."""
    name: Text = "scenario"
    description: Text = ""
    duration_h: float = Field(default=8.0, gt=0, le=MAX_DURATION_H)
    warmup_h: NonNegative = 0.5
    """KPIs count from the end of the warm-up; orders and events are recorded from t=0."""
    seed: int = Field(default=1, ge=0)
    start_h: HourOfDay = 0.0
    """Time of day at t=0, for the demand profile."""
    fleet: FleetConfig = FleetConfig()
    demand: DemandConfig = DemandConfig()
    dispatch: DispatchConfig = DispatchConfig()
    traffic: TrafficConfig = TrafficConfig()
    rules: Rules = Rules()
    charging: ChargingConfig = ChargingConfig()
    incidents: IncidentsConfig = IncidentsConfig()
    motion: Literal["closed_form", "sumo"] = "closed_form"
    """How AGVs move between nodes: closed_form (exact trapezoidal profiles per hop,
    fleet_sim.model.kinematics) or sumo (SUMO's car-following model through libsumo,
    fleet_sim.sim.sumo.backend, stepping with SimPy; dispatching, states, charging, incidents and
    traffic locks stay in the SimPy model). See docs/background/sumo.md."""
    sumo: SumoConfig = SumoConfig()
    _base_dir: str = PrivateAttr(default=".")
    """The scenario file's folder (files it names are relative to it); not a key of the file."""

    @model_validator(mode="after")
    def _warmup_within_run(self, info: ValidationInfo) -> Scenario:
        if self.warmup_h >= self.duration_h:
            raise Problem("warmup_h", self.warmup_h,
                          f"a warm-up >= 0 h and shorter than duration_h ({self.duration_h})")
        cap = self.dispatch.max_active_agvs
        if isinstance(cap, int) and self.fleet.start_nodes and cap < self.fleet.size:
            raise Problem("dispatch.max_active_agvs", cap,
                          f"at least fleet.size ({self.fleet.size}) when the AGVs start on "
                          "the track (fleet.start_nodes); leave start_nodes out to start them "
                          "in parking")
        if info.context and "base_dir" in info.context:
            self._base_dir = str(info.context["base_dir"])
        return self

    @property
    def base_dir(self) -> str:
        return self._base_dir

    @property
    def duration_s(self) -> float:
        return self.duration_h * 3600.0

    @property
    def warmup_s(self) -> float:
        return self.warmup_h * 3600.0

    def path(self, relative: str) -> Path:
        """A file named in the scenario, relative to the scenario file's folder."""
        p = Path(relative)
        return p if p.is_absolute() else Path(self._base_dir) / p


def load_scenario(path: str | Path, overrides: dict[str, Any] | None = None) -> Scenario:
    """Read a scenario file; `overrides` maps dotted keys (``fleet.size``) to new values."""
    path = Path(path)
    return scenario_with(scenario_data(path), overrides or {}, str(path), path.parent)


def scenario_data(path: Path) -> dict[str, Any]:
    """A scenario file's YAML, read and parsed once: a mapping, and not an experiment's."""
    data = read_yaml(path)
    if data is not None and not isinstance(data, dict):
        raise InputError(str(path), "top level", data, "a mapping")
    data = dict(data or {})
    if "scenario" in data and "factors" in data:
        raise InputError(str(path), "top level", "an experiment file (scenario, factors...)",
                         "a scenario file; run experiments with `fleet-sim sweep` or "
                         "`fleet-sim size`")
    return data


def scenario_with(data: dict[str, Any], overrides: dict[str, Any], file: str,
                  base_dir: str | Path) -> Scenario:
    """The scenario of `data` (left as it is) with `overrides` set; `file` names it in errors,
    `base_dir` is its folder."""
    data = copy.deepcopy(data)
    for dotted, value in overrides.items():
        _set_dotted(data, dotted, value, file)
    return parse_scenario(data, file, base_dir)


def parse_scenario(data: Any, file: str, base_dir: str | Path = ".") -> Scenario:
    """A scenario from parsed YAML; `file` names it in errors, `base_dir` is its folder."""
    return validate(Scenario, data, file, context={"base_dir": str(base_dir)})


def _set_dotted(data: dict[str, Any], dotted: str, value: Any, file: str = "<overrides>") -> None:
    """Set `value` at a dotted path of a scenario's data. `fleet.vehicles` is a list: the key
    after it names a type (``fleet.vehicles.heavy.count``)."""
    keys = dotted.split(".")
    target = data
    i = 0
    while i < len(keys) - 1:
        key = keys[i]
        nxt = target.get(key)
        if ".".join(keys[:i + 1]) == VEHICLE_TYPES:
            target = _vehicle_type_entry(nxt, keys, i, dotted, file)
            i += 2
            continue
        if not isinstance(nxt, dict):
            nxt = {}
            target[key] = nxt
        target = nxt
        i += 1
    target[keys[-1]] = value


def _vehicle_type_entry(types: Any, keys: list[str], i: int, dotted: str,
                        file: str) -> dict[str, Any]:
    """The entry of fleet.vehicles that keys[i + 1] names."""
    if not isinstance(types, list) or not types:
        raise InputError(file, dotted, keys[i + 1] if i + 1 < len(keys) else "",
                         "a type of a mixed fleet (fleet.vehicles); the scenario's fleet has "
                         "one vehicle type: vary fleet.size")
    names = [t.get("type") for t in types if isinstance(t, dict)]
    if i + 1 >= len(keys) - 1:
        raise InputError(file, dotted, dotted, "a field of one vehicle type, such as "
                         f"{type_count_path(str(names[0]))}")
    for entry in types:
        if isinstance(entry, dict) and str(entry.get("type")) == keys[i + 1]:
            return entry
    raise InputError(file, dotted, keys[i + 1],
                     f"a type of fleet.vehicles ({', '.join(str(n) for n in names)})")


def resolved(scenario: Scenario) -> dict[str, Any]:
    """The scenario with every default written out, as plain data for YAML: a scenario file
    that `fleet-sim run` reads from anywhere (the files it names are made absolute)."""
    plain = scenario.model_dump(mode="json", by_alias=True)
    plain["layout"] = str(scenario.path(scenario.layout).resolve())
    if scenario.demand.trace_csv is not None:
        plain["demand"]["trace_csv"] = str(scenario.path(scenario.demand.trace_csv).resolve())
    for flow in plain["demand"]["flows"]:  # a flow is written as given: from/to, or stops
        for key in ("from", "to") if flow["stops"] else ("stops",):
            del flow[key]
    fleet = plain["fleet"]
    if scenario.fleet.vehicles:  # the size is the counts' sum; each type has its vehicle
        del fleet["size"], fleet["vehicle"]
        for written in fleet["vehicles"]:
            name = written["profile"]
            if name is not None and name not in profile_names():
                written["profile"] = str(scenario.path(name).resolve())
    else:  # a one-type fleet: no vehicles
        del fleet["vehicles"]
    return plain
