"""The Incidents section: deadlocks, reroutes, give-way circulations and back-offs against the
x axis, and the deadlocks in runs of the recommended fleet.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pandas as pd

from fleet_sim.report import figures as figs
from fleet_sim.report.content import Section, Table, png_figure
from fleet_sim.report.results_folder import ReportData, sample_runs
from fleet_sim.report.wording import fmt
from fleet_sim.study.results import runs_table_sql

INCIDENT_EVENTS = ("deadlock_detected", "deadlock_unresolved", "reroute", "circulate", "backoff")


@dataclass(kw_only=True)
class IncidentsSection(Section):
    title: ClassVar[str] = "Incidents"
    template: ClassVar[str] = "incidents.html.j2"
    deadlocks: int
    runs: int
    deadlock_events: Table | None = None


def section_incidents(data: ReportData, recommended: dict[str, int | None]) -> IncidentsSection:
    ok = data.ok
    counts = _incident_counts(data)
    total = int(ok["deadlocks_detected"].fillna(0).sum()) if "deadlocks_detected" in ok else 0
    sec = IncidentsSection(deadlocks=total, runs=len(ok))
    if data.x:
        merged = ok[["run_id", data.x, *data.others]]
        if "deadlocks_detected" in ok:
            merged = merged.assign(deadlocks=ok["deadlocks_detected"].fillna(0))
        if counts is not None:
            merged = merged.merge(counts, on="run_id", how="left")
        kinds = [k for k in ("deadlocks", *INCIDENT_EVENTS[1:]) if k in merged.columns]
        if kinds:
            merged = merged.assign(**{k: merged[k].fillna(0) for k in kinds})
            first = merged
            for name in data.others:
                first = first[first[name] == merged.sort_values(data.others)[name].iloc[0]]
            mean = first.groupby(data.x)[kinds].mean().reset_index()
            sec.figures.append(png_figure("incidents", "Incidents against " + data.x,
                                          figs.incidents(mean, data.x)))
    sec.text.append(f"{total} deadlocks detected in {len(ok)} runs.")
    rows: list[list[str]] = []
    for run_id in sample_runs(data, recommended)[:3]:
        path = data.out_dir / "runs" / run_id / "events.parquet"
        if not path.exists():
            continue
        events = pd.read_parquet(path, columns=["time_s", "agv", "event", "node", "detail"])
        dead = events[events["event"].astype(str) == "deadlock_detected"]
        for _, r in dead.head(4).iterrows():
            rows.append([run_id, fmt(float(r["time_s"]) / 3600.0, 3), str(r["agv"]),
                         str(r["event"]), str(r["node"]), str(r["detail"])])
    if rows:
        sec.deadlock_events = Table(["run", "time [h]", "AGV", "event", "node", "detail"], rows)
    return sec


def _incident_counts(data: ReportData) -> pd.DataFrame | None:
    import duckdb

    events = runs_table_sql(data.out_dir / "runs", "events")
    if events is None:
        return None
    kinds = ", ".join(f"'{k}'" for k in INCIDENT_EVENTS)
    con = duckdb.connect()
    try:
        frame = con.execute(f"SELECT run_id, event, count(*) AS n FROM ({events}) "
                            f"WHERE event IN ({kinds}) GROUP BY ALL").df()
    finally:
        con.close()
    if frame.empty:
        return pd.DataFrame({"run_id": pd.Series(dtype="string")})
    return frame.pivot_table(index="run_id", columns="event", values="n",
                             aggfunc="sum").reset_index()
