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
  whose plans need something in R. The graph was acyclic; the grant closes a cycle exactly when
  a reaches such a t (`may_grant`: a depth-first walk from a, skipped when nobody else's plan
  needs R).
* **A new plan** for a adds edges from a to the holders of what it needs; it closes a cycle
  exactly when one of them reaches a (`may_declare`). A refused plan leaves the old one in
  force: the AGV drives on along it (to parking, at worst) and asks again at every node.
* Advancing along a plan, letting go of a lock and driving off into parking only remove edges.

Why this never locks solid: an acyclic graph has a sink, an AGV none of whose remaining
resources another AGV holds; its next hop is free and granting it adds edges into the sink
only, so it is granted. A wait-for cycle needs every member to wait for a resource another
member holds, which is an edge of the claim graph for each: never while it is acyclic.

Decisions (the issue and RSS-AGV-001 are silent):

* The exit is the parking access nearest the goal by free-flow time, whatever its room: the
  check assumes an AGV can drive off there (true up to the parking capacity with one area;
  with several, an AGV told a nearer area is full declares its way to another, checked).
* A zone that holds several AGVs counts as needing every holder gone (an edge to each): that
  can only refuse more, never grant an unsafe state.
* AGVs placed on the track at the start (`fleet.start_nodes`) get their exit plans unchecked.
* An AGV that stands still for a while (handling, charging, an obstacle, a fault being
  repaired) still finishes its plan in the argument: it will move on, and until it does the
  AGVs behind it wait, which is a queue, not a deadlock.
* The cost: an AGV that must go round a loop to reach parking needs the nodes of the AGVs
  behind it, so two AGVs following each other round a loop may not both hold their places;
  the one behind waits until the one ahead is clear of its plan (docs/background/engine.md
  gives the figures). Driving the plans forward node by node instead of whole ("can the AGVs
  get off the track one step at a time?") refuses far less, but a check that only finds one
  such order is not closed under the moves it allows: on the warehouse at 40 AGVs every
  request came to be refused (tried 2026-11-27; see engine.md).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

from fleet_sim.errors import SimulationError
from fleet_sim.sim.traffic.locks import Claim, Lock

if TYPE_CHECKING:
    from fleet_sim.sim.traffic.control import Traffic
    from fleet_sim.sim.traffic.routing import Routes

POLICIES = ("reactive", "avoiding")

Step = tuple[tuple[Lock, int], ...]
"""What reaching one node of a plan takes: (lock, direction) pairs: the node, the corridor and
zones of the hop into it, and the corridor or aisle entered from it (taken at its mouth, as
fleet_sim.sim.traffic.allocation does); the direction is a same-direction zone's, else 0."""


class Plans:
    """Every AGV's declared plan, the resources each still needs, and the safety checks."""

    def __init__(self, traffic: Traffic) -> None:
        self.traffic = traffic
        self.path: dict[int, list[str]] = {}
        """Client id -> its plan: nodes from where it stood when it declared it to a parking
        access."""
        self.at: dict[int, int] = {}
        """Client id -> the index in its plan of the node it stands on."""
        self._steps: dict[int, list[Step]] = {}
        """Client id -> per plan index k, what reaching path[k] takes."""
        self.needs: dict[int, Counter[Lock]] = {}
        """Client id -> the resources its plan still needs (ahead of where it stands)."""
        self.users_of: dict[Lock, set[int]] = {}
        """Resource -> the clients whose remaining plan needs it."""
        self._exits: dict[tuple[int, str], list[str]] = {}
        """(routes, node) -> the route from node to the nearest parking access."""
        self.checks = 0
        """Claim-graph walks (grants and plans that someone else's plan could conflict
        with)."""
        self.walks = 0
        """Plans driven forward (stage 2), and the AGVs moved in them."""
        self.walked_agvs = 0
        self.refused_grants = 0
        self.refused_plans = 0

    # ---- plans ----------------------------------------------------------------------------------
    def exit_route(self, routes: Routes, node: str) -> list[str]:
        """Nodes from `node` to the parking access nearest it (by free-flow time)."""
        key = (id(routes), node)
        path = self._exits.get(key)
        if path is None:
            accesses = sorted(p.nodes[0] for p in self.traffic.layout.parking)
            best = min(accesses, key=lambda a: (routes.travel_time_s(node, a), a))
            path = routes.route(node, best)
            self._exits[key] = path
        return path

    def steps(self, path: Sequence[str]) -> list[Step]:
        """Per index k of `path`: what reaching path[k] takes (`Step`)."""
        traffic = self.traffic
        layout = traffic.layout
        corridor_of = layout.corridor_of
        out: list[Step] = [((traffic.node_locks[path[0]], 0),)]
        n = len(path)
        for k in range(1, n):
            a, b = path[k - 1], path[k]
            step: list[tuple[Lock, int]] = [(traffic.node_locks[b], 0)]
            for u, v in ((a, b), (b, path[k + 1] if k + 1 < n else None)):
                if v is None:
                    continue
                corridor = corridor_of(u, v)
                if corridor is not None and u not in corridor.members:
                    lock = traffic.corridor_locks[corridor.id]
                    if all(lk is not lock for lk, _ in step):
                        step.append((lock, 0))
                if layout.direction_zones_at:
                    along = layout.direction_zone_of(u, v)
                    if along is not None:
                        lock = traffic.zone_locks[along[0].id]
                        if all(lk is not lock for lk, _ in step):
                            step.append((lock, along[1]))
            for zone in layout.mutex_zones_at.get(b, ()):
                step.append((traffic.zone_locks[zone.id], 0))
            out.append(tuple(step))
        return out

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
        self._steps[client_id] = steps
        self.needs[client_id] = needs
        for lock in needs:
            self.users_of.setdefault(lock, set()).add(client_id)

    def clear(self, client_id: int) -> None:
        """The client has no plan (off the track)."""
        needs = self.needs.pop(client_id, None)
        if needs is None:
            return
        del self.path[client_id], self.at[client_id], self._steps[client_id]
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
        needs = self._remaining(steps, 0)
        holders = {h for lock in needs for h in _holders(lock) if h != client_id}
        if not holders:
            return True
        self.checks += 1
        if self._reaches(holders, lambda h: h == client_id, skip=client_id):
            self.refused_plans += 1
            return False
        return True

    def may_grant(self, client_id: int, locks: Sequence[tuple[Lock, int]]) -> bool:
        """Would the state stay safe if the client took `locks` ((lock, direction), free, on
        its plan)?"""
        users_of = self.users_of
        targets: set[int] = set()
        for lock, _ in locks:
            users = users_of.get(lock)
            if users:
                targets |= users
        targets.discard(client_id)
        if not targets:
            return True
        self.checks += 1
        if self._reaches((client_id,), targets.__contains__):
            self.refused_grants += 1
            return False
        return True

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
                for h in _holders(lock):
                    if h == x:
                        continue
                    if hit(h):
                        return True
                    if h not in seen:
                        seen.add(h)
                        stack.append(h)
        return False


def _holders(lock: Lock) -> Iterable[int]:
    for claim in lock.users:
        yield claim.client_id if isinstance(claim, Claim) else -1
