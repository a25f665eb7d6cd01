"""`fleet-sim export DIR --csv|--xlsx`: a run's or a sweep's tables for the people who live in
spreadsheets.

A run directory gives `kpis` (one row per KPI: value, unit, meaning), `orders`, `events` and
`soc` (each AGV's state of charge over time); a sweep or sizing results folder gives `summary`
(one row per run: factors, seed, every KPI), `stats` (mean and 95 % interval per design point
and KPI), and `orders`, `events` and `soc` of every run with its `run_id` and its factor levels.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from fleet_sim.analysis.kpis import CATALOGUE, NOTE_MEANINGS, RUN_FIELDS
from fleet_sim.errors import FleetSimError, InputError, require_extra
from fleet_sim.study.results import read_summary, runs_table_sql
from userfiles.writing import atomic_path

EXCEL_MAX_ROWS = 1_048_575
"""Data rows per sheet (Excel's 1,048,576 rows, less the header)."""
RUN_TABLES = ("orders", "events", "soc")
"""The tables of each run exported, in this order (those that exist)."""
LEVELS = "levels"
"""The frame (run_id and the factor columns of the summary) joined to a sweep's run tables."""

Note = Callable[[str], None]


@dataclass(frozen=True)
class Exported:
    """One table written: where, and how many rows."""

    table: str
    path: Path
    rows: int


def _sql(path: Path) -> str:
    return str(path.resolve()).replace("'", "''")


def _ident(name: str) -> str:
    """A column name inside double quotes in SQL."""
    return name.replace('"', '""')


def _kpi_rows(figures: dict[str, Any], typed: bool = False) -> pd.DataFrame:
    """kpis.json as rows (kpi, value, unit, meaning); per-code counts flattened. The value is
    text as kpis.json writes it, or (`typed`) the number itself where it is one."""
    known = {k.name: k for k in CATALOGUE}
    rows: list[tuple[str, Any, str, str]] = []
    for key, value in figures.items():
        if isinstance(value, dict):
            items = [(f"{key}.{code}", count) for code, count in value.items()]
        else:
            items = [(key, value)]
        for name, item in items:
            kpi = known.get(name)
            meaning = kpi.meaning if kpi else ("about the run" if name in RUN_FIELDS
                                               else NOTE_MEANINGS.get(name, ""))
            cell: Any = "" if item is None else str(item)
            if typed and isinstance(item, (int, float)) and not isinstance(item, bool):
                cell = item
            elif typed and item is None:
                cell = None
            rows.append((name, cell, kpi.unit if kpi else "", meaning))
    frame = pd.DataFrame(rows, columns=["kpi", "value", "unit", "meaning"])
    if typed:
        return frame.astype({"kpi": "string", "unit": "string", "meaning": "string"})
    return frame.astype("string")


@dataclass(frozen=True)
class _Source:
    """What one folder exports: table name -> a DuckDB query or a frame, in the order written,
    and the frames the queries read (registered by name)."""

    tables: dict[str, str | pd.DataFrame]
    frames: dict[str, pd.DataFrame]


def _tables(source: Path, typed: bool = False) -> _Source:
    """The tables of a run directory or of a sweep or sizing results folder; `typed`: KPI
    values as numbers (the workbook)."""
    if (source / "config.resolved.yaml").is_file() and (source / "events.parquet").is_file():
        kpis_file = source / "kpis.json"
        tables: dict[str, str | pd.DataFrame] = {}
        if kpis_file.is_file():
            tables["kpis"] = _kpi_rows(json.loads(kpis_file.read_text(encoding="utf-8")), typed)
        for name in RUN_TABLES:
            if name == "soc" and not (source / f"{name}.parquet").is_file():
                continue
            tables[name] = f"SELECT * FROM read_parquet('{_sql(source / f'{name}.parquet')}')"
        return _Source(tables, {})
    if (source / "experiment.resolved.yaml").is_file():
        import yaml

        experiment = yaml.safe_load((source / "experiment.resolved.yaml").read_text(
            encoding="utf-8")) or {}
        factors = list(experiment.get("factors") or {})
        summary, _ = read_summary(source, factors)
        damaged = summary[summary["status"].astype(str) == "damaged"] if len(summary) \
            else summary
        if len(damaged):
            first = damaged.iloc[0]
            raise FleetSimError(
                f"{source / 'runs' / str(first['run_id'])}: {first['error']} (of "
                f"{len(damaged)} damaged run(s)); nothing was exported")
        tables = {"summary": summary}
        if (source / "stats.parquet").is_file():
            tables["stats"] = f"SELECT * FROM read_parquet('{_sql(source / 'stats.parquet')}')"
        levels = summary[["run_id", *(f for f in factors if f in summary.columns)]]
        level_columns = "".join(f', {LEVELS}."{_ident(f)}"' for f in levels.columns[1:])
        runs = source / "runs"
        for name in RUN_TABLES:
            query = runs_table_sql(runs, name, row_numbers=True)
            if query is not None:
                tables[name] = (
                    f"SELECT t.run_id{level_columns}, t.* EXCLUDE (run_id, file_row_number) "
                    f"FROM ({query}) t LEFT JOIN {LEVELS} "
                    f"ON {LEVELS}.run_id = t.run_id ORDER BY t.run_id, t.file_row_number")
        return _Source(tables, {LEVELS: levels})
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
    found = _tables(source, typed=fmt == "xlsx")
    tables = found.tables
    written: list[Exported] = []
    con = duckdb.connect()
    for name, frame in found.frames.items():
        con.register(name, frame)
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
                with atomic_path(path) as tmp:
                    con.execute(f"COPY ({query}) TO '{_sql(tmp)}' (HEADER, DELIMITER ',')")
                if isinstance(table, pd.DataFrame):
                    con.unregister("frame")
                written.append(Exported(name, path, int(rows[0]) if rows else 0))
            return written
        path = out or source / "export.xlsx"
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp, pd.ExcelWriter(tmp, engine="openpyxl") as writer:
            for name, table in tables.items():
                say(f"reading {name}")
                frame = table if isinstance(table, pd.DataFrame) else con.execute(table).df()
                for part, first in enumerate(range(0, max(len(frame), 1), EXCEL_MAX_ROWS)):
                    sheet = name if part == 0 else f"{name} ({part + 1})"
                    say(f"writing sheet {sheet} of {path.name}")
                    frame.iloc[first:first + EXCEL_MAX_ROWS].to_excel(
                        writer, sheet_name=sheet, index=False)
                    _header_row(writer.sheets[sheet])
                written.append(Exported(name, path, len(frame)))
        return written
    finally:
        con.close()


def _header_row(sheet: Any) -> None:
    """Freeze the header row and put an autofilter on it (openpyxl worksheet)."""
    sheet.freeze_panes = "A2"
    sheet.auto_filter.ref = sheet.dimensions
