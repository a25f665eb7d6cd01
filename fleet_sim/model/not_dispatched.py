"""Why an AGV stands Idle while orders wait: the reasons the fleet manager records.

Work conservation is a checked invariant of the model: whenever at least one order waits
unassigned in the fleet manager's queue and an AGV is in state Idle (ST_002), the fleet manager
either assigns it an order or records why not. It records an event `NOT_DISPATCHED` (detail: the
reason) when such a spell starts or its reason changes, and `NOT_DISPATCHED_END` (detail: the
reason that ended) when the AGV leaves Idle, gets an order, or no order waits any more. So at
every moment of positive length at which an AGV is Idle while an order waits, one reason is open
for it; the dispatch latency is zero (the waits of the status poll and of the command link are
reasons of their own). The KPI `idle_with_orders_waiting_pct` and its breakdown by reason
(fleet_sim.analysis.kpis) are computed from these spells.

"Idle" is the state machine's Idle, whatever the AGV holds: an AGV waiting at a tag for the FMS
link with its order (Req.Err.011), or one whose assign command is still on its way, stands Idle
too, and its reason says so.

To add a reason (zones that are full...): add a member here
with its meaning; the KPI catalogue, kpis.json and the report pick it up. The fleet manager
decides the reason (`FleetManager._reason`), or the AGV gives it when it withdraws.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Final

NOT_DISPATCHED: Final = "not_dispatched"
"""Event: an AGV stands Idle while orders wait, for the reason in its detail (or a new one)."""
NOT_DISPATCHED_END: Final = "not_dispatched_end"
"""Event: the spell of the reason in its detail is over."""


class NotDispatched(StrEnum):
    """Why an Idle AGV is not given a waiting order (the detail of a not_dispatched event)."""

    WAITING_FOR_CHARGER = "waiting_for_charger"
    BATTERY_LOW = "battery_low"
    LINK_LOST = "link_lost"
    STATUS_POLL = "status_poll"
    COMMAND_IN_TRANSIT = "command_in_transit"
    TYPE_NOT_ALLOWED = "type_not_allowed"
    ADMISSION_FULL = "admission_full"

    @property
    def meaning(self) -> str:
        return MEANINGS[self]


MEANINGS: Final[dict[NotDispatched, str]] = {
    NotDispatched.WAITING_FOR_CHARGER:
        "it asked for a charger (SOC at the charging threshold, or a scheduled charge) and "
        "none is free or reachable yet",
    NotDispatched.BATTERY_LOW:
        "SOC at or below P_050 (20 %) with charging off: it may not move (4.2.2) and stands "
        "until E_201",
    NotDispatched.LINK_LOST:
        "no FMS link (heartbeat lost or a Wi-Fi dead spot): the fleet manager cannot reach it",
    NotDispatched.STATUS_POLL:
        "it is free, but the fleet manager learns it only at its next status poll "
        "(fleet.status_poll_s)",
    NotDispatched.COMMAND_IN_TRANSIT:
        "an order or a resume command is on its way over the command link, or the AGV's "
        "boot report (its type's profile's protocol, or fleet.command_profile)",
    NotDispatched.TYPE_NOT_ALLOWED:
        "its vehicle type may not serve the stations of any waiting order (mixed fleets, "
        "`allowed_types` in the layout)",
    NotDispatched.ADMISSION_FULL:
        "it stands in parking and the track already holds dispatch.max_active_agvs AGVs "
        "(admission control)",
}
