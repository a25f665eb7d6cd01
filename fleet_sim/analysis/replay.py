"""What each AGV did and where it was, read back from a run directory: the data of the replay
(`fleet-sim replay`, drawn by fleet_sim.report.replay), of the per-AGV timeline and of the order
lead-time breakdown.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from fleet_sim.analysis.tables import (
    MOVES,
    SortedTable,
    events_table,
    moves_frame,
    table_schema,
)
from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario, load_layout_for, load_scenario
from fleet_sim.config.trace import load_trace
from fleet_sim.errors import InputError
from fleet_sim.model.kinematics import Piece, distance_at
from fleet_sim.model.records import Recorder

MOVES_FILE = f"{MOVES}.parquet"
CONFIG_FILE = "config.resolved.yaml"
POSITIONAL = ("drive", "track", "parking", "off")
"""Kinds of move rows that say where an AGV is (waits and charger waits do not move it)."""

ProgressCallback = Callable[[float, float], None]

_ORDER = re.compile(r"\border (\d+)")


# ---- the moves table ------------------------------------------------------------------------


def moves_table(recorder: Recorder) -> pd.DataFrame:
    """One row per drive, lock wait and placement (moves.parquet), by AGV and start time; rows
    that start together keep the order they happened in."""
    frame = moves_frame(recorder.moves)
    return frame.sort_values(["agv", "start_s"], kind="stable").reset_index(drop=True)


def write_moves(recorder: Recorder, run_dir: Path) -> Path:
    """moves.parquet of a run kept in memory, by its one writer (fleet_sim.analysis.tables;
    `fleet-sim run --replay` streams it as the run goes)."""
    path = run_dir / MOVES_FILE
    table = SortedTable(path, table_schema(MOVES), "start_s", "agv", recorder.batch_rows)
    try:
        for start in range(0, len(recorder.moves), recorder.batch_rows):
            table.add(pa.Table.from_pandas(
                moves_frame(recorder.moves[start:start + recorder.batch_rows]),
                schema=table_schema(MOVES), preserve_index=False))
        table.close(table_schema(MOVES))
        table.commit()
    except BaseException:
        table.abort()
        raise
    return path


# ---- a run directory, read back ---------------------------------------------------------------


@dataclass(frozen=True)
class RunRecord:
    """A finished run as its directory holds it, with the moves (read or re-simulated)."""

    run_dir: Path
    scenario: Scenario
    layout: Layout
    events: pd.DataFrame
    orders: pd.DataFrame
    soc: pd.DataFrame
    moves: pd.DataFrame
    resimulated: bool
    """True if the moves come from a re-run of config.resolved.yaml."""


def load_run(run_dir: Path, progress: ProgressCallback | None = None,
             resimulate: bool = True) -> RunRecord:
    """Read a run directory (of `fleet-sim run`, or a sweep's runs/<id>). Without moves.parquet
    the run is simulated again (`progress` sees it), unless `resimulate` is False: then the
    moves are empty."""
    config = run_dir / CONFIG_FILE
    for name in (CONFIG_FILE, "events.parquet", "orders.parquet"):
        if not (run_dir / name).is_file():
            raise InputError(str(run_dir), "run directory", str(run_dir),
                             f"a run directory of `fleet-sim run` or a sweep (with {name})")
    scenario = load_scenario(config)
    layout = load_layout_for(scenario, str(config))
    if scenario.motion != "closed_form":
        raise InputError(str(config), "motion", scenario.motion,
                         "closed_form: a replay draws the closed-form speed profile, and with "
                         "SUMO moving the AGVs their positions between nodes are not recorded")
    events = pd.read_parquet(run_dir / "events.parquet")
    orders = pd.read_parquet(run_dir / "orders.parquet")
    soc_file = run_dir / "soc.parquet"
    soc = pd.read_parquet(soc_file) if soc_file.is_file() else pd.DataFrame(
        {"time_s": pd.Series(dtype="float64"), "agv": pd.Series(dtype="int64"),
         "soc_pct": pd.Series(dtype="float64")})
    moves_file = run_dir / MOVES_FILE
    if moves_file.is_file():
        return RunRecord(run_dir, scenario, layout, events, orders, soc,
                         pd.read_parquet(moves_file), False)
    if not resimulate:
        return RunRecord(run_dir, scenario, layout, events, orders, soc,
                         moves_table(Recorder(0.0, 0.0)), False)
    from fleet_sim.sim.engine import simulate

    trace = []
    if scenario.demand.kind == "trace":
        assert scenario.demand.trace_csv is not None
        trace = load_trace(scenario.path(scenario.demand.trace_csv), layout)
    run = simulate(scenario, layout, trace, progress=progress, record_moves=True)
    again = events_table(run.recorder)
    if not _same_events(again, events):
        raise InputError(str(run_dir / "events.parquet"), "events", f"{len(events)} rows",
                         f"the events of a re-run of {CONFIG_FILE} ({len(again)} rows, not "
                         "the same): the run cannot be reproduced, it was probably made by "
                         "another version of fleet_sim; run it again with "
                         "`fleet-sim run ... --replay`")
    return RunRecord(run_dir, scenario, layout, events, orders, soc,
                     moves_table(run.recorder), True)


def _same_events(a: pd.DataFrame, b: pd.DataFrame) -> bool:
    if list(a.columns) != list(b.columns) or len(a) != len(b):
        return False
    for column in a.columns:
        x, y = a[column].to_numpy(), b[column].to_numpy()
        if x.dtype.kind == "f" or y.dtype.kind == "f":
            if not np.array_equal(x.astype(float), y.astype(float)):
                return False
        elif [str(v) for v in x] != [str(v) for v in y]:
            return False
    return True


# ---- who holds each traffic zone ---------------------------------------------------------------


def zone_holders_at(moves: pd.DataFrame, t_s: float) -> dict[str, list[tuple[int, str]]]:
    """Zone id -> (AGV, direction) of every AGV holding the zone at `t_s` (direction
    "forward" or "backward" for a same-direction zone, "" for a mutex zone), by AGV; zones
    nobody holds are left out. A hold given back at `t_s` is over."""
    holds = moves[(moves["kind"] == "zone") & (moves["start_s"] <= t_s) & (moves["end_s"] > t_s)]
    out: dict[str, list[tuple[int, str]]] = {}
    for agv, zone, direction in zip(holds["agv"].tolist(), holds["u"].tolist(),
                                    holds["v"].tolist(), strict=True):
        out.setdefault(str(zone), []).append((int(agv), str(direction)))
    return {z: sorted(h) for z, h in sorted(out.items())}


# ---- where each AGV is -------------------------------------------------------------------------


@dataclass(frozen=True)
class Position:
    """Where an AGV is: floor coordinates, and on what."""

    x_m: float
    y_m: float
    where: str
    """"track", "parking" (in the area beside the track through `node`) or "off" (taken off
    the track by an operator, where it stood)."""
    node: str
    """The node it is at or drove from."""
    to_node: str = ""
    """On a segment: the node it drives to ("" at a node)."""
    along_m: float = 0.0
    """On a segment: how far from `node`."""


def hop_pieces(length_m: float, curve_m: float, curve_mps: float,
               limit_mps: float) -> tuple[Piece, ...]:
    """A drive row's pieces: the curve (if it turns), then the rest of the segment."""
    if curve_m > 0.0:
        return ((curve_m, curve_mps), (length_m - curve_m, limit_mps))
    return ((length_m, limit_mps),)


def positions_at(moves: pd.DataFrame, layout: Layout, t_s: float) -> dict[int, Position]:
    """Where every AGV placed by time `t_s` is at `t_s`, from the moves (see the module
    docstring). The engine's own record of the motion: the replay page draws the same."""
    out: dict[int, Position] = {}
    rows = moves[moves["kind"].isin(POSITIONAL)]
    for agv, group in rows.groupby("agv", sort=True):
        group = group[group["start_s"] <= t_s]
        if group.empty:
            continue
        out[int(str(agv))] = _position(group, len(group) - 1, t_s, layout)
    return out


def _position(rows: pd.DataFrame, i: int, t_s: float, layout: Layout) -> Position:
    row = rows.iloc[i]
    kind = str(row["kind"])
    u = str(row["u"])
    if kind == "drive":
        v = str(row["v"])
        length = float(layout.graph.edges[u, v]["length_m"])
        pieces = hop_pieces(length, float(row["curve_m"]), float(row["curve_mps"]),
                            float(row["limit_mps"]))
        driven = float(row["driven_s"]) + min(t_s, float(row["end_s"])) - float(row["start_s"])
        along = distance_at(pieces, float(row["v_in_mps"]), float(row["v_out_mps"]),
                            float(row["accel_mps2"]), float(row["decel_mps2"]), driven)
        (x0, y0), (x1, y1) = layout.position(u), layout.position(v)
        share = along / length
        if along >= length:
            return Position(x1, y1, "track", v)
        return Position(x0 + (x1 - x0) * share, y0 + (y1 - y0) * share, "track", u, v, along)
    if kind == "off":
        if i == 0:
            x, y = layout.position(u)
            return Position(x, y, "off", u)
        before = _position(rows, i - 1, float(row["start_s"]), layout)
        return Position(before.x_m, before.y_m, "off", before.node, before.to_node,
                        before.along_m)
    x, y = layout.position(u)
    return Position(x, y, kind, u)


# ---- the timeline ------------------------------------------------------------------------------


def state_spells(events: pd.DataFrame, start_s: float, end_s: float) -> pd.DataFrame:
    """Per AGV, one row per spell in a state within [start_s, end_s]: agv, start_s, end_s,
    state, event (that started it), detail (its reason), order_id (-1: none), loaded."""
    columns = {"agv": "int64", "start_s": "float64", "end_s": "float64", "state": "string",
               "event": "string", "detail": "string", "order_id": "int64", "loaded": "bool"}
    rows: list[tuple[int, float, float, str, str, str, int, bool]] = []
    ordered = events.sort_values(["agv", "time_s"], kind="stable")
    for agv, group in ordered.groupby("agv", sort=True):
        order, loaded = -1, False
        spells: list[tuple[float, str, str, str, int, bool]] = []
        for t, event, before, after, detail in zip(
                *(group[c].tolist() for c in ("time_s", "event", "from_state", "to_state",
                                              "detail")), strict=True):
            if event == "order_assigned":
                found = _ORDER.search(detail)
                order = int(found.group(1)) if found else -1
            elif event in ("order_reassigned", "Event_Unload_Complete", "Event_Critical_Error"):
                order = -1
            if event == "Event_Load_Complete":
                loaded = True
            elif event in ("Event_Unload_Complete", "Event_Critical_Error"):
                loaded = False
            if before != after:
                spells.append((float(t), after, event, detail, order, loaded))
        for k, (t, state, event, detail, order_id, is_loaded) in enumerate(spells):
            until = spells[k + 1][0] if k + 1 < len(spells) else end_s
            lo, hi = max(t, start_s), min(until, end_s)
            if hi > lo:
                rows.append((int(str(agv)), lo, hi, state, event, detail, order_id, is_loaded))
    frame = pd.DataFrame(rows, columns=list(columns))
    return frame.astype(columns)


def orders_held(events: pd.DataFrame) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Per AGV, the times its order changed and the order from then on (-1: none)."""
    out: dict[int, tuple[list[float], list[int]]] = {}
    picked = events[events["event"].astype(str).isin(
        ("order_assigned", "order_reassigned", "Event_Unload_Complete", "Event_Critical_Error"))]
    for t, agv, event, detail in zip(
            *(picked[c].tolist() for c in ("time_s", "agv", "event", "detail")), strict=True):
        order = -1
        if event == "order_assigned":
            found = _ORDER.search(detail)
            order = int(found.group(1)) if found else -1
        times, ids = out.setdefault(int(agv), ([], []))
        times.append(float(t))
        ids.append(order)
    return {a: (np.array(t, dtype=float), np.array(o, dtype=np.int64))
            for a, (t, o) in sorted(out.items())}


def incidents(events: pd.DataFrame) -> pd.DataFrame:
    """What a planner jumps to: deadlocks and errors, in time order (time_s, agv, kind, code,
    detail); `code` is the error code (E_101...) of an error."""
    kind = events["event"].astype(str)
    dead = events[kind.isin(("deadlock_detected", "deadlock_unresolved"))]
    err = events[kind == "Event_Critical_Error"]
    frame = pd.concat([
        pd.DataFrame({"time_s": dead["time_s"], "agv": dead["agv"], "kind": "deadlock",
                      "code": "", "detail": dead["event"].astype(str) + ": "
                      + dead["detail"].astype(str)}),
        pd.DataFrame({"time_s": err["time_s"], "agv": err["agv"], "kind": "error",
                      "code": err["detail"].astype(str).str.split().str[0].fillna(""),
                      "detail": err["detail"].astype(str)})])
    frame = frame.sort_values(["time_s", "agv"], kind="stable").reset_index(drop=True)
    return frame.astype({"time_s": "float64", "agv": "int64", "kind": "string",
                         "code": "string", "detail": "string"})


# ---- lead times ----------------------------------------------------------------------------------

LEAD_PARTS = ("wait_assign_s", "drive_empty_s", "load_s", "drive_loaded_s", "unload_s",
              "blocked_s")
"""The parts of an order's lead time, in the order they come (blocked: within the drives)."""
LEAD_LABELS: Mapping[str, str] = {
    "wait_assign_s": "wait for assignment", "drive_empty_s": "drive empty", "load_s": "load",
    "drive_loaded_s": "drive loaded", "unload_s": "unload", "blocked_s": "blocked by traffic"}


def lead_times(orders: pd.DataFrame, moves: pd.DataFrame | None, start_s: float = 0.0,
               end_s: float = math.inf) -> pd.DataFrame:
    """Per order delivered within [start_s, end_s]: order_id, agv, created_s, delivered_s,
    lead_time_s and its parts (LEAD_PARTS), which add up to it. Without moves the blocked time
    is unknown: blocked_s is NaN and the drives keep it."""
    done = orders[orders["delivered_s"].notna() & orders["agv"].notna()]
    done = done[(done["delivered_s"] >= start_s) & (done["delivered_s"] <= end_s)]
    done = done.sort_values("order_id", kind="stable")
    assigned = done["assigned_s"].to_numpy(dtype=float)
    arrive_pick = done["pickup_arrival_s"].to_numpy(dtype=float)
    picked = done["picked_s"].to_numpy(dtype=float)
    arrive_drop = done["dropoff_arrival_s"].to_numpy(dtype=float)
    delivered = done["delivered_s"].to_numpy(dtype=float)
    agvs = done["agv"].to_numpy(dtype=np.int64)
    blocked_empty = np.full(len(done), math.nan)
    blocked_loaded = np.full(len(done), math.nan)
    if moves is not None:
        blocked_empty[:] = 0.0
        blocked_loaded[:] = 0.0
        waits = moves[moves["kind"] == "wait"]
        for agv, group in waits.groupby("agv", sort=True):
            mine = agvs == int(str(agv))
            if not mine.any():
                continue
            starts = group["start_s"].to_numpy(dtype=float)
            ends = group["end_s"].to_numpy(dtype=float)

            def waited(x: np.ndarray, starts: np.ndarray = starts,
                       ends: np.ndarray = ends) -> np.ndarray:
                return _waited_before(starts, ends, x)

            blocked_empty[mine] = waited(arrive_pick[mine]) - waited(assigned[mine])
            blocked_loaded[mine] = waited(arrive_drop[mine]) - waited(picked[mine])
    created = done["created_s"].to_numpy(dtype=float)
    frame = pd.DataFrame({
        "order_id": done["order_id"].to_numpy(dtype=np.int64),
        "agv": agvs,
        "created_s": created,
        "delivered_s": delivered,
        "lead_time_s": delivered - created,
        "wait_assign_s": assigned - created,
        "drive_empty_s": arrive_pick - assigned - np.nan_to_num(blocked_empty),
        "load_s": picked - arrive_pick,
        "drive_loaded_s": arrive_drop - picked - np.nan_to_num(blocked_loaded),
        "unload_s": delivered - arrive_drop,
        "blocked_s": blocked_empty + blocked_loaded,
    })
    return frame.reset_index(drop=True)


def _waited_before(starts: np.ndarray, ends: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Seconds spent in the (sorted, disjoint) waits before each time in `x`."""
    if len(starts) == 0:
        return np.zeros(len(x))
    k = np.searchsorted(starts, x, side="right")
    full = np.concatenate([[0.0], np.cumsum(ends - starts)])
    last = np.maximum(k - 1, 0)
    part = np.clip(x - starts[last], 0.0, ends[last] - starts[last])
    return np.where(k > 0, full[last] + part, 0.0)
