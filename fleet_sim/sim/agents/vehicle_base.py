"""What every part of the AGV shares: its facts, its state machine and the fleet manager's link.

`VehicleBase` holds the AGV's attributes, the facts the guards of fleet_sim.model.state_machine
read, and `fire(event)`, through which every change of state goes: it looks the (state, event)
pair up in the transition table, checks the guard against this vehicle's facts (SOC, load sensor,
link, obstacle timing...) and records the transition. The AGV's concerns are mixins on top of it
(fleet_sim.sim.agents.vehicle_charging, vehicle_link, vehicle_faults, vehicle_travel), put
together with the order work in fleet_sim.sim.agents.vehicle.Vehicle; each concern calls the
others' steps through the hooks declared here.

The AGV knows the fleet manager only through `FleetManagerLink` (declared here); the fleet
manager hands it work by calling `assign`, and a scheduled charging call by `call_to_charge`.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import Any, NoReturn, Protocol

import numpy as np
import simpy

from fleet_sim.config.layout import Place
from fleet_sim.config.scenario import ChargingConfig, IncidentsConfig, Rules, Scenario
from fleet_sim.config.vehicle import BatteryProfile, VehicleProfile
from fleet_sim.model.battery import StateOfCharge
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.model.records import Order, Recorder
from fleet_sim.model.state_machine import transition_for
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.driving import Driver, Proc
from fleet_sim.sim.commands import CommandPath
from fleet_sim.sim.traffic.control import Traffic
from fleet_sim.sim.traffic.routing import Routes


class FleetManagerLink(Protocol):
    """What the AGV asks of the fleet manager (fleet_sim.sim.agents.fleet_manager)."""

    @property
    def commands(self) -> CommandPath: ...

    @property
    def park_idle(self) -> bool: ...

    def vehicle_idle(self, agv: VehicleBase) -> None: ...

    def withdraw(self, agv: VehicleBase, reason: NotDispatched | None = None) -> None: ...

    def status_changed(self, agv: VehicleBase) -> None: ...

    def resume(self, agv: VehicleBase) -> Generator[simpy.Event, Any, None]: ...

    def boot_report(self, agv: VehicleBase) -> Generator[simpy.Event, Any, None]: ...

    def requeue(self, agv: VehicleBase, order: Order) -> None: ...

    def order_failed(self, order: Order, code: str) -> None: ...

    def left_station(self, node: str) -> None: ...

    def reserve_parking(self, agv: VehicleBase) -> Place | None: ...

    def release_parking(self, place: Place) -> None: ...

    def parked(self, agv: VehicleBase) -> None: ...

    def charger_available(self) -> bool: ...

    def request_charger(self, agv: VehicleBase) -> simpy.Event: ...

    def cancel_charger_request(self, agv: VehicleBase, request: simpy.Event) -> None: ...

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


class VehicleBase:
    """The AGV's attributes, facts and state machine; the concerns are mixins on top of it."""

    driver: Driver
    """Moves the AGV from node to node under traffic control (built by `Vehicle`, its host)."""
    routes: Routes
    """The routes and hop kinematics of the AGV's vehicle type (its driver's)."""

    def __init__(self, agv_id: int, env: simpy.Environment, traffic: Traffic,
                 fleet: FleetManagerLink, recorder: Recorder, scenario: Scenario,
                 incident_rng: np.random.Generator, profile: VehicleProfile,
                 segment_facts: dict[tuple[str, str], SegmentFacts] | None) -> None:
        self.id = agv_id
        self.env = env
        self.traffic = traffic
        self.recorder = recorder
        self.profile = profile
        self.state = VehicleState.BOOTING
        self.order: Order | None = None
        self.failing = False
        self.process: simpy.Process | None = None
        self.rules: Rules = scenario.rules
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

    # ---- steps every concern takes --------------------------------------------------------------
    def fail_now(self, code: str) -> NoReturn:
        """A fault found by the AGV's own process: raise it as an interrupt to itself."""
        self.failing = True
        raise simpy.Interrupt(Failure(code))

    def _link_changed(self) -> None:
        """Wake the AGV's waits on the FMS link (`link_changed`): lost or back."""
        if not self.link_changed.triggered:
            self.link_changed.succeed()
        self.link_changed = self.env.event()

    def _unpark(self) -> Proc:
        """Leave the parking bay for the track (an order or a charger has come)."""
        place = self.parked_in
        assert place is not None
        yield from self.driver.reenter_track(place.nodes[0])
        self.driver.parked_in = None
        self.fleet.release_parking(place)

    # ---- the concerns' steps that the others call (defined in the mixins) --------------------
    def _drive_to(self, goal: str) -> Proc:
        """Drive to `goal` under the FMS link rules (fleet_sim.sim.agents.vehicle_link)."""
        raise NotImplementedError

    def _charge(self) -> Proc:
        """Ask for a charger, drive there and charge (fleet_sim.sim.agents.vehicle_charging)."""
        raise NotImplementedError

    def _charge_trigger(self) -> str:
        """The event that sends the AGV to a charger (fleet_sim.sim.agents.vehicle_charging)."""
        raise NotImplementedError
