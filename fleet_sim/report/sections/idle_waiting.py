"""The Idle AGVs while orders wait section (work conservation): the design points where AGVs
stood Idle while orders waited, by reason, and the setup warnings the runs recorded.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from fleet_sim.analysis.kpis import BY_REASON
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.report.content import Section, Table
from fleet_sim.report.results_folder import ReportData
from fleet_sim.report.wording import fmt


@dataclass(kw_only=True)
class IdleWaitingSection(Section):
    title: ClassVar[str] = "Idle AGVs while orders wait"
    template: ClassVar[str] = "idle_waiting.html.j2"
    runs: int
    runs_above_zero: int
    points: Table | None = None
    """Design points with AGVs Idle while orders waited: mean share of AGV time, by reason."""
    reasons: list[tuple[str, str]] = field(default_factory=list)
    """(reason, meaning) of the reasons in the table."""
    warnings: list[str] = field(default_factory=list)
    """The runs' setup warnings, each once, with how many runs recorded it."""


IDLE_WAITING = "idle_with_orders_waiting_pct"


def section_idle_waiting(data: ReportData) -> IdleWaitingSection:
    ok = data.ok
    warnings: dict[str, int] = {}
    if "setup_warnings" in ok:
        for text in ok["setup_warnings"].dropna().astype(str):
            for line in filter(None, text.split("\n")):
                warnings[line] = warnings.get(line, 0) + 1
    shown = [f"{line} ({n} of {len(ok)} runs)" for line, n in warnings.items()]
    if IDLE_WAITING not in ok:
        sec = IdleWaitingSection(runs=len(ok), runs_above_zero=0, warnings=shown)
        sec.text += ["Settings warning: " + w for w in shown]
        return sec
    above = ok[ok[IDLE_WAITING].fillna(0) > 0]
    sec = IdleWaitingSection(runs=len(ok), runs_above_zero=len(above), warnings=shown)
    sec.text += ["Settings warning: " + w for w in shown]
    if above.empty:
        sec.text.append("No AGV stood Idle while orders waited in any run.")
        return sec
    reasons = [r for r in NotDispatched if f"{BY_REASON}.{r.value}" in ok
               and float(ok[f"{BY_REASON}.{r.value}"].fillna(0).max()) > 0]
    columns = [IDLE_WAITING, *(f"{BY_REASON}.{r.value}" for r in reasons)]
    keys = [*data.others, data.x] if data.x else []
    means = ok.groupby(keys, sort=True, dropna=False)[columns].mean().reset_index() if keys \
        else ok[columns].mean().to_frame().T
    means = means[means[IDLE_WAITING] > 0]
    rows = [[*(str(r[k]) for k in keys), *(fmt(float(r[c]), 3) for c in columns)]
            for r in means.to_dict("records")]
    sec.points = Table([*keys, "Idle with orders waiting [% of AGV time]",
                        *(r.value for r in reasons)], rows, "stats")
    sec.reasons = [(r.value, r.meaning) for r in reasons]
    sec.text.append(f"AGVs stood Idle while orders waited in {len(above)} of {len(ok)} runs "
                    "(mean % of AGV time; by reason):")
    sec.text += [", ".join(f"{h} {c}" for h, c in zip(sec.points.header, row, strict=True))
                 for row in rows]
    return sec
