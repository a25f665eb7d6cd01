"""How a scenario's fleet is run: the fleet manager's dispatch and admission (`dispatch:`),
traffic control (`traffic:`) and the charging policy (`charging:`)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator

from fleet_sim.config.scenario_fleet import MAX_FLEET_SIZE
from userfiles.checking import HourOfDay, Items, Percent, Positive, Problem, StrictModel


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


class ChargingConfig(StrictModel):
    enabled: bool = True
    threshold_pct: Percent = 30.0
    """Assumed policy: an AGV with nothing to do goes to charge at or below this SOC."""
    opportunity: bool = False
    """Charge while idle whenever a charger is free and SOC is below opportunity_below_pct."""
    opportunity_below_pct: Percent = 80.0
    schedule_h: Items[HourOfDay] = ()
    """Clock hours (0-24) at which every AGV goes to charge once it is free (scheduled)."""
