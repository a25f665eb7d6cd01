"""The first screen's answer: the recommended fleet per series with its statements (from
sizing.json, else from the sweep's grid with the same rule), and a sweep's sentences on what
changing each factor does.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import math
from typing import Any

from fleet_sim.analysis.kpis import kpi_short
from fleet_sim.analysis.paired import number_text, signed_text
from fleet_sim.analysis.stats import (
    PairDifference,
    check_targets,
    factor_effect,
    is_number,
    one_factor_pairs,
)
from fleet_sim.config.experiment import level_text
from fleet_sim.report.results_folder import ReportData
from fleet_sim.report.wording import and_words, factor_words, unit_after


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


def change_sentence(factor: str, from_level: Any, to_level: Any, numeric: bool,
                    others: list[str], diffs: list[PairDifference]) -> str:
    """One sentence: what changing one factor does to the study's KPIs, paired by
    replication: "Raising demand rate per hour from 45 to 60 raises p95 lead time by 120 s (80
    to 160 s); no difference we can detect in throughput: +0.4 orders/h (-1.2 to +2)."."""
    a, b = level_text(from_level), level_text(to_level)
    subject = (f"Raising {factor_words(factor)} from {a} to {b}" if numeric else
               f"{factor_words(factor)} {b} instead of {a}".capitalize())
    if others:
        subject += f" (mean over the levels of {and_words([factor_words(f) for f in others])})"
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
        text = (f"{subject} gives the same {and_words([kpi_short(d.kpi) for d in usable])} in "
                "every replication")
    elif effects:
        text = f"{subject} {and_words(effects)}"
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
