"""What a run records: events, orders, traffic figures. Plain Python records, collected in one
place and turned into tables and KPIs only after the run (fleet_sim.analysis.tables, .kpis).

Decision: events and occupancy spells are typed NamedTuples rather than dataclasses. They are
immutable and read by field name like a frozen dataclass with slots, cost no more to create than
the plain tuples they replace (a run records some 100,000 events), and pandas builds a table
from a list of them directly, in field order (the columns of events.parquet).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import NamedTuple


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


@dataclass
class Recorder:
    """Collects everything the KPIs are computed from. `warmup_s` splits off the warm-up for the
    running totals (blocked time, distance); events and orders keep their own timestamps."""

    warmup_s: float
    end_s: float
    record_occupancy: bool = False
    events: list[EventRecord] = field(default_factory=list)
    orders: list[Order] = field(default_factory=list)
    queue_lengths: list[tuple[float, int]] = field(default_factory=list)
    blocked_s: float = 0.0
    distance_m: float = 0.0
    distance_total_m: float = 0.0
    deadlocks: int = 0
    occupancy: list[OccupancySpell] = field(default_factory=list)
    """Node holds and segment traversals, when traced (record_occupancy)."""
    charge_waits: list[tuple[float, float]] = field(default_factory=list)
    """(asked_s, charger_assigned_s) per charging."""
    obstacle_pauses: int = 0
    comm_losses: int = 0
    commands_sent: int = 0
    command_retries: int = 0
    errors: list[ErrorRecord] = field(default_factory=list)
    """Every Error, in time order."""
    warnings: Counter[str] = field(default_factory=Counter)
    soc_samples: list[tuple[float, int, float]] = field(default_factory=list)
    """(time_s, agv, soc_pct) at every state change, for battery plots."""
    zone_wait_s: dict[str, float] = field(default_factory=dict)
    """Mutex and same-direction zone id -> AGV-seconds spent (in the window) waiting to enter
    it; the engine lists every such zone of the layout (none: no zone_wait_s KPI)."""
    record_moves: bool = False
    moves: list[MoveRecord] = field(default_factory=list)
    """Drives, lock waits and placements of every AGV, when traced (record_moves): the
    replay's data."""

    def zone_waited(self, zone_id: str, start_s: float, end_s: float) -> None:
        self.zone_wait_s[zone_id] = self.zone_wait_s.get(zone_id, 0.0) \
            + self.window(start_s, end_s)

    def warning(self, code: str) -> None:
        self.warnings[code] += 1

    def event(self, time_s: float, agv: int, event: str, from_state: str, to_state: str,
              node: str, detail: str = "") -> None:
        self.events.append(EventRecord(time_s, agv, event, from_state, to_state, node, detail))

    def error(self, time_s: float, agv: int, code: str, level: str) -> None:
        self.errors.append(ErrorRecord(time_s, agv, code, level))

    def window(self, start_s: float, end_s: float) -> float:
        """The part of [start_s, end_s] inside the measured window (after warm-up)."""
        return max(0.0, min(end_s, self.end_s) - max(start_s, self.warmup_s))

    def blocked(self, start_s: float, end_s: float) -> None:
        self.blocked_s += self.window(start_s, end_s)

    def drove(self, start_s: float, end_s: float, length_m: float) -> None:
        self.distance_total_m += length_m
        span = end_s - start_s
        if span > 0:
            self.distance_m += length_m * self.window(start_s, end_s) / span
        elif start_s >= self.warmup_s:
            self.distance_m += length_m

    def occupied(self, kind: str, key: str, agv: int, start_s: float, end_s: float) -> None:
        if self.record_occupancy:
            self.occupancy.append(OccupancySpell(kind, key, agv, start_s, end_s))

    def moved(self, record: MoveRecord) -> None:
        if self.record_moves:
            self.moves.append(record)
