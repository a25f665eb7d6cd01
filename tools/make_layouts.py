"""Generate the bundled warehouse layouts (layouts/warehouse.yaml, distribution_centre.yaml,
fulfilment_centre.yaml).

Run `python tools/make_layouts.py` after changing this script; the YAML files are committed.
The warehouse and the distribution centre: a one-way main loop (counter-clockwise) with RFID
tags every 4 m; two-way aisles across it with drop-off stations inside; pickup stations on
one-way sidings below the loop (a queue tag, the station, an exit tag); chargers on two-way
spurs to the west; parking areas on sidings.

The fulfilment centre (`make_grid`) is built for hundreds of AGVs: a grid of one-way travel
aisles (north and south in turn, 12 m apart: a 9 m rack block and a 3 m lane) crossed by one-way
cross-aisles (east and west in turn, every 20 m), tags every 4 m, so every block of racks is a
loop and traffic has many alternatives. The outermost aisles and cross-aisles run round the
floor counter-clockwise, which makes the grid strongly connected. Nothing is two-way, so no
single-track corridor serialises a stream of AGVs. Stations sit on one-way sidings beside the
aisles (queue tag, station, exit tag, 3 m into the rack block), so an AGV handling a load
never blocks the aisle; they are spread over the floor in a diagonal pattern, pickups and
drop-offs in turn. Chargers sit on short sidings off the outer cross-aisles (south and north
walls), parking areas on sidings outside the west and east walls.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path
from typing import Any

import yaml

STEP = 4


class Builder:
    def __init__(self, name: str, description: str) -> None:
        self.name = name
        self.description = description
        self.nodes: list[dict[str, Any]] = []
        self.segments: list[dict[str, Any]] = []
        self.at: dict[tuple[int, int], str] = {}

    def node(self, nid: str, x: int, y: int, kind: str = "tag") -> str:
        self.nodes.append({"id": nid, "x": x, "y": y, "kind": kind})
        self.at[(x, y)] = nid
        return nid

    def seg(self, a: str, b: str, two_way: bool = False) -> None:
        item: dict[str, Any] = {"from": a, "to": b}
        if two_way:
            item["direction"] = "two_way"
        self.segments.append(item)


def make(name: str, description: str, width: int, height: int, aisle_xs: list[int],
         drop_ys: list[int], pickup_xs: list[int], charger_ys: list[int],
         parking: list[tuple[str, int]]) -> dict[str, Any]:
    b = Builder(name, description)
    ring: list[tuple[int, int]] = []
    ring += [(x, 0) for x in range(0, width + 1, STEP)]
    ring += [(width, y) for y in range(STEP, height, STEP)]
    ring += [(x, height) for x in range(width, -1, -STEP)]
    ring += [(0, y) for y in range(height - STEP, 0, -STEP)]
    ids = [b.node(f"M{i:03d}", x, y) for i, (x, y) in enumerate(ring)]
    for a, c in zip(ids, ids[1:] + ids[:1], strict=True):
        b.seg(a, c)
    drops: list[dict[str, Any]] = []
    for ai, x in enumerate(aisle_xs, start=1):
        chain = [b.at[(x, 0)]]
        for y in range(STEP, height, STEP):
            if y in drop_ys:
                nid = b.node(f"D{len(drops) + 1:02d}", x, y, "station")
                drops.append({"id": f"DROP{len(drops) + 1:02d}", "kind": "dropoff",
                              "nodes": [nid], "handling": {"dist": "triangular", "low_s": 10,
                                                           "mode_s": 15, "high_s": 25}})
            else:
                nid = b.node(f"A{ai:02d}_{y:02d}", x, y)
            chain.append(nid)
        chain.append(b.at[(x, height)])
        for a, c in itertools.pairwise(chain):
            b.seg(a, c, two_way=True)
    picks: list[dict[str, Any]] = []
    for pi, x0 in enumerate(pickup_xs, start=1):
        q = b.node(f"Q{pi:02d}", x0, -STEP)
        p = b.node(f"P{pi:02d}", x0 + STEP, -STEP, "station")
        e = b.node(f"E{pi:02d}", x0 + 2 * STEP, -STEP)
        b.seg(b.at[(x0, 0)], q)
        b.seg(q, p)
        b.seg(p, e)
        b.seg(e, b.at[(x0 + 2 * STEP, 0)])
        picks.append({"id": f"PICK{pi:02d}", "kind": "pickup", "nodes": [p],
                      "handling": {"dist": "triangular", "low_s": 15, "mode_s": 20,
                                   "high_s": 35}})
    chargers: list[dict[str, Any]] = []
    for ci, y in enumerate(charger_ys, start=1):
        c = b.node(f"C{ci:02d}", -STEP, y, "charger")
        b.seg(b.at[(0, y)], c, two_way=True)
        chargers.append({"id": f"CHG{ci:02d}", "node": c, "power_kw": 3.0, "docking_s": 30})
    parks: list[dict[str, Any]] = []
    for ki, (side, capacity) in enumerate(parking, start=1):
        if side == "east":
            pts = [(width, 8), (width + STEP, 8), (width + STEP, 16), (width + STEP, 24),
                   (width, 24)]
        else:  # north: the top side runs west, so the siding leaves further east
            x = width - 12
            pts = [(x, height), (x, height + STEP), (x - 8, height + STEP),
                   (x - 16, height + STEP), (x - 16, height)]
        k1 = b.node(f"K{ki}a", *pts[1])
        park = b.node(f"PARK{ki}", *pts[2], "parking")
        k2 = b.node(f"K{ki}b", *pts[3])
        b.seg(b.at[pts[0]], k1)
        b.seg(k1, park)
        b.seg(park, k2)
        b.seg(k2, b.at[pts[4]])
        parks.append({"id": f"PARK{ki}", "node": park, "capacity": capacity})
    return {
        "name": name,
        "description": description,
        "defaults": {"speed_limit_mps": 1.0, "turn_length_m": 1.0},
        "nodes": b.nodes,
        "segments": b.segments,
        "stations": picks + drops,
        "chargers": chargers,
        "parking": parks,
    }


def make_grid(name: str, description: str, columns: int, rows: int, column_pitch: int,
              row_pitch: int, station_every: int, chargers_per_wall: int,
              parking_rows: list[int], parking_capacity: int) -> dict[str, Any]:
    """A grid of one-way aisles: see the module docstring. `columns` and `rows` must be even
    (the outer aisles then run round the floor one way)."""
    assert columns % 2 == 0 and rows % 2 == 0
    assert column_pitch % STEP == 0 and row_pitch % STEP == 0
    b = Builder(name, description)
    width, height = (columns - 1) * column_pitch, (rows - 1) * row_pitch

    def tag(x: int, y: int) -> str:
        if (x, y) not in b.at:
            b.node(f"T{x:03d}_{y:03d}", x, y)
        return b.at[(x, y)]

    # travel aisles: the westmost runs south, then north and south in turn (the eastmost north)
    for ci in range(columns):
        x = ci * column_pitch
        ys = list(range(0, height + 1, STEP))
        if ci % 2 == 0:
            ys.reverse()
        chain = [tag(x, y) for y in ys]
        for a, c in itertools.pairwise(chain):
            b.seg(a, c)
    # cross-aisles: the southmost runs east, then west and east in turn (the northmost west)
    for ri in range(rows):
        y = ri * row_pitch
        xs = list(range(0, width + 1, STEP))
        if ri % 2 == 1:
            xs.reverse()
        chain = [tag(x, y) for x in xs]
        for a, c in itertools.pairwise(chain):
            b.seg(a, c)
    # stations on sidings east of the aisles (3 m into the rack block), in a diagonal pattern
    picks: list[dict[str, Any]] = []
    drops: list[dict[str, Any]] = []
    for ci in range(columns - 1):
        x = ci * column_pitch
        north = ci % 2 == 1
        for ri in range(rows - 1):
            if (ci + 3 * ri) % station_every != 0:
                continue
            y0 = ri * row_pitch
            ys = [y0 + 6, y0 + row_pitch // 2, y0 + row_pitch - 6]
            leave, rejoin = (y0 + 4, y0 + row_pitch - 4)
            if not north:
                ys.reverse()
                leave, rejoin = rejoin, leave
            pickup = (len(picks) + len(drops)) % 2 == 0
            number = (len(picks) if pickup else len(drops)) + 1
            letter = "P" if pickup else "D"
            q = b.node(f"{letter}Q{number:02d}", x + 3, ys[0])
            st = b.node(f"{letter}{number:02d}", x + 3, ys[1], "station")
            e = b.node(f"{letter}E{number:02d}", x + 3, ys[2])
            b.seg(b.at[(x, leave)], q)
            b.seg(q, st)
            b.seg(st, e)
            b.seg(e, b.at[(x, rejoin)])
            if pickup:
                picks.append({"id": f"PICK{number:02d}", "kind": "pickup", "nodes": [st],
                              "handling": {"dist": "triangular", "low_s": 15, "mode_s": 20,
                                           "high_s": 35}})
            else:
                drops.append({"id": f"DROP{number:02d}", "kind": "dropoff", "nodes": [st],
                              "handling": {"dist": "triangular", "low_s": 10, "mode_s": 15,
                                           "high_s": 25}})
    # chargers on sidings outside the south and north walls, spread along them
    chargers: list[dict[str, Any]] = []
    gaps = columns - 1
    for wall_y, outside, east in ((0, -3, True), (height, height + 3, False)):
        for k in range(chargers_per_wall):
            # halfway between two aisles; the siding leaves and rejoins the wall at the tags
            # 2 m either side
            x0 = (k * gaps // chargers_per_wall) * column_pitch + column_pitch // 2
            enter, leave = (x0 - 2, x0 + 2) if east else (x0 + 2, x0 - 2)
            number = len(chargers) + 1
            c = b.node(f"C{number:02d}", x0, outside, "charger")
            b.seg(b.at[(enter, wall_y)], c)
            b.seg(c, b.at[(leave, wall_y)])
            chargers.append({"id": f"CHG{number:02d}", "node": c, "power_kw": 3.0,
                             "docking_s": 30})
    # parking areas on sidings outside the west (southbound) and east (northbound) walls, in
    # the bands `parking_rows` (clear of the stations on the westmost aisle), listed west and
    # east in turn: a fleet starts in the areas listed first, so it starts spread over both
    parks: list[dict[str, Any]] = []
    for ri in parking_rows:
        for wall_x, outside, north in ((0, -STEP, False), (width, width + STEP, True)):
            y0 = ri * row_pitch
            ys = [y0 + 6, y0 + row_pitch // 2, y0 + row_pitch - 6]
            leave, rejoin = y0 + 4, y0 + row_pitch - 4
            if not north:
                ys.reverse()
                leave, rejoin = rejoin, leave
            number = len(parks) + 1
            k1 = b.node(f"K{number:02d}a", outside, ys[0])
            park = b.node(f"PARK{number:02d}", outside, ys[1], "parking")
            k2 = b.node(f"K{number:02d}b", outside, ys[2])
            b.seg(b.at[(wall_x, leave)], k1)
            b.seg(k1, park)
            b.seg(park, k2)
            b.seg(k2, b.at[(wall_x, rejoin)])
            parks.append({"id": f"PARK{number:02d}", "node": park, "capacity": parking_capacity})
    return {
        "name": name,
        "description": description,
        "defaults": {"speed_limit_mps": 1.0, "turn_length_m": 1.0},
        "nodes": b.nodes,
        "segments": b.segments,
        "stations": picks + drops,
        "chargers": chargers,
        "parking": parks,
    }


def layout_texts() -> dict[str, str]:
    """The text of every generated layout file, by file name (tests compare them with the
    committed files)."""
    warehouse = make(
        "warehouse",
        "Realistic warehouse: 96 x 40 m one-way main loop, 10 two-way aisles with 12 drop-off "
        "stations, 6 pickup sidings, 4 chargers, 2 parking areas.",
        96, 40, aisle_xs=[12 + 8 * i for i in range(10)], drop_ys=[20],
        pickup_xs=[4 + 16 * i for i in range(6)], charger_ys=[8, 16, 24, 32],
        parking=[("east", 100), ("north", 100)])
    # two more drop-off stations in aisles 3 and 8, as a site grows
    extra = {"A03_08": "D11", "A08_08": "D12"}
    for node in warehouse["nodes"]:
        if node["id"] in extra:
            old = node["id"]
            node["id"], node["kind"] = extra[old], "station"
            for seg in warehouse["segments"]:
                for end in ("from", "to"):
                    if seg[end] == old:
                        seg[end] = node["id"]
            warehouse["stations"].append(
                {"id": f"DROP{node['id'][1:]}", "kind": "dropoff", "nodes": [node["id"]],
                 "handling": {"dist": "triangular", "low_s": 10, "mode_s": 15, "high_s": 25}})
    dc = make(
        "distribution_centre",
        "Large distribution centre: 200 x 80 m one-way main loop, 23 two-way aisles with 46 "
        "drop-off stations, 12 pickup sidings, 8 chargers, 2 parking areas.",
        200, 80, aisle_xs=[12 + 8 * i for i in range(23)], drop_ys=[28, 52],
        pickup_xs=[4 + 16 * i for i in range(12)], charger_ys=[12, 20, 28, 36, 44, 52, 60, 68],
        parking=[("east", 250), ("north", 250)])
    site = make_grid(
        "fulfilment_centre",
        "Fulfilment centre for hundreds of AGVs: 324 x 180 m grid of 28 one-way travel aisles "
        "12 m apart and 10 one-way cross-aisles 20 m apart, stations on sidings beside the "
        "aisles, chargers along the south and north walls, parking outside the west and east "
        "walls.",
        columns=28, rows=10, column_pitch=12, row_pitch=20, station_every=5,
        chargers_per_wall=24, parking_rows=[4, 3, 6, 2, 7, 1], parking_capacity=50)
    texts: dict[str, str] = {}
    for data in (warehouse, dc, site):
        header = f"# Generated by tools/make_layouts.py; {len(data['nodes'])} nodes.\n"
        text = yaml.safe_dump(data, sort_keys=False, width=100, default_flow_style=None)
        texts[f"{data['name']}.yaml"] = header + text
    return texts


def main() -> None:
    out = Path(__file__).resolve().parent.parent / "layouts"
    for name, text in layout_texts().items():
        path = out / name
        path.write_text(text, encoding="utf-8")
        sys.stdout.write(f"{path}: {text.splitlines()[0].removeprefix('# ')}\n")


if __name__ == "__main__":
    main()
