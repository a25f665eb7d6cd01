"""The Congestion section: blocked time against the x axis, and a heat map of where AGVs waited
on the layout drawing with the nodes of most waiting.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pandas as pd

from fleet_sim.report import figures as figs
from fleet_sim.report.content import Figure, Section, Table, png_figure
from fleet_sim.report.results_folder import ReportData, sample_runs
from fleet_sim.report.wording import fmt


@dataclass(kw_only=True)
class CongestionSection(Section):
    title: ClassVar[str] = "Congestion"
    template: ClassVar[str] = "congestion.html.j2"
    has_waits: bool
    level: str = ""
    """The design point of the heat map, as ``fleet.size = 8``."""
    top_nodes: Table | None = None


def section_congestion(data: ReportData, series: dict[str, pd.DataFrame],
                       recommended: dict[str, int | None]) -> CongestionSection:
    figures: list[Figure] = []
    if "blocked_time_pct" in set(next(iter(series.values()))["kpi"]):
        figures.append(png_figure("blocked", "Blocked time against " + data.x,
                                  figs.kpi_panels(series, data.x, ["blocked_time_pct"], [],
                                                  recommended)))
    sample = sample_runs(data, recommended)
    frames = []
    for run_id in sample:
        path = data.out_dir / "runs" / run_id / "node_waits.parquet"
        if path.exists():
            frames.append(pd.read_parquet(path).assign(run_id=run_id))
    if data.layout is None or not frames:
        return CongestionSection(has_waits=False, figures=figures)
    waits = pd.concat(frames)
    window_h = float(data.ok["duration_h"].iloc[0] - data.ok["warmup_h"].iloc[0]) \
        if "duration_h" in data.ok else 1.0
    per_node = (waits.groupby("node")["wait_s"].sum() / len(frames) / window_h).reset_index()
    per_node = per_node.rename(columns={"wait_s": "wait_s_per_h"})
    level = data.ok[data.ok["run_id"].isin(sample)][data.x].iloc[0]
    title = (f"Where AGVs waited: {data.x} = {level}, mean of {len(frames)} replications "
             "(seconds of waiting per hour at each node)")
    figures.append(png_figure("heatmap", title, figs.heat_map(data.layout, per_node, title)))
    top = per_node.sort_values("wait_s_per_h", ascending=False).head(8)
    top = top[top["wait_s_per_h"] > 0]
    rows = [[str(node), fmt(float(value), 3)]
            for node, value in zip(top["node"], top["wait_s_per_h"], strict=True)]
    sec = CongestionSection(has_waits=True, level=f"{data.x} = {level}", figures=figures,
                            top_nodes=Table(["node", "AGV waiting [s/h]"], rows) if rows
                            else None)
    if rows:
        sec.text.append("Most waiting at: " + ", ".join(
            f"{node} ({float(value):.0f} s/h)"
            for node, value in zip(top["node"], top["wait_s_per_h"], strict=True)))
    return sec
