"""The rules of RSS-AGV-001 a scenario may set (`rules:`): thresholds and timings, each
defaulting to the spec's figure (section 7.1) or marked assumed."""

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from userfiles.checking import NonNegative, Percent, Positive, Problem, StrictModel


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
