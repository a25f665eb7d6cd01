"""A run's records as tables (pandas), the Parquet files they are written to, and the run
directory on disk.

The tables are what a planner queries afterwards (events, orders, state of charge); the KPIs
are computed from the records themselves (fleet_sim.analysis.kpis), never read back from here.
Same scenario and seed, same bytes: columns, dtypes and row order are fixed below.

Decisions:

* `ParquetTables` is the one writer of events.parquet, orders.parquet and soc.parquet: a
  `RecordSink` that appends each batch the recorder hands it as one row group (pyarrow's
  ParquetWriter), so a run of any length holds one batch at a time. A run kept in memory is
  written by handing it over to the same sink (`write_run`), in the same batches: both ways
  give the same bytes.
* Each batch goes through the same pandas frame builders as the in-memory tables
  (`events_frame`, `orders_frame`, `soc_frame`) and is written with the schema of an empty
  such frame, pandas metadata included, so `pd.read_parquet` gives back the dtypes of the
  in-memory tables (`string`, nullable `Int64` AGV of an order never assigned).
* Row order: events and SOC samples in the order recorded (time order); orders in the order
  they finished (delivered or failed), then the orders still open at the end in creation
  order (fleet_sim.model.records explains why); sort by order_id for id order.
* A run that fails or is interrupted leaves no half-written table under its final name: the
  files are written as ``.<name>.partial`` and renamed when the run has finished; on an
  exception the partial files are removed. A process killed outright (SIGKILL, the OOM killer)
  can leave ``.*.partial`` files: they are never read, and the next run into the folder
  replaces them. kpis.json and run_info.json are written after the tables.
"""

from __future__ import annotations

import functools
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import yaml

from fleet_sim.analysis.kpis import KpiSums, run_kpis
from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario, resolved
from fleet_sim.config.trace import TraceOrder
from fleet_sim.model.records import (
    BATCH_ROWS,
    EVENT_COLUMNS,
    ChargeWait,
    ErrorRecord,
    EventRecord,
    Fanout,
    Order,
    QueueLength,
    Recorder,
    SocSample,
)
from fleet_sim.sim.engine import ProgressCallback, RunOutput, simulate

ORDER_COLUMNS = ("order_id", "created_s", "pickup", "dropoff", "pickup_node", "dropoff_node",
                 "agv", "assigned_s", "pickup_arrival_s", "picked_s", "dropoff_arrival_s",
                 "delivered_s", "pickup_handling_s", "dropoff_handling_s", "lead_time_s",
                 "failed_s", "failure", "reassigned")
SOC_COLUMNS = SocSample._fields
TABLES = ("events", "orders", "soc")
"""The tables of a run directory, each written to <name>.parquet."""


# ---- rows -> frames ------------------------------------------------------------------------


def events_frame(rows: Sequence[EventRecord]) -> pd.DataFrame:
    """One row per state change and incident (events.parquet)."""
    frame = pd.DataFrame(list(rows), columns=list(EVENT_COLUMNS))
    return frame.astype({"time_s": "float64", "agv": "int64", "event": "string",
                         "from_state": "string", "to_state": "string", "node": "string",
                         "detail": "string"})


def orders_frame(rows: Sequence[Order]) -> pd.DataFrame:
    """One row per order with its timestamps and lead time (orders.parquet)."""
    records = [
        (o.id, o.created_s, o.pickup, o.dropoff, o.pickup_node, o.dropoff_node, o.agv,
         o.assigned_s, o.pickup_arrival_s, o.picked_s, o.dropoff_arrival_s, o.delivered_s,
         o.pickup_handling_s, o.dropoff_handling_s,
         None if o.delivered_s is None else o.delivered_s - o.created_s,
         o.failed_s, o.failure, o.reassigned)
        for o in rows
    ]
    frame = pd.DataFrame(records, columns=list(ORDER_COLUMNS))
    floats = [c for c in ORDER_COLUMNS if c.endswith("_s")]
    frame[floats] = frame[floats].astype("float64")
    frame["order_id"] = frame["order_id"].astype("int64")
    frame["agv"] = frame["agv"].astype("Int64")
    frame["reassigned"] = frame["reassigned"].astype("int64")
    for column in ("pickup", "dropoff", "pickup_node", "dropoff_node", "failure"):
        frame[column] = frame[column].astype("string")
    return frame


def soc_frame(rows: Sequence[SocSample]) -> pd.DataFrame:
    """State of charge of every AGV at each of its state changes (for battery plots)."""
    frame = pd.DataFrame(list(rows), columns=list(SOC_COLUMNS))
    return frame.astype({"time_s": "float64", "agv": "int64", "soc_pct": "float64"})


# ---- tables of a run kept in memory --------------------------------------------------------


def events_table(recorder: Recorder) -> pd.DataFrame:
    """events.parquet of a run kept in memory."""
    return events_frame(recorder.events)


def orders_table(recorder: Recorder) -> pd.DataFrame:
    """orders.parquet of a run kept in memory, in the file's row order (finished, then open)."""
    return orders_frame([*recorder.finished, *recorder.open_orders.values()])


def soc_table(recorder: Recorder) -> pd.DataFrame:
    """soc.parquet of a run kept in memory."""
    return soc_frame(recorder.soc_samples)


# ---- the Parquet files ---------------------------------------------------------------------


@functools.cache
def table_schema(name: str) -> pa.Schema:
    """The Arrow schema of table `name`, pandas metadata included (that of an empty frame)."""
    frames = {"events": events_frame([]), "orders": orders_frame([]), "soc": soc_frame([])}
    return pa.Table.from_pandas(frames[name], preserve_index=False).schema


class ParquetTables:
    """A `RecordSink` writing events.parquet, orders.parquet and soc.parquet into `out_dir`, a
    row group per batch; the files get their names on `close()` (see the module). Used as a
    context manager, it removes its partial files when the block raises."""

    def __init__(self, out_dir: Path) -> None:
        out_dir.mkdir(parents=True, exist_ok=True)
        self.out_dir = out_dir
        self._writers: dict[str, pq.ParquetWriter] = {}
        for name in TABLES:
            self._writers[name] = pq.ParquetWriter(self._partial(name), table_schema(name))

    def _partial(self, name: str) -> Path:
        return self.out_dir / f".{name}.parquet.partial"

    def _write(self, name: str, frame: pd.DataFrame) -> None:
        table = pa.Table.from_pandas(frame, schema=table_schema(name), preserve_index=False)
        self._writers[name].write_table(table)

    def events(self, rows: Sequence[EventRecord]) -> None:
        self._write("events", events_frame(rows))

    def orders(self, rows: Sequence[Order]) -> None:
        self._write("orders", orders_frame(rows))

    def soc_samples(self, rows: Sequence[SocSample]) -> None:
        self._write("soc", soc_frame(rows))

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        """Not a table (the KPIs' sums take them)."""

    def charge_waits(self, rows: Sequence[ChargeWait]) -> None:
        """Not a table (the KPIs' sums take them)."""

    def errors(self, rows: Sequence[ErrorRecord]) -> None:
        """Not a table: every Error is also a row of events.parquet."""

    def close(self) -> None:
        """The run finished: close the files and give them their names."""
        writers, self._writers = self._writers, {}
        for name, writer in writers.items():
            writer.close()
            os.replace(self._partial(name), self.out_dir / f"{name}.parquet")

    def abort(self) -> None:
        """The run did not finish: close and remove the partial files."""
        writers, self._writers = self._writers, {}
        for name, writer in writers.items():
            writer.close()
            self._partial(name).unlink(missing_ok=True)

    def __enter__(self) -> ParquetTables:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 trace: TracebackType | None) -> None:
        if kind is not None:
            self.abort()


# ---- the run directory ---------------------------------------------------------------------


@dataclass(frozen=True)
class RunTables:
    """The tables of one run, read back from its run directory."""

    events: pd.DataFrame
    orders: pd.DataFrame
    soc: pd.DataFrame


def read_tables(out_dir: Path) -> RunTables:
    """The tables of a run directory, in memory (for tests and small runs)."""
    return RunTables(*(pd.read_parquet(out_dir / f"{name}.parquet") for name in TABLES))


def stream_run(scenario: Scenario, layout: Layout, out_dir: Path,
               trace: Sequence[TraceOrder] = (), progress: ProgressCallback | None = None,
               record_occupancy: bool = False,
               batch_rows: int = BATCH_ROWS) -> tuple[RunOutput, dict[str, Any]]:
    """Run the scenario, its tables streamed into `out_dir` as it goes and its KPIs summed on
    the way, and write the run directory (`fleet-sim run` and every sweep run). Returns the
    run (its recorder holds the running totals, not the rows) and its KPIs."""
    sums = KpiSums(scenario.warmup_s, scenario.duration_s)
    with ParquetTables(out_dir) as tables:
        run = simulate(scenario, layout, trace, progress, record_occupancy,
                       sink=Fanout(sums, tables), batch_rows=batch_rows)
    figures = run_kpis(run, sums)
    _write_run_files(run, out_dir, figures)
    return run, figures


def write_run(run: RunOutput, out_dir: Path, figures: dict[str, Any]) -> None:
    """Write the run directory of a run kept in memory: the same files, and the same bytes, as
    `stream_run` writes for it."""
    with ParquetTables(out_dir) as tables:
        run.recorder.hand_over(tables)
    _write_run_files(run, out_dir, figures)


def _write_run_files(run: RunOutput, out_dir: Path, figures: dict[str, Any]) -> None:
    """Beside the tables: resolved config, kpis.json (`figures`) and run_info.json (wall time,
    events simulated)."""
    (out_dir / "config.resolved.yaml").write_text(
        yaml.safe_dump(resolved(run.scenario), sort_keys=False, allow_unicode=True),
        encoding="utf-8")
    (out_dir / "kpis.json").write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
    info = {"wall_s": round(run.wall_s, 3), "sim_events": run.sim_events,
            "sim_hours_per_wall_s": round(run.scenario.duration_h / max(run.wall_s, 1e-9), 3)}
    (out_dir / "run_info.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
