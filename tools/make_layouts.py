"""Generate the bundled warehouse layouts (layouts/warehouse.yaml, distribution_centre.yaml).

Run `python tools/make_layouts.py` after changing this script; the YAML files are committed.
The shape: a one-way main loop (counter-clockwise) with RFID tags every 4 m; two-way aisles across
it with drop-off stations inside; pickup stations on one-way sidings below the loop (a queue tag,
the station, an exit tag); chargers on two-way spurs to the west; parking areas on sidings.
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


def main() -> None:
    out = Path(__file__).resolve().parent.parent / "layouts"
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
    for data in (warehouse, dc):
        path = out / f"{data['name']}.yaml"
        header = f"# Generated by tools/make_layouts.py; {len(data['nodes'])} nodes.\n"
        text = yaml.safe_dump(data, sort_keys=False, width=100, default_flow_style=None)
        path.write_text(header + text, encoding="utf-8")
        sys.stdout.write(f"{path}: {len(data['nodes'])} nodes, {len(data['segments'])} "
                         "segments\n")


if __name__ == "__main__":
    main()
