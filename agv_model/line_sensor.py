"""The 16-bit magnetic line sensor of RSS-AGV-001 5.1: a row of on/off elements across the tape.

The spec says only "磁気センサーアレイ（16bit）". The geometry here is assumed, typical of
magnetic guide sensors: 16 elements at a 10 mm pitch (160 mm across) over 50 mm tape. An element
is on when its centre lies over the middle 45 mm of the tape (the field is weak at the edges), so
4 or 5 elements are on and the sensor's report, the centroid of the elements that are on, moves
in 5 mm steps: 0 while the tape centre is within 2.5 mm of the sensor centre, +-5 mm up to
7.5 mm, and so on. (Had the detecting width been a whole number of pitches, the report would
never be 0 and would jump between -5 and +5 mm around the centre.) The tape is seen while its
centre lies within 7.5 pitches + 22.5 mm = 97.5 mm of the sensor centre. No element on is
"All Sensors OFF" (Req.Err.010, line lost).

Sign convention: offsets are positive to the LEFT of the sensor centre (looking forward).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LineSensor:
    elements: int = 16
    """RSS-AGV-001 5.1: a 16-bit array."""
    pitch_m: float = 0.010
    """Assumed: 10 mm between element centres."""
    detect_width_m: float = 0.045
    """Assumed: an element turns on over the middle 45 mm of a 50 mm magnetic tape."""

    def __post_init__(self) -> None:
        if self.elements < 1 or self.elements > 64:
            raise ValueError(f"elements ({self.elements}) must be between 1 and 64")
        if self.pitch_m <= 0 or self.detect_width_m <= 0:
            raise ValueError(f"pitch_m ({self.pitch_m}) and detect_width_m "
                             f"({self.detect_width_m}) must be > 0")

    @property
    def width_m(self) -> float:
        """Width the elements span, centre to centre plus one pitch."""
        return self.elements * self.pitch_m

    @property
    def range_m(self) -> float:
        """Largest tape offset at which at least one element is still on."""
        return (self.elements - 1) / 2 * self.pitch_m + self.detect_width_m / 2

    def element_offset_m(self, index: int) -> float:
        """Lateral offset of element `index` (0 = rightmost) from the sensor centre."""
        return (index - (self.elements - 1) / 2) * self.pitch_m

    def bits(self, tape_offset_m: float | None) -> int:
        """The sensor word for tape whose centre lies `tape_offset_m` left of the sensor centre
        (None: no tape under the sensor). Bit i is element i."""
        if tape_offset_m is None:
            return 0
        half = self.detect_width_m / 2
        word = 0
        for i in range(self.elements):
            if abs(self.element_offset_m(i) - tape_offset_m) <= half + 1e-12:
                word |= 1 << i
        return word

    def reading_m(self, word: int) -> float | None:
        """Tape offset the sensor reports: the centroid of the elements that are on; None when
        every element is off."""
        if word < 0 or word >> self.elements:
            raise ValueError(f"sensor word {word:#x} has bits beyond {self.elements} elements")
        on = [i for i in range(self.elements) if word >> i & 1]
        if not on:
            return None
        return sum(self.element_offset_m(i) for i in on) / len(on)

    def read_m(self, tape_offset_m: float | None) -> float | None:
        """bits() then reading_m(): what the controller sees for a true tape offset."""
        return self.reading_m(self.bits(tape_offset_m))
