"""Scenario files -> one typed, frozen, validated config.

Every key has a default written here, with its source: RSS-AGV-001 section 7.1 where the spec
gives a figure, "assumed" where it does not. Unknown keys are errors. The resolved config (every
default written out) is `resolved(scenario)`, saved with each run.

Decisions, where the issue is silent:

* The models are pydantic (`userfiles.checking.StrictModel`): frozen and hashable; copy one with
  ``model_copy(update=...)``. Checks that tie fields together are model validators whose errors
  name the field (``warmup_h``, ``fleet.start_nodes``); checks against the layout are
  `check_against_layout`.
* The scenario file's folder, against which the files it names are resolved, is a private
  attribute (`base_dir`), set from the validation context: no key of the file and not in the
  schema. It takes part in equality (the same text read from two folders may name two
  layouts), not in the hash.
* The resolved config names the layout and the order trace by absolute path, so
  ``fleet-sim run results/<run>/config.resolved.yaml`` reruns the run from any folder.
* Battery traps are warned about, not refused (`setup_warnings`, one line each): "how long
  does the fleet last without charging" is a fair question, and the answer (each AGV runs down
  and stops with E_201) is in the results. ``fleet-sim run`` prints them; ``sweep`` and
  ``size`` print each kind once per experiment (`fleet_sim.config.experiment
  .experiment_warnings`); every run records them in kpis.json (``warnings``).

  - Charging on, but some AGVs cannot reach a charger from where they start (no charger in the
    layout, or none reachable along one-way segments): `agvs_without_charger` names them.
    Warned whatever the run's length: charging that cannot happen is a contradiction in the
    files.
  - Charging off with a battery that drains: warned when the run is long enough for an AGV
    working flat out to reach P_050 (20 %), where it stops taking orders (4.2.2) and stands
    until E_201. A shorter run with charging off is a fair choice and is not warned about.
    No battery model at all is ``fleet.vehicle.battery: off``.

  How long a battery lasts (`battery_hours`): the energy between two SOCs,
  E = (from_pct - to_pct) / 100 x capacity_wh, over a power: standing idle, idle_w; working
  flat out, the larger of handling_w and driving at max_speed_mps with half the distance
  loaded, idle_w + (drive_wh_per_m + drive_loaded_wh_per_m) / 2 x max_speed_mps x 3600 W (the
  controller's idle draw goes on while driving, as in fleet_sim.model.battery). With the
  defaults, 90 % -> 20 % is 672 Wh: 3.4 h flat out (200 W), 33.6 h idle (20 W); 20 % -> 10 %
  standing idle is 4.8 h. Real work lies in between.
* The scenario ``name`` is free text (reports show it, escaped); the default run folder is
  ``results/<folder_name(name)>``, every character outside the experiment name's rule
  (`is_folder_name`) replaced by ``_``, so ``../x`` or ``/abs`` never writes outside
  ``results/``. (Refusing such names would refuse files that load today.)
"""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path
from typing import Annotated, Any, Final, Literal, NamedTuple

import networkx as nx
from pydantic import Field, PrivateAttr, ValidationInfo, field_validator, model_validator
from pydantic.config import JsonDict

from agv_model.link import LinkSettings
from agv_model.profile import Profile as AgvModelProfile
from agv_model.profile import load_profile, profile_names, read_profile
from fleet_sim.config.chains import MAX_STOPS, MIN_STOPS, check_chain
from fleet_sim.config.distributions import ExponentialTime, TimeDistribution, TriangularTime
from fleet_sim.config.layout import Layout, Place, load_layout
from fleet_sim.config.vehicle import VehicleProfile, vehicle_from_profile
from fleet_sim.errors import InputError
from userfiles.checking import (
    HourOfDay,
    Items,
    NonNegative,
    Percent,
    Positive,
    Problem,
    Share,
    StrictModel,
    Text,
    validate,
)
from userfiles.reading import read_yaml

MAX_DURATION_H: Final = 8760.0
"""Longest run: one year of operation; a longer run tells nothing more and runs for days."""
MAX_RATE_PER_HOUR: Final = 100_000.0
"""Highest order rate: ~28 orders a second is beyond any AGV warehouse and would flood memory."""
FOLDER_NAME: Final = "letters, digits, '_', '.', '-', not '.' or '..' (it names the results folder)"
"""What a scenario or experiment name may be: it becomes a folder under results/, so no path."""
MAX_FLEET_SIZE: Final = 2_000
"""Largest fleet: ten times the largest AGV fleets in service; beyond it a run takes hours."""


def is_folder_name(name: str) -> bool:
    """True if `name` can name a folder under results/ without leaving it."""
    return bool(re.fullmatch(r"[A-Za-z0-9_.-]+", name)) and name not in (".", "..")


def folder_name(name: str) -> str:
    """`name` as one folder name under results/: unsafe characters become '_'."""
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", name)
    return safe if is_folder_name(safe) else safe.replace(".", "_") or "scenario"


class CommandLink(NamedTuple):
    """What an AGV's commands go over: the protocol and link of an agv_model profile."""

    profile: str
    protocol: str | None
    """None: the generic RSS-AGV-001 vehicle, whose messages have no stated bytes."""
    link: LinkSettings


def _command_link(name: str, profile: AgvModelProfile) -> CommandLink:
    return CommandLink(name, profile.protocol, profile.link)


class VehicleType(StrictModel):
    """One type of a mixed fleet (`fleet.vehicles`): `count` AGVs of one vehicle profile."""

    type: Text
    """The type's name, as the layout's `allowed_types` and the KPIs (by_type.<type>) say it."""
    count: int = Field(ge=1, le=MAX_FLEET_SIZE)
    profile: Text | None = None
    """An agv_model vehicle profile that fills `vehicle` (fleet_sim.config.vehicle
    .vehicle_from_profile): a bundled one (rss-agv-001, carriro-ad-plus, ktm-02, tabo, agv-3)
    or a profile file, such as one `fleet-sim profile import` wrote from a VDA 5050
    factsheet, relative to the scenario file. Fields given under `vehicle` win over it."""
    vehicle: VehicleProfile = VehicleProfile()
    """The type's kinematics, body, station times and battery (as `fleet.vehicle`)."""
    _command_link: CommandLink | None = PrivateAttr(default=None)
    """The protocol and link of `profile` (none without one); not a key of the file."""

    @property
    def command_link(self) -> CommandLink | None:
        """The protocol and link the type's profile names; None without a profile."""
        return self._command_link

    @model_validator(mode="after")
    def _link_of_profile(self, info: ValidationInfo) -> VehicleType:
        if self.profile is not None:
            base_dir = (info.context or {}).get("base_dir", ".")
            self._command_link = _command_link(self.profile,
                                               _read_agv_profile(self.profile, base_dir))
        return self

    @model_validator(mode="before")
    @classmethod
    def _from_profile(cls, data: Any, info: ValidationInfo) -> Any:
        if not isinstance(data, dict) or not isinstance(data.get("profile"), str):
            return data
        given = data.get("vehicle", {})
        if not isinstance(given, dict):
            return data  # not a mapping: the field's own check names it
        base_dir = (info.context or {}).get("base_dir", ".")
        return {**data, "vehicle": _deep_merge(_profile_fields(data["profile"], base_dir),
                                               given)}


def _profile_fields(name: str, base_dir: str) -> dict[str, Any]:
    """The vehicle fields of profile `name` (bundled, or a file relative to `base_dir`)."""
    return vehicle_from_profile(_read_agv_profile(name, base_dir))


def _read_agv_profile(name: str, base_dir: str) -> AgvModelProfile:
    """Profile `name`: a bundled one, or a file relative to `base_dir`."""
    try:
        if name in profile_names():
            profile = load_profile(name)
        else:
            path = Path(name) if Path(name).is_absolute() else Path(base_dir) / name
            if path.suffix not in (".yaml", ".yml") or not path.is_file():
                raise Problem("profile", name,
                              f"a bundled profile ({', '.join(profile_names())}) or a profile "
                              f"file (.yaml; looked for {path})")
            profile = read_profile(path)
    except InputError as exc:
        raise Problem("profile", name, f"a valid profile file ({exc})") from None
    return profile


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def _off_schema(schema: JsonDict) -> None:
    """Publish ``false`` (YAML ``off``) beside the switch's words."""
    words = schema.pop("enum", None)
    schema.pop("type", None)
    schema["anyOf"] = [{"enum": words, "type": "string"}, {"const": False}]


class FleetConfig(StrictModel):
    size: int = Field(default=4, ge=1, le=MAX_FLEET_SIZE)
    """Number of AGVs; with `vehicles`, the sum of their counts (may be left out)."""
    vehicle: VehicleProfile = VehicleProfile()
    """The vehicle of a one-type fleet; not given with `vehicles`."""
    vehicles: Items[VehicleType] = ()
    """A mixed fleet: types of vehicle and how many of each (AGVs numbered type by type, in
    this order); empty: `size` AGVs of `vehicle`."""
    start_nodes: Items[Text] = ()
    """Where AGVs start, one node each; empty: inside the parking areas, filled in file order."""
    command_timing: Literal["auto", "off"] = Field(default="auto",
                                                   json_schema_extra=_off_schema)
    """auto: the fleet manager's commands to an AGV, its boot report and (granted hop by hop,
    `traffic.grants`) its route permissions take the time its type's profile's protocol and
    link take to carry them, for every type of `vehicles` that names a profile with a
    protocol (fleet_sim.sim.commands); other AGVs' take none. off (false): none take time."""
    command_profile: Text | None = None
    """A one-type fleet: the agv_model vehicle profile whose protocol and link carry every
    command (rss-agv-001, carriro-ad-plus, ktm-02, tabo, agv-3); none: commands take no time.
    A mixed fleet's types name their own (`vehicles[].profile`)."""
    status_poll_s: NonNegative = 0.0
    """The fleet manager polls each AGV this often and learns it is free at the next poll;
    0: AGVs report at once."""

    @field_validator("command_timing", mode="before")
    @classmethod
    def _timing_off(cls, value: Any) -> Any:
        """YAML reads `off` as false."""
        return "off" if value is False else value

    @model_validator(mode="before")
    @classmethod
    def _size_of_mix(cls, data: Any) -> Any:
        """With `vehicles`, `size` is the sum of the counts, and `vehicle` is each type's."""
        if not isinstance(data, dict) or not data.get("vehicles"):
            return data
        if "vehicle" in data:
            raise Problem("vehicle", "given", "no fleet.vehicle with fleet.vehicles (each type "
                                              "has its own vehicle or profile)")
        types = data["vehicles"]
        counts = [t.get("count") for t in types if isinstance(t, dict)] \
            if isinstance(types, list | tuple) else []
        if "size" not in data and counts and len(counts) == len(types) \
                and all(type(c) is int and c >= 1 for c in counts):
            return {**data, "size": sum(counts)}
        return data

    @property
    def agv_types(self) -> tuple[str, ...]:
        """The type of each AGV, in AGV order (one-type fleet: the vehicle's name)."""
        if not self.vehicles:
            return (self.vehicle.name,) * self.size
        return tuple(t.type for t in self.vehicles for _ in range(t.count))

    @property
    def agv_profiles(self) -> tuple[VehicleProfile, ...]:
        """The vehicle profile of each AGV, in AGV order."""
        if not self.vehicles:
            return (self.vehicle,) * self.size
        return tuple(t.vehicle for t in self.vehicles for _ in range(t.count))

    @property
    def type_profiles(self) -> dict[str, VehicleProfile]:
        """Type name -> its vehicle profile, in fleet order."""
        if not self.vehicles:
            return {self.vehicle.name: self.vehicle}
        return {t.type: t.vehicle for t in self.vehicles}

    @property
    def agv_command_links(self) -> tuple[CommandLink | None, ...]:
        """What each AGV's commands go over, in AGV order; None: they take no time.
        `command_profile`: its link for every AGV. Else, `command_timing: auto`: each type's
        profile's, if the profile has a protocol (the generic RSS-AGV-001 profile has none:
        its messages have no stated bytes, so they are timed only when named by
        command_profile)."""
        if self.command_profile is not None:
            name = self.command_profile
            return (_command_link(name, load_profile(name)),) * self.size
        if self.command_timing == "off" or not self.vehicles:
            return (None,) * self.size
        links = [t.command_link if t.command_link is not None
                 and t.command_link.protocol is not None else None for t in self.vehicles]
        return tuple(link for t, link in zip(self.vehicles, links, strict=True)
                     for _ in range(t.count))

    @property
    def max_speed_mps(self) -> float:
        """The fastest type's top speed (segment limits above it are refused)."""
        return max(p.max_speed_mps for p in self.type_profiles.values())

    @model_validator(mode="after")
    def _consistent(self) -> FleetConfig:
        if self.vehicles:
            total = sum(t.count for t in self.vehicles)
            if self.size != total:
                raise Problem("size", self.size, f"the sum of fleet.vehicles' counts ({total}); "
                              "leave fleet.size out with fleet.vehicles (to vary one type's "
                              "count: fleet.vehicles.<type>.count, e.g. "
                              f"{type_count_path(self.vehicles[-1].type)})")
            names = [t.type for t in self.vehicles]
            for i, name in enumerate(names):
                if name in names[:i]:
                    raise Problem(f"vehicles[{i}].type", name, "a type named once")
        if self.start_nodes and len(self.start_nodes) < self.size:
            raise Problem("start_nodes", list(self.start_nodes),
                          f"at least one start node per AGV ({self.size})")
        if self.command_profile is not None and self.command_profile not in profile_names():
            raise Problem("command_profile", self.command_profile,
                          f"one of {', '.join(profile_names())}")
        if self.command_profile is not None and self.vehicles:
            raise Problem("command_profile", self.command_profile,
                          "no command_profile with fleet.vehicles: each type's commands go "
                          "over its own profile's protocol and link (fleet.vehicles[].profile;"
                          " fleet.command_timing: off for commands that take no time)")
        if self.command_profile is not None and self.command_timing == "off":
            raise Problem("command_timing", "off",
                          "auto with fleet.command_profile (which times every command on its "
                          "link); leave command_profile out for commands that take no time")
        if len(set(self.start_nodes)) != len(self.start_nodes):
            raise Problem("start_nodes", list(self.start_nodes),
                          "distinct nodes (one AGV per node)")
        return self


class Flow(StrictModel):
    """An order flow: plain orders from one pickup to one dropoff (`from`, `to`), or chains of
    stops (`stops`, fleet_sim.config.chains), one or the other."""

    from_station: Text | None = Field(default=None, alias="from")
    to_station: Text | None = Field(default=None, alias="to")
    weight: Positive = 1.0
    stops: Items[Text] = ()
    """A multi-stop order: stations alternating pickup, dropoff, pickup, dropoff... (an even
    number, 2 to 20); empty: the plain order `from` -> `to`."""

    @model_validator(mode="after")
    def _from_to_or_stops(self) -> Flow:
        if self.stops:
            if self.from_station is not None or self.to_station is not None:
                raise Problem("stops", list(self.stops), "either from and to, or stops, not both")
            if not MIN_STOPS <= len(self.stops) <= MAX_STOPS or len(self.stops) % 2:
                raise Problem("stops", list(self.stops),
                              f"an even number of stops from {MIN_STOPS} to {MAX_STOPS} "
                              "(pickup, dropoff, pickup, dropoff...)")
        elif self.from_station is None or self.to_station is None:
            missing = "from" if self.from_station is None else "to"
            raise Problem(missing, None, "a station (a flow has from and to, or stops)")
        return self

    @property
    def chain(self) -> tuple[str, ...]:
        """The flow's stops: `stops`, or (from, to)."""
        if self.stops:
            return self.stops
        assert self.from_station is not None and self.to_station is not None
        return (self.from_station, self.to_station)


class RatePeriod(StrictModel):
    from_h: HourOfDay
    """Time of day (hours, 0-24) from which `multiplier` applies, until the next period."""
    multiplier: NonNegative


class DemandConfig(StrictModel):
    kind: Literal["poisson", "trace"] = "poisson"
    rate_per_hour: float = Field(default=60.0, ge=0, le=MAX_RATE_PER_HOUR)
    """Mean orders per hour at multiplier 1 (poisson)."""
    flows: Items[Flow] = ()
    """Order flows between stations; empty: every pickup to every dropoff, equal weights."""
    profile: Items[RatePeriod] = ()
    """Time-of-day rate multipliers, repeating daily; empty: constant rate."""
    trace_csv: Text | None = None
    """Order trace (columns time_s, pickup, dropoff), relative to the scenario file."""

    @model_validator(mode="after")
    def _consistent(self) -> DemandConfig:
        if self.kind == "trace" and self.trace_csv is None:
            raise Problem("trace_csv", None,
                          "the path of an order trace CSV when kind is 'trace'")
        hours = [p.from_h for p in self.profile]
        if hours and (hours[0] != 0 or hours != sorted(set(hours))):
            raise Problem("profile", hours, "periods in increasing from_h, the first at 0")
        return self

    def multiplier_at(self, hour_of_day: float) -> float:
        value = 1.0
        for period in self.profile:
            if period.from_h <= hour_of_day:
                value = period.multiplier
        return value

    @property
    def max_multiplier(self) -> float:
        return max((p.multiplier for p in self.profile), default=1.0)


class DispatchConfig(StrictModel):
    policy: Literal["nearest_idle", "fcfs"] = "nearest_idle"
    """nearest_idle: each order, oldest first, to the idle AGV with the shortest travel time to
    its pickup. fcfs: each order, oldest first, to the AGV that has been idle longest."""
    park_idle: bool = True
    """Send AGVs with nothing to do to the nearest parking area with room."""
    max_active_agvs: Annotated[int, Field(ge=1, le=MAX_FLEET_SIZE)] | Literal["auto"] | None \
        = None
    """Admission: at most this many AGVs on the track at once (driving, handling, charging,
    or standing outside parking); the others wait in parking until one parks. `auto`: the
    layout's critical fleet, the AGVs that keep its busiest corridor, zone or node busy at
    free-flow speed under the order flows (fleet_sim.sim.estimate.bottleneck). None (not
    given): no limit under `traffic.policy: reactive` (RSS-AGV-001 has no such rule), `auto`
    under `avoiding`. See fleet_sim.sim.agents.fleet_manager."""

    @field_validator("max_active_agvs", mode="before")
    @classmethod
    def _limit_or_auto(cls, value: Any) -> Any:
        """One message for both forms: a whole number in range, or `auto`."""
        if value is None or value == "auto" or (
                isinstance(value, int) and not isinstance(value, bool)
                and 1 <= value <= MAX_FLEET_SIZE):
            return value
        raise Problem("", value, f"an integer in [1, {MAX_FLEET_SIZE}], or auto (the layout's "
                      "critical fleet)")


class TrafficConfig(StrictModel):
    grants: Literal["auto", "per_hop", "whole_route"] = "auto"
    """How the fleet manager gives an AGV whose commands take time (fleet.command_timing,
    fleet.command_profile) its route: `per_hop`, each hop traffic grants is a permission
    message (the protocol's resume) the AGV must have before it drives the hop; `whole_route`,
    the order carries the route and traffic's grants cost no message; `auto` (default): as
    its protocol's document has it, hop by hop for KTM-02 and TABO (motion commands only, no
    route), the whole route for CarriRo AD+, AGV-3 and RSS-AGV-001
    (agv_model.fleet_commands.GRANTS_PER_HOP)."""
    policy: Literal["reactive", "avoiding"] = "reactive"
    """How traffic control keeps the fleet from locking solid. `reactive` (default): locks are
    granted when free, wait-for cycles are found and broken (one AGV reroutes or backs off).
    `avoiding`: a node, corridor or zone is granted only when the grant cannot close a cycle of
    waits (a Banker's-type check on every AGV's declared plan, which ends in parking;
    fleet_sim.sim.traffic.avoidance, docs/background/engine.md), and, unless
    dispatch.max_active_agvs says otherwise, at most the layout's critical fleet is admitted
    onto the track (`auto`)."""
    deadlock_check_s: Positive = 10.0
    """How often an AGV that is still blocked looks again for a wait-for cycle."""
    replan_after_s: Positive = 30.0
    """Blocked this long, an AGV takes another route if one exists."""
    give_way_after_s: Positive = 10.0
    """Blocked this long with another AGV queued behind it, an AGV drives on and comes back
    round rather than block the way (assumed; see fleet_sim.sim.traffic.control)."""
    backoff_s: Positive = 5.0
    """Mean wait before a deadlocked AGV that cannot move tries again."""
    gridlock_after_s: Positive = 600.0
    """An unresolved wait-for cycle, or no AGV moving while orders are open and AGVs wait for
    locks, that lasts this long is a gridlock: the run records it (event `gridlock`, KPI
    gridlock_at_h) and its summary warns (fleet_sim.sim.gridlock says why 10 minutes)."""
    congestion_cost_s: float = Field(default=0.0, ge=0, le=3600)
    """Route cost (seconds) added per AGV standing on or queued for the node a segment leads
    to, when the route is planned: routes go round congested segments. 0 (default): shortest
    free-flow routes, as the spec has them."""
    weak_wifi_cost_s: float = Field(default=0.0, ge=0, le=3600)
    """Route cost (seconds) added per segment whose Wi-Fi signal is below
    rules.weak_rssi_dbm: routes keep off weak-Wi-Fi segments where there is another way. 0
    (default): off."""


class Rules(StrictModel):
    """Thresholds and timings of RSS-AGV-001, each configurable, each defaulting to the spec."""

    bat_low_pct: Percent = 20.0
    """P_050 BAT_LOW_TH: Idle -> Moving only above it (4.2.2); Event_Low_Battery at it."""
    bat_critical_pct: Percent = 10.0
    """P_051 BAT_CRIT_TH: below it the AGV shuts down with E_201."""
    charge_done_pct: Percent = 95.0
    """4.2.10: charging ends once SOC > 95 %."""
    safe_mode_soc_pct: Percent = 15.0
    """4.2.14 / 6.3."""
    safe_mode_rssi_dbm: float = -80.0
    """4.2.14."""
    safe_mode_draw_w: NonNegative = 2.0
    """Assumed: the draw in SafeMode, drive relay off and the controller in deep sleep (6.3;
    the document gives no figure): a beacon and the sleeping controller."""
    obstacle_pause_s: NonNegative = 0.3
    """4.2.3: obstacle within 1.0 m for >= 300 ms."""
    obstacle_clear_s: NonNegative = 2.0
    """4.2.4: path clear for >= 2000 ms."""
    obstacle_timeout_s: NonNegative = 300.0
    """6.1 E_101: paused for 5 minutes."""
    obstacle_slow_speed_mps: Positive = 0.3
    """Assumed: creep speed inside the detection zone."""
    lds_stop_m: Positive = 1.0
    """4.2.3: the LDS pauses the AGV for an obstacle closer than this."""
    lds_clear_m: Positive = 1.2
    """4.2.4: the way counts as clear beyond this."""
    lds_slow_m: Positive = 1.5
    """P_005: the LDS's detection (slowing) zone."""
    agv_ahead: Literal["lds", "held_back"] = "lds"
    """The AGV ahead in a queue: ``lds`` (default, the document as written) closes up to
    `min_gap_m` (P_006) and is paused by its LDS like any obstacle (4.2.3/4.2.4, E_101 after
    5 minutes); ``held_back``: the fleet manager keeps AGVs `lds_slow_m` apart, so the LDS
    never sees one (fleet_sim.sim.agents.lds)."""
    comm_policy: Literal["req_err_011", "timeout_60s"] = "req_err_011"
    """FMS heartbeat loss: Req.Err.011 (default, fleet_sim's reading) or 4.2.11's 60 s to Error."""
    comm_timeout_s: NonNegative = 60.0
    """4.2.11: communication timeout to Error (policy timeout_60s; internal links always)."""
    reconnect_timeout_s: NonNegative = 600.0
    """Req.Err.011: Error after 10 minutes without reconnecting."""
    heartbeat_timeout_s: NonNegative = 3.0
    """Assumed: the FMS and the AGV notice a lost link after 3 missed 1-s heartbeats."""
    comm_loss_speed_mps: Positive = 0.3
    """Assumed: the slow mode of Req.Err.011."""
    link_min_rssi_dbm: float = -80.0
    """Assumed: no Wi-Fi link below this signal (the 4.2.14 threshold)."""
    weak_rssi_dbm: float = -70.0
    """Assumed: E_002 (Wi-Fi signal low, warning) below this signal."""
    line_keep_heading_m: NonNegative = 0.5
    """Req.Err.010: keep the last heading for up to 50 cm looking for the tape."""
    marker_pause_s: NonNegative = 3.0
    """5.3 TYPE_CMD 0x20: pause 3 s."""

    @model_validator(mode="after")
    def _critical_below_low(self) -> Rules:
        if self.bat_critical_pct >= self.bat_low_pct:
            raise Problem("bat_critical_pct", self.bat_critical_pct,
                          f"below bat_low_pct ({self.bat_low_pct})")
        return self


class ChargingConfig(StrictModel):
    enabled: bool = True
    threshold_pct: Percent = 30.0
    """Assumed policy: an AGV with nothing to do goes to charge at or below this SOC."""
    opportunity: bool = False
    """Charge while idle whenever a charger is free and SOC is below opportunity_below_pct."""
    opportunity_below_pct: Percent = 80.0
    schedule_h: Items[HourOfDay] = ()
    """Clock hours (0-24) at which every AGV goes to charge once it is free (scheduled)."""


class SegmentBlock(StrictModel):
    """A scripted obstacle: the segment between two nodes is blocked for a while."""

    from_node: Text = Field(alias="from")
    to_node: Text = Field(alias="to")
    at_s: NonNegative = 0.0
    duration_s: NonNegative = 900.0


class LinkLoss(StrictModel):
    """A scripted Wi-Fi loss: AGV `agv` loses the FMS link at `at_s` for `duration_s`."""

    agv: int
    at_s: NonNegative
    duration_s: NonNegative


class Fault(StrictModel):
    """A scripted fault: AGV `agv` raises `code` at `at_s`."""

    agv: int
    at_s: NonNegative
    code: Literal["E_101", "E_102", "E_201", "E_202", "E_999", "E_301"] = "E_999"


class IncidentsConfig(StrictModel):
    obstacle_rate_per_km: NonNegative = 0.0
    """People and forklifts met per km driven (layout zones may set their own)."""
    obstacle_duration: TimeDistribution = ExponentialTime(dist="exponential", mean_s=4.0)
    """How long an obstacle stays within range (assumed: exponential, mean 4 s)."""
    blocks: Items[SegmentBlock] = ()
    link_loss_rate_per_h: NonNegative = 0.0
    """Random FMS link losses per AGV and hour (dead spots come from the layout's RSSI)."""
    link_loss_duration: TimeDistribution = ExponentialTime(dist="exponential", mean_s=30.0)
    link_losses: Items[LinkLoss] = ()
    internal_link_loss_rate_per_h: NonNegative = 0.0
    """Losses of the vehicle's internal links (sensor bus); > comm_timeout_s means Error."""
    internal_link_loss_duration: TimeDistribution = ExponentialTime(dist="exponential",
                                                                    mean_s=20.0)
    mtbf_h: NonNegative = 0.0
    """Mean operating hours between random critical faults (E_999) per AGV; 0: none."""
    transfer_failure_prob: Share = 0.0
    """Chance that a load transfer fails (E_102)."""
    line_loss_per_km: NonNegative = 0.0
    """Times per km an AGV loses the tape (Req.Err.010)."""
    line_found_prob: Share = 0.8
    """Assumed: share of line losses where the tape is found again within 50 cm (E_001)."""
    line_search_s: float = 2.0
    """Assumed: time lost finding the tape again."""
    faults: Items[Fault] = ()
    cpu_reset: Literal["reboot", "operator"] = "reboot"
    """E_999 (CPU exception, watchdog reset; RSS-AGV-001 6.1): ``reboot`` (default) restarts
    the AGV through Booting (POST, the start-up report) where it stands, its position unknown
    until it reads a TYPE_LOC tag; ``operator``: like any Error, an operator and
    Maintenance."""
    operator_response: TimeDistribution = TriangularTime(dist="triangular", low_s=60.0,
                                                         mode_s=180.0, high_s=600.0)
    """Assumed: time until an operator reaches a failed AGV and turns it to MANUAL."""
    repair: TimeDistribution = TriangularTime(dist="triangular", low_s=120.0, mode_s=300.0,
                                              high_s=1200.0)
    """Assumed: time in Maintenance."""
    relocalise_s: NonNegative = 10.0
    """Assumed: initial position estimation on return to AUTO (4.2.13)."""
    rescue: TimeDistribution = TriangularTime(dist="triangular", low_s=300.0, mode_s=900.0,
                                              high_s=1800.0)
    """Assumed: time until an operator rescues an AGV in SafeMode."""
    rescue_soc_pct: float = 50.0
    """Assumed: SOC an operator leaves a rescued or shut-down AGV with (manual charge)."""


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
    fleet_sim.sim.motion.sumo, stepping with SimPy; dispatching, states, charging, incidents and
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

VEHICLE_TYPES: Final = "fleet.vehicles"
"""Where a mixed fleet's types are; an override enters one by its name:
``fleet.vehicles.<type>.count``."""


def type_count_path(vehicle_type: str) -> str:
    """The dotted path (override, factor) of a mixed fleet's count of `vehicle_type`."""
    return f"{VEHICLE_TYPES}.{vehicle_type}.count"


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


def load_layout_for(scenario: Scenario, scenario_file: str) -> Layout:
    """Load the scenario's layout and check the scenario against it."""
    layout_path = scenario.path(scenario.layout)
    if not layout_path.exists():
        raise InputError(scenario_file, "layout", scenario.layout,
                         f"an existing layout file (looked for {layout_path})")
    layout = load_layout(layout_path, max_speed_mps=scenario.fleet.max_speed_mps)
    check_against_layout(scenario, layout, scenario_file)
    return layout


def check_against_layout(scenario: Scenario, layout: Layout, file: str) -> None:
    for i, flow in enumerate(scenario.demand.flows):
        if flow.stops:
            check_chain(flow.stops, layout, file, f"demand.flows[{i}].stops")
            continue
        for key, station, kind in (("from", flow.from_station, "pickup"),
                                   ("to", flow.to_station, "dropoff")):
            assert station is not None
            place = layout.places.get(station)
            if place is None or place.kind != kind:
                names = ", ".join(p.id for p in layout.places.values() if p.kind == kind)
                raise InputError(file, f"demand.flows[{i}].{key}", station,
                                 f"a {kind} station of layout {layout.name} ({names})")
    for i, node in enumerate(scenario.fleet.start_nodes):
        if node not in layout.graph:
            raise InputError(file, f"fleet.start_nodes[{i}]", node,
                             f"a node of layout {layout.name}")
    for i, block in enumerate(scenario.incidents.blocks):
        if not layout.graph.has_edge(block.from_node, block.to_node):
            raise InputError(file, f"incidents.blocks[{i}]",
                             f"{block.from_node} -> {block.to_node}",
                             f"a segment of layout {layout.name}")
    numbered = [("link_losses", i, x.agv) for i, x in enumerate(scenario.incidents.link_losses)]
    numbered += [("faults", i, x.agv) for i, x in enumerate(scenario.incidents.faults)]
    for key, i, agv in numbered:
        if not 0 <= agv < scenario.fleet.size:
            raise InputError(file, f"incidents.{key}[{i}].agv", agv,
                             f"an AGV number from 0 to {scenario.fleet.size - 1}")
    if not scenario.fleet.start_nodes:
        room = sum(p.capacity for p in layout.parking)
        if scenario.fleet.size > room:
            raise InputError(file, "fleet.size", scenario.fleet.size,
                             f"at most the parking capacity of layout {layout.name} ({room}), "
                             "or fleet.start_nodes for the rest")
    _check_types(scenario, layout, file)
    _check_vehicles_fit(scenario, layout, file)


def _check_vehicles_fit(scenario: Scenario, layout: Layout, file: str) -> None:
    """Every vehicle type fits the track it drives: an AGV coming back to a place it serves
    (station, charger, parking) must have left it behind, that is have driven at least its
    `length_m` + `min_gap_m` since (the stretch it holds behind itself,
    fleet_sim.sim.agents.driving). Else it waits for itself there for ever: a vehicle longer
    than the whole loop ran with no order delivered and no deadlock reported.

    Refused only where it is certain on the layout's shortest ways: for a place's node x, the
    way back in is from one of x's predecessors u, reached from x after at least d(x, u) m
    (shortest path, the type's own track); a type is refused when every such u is nearer than
    its length plus gap. So the limit on the tiny loop (48 m, tags every 4 m) is 44 m of
    length plus gap, which the simulation bears out (43.5 m runs, 44.5 m stands still). The
    search goes no further from x than that length plus gap, so it costs next to nothing for
    real vehicles."""
    fleet = scenario.fleet
    for i, (name, profile) in enumerate(fleet.type_profiles.items()):
        clear_m = profile.length_m + profile.min_gap_m
        graph = layout.type_graph(name) if layout.restricts_types else layout.graph
        places = [p for p in layout.places.values()
                  if p.kind == "parking" or (p.kind == "charger" and scenario.charging.enabled)
                  or (p.kind in ("pickup", "dropoff") and p.serves(name))]
        tightest: tuple[float, Place, str] | None = None
        for place in places:
            for node in place.nodes:
                ways_in = [u for u in graph.predecessors(node) if u != node]
                if not ways_in:
                    continue
                near = nx.single_source_dijkstra_path_length(graph, node, cutoff=clear_m,
                                                             weight="length_m")
                if not all(u in near and near[u] < clear_m - 1e-9 for u in ways_in):
                    continue
                room_m = max(near[u] for u in ways_in)
                if tightest is None or room_m < tightest[0]:
                    tightest = (room_m, place, node)
        if tightest is not None:
            room_m, place, node = tightest
            where = f"fleet.vehicles[{i}].vehicle.length_m" if fleet.vehicles \
                else "fleet.vehicle.length_m"
            raise InputError(file, where, profile.length_m,
                             f"a vehicle that fits the track of layout {layout.name}: at most "
                             f"{max(room_m - profile.min_gap_m, 0.0):g} m (an AGV coming back "
                             f"to {place.kind} {place.id}, node {node}, has driven at most "
                             f"{room_m:g} m since it left it, and its length plus min_gap_m "
                             f"{profile.min_gap_m:g} m must be clear of it)")


def _check_types(scenario: Scenario, layout: Layout, file: str) -> None:
    """Where the layout closes segments or stations to some vehicle types: every type can
    drive between all parking areas, chargers (charging on), its AGVs' start nodes and the
    stations it may serve; and every flow has a type that may serve both its stations."""
    if not layout.restricts_types:
        return
    fleet = scenario.fleet
    starts = agv_start_nodes(scenario, layout)
    for i, name in enumerate(fleet.type_profiles):
        where = f"fleet.vehicles[{i}].type" if fleet.vehicles else "fleet.vehicle.name"
        must = [(f"parking {p.id}", p.nodes[0]) for p in layout.parking]
        if scenario.charging.enabled:
            must += [(f"charger {c.id}", c.nodes[0]) for c in layout.chargers]
        must += [(f"station {p.id}", n) for p in layout.pickups + layout.dropoffs
                 if p.serves(name) for n in p.nodes]
        must += [(f"the start of AGV {agv}", node) for agv, (node, kind)
                 in enumerate(zip(starts, fleet.agv_types, strict=False)) if kind == name]
        graph = layout.type_graph(name)
        anchor = must[0][1]
        both_ways = (nx.descendants(graph, anchor) | {anchor}) \
            & (nx.ancestors(graph, anchor) | {anchor})
        for what, node in must:
            if node not in both_ways:
                raise InputError(file, where, name,
                                 f"a vehicle type that can drive to and from {what} (node "
                                 f"{node}) and parking {layout.parking[0].id} on layout "
                                 f"{layout.name}; the segments' allowed_types cut it off")
    names = tuple(fleet.type_profiles)
    for i, flow in enumerate(scenario.demand.flows):
        if flow.stops:
            if not chain_serving_types(layout, flow.stops, names):
                raise InputError(file, f"demand.flows[{i}].stops", " -> ".join(flow.stops),
                                 "stops that one vehicle type of the fleet "
                                 f"({', '.join(names)}) may serve all of (stations' "
                                 "allowed_types)")
            continue
        assert flow.from_station is not None and flow.to_station is not None
        if not serving_types(layout, flow.from_station, flow.to_station, names):
            raise InputError(file, f"demand.flows[{i}]", f"{flow.from_station} -> "
                             f"{flow.to_station}", "stations that one vehicle type of the "
                             f"fleet ({', '.join(names)}) may serve both of (stations' "
                             "allowed_types)")
    if not scenario.demand.flows and not any(
            serving_types(layout, p.id, d.id, names)
            for p in layout.pickups for d in layout.dropoffs):
        raise InputError(file, "demand.flows", [], "flows, or a pickup and a dropoff station "
                         f"that one vehicle type of the fleet ({', '.join(names)}) may serve")


def serving_types(layout: Layout, pickup: str, dropoff: str,
                  types: tuple[str, ...]) -> tuple[str, ...]:
    """The types among `types` that may serve both stations."""
    a, b = layout.places[pickup], layout.places[dropoff]
    return tuple(t for t in types if a.serves(t) and b.serves(t))


def chain_serving_types(layout: Layout, stops: tuple[str, ...],
                        types: tuple[str, ...]) -> tuple[str, ...]:
    """The types among `types` that may serve every stop of a chain."""
    places = [layout.places[s] for s in stops]
    return tuple(t for t in types if all(p.serves(t) for p in places))


def agv_start_nodes(scenario: Scenario, layout: Layout) -> list[str]:
    """The node each AGV starts on, in AGV order, as the engine places them: the scenario's
    start nodes, else the parking areas' slots in file order."""
    if scenario.fleet.start_nodes:
        return list(scenario.fleet.start_nodes[:scenario.fleet.size])
    slots = [p.nodes[0] for p in layout.parking for _ in range(p.capacity)]
    return slots[:scenario.fleet.size]


def agvs_without_charger(scenario: Scenario, layout: Layout) -> list[int]:
    """The AGVs (numbers) that cannot drive to any charger from their start, if charging is on;
    empty when charging is off or there is no battery model."""
    if not scenario.charging.enabled:
        return []
    chargers = {n for c in layout.chargers for n in c.nodes}
    stranded: list[int] = []
    reach: dict[str, bool] = {}
    profiles = scenario.fleet.agv_profiles
    for agv, node in enumerate(agv_start_nodes(scenario, layout)):
        if profiles[agv].battery is None:
            continue
        if node not in reach:
            reach[node] = node in layout.graph and bool(
                chargers & (nx.descendants(layout.graph, node) | {node}))
        if not reach[node]:
            stranded.append(agv)
    return stranded


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
    else:  # a one-type fleet's resolved config is written as it always was
        del fleet["vehicles"]
    return plain
