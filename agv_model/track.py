"""The magnetic line one vehicle follows: straight runs and arcs, RFID markers, gaps in the tape.

Positions are metres along the line from its start. An arc turns left for a positive angle. Every
arc is driven at the turn speed (RSS-AGV-001 5.1: slow down on curves; Req.Nav.005: 0.3 m/s on a
branch), so a branch turn is an arc after the branch node, as in the fleet engine's closed form
(a curve of `turn_length_m`, default 1.0 m). At a branch the vehicle follows the chosen tape and
masks the other (Req.Nav.005), so the model's line is the chosen path only. The tape goes on
straight past the end of the track, so a vehicle stopping at the end still sees it.

Markers are the RFID tags of 5.3: TYPE_SPD sets the cruise speed, TYPE_LOC corrects the
vehicle's odometry to the tag's position, TYPE_CMD 0x20 pauses 3 s. TYPE_CMD 0x10 (spin 180
degrees in place) is not modelled: a track holding one is refused.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from enum import StrEnum


@dataclass(frozen=True)
class Straight:
    length_m: float

    @property
    def curvature_per_m(self) -> float:
        return 0.0


@dataclass(frozen=True)
class Arc:
    length_m: float
    turn_rad: float
    """Heading change over the arc; positive turns left."""

    @property
    def curvature_per_m(self) -> float:
        return self.turn_rad / self.length_m

    @property
    def radius_m(self) -> float:
        return self.length_m / abs(self.turn_rad) if self.turn_rad else math.inf


Piece = Straight | Arc


class TagType(StrEnum):
    SPD = "TYPE_SPD"
    LOC = "TYPE_LOC"
    CMD = "TYPE_CMD"


SPEED_TAG_MPS: dict[int, float] = {0x01: 0.2, 0x02: 0.5, 0x03: 1.0}
"""RSS-AGV-001 5.3: TYPE_SPD 0x01 Low 0.2 m/s, 0x02 Mid 0.5 m/s, 0x03 High 1.0 m/s."""
CMD_SPIN = 0x10
CMD_PAUSE = 0x20
PAUSE_S = 3.0
"""RSS-AGV-001 5.3: TYPE_CMD 0x20 pauses for 3 seconds."""


@dataclass(frozen=True)
class Marker:
    position_m: float
    tag: TagType
    value: int = 0
    """TYPE_SPD: 0x01-0x03; TYPE_CMD: 0x20; TYPE_LOC: the zone id (not used by the model)."""

    def __post_init__(self) -> None:
        if self.tag is TagType.SPD and self.value not in SPEED_TAG_MPS:
            raise ValueError(f"TYPE_SPD marker at {self.position_m} m has value "
                             f"{self.value:#04x}; expected one of 0x01, 0x02, 0x03")
        if self.tag is TagType.CMD and self.value != CMD_PAUSE:
            what = "spin (0x10) is not modelled" if self.value == CMD_SPIN else "unknown"
            raise ValueError(f"TYPE_CMD marker at {self.position_m} m has value "
                             f"{self.value:#04x}: {what}; expected 0x20 (pause)")

    @staticmethod
    def speed(position_m: float, speed_mps: float) -> Marker:
        """A TYPE_SPD tag for one of the speeds of 5.3 (0.2, 0.5 or 1.0 m/s)."""
        for value, tag_speed in SPEED_TAG_MPS.items():
            if math.isclose(tag_speed, speed_mps):
                return Marker(position_m, TagType.SPD, value)
        raise ValueError(f"no TYPE_SPD value for {speed_mps} m/s; expected 0.2, 0.5 or 1.0")


@dataclass(frozen=True)
class Track:
    pieces: tuple[Piece, ...]
    markers: tuple[Marker, ...] = ()
    gaps: tuple[tuple[float, float], ...] = ()
    """Stretches (start_m, end_m) with no tape: the sensor reads all elements off there."""
    _starts: tuple[float, ...] = field(init=False, repr=False, compare=False)
    _headings: tuple[float, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.pieces:
            raise ValueError("a track needs at least one piece")
        for i, piece in enumerate(self.pieces):
            if not piece.length_m > 0:
                raise ValueError(f"piece {i} ({piece}) has length_m {piece.length_m}; "
                                 "expected > 0")
        starts = [0.0]
        headings = [0.0]
        for piece in self.pieces:
            starts.append(starts[-1] + piece.length_m)
            headings.append(headings[-1] + piece.curvature_per_m * piece.length_m)
        object.__setattr__(self, "_starts", tuple(starts))
        object.__setattr__(self, "_headings", tuple(headings))
        for marker in self.markers:
            if not 0.0 <= marker.position_m <= self.length_m:
                raise ValueError(f"marker at {marker.position_m} m lies off the track "
                                 f"(0 to {self.length_m} m)")
        for start, end in self.gaps:
            if not start < end:
                raise ValueError(f"tape gap ({start}, {end}) must have start < end")
        object.__setattr__(self, "markers",
                           tuple(sorted(self.markers, key=lambda m: m.position_m)))

    @staticmethod
    def straight(length_m: float, markers: tuple[Marker, ...] = ()) -> Track:
        return Track((Straight(length_m),), markers)

    @staticmethod
    def branch(before_m: float, after_m: float, turn_length_m: float = 1.0,
               turn_rad: float = math.pi / 2) -> Track:
        """A straight run to a branch node, a curve of `turn_length_m` turning `turn_rad`, and
        the rest of the next segment (`after_m` counts the curve, as a layout segment does)."""
        if after_m < turn_length_m:
            raise ValueError(f"after_m ({after_m}) must be at least turn_length_m "
                             f"({turn_length_m})")
        pieces: list[Piece] = [Straight(before_m), Arc(turn_length_m, turn_rad)]
        if after_m > turn_length_m:
            pieces.append(Straight(after_m - turn_length_m))
        return Track(tuple(pieces))

    @property
    def length_m(self) -> float:
        return self._starts[-1]

    def _index(self, position_m: float) -> int:
        """Index of the piece holding `position_m`; -1 before the start, len past the end."""
        if position_m < 0:
            return -1
        return bisect.bisect_right(self._starts, position_m) - 1

    def curvature_at(self, position_m: float) -> float:
        i = self._index(position_m)
        if i < 0 or i >= len(self.pieces):
            return 0.0
        return self.pieces[i].curvature_per_m

    def heading_at(self, position_m: float) -> float:
        """Heading of the line (rad, 0 along the first piece)."""
        i = self._index(position_m)
        if i < 0:
            return 0.0
        if i >= len(self.pieces):
            return self._headings[-1]
        return self._headings[i] + self.pieces[i].curvature_per_m * (position_m - self._starts[i])

    def bend_m(self, position_m: float, ahead_m: float) -> float:
        """How far (left positive) the line at `position_m + ahead_m` lies from the tangent at
        `position_m`: the integral of curvature x (ahead - u) over the look-ahead, small-angle."""
        total = 0.0
        for i, piece in enumerate(self.pieces):
            k = piece.curvature_per_m
            if k == 0.0:
                continue
            u0 = max(self._starts[i] - position_m, 0.0)
            u1 = min(self._starts[i + 1] - position_m, ahead_m)
            if u1 > u0:
                total += k * ((ahead_m - u0) ** 2 - (ahead_m - u1) ** 2) / 2.0
        return total

    def has_tape(self, position_m: float) -> bool:
        return not any(start <= position_m < end for start, end in self.gaps)

    def curves(self) -> list[tuple[float, float]]:
        """(start_m, end_m) of every arc, where the turn speed applies."""
        return [(self._starts[i], self._starts[i + 1]) for i, p in enumerate(self.pieces)
                if isinstance(p, Arc)]
