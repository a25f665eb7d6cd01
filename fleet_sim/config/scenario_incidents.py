"""What disturbs a scenario's fleet (`incidents:`): obstacles, link losses, faults, line
losses and scripted blocks, with the operator's and repair times that follow."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from fleet_sim.config.distributions import ExponentialTime, TimeDistribution, TriangularTime
from userfiles.checking import Items, NonNegative, Share, StrictModel, Text


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
