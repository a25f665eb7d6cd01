"""`fleet-sim export DIR --csv|--xlsx`: a run's or a sweep's tables for the people who live in
spreadsheets.

A run directory gives `kpis` (one row per KPI: value, unit, meaning), `orders` and `events`; a
sweep or sizing results folder gives `summary` (one row per run: factors, seed, every KPI),
`stats` (mean and 95 % interval per design point and KPI), and `orders` and `events` of every
run with its `run_id`.

Decisions, where the issue is silent:

* CSV through DuckDB (`COPY ... TO`), one file per table in DIR/export/ (or --out), comma
  separated with a header, rows in the order of the run's own tables (runs in run-id order);
  the same run gives the same bytes. XLSX through pandas and openpyxl (the ``export`` extra:
  ``pip install 'fleet-sim[export]'``; CSV needs nothing more), one workbook
  (DIR/export.xlsx, or --out) with one sheet per table. A sheet holds at most 1,048,576 rows:
  a longer table (a big sweep's events) goes on in sheets "events (2)", "events (3)"...; nothing
  is cut. openpyxl stamps the workbook with the time it was saved, so two exports of one run
  differ in that stamp only.
* Missing values (a lead time not yet known, an order never delivered) are empty cells.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from fleet_sim.analysis.kpis import CATALOGUE, RUN_FIELDS
from fleet_sim.errors import InputError, require_extra
from fleet_sim.study.sweep import read_summary

EXCEL_MAX_ROWS = 1_048_575
"""Data rows per sheet (Excel's 1,048,576 rows, less the header)."""

Note = Callable[[str], None]


@dataclass(frozen=True)
class Exported:
    """One table written: where, and how many rows."""

    table: str
    path: Path
    rows: int


def _sql(path: Path) -> str:
    return str(path.resolve()).replace("'", "''")


def _kpi_rows(figures: dict[str, Any]) -> pd.DataFrame:
    """kpis.json as rows (kpi, value, unit, meaning); per-code counts flattened."""
    known = {k.name: k for k in CATALOGUE}
    rows: list[tuple[str, str, str, str]] = []
    for key, value in figures.items():
        if isinstance(value, dict):
            items = [(f"{key}.{code}", count) for code, count in value.items()]
        else:
            items = [(key, value)]
        for name, item in items:
            kpi = known.get(name)
            meaning = kpi.meaning if kpi else ("about the run" if name in RUN_FIELDS else "")
            rows.append((name, "" if item is None else str(item), kpi.unit if kpi else "",
                         meaning))
    return pd.DataFrame(rows, columns=["kpi", "value", "unit", "meaning"]).astype("string")


def _tables(source: Path) -> tuple[str, dict[str, str | pd.DataFrame]]:
    """("run" or "sweep", table name -> a DuckDB query or a frame), in the order written."""
    if (source / "config.resolved.yaml").is_file() and (source / "events.parquet").is_file():
        kpis_file = source / "kpis.json"
        tables: dict[str, str | pd.DataFrame] = {}
        if kpis_file.is_file():
            tables["kpis"] = _kpi_rows(json.loads(kpis_file.read_text(encoding="utf-8")))
        for name in ("orders", "events"):
            tables[name] = f"SELECT * FROM read_parquet('{_sql(source / f'{name}.parquet')}')"
        return "run", tables
    if (source / "experiment.resolved.yaml").is_file():
        import yaml

        experiment = yaml.safe_load((source / "experiment.resolved.yaml").read_text(
            encoding="utf-8")) or {}
        summary, _ = read_summary(source, list(experiment.get("factors") or {}))
        tables = {"summary": summary}
        if (source / "stats.parquet").is_file():
            tables["stats"] = f"SELECT * FROM read_parquet('{_sql(source / 'stats.parquet')}')"
        runs = source / "runs"
        for name in ("orders", "events"):
            if any(runs.glob(f"*/{name}.parquet")):
                pattern = _sql(runs / "*" / f"{name}.parquet")
                tables[name] = (
                    f"SELECT regexp_extract(filename, '([^/]+)/{name}.parquet$', 1) AS run_id, "
                    f"* EXCLUDE (filename, file_row_number) FROM read_parquet('{pattern}', "
                    "filename = true, file_row_number = true, union_by_name = true) "
                    "ORDER BY run_id, file_row_number")
        return "sweep", tables
    raise InputError(str(source), "folder", str(source),
                     "a run directory (with config.resolved.yaml and events.parquet) or a "
                     "sweep or sizing results folder (with experiment.resolved.yaml)")


def export(source: Path, fmt: str, out: Path | None = None,
           note: Note | None = None) -> list[Exported]:
    """Write the tables of `source` as CSV files (`fmt` "csv") or one workbook ("xlsx")."""
    import duckdb

    if fmt == "xlsx":  # before anything is read or written
        require_extra("openpyxl", "export", "export --xlsx")
    say = note or (lambda text: None)
    _, tables = _tables(source)
    written: list[Exported] = []
    con = duckdb.connect()
    try:
        if fmt == "csv":
            folder = out or source / "export"
            folder.mkdir(parents=True, exist_ok=True)
            for name, table in tables.items():
                path = folder / f"{name}.csv"
                say(f"writing {path}")
                if isinstance(table, pd.DataFrame):
                    con.register("frame", table)
                    query = "SELECT * FROM frame"
                else:
                    query = table
                rows = con.execute(f"SELECT count(*) FROM ({query})").fetchone()
                con.execute(f"COPY ({query}) TO '{_sql(path)}' (HEADER, DELIMITER ',')")
                if isinstance(table, pd.DataFrame):
                    con.unregister("frame")
                written.append(Exported(name, path, int(rows[0]) if rows else 0))
            return written
        path = out or source / "export.xlsx"
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        with pd.ExcelWriter(tmp, engine="openpyxl") as writer:
            for name, table in tables.items():
                say(f"reading {name}")
                frame = table if isinstance(table, pd.DataFrame) else con.execute(table).df()
                for part, first in enumerate(range(0, max(len(frame), 1), EXCEL_MAX_ROWS)):
                    sheet = name if part == 0 else f"{name} ({part + 1})"
                    say(f"writing sheet {sheet} of {path.name}")
                    frame.iloc[first:first + EXCEL_MAX_ROWS].to_excel(
                        writer, sheet_name=sheet, index=False)
                written.append(Exported(name, path, len(frame)))
        tmp.replace(path)
        return written
    finally:
        con.close()
