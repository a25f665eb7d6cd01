"""Congestion per node: where AGVs stood waiting for the way ahead (node_waits.parquet).

An AGV stands at a node between the end of one segment traversal and the start of the next. If
it drives on with work to do (state Moving, or an order assigned while parked), the standing
since it got that work (not the handling or idling before it, nor a park-in manoeuvre) is
waiting for the way ahead. Summed over the measured window (after warm-up), per node, it
equals the engine's blocked time. Needs the engine's occupancy trace, which studies turn on; it
does not change the run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from fleet_sim.model.records import OccupancySpell


def node_waits(occupancy: Sequence[OccupancySpell], events: pd.DataFrame,
               start_s: float, end_s: float) -> pd.DataFrame:
    """Per node: AGV passes, and seconds AGVs with work to do stood there waiting for the way."""
    segs = pd.DataFrame([o for o in occupancy if o.kind == "segment"],
                        columns=["kind", "key", "agv", "start", "end"])
    if segs.empty:
        return pd.DataFrame({"node": pd.Series(dtype="string"),
                             "passes": pd.Series(dtype="int64"),
                             "wait_s": pd.Series(dtype="float64"),
                             "stops": pd.Series(dtype="int64")})
    segs["node"] = segs["key"].str.split(">").str[1]
    spells = _work_spells(events)
    passes: dict[str, int] = {}
    waits: dict[str, float] = {}
    stops: dict[str, int] = {}
    for agv, group in segs.sort_values(["agv", "start"]).groupby("agv", sort=False):
        ends = group["end"].to_numpy()
        starts = group["start"].to_numpy()
        nodes = group["node"].to_numpy()
        for node in nodes[(ends >= start_s) & (ends <= end_s)]:
            passes[node] = passes.get(node, 0) + 1
        # standing at nodes[i] from its arrival until the next departure (a wait still going
        # on at the end of the run is not counted, as the engine does not count it either)
        stand_from, stand_to = ends[:-1], starts[1:]
        sp_from, sp_to = spells.get(int(str(agv)), (np.empty(0), np.empty(0)))
        if len(sp_from) == 0:
            continue
        # the work spell the AGV departs in; it waited from the later of its arrival and the
        # spell's start (handling, idling or a park-in manoeuvre before that is not waiting)
        k = np.searchsorted(sp_from, stand_to, side="right") - 1
        kk = np.maximum(k, 0)
        valid = (k >= 0) & (sp_to[kk] >= stand_to - 1e-9)
        lo = np.clip(np.maximum(stand_from, sp_from[kk]), start_s, end_s)
        hi = np.clip(stand_to, start_s, end_s)
        for i in np.nonzero(valid & (hi - lo > 1e-9))[0]:
            node = nodes[i]
            waits[node] = waits.get(node, 0.0) + float(hi[i] - lo[i])
            stops[node] = stops.get(node, 0) + 1
    names = sorted(set(passes) | set(waits))
    return pd.DataFrame({
        "node": pd.Series(names, dtype="string"),
        "passes": pd.Series([passes.get(n, 0) for n in names], dtype="int64"),
        "wait_s": pd.Series([round(waits.get(n, 0.0), 6) for n in names], dtype="float64"),
        "stops": pd.Series([stops.get(n, 0) for n in names], dtype="int64"),
    })


WORK_SPELL_COLUMNS = ("time_s", "agv", "event", "from_state", "to_state")
"""The columns of events.parquet that node_waits reads."""


def _work_spells(events: pd.DataFrame) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Per AGV, the (start, end) spells in which it has somewhere to go: state Moving (or
    Paused on the way, behind an AGV in a queue among others), or Idle with an order assigned
    (waiting to leave parking) until it moves."""
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    ordered = events.sort_values(["agv", "time_s"], kind="stable")
    for agv, group in ordered.groupby("agv", sort=False):
        starts: list[float] = []
        stops: list[float] = []
        open_at: float | None = None
        for t, event, before, after in zip(group["time_s"], group["event"], group["from_state"],
                                           group["to_state"], strict=True):
            committed = after in ("Moving", "Paused") \
                or (event == "order_assigned" and after == "Idle")
            if committed and open_at is None:
                open_at = float(t)
            elif not committed and before != after and open_at is not None:
                starts.append(open_at)
                stops.append(float(t))
                open_at = None
        if open_at is not None:
            starts.append(open_at)
            stops.append(math.inf)
        out[int(str(agv))] = (np.array(starts, dtype=float), np.array(stops, dtype=float))
    return out

