"""The report of a sweep or a sizing search: a results folder -> a `Report` of plain data (text,
formatted numbers, tables of strings, figures), which fleet_sim.report.render turns into HTML
(Jinja2 templates) and a PDF.

Sections, one module each in fleet_sim.report.sections beside its template: the recommendation
with its confidence (fleet_sim.report.answer: from sizing.json when `fleet-sim size` ran, else
from the sweep's grid with the same rule: the smallest fleet whose 95 % intervals meet every
target); the scenario and the layout; throughput and p95 lead time (and every target's KPI)
against fleet size with 95 % bands and the targets; utilisation by state as stacked bars;
charging and battery; congestion (blocked time, and a heat map of where AGVs waited on the
layout drawing); AGVs standing Idle while orders waited, by reason, and the runs' settings
warnings; a run in detail; incidents (deadlocks, reroutes, give-way circulations); statistics
per design point, wide-interval warnings and paired differences; failed runs.

What the study is sets the title and the first screen (`ReportData.kind`): a sizing search
(sizing.json: "Fleet sizing report", the recommendation), a sweep over the fleet factor with
targets ("Fleet sizing sweep", the smallest fleet of the grid meeting every target), any other
sweep ("Sweep over demand rate per hour and dispatch policy", "What the sweep shows": one
sentence per factor). A comparison of variants has its own report (compare_report), and so
has an optimise search (optimise_report).

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import time
from pathlib import Path

import pandas as pd

from fleet_sim.analysis.kpis import kpi_short, target_words
from fleet_sim.analysis.stats import point_stats
from fleet_sim.errors import InputError
from fleet_sim.report.answer import recommendations
from fleet_sim.report.content import Report, Section
from fleet_sim.report.results_folder import ReportData, load, series_of
from fleet_sim.report.sections.charging import section_charging
from fleet_sim.report.sections.congestion import section_congestion
from fleet_sim.report.sections.detail import section_detail
from fleet_sim.report.sections.idle_waiting import section_idle_waiting
from fleet_sim.report.sections.incidents import section_incidents
from fleet_sim.report.sections.kpis import section_kpis
from fleet_sim.report.sections.runs import section_runs
from fleet_sim.report.sections.scenario import section_scenario
from fleet_sim.report.sections.states import section_states
from fleet_sim.report.sections.statistics import section_statistics
from fleet_sim.report.stalls import stall_statements
from fleet_sim.report.wording import and_words, factor_words
from fleet_sim.study.study_folder import read_plan, study_running


def progress_text(out_dir: Path, summary: pd.DataFrame) -> str:
    """For a study not (yet) finished, the sentence that says so first: "12 of 28 runs
    finished, sweep still running." (or stopped); runs found damaged are named. Empty for a
    finished study."""
    plan = read_plan(out_dir) or {}
    study = str(plan.get("study") or "study")
    planned = plan.get("runs")
    statuses = summary["status"].astype(str) if len(summary) else pd.Series(dtype=str)
    n_ok = int((statuses == "ok").sum())
    running = study_running(out_dir)
    damaged = [str(r) for r in summary.loc[statuses == "damaged", "run_id"]] \
        if len(summary) else []
    text = ""
    if running or (isinstance(planned, list) and n_ok < len(planned)):
        total = f" of {len(planned)}" if isinstance(planned, list) else ""
        state = "still running" if running else "stopped before it finished (run it again to go on)"
        text = f"{n_ok}{total} runs finished, {study} {state}. "
    if damaged:
        shown = ", ".join(damaged[:3]) + (f" and {len(damaged) - 3} more" if len(damaged) > 3
                                          else "")
        text += (f"{len(damaged)} finished run(s) found damaged ({shown}): left out; run the "
                 f"{study} again to make them again. ")
    return text


def build_report(out_dir: Path) -> Report:
    """Read a results folder and prepare every section (figures drawn, numbers formatted).

    The report keeps matplotlib figures for the PDF: call `Report.close` when done."""
    data = load(out_dir)
    stats = point_stats(data.summary, data.factors)
    if stats.empty:
        raise InputError(str(out_dir), "runs", 0, "at least one finished run")
    series = series_of(data, stats)
    recommended, statements, estimates = recommendations(data)
    sections: list[Section] = [
        section_scenario(data), section_kpis(data, series, recommended), section_states(data),
        section_idle_waiting(data), section_charging(data, series, recommended),
        section_congestion(data, series, recommended), section_detail(data, recommended),
        section_incidents(data, recommended),
        section_statistics(data, stats), section_runs(data)]
    statements = [*stall_statements(data.summary), *statements]
    name = data.experiment.get("name", "experiment")
    n_ok = int((data.summary["status"] == "ok").sum())
    lead = (f"{question(data)} {progress_text(out_dir, data.summary)}{n_ok} of "
            f"{len(data.summary)} runs finished; generated {time.strftime('%Y-%m-%d %H:%M')} "
            "by fleet-sim.")
    if data.kind == "sweep":
        what = "Sweep over " + and_words([factor_words(f) for f in data.factors]) \
            if data.factors else "Replications of one design point"
        return Report(f"{what}: {name}", lead, statements, estimates, sections,
                      answer_title="What the sweep shows")
    title = "Fleet sizing report" if data.kind == "sizing" else "Fleet sizing sweep"
    return Report(f"{title}: {name}", lead, statements, estimates, sections)


def question(data: ReportData) -> str:
    """The report's first sentence: the question the study answers, in a planner's words."""
    scenario = data.scenario.name if data.scenario else "?"
    layout = data.layout.name if data.layout else "?"
    targets = "; ".join(target_words(t) for t in data.targets)
    points = data.ok.groupby(data.factors, dropna=False).ngroups if data.factors else 1
    if data.kind == "sizing":
        return (f"How many {data.fleet_unit} does scenario {scenario} on layout {layout} need "
                f"to meet its targets ({targets})? `fleet-sim size` searched the fleet sizes, "
                "adding replications until each was decided.")
    if data.kind == "sizing sweep":
        return (f"How many {data.fleet_unit} does scenario {scenario} on layout {layout} need "
                f"to meet its targets ({targets})? A sweep of {points} design points answers "
                "from its grid.")
    shorts = list(dict.fromkeys(kpi_short(k) for k in data.compared_kpis))
    kpis = and_words(shorts) if shorts else "the KPIs"
    if not data.factors:
        return f"Scenario {scenario} on layout {layout}: {kpis} over its replications."
    return (f"How {kpis} change with {and_words([factor_words(f) for f in data.factors])}: "
            f"scenario {scenario} on layout {layout}, {points} design points, replication r "
            "with the same seed at every point (common random numbers), so each change is "
            "measured as a paired difference.")
