"""The emulated AGV-3's own state: where it drives, what it carries, its battery, and the STATus
that follows from them, changing by itself as simulated time passes.

Source: the AGV-3 protocol document ("Grupp 3 AGV protokoll", revision 1.1), cited by heading.
Its STATus table names the states and their info but not the world behind them. The readings
taken here; every figure is an assumed, configurable `Agv3World` setting:

1. Track (STArt, STATus LEADING/FOLLOWING "på huvudväg"): the main road is a loop passing the
   turn-offs of stations 0, 1, 2, 3 in that order, ``station_gap_s`` apart (10 s: 3 m at the
   AGV-3 profile's 0.3 m/s). STArt "börjar att köra framåt tills att den hittar linjen": the
   line is found ``line_search_s`` (2 s) later, the first time half a gap before station 0's
   turn-off, after a STOp where the AGV stopped.
2. Stations (PICKUp, DROPOff: "utföras beroende på vilken station som kommer först"): the AGV
   turns off at the first turn-off ahead whose station has a pick-up or drop-off order (count
   above 0) and drives past the others; with no order it drives round the loop. An order given
   as it passes a turn-off waits a lap.
3. STATION info ("ENTER" vid påfart, "STOPPED" vid paus, "EXIT" vid avfart): påfart and avfart
   are read from the station's side, as the words ENTER and EXIT say: ENTER from leaving the
   main road until the AGV stands at the platform (``ramp_s``, 3 s), STOPPED while it stands
   there (``station_stop_s``, 5 s), EXIT until it is back on the main road (``ramp_s``). The
   station's orders are carried out as it stops: the drop-off first, then the pick-up as far
   as PASSengers' max allows (the rest are left behind); both read "0 0" from then on.
4. FOLLOWING info ("Id på framförhållande AGV eller -1 om den ej hunnit ikapp/ej ser skylt"):
   the emulated world holds one AGV ahead on the main road whose sign shows ``leader_id`` (1;
   None: nobody ahead, always -1). A follower reads -1 from joining the main road (line found,
   a station left, or ROLe FOLLOW on the road) until it has caught up ``catch_up_s`` (5 s)
   later, then the leader's id. A station visit loses sight of the leader.
5. FAULT ("har stött på ett oväntat fel och har stannat", info "Felmeddelande"): the document
   names no fault. The AGV detects two itself, stops and reports them: ``line not found`` when
   STArt's search lasts ``line_search_limit_s`` (10 s) without finding the line (never found
   with ``line_search_s`` None), and ``battery low`` when the battery is empty. A FAULT holds
   until the next STArt (which tries again: an empty battery faults again at once) or STOp.
6. BATtery ("<bat>V"): the reading falls linearly with the energy drawn, from ``battery_v``
   (full; 1.092556 V, the document's example) to ``battery_empty_v`` (None: 0.75 x full, a
   lithium cell's 3.15 V of 4.2 V) when ``battery_wh`` (16 Wh, the AGV-3 profile's) is used.
   It draws ``moving_w`` (8 W, the profile's) while it drives (looking for the line, on the
   main road, on a station's ramps) and nothing while it stands, so that a standing AGV's
   reading holds still: the default AGV-3 drives 2 h before FAULT battery low.
7. STOPPED ("AGV:n har ej fått start order"): before STArt and after STOp or EStop, which
   withdraw the start order. STArt while the AGV is already started changes nothing.
8. The owner's `Agv3Vehicle.set_status` and `arrive_at_station` put the AGV in a state; it
   drives on from there by itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

STATIONS = 4  # PICKUp <station, 0-3 = 0>
PASSENGERS_DEFAULT = 10  # PASSengers <max antal=10>
STATES = ("STOPPED", "STARTED", "FOLLOWING", "LEADING", "STATION", "FAULT")  # STATus table
STATION_INFO = ("ENTER", "STOPPED", "EXIT")  # STATus, STATION: påfart, paus, avfart
LINE_NOT_FOUND = "line not found"
BATTERY_LOW = "battery low"
START_POSITION = STATIONS - 0.5  # half a gap before station 0's turn-off (reading 1)
EMPTY_FRACTION = 0.75  # reading 6: empty at 0.75 x full
_SAME_PLACE = 1e-9  # gaps: a turn-off this close behind is passed, the order waits a lap

Phase = Literal["stopped", "searching", "road", "enter", "pause", "exit", "fault"]
_MOVING: frozenset[Phase] = frozenset({"searching", "road", "enter", "exit"})
_AT_STATION: dict[Phase, str] = {"enter": "ENTER", "pause": "STOPPED", "exit": "EXIT"}
Event = tuple[float, Callable[[float], None]]


@dataclass(frozen=True)
class Agv3World:
    """The emulated AGV-3 and what it meets; the document gives none of these figures."""

    line_search_s: float | None = 2.0
    line_search_limit_s: float = 10.0
    station_gap_s: float = 10.0
    ramp_s: float = 3.0
    station_stop_s: float = 5.0
    leader_id: int | None = 1
    catch_up_s: float = 5.0
    battery_v: float = 1.092556
    battery_empty_v: float | None = None
    battery_wh: float = 16.0
    moving_w: float = 8.0

    def __post_init__(self) -> None:
        for name in ("line_search_limit_s", "ramp_s", "station_stop_s", "catch_up_s",
                     "moving_w"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} ({getattr(self, name)}) must be at least 0")
        if self.line_search_s is not None and self.line_search_s < 0:
            raise ValueError(f"line_search_s ({self.line_search_s}) must be at least 0 or None")
        for name in ("station_gap_s", "battery_wh"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} ({getattr(self, name)}) must be greater than 0")
        if self.leader_id is not None and self.leader_id < 0:
            raise ValueError(f"leader_id ({self.leader_id}) must be at least 0 or None")
        if not 0 <= self.empty_v <= self.battery_v:
            raise ValueError(f"battery_empty_v ({self.empty_v}) must be between 0 and "
                             f"battery_v ({self.battery_v})")

    @property
    def empty_v(self) -> float:
        return EMPTY_FRACTION * self.battery_v if self.battery_empty_v is None \
            else self.battery_empty_v


@dataclass
class Order:
    """A PICKUp or DROPOff order; count 0 is no order."""

    station: int = 0
    count: int = 0

    def text(self) -> str:
        return f"{self.station} {self.count}"


class Agv3Vehicle:
    """One AGV-3 in simulated time: `advance` plays out what happens by itself; the commands
    (`start`, `stop`, `set_role`, `set_order`) act at a time no earlier than the last advance."""

    def __init__(self, world: Agv3World | None = None) -> None:
        self.world = world if world is not None else Agv3World()
        self.role = "LEAD"
        self.max_passengers = PASSENGERS_DEFAULT
        self.passengers = 0
        self.pickup = Order()
        self.dropoff = Order()
        self.leader_id = self.world.leader_id
        self.phase: Phase = "stopped"
        self.since_s = 0.0
        self.position = START_POSITION  # main-road gaps past station 0's turn-off, at since_s
        self.fault = ""
        self.leader_seen_s = 0.0  # a follower on the main road sees its leader from then on
        self._used_wh = 0.0  # energy drawn up to since_s
        self.now_s = 0.0

    # -- time ------------------------------------------------------------------------------

    def advance(self, now_s: float) -> None:
        """Play out every change due by `now_s`, in order."""
        while (event := self._next_event()) is not None and event[0] <= now_s:
            at_s, happen = event
            happen(at_s)
        self.now_s = max(self.now_s, now_s)

    def _next_event(self) -> Event | None:
        w = self.world
        events: list[Event] = []
        if self.phase in _MOVING and w.moving_w > 0:
            left_s = (w.battery_wh - self._used_wh) * 3600 / w.moving_w
            events.append((self.since_s + left_s, self._battery_empty))
        if self.phase == "searching":
            if w.line_search_s is None or w.line_search_s > w.line_search_limit_s:
                events.append((self.since_s + w.line_search_limit_s, self._line_not_found))
            else:
                events.append((self.since_s + w.line_search_s, self._join_road))
        elif self.phase == "road":
            ahead = self._next_ordered_station()
            if ahead is not None:
                gaps, station = ahead
                events.append((self.since_s + gaps * w.station_gap_s,
                               lambda at_s: self._turn_off(at_s, station)))
        elif self.phase == "enter":
            events.append((self.since_s + w.ramp_s, self._stop_at_station))
        elif self.phase == "pause":
            events.append((self.since_s + w.station_stop_s, lambda at_s: self._set("exit", at_s)))
        elif self.phase == "exit":
            events.append((self.since_s + w.ramp_s, self._join_road))
        return min(events, key=lambda event: event[0], default=None)  # the battery on a tie

    def _next_ordered_station(self) -> tuple[float, int] | None:
        """(gaps to drive, station) for the first ordered station's turn-off ahead."""
        ordered = {o.station for o in (self.pickup, self.dropoff) if o.count}
        best: tuple[float, int] | None = None
        for station in ordered:
            gaps = (station - self.position) % STATIONS
            if gaps < _SAME_PLACE:
                gaps += STATIONS
            if best is None or gaps < best[0]:
                best = (gaps, station)
        return best

    # -- what happens by itself ------------------------------------------------------------

    def _set(self, phase: Phase, at_s: float) -> None:
        """Enter `phase` at `at_s`, counting the energy drawn and the road driven so far."""
        self._used_wh = self._energy_wh(at_s)
        if self.phase == "road":
            self.position = self._road_position(at_s)
        self.phase, self.since_s = phase, at_s

    def _join_road(self, at_s: float) -> None:
        self._set("road", at_s)
        self.leader_seen_s = at_s + self.world.catch_up_s

    def _turn_off(self, at_s: float, station: int) -> None:
        self._set("enter", at_s)
        self.position = float(station)

    def _stop_at_station(self, at_s: float) -> None:
        self._set("pause", at_s)
        self._serve(round(self.position) % STATIONS)

    def _serve(self, station: int) -> None:
        """The drop-off, then the pick-up as far as there is room; both orders done."""
        if self.dropoff.count and self.dropoff.station == station:
            self.passengers -= min(self.dropoff.count, self.passengers)
            self.dropoff = Order()
        if self.pickup.count and self.pickup.station == station:
            room = max(0, self.max_passengers - self.passengers)
            self.passengers += min(self.pickup.count, room)
            self.pickup = Order()

    def _line_not_found(self, at_s: float) -> None:
        self._fail(LINE_NOT_FOUND, at_s)

    def _battery_empty(self, at_s: float) -> None:
        self._fail(BATTERY_LOW, at_s)

    def _fail(self, message: str, at_s: float) -> None:
        self._set("fault", at_s)
        self.fault = message

    def _energy_wh(self, at_s: float) -> float:
        w = self.world
        drawn = w.moving_w * max(0.0, at_s - self.since_s) / 3600 \
            if self.phase in _MOVING else 0.0
        return min(w.battery_wh, self._used_wh + drawn)

    def _road_position(self, at_s: float) -> float:
        return (self.position + (at_s - self.since_s) / self.world.station_gap_s) % STATIONS

    # -- commands --------------------------------------------------------------------------

    def start(self, at_s: float) -> None:
        if self.phase in ("stopped", "fault"):
            self._set("searching", at_s)

    def stop(self, at_s: float) -> None:
        self._set("stopped", at_s)

    def set_role(self, role: str, at_s: float) -> None:
        if role == "FOLLOW" and self.role != role and self.phase == "road":
            self.leader_seen_s = at_s + self.world.catch_up_s
        self.role = role

    def set_order(self, kind: Literal["pickup", "dropoff"], order: Order, at_s: float) -> None:
        if self.phase == "road":
            self._set("road", at_s)  # the next turn-off is looked for from here on
        if kind == "pickup":
            self.pickup = order
        else:
            self.dropoff = order

    # -- readings --------------------------------------------------------------------------

    def status(self, at_s: float) -> tuple[str, str]:
        """STATus's (state, info) at `at_s` (advanced to)."""
        if self.phase == "stopped":
            return "STOPPED", ""
        if self.phase == "searching":
            return "STARTED", ""
        if self.phase == "road":
            if self.role == "LEAD":
                return "LEADING", ""
            seen = self.leader_id is not None and at_s >= self.leader_seen_s
            return "FOLLOWING", str(self.leader_id) if seen else "-1"
        if self.phase == "fault":
            return "FAULT", self.fault
        return "STATION", _AT_STATION[self.phase]

    def battery_v(self, at_s: float) -> float:
        w = self.world
        return w.battery_v - (w.battery_v - w.empty_v) * self._energy_wh(at_s) / w.battery_wh

    # -- the owner's API -------------------------------------------------------------------

    def set_status(self, state: str, info: str = "") -> None:
        """Put the AGV in a STATus state now (FOLLOWING 4: following AGV 4, seen; STATION
        ENTER/STOPPED/EXIT: at the next turn-off ahead); it drives on from there by itself."""
        at_s = self.now_s
        if state not in STATES:
            raise ValueError(f"state {state!r} must be one of {', '.join(STATES)}")
        if state == "STATION" and info not in STATION_INFO:
            raise ValueError(f"STATION info {info!r} must be one of {', '.join(STATION_INFO)}")
        if state == "FOLLOWING" and info not in ("", "-1") and not info.isdigit():
            raise ValueError(f"FOLLOWING info {info!r} must be an AGV id or -1")
        if state == "STOPPED":
            self.stop(at_s)
        elif state == "STARTED":
            self._set("searching", at_s)
        elif state in ("LEADING", "FOLLOWING"):
            self.role = "LEAD" if state == "LEADING" else "FOLLOW"
            self._join_road(at_s)
            if info.isdigit():
                self.leader_id, self.leader_seen_s = int(info), at_s
        elif state == "STATION":
            at_station = self.phase in _AT_STATION
            self._set(next(p for p, text in _AT_STATION.items() if text == info), at_s)
            if not at_station:
                self.position = float(math.ceil(self.position - _SAME_PLACE) % STATIONS)
        else:
            self._fail(info, at_s)

    def arrive_at_station(self, station: int) -> None:
        """Stand at `station` now with its orders carried out; it drives on by itself."""
        if not 0 <= station < STATIONS:
            raise ValueError(f"station ({station}) must be 0-{STATIONS - 1}")
        self._set("pause", self.now_s)
        self.position = float(station)
        self._serve(station)
