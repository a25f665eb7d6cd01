"""`fleet-sim replay RUN_DIR`: RUN_DIR/replay.html, one self-contained page that draws the layout
and animates every AGV at its recorded times, with its per-AGV timeline (Gantt) and the order
lead-time breakdown.

Decisions, where the issue is silent:

* Plain canvas and our own JavaScript (static/replay.js, its kinematics twin in
  static/replay_kinematics.js: plain files, inlined into the page by `render.static_script`, so
  the page stays one file): no library, nothing fetched. The data is one JSON block in
  the page (Jinja2's `tojson`, which escapes `<`, `>`, `&` and `'`, so no name from a user file
  can end the script); names reach the page only as canvas text and `textContent`, never as
  markup. A Content-Security-Policy meta tag (`default-src 'none'`, inline script and style,
  data: images) makes the browser refuse any request the page might try.
* The JSON is columnar (one list per field) and interned: times rounded to the millisecond
  (an AGV at 1 m/s moves 1 mm in that time), each distinct hop profile (segment, entry and exit
  speed, curve, limit) written once and drive rows pointing at it, every text once in
  `strings`. Deterministic: keys sorted, no timestamp, no random id; same run and window, same
  bytes. Its every object and field is described once, in fleet_sim.report.replay_payload
  (TypedDicts that mypy holds `page_data` to, and that replay.js's JSDoc typedefs come from).
* The window (`--from/--to`, hours of simulated time since the start) cuts every table to what
  is needed from `from` to `to`: the rows that overlap it, plus for each AGV the last
  placement before it (where it stands when the window opens) and its state, order and SOC then.
* Parked AGVs are drawn side by side in a small grid beside their parking area's node; the
  page's `positionsAt(t)` gives the recorded position (the node), `drawn` what was drawn.
* Colours: the states' are the report's (fleet_sim.report.figures.STATE_COLOURS), the places'
  and traffic zones' the layout drawing's (fleet_sim.report.layout_plot).
* Traffic zones are drawn under the track as the layout drawing draws them: mutex and ban
  zones as dashed outlines round their nodes, same-direction zones as a band along the aisle
  with an arrow the forward way; each labelled with its id and rule, and, for mutex and
  same-direction zones, live while anyone holds or waits for it: how many AGVs hold it (and,
  for a same-direction zone, the way they drive it, its arrow turned that way) and how many
  wait for it, from the run's zone rows (fleet_sim.analysis.replay.zone_holders_at is the
  Python twin). The side panel lists each zone's holders and waiters by AGV.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
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
from fleet_sim.config.scenario import load_scenario
from fleet_sim.errors import InputError
from fleet_sim.model.states import VehicleState
from fleet_sim.report.figures import LEAD_COLOURS, STATE_COLOURS
from fleet_sim.report.layout_plot import KIND_STYLE, PLACE_COLOUR, ZONE_COLOUR, zone_rule
from fleet_sim.report.render import environment, static_script
from fleet_sim.report.replay_payload import Agv, Leads, ReplayPayload
from userfiles.writing import write_text_atomic

REPLAY_FILE = "replay.html"
KIND_CODES = {"drive": 0, "track": 1, "parking": 2, "off": 3}
STATE_INDEX = {s.value: i for i, s in enumerate(VehicleState)}
"""How the page's positional rows name their kind."""

ProgressCallback = Callable[[float, float], None]
_DIRECTION = {"forward": 1, "backward": -1}
"""How the page's zone rows name the way a same-direction zone is driven (0: a mutex zone)."""


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


def page_data(run: RunRecord, from_s: float, to_s: float) -> ReplayPayload:
    """Everything the page draws, as JSON-ready columns (see the module docstring; every field
    is described in fleet_sim.report.replay_payload)."""
    layout = run.layout
    scenario = run.scenario
    text = _Strings()
    node_ids = sorted(layout.graph.nodes)
    node_index = {n: i for i, n in enumerate(node_ids)}
    place_of = {node: place for place in layout.places.values() for node in place.nodes}
    edges = sorted(layout.graph.edges)
    edge_index = {e: i for i, e in enumerate(edges)}
    corridors = {f"corridor {c.id}": sorted(edge_index[s] for s in c.segments)
                 for c in layout.corridors}

    moves = run.moves
    profiles: dict[tuple[int, float, float, float, float, float, float, float], int] = {}
    agvs: list[Agv] = []
    spells = state_spells(run.events, from_s, to_s)
    held = orders_held(run.events)
    fleet = scenario.fleet.size
    profiles_by_agv = scenario.fleet.agv_profiles
    by_agv = {int(str(a)): g for a, g in moves.groupby("agv", sort=True)} if len(moves) else {}
    soc_by_agv = {int(str(a)): g for a, g in run.soc.groupby("agv", sort=True)}
    spells_by_agv = {int(str(a)): g for a, g in spells.groupby("agv", sort=True)}
    for agv in range(fleet):
        rows = by_agv.get(agv, moves.iloc[0:0])
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
                key = (edge_index[(u, v)], float(vin), float(vout), float(cm), float(cv),
                       float(lim), float(acc), float(dec))
                p_ref.append(profiles.setdefault(key, len(profiles)))
            else:
                p_ref.append(node_index[u])
        waits = rows[(rows["kind"] == "wait") & (rows["end_s"] >= from_s)
                     & (rows["start_s"] <= to_s)]
        mine = spells_by_agv.get(agv, spells.iloc[0:0])
        times, ids = held.get(agv, (np.empty(0), np.empty(0, dtype=np.int64)))
        first = max(int(np.searchsorted(times, from_s, side="right")) - 1, 0)
        keep = slice(first, int(np.searchsorted(times, to_s, side="right")))
        soc = soc_by_agv.get(agv, run.soc.iloc[0:0])
        soc_t = soc["time_s"].to_numpy(dtype=float)
        soc_keep = slice(max(int(np.searchsorted(soc_t, from_s, side="right")) - 1, 0),
                         int(np.searchsorted(soc_t, to_s, side="right")))
        agvs.append({
            "id": agv, "length_m": profiles_by_agv[agv].length_m,
            "p": {"t": _ms(positional["start_s"]), "e": _ms(positional["end_s"]),
                  "k": [KIND_CODES[k] for k in positional["kind"].tolist()],
                  "a": p_ref, "d": _ms(positional["driven_s"])},
            "s": {"t": _ms(mine["start_s"]), "e": _ms(mine["end_s"]),
                  "st": [STATE_INDEX[s] for s in mine["state"].tolist()],
                  "ev": text.many(mine["event"].tolist()),
                  "det": text.many(mine["detail"].tolist()),
                  "o": [int(o) for o in mine["order_id"].tolist()],
                  "l": [int(bool(x)) for x in mine["loaded"].tolist()]},
            "o": {"t": _ms(times[keep]), "id": [int(o) for o in ids[keep]]},
            "b": {"t": _ms(soc_t[soc_keep]),
                  "v": [round(float(v), 1) for v in soc["soc_pct"].to_numpy()[soc_keep]]},
            "w": {"t": _ms(waits["start_s"]), "e": _ms(waits["end_s"]),
                  "n": [node_index[u] for u in waits["u"].tolist()],
                  "lock": text.many(waits["v"].tolist()),
                  "h": [int(h) for h in waits["other"].tolist()]},
        })
    charger_waits = moves[(moves["kind"] == "charger_wait") & (moves["end_s"] >= from_s)
                          & (moves["start_s"] <= to_s)] if len(moves) else moves
    places = sorted(layout.places.values(), key=lambda p: p.id)
    place_index = {p.id: i for i, p in enumerate(places)}
    found = incidents(run.events)
    found = found[(found["time_s"] >= from_s) & (found["time_s"] <= to_s)]
    leads = lead_times(run.orders, moves if len(moves) else None, from_s, to_s)
    profile_keys = list(profiles)
    zones = layout.traffic_zones
    zone_index = {z.id: i for i, z in enumerate(zones)}
    holds = moves[(moves["kind"] == "zone") & (moves["end_s"] >= from_s)
                  & (moves["start_s"] <= to_s)] if len(moves) else moves
    holds = holds[holds["u"].isin(list(zone_index))] if len(holds) else holds
    return {
        "meta": {
            "scenario": scenario.name, "layout": layout.name, "agvs": fleet,
            "seed": scenario.seed, "duration_s": scenario.duration_s,
            "warmup_s": scenario.warmup_s, "start_h": scenario.start_h,
            "from_s": from_s, "to_s": to_s,
            "resimulated": run.resimulated,
        },
        "states": [s.value for s in VehicleState],
        "stateColours": [STATE_COLOURS.get(s.key, "#80868b") for s in VehicleState],
        "nodes": {
            "id": node_ids,
            "x": [float(layout.graph.nodes[n]["x"]) for n in node_ids],
            "y": [float(layout.graph.nodes[n]["y"]) for n in node_ids],
            "kind": [str(layout.graph.nodes[n]["kind"]) for n in node_ids],
            "colour": [PLACE_COLOUR[place_of[n].kind] if n in place_of
                       else KIND_STYLE.get(str(layout.graph.nodes[n]["kind"]),
                                           ("#9aa0a6", 0))[0] for n in node_ids],
            "place": [place_index[place_of[n].id] if n in place_of else -1 for n in node_ids],
        },
        "segs": {"u": [node_index[u] for u, _ in edges], "v": [node_index[v] for _, v in edges],
                 "len": [float(layout.graph.edges[e]["length_m"]) for e in edges],
                 "twoWay": [int(layout.graph.has_edge(v, u)) for u, v in edges]},
        "corridors": corridors,
        "places": {"id": [p.id for p in places], "kind": [p.kind for p in places],
                   "node": [node_index[p.nodes[0]] for p in places],
                   "capacity": [p.capacity for p in places]},
        "profiles": {"seg": [k[0] for k in profile_keys], "vin": [k[1] for k in profile_keys],
                     "vout": [k[2] for k in profile_keys], "cm": [k[3] for k in profile_keys],
                     "cv": [k[4] for k in profile_keys], "lim": [k[5] for k in profile_keys],
                     "acc": [k[6] for k in profile_keys], "dec": [k[7] for k in profile_keys]},
        "agv": agvs,
        "chargerWaits": {
            "agv": [int(a) for a in charger_waits["agv"]],
            "t": _ms(charger_waits["start_s"]), "e": _ms(charger_waits["end_s"]),
            "n": [node_index[u] for u in charger_waits["u"].tolist()],
            "ch": [place_index.get(str(v), -1) for v in charger_waits["v"].tolist()]},
        "zones": {"id": [z.id for z in zones], "kind": [z.kind for z in zones],
                  "rule": [zone_rule(z) for z in zones],
                  "colour": [ZONE_COLOUR[z.kind] for z in zones],
                  "nodes": [[node_index[n] for n in sorted(z.nodes | set(z.path))]
                            for z in zones],
                  "path": [[node_index[n] for n in z.path] for z in zones]},
        "zoneHolds": {"agv": [int(a) for a in holds["agv"]],
                      "t": _ms(holds["start_s"]), "e": _ms(holds["end_s"]),
                      "z": [zone_index[str(u)] for u in holds["u"].tolist()],
                      "dir": [_DIRECTION.get(str(v), 0) for v in holds["v"].tolist()]},
        "blocks": [{"u": node_index[b.from_node], "v": node_index[b.to_node],
                    "t": b.at_s, "e": b.at_s + b.duration_s}
                   for b in scenario.incidents.blocks],
        "incidents": {"t": _ms(found["time_s"]), "agv": [int(a) for a in found["agv"]],
                      "kind": text.many(found["kind"]), "code": text.many(found["code"]),
                      "det": text.many(found["detail"])},
        "leads": _leads(leads),
        "strings": text.strings,
    }


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
