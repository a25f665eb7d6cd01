"""Stalls that are not traffic: charging starvation and a fleet out of service.

Orders can wait with no AGV to take them for reasons that have nothing to do with traffic:

* **charging starvation**: orders wait for an AGV while AGVs stand waiting for a charger
  (every charger taken). While orders wait no AGV is free to take one (work conservation,
  fleet_sim.model.not_dispatched): those that could are held by their batteries. Typically
  the fleet drained at one pace and reached the charging threshold together (synchronised
  charging), and the chargers take the AGVs one after another while orders wait. How deep it
  went is kept too: at its worst, how many AGVs were charging, waiting for or on their way to
  a charger, or at or below the threshold.
* **out of service**: orders wait and every AGV is in Error, Maintenance or SafeMode.

`StallMeter` keeps, per AGV, what holds it (`held`: its battery or a fault), and the spells of
both stalls. It is fed by the `Recorder` (fleet_sim.model.records) with what the run records
anyway: state changes, SOC samples, charger requests, the waiting-order count and the fleet
manager's not_dispatched notes. It only reads: a run that has it gives the results it gave
without it. The gridlock watcher (fleet_sim.sim.gridlock) asks it why the AGVs at the head of
a chain of lock waits stand, so that a standstill behind AGVs waiting for chargers (or out of
service) is not called a traffic gridlock. The KPIs (fleet_sim.analysis.kpis:
charging_starvation_h, out_of_service_h and theirs) are read from its spells.

What counts as a stall, from when, and which faults explain a standstill (the choices where the
issues were silent): docs/background/decisions/sim.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Final

from fleet_sim.model.not_dispatched import NOT_DISPATCHED, NOT_DISPATCHED_END, NotDispatched
from fleet_sim.model.states import VehicleState

DOWN_STATES: Final = frozenset(s.value for s in (
    VehicleState.ERROR, VehicleState.MAINTENANCE, VehicleState.SAFE_MODE))
"""The states of an AGV out of service, as the recorder is told them."""
CHARGING_STATE: Final = VehicleState.CHARGING.value
WAITING_FOR_CHARGER: Final = NotDispatched.WAITING_FOR_CHARGER.value
BATTERY_LOW: Final = NotDispatched.BATTERY_LOW.value
BLOCKED_FAULTS: Final = frozenset({"E_101"})
"""Faults that are what being blocked ends in (an obstacle timeout: 5 minutes paused, behind
an AGV as well as a person): an AGV down with one of these does not explain a standstill."""


class Held(Enum):
    """What keeps an AGV from taking an order, for the stalls (None: nothing of these)."""

    CHARGING = "charging"
    """In state Charging."""
    CHARGER = "waiting for or on its way to a charger"
    """Asked for a charger and not charging yet."""
    LOW = "at or below the charging threshold"
    """Busy, it charges next; with charging off, it may not move (P_050)."""
    DOWN = "out of service"
    """In Error, Maintenance or SafeMode."""


HELD_WORDS: Final = {
    Held.CHARGING: "charging",
    Held.CHARGER: "waiting for a charger or on the way to one",
    Held.LOW: "at or below the {pct:g} % threshold",
    Held.DOWN: "out of service",
}
"""Each reason in a planner's words, after a count (``{pct}``: the threshold)."""


class Stall(Enum):
    CHARGING_STARVATION = "charging_starvation"
    OUT_OF_SERVICE = "out_of_service"


@dataclass(frozen=True)
class Spell:
    """A stall from start_s to end_s. `held`: at its worst (most AGVs held by their battery,
    or the first moment for a fleet out of service), how many AGVs each reason held (reasons
    with none left out)."""

    start_s: float
    end_s: float
    held: tuple[tuple[Held, int], ...]

    def agvs_held(self) -> int:
        """AGVs held at the spell's worst."""
        return sum(n for _, n in self.held)


@dataclass
class StallMeter:
    """The stalls of one run (see the module). `low_pct`: the SOC at or below which an AGV is
    held by its battery."""

    agvs: int
    low_pct: float
    spells: dict[Stall, list[Spell]] = field(default_factory=lambda: {s: [] for s in Stall})
    _down: set[int] = field(default_factory=set)
    _charging: set[int] = field(default_factory=set)
    _asked: set[int] = field(default_factory=set)
    _low: set[int] = field(default_factory=set)
    _battery_low: set[int] = field(default_factory=set)
    _held: dict[int, Held] = field(default_factory=dict)
    """AGV -> what holds it (AGVs held by nothing are not in it)."""
    _n_down: int = 0
    _fault: dict[int, str] = field(default_factory=dict)
    """AGV -> the code of the fault it is down with."""
    _waiting_for_charger: set[int] = field(default_factory=set)
    """AGVs whose open not_dispatched reason is waiting_for_charger."""
    _orders_waiting: int = 0
    _open: Stall | None = None
    _open_s: float = 0.0
    _worst: tuple[tuple[Held, int], ...] = ()
    _ended: bool = False

    # ---- what the recorder hands on ---------------------------------------------------------
    def state_changed(self, time_s: float, agv: int, from_state: str, to_state: str) -> None:
        self._battery_low.discard(agv)
        if to_state in DOWN_STATES:
            self._down.add(agv)
            self._asked.discard(agv)  # a failed AGV's charger request is cancelled
        else:
            self._down.discard(agv)
            self._fault.pop(agv, None)
        if to_state == CHARGING_STATE:
            self._charging.add(agv)
        else:
            self._charging.discard(agv)
            if from_state == CHARGING_STATE:
                self._asked.discard(agv)
        self._changed(time_s, agv)

    def soc(self, time_s: float, agv: int, soc_pct: float) -> None:
        if soc_pct <= self.low_pct:
            self._low.add(agv)
        else:
            self._low.discard(agv)
        self._changed(time_s, agv)

    def fault(self, agv: int, code: str) -> None:
        """AGV `agv` raised Error `code` (its state change follows or came first)."""
        self._fault[agv] = code

    def charger_asked(self, time_s: float, agv: int) -> None:
        self._asked.add(agv)
        self._changed(time_s, agv)

    def note(self, time_s: float, agv: int, event: str, detail: str) -> None:
        """An event that changes no state: the fleet manager's not_dispatched notes count."""
        if event == NOT_DISPATCHED:
            if detail == WAITING_FOR_CHARGER:
                self._waiting_for_charger.add(agv)
            else:
                self._waiting_for_charger.discard(agv)
            if detail == BATTERY_LOW:
                self._battery_low.add(agv)
            self._changed(time_s, agv)
            self._look(time_s)
        elif event == NOT_DISPATCHED_END:
            self._waiting_for_charger.discard(agv)
            self._look(time_s)

    def orders_waiting(self, time_s: float, orders: int) -> None:
        self._orders_waiting = orders
        self._look(time_s)

    def end(self, end_s: float) -> None:
        """The run is over: a spell still open lasts to `end_s` (once)."""
        if not self._ended:
            self._close(end_s)
            self._ended = True

    # ---- what it tells ------------------------------------------------------------------------
    def held(self, agv: int) -> Held | None:
        """What keeps AGV `agv` from taking an order now, if its battery or a fault does."""
        return self._held.get(agv)

    def explains_standstill(self, agv: int) -> bool:
        """Is AGV `agv`, at the front of a chain of lock waits, held by its battery or out of
        service, so that the AGVs behind it wait for a charger or a repair, not for traffic?
        Not if it is down with an obstacle timeout (`BLOCKED_FAULTS`): an AGV that timed out
        standing in a jam, behind an AGV, is a symptom of the jam."""
        reason = self._held.get(agv)
        if reason is None:
            return False
        return reason is not Held.DOWN or self._fault.get(agv) not in BLOCKED_FAULTS

    def spells_to(self, kind: Stall, end_s: float) -> list[Spell]:
        """The spells of `kind`, one still open lasting to `end_s` (the meter is unchanged)."""
        spells = list(self.spells[kind])
        if self._open is kind:
            _add(spells, kind, self._open_s, end_s, self._worst)
        return spells

    def words(self, held: tuple[tuple[Held, int], ...]) -> str:
        """``9 of 10 AGVs: 3 charging, 4 waiting for a charger or on the way to one, 2 at or
        below the 30 % threshold``: what held how many AGVs."""
        parts = ", ".join(f"{n} {HELD_WORDS[reason].format(pct=self.low_pct)}"
                          for reason, n in held)
        return f"{sum(n for _, n in held)} of {self.agvs} AGVs: {parts}"

    def stalled(self) -> Stall | None:
        """The stall under way now, if any."""
        if self._ended or self._orders_waiting <= 0:
            return None
        if self.agvs > 0 and self._n_down >= self.agvs:
            return Stall.OUT_OF_SERVICE
        return Stall.CHARGING_STARVATION if self._waiting_for_charger else None

    # ---- spells -------------------------------------------------------------------------------
    def _changed(self, time_s: float, agv: int) -> None:
        """AGV `agv`'s facts changed: what holds it, then (if that changed) whether the fleet
        is stalled."""
        if agv in self._down:
            reason: Held | None = Held.DOWN
        elif agv in self._charging:
            reason = Held.CHARGING
        elif agv in self._asked:
            reason = Held.CHARGER
        elif agv in self._low or agv in self._battery_low:
            reason = Held.LOW
        else:
            reason = None
        before = self._held.get(agv)
        if reason is before:
            return
        self._n_down += (reason is Held.DOWN) - (before is Held.DOWN)
        if reason is None:
            del self._held[agv]
        else:
            self._held[agv] = reason
        self._look(time_s)

    def _look(self, time_s: float) -> None:
        if self._ended:
            return
        now = self.stalled()
        if now is not self._open:
            self._close(time_s)
            if now is not None:
                self._open, self._open_s, self._worst = now, time_s, self._counts()
        elif now is Stall.CHARGING_STARVATION \
                and len(self._held) - self._n_down > sum(
                    n for reason, n in self._worst if reason is not Held.DOWN):
            self._worst = self._counts()

    def _close(self, time_s: float) -> None:
        kind = self._open
        if kind is None:
            return
        self._open = None
        _add(self.spells[kind], kind, self._open_s, time_s, self._worst)

    def _counts(self) -> tuple[tuple[Held, int], ...]:
        counts = dict.fromkeys(Held, 0)
        for reason in self._held.values():
            counts[reason] += 1
        return tuple((reason, n) for reason, n in counts.items() if n)


def _add(spells: list[Spell], kind: Stall, start_s: float, end_s: float,
         worst: tuple[tuple[Held, int], ...]) -> None:
    """Add the spell [start_s, end_s] to `spells`: joined to the last if they touch, dropped if
    it has no length; the worst of the two kept."""
    if end_s <= start_s:
        return
    if spells and spells[-1].end_s == start_s:
        last = spells.pop()
        start_s = last.start_s
        if kind is Stall.OUT_OF_SERVICE or _battery_held(last.held) >= _battery_held(worst):
            worst = last.held
    spells.append(Spell(start_s, end_s, worst))


def _battery_held(held: tuple[tuple[Held, int], ...]) -> int:
    return sum(n for reason, n in held if reason is not Held.DOWN)
