"""The Scenario and layout section: the settings of the study (experiment, scenario, demand,
factors, design, replications, targets) and the layout drawing.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pandas as pd

from fleet_sim.report import figures as figs
from fleet_sim.report.content import Figure, Section, Table
from fleet_sim.report.results_folder import ReportData


@dataclass(kw_only=True)
class ScenarioSection(Section):
    title: ClassVar[str] = "Scenario and layout"
    template: ClassVar[str] = "scenario.html.j2"
    settings: Table
    problem: str = ""


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
