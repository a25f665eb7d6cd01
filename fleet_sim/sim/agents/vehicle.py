"""The AGV: the RSS-AGV-001 state machine driving a `Driver` through its day.

The vehicle holds its driver (fleet_sim.sim.agents.driving) and is the driver's `DriverHost`:
where it is, what it holds and how it hops are the driver's; its state, its order, its battery
and its faults are the vehicle's.

Every change of state goes through `fire(event)`, which looks the (state, event) pair up in the
table of fleet_sim.model.state_machine, checks the guard against this vehicle's facts (SOC, load
sensor, link, obstacle timing...) and records the transition. The behaviours:

* Orders: Idle -> Moving -> Loading (L_Approach, L_Handshake, L_Transfer, L_Verify) -> Moving ->
  Unloading (U_Approach, U_Handshake, U_Transfer, U_Verify) -> Idle. L_Transfer is the station's
  handling time; the other sub-states take the vehicle profile's times. A multi-stop order
  (fleet_sim.config.chains) repeats Moving -> Loading -> Moving -> Unloading stop by stop,
  Unloading -> Moving (Event_Next_Stop) between a drop-off and the next pickup (`_serve_chain`).
* Battery: drained per metre (more when loaded), by handling and by idling. An AGV at or below the
  charging threshold (or P_050, Event_Low_Battery) asks the fleet manager for a charger, drives
  there (Moving, purpose to_charger), docks, charges along the charge curve until SOC > 95 %,
  undocks. Below P_051 it shuts down with E_201. With charging off, an AGV at P_050 withdraws
  from the orders (reason battery_low) and stands until E_201. With no battery model
  (``fleet.vehicle.battery: off``) SOC stays at 100 %, nothing drains it, the AGV never charges
  and its SOC is not recorded.
* Obstacles (4.2.3/4.2.4): met while driving; seen for < 300 ms they only slow the AGV (the
  P_005/P_006 zone), otherwise it pauses until the path has been clear for 2000 ms; E_101 after
  5 minutes paused. Scripted blocks stop AGVs in front of the blocked segment.
* FMS link (Req.Err.011 by default): a lost heartbeat is noticed after `heartbeat_timeout_s`; the
  AGV drives on slowly to the next tag, waits in Idle, resumes when the link is back, and raises
  an Error after 10 minutes. Policy `timeout_60s` (4.2.11) instead raises an Error after 60 s.
  Segments below `link_min_rssi_dbm` are dead spots. A lost AGV takes no new orders and keeps the
  order it carries.
* Faults: line loss (Req.Err.010), transfer failure (E_102), random critical faults (MTBF) and
  scripted ones: Error, an operator comes (Event_Switch_Manual -> Maintenance, the AGV is taken off
  the track), repairs it, and switches back to AUTO (-> Idle after position re-estimation). An
  order not yet loaded goes back to the queue; a loaded one is recorded as failed. SafeMode per
  4.2.14/6.3; only an operator rescue brings an AGV back from it.

The AGV knows the fleet manager only through `FleetManagerLink` (declared here); the fleet
manager hands it work by calling `assign`, and a scheduled charging call by `call_to_charge`.
Both wake the AGV if it waits idle; nothing outside writes its attributes. The AGV tells the
fleet manager of every change of state or FMS link (`status_changed`), which is how the fleet
manager knows which AGVs stand Idle while orders wait (fleet_sim.model.not_dispatched).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from typing import Any, NoReturn, Protocol

import networkx as nx
import numpy as np
import simpy

from fleet_sim.config.layout import MARKER_SPEED_MPS, Place
from fleet_sim.config.scenario import ChargingConfig, IncidentsConfig, Rules, Scenario
from fleet_sim.config.vehicle import BatteryProfile, VehicleProfile
from fleet_sim.model.battery import StateOfCharge, charge_time_s
from fleet_sim.model.error_codes import describe
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.model.records import MoveRecord, Order, Recorder
from fleet_sim.model.state_machine import transition_for
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.driving import Driver, Proc
from fleet_sim.sim.agents.lds import AgvAhead
from fleet_sim.sim.commands import CommandPath
from fleet_sim.sim.traffic.control import Traffic


class FleetManagerLink(Protocol):
    """What the AGV asks of the fleet manager (fleet_sim.sim.agents.fleet_manager)."""

    @property
    def commands(self) -> CommandPath: ...

    @property
    def park_idle(self) -> bool: ...

    def vehicle_idle(self, agv: Vehicle) -> None: ...

    def withdraw(self, agv: Vehicle, reason: NotDispatched | None = None) -> None: ...

    def status_changed(self, agv: Vehicle) -> None: ...

    def resume(self, agv: Vehicle) -> Generator[simpy.Event, Any, None]: ...

    def boot_report(self, agv: Vehicle) -> Generator[simpy.Event, Any, None]: ...

    def requeue(self, agv: Vehicle, order: Order) -> None: ...

    def order_failed(self, order: Order, code: str) -> None: ...

    def left_station(self, node: str) -> None: ...

    def reserve_parking(self, agv: Vehicle) -> Place | None: ...

    def release_parking(self, place: Place) -> None: ...

    def parked(self, agv: Vehicle) -> None: ...

    def charger_available(self) -> bool: ...

    def request_charger(self, agv: Vehicle) -> simpy.Event: ...

    def cancel_charger_request(self, agv: Vehicle, request: simpy.Event) -> None: ...

    def release_charger(self, place: Place) -> None: ...


SegmentFacts = tuple[bool, bool, float | None, float | None]
"""What `Vehicle.travel` reads of a segment: a dead spot, a weak signal, the chance of an
obstacle and of losing the line on it (None: no chance, no draw)."""

NO_BATTERY = BatteryProfile(initial_soc_pct=100.0, drive_wh_per_m=0.0, drive_loaded_wh_per_m=0.0,
                            handling_w=0.0, idle_w=0.0)
"""The battery of an AGV without a battery model: full, and nothing drains it."""


class Failure:
    """The cause of an interrupt that sends an AGV to Error."""

    def __init__(self, code: str, detail: str = "") -> None:
        self.code = code
        self.detail = detail


class Vehicle:
    def __init__(self, agv_id: int, env: simpy.Environment, traffic: Traffic,
                 fleet: FleetManagerLink, recorder: Recorder, scenario: Scenario,
                 rng: np.random.Generator, incident_rng: np.random.Generator,
                 profile: VehicleProfile | None = None,
                 segment_facts: dict[tuple[str, str], SegmentFacts] | None = None) -> None:
        """`profile`: the AGV's vehicle (mixed fleets); default `scenario.fleet.vehicle`.
        `segment_facts`: the fleet's shared `_facts_of` cache (the facts are the scenario's and
        the layout's, the same for every AGV); default its own."""
        profile = profile if profile is not None else scenario.fleet.vehicle
        self.id = agv_id
        self.env = env
        self.traffic = traffic
        self.recorder = recorder
        self.profile = profile
        self.state = VehicleState.BOOTING
        self.order: Order | None = None
        self.failing = False
        self.process: simpy.Process | None = None
        self.driver = Driver(agv_id, env, traffic, recorder, profile, scenario.traffic, rng,
                             host=self, permission=fleet.commands.permission(agv_id))
        """Moves the AGV from node to node under traffic control."""
        self.rules: Rules = scenario.rules
        if self.rules.agv_ahead == "lds":
            self.driver.lds = AgvAhead(env, self.rules, profile.min_gap_m, self)
        else:
            self.driver.hold_back(self.rules.lds_slow_m)
        self.routes = self.driver.routes
        self.fleet = fleet
        self.charging: ChargingConfig = scenario.charging
        self.incidents: IncidentsConfig = scenario.incidents
        self.incident_rng = incident_rng
        self.has_battery = profile.battery is not None
        """False with ``battery: off``: no drain, no charging, no SOC record."""
        self.battery = StateOfCharge(profile.battery or NO_BATTERY, env.now)
        self._wake_up: simpy.Event = env.event()
        """Succeeds when an order or a charging call comes for the AGV waiting idle."""
        self.loaded = False
        self._position_known = True
        self._obstacle_near_s = 0.0
        self._obstacle_clear_s = 0.0
        self.error_code: str | None = None
        self.links_down = 0
        """FMS link losses in force (scripted or random, noticed)."""
        self.in_dead_spot = False
        self.link_changed: simpy.Event = env.event()
        self.charger: Place | None = None
        self.docked = False
        self.charge_due = False
        self.marker_speed_mps: float | None = None
        self.parking_target: Place | None = None
        self._segment_facts = segment_facts if segment_facts is not None else {}
        """Segment -> what `travel` needs of it (`_facts_of`), once per segment."""
        self._charger_asked_s: float | None = None
        """With moves recorded: when the AGV asked for the charger it waits for."""

    # ---- where it is: the driver's ------------------------------------------------------------
    @property
    def node(self) -> str:
        return self.driver.node

    @property
    def prev(self) -> str | None:
        return self.driver.prev

    @property
    def speed_mps(self) -> float:
        return self.driver.speed_mps

    @property
    def parked_in(self) -> Place | None:
        return self.driver.parked_in

    @property
    def in_parking(self) -> bool:
        """In a parking area, off the track."""
        return self.driver.in_parking

    @property
    def dispatch_node(self) -> str:
        """Where the dispatcher should measure travel from: the node the AGV is committed to."""
        return self.driver.dispatch_node

    def note(self, event: str, detail: str = "") -> None:
        """Record an event that changes no state (deadlock, reroute, assignment...)."""
        self.driver.note(event, detail)

    def place_at(self, node: str) -> None:
        """Stand on `node` at t=0."""
        self.driver.place_at(node)

    def place_in_parking(self, place: Place) -> None:
        self.driver.place_in_parking(place)

    def drive(self, goal: str, stop_early: Callable[[], bool] | None = None) -> Proc:
        """Drive to `goal` (fleet_sim.sim.agents.driving.Driver.drive: its generator itself,
        not one wrapped in another, which every resumption would pass through)."""
        return self.driver.drive(goal, stop_early)

    # ---- facts the guards read (fleet_sim.model.state_machine.Facts) -----------------------
    @property
    def soc_pct(self) -> float:
        return self.battery.soc_pct(self.env.now)

    @property
    def position_known(self) -> bool:
        return self._position_known

    @property
    def obstacle_near_s(self) -> float:
        return self._obstacle_near_s

    @property
    def obstacle_clear_s(self) -> float:
        return self._obstacle_clear_s

    @property
    def load_on(self) -> bool:
        return self.loaded

    @property
    def charger_assigned(self) -> bool:
        return self.charger is not None

    @property
    def error_flags(self) -> bool:
        return self.error_code is not None

    @property
    def rssi_dbm(self) -> float:
        graph = self.traffic.graph
        if self.prev is not None and graph.has_edge(self.prev, self.node):
            return float(graph.edges[self.prev, self.node]["rssi_dbm"])
        return max((float(d["rssi_dbm"]) for _, _, d in graph.out_edges(self.node, data=True)),
                   default=self.traffic.layout.spec.defaults.rssi_dbm)

    @property
    def fms_link(self) -> bool:
        return self.links_down == 0 and not self.in_dead_spot

    @property
    def on_charger(self) -> bool:
        return self.docked

    # ---- the state machine ------------------------------------------------------------------
    def may(self, event: str) -> bool:
        """Whether `event`'s transition from the current state would pass its guard (nothing
        recorded: a look again, not an attempt)."""
        transition = transition_for(self.id, self.state, event)
        return transition.guard is None or bool(transition.guard(self, self.rules))

    def fire(self, event: str, detail: str = "") -> bool:
        """Take the transition for `event` from the current state; False if its guard fails.
        An event with no transition from here raises InvalidTransition."""
        transition = transition_for(self.id, self.state, event)
        if transition.guard is not None and not transition.guard(self, self.rules):
            self.note("guard_failed", f"{event}: needs {transition.condition}")
            return False
        now = self.env.now
        self.recorder.event(now, self.id, event, self.state.value, transition.target.value,
                            self.node, detail)
        if self.has_battery:
            self.recorder.soc(now, self.id, self.soc_pct)
        self.state = transition.target
        self.fleet.status_changed(self)
        return True

    def start(self) -> None:
        self.in_dead_spot = self.rssi_dbm < self.rules.link_min_rssi_dbm
        self.recorder.event(self.env.now, self.id, "Event_Power_On", "", VehicleState.BOOTING.value,
                            self.node)
        self.process = self.env.process(self.run())

    def fail(self, code: str, detail: str = "") -> bool:
        """Send the AGV to Error from wherever it is (an incident process calls this)."""
        if self.failing or self.process is None or not self.process.is_alive:
            return False
        self.failing = True
        self.process.interrupt(Failure(code, detail))
        return True

    # ---- what the fleet manager hands it ------------------------------------------------------
    def assign(self, order: Order) -> None:
        """The assign command with `order` has reached the AGV."""
        self.order = order
        self.note("order_assigned", f"order {order.id} {order.pickup} -> {order.dropoff}"
                  if not order.stops else
                  f"order {order.id} {' -> '.join(order.stops[order.stops_done:])}")
        self._wake()

    def call_to_charge(self) -> None:
        """A scheduled charging call (the `stop` command) has reached the AGV."""
        self.charge_due = True
        self._wake()

    def _wake(self) -> None:
        if not self._wake_up.triggered:
            self._wake_up.succeed()

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

    def fail_now(self, code: str) -> NoReturn:
        """A fault found by the AGV's own process: raise it as an interrupt to itself."""
        self.failing = True
        raise simpy.Interrupt(Failure(code))

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

    def _unpark(self) -> Proc:
        place = self.parked_in
        assert place is not None
        yield from self.driver.reenter_track(place.nodes[0])
        self.driver.parked_in = None
        self.fleet.release_parking(place)

    # ---- charging ------------------------------------------------------------------------------
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

    def end_of_run(self) -> None:
        self.driver.end_of_run()
        self._close_charger_wait(None)

    # ---- driving with the link, markers, obstacles and the battery -----------------------------
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

    def _link_changed(self) -> None:
        if not self.link_changed.triggered:
            self.link_changed.succeed()
        self.link_changed = self.env.event()

    def speed_cap_mps(self) -> float | None:
        """DriverHost: markers and slow modes cap the next hop's speed."""
        cap = self.marker_speed_mps
        if not self.fms_link and self.rules.comm_policy == "req_err_011":
            slow = self.rules.comm_loss_speed_mps
            cap = slow if cap is None else min(cap, slow)
        return cap

    def travel(self, u: str, v: str, time_s: float) -> Proc:
        """DriverHost: drive the hop, with dead spots, blocks, obstacles and line losses."""
        facts = self._segment_facts.get((u, v))
        if facts is None:
            facts = self._segment_facts[u, v] = self._facts_of(u, v)
        dead, weak, obstacle_p, line_p = facts
        if dead != self.in_dead_spot:
            self.in_dead_spot = dead
            self.recorder.comm_losses += dead
            self.note("dead_spot_in" if dead else "dead_spot_out", f"{u} -> {v}")
            self._link_changed()
        if weak:
            self.recorder.warning("E_002")
        traffic = self.traffic
        if traffic.blocks:
            blocked_until = traffic.blocked_until(u, v, self.env.now)
            if blocked_until is not None:
                yield from self._obstacle(blocked_until - self.env.now,
                                          f"segment {u} -> {v} blocked")
        rng = self.incident_rng
        if obstacle_p is not None and rng.random() < obstacle_p:
            share = float(rng.random())
            edge = traffic.routes.edge[u, v]
            duration = edge["obstacle_duration"] or self.incidents.obstacle_duration
            yield from self.driver.move(u, v, time_s, share)
            yield from self._obstacle(duration.sample(rng), f"on {u} -> {v}")
            yield from self.driver.move(u, v, time_s, 1.0)
        else:
            yield from self.driver.move(u, v, time_s, 1.0)
        if line_p is not None and rng.random() < line_p:
            if rng.random() < self.incidents.line_found_prob:
                self.recorder.warning("E_001")
                self.note("line_lost", f"found again within {self.rules.line_keep_heading_m} m")
                yield from self.driver.pause(self.incidents.line_search_s)
            else:
                self.fail_now("E_202")

    def _facts_of(self, u: str, v: str) -> SegmentFacts:
        """Segment u -> v as `travel` sees it: a dead spot, a weak signal, the chance of an
        obstacle on it and of losing the line on it (None: no chance, no draw)."""
        edge = self.traffic.routes.edge[u, v]
        length = edge["length_m"]
        rate = edge["obstacle_rate_per_km"]
        if rate is None:
            rate = self.incidents.obstacle_rate_per_km
        line_rate = self.incidents.line_loss_per_km
        return (edge["rssi_dbm"] < self.rules.link_min_rssi_dbm,
                edge["rssi_dbm"] < self.rules.weak_rssi_dbm,
                1.0 - math.exp(-rate * length / 1000.0) if rate > 0 else None,
                1.0 - math.exp(-line_rate * length / 1000.0) if line_rate > 0 else None)

    def _obstacle(self, seen_s: float, where: str) -> Proc:
        """An obstacle appears in front and stays within range for `seen_s` seconds.

        Seen for less than 300 ms (4.2.3), it only slows the AGV through the detection zone
        (P_005/P_006): braking to the creep speed and speeding up again cost time. Seen longer,
        the AGV pauses 300 ms after it appeared and drives on 2000 ms after it has gone (4.2.4);
        paused for 5 minutes, it raises E_101.
        """
        rules = self.rules
        motion = self.routes.motion
        v = max(self.speed_mps, min(self.profile.max_speed_mps, 1.0))
        self._obstacle_near_s = seen_s
        if self.traffic.motion_backend is not None:
            yield from self._obstacle_held(seen_s, where)
            return
        if seen_s < rules.obstacle_pause_s:
            slow = min(rules.obstacle_slow_speed_mps, v)
            extra = (v - slow) / motion.decel_mps2 + (v - slow) / motion.accel_mps2 \
                - (v * v - slow * slow) * (1 / motion.decel_mps2 + 1 / motion.accel_mps2) / (2 * v)
            self.note("obstacle_slowdown", f"{where}: seen {seen_s:.2f} s")
            yield self.env.timeout(extra + seen_s * (1 - slow / v))
            return
        yield self.env.timeout(rules.obstacle_pause_s)
        self.fire("Event_Obstacle_Detected", f"{where}: within 1.0 m for "
                                              f">= {rules.obstacle_pause_s * 1000:.0f} ms")
        self.recorder.obstacle_pauses += 1
        wait = seen_s - rules.obstacle_pause_s + rules.obstacle_clear_s
        if wait >= rules.obstacle_timeout_s:
            yield self.env.timeout(rules.obstacle_timeout_s)
            self.fail_now("E_101")
        yield self.env.timeout(wait)
        self._obstacle_clear_s = rules.obstacle_clear_s
        self.fire("Event_Obstacle_Cleared", f"paused {wait:.2f} s")
        yield self.env.timeout(v / (2 * motion.accel_mps2))  # speeding up again from a stop

    def _obstacle_held(self, seen_s: float, where: str) -> Proc:
        """`_obstacle` with a motion backend: the same rules, but the backend brakes the AGV
        (to the creep speed, or to a stop) and speeds it up again, so the time lost is its
        own, and AGVs behind it close up."""
        rules = self.rules
        if seen_s < rules.obstacle_pause_s:
            self.note("obstacle_slowdown", f"{where}: seen {seen_s:.2f} s")
            yield from self.driver.pause(seen_s, rules.obstacle_slow_speed_mps)
            return
        yield from self.driver.pause(rules.obstacle_pause_s, rules.obstacle_slow_speed_mps)
        self.fire("Event_Obstacle_Detected", f"{where}: within 1.0 m for "
                                              f">= {rules.obstacle_pause_s * 1000:.0f} ms")
        self.recorder.obstacle_pauses += 1
        wait = seen_s - rules.obstacle_pause_s + rules.obstacle_clear_s
        if wait >= rules.obstacle_timeout_s:
            yield from self.driver.pause(rules.obstacle_timeout_s)
            self.fail_now("E_101")
        yield from self.driver.pause(wait)
        self._obstacle_clear_s = rules.obstacle_clear_s
        self.fire("Event_Obstacle_Cleared", f"paused {wait:.2f} s")

    def pause_for_agv(self, ahead: int, gap_m: float) -> bool:
        """PausedHost: the AGV ahead stands within the LDS's stop distance (4.2.3)."""
        if self.state is not VehicleState.MOVING or self.failing:
            return False
        self._obstacle_near_s = self.rules.obstacle_pause_s
        self.fire("Event_Obstacle_Detected",
                  f"AGV {ahead} {gap_m:.2f} m ahead for >= "
                  f"{self.rules.obstacle_pause_s * 1000:.0f} ms")
        self.recorder.agv_obstacle_pauses += 1
        return True

    def resume_after_agv(self, paused_s: float) -> None:
        """PausedHost: the way has been clear long enough (4.2.4)."""
        self._obstacle_clear_s = self.rules.obstacle_clear_s
        self.fire("Event_Obstacle_Cleared", f"paused {paused_s:.2f} s behind an AGV")

    def arrived(self, v: str, length_m: float) -> Proc | None:
        """DriverHost: battery use and markers at `v`; a spin or a pause marker is a stop,
        returned to be driven (None: none)."""
        self.battery.drive(self.env.now, length_m, self.loaded)
        marker = self.traffic.layout.markers.get(v)
        if marker is not None:
            if marker == "spin" or marker == "pause":
                return self._stop_at_marker(v, marker)
            if marker in MARKER_SPEED_MPS:
                self.marker_speed_mps = MARKER_SPEED_MPS[marker]
            elif marker == "location":
                self._position_known = True
            self.note(f"marker_{marker}", v)
        if self.battery.soc_pct(self.env.now) < self.rules.bat_critical_pct:
            self.fail_now("E_201")
        return None

    def _stop_at_marker(self, v: str, marker: str) -> Proc:
        """A spin or a pause marker at `v`: the AGV stops there."""
        if marker == "spin":
            yield self.env.timeout(self.profile.spin_s)
        else:
            yield self.env.timeout(self.rules.marker_pause_s)
        self.note(f"marker_{marker}", v)
        if self.soc_pct < self.rules.bat_critical_pct:
            self.fail_now("E_201")

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

    # ---- faults and recovery -------------------------------------------------------------------
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
        if with_loc:
            times = nx.single_source_dijkstra_path_length(graph, self.node,
                                                          weight=self.routes.weight)
            found = sorted((t, n) for n, t in times.items() if markers.get(n) == "location")
            goal = found[0][1] if found else self.node
        else:
            goal = self.driver.next_node or min(graph.successors(self.node), default=self.node)
        self.fire("Event_Locate", f"position unknown after the reset: to {goal}")
        self.marker_speed_mps = self.rules.obstacle_slow_speed_mps
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
