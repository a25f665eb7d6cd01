"""The report's content: a sweep or sizing results folder -> a `Report` of plain data (text,
formatted numbers, tables of strings, figures), which fleet_sim.report.render turns into HTML
(Jinja2 templates) and a PDF.

Sections: the recommendation with its confidence (from sizing.json when `fleet-sim size` ran,
else from the sweep's grid with the same rule: the smallest fleet whose 95 % intervals meet every
target); the scenario and the layout; throughput and p95 lead time (and every target's KPI)
against fleet size with 95 % bands and the targets; utilisation by state as stacked bars;
charging and battery; congestion (blocked time, and a heat map of where AGVs waited on the layout
drawing); AGVs standing Idle while orders waited, by reason, and the runs' settings warnings;
incidents (deadlocks, reroutes, give-way circulations); statistics per design point,
wide-interval warnings and paired differences; failed runs.

What the study is sets the title and the first screen (`ReportData.kind`): a sizing search
(sizing.json: "Fleet sizing report", the recommendation), a sweep over the fleet factor with
targets ("Fleet sizing sweep", the smallest fleet of the grid meeting every target), any other
sweep ("Sweep over demand rate per hour and dispatch policy", "What the sweep shows": one
sentence per factor). A comparison of variants has its own report (compare_report).

Decisions, where the issue is silent:

* Nothing here writes markup: every string is plain text (names from user files as they are),
  and the templates escape it. The prose of each section lives in its template
  (``templates/sections/``); the PDF's plain-text lines (`Section.text`) are written here.
* Figures are PNG, base64-embedded: the HTML is one file that opens anywhere, offline. The PDF
  has the same figures (vector) after a text page with the recommendation and the tables.
* The x axis is fleet.size when it is a factor, else the first factor; each combination of the
  other factors is one line (series).
* The heat map shows the mean seconds per hour that AGVs with work to do stood waiting at each
  node (fleet_sim.analysis.congestion), over the replications of the recommended fleet (else the
  largest fleet run).
* A run in detail: the first replication of the recommended fleet (of the first series; else
  of its largest fleet run) is simulated again from its config.resolved.yaml with the AGVs'
  moves recorded (fleet_sim.analysis.replay.load_run: the re-run must reproduce the run's
  events), for its per-AGV timeline (an inline SVG: hover shows the order and the reason, no
  script) and the breakdown of its orders' lead times (orders delivered after the warm-up).
  If the run cannot be reproduced, the timeline is drawn from its events and the lead times
  keep the blocked time inside the drives; the section says so. The PDF gets the same as
  matplotlib figures.
* Idle with orders waiting (work conservation): a table of the design points where the mean
  ``idle_with_orders_waiting_pct`` is above zero, with its reasons (the reasons above zero
  somewhere), and the setup warnings the runs recorded (kpis.json ``setup_warnings``), each
  once with the number of runs. Where it is zero everywhere, one sentence says so.
* A sweep's sentences: per factor, a number factor from its lowest to its highest level, any
  other factor each level against its first as the file lists it; the difference is averaged
  over the other factors' levels replication by replication (stats.factor_effect), so one
  sentence speaks for the whole grid (the Statistics section has every one-factor pair at
  every level of the others). A KPI whose 95 % interval excludes zero is said with a verb
  ("raises throughput by 26 orders/h (11 to 41 orders/h)"), the others as "no difference we
  can detect" with their intervals; results equal in every replication say so. At most
  MAX_STATEMENTS sentences; the KPIs are the targets', then throughput and p95 lead time.
* Names: a KPI is shown by its name and unit from the KPI catalogue (kpis.kpi_label), in
  tables and on axes; a factor by its dotted path in tables (what the file and the summary
  call it), in words ("demand rate per hour") in titles and sentences.
* The settings table counts the replications each design point actually ran (finished runs
  in the summary), as a range when they differ: a sizing search adds replications.
* The query hint runs the DuckDB Python package with the Python that wrote the report
  (sys.executable: the project's venv, or wherever fleet-sim is installed) on the
  database's absolute path, so it works from any folder and without the `duckdb` command;
  it groups by the study's own factors (none: one row).
* Charging: the runs' charging KPIs (``state_charging_pct``, ``charges``, the charger queue wait
  and any ``charger_*``/``soc_*`` KPI) against fleet size, and SOC curves of a few AGVs from the
  run's ``soc.parquet``. A run without charging says so instead of drawing empty axes.
* Stalls (issue 33, item 7), each named for what it is, with its own advice: runs that locked
  solid (gridlock: traffic; limit the AGVs on the floor), runs starved of charging (orders
  waited while AGVs waited for a charger: spread the charging) and runs whose whole fleet
  stood out of service (repairs). Each has a statement at the top when a run had it; the
  starvation a table per design point under Charging, the other two their runs under Runs.
"""

from __future__ import annotations

import base64
import json
import math
import shlex
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd
import yaml

from fleet_sim.analysis.kpis import (
    BY_REASON,
    CHARGING_ADVICE,
    OUT_OF_SERVICE_ADVICE,
    kpi_better,
    kpi_label,
    kpi_short,
    kpi_unit,
    target_words,
)
from fleet_sim.analysis.paired import number_text, signed_text
from fleet_sim.analysis.replay import LEAD_LABELS, LEAD_PARTS, lead_times, load_run, state_spells
from fleet_sim.analysis.stats import (
    PairDifference,
    check_targets,
    factor_effect,
    is_number,
    kpi_columns,
    one_factor_pairs,
    paired_differences,
    point_stats,
)
from fleet_sim.config.experiment import FLEET, Target, layout_for, level_text, point_text
from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario, load_scenario, type_count_path
from fleet_sim.errors import InputError
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.model.states import VehicleState
from fleet_sim.report import figures as figs
from fleet_sim.study.results import read_summary, runs_table_sql
from fleet_sim.study.runner import read_plan, study_running

INCIDENT_EVENTS = ("deadlock_detected", "deadlock_unresolved", "reroute", "circulate", "backoff")
MAIN_KPIS = ("throughput_per_hour", "lead_time_p95_s")
TABLE_KPIS = ("throughput_per_hour", "throughput_pct_of_demand", "lead_time_mean_s",
              "lead_time_p95_s", "agv_utilisation_pct", "blocked_time_pct", "deadlocks_detected")


def fmt(value: Any, digits: int = 4) -> str:
    """Numbers for tables: no exponents for the sizes a planner reads."""
    if value is None:
        return "n/a"
    if isinstance(value, (float, np.floating)):
        if np.isnan(value):
            return "n/a"
        if abs(value) >= 10 ** (digits - 1):
            return f"{value:,.0f}"
        return f"{value:.{digits}g}"
    return str(value)


# ---- what the templates are given ----------------------------------------------------------


@dataclass(frozen=True)
class Figure:
    """One figure: PNG for the HTML page, and the matplotlib figure for the PDF."""

    key: str
    caption: str
    png: bytes
    pdf_figure: Any = None
    in_html: bool = True
    """False: for the PDF only (the page shows the same otherwise, such as an inline SVG)."""

    @property
    def data_uri(self) -> str:
        """The PNG as a data: URI (base64 has no character HTML needs to escape)."""
        return "data:image/png;base64," + base64.b64encode(self.png).decode("ascii")


@dataclass(frozen=True)
class Table:
    """A table of plain-text cells (the template escapes them)."""

    header: list[str]
    rows: list[list[str]]
    css_class: str = ""


@dataclass(kw_only=True)
class Section:
    """A section of the report; each subclass has its template in templates/sections/."""

    title: ClassVar[str]
    template: ClassVar[str]
    figures: list[Figure] = field(default_factory=list)
    text: list[str] = field(default_factory=list)
    """Plain text for the PDF's text page."""


@dataclass(kw_only=True)
class ScenarioSection(Section):
    title: ClassVar[str] = "Scenario and layout"
    template: ClassVar[str] = "scenario.html.j2"
    settings: Table
    problem: str = ""


@dataclass(kw_only=True)
class KpiSection(Section):
    title: ClassVar[str] = "Throughput and lead time"
    template: ClassVar[str] = "kpis.html.j2"


@dataclass(kw_only=True)
class StatesSection(Section):
    title: ClassVar[str] = "Utilisation by state"
    template: ClassVar[str] = "states.html.j2"
    has_states: bool


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


@dataclass(kw_only=True)
class ChargingSection(Section):
    title: ClassVar[str] = "Charging and battery"
    template: ClassVar[str] = "charging.html.j2"
    charging: bool
    starvation: Table | None = None
    """Per design point, the runs starved of charging (charging_starvation_h above zero)."""
    advice: str = ""


@dataclass(kw_only=True)
class CongestionSection(Section):
    title: ClassVar[str] = "Congestion"
    template: ClassVar[str] = "congestion.html.j2"
    has_waits: bool
    level: str = ""
    """The design point of the heat map, as ``fleet.size = 8``."""
    top_nodes: Table | None = None


@dataclass(frozen=True)
class GanttBar:
    """One spell of one AGV in the timeline: position in the SVG's units, colour, hover."""

    x: float
    y: float
    width: float
    colour: str
    loaded: bool
    title: str


@dataclass(frozen=True)
class Gantt:
    """The timeline of one run as an inline SVG (drawn by the template, escaped)."""

    width: int
    height: int
    label_width: int
    row_height: int
    rows: list[tuple[str, int]]
    """(label, y) per AGV."""
    ticks: list[tuple[float, str]]
    """(x, label) along the time axis."""
    bars: list[GanttBar]
    legend: list[tuple[str, str]]
    """(state, colour)."""


@dataclass(kw_only=True)
class DetailSection(Section):
    title: ClassVar[str] = "A run in detail: timeline and lead times"
    template: ClassVar[str] = "detail.html.j2"
    run_id: str = ""
    level: str = ""
    run_dir: str = ""
    problem: str = ""
    gantt: Gantt | None = None
    lead_rows: Table | None = None
    orders: int = 0


@dataclass(kw_only=True)
class IncidentsSection(Section):
    title: ClassVar[str] = "Incidents"
    template: ClassVar[str] = "incidents.html.j2"
    deadlocks: int
    runs: int
    deadlock_events: Table | None = None


@dataclass(kw_only=True)
class StatisticsSection(Section):
    title: ClassVar[str] = "Statistics"
    template: ClassVar[str] = "statistics.html.j2"
    points: Table
    warnings: list[str]
    differences: Table | None = None


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


@dataclass(frozen=True)
class Report:
    """Everything the report shows, as plain data."""

    title: str
    lead: str
    statements: list[str]
    """The recommendation, one statement per series (bold in the page)."""
    estimates: list[str]
    sections: list[Section]
    template: str = "report.html.j2"
    """The page's template: a sweep's or sizing's report, or a comparison's (compare.html.j2)."""
    answer_title: str = "Recommendation"
    """The heading of the first screen's box (and of the PDF's first lines)."""

    def figures(self) -> Iterator[Figure]:
        for sec in self.sections:
            yield from sec.figures

    def close(self) -> None:
        """Free the matplotlib figures kept for the PDF."""
        for fig in self.figures():
            figs.close(fig.pdf_figure)


# ---- the results folder --------------------------------------------------------------------


@dataclass
class ReportData:
    out_dir: Path
    experiment: dict[str, Any]
    summary: pd.DataFrame
    factors: list[str]
    targets: list[Target]
    sizing: dict[str, Any] | None
    scenario: Scenario | None
    layout: Layout | None
    problem: str = ""

    @property
    def fleet(self) -> str:
        """The fleet's factor: fleet.size, or a mixed fleet's count of `sizing.vary_type`."""
        vary = (self.experiment.get("sizing") or {}).get("vary_type")
        return FLEET if vary is None else type_count_path(str(vary))

    @property
    def fleet_unit(self) -> str:
        """What the fleet factor counts: "AGVs", or "heavy AGVs"."""
        vary = (self.experiment.get("sizing") or {}).get("vary_type")
        return "AGVs" if vary is None else f"{vary} AGVs"

    @property
    def x(self) -> str:
        if self.fleet in self.factors:
            return self.fleet
        return self.factors[0] if self.factors else ""

    @property
    def others(self) -> list[str]:
        return [f for f in self.factors if f != self.x]

    @property
    def ok(self) -> pd.DataFrame:
        return self.summary[self.summary["status"] == "ok"]

    def series_key(self, row: dict[str, Any]) -> str:
        return point_text({k: row[k] for k in self.others})

    @property
    def kind(self) -> str:
        """What the study is: "sizing" (`fleet-sim size` ran: sizing.json), "sizing sweep" (a
        sweep over the fleet factor with targets), or "sweep" (any other sweep)."""
        if self.sizing is not None:
            return "sizing"
        if self.x == self.fleet and self.targets:
            return "sizing sweep"
        return "sweep"

    @property
    def listed(self) -> dict[str, list[Any]]:
        """Each factor's levels as the experiment file lists them."""
        return {name: list(levels) if isinstance(levels, list) else [levels]
                for name, levels in (self.experiment.get("factors") or {}).items()}

    @property
    def compared_kpis(self) -> list[str]:
        """The KPIs the study is about: every target's, then throughput and p95 lead time."""
        kpis = dict.fromkeys([*(t.kpi for t in self.targets), *MAIN_KPIS])
        return [k for k in kpis if k in self.summary.columns]


def load(out_dir: Path) -> ReportData:
    resolved = out_dir / "experiment.resolved.yaml"
    if not resolved.exists():
        raise InputError(str(out_dir), "folder", str(out_dir),
                         "a results folder of `fleet-sim sweep` or `fleet-sim size` "
                         "(with experiment.resolved.yaml)")
    experiment = yaml.safe_load(resolved.read_text(encoding="utf-8"))
    factors = list(experiment.get("factors") or {})
    # summary.parquet, unless the run folders say otherwise (a sweep or size killed before
    # it rewrote the summary): then the summary of the run folders themselves
    summary, _ = read_summary(out_dir, factors)
    if summary.empty or "status" not in summary.columns:
        raise InputError(str(out_dir), "runs", 0, "at least one run in the results folder")
    targets = [Target(kpi=t["kpi"], at_least=t.get("at_least"), at_most=t.get("at_most"))
               for t in experiment.get("targets") or []]
    sizing_file = out_dir / "sizing.json"
    sizing = json.loads(sizing_file.read_text(encoding="utf-8")) if sizing_file.exists() \
        else None
    scenario: Scenario | None = None
    layout: Layout | None = None
    problem = ""
    try:
        scenario = load_scenario(experiment["scenario"], experiment.get("overrides") or {})
        layout = layout_for(scenario, experiment["scenario"])
    except InputError as exc:
        problem = f"The scenario or layout could not be read again: {exc}"
    return ReportData(out_dir, experiment, summary, factors, targets, sizing, scenario, layout,
                      problem)


# ---- recommendation ------------------------------------------------------------------------


def recommendations(data: ReportData) -> tuple[dict[str, int | None], list[str], list[str]]:
    """Per series: the recommended fleet; the statements; the analytic estimates."""
    recommended: dict[str, int | None] = {}
    statements: list[str] = []
    estimates: list[str] = []
    if data.sizing is not None:
        for group in data.sizing.get("groups", []):
            key = data.series_key({k: group["fixed"].get(k) for k in data.others})
            recommended[key] = group.get("recommended")
            statements.append(group.get("statement", ""))
            est = group.get("estimate") or {}
            if est:
                estimates.append(
                    (f"{key}: " if key else "") +
                    f"analytic estimate {est['agvs']:.2f} AGVs busy at the mean demand of "
                    f"{est['demand_per_hour']:.1f} orders/h ({est['agvs_at_peak']:.2f} at the "
                    f"peak of {est['peak_demand_per_hour']:.1f}): {est['cycle_s']:.1f} s per "
                    f"order = {est['empty_travel_s']:.1f} s empty + {est['loaded_travel_s']:.1f}"
                    f" s loaded travel + {est['handling_s']:.1f} s handling, one AGV carries "
                    f"{est['capacity_per_agv_per_hour']:.1f} orders/h. So at least "
                    f"{est['minimum']} AGVs; the simulation adds waiting and traffic.")
        return recommended, statements, estimates
    if data.kind == "sweep":
        return recommended, sweep_statements(data), []
    checks = check_targets(data.summary, data.factors, data.targets)
    by_series: dict[str, dict[int, list[str]]] = {}
    for check in checks:
        key = data.series_key(check.point)
        by_series.setdefault(key, {}).setdefault(int(check.point[data.fleet]), []).append(
            check.decision)
    for key, sizes in by_series.items():
        meeting = [n for n, ds in sorted(sizes.items()) if all(d == "meets" for d in ds)]
        recommended[key] = meeting[0] if meeting else None
        head = f"{key}: " if key else ""
        if meeting:
            statements.append(f"{head}{meeting[0]} {data.fleet_unit} is the smallest fleet of "
                              "the grid that "
                              "meets every target with 95 % confidence (grid of the sweep; "
                              "`fleet-sim size` refines it).")
        else:
            statements.append(f"{head}{'n' if head else 'N'}o fleet of the grid meets every "
                              "target with 95 % confidence.")
    return recommended, statements, estimates


MAX_STATEMENTS = 8
"""Sentences on a sweep's first screen; the rest are in the Statistics section."""


def unit_after(kpi: str, difference: bool = False) -> str:
    """The unit after a number; a difference of percentages is in percentage points."""
    unit = kpi_unit(kpi)
    if unit == "%" and difference:
        return " points"
    return f" {unit}" if unit and unit != "count" else ""


def factor_words(name: str) -> str:
    """A factor (a dotted scenario path) in words: ``demand.rate_per_hour`` -> ``demand rate
    per hour``."""
    return name.replace(".", " ").replace("_", " ")


def _and(parts: list[str]) -> str:
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def change_sentence(factor: str, from_level: Any, to_level: Any, numeric: bool,
                    others: list[str], diffs: list[PairDifference]) -> str:
    """One sentence: what changing one factor does to the study's KPIs, paired by
    replication: "Raising demand rate per hour from 45 to 60 raises p95 lead time by 120 s (80
    to 160 s); no difference we can detect in throughput: +0.4 orders/h (-1.2 to +2)."."""
    a, b = level_text(from_level), level_text(to_level)
    subject = (f"Raising {factor_words(factor)} from {a} to {b}" if numeric else
               f"{factor_words(factor)} {b} instead of {a}".capitalize())
    if others:
        subject += f" (mean over the levels of {_and([factor_words(f) for f in others])})"
    usable = [d for d in diffs if d.pairs >= 2 and not math.isnan(d.interval.half_width)]
    missing = [kpi_short(d.kpi) for d in diffs if d not in usable]
    effects: list[str] = []
    none: list[str] = []
    for diff in usable:
        ci, u = diff.interval, unit_after(diff.kpi, difference=True)
        if diff.excludes_zero:
            verb, mean, low, high = ("cuts", -ci.mean, -ci.high, -ci.low) if ci.mean < 0 \
                else ("raises", ci.mean, ci.low, ci.high)
            effects.append(f"{verb} {kpi_short(diff.kpi)} by {number_text(mean)}{u} "
                           f"({number_text(low)} to {number_text(high)}{u})")
        else:
            none.append(f"{kpi_short(diff.kpi)} {signed_text(ci.mean)}{u} "
                        f"({signed_text(ci.low)} to {signed_text(ci.high)}{u})")
    if usable and all(d.interval.mean == 0 and d.interval.sd == 0 for d in usable):
        text = (f"{subject} gives the same {_and([kpi_short(d.kpi) for d in usable])} in "
                "every replication")
    elif effects:
        text = f"{subject} {_and(effects)}"
        if none:
            text += "; no difference we can detect in " + "; ".join(none)
    else:
        text = f"{subject} changes nothing we can detect" + (": " + "; ".join(none)
                                                             if none else "")
    if missing:
        text += "; too few paired replications to compare " + ", ".join(missing)
    pairs = max((d.pairs for d in diffs), default=0)
    return text + f" (paired over {pairs} replications, 95 % intervals)."


def headline_changes(data: ReportData) -> list[tuple[str, Any, Any, bool]]:
    """The changes a sweep's first screen states, per factor: a numeric factor from its
    lowest to its highest level, any other each level against its first listed.
    (factor, from, to, numeric)."""
    out: list[tuple[str, Any, Any, bool]] = []
    for factor in data.factors:
        pairs = [p for p in one_factor_pairs(data.summary, [factor], listed=data.listed)]
        if not pairs:
            continue
        if all(is_number(p.from_level) and is_number(p.to_level) for p in pairs):
            out.append((factor, pairs[0].from_level, pairs[-1].to_level, True))
        else:
            out += [(factor, p.from_level, p.to_level, False) for p in pairs]
    return out


def sweep_statements(data: ReportData) -> list[str]:
    """A sweep's answer in a planner's words: per factor, what changing it does to the
    study's KPIs (paired differences, averaged over the other factors), at most
    MAX_STATEMENTS sentences."""
    changes = headline_changes(data)
    if not changes:
        return ["One design point: no factor varies, so there is no change to compare; its "
                "KPIs are below."]
    statements = []
    for factor, a, b, numeric in changes[:MAX_STATEMENTS]:
        others = [f for f in data.factors if f != factor]
        statements.append(change_sentence(factor, a, b, numeric, others, [
            factor_effect(data.summary, data.factors, factor, a, b, kpi)
            for kpi in data.compared_kpis]))
    if len(changes) > MAX_STATEMENTS:
        statements.append(f"... and {len(changes) - MAX_STATEMENTS} more changes: every paired "
                          "difference is in the Statistics section.")
    return statements


# ---- sections ------------------------------------------------------------------------------


def _figure(key: str, caption: str, fig: Any) -> Figure:
    return Figure(key, caption, figs.png_bytes(fig), fig)


def _series(data: ReportData, stats: pd.DataFrame) -> dict[str, pd.DataFrame]:
    if not data.others:
        return {"": stats}
    out: dict[str, pd.DataFrame] = {}
    for key, group in stats.groupby(data.others, sort=True, dropna=False):
        values = key if isinstance(key, tuple) else (key,)
        out[data.series_key(dict(zip(data.others, values, strict=True)))] = group
    return out


def section_scenario(data: ReportData) -> ScenarioSection:
    exp = data.experiment
    rows: list[list[str]] = [["experiment", str(exp.get("name", ""))],
                             ["description", str(exp.get("description", ""))]]
    if data.scenario is not None:
        sc = data.scenario
        demand = (f"{sc.demand.kind}, {sc.demand.rate_per_hour:g} orders/h" +
                  (", profile " + ", ".join(f"from {p.from_h:g} h x{p.multiplier:g}"
                                            for p in sc.demand.profile)
                   if sc.demand.profile else ""))
        rows += [["scenario", f"{sc.name}: {sc.description}" if sc.description else sc.name],
                 ["layout", data.layout.name if data.layout else sc.layout],
                 ["run length", f"{sc.duration_h:g} h, warm-up {sc.warmup_h:g} h, "
                                f"start at {sc.start_h:g} h"],
                 ["demand", demand],
                 ["dispatch", f"{sc.dispatch.policy}, park idle: {sc.dispatch.park_idle}"]]
    overrides = exp.get("overrides") or {}
    if overrides:
        rows.append(["set in every run", ", ".join(f"{k} = {v}" for k, v in overrides.items())])
    for name, levels in (exp.get("factors") or {}).items():
        rows.append([f"factor {name}", str(levels)])
    rows += [["design", f"{exp.get('design')}, master seed {exp.get('master_seed')}"],
             ["replications", replications_text(data)],
             ["targets", "; ".join(t.describe() for t in data.targets) or "none"]]
    sec = ScenarioSection(settings=Table(["", ""], rows, "settings"), problem=data.problem)
    sec.text += [f"{name}: {value}" for name, value in rows]
    if data.layout is not None:
        png = figs.layout_png(data.layout)
        caption = f"Layout {data.layout.name}"
        sec.figures.append(Figure("layout", caption, png, figs.image_page(png, caption)))
    return sec


def replications_text(data: ReportData) -> str:
    """The replications run per design point, counted in the summary (finished runs): a
    sizing search adds replications where a fleet size is undecided, so the file's number
    is where each point started, not what the answer used."""
    asked = data.experiment.get("replications")
    ok = data.ok
    if ok.empty:
        return f"none finished (the file asks for {asked} per design point)"
    counts = ok.groupby(data.factors, dropna=False).size() if data.factors \
        else pd.Series([len(ok)])
    low, high = int(counts.min()), int(counts.max())
    ran = f"{low}" if low == high else f"{low} to {high}"
    text = (f"{ran} per design point ({len(ok)} finished runs at {len(counts)} design "
            f"point{'s' if len(counts) != 1 else ''})")
    if low == high == asked:
        return text
    if data.sizing is not None and high > (asked or 0):
        return text + (f"; the file asks for {asked}, and `fleet-sim size` added replications "
                       "where a fleet size was not yet decided")
    return text + f"; the file asks for {asked}"


def section_kpis(data: ReportData, series: dict[str, pd.DataFrame],
                 recommended: dict[str, int | None]) -> KpiSection:
    sec = KpiSection()
    kpis = [k for k in MAIN_KPIS if k in set(next(iter(series.values()))["kpi"])]
    kpis += [t.kpi for t in data.targets if t.kpi not in kpis]
    sec.figures.append(_figure("kpis", "KPIs against " + data.x,
                               figs.kpi_panels(series, data.x, kpis, data.targets,
                                               recommended)))
    return sec


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
        sec.figures.append(_figure(f"states-{len(sec.figures)}", title,
                                   figs.state_bars(means, data.x, title)))
    return sec


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
        sec.figures.append(_figure("charging", "Charging against " + data.x,
                                   figs.kpi_panels(series, data.x, active, data.targets,
                                                   recommended)))
    sample = _sample_runs(data, recommended)
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
                sec.figures.append(_figure("soc", f"SOC of {len(agvs)} AGVs, run {run_id}",
                                           figs.soc_curves(curves, f"State of charge, run "
                                                           f"{run_id}")))
    return sec


def _sample_runs(data: ReportData, recommended: dict[str, int | None]) -> list[str]:
    """Runs of the first series at its recommended fleet (else its largest fleet run)."""
    ok = data.ok
    if ok.empty or not data.x:
        return [str(r) for r in ok["run_id"]]
    pick = ok
    if data.others:
        first = ok.sort_values(data.others).iloc[0]
        for name in data.others:
            pick = pick[pick[name] == first[name]]
        key = data.series_key({str(k): v for k, v in first.to_dict().items()})
    else:
        key = ""
    rec = recommended.get(key)
    level = rec if rec is not None and (pick[data.x] == rec).any() else pick[data.x].max()
    return [str(r) for r in pick[pick[data.x] == level]["run_id"]]


def section_congestion(data: ReportData, series: dict[str, pd.DataFrame],
                       recommended: dict[str, int | None]) -> CongestionSection:
    figures: list[Figure] = []
    if "blocked_time_pct" in set(next(iter(series.values()))["kpi"]):
        figures.append(_figure("blocked", "Blocked time against " + data.x,
                               figs.kpi_panels(series, data.x, ["blocked_time_pct"], [],
                                               recommended)))
    sample = _sample_runs(data, recommended)
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
    figures.append(_figure("heatmap", title, figs.heat_map(data.layout, per_node, title)))
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


def _hms(seconds: float) -> str:
    whole = round(seconds)
    return f"{whole // 3600}:{whole % 3600 // 60:02d}:{whole % 60:02d}"


def gantt_svg(spells: pd.DataFrame, agvs: list[int], start_s: float, end_s: float) -> Gantt:
    """The state spells as SVG bars (one row per AGV) with a hover text each."""
    label_w, plot_w, row_h, top = 58, 1000, 12, 16
    span = max(end_s - start_s, 1e-9)
    keys = {s.value: s.key for s in VehicleState}
    rows = [(f"AGV {a}", top + i * row_h) for i, a in enumerate(agvs)]
    row_of = {a: top + i * row_h for i, a in enumerate(agvs)}
    bars = []
    for agv, t0, t1, state, event, detail, order, loaded in zip(
            *(spells[c].tolist() for c in ("agv", "start_s", "end_s", "state", "event", "detail",
                                           "order_id", "loaded")), strict=True):
        x = label_w + (float(t0) - start_s) / span * plot_w
        width = max((float(t1) - float(t0)) / span * plot_w, 0.3)
        title = (f"AGV {agv}: {state} {_hms(float(t0))} to {_hms(float(t1))} "
                 f"({float(t1) - float(t0):.0f} s); order {order if order >= 0 else 'none'}, "
                 f"{'loaded' if loaded else 'empty'}; reason: {event}"
                 + (f": {detail}" if detail else ""))
        bars.append(GanttBar(round(x, 2), row_of[int(agv)], round(width, 2),
                             figs.STATE_COLOURS.get(keys.get(state, ""), "#80868b"),
                             bool(loaded), title))
    step = next((s for s in (300, 600, 900, 1800, 3600, 7200) if span / s <= 12), 14400)
    first = math.ceil(start_s / step) * step
    ticks = [(round(label_w + (t - start_s) / span * plot_w, 2), _hms(t))
             for t in np.arange(first, end_s + 1e-9, step)]
    legend = [(s.value, figs.STATE_COLOURS[s.key]) for s in VehicleState]
    return Gantt(label_w + plot_w + 4, top + row_h * len(agvs) + 4, label_w, row_h, rows, ticks,
                 bars, legend)


def section_detail(data: ReportData, recommended: dict[str, int | None]) -> DetailSection:
    ok = data.ok
    sample = _sample_runs(data, recommended)
    picked = ok[ok["run_id"].astype(str).isin(sample)]
    if picked.empty or data.layout is None:
        return DetailSection(problem="No finished run to show.")
    if "replication" in picked.columns:
        picked = picked.sort_values("replication", kind="stable")
    row = picked.iloc[0]
    run_id = str(row["run_id"])
    level = f"{data.x} = {row[data.x]}" if data.x else ""
    run_dir = data.out_dir / "runs" / run_id
    problem = ""
    try:
        run = load_run(run_dir)
    except InputError as exc:
        problem = (f"The moves of run {run_id} could not be re-simulated ({exc}); the timeline "
                   "is drawn from its events, and blocked time stays inside the drives.")
        try:
            run = load_run(run_dir, resimulate=False)
        except InputError as again:
            return DetailSection(run_id=run_id, level=level, problem=str(again))
    scenario = run.scenario
    spells = state_spells(run.events, 0.0, scenario.duration_s)
    agvs = list(range(scenario.fleet.size))
    leads = lead_times(run.orders, run.moves if run.resimulated or len(run.moves) else None,
                       scenario.warmup_s, scenario.duration_s)
    header = ["part", "mean [s]", "median [s]", "p95 [s]", "share of lead time"]
    total = float(leads["lead_time_s"].sum()) if len(leads) else 0.0
    rows: list[list[str]] = []
    for part in (*LEAD_PARTS, "lead_time_s"):
        values = leads[part].dropna().to_numpy(dtype=float)
        name = LEAD_LABELS.get(part, "lead time (all parts)")
        if len(values) == 0:
            rows.append([name, "n/a", "n/a", "n/a", "n/a"])
            continue
        share = f"{100.0 * values.sum() / total:.1f} %" if total > 0 else "n/a"
        rows.append([name, fmt(float(values.mean())), fmt(float(np.median(values))),
                     fmt(float(np.percentile(values, 95))), share])
    sec = DetailSection(run_id=run_id, level=level, run_dir=str(run_dir), problem=problem,
                        gantt=gantt_svg(spells, agvs, 0.0, scenario.duration_s),
                        lead_rows=Table(header, rows, "leads"), orders=len(leads))
    title = f"Run {run_id} ({level}): every AGV's state"
    sec.figures.append(Figure("gantt", title, b"", figs.gantt(spells, agvs, title),
                              in_html=False))
    lead_title = f"Run {run_id}: lead time of each order, by part"
    sec.figures.append(_figure("leads", lead_title,
                               figs.lead_breakdown(leads, LEAD_LABELS, lead_title)))
    sec.text.append(f"Run {run_id} ({level}), {len(leads)} orders delivered after the warm-up; "
                    "mean lead time by part: " + ", ".join(f"{r[0]} {r[1]} s" for r in rows))
    if problem:
        sec.text.append(problem)
    return sec


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
            sec.figures.append(_figure("incidents", "Incidents against " + data.x,
                                       figs.incidents(mean, data.x)))
    sec.text.append(f"{total} deadlocks detected in {len(ok)} runs.")
    rows: list[list[str]] = []
    for run_id in _sample_runs(data, recommended)[:3]:
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


def section_statistics(data: ReportData, stats: pd.DataFrame) -> StatisticsSection:
    present = set(stats["kpi"])
    kpis = [k for k in dict.fromkeys([*TABLE_KPIS, *(t.kpi for t in data.targets)])
            if k in present]
    keys = [*data.others, data.x] if data.x else []
    header = [*keys, "replications", *(kpi_label(k) for k in kpis)]
    rows: list[list[str]] = []
    wide = stats.pivot_table(index=keys, columns="kpi", values=["mean", "half_width", "n"],
                             aggfunc="first", dropna=False) if keys else None
    if wide is not None:
        for index, row in wide.iterrows():
            idx = index if isinstance(index, tuple) else (index,)
            counts = [row[("n", k)] for k in kpis if pd.notna(row[("n", k)])]
            if kpis and not counts:
                continue  # a combination of levels the study never ran (a sizing search)
            n = int(max(counts)) if counts else 0
            cells = [level_text(v) for v in idx] + [str(n)]
            for k in kpis:
                mean, half = row[("mean", k)], row[("half_width", k)]
                cells.append(f"{fmt(mean)} \u00b1 {fmt(half, 2)}")
            rows.append(cells)
    checks = check_targets(data.summary, data.factors, data.targets)
    warnings = [w for w in (c.warning() for c in checks) if w]
    sec = StatisticsSection(points=Table(header, rows, "stats"), warnings=warnings)
    sec.text += ["Too wide to decide: " + w for w in warnings]
    diffs = paired_differences(data.summary, data.factors, data.compared_kpis,
                               listed=data.listed)
    if not diffs.empty:
        drows = []
        for r in diffs.to_dict("records"):
            fixed = point_text({f: r[f] for f in data.factors if f != r["factor"]})
            u = unit_after(r["kpi"], difference=True)
            drows.append([
                str(r["factor"]), f"{level_text(r['from_level'])} \u2192 "
                f"{level_text(r['to_level'])}", fixed or "-", kpi_label(r["kpi"]),
                str(r["pairs"]), f"{fmt(r['from_mean'])} \u2192 {fmt(r['to_mean'])}",
                f"{signed_text(r['mean_diff'])}{u} ({signed_text(r['ci_low'])} to "
                f"{signed_text(r['ci_high'])})", difference_words(r["kpi"], r["ci_low"],
                                                             r["ci_high"])])
        sec.differences = Table(["factor", "change", "other factors", "KPI", "pairs",
                                 "means", "paired difference (95 % CI)", "reading"], drows,
                                "differences")
        sec.text += [f"{r[0]} {r[1]} ({r[2]}), {r[3]}: {r[6]}, {r[7]}" for r in drows]
    return sec


def difference_words(kpi: str, low: float, high: float) -> str:
    """A paired difference's interval in words: higher / lower, or none detected."""
    if math.isnan(low) or math.isnan(high):
        return "too few pairs"
    if low <= 0 <= high:
        return "no difference detected"
    up = low > 0
    better = kpi_better(kpi)
    word = "higher" if up else "lower"
    if better is None:
        return word
    return f"{word} (better)" if up == (better == "higher") else f"{word} (worse)"


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


# ---- the report ----------------------------------------------------------------------------


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
    series = _series(data, stats)
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
        what = "Sweep over " + _and([factor_words(f) for f in data.factors]) \
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
    kpis = _and(shorts) if shorts else "the KPIs"
    if not data.factors:
        return f"Scenario {scenario} on layout {layout}: {kpis} over its replications."
    return (f"How {kpis} change with {_and([factor_words(f) for f in data.factors])}: "
            f"scenario {scenario} on layout {layout}, {points} design points, replication r "
            "with the same seed at every point (common random numbers), so each change is "
            "measured as a paired difference.")
