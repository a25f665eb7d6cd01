"""Scenario files -> one typed, frozen, validated config.

Every key has a default written here, with its source: RSS-AGV-001 section 7.1 where the spec
gives a figure, "assumed" where it does not. Unknown keys are errors. The resolved config (every
default written out) is `resolved(scenario)`, saved with each run.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from fleet_sim.confparse import build, read_yaml, to_plain
from fleet_sim.errors import InputError
from fleet_sim.layout import Layout, load_layout


@dataclass(frozen=True)
class VehicleProfile:
    name: str = "rss-agv-001"
    max_speed_mps: float = 1.0
    """P_001 VEL_MAX 1000 mm/s."""
    accel_mps2: float = 0.5
    """P_002 VEL_ACC 500 mm/s2."""
    decel_mps2: float = 0.5
    """P_003 VEL_DEC 500 mm/s2."""
    turn_speed_mps: float = 0.3
    """P_004 TURN_SPEED 300 mm/s; Req.Nav.005 limits branch turns to 0.3 m/s."""
    length_m: float = 1.0
    """Assumed: body length of a typical tape-guided tugger/carrier."""
    min_gap_m: float = 0.5
    """Gap kept to the AGV ahead; P_006 OBS_STOP_DIST 500 mm, the distance the LDS stops at."""
    boot_s: float = 5.0
    """Assumed: time in ST_001 Booting before Event_Init_Complete."""

    def check(self, file: str, element: str) -> None:
        for name in ("max_speed_mps", "accel_mps2", "decel_mps2", "turn_speed_mps", "length_m"):
            value = getattr(self, name)
            if value <= 0:
                raise InputError(file, f"{element}.{name}", value, "a number > 0")
        for name in ("min_gap_m", "boot_s"):
            value = getattr(self, name)
            if value < 0:
                raise InputError(file, f"{element}.{name}", value, "a number >= 0")
        if self.turn_speed_mps > self.max_speed_mps:
            raise InputError(file, f"{element}.turn_speed_mps", self.turn_speed_mps,
                             f"at most max_speed_mps ({self.max_speed_mps})")


@dataclass(frozen=True)
class FleetConfig:
    size: int = 4
    vehicle: VehicleProfile = VehicleProfile()
    start_nodes: tuple[str, ...] = ()
    """Where AGVs start, one node each; empty: inside the parking areas, filled in file order."""

    def check(self, file: str, element: str) -> None:
        if self.size < 1:
            raise InputError(file, f"{element}.size", self.size, "an integer >= 1")
        if self.start_nodes and len(self.start_nodes) < self.size:
            raise InputError(file, f"{element}.start_nodes", list(self.start_nodes),
                             f"at least one start node per AGV ({self.size})")
        if len(set(self.start_nodes)) != len(self.start_nodes):
            raise InputError(file, f"{element}.start_nodes", list(self.start_nodes),
                             "distinct nodes (one AGV per node)")


@dataclass(frozen=True)
class Flow:
    from_station: str = field(metadata={"key": "from"})
    to_station: str = field(metadata={"key": "to"})
    weight: float = 1.0

    def check(self, file: str, element: str) -> None:
        if self.weight <= 0:
            raise InputError(file, f"{element}.weight", self.weight, "a weight > 0")


@dataclass(frozen=True)
class RatePeriod:
    from_h: float
    """Time of day (hours, 0-24) from which `multiplier` applies, until the next period."""
    multiplier: float

    def check(self, file: str, element: str) -> None:
        if not 0 <= self.from_h < 24:
            raise InputError(file, f"{element}.from_h", self.from_h, "an hour of day in [0, 24)")
        if self.multiplier < 0:
            raise InputError(file, f"{element}.multiplier", self.multiplier, "a number >= 0")


@dataclass(frozen=True)
class DemandConfig:
    kind: Literal["poisson", "trace"] = "poisson"
    rate_per_hour: float = 60.0
    """Mean orders per hour at multiplier 1 (poisson)."""
    flows: tuple[Flow, ...] = ()
    """Order flows between stations; empty: every pickup to every dropoff, equal weights."""
    profile: tuple[RatePeriod, ...] = ()
    """Time-of-day rate multipliers, repeating daily; empty: constant rate."""
    trace_csv: str | None = None
    """Order trace (columns time_s, pickup, dropoff), relative to the scenario file."""

    def check(self, file: str, element: str) -> None:
        if self.rate_per_hour < 0:
            raise InputError(file, f"{element}.rate_per_hour", self.rate_per_hour, "a rate >= 0")
        if self.kind == "trace" and self.trace_csv is None:
            raise InputError(file, f"{element}.trace_csv", None,
                             "the path of an order trace CSV when kind is 'trace'")
        hours = [p.from_h for p in self.profile]
        if hours and (hours[0] != 0 or hours != sorted(set(hours))):
            raise InputError(file, f"{element}.profile", hours,
                             "periods in increasing from_h, the first at 0")

    def multiplier_at(self, hour_of_day: float) -> float:
        value = 1.0
        for period in self.profile:
            if period.from_h <= hour_of_day:
                value = period.multiplier
        return value

    @property
    def max_multiplier(self) -> float:
        return max((p.multiplier for p in self.profile), default=1.0)


@dataclass(frozen=True)
class DispatchConfig:
    policy: Literal["nearest_idle", "fcfs"] = "nearest_idle"
    """nearest_idle: each order, oldest first, to the idle AGV with the shortest travel time to
    its pickup. fcfs: each order, oldest first, to the AGV that has been idle longest."""
    park_idle: bool = True
    """Send AGVs with nothing to do to the nearest parking area with room."""


@dataclass(frozen=True)
class TrafficConfig:
    deadlock_check_s: float = 10.0
    """How often an AGV that is still blocked looks again for a wait-for cycle."""
    replan_after_s: float = 30.0
    """Blocked this long, an AGV takes another route if one exists."""
    give_way_after_s: float = 10.0
    """Blocked this long with another AGV queued behind it, an AGV drives on and comes back
    round rather than block the way (assumed; see fleet_sim.traffic)."""
    backoff_s: float = 5.0
    """Mean wait before a deadlocked AGV that cannot move tries again."""

    def check(self, file: str, element: str) -> None:
        for name in ("deadlock_check_s", "replan_after_s", "give_way_after_s", "backoff_s"):
            if getattr(self, name) <= 0:
                raise InputError(file, f"{element}.{name}", getattr(self, name), "a time > 0 s")


@dataclass(frozen=True)
class Scenario:
    layout: str
    """Layout file, relative to the scenario file."""
    name: str = "scenario"
    description: str = ""
    duration_h: float = 8.0
    warmup_h: float = 0.5
    """KPIs count from the end of the warm-up; orders and events are recorded from t=0."""
    seed: int = 1
    start_h: float = 0.0
    """Time of day at t=0, for the demand profile."""
    fleet: FleetConfig = FleetConfig()
    demand: DemandConfig = DemandConfig()
    dispatch: DispatchConfig = DispatchConfig()
    traffic: TrafficConfig = TrafficConfig()
    base_dir: str = field(default=".", metadata={"key": "_base_dir"}, compare=False)

    def check(self, file: str, element: str) -> None:
        if self.duration_h <= 0:
            raise InputError(file, "duration_h", self.duration_h, "a duration > 0 h")
        if not 0 <= self.warmup_h < self.duration_h:
            raise InputError(file, "warmup_h", self.warmup_h,
                             f"a warm-up >= 0 h and shorter than duration_h ({self.duration_h})")
        if self.seed < 0:
            raise InputError(file, "seed", self.seed, "an integer >= 0")
        if not 0 <= self.start_h < 24:
            raise InputError(file, "start_h", self.start_h, "an hour of day in [0, 24)")

    @property
    def duration_s(self) -> float:
        return self.duration_h * 3600.0

    @property
    def warmup_s(self) -> float:
        return self.warmup_h * 3600.0

    def path(self, relative: str) -> Path:
        """A file named in the scenario, relative to the scenario file's folder."""
        p = Path(relative)
        return p if p.is_absolute() else Path(self.base_dir) / p


def load_scenario(path: str | Path, overrides: dict[str, Any] | None = None) -> Scenario:
    """Read a scenario file; `overrides` maps dotted keys (``fleet.size``) to new values."""
    path = Path(path)
    data = read_yaml(path)
    if data is not None and not isinstance(data, dict):
        raise InputError(str(path), "top level", data, "a mapping")
    data = dict(data or {})
    if "_base_dir" in data:
        raise InputError(str(path), "_base_dir", data["_base_dir"], "no such key (it is internal)")
    for dotted, value in (overrides or {}).items():
        _set_dotted(data, dotted, value)
    data["_base_dir"] = str(path.parent)
    return build(Scenario, data, str(path))


def _set_dotted(data: dict[str, Any], dotted: str, value: Any) -> None:
    keys = dotted.split(".")
    target = data
    for key in keys[:-1]:
        nxt = target.get(key)
        if not isinstance(nxt, dict):
            nxt = {}
            target[key] = nxt
        target = nxt
    target[keys[-1]] = value


def load_layout_for(scenario: Scenario, scenario_file: str) -> Layout:
    """Load the scenario's layout and check the scenario against it."""
    layout_path = scenario.path(scenario.layout)
    if not layout_path.exists():
        raise InputError(scenario_file, "layout", scenario.layout,
                         f"an existing layout file (looked for {layout_path})")
    layout = load_layout(layout_path, max_speed_mps=scenario.fleet.vehicle.max_speed_mps)
    check_against_layout(scenario, layout, scenario_file)
    return layout


def check_against_layout(scenario: Scenario, layout: Layout, file: str) -> None:
    for i, flow in enumerate(scenario.demand.flows):
        for key, station, kind in (("from", flow.from_station, "pickup"),
                                   ("to", flow.to_station, "dropoff")):
            place = layout.places.get(station)
            if place is None or place.kind != kind:
                names = ", ".join(p.id for p in layout.places.values() if p.kind == kind)
                raise InputError(file, f"demand.flows[{i}].{key}", station,
                                 f"a {kind} station of layout {layout.name} ({names})")
    for i, node in enumerate(scenario.fleet.start_nodes):
        if node not in layout.graph:
            raise InputError(file, f"fleet.start_nodes[{i}]", node,
                             f"a node of layout {layout.name}")
    if not scenario.fleet.start_nodes:
        room = sum(p.capacity for p in layout.parking)
        if scenario.fleet.size > room:
            raise InputError(file, "fleet.size", scenario.fleet.size,
                             f"at most the parking capacity of layout {layout.name} ({room}), "
                             "or fleet.start_nodes for the rest")


def resolved(scenario: Scenario) -> dict[str, Any]:
    """The scenario with every default written out, as plain data for YAML."""
    plain = to_plain(scenario)
    assert isinstance(plain, dict)
    plain.pop("_base_dir", None)
    return plain


def with_overrides(scenario: Scenario, **changes: Any) -> Scenario:
    """A copy with top-level fields replaced (``fleet=...``)."""
    return dataclasses.replace(scenario, **changes)
