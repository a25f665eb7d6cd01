"""The AGV: the RSS-AGV-001 state machine driving a `Driver` through its day.

The vehicle holds its driver (fleet_sim.sim.agents.driving) and is the driver's `DriverHost`:
where it is, what it holds and how it hops are the driver's; its state, its order, its battery
and its faults are the vehicle's. `Vehicle` is its day's loop and its order work; its concerns
are mixins, each in a module of its own:

* fleet_sim.sim.agents.vehicle_base: its attributes, the facts the guards read, `fire(event)`
  (every change of state), and `FleetManagerLink`;
* fleet_sim.sim.agents.vehicle_charging: the battery thresholds, the charger, the charge;
* fleet_sim.sim.agents.vehicle_link: the FMS link lost and back (Req.Err.011);
* fleet_sim.sim.agents.vehicle_travel: a hop's battery use, markers, dead spots, obstacles and
  line losses;
* fleet_sim.sim.agents.vehicle_faults: Error, the operator, Maintenance, SafeMode, the reboot.

Orders: Idle -> Moving -> Loading (L_Approach, L_Handshake, L_Transfer, L_Verify) -> Moving ->
Unloading (U_Approach, U_Handshake, U_Transfer, U_Verify) -> Idle. L_Transfer is the station's
handling time; the other sub-states take the vehicle profile's times. A multi-stop order
(fleet_sim.config.chains) repeats Moving -> Loading -> Moving -> Unloading stop by stop,
Unloading -> Moving (Event_Next_Stop) between a drop-off and the next pickup (`_serve_chain`).
With nothing to do, the AGV offers itself to the dispatcher and drives to parking.

The AGV knows the fleet manager only through `FleetManagerLink`; the fleet manager hands it work
by calling `assign`, and a scheduled charging call by `call_to_charge`. Both wake the AGV if it
waits idle; nothing outside writes its attributes. The AGV tells the fleet manager of every
change of state or FMS link (`status_changed`), which is how the fleet manager knows which AGVs
stand Idle while orders wait (fleet_sim.model.not_dispatched).
"""

from __future__ import annotations

import math

import numpy as np
import simpy

from fleet_sim.config.scenario import Scenario
from fleet_sim.config.vehicle import VehicleProfile
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.model.records import Order, Recorder
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.driving import Driver, Proc
from fleet_sim.sim.agents.lds import AgvAhead
from fleet_sim.sim.agents.vehicle_base import Failure, FleetManagerLink, SegmentFacts
from fleet_sim.sim.agents.vehicle_charging import VehicleCharging
from fleet_sim.sim.agents.vehicle_faults import VehicleFaults
from fleet_sim.sim.agents.vehicle_link import VehicleLink
from fleet_sim.sim.agents.vehicle_travel import VehicleTravel
from fleet_sim.sim.traffic.control import Traffic


class Vehicle(VehicleCharging, VehicleLink, VehicleTravel, VehicleFaults):
    """One AGV: its day (`run`) and its orders, with the concerns of its mixins. It builds its
    driver, whose host it is."""

    def __init__(self, agv_id: int, env: simpy.Environment, traffic: Traffic,
                 fleet: FleetManagerLink, recorder: Recorder, scenario: Scenario,
                 rng: np.random.Generator, incident_rng: np.random.Generator,
                 profile: VehicleProfile | None = None,
                 segment_facts: dict[tuple[str, str], SegmentFacts] | None = None) -> None:
        """`profile`: the AGV's vehicle (mixed fleets); default `scenario.fleet.vehicle`.
        `segment_facts`: the fleet's shared `_facts_of` cache (the facts are the scenario's and
        the layout's, the same for every AGV); default its own."""
        profile = profile if profile is not None else scenario.fleet.vehicle
        super().__init__(agv_id, env, traffic, fleet, recorder, scenario, incident_rng, profile,
                         segment_facts)
        self.driver = Driver(agv_id, env, traffic, recorder, profile, scenario.traffic, rng,
                             host=self, permission=fleet.commands.permission(agv_id))
        if self.rules.agv_ahead == "lds":
            self.driver.lds = AgvAhead(env, self.rules, profile.min_gap_m, self,
                                       traffic.clock)
        else:
            self.driver.hold_back(self.rules.lds_slow_m)
        self.routes = self.driver.routes

    def start(self) -> None:
        self.in_dead_spot = self.rssi_dbm < self.rules.link_min_rssi_dbm
        self.recorder.event(self.env.now, self.id, "Event_Power_On", "", VehicleState.BOOTING.value,
                            self.node)
        self.process = self.env.process(self.run())

    # ---- its day ------------------------------------------------------------------------------
    def run(self) -> Proc:
        try:
            yield self.env.timeout(self.profile.boot_s)
            self.fire("Event_Init_Complete")
            yield from self.fleet.boot_report(self)  # 4.2.1: it reports to the FMS
        except simpy.Interrupt as interrupt:  # a fault while booting
            if not isinstance(interrupt.cause, Failure):
                raise
            yield from self._recover(interrupt.cause)
        while True:
            try:
                if not self._position_known:
                    yield from self._locate()
                if self.order is None:
                    yield from self._idle()
                if self.order is not None:
                    yield from self._serve(self.order)
            except simpy.Interrupt as interrupt:
                if not isinstance(interrupt.cause, Failure):
                    raise
                yield from self._recover(interrupt.cause)

    def _idle(self) -> Proc:
        """Nothing to do: charge if needed, else offer itself to the dispatcher and park."""
        if self.needs_charge():
            yield from self._charge()
            return
        if self.soc_pct <= self.rules.bat_low_pct:
            # may not start moving (P_050) and may not charge: stand until the battery dies
            self.fleet.withdraw(self, NotDispatched.BATTERY_LOW)
            yield self.env.timeout(
                self.battery.seconds_until(self.env.now, self.rules.bat_critical_pct) + 1e-6)
            self.fail_now("E_201")
        self._wake_up = self.env.event()
        self.fleet.vehicle_idle(self)
        if self.order is not None:
            return
        if self.parked_in is None and self.fleet.park_idle and self.fms_link:
            place = self.fleet.reserve_parking(self)
            if place is not None:
                self.parking_target = place
                self.fire("Event_Go_Park", f"to_parking {place.id}")
                access = place.nodes[0]
                yield from self.drive(access, stop_early=self._stop_parking_trip)
                if self.node == access and self.order is None and not self.charge_due:
                    # drive off the tape into a bay, at turn speed, before letting go of it
                    yield self.env.timeout(self.driver.body_m / self.profile.turn_speed_mps)
                    self.driver.enter_parking(place)
                    if self.order is None:  # not one assigned while it drove in
                        self.fleet.parked(self)
                    self.parking_target = None
                    self.fire("Event_Arrived_Parking", place.id)
                else:
                    self.parking_target = None
                    self.fleet.release_parking(place)
                    self.fire("Event_Stop", "trip to parking cut short")
                    if self.order is None:
                        self.fleet.withdraw(self)
                        return
                if self.order is not None:
                    return
        # wait for work, a charging call, the battery running down (to the charging threshold, or
        # with charging off to P_050, below which it may not move), or (no link) 10 minutes
        threshold = max(self.charging.threshold_pct, self.rules.bat_low_pct) \
            if self.charging.enabled else self.rules.bat_low_pct
        until_low = self.battery.seconds_until(self.env.now, threshold)
        events = [self._wake_up]
        if math.isfinite(until_low):
            events.append(self.env.timeout(until_low + 1e-6))
        lost = not self.fms_link
        if lost:  # Req.Err.011: waiting and retrying; Error after 10 minutes
            events += [self.link_changed, self.env.timeout(self.rules.reconnect_timeout_s)]
        started = self.env.now
        yield self.env.any_of(events)
        if self.order is None:
            self.fleet.withdraw(self)
            if self.soc_pct < self.rules.bat_critical_pct:
                self.fail_now("E_201")
            if lost and not self.fms_link \
                    and self.env.now - started >= self.rules.reconnect_timeout_s:
                self.fail_now("E_301")

    def _stop_parking_trip(self) -> bool:
        return self.order is not None or self.charge_due or not self.fms_link

    def _serve(self, order: Order) -> Proc:
        if order.stops:
            yield from self._serve_chain(order)
            return
        if not self.fire("Event_Transport_Order", f"to_pickup order {order.id}"):
            self.fleet.requeue(self, order)
            self.order = None
            return
        if self.parked_in is not None:
            yield from self._unpark()
        assert order.pickup_node is not None and order.dropoff_node is not None
        yield from self._drive_to(order.pickup_node)
        order.pickup_arrival_s = self.env.now
        self.fire("Event_Arrived_Pickup", f"order {order.id}")
        yield from self._handle("L", order.pickup_handling_s, order)
        self.loaded = True
        order.picked_s = self.env.now
        self.fleet.left_station(order.pickup_node)
        self.fire("Event_Load_Complete", f"to_dropoff order {order.id}")
        yield from self._drive_to(order.dropoff_node)
        order.dropoff_arrival_s = self.env.now
        self.fire("Event_Arrived_Dropoff", f"order {order.id}")
        yield from self._handle("U", order.dropoff_handling_s, order)
        self.loaded = False
        order.delivered_s = self.env.now
        self.recorder.order_finished(order)
        self.fleet.left_station(order.dropoff_node)
        self.order = None
        self.fire("Event_Unload_Complete", f"order {order.id}")

    def _serve_chain(self, order: Order) -> Proc:
        """A multi-stop order, from the first stop not yet done: at each pickup the Loading
        sub-states, at each dropoff the Unloading ones; after a dropoff that is not the last,
        Unloading -> Moving on to the next pickup (Event_Next_Stop). The details of the arrival
        and completion events name the stop: ``order 7 stop 2/4 DROP_B``."""
        stops, n = order.stops, len(order.stops)

        def tag(k: int) -> str:
            return f"order {order.id} stop {k + 1}/{n} {stops[k]}"

        if not self.fire("Event_Transport_Order", f"to_pickup {tag(order.stops_done)}"):
            self.fleet.requeue(self, order)
            self.order = None
            return
        if self.parked_in is not None:
            yield from self._unpark()
        for k in range(order.stops_done, n):
            node = order.stop_nodes[k]
            assert node is not None
            yield from self._drive_to(node)
            if k % 2 == 0:  # a pickup
                if k == 0:
                    order.pickup_arrival_s = self.env.now
                self.fire("Event_Arrived_Pickup", tag(k))
                yield from self._handle("L", order.stop_handling_s[k], order)
                self.loaded = True
                if k == 0:
                    order.picked_s = self.env.now
                order.stops_done = k + 1
                self.fleet.left_station(node)
                self.fire("Event_Load_Complete", f"to_dropoff {tag(k + 1)}")
                continue
            last = k == n - 1
            if last:
                order.dropoff_arrival_s = self.env.now
            self.fire("Event_Arrived_Dropoff", tag(k))
            yield from self._handle("U", order.stop_handling_s[k], order)
            self.loaded = False
            order.stops_done = k + 1
            self.fleet.left_station(node)
            if last:
                order.delivered_s = self.env.now
                self.recorder.order_finished(order)
                self.order = None
                self.fire("Event_Unload_Complete", tag(k))
            else:
                self.fire("Event_Next_Stop", f"to_pickup {tag(k + 1)}")

    def _handle(self, prefix: str, transfer_s: float, order: Order) -> Proc:
        """The four sub-states of Loading (4.3) or Unloading: approach, handshake, transfer,
        verify. A failed transfer raises E_102."""
        profile = self.profile
        self.battery.draw(self.env.now, self.battery.profile.handling_w)
        for name, seconds in (("Approach", profile.approach_s),
                              ("Handshake", profile.handshake_s),
                              ("Transfer", transfer_s), ("Verify", profile.verify_s)):
            self.note(f"{prefix}_{name}", f"order {order.id}")
            yield self.env.timeout(seconds)
            if name == "Transfer" and self.incidents.transfer_failure_prob > 0 \
                    and self.incident_rng.random() < self.incidents.transfer_failure_prob:
                self.battery.draw(self.env.now, self.battery.profile.idle_w)
                self.fail_now("E_102")
        self.battery.draw(self.env.now, self.battery.profile.idle_w)

    def end_of_run(self) -> None:
        self.driver.end_of_run()
        self._close_charger_wait(None)

