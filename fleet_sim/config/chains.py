"""Multi-stop orders: a chain of stops checked against the layout.

An order is a chain of stations that alternate pickup, dropoff, pickup, dropoff...: pick at A,
drop at B, pick at C, drop at D is one task chain served by one AGV. The plain order is the chain
of two stops (pickup, dropoff). An AGV carries one load at a time: it is loaded between each
pickup and the dropoff after it, empty between a dropoff and the next pickup.

The choices where the issues were silent: docs/background/decisions/config.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final, Literal

from fleet_sim.config.layout import Layout
from fleet_sim.errors import InputError

MIN_STOPS: Final = 2
MAX_STOPS: Final = 20
"""Most stops of one order (ten loads); see the module docstring."""
SEPARATOR: Final = ">"
"""Between the stations of a chain in a trace CSV cell: ``A>B>C>D``."""


def stop_kind(index: int) -> Literal["pickup", "dropoff"]:
    """The kind of station stop `index` (from 0) must be: even stops pick, odd stops drop."""
    return "pickup" if index % 2 == 0 else "dropoff"


def check_chain(stops: Sequence[str], layout: Layout, file: str, where: str) -> None:
    """Raise an InputError naming `where` (and the stop) unless `stops` is a chain of
    `MIN_STOPS`..`MAX_STOPS` stations of the layout alternating pickup and dropoff."""
    if not MIN_STOPS <= len(stops) <= MAX_STOPS or len(stops) % 2:
        raise InputError(file, where, SEPARATOR.join(stops),
                         f"an even number of stops from {MIN_STOPS} to {MAX_STOPS} "
                         "(pickup, dropoff, pickup, dropoff...)")
    for i, station in enumerate(stops):
        kind = stop_kind(i)
        place = layout.places.get(station)
        if place is None or place.kind != kind:
            names = ", ".join(p.id for p in layout.places.values() if p.kind == kind)
            raise InputError(file, f"{where}[{i}]", station,
                             f"a {kind} station of layout {layout.name} ({names}); stops "
                             "alternate pickup, dropoff, starting with a pickup")
