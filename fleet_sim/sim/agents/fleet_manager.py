"""The fleet manager (FMS): takes orders, assigns them to AGVs, sends idle AGVs to parking.

Dispatch policies (scenario `dispatch.policy`), both serving orders oldest first:

* ``nearest_idle``: the idle AGV with the shortest free-flow travel time to the order's pickup
  (ties: lowest AGV id).
* ``fcfs``: the AGV that has been idle longest, wherever it is.

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
from typing import TYPE_CHECKING, Any

import simpy

from fleet_sim.config.layout import Layout, Place
from fleet_sim.config.scenario import DispatchConfig
from fleet_sim.model.records import Order, Recorder
from fleet_sim.sim.commands import CommandPath
from fleet_sim.sim.traffic.control import Traffic

if TYPE_CHECKING:
    from fleet_sim.sim.agents.vehicle import Vehicle


class FleetManager:
    def __init__(self, env: simpy.Environment, layout: Layout, traffic: Traffic,
                 config: DispatchConfig, recorder: Recorder, commands: CommandPath) -> None:
        self.env = env
        self.commands = commands
        self.offers: dict[int, int] = {}
        """AGV id -> count of its offers to work; an offer noticed late counts if still current."""
        self.assigning: set[int] = set()
        """AGVs an order has been decided for, while the assign command is on its way."""
        self.layout = layout
        self.traffic = traffic
        self.config = config
        self.recorder = recorder
        self.waiting: deque[Order] = deque()
        self.idle: list[Vehicle] = []
        self.parking_free = {p.id: p.capacity for p in layout.parking}
        self.bound_for: Counter[str] = Counter()
        self.chargers_free: list[Place] = list(layout.chargers)
        self.charger_queue: deque[tuple[Vehicle, simpy.Event]] = deque()
        recorder.queue_lengths.append((env.now, 0))

    # ---- orders -----------------------------------------------------------------------------
    def submit(self, order: Order) -> None:
        self.recorder.orders.append(order)
        self.waiting.append(order)
        self._dispatch()

    def vehicle_idle(self, vehicle: Vehicle) -> None:
        """The AGV is free; the fleet manager knows at once, or at its next status poll."""
        if vehicle.id in self.assigning:
            return
        offer = self.offers.get(vehicle.id, 0) + 1
        self.offers[vehicle.id] = offer
        delay = self.commands.notice_delay_s(vehicle.id)
        if delay <= 0:
            self._take_offer(vehicle, offer)
        else:
            self.env.process(self._notice(vehicle, offer, delay))

    def _notice(self, vehicle: Vehicle, offer: int,
                delay: float) -> Generator[simpy.Event, Any, None]:
        yield self.env.timeout(delay)
        self._take_offer(vehicle, offer)

    def _take_offer(self, vehicle: Vehicle, offer: int) -> None:
        if self.offers.get(vehicle.id) == offer and vehicle not in self.idle:
            self.idle.append(vehicle)
            self._dispatch()

    def withdraw(self, vehicle: Vehicle) -> None:
        """The AGV is no longer available for orders (charging, failed...)."""
        self.offers[vehicle.id] = self.offers.get(vehicle.id, 0) + 1
        if vehicle in self.idle:
            self.idle.remove(vehicle)

    def link_restored(self) -> None:
        self._dispatch()

    def give_back(self, vehicle: Vehicle, order: Order) -> None:
        """An order its AGV cannot carry out goes back to the front of the queue."""
        for node in (order.pickup_node, order.dropoff_node):
            if node is not None:
                self.bound_for[node] -= 1
        order.pickup_node = order.dropoff_node = None
        order.agv = None
        order.assigned_s = None
        order.reassigned += 1
        vehicle.note("order_reassigned", f"order {order.id}")
        self.waiting.appendleft(order)
        self._dispatch()

    def order_failed(self, order: Order, code: str) -> None:
        order.failed_s = self.env.now
        order.failure = code
        if order.pickup_node is not None and order.picked_s is None:
            self.bound_for[order.pickup_node] -= 1
        if order.dropoff_node is not None:
            self.bound_for[order.dropoff_node] -= 1

    # ---- chargers -------------------------------------------------------------------------------
    def charger_available(self) -> bool:
        return bool(self.chargers_free) and not self.charger_queue

    def request_charger(self, vehicle: Vehicle) -> simpy.Event:
        """An event that succeeds with the charger assigned to `vehicle`."""
        self.withdraw(vehicle)
        event = self.env.event()
        self.charger_queue.append((vehicle, event))
        self._assign_chargers()
        return event

    def cancel_charger_request(self, vehicle: Vehicle) -> None:
        self.charger_queue = deque((v, e) for v, e in self.charger_queue if v is not vehicle)

    def release_charger(self, place: Place) -> None:
        self.chargers_free.append(place)
        self._assign_chargers()

    def _assign_chargers(self) -> None:
        while self.chargers_free and self.charger_queue:
            vehicle, event = self.charger_queue.popleft()
            place = min(self.chargers_free, key=lambda c: (
                self.traffic.travel_time_s(vehicle.dispatch_node, c.nodes[0]), c.id))
            self.chargers_free.remove(place)
            self.commands.send("assign", partial(event.succeed, place))
    def left_station(self, node: str) -> None:
        self.bound_for[node] -= 1

    def _dispatch(self) -> None:
        changed = False
        while self.waiting and self.idle:
            order = self.waiting[0]
            pickup = self.layout.places[order.pickup]
            vehicle = self._choose(min(pickup.nodes, key=lambda n: self.bound_for[n]))
            if vehicle is None:
                break
            self.waiting.popleft()
            order.pickup_node = self._docking_node(pickup)
            self.idle.remove(vehicle)
            order.dropoff_node = self._docking_node(self.layout.places[order.dropoff])
            order.agv = vehicle.id
            order.assigned_s = self.env.now
            self.assigning.add(vehicle.id)
            self.commands.send("assign", partial(self._deliver, vehicle, order))
            changed = True
        if changed or not self.recorder.queue_lengths \
                or self.recorder.queue_lengths[-1][1] != len(self.waiting):
            self.recorder.queue_lengths.append((self.env.now, len(self.waiting)))

    def _deliver(self, vehicle: Vehicle, order: Order) -> None:
        """The assign command has reached the AGV."""
        self.assigning.discard(vehicle.id)
        vehicle.order = order
        vehicle.note("order_assigned", f"order {order.id} {order.pickup} -> {order.dropoff}")
        if not vehicle.work.triggered:
            vehicle.work.succeed()

    def _choose(self, pickup_node: str) -> Vehicle | None:
        ready = [v for v in self.idle if v.fms_link]
        if not ready:
            return None
        if self.config.policy == "fcfs":
            return ready[0]
        return min(ready,
                   key=lambda v: (self.traffic.travel_time_s(v.dispatch_node, pickup_node), v.id))

    def _docking_node(self, place: Place) -> str:
        node = min(place.nodes, key=lambda n: self.bound_for[n])
        self.bound_for[node] += 1
        return node

    # ---- parking ----------------------------------------------------------------------------
    def reserve_parking(self, vehicle: Vehicle) -> Place | None:
        """The nearest parking area with room, now reserved for `vehicle`; None if all are full."""
        free = [p for p in self.layout.parking if self.parking_free[p.id] > 0]
        if not free:
            return None
        place = min(free, key=lambda p: (self.traffic.travel_time_s(vehicle.node, p.nodes[0]),
                                         p.id))
        self.parking_free[place.id] -= 1
        return place

    def release_parking(self, place: Place) -> None:
        self.parking_free[place.id] += 1
