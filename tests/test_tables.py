"""A run's tables streamed to Parquet as it goes: the same rows, row order and dtypes as the run
kept in memory, the same bytes for the same seed, the same kpis.json whatever the batch size
(mixed fleet, multi-stop orders, a mutex zone, admission and the replay's moves included), at
most a batch of rows held, no half-written table left by a failed run, KPIs from the running
sums equal to KPIs worked out from the full tables, and the merge that puts orders and moves in
order."""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from fleet_sim.analysis.kpi_sums import run_kpis
from fleet_sim.analysis.replay import MOVES_FILE, moves_table, write_moves
from fleet_sim.analysis.tables import (
    STOPS_COLUMN,
    TABLES,
    SortedTable,
    events_table,
    orders_table,
    read_tables,
    soc_table,
    stream_run,
    write_run,
)
from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.scenario import Scenario
from fleet_sim.model.records import (
    ChargeWait,
    ErrorRecord,
    EventRecord,
    MoveRecord,
    Order,
    QueueLength,
    SocSample,
)
from fleet_sim.sim.engine import build_simulation, simulate

from .conftest import LAYOUTS, make_scenario, write_yaml
from .test_multistop import four_station_loop


@pytest.fixture(scope="module")
def charger_loop(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny loop with a charger spur west of N1."""
    data = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text())
    data["nodes"].append({"id": "C", "x": 4, "y": 12, "kind": "charger"})
    data["segments"].append({"from": "N1", "to": "C", "direction": "two_way"})
    data["chargers"] = [{"id": "CHG", "node": "C", "power_kw": 1.0, "docking_s": 10}]
    return write_yaml(tmp_path_factory.mktemp("layout") / "tiny_charger.yaml", data)


def eventful(layout_file: Path, seed: int = 4, duration_h: float = 6.0) -> Scenario:
    """3 AGVs with small batteries (they charge) and every kind of incident."""
    return make_scenario(
        str(layout_file), duration_h=duration_h, warmup_h=0.5, seed=seed,
        fleet={"size": 3, "vehicle": {"battery": {"capacity_wh": 150.0,
                                                  "initial_soc_pct": 60.0}}},
        demand={"rate_per_hour": 40}, charging={"threshold_pct": 40},
        incidents={"obstacle_rate_per_km": 2.0, "transfer_failure_prob": 0.05,
                   "mtbf_h": 2.0, "link_loss_rate_per_h": 0.5, "line_loss_per_km": 0.3})


def test_streamed_tables_equal_the_in_memory_tables(tmp_path: Path, charger_loop: Path) -> None:
    """Several flushes (batches of 500 rows) or one (batches of 50,000): the rows, row order
    and dtypes of the run kept in memory (orders in creation order, though they reach the
    writer in the order they finish)."""
    scenario = eventful(charger_loop)
    layout = load_layout(charger_loop)
    memory = simulate(scenario, layout)
    recorder = memory.recorder
    assert len(recorder.events) > 5 * 500 and len(recorder.orders) > 150
    finished = [o.id for o in recorder.finished]
    assert finished != sorted(finished)  # the order in which they reach the writer
    for folder, batch_rows in (("small", 500), ("one", 50_000)):
        stream_run(scenario, layout, tmp_path / folder, batch_rows=batch_rows)
        streamed = read_tables(tmp_path / folder)
        pd.testing.assert_frame_equal(streamed.events, events_table(recorder), check_exact=True)
        pd.testing.assert_frame_equal(streamed.soc, soc_table(recorder), check_exact=True)
        pd.testing.assert_frame_equal(streamed.orders, orders_table(recorder), check_exact=True)
        assert list(streamed.orders["order_id"]) == [o.id for o in recorder.orders]
        assert STOPS_COLUMN not in streamed.orders.columns
        assert sorted((tmp_path / folder).iterdir()) == sorted(
            tmp_path / folder / name for name in (
                "events.parquet", "orders.parquet", "soc.parquet", "kpis.json",
                "run_info.json", "config.resolved.yaml"))
    groups = {name: pq.ParquetFile(tmp_path / "small" / f"{name}.parquet").num_row_groups
              for name in TABLES}
    assert groups["events"] == -(-len(recorder.events) // 500) > 5
    assert groups["orders"] == -(-len(recorder.orders) // 500)
    assert pq.ParquetFile(tmp_path / "one" / "events.parquet").num_row_groups == 1
    dtypes = dict(read_tables(tmp_path / "small").orders.dtypes.astype(str))
    assert dtypes["agv"] == "Int64" and dtypes["pickup"] == "string"
    assert dtypes["delivered_s"] == "float64" and dtypes["order_id"] == "int64"


def test_same_seed_same_bytes_streamed_or_written_from_memory(tmp_path: Path,
                                                              charger_loop: Path) -> None:
    layout = load_layout(charger_loop)
    scenario = eventful(charger_loop, duration_h=2.0)
    stream_run(scenario, layout, tmp_path / "a", batch_rows=300, record_moves=True)
    stream_run(scenario, layout, tmp_path / "b", batch_rows=300, record_moves=True)
    memory = simulate(scenario, layout, batch_rows=300, record_moves=True)
    write_run(memory, tmp_path / "c", run_kpis(memory), moves=True)
    stream_run(eventful(charger_loop, seed=5, duration_h=2.0), layout, tmp_path / "d",
               batch_rows=300)
    (tmp_path / "e").mkdir()
    write_moves(memory.recorder, tmp_path / "e")
    assert (tmp_path / "e" / MOVES_FILE).read_bytes() == (tmp_path / "a" / MOVES_FILE).read_bytes()
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "a" / MOVES_FILE),
                                  moves_table(memory.recorder), check_exact=True)
    for name in ("events.parquet", "orders.parquet", "soc.parquet", "kpis.json",
                 "config.resolved.yaml", MOVES_FILE):
        a = (tmp_path / "a" / name).read_bytes()
        assert a == (tmp_path / "b" / name).read_bytes() == (tmp_path / "c" / name).read_bytes()
    assert (tmp_path / "a" / "orders.parquet").read_bytes() \
        != (tmp_path / "d" / "orders.parquet").read_bytes()


class CountingSink:
    """Counts what it is handed, and the largest batch."""

    def __init__(self) -> None:
        self.rows: Counter[str] = Counter()
        self.largest: Counter[str] = Counter()
        self.closed = 0

    def _take(self, kind: str, rows: Sequence[Any]) -> None:
        self.rows[kind] += len(rows)
        self.largest[kind] = max(self.largest[kind], len(rows))

    def events(self, rows: Sequence[EventRecord]) -> None:
        self._take("events", rows)

    def orders(self, rows: Sequence[Order]) -> None:
        self._take("orders", rows)

    def soc_samples(self, rows: Sequence[SocSample]) -> None:
        self._take("soc", rows)

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        self._take("queue", rows)

    def charge_waits(self, rows: Sequence[ChargeWait]) -> None:
        self._take("charge", rows)

    def errors(self, rows: Sequence[ErrorRecord]) -> None:
        self._take("errors", rows)

    def moves(self, rows: Sequence[MoveRecord]) -> None:
        self._take("moves", rows)

    def close(self) -> None:
        self.closed += 1


def test_a_streaming_recorder_holds_at_most_a_batch(charger_loop: Path) -> None:
    """Checked every simulated 10 minutes of a day: fewer than `batch_rows` rows of each kind
    held, and no more open orders than are waiting or in hand; every row reaches the sink."""
    batch_rows = 200
    scenario = eventful(charger_loop, duration_h=24.0)
    layout: Layout = load_layout(charger_loop)
    sink = CountingSink()
    model = build_simulation(scenario, layout, record_moves=True, sink=sink, batch_rows=batch_rows)
    rec = model.recorder
    held: dict[str, int] = Counter()
    for step in range(1, 24 * 6 + 1):
        model.env.run(until=step * 600.0)
        for kind, rows in (("events", rec.events), ("finished", rec.finished),
                           ("soc", rec.soc_samples), ("queue", rec.queue_lengths),
                           ("charge", rec.charge_waits), ("errors", rec.errors),
                           ("moves", rec.moves)):
            held[kind] = max(held[kind], len(rows))
        assert len(rec.open_orders) <= len(model.fleet.waiting) + scenario.fleet.size
        assert rec.orders == []
    rec.finish()
    assert rec.rows_held() == 0 and sink.closed == 1
    assert max(held.values()) < batch_rows and max(sink.largest.values()) <= batch_rows
    memory = build_simulation(scenario, layout, record_moves=True)  # the same run, in memory
    memory.env.run(until=scenario.duration_s)
    assert sink.rows["moves"] == len(memory.recorder.moves) > 50 * batch_rows
    memory = simulate(scenario, layout).recorder
    assert sink.rows["events"] == len(memory.events) > 50 * batch_rows
    assert sink.rows["orders"] == len(memory.orders) > 3 * batch_rows
    assert sink.rows["soc"] == len(memory.soc_samples)
    assert sink.rows["queue"] == len(memory.queue_lengths)
    assert sink.rows["charge"] == len(memory.charge_waits) > 0
    assert sink.rows["errors"] == len(memory.errors) > 0


def kpis_from_tables(events: pd.DataFrame, orders: pd.DataFrame,
                     scenario: Scenario) -> dict[str, float]:
    """The order and state KPIs worked out again, with pandas, from the full tables."""
    start, end = scenario.warmup_s, scenario.duration_s
    agv_s = scenario.fleet.size * (end - start)
    delivered = orders[orders["delivered_s"].notna()]
    lead = delivered.loc[delivered["delivered_s"].between(start, end), "lead_time_s"]
    done = orders["delivered_s"].fillna(orders["failed_s"]).fillna(end)
    busy = (done.clip(start, end) - orders["assigned_s"].clip(start, end)).sum()
    changes = events[events["from_state"] != events["to_state"]] \
        .sort_values(["agv", "time_s"], kind="stable")
    until = changes.groupby("agv")["time_s"].shift(-1).fillna(end)
    spent = (until.clip(start, end) - changes["time_s"].clip(start, end)) \
        .groupby(changes["to_state"]).sum()
    out = {
        "orders_created": len(orders), "orders_completed": len(delivered),
        "throughput_per_hour": len(lead) / ((end - start) / 3600),
        "lead_time_mean_s": lead.mean(), "lead_time_p95_s": lead.quantile(0.95),
        "agv_utilisation_pct": 100 * busy / agv_s,
        "order_wait_mean_s": (orders["assigned_s"] - orders["created_s"]).mean(),
        "orders_failed": int(orders["failed_s"].notna().sum()),
        "orders_reassigned": int(orders["reassigned"].sum()),
        "demand_per_hour": orders["created_s"].between(start, end).sum() / ((end - start) / 3600),
        "availability_pct": 100 * (1 - spent.reindex(["Error", "Maintenance", "SafeMode"])
                                   .fillna(0).sum() / agv_s),
    }
    for state in ("Idle", "Moving", "Loading", "Charging", "Paused", "Error", "Maintenance"):
        out[f"state_{state.lower()}_pct"] = 100 * spent.get(state, 0.0) / agv_s
    return out


def test_kpis_from_running_sums_equal_kpis_from_the_full_tables(tmp_path: Path,
                                                                 charger_loop: Path) -> None:
    """A run with charging, failed and reassigned orders, errors and link losses."""
    scenario = eventful(charger_loop, seed=6)
    layout = load_layout(charger_loop)
    run, figures = stream_run(scenario, layout, tmp_path / "run", batch_rows=400)
    assert figures["charges"] > 0 and figures["orders_failed"] > 0
    assert figures["orders_reassigned"] > 0 and figures["errors_by_code"]
    assert figures["state_error_pct"] > 0 and figures["state_charging_pct"] > 0
    tables = read_tables(tmp_path / "run")
    expected = kpis_from_tables(tables.events, tables.orders, scenario)
    for name, value in expected.items():
        assert figures[name] == pytest.approx(value, rel=1e-9, abs=1e-6), name
    # the run kept in memory gives the same figures to the last bit
    assert run_kpis(simulate(scenario, layout)) == figures
    with pytest.raises(ValueError, match="its own sink"):  # no KPIs from rows handed over
        run_kpis(run)


def test_a_failed_run_leaves_no_table_behind(tmp_path: Path, charger_loop: Path) -> None:
    def fail_half_way(now_s: float, end_s: float) -> None:
        if now_s >= end_s / 2:
            raise RuntimeError("stopped")

    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match="stopped"):
        stream_run(eventful(charger_loop, duration_h=1.0), load_layout(charger_loop), out,
                   progress=fail_half_way, batch_rows=100, record_moves=True)
    assert list(out.iterdir()) == []


# ---- every feature, any batch size ---------------------------------------------------------


def feature_rich(folder: Path) -> tuple[Scenario, Layout]:
    """Two vehicle types on the four-station loop with a mutex zone on its east side, chains
    of four stops beside plain orders, admission, faults and obstacles."""
    path = four_station_loop(folder)
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    data["traffic_zones"] = [{"id": "EAST", "kind": "mutex", "nodes": ["SE", "E1"],
                              "segments": [["SE", "E1"], ["E1", "NE"]], "capacity": 1}]
    write_yaml(path, data)
    scenario = make_scenario(
        "four.yaml", folder, duration_h=6.0, warmup_h=0.5, seed=8,
        fleet={"vehicles": [{"type": "quick", "count": 2},
                            {"type": "slow", "count": 2, "vehicle": {"max_speed_mps": 0.6}}]},
        demand={"rate_per_hour": 70, "flows": [{"stops": ["A", "B", "C", "D"], "weight": 1.0},
                                                {"from": "A", "to": "B", "weight": 2.0},
                                                {"from": "C", "to": "D", "weight": 1.0}]},
        dispatch={"max_active_agvs": 3}, charging={"enabled": False},
        incidents={"obstacle_rate_per_km": 1.0, "mtbf_h": 4.0})
    return scenario, load_layout(path)


def test_any_batch_size_gives_the_same_kpis_json_and_tables(tmp_path: Path) -> None:
    """Batches of 7 rows (the KPI sums see the event and queue streams interleave in many
    ways, the sorted tables merge hundreds of runs) or one batch: kpis.json byte for byte,
    and every table equal to the run kept in memory. If streaming changed a KPI, or a row of
    orders.parquet or moves.parquet, this would fail."""
    scenario, layout = feature_rich(tmp_path)
    memory = simulate(scenario, layout, record_moves=True)
    recorder = memory.recorder
    figures = run_kpis(memory)
    assert figures["by_type"] and "EAST" in figures["zone_wait_s"]
    assert figures["idle_with_orders_waiting_pct"] > 0 and figures["orders_failed"] >= 0
    assert any(o.stops for o in recorder.orders) and len(recorder.moves) > 1000
    expected = json.dumps(figures, indent=2) + "\n"
    for batch_rows in (7, 50_000):
        out = tmp_path / f"batch{batch_rows}"
        _, streamed_figures = stream_run(scenario, layout, out, record_moves=True,
                                         batch_rows=batch_rows)
        assert streamed_figures == figures
        assert (out / "kpis.json").read_text(encoding="utf-8") == expected
        tables = read_tables(out)
        pd.testing.assert_frame_equal(tables.events, events_table(recorder), check_exact=True)
        pd.testing.assert_frame_equal(tables.orders, orders_table(recorder), check_exact=True)
        pd.testing.assert_frame_equal(tables.soc, soc_table(recorder), check_exact=True)
        pd.testing.assert_frame_equal(pd.read_parquet(out / MOVES_FILE),
                                      moves_table(recorder), check_exact=True)
        assert STOPS_COLUMN in tables.orders.columns


def test_the_merge_puts_rows_in_order_holding_few_runs(tmp_path: Path) -> None:
    """Nearly sorted rows with ties, in batches of random sizes, grouped: the stable sort by
    (group, key); row groups of exactly `batch_rows` rows but the last."""
    rng = np.random.default_rng(3)
    n = 5000
    group = rng.integers(0, 4, n)
    key = np.round(np.arange(n) / 10 + rng.exponential(3.0, n))  # late rows, many ties
    frame = pd.DataFrame({"group": group, "key": key, "row": np.arange(n)})
    schema = pa.Schema.from_pandas(frame.iloc[:0], preserve_index=False)
    path = tmp_path / "t.parquet"
    table = SortedTable(path, schema, "key", "group", batch_rows=128)
    start = 0
    while start < n:
        size = int(rng.integers(1, 300))
        table.add(pa.Table.from_pandas(frame.iloc[start:start + size], schema=schema,
                                       preserve_index=False))
        start += size
    table.close(schema)
    table.commit()
    written = pd.read_parquet(path)
    expected = frame.sort_values(["group", "key"], kind="stable").reset_index(drop=True)
    pd.testing.assert_frame_equal(written, expected, check_exact=True)
    sizes = [pq.ParquetFile(path).metadata.row_group(i).num_rows
             for i in range(pq.ParquetFile(path).num_row_groups)]
    assert set(sizes[:-1]) == {128} and 0 < sizes[-1] <= 128
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.parquet"]
