"""AGV time Idle while orders waited (idle_with_orders_waiting_pct and the part under each
not_dispatched reason), matched spell by spell as a run's events and queue lengths stream in;
one of the running sums of fleet_sim.analysis.kpi_sums."""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from collections.abc import Sequence

from fleet_sim.model.not_dispatched import NOT_DISPATCHED, NOT_DISPATCHED_END, NotDispatched
from fleet_sim.model.records import EventRecord, QueueLength
from fleet_sim.model.states import VehicleState

IDLE = VehicleState.IDLE.value

Spell = list[float]
"""[start_s, end_s] of a spell."""


class IdleWhileWaiting:
    """AGV-seconds in state Idle while at least one order waited unassigned, and the part of
    them under each not_dispatched reason, from the events and the queue lengths as they come.

    Per AGV, its Idle spells are matched with the spells in which orders waited (the queue
    above zero, clipped to the window, touching spells joined) and each piece in common with
    the AGV's reason spells (not_dispatched opens or changes a reason, not_dispatched_end
    closes it). The two kinds of records come as independent streams, so a piece is counted
    only once both have gone past its end; what is not matched yet waits here. Pieces are
    summed per AGV in time order, and the AGVs in the order their first Idle spell ended
    (those Idle at the end last, in the order they became Idle)."""

    def __init__(self, start_s: float, end_s: float) -> None:
        self.start_s, self.end_s = start_s, end_s
        self.event_s = -math.inf
        """The time of the newest event: every Idle and reason spell before it is known."""
        self.waiting: list[Spell] = []
        """Closed spells in which orders waited, from `offset` on (the last may still grow)."""
        self.offset = 0
        self.queue_last: tuple[float, int] | None = None
        """The newest change of the queue length."""
        self.idle_since: dict[int, float] = {}
        """AGVs Idle now, since when (in the order they became Idle)."""
        self.idle: dict[int, deque[tuple[float, float | None]]] = {}
        """Per AGV, Idle spells not fully matched yet (end None: still Idle)."""
        self.cursor: dict[int, int] = {}
        """Per AGV with Idle spells to match, the waiting spell it has reached."""
        self.reasons: dict[int, deque[tuple[NotDispatched, float, float]]] = {}
        """Per AGV, closed reason spells that may still meet an Idle spell."""
        self.reason_open: dict[int, tuple[NotDispatched, float]] = {}
        self.order: dict[int, None] = {}
        """AGVs in the order their first Idle spell ended."""
        self.total_s: dict[int, float] = {}
        self.by_reason_s: dict[int, dict[NotDispatched, float]] = {}
        self.closed = False

    # ---- the streams --------------------------------------------------------------------------
    def events(self, rows: Sequence[EventRecord]) -> None:
        for e in rows:
            if e.event == NOT_DISPATCHED:
                if e.agv in self.reason_open:
                    self._close_reason(e.agv, e.time_s)
                self.reason_open[e.agv] = (NotDispatched(e.detail), e.time_s)
            elif e.event == NOT_DISPATCHED_END and e.agv in self.reason_open:
                self._close_reason(e.agv, e.time_s)
            if e.from_state == e.to_state:
                continue
            if e.agv in self.idle_since:
                self._close_idle(e.agv, e.time_s)
            if e.to_state == IDLE:
                self._open_idle(e.agv, e.time_s)
        if rows:
            self.event_s = rows[-1].time_s
        self._match()

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        for t1, value in rows:
            if self.queue_last is not None:
                self._step_ended(*self.queue_last, t1)
            self.queue_last = (t1, value)
        self._match()

    def close(self) -> None:
        """The run is over: the queue's last step, the Idle spells and the reasons still open
        last to its end."""
        if self.closed:
            return
        if self.queue_last is not None:
            self._step_ended(*self.queue_last, self.end_s)
            self.queue_last = None
        for agv in list(self.idle_since):
            self._close_idle(agv, self.end_s)
        for agv in list(self.reason_open):
            self._close_reason(agv, self.end_s)
        self.closed = True
        self.event_s = math.inf
        self._match()

    def seconds(self) -> tuple[float, dict[NotDispatched, float]]:
        """The total and the part under each reason, once closed."""
        total = 0.0
        by_reason = dict.fromkeys(NotDispatched, 0.0)
        for agv in self.order:
            total += self.total_s.get(agv, 0.0)
            for reason, seconds in self.by_reason_s.get(agv, {}).items():
                by_reason[reason] += seconds
        return total, by_reason

    # ---- spells -------------------------------------------------------------------------------
    def _step_ended(self, t0: float, value: int, t1: float) -> None:
        a, b = max(t0, self.start_s), min(t1, self.end_s)
        if value > 0 and b > a:
            if self.waiting and self.waiting[-1][1] == a:
                self.waiting[-1][1] = b
            else:
                self.waiting.append([a, b])

    def _open_idle(self, agv: int, time_s: float) -> None:
        self.idle_since[agv] = time_s
        spells = self.idle.setdefault(agv, deque())
        if not spells:  # from the first waiting spell that may meet this Idle spell
            first = bisect_right(self.waiting, time_s, key=lambda w: w[1])
            if first == len(self.waiting) and self._may_grow():
                first -= 1  # the last one may still grow past time_s
            self.cursor[agv] = self.offset + first
        spells.append((time_s, None))

    def _close_idle(self, agv: int, time_s: float) -> None:
        since = self.idle_since.pop(agv)
        spells = self.idle[agv]
        assert spells[-1] == (since, None)
        spells[-1] = (since, time_s)
        self.order.setdefault(agv, None)

    def _close_reason(self, agv: int, time_s: float) -> None:
        reason, since = self.reason_open.pop(agv)
        self.reasons.setdefault(agv, deque()).append((reason, since, time_s))

    # ---- matching ------------------------------------------------------------------------------
    def _waiting_at(self, j: int) -> tuple[float, float, bool] | None:
        """Waiting spell `j` (absolute index) and whether its end is final, or None if it is
        not known yet."""
        k = j - self.offset
        if k >= len(self.waiting):
            return None
        a, b = self.waiting[k]
        final = self.closed or k < len(self.waiting) - 1 or not self._may_grow()
        return a, b, final

    def _may_grow(self) -> bool:
        """Can the last waiting spell still grow (the queue's open step joins it)?"""
        if self.queue_last is None or not self.waiting:
            return False
        t0, value = self.queue_last
        return value > 0 and self.waiting[-1][1] == max(t0, self.start_s)

    def _next_waiting_from(self) -> float:
        """Waiting spells not known yet start at or after this."""
        if self.closed:
            return math.inf
        if self.queue_last is None:
            return -math.inf
        return max(self.queue_last[0], self.start_s)

    def _match(self) -> None:
        for agv, spells in self.idle.items():
            if spells:
                self._match_agv(agv, spells)
        self._forget()

    def _match_agv(self, agv: int, spells: deque[tuple[float, float | None]]) -> None:
        j = self.cursor[agv]
        while spells:
            s, e = spells[0]
            spell = self._waiting_at(j)
            if spell is None:  # every known waiting spell is behind
                if e is not None and e <= self._next_waiting_from():
                    spells.popleft()
                    continue
                break
            a, b, final = spell
            if e is not None and (final or e <= b):
                hi, idle_first = min(e, b), e <= b
            elif final and b <= self.event_s:  # Idle goes on at least to the newest event
                hi, idle_first = b, False
            else:
                break
            lo = max(s, a)
            if hi > lo:
                self._piece(agv, lo, hi)
            if idle_first:
                spells.popleft()
            else:
                j += 1
        self.cursor[agv] = j

    def _piece(self, agv: int, lo: float, hi: float) -> None:
        """[lo, hi]: Idle while orders waited; and its part under each reason."""
        self.total_s[agv] = self.total_s.get(agv, 0.0) + (hi - lo)
        held = self.reasons.get(agv)
        spells: list[tuple[NotDispatched, float, float]] = list(held) if held else []
        if agv in self.reason_open:  # open: lasts at least to the newest event, past hi
            reason, since = self.reason_open[agv]
            spells.append((reason, since, math.inf))
        for reason, ra, rb in spells:
            if ra >= hi:
                break
            piece = min(hi, rb) - max(lo, ra)
            if piece > 0:
                sums = self.by_reason_s.setdefault(agv, {})
                sums[reason] = sums.get(reason, 0.0) + piece
        while held and held[0][2] <= hi:  # no later piece (they start at hi or after) meets it
            held.popleft()

    def _forget(self) -> None:
        """Drop what no Idle spell can meet any more: waiting spells before every AGV's cursor
        (and, for AGVs not Idle, before the newest event); reasons of AGVs not Idle that ended
        before the newest event."""
        keep_from = self.offset + bisect_right(self.waiting, self.event_s, key=lambda w: w[1])
        for agv, spells in self.idle.items():
            if spells:
                keep_from = min(keep_from, self.cursor[agv])
        keep_from = min(keep_from, self.offset + max(0, len(self.waiting) - 1))
        drop = keep_from - self.offset
        if drop > 64 and drop * 2 > len(self.waiting):
            del self.waiting[:drop]
            self.offset = keep_from
        for agv, held in self.reasons.items():
            if not self.idle.get(agv):
                while held and held[0][2] <= self.event_s:
                    held.popleft()
