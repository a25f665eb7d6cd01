"""The AGV's FMS link: what it does when the link is lost and when it is back.

Req.Err.011 (the default `rules.comm_policy`): a lost heartbeat is noticed after
`heartbeat_timeout_s`; the AGV drives on slowly to the next tag, waits in Idle, resumes when the
link is back, and raises an Error after 10 minutes. Policy `timeout_60s` (4.2.11) instead raises
an Error after 60 s. Segments below `link_min_rssi_dbm` are dead spots
(fleet_sim.sim.agents.vehicle_travel). A lost AGV takes no new orders and keeps the order it
carries.
"""

from __future__ import annotations

from fleet_sim.sim.agents.driving import Proc
from fleet_sim.sim.agents.vehicle_base import VehicleBase


class VehicleLink(VehicleBase):
    """Driving under the FMS link rules, waiting for the link, and the link's losses."""

    def _drive_to(self, goal: str) -> Proc:
        """Drive to `goal`; under Req.Err.011, stop at the next tag when the FMS link is lost,
        wait in Idle, and drive on when it is back (Error after 10 minutes)."""
        while True:
            if self.rules.comm_policy == "req_err_011":
                if not self.fms_link:  # no route from the FMS: do not set off
                    yield from self._wait_for_link()
                    continue
                yield from self.drive(goal, stop_early=lambda: not self.fms_link)
            else:
                yield from self.drive(goal)
            if self.node == goal:
                return
            yield from self._wait_for_link()

    def _wait_for_link(self) -> Proc:
        self.fire("Event_Heartbeat_Lost", "Req.Err.011: waiting at the nearest tag")
        lost = self.env.now
        while not self.fms_link:
            left = self.rules.reconnect_timeout_s - (self.env.now - lost)
            if left <= 0:
                self.fail_now("E_301")
            yield self.link_changed | self.env.timeout(left)
        yield from self.fleet.resume(self)
        if self.fire("Event_Heartbeat_Restored", "link back"):
            return
        # may not move on (SOC at or below P_050): on the way to the charger it holds, drive on
        # to it (as when it first set off); on any other trip, charge first, then resume it
        if self.charger is not None:
            self.fire(self._charge_trigger(),
                      f"to_charger {self.charger.id} soc {self.soc_pct:.1f} (link back)")
            return
        yield from self._charge()
        self.fire("Event_Transport_Order", "resume after charging")

    def set_link(self, down_delta: int) -> None:
        """An FMS link loss starts (+1) or ends (-1); wakes an AGV waiting for the link."""
        self.links_down += down_delta
        self._link_changed()
        self.fleet.status_changed(self)

