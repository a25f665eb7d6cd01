"""The Throughput and lead time section: the main KPIs and every target's against the x axis,
with their 95 % bands and the targets.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pandas as pd

from fleet_sim.report import figures as figs
from fleet_sim.report.content import Section, png_figure
from fleet_sim.report.results_folder import MAIN_KPIS, ReportData


@dataclass(kw_only=True)
class KpiSection(Section):
    title: ClassVar[str] = "Throughput and lead time"
    template: ClassVar[str] = "kpis.html.j2"


def section_kpis(data: ReportData, series: dict[str, pd.DataFrame],
                 recommended: dict[str, int | None]) -> KpiSection:
    sec = KpiSection()
    kpis = [k for k in MAIN_KPIS if k in set(next(iter(series.values()))["kpi"])]
    kpis += [t.kpi for t in data.targets if t.kpi not in kpis]
    sec.figures.append(png_figure("kpis", "KPIs against " + data.x,
                                  figs.kpi_panels(series, data.x, kpis, data.targets,
                                                  recommended)))
    return sec
