"""Order trace CSV files (columns time_s, pickup, dropoff; extra columns are ignored).

Each row is checked by the same models and messages as the YAML files; its element is
``row N.column``, N the row's line in the file (the header is row 1, as in a spreadsheet).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

from pydantic import Field, Strict

from agv_model.inputs import StrictModel, Text, read_text, validate
from fleet_sim.config.layout import Layout
from fleet_sim.errors import InputError

REQUIRED = ("time_s", "pickup", "dropoff")


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


def load_trace(path: Path, layout: Layout) -> list[TraceOrder]:
    file = str(path)
    text = read_text(path)  # the same size cap and UTF-8 check as the YAML files
    with io.StringIO(text, newline="") as handle:
        reader = csv.DictReader(handle)
        try:
            header = reader.fieldnames or []
        except csv.Error as exc:
            raise InputError(file, "header", str(exc), "a well-formed CSV header") from None
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise InputError(file, "header", ",".join(header),
                             f"columns {', '.join(REQUIRED)} (missing {', '.join(missing)})")
        orders: list[TraceOrder] = []
        for line, cells in _rows(reader, file):
            where = f"row {line}"
            row = validate(TraceRow, {c: cells[c] for c in REQUIRED}, file, where)
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
