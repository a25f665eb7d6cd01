"""Driving under traffic control: the part of an AGV that moves it from node to node.

Standing at a node, the AGV takes the next node (waiting if it must), then tries to take the node
after it; with it, it may pass through the next node at the highest speed from which it could
still stop at the one after; without it, it brakes to stop at the next node. Each hop's time is
closed form (fleet_sim.model.kinematics), or, when the traffic has a motion backend
(`motion: sumo`, fleet_sim.sim.motion.sumo), the time SUMO takes to drive it. See
fleet_sim.sim.traffic and docs/background/engine.md for the rules.

The driver is a client of the reservation table (`TrafficClient`): it asks `Traffic` for each
lock, waits for the claim, and gives it back; it keeps only its own driving bookkeeping (which
claims are behind it and how far). A deadlock victim is told so by a `DeadlockVictim` interrupt
cause; any other interrupt cause (a fault) makes it let go of the claim it waited for and passes
the interrupt on.

Mutex zones: before it takes its first node in a zone, the AGV takes the zone (waiting outside
when it is full, the wait counted in `zone_wait_s`); it lets go once it holds no node in it.
Same-direction zones (fleet_sim.sim.traffic.zones): before it takes the end node from which it
drives into the aisle, the AGV takes the zone for the direction it will drive (waiting outside
while AGVs drive it the other way, counted in `zone_wait_s`); every hop along the aisle must be
the way its claim says; it lets go once it holds no node inside, or when it gives up entering.

`Driver` is the base of `fleet_sim.sim.agents.vehicle.Vehicle`; the hooks `_speed_cap_mps`,
`_travel` and `_arrived` let the vehicle add markers, obstacles, battery use and slow modes to
each hop.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import simpy

from fleet_sim.config.layout import BACKWARD, FORWARD, Place, TrafficZone
from fleet_sim.config.scenario import TrafficConfig
from fleet_sim.config.vehicle import VehicleProfile
from fleet_sim.errors import SimulationError
from fleet_sim.model.kinematics import Piece, traverse
from fleet_sim.model.records import MoveRecord, Order, Recorder
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.traffic.control import Traffic
from fleet_sim.sim.traffic.deadlock import DeadlockVictim
from fleet_sim.sim.traffic.locks import Claim, Lock, ZoneLock
from fleet_sim.sim.traffic.zones import ANY_DIRECTION, DirectedClaim, DirectionGate

Proc = Generator[simpy.Event, Any, Any]

STOP_MARKERS = ("spin", "pause")
"""RSS-AGV-001 5.3 markers that stop the AGV at their node."""
_DIRECTION_NAMES = {FORWARD: "forward", BACKWARD: "backward", ANY_DIRECTION: ""}
"""How the replay's zone rows name a same-direction claim's direction ("": a mutex zone)."""


@dataclass(slots=True)
class Held:
    """A node claim the AGV holds or drives to."""

    node: str
    claim: Claim
    since_s: float
    behind_m: float = 0.0
    """How far the AGV has driven past this node."""


class Driver:
    """Node and corridor locks, routes, hops, waits and deadlock escapes of one AGV."""

    def __init__(self, agv_id: int, env: simpy.Environment, traffic: Traffic,
                 recorder: Recorder, profile: VehicleProfile, config: TrafficConfig,
                 rng: np.random.Generator) -> None:
        self.id = agv_id
        self.env = env
        self.traffic = traffic
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
        self.goal: str | None = None
        self.next_node: str | None = None
        self.order: Order | None = None
        self.parked_in: Place | None = None
        self.failing = False
        self.state = VehicleState.BOOTING
        self.process: simpy.Process | None = None
        self._leg: simpy.Event | None = None
        """The motion backend's event for the hop under way."""
        self._moved = 0.0
        """Share of the hop under way already driven (see `_move`)."""
        self._plan: tuple[tuple[Piece, ...], float, float, float] | None = None
        """With moves recorded: the hop under way's pieces, entry and exit speed and time."""
        self._drive_open: tuple[str, str, float, float] | None = None
        """With moves recorded: the stretch being driven (u, v, since_s, driven_s)."""
        self._wait_open: tuple[float, str, int] | None = None
        """With moves recorded: the lock wait under way (since_s, lock, holder)."""
        traffic.register(self)
        self.routes = traffic.routes_of(agv_id)
        """Routes and hop kinematics of this AGV's vehicle type."""
        self._corridors = traffic.corridors_of(self.id)
        """The corridors traffic has given this AGV (its view of the table, read-only)."""
        self._zones = traffic.zones_of(self.id)
        """The zones traffic has given this AGV (read-only view)."""
        self._zone_since: dict[str, float] = {}
        """Zone id -> when the AGV was given the zone it holds."""
        self._zone_entry: dict[str, str] = {}
        """Same-direction zone id -> the end node from which the AGV will drive in, while it
        holds the zone and is not inside yet."""

    def note(self, event: str, detail: str = "") -> None:
        """Record an event that changes no state (deadlock, reroute, assignment...)."""
        self.recorder.event(self.env.now, self.id, event, self.state.value, self.state.value,
                            self.node, detail)

    def on_deadlock_victim(self, cause: DeadlockVictim) -> None:
        """Traffic chose this AGV to break a wait-for cycle: interrupt its wait."""
        assert self.process is not None
        self.process.interrupt(cause)

    @property
    def in_parking(self) -> bool:
        """In a parking area, off the track."""
        return self.parked_in is not None

    @property
    def dispatch_node(self) -> str:
        """Where the dispatcher should measure travel from: the node the AGV is committed to."""
        if self.ahead:
            return self.ahead[-1].node
        return self.node

    # ---- hooks for the vehicle ------------------------------------------------------------
    def _speed_cap_mps(self) -> float | None:
        """A speed the next hop must not exceed (markers, slow modes), or None."""
        return None

    def _travel(self, u: str, v: str, time_s: float) -> Proc:
        """Drive the hop (the vehicle adds obstacles here). `time_s` is the closed-form
        driving time (0 with a motion backend, which times the hop itself)."""
        yield from self._move(u, v, time_s, 1.0)

    # ---- motion: closed form, or a backend ------------------------------------------------
    def _move(self, u: str, v: str, time_s: float, share: float) -> Proc:
        """Drive on until `share` of the hop u -> v is behind the AGV."""
        backend = self.traffic.motion_backend
        if backend is None:
            if self._plan is not None:
                self._drive_open = (u, v, self.env.now, time_s * self._moved)
            try:
                yield self.env.timeout(time_s * (share - self._moved))
            finally:  # also when a fault interrupts the hop: the AGV stops where it is
                self._close_drive()
        elif share >= 1.0:
            assert self._leg is not None
            yield self._leg
        else:
            yield backend.reach(self.id, u, v, share)
        self._moved = share

    def _pause(self, seconds: float, speed_mps: float = 0.0) -> Proc:
        """Lose `seconds` where the AGV is (line search, obstacle): with a backend, the AGV
        is held at `speed_mps` meanwhile and speeds up again on its own afterwards."""
        backend = self.traffic.motion_backend
        if backend is not None:
            backend.hold(self.id, speed_mps)
        try:
            yield self.env.timeout(seconds)
        finally:
            if backend is not None:
                backend.release(self.id)

    def _halt(self) -> None:
        """A fault stops the AGV where it is."""
        self.speed_mps = 0.0
        if self.traffic.motion_backend is not None:
            self.traffic.motion_backend.halt(self.id)

    def _arrived(self, v: str, length_m: float) -> Proc:
        """At `v` after a hop of `length_m` (the vehicle adds battery use and markers here)."""
        yield from ()

    # ---- placement --------------------------------------------------------------------------
    def place_at(self, node: str) -> None:
        """Stand on `node` at t=0 (holding it, and its corridor if it is inside one)."""
        traffic = self.traffic
        corridor = traffic.layout.corridor_at(node)
        if corridor is not None:
            claim = traffic.request(self.id, traffic.corridor_locks[corridor.id])
            if not claim.triggered:
                raise SimulationError(f"AGV {self.id} starts in corridor {corridor.id}, "
                                      "which another AGV already occupies")
        for zone in self._zones_at(node):
            if not traffic.request(self.id, traffic.zone_locks[zone.id]).triggered:
                raise SimulationError(f"AGV {self.id} starts on node {node} in zone {zone.id}, "
                                      "which is full")
            self._zone_since[zone.id] = self.env.now
        claim = traffic.request(self.id, traffic.node_locks[node])
        if not claim.triggered:
            raise SimulationError(f"AGV {self.id} starts on node {node}, already occupied")
        self.held = [Held(node, claim, self.env.now)]
        self.node = node
        self._placed("track", node)

    def place_in_parking(self, place: Place) -> None:
        self.parked_in = place
        self.node = place.nodes[0]
        self._placed("parking", self.node)

    # ---- on and off the track -------------------------------------------------------------
    def _enter_parking(self, place: Place) -> None:
        """Drive off the tape into the parking area: every lock is let go."""
        for held in self.held:
            self._release(held)
        self.held = []
        for cid in list(self._corridors):
            self._release_corridor(cid)
        self._release_left_zones()
        self.parked_in = place
        self.prev = None
        if self.traffic.motion_backend is not None:
            self.traffic.motion_backend.off_track(self.id)
        self._placed("parking", place.nodes[0])

    def _leave_track(self) -> None:
        """Off the tape (into a parking bay, or taken off by an operator): let go of all."""
        for held in self.held + self.ahead:
            self._release(held)
        self.held, self.ahead = [], []
        for cid in list(self._corridors):
            self._release_corridor(cid)
        self._release_left_zones()
        self.prev, self.speed_mps = None, 0.0
        if self.traffic.motion_backend is not None:
            self.traffic.motion_backend.off_track(self.id)
        self._placed("off", self.node)

    def _reenter_track(self, access: str) -> Proc:
        """Back onto the tape at `access`, once it (its corridor and mutex zones) is free. An
        attempt whose wait traffic breaks (the AGV chosen to break a wait-for cycle) lets go of
        what it took and tries again a deadlock check later."""
        while not (yield from self._try_reenter(access)):
            self.traffic.take_escape(self.id)  # its way out is to stay where it is
            yield self.env.timeout(self.config.deadlock_check_s)
        self.node = access
        self._placed("track", access)

    def _try_reenter(self, access: str) -> Generator[simpy.Event, Any, bool]:
        traffic = self.traffic
        corridor = traffic.layout.corridor_at(access)
        taken: list[Claim] = []
        if corridor is not None:
            lock = traffic.corridor_locks[corridor.id]
            claim = traffic.request(self.id, lock)
            if not (yield from self._wait(lock, claim, may_escape=False)):
                return False
            taken.append(claim)
        for zone in self._zones_at(access):
            gate = traffic.zone_locks[zone.id]
            if not (yield from self._wait_zone(zone.id, gate, traffic.request(self.id, gate),
                                               False)):
                self._let_go_of(taken)
                return False
        lock = traffic.node_locks[access]
        claim = traffic.request(self.id, lock)
        if not (yield from self._wait(lock, claim, may_escape=False)):
            self._let_go_of(taken)
            return False
        self.held = [Held(access, claim, self.env.now)]
        return True

    def _let_go_of(self, corridor_claims: list[Claim]) -> None:
        """Give back what a broken attempt to re-enter took: its corridor, its mutex zones."""
        for claim in corridor_claims:
            self.traffic.free(self.id, claim)
        self._release_left_zones()  # holding no node, it is inside none of them

    # ---- driving ------------------------------------------------------------------------------
    def drive(self, goal: str, stop_early: Callable[[], bool] | None = None) -> Proc:
        """Drive to `goal` and stop there, holding it. When `stop_early()` turns true, stop at
        the first node where the AGV can instead."""
        self.goal = goal
        path = self.traffic.route(self.node, goal, self.id)
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
            stop_marker = self.traffic.layout.markers.get(nxt) in STOP_MARKERS
            if nxt != self.goal and i + 2 < len(path) and not stop_marker:
                w = path[i + 2]
                x = path[i + 3] if i + 3 < len(path) else None
                if self._try_take(nxt, w, x):
                    v_end_max = self.routes.pass_speed_mps(self.node, nxt, w)
            yield from self._hop(nxt, v_end_max)
            i += 1
            if stop_early is not None and stop_early():
                self.goal = self.ahead[-1].node if self.ahead else self.node
        self.next_node = None
        self._drop_pending_corridors()
        if self._zone_entry:
            self._drop_pending_zones()
        if self.ahead or self.speed_mps > 1e-9:
            raise SimulationError(f"AGV {self.id} ended a drive at {self.node} still moving")

    def _hop(self, nxt: str, v_end_max: float) -> Proc:
        u = self.node
        traffic = self.traffic
        corridor = traffic.layout.corridor_of(u, nxt)
        if corridor is not None and corridor.id not in self._corridors:
            raise SimulationError(f"AGV {self.id} about to enter corridor {corridor.id} "
                                  f"({u} -> {nxt}) without holding it")
        cap = self._speed_cap_mps()
        backend = traffic.motion_backend
        self._moved = 0.0
        if backend is not None:  # the backend times the hop; the AGV passes through nxt
            after = self.ahead[1].node if v_end_max > 0 and len(self.ahead) > 1 else None
            self._leg = backend.hop(self.id, self.prev, u, nxt, after, cap)
            time_s = v_end = 0.0
        elif cap is None:
            time_s, v_end = self.routes.hop(self.prev, u, nxt, self.speed_mps, v_end_max)
        else:
            pieces: tuple[Piece, ...] = tuple(
                (length, min(limit, cap))
                for length, limit in self.routes.pieces(self.prev, u, nxt))
            motion = self.routes.motion
            time_s, v_end = traverse(pieces, self.speed_mps, min(v_end_max, cap),
                                     motion.accel_mps2, motion.decel_mps2)
        if self.recorder.record_moves and backend is None:
            self._plan = (self._pieces(u, nxt, cap), self.speed_mps, v_end, time_s)
        start = self.env.now
        yield from self._travel(u, nxt, time_s)
        self._plan = None
        if self._leg is not None:
            if self._moved < 1.0:  # a _travel override that did not drive to the end
                yield from self._move(u, nxt, time_s, 1.0)
            speed = self._leg.value
            assert isinstance(speed, float)
            v_end = speed
            self._leg = None
        length = traffic.routes.edge[u, nxt]["length_m"]
        self.recorder.drove(start, self.env.now, length)
        if self.recorder.record_occupancy:
            self.recorder.occupied("segment", f"{u}>{nxt}", self.id, start, self.env.now)
        self.prev, self.node, self.speed_mps = u, nxt, v_end
        arrived = self.ahead.pop(0)
        for held in self.held:
            held.behind_m += length
        self.held.append(arrived)
        while len(self.held) > 1 and self.held[0].behind_m >= self.clear_m - 1e-9:
            self._release(self.held.pop(0))
        if corridor is not None:
            traffic.entered_corridor(self.id, corridor.id)
        self._release_left_corridors()
        if self._zones:
            self._release_left_zones()
        yield from self._arrived(nxt, length)

    def _take(self, node: str, after: str | None) -> Generator[simpy.Event, Any, bool]:
        """Take `node` (and the corridors the AGV enters on its way), waiting if need be.
        False when the AGV gave up waiting and must find another way."""
        traffic = self.traffic
        taken_corridors: list[int] = []
        for a, b in ((self.node, node), (node, after)):
            corridor = traffic.entry_corridor(a, b)
            if corridor is None or corridor.id in self._corridors:
                continue
            lock = traffic.corridor_locks[corridor.id]
            claim = traffic.request(self.id, lock, entry=a)
            ok = yield from self._wait(lock, claim)
            if not ok:
                for cid in taken_corridors:
                    self._release_corridor(cid)
                return False
            taken_corridors.append(corridor.id)
        for zone in traffic.layout.mutex_zones_at.get(node, ()):
            if zone.id in self._zones:
                continue
            gate = traffic.zone_locks[zone.id]
            ok = yield from self._wait_zone(zone.id, gate, traffic.request(self.id, gate))
            if not ok:
                for cid in taken_corridors:
                    self._release_corridor(cid)
                self._release_left_zones()
                return False
        if traffic.layout.direction_zones_at:
            for a, b in ((self.node, node), (node, after)):
                along = traffic.layout.direction_zone_of(a, b) if b is not None else None
                if along is None:
                    continue
                ok = yield from self._take_direction(along[0].id, along[1], a)
                if not ok:
                    for cid in taken_corridors:
                        self._release_corridor(cid)
                    self._drop_pending_zones()
                    self._release_left_zones()
                    return False
        lock = traffic.node_locks[node]
        claim = traffic.request(self.id, lock)
        ok = yield from self._wait(lock, claim)
        if not ok:
            for cid in taken_corridors:
                self._release_corridor(cid)
            self._release_left_zones()
            return False
        self.ahead.append(Held(node, claim, self.env.now))
        return True

    def _try_take(self, via: str, node: str, after: str | None) -> bool:
        """Take `node` now if it and the corridors on the way are free; never wait."""
        traffic = self.traffic
        needed: list[tuple[int, str]] = []
        for a, b in ((via, node), (node, after)):
            corridor = traffic.entry_corridor(a, b)
            if corridor is None or corridor.id in self._corridors:
                continue
            if not traffic.corridor_locks[corridor.id].is_free:
                return False
            needed.append((corridor.id, a))
        lock = traffic.node_locks[node]
        if not lock.is_free:
            return False
        zones = [z.id for z in traffic.layout.mutex_zones_at.get(node, ())
                 if z.id not in self._zones]
        if any(not traffic.zone_locks[z].is_free for z in zones):
            return False
        directed: dict[str, tuple[int, str]] = {}
        if traffic.layout.direction_zones_at:
            for a, b in ((via, node), (node, after)):
                along = traffic.layout.direction_zone_of(a, b) if b is not None else None
                if along is None:
                    continue
                zone, direction = along
                held = self._zones.get(zone.id)
                if held is not None:
                    if cast(DirectedClaim, held).direction != direction:
                        return False  # never the other way on the claim it holds
                    continue
                if not cast(DirectionGate, traffic.zone_locks[zone.id]).admits(direction):
                    return False
                directed.setdefault(zone.id, (direction, a))
        for zone_id in zones:
            traffic.request(self.id, traffic.zone_locks[zone_id])
            self._zone_since[zone_id] = self.env.now
        for zone_id, (direction, entry) in directed.items():
            traffic.request(self.id, traffic.zone_locks[zone_id], direction=direction)
            self._zone_since[zone_id] = self.env.now
            self._note_entry(zone_id, entry)
        for cid, entry in needed:
            traffic.request(self.id, traffic.corridor_locks[cid], entry=entry)
        self.ahead.append(Held(node, traffic.request(self.id, lock), self.env.now))
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
        traffic.start_waiting(self.id, lock)
        self.recorder.wait_began(self.id, start,
                                 lock.key.zone_id if isinstance(lock.key, ZoneLock) else None)
        if self.recorder.record_moves:
            holder = lock.holder
            self._wait_open = (start, str(lock.key), -1 if holder is None else holder)
        looked_at: tuple[int, bool, bool] | None = None
        try:
            while True:
                waited = env.now - start
                now_seen = (traffic.version, waited >= self.config.give_way_after_s,
                            waited >= self.config.replan_after_s)
                if may_escape and now_seen != looked_at:  # nothing changed, nothing to look at
                    looked_at = now_seen
                    if traffic.resolve_deadlock(self) is not None \
                            or traffic.other_way(self, now_seen[1], now_seen[2]) is not None:
                        traffic.withdraw(self.id, claim)
                        return False
                try:
                    yield claim | env.timeout(self.config.deadlock_check_s)
                except simpy.Interrupt as interrupt:
                    if not isinstance(interrupt.cause, DeadlockVictim):
                        # a fault: let go and pass it on
                        if claim.triggered:
                            traffic.free(self.id, claim)
                        else:
                            traffic.withdraw(self.id, claim)
                        raise
                    if claim.triggered:
                        traffic.take_escape(self.id)  # the way is open after all
                        return True
                    traffic.withdraw(self.id, claim)
                    return False
                if claim.triggered:
                    return True
        finally:
            traffic.stop_waiting(self.id)
            self.recorder.blocked(start, env.now, self.id)
            self._close_wait()

    def _wait_zone(self, zone_id: str, gate: Lock, claim: Claim,
                   may_escape: bool = True) -> Generator[simpy.Event, Any, bool]:
        """`_wait` for a zone, its waiting time counted for the zone."""
        start = self.env.now
        ok = yield from self._wait(gate, claim, may_escape)
        if start < self.env.now:
            self.recorder.zone_waited(zone_id, start, self.env.now)
        if ok:
            self._zone_since[zone_id] = self.env.now
        return ok

    def _zones_at(self, node: str) -> list[TrafficZone]:
        """The mutex zones and the same-direction zone that `node` lies inside."""
        layout = self.traffic.layout
        zones = list(layout.mutex_zones_at.get(node, ()))
        aisle = layout.direction_zones_at.get(node)
        if aisle is not None:
            zones.append(aisle)
        return zones

    def _take_direction(self, zone_id: str, direction: int,
                        entry: str) -> Generator[simpy.Event, Any, bool]:
        """Hold same-direction zone `zone_id` for `direction` before driving along it from
        `entry`: at once if the AGV holds it that way, else by asking (waiting outside, or,
        holding it the other way, turning once alone inside). False if it gave up waiting."""
        traffic = self.traffic
        held = self._zones.get(zone_id)
        if held is not None and cast(DirectedClaim, held).direction == direction:
            return True
        gate = traffic.zone_locks[zone_id]
        since = self._zone_since.get(zone_id, self.env.now)
        claim = traffic.request(self.id, gate, direction=direction)
        ok = yield from self._wait_zone(zone_id, gate, claim)
        if not ok:
            return False
        if held is not None:  # a turn inside: the old claim ends here
            self._record_zone(zone_id, cast(DirectedClaim, held), since)
            traffic.turned(self.id, claim)
            self.note("zone_turn", f"{zone_id} {_DIRECTION_NAMES[direction]}")
        self._note_entry(zone_id, entry)
        return True

    def _note_entry(self, zone_id: str, entry: str) -> None:
        """The AGV holds same-direction zone `zone_id` and will drive in from `entry` (if
        `entry` is an end of it, not inside)."""
        if entry not in self.traffic.layout.traffic_zone_by_id[zone_id].nodes:
            self._zone_entry[zone_id] = entry

    def _get_out(self) -> Generator[simpy.Event, Any, list[str]]:
        """After giving up a wait: take the escape (another route, or one hop back), or wait a
        little and try the usual route again. Returns the new path from the current node."""
        escape = self.traffic.take_escape(self.id) or self.traffic.escape_for(self)
        self._drop_pending_corridors()
        if self._zone_entry:
            self._drop_pending_zones()
        if self._zones:
            self._release_left_zones()
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
                return self.traffic.route(self.node, self.goal, self.id)
        yield self.env.timeout(float(self.rng.exponential(self.config.backoff_s)))
        return self.traffic.route(self.node, self.goal, self.id)

    # ---- the replay's record (moves) ----------------------------------------------------------
    def _pieces(self, u: str, v: str, cap: float | None) -> tuple[Piece, ...]:
        pieces = self.routes.pieces(self.prev, u, v)
        if cap is None:
            return pieces
        return tuple((length, min(limit, cap)) for length, limit in pieces)

    def _placed(self, kind: str, node: str) -> None:
        if self.recorder.record_moves:
            now = self.env.now
            self.recorder.moved(MoveRecord(self.id, kind, now, now, node))

    def _close_drive(self) -> None:
        if self._drive_open is None or self._plan is None:
            return
        u, v, since, driven = self._drive_open
        self._drive_open = None
        now = self.env.now
        if now <= since or not self.recorder.record_moves:
            return
        pieces, v_in, v_out, hop_s = self._plan
        curve_m, curve_mps = pieces[0] if len(pieces) > 1 else (0.0, 0.0)
        motion = self.routes.motion
        self.recorder.moved(MoveRecord(self.id, "drive", since, now, u, v, -1, hop_s, driven,
                                       v_in, v_out, curve_m, curve_mps, pieces[-1][1],
                                       motion.accel_mps2, motion.decel_mps2))

    def _close_wait(self) -> None:
        if self._wait_open is None:
            return
        since, lock, holder = self._wait_open
        self._wait_open = None
        self.recorder.moved(MoveRecord(self.id, "wait", since, self.env.now, self.node, lock,
                                       holder))

    def end_of_run(self) -> None:
        """The run ends: record the stretch, the wait and the zones under way, as far as they
        got."""
        self._close_drive()
        self._close_wait()
        if self.recorder.record_moves:
            for zone_id, claim in self._zones.items():
                if claim.triggered and zone_id in self._zone_since:
                    self._record_zone(zone_id, claim, self._zone_since[zone_id])

    # ---- releasing ------------------------------------------------------------------------------
    def _release(self, held: Held) -> None:
        self.traffic.free(self.id, held.claim)
        self.recorder.occupied("node", held.node, self.id, held.since_s, self.env.now)

    def _release_corridor(self, cid: int) -> None:
        claim, _ = self._corridors[cid]
        self.traffic.free(self.id, claim)

    def _release_left_corridors(self) -> None:
        """Let go of corridors the AGV has entered and fully left, and of pending ones whose
        entry node it is no longer at or heading to."""
        corridors = self._corridors
        if not corridors:
            return
        layout = self.traffic.layout
        nodes = [h.node for h in self.held]
        spots = set(nodes) | {h.node for h in self.ahead}
        for cid, (_, entry) in list(corridors.items()):
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

    def _release_left_zones(self) -> None:
        """Let go of the zones in which the AGV holds no node (and is not driving to one),
        but for a same-direction zone it is about to drive into from the node it holds."""
        spots = {h.node for h in self.held} | {h.node for h in self.ahead}
        zones = self.traffic.layout.traffic_zone_by_id
        for zone_id, claim in list(self._zones.items()):
            if not claim.triggered:
                continue
            if spots & zones[zone_id].nodes:
                self._zone_entry.pop(zone_id, None)  # inside
                continue
            entry = self._zone_entry.get(zone_id)
            if entry is not None and entry in spots:
                continue
            self._free_zone(zone_id, claim)

    def _drop_pending_zones(self) -> None:
        """Let go of the same-direction zones the AGV holds but has not driven into."""
        for zone_id in list(self._zone_entry):
            claim = self._zones.get(zone_id)
            if claim is not None and claim.triggered:
                self._free_zone(zone_id, claim)
            else:
                del self._zone_entry[zone_id]

    def _free_zone(self, zone_id: str, claim: Claim) -> None:
        self._zone_entry.pop(zone_id, None)
        self.traffic.free(self.id, claim)
        self._record_zone(zone_id, claim, self._zone_since.pop(zone_id, self.env.now))

    def _record_zone(self, zone_id: str, claim: Claim, since: float) -> None:
        """The AGV held zone `zone_id` from `since` until now (the replay's holders)."""
        now = self.env.now
        self.recorder.occupied("zone", zone_id, self.id, since, now)
        if self.recorder.record_moves:
            direction = claim.direction if isinstance(claim, DirectedClaim) else 0
            self.recorder.moved(MoveRecord(self.id, "zone", since, now, zone_id,
                                           _DIRECTION_NAMES[direction]))

    def _drop_pending_corridors(self) -> None:
        for cid, (_, entry) in list(self._corridors.items()):
            if entry is not None:
                self._release_corridor(cid)
