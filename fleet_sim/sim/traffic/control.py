"""Traffic control: node and corridor locks, routes by travel time, deadlock detection.

Rules (see docs/engine.md for why):

* One AGV per node. An AGV holds the node it stands on, the node it drives to, and the nodes
  behind it until its body and the minimum gap have cleared them. It reserves the node after the
  next one on the fly (look-ahead) so it can pass through without stopping; when that node is
  taken it brakes to stop at the next node. On a segment there is therefore one AGV at a time,
  in order, at least the minimum gap behind the one ahead: no overtaking and no overlap.
* Corridors (chains of two-way segments) are single-track: an AGV takes the corridor lock before
  it takes the node from which it enters the corridor, so two AGVs never meet head-on.
* Routes follow the shortest free-flow travel time, from per-destination tables computed once.
* A wait-for cycle (AGV a waits for a lock that b holds, b for one that c holds, ..., back to a)
  is looked for whenever an AGV starts waiting and every `deadlock_check_s` while it still waits.
  A cycle is recorded and resolved: one member takes another route or backs off to a free node.
* Giving way: an AGV that has waited `give_way_after_s` for a corridor or a side track while
  another AGV queues behind it drives on and comes back round (circulates) instead of blocking
  the main loop. This keeps loops flowing, which avoids most deadlocks by construction.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, cast

import networkx as nx
import simpy
from simpy.resources.resource import Request

from fleet_sim.config.layout import Corridor, Layout
from fleet_sim.model.kinematics import Motion, MotionBackend, Piece, stop_entry_speed, traverse

if TYPE_CHECKING:
    from fleet_sim.sim.agents.driving import Driver as Vehicle


class Claim(Request):
    """A request for a lock that knows which AGV made it."""

    def __init__(self, resource: Lock, agv_id: int) -> None:
        self.agv_id = agv_id
        super().__init__(resource)


class Lock(simpy.Resource):
    """An exclusive lock on a node or a corridor: a SimPy resource of capacity one."""

    def __init__(self, env: simpy.Environment, key: str) -> None:
        super().__init__(env, capacity=1)
        self.key = key

    def claim(self, agv_id: int) -> Claim:
        return Claim(self, agv_id)

    @property
    def holder(self) -> int | None:
        if not self.users:
            return None
        claim = cast(Claim, self.users[0])
        return claim.agv_id

    @property
    def is_free(self) -> bool:
        return not self.users and not self.put_queue


@dataclass(frozen=True)
class Escape:
    """How a deadlocked AGV gets out: another route, or a step back to a free node."""

    kind: Literal["yield", "reroute", "circulate", "backoff"]
    path: tuple[str, ...]
    """Nodes from the AGV's node onwards (reroute, circulate: to its goal; backoff: one hop;
    yield: none, the AGV gives up a corridor it reserved and tries again a little later)."""


class Traffic:
    def __init__(self, env: simpy.Environment, layout: Layout, motion: Motion) -> None:
        self.env = env
        self.layout = layout
        self.graph = layout.graph
        self.motion = motion
        self.node_locks = {n: Lock(env, n) for n in self.graph.nodes}
        self.corridor_locks = {c.id: Lock(env, f"corridor {c.id}") for c in layout.corridors}
        self.waiting: dict[int, Lock] = {}
        self.blocks: dict[tuple[str, str], list[tuple[float, float]]] = {}
        """Scripted obstacles: segment (both directions) -> [(from_s, until_s)]."""
        self.known_blocks: dict[tuple[str, str], float] = {}
        """Blocks an AGV has reported: routes keep off them until they end."""
        self.version = 0
        """Counts changes of lock ownership and waits: a blocked AGV that sees the same count
        as at its last look has nothing new to find."""
        self.vehicles: dict[int, Vehicle] = {}
        self.motion_backend: MotionBackend | None = None
        """Moves the AGVs when set (`motion: sumo`); None: closed-form hops."""
        self._known_cycles: set[frozenset[int]] = set()
        for _, _, data in self.graph.edges(data=True):
            data["free_time_s"] = data["length_m"] / min(data["speed_limit_mps"],
                                                         motion.max_speed_mps)
        self._to_dest: dict[str, tuple[dict[str, float], dict[str, str]]] = {}
        self._pieces: dict[tuple[str | None, str, str], tuple[Piece, ...]] = {}
        self._stop_entry: dict[tuple[str, str, str], float] = {}
        self._detours: dict[tuple[str, str, frozenset[str], frozenset[tuple[str, str]]],
                            list[str] | None] = {}

    # ---- routes ---------------------------------------------------------------------------
    def _table(self, dest: str) -> tuple[dict[str, float], dict[str, str]]:
        table = self._to_dest.get(dest)
        if table is None:
            dist, paths = nx.single_source_dijkstra(self.graph.reverse(copy=False), dest,
                                                    weight="free_time_s")
            next_hop = {n: p[-2] for n, p in paths.items() if len(p) > 1}
            table = (dist, next_hop)
            self._to_dest[dest] = table
        return table

    def travel_time_s(self, src: str, dest: str) -> float:
        """Free-flow travel time from src to dest (cached per destination)."""
        return self._table(dest)[0][src]

    def block(self, u: str, v: str, from_s: float, until_s: float) -> None:
        for key in ((u, v), (v, u)):
            self.blocks.setdefault(key, []).append((from_s, until_s))

    def blocked_until(self, u: str, v: str, now_s: float) -> float | None:
        """End of the scripted block on u -> v in force now, if any; reported to routing."""
        for start, end in self.blocks.get((u, v), ()):
            if start <= now_s < end:
                self.known_blocks[(u, v)] = end
                self.known_blocks[(v, u)] = end
                return end
        return None

    def route(self, src: str, dest: str) -> list[str]:
        """Nodes from src to dest by shortest free-flow travel time, src included; around
        segments reported blocked when there is a way round."""
        if self.known_blocks:
            now = self.env.now
            self.known_blocks = {k: t for k, t in self.known_blocks.items() if t > now}
            if self.known_blocks:
                around = self.route_avoiding(src, dest, set(), set(self.known_blocks))
                if around is not None:
                    return around
        next_hop = self._table(dest)[1]
        path = [src]
        node = src
        while node != dest:
            node = next_hop[node]
            path.append(node)
        return path

    def route_avoiding(self, src: str, dest: str, avoid: set[str],
                       avoid_edges: set[tuple[str, str]] | None = None) -> list[str] | None:
        """Shortest route that keeps off `avoid` nodes and edges (not cached: used when
        blocked)."""
        if dest in avoid or src in avoid:
            return None
        key = (src, dest, frozenset(avoid), frozenset(avoid_edges or ()))
        if key in self._detours:
            return self._detours[key]
        view = nx.restricted_view(self.graph, list(avoid), list(avoid_edges or ()))
        try:
            path: list[str] | None = list(nx.shortest_path(view, src, dest, weight="free_time_s"))
        except nx.NetworkXNoPath:
            path = None
        self._detours[key] = path
        return path

    # ---- kinematics per hop ---------------------------------------------------------------
    def pieces(self, prev: str | None, u: str, v: str) -> tuple[Piece, ...]:
        """The stretch u -> v for an AGV that came from prev: a turn curve first if it turns."""
        key = (prev, u, v)
        found = self._pieces.get(key)
        if found is None:
            data = self.graph.edges[u, v]
            length = data["length_m"]
            limit = min(data["speed_limit_mps"], self.motion.max_speed_mps)
            turn = self.layout.turn(prev, u, v)
            curve = min(self.layout.turn_length_m, length)
            if turn in ("left", "right") and curve > 0:
                turn_limit = min(limit, self.motion.turn_speed_mps)
                found = ((curve, turn_limit), (length - curve, limit)) if length > curve \
                    else ((length, turn_limit),)
            else:
                found = ((length, limit),)
            self._pieces[key] = found
        return found

    def pass_speed_mps(self, u: str, v: str, w: str) -> float:
        """Highest speed at v for an AGV on u -> v that goes on to w and may have to stop at w."""
        key = (u, v, w)
        found = self._stop_entry.get(key)
        if found is None:
            if self.layout.turn(u, v, w) == "reverse":
                found = 0.0
            else:
                found = stop_entry_speed(self.pieces(u, v, w), self.motion.decel_mps2)
            self._stop_entry[key] = found
        return found

    def hop(self, prev: str | None, u: str, v: str, v_in: float,
            v_end_max: float) -> tuple[float, float]:
        """(time_s, v_end) for u -> v, closed form."""
        return traverse(self.pieces(prev, u, v), v_in, v_end_max,
                        self.motion.accel_mps2, self.motion.decel_mps2)

    # ---- locks ----------------------------------------------------------------------------
    def entry_corridor(self, node: str, nxt: str | None) -> Corridor | None:
        """The corridor an AGV enters when it leaves `node` for `nxt`, if `node` is outside it."""
        if nxt is None:
            return None
        corridor = self.layout.corridor_of(node, nxt)
        if corridor is None or node in corridor.members:
            return None
        return corridor

    # ---- deadlocks ------------------------------------------------------------------------
    def find_cycle(self, start: int) -> list[int] | None:
        """The wait-for cycle through AGV `start`, as AGV ids in wait order, if there is one."""
        chain = [start]
        seen = {start}
        agv = start
        while True:
            lock = self.waiting.get(agv)
            if lock is None:
                return None
            holder = lock.holder
            if holder is None or holder == agv:
                return None
            if holder == start:
                return chain
            if holder in seen:
                return None  # a cycle that does not pass through start: its members handle it
            seen.add(holder)
            chain.append(holder)
            agv = holder

    def new_cycle(self, cycle: list[int]) -> bool:
        """True the first time a cycle with these members is seen while it persists."""
        key = frozenset(cycle)
        self._known_cycles = {c for c in self._known_cycles if self._still_cycle(c)}
        if key in self._known_cycles:
            return False
        self._known_cycles.add(key)
        return True

    def _still_cycle(self, members: frozenset[int]) -> bool:
        first = min(members)
        cycle = self.find_cycle(first)
        return cycle is not None and frozenset(cycle) == members

    def escape_for(self, vehicle: Vehicle, must_free: Lock | None = None) -> Escape | None:
        """A way out for a blocked AGV that lets go of `must_free` (a lock it holds that another
        AGV waits for): give up a corridor it has reserved but not entered, take another route
        whose first node is free, or back off to a free neighbour."""
        lock = self.waiting.get(vehicle.id)
        node = vehicle.node
        goal = vehicle.goal
        inside: Corridor | None = None
        if must_free is not None and must_free.key not in self.node_locks:
            cid = int(must_free.key.split()[1])
            _, entry = vehicle.corridors.get(cid, (None, "?"))
            if entry is not None:
                return Escape("yield", (node,))
            inside = self.layout.corridors[cid]
        avoid_nodes: set[str] = set()
        avoid_edges: set[tuple[str, str]] = set()
        if lock is not None and lock.key in self.node_locks:
            avoid_nodes.add(lock.key)
        elif lock is not None:
            corridor = self.layout.corridors[int(lock.key.split()[1])]
            avoid_nodes |= corridor.members
            avoid_edges |= corridor.segments
        if goal is not None and (avoid_nodes or avoid_edges):
            path = self.route_avoiding(node, goal, avoid_nodes, avoid_edges)
            if path is not None and len(path) > 1 and self._free_to_enter(vehicle, node, path[1]) \
                    and (inside is None or any(n not in inside.members for n in path[1:])):
                return Escape("reroute", tuple(path))
        if goal is not None and inside is None and (avoid_nodes or avoid_edges):
            circle = self._circulate(vehicle, goal, avoid_nodes, avoid_edges)
            if circle is not None:
                return circle
        for nxt in sorted(self.graph.successors(node)):
            if nxt in avoid_nodes or (node, nxt) in avoid_edges or nxt == vehicle.next_node:
                continue
            if inside is not None and nxt in inside.members:
                continue
            if self._free_to_enter(vehicle, node, nxt):
                return Escape("backoff", (node, nxt))
        return None

    def _circulate(self, vehicle: Vehicle, goal: str, avoid_nodes: set[str],
                   avoid_edges: set[tuple[str, str]]) -> Escape | None:
        """Drive on two hops past what blocks the way (a busy corridor, a full siding) and come
        back round by the usual route: a loop's answer to waiting in everyone's way."""
        node = vehicle.node
        for first in sorted(self.graph.successors(node)):
            if first in avoid_nodes or (node, first) in avoid_edges:
                continue
            if not self._free_to_enter(vehicle, node, first):
                continue
            for second in sorted(self.graph.successors(first)):
                if second in avoid_nodes or (first, second) in avoid_edges or second == node:
                    continue
                if self.layout.corridor_of(first, second) is not None:
                    continue  # circulate on one-way track only
                back = self.route(second, goal)
                return Escape("circulate", (node, first, *back))
        return None

    def blocks_others(self, vehicle: Vehicle) -> bool:
        """True if another AGV waits for a node or corridor that `vehicle` holds."""
        locks = self.node_locks
        if any(locks[h.node].put_queue for h in vehicle.held):
            return True
        corridors = self.corridor_locks
        return any(corridors[cid].put_queue for cid in vehicle.corridors)

    def _free_to_enter(self, vehicle: Vehicle, node: str, nxt: str) -> bool:
        if not self.node_locks[nxt].is_free:
            return False
        corridor = self.layout.corridor_of(node, nxt)
        if corridor is None or corridor.id in vehicle.corridors:
            return True
        return self.corridor_locks[corridor.id].is_free

    def holders(self) -> Iterator[tuple[str, int]]:
        """(node, AGV id) for every held node lock (for invariant checks)."""
        for node, lock in self.node_locks.items():
            if lock.users:
                claim = cast(Claim, lock.users[0])
                yield node, claim.agv_id
