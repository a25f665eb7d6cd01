"""Deadlocks: wait-for cycles, the ways out of one, and the strategy that picks the victim.

A wait-for cycle is AGV a waiting for a lock b holds, b for one c holds, ..., back to a. Each
member's possible escape lets go of the lock the member before it waits for (`Escape`); the
`VictimChoice` handed to `Traffic` picks which member moves. The victim, when it is not the AGV
that found the cycle, is interrupted with a `DeadlockVictim` cause carrying its escape (like
SimPy's `Preempted`: an object with fields, not a string).

The choices where the issues were silent: docs/background/decisions/sim.md.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

from fleet_sim.sim.traffic.locks import Lock

EscapeKind = Literal["yield", "reroute", "circulate", "backoff"]


@dataclass(frozen=True)
class Escape:
    """How a blocked AGV gets out: another route, or a step back to a free node."""

    kind: EscapeKind
    path: tuple[str, ...]
    """Nodes from the AGV's node onwards (reroute, circulate: to its goal; backoff: one hop;
    yield: none, the AGV gives up a corridor it reserved and tries again a little later)."""

    def brief(self) -> str:
        """The first nodes of the path, for the event's detail."""
        return " ".join(self.path[:4]) + (" ..." if len(self.path) > 4 else "")


@dataclass(frozen=True)
class DeadlockVictim:
    """Interrupt cause: the AGV was chosen to break a wait-for cycle and should take `escape`."""

    escape: Escape


def find_cycle(start: int, waiting: Mapping[int, Lock]) -> list[int] | None:
    """The wait-for cycle through client `start`, as client ids in wait order, if there is one.
    `waiting` maps each waiting client to the lock it waits for; a client waits for the
    lock's `blockers` (its holder; a same-direction zone may name several, each of which
    must let go). Depth first, so with one blocker per lock this walks the one chain."""
    lock = waiting.get(start)
    if lock is None:
        return None
    chain = [start]
    seen = {start}
    client = start
    # The common case first: while each lock names its holder alone (`Lock.blockers`), the
    # search below walks one chain; walk it directly.
    while type(lock).blockers is Lock.blockers:
        users = lock.users
        if not users:
            return None
        holder: int = users[0].client_id  # type: ignore[attr-defined]  # a Claim
        if holder == client:
            return None
        if holder == start:
            return chain
        if holder in seen:
            return None
        seen.add(holder)
        lock = waiting.get(holder)
        if lock is None:
            return None
        chain.append(holder)
        client = holder
    # A lock that may name several (a same-direction zone): depth first from here, the
    # locks walked above having no other blockers left.
    stack: list[Iterator[int]] = [iter(()) for _ in chain[:-1]]
    stack.append(iter(lock.blockers(client)))
    while stack:
        blocker = next(stack[-1], None)
        if blocker is None:
            stack.pop()
            chain.pop()
            continue
        if blocker == start:
            return chain
        if blocker in seen:
            continue  # on the chain (a cycle not through start: its members handle it) or done
        seen.add(blocker)
        lock = waiting.get(blocker)
        if lock is None:
            continue
        chain.append(blocker)
        stack.append(iter(lock.blockers(blocker)))
    return None


class KnownCycles:
    """The cycles already counted, forgotten once they no longer stand."""

    def __init__(self) -> None:
        self._cycles: set[frozenset[int]] = set()

    def is_new(self, cycle: Sequence[int], waiting: Mapping[int, Lock]) -> bool:
        """True the first time a cycle with these members is seen while it persists."""
        key = frozenset(cycle)
        self._cycles = {c for c in self._cycles if _still_cycle(c, waiting)}
        if key in self._cycles:
            return False
        self._cycles.add(key)
        return True


def _still_cycle(members: frozenset[int], waiting: Mapping[int, Lock]) -> bool:
    cycle = find_cycle(min(members), waiting)
    return cycle is not None and frozenset(cycle) == members


class VictimChoice(Protocol):
    """Picks the member of a wait-for cycle that moves, and its escape."""

    def choose(self, options: Sequence[tuple[int, Escape | None]]) -> tuple[int, Escape] | None:
        """`options`: (client id, its escape or None) for each member, in wait order starting
        with the client that found the cycle. None: nobody can move yet."""
        ...


class GentlestEscapeFirst:
    """The default choice: the gentlest kind of escape any member has; the first such member."""

    ORDER: tuple[EscapeKind, ...] = ("yield", "reroute", "circulate", "backoff")

    def choose(self, options: Sequence[tuple[int, Escape | None]]) -> tuple[int, Escape] | None:
        for kind in self.ORDER:
            for client_id, escape in options:
                if escape is not None and escape.kind == kind:
                    return client_id, escape
        return None


NOBODY = -1
"""No AGV (ids count from 0)."""


def chain_heads(agvs: Sequence[int], waiting: Mapping[int, Lock]) -> set[int] | None:
    """The AGVs at the front of the chains of lock waits from `agvs`: those they wait for, and
    those these wait for, ..., up to AGVs that wait for no lock. None if a chain runs round a
    cycle or reaches a lock that names nobody."""
    def ahead(agv: int) -> tuple[int, ...] | None:  # None: it waits for no lock
        lock = waiting.get(agv)
        return None if lock is None else lock.blockers(agv)

    heads: set[int] = set()
    done: set[int] = set()
    for start in agvs:
        on_path: set[int] = set()
        stack: list[tuple[int, Iterator[int]]] = [(NOBODY, iter((start,)))]
        while stack:
            agv, rest = stack[-1]
            nxt = next(rest, NOBODY)
            if nxt == NOBODY:  # all it waits for looked at
                stack.pop()
                on_path.discard(agv)
                done.add(agv)
                continue
            if nxt in on_path:
                return None
            if nxt in done:
                continue
            more = ahead(nxt)
            if more is None:
                heads.add(nxt)
                done.add(nxt)
            elif not more:
                return None
            else:
                on_path.add(nxt)
                stack.append((nxt, iter(more)))
    return heads
