"""A sweep's or sizing's results folder read for the report (`ReportData`, `load`): the
experiment, the summary, the targets, sizing.json, the scenario and layout read again; the
study's series and the runs a section shows of it.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import yaml

from fleet_sim.config.experiment import FLEET, Target, layout_for, point_text
from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario, load_scenario, type_count_path
from fleet_sim.errors import InputError
from fleet_sim.study.results import read_summary

MAIN_KPIS = ("throughput_per_hour", "lead_time_p95_s")
"""The KPIs every study is about, after its targets'."""


@dataclass
class ReportData:
    """A sweep's or sizing's results folder as the report reads it (`load`)."""

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


def series_of(data: ReportData, stats: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The design points' statistics by series (each combination of the factors other
    than the x axis's; one series "" when there is none)."""
    if not data.others:
        return {"": stats}
    out: dict[str, pd.DataFrame] = {}
    for key, group in stats.groupby(data.others, sort=True, dropna=False):
        values = key if isinstance(key, tuple) else (key,)
        out[data.series_key(dict(zip(data.others, values, strict=True)))] = group
    return out


def sample_runs(data: ReportData, recommended: dict[str, int | None]) -> list[str]:
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
