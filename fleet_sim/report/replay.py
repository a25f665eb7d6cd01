"""`fleet-sim replay RUN_DIR`: RUN_DIR/replay.html, one self-contained page that draws the layout
and animates every AGV at its recorded times, with its per-AGV timeline (Gantt) and the order
lead-time breakdown.

The page is one file that fetches nothing: our own scripts inlined, the run as one JSON
block (columnar, interned, deterministic: the same run and window give the same bytes).

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fleet_sim.analysis.replay import (
    CONFIG_FILE,
    LEAD_LABELS,
    LEAD_PARTS,
    POSITIONAL,
    RunRecord,
    incidents,
    lead_times,
    load_run,
    orders_held,
    state_spells,
)
from fleet_sim.config.layout import Layout, Place
from fleet_sim.config.scenario import load_scenario
from fleet_sim.errors import InputError
from fleet_sim.model.states import VehicleState
from fleet_sim.report.figures import LEAD_COLOURS, STATE_COLOURS
from fleet_sim.report.layout_plot import KIND_STYLE, PLACE_COLOUR, ZONE_COLOUR, zone_rule
from fleet_sim.report.render import environment, static_script
from fleet_sim.report.replay_payload import (
    Agv,
    AgvPlacements,
    AgvSoc,
    AgvSpells,
    AgvWaits,
    Leads,
    Nodes,
    Profiles,
    ReplayPayload,
    Zones,
)
from userfiles.writing import write_text_atomic

REPLAY_FILE = "replay.html"
KIND_CODES = {"drive": 0, "track": 1, "parking": 2, "off": 3}
STATE_INDEX = {s.value: i for i, s in enumerate(VehicleState)}
"""How the page's positional rows name their kind."""

ProgressCallback = Callable[[float, float], None]
_DIRECTION = {"forward": 1, "backward": -1}
"""How the page's zone rows name the way a same-direction zone is driven (0: a mutex zone)."""
_ProfileKey = tuple[int, float, float, float, float, float, float, float]
"""A hop profile: segment index, entry and exit speed, curve length and speed, limit, accel,
decel."""


def _ms(values: Any) -> list[float]:
    """Times (s) rounded to the millisecond, as plain floats."""
    return [float(v) for v in np.round(np.asarray(values, dtype=float), 3)]


class _Strings:
    """Every text of the page once: columns hold indices into `strings`."""

    def __init__(self) -> None:
        self.index: dict[str, int] = {}

    def __call__(self, text: str) -> int:
        found = self.index.get(text)
        if found is None:
            found = self.index[text] = len(self.index)
        return found

    def many(self, texts: Iterable[Any]) -> list[int]:
        return [self(str(t)) for t in texts]

    @property
    def strings(self) -> list[str]:
        return list(self.index)


def check_window(run_dir: Path, from_h: float | None, to_h: float | None) -> tuple[float, float]:
    """The window in seconds; one error naming the option when it is outside the run, not
    finite or empty."""
    config = run_dir / CONFIG_FILE
    if not config.is_file():
        raise InputError(str(run_dir), "run directory", str(run_dir),
                         f"a run directory of `fleet-sim run` or a sweep (with {CONFIG_FILE})")
    duration_h = load_scenario(config).duration_h
    lo = 0.0 if from_h is None else from_h
    hi = duration_h if to_h is None else to_h
    where = f"window of {run_dir}"
    for option, value in (("--from", lo), ("--to", hi)):
        if not math.isfinite(value) or not 0.0 <= value <= duration_h:
            raise InputError(option, where, value,
                             f"a finite number of hours within the run (0 to {duration_h:g})")
    if lo >= hi:
        raise InputError("--from", where, lo, f"less than --to ({hi:g} h)")
    return lo * 3600.0, hi * 3600.0


@dataclass(frozen=True)
class _Index:
    """Where each node, segment, place and traffic zone of the layout sits in the page's
    columns (other objects point at them by these indices)."""

    node_ids: list[str]
    node: dict[str, int]
    edges: list[tuple[str, str]]
    edge: dict[tuple[str, str], int]
    place_of: dict[str, Place]
    """The place each node of a place belongs to."""
    places: list[Place]
    place: dict[str, int]
    zone: dict[str, int]


def _index(layout: Layout) -> _Index:
    node_ids = sorted(layout.graph.nodes)
    edges = sorted(layout.graph.edges)
    places = sorted(layout.places.values(), key=lambda p: p.id)
    return _Index(
        node_ids=node_ids, node={n: i for i, n in enumerate(node_ids)},
        edges=edges, edge={e: i for i, e in enumerate(edges)},
        place_of={node: place for place in layout.places.values() for node in place.nodes},
        places=places, place={p.id: i for i, p in enumerate(places)},
        zone={z.id: i for i, z in enumerate(layout.traffic_zones)})


def _during(rows: pd.DataFrame, kind: str, from_s: float, to_s: float) -> pd.DataFrame:
    """The moves of one kind that overlap the window."""
    return rows[(rows["kind"] == kind) & (rows["end_s"] >= from_s) & (rows["start_s"] <= to_s)]


def page_data(run: RunRecord, from_s: float, to_s: float) -> ReplayPayload:
    """Everything the page draws, as JSON-ready columns (see the module docstring; every field
    is described in fleet_sim.report.replay_payload)."""
    layout = run.layout
    scenario = run.scenario
    text = _Strings()
    index = _index(layout)
    moves = run.moves
    profiles: dict[_ProfileKey, int] = {}
    agvs = _agvs(run, from_s, to_s, index, profiles, text)
    charger_waits = _during(moves, "charger_wait", from_s, to_s) if len(moves) else moves
    found = incidents(run.events)
    found = found[(found["time_s"] >= from_s) & (found["time_s"] <= to_s)]
    leads = lead_times(run.orders, moves if len(moves) else None, from_s, to_s)
    holds = _during(moves, "zone", from_s, to_s) if len(moves) else moves
    holds = holds[holds["u"].isin(list(index.zone))] if len(holds) else holds
    return {
        "meta": {
            "scenario": scenario.name, "layout": layout.name, "agvs": scenario.fleet.size,
            "seed": scenario.seed, "duration_s": scenario.duration_s,
            "warmup_s": scenario.warmup_s, "start_h": scenario.start_h,
            "from_s": from_s, "to_s": to_s,
            "resimulated": run.resimulated,
        },
        "states": [s.value for s in VehicleState],
        "stateColours": [STATE_COLOURS.get(s.key, "#80868b") for s in VehicleState],
        "nodes": _nodes(layout, index),
        "segs": {"u": [index.node[u] for u, _ in index.edges],
                 "v": [index.node[v] for _, v in index.edges],
                 "len": [float(layout.graph.edges[e]["length_m"]) for e in index.edges],
                 "twoWay": [int(layout.graph.has_edge(v, u)) for u, v in index.edges]},
        "corridors": {f"corridor {c.id}": sorted(index.edge[s] for s in c.segments)
                      for c in layout.corridors},
        "places": {"id": [p.id for p in index.places], "kind": [p.kind for p in index.places],
                   "node": [index.node[p.nodes[0]] for p in index.places],
                   "capacity": [p.capacity for p in index.places]},
        "profiles": _profiles(list(profiles)),
        "agv": agvs,
        "chargerWaits": {
            "agv": [int(a) for a in charger_waits["agv"]],
            "t": _ms(charger_waits["start_s"]), "e": _ms(charger_waits["end_s"]),
            "n": [index.node[u] for u in charger_waits["u"].tolist()],
            "ch": [index.place.get(str(v), -1) for v in charger_waits["v"].tolist()]},
        "zones": _zones(layout, index),
        "zoneHolds": {"agv": [int(a) for a in holds["agv"]],
                      "t": _ms(holds["start_s"]), "e": _ms(holds["end_s"]),
                      "z": [index.zone[str(u)] for u in holds["u"].tolist()],
                      "dir": [_DIRECTION.get(str(v), 0) for v in holds["v"].tolist()]},
        "blocks": [{"u": index.node[b.from_node], "v": index.node[b.to_node],
                    "t": b.at_s, "e": b.at_s + b.duration_s}
                   for b in scenario.incidents.blocks],
        "incidents": {"t": _ms(found["time_s"]), "agv": [int(a) for a in found["agv"]],
                      "kind": text.many(found["kind"]), "code": text.many(found["code"]),
                      "det": text.many(found["detail"])},
        "leads": _leads(leads),
        "strings": text.strings,
    }


def _nodes(layout: Layout, index: _Index) -> Nodes:
    """The layout's nodes: position, kind, and the colour of their place or kind."""
    graph = layout.graph
    return {
        "id": index.node_ids,
        "x": [float(graph.nodes[n]["x"]) for n in index.node_ids],
        "y": [float(graph.nodes[n]["y"]) for n in index.node_ids],
        "kind": [str(graph.nodes[n]["kind"]) for n in index.node_ids],
        "colour": [PLACE_COLOUR[index.place_of[n].kind] if n in index.place_of
                   else KIND_STYLE.get(str(graph.nodes[n]["kind"]), ("#9aa0a6", 0))[0]
                   for n in index.node_ids],
        "place": [index.place[index.place_of[n].id] if n in index.place_of else -1
                  for n in index.node_ids],
    }


def _profiles(keys: list[_ProfileKey]) -> Profiles:
    """The distinct hop profiles, in the order the drives first used them."""
    return {"seg": [k[0] for k in keys], "vin": [k[1] for k in keys],
            "vout": [k[2] for k in keys], "cm": [k[3] for k in keys],
            "cv": [k[4] for k in keys], "lim": [k[5] for k in keys],
            "acc": [k[6] for k in keys], "dec": [k[7] for k in keys]}


def _zones(layout: Layout, index: _Index) -> Zones:
    """The traffic zones as the layout drawing draws them: kind, rule, colour, nodes, path."""
    zones = layout.traffic_zones
    return {"id": [z.id for z in zones], "kind": [z.kind for z in zones],
            "rule": [zone_rule(z) for z in zones],
            "colour": [ZONE_COLOUR[z.kind] for z in zones],
            "nodes": [[index.node[n] for n in sorted(z.nodes | set(z.path))] for z in zones],
            "path": [[index.node[n] for n in z.path] for z in zones]}


def _agvs(run: RunRecord, from_s: float, to_s: float, index: _Index,
          profiles: dict[_ProfileKey, int], text: _Strings) -> list[Agv]:
    """Every AGV's rows in the window, in AGV order (`profiles` and `text` collect the hop
    profiles and texts they point at)."""
    moves = run.moves
    spells = state_spells(run.events, from_s, to_s)
    held = orders_held(run.events)
    by_agv = {int(str(a)): g for a, g in moves.groupby("agv", sort=True)} if len(moves) else {}
    soc_by_agv = {int(str(a)): g for a, g in run.soc.groupby("agv", sort=True)}
    spells_by_agv = {int(str(a)): g for a, g in spells.groupby("agv", sort=True)}
    agvs: list[Agv] = []
    for agv in range(run.scenario.fleet.size):
        rows = by_agv.get(agv, moves.iloc[0:0])
        times, ids = held.get(agv, (np.empty(0), np.empty(0, dtype=np.int64)))
        first = max(int(np.searchsorted(times, from_s, side="right")) - 1, 0)
        keep = slice(first, int(np.searchsorted(times, to_s, side="right")))
        agvs.append({
            "id": agv, "length_m": run.scenario.fleet.agv_profiles[agv].length_m,
            "p": _placements(rows, from_s, to_s, index, profiles),
            "s": _spells(spells_by_agv.get(agv, spells.iloc[0:0]), text),
            "o": {"t": _ms(times[keep]), "id": [int(o) for o in ids[keep]]},
            "b": _soc(soc_by_agv.get(agv, run.soc.iloc[0:0]), from_s, to_s),
            "w": _waits(rows, from_s, to_s, index, text),
        })
    return agvs


def _placements(rows: pd.DataFrame, from_s: float, to_s: float, index: _Index,
                profiles: dict[_ProfileKey, int]) -> AgvPlacements:
    """One AGV's positional rows in the window, from the last placement before it: a drive
    points at its hop profile (added to `profiles` when new), any other row at its node."""
    positional = rows[rows["kind"].isin(POSITIONAL)]
    starts = positional["start_s"].to_numpy(dtype=float)
    anchor = max(int(np.searchsorted(starts, from_s, side="right")) - 2, 0)
    positional = positional.iloc[anchor:]
    positional = positional[positional["start_s"] <= to_s]
    p_ref: list[int] = []
    for kind, u, v, vin, vout, cm, cv, lim, acc, dec in zip(
            *(positional[c].tolist() for c in ("kind", "u", "v", "v_in_mps", "v_out_mps",
                                               "curve_m", "curve_mps", "limit_mps",
                                               "accel_mps2", "decel_mps2")),
            strict=True):
        if kind == "drive":
            key = (index.edge[(u, v)], float(vin), float(vout), float(cm), float(cv),
                   float(lim), float(acc), float(dec))
            p_ref.append(profiles.setdefault(key, len(profiles)))
        else:
            p_ref.append(index.node[u])
    return {"t": _ms(positional["start_s"]), "e": _ms(positional["end_s"]),
            "k": [KIND_CODES[k] for k in positional["kind"].tolist()],
            "a": p_ref, "d": _ms(positional["driven_s"])}


def _spells(mine: pd.DataFrame, text: _Strings) -> AgvSpells:
    """One AGV's state spells in the window: state, the event and detail that began each,
    the order and whether it was loaded."""
    return {"t": _ms(mine["start_s"]), "e": _ms(mine["end_s"]),
            "st": [STATE_INDEX[s] for s in mine["state"].tolist()],
            "ev": text.many(mine["event"].tolist()),
            "det": text.many(mine["detail"].tolist()),
            "o": [int(o) for o in mine["order_id"].tolist()],
            "l": [int(bool(x)) for x in mine["loaded"].tolist()]}


def _soc(soc: pd.DataFrame, from_s: float, to_s: float) -> AgvSoc:
    """One AGV's state of charge in the window, from its last reading before it."""
    soc_t = soc["time_s"].to_numpy(dtype=float)
    soc_keep = slice(max(int(np.searchsorted(soc_t, from_s, side="right")) - 1, 0),
                     int(np.searchsorted(soc_t, to_s, side="right")))
    return {"t": _ms(soc_t[soc_keep]),
            "v": [round(float(v), 1) for v in soc["soc_pct"].to_numpy()[soc_keep]]}


def _waits(rows: pd.DataFrame, from_s: float, to_s: float, index: _Index,
           text: _Strings) -> AgvWaits:
    """One AGV's waits in the window: where, for which lock, behind which AGV."""
    waits = _during(rows, "wait", from_s, to_s)
    return {"t": _ms(waits["start_s"]), "e": _ms(waits["end_s"]),
            "n": [index.node[u] for u in waits["u"].tolist()],
            "lock": text.many(waits["v"].tolist()),
            "h": [int(h) for h in waits["other"].tolist()]}


def _leads(leads: pd.DataFrame) -> Leads:
    """The lead-time breakdown of the orders delivered in the window (parts -1 where none)."""
    def part(name: str) -> list[float]:
        return _ms(leads[name].fillna(-1.0))

    return {"parts": list(LEAD_PARTS), "labels": [LEAD_LABELS[p] for p in LEAD_PARTS],
            "colours": [LEAD_COLOURS[p] for p in LEAD_PARTS],
            "id": [int(i) for i in leads["order_id"]], "agv": [int(a) for a in leads["agv"]],
            "created": _ms(leads["created_s"]), "lead": _ms(leads["lead_time_s"]),
            "wait_assign_s": part("wait_assign_s"), "drive_empty_s": part("drive_empty_s"),
            "load_s": part("load_s"), "drive_loaded_s": part("drive_loaded_s"),
            "unload_s": part("unload_s"), "blocked_s": part("blocked_s")}


def lead_summary(leads: pd.DataFrame) -> list[dict[str, str]]:
    """Mean, median and p95 of each part of the lead time (rows of plain text)."""
    rows = []
    for part in (*LEAD_PARTS, "lead_time_s"):
        values = leads[part].dropna().to_numpy(dtype=float)
        label = LEAD_LABELS.get(part, "lead time (all parts)")
        if len(values) == 0:
            rows.append({"part": label, "mean": "n/a", "median": "n/a", "p95": "n/a"})
            continue
        rows.append({"part": label, "mean": f"{values.mean():.1f}",
                     "median": f"{np.median(values):.1f}",
                     "p95": f"{np.percentile(values, 95):.1f}"})
    return rows


def render_replay(run: RunRecord, from_s: float, to_s: float) -> str:
    """The page as one HTML string."""
    data = page_data(run, from_s, to_s)
    leads = lead_times(run.orders, run.moves if len(run.moves) else None, from_s, to_s)
    scenario = run.scenario
    title = f"Replay: {scenario.name} on {run.layout.name}, {scenario.fleet.size} AGVs, " \
            f"seed {scenario.seed}"
    return environment().get_template("replay.html.j2").render(
        title=title, data=data, lead_rows=lead_summary(leads), orders=len(leads),
        scripts=[static_script("replay_kinematics.js"), static_script("replay.js")],
        window=f"{_clock(from_s)} to {_clock(to_s)} of the run "
               f"({scenario.duration_h:g} h, warm-up {scenario.warmup_h:g} h)",
        resimulated=run.resimulated)


def _clock(seconds: float) -> str:
    whole = round(seconds)
    return f"{whole // 3600}:{whole % 3600 // 60:02d}:{whole % 60:02d}"


def write_replay(run_dir: Path, from_h: float | None = None, to_h: float | None = None,
                 progress: ProgressCallback | None = None,
                 writing: Callable[[], None] | None = None) -> Path:
    """Write RUN_DIR/replay.html for the window (hours; default: the whole run), from the run
    directory (re-simulated if it has no moves.parquet: `progress` sees that; `writing` is
    called when the page is being written)."""
    from_s, to_s = check_window(run_dir, from_h, to_h)
    run = load_run(run_dir, progress)
    if writing is not None:
        writing()
    path = run_dir / REPLAY_FILE
    write_text_atomic(path, render_replay(run, from_s, to_s))
    return path
