"""The AGV's faults and the recovery from them: Error, the operator, SafeMode, the reboot.

Line loss (Req.Err.010), transfer failure (E_102), random critical faults (MTBF) and scripted
ones: Error, an operator comes (Event_Switch_Manual -> Maintenance, the AGV is taken off the
track), repairs it, and switches back to AUTO (-> Idle after position re-estimation). An order
not yet loaded goes back to the queue; a loaded one is recorded as failed. SafeMode per
4.2.14/6.3; only an operator rescue brings an AGV back from it. E_999 under
`incidents.cpu_reset: reboot`: the watchdog reboots the AGV where it stands, and one whose
position is then unknown finds it at the nearest TYPE_LOC tag (`_locate`).
"""

from __future__ import annotations

import math
from collections.abc import Generator
from typing import Any

import networkx as nx
import simpy

from fleet_sim.model.error_codes import describe
from fleet_sim.sim.agents.driving import Proc
from fleet_sim.sim.agents.vehicle_base import Failure, VehicleBase


class VehicleFaults(VehicleBase):
    """Error and what follows it: the operator, Maintenance, SafeMode, the watchdog's reboot."""

    def _recovery_node(self) -> str:
        """Where the operator puts the AGV back on the track: where it failed, or, if there is
        no Wi-Fi there, the nearest node (by driving time) that has it."""
        graph = self.traffic.graph
        limit = self.rules.link_min_rssi_dbm

        def has_link(node: str) -> bool:
            return max((float(d["rssi_dbm"]) for _, _, d in graph.out_edges(node, data=True)),
                       default=limit) >= limit

        if has_link(self.node):
            return self.node
        times = nx.single_source_dijkstra_path_length(graph, self.node, weight=self.routes.weight)
        good = [n for n in sorted(times, key=lambda n: (times[n], n)) if has_link(n)]
        return good[0] if good else self.node

    def _wait_in_error(self) -> Generator[simpy.Event, Any, bool]:
        """Wait in Error for the operator; SafeMode's conditions (4.2.14, 6.3) are looked at
        again whenever one of them may have changed: the FMS link (lost or back) and the
        state of charge falling below its threshold (the idle draw goes on in Error). True:
        SafeMode was entered before the operator came."""
        arrived = self.env.timeout(self.incidents.operator_response.sample(self.incident_rng))
        while True:
            events: list[simpy.Event] = [arrived, self.link_changed]
            until_low = self.battery.seconds_until(self.env.now, self.rules.safe_mode_soc_pct)
            if math.isfinite(until_low) and until_low > 0:
                events.append(self.env.timeout(until_low + 1e-6))
            yield self.env.any_of(events)
            if arrived.processed:  # (a Timeout is "triggered" from the start)
                return False
            if self.may("Event_NetLoss_LowBat"):
                self.fire("Event_NetLoss_LowBat", "4.2.14 while in Error: no link, low "
                          "battery, no charger")
                return True

    def _safe_mode(self) -> Proc:
        """SafeMode (4.2.14, 6.3): the drive relay off and the controller asleep (the draw of
        rules.safe_mode_draw_w) until an operator rescues the AGV."""
        self.battery.draw(self.env.now, self.rules.safe_mode_draw_w)
        yield self.env.timeout(self.incidents.rescue.sample(self.incident_rng))
        self.battery.draw(self.env.now, self.battery.profile.idle_w)
        self.fire("Event_Operator_Rescue")

    def _reboot(self) -> Proc:
        """E_999 under `incidents.cpu_reset: reboot`: the watchdog resets the CPU where the AGV
        stands (Error -> Booting), POST takes the boot time, the start-up report goes to the
        fleet manager (4.2.1), and the AGV, its position unknown (4.2.2's guard), creeps along
        the tape to the nearest TYPE_LOC tag (5.3) before it takes orders again. A charge
        under way is lost (the charger is let go of); in a parking bay or at a tag, with a
        layout that has no TYPE_LOC tags, the tag it stands on tells it where it is."""
        self.fire("Event_Watchdog_Reset", "E_999: CPU exception, the watchdog resets the CPU")
        mid_hop = self.driver.stop_where_it_is()
        if self.charger is not None:
            self.docked = False
            self.fleet.release_charger(self.charger)
            self.charger = None
        self.marker_speed_mps = None
        locating = self.traffic.layout.markers
        self._position_known = self.parked_in is not None or (
            not mid_hop and "location" not in locating.values())
        yield self.env.timeout(self.profile.boot_s)  # POST
        self.error_code = None
        self.fire("Event_Init_Complete", "after the watchdog reset")
        yield from self.fleet.boot_report(self)
        self.failing = False  # (then `run` has it find its position, faults and all)

    def _locate(self) -> Proc:
        """Position unknown: creep (rules.obstacle_slow_speed_mps) to the nearest TYPE_LOC
        tag, or, on a layout without any, to the next tag ahead."""
        markers = self.traffic.layout.markers
        graph = self.traffic.graph
        with_loc = any(m == "location" for m in markers.values())
        if with_loc:  # (stopped between tags, it cannot turn back: from the tag ahead)
            ahead = self.driver.ahead
            origin = ahead[0].node if ahead else self.node
            times = nx.single_source_dijkstra_path_length(graph, origin,
                                                          weight=self.routes.weight)
            found = sorted((t, n) for n, t in times.items() if markers.get(n) == "location")
            goal = found[0][1] if found else origin
        else:
            goal = self.driver.next_node or min(graph.successors(self.node), default=self.node)
        self.fire("Event_Locate", f"position unknown after the reset: to {goal}")
        self.marker_speed_mps = self.rules.obstacle_slow_speed_mps
        if goal == self.node and self.driver.ahead:  # round the loop to where it stopped
            yield from self.drive(self.driver.ahead[0].node)
        if goal != self.node:
            yield from self.drive(goal)
        self.marker_speed_mps = None
        self._position_known = True
        self.fire("Event_Located", f"TYPE_LOC tag read at {goal}" if with_loc
                  else f"the tag at {goal} read (the layout has no TYPE_LOC tags)")

    def _recover(self, failure: Failure) -> Proc:
        """Error -> (operator) -> Maintenance -> (repair) -> Idle, or SafeMode -> rescue."""
        env = self.env
        self.fleet.withdraw(self)
        self.driver.halt()
        self.error_code = failure.code
        level, text = describe(failure.code)
        self.recorder.error(env.now, self.id, failure.code, level)
        self.fire("Event_Critical_Error", f"{failure.code} {level}: {text} {failure.detail}")
        order = self.order
        if order is not None:
            self.order = None
            if self.loaded:
                self.fleet.order_failed(order, failure.code)
            else:
                self.fleet.requeue(self, order)
        self.loaded = False
        if self.parking_target is not None:
            self.fleet.release_parking(self.parking_target)
            self.parking_target = None
        if self.charger is not None and not self.docked:
            self.fleet.release_charger(self.charger)
            self.charger = None
        if failure.code == "E_999" and self.incidents.cpu_reset == "reboot":
            yield from self._reboot()
            return
        safe = self.fire("Event_NetLoss_LowBat", "4.2.14: no link, low battery, no charger")
        if safe or (yield from self._wait_in_error()):
            yield from self._safe_mode()
        else:
            self.fire("Event_Switch_Manual", "operator at the AGV")
        if self.parked_in is None:
            self.driver.leave_track()
        if self.docked and self.charger is not None:
            self.docked = False
            self.fleet.release_charger(self.charger)
            self.charger = None
        yield env.timeout(self.incidents.repair.sample(self.incident_rng))
        if self.soc_pct < self.incidents.rescue_soc_pct:
            self.battery.set_soc(env.now, self.incidents.rescue_soc_pct)  # charged by hand
        self.error_code = None
        self.marker_speed_mps = None
        yield env.timeout(self.incidents.relocalise_s)
        if self.parked_in is None:
            yield from self.driver.reenter_track(self._recovery_node())
            self.in_dead_spot = self.rssi_dbm < self.rules.link_min_rssi_dbm
        self.failing = False
        self._position_known = True  # 4.2.13's initial position estimation
        self.fire("Event_Switch_Auto", "back to AUTO, position re-estimated")
