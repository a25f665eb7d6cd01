"""The Statistics section: the mean and 95 % interval of each KPI per design point, the
intervals too wide to decide, and the paired differences between design points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import pandas as pd

from fleet_sim.analysis.kpis import kpi_better, kpi_label
from fleet_sim.analysis.paired import signed_text
from fleet_sim.analysis.stats import check_targets, paired_differences
from fleet_sim.config.experiment import level_text, point_text
from fleet_sim.report.content import Section, Table
from fleet_sim.report.results_folder import ReportData
from fleet_sim.report.wording import fmt, unit_after

TABLE_KPIS = ("throughput_per_hour", "throughput_pct_of_demand", "lead_time_mean_s",
              "lead_time_p95_s", "agv_utilisation_pct", "blocked_time_pct", "deadlocks_detected")


@dataclass(kw_only=True)
class StatisticsSection(Section):
    title: ClassVar[str] = "Statistics"
    template: ClassVar[str] = "statistics.html.j2"
    points: Table
    warnings: list[str]
    differences: Table | None = None


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
