"""Order trace CSV files (columns time_s, pickup, dropoff; extra columns are ignored)."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

from fleet_sim.config.layout import Layout
from fleet_sim.errors import InputError

REQUIRED = ("time_s", "pickup", "dropoff")


@dataclass(frozen=True)
class TraceOrder:
    time_s: float
    pickup: str
    dropoff: str


def load_trace(path: Path, layout: Layout) -> list[TraceOrder]:
    file = str(path)
    try:
        handle = path.open(newline="", encoding="utf-8")
    except OSError:
        raise InputError(file, "file", file, "an existing, readable order trace CSV") from None
    with handle:
        reader = csv.DictReader(handle)
        header = reader.fieldnames or []
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise InputError(file, "header", ",".join(header),
                             f"columns {', '.join(REQUIRED)} (missing {', '.join(missing)})")
        orders: list[TraceOrder] = []
        for row in reader:
            line = reader.line_num
            try:
                time_s = float(row["time_s"])
            except (TypeError, ValueError):
                raise InputError(file, f"line {line}, time_s", row["time_s"],
                                 "a time in seconds") from None
            if time_s < 0:
                raise InputError(file, f"line {line}, time_s", time_s, "a time >= 0 s")
            for column, kind in (("pickup", "pickup"), ("dropoff", "dropoff")):
                place = layout.places.get(row[column] or "")
                if place is None or place.kind != kind:
                    names = ", ".join(p.id for p in layout.places.values() if p.kind == kind)
                    raise InputError(file, f"line {line}, {column}", row[column],
                                     f"a {kind} station of layout {layout.name} ({names})")
            orders.append(TraceOrder(time_s, row["pickup"], row["dropoff"]))
    orders.sort(key=lambda o: o.time_s)
    return orders
