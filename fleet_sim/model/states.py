"""The ten vehicle states of RSS-AGV-001 section 4.1 (ST_001 ... ST_010).

The engine records every change of state with its trigger (the spec's event names, such as
Event_Transport_Order). The transition table of section 4.2 is fleet_sim.model.state_machine.
"""

from __future__ import annotations

from enum import Enum


class VehicleState(Enum):
    BOOTING = "Booting"
    IDLE = "Idle"
    MOVING = "Moving"
    LOADING = "Loading"
    UNLOADING = "Unloading"
    CHARGING = "Charging"
    PAUSED = "Paused"
    ERROR = "Error"
    MAINTENANCE = "Maintenance"
    SAFE_MODE = "SafeMode"

    @property
    def spec_id(self) -> str:
        """The spec's id, ST_001 ... ST_010."""
        return f"ST_{list(VehicleState).index(self) + 1:03d}"

    @property
    def key(self) -> str:
        """Lower-case name for KPI keys (``state_moving_pct``)."""
        return self.name.lower()
