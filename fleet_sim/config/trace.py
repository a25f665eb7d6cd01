"""Order trace CSV files (columns time_s, pickup, dropoff; extra columns are ignored).

Each row is checked by the same models and messages as the YAML files; its element is
``row N.column``, N the row's line in the file (the header is row 1, as in a spreadsheet).

Multi-stop orders (fleet_sim.config.chains): an optional column ``stops``. A row whose
``stops`` cell is not empty is one order with that chain, its stations joined by ``>``
(``PICK_A>DROP_B>PICK_C>DROP_D``); its pickup and dropoff cells may be left empty, and if
given must be the chain's first and last stop. A row with an empty ``stops`` cell is a plain
order, as in a file without the column. (One row per order, rather than rows sharing a task
id, keeps "one row, one order" and the file sorted by time.)
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from pydantic import Field, Strict

from fleet_sim.config.chains import SEPARATOR, check_chain
from fleet_sim.config.layout import Layout
from fleet_sim.errors import InputError
from userfiles.checking import StrictModel, Text, validate
from userfiles.reading import read_text

REQUIRED = ("time_s", "pickup", "dropoff")
STOPS = "stops"
"""The optional column of multi-stop orders."""


class TraceRow(StrictModel):
    """One row as written: CSV cells are text, so the time is read from its text."""

    time_s: Annotated[float, Strict(False), Field(ge=0)]
    """Seconds from the start of the run."""
    pickup: Text
    dropoff: Text


@dataclass(frozen=True)
class TraceOrder:
    """One order of a trace, checked against the layout."""

    time_s: float
    pickup: str
    dropoff: str
    stops: tuple[str, ...] = ()
    """A multi-stop order's chain (first stop `pickup`, last `dropoff`); empty: plain."""


def load_trace(path: Path, layout: Layout) -> list[TraceOrder]:
    file = str(path)
    text = read_text(path)  # the same size cap and UTF-8 check as the YAML files
    with io.StringIO(text, newline="") as handle:
        reader = csv.DictReader(handle)
        try:
            header = reader.fieldnames or []
        except csv.Error as exc:
            raise InputError(file, "header", str(exc), "a well-formed CSV header") from None
        required = ("time_s",) if STOPS in header else REQUIRED
        missing = [c for c in required if c not in header]
        if missing:
            raise InputError(file, "header", ",".join(header),
                             f"columns {', '.join(REQUIRED)} (missing {', '.join(missing)})")
        orders: list[TraceOrder] = []
        for line, cells in _rows(reader, file):
            where = f"row {line}"
            chain = _chain(cells, layout, file, where) if STOPS in header else None
            if chain is not None:
                orders.append(chain)
                continue
            given = {c: cells[c] for c in REQUIRED} if STOPS not in header \
                else {c: cells.get(c) or "" for c in REQUIRED}  # a stops file may lack them
            row = validate(TraceRow, given, file, where)
            for column, kind in (("pickup", "pickup"), ("dropoff", "dropoff")):
                station = getattr(row, column)
                place = layout.places.get(station)
                if place is None or place.kind != kind:
                    names = ", ".join(p.id for p in layout.places.values() if p.kind == kind)
                    raise InputError(file, f"{where}.{column}", station,
                                     f"a {kind} station of layout {layout.name} ({names})")
            orders.append(TraceOrder(row.time_s, row.pickup, row.dropoff))
    orders.sort(key=lambda o: o.time_s)
    return orders


def _chain(cells: Mapping[str, str | None], layout: Layout, file: str,
           where: str) -> TraceOrder | None:
    """The multi-stop order of a row with a `stops` cell; None for a plain row."""
    text = (cells.get(STOPS) or "").strip()
    if not text:
        return None
    stops = tuple(s.strip() for s in text.split(SEPARATOR))
    check_chain(stops, layout, file, f"{where}.{STOPS}")
    time_row = validate(TraceRow, {"time_s": cells["time_s"], "pickup": stops[0],
                                   "dropoff": stops[-1]}, file, where)
    for column, which, expected in (("pickup", "first", stops[0]),
                                    ("dropoff", "last", stops[-1])):
        given = (cells.get(column) or "").strip()
        if given and given != expected:
            raise InputError(file, f"{where}.{column}", given,
                             f"empty, or the {which} stop of the row's stops ({expected})")
    return TraceOrder(time_row.time_s, stops[0], stops[-1], stops)


def _rows(reader: csv.DictReader[str], file: str) -> Iterator[tuple[int, dict[str, str]]]:
    """(line number, cells) per row; a malformed row (a NUL, a runaway quote) is an InputError."""
    while True:
        try:
            cells = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            raise InputError(file, f"row {reader.line_num}", str(exc),
                             "a well-formed CSV row") from None
        yield reader.line_num, cells
