"""The Charging and battery section: the runs' charging KPIs against the x axis, SOC curves of
a few AGVs, and the design points whose runs were starved of charging.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pandas as pd

from fleet_sim.analysis.kpis import CHARGING_ADVICE
from fleet_sim.analysis.stats import kpi_columns
from fleet_sim.config.experiment import level_text
from fleet_sim.report import figures as figs
from fleet_sim.report.content import Section, Table, png_figure
from fleet_sim.report.results_folder import ReportData, sample_runs
from fleet_sim.report.wording import fmt


@dataclass(kw_only=True)
class ChargingSection(Section):
    title: ClassVar[str] = "Charging and battery"
    template: ClassVar[str] = "charging.html.j2"
    charging: bool
    starvation: Table | None = None
    """Per design point, the runs starved of charging (charging_starvation_h above zero)."""
    advice: str = ""


def section_charging(data: ReportData, series: dict[str, pd.DataFrame],
                     recommended: dict[str, int | None]) -> ChargingSection:
    ok = data.ok
    kpis = [c for c in kpi_columns(ok, data.factors)
            if c in ("state_charging_pct", "charges", "charging_queue_wait_mean_s")
            or c.startswith(("charger_", "soc_", "battery_"))]
    active = [k for k in kpis if float(ok[k].fillna(0).abs().max()) > 0]
    sec = ChargingSection(charging=bool(active))
    sec.starvation = starvation_table(data)
    if sec.starvation is not None:
        sec.advice = CHARGING_ADVICE
        sec.text += [f"charging starvation: {', '.join(row)}" for row in sec.starvation.rows]
    if not active:
        sec.text.append("No charging in these runs.")
    else:
        sec.figures.append(png_figure("charging", "Charging against " + data.x,
                                      figs.kpi_panels(series, data.x, active, data.targets,
                                                      recommended)))
    sample = sample_runs(data, recommended)
    for run_id in sample[:1]:
        run_dir = data.out_dir / "runs" / run_id
        table = run_dir / "soc.parquet"
        if not table.exists():
            table = run_dir / "events.parquet"
        if not table.exists():
            continue
        frame = pd.read_parquet(table)
        if "soc_pct" in frame.columns:
            agvs = sorted(frame["agv"].unique())[:4]
            curves = frame[frame["agv"].isin(agvs)][["time_s", "agv", "soc_pct"]].dropna()
            if not curves.empty:
                sec.figures.append(png_figure("soc", f"SOC of {len(agvs)} AGVs, run {run_id}",
                                              figs.soc_curves(curves, f"State of charge, run "
                                                              f"{run_id}")))
    return sec


def starvation_table(data: ReportData) -> Table | None:
    """Per design point with a starved run: the runs starved, the mean hours of starvation
    over all its runs, the earliest start, the most AGVs held by their batteries at once."""
    ok = data.ok
    if "charging_starvation_h" not in ok.columns:
        return None
    hours = pd.to_numeric(ok["charging_starvation_h"], errors="coerce").fillna(0)
    if not (hours > 0).any():
        return None
    factors = [f for f in data.factors if f in ok.columns]
    frame = ok.assign(_h=hours, _at=pd.to_numeric(ok["charging_starvation_at_h"],
                                                   errors="coerce"),
                      _peak=pd.to_numeric(ok["charging_starvation_peak_agvs"],
                                          errors="coerce"))
    groups = frame.groupby(factors, sort=True, dropna=False) if factors else [((), frame)]
    rows = []
    for key, group in groups:
        starving = group[group["_h"] > 0]
        if starving.empty:
            continue
        values = key if isinstance(key, tuple) else (key,)
        rows.append([*(level_text(v) for v in values), f"{len(starving)} of {len(group)}",
                     f"{group['_h'].mean():.2f}", f"{starving['_at'].min():.2f}",
                     f"{int(starving['_peak'].max())} of {int(group['agvs'].max())}"
                     if "agvs" in group else fmt(starving["_peak"].max())])
    return Table([*factors, "runs starved", "starvation per run (h, mean)",
                  "first from (h)", "most AGVs held by their batteries"], rows)
