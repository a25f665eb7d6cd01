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
    assert sorted(p.name for p in folder.iterdir()) == ["events.csv", "kpis.csv", "orders.csv"]
    for name in ("orders", "events"):
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
    assert book.sheetnames == ["kpis", "orders", "events"]
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
    assert [w.table for w in written] == ["summary", "stats", "orders", "events"]
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
    assert list(sheets) == ["summary", "stats", "orders", "events"]
    assert len(sheets["orders"]) == total


def test_export_of_something_else_is_one_line(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", str(tmp_path), "--csv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "expected a run directory" in err[0]
    with pytest.raises(SystemExit) as stop:
        main(["export", str(tmp_path)])
    assert stop.value.code == 2
