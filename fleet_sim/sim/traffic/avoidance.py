"""Deadlock avoidance (`traffic.policy: avoiding`): every AGV on the track declares a plan that
ends in parking, and traffic grants a node, corridor or zone only when, with the grant, every
AGV could still finish its plan in some order.

The scheme is the Banker's algorithm of Habermann (1969, CACM 12(7):373-385), applied to buffer
space by Lawley, Reveliotis and Ferreira (1997, Int. J. Flexible Manufacturing Systems
10:73-100) and to zone-controlled AGV guide paths by Reveliotis (2000, IIE Transactions
32(7):647-659): each resource (a node, a single-track corridor, a mutex or same-direction
zone) is a buffer, an AGV's remaining plan is its maximum claim, and a state is *safe* when
some order of the AGVs lets each drive its whole plan alone, those before it having driven
off. A plan is the route to the AGV's goal followed by the route from the goal to the nearest
parking access, where the AGV drives off the track and lets go of everything.

The state's *claim graph* has an edge x -> y when a resource in x's remaining plan is held by
y. The state is safe when this graph has no cycle: finish the AGVs in reverse topological
order (Habermann's sequence). Traffic keeps it acyclic:

* **A grant** to AGV a of resources R (free, and on a's plan) adds edges t -> a for the AGVs t
  whose plans need something in R. The graph is acyclic before the grant, which closes a cycle
  exactly when a reaches such a t (`may_grant`: a depth-first walk from a, skipped when nobody
  else's plan needs R).
* **A new plan** for a adds edges from a to the holders of what it needs; it closes a cycle
  exactly when one of them reaches a (`may_declare`). A refused plan leaves the plan in force
  as it is: the AGV drives on along it (to parking, at worst) and asks again at every node.
* Advancing along a plan, letting go of a lock and driving off into parking only remove edges.
* **A cyclic graph** may still be safe: `Walk` drives every AGV forward one node at a time
  and, if all get off the track, keeps the order of moves as the *witness*. A request that is
  the witness's next move (`_is_next`), or a later move that no move before it takes anything
  of (`_moves_first`), is granted without a new walk. A grant the walk refused is asked again
  at every wake (its move may have come next), but walked again only once an AGV of the cycle
  of waits the walk got stuck on has moved (`Walk.stuck`; without one, once the AGV could
  have driven the hop, `retry_at`). Until then a walk mostly sticks there again (not always:
  other AGVs' moves change the walk too; the rule only delays a grant, it never makes one).
* **A fit** (fleet_sim.sim.traffic.schedule) spares a walk: a new plan, or a grant that is
  neither next nor first, is fitted in among the other AGVs' moves of the witness (each lock's
  holds kept from the walk), the client's moves each as early as they may go; the fitted
  witness shows the state safe by construction. Fits are tried only until the first walk
  that fails (`_fits`): they show states safe that the greedy walk may not, and where the walk
  refuses, the fleet then moves only in the witness's order (the distribution centre's
  refusals doubled).
* The walk keeps a member out of a junction (a node more than one segment leads into) while
  the node after it is held, unless nobody else can move: standing in it, the member would
  block who crosses there, and the greedy walk would close a cycle of waits in a state that
  is safe (as in the dense states of 300 AGVs on the fulfilment centre). Any order of legal
  moves is a witness, so this changes which order is found, never what is granted.
* A blocked AGV takes another route as reactive traffic does after `replan_after_s`
  (`AvoidingPolicy._replan_safely`), as a new plan the check accepts (`may_declare`) or not at all.

Why this never locks solid: an acyclic graph has a sink, an AGV none of whose remaining
resources another AGV holds; its next hop is free and granting it adds edges into the sink
only, so it is granted. A wait-for cycle needs every member to wait for a resource another
member holds, which is an edge of the claim graph for each: never while it is acyclic.

The choices where the issues were silent (the exit, zones with several holders, AGVs standing
still, what the check costs): docs/background/decisions/sim.md.
"""

from __future__ import annotations

import bisect
import itertools
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import networkx as nx

from fleet_sim.errors import SimulationError
from fleet_sim.sim.traffic.locks import Lock
from fleet_sim.sim.traffic.schedule import Schedule
from fleet_sim.sim.traffic.walk import Move, Step, Walk, holders_of
from fleet_sim.sim.traffic.zones import DirectionGate

if TYPE_CHECKING:
    from fleet_sim.sim.traffic.routing import Routes
    from fleet_sim.sim.traffic.table import Reservations

REFITS = 1
"""How many other AGVs' moves a fit may fit again after the client's (`Plans._fit`)."""


class Plans:
    """Every AGV's declared plan, the resources each still needs, and the safety checks."""

    def __init__(self, table: Reservations, routes: Routes) -> None:
        self.table = table
        self.routes = routes
        """The default vehicle type's routes (hop lengths and times)."""
        self.path: dict[int, list[str]] = {}
        """Client id -> its plan: nodes from where it stood when it declared it to a parking
        access."""
        self.at: dict[int, int] = {}
        """Client id -> the index in its plan of the node it stands on."""
        self._steps: dict[int, list[Step]] = {}
        """Client id -> per plan index k, what reaching path[k] takes."""
        self._takes: dict[int, dict[Lock, list[int]]] = {}
        """Client id -> lock -> the indices k of its plan (ascending) whose steps take it."""
        self._costs: dict[int, list[tuple[float, float]]] = {}
        """Client id -> per plan index k, the hop into path[k]: (free-flow s, m) (`costs`)."""
        self.needs: dict[int, Counter[Lock]] = {}
        """Client id -> the resources its plan still needs (ahead of where it stands)."""
        self.users_of: dict[Lock, set[int]] = {}
        """Resource -> the clients whose remaining plan needs it."""
        self._exits: dict[tuple[int, str], list[str]] = {}
        """(routes, node) -> the route from node to the nearest parking access."""
        self.granted: dict[int, int] = {}
        """Client id -> the index in its plan of the furthest node it was granted."""
        self.plan_id: dict[int, int] = {}
        """Client id -> the number of its plan (each declaration a new one)."""
        self._plans_made = 0
        self.witness: list[Move] | None = None
        """None while the claim graph is acyclic; else an order of moves, one node at a time,
        that takes every AGV on the track off it (found by the last walk, `Walk`)."""
        self._next = 0
        """The first move of `witness` not yet made."""
        self._fits = True
        """Fits spare walks (`_fit`) until the first walk that fails: from then on every
        change is walked, as before fits (engine.md, "Fitted witnesses")."""
        self._schedule: Schedule | None = None
        """The witness's moves at positions and every lock's holds, for fitting one AGV's
        changed moves in (`_fit`)."""
        self._refused: dict[int, _Refusal] = {}
        """Client id -> its last grant the walk refused, while it waits for it: asked again, it
        is walked again only once an AGV the walk got stuck on has moved (`may_grant`)."""
        self.refused_grants = 0
        self.walks = 0
        self.walked_moves = 0
        """Walks made (`_walk`), and the moves they made, all told (for benches)."""
        self.fits = 0
        self.refits = 0
        """Walks spared by fitting the client's moves into the witness (`_fit`), and of those,
        the fits that fitted another AGV's moves again too."""
        self.refused_plans = 0

    # ---- plans ----------------------------------------------------------------------------------
    def exit_route(self, routes: Routes, node: str) -> list[str]:
        """Nodes from `node` to the parking access nearest it (by free-flow time)."""
        key = (id(routes), node)
        path = self._exits.get(key)
        if path is None:
            accesses = sorted(p.nodes[0] for p in self.table.layout.parking)
            best = min(accesses, key=lambda a: (routes.travel_time_s(node, a), a))
            path = routes.route(node, best)
            self._exits[key] = path
        return path

    def steps(self, path: Sequence[str]) -> list[Step]:
        """Per index k of `path`: what reaching path[k] takes (`Step`)."""
        table = self.table
        layout = table.layout
        corridor_of = layout.corridor_of
        out: list[Step] = [((table.node_locks[path[0]], 0),)]
        n = len(path)
        for k in range(1, n):
            a, b = path[k - 1], path[k]
            step: list[tuple[Lock, int]] = [(table.node_locks[b], 0)]
            for u, v in ((a, b), (b, path[k + 1] if k + 1 < n else None)):
                if v is None:
                    continue
                corridor = corridor_of(u, v)
                if corridor is not None and u not in corridor.members:
                    lock = table.corridor_locks[corridor.id]
                    if all(lk is not lock for lk, _ in step):
                        step.append((lock, 0))
                if layout.direction_zones_at:
                    along = layout.direction_zone_of(u, v)
                    if along is not None:  # both ways: it turns round at b (alone inside)
                        lock = table.zone_locks[along[0].id]
                        if (lock, along[1]) not in step:
                            step.append((lock, along[1]))
            for zone in layout.mutex_zones_at.get(b, ()):
                step.append((table.zone_locks[zone.id], 0))
            out.append(tuple(step))
        return out

    def costs(self, path: Sequence[str]) -> list[tuple[float, float]]:
        """Per index k of `path`: the free-flow seconds and metres of the hop into path[k]
        ((0, 0) at the start), read once per plan rather than at every step of every walk."""
        edge = self.routes.edge
        return [(0.0, 0.0)] + [(e["free_time_s"], e["length_m"]) for e in
                               (edge[hop] for hop in itertools.pairwise(path))]

    @staticmethod
    def _remaining(steps: Sequence[Step], at: int) -> Counter[Lock]:
        return Counter(lock for step in steps[at + 1:] for lock, _ in step)

    def declare(self, client_id: int, path: Sequence[str]) -> None:
        """Make `path` (from the node the client stands on) its plan, unchecked."""
        self.clear(client_id)
        steps = self.steps(path)
        needs = self._remaining(steps, 0)
        self.path[client_id] = list(path)
        self.at[client_id] = 0
        self._plans_made += 1
        self.plan_id[client_id] = self._plans_made
        self.granted[client_id] = 0
        self._steps[client_id] = steps
        takes: dict[Lock, list[int]] = {}
        for k in range(1, len(steps)):
            for lock, _ in steps[k]:
                takes.setdefault(lock, []).append(k)
        self._takes[client_id] = takes
        self._costs[client_id] = self.costs(path)
        self.needs[client_id] = needs
        for lock in needs:
            self.users_of.setdefault(lock, set()).add(client_id)

    def clear(self, client_id: int) -> None:
        """The client has no plan (off the track)."""
        needs = self.needs.pop(client_id, None)
        if needs is None:
            return
        del self.path[client_id], self.at[client_id], self._steps[client_id]
        del self._costs[client_id], self._takes[client_id]
        self._refused.pop(client_id, None)
        del self.plan_id[client_id], self.granted[client_id]
        for lock in needs:
            self.users_of[lock].discard(client_id)

    def advance(self, client_id: int, node: str) -> None:
        """The client drove onto `node`, the next node of its plan."""
        path = self.path.get(client_id)
        if path is None:
            return
        k = self.at[client_id] + 1
        if k >= len(path) or path[k] != node:
            raise SimulationError(f"AGV {client_id} drove to {node} off its plan "
                                  f"({' '.join(path[k - 1:k + 2])} ...)")
        self.at[client_id] = k
        needs = self.needs[client_id]
        for lock, _ in self._steps[client_id][k]:
            left = needs[lock] - 1
            if left > 0:
                needs[lock] = left
            else:
                del needs[lock]
                self.users_of[lock].discard(client_id)

    def took(self, client_id: int, node: str) -> None:
        """The client was granted `node`, one or two nodes ahead on its plan."""
        path = self.path.get(client_id)
        if path is None:
            return
        k = self.at[client_id]
        for d in (1, 2):
            if k + d < len(path) and path[k + d] == node:
                self.granted[client_id] = max(self.granted[client_id], k + d)
                return

    def step(self, client_id: int, ahead: int) -> str | None:
        """The node `ahead` hops further along the client's plan, if the plan goes that far."""
        path = self.path.get(client_id)
        if path is None:
            return None
        k = self.at[client_id] + ahead
        return path[k] if k < len(path) else None

    # ---- the checks ------------------------------------------------------------------------------
    def may_declare(self, client_id: int, path: Sequence[str]) -> bool:
        """Would the state stay safe with `path` as the client's plan?"""
        steps = self.steps(path)
        if self.witness is None:
            needs = self._remaining(steps, 0)
            holders = {h for lock in needs for h in holders_of(lock) if h != client_id}
            if not holders:
                return True
            if not self._reaches(holders, lambda h: h == client_id, skip=client_id):
                return True
        elif not any(self.table.held_locks(client_id)):
            return True  # off the track: in nobody's way, and in no move of the witness
        plan = (list(path), steps, self.costs(path))
        if self.witness is not None and self._fits and self._fit(client_id, plan, ()):
            return True
        if self._walk(client_id, plan, ()) is None:
            return True
        self.refused_plans += 1
        return False

    def may_grant(self, client_id: int, locks: Sequence[tuple[Lock, int]], node: str,
                  waits: bool = False) -> bool:
        """Would the state stay safe if the client took `locks` ((lock, direction), free, on
        its plan) to drive to `node`? `waits`: the client waits for the grant (not a
        look-ahead): once the walk refused it, it is walked again only from `retry_at` on."""
        users_of = self.users_of
        targets: set[int] = set()
        for lock, _ in locks:
            users = users_of.get(lock)
            if users:
                targets |= users
        targets.discard(client_id)
        if not targets:
            return True
        turns = self._turns_in(client_id, locks)
        if self.witness is None:
            if not self._reaches((client_id,), targets.__contains__):
                return True
        elif turns:
            pass  # walked: the witness's order may not hold (`_turns_in`)
        elif self._is_next(client_id, node):
            self._next += 1
            return True
        elif self._moves_first(client_id, locks, node):
            return True
        if waits and not self._may_walk_again(client_id, node):
            return False  # walked and refused, and nothing the walk stuck on has moved
        if self.witness is not None and not turns and self._fits \
                and self._fit(client_id, None, locks):
            return True
        failed = self._walk(client_id, None, locks)
        if failed is None:
            return True
        if waits:
            k = self.path[client_id].index(node, self.at[client_id])
            self._refused[client_id] = _Refusal(
                self.plan_id[client_id], node, self.table.env.now + self._costs[client_id][k][0],
                self._where(failed.stuck(client_id)))
        self.refused_grants += 1
        return False

    def _turns_in(self, client_id: int, locks: Sequence[tuple[Lock, int]]) -> bool:
        """Does another AGV hold a same-direction aisle of `locks` with a hop granted and not
        driven yet? A replay drives granted hops first (`proof`), but one that turns round in
        the aisle may do so only alone in it, which the client in it would prevent: granted
        from the witness (next, moved first or fitted), the state may not be shown safe (the
        greedy walk decides)."""
        granted, at = self.granted, self.at
        for lock, _ in locks:
            if isinstance(lock, DirectionGate):
                for y in holders_of(lock):
                    if y != client_id and granted.get(y, -1) > at.get(y, -1):
                        return True
        return False

    def _may_walk_again(self, client_id: int, node: str) -> bool:
        """False while the client's last refused grant, for `node` under the same plan, would
        stick where it stuck: no AGV of that cycle has moved (with no cycle: before
        `until_s`)."""
        refused = self._refused.get(client_id)
        if refused is None or refused.plan != self.plan_id[client_id] or refused.node != node:
            return True
        if not refused.stuck:
            return self.table.env.now + 1e-9 >= refused.until_s
        return refused.stuck != self._where(y for y, *_ in refused.stuck)

    def retry_at(self, client_id: int) -> float | None:
        """When a grant the walk refused the client may be walked again, if it is waiting for
        that (`may_grant`)."""
        refused = self._refused.get(client_id)
        if refused is None or refused.plan != self.plan_id.get(client_id) or refused.stuck:
            return None
        return refused.until_s

    def _where(self, clients: Iterable[int]) -> tuple[tuple[int, int, int, int], ...]:
        """Where each client is: (id, plan number, index in the plan of the node it stands on
        and of the furthest node granted; -1 off the track)."""
        plan_id, at, granted = self.plan_id, self.at, self.granted
        return tuple((y, plan_id.get(y, -1), at.get(y, -1), granted.get(y, -1))
                     for y in clients)

    def _is_next(self, client_id: int, node: str) -> bool:
        """Is driving to `node` the client's move that comes next in the witness?"""
        witness = self.witness
        assert witness is not None
        if self._skip_made() == len(witness):
            return False
        x, _, k = witness[self._next]
        path = self.path[x]
        if k == len(path):  # driving off at the end of its plan: no grant, wait for it
            return False
        return x == client_id and path[k] == node

    def _skip_made(self) -> int:
        """Move `_next` past the witness's moves made or granted already, or of a plan given
        up (its AGV left the track or took another); the index of the first move not made."""
        witness = self.witness
        assert witness is not None
        plan_id, at, granted = self.plan_id, self.at, self.granted
        n = len(witness)
        while self._next < n:
            x, plan, k = witness[self._next]
            if plan_id.get(x) != plan or at[x] >= k or granted[x] >= k:
                self._next += 1
                continue
            break
        return self._next

    def _moves_first(self, client_id: int, locks: Sequence[tuple[Lock, int]],
                     node: str) -> bool:
        """May the client's move to `node`, further on in the witness, be made now? Yes if it
        is the client's first move not made and no move before it in the witness, not made,
        takes any of `locks`: made first, it holds nothing those moves need (what it lets go
        of sooner only helps them), and the rest of the witness holds unchanged. The move is
        put first and counted as made. Only the AGVs whose plans still take one of `locks`
        are looked at (`users_of`), each at its first move not made that takes it: its
        position in the witness against the client's (`Schedule.position`)."""
        witness, schedule = self.witness, self._schedule
        assert witness is not None and schedule is not None
        at, granted, plan_id = self.at, self.granted, self.plan_id
        k = max(at[client_id], granted[client_id]) + 1
        path = self.path[client_id]
        if k >= len(path) or path[k] != node:
            return False
        mine = schedule.position(client_id, k, plan_id[client_id])
        start = self._next
        j = schedule.index_of(mine, start) if mine is not None else None
        if mine is None or j is None:
            return False  # not in the witness from its first move not made on
        for lock, _ in locks:
            for y in self.users_of.get(lock, ()):
                if y == client_id:
                    continue
                takes = self._takes[y][lock]
                for kk in takes[bisect.bisect_right(takes, max(at[y], granted[y])):]:
                    theirs = schedule.position(y, kk, plan_id[y])
                    if theirs is None:
                        continue
                    if theirs >= mine:
                        break  # its later moves come later still
                    if schedule.index_of(theirs, start) is not None:
                        return False  # a move not made before it takes what it takes
        witness.insert(start, witness.pop(j))
        schedule.moved_first(j, start)
        self._next += 1
        return True

    def _fit(self, client_id: int,
             new_plan: tuple[list[str], list[Step], list[tuple[float, float]]] | None,
             granted: Sequence[tuple[Lock, int]]) -> bool:
        """Fit the client's moves, under its new plan or with the locks it is granted, into
        the witness among the others' (`Schedule.fit`); where they stick on an AGV's hold of
        what the client holds now, that AGV's moves are fitted again after the client's (up
        to `REFITS` AGVs). True: the witness is the fitted one and the state is safe with the
        change. False: none found (a walk may still find one)."""
        schedule = self._schedule
        if schedule is None:
            return False
        if new_plan is not None:
            plan = self._plans_made + 1
            chains = [(client_id, plan, self._alone(client_id, plan, new_plan, 0, ()))]
        else:
            plan = self.plan_id[client_id]
            chains = [(client_id, plan, self._alone(client_id, plan, self._route(client_id),
                                                    self.at[client_id], granted))]
        start = self._skip_made()
        plan_id = self.plan_id

        def plan_now(y: int) -> int | None:  # the client's: the plan it is about to declare
            return plan if y == client_id else plan_id.get(y)

        for _ in range(REFITS + 1):
            if any(not walk.moves for _, _, walk in chains):
                return False  # stuck alone (cannot happen on a plan that is whole)
            stuck = schedule.fit(chains, start, plan_now)
            if stuck is None:
                self.fits += 1
                self.refits += len(chains) > 1
                return True
            if stuck < 0 or stuck not in self.path or any(y == stuck for y, _, _ in chains):
                return False
            y = stuck
            chains.append((y, self.plan_id[y], self._alone(y, self.plan_id[y], self._route(y),
                                                           self.at[y], ())))
        return False

    def _route(self, x: int) -> tuple[list[str], list[Step], list[tuple[float, float]]]:
        """x's plan: its nodes, what reaching each takes, the hop into each (s, m)."""
        return self.path[x], self._steps[x], self._costs[x]

    def _alone(self, x: int, plan: int,
               route: tuple[list[str], list[Step], list[tuple[float, float]]], k: int,
               granted: Sequence[tuple[Lock, int]]) -> Walk:
        """x driven alone from index k of its plan `route` to parking, its holds recorded
        (no moves: it got stuck, which a plan driven alone does not)."""
        walk = Walk(self.table, alone=True)
        path, steps, costs = route
        walk.add(x, plan, path, steps, costs, k, granted)
        walk.holds = {}
        if not walk.run():
            walk.moves = []
        return walk

    def _walk(self, client_id: int,
              new_plan: tuple[list[str], list[Step], list[tuple[float, float]]] | None,
              granted: Sequence[tuple[Lock, int]]) -> Walk | None:
        """Drive every AGV on the track forward along its plan, one node at a time, with the
        client's new plan or the locks it is granted: if all get off the track, the order
        of moves becomes the witness and None is returned; else the walk where it got stuck
        (`Walk.stuck` names the cycle of waits)."""
        walk = Walk(self.table)
        held_locks = self.table.held_locks
        for x in sorted(self.path):
            if x == client_id:
                path, steps, costs = new_plan if new_plan is not None \
                    else self._route(x)
                walk.add(x, self.plan_id[x] if new_plan is None else self._plans_made + 1,
                         path, steps, costs, 0 if new_plan is not None else self.at[x], granted)
            elif any(held_locks(x)):
                walk.add(x, self.plan_id[x], *self._route(x), self.at[x], ())
        if self._fits:
            walk.holds = {}
        ok = walk.run()
        self.walks += 1
        self.walked_moves += len(walk.moves)
        if not ok:
            self._fits = False
            return walk
        self.witness = walk.moves
        self._schedule = Schedule(walk.moves, walk)
        self._next = 0
        return None

    def proof(self) -> str | None:
        """Why the state is safe, checked from scratch (for tests and bug hunts): "acyclic"
        (the claim graph has no cycle), "witness" (the witness's moves, those granted but not
        driven yet first, take every AGV on the track off it), or None: not shown safe."""
        table = self.table
        if self.witness is None:
            graph: nx.DiGraph = nx.DiGraph()
            for x, needs in self.needs.items():
                graph.add_edges_from((x, y) for lock in needs for y in holders_of(lock) if y != x)
            return "acyclic" if nx.is_directed_acyclic_graph(graph) else None
        walk = Walk(table)
        junctions, walk.junctions = walk.junctions, frozenset()  # replayed moves are made as
        for x in sorted(self.path):  # they come, into a junction too
            if any(table.held_locks(x)):
                walk.add(x, self.plan_id[x], *self._route(x), self.at[x], ())
        for x in sorted(walk.plans):  # the nodes granted and not driven yet: held, so driving
            while x in walk.plans and walk.at[x] < self.granted[x] and walk.step(x):
                pass  # to them takes nothing new and only lets go of what is left behind
        for x, plan, k in self.witness:
            if self.plan_id.get(x) != plan or x not in walk.plans or walk.at[x] >= k:
                continue
            if walk.at[x] != k - 1:
                return None
            walk.step(x)
            if x in walk.plans and walk.at[x] != k:
                return None  # its move is blocked
        walk.junctions = junctions
        walk.queue = sorted((walk.time_s[x], x) for x in walk.plans)  # came on since, granted
        walk.waiting = {}  # only what nobody else's plan needs: after the witness, alone
        return "witness" if walk.run() else None

    def _reaches(self, start: Iterable[int], hit: Callable[[int], bool],
                 skip: int | None = None) -> bool:
        """True if a walk along the claim graph from `start` comes to a client for which `hit`
        is true (not counting the start itself); `skip`: a client whose edges are not walked."""
        needs = self.needs
        stack = list(start)
        seen = set(stack)
        while stack:
            x = stack.pop()
            if x == skip:
                continue
            for lock in needs.get(x, ()):
                for h in holders_of(lock):
                    if h == x:
                        continue
                    if hit(h):
                        return True
                    if h not in seen:
                        seen.add(h)
                        stack.append(h)
        return False


@dataclass(frozen=True, slots=True)
class _Refusal:
    """A grant the walk refused a client that waits for it (`Plans.may_grant`)."""

    plan: int
    node: str
    until_s: float
    """With no cycle found: walked again from then on (the hop's free-flow seconds later)."""
    stuck: tuple[tuple[int, int, int, int], ...]
    """Where the AGVs of the cycle of waits the walk got stuck on stood (`Plans._where`):
    walked again once one of them has moved."""
