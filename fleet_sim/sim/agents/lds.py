"""The AGV ahead as an obstacle to the LDS (RSS-AGV-001 4.2.3, 4.2.4, 6.1 E_101; P_005, P_006).

The laser scanner does not know an AGV from a person: an AGV queued behind another that
stands still sees it within range. Which reading holds is `rules.agv_ahead`:

* ``lds`` (default, the document as written): an AGV that traffic makes wait for the node a
  standing AGV holds closes up behind it to the minimum gap (`min_gap_m`, P_006). When that gap
  is under `rules.lds_stop_m` (1.0 m, 4.2.3) the AGV is Paused `obstacle_pause_s` (300 ms)
  after it began to wait (`Event_Obstacle_Detected`, counted in `agv_obstacle_pauses`, apart
  from other obstacles). It moves on (`Event_Obstacle_Cleared`) once traffic grants the node
  and the way has been clear by more than `rules.lds_clear_m` (1.2 m, 4.2.4) for
  `obstacle_clear_s` (2000 ms): counted from when the AGV ahead set off and opened the gap
  from standstill at its acceleration. Paused `obstacle_timeout_s` (5 minutes) it raises
  E_101: behind an AGV that broke down, the queue's AGVs fail one by one, as on the floor.
* ``held_back``: the fleet manager holds each AGV far enough back that the LDS never sees the
  one ahead (not even in the P_005 slowing zone, `rules.lds_slow_m`, 1.5 m): an AGV lets go
  of a node only once its rear is `lds_slow_m` past it (not `min_gap_m`), so queues need more
  track. On layouts whose segments are longer than an AGV plus `lds_slow_m` (every bundled
  one) this gives the same results as leaving the AGV ahead out of the LDS altogether.

The readings: docs/background/spec-readings.md; the choices where the documents are silent:
docs/background/decisions/sim.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from typing import Any, Protocol

import simpy

from fleet_sim.config.scenario import Rules
from fleet_sim.sim.traffic.waking import AlarmClock, call_at

LOOK_AGAIN_S = 1.0
"""While an AGV waits behind one that is driving, how often it looks whether that one has
stopped (assumed; a pause starts at most this late after the AGV ahead stopped). Looks that
would see it still on the hop it drives are skipped, and so are those while it waits for a
corridor or zone, which would see nobody (`AgvAhead._look`)."""


class Ahead(Protocol):
    """What the AGV behind can see of the one ahead (a `Driver`)."""

    @property
    def id(self) -> int: ...

    @property
    def standing(self) -> bool:
        """Not driving a hop (waiting, handling a load, down, charging)."""
        ...

    @property
    def departed_s(self) -> float:
        """When it last set off (or left the track)."""
        ...

    @property
    def accel_mps2(self) -> float: ...

    @property
    def hop_ends_s(self) -> float | None:
        """When the hop it drives ends, if it drives one and the time is known (closed-form
        motion); None otherwise."""
        ...

    def when_halted(self, tell: Callable[[], None]) -> None:
        """Call `tell` if a fault stops it before the end of the hop it drives."""
        ...


Finder = Callable[[], "tuple[int, Ahead, bool] | None"]
"""Names the AGV holding the node the AGV waits for (its id, what it sees of it, and whether it
is on the node or its body still over it); None: it waits for no node, or nobody holds it."""


class PausedHost(Protocol):
    """What the watch needs of the AGV behind (its `Vehicle`)."""

    def pause_for_agv(self, ahead: int, gap_m: float) -> bool:
        """Enter Paused (Event_Obstacle_Detected) for AGV `ahead`; False if the state
        machine refuses (not Moving)."""
        ...

    def resume_after_agv(self, paused_s: float) -> None:
        """Event_Obstacle_Cleared after a pause behind an AGV."""
        ...

    def fail(self, code: str, detail: str = "") -> bool: ...


class _Timeout:
    """A pause's E_101 timeout, an alarm of the run's `AlarmClock` (most pauses end long
    before it, and a timer that is turned off costs no event)."""

    __slots__ = ("alarm_eid", "alarm_s", "tell")

    def __init__(self, tell: Callable[[], None]) -> None:
        self.tell = tell
        self.alarm_s = math.inf
        self.alarm_eid = 0

    def ring(self, at_once: bool) -> None:
        self.tell()

    def off(self) -> None:
        self.alarm_s = math.inf


class AgvAhead:
    """One AGV's watch over the AGV ahead while traffic makes it wait (``lds`` reading)."""

    def __init__(self, env: simpy.Environment, rules: Rules, min_gap_m: float,
                 host: PausedHost, clock: AlarmClock) -> None:
        self.env = env
        self.clock = clock
        """The run's alarm clock: the pause's E_101 timeout is one of its alarms."""
        self.rules = rules
        self.gap_m = min_gap_m
        """How close it closes up (P_006)."""
        self.host = host
        self.waiting = False
        """Traffic makes the AGV wait now."""
        self._wait_no = 0
        """Counts the waits: a watch ends when the wait it was started for does."""
        self._first_look_s = 0.0
        """When the wait's first look is (its looks follow every LOOK_AGAIN_S)."""
        self._node_wait = False
        """The lock traffic makes it wait for now is a node's (not a corridor's or a zone's)."""
        self._unmade_look_s: float | None = None
        """While the watch does not look (the AGV waits for a corridor or zone: a look would see
        nobody), when its next look would have been; once the wait turns to a node it looks at
        the first of its looks from then that is not past (`began_waiting`)."""
        self._unmade_eid = 0
        """The event id the timer of that next look would have taken (reserved when the watch
        stopped looking): the look it makes comes at that place among its instant's events."""
        self.paused_since: float | None = None
        self.paused_behind: Ahead | None = None
        self._pause_no = 0
        self._timeout: _Timeout | None = None

    @property
    def sees_agvs(self) -> bool:
        """Whether the LDS can see the AGV ahead at all: closed up to the minimum gap, it is
        within the stop distance."""
        return self.gap_m < self.rules.lds_stop_m

    def began_waiting(self, find: Finder, for_node: bool) -> None:
        """Traffic made the AGV wait for a lock (`for_node`: a node's); `find()` names the AGV
        holding the node it waits for. Told again in the same wait (the hop's corridor or zone
        was granted, its node is waited for now), a watch that stopped looking looks again at
        the first of its looks after now."""
        if not self.sees_agvs:
            return
        self._node_wait = for_node
        if self.waiting:
            unmade_s = self._unmade_look_s
            if unmade_s is not None and for_node:
                self._unmade_look_s = None
                self._look_at(self._look_from(unmade_s), self._unmade_eid, find, self._wait_no)
            return
        self.waiting = True
        self._wait_no += 1
        self._first_look_s = self.env.now + self.rules.obstacle_pause_s
        if for_node:
            self._unmade_look_s = None
            self._look_in(self.rules.obstacle_pause_s, find, self._wait_no)
        else:
            self._stop_looking(self._first_look_s)

    def _stop_looking(self, next_look_s: float) -> None:
        """Make no look from `next_look_s` on while the AGV waits for a corridor or zone.
        Reserving the event id its timer would have taken puts the look it makes once the wait
        turns to a node where that look would have come among its instant's events if it comes
        at `next_look_s`, and before the looks of other watches on the same times of look
        (AGVs that began waiting together) if later: exact unless the watch had been behind
        one of them (none in the runs of tests/test_engine.py, 1 and 8 hours)."""
        self._unmade_look_s = next_look_s
        self._unmade_eid = next(self.env._eid)

    def _look_from(self, unmade_s: float) -> float:
        """The first look, not past, of those a watch looking every LOOK_AGAIN_S from
        `unmade_s` on would make: the same floats as its timers (each the last plus the
        period)."""
        now = self.env.now
        at_s = unmade_s
        while at_s < now:
            at_s += LOOK_AGAIN_S
        return at_s

    def _look_at(self, at_s: float, eid: int, find: Finder, wait_no: int) -> None:
        """Look at `at_s` exactly, at the place of event id `eid` among that instant's
        events (`call_at`)."""
        call_at(self.env, at_s, eid, lambda _: self._look(find, wait_no))

    def _look_in(self, delay_s: float, find: Finder, wait_no: int) -> None:
        """Look at the AGV ahead `delay_s` from now: a timeout's callback, not a process (no
        process to start and resume for each look)."""
        look = self.env.timeout(delay_s)
        look.callbacks.append(lambda _: self._look(find, wait_no))

    def _look(self, find: Finder, wait_no: int) -> None:
        """Paused if the AGV holding the node stands on it; else look again `LOOK_AGAIN_S` on,
        or, while it drives a hop (`Ahead.hop_ends_s`), at the first of those looks at or after
        the hop's end (the looks between would see it driving), or, while the AGV waits for a
        corridor or zone, once it waits for a node (the looks between would see nobody)."""
        if not self.waiting or self._wait_no != wait_no or self.paused_since is not None:
            return  # the wait is over, or another has begun
        found = find()
        if found is None and not self._node_wait:
            self._stop_looking(self.env.now + LOOK_AGAIN_S)
            return
        if found is not None and found[2] and found[1].standing:
            agv, ahead, _ = found
            if self.host.pause_for_agv(agv, self.gap_m):
                self.paused_since = self.env.now
                self.paused_behind = ahead
                self._pause_no += 1
                pause_no = self._pause_no
                # at the time and place of a timeout set now (the event id it would take)
                timeout = self._timeout = _Timeout(lambda: self._time_out(pause_no, agv))
                env = self.env
                self.clock.set(timeout, env.now + self.rules.obstacle_timeout_s, next(env._eid))
            return
        ends_s = found[1].hop_ends_s if found is not None else None
        if found is None or ends_s is None:
            self._look_in(LOOK_AGAIN_S, find, wait_no)
            return
        # looking every LOOK_AGAIN_S, the first look that can see it stopped: the first at or
        # after the end of its hop, or after a fault halts it on the way
        self._look_in(self._next_look_s(ends_s) - self.env.now, find, wait_no)
        found[1].when_halted(lambda: self._halted(find, wait_no))

    def _halted(self, find: Finder, wait_no: int) -> None:
        """The AGV looked at was halted by a fault on its hop: look at the next look."""
        if self.waiting and self._wait_no == wait_no and self.paused_since is None:
            self._look_in(self._next_look_s(self.env.now) - self.env.now, find, wait_no)

    def _next_look_s(self, time_s: float) -> float:
        """The first of the wait's looks (every LOOK_AGAIN_S from the first) at or after
        `time_s`, and after now."""
        now = self.env.now
        looks = math.ceil((max(time_s, now) - self._first_look_s) / LOOK_AGAIN_S - 1e-9)
        at_s = self._first_look_s + max(looks, 0) * LOOK_AGAIN_S
        return at_s if at_s > now + 1e-9 else at_s + LOOK_AGAIN_S

    def _time_out(self, pause_no: int, agv: int) -> None:
        if self._pause_no == pause_no and self.paused_since is not None:
            self.host.fail("E_101", f"paused {self.rules.obstacle_timeout_s:.0f} s behind "
                                    f"AGV {agv}")

    def wait_over(self) -> Generator[simpy.Event, Any, None]:
        """The wait has ended (granted, or given up): if paused, stay so until the way has
        been clear long enough, then move on."""
        self.waiting = False
        if self.paused_since is None:
            return
        ahead = self.paused_behind
        assert ahead is not None
        rules = self.rules
        open_m = max(0.0, rules.lds_clear_m - self.gap_m)
        since = ahead.departed_s if ahead.departed_s >= self.paused_since else self.env.now
        clear_at = since + math.sqrt(2 * open_m / ahead.accel_mps2) + rules.obstacle_clear_s
        if clear_at > self.env.now:
            yield self.env.timeout(clear_at - self.env.now)
        paused = self.env.now - self.paused_since
        self.stop()
        self.host.resume_after_agv(paused)

    def stop(self) -> None:
        """Forget the pause (moved on, or a fault took the AGV)."""
        self.paused_since = None
        self.paused_behind = None
        self.waiting = False
        if self._timeout is not None:
            self._timeout.off()
            self._timeout = None
