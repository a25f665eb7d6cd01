"""A hop's allocation: what an AGV needs to drive one hop, and the modules that say whether each
part of it may be allocated.

The model is openTCS's `Scheduler.allocate(client, resources)` with its modules (the
same-direction block module among them): the AGV asks traffic control once for the whole set a
hop needs (`Hop`: the node it takes, the single-track corridors it enters on the way, the mutex
and same-direction zones it enters), and `Traffic` grants it all or nothing
(`Traffic.try_allocate`, the look-ahead, which never waits) or queues the AGV for it
(`Traffic.allocate`), giving back what it took when the AGV gives up waiting. Each kind of
resource is one `AllocationModule`: it names the locks of its kind the hop needs that the AGV
does not hold yet (`needs`), and answers whether one may be granted now (`may_allocate`).

The modules' order is the order in which a queued request takes its parts (corridors, mutex
zones, same-direction zones, the node): an AGV reserves a corridor or an aisle before the node
from which it drives in, since waiting there it would block the way out.

The choices where the issues were silent: docs/background/decisions/sim.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple, Protocol, cast

from fleet_sim.config.layout import BACKWARD, FORWARD
from fleet_sim.sim.traffic.locks import Lock, ZoneLock
from fleet_sim.sim.traffic.zones import ANY_DIRECTION, DirectedClaim, DirectionGate

if TYPE_CHECKING:
    from fleet_sim.sim.traffic.table import Reservations

DIRECTION_NAMES = {FORWARD: "forward", BACKWARD: "backward", ANY_DIRECTION: ""}
"""How the replay's zone rows name a same-direction claim's direction ("": a mutex zone)."""


class Hop(NamedTuple):
    """One hop an AGV asks to drive: from `via` to `node`, and on to `after` (if it knows it
    already: the corridor or aisle it would enter from `node` is reserved with the node)."""

    via: str
    node: str
    after: str | None = None


class Need(NamedTuple):
    """One lock a hop needs that the AGV does not hold yet."""

    lock: Lock
    entry: str | None = None
    """Corridor or same-direction zone: the node from which the AGV drives in."""
    direction: int = ANY_DIRECTION
    """Same-direction zone: the way the AGV will drive it."""
    turn: bool = False
    """Same-direction zone: the AGV holds it the other way (it asks to turn round)."""

    @property
    def zone_id(self) -> str:
        return cast(ZoneLock, self.lock.key).zone_id


NO_NEEDS: tuple[Need, ...] = ()


class AllocationModule(Protocol):
    """One kind of resource of a hop (openTCS: a Scheduler module)."""

    name: str

    def needs(self, client_id: int, hop: Hop) -> Sequence[Need]:
        """The locks of this kind the hop needs that the client does not hold yet."""
        ...

    def may_allocate(self, client_id: int, need: Need) -> bool:
        """True if `need` would be granted now, nobody waiting before."""
        ...


class CorridorModule:
    """Single-track corridors: one AGV at a time, taken before the node it enters from."""

    name = "corridor"

    def __init__(self, table: Reservations) -> None:
        self.table = table
        self._entered: dict[Hop, tuple[tuple[int, Need], ...]] = {}
        """Hop -> the corridors it enters (each once, with the node it enters from), whoever
        asks; `needs` leaves out those the client holds."""

    def needs(self, client_id: int, hop: Hop) -> Sequence[Need]:
        entered = self._entered.get(hop)
        if entered is None:
            entered = self._entered[hop] = self._enters(hop)
        if not entered:
            return NO_NEEDS
        held = self.table.corridors_of(client_id)
        return [need for cid, need in entered if cid not in held]

    def _enters(self, hop: Hop) -> tuple[tuple[int, Need], ...]:
        table = self.table
        corridor_of = table.layout.corridor_of
        out: list[tuple[int, Need]] = []
        for a, b in ((hop.via, hop.node), (hop.node, hop.after)):
            corridor = corridor_of(a, b) if b is not None else None
            if corridor is None or a in corridor.members:
                continue
            if all(cid != corridor.id for cid, _ in out):
                out.append((corridor.id, Need(table.corridor_locks[corridor.id], a)))
        return tuple(out)

    def may_allocate(self, client_id: int, need: Need) -> bool:
        return need.lock.is_free


class MutexZoneModule:
    """Mutex zones: at most N AGVs inside; taken before the first node inside."""

    name = "mutex"

    def __init__(self, table: Reservations) -> None:
        self.table = table

    def needs(self, client_id: int, hop: Hop) -> Sequence[Need]:
        table = self.table
        zones = table.layout.mutex_zones_at.get(hop.node)
        if not zones:
            return NO_NEEDS
        held = table.zones_of(client_id)
        return [Need(table.zone_locks[z.id]) for z in zones if z.id not in held]

    def may_allocate(self, client_id: int, need: Need) -> bool:
        return need.lock.is_free


class SameDirectionModule:
    """Same-direction zones (openTCS's same-direction blocks): the AGVs inside all drive the
    aisle one way; taken for the way the AGV enters by, before the node it drives in from."""

    name = "same_direction"

    def __init__(self, table: Reservations) -> None:
        self.table = table

    def needs(self, client_id: int, hop: Hop) -> Sequence[Need]:
        table = self.table
        layout = table.layout
        if not layout.direction_zones_at:
            return NO_NEEDS
        held_zones = table.zones_of(client_id)
        out: list[Need] = []
        for a, b in ((hop.via, hop.node), (hop.node, hop.after)):
            along = layout.direction_zone_of(a, b) if b is not None else None
            if along is None:
                continue
            zone, direction = along
            held = held_zones.get(zone.id)
            if held is not None and cast(DirectedClaim, held).direction == direction:
                continue
            if any(n.zone_id == zone.id for n in out):
                continue
            out.append(Need(table.zone_locks[zone.id], a, direction, held is not None))
        return out

    def may_allocate(self, client_id: int, need: Need) -> bool:
        # never the other way on the claim it holds without waiting for the turn
        return not need.turn and cast(DirectionGate, need.lock).admits(need.direction)


class NodeModule:
    """Nodes: one AGV per node."""

    name = "node"

    def __init__(self, table: Reservations) -> None:
        self.table = table
        self._needs = {node: (Need(lock),) for node, lock in table.node_locks.items()}

    def needs(self, client_id: int, hop: Hop) -> Sequence[Need]:
        return self._needs[hop.node]

    def may_allocate(self, client_id: int, need: Need) -> bool:
        return need.lock.is_free
