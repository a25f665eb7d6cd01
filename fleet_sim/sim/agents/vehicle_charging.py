"""The AGV's charging: when it needs a charge, the trip to the charger, the charge itself.

Battery: drained per metre (more when loaded), by handling and by idling. An AGV at or below the
charging threshold (or P_050, Event_Low_Battery) asks the fleet manager for a charger, drives
there (Moving, purpose to_charger), docks, charges along the charge curve until SOC > 95 %,
undocks. Below P_051 it shuts down with E_201. With charging off, an AGV at P_050 withdraws
from the orders (reason battery_low) and stands until E_201. With no battery model
(``fleet.vehicle.battery: off``) SOC stays at 100 %, nothing drains it, the AGV never charges
and its SOC is not recorded.
"""

from __future__ import annotations

import math

import simpy

from fleet_sim.config.layout import Place
from fleet_sim.model.battery import charge_time_s
from fleet_sim.model.records import MoveRecord
from fleet_sim.sim.agents.driving import Proc
from fleet_sim.sim.agents.vehicle_base import VehicleBase


class VehicleCharging(VehicleBase):
    """The battery thresholds and the charger: asking, waiting, driving there, charging."""

    def needs_charge(self) -> bool:
        if not self.charging.enabled or not self.has_battery:
            return False
        soc = self.soc_pct
        if soc <= max(self.charging.threshold_pct, self.rules.bat_low_pct):
            return True
        if self.charge_due and soc <= self.rules.charge_done_pct:
            return True
        return self.charging.opportunity and soc < self.charging.opportunity_below_pct \
            and self.fleet.charger_available()

    def _charge_trigger(self) -> str:
        """Idle -> Moving to a charger: Event_Low_Battery at or below P_050, else a planned
        charge (Event_Go_Charge)."""
        return "Event_Low_Battery" if self.soc_pct <= self.rules.bat_low_pct \
            else "Event_Go_Charge"

    def _charge(self) -> Proc:
        trigger = self._charge_trigger()
        asked = self.env.now
        request = self.fleet.request_charger(self)
        until_dead = self.battery.seconds_until(self.env.now, self.rules.bat_critical_pct)
        events: list[simpy.Event] = [request]
        if math.isfinite(until_dead):
            events.append(self.env.timeout(until_dead + 1e-6))
        if self.recorder.record_moves:
            self._charger_asked_s = asked
        self.recorder.charger_asked(self.id, asked)
        try:
            yield self.env.any_of(events)
        except simpy.Interrupt:  # failed while waiting: the charger must not wait for it
            self.fleet.cancel_charger_request(self, request)
            raise
        finally:
            self.recorder.charger_wait_over(self.id)
            self._close_charger_wait(request)
        if not request.triggered:
            self.fleet.cancel_charger_request(self, request)
            self.fail_now("E_201")
        place = request.value
        assert isinstance(place, Place)
        self.charger = place
        self.recorder.charge_wait(asked, self.env.now)
        self.charge_due = False
        self.fire(trigger, f"to_charger {place.id} soc {self.soc_pct:.1f}")
        if self.parked_in is not None:
            yield from self._unpark()
        yield from self._drive_to(place.nodes[0])
        self.fire("Event_Arrived_Charger", place.id)
        self.docked = True
        self.battery.draw(self.env.now, 0.0)  # the charger powers the AGV
        yield self.env.timeout(place.docking_s)
        start = self.soc_pct
        target = self.rules.charge_done_pct + 0.1
        charge_s = charge_time_s(self.battery.profile, start, target, place.power_kw)
        yield self.env.timeout(charge_s)
        self.battery.set_soc(self.env.now, max(start, target))
        yield self.env.timeout(place.docking_s)  # undocking
        self.docked = False
        self.battery.draw(self.env.now, self.battery.profile.idle_w)
        self.fire("Event_Charge_Complete", f"{place.id} soc {self.soc_pct:.1f}")
        self.charger = None
        self.fleet.release_charger(place)

    def _close_charger_wait(self, request: simpy.Event | None) -> None:
        asked = self._charger_asked_s
        if asked is None:
            return
        self._charger_asked_s = None
        got = request.value.id if request is not None and request.triggered \
            and isinstance(request.value, Place) else ""
        self.recorder.moved(MoveRecord(self.id, "charger_wait", asked, self.env.now, self.node,
                                       got))

