"""The AGV process: drives routes hop by hop under traffic control and serves orders.

Driving (see fleet_sim.traffic for the rules): standing at a node, the AGV takes the next node
(waiting if it must), then tries to take the node after it; with it, it may pass through the next
node at the highest speed from which it could still stop at the one after; without it, it brakes
to stop at the next node. Each hop's time is closed form (fleet_sim.kinematics).

The order cycle uses the states and triggers of RSS-AGV-001 4.2: Idle -(Event_Transport_Order)->
Moving -(Event_Arrived_Pickup)-> Loading -(Event_Load_Complete)-> Moving -(Event_Arrived_Dropoff)->
Unloading -(Event_Unload_Complete)-> Idle. Trips to parking are Moving with purpose ``to_parking``.
"""

from __future__ import annotations

import itertools
from collections.abc import Generator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import simpy

from fleet_sim.errors import SimulationError
from fleet_sim.layout import Place
from fleet_sim.records import Order, Recorder
from fleet_sim.scenario import TrafficConfig, VehicleProfile
from fleet_sim.states import State
from fleet_sim.traffic import Claim, Escape, Lock, Traffic

if TYPE_CHECKING:
    from fleet_sim.fleet_manager import FleetManager

Proc = Generator[simpy.Event, Any, Any]


@dataclass(slots=True)
class Held:
    node: str
    claim: Claim
    since_s: float
    behind_m: float = 0.0
    """How far the AGV has driven past this node."""


class Vehicle:
    def __init__(self, agv_id: int, env: simpy.Environment, traffic: Traffic,
                 fleet: FleetManager, recorder: Recorder, profile: VehicleProfile,
                 config: TrafficConfig, rng: np.random.Generator) -> None:
        self.id = agv_id
        self.env = env
        self.traffic = traffic
        self.fleet = fleet
        self.recorder = recorder
        self.profile = profile
        self.config = config
        self.rng = rng
        self.clear_m = profile.length_m + profile.min_gap_m
        self.node = ""
        self.prev: str | None = None
        self.speed_mps = 0.0
        self.held: list[Held] = []
        self.ahead: list[Held] = []
        self.corridors: dict[int, tuple[Claim, str | None]] = {}
        """Corridor id -> (claim, entry node while not yet entered, None once inside)."""
        self.goal: str | None = None
        self.next_node: str | None = None
        self.order: Order | None = None
        self.parked_in: Place | None = None
        self.escape: Escape | None = None
        self.work: simpy.Event = env.event()
        self.state = State.BOOTING
        self.process: simpy.Process | None = None
        traffic.vehicles[agv_id] = self

    # ---- placement --------------------------------------------------------------------------
    def place_at(self, node: str) -> None:
        """Stand on `node` at t=0 (holding it, and its corridor if it is inside one)."""
        corridor = self.traffic.layout.corridor_at(node)
        if corridor is not None:
            claim = self.traffic.corridor_locks[corridor.id].claim(self.id)
            if not claim.triggered:
                raise SimulationError(f"AGV {self.id} starts in corridor {corridor.id}, "
                                      "which another AGV already occupies")
            self.corridors[corridor.id] = (claim, None)
        claim = self.traffic.node_locks[node].claim(self.id)
        if not claim.triggered:
            raise SimulationError(f"AGV {self.id} starts on node {node}, already occupied")
        self.held = [Held(node, claim, self.env.now)]
        self.node = node

    def place_in_parking(self, place: Place) -> None:
        self.parked_in = place
        self.node = place.nodes[0]

    def start(self) -> None:
        self.recorder.event(self.env.now, self.id, "Event_Power_On", "", State.BOOTING.value,
                            self.node)
        self.process = self.env.process(self.run())

    # ---- states -----------------------------------------------------------------------------
    def set_state(self, new: State, trigger: str, detail: str = "") -> None:
        self.recorder.event(self.env.now, self.id, trigger, self.state.value, new.value,
                            self.node, detail)
        self.state = new

    def note(self, event: str, detail: str = "") -> None:
        """Record an event that changes no state (deadlock, reroute, assignment...)."""
        self.recorder.event(self.env.now, self.id, event, self.state.value, self.state.value,
                            self.node, detail)

    @property
    def dispatch_node(self) -> str:
        """Where the dispatcher should measure travel from: the node the AGV is committed to."""
        if self.ahead:
            return self.ahead[-1].node
        return self.node

    # ---- the order cycle --------------------------------------------------------------------
    def run(self) -> Proc:
        yield self.env.timeout(self.profile.boot_s)
        self.set_state(State.IDLE, "Event_Init_Complete")
        while True:
            if self.order is None:
                yield from self._idle()
            assert self.order is not None
            yield from self._serve(self.order)

    def _idle(self) -> Proc:
        self.work = self.env.event()
        self.fleet.vehicle_idle(self)
        while self.order is None:
            place = None
            if self.parked_in is None and self.fleet.config.park_idle:
                place = self.fleet.reserve_parking(self)
            if place is None:
                yield self.work
                continue
            self.set_state(State.MOVING, "Event_Transport_Order", "to_parking")
            access = place.nodes[0]
            yield from self.drive(access, stop_for_order=True)
            if self.order is None and self.node == access:
                # drive off the tape into a bay, at turn speed, before letting go of the track
                yield self.env.timeout(self.clear_m / self.profile.turn_speed_mps)
                self._enter_parking(place)
                self.set_state(State.IDLE, "Event_Arrived_Parking", place.id)
            else:
                self.fleet.release_parking(place)
                if self.order is None:
                    self.set_state(State.IDLE, "Event_Stop")

    def _serve(self, order: Order) -> Proc:
        if self.parked_in is not None:
            yield from self._leave_parking()
        assert order.pickup_node is not None and order.dropoff_node is not None
        self.set_state(State.MOVING, "Event_Transport_Order", f"to_pickup order {order.id}")
        yield from self.drive(order.pickup_node)
        order.pickup_arrival_s = self.env.now
        self.set_state(State.LOADING, "Event_Arrived_Pickup", f"order {order.id}")
        yield self.env.timeout(order.pickup_handling_s)
        order.picked_s = self.env.now
        self.fleet.left_station(order.pickup_node)
        self.set_state(State.MOVING, "Event_Load_Complete", f"to_dropoff order {order.id}")
        yield from self.drive(order.dropoff_node)
        order.dropoff_arrival_s = self.env.now
        self.set_state(State.UNLOADING, "Event_Arrived_Dropoff", f"order {order.id}")
        yield self.env.timeout(order.dropoff_handling_s)
        order.delivered_s = self.env.now
        self.fleet.left_station(order.dropoff_node)
        self.order = None
        self.set_state(State.IDLE, "Event_Unload_Complete", f"order {order.id}")

    # ---- parking ------------------------------------------------------------------------------
    def _enter_parking(self, place: Place) -> None:
        """Drive off the tape into the parking area: every lock is let go."""
        for held in self.held:
            self._release(held)
        self.held = []
        for cid in list(self.corridors):
            self._release_corridor(cid)
        self.parked_in = place
        self.prev = None

    def _leave_parking(self) -> Proc:
        place = self.parked_in
        assert place is not None
        access = place.nodes[0]
        corridor = self.traffic.layout.corridor_at(access)
        if corridor is not None:
            lock = self.traffic.corridor_locks[corridor.id]
            claim = lock.claim(self.id)
            yield from self._wait(lock, claim, may_escape=False)
            self.corridors[corridor.id] = (claim, None)
        lock = self.traffic.node_locks[access]
        claim = lock.claim(self.id)
        yield from self._wait(lock, claim, may_escape=False)
        self.held = [Held(access, claim, self.env.now)]
        self.traffic.version += 1
        self.node = access
        self.parked_in = None
        self.fleet.release_parking(place)

    # ---- driving ------------------------------------------------------------------------------
    def drive(self, goal: str, stop_for_order: bool = False) -> Proc:
        """Drive to `goal` and stop there, holding it. With `stop_for_order`, stop at the first
        node where the AGV can once an order has been assigned to it."""
        self.goal = goal
        path = self.traffic.route(self.node, goal)
        i = 0
        while self.node != self.goal:
            nxt = path[i + 1]
            self.next_node = nxt
            if not self.ahead:
                after = path[i + 2] if i + 2 < len(path) else None
                taken = yield from self._take(nxt, after)
                if not taken:
                    path = yield from self._get_out()
                    i = 0
                    continue
            v_end_max = 0.0
            if nxt != self.goal and i + 2 < len(path):
                w = path[i + 2]
                x = path[i + 3] if i + 3 < len(path) else None
                if self._try_take(nxt, w, x):
                    v_end_max = self.traffic.pass_speed_mps(self.node, nxt, w)
            yield from self._hop(nxt, v_end_max)
            i += 1
            if stop_for_order and self.order is not None:
                self.goal = self.ahead[-1].node if self.ahead else self.node
        self.next_node = None
        self._drop_pending_corridors()
        if self.ahead or self.speed_mps > 1e-9:
            raise SimulationError(f"AGV {self.id} ended a drive at {self.node} still moving")

    def _hop(self, nxt: str, v_end_max: float) -> Proc:
        u = self.node
        corridor = self.traffic.layout.corridor_of(u, nxt)
        if corridor is not None and corridor.id not in self.corridors:
            raise SimulationError(f"AGV {self.id} about to enter corridor {corridor.id} "
                                  f"({u} -> {nxt}) without holding it")
        time_s, v_end = self.traffic.hop(self.prev, u, nxt, self.speed_mps, v_end_max)
        start = self.env.now
        yield self.env.timeout(time_s)
        length = self.traffic.graph.edges[u, nxt]["length_m"]
        self.recorder.drove(start, self.env.now, length)
        if self.recorder.trace_occupancy:
            self.recorder.occupied("segment", f"{u}>{nxt}", self.id, start, self.env.now)
        self.prev, self.node, self.speed_mps = u, nxt, v_end
        arrived = self.ahead.pop(0)
        for held in self.held:
            held.behind_m += length
        self.held.append(arrived)
        while len(self.held) > 1 and self.held[0].behind_m >= self.clear_m - 1e-9:
            self._release(self.held.pop(0))
        if corridor is not None:
            claim, _ = self.corridors[corridor.id]
            self.corridors[corridor.id] = (claim, None)
        self._release_left_corridors()

    def _take(self, node: str, after: str | None) -> Generator[simpy.Event, Any, bool]:
        """Take `node` (and the corridors the AGV enters on its way), waiting if need be.
        False when the AGV gave up waiting and must find another way."""
        taken_corridors: list[int] = []
        for a, b in ((self.node, node), (node, after)):
            corridor = self.traffic.entry_corridor(a, b)
            if corridor is None or corridor.id in self.corridors:
                continue
            lock = self.traffic.corridor_locks[corridor.id]
            claim = lock.claim(self.id)
            ok = yield from self._wait(lock, claim)
            if not ok:
                for cid in taken_corridors:
                    self._release_corridor(cid)
                return False
            self.corridors[corridor.id] = (claim, a)
            taken_corridors.append(corridor.id)
        lock = self.traffic.node_locks[node]
        claim = lock.claim(self.id)
        ok = yield from self._wait(lock, claim)
        if not ok:
            for cid in taken_corridors:
                self._release_corridor(cid)
            return False
        self.ahead.append(Held(node, claim, self.env.now))
        self.traffic.version += 1
        return True

    def _try_take(self, via: str, node: str, after: str | None) -> bool:
        """Take `node` now if it and the corridors on the way are free; never wait."""
        traffic = self.traffic
        needed: list[tuple[int, str]] = []
        for a, b in ((via, node), (node, after)):
            corridor = traffic.entry_corridor(a, b)
            if corridor is None or corridor.id in self.corridors:
                continue
            if not traffic.corridor_locks[corridor.id].is_free:
                return False
            needed.append((corridor.id, a))
        lock = traffic.node_locks[node]
        if not lock.is_free:
            return False
        for cid, entry in needed:
            self.corridors[cid] = (traffic.corridor_locks[cid].claim(self.id), entry)
        self.ahead.append(Held(node, lock.claim(self.id), self.env.now))
        traffic.version += 1
        return True

    def _wait(self, lock: Lock, claim: Claim,
              may_escape: bool = True) -> Generator[simpy.Event, Any, bool]:
        """Wait for `claim`. Returns True once held; False if the AGV gave up (deadlock victim,
        or blocked for long with another route at hand) and the claim was withdrawn."""
        if claim.triggered:
            return True
        env = self.env
        traffic = self.traffic
        start = env.now
        traffic.waiting[self.id] = lock
        traffic.version += 1
        looked_at: tuple[int, bool, bool] | None = None
        try:
            while True:
                waited = env.now - start
                now_seen = (traffic.version, waited >= self.config.give_way_after_s,
                            waited >= self.config.replan_after_s)
                if may_escape and now_seen != looked_at:  # nothing changed, nothing to look at
                    looked_at = now_seen
                    if self._deadlocked() or self._takes_other_way(now_seen[1], now_seen[2]):
                        claim.cancel()
                        return False
                try:
                    yield claim | env.timeout(self.config.deadlock_check_s)
                except simpy.Interrupt:
                    if claim.triggered:
                        self.escape = None
                        return True
                    claim.cancel()
                    return False
                if claim.triggered:
                    return True
        finally:
            del traffic.waiting[self.id]
            traffic.version += 1
            self.recorder.blocked(start, env.now)

    def _takes_other_way(self, may_give_way: bool, may_replan: bool) -> bool:
        """Blocked long enough: take another route if there is one; with someone queued behind,
        circulate rather than block them."""
        give_way = may_give_way and self.traffic.blocks_others(self)
        if not (give_way or may_replan):
            return False
        escape = self.traffic.escape_for(self)
        if escape is None or not (escape.kind == "reroute"
                                  or (give_way and escape.kind == "circulate")):
            return False
        self.escape = escape
        return True

    def _deadlocked(self) -> bool:
        """Look for a wait-for cycle through this AGV; resolve it. True if this AGV must move."""
        traffic = self.traffic
        cycle = traffic.find_cycle(self.id)
        if cycle is None:
            return False
        vehicles = [traffic.vehicles[m] for m in cycle]
        if any(v.escape is not None for v in vehicles):
            return False  # already being resolved
        new = traffic.new_cycle(cycle)
        members = " ".join(str(m) for m in cycle)
        locks = " ".join(traffic.waiting[m].key for m in cycle)
        if new:
            self.recorder.deadlocks += 1
            self.note("deadlock_detected", f"agvs {members} waiting for {locks}")
        # Member i holds the lock that member i-1 waits for; its escape must let go of it.
        options = [(v, traffic.escape_for(v, traffic.waiting[cycle[i - 1]]))
                   for i, v in enumerate(vehicles)]
        chosen: tuple[Vehicle, Escape] | None = None
        for kind in ("yield", "reroute", "circulate", "backoff"):
            for vehicle, escape in options:
                if escape is not None and escape.kind == kind:
                    chosen = (vehicle, escape)
                    break
            if chosen is not None:
                break
        if chosen is None:
            if new:
                self.note("deadlock_unresolved", f"agvs {members}: no free way out yet")
            return False
        victim, escape = chosen
        victim.note("deadlock_resolved", f"{escape.kind} via {' '.join(escape.path)}")
        victim.escape = escape
        if victim is self:
            return True
        assert victim.process is not None
        victim.process.interrupt("deadlock")
        return False

    def _get_out(self) -> Generator[simpy.Event, Any, list[str]]:
        """After giving up a wait: take the escape (another route, or one hop back), or wait a
        little and try the usual route again. Returns the new path from the current node."""
        escape = self.escape or self.traffic.escape_for(self)
        self.escape = None
        self._drop_pending_corridors()
        assert self.goal is not None
        if escape is not None and escape.kind in ("reroute", "circulate"):
            self.note(escape.kind, " ".join(escape.path[:4]) + (" ..." if len(escape.path) > 4
                                                                 else ""))
            return list(escape.path)
        if escape is not None and escape.kind == "backoff":
            step = escape.path[1]
            if self._try_take(self.node, step, None):
                self.note("backoff", f"{self.node} -> {step}")
                yield from self._hop(step, 0.0)
                return self.traffic.route(self.node, self.goal)
        yield self.env.timeout(float(self.rng.exponential(self.config.backoff_s)))
        return self.traffic.route(self.node, self.goal)

    # ---- releasing ------------------------------------------------------------------------------
    def _release(self, held: Held) -> None:
        lock = self.traffic.node_locks[held.node]
        lock.release(held.claim)
        self.traffic.version += 1
        self.recorder.occupied("node", held.node, self.id, held.since_s, self.env.now)

    def _release_corridor(self, cid: int) -> None:
        claim, _ = self.corridors.pop(cid)
        self.traffic.corridor_locks[cid].release(claim)
        self.traffic.version += 1

    def _release_left_corridors(self) -> None:
        """Let go of corridors the AGV has entered and fully left, and of pending ones whose
        entry node it is no longer at or heading to."""
        if not self.corridors:
            return
        layout = self.traffic.layout
        nodes = [h.node for h in self.held]
        spots = set(nodes) | {h.node for h in self.ahead}
        for cid, (_, entry) in list(self.corridors.items()):
            corridor = layout.corridors[cid]
            if entry is not None:
                if entry not in spots:
                    self._release_corridor(cid)
                continue
            if any(n in corridor.members for n in nodes):
                continue
            if any((a, b) in corridor.segments for a, b in itertools.pairwise(nodes)):
                continue
            self._release_corridor(cid)

    def _drop_pending_corridors(self) -> None:
        for cid, (_, entry) in list(self.corridors.items()):
            if entry is not None:
                self._release_corridor(cid)
