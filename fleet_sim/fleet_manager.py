"""The fleet manager (FMS): takes orders, assigns them to AGVs, sends idle AGVs to parking.

Dispatch policies (scenario `dispatch.policy`), both serving orders oldest first:

* ``nearest_idle``: the idle AGV with the shortest free-flow travel time to the order's pickup
  (ties: lowest AGV id).
* ``fcfs``: the AGV that has been idle longest, wherever it is.

An AGV counts as idle from the moment it has no order, including while it drives to parking; an
order assigned to it then turns it round at the next node where it can stop.
A station with several docking nodes sends each AGV to the node with the fewest AGVs bound for it.
"""

from __future__ import annotations

from collections import Counter, deque
from typing import TYPE_CHECKING

import simpy

from fleet_sim.layout import Layout, Place
from fleet_sim.records import Order, Recorder
from fleet_sim.scenario import DispatchConfig
from fleet_sim.traffic import Traffic

if TYPE_CHECKING:
    from fleet_sim.vehicle import Vehicle


class FleetManager:
    def __init__(self, env: simpy.Environment, layout: Layout, traffic: Traffic,
                 config: DispatchConfig, recorder: Recorder) -> None:
        self.env = env
        self.layout = layout
        self.traffic = traffic
        self.config = config
        self.recorder = recorder
        self.waiting: deque[Order] = deque()
        self.idle: list[Vehicle] = []
        self.parking_free = {p.id: p.capacity for p in layout.parking}
        self.bound_for: Counter[str] = Counter()
        recorder.queue_trace.append((env.now, 0))

    # ---- orders -----------------------------------------------------------------------------
    def submit(self, order: Order) -> None:
        self.recorder.orders.append(order)
        self.waiting.append(order)
        self._dispatch()

    def vehicle_idle(self, vehicle: Vehicle) -> None:
        self.idle.append(vehicle)
        self._dispatch()

    def left_station(self, node: str) -> None:
        self.bound_for[node] -= 1

    def _dispatch(self) -> None:
        changed = False
        while self.waiting and self.idle:
            order = self.waiting.popleft()
            order.pickup_node = self._docking_node(self.layout.places[order.pickup])
            vehicle = self._choose(order.pickup_node)
            self.idle.remove(vehicle)
            order.dropoff_node = self._docking_node(self.layout.places[order.dropoff])
            order.agv = vehicle.id
            order.assigned_s = self.env.now
            vehicle.order = order
            vehicle.note("order_assigned", f"order {order.id} {order.pickup} -> {order.dropoff}")
            if not vehicle.work.triggered:
                vehicle.work.succeed()
            changed = True
        if changed or not self.recorder.queue_trace \
                or self.recorder.queue_trace[-1][1] != len(self.waiting):
            self.recorder.queue_trace.append((self.env.now, len(self.waiting)))

    def _choose(self, pickup_node: str) -> Vehicle:
        if self.config.policy == "fcfs":
            return self.idle[0]
        return min(self.idle,
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
