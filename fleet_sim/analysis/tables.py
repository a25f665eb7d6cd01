"""A run's records as tables (pandas), the Parquet files they are written to, and the run
directory on disk.

The tables are what a planner queries afterwards (events, orders, state of charge, and with
`--replay` the moves); the KPIs are computed from the records themselves
(fleet_sim.analysis.kpi_sums), never read back from here. Same scenario and seed, same bytes:
columns, dtypes and row order are fixed below.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import yaml

from fleet_sim.analysis.kpi_sums import KpiSums, run_kpis
from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario, resolved
from fleet_sim.config.trace import TraceOrder
from fleet_sim.model.records import (
    BATCH_ROWS,
    EVENT_COLUMNS,
    MOVE_COLUMNS,
    ChargeWait,
    ErrorRecord,
    EventRecord,
    Fanout,
    MoveRecord,
    Order,
    QueueLength,
    Recorder,
    SocSample,
)
from fleet_sim.sim.engine import ProgressCallback, RunOutput, simulate
from userfiles.writing import fsync_path, write_text_atomic

ORDER_COLUMNS = ("order_id", "created_s", "pickup", "dropoff", "pickup_node", "dropoff_node",
                 "agv", "assigned_s", "pickup_arrival_s", "picked_s", "dropoff_arrival_s",
                 "delivered_s", "pickup_handling_s", "dropoff_handling_s", "lead_time_s",
                 "failed_s", "failure", "reassigned")

STOPS_COLUMN = "stops"
"""Added after ORDER_COLUMNS when a run has multi-stop orders: each order's chain of stations
(plain orders: "pickup>dropoff"). Runs without them keep the columns above, byte for byte."""

SOC_COLUMNS = SocSample._fields
TABLES = ("events", "orders", "soc")
"""The tables of every run directory, each written to <name>.parquet."""
MOVES = "moves"
"""The replay's table, moves.parquet, written only when the run records moves."""


# ---- rows -> frames ------------------------------------------------------------------------


def events_frame(rows: Sequence[EventRecord]) -> pd.DataFrame:
    """One row per state change and incident (events.parquet)."""
    frame = pd.DataFrame(list(rows), columns=list(EVENT_COLUMNS))
    return frame.astype({"time_s": "float64", "agv": "int64", "event": "string",
                         "from_state": "string", "to_state": "string", "node": "string",
                         "detail": "string"})


def orders_frame(rows: Sequence[Order], stops: bool = False) -> pd.DataFrame:
    """One row per order with its timestamps and lead time (orders.parquet), and with `stops`
    each order's chain. A multi-stop order's timestamps are those of its first pickup and last
    dropoff; its lead time runs from creation to the last dropoff."""
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
    if stops:  # multi-stop orders: their chains, "A>B>C>D"
        frame[STOPS_COLUMN] = pd.Series([">".join(o.chain) for o in rows], dtype="string")
    return frame


def soc_frame(rows: Sequence[SocSample]) -> pd.DataFrame:
    """State of charge of every AGV at each of its state changes (for battery plots)."""
    frame = pd.DataFrame(list(rows), columns=list(SOC_COLUMNS))
    return frame.astype({"time_s": "float64", "agv": "int64", "soc_pct": "float64"})


def moves_frame(rows: Sequence[MoveRecord]) -> pd.DataFrame:
    """One row per drive, lock wait and placement, in the order given (moves.parquet holds
    them by AGV and start time)."""
    frame = pd.DataFrame(list(rows), columns=list(MOVE_COLUMNS))
    return frame.astype({"agv": "int64", "kind": "string", "start_s": "float64",
                         "end_s": "float64", "u": "string", "v": "string", "other": "int64",
                         "hop_s": "float64", "driven_s": "float64", "v_in_mps": "float64",
                         "v_out_mps": "float64", "curve_m": "float64", "curve_mps": "float64",
                         "limit_mps": "float64", "accel_mps2": "float64",
                         "decel_mps2": "float64"})


# ---- tables of a run kept in memory --------------------------------------------------------


def events_table(recorder: Recorder) -> pd.DataFrame:
    """events.parquet of a run kept in memory."""
    return events_frame(recorder.events)


def orders_table(recorder: Recorder) -> pd.DataFrame:
    """orders.parquet of a run kept in memory (in creation order)."""
    return orders_frame(recorder.orders, stops=any(o.stops for o in recorder.orders))


def soc_table(recorder: Recorder) -> pd.DataFrame:
    """soc.parquet of a run kept in memory."""
    return soc_frame(recorder.soc_samples)


# ---- the Parquet files ---------------------------------------------------------------------


@functools.cache
def table_schema(name: str, stops: bool = False) -> pa.Schema:
    """The Arrow schema of table `name`, pandas metadata included (that of an empty frame);
    `stops`: orders with their chains."""
    frames: dict[str, Callable[[], pd.DataFrame]] = {
        "events": lambda: events_frame([]), "soc": lambda: soc_frame([]),
        MOVES: lambda: moves_frame([]), "orders": lambda: orders_frame([], stops=stops)}
    return pa.Table.from_pandas(frames[name](), preserve_index=False).schema


SEQ = "_seq"
"""The scratch runs' column of each row's place in the order rows came."""


class SortedTable:
    """A Parquet table whose rows come in batches in one order and are written in another:
    by `group` (if any), then `key`, rows with equal keys in the order they came. Each batch is
    sorted and appended to a scratch Arrow IPC file as runs (one per group value); `close`
    merges the runs into `path`, in row groups of `batch_rows` rows (see the module)."""

    def __init__(self, path: Path, schema: pa.Schema, key: str, group: str | None,
                 batch_rows: int) -> None:
        self.path, self.key, self.group, self.batch_rows = path, key, group, batch_rows
        self.schema = schema.remove_metadata().append(pa.field(SEQ, pa.int64()))
        self.scratch = path.with_name(f".{path.name}.runs.partial")
        self.partial = path.with_name(f".{path.name}.partial")
        self._writer: pa.ipc.RecordBatchFileWriter | None = pa.ipc.new_file(
            str(self.scratch), self.schema)
        self._runs: list[tuple[Any, Any, int, int]] = []
        """(group value, first key, first seq, batch index) of each run."""
        self._rows = 0

    def add(self, table: pa.Table) -> None:
        """Rows, in the order they came, with the columns of the schema (SEQ added here)."""
        n = table.num_rows
        if n == 0:
            return
        assert self._writer is not None
        table = table.append_column(SEQ, pa.array(np.arange(self._rows, self._rows + n),
                                                  pa.int64()))
        self._rows += n
        order = [(self.key, "ascending"), (SEQ, "ascending")]
        if self.group is not None:
            order.insert(0, (self.group, "ascending"))
        table = table.sort_by(order).cast(self.schema).combine_chunks()
        for part in self._split(table):
            batch = part.to_batches()[0]
            group = part[self.group][0].as_py() if self.group is not None else None
            self._runs.append((group, part[self.key][0].as_py(), part[SEQ][0].as_py(),
                               len(self._runs)))
            self._writer.write_batch(batch)

    def _split(self, table: pa.Table) -> Iterator[pa.Table]:
        if self.group is None:
            yield table
            return
        values = table[self.group].to_numpy()
        cuts = [0, *(np.flatnonzero(values[1:] != values[:-1]) + 1).tolist(), len(values)]
        for a, b in itertools.pairwise(cuts):
            yield table.slice(a, b - a)

    def close(self, schema: pa.Schema) -> None:
        """Merge the runs into the table, written with `schema` (its columns and pandas
        metadata; scratch columns it lacks are dropped) under its partial name; `commit`
        gives it its name."""
        assert self._writer is not None
        self._writer.close()
        self._writer = None
        names = schema.names
        with pq.ParquetWriter(self.partial, schema) as out, pa.OSFile(str(self.scratch)) as f:
            reader = pa.ipc.open_file(f)
            pending: list[pa.Table] = []
            held = 0

            def emit(rows: pa.Table | None) -> None:
                """Rows in their final order; None: the last have come."""
                nonlocal held
                if rows is not None and rows.num_rows:
                    pending.append(rows.select(names).cast(schema))
                    held += rows.num_rows
                while held >= self.batch_rows or (rows is None and held):
                    table = pa.concat_tables(pending).combine_chunks()
                    size = min(self.batch_rows, held)
                    out.write_table(table.slice(0, size), row_group_size=size)
                    pending[:] = [table.slice(size)]
                    held -= size

            for group in sorted({r[0] for r in self._runs}, key=lambda g: (g is None, g)):
                runs = sorted((r for r in self._runs if r[0] == group), key=lambda r: r[1:])
                loaded: pa.Table | None = None
                for _, first_key, first_seq, index in runs:
                    if loaded is not None:  # every row before this run's first is final
                        keys = loaded[self.key].to_numpy()
                        seqs = loaded[SEQ].to_numpy()
                        ready = int(np.count_nonzero(
                            (keys < first_key) | ((keys == first_key) & (seqs < first_seq))))
                        emit(loaded.slice(0, ready))
                        loaded = loaded.slice(ready)
                    run = pa.Table.from_batches([reader.get_batch(index)])
                    loaded = run if loaded is None or loaded.num_rows == 0 else \
                        pa.concat_tables([loaded, run]).sort_by(
                            [(self.key, "ascending"), (SEQ, "ascending")]).combine_chunks()
                if loaded is not None:
                    emit(loaded)
            emit(None)
        self.scratch.unlink()

    def commit(self) -> None:
        """Give the merged table (closed) its name, flushed to disk first."""
        fsync_path(self.partial)
        os.replace(self.partial, self.path)

    def abort(self) -> None:
        if self._writer is not None:
            with contextlib.suppress(OSError):
                self._writer.close()
            self._writer = None
        self.scratch.unlink(missing_ok=True)
        self.partial.unlink(missing_ok=True)


class ParquetTables:
    """A `RecordSink` writing events.parquet, orders.parquet, soc.parquet and, with `moves`,
    moves.parquet into `out_dir`, events and SOC a row group per batch, orders and moves put
    in order on the way; the files get their names on `close()` (see the module). Used as a
    context manager, it removes its partial files when the block raises."""

    def __init__(self, out_dir: Path, moves: bool = False,
                 batch_rows: int = BATCH_ROWS) -> None:
        out_dir.mkdir(parents=True, exist_ok=True)
        self.out_dir = out_dir
        self._writers: dict[str, pq.ParquetWriter] = {}
        for name in ("events", "soc"):
            self._writers[name] = pq.ParquetWriter(self._partial(name), table_schema(name))
        self._sorted: dict[str, SortedTable] = {
            "orders": SortedTable(out_dir / "orders.parquet", table_schema("orders", True),
                                  "order_id", None, batch_rows)}
        if moves:
            self._sorted[MOVES] = SortedTable(out_dir / f"{MOVES}.parquet",
                                              table_schema(MOVES), "start_s", "agv",
                                              batch_rows)
        self._stops = False
        """Has an order had a chain of stops (the `stops` column)?"""

    def _partial(self, name: str) -> Path:
        return self.out_dir / f".{name}.parquet.partial"

    def _write(self, name: str, frame: pd.DataFrame) -> None:
        table = pa.Table.from_pandas(frame, schema=table_schema(name), preserve_index=False)
        self._writers[name].write_table(table)

    def events(self, rows: Sequence[EventRecord]) -> None:
        self._write("events", events_frame(rows))

    def orders(self, rows: Sequence[Order]) -> None:
        self._stops = self._stops or any(o.stops for o in rows)
        self._sorted["orders"].add(pa.Table.from_pandas(
            orders_frame(rows, stops=True), schema=table_schema("orders", True),
            preserve_index=False))

    def soc_samples(self, rows: Sequence[SocSample]) -> None:
        self._write("soc", soc_frame(rows))

    def moves(self, rows: Sequence[MoveRecord]) -> None:
        if MOVES in self._sorted:
            self._sorted[MOVES].add(pa.Table.from_pandas(
                moves_frame(rows), schema=table_schema(MOVES), preserve_index=False))

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        """Not a table (the KPIs' sums take them)."""

    def charge_waits(self, rows: Sequence[ChargeWait]) -> None:
        """Not a table (the KPIs' sums take them)."""

    def errors(self, rows: Sequence[ErrorRecord]) -> None:
        """Not a table: every Error is also a row of events.parquet."""

    def close(self) -> None:
        """The run finished: close the files (merging the sorted ones) and give them their
        names."""
        done: list[tuple[Path, Path]] = []
        for name, writer in self._writers.items():
            writer.close()
            done.append((self._partial(name), self.out_dir / f"{name}.parquet"))
        for name, table in self._sorted.items():
            table.close(table_schema(name, self._stops) if name == "orders"
                        else table_schema(name))
            done.append((table.partial, table.path))
        # every table complete before any gets its name: a full disk while the last one is
        # merged leaves none of them under a final name
        for partial, _ in done:
            fsync_path(partial)
        for partial, final in done:
            os.replace(partial, final)
        self._writers, self._sorted = {}, {}

    def abort(self) -> None:
        """The run did not finish: close and remove the partial files."""
        writers, self._writers = self._writers, {}
        for name, writer in writers.items():
            with contextlib.suppress(OSError):  # a full disk may fail the close as well
                writer.close()
            self._partial(name).unlink(missing_ok=True)
        tables, self._sorted = self._sorted, {}
        for table in tables.values():
            table.abort()

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
               record_occupancy: bool = False, record_moves: bool = False,
               batch_rows: int = BATCH_ROWS) -> tuple[RunOutput, dict[str, Any]]:
    """Run the scenario, its tables streamed into `out_dir` as it goes and its KPIs summed on
    the way, and write the run directory (`fleet-sim run` and every sweep run; with
    `record_moves` also moves.parquet). Returns the run (its recorder holds the running
    totals, not the rows) and its KPIs."""
    sums = KpiSums(scenario.warmup_s, scenario.duration_s)
    with ParquetTables(out_dir, moves=record_moves, batch_rows=batch_rows) as tables:
        run = simulate(scenario, layout, trace, progress, record_occupancy, record_moves,
                       sink=Fanout(sums, tables), batch_rows=batch_rows)
    figures = run_kpis(run, sums)
    _write_run_files(run, out_dir, figures)
    return run, figures


def write_run(run: RunOutput, out_dir: Path, figures: dict[str, Any],
              moves: bool = False) -> None:
    """Write the run directory of a run kept in memory (with `moves`, its moves.parquet too):
    the same files, and the same bytes, as `stream_run` writes for it with the same batch
    size."""
    with ParquetTables(out_dir, moves=moves, batch_rows=run.recorder.batch_rows) as tables:
        run.recorder.hand_over(tables)
    _write_run_files(run, out_dir, figures)


def _write_run_files(run: RunOutput, out_dir: Path, figures: dict[str, Any]) -> None:
    """Beside the tables: resolved config, kpis.json (`figures`) and run_info.json (wall time,
    events simulated)."""
    write_text_atomic(out_dir / "config.resolved.yaml",
                      yaml.safe_dump(resolved(run.scenario), sort_keys=False,
                                     allow_unicode=True))
    info: dict[str, Any] = {"wall_s": round(run.wall_s, 3), "sim_events": run.sim_events,
            "sim_hours_per_wall_s": round(run.scenario.duration_h / max(run.wall_s, 1e-9), 3)}
    if run.admission is not None:  # admission `auto`: the limit and what it was derived from
        info["max_active_agvs"], neck = run.admission
        info["admission_basis"] = neck.describe()
    write_text_atomic(out_dir / "run_info.json", json.dumps(info, indent=2) + "\n")
    write_text_atomic(out_dir / "kpis.json", json.dumps(figures, indent=2) + "\n")
