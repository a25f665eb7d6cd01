"""A run's records as tables (pandas), and the run directory on disk.

The tables are what a planner queries afterwards (events, orders, state of charge); the KPIs
are computed from the records themselves (fleet_sim.analysis.kpis), never read back from here.
Same scenario and seed, same bytes: columns, dtypes and row order are fixed below.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import yaml

from fleet_sim.config.scenario import resolved
from fleet_sim.model.records import EVENT_COLUMNS, Recorder
from fleet_sim.sim.engine import RunOutput

ORDER_COLUMNS = ("order_id", "created_s", "pickup", "dropoff", "pickup_node", "dropoff_node",
                 "agv", "assigned_s", "pickup_arrival_s", "picked_s", "dropoff_arrival_s",
                 "delivered_s", "pickup_handling_s", "dropoff_handling_s", "lead_time_s",
                 "failed_s", "failure", "reassigned")

STOPS_COLUMN = "stops"
"""Added after ORDER_COLUMNS when a run has multi-stop orders: each order's chain of stations
(plain orders: "pickup>dropoff"). Runs without them keep the columns above, byte for byte."""


def events_table(recorder: Recorder) -> pd.DataFrame:
    """One row per state change and incident (events.parquet)."""
    frame = pd.DataFrame(recorder.events, columns=list(EVENT_COLUMNS))
    return frame.astype({"time_s": "float64", "agv": "int64", "event": "string",
                         "from_state": "string", "to_state": "string", "node": "string",
                         "detail": "string"})


def orders_table(recorder: Recorder) -> pd.DataFrame:
    """One row per order with its timestamps and lead time (orders.parquet). A multi-stop
    order's timestamps are those of its first pickup and last dropoff; its lead time runs
    from creation to the last dropoff."""
    rows = [
        (o.id, o.created_s, o.pickup, o.dropoff, o.pickup_node, o.dropoff_node, o.agv,
         o.assigned_s, o.pickup_arrival_s, o.picked_s, o.dropoff_arrival_s, o.delivered_s,
         o.pickup_handling_s, o.dropoff_handling_s,
         None if o.delivered_s is None else o.delivered_s - o.created_s,
         o.failed_s, o.failure, o.reassigned)
        for o in recorder.orders
    ]
    frame = pd.DataFrame(rows, columns=list(ORDER_COLUMNS))
    floats = [c for c in ORDER_COLUMNS if c.endswith("_s")]
    frame[floats] = frame[floats].astype("float64")
    frame["agv"] = frame["agv"].astype("Int64")
    frame["reassigned"] = frame["reassigned"].astype("int64")
    for column in ("pickup", "dropoff", "pickup_node", "dropoff_node", "failure"):
        frame[column] = frame[column].astype("string")
    if any(o.stops for o in recorder.orders):  # multi-stop orders: their chains, "A>B>C>D"
        frame[STOPS_COLUMN] = pd.Series(
            [">".join(o.chain) for o in recorder.orders], dtype="string")
    return frame


def soc_table(recorder: Recorder) -> pd.DataFrame:
    """State of charge of every AGV at each of its state changes (for battery plots)."""
    frame = pd.DataFrame(recorder.soc_samples, columns=["time_s", "agv", "soc_pct"])
    return frame.astype({"time_s": "float64", "agv": "int64", "soc_pct": "float64"})


@dataclass(frozen=True)
class RunTables:
    """The tables of one run, as written to its run directory."""

    events: pd.DataFrame
    orders: pd.DataFrame
    soc: pd.DataFrame


def write_run(run: RunOutput, out_dir: Path, figures: dict[str, Any]) -> RunTables:
    """Write the run directory: resolved config, kpis.json (`figures`), the tables as Parquet
    and run_info.json (wall time, events simulated). Returns the tables."""
    out_dir.mkdir(parents=True, exist_ok=True)
    tables = RunTables(events_table(run.recorder), orders_table(run.recorder),
                       soc_table(run.recorder))
    (out_dir / "config.resolved.yaml").write_text(
        yaml.safe_dump(resolved(run.scenario), sort_keys=False, allow_unicode=True),
        encoding="utf-8")
    (out_dir / "kpis.json").write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
    tables.events.to_parquet(out_dir / "events.parquet", index=False)
    tables.orders.to_parquet(out_dir / "orders.parquet", index=False)
    tables.soc.to_parquet(out_dir / "soc.parquet", index=False)
    info = {"wall_s": round(run.wall_s, 3), "sim_events": run.sim_events,
            "sim_hours_per_wall_s": round(run.scenario.duration_h / max(run.wall_s, 1e-9), 3)}
    (out_dir / "run_info.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    return tables
