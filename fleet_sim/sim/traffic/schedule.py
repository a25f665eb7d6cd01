"""The witness as a schedule (fleet_sim.sim.traffic.avoidance): each move of the witness at a
position on one line, and what each lock's holders hold it over, so that one AGV's changed
moves (a new plan, or a grant out of the witness's order) are fitted in between the others'
without walking every AGV again.

The witness is a list of moves that, made in order, takes every AGV on the track off it
(`Walk`). The walk that found it also logged, for every lock, when each member took it and
let go of it: a *hold* (taken at, let go at, member, plan), in positions of moves. An AGV's
moves depend on no other AGV (what a move takes and lets go of follows from its own plan and
body), so the others' holds stay what they are whatever is done with one AGV's moves.

`fit` drives the one AGV alone (a `Walk` of it by itself) for its moves and holds, and looks
for a place for each of its moves between the others' moves, in order, so that no hold of
it overlaps another AGV's hold of an exclusive lock (nor more than a zone's capacity of
them): each move as early as it may go; where a hold of it meets another AGV's, the move that
took the lock goes after the other lets go of it (the only way round, as the moves after it
cannot go earlier), and the moves after it follow. A hold it has already (what it holds now)
cannot move: a clash there fails, naming the AGV it clashed with, which the caller may fit
again after it (`Plans._fit`; several chains of moves are fitted in turn, and undone together
if one fails). A fitted schedule is a witness by construction: the others' moves in their
order, each taking what is free when it comes, and the AGV's among them. When no place is
found, the caller walks every AGV as before; a fit only spares a walk, it never refuses
anything. A same-direction aisle is fitted as an exclusive lock (its turning rules need no
more), a zone of several AGVs not at all (walked).

Positions are floats: the walk numbers its moves 0, 1, 2, ...; a fitted move goes between two
neighbours. What happened since the walk is read off the state as it is: an AGV that holds a
lock now holds it from the start (its first hold of it that is not over), one that holds it
and has no hold of it in the schedule holds it for ever; holds of AGVs with another plan
since are dropped. The positions of each AGV's moves (`position`) also serve the moves-first
rule (`Plans._moves_first`), which compares moves by position instead of scanning the
witness: the schedule is kept after every walk, its holds only while fits are on.
"""

from __future__ import annotations

import bisect
import itertools
from collections.abc import Callable, Sequence

from fleet_sim.sim.traffic.locks import Lock
from fleet_sim.sim.traffic.walk import INF, Hold, Move, Walk, holders_of
from fleet_sim.sim.traffic.zones import DirectionGate

MAX_BUMPS = 400
"""A fit that has moved a move later this many times gives up (the caller walks)."""


class Schedule:
    """The witness's moves, each at a position, and every lock's holds (`fit`)."""

    def __init__(self, moves: list[Move], walk: Walk) -> None:
        """`walk`: the walk that found the witness `moves`, its holds recorded (`Walk.holds`;
        without them nothing can be fitted, and the schedule only places the moves)."""
        self.moves = moves
        """The witness (the same list as `Plans.witness`)."""
        self.pos: list[float] = list(map(float, range(len(moves))))
        """The position of each move of `moves`; ascending from the first move not made."""
        self.holds: dict[Lock, list[Hold]] = walk.holds if walk.holds is not None else {}
        """Lock -> its holds (`Hold`: the last field names the holder's moves, `current`)."""
        self.current: dict[int, tuple[int, int]] = {x: (p, p) for x, p in walk.plan_of.items()}
        """Client -> the number its holds in the schedule carry, and its plan's number: holds
        with another, or of a client whose plan is another now, are dropped."""
        self._fitted = 0
        self.positions: dict[int, tuple[int, list[float]]] = {}
        """Client -> the index in its plan of its first move in the witness, and the positions
        of its moves there, one for each index of its plan from that on."""
        positions = self.positions
        for i, (x, _, k) in enumerate(moves):
            mine = positions.get(x)
            if mine is None:
                positions[x] = (k, [float(i)])
            else:
                mine[1].append(float(i))

    def position(self, x: int, k: int, plan: int) -> float | None:
        """The position of x's move onto index k of its plan, if the witness has that move of
        plan number `plan` (None: not so)."""
        now = self.current.get(x)
        mine = self.positions.get(x)
        if now is None or now[1] != plan or mine is None:
            return None
        i = k - mine[0]
        return mine[1][i] if 0 <= i < len(mine[1]) else None

    def index_of(self, at: float, start: int) -> int | None:
        """The index in the witness of the move at position `at`, if it is among the moves
        from index `start` on (None: it is not, made out of order (`moved_first`) or gone)."""
        pos = self.pos
        j = bisect.bisect_left(pos, at, start)
        return j if j < len(pos) and pos[j] == at else None

    def moved_first(self, j: int, to: int) -> None:
        """The move at index `j` of the witness was put at index `to` (`Plans._moves_first`):
        its position goes with it (its holds stay: what it took, its AGV holds now; what it
        let go of, the schedule lets go of later, which only makes a fit stricter)."""
        self.pos.insert(to, self.pos.pop(j))

    def fit(self, chains: Sequence[tuple[int, int, Walk]], start: int,
            plan_now: Callable[[int], int | None]) -> int | None:
        """Fit each chain's moves in turn, (x, its plan's number, a walk of x alone, its
        holds recorded, run to parking), in place of x's moves in the witness, among the
        moves from index `start` on (the first not made); while a chain is fitted, each AGV
        of the chains after it holds what it holds now until its moves in the schedule let
        go of it, and takes nothing (its own fit, later, shows that its new moves let go of
        it before the chain's moves take it, or fails). `plan_now(y)`: y's plan
        number now (None: none). None: fitted, the witness and the holds are the fitted ones;
        else nothing changed and the AGV (-1: none) on whose hold a chain stuck with what it
        holds now (to be fitted again too, `Plans._fit`)."""
        witness, pos = list(self.moves), list(self.pos)
        current, positions = dict(self.current), dict(self.positions)
        added: list[tuple[Lock, int]] = []
        for i, (x, plan, walk) in enumerate(chains):
            pending = {y for y, _, _ in chains[i + 1:]}
            stuck = self._fit_one(x, plan, walk, start, plan_now, pending, added, current)
            if stuck is not None:  # undone
                self.moves[:], self.pos[:] = witness, pos
                self.current, self.positions = current, positions
                tags = {tag for _, tag in added}
                for lock in {lock for lock, _ in added}:
                    self.holds[lock] = [h for h in self.holds[lock] if h[3] not in tags]
                return stuck
        holds, current = self.holds, self.current
        for lock in {lock for lock, _ in added}:  # the fitted AGVs' old holds out
            holds[lock] = [h for h in holds[lock] if current[h[2]][0] == h[3]]
        return None

    def _fit_one(self, x: int, plan: int, walk: Walk, start: int,
                 plan_now: Callable[[int], int | None], pending: set[int],
                 added: list[tuple[Lock, int]], committed: dict[int, tuple[int, int]]
                 ) -> int | None:
        """Fit one chain (`fit`); None: done, else the AGV it stuck on (-1: none)."""
        pos = self.pos
        n = len(walk.moves)
        assert walk.holds is not None
        # x's holds, by the index of the move that took (-1: held now) and let go of each,
        # ascending by the latter
        mine = sorted(((lock, int(t) if t >= 0 else -1, int(r))
                       for lock, holds in walk.holds.items() for t, r, _, _ in holds),
                      key=lambda h: h[2])
        let_go_at = [b for _, _, b in mine]
        start_at = pos[start] if start < len(pos) else INF
        others: dict[Lock, list[tuple[float, float, int]]] = {}
        for lock, _, _ in mine:
            if lock not in others:
                others[lock] = self._others(lock, x, start, start_at, plan_now, pending,
                                            committed)
        # place[i]: x's move i goes just before the move at this index of the witness
        # (len: after them all), at least at `floor[i]`
        end = len(pos)
        floor = [start] * n
        place = [start] * n
        bumps = 0
        i0 = 0
        while True:
            for i in range(i0, n):
                place[i] = max(floor[i], place[i - 1] if i else start)
            clash = self._clash(mine, bisect.bisect_left(let_go_at, i0), place, others)
            if clash is None:
                break
            a, r, y = clash
            bumps += 1
            if a < 0 or r == INF or bumps > MAX_BUMPS:
                return y if a < 0 else -1
            floor[a] = bisect.bisect_right(pos, r, start, end)
            i0 = a
        return None if self._put(x, plan, walk, place, mine, start, added) else -1

    def _others(self, lock: Lock, x: int, start: int, start_at: float,
                plan_now: Callable[[int], int | None], pending: set[int],
                committed: dict[int, tuple[int, int]]) -> list[tuple[float, float, int]]:
        """The holds of `lock` by other AGVs that are not over, as (taken, let go, holder)
        positions; what an AGV holds now from the start. Holds of moves given up (under
        `committed` and now) and holds over of AGVs that hold the lock no more are dropped
        for good."""
        current = self.current
        out: list[tuple[float, float, int]] = []
        first: dict[int, int] = {}
        known: set[int] = set()
        waiting: dict[int, tuple[float, float, int]] = {}
        holders = set(holders_of(lock))
        holds = self.holds.get(lock, [])
        live: list[Hold] = []
        for hold in holds:
            t, r, y, g = hold
            now = current[y]
            if now[0] != g:
                was = committed.get(y)
                if was is None or was[0] != g:
                    continue  # moves given up: dropped
                live.append(hold)
                continue
            if r < start_at and y not in holders:
                continue  # over: dropped
            live.append(hold)
            if y == x or plan_now(y) != now[1] or (y in pending and y not in holders):
                continue  # its own, of a plan given up, or to be fitted again after x
            known.add(y)
            if r < start_at:
                continue  # let go of by a move made or granted
            if self.index_of(r, start) is None:
                continue  # let go of by a move made out of order (`moved_first`)
            if y in pending:  # fitted after x: only what it holds now, as the schedule has it
                if y not in waiting or t < waiting[y][0]:
                    waiting[y] = (t, r, y)
                continue
            j = first.get(y)
            if j is None or t < out[j][0]:
                first[y] = len(out)
            out.append((t, r, y))
        if len(live) < len(holds):
            self.holds[lock] = live
        for y, held in waiting.items():
            first[y] = len(out)
            out.append(held)
        for y in holders:
            if y == x:
                continue
            j = first.get(y)
            if j is not None:
                out[j] = (-INF, out[j][1], y)  # held now: from the start
            elif y not in known:
                out.append((-INF, INF, y))  # held, and not let go of in the schedule
            elif isinstance(lock, DirectionGate):  # let go of by a hop granted, driven
                out.append((-INF, -INF, y))  # first: x may not be in it already
                # (`Plans._turns_in`)
        return out

    def _clash(self, mine: list[tuple[Lock, int, int]], first: int, place: list[int],
               others: dict[Lock, list[tuple[float, float, int]]]
               ) -> tuple[int, float, int] | None:
        """The first hold of x, from index `first` of `mine` on, that meets others' holds of
        its lock beyond what the lock admits: (the index of the move that took it, -1: held
        now; the position from which the lock is free of the hold it meets; its holder), or
        None."""
        pos = self.pos
        end = len(pos)
        for lock, a, b in itertools.islice(mine, first, None):
            held = others[lock]
            if not held:
                continue
            qa, qb = (place[a] if a >= 0 else -1), place[b]
            took = pos[qa] if 0 <= qa < end else (-INF if qa < 0 else INF)
            let_go = pos[qb] if qb < end else INF
            meets = [hold for hold in held if not (let_go <= hold[0] or took > hold[1])]
            if not meets:
                continue
            capacity = 1 if isinstance(lock, DirectionGate) else lock.capacity
            if len(meets) < capacity:
                continue
            if capacity > 1:
                return -1, INF, -1  # a zone of several: not fitted (walked)
            return a, meets[0][1], meets[0][2]
        return None

    def _put(self, x: int, plan: int, walk: Walk, place: list[int],
             mine: list[tuple[Lock, int, int]], start: int,
             added: list[tuple[Lock, int]]) -> bool:
        """Make the fitted schedule the witness: x's moves at their places among the others'
        from `start` on (its old moves out), and x's holds those of its fitted moves."""
        pos, witness = self.pos, self.moves
        moves = walk.moves
        end = len(pos)
        at: list[float] = []
        i = 0
        n = len(moves)
        while i < n:
            q = place[i]
            j = i
            while j < n and place[j] == q:
                j += 1
            after = pos[q] if q < end else (pos[-1] + 2.0 if end else 2.0)
            before = pos[q - 1] if q > start else after - 1.0
            gap = (after - before) / (j - i + 1)
            if gap < 1e-6:
                return False  # too close to tell apart: walked (and numbered afresh)
            at += [before + gap * (m + 1) for m in range(j - i)]
            i = j
        old = []
        for p in self.positions.get(x, (0, []))[1]:
            found = self.index_of(p, start)
            if found is not None and witness[found][0] == x:
                old.append(found)
        for j in sorted(old, reverse=True):
            del witness[j], pos[j]
        for move, p in zip(moves, at, strict=True):
            j = bisect.bisect_left(pos, p, start)
            witness.insert(j, (x, plan, move[2]))
            pos.insert(j, p)
        self.positions[x] = (moves[0][2], at)
        self._fitted -= 1
        tag = self._fitted  # fitted moves' number: below every plan's (from 1 up)
        self.current[x] = (tag, plan)
        holds = self.holds
        for lock, a, b in mine:
            hold = (at[a] if a >= 0 else -INF, at[b], x, tag)
            of_lock = holds.get(lock)
            if of_lock is None:
                holds[lock] = [hold]
            else:
                of_lock.append(hold)
            added.append((lock, tag))
        return True
