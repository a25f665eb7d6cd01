"""The Runs section: how many runs finished, the failed ones, the runs that locked solid or
stood out of service, the orders left open, and a query of every run with SQL.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import pandas as pd

from fleet_sim.analysis.kpis import OUT_OF_SERVICE_ADVICE
from fleet_sim.report.content import Section, Table
from fleet_sim.report.results_folder import ReportData
from fleet_sim.report.stalls import gridlocked_runs, stalled_runs
from fleet_sim.report.wording import fmt


@dataclass(kw_only=True)
class RunsSection(Section):
    title: ClassVar[str] = "Runs"
    template: ClassVar[str] = "runs.html.j2"
    runs: int
    finished: int
    failed: int
    wall_s: str
    failed_runs: Table | None
    database: str
    query: str = ""
    """A command that queries sweep.duckdb (`query_command`), shown as the example."""
    gridlocked_runs: Table | None = None
    """Runs that locked solid (gridlock_at_h set): when, where, what they left open."""
    out_of_service_runs: Table | None = None
    """Runs in which orders waited while every AGV was out of service: when, how long."""
    out_of_service_advice: str = ""
    open_orders: str = ""
    """One line on the orders open at the end of the finished runs, when any run left some."""


def section_runs(data: ReportData) -> RunsSection:
    summary = data.summary
    bad = summary[summary["status"] != "ok"]
    wall = float(summary["wall_s"].fillna(0).sum()) if "wall_s" in summary else 0.0
    failed = (Table(["run", "status", "error"],
                    [[str(r["run_id"]), str(r["status"]), str(r.get("error", ""))]
                     for _, r in bad.iterrows()])
              if not bad.empty else None)
    database = (data.out_dir / "sweep.duckdb").resolve()
    sec = RunsSection(runs=len(summary), finished=len(summary) - len(bad), failed=len(bad),
                      wall_s=f"{wall:.0f}", failed_runs=failed, database=str(database),
                      query=query_command(database, data.factors,
                                          orders=any((data.out_dir / "runs").glob(
                                              "*/orders.parquet"))))
    sec.text += [f"run {r['run_id']}: {r['status']}: {r.get('error', '')}"
                 for _, r in bad.iterrows()]
    locked = gridlocked_runs(summary)
    if not locked.empty:
        rows = [[str(r["run_id"]), fmt(r["gridlock_at_h"]), str(r.get("gridlock_where") or ""),
                 fmt(r.get("orders_open_at_end")), fmt(r.get("open_order_age_max_s"))]
                for _, r in locked.iterrows()]
        sec.gridlocked_runs = Table(["run", "gridlock at (h)", "where", "orders open at end",
                                     "oldest open order (s)"], rows)
        sec.text += [f"run {r[0]}: GRIDLOCK at {r[1]} h, {r[2]}; {r[3]} orders open"
                     for r in rows]
    down = stalled_runs(summary, "out_of_service_h")
    if not down.empty:
        rows = [[str(r["run_id"]), fmt(r["out_of_service_at_h"]), fmt(r["out_of_service_h"]),
                 fmt(r.get("orders_open_at_end"))] for _, r in down.iterrows()]
        sec.out_of_service_runs = Table(["run", "from (h)", "for (h)", "orders open at end"],
                                        rows)
        sec.out_of_service_advice = OUT_OF_SERVICE_ADVICE
        sec.text += [f"run {r[0]}: OUT OF SERVICE from {r[1]} h for {r[2]} h" for r in rows]
    sec.open_orders = open_orders_line(summary)
    if sec.open_orders:
        sec.text.append(sec.open_orders)
    return sec


def query_command(database: Path, factors: list[str], orders: bool = True,
                  python: str | None = None) -> str:
    """A shell command that queries `database` (sweep.duckdb) by design point, through the
    DuckDB Python package of the Python running fleet-sim (no `duckdb` command needed): the
    lead times of the orders delivered after the warm-up (view `orders`, or the summary's KPIs
    when no run wrote orders), grouped by the study's own factors."""
    columns = "".join(f's."{f}", ' for f in factors)
    if orders:
        sql = (f"SELECT {columns}count(DISTINCT run_id) AS runs, count(*) AS orders, "
               "round(avg(o.lead_time_s), 1) AS lead_time_mean_s FROM orders o JOIN summary s "
               "USING (run_id) WHERE o.delivered_s >= s.warmup_h * 3600")
    else:
        sql = (f"SELECT {columns}count(*) AS runs, round(avg(s.throughput_per_hour), 2) AS "
               "throughput_per_hour FROM summary s WHERE s.status = 'ok'")
    if factors:
        sql += " GROUP BY ALL ORDER BY ALL"
    code = (f"import duckdb; print(duckdb.connect({str(database)!r}, read_only=True)"
            f".sql({sql!r}))")
    quoted = "".join("\\" + c if c in '"\\$`' else c for c in code)
    return f'{shlex.quote(python or sys.executable)} -c "{quoted}"'


def open_orders_line(summary: pd.DataFrame) -> str:
    """Orders open at the end of the finished runs, when any run left some ("" if none)."""
    if "orders_open_at_end" not in summary.columns:
        return ""
    ok = summary[summary["status"] == "ok"]
    open_orders = ok["orders_open_at_end"].fillna(0)
    if ok.empty or not (open_orders > 0).any():
        return ""
    oldest = ok["open_order_age_max_s"].max() if "open_order_age_max_s" in ok else None
    return (f"Orders open at the end of a run: {open_orders.mean():.1f} on average, at most "
            f"{int(open_orders.max())}; the oldest had waited {fmt(oldest)} s (lead times count "
            "delivered orders only; a lead-time target also holds the open orders' age to "
            "its bound).")
