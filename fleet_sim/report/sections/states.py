"""The Utilisation by state section: the mean share of AGV time in each state, as stacked bars
per series.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from fleet_sim.report import figures as figs
from fleet_sim.report.content import Section, png_figure
from fleet_sim.report.results_folder import ReportData


@dataclass(kw_only=True)
class StatesSection(Section):
    title: ClassVar[str] = "Utilisation by state"
    template: ClassVar[str] = "states.html.j2"
    has_states: bool


def section_states(data: ReportData) -> StatesSection:
    states = [c for c in data.ok.columns if c.startswith("state_") and c.endswith("_pct")]
    sec = StatesSection(has_states=bool(states))
    if not states:
        return sec
    groups = data.ok.groupby(data.others, sort=True) if data.others else [((), data.ok)]
    for key, group in groups:
        values = key if isinstance(key, tuple) else (key,)
        name = data.series_key(dict(zip(data.others, values, strict=True)))
        means = group.groupby(data.x, sort=True)[states].mean().reset_index()
        title = "Utilisation by state" + (f" ({name})" if name else "")
        sec.figures.append(png_figure(f"states-{len(sec.figures)}", title,
                                      figs.state_bars(means, data.x, title)))
    return sec
