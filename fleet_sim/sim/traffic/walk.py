"""The walk behind the deadlock-avoiding policy's proofs (fleet_sim.sim.traffic.avoidance):
every AGV on the track driven forward along its plan, one node at a time, each move taking and
letting go of what traffic would; a move the walk cannot make waits for what blocks it."""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

from fleet_sim.sim.traffic.locks import Claim, CorridorLock, Lock, NodeLock, ZoneLock
from fleet_sim.sim.traffic.zones import ANY_DIRECTION, DirectionGate

if TYPE_CHECKING:
    from fleet_sim.sim.traffic.table import Reservations

Move = tuple[int, int, int]
"""One move of a witness: (client, plan number, the index in the plan of the node reached;
one past its end: driving off into parking)."""

INF = float("inf")

Hold = tuple[float, float, int, int]
"""A member's hold of a lock in a walk (`Walk.holds`), or in a schedule
(fleet_sim.sim.traffic.schedule): the positions of the move that took it (-inf: held before)
and of the move that let go of it, the member, and a number naming its moves (its plan)."""

Step = tuple[tuple[Lock, int], ...]
"""What reaching one node of a plan takes: (lock, direction) pairs: the node, the corridor and
zones of the hop into it, and the corridor or aisle entered from it (taken at its mouth, as
fleet_sim.sim.traffic.allocation does); the direction is a same-direction zone's, else 0."""


class Walk:
    """Every AGV on the track driven forward along its plan, one node at a time, the one that
    can move and has driven least (free-flow seconds) first (Plans._walk); each move takes
    what the hop takes, and lets go of what the body has cleared and the corridors and zones
    it has left, as the driver and traffic do."""

    def __init__(self, table: Reservations, alone: bool = False) -> None:
        self.table = table
        self.alone = alone
        """Only the members' own holds count (`Schedule.fit` walks one AGV by itself)."""
        self.holders: dict[Lock, list[int]] = {}
        self.ways: dict[Lock, int] = {}
        self.plans: dict[int, tuple[list[str], list[Step], list[tuple[float, float]]]] = {}
        """Member -> its plan: nodes, what reaching each takes, the hop into each (s, m)."""
        self.at: dict[int, int] = {}
        self.body: dict[int, list[tuple[Lock, float]]] = {}
        """Member -> the nodes its body covers, oldest first (the one it stands on last), each
        with the member's `odometer_m` when it stood on it."""
        self.odometer_m: dict[int, float] = {}
        """Member -> metres driven in the walk (its body's start: minus how far it had driven
        past each node)."""
        self.ahead: dict[int, list[Lock]] = {}
        """Member -> nodes it holds ahead on its plan (the look-ahead)."""
        self.others: dict[int, list[Lock]] = {}
        """Member -> the corridors and zones it holds."""
        self.clear_m: dict[int, float] = {}
        self.waiting: dict[Lock, list[int]] = {}
        self.queue: list[tuple[float, int]] = []
        """Members that may move, by `time_s` (the one furthest behind moves first, one step at
        a time; the lowest id among equals)."""
        self.time_s: dict[int, float] = {}
        """Member -> free-flow seconds its moves in the walk have taken: the walk moves the
        AGVs in about the order they will drive, so that the witness foresees the requests."""
        self.plan_of: dict[int, int] = {}
        self.moves: list[Move] = []
        """The moves made, in order."""
        self.junctions = table.junction_locks
        self.deferred: dict[int, Lock] = {}
        """Member -> the node it waits to see free before it drives into the junction before
        it (`step`: not blocking the junction)."""
        self.forced: int | None = None
        """A deferred member let into its junction all the same (nobody else could move)."""
        self.holds: dict[Lock, list[Hold]] | None = None
        """If a dict: from then on, each lock's holds, as (the index in `moves` of the move
        that took it, -inf: held before; of the move that let go of it; the member; its plan
        number) (fleet_sim.sim.traffic.schedule)."""
        self._took: dict[tuple[int, Lock], int] = {}

    def held_by(self, lock: Lock) -> list[int]:
        h = self.holders.get(lock)
        if h is None:
            h = self.holders[lock] = [y for y in holders_of(lock) if y in self.plans] \
                if self.alone else list(holders_of(lock))
            if isinstance(lock, DirectionGate):
                self.ways[lock] = lock.direction
        return h

    def take(self, x: int, lock: Lock, way: int) -> None:
        h = self.held_by(lock)
        if x in h:
            if isinstance(lock, DirectionGate) and way:
                self.ways[lock] = way  # alone inside, it turns round (free_for)
            return
        h.append(x)
        if self.holds is not None:
            self._took[(x, lock)] = len(self.moves)
        if isinstance(lock, DirectionGate) and len(h) == 1:
            self.ways[lock] = way or 1

    def let_go(self, x: int, lock: Lock) -> None:
        h = self.holders.get(lock)
        if h is None:
            h = self.held_by(lock)
        h.remove(x)
        holds = self.holds
        if holds is not None:
            hold = (self._took.pop((x, lock), -INF), len(self.moves) - 1, x, self.plan_of[x])
            of_lock = holds.get(lock)
            if of_lock is None:
                holds[lock] = [hold]
            else:
                of_lock.append(hold)
        if self.waiting:
            woken = self.waiting.pop(lock, None)
            if woken:
                for y in woken:
                    self._ready(y)

    def free_for(self, x: int, lock: Lock, way: int) -> bool:
        h = self.held_by(lock)
        if x in h:  # the other way round a same-direction aisle only alone in it
            return not (isinstance(lock, DirectionGate) and way
                        and self.ways.get(lock) != way and len(h) > 1)
        if len(h) >= lock.capacity:
            return False
        if isinstance(lock, DirectionGate) and h:
            return way == ANY_DIRECTION or self.ways.get(lock) == way
        return True

    def add(self, x: int, plan: int, path: list[str], steps: list[Step],
            costs: list[tuple[float, float]], k: int, granted: Sequence[tuple[Lock, int]]) -> None:
        table = self.table
        node_locks = table.node_locks
        self.plans[x] = (path, steps, costs)
        self.plan_of[x] = plan
        self.at[x] = k
        self.time_s[x] = 0.0
        self.clear_m[x] = table.clearance_m(x)
        nodes, others = table.held_locks(x)
        for lock, way in granted:
            self.take(x, lock, way)
            mine = nodes if isinstance(lock.key, NodeLock) else others
            if lock not in mine:  # a turn: the zone it holds the other way
                mine.append(lock)
        here = node_locks[path[k]]
        on_plan = {node_locks[n] for n in path[k + 1:k + 3]}
        past = table.past_m(x)
        behind = sorted((lk for lk in nodes if lk is not here),
                        key=lambda lk: (-past.get(str(lk.key), 0.0), str(lk.key)))
        self.ahead[x] = [lk for lk in behind if lk in on_plan]
        self.odometer_m[x] = 0.0
        self.body[x] = [(lk, -past.get(str(lk.key), 0.0)) for lk in behind if lk not in on_plan]
        if here in nodes:
            self.body[x].append((here, -past.get(path[k], 0.0)))
        self.others[x] = others
        self._ready(x)

    def stuck(self, start: int) -> list[int]:
        """After a run that failed: members in a cycle of waits, each waiting for a lock the
        next holds, reached from `start` (or the first member waiting); [] if none."""
        waits_for = {y: lock for lock, ys in self.waiting.items() for y in ys
                     if y in self.plans}
        x: int | None = start if start in waits_for else next(iter(waits_for), None)
        seen: dict[int, int] = {}
        chain: list[int] = []
        while x is not None and x not in seen:
            seen[x] = len(chain)
            chain.append(x)
            lock = waits_for.get(x)
            if lock is None:
                return []
            x = next((h for h in self.holders.get(lock, ()) if h != x and h in self.plans), None)
        return [] if x is None else chain[seen[x]:]

    def _ready(self, x: int) -> None:
        if self.deferred:
            self.deferred.pop(x, None)
        heapq.heappush(self.queue, (self.time_s[x], x))

    def run(self) -> bool:
        """Move the members on until none can: True if every one drove off the track."""
        queue = self.queue
        plans = self.plans
        step = self.step
        time_s = self.time_s
        heappop = heapq.heappop
        heappushpop = heapq.heappushpop  # a member is in the queue at most once, so pushing
        # it back and popping the first is one pop of the same order, cheaper when it is first
        if not queue:
            return not plans
        _, x = heappop(queue)
        while True:
            if x in plans and step(x):
                _, x = heappushpop(queue, (time_s[x], x))
            elif queue:
                _, x = heappop(queue)
            elif self.deferred:  # nobody else can move: into its junction after all
                x = min(self.deferred, key=lambda y: (time_s[y], y))
                self.waiting[self.deferred.pop(x)].remove(x)
                self.forced = x
            else:
                return not plans

    def step(self, x: int) -> bool:
        """Move `x` one node on if it can (False: it waits, or it drove off the track)."""
        path, steps, costs = self.plans[x]
        k = self.at[x]
        last = len(path) - 1
        body = self.body[x]
        ahead = self.ahead[x]
        others = self.others[x]
        if k < last:
            step = steps[k + 1]
            here = step[0][0]  # the node's lock
            if len(step) == 1:  # the node alone (most hops): `free_for` and `take` for a
                # lock of capacity one, written out (the walk's hot path)
                h = self.holders.get(here)
                if h is None:
                    h = self.held_by(here)
                if not h:
                    if here in self.junctions and k + 2 <= last and self.forced != x:
                        after = steps[k + 2][0][0]
                        held = self.holders.get(after)
                        if held is None:
                            held = self.held_by(after)
                        if held and x not in held:  # it would stand in the junction, in
                            # the way of who crosses it: first the node after it
                            self.waiting.setdefault(after, []).append(x)
                            self.deferred[x] = after
                            return False
                    h.append(x)
                    if self.holds is not None:
                        self._took[(x, here)] = len(self.moves)
                elif x not in h:
                    self.waiting.setdefault(here, []).append(x)
                    return False
            else:
                blocked = next((lk for lk, way in step if not self.free_for(x, lk, way)), None)
                if blocked is not None:
                    self.waiting.setdefault(blocked, []).append(x)
                    return False
                for lock, way in step:
                    new = x not in self.held_by(lock)
                    self.take(x, lock, way)
                    if new and not isinstance(lock.key, NodeLock):
                        others.append(lock)
            k += 1
            self.at[x] = k
            self.forced = None
            self.moves.append((x, self.plan_of[x], k))
            if ahead and here in ahead:
                ahead.remove(here)
            time_s, length_m = costs[k]
            self.time_s[x] += time_s
            odometer = self.odometer_m[x] = self.odometer_m[x] + length_m
            body.append((here, odometer))
            clear = odometer - self.clear_m[x] + 1e-9  # cleared: stood on at or before it
            while len(body) > 1 and body[0][1] <= clear:
                self.let_go(x, body.pop(0)[0])
            if others:
                nodes = [str(lock.key) for lock, _ in body] + [str(lk.key) for lk in ahead]
                self._leave(x, nodes, list(itertools.pairwise(path[k:k + len(ahead) + 2])))
        if k == last:  # off into parking: everything let go
            self.moves.append((x, self.plan_of[x], last + 1))
            for lock in [lock for lock, _ in body] + ahead + others:
                self.let_go(x, lock)
            del self.plans[x]
            return False
        return True

    def _leave(self, x: int, nodes: list[str], hops: list[tuple[str, str]]) -> None:
        """Let go of the corridors and zones `x` has left: holding none of their nodes and
        not about to drive in from a node it holds (`hops`: its plan's hops from where it
        stands through the nodes it holds ahead, and one more), as traffic keeps a corridor
        or aisle taken at its mouth while the AGV holds the mouth."""
        layout = self.table.layout
        held = self.others[x]
        for lock in list(held):
            key = lock.key
            if isinstance(key, CorridorLock):
                corridor = layout.corridors[key.corridor_id]
                keep = any(n in corridor.members for n in nodes) \
                    or any(hop in corridor.segments for hop in itertools.pairwise(nodes)) \
                    or any(hop in corridor.segments for hop in hops)
            else:
                assert isinstance(key, ZoneLock)
                zone = layout.traffic_zone_by_id[key.zone_id]
                keep = any(n in zone.nodes for n in nodes)
                if not keep and zone.kind == "same_direction":
                    for hop in hops:
                        along = layout.direction_zone_of(*hop)
                        if along is not None and along[0].id == zone.id:
                            keep = True
                            break
            if not keep:
                held.remove(lock)
                self.let_go(x, lock)


def holders_of(lock: Lock) -> Iterable[int]:
    for claim in lock.users:
        yield claim.client_id if isinstance(claim, Claim) else -1
