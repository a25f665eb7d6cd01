"""How a blocked AGV is woken: by its claim's grant, and otherwise only when looking again for
a way out could find something new (fleet_sim.sim.traffic.reactive).

A blocked AGV's process waits on its claim alone (passed on by a `Relay`).
A `Sleeper` stands for the wait. It looks again at the times a blocked AGV looks (every
`deadlock_check_s` from the start of its wait), but only at those where a look may find
something new: a threshold of its wait, a suspect's next look, or the first look after a
change that may open a way out (a lock it could drive into let go of, another AGV queuing for
what it holds, a new wait-for cycle through it). Its `AlarmClock` alarm wakes it then (a
`Nudge`, an interrupt with the cause `LOOK_AGAIN`). The clock keeps one timer for all the
alarms, not one per wait: most waits end before their first alarm, and a timer set for one
would still be an event. The run has one clock (`Traffic.clock`); a paused AGV's E_101 timeout
(fleet_sim.sim.agents.lds) is one of its alarms too.

An event that would be the next processed all the same (nothing else queued for its instant:
`at_once`) is processed there and then, not scheduled: a nudge, a claim granted from the
queue (fleet_sim.sim.traffic.locks.Released) and its relay.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from typing import Protocol

import simpy
from simpy.events import NORMAL, PENDING, Event

SCAN_LOOKS = 64
"""How many of a sleeper's look times past now are scanned for the one an alarm is set for; a
threshold further away (a `replan_after_s` of days) is reached in steps of as many looks."""

LOOK_AGAIN = object()
"""The cause of a `Nudge`: look again for a way out, the claim is still not granted."""


def at_once(env: simpy.Environment) -> bool:
    """An event scheduled now would be the next processed: nothing else is queued for this
    instant (then processing it now, not scheduling it, keeps the order of every event)."""
    queue = env._queue
    return not queue or queue[0][0] > env._now


def process_now(event: Event) -> None:
    """Process a triggered event now, as `Environment.step` would (`at_once`)."""
    callbacks, event.callbacks = event.callbacks, None  # type: ignore[assignment]
    for callback in callbacks:
        callback(event)


def call_at(env: simpy.Environment, at_s: float, eid: int,
            callback: Callable[[Event], None]) -> None:
    """Have SimPy call `callback` at `at_s` exactly, at the place of event id `eid` among
    that instant's events (an id reserved earlier: where a timer set then would have come). A
    timeout of `at_s - now` may round to another float and takes a new id."""
    event = Event(env)
    event._ok = True
    event._value = None
    event.callbacks.append(callback)
    heapq.heappush(env._queue, (at_s, NORMAL, eid, event))


class Sleeper:
    """A blocked AGV's wait for its claim. It looks again for a way out only at its look times
    (every `period_s` from `start_s`, the times a blocked AGV has always looked at), and only
    at those its `AlarmClock` alarm is set for: a threshold of its wait, a suspect's next look,
    or the next look after a change that may have opened a way out (`changed`). While the AGV
    sleeps (`awake` False) the alarm wakes it (a `Nudge`); once the wait is over nothing does."""

    __slots__ = ("_reached_s", "alarm_eid", "alarm_s", "awake", "claim", "clock", "eid",
                 "looked_s", "period_s", "process", "start_s", "watching")

    def __init__(self, process: simpy.Process, clock: AlarmClock, start_s: float,
                 period_s: float) -> None:
        self.process = process
        self.claim: Event | None = None
        """What the process waits on while it sleeps (the claim's `Relay`)."""
        self.clock = clock
        self.start_s = start_s
        self.period_s = period_s
        self.awake = True
        self.alarm_s = math.inf
        """When its alarm rings (inf: none is set; nan: the wait is over)."""
        self.eid = 0
        """Its place among the events of an instant: the event id SimPy would have given the
        timer a blocked AGV set when it last went to sleep (reserved then, `sleep`)."""
        self.alarm_eid = 0
        """The place its alarm rings at (the `eid` when it was set)."""
        self.looked_s = start_s
        """When it last looked."""
        self._reached_s = start_s
        """A look time (or the start) before now, from which the next ones are added up."""
        self.watching = False
        """It is on the watch lists of the locks its way out depends on (from its first look
        past a threshold until the wait is over)."""

    def _first_look(self, found: Callable[[float], bool]) -> float:
        """The first of its look times after now for which `found` is true (`found` is false
        up to some time, true after it), or, more than `SCAN_LOOKS` looks after now, that
        look (a look time all the same: it looks then, finds nothing new and sets its alarm
        again). Look times are as a timer of `period_s` set again at each look gives them
        (each the last plus the period: the same floats), walked on from `_reached_s`, so a
        long wait costs one addition per look time, not one per look time per call."""
        now = self.clock.env.now
        period_s = self.period_s
        at_s = self._reached_s
        while True:
            nxt = at_s + period_s
            if nxt >= now:
                break
            at_s = nxt
        self._reached_s = at_s  # the last look time before now: every answer is after it
        for _ in range(SCAN_LOOKS):
            at_s = at_s + period_s
            if found(at_s):
                return at_s
        return at_s

    def first_look_waited(self, wait_s: float) -> float:
        """The first of its look times at which it has waited `wait_s` (now - start >= wait_s,
        as the look tests it), or an earlier one, if that is more than `SCAN_LOOKS` looks
        away (`_first_look`). Asked only before it has waited that long."""
        start_s = self.start_s
        return self._first_look(lambda at_s: at_s - start_s >= wait_s)

    def next_look(self) -> float:
        """The first of its look times it has not made: after now, or now if it has not
        looked yet in this instant (a change in the instant of a look time comes before the
        look, which waits for the instant's events queued before it)."""
        now = self.clock.env.now
        looked_now = self.looked_s == now
        return self._first_look(lambda at_s: at_s > now or (at_s == now and not looked_now))

    def changed(self) -> None:
        """Something that may open a way out changed: look at the next look time."""
        if self.alarm_s != self.alarm_s:  # nan: the wait is over
            return
        at_s = self.next_look()
        if at_s < self.alarm_s:
            self.clock.set(self, at_s, self.eid)

    def sleep(self) -> None:
        """It goes to sleep: reserve the place among an instant's events that the timer a
        blocked AGV set then would have had, so that its looks come where they always have
        (before a grant of the same instant, for one)."""
        self.eid = next(self.clock.env._eid)

    def ring(self, at_once: bool) -> None:
        """Its alarm: wake the AGV to look again (a `Nudge`), unless it is awake. Nudges
        scheduled now would come after every event already queued for this instant and before
        any the woken AGVs schedule, one after another: with none queued (`at_once`), they are
        delivered now, in the same order, with nothing in between."""
        if not self.awake:
            self.awake = True
            Nudge(self, at_once)

    def over(self) -> None:
        """The wait has ended: nothing wakes it any more."""
        self.awake = True
        self.alarm_s = math.nan


class Relay(Event):
    """A claim's grant passed on as an event of its own, scheduled when the claim is processed:
    where SimPy's `claim | timeout` would resume the AGV, so that the events of the instant
    come in the order they always have (the AGV resumed at once would act before them)."""

    def __init__(self, env: simpy.Environment, claim: Event) -> None:
        self.env = env
        self.callbacks = []
        self._value = PENDING
        self._claim = claim
        claim.callbacks.append(self._pass)

    def _pass(self, _: Event) -> None:
        """The claim is processed (its only callback: its process waits on the relay): the
        relay is scheduled, or, when it would be the next event processed, processed now."""
        if self._value is PENDING:
            self._ok = True
            self._value = None
            if at_once(self.env):
                process_now(self)
            else:
                self.env.schedule(self)

    def drop(self) -> None:
        """The AGV no longer waits on it: the claim need not pass its grant on."""
        callbacks = self._claim.callbacks
        if callbacks and self._pass in callbacks:
            callbacks.remove(self._pass)


class Nudge(Event):
    """SimPy's `Interruption` with the cause `LOOK_AGAIN`, at normal priority (an interrupt
    scheduled with it comes first), delivered only if the process still waits for the claim
    it slept on (it may have been granted it, or a fault may have taken it elsewhere,
    meanwhile). `at_once`: delivered now, not scheduled, where it would be processed next all
    the same (`AlarmClock._ring`)."""

    def __init__(self, sleeper: Sleeper, at_once: bool) -> None:
        self.env = sleeper.process.env
        self.callbacks = [self._deliver]
        self._value = simpy.Interrupt(LOOK_AGAIN)
        self._ok = False
        self._defused = True
        self.sleeper = sleeper
        if at_once:
            process_now(self)
        else:
            self.env.schedule(self)

    def _deliver(self, _: Event) -> None:
        process = self.sleeper.process
        if process._value is not PENDING or process._target is not self.sleeper.claim:
            return
        process._target.callbacks.remove(process._resume)
        process._resume(self)


class Alarm(Protocol):
    """What an `AlarmClock` rings: it set for `alarm_s` at the event id `alarm_eid` (both
    set by the clock; an alarm whose two no longer match what it was set for is off)."""

    alarm_s: float
    alarm_eid: int

    def ring(self, at_once: bool) -> None:
        """Its time and place have come. `at_once`: an event scheduled now would be the next
        processed (`at_once()`, as it stood when the clock rang)."""
        ...


class AlarmClock:
    """The run's alarms that mostly never ring: blocked AGVs' looks (`Sleeper`) and a paused
    AGV's E_101 timeout (fleet_sim.sim.agents.lds). Each rings at its time and at the place
    among that instant's events of the event id given when it was set, as its own timer would
    have; but only the earliest alarm still set is in SimPy's queue at any time (most alarms
    are turned off before their time: the wait or pause ends first), so an alarm costs an
    event only if it rings or is turned off after it came to the front."""

    def __init__(self, env: simpy.Environment) -> None:
        self.env = env
        self._alarms: list[tuple[float, int, Alarm]] = []
        self._queued: set[tuple[float, int]] = set()
        """The alarms put in SimPy's queue and not rung yet."""
        self._front: tuple[float, int] | None = None
        """The earliest of them."""

    def set(self, alarm: Alarm, at_s: float, eid: int) -> None:
        """Ring `alarm` at `at_s`, at the place of event id `eid` (its previous time is off)."""
        alarm.alarm_s = at_s
        alarm.alarm_eid = eid
        key = (at_s, eid)
        heapq.heappush(self._alarms, (at_s, eid, alarm))
        if self._front is None or key < self._front:
            self._queue(key)

    def _queue(self, key: tuple[float, int]) -> None:
        """Put the alarm `key` in SimPy's queue at its time and place."""
        self._front = key
        if key in self._queued:
            return
        self._queued.add(key)
        call_at(self.env, max(key[0], self.env.now), key[1], lambda _: self._ring(key))

    def _ring(self, key: tuple[float, int]) -> None:
        self._queued.discard(key)
        if self._front == key:
            self._front = None
        alarms = self._alarms
        rung: list[Alarm] = []
        while alarms and (alarms[0][0], alarms[0][1]) <= key:
            at_s, eid, alarm = heapq.heappop(alarms)
            if alarm.alarm_s == at_s and alarm.alarm_eid == eid:
                alarm.alarm_s = math.inf
                rung.append(alarm)
        while alarms and (alarms[0][2].alarm_s != alarms[0][0]
                          or alarms[0][2].alarm_eid != alarms[0][1]):
            heapq.heappop(alarms)  # alarms turned off
        if alarms:
            nxt = (alarms[0][0], alarms[0][1])
            if self._front is None or nxt < self._front:
                self._queue(nxt)
        if rung:
            now = at_once(self.env)
            for alarm in rung:
                alarm.ring(now)
