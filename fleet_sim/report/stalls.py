"""Stalls of a study's runs, each named for what it is: runs that locked solid (gridlock), runs
starved of charging, runs whose whole fleet stood out of service; which runs, and the report's
statement on each (also printed by the commands, fleet_sim.report.console).

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import pandas as pd

from fleet_sim.analysis.kpis import CHARGING_ADVICE, OUT_OF_SERVICE_ADVICE


def gridlocked_runs(summary: pd.DataFrame) -> pd.DataFrame:
    """The finished runs of a summary that locked solid (a gridlock_at_h), by run id."""
    if "gridlock_at_h" not in summary.columns:
        return summary.iloc[0:0]
    ok = summary[summary["status"] == "ok"]
    return ok[ok["gridlock_at_h"].notna()].sort_values("run_id")


def gridlock_statement(summary: pd.DataFrame) -> str | None:
    """The report's warning when runs locked solid (None when none did)."""
    locked = gridlocked_runs(summary)
    if locked.empty:
        return None
    finished = int((summary["status"] == "ok").sum())
    first = locked.sort_values("gridlock_at_h").iloc[0]
    return (f"WARNING: {len(locked)} of {finished} finished runs locked solid (gridlock; the "
            f"earliest {first['run_id']} at {float(first['gridlock_at_h']):.2f} h): their "
            "throughput and lead times describe a stopped fleet. Limit the AGVs on the floor "
            "(admission, dispatch.max_active_agvs) or run fewer AGVs; the runs are listed "
            "under Runs.")


def stalled_runs(summary: pd.DataFrame, kpi: str) -> pd.DataFrame:
    """The finished runs of a summary with `kpi` (charging_starvation_h, out_of_service_h)
    above zero, by run id."""
    if kpi not in summary.columns:
        return summary.iloc[0:0]
    ok = summary[summary["status"] == "ok"]
    return ok[pd.to_numeric(ok[kpi], errors="coerce").fillna(0) > 0].sort_values("run_id")


def starvation_statement(summary: pd.DataFrame) -> str | None:
    """The report's statement when runs were starved of charging (None when none was)."""
    starving = stalled_runs(summary, "charging_starvation_h")
    if starving.empty:
        return None
    finished = int((summary["status"] == "ok").sum())
    hours = pd.to_numeric(starving["charging_starvation_h"])
    at_h = pd.to_numeric(starving["charging_starvation_at_h"])
    peak = starving.sort_values("charging_starvation_peak_agvs", ascending=False,
                                kind="stable").iloc[0]
    return (f"CHARGING STARVATION in {len(starving)} of {finished} finished runs: orders waited, "
            "no AGV free to take them, while AGVs waited for a charger, "
            f"{hours.mean():.2f} h per run on average (at most {hours.max():.2f} h), first "
            f"from {at_h.min():.2f} h; at worst {peak['charging_starvation_worst']} (run "
            f"{peak['run_id']}): the fleet charges together, not a traffic gridlock. "
            f"{CHARGING_ADVICE}")


def out_of_service_statement(summary: pd.DataFrame) -> str | None:
    """The report's statement when every AGV of a run stood out of service while orders
    waited (None when that never happened)."""
    down = stalled_runs(summary, "out_of_service_h")
    if down.empty:
        return None
    finished = int((summary["status"] == "ok").sum())
    first = down.sort_values("out_of_service_at_h").iloc[0]
    return (f"OUT OF SERVICE in {len(down)} of {finished} finished runs: orders waited while "
            "every AGV was in Error, Maintenance or SafeMode (the earliest "
            f"{first['run_id']} from {float(first['out_of_service_at_h']):.2f} h, for "
            f"{float(first['out_of_service_h']):.2f} h); the runs are listed under Runs. "
            f"{OUT_OF_SERVICE_ADVICE}")


def stall_statements(summary: pd.DataFrame) -> list[str]:
    """The statements on gridlock, charging starvation and a fleet out of service, in that
    order, those that apply."""
    return [s for s in (gridlock_statement(summary), starvation_statement(summary),
                        out_of_service_statement(summary)) if s is not None]
