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

Work conservation (fleet_sim.model.not_dispatched): AGVs tell the fleet manager of every change
of state or link (`status_changed`), so it knows which stand Idle. Whenever orders wait, it
records for each Idle AGV why it is not given one (`_reason`: a command on its way, waiting for
a charger, battery low with charging off, no FMS link, the status poll not yet come), as
`not_dispatched` events on changes only. It looks once per simulated instant, after every
other event of that instant (`EndOfInstant`), so what it records is the settled state, not the
steps an AGV takes within one instant. An Idle AGV with orders waiting and none of these
reasons would be a dispatching bug: the run stops with a SimulationError naming it.

Vehicle types (mixed fleets, or a layout whose stations have `allowed_types`; `set_types`): an
order goes only to an AGV whose type may serve both its stations, oldest order first; an order
that no idle AGV may serve waits while younger ones are served (no head-of-line blocking). An
Idle AGV that may serve none of the waiting orders is recorded as not dispatched for the reason
``type_not_allowed`` (work conservation). An
order that no type of the fleet may serve (from a trace; flows are checked when the scenario is
read) fails when it is created, with failure ``type_not_allowed``.

Multi-stop orders (fleet_sim.config.chains): an order goes only to an AGV whose type may serve
every stop; the docking node of each stop is chosen when the order is assigned, and the AGV is
chosen by its travel time to the next stop. An AGV that fails while it carries no load (before
a pickup, or between a dropoff and the next pickup) gives the order back: it returns to the
front of the queue with the stops not yet done (a shorter chain, the same order id; stops done
stay done). One that fails loaded loses the order, as a plain one (`order_failed`).

Admission (scenario `dispatch.max_active_agvs`, off by default: RSS-AGV-001 has no such rule):
at most N AGVs on the track at once; the others wait in parking. An AGV holds an admission from
the moment the fleet manager gives a parked AGV work (an order or a charger) until it has driven
back into a parking area; one that starts on the track holds one from the start, and a failed
AGV keeps its own while the operator has it. Once N are admitted, orders go only to idle AGVs
already on the track, and a freed admission goes to a parked AGV waiting for a charger before
any order when a charger is free (a battery must not run down in parking); with every charger
taken it goes to an order, and the AGV waiting in parking gets the next place that frees while
a charger is free. Like a CONWIP limit in a factory: a loop
packed beyond what it can carry stops carrying anything (100 busy AGVs lock the 186-node
warehouse solid), so a planner caps the AGVs on the track at the loop's working load and the
rest wait; throughput then plateaus as the fleet grows instead of collapsing.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Generator
from functools import partial
from typing import Any, Protocol

import simpy
from simpy.events import EventPriority

from agv_model.fleet_commands import Kind
from fleet_sim.config.layout import Layout, Place
from fleet_sim.config.scenario import DispatchConfig
from fleet_sim.errors import SimulationError
from fleet_sim.model.not_dispatched import NOT_DISPATCHED, NOT_DISPATCHED_END, NotDispatched
from fleet_sim.model.records import Order, Recorder
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.dispatch import POLICIES, Candidate, DispatchPolicy, TravelTime
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

    @property
    def state(self) -> VehicleState:
        """Its RSS-AGV-001 state, as its status reports it."""
        ...

    @property
    def in_parking(self) -> bool:
        """The AGV stands in a parking area, off the track."""
        ...

    def note(self, event: str, detail: str = "") -> None:
        """Record an event about the AGV that changes no state (order_assigned...)."""

    def assign(self, order: Order) -> None:
        """The assign command with `order` has reached the AGV."""


END_OF_INSTANT = EventPriority(2)
"""SimPy priority after URGENT (0) and NORMAL (1): processed after every other event of the same
simulated time, including those scheduled later within it."""


class EndOfInstant(simpy.Event):
    """An event that fires at the current time, after every other event of this instant (like
    simpy.Timeout(0), at a lower priority)."""

    def __init__(self, env: simpy.Environment) -> None:
        super().__init__(env)
        self._ok = True
        self._value = None
        env.schedule(self, priority=END_OF_INSTANT)


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
        self.idle: dict[int, FleetAgv] = {}
        """AGVs free for orders, by id, in the order they offered themselves."""
        self._idle_since: dict[int, int] = {}
        """AGV id -> its place in that order (a counter), for the idle AGVs."""
        self._offer_count = 0
        self.idle_admitted: dict[int, FleetAgv] = {}
        """The idle AGVs that hold an admission (admission only): once the track is full, only
        they may be given orders, and listing them from here costs what they number, not what
        the parked fleet numbers."""
        self.parking_free = {p.id: p.capacity for p in layout.parking}
        self.bound_for: Counter[str] = Counter()
        self.chargers_free: list[Place] = list(layout.chargers)
        self.charger_queue: deque[tuple[FleetAgv, simpy.Event]] = deque()
        self.charger_cancelled: set[simpy.Event] = set()
        """Charger requests given up while their charger's assign command was on its way."""
        if config.max_active_agvs == "auto":
            raise ValueError("dispatch.max_active_agvs 'auto' is resolved to a number before "
                             "the fleet manager is built (fleet_sim.sim.engine.admission_limit)")
        self.max_active: int | None = config.max_active_agvs
        """Admission: most AGVs on the track at once (None: no limit)."""
        self.admitted: set[int] = set()
        """AGVs holding an admission (on the track, or given work to leave parking for)."""
        self.queue_recorded = 0
        """The queue length last recorded (`recorder.queue_length`)."""
        recorder.queue_length(env.now, 0)
        # work conservation: who stands Idle, and what holds each back
        self.standing: dict[int, FleetAgv] = {}
        """AGVs in state Idle, by id, in the order they became Idle."""
        self.held_back: dict[int, NotDispatched] = {}
        """Reasons AGVs gave when they withdrew (battery low)."""
        self.polling: set[int] = set()
        """AGVs that are free but not yet noticed (the next status poll)."""
        self.resuming: set[int] = set()
        """AGVs a resume command is on its way to, or whose boot report is on its way."""
        self.charger_wait: set[int] = set()
        """AGVs that asked for a charger and do not have it yet."""
        self.not_dispatched: dict[int, tuple[FleetAgv, NotDispatched]] = {}
        """The open not_dispatched spells: AGV id -> (AGV, reason)."""
        self._review_due = False
        self.agv_types: dict[int, str] = {}
        """AGV id -> its vehicle type; empty: every AGV may serve every order."""

    # ---- vehicle types ----------------------------------------------------------------------
    def set_types(self, agv_types: dict[int, str]) -> None:
        """The vehicle type of each AGV: orders go only to types their stations allow."""
        self.agv_types = dict(agv_types)

    def may_serve(self, agv: FleetAgv, order: Order) -> bool:
        """May `agv`'s type serve both stations of `order`?"""
        kind = self.agv_types.get(agv.id)
        if kind is None:
            return True
        places = self.layout.places
        if order.stops:
            return all(places[s].serves(kind) for s in order.stops)
        return places[order.pickup].serves(kind) and places[order.dropoff].serves(kind)

    def _travel_of(self, agv: Candidate) -> TravelTime:
        return partial(self.traffic.travel_time_s, client_id=agv.id)

    # ---- orders -----------------------------------------------------------------------------
    def submit(self, order: Order) -> None:
        self.recorder.order_created(order)
        if self.agv_types and not self._servable(order):
            order.failed_s = self.env.now
            order.failure = "type_not_allowed"
            self.recorder.order_finished(order)
            return
        self.waiting.append(order)
        self._dispatch()

    def vehicle_idle(self, agv: FleetAgv) -> None:
        """The AGV is free; the fleet manager knows at once, or at its next status poll."""
        if agv.id in self.assigning:
            return
        offer = self.offers.get(agv.id, 0) + 1
        self.offers[agv.id] = offer
        self.held_back.pop(agv.id, None)
        delay = self.commands.notice_delay_s(agv.id)
        if delay <= 0:
            self._take_offer(agv, offer)
        else:
            self.polling.add(agv.id)
            self._changed()
            self.env.process(self._notice(agv, offer, delay))

    def _notice(self, agv: FleetAgv, offer: int,
                delay: float) -> Generator[simpy.Event, Any, None]:
        yield self.env.timeout(delay)
        self._take_offer(agv, offer)

    def _take_offer(self, agv: FleetAgv, offer: int) -> None:
        if self.offers.get(agv.id) == offer:
            self.polling.discard(agv.id)
            if agv.id not in self.idle:
                self._add_idle(agv)
            self._dispatch()

    def withdraw(self, agv: FleetAgv, reason: NotDispatched | None = None) -> None:
        """The AGV is no longer available for orders (charging, failed...); `reason`: why, if
        it stands Idle meanwhile for a reason of its own (battery low)."""
        self.offers[agv.id] = self.offers.get(agv.id, 0) + 1
        self.polling.discard(agv.id)
        if reason is None:
            self.held_back.pop(agv.id, None)
        else:
            self.held_back[agv.id] = reason
        if agv.id in self.idle:
            self._remove_idle(agv)
        self._changed()

    def link_restored(self) -> None:
        self._dispatch()

    def status_changed(self, agv: FleetAgv) -> None:
        """The AGV's state or FMS link changed (its status says so)."""
        if agv.state is VehicleState.IDLE:
            self.standing[agv.id] = agv
        elif agv.id in self.standing:
            del self.standing[agv.id]
            self.held_back.pop(agv.id, None)
        else:
            return
        self._changed()

    def resume(self, agv: FleetAgv) -> Generator[simpy.Event, Any, None]:
        """Send the AGV the resume command after its link is back (for its process to yield
        from); it stands Idle until the command arrives."""
        yield from self._command_from(agv, "resume")

    def boot_report(self, agv: FleetAgv) -> Generator[simpy.Event, Any, None]:
        """The AGV has booted and reports it (RSS-AGV-001 4.2.1), for its process to yield
        from: one status round trip on its link (fleet_sim.sim.commands); it stands Idle
        meanwhile."""
        yield from self._command_from(agv, "status")

    def _command_from(self, agv: FleetAgv, kind: Kind) -> Generator[simpy.Event, Any, None]:
        """A command exchange the AGV waits for, Idle and not dispatched (command_in_transit);
        nothing when its commands take no time."""
        if self.commands.immediate(agv.id):
            return
        self.resuming.add(agv.id)
        self._changed()
        try:
            yield from self.commands.wait(agv.id, kind)
        finally:
            self.resuming.discard(agv.id)
            self._changed()

    @property
    def park_idle(self) -> bool:
        """Idle AGVs drive to parking (scenario `dispatch.park_idle`)."""
        return self.config.park_idle

    def requeue(self, agv: FleetAgv, order: Order) -> None:
        """An order its AGV cannot carry out goes back to the front of the queue (a chain with
        the stops not yet done)."""
        if order.stops:
            self._undock_chain(order)
            if order.stops_done == 0:
                order.pickup_node = None
            order.dropoff_node = None
            order.agv = None
            order.assigned_s = None
            order.reassigned += 1
            agv.note("order_reassigned", f"order {order.id} from stop {order.stops_done + 1}")
            self.waiting.appendleft(order)
            self._dispatch()
            return
        for node in (order.pickup_node, order.dropoff_node):
            if node is not None:
                self.bound_for[node] -= 1
        order.pickup_node = order.dropoff_node = None
        order.agv = None
        order.assigned_s = None
        order.reassigned += 1
        agv.note("order_reassigned", f"order {order.id}")
        self.waiting.appendleft(order)
        self._release_if_parked(agv)
        self._dispatch()

    def order_failed(self, order: Order, code: str) -> None:
        order.failed_s = self.env.now
        order.failure = code
        self.recorder.order_finished(order)
        if order.stops:
            self._undock_chain(order)
            return
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
        self.charger_wait.add(agv.id)
        self._assign_chargers()
        return event

    def cancel_charger_request(self, agv: FleetAgv, request: simpy.Event) -> None:
        """`agv` no longer waits for the charger `request` stands for (its battery died, or it
        failed while waiting): out of the queue if still in it; a charger already given to it
        goes back at once, one whose assign command is on its way goes back when it arrives.
        Without this a charger would stay given to an AGV that never comes."""
        if any(e is request for _, e in self.charger_queue):
            self.charger_queue = deque((v, e) for v, e in self.charger_queue
                                       if e is not request)
        elif request.triggered:
            place = request.value
            assert isinstance(place, Place)
            self.release_charger(place)
        else:
            self.charger_cancelled.add(request)
        self.charger_wait.discard(agv.id)
        self._release_if_parked(agv)
        self._changed()

    def release_charger(self, place: Place) -> None:
        self.chargers_free.append(place)
        self._assign_chargers()

    def _assign_chargers(self) -> None:
        while self.chargers_free and self.charger_queue:
            queued = next((item for item in self.charger_queue if self._may_admit(item[0])),
                          None)
            if queued is None:
                break  # the AGVs queued wait in parking for an admission
            self.charger_queue.remove(queued)
            agv, event = queued
            self._admit(agv)
            place = min(self.chargers_free, key=lambda c: (
                self.traffic.travel_time_s(agv.dispatch_node, c.nodes[0], agv.id), c.id))
            self.chargers_free.remove(place)
            self.commands.send(agv.id, "assign",
                               partial(self._charger_delivered, agv, event, place))

    def _charger_delivered(self, agv: FleetAgv, event: simpy.Event, place: Place) -> None:
        """The charger's assign command has reached the AGV (or, if it gave up meanwhile, the
        charger goes back)."""
        if event in self.charger_cancelled:
            self.charger_cancelled.discard(event)
            self.release_charger(place)
            return
        self.charger_wait.discard(agv.id)
        event.succeed(place)
        self._changed()

    def left_station(self, node: str) -> None:
        self.bound_for[node] -= 1

    def _servable(self, order: Order) -> bool:
        places = self.layout.places
        if order.stops:
            return any(all(places[s].serves(t) for s in order.stops)
                       for t in set(self.agv_types.values()))
        return any(places[order.pickup].serves(t) and places[order.dropoff].serves(t)
                   for t in set(self.agv_types.values()))

    def _dispatch(self) -> None:
        changed = False
        skipped = 0  # orders at the head that no idle AGV's type may serve (types only)
        while len(self.waiting) > skipped and self.idle:
            order = self.waiting[skipped]
            pickup = self.layout.places[order.chain[order.stops_done]]
            agv = self._choose(min(pickup.nodes, key=lambda n: self.bound_for[n]), order)
            if agv is None:
                if self.agv_types and any(v.fms_link for v in self.idle.values()):
                    skipped += 1  # ready AGVs, none of a type that may serve it: the next
                    continue
                break
            del self.waiting[skipped]
            if order.stops:
                self._remove_idle(agv)
                self._admit(agv)
                self._dock_chain(order)
            else:
                order.pickup_node = self._docking_node(pickup)
                self._remove_idle(agv)
                self._admit(agv)
                order.dropoff_node = self._docking_node(self.layout.places[order.dropoff])
            order.agv = agv.id
            order.assigned_s = self.env.now
            self.assigning.add(agv.id)
            self.commands.send(agv.id, "assign", partial(self._deliver, agv, order))
            changed = True
        if changed or self.queue_recorded != len(self.waiting):
            self.queue_recorded = len(self.waiting)
            self.recorder.queue_length(self.env.now, self.queue_recorded)
        self._changed()

    def _deliver(self, agv: FleetAgv, order: Order) -> None:
        """The assign command has reached the AGV."""
        self.assigning.discard(agv.id)
        agv.assign(order)
        self._changed()

    def _choose(self, pickup_node: str, order: Order | None = None) -> FleetAgv | None:
        ready = [v for v in self._may_work() if v.fms_link]
        if not ready:
            return None
        if self.agv_types and order is not None:
            allowed = [v for v in ready if self.may_serve(v, order)]
            if not allowed:
                return None  # recorded as not_dispatched type_not_allowed by _review
            return self.policy.choose(allowed, pickup_node, self.traffic.travel_time_s,
                                      self._travel_of)
        return self.policy.choose(ready, pickup_node, self.traffic.travel_time_s)

    def _add_idle(self, agv: FleetAgv) -> None:
        self.idle[agv.id] = agv
        self._offer_count += 1
        self._idle_since[agv.id] = self._offer_count
        if agv.id in self.admitted:
            self.idle_admitted[agv.id] = agv

    def _remove_idle(self, agv: FleetAgv) -> None:
        del self.idle[agv.id]
        del self._idle_since[agv.id]
        self.idle_admitted.pop(agv.id, None)

    def _may_work(self) -> list[FleetAgv]:
        """The idle AGVs that admission lets work, in the order they offered themselves: all
        of them while the track has room, else those already admitted (the same AGVs as
        filtering `idle` with `_may_admit`, without walking the AGVs waiting in parking)."""
        if self.max_active is None or len(self.admitted) < self.max_active:
            return list(self.idle.values())
        return sorted(self.idle_admitted.values(), key=lambda v: self._idle_since[v.id])

    def _dock_chain(self, order: Order) -> None:
        """Choose the docking node of every stop of a chain not yet done."""
        for k in range(order.stops_done, len(order.stops)):
            order.stop_nodes[k] = self._docking_node(self.layout.places[order.stops[k]])
        if order.stops_done == 0:
            order.pickup_node = order.stop_nodes[0]
        order.dropoff_node = order.stop_nodes[-1]

    def _undock_chain(self, order: Order) -> None:
        """Let go of the docking nodes of the stops of a chain not yet done."""
        for k in range(order.stops_done, len(order.stops)):
            node = order.stop_nodes[k]
            if node is not None:
                self.bound_for[node] -= 1
            order.stop_nodes[k] = None

    def _docking_node(self, place: Place) -> str:
        node = min(place.nodes, key=lambda n: self.bound_for[n])
        self.bound_for[node] += 1
        return node

    # ---- work conservation ----------------------------------------------------------------------
    def _changed(self) -> None:
        """Something that may start, change or end a not_dispatched spell happened: look again
        at the end of this instant (once, however many things changed)."""
        if self._review_due or not (self.waiting or self.not_dispatched):
            return
        self._review_due = True
        EndOfInstant(self.env).callbacks.append(self._review)

    def _review(self, _event: simpy.Event | None = None) -> None:
        """Record, for every Idle AGV, why it has no order while orders wait (on changes)."""
        self._review_due = False
        for agv_id, (agv, ended) in list(self.not_dispatched.items()):
            if not self.waiting or agv_id not in self.standing:
                del self.not_dispatched[agv_id]
                agv.note(NOT_DISPATCHED_END, ended.value)
        if not self.waiting:
            return
        # the AGVs waiting in parking for a place on a full track, the many when a large fleet
        # runs with admission, are told apart without `_reason`'s whole walk (the same answer)
        held = None
        if self.max_active is not None and len(self.admitted) >= self.max_active \
                and not self.agv_types:
            held = self.assigning | self.resuming | self.charger_wait | self.polling \
                | self.held_back.keys()
        admitted = self.admitted
        for agv in self.standing.values():
            if held is not None and agv.id not in held and agv.id not in admitted \
                    and agv.fms_link:
                reason: NotDispatched | None = NotDispatched.ADMISSION_FULL
            else:
                reason = self._reason(agv)
            if reason is None:
                raise SimulationError(
                    f"work conservation broken at t={self.env.now:.3f} s: AGV {agv.id} stands "
                    f"Idle at {agv.node} while {len(self.waiting)} orders wait, and nothing "
                    "holds it back (a new reason for not dispatching needs a NotDispatched "
                    "member, fleet_sim.model.not_dispatched)")
            current = self.not_dispatched.get(agv.id)
            if current is None or current[1] is not reason:
                self.not_dispatched[agv.id] = (agv, reason)
                agv.note(NOT_DISPATCHED, reason.value)

    def _reason(self, agv: FleetAgv) -> NotDispatched | None:
        """Why the Idle AGV `agv` has no order while orders wait; None if nothing holds it."""
        if agv.id in self.assigning or agv.id in self.resuming:
            return NotDispatched.COMMAND_IN_TRANSIT
        if agv.id in self.charger_wait:
            return NotDispatched.WAITING_FOR_CHARGER
        if agv.id in self.held_back:
            return self.held_back[agv.id]
        if not agv.fms_link:
            return NotDispatched.LINK_LOST
        if agv.id in self.polling:
            return NotDispatched.STATUS_POLL
        if not self._may_admit(agv):
            return NotDispatched.ADMISSION_FULL
        if self.agv_types and not any(self.may_serve(agv, order) for order in self.waiting):
            return NotDispatched.TYPE_NOT_ALLOWED
        return None

    # ---- admission ----------------------------------------------------------------------------
    def _may_admit(self, agv: FleetAgv) -> bool:
        """The AGV may be given work: no limit, it holds an admission, or one is free."""
        return self.max_active is None or agv.id in self.admitted \
            or len(self.admitted) < self.max_active

    def _admit(self, agv: FleetAgv) -> None:
        if self.max_active is None or agv.id in self.admitted:
            return
        self.admitted.add(agv.id)
        if agv.id in self.idle:
            self.idle_admitted[agv.id] = agv
        agv.note("admitted", f"{len(self.admitted)} of {self.max_active} on the track")

    def on_track_at_start(self, agv: FleetAgv) -> None:
        """The AGV starts on the track (scenario `fleet.start_nodes`): it holds an admission."""
        if self.max_active is not None:
            self.admitted.add(agv.id)
            if agv.id in self.idle:
                self.idle_admitted[agv.id] = agv

    def parked(self, agv: FleetAgv) -> None:
        """The AGV has driven into a parking area with no order: its admission is free for
        another (unless an order is on its way to it)."""
        self._release_if_parked(agv)

    def _release_if_parked(self, agv: FleetAgv) -> None:
        if agv.id in self.admitted and agv.in_parking and agv.id not in self.assigning:
            self.admitted.discard(agv.id)
            self.idle_admitted.pop(agv.id, None)
            self._assign_chargers()  # a battery first, then orders
            self._dispatch()

    # ---- parking ----------------------------------------------------------------------------
    def reserve_parking(self, agv: FleetAgv) -> Place | None:
        """The nearest parking area with room, now reserved for `agv`; None if all are full."""
        free = [p for p in self.layout.parking if self.parking_free[p.id] > 0]
        if not free:
            return None
        place = min(free, key=lambda p: (
            self.traffic.travel_time_s(agv.node, p.nodes[0], agv.id), p.id))
        self.parking_free[place.id] -= 1
        return place

    def release_parking(self, place: Place) -> None:
        self.parking_free[place.id] += 1
