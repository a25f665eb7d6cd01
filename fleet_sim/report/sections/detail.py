"""The A run in detail section: one run simulated again with its moves recorded, its per-AGV
timeline (an inline SVG, `Gantt`) and the breakdown of its orders' lead times.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pandas as pd

from fleet_sim.analysis.replay import LEAD_LABELS, LEAD_PARTS, lead_times, load_run, state_spells
from fleet_sim.errors import InputError
from fleet_sim.model.states import VehicleState
from fleet_sim.report import figures as figs
from fleet_sim.report.content import Figure, Section, Table, png_figure
from fleet_sim.report.results_folder import ReportData, sample_runs
from fleet_sim.report.wording import fmt


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
    sample = sample_runs(data, recommended)
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
    sec.figures.append(png_figure("leads", lead_title,
                                  figs.lead_breakdown(leads, LEAD_LABELS, lead_title)))
    sec.text.append(f"Run {run_id} ({level}), {len(leads)} orders delivered after the warm-up; "
                    "mean lead time by part: " + ", ".join(f"{r[0]} {r[1]} s" for r in rows))
    if problem:
        sec.text.append(problem)
    return sec
