"""The traps in a scenario's settings that are warned about, not refused (`setup_warnings`):
battery and charging traps, and per-type speed limits for types the fleet lacks. Why warned,
and how long a battery lasts: docs/background/decisions/config.md."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario_checks import agvs_without_charger
from fleet_sim.config.vehicle import VehicleProfile

if TYPE_CHECKING:
    from fleet_sim.config.scenario import Scenario


class BatteryHours(NamedTuple):
    """How long a battery takes to fall from one SOC to another (see the module docstring)."""

    busy_h: float
    """Working flat out: driving at top speed, half the distance loaded (or handling)."""
    idle_h: float
    """Standing idle (inf if idling draws nothing)."""


def battery_hours(vehicle: VehicleProfile, from_pct: float, to_pct: float) -> BatteryHours:
    """Hours for the vehicle's battery to fall from `from_pct` to `to_pct`; zero if it is
    there already, inf if nothing drains it. No battery model: inf."""
    battery = vehicle.battery
    if battery is None:
        return BatteryHours(math.inf, math.inf)
    energy_wh = max(0.0, from_pct - to_pct) / 100.0 * battery.capacity_wh
    driving_w = battery.idle_w + (battery.drive_wh_per_m + battery.drive_loaded_wh_per_m) \
        / 2.0 * vehicle.max_speed_mps * 3600.0
    busy_w = max(driving_w, battery.handling_w)

    def hours(power_w: float) -> float:
        if energy_wh == 0:
            return 0.0
        return energy_wh / power_w if power_w > 0 else math.inf

    return BatteryHours(hours(busy_w), hours(battery.idle_w))


class SetupWarning(NamedTuple):
    """A trap in a scenario's settings: `kind` groups the same trap across the design points
    of an experiment, `text` is the one line shown."""

    kind: str
    text: str


def setup_warnings(scenario: Scenario, layout: Layout) -> list[SetupWarning]:
    """The battery and charging traps of `scenario` on `layout`, one line each (see the module
    docstring): AGVs that cannot reach a charger with charging on; a draining battery with
    charging off on a run long enough to run it down. A mixed fleet is looked at type by type
    (the first type whose battery gives the trap is named); its layout's per-type speed limits
    must name its types (`_unknown_limited_types`)."""
    out: list[SetupWarning] = []
    for name, vehicle in scenario.fleet.type_profiles.items():
        found = _type_warnings(scenario, layout, vehicle)
        if found:
            if scenario.fleet.vehicles:
                found = [SetupWarning(w.kind, f"vehicle type {name}: {w.text}".replace(
                    "fleet.vehicle.battery", f"the battery of type {name}")) for w in found]
            out = found
            break
    return out + _unknown_limited_types(scenario, layout)


def _unknown_limited_types(scenario: Scenario, layout: Layout) -> list[SetupWarning]:
    """A mixed fleet on a layout whose per-type speed limits name a type the fleet does not
    have (a typo, or a layout drawn for a larger fleet): warned once, with the first segment
    that names it. A one-type fleet is not warned: a layout is shared by many scenarios, and
    a limit for a type the fleet lacks applies to no AGV, as `allowed_types` naming it do."""
    fleet_types = scenario.fleet.type_profiles
    if not scenario.fleet.vehicles:
        return []
    for i, seg in enumerate(layout.spec.segments):
        for name in seg.speed_limit_mps_by_type:
            if name not in fleet_types:
                return [SetupWarning("unknown_type_limit", (
                    f"{layout.file}: segments[{i}].speed_limit_mps_by_type names vehicle type "
                    f"{name!r}, not a type of the fleet ({', '.join(fleet_types)}): its limit "
                    "applies to no AGV (misspelt?)"))]
    return []


def _type_warnings(scenario: Scenario, layout: Layout,
                   vehicle: VehicleProfile) -> list[SetupWarning]:
    battery = vehicle.battery
    if battery is None:
        return []
    rules, charging = scenario.rules, scenario.charging
    out: list[SetupWarning] = []
    if charging.enabled:
        stranded = agvs_without_charger(scenario, layout)
        if stranded:
            stop = max(charging.threshold_pct, rules.bat_low_pct)
            down = battery_hours(vehicle, battery.initial_soc_pct, stop)
            dead = battery_hours(vehicle, stop, rules.bat_critical_pct)
            shown = ", ".join(str(a) for a in stranded[:20]) \
                + (", ..." if len(stranded) > 20 else "")
            why = "the layout has no charger" if not layout.chargers \
                else "no charger is reachable from their start nodes"
            out.append(SetupWarning("no_charger", (
                f"charging is on but {why}: AGV {shown} ({len(stranded)} of "
                f"{scenario.fleet.size}) will run down and stop with E_201: from "
                f"{battery.initial_soc_pct:g} % to the charging threshold {stop:g} %, where "
                f"they stop taking orders, in about {_hours(down.busy_h)} working flat out or "
                f"{_hours(down.idle_h)} idle, then E_201 at {rules.bat_critical_pct:g} % "
                f"{_hours(dead.idle_h)} later")))
        return out
    down = battery_hours(vehicle, battery.initial_soc_pct, rules.bat_low_pct)
    if scenario.duration_h > down.busy_h:
        dead = battery_hours(vehicle, rules.bat_low_pct, rules.bat_critical_pct)
        out.append(SetupWarning("charging_off", (
            f"charging.enabled is false but the battery drains (fleet.vehicle.battery): from "
            f"{battery.initial_soc_pct:g} % an AGV runs down to {rules.bat_low_pct:g} % (P_050) "
            f"and stops taking orders after about {_hours(down.busy_h)} working flat out or "
            f"{_hours(down.idle_h)} idle, then stands until E_201 at "
            f"{rules.bat_critical_pct:g} % {_hours(dead.idle_h)} later; the run is "
            f"{scenario.duration_h:g} h. For no battery model set fleet.vehicle.battery: off")))
    return out


def _hours(hours: float) -> str:
    if hours == 0:
        return "no time"
    return "never" if math.isinf(hours) else f"{hours:.1f} h"
