"""The fleet manager (FMS): takes orders, assigns them to AGVs, sends idle AGVs to parking.

Orders are served oldest first; which idle AGV gets one is the dispatch policy's choice
(fleet_sim.sim.agents.dispatch, handed to the constructor). The fleet manager knows AGVs only
through `FleetAgv` (declared here) and hands an order over by calling `FleetAgv.assign`; it never
writes an AGV's attributes.

An AGV counts as idle from the moment it has no order, including while it drives to parking; an
order assigned to it then turns it round at the next node where it can stop. AGVs without an FMS
link take no orders. A station with several docking nodes sends each AGV to the node with the
fewest AGVs bound for it.

Chargers: an AGV asks for one; the fleet manager gives it the nearest free charger, or queues it
(first come, first served) until one frees up. One AGV per charger.
Orders of a failed AGV: one not yet loaded goes back to the front of the queue; a loaded one is
recorded as failed (its load is with the broken AGV).
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Generator
from functools import partial
from typing import Any, Protocol

import simpy

from fleet_sim.config.layout import Layout, Place
from fleet_sim.config.scenario import DispatchConfig
from fleet_sim.model.records import Order, Recorder
from fleet_sim.sim.agents.dispatch import POLICIES, DispatchPolicy
from fleet_sim.sim.commands import CommandPath
from fleet_sim.sim.traffic.control import Traffic


class FleetAgv(Protocol):
    """What the fleet manager knows of an AGV."""

    @property
    def id(self) -> int: ...

    @property
    def node(self) -> str: ...

    @property
    def dispatch_node(self) -> str:
        """The node the AGV is committed to: where travel to a pickup is measured from."""
        ...

    @property
    def fms_link(self) -> bool:
        """The AGV hears the fleet manager (no orders for it otherwise)."""
        ...

    def note(self, event: str, detail: str = "") -> None:
        """Record an event about the AGV that changes no state (order_assigned...)."""

    def assign(self, order: Order) -> None:
        """The assign command with `order` has reached the AGV."""





class FleetManager:
    def __init__(self, env: simpy.Environment, layout: Layout, traffic: Traffic,
                 config: DispatchConfig, recorder: Recorder, commands: CommandPath,
                 policy: DispatchPolicy | None = None) -> None:
        self.env = env
        self.commands = commands
        self.offers: dict[int, int] = {}
        """AGV id -> count of its offers to work; an offer noticed late counts if still current."""
        self.assigning: set[int] = set()
        """AGVs an order has been decided for, while the assign command is on its way."""
        self.layout = layout
        self.traffic = traffic
        self.config = config
        self.policy: DispatchPolicy = policy if policy is not None else POLICIES[config.policy]()
        self.recorder = recorder
        self.waiting: deque[Order] = deque()
        self.idle: list[FleetAgv] = []
        self.parking_free = {p.id: p.capacity for p in layout.parking}
        self.bound_for: Counter[str] = Counter()
        self.chargers_free: list[Place] = list(layout.chargers)
        self.charger_queue: deque[tuple[FleetAgv, simpy.Event]] = deque()
        self.queue_recorded = 0
        """The queue length last recorded (`recorder.queue_length`)."""
        recorder.queue_length(env.now, 0)

    # ---- orders -----------------------------------------------------------------------------
    def submit(self, order: Order) -> None:
        self.recorder.order_created(order)
        self.waiting.append(order)
        self._dispatch()

    def vehicle_idle(self, agv: FleetAgv) -> None:
        """The AGV is free; the fleet manager knows at once, or at its next status poll."""
        if agv.id in self.assigning:
            return
        offer = self.offers.get(agv.id, 0) + 1
        self.offers[agv.id] = offer
        delay = self.commands.notice_delay_s(agv.id)
        if delay <= 0:
            self._take_offer(agv, offer)
        else:
            self.env.process(self._notice(agv, offer, delay))

    def _notice(self, agv: FleetAgv, offer: int,
                delay: float) -> Generator[simpy.Event, Any, None]:
        yield self.env.timeout(delay)
        self._take_offer(agv, offer)

    def _take_offer(self, agv: FleetAgv, offer: int) -> None:
        if self.offers.get(agv.id) == offer and agv not in self.idle:
            self.idle.append(agv)
            self._dispatch()

    def withdraw(self, agv: FleetAgv) -> None:
        """The AGV is no longer available for orders (charging, failed...)."""
        self.offers[agv.id] = self.offers.get(agv.id, 0) + 1
        if agv in self.idle:
            self.idle.remove(agv)

    def link_restored(self) -> None:
        self._dispatch()

    @property
    def park_idle(self) -> bool:
        """Idle AGVs drive to parking (scenario `dispatch.park_idle`)."""
        return self.config.park_idle

    def requeue(self, agv: FleetAgv, order: Order) -> None:
        """An order its AGV cannot carry out goes back to the front of the queue."""
        for node in (order.pickup_node, order.dropoff_node):
            if node is not None:
                self.bound_for[node] -= 1
        order.pickup_node = order.dropoff_node = None
        order.agv = None
        order.assigned_s = None
        order.reassigned += 1
        agv.note("order_reassigned", f"order {order.id}")
        self.waiting.appendleft(order)
        self._dispatch()

    def order_failed(self, order: Order, code: str) -> None:
        order.failed_s = self.env.now
        order.failure = code
        self.recorder.order_finished(order)
        if order.pickup_node is not None and order.picked_s is None:
            self.bound_for[order.pickup_node] -= 1
        if order.dropoff_node is not None:
            self.bound_for[order.dropoff_node] -= 1

    # ---- chargers -------------------------------------------------------------------------------
    def charger_available(self) -> bool:
        return bool(self.chargers_free) and not self.charger_queue

    def request_charger(self, agv: FleetAgv) -> simpy.Event:
        """An event that succeeds with the charger assigned to `agv`."""
        self.withdraw(agv)
        event = self.env.event()
        self.charger_queue.append((agv, event))
        self._assign_chargers()
        return event

    def cancel_charger_request(self, agv: FleetAgv) -> None:
        self.charger_queue = deque((v, e) for v, e in self.charger_queue if v is not agv)

    def release_charger(self, place: Place) -> None:
        self.chargers_free.append(place)
        self._assign_chargers()

    def _assign_chargers(self) -> None:
        while self.chargers_free and self.charger_queue:
            agv, event = self.charger_queue.popleft()
            place = min(self.chargers_free, key=lambda c: (
                self.traffic.travel_time_s(agv.dispatch_node, c.nodes[0]), c.id))
            self.chargers_free.remove(place)
            self.commands.send("assign", partial(event.succeed, place))

    def left_station(self, node: str) -> None:
        self.bound_for[node] -= 1

    def _dispatch(self) -> None:
        changed = False
        while self.waiting and self.idle:
            order = self.waiting[0]
            pickup = self.layout.places[order.pickup]
            agv = self._choose(min(pickup.nodes, key=lambda n: self.bound_for[n]))
            if agv is None:
                break
            self.waiting.popleft()
            order.pickup_node = self._docking_node(pickup)
            self.idle.remove(agv)
            order.dropoff_node = self._docking_node(self.layout.places[order.dropoff])
            order.agv = agv.id
            order.assigned_s = self.env.now
            self.assigning.add(agv.id)
            self.commands.send("assign", partial(self._deliver, agv, order))
            changed = True
        if changed or self.queue_recorded != len(self.waiting):
            self.queue_recorded = len(self.waiting)
            self.recorder.queue_length(self.env.now, self.queue_recorded)

    def _deliver(self, agv: FleetAgv, order: Order) -> None:
        """The assign command has reached the AGV."""
        self.assigning.discard(agv.id)
        agv.assign(order)

    def _choose(self, pickup_node: str) -> FleetAgv | None:
        ready = [v for v in self.idle if v.fms_link]
        if not ready:
            return None
        return self.policy.choose(ready, pickup_node, self.traffic.travel_time_s)

    def _docking_node(self, place: Place) -> str:
        node = min(place.nodes, key=lambda n: self.bound_for[n])
        self.bound_for[node] += 1
        return node

    # ---- parking ----------------------------------------------------------------------------
    def reserve_parking(self, agv: FleetAgv) -> Place | None:
        """The nearest parking area with room, now reserved for `agv`; None if all are full."""
        free = [p for p in self.layout.parking if self.parking_free[p.id] > 0]
        if not free:
            return None
        place = min(free, key=lambda p: (self.traffic.travel_time_s(agv.node, p.nodes[0]),
                                         p.id))
        self.parking_free[place.id] -= 1
        return place

    def release_parking(self, place: Place) -> None:
        self.parking_free[place.id] += 1
