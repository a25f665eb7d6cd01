"""What a run records: events, orders, state of charge, the replay's moves, traffic figures.
Plain Python records, collected in one place (`Recorder`) and turned into tables and KPIs by
fleet_sim.analysis.

Two ways to keep them:

* **In memory** (no sink, the default of `simulate`): the recorder keeps every row in its lists
  for the whole run, as tests and cross-checks want them.
* **Streamed** (a `RecordSink`, as `fleet-sim run` and every sweep run use it): the recorder
  holds at most `batch_rows` rows of each kind and hands them to the sink in batches as the run
  goes; the sink writes the Parquet tables and keeps the KPIs' running sums
  (fleet_sim.analysis). A run's memory then stays flat in simulated time.

The core knows no file format: `RecordSink` is a Protocol declared here and implemented above the
core (fleet_sim.analysis), so the simulation never imports pyarrow. How rows are kept, batched,
handed over and closed at the end, and why: docs/background/decisions/sim.md.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final, NamedTuple, Protocol, TypeVar

from fleet_sim.model.stalls import StallMeter

BATCH_ROWS: Final = 10_000
"""Rows of one kind a streaming recorder holds before it hands them to its sink, and the rows of
one Parquet row group. Measured on the bundled 12-AGV shift (tracemalloc, roughly), 10,000 rows
are 1.6 MB of events, 3.4 MB of orders, 1.4 MB of SOC samples; that shift records 35,000 events
and 2,200 orders a simulated day. With 50,000, a 30-day run peaks at 1.40x a 1-day run
(bench/memory_flat.py): the orders' batch fills for 23 days and its conversion to a table at
the hand-over comes on top. Smaller batches would make more, smaller row groups, and a
larger file footer that the writer holds until the end."""


class EventRecord(NamedTuple):
    """One state transition or incident of one AGV: a row of events.parquet."""

    time_s: float
    agv: int
    event: str
    """The RSS-AGV-001 event (Event_...) or the incident/note (order_assigned, deadlock...)."""
    from_state: str
    to_state: str
    """Equal to from_state for an event that changes no state."""
    node: str
    detail: str = ""


EVENT_COLUMNS = EventRecord._fields


class OccupancySpell(NamedTuple):
    """An AGV holding a node or traversing a segment (key "u>v") from start_s to end_s."""

    kind: str
    """"node", "segment" or "zone" (a traffic zone held, key its id)."""
    key: str
    agv: int
    start_s: float
    end_s: float


class MoveRecord(NamedTuple):
    """Where an AGV is, for the replay (recorded only with `record_moves`): a row of
    moves.parquet.

    kind "drive": it drove the hop u -> v from start_s to end_s without stopping, from
    `driven_s` seconds into the hop's closed-form profile on (pieces: a curve of `curve_m` at
    `curve_mps` if it turns, then the rest of the segment at `limit_mps`; entered at
    `v_in_mps`, left at `v_out_mps`, with the AGV's own `accel_mps2` and `decel_mps2`;
    `hop_s` in all). An obstacle pause splits a hop into two rows; a fault ends one early.
    "wait": it stood at u waiting for lock v (a node, "corridor 3" or "zone Z") that AGV
    `other` held when the wait began (-1: none). "track": set on the track at u (at the
    start, back from parking or repair); "parking": into the parking area reached through u;
    "off": taken off the track where it stood. "charger_wait": asked at u for a charger at
    start_s and got charger v at end_s ("": none, it failed first). "zone": it held traffic
    zone u from start_s to end_s, driving it v ("forward" or "backward" for a same-direction
    zone, "" for a mutex zone).
    """

    agv: int
    kind: str
    start_s: float
    end_s: float
    u: str
    v: str = ""
    other: int = -1
    hop_s: float = 0.0
    driven_s: float = 0.0
    v_in_mps: float = 0.0
    v_out_mps: float = 0.0
    curve_m: float = 0.0
    curve_mps: float = 0.0
    limit_mps: float = 0.0
    accel_mps2: float = 0.0
    decel_mps2: float = 0.0


MOVE_COLUMNS = MoveRecord._fields


class ErrorRecord(NamedTuple):
    """An AGV entering Error (RSS-AGV-001 6.1): when, which AGV, the code and its level."""

    time_s: float
    agv: int
    code: str
    level: str


@dataclass(slots=True)
class Order:
    """One transport order and its timestamps (None until reached)."""

    id: int
    created_s: float
    pickup: str
    dropoff: str
    pickup_handling_s: float = 0.0
    dropoff_handling_s: float = 0.0
    pickup_node: str | None = None
    dropoff_node: str | None = None
    agv: int | None = None
    assigned_s: float | None = None
    pickup_arrival_s: float | None = None
    picked_s: float | None = None
    dropoff_arrival_s: float | None = None
    delivered_s: float | None = None
    failed_s: float | None = None
    failure: str | None = None
    """Error code of the fault that lost a loaded order."""
    reassigned: int = 0
    """Times the order went back to the queue because its AGV failed before loading."""
    stops: tuple[str, ...] = ()
    """A multi-stop order's chain (fleet_sim.config.chains): `pickup` is its first stop,
    `dropoff` its last; the timestamps above are those of the first pickup (pickup_arrival_s,
    picked_s) and the last dropoff (dropoff_arrival_s, delivered_s). Empty: a plain order."""
    stop_handling_s: tuple[float, ...] = ()
    """Transfer time at each stop of `stops`."""
    stop_nodes: list[str | None] = field(default_factory=list)
    """The docking node of each stop of `stops`, chosen when the order is assigned."""
    stops_done: int = 0
    """Stops whose transfer is complete (a chain taken back after a failure resumes here)."""

    @property
    def chain(self) -> tuple[str, ...]:
        """The order's stops: `stops`, or (pickup, dropoff) for a plain order."""
        return self.stops or (self.pickup, self.dropoff)

    def stop_node(self, index: int) -> str | None:
        """The docking node of stop `index` (plain orders: pickup_node, dropoff_node)."""
        if self.stops:
            return self.stop_nodes[index]
        return self.pickup_node if index == 0 else self.dropoff_node

    def stop_handling(self, index: int) -> float:
        """The transfer time at stop `index`."""
        if self.stops:
            return self.stop_handling_s[index]
        return self.pickup_handling_s if index == 0 else self.dropoff_handling_s


class SocSample(NamedTuple):
    """An AGV's state of charge at one of its state changes: a row of soc.parquet."""

    time_s: float
    agv: int
    soc_pct: float


class QueueLength(NamedTuple):
    """The number of orders waiting for an AGV, from time_s until the next change."""

    time_s: float
    orders: int


class Gridlock(NamedTuple):
    """The fleet locked solid: since when, which AGVs, where they stand, and why it counts."""

    since_s: float
    """When it locked: the cycle closed (its last member began to wait), or the last hop
    ended with orders open and AGVs waiting for locks."""
    agvs: tuple[int, ...]
    nodes: tuple[str, ...]
    """The nodes the AGVs stand at, in the same order."""
    kind: str
    """"cycle" (an unresolved wait-for cycle) or "standstill" (no AGV moved while orders
    were open and AGVs waited for locks)."""

    def where(self) -> str:
        """``agvs 3 5 at nodes M007 M008 (wait-for cycle)``: who and where, in one line."""
        why = "wait-for cycle" if self.kind == "cycle" else "nothing moving"
        return (f"agvs {' '.join(map(str, self.agvs))} at nodes {' '.join(self.nodes)} "
                f"({why})")


class ChargeWait(NamedTuple):
    """One charging stop: when the AGV asked for a charger and when it got one."""

    asked_s: float
    assigned_s: float


class RecordSink(Protocol):
    """Where a streaming `Recorder` hands what it records, in batches, each kind in the order
    recorded: the Parquet tables and the KPIs' running sums (fleet_sim.analysis) implement
    it. A sink keeps no reference to a batch's list after the call returns."""

    def events(self, rows: Sequence[EventRecord]) -> None: ...

    def orders(self, rows: Sequence[Order]) -> None:
        """Finished orders in the order they finished; at the end, the open ones."""

    def soc_samples(self, rows: Sequence[SocSample]) -> None: ...

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None: ...

    def charge_waits(self, rows: Sequence[ChargeWait]) -> None: ...

    def errors(self, rows: Sequence[ErrorRecord]) -> None: ...

    def moves(self, rows: Sequence[MoveRecord]) -> None:
        """Only when the run records moves (`record_moves`)."""

    def close(self) -> None:
        """Everything has been handed over: the run finished."""


class Fanout:
    """One sink that hands every batch to several, in the order given."""

    def __init__(self, *sinks: RecordSink) -> None:
        self.sinks = sinks

    def events(self, rows: Sequence[EventRecord]) -> None:
        for sink in self.sinks:
            sink.events(rows)

    def orders(self, rows: Sequence[Order]) -> None:
        for sink in self.sinks:
            sink.orders(rows)

    def soc_samples(self, rows: Sequence[SocSample]) -> None:
        for sink in self.sinks:
            sink.soc_samples(rows)

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        for sink in self.sinks:
            sink.queue_lengths(rows)

    def charge_waits(self, rows: Sequence[ChargeWait]) -> None:
        for sink in self.sinks:
            sink.charge_waits(rows)

    def errors(self, rows: Sequence[ErrorRecord]) -> None:
        for sink in self.sinks:
            sink.errors(rows)

    def moves(self, rows: Sequence[MoveRecord]) -> None:
        for sink in self.sinks:
            sink.moves(rows)

    def close(self) -> None:
        for sink in self.sinks:
            sink.close()


Row = TypeVar("Row")


@dataclass
class Recorder:
    """Collects everything the tables and KPIs are made of. `warmup_s` splits off the warm-up
    for the running totals (blocked time, distance); events and orders keep their own
    timestamps.

    Without a `sink` every list below holds the whole run. With one, each list holds at most
    `batch_rows` rows not yet handed over (`orders` stays empty; `open_orders` holds the orders
    not finished yet), and `finish()` hands over the rest. The counters (blocked_s, distance,
    deadlocks, incidents, commands, warnings, zone waits) are running totals either way."""

    warmup_s: float
    end_s: float
    record_occupancy: bool = False
    sink: RecordSink | None = None
    batch_rows: int = BATCH_ROWS
    events: list[EventRecord] = field(default_factory=list)
    orders: list[Order] = field(default_factory=list)
    """Every order, in creation order (in memory only)."""
    open_orders: dict[int, Order] = field(default_factory=dict)
    """Orders created and not finished yet, by id, in creation order."""
    finished: list[Order] = field(default_factory=list)
    """Finished orders, in the order they finished (to be handed over)."""
    queue_lengths: list[QueueLength] = field(default_factory=list)
    blocked_s: float = 0.0
    distance_m: float = 0.0
    distance_total_m: float = 0.0
    deadlocks: int = 0
    occupancy: list[OccupancySpell] = field(default_factory=list)
    """Node holds and segment traversals, when traced (record_occupancy); never streamed."""
    charge_waits: list[ChargeWait] = field(default_factory=list)
    obstacle_pauses: int = 0
    """Pauses for people, forklifts and scripted blocks (not other AGVs)."""
    agv_obstacle_pauses: int = 0
    """Pauses behind an AGV standing ahead in a queue (fleet_sim.sim.agents.lds)."""
    comm_losses: int = 0
    commands_sent: int = 0
    command_retries: int = 0
    errors: list[ErrorRecord] = field(default_factory=list)
    """Every Error, in time order."""
    warnings: Counter[str] = field(default_factory=Counter)
    soc_samples: list[SocSample] = field(default_factory=list)
    """(time_s, agv, soc_pct) at every state change of an AGV with a battery model."""
    zone_wait_s: dict[str, float] = field(default_factory=dict)
    """Mutex and same-direction zone id -> AGV-seconds spent (in the window) waiting to enter
    it; the engine lists every such zone of the layout (none: no zone_wait_s KPI)."""
    record_moves: bool = False
    moves: list[MoveRecord] = field(default_factory=list)
    """Drives, lock waits and placements of every AGV, when traced (record_moves): the
    replay's data."""
    open_waits: dict[int, tuple[float, str | None]] = field(default_factory=dict)
    """AGV -> (since_s, zone id or None) of the lock wait under way (see the module)."""
    charger_asked_s: dict[int, float] = field(default_factory=dict)
    """AGV -> when it asked for the charger it still waits for."""
    charger_waits_open: list[float] = field(default_factory=list)
    """At the end of the run (`end_of_run`): the ask times of the charger requests still
    waiting, by AGV."""
    moved_s: float = 0.0
    """When the latest hop ended (fleet_sim.sim.gridlock: nothing moving)."""
    gridlock: Gridlock | None = None
    stalls: StallMeter | None = None
    """Charging starvation and a fleet out of service (fleet_sim.model.stalls), if metered."""
    ended: bool = False
    """`end_of_run` has closed the open spells: the totals are final."""
    _full: float = field(init=False, repr=False)
    _closed: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.batch_rows < 1:
            raise ValueError(f"batch_rows ({self.batch_rows}) must be at least 1")
        self._full = self.batch_rows if self.sink is not None else float("inf")

    def rows_held(self) -> int:
        """Rows the recorder holds now (occupancy spells not counted: see the module)."""
        return (len(self.events) + len(self.orders) + len(self.open_orders)
                + len(self.finished) + len(self.queue_lengths) + len(self.charge_waits)
                + len(self.errors) + len(self.soc_samples) + len(self.moves))

    # ---- what the model records ----------------------------------------------------------------
    def zone_waited(self, zone_id: str, start_s: float, end_s: float) -> None:
        if self.ended:
            return
        self.zone_wait_s[zone_id] = self.zone_wait_s.get(zone_id, 0.0) \
            + self.window(start_s, end_s)

    def wait_began(self, agv: int, start_s: float, zone_id: str | None = None) -> None:
        """AGV `agv` began waiting for a lock (for zone `zone_id`'s gate, if given)."""
        self.open_waits[agv] = (start_s, zone_id)

    def charger_asked(self, agv: int, asked_s: float) -> None:
        self.charger_asked_s[agv] = asked_s
        if self.stalls is not None:
            self.stalls.charger_asked(asked_s, agv)

    def charger_wait_over(self, agv: int) -> None:
        """The AGV got its charger, or stopped waiting for one (it failed first)."""
        self.charger_asked_s.pop(agv, None)

    def end_of_run(self) -> None:
        """The clock has reached the end: what is still open lasts to the end (once)."""
        if self.ended:
            return
        for start_s, zone_id in self.open_waits.values():
            self.blocked_s += self.window(start_s, self.end_s)
            if zone_id is not None:
                self.zone_wait_s[zone_id] = self.zone_wait_s.get(zone_id, 0.0) \
                    + self.window(start_s, self.end_s)
        self.open_waits.clear()
        self.charger_waits_open = [self.charger_asked_s[agv]
                                   for agv in sorted(self.charger_asked_s)]
        self.charger_asked_s.clear()
        if self.stalls is not None:
            self.stalls.end(self.end_s)
        self.ended = True

    def warning(self, code: str) -> None:
        self.warnings[code] += 1

    def event(self, time_s: float, agv: int, event: str, from_state: str, to_state: str,
              node: str, detail: str = "") -> None:
        self.events.append(EventRecord(time_s, agv, event, from_state, to_state, node, detail))
        stalls = self.stalls
        if stalls is not None:
            if from_state != to_state:
                stalls.state_changed(time_s, agv, from_state, to_state)
            else:
                stalls.note(time_s, agv, event, detail)
        if len(self.events) >= self._full:
            self._hand(self.events, self._sink.events)

    def soc(self, time_s: float, agv: int, soc_pct: float) -> None:
        self.soc_samples.append(SocSample(time_s, agv, soc_pct))
        if self.stalls is not None:
            self.stalls.soc(time_s, agv, soc_pct)
        if len(self.soc_samples) >= self._full:
            self._hand(self.soc_samples, self._sink.soc_samples)

    def order_created(self, order: Order) -> None:
        if self.sink is None:
            self.orders.append(order)
        self.open_orders[order.id] = order

    def order_finished(self, order: Order) -> None:
        """The order was delivered or failed: its record is complete."""
        del self.open_orders[order.id]
        self.finished.append(order)
        if len(self.finished) >= self._full:
            self._hand(self.finished, self._sink.orders)

    def queue_length(self, time_s: float, orders: int) -> None:
        self.queue_lengths.append(QueueLength(time_s, orders))
        if self.stalls is not None:
            self.stalls.orders_waiting(time_s, orders)
        if len(self.queue_lengths) >= self._full:
            self._hand(self.queue_lengths, self._sink.queue_lengths)

    def charge_wait(self, asked_s: float, assigned_s: float) -> None:
        self.charge_waits.append(ChargeWait(asked_s, assigned_s))
        if len(self.charge_waits) >= self._full:
            self._hand(self.charge_waits, self._sink.charge_waits)

    def error(self, time_s: float, agv: int, code: str, level: str) -> None:
        self.errors.append(ErrorRecord(time_s, agv, code, level))
        if self.stalls is not None:
            self.stalls.fault(agv, code)
        if len(self.errors) >= self._full:
            self._hand(self.errors, self._sink.errors)

    def window(self, start_s: float, end_s: float) -> float:
        """The part of [start_s, end_s] inside the measured window (after warm-up)."""
        return max(0.0, min(end_s, self.end_s) - max(start_s, self.warmup_s))

    def blocked(self, start_s: float, end_s: float, agv: int | None = None) -> None:
        """A lock wait ended (of `agv`: its open wait is closed)."""
        if self.ended:
            return
        if agv is not None:
            self.open_waits.pop(agv, None)
        self.blocked_s += self.window(start_s, end_s)

    def drove(self, start_s: float, end_s: float, length_m: float) -> None:
        self.distance_total_m += length_m
        if end_s > self.moved_s:
            self.moved_s = end_s
        span = end_s - start_s
        warmup_s = self.warmup_s
        if span > 0:  # `window`, written out (once a hop; min and max as conditionals)
            window = (self.end_s if self.end_s < end_s else end_s) \
                - (warmup_s if warmup_s > start_s else start_s)
            self.distance_m += length_m * (window if window > 0.0 else 0.0) / span
        elif start_s >= warmup_s:
            self.distance_m += length_m

    def occupied(self, kind: str, key: str, agv: int, start_s: float, end_s: float) -> None:
        if self.record_occupancy:
            self.occupancy.append(OccupancySpell(kind, key, agv, start_s, end_s))

    def moved(self, record: MoveRecord) -> None:
        if self.record_moves:
            self.moves.append(record)
            if len(self.moves) >= self._full:
                self._hand(self.moves, self._sink.moves)

    # ---- handing over --------------------------------------------------------------------------
    def finish(self) -> None:
        """The run is over. Streaming: hand over every row still held, the open orders last,
        and close the sink (once). In memory: nothing (the lists are the records)."""
        if self.sink is None or self._closed:
            return
        self._closed = True
        self._hand_all(self.sink)
        self.sink.close()

    def hand_over(self, sink: RecordSink) -> None:
        """Hand a finished in-memory run to `sink` in the batches and order a streaming run
        hands them, and close it; the lists are kept (the in-memory run's files and KPIs are
        then made the one way a streamed run's are)."""
        if self.sink is not None:
            raise ValueError("a streaming recorder hands its rows to its own sink")
        self._hand_all(sink, keep=True)
        sink.close()

    def _hand_all(self, sink: RecordSink, keep: bool = False) -> None:
        size = self.batch_rows
        _in_batches(self.events, size, sink.events)
        _in_batches(self.finished, size, sink.orders)
        _in_batches(list(self.open_orders.values()), size, sink.orders)
        _in_batches(self.soc_samples, size, sink.soc_samples)
        _in_batches(self.queue_lengths, size, sink.queue_lengths)
        _in_batches(self.charge_waits, size, sink.charge_waits)
        _in_batches(self.errors, size, sink.errors)
        _in_batches(self.moves, size, sink.moves)
        if not keep:
            for rows in (self.events, self.finished, self.soc_samples, self.queue_lengths,
                         self.charge_waits, self.errors, self.moves):
                rows.clear()
            self.open_orders.clear()

    @property
    def _sink(self) -> RecordSink:
        assert self.sink is not None
        return self.sink

    @staticmethod
    def _hand(rows: list[Row], to: Callable[[list[Row]], None]) -> None:
        batch = rows[:]
        rows.clear()
        to(batch)


def _in_batches(rows: list[Row], size: int, to: Callable[[list[Row]], None]) -> None:
    for start in range(0, len(rows), size):
        to(rows[start:start + size])
