"""Driving under traffic control: the part of an AGV that moves it from node to node.

Standing at a node, the AGV asks traffic control for the next hop (the next node, with the
corridors and zones it enters on the way: `Traffic.allocate`, waiting if it must), then for the
hop after it without waiting (`Traffic.try_allocate`, the look-ahead); with it, it may pass
through the next node at the highest speed from which it could still stop at the one after;
without it, it brakes to stop at the next node. Each hop's time is closed form
(fleet_sim.model.kinematics), or, when the traffic has a motion backend (`motion: sumo`,
fleet_sim.sim.sumo.backend), the time SUMO takes to drive it. See fleet_sim.sim.traffic and
docs/background/engine.md for the rules.

The driver is a client of the reservation table (`TrafficClient`): traffic control decides what
a hop needs, in which order it is taken, what is given back when the AGV gives up waiting, and
when corridors and zones are let go of; the driver never reads a lock. It keeps only its own
driving bookkeeping: the node claims behind it and how far it has driven past them (it lets go
of a node once its body and the minimum gap have cleared it). A deadlock victim is told so by a
`DeadlockVictim` interrupt cause; any other interrupt cause (a fault) makes traffic let go of the
claim it waited for and passes the interrupt on.

A `fleet_sim.sim.agents.vehicle.Vehicle` holds a `Driver` (it does not inherit from it) and is its
`DriverHost`: the hooks `speed_cap_mps`, `travel` and `arrived` let the vehicle add markers,
obstacles, battery use and slow modes to each hop; its state and its fault flag are the
vehicle's.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, Protocol, cast

import numpy as np
import simpy
from simpy.events import Timeout

from fleet_sim.config.layout import Place
from fleet_sim.config.scenario import TrafficConfig
from fleet_sim.config.vehicle import VehicleProfile
from fleet_sim.errors import SimulationError
from fleet_sim.model.kinematics import Piece, traverse
from fleet_sim.model.records import MoveRecord, Recorder
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.lds import AgvAhead, Ahead
from fleet_sim.sim.traffic.allocation import Hop
from fleet_sim.sim.traffic.avoiding import AvoidingPolicy
from fleet_sim.sim.traffic.control import Traffic
from fleet_sim.sim.traffic.deadlock import DeadlockVictim
from fleet_sim.sim.traffic.locks import Claim, Lock, NodeLock

Proc = Generator[simpy.Event, Any, Any]

STOP_MARKERS = ("spin", "pause")
"""RSS-AGV-001 5.3 markers that stop the AGV at their node."""


@dataclass(slots=True)
class Held:
    """A node claim the AGV holds or drives to."""

    node: str
    claim: Claim
    since_s: float
    behind_m: float = 0.0
    """How far the AGV has driven past this node."""
    ready_s: float = 0.0
    """When the fleet manager's permission to drive to this node reaches the AGV (a route
    granted hop by hop, fleet_sim.sim.commands); 0: traffic's grant is the permission."""


class DriverHost(Protocol):
    """What a driver needs of the vehicle it drives."""

    @property
    def state(self) -> VehicleState:
        """The vehicle's RSS-AGV-001 state (events the driver records carry it)."""
        ...

    @property
    def failing(self) -> bool:
        """A fault is on its way: the vehicle is about to let go of everything."""
        ...

    @property
    def process(self) -> simpy.Process | None:
        """The vehicle's process (a deadlock victim's wait is interrupted through it)."""
        ...

    def speed_cap_mps(self) -> float | None:
        """A speed the next hop must not exceed (markers, slow modes), or None."""
        ...

    def travel(self, u: str, v: str, time_s: float) -> Proc:
        """Drive the hop (`Driver.move` to its end; the vehicle adds obstacles). `time_s` is
        the closed-form driving time (0 with a motion backend, which times the hop itself)."""
        ...

    def arrived(self, v: str, length_m: float) -> Proc | None:
        """At `v` after a hop of `length_m` (battery use, markers): the stop to make there
        (a spin or a pause marker), if any, to be driven to its end."""
        ...


class Driver:
    """Hops, waits and deadlock escapes of one AGV, through traffic control."""

    def __init__(self, agv_id: int, env: simpy.Environment, traffic: Traffic,
                 recorder: Recorder, profile: VehicleProfile, config: TrafficConfig,
                 rng: np.random.Generator, host: DriverHost,
                 permission: Callable[[], float] | None = None) -> None:
        """`permission`: its route granted hop by hop, sends a hop's permission and says
        when it arrives (fleet_sim.sim.commands.CommandPath.permission); None: not."""
        self.id = agv_id
        self.env = env
        self.traffic = traffic
        self.recorder = recorder
        self.profile = profile
        self.config = config
        self.rng = rng
        self.host = host
        self.permission = permission
        self.body_m = profile.length_m + profile.min_gap_m
        """Its length and the minimum gap behind it (the way into a parking bay)."""
        self.clear_m = self.body_m
        """How far past a node it drives before it lets go of it (TrafficClient)."""
        self.node = ""
        self.prev: str | None = None
        self.speed_mps = 0.0
        self.held: list[Held] = []
        self.ahead: list[Held] = []
        self.goal: str | None = None
        self.next_node: str | None = None
        self.parked_in: Place | None = None
        self._leg: simpy.Event | None = None
        """The motion backend's event for the hop under way."""
        self._moved = 0.0
        """Share of the hop under way already driven (see `move`)."""
        self._plan: tuple[tuple[Piece, ...], float, float, float] | None = None
        """With moves recorded: the hop under way's pieces, entry and exit speed and time."""
        self._drive_open: tuple[str, str, float, float] | None = None
        """With moves recorded: the stretch being driven (u, v, since_s, driven_s)."""
        self._in_hop = False
        self._hop_ends_s: float | None = None
        """When the hop under way ends as planned (closed form); None with a motion backend."""
        self._halt_watchers: list[Callable[[], None]] = []
        """Told if a fault stops the AGV during the hop under way (`when_halted`)."""
        self.halted_mid_hop = False
        """Stopped by a fault on the way to `next_node` (until it drives again)."""
        self.departed_s = 0.0
        """When it last set off on a hop (or left the track)."""
        self.lds: AgvAhead | None = None
        """Its LDS's watch over the AGV ahead in a queue (`rules.agv_ahead: lds`), if on."""
        traffic.register(self)
        self.routes = traffic.routes_of(agv_id)
        """Routes and hop kinematics of this AGV's vehicle type."""

    # ---- what traffic control knows of it (TrafficClient) -----------------------------------
    @property
    def failing(self) -> bool:
        return self.host.failing

    def note(self, event: str, detail: str = "") -> None:
        """Record an event that changes no state (deadlock, reroute, assignment...)."""
        state = self.host.state.value
        self.recorder.event(self.env.now, self.id, event, state, state, self.node, detail)

    def on_deadlock_victim(self, cause: DeadlockVictim) -> None:
        """Traffic chose this AGV to break a wait-for cycle: interrupt its wait."""
        process = self.host.process
        assert process is not None
        process.interrupt(cause)

    def past_m(self) -> dict[str, float]:
        """Node -> how far the AGV has driven past it, for the nodes behind it it holds."""
        return {h.node: h.behind_m for h in self.held}

    def began_waiting(self, lock: Lock) -> None:
        """Traffic makes the AGV wait for `lock`: on a drive, its LDS may see the AGV ahead
        (once the hop's wait is for its node: a corridor or a zone is asked for first)."""
        if self.lds is not None and self.next_node is not None:
            self.lds.began_waiting(self._agv_ahead, isinstance(lock.key, NodeLock))

    def _agv_ahead(self) -> tuple[int, Ahead, bool] | None:
        """The AGV holding the node this one waits for, and whether it stands on that node or
        its body is still over it; None if it waits for no node or nobody holds it."""
        found = self.traffic.node_holder(self.id)
        if found is None:
            return None
        ahead, node = found
        if not isinstance(ahead, Driver):
            return None
        return ahead.id, ahead, ahead.covers(node)

    def covers(self, node: str) -> bool:
        """Whether the AGV stands on `node` or its body is still over it."""
        return any(h.node == node for h in self.held)

    @property
    def standing(self) -> bool:
        """Not driving a hop (Ahead)."""
        return not self._in_hop

    @property
    def accel_mps2(self) -> float:
        return self.routes.motion.accel_mps2

    @property
    def hop_ends_s(self) -> float | None:
        """Ahead: when the hop under way ends as planned, if one is and it is known."""
        return self._hop_ends_s if self._in_hop else None

    def when_halted(self, tell: Callable[[], None]) -> None:
        """Ahead: `tell` is called if a fault stops the AGV before the hop under way ends."""
        self._halt_watchers.append(tell)

    def hold_back(self, distance_m: float) -> None:
        """Let go of a node only once the rear is `distance_m` past it (not `min_gap_m`): the
        AGV behind stays out of the LDS's range (`rules.agv_ahead: held_back`)."""
        self.clear_m = self.profile.length_m + max(self.profile.min_gap_m, distance_m)

    def _allocate(self, hop: Hop) -> Generator[simpy.Event, Any, Claim | None]:
        """`Traffic.allocate`, with the LDS's pause behind the AGV ahead while it waits."""
        lds = self.lds
        if lds is None:
            return (yield from self.traffic.allocate(self, hop))
        try:
            claim = yield from self.traffic.allocate(self, hop)
            lds.waiting = False
            if claim is None:  # gave up: turning away, it is paused until clear all the same
                yield from self._stand_paused(lds, hop.node)
        except BaseException:  # a fault (E_101 among them): the pause is over
            lds.stop()
            raise
        return claim

    def _move_on(self) -> Proc:
        """Granted while paused behind an AGV: paused until the way is clear (4.2.4). The
        grant is in `ahead` meanwhile, so a fault lets go of it with the rest."""
        lds = self.lds
        if lds is None or lds.paused_since is None:
            return
        try:
            yield from self._stand_paused(lds, self.ahead[0].node)
        except BaseException:
            lds.stop()
            raise

    def _stand_paused(self, lds: AgvAhead, node: str) -> Proc:
        """`AgvAhead.wait_over`; the time it stands on after traffic's wait ended is blocked
        time like the wait (the AGV ahead keeps it there), and a wait in the replay."""
        ahead = lds.paused_behind
        start = self.env.now
        yield from lds.wait_over()
        now = self.env.now
        if now <= start or ahead is None:
            return
        self.recorder.blocked(start, now)
        if self.recorder.record_moves:
            self.recorder.moved(MoveRecord(self.id, "wait", start, now, self.node, node,
                                           ahead.id))

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

    # ---- motion: closed form, or a backend ------------------------------------------------
    def move(self, u: str, v: str, time_s: float, share: float) -> Proc:
        """Drive on until `share` of the hop u -> v is behind the AGV."""
        backend = self.traffic.motion_backend
        if backend is None:
            if self._plan is not None:
                self._drive_open = (u, v, self.env.now, time_s * self._moved)
            try:
                yield Timeout(self.env, time_s * (share - self._moved))
            finally:  # also when a fault interrupts the hop: the AGV stops where it is
                if self._drive_open is not None:
                    self._close_drive()
        elif share >= 1.0:
            assert self._leg is not None
            yield self._leg
        else:
            yield backend.reach(self.id, u, v, share)
        self._moved = share

    def pause(self, seconds: float, speed_mps: float = 0.0) -> Proc:
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

    def stop_where_it_is(self) -> bool:
        """A reset stops the AGV where it is, on the track: what it was granted ahead is given
        back, what its body stands on is kept. True if it stopped on the way to `next_node`
        (which stays set: the tag ahead of it)."""
        mid_hop = self.halted_mid_hop
        self.halt()
        keep = 1 if mid_hop else 0  # the node it was driving to
        for held in self.ahead[keep:]:
            self._release(held)
        del self.ahead[keep:]
        if not mid_hop:  # (mid-hop, the corridor it drives into is kept with the node)
            self.traffic.drop_pending(self.id)
            self.next_node = None
        return mid_hop

    def halt(self) -> None:
        """A fault stops the AGV where it is."""
        self.speed_mps = 0.0
        self.halted_mid_hop = self.halted_mid_hop or self._in_hop
        self._in_hop = False
        if self._halt_watchers:
            watchers, self._halt_watchers = self._halt_watchers, []
            for tell in watchers:
                tell()
        if self.traffic.motion_backend is not None:
            self.traffic.motion_backend.halt(self.id)

    # ---- placement --------------------------------------------------------------------------
    def place_at(self, node: str) -> None:
        """Stand on `node` at t=0 (holding it, and its corridor and zones)."""
        claim = self.traffic.place(self.id, node)
        self.held = [Held(node, claim, self.env.now)]
        self.node = node
        self._placed("track", node)

    def place_in_parking(self, place: Place) -> None:
        self.parked_in = place
        self.node = place.nodes[0]
        self._placed("parking", self.node)

    # ---- on and off the track -------------------------------------------------------------
    def enter_parking(self, place: Place) -> None:
        """Drive off the tape into the parking area: every lock is let go."""
        for held in self.held:
            self._release(held)
        self.held = []
        self.departed_s = self.env.now
        self.traffic.let_go(self.id)
        self.parked_in = place
        self.prev = None
        if self.traffic.motion_backend is not None:
            self.traffic.motion_backend.off_track(self.id)
        self._placed("parking", place.nodes[0])

    def leave_track(self) -> None:
        """Off the tape (into a parking bay, or taken off by an operator): let go of all."""
        for held in self.held + self.ahead:
            self._release(held)
        self.held = []
        self.ahead.clear()  # the same list: a drive holds it
        self.departed_s = self.env.now
        self.traffic.let_go(self.id)
        self.prev, self.speed_mps = None, 0.0
        if self.traffic.motion_backend is not None:
            self.traffic.motion_backend.off_track(self.id)
        self._placed("off", self.node)

    def reenter_track(self, access: str) -> Proc:
        """Back onto the tape at `access`, once it (its corridor and zones) is free. An
        attempt whose wait traffic breaks (the AGV chosen to break a wait-for cycle) lets go of
        what it took and tries again a deadlock check later."""
        while True:
            claim = yield from self.traffic.reenter(self, access)
            if claim is not None:
                break
            self.traffic.take_escape(self.id)  # its way out is to stay where it is
            yield self.env.timeout(self.config.deadlock_check_s)
        self.held = [Held(access, claim, self.env.now)]
        self.node = access
        self._placed("track", access)

    # ---- driving ------------------------------------------------------------------------------
    def drive(self, goal: str, stop_early: Callable[[], bool] | None = None) -> Proc:
        """Drive to `goal` and stop there, holding it. When `stop_early()` turns true, stop at
        the first node where the AGV can instead. How, the traffic policy says (`DRIVES`)."""
        return DRIVES[self.traffic.strategy.name](self, goal, stop_early)

    def _drive_reactively(self, goal: str, stop_early: Callable[[], bool] | None) -> Proc:
        """`drive` under `traffic.policy: reactive`: along the route, hop by hop; a wait given
        up (a deadlock victim, or blocked long with another way) takes the escape."""
        traffic = self.traffic
        self.goal = goal
        if self.ahead:  # stopped on the way to a node it holds (a reset): on to it first
            path = [self.node, *traffic.route(self.ahead[0].node, goal, self.id)]
        else:
            path = traffic.route(self.node, goal, self.id)
        markers = traffic.layout.markers
        pass_speed_mps = self.routes.pass_speed_mps
        try_allocate = traffic.try_allocate
        ahead = self.ahead
        agv = self.id
        i = 0
        while self.node != self.goal:
            nxt = path[i + 1]
            self.next_node = nxt
            if not ahead:
                after = path[i + 2] if i + 2 < len(path) else None
                claim = yield from self._allocate(Hop(self.node, nxt, after))
                if claim is None:
                    path = yield from self._get_out()
                    i = 0
                    continue
                ahead.append(self._granted(nxt, claim))
                if self.lds is not None and self.lds.paused_since is not None:
                    yield from self._move_on()
            v_end_max = 0.0
            if nxt != self.goal and i + 2 < len(path) and markers.get(nxt) not in STOP_MARKERS:
                w = path[i + 2]
                # the look-ahead (`_look_ahead`, written out)
                claim = try_allocate(agv, Hop(nxt, w, path[i + 3] if i + 3 < len(path) else None))
                if claim is not None:
                    ahead.append(self._granted(w, claim))
                    v_end_max = pass_speed_mps(self.node, nxt, w)
            yield from self._hop(nxt, v_end_max)
            i += 1
            if stop_early is not None and stop_early():
                self.goal = ahead[-1].node if ahead else self.node
        self._end_drive()

    def _drive_safely(self, goal: str, stop_early: Callable[[], bool] | None) -> Proc:
        """`drive` under `traffic.policy: avoiding`: along the plan declared with traffic (the
        route to `goal`, then on to parking). While traffic refuses the plan (the state would
        not be safe with it), the AGV drives on along the plan it has, stopping at each node to
        ask again. Blocked long, it may take another way (`AvoidingPolicy._replan_safely`: a
        new plan the check accepted; the wait ends without a claim); it never backs off."""
        traffic = cast(AvoidingPolicy, self.traffic.strategy)
        self.goal = goal
        # stopped on the way to a node it holds (a reset): the plan goes on to it first
        on_plan = traffic.declare(self, goal, self.ahead[0].node if self.ahead else None)
        while self.node != self.goal:
            if not self.ahead:
                if not on_plan:
                    on_plan = traffic.declare(self, goal)
                nxt = traffic.plan_step(self.id, 1)
                if nxt is None:  # at the end of the plan in force: a parking access
                    yield from self._through_parking(goal)
                    on_plan = True
                    continue
                self.next_node = nxt
                claim = yield from self._allocate(
                    Hop(self.node, nxt, traffic.plan_step(self.id, 2)))
                if claim is None:  # blocked long: it took another way (a new plan)
                    on_plan = True
                    continue
                self.ahead.append(self._granted(nxt, claim))
                if self.lds is not None and self.lds.paused_since is not None:
                    yield from self._move_on()
            nxt = self.ahead[0].node
            self.next_node = nxt
            v_end_max = 0.0
            if on_plan and nxt != self.goal \
                    and self.traffic.layout.markers.get(nxt) not in STOP_MARKERS:
                w = traffic.plan_step(self.id, 2)
                if w is not None and self._look_ahead(
                        Hop(nxt, w, traffic.plan_step(self.id, 3))):
                    v_end_max = self.routes.pass_speed_mps(self.node, nxt, w)
            yield from self._hop(nxt, v_end_max)
            if stop_early is not None and stop_early():
                self.goal = self.ahead[-1].node if self.ahead else self.node
        self._end_drive()

    def _end_drive(self) -> None:
        """At the end of a drive: give back what was reserved beyond it; it stands still."""
        self.next_node = None
        self.traffic.drop_pending(self.id)
        if self.ahead or self.speed_mps > 1e-9:
            raise SimulationError(f"AGV {self.id} ended a drive at {self.node} still moving")

    def _through_parking(self, goal: str) -> Proc:
        """Avoiding, at the parking access where its plan ends, the way on refused: drive
        into the parking area (letting go of everything), take the way on as the plan (off the
        track it holds nothing another AGV waits for, so that closes no cycle) and come back
        out once traffic grants the access."""
        place = self.traffic.parking_at(self.node)
        if place is None:
            raise SimulationError(f"AGV {self.id}: its plan ends at {self.node}, which is no "
                                  "parking access")
        self.note("through_parking", f"{place.id} on the way to {goal}")
        self.next_node = None
        yield self.env.timeout(self.body_m / self.profile.turn_speed_mps)
        self.enter_parking(place)
        accepted = cast(AvoidingPolicy, self.traffic.strategy).declare(self, goal)
        assert accepted
        yield from self.reenter_track(place.nodes[0])
        self.parked_in = None

    def _look_ahead(self, hop: Hop) -> bool:
        """Take the hop now if traffic grants all of it at once; never wait."""
        claim = self.traffic.try_allocate(self.id, hop)
        if claim is None:
            return False
        self.ahead.append(self._granted(hop.node, claim))
        return True

    def _granted(self, node: str, claim: Claim) -> Held:
        """A hop traffic has granted; granted hop by hop, its permission is sent now."""
        now = self.env.now
        if self.permission is None:
            return Held(node, claim, now)
        return Held(node, claim, now, ready_s=self.permission())

    def _hop(self, nxt: str, v_end_max: float) -> Proc:
        ready_s = self.ahead[0].ready_s
        if ready_s > self.env.now:  # its permission is on its way: it stands until it comes
            self.speed_mps = 0.0
            yield self.env.timeout(ready_s - self.env.now)
        u = self.node
        agv = self.id
        traffic = self.traffic
        traffic.check_hop(agv, u, nxt)
        host = self.host
        cap = host.speed_cap_mps()
        backend = traffic.motion_backend
        recorder = self.recorder
        self._moved = 0.0
        if backend is not None:  # the backend times the hop; the AGV passes through nxt
            after = self.ahead[1].node if v_end_max > 0 and len(self.ahead) > 1 else None
            self._leg = backend.hop(agv, self.prev, u, nxt, after, cap)
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
        if recorder.record_moves and backend is None:
            self._plan = (self._pieces(u, nxt, cap), self.speed_mps, v_end, time_s)
        env = self.env
        start = env.now
        self._in_hop = True
        self.halted_mid_hop = False
        self.departed_s = start
        self._hop_ends_s = None if backend is not None else start + time_s
        yield from host.travel(u, nxt, time_s)
        self._in_hop = False
        if self._halt_watchers:
            self._halt_watchers.clear()
        self._plan = None
        if self._leg is not None:
            if self._moved < 1.0:  # a travel hook that did not drive to the end
                yield from self.move(u, nxt, time_s, 1.0)
            speed = self._leg.value
            assert isinstance(speed, float)
            v_end = speed
            self._leg = None
        length = traffic.routes.length_m[u, nxt]
        now = env.now
        recorder.drove(start, now, length)
        if recorder.record_occupancy:
            recorder.occupied("segment", f"{u}>{nxt}", agv, start, now)
        self.prev, self.node, self.speed_mps = u, nxt, v_end
        arrived = self.ahead.pop(0)
        held = self.held
        for h in held:
            h.behind_m += length
        held.append(arrived)
        clear = self.clear_m - 1e-9
        while len(held) > 1 and held[0].behind_m >= clear:
            self._release(held.pop(0))
        traffic.hopped(agv, u, nxt, [h.node for h in held])
        stop = host.arrived(nxt, length)
        if stop is not None:
            yield from stop

    def _get_out(self) -> Generator[simpy.Event, Any, list[str]]:
        """After giving up a wait: take the escape (another route, or one hop back), or wait a
        little and try the usual route again. Returns the new path from the current node."""
        traffic = self.traffic
        escape = traffic.take_escape(self.id) or traffic.escape_for(self)
        traffic.give_up(self.id)
        assert self.goal is not None
        if escape is not None and escape.kind in ("reroute", "circulate"):
            self.note(escape.kind, escape.brief())
            return list(escape.path)
        if escape is not None and escape.kind == "backoff":
            step = escape.path[1]
            if self._look_ahead(Hop(self.node, step)):
                self.note("backoff", f"{self.node} -> {step}")
                yield from self._hop(step, 0.0)
                return traffic.route(self.node, self.goal, self.id)
        yield self.env.timeout(float(self.rng.exponential(self.config.backoff_s)))
        return traffic.route(self.node, self.goal, self.id)

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

    def end_of_run(self) -> None:
        """The run ends: record the stretch, the wait and the zones under way, as far as they
        got."""
        self._close_drive()
        self.traffic.end_of_run(self.id)

    # ---- releasing ------------------------------------------------------------------------------
    def _release(self, held: Held) -> None:
        self.traffic.free(self.id, held.claim)
        recorder = self.recorder
        if recorder.record_occupancy:
            recorder.occupied("node", held.node, self.id, held.since_s, self.env.now)


DRIVES: dict[str, Callable[[Driver, str, Callable[[], bool] | None], Proc]] = {
    "reactive": Driver._drive_reactively,
    "avoiding": Driver._drive_safely,
}
"""Traffic policy name (`traffic.policy`) -> how a driver drives under it."""
