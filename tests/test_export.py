"""`fleet-sim export`: a run's and a sweep's tables as CSV files and as one workbook, through
DuckDB and pandas; every row there, read back as written."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pandas as pd
import pytest

from fleet_sim.cli import main
from fleet_sim.config.experiment import load_experiment
from fleet_sim.report import export as export_module
from fleet_sim.study.sweep import sweep

from .conftest import LAYOUTS, write_yaml


def _scenario(tmp: Path) -> Path:
    return write_yaml(tmp / "s.yaml", {
        "name": "tiny", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.5,
        "warmup_h": 0.1, "fleet": {"size": 2}, "demand": {"rate_per_hour": 40}})


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("export")
    out = tmp / "run"
    assert main(["run", str(_scenario(tmp)), "--out", str(out), "--quiet"]) == 0
    return out


def _csv_rows(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


def test_a_run_as_csv(run_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(run_dir), "--csv"]) == 0
    folder = run_dir / "export"
    assert sorted(p.name for p in folder.iterdir()) == ["events.csv", "kpis.csv", "orders.csv",
                                                        "soc.csv"]
    for name in ("orders", "events", "soc"):
        table = pd.read_parquet(run_dir / f"{name}.parquet")
        rows = _csv_rows(folder / f"{name}.csv")
        assert len(rows) == len(table) > 10
        assert list(rows[0]) == list(table.columns)
        assert [r[table.columns[1]] for r in rows] == [
            "" if pd.isna(v) else str(v) for v in table[table.columns[1]]]
    kpis = {r["kpi"]: r for r in _csv_rows(folder / "kpis.csv")}
    figures = json.loads((run_dir / "kpis.json").read_text())
    assert kpis["throughput_per_hour"]["value"] == str(figures["throughput_per_hour"])
    assert kpis["throughput_per_hour"]["unit"] == "orders/h"
    assert "rows" in capsys.readouterr().out
    first = {p.name: p.read_bytes() for p in folder.iterdir()}
    assert main(["export", str(run_dir), "--csv"]) == 0
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == first  # same bytes again


def test_a_run_as_a_workbook(run_dir: Path, tmp_path: Path) -> None:
    import openpyxl

    book_path = tmp_path / "book.xlsx"
    assert main(["export", str(run_dir), "--xlsx", "--out", str(book_path)]) == 0
    book = openpyxl.load_workbook(book_path, read_only=True)
    assert book.sheetnames == ["kpis", "orders", "events", "soc"]
    orders = pd.read_parquet(run_dir / "orders.parquet")
    sheet = list(book["orders"].iter_rows(values_only=True))
    assert list(sheet[0]) == list(orders.columns)
    assert len(sheet) == len(orders) + 1
    assert [row[0] for row in sheet[1:]] == list(orders["order_id"])
    assert pd.read_excel(book_path, sheet_name="events").shape == pd.read_parquet(
        run_dir / "events.parquet").shape


def test_a_long_table_goes_on_in_more_sheets(run_dir: Path, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(export_module, "EXCEL_MAX_ROWS", 100)
    events = pd.read_parquet(run_dir / "events.parquet")
    book = tmp_path / "split.xlsx"
    export_module.export(run_dir, "xlsx", book)
    sheets = pd.read_excel(book, sheet_name=None)
    parts = [name for name in sheets if name.startswith("events")]
    assert parts[:2] == ["events", "events (2)"] and len(parts) == -(-len(events) // 100)
    joined = pd.concat([sheets[p] for p in parts], ignore_index=True)
    assert len(joined) == len(events)
    assert list(joined["time_s"]) == pytest.approx(list(events["time_s"]))


def test_a_sweep_as_csv_and_workbook(tmp_path: Path) -> None:
    experiment = load_experiment(write_yaml(tmp_path / "e.yaml", {
        "name": "e", "scenario": str(_scenario(tmp_path)), "factors": {"fleet.size": [1, 2]},
        "replications": 2, "master_seed": 3}))
    out = tmp_path / "sweep"
    sweep(experiment, out, workers=1, quiet=True)
    written = export_module.export(out, "csv")
    assert [w.table for w in written] == ["summary", "stats", "orders", "events", "soc"]
    summary = _csv_rows(out / "export" / "summary.csv")
    assert len(summary) == 4 and {"run_id", "fleet.size", "throughput_per_hour"} <= set(summary[0])
    orders = _csv_rows(out / "export" / "orders.csv")
    runs = sorted({r["run_id"] for r in orders})
    assert runs == sorted(p.name for p in (out / "runs").iterdir())
    total = sum(len(pd.read_parquet(out / "runs" / r / "orders.parquet")) for r in runs)
    assert len(orders) == total
    first_run = [r["order_id"] for r in orders if r["run_id"] == runs[0]]
    assert first_run == [str(i) for i in pd.read_parquet(
        out / "runs" / runs[0] / "orders.parquet")["order_id"]]
    export_module.export(out, "xlsx")
    sheets = pd.read_excel(out / "export.xlsx", sheet_name=None)
    assert list(sheets) == ["summary", "stats", "orders", "events", "soc"]
    assert len(sheets["orders"]) == total


def test_export_of_something_else_is_one_line(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(tmp_path), "--csv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "expected a run directory" in err[0]
    with pytest.raises(SystemExit) as stop:
        main(["export", str(tmp_path)])
    assert stop.value.code == 2


def test_the_workbook_holds_numbers_soc_and_filtered_frozen_headers(run_dir: Path,
                                                                    tmp_path: Path) -> None:
    """KPI values are number cells (not text), the SOC samples have their sheet, and every
    sheet's header row is frozen with an autofilter over the table."""
    import openpyxl

    book_path = tmp_path / "book.xlsx"
    export_module.export(run_dir, "xlsx", book_path)
    book = openpyxl.load_workbook(book_path)
    figures = json.loads((run_dir / "kpis.json").read_text())
    kpis = {row[0].value: row[1] for row in book["kpis"].iter_rows(min_row=2)}
    for name in ("throughput_per_hour", "orders_completed", "lead_time_p95_s"):
        assert kpis[name].data_type == "n" and kpis[name].value == pytest.approx(figures[name])
    soc = pd.read_parquet(run_dir / "soc.parquet")
    assert len(soc) > 2
    sheet = pd.read_excel(book_path, sheet_name="soc")
    assert list(sheet.columns) == list(soc.columns) == ["time_s", "agv", "soc_pct"]
    assert list(sheet["soc_pct"]) == pytest.approx(list(soc["soc_pct"]))
    for ws in book.worksheets:
        assert ws.freeze_panes == "A2", ws.title
        assert ws.auto_filter.ref == ws.dimensions and ws.dimensions.startswith("A1:"), ws.title


@pytest.fixture(scope="module")
def one_factor_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A sweep of one factor, charging.enabled: its run folders are named
    `charging.enabled=False__r00`, which DuckDB reads as a Hive partition if let."""
    tmp = tmp_path_factory.mktemp("one_factor")
    experiment = load_experiment(write_yaml(tmp / "e.yaml", {
        "name": "one", "scenario": str(_scenario(tmp)),
        "factors": {"charging.enabled": [False, True]}, "replications": 1}))
    out = tmp / "sweep"
    sweep(experiment, out, workers=1, quiet=True)
    return out


def test_a_one_factor_sweep_exports_the_level_not_the_folder_name(one_factor_sweep: Path
                                                                  ) -> None:
    """The factor column holds the level (it held 'False__r00' in the orders and events,
    read from the folder name as a Hive partition)."""
    export_module.export(one_factor_sweep, "xlsx")
    sheets = pd.read_excel(one_factor_sweep / "export.xlsx", sheet_name=None)
    assert sorted(sheets["summary"]["charging.enabled"]) == [False, True]
    for name in ("orders", "events", "soc"):
        table = sheets[name]
        assert list(table.columns[:2]) == ["run_id", "charging.enabled"], name
        levels = {run: level for run, level in zip(table["run_id"], table["charging.enabled"],
                                                   strict=True)}
        assert levels == {"charging.enabled=False__r00": False,
                          "charging.enabled=True__r00": True}, name
    export_module.export(one_factor_sweep, "csv")
    rows = _csv_rows(one_factor_sweep / "export" / "orders.csv")
    assert {r["charging.enabled"] for r in rows} == {"false", "true"}


def test_sweep_duckdb_views_hold_no_folder_name_as_a_factor(one_factor_sweep: Path) -> None:
    """sweep.duckdb's views over the runs' tables: no column holds 'False__r00' (DuckDB's
    Hive-partition guess on `charging.enabled=False__r00/orders.parquet`)."""
    import duckdb

    con = duckdb.connect(str(one_factor_sweep / "sweep.duckdb"), read_only=True)
    try:
        for view in ("orders", "events", "node_waits"):
            frame = con.execute(f"SELECT * FROM {view}").df()
            bad = [c for c in frame.columns if c != "run_id" and frame[c].astype(str)
                   .str.endswith("__r00").any()]
            assert bad == [], (view, bad)
    finally:
        con.close()
