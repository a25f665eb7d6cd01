"""The comparison report: a `fleet-sim compare` results folder -> a `Report` (plain data, as
fleet_sim.report.study_report's) that fleet_sim.report.render writes as HTML and PDF.

The first screen answers in a planner's words, one sentence per variant (and design point):
"Opportunity charging cuts p95 lead time by 180 s (41 to 320 s)", "Making aisle 3 one-way
changes nothing we can detect: p95 lead time +7 s (-34 to +48 s)", then the selection of the
best variant when the file named an objective. Below: the forest plot of paired differences
and their table, the KPIs side by side, each variant's layout with its changes in red, where
congestion moved (node waits, variant minus baseline), the statistics used, the runs.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from fleet_sim.analysis.kpis import kpi_label, kpi_short, kpi_unit
from fleet_sim.analysis.paired import number_text, signed_text
from fleet_sim.analysis.stats import point_stats
from fleet_sim.config.experiment import BASE_VARIANT, Experiment, load_experiment, point_text
from fleet_sim.errors import FleetSimError, InputError
from fleet_sim.report import compare_figures as cfigs
from fleet_sim.report.content import Report, Section, Table, png_figure
from fleet_sim.report.layout_plot import variant_figure
from fleet_sim.report.sections.compare_section import CompareSection
from fleet_sim.study.compare import COMPARE_FILE, read_compare
from fleet_sim.study.results import read_summary


def is_compare_folder(out_dir: Path) -> bool:
    return (out_dir / COMPARE_FILE).exists()


# ---- words ------------------------------------------------------------------------------------


def _unit(kpi: str, difference: bool = False) -> str:
    """The unit after a number; a difference of percentages is in percentage points."""
    unit = kpi_unit(kpi)
    if unit == "%" and difference:
        return " points"
    return f" {unit}" if unit and unit != "count" else ""


def _and(parts: Sequence[str]) -> str:
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def _clause_effect(row: Mapping[str, Any]) -> str:
    """``cuts p95 lead time by 180 s (41 to 320 s)``."""
    kpi, mean, low, high = row["kpi"], row["difference"], row["ci_low"], row["ci_high"]
    u = _unit(kpi, difference=True)
    if mean < 0:
        return (f"cuts {kpi_short(kpi)} by {number_text(-mean)}{u} ({number_text(-high)} to "
                f"{number_text(-low)}{u})")
    return (f"raises {kpi_short(kpi)} by {number_text(mean)}{u} ({number_text(low)} to "
            f"{number_text(high)}{u})")


def _clause_none(row: Mapping[str, Any]) -> str:
    """``p95 lead time +7 s (-34 to +48 s)``."""
    kpi = row["kpi"]
    u = _unit(kpi, difference=True)
    return (f"{kpi_short(kpi)} {signed_text(row['difference'])}{u} "
            f"({signed_text(row['ci_low'])} to {signed_text(row['ci_high'])}{u})")


def variant_sentence(subject: str, rows: Sequence[Mapping[str, Any]]) -> str:
    """One sentence: what the variant changes, in a planner's words (see the module)."""
    effects = [r for r in rows if r["verdict"] in ("better", "worse", "higher", "lower")]
    others = [r for r in rows if r not in effects and r["difference"] is not None]
    missing = [r for r in rows if r["difference"] is None]
    open_ = [r for r in others if r["verdict"] == "undecided"]
    none = [r for r in others if r not in open_]
    parts: list[str] = []
    if effects:
        parts.append(_and([_clause_effect(r) for r in effects]))
    if open_:
        parts.append("is not decided at the replication limit on " + "; ".join(
            _clause_none(r) for r in open_) + " (more replications could still tell)")
    if none:
        parts.append("no difference we can detect in " + "; ".join(_clause_none(r)
                                                                    for r in none))
    if not effects and not open_:
        text = f"{subject} changes nothing we can detect"
        if none:
            text += ": " + "; ".join(_clause_none(r) for r in none)
    else:
        text = f"{subject} " + "; ".join(parts)
    if missing:
        text += "; no value to compare for " + ", ".join(kpi_short(r["kpi"]) for r in missing)
    return text + "."


def _subject(name: str, descriptions: Mapping[str, str]) -> str:
    text = (descriptions.get(name) or "").strip().rstrip(".")
    if not text:
        return f"Variant {name}"
    return text[0].upper() + text[1:]


# ---- the report -------------------------------------------------------------------------------


def build_compare_report(out_dir: Path) -> Report:
    """Read a compare results folder and prepare every section (figures drawn)."""
    data = read_compare(out_dir)
    resolved_file = out_dir / "experiment.resolved.yaml"
    if data is None or not resolved_file.exists():
        raise InputError(str(out_dir), "folder", str(out_dir),
                         "a results folder of `fleet-sim compare` (with compare.json)")
    resolved = yaml.safe_load(resolved_file.read_text(encoding="utf-8"))
    factors = list(resolved.get("factors") or {})
    summary, _ = read_summary(out_dir, factors)
    rows: list[dict[str, Any]] = data["comparisons"]
    variants: list[str] = data["variants"]
    kpis: list[str] = data["kpis"]
    descriptions: dict[str, str] = data.get("descriptions") or {}

    statements: list[str] = []
    for variant in variants[1:]:
        points = list(dict.fromkeys(point_text(r["point"]) for r in rows
                                    if r["variant"] == variant))
        for where in points:
            mine = [r for r in rows if r["variant"] == variant
                    and point_text(r["point"]) == where]
            sentence = variant_sentence(_subject(variant, descriptions), mine)
            statements.append(f"At {where}: {sentence}" if where else sentence)
    statements += [s["statement"] for s in data.get("selection") or []]

    experiment, problem = _experiment(resolved)
    sections: list[Section] = [
        _section_differences(data, rows, kpis),
        _section_side_by_side(summary, factors, kpis, variants),
        _section_layouts(experiment, variants, problem),
        _section_congestion(out_dir, summary, experiment, variants, factors, problem),
        _section_statistics(data),
        _section_runs(summary, data),
    ]
    name = data.get("experiment", "experiment")
    lead = (f"{len(variants) - 1} variant(s) against {data['baseline']} with common random "
            f"numbers, {data['replications']} replications each "
            f"({data['stopped']}); generated {time.strftime('%Y-%m-%d %H:%M')} by fleet-sim.")
    return Report(f"What-if comparison: {name}", lead, statements, [], sections,
                  template="compare.html.j2", answer_title="Answer")


def _experiment(resolved: Mapping[str, Any]) -> tuple[Experiment | None, str]:
    file = resolved.get("experiment_file")
    try:
        return load_experiment(str(file)), ""
    except (InputError, FleetSimError, OSError) as exc:
        return None, f"The experiment file {file} could not be read again: {exc}"


def _section_differences(data: Mapping[str, Any], rows: Sequence[Mapping[str, Any]],
                         kpis: Sequence[str]) -> CompareSection:
    level = float(data["correction"]["level_each_interval"])
    table = Table(["variant", "design point", "KPI", "baseline", "variant mean",
                   "difference (interval)", "pairs", "verdict"],
                  [[str(r["variant"]), point_text(r["point"]) or "-", kpi_label(r["kpi"]),
                    number_text(r["baseline_mean"]), number_text(r["variant_mean"]),
                    f"{signed_text(r['difference'])} ({signed_text(r['ci_low'])} to "
                    f"{signed_text(r['ci_high'])})", str(r["pairs"]), str(r["words"])]
                   for r in rows])
    sec = CompareSection(heading="Paired differences from the baseline", tables=[table])
    sec.paragraphs.append(
        f"Variant minus baseline, replication by replication (the same seed and the same "
        f"orders in every variant), with intervals at {level:.3%} each: "
        f"{data['correction']['confidence']:.0%} for all {data['correction']['comparisons']} "
        f"comparisons over up to {data['correction']['looks']} looks together (Bonferroni).")
    sec.figures.append(png_figure("forest", "Paired differences per KPI (dot: mean; bar: "
                                  "interval)", cfigs.forest(rows, kpis, level)))
    sec.text += [f"{r['variant']} {point_text(r['point'])} {r['kpi']}: {r['words']}"
                 for r in rows]
    return sec


def _section_side_by_side(summary: pd.DataFrame, factors: Sequence[str], kpis: Sequence[str],
                          variants: Sequence[str]) -> CompareSection:
    sec = CompareSection(heading="The KPIs side by side")
    if "variant" not in summary.columns:
        sec.paragraphs.append("The summary has no variant column: no run of a variant yet.")
        return sec
    stats = point_stats(summary, ["variant", *factors])
    first = stats
    where = ""
    if factors and not stats.empty:
        values = {f: stats[f].iloc[0] for f in factors}
        for f, v in values.items():
            first = first[first[f] == v]
        where = point_text(values)
    means: dict[str, dict[str, tuple[float, float]]] = {}
    for kpi in kpis:
        for variant in variants:
            row = first[(first["kpi"] == kpi) & (first["variant"] == variant)]
            if len(row):
                means.setdefault(kpi, {})[variant] = (float(row["mean"].iloc[0]),
                                                      float(row["half_width"].iloc[0]))
    header = ["KPI", *variants]

    def mean_pm(kpi: str, v: str) -> str:
        mean, half = means.get(kpi, {}).get(v, (np.nan, np.nan))[:2]
        return f"{number_text(mean)} ± {number_text(half)}"

    table_rows = [[kpi_label(kpi), *(mean_pm(kpi, v) for v in variants)] for kpi in kpis]
    sec.tables.append(Table(header, table_rows))
    sec.paragraphs.append("Each variant's mean ± the half-width of its own 95 % interval"
                          + (f" at {where}" if where else "") + ". The comparison is the "
                          "paired difference above, which is much narrower: the variants "
                          "share their replications' orders.")
    sec.figures.append(png_figure("side_by_side", "KPIs of every variant (mean and 95 % "
                                  "interval)", cfigs.kpis_side_by_side(means, kpis, variants)))
    return sec


def _section_layouts(experiment: Experiment | None, variants: Sequence[str],
                     problem: str) -> CompareSection:
    sec = CompareSection(heading="The variants' layouts")
    if experiment is None:
        sec.paragraphs.append(problem)
        return sec
    settings_only: list[str] = []
    for variant in variants[1:]:
        spec = experiment.variant_spec(variant)
        try:
            drawn = experiment.variant_layout(variant)
        except (InputError, FleetSimError) as exc:
            sec.paragraphs.append(f"{variant}: the layout could not be drawn: {exc}")
            continue
        if drawn.diff.empty:
            changes = ", ".join(f"{k} = {v}" for k, v in (spec.overrides.items()
                                                          if spec is not None else []))
            settings_only.append(f"{variant} ({changes})" if changes else variant)
            continue
        title = f"{variant}: its layout changes in red (new or changed hops, nodes ringed)"
        sec.figures.append(png_figure(f"layout_{variant}", title,
                                      variant_figure(drawn.layout, drawn.baseline, drawn.diff,
                                                     title)))
    if settings_only:
        sec.paragraphs.append("The baseline's layout, with other settings: "
                              + "; ".join(settings_only) + ".")
    return sec


def _node_waits(out_dir: Path, run_ids: Sequence[str], window_h: float) -> pd.Series | None:
    frames = []
    for run_id in run_ids:
        path = out_dir / "runs" / run_id / "node_waits.parquet"
        if path.exists():
            frames.append(pd.read_parquet(path, columns=["node", "wait_s"]))
    if not frames:
        return None
    waits = pd.concat(frames).groupby("node")["wait_s"].sum()
    return waits / len(frames) / window_h


def _section_congestion(out_dir: Path, summary: pd.DataFrame, experiment: Experiment | None,
                        variants: Sequence[str], factors: Sequence[str],
                        problem: str) -> CompareSection:
    sec = CompareSection(heading="Where congestion moved")
    if experiment is None:
        sec.paragraphs.append(problem)
        return sec
    ok = summary[summary["status"] == "ok"] if "status" in summary.columns else summary
    if "variant" not in ok.columns or ok.empty:
        sec.paragraphs.append("No finished runs of the variants yet.")
        return sec
    point = dict(experiment.points[0]) if experiment.points else {}
    for f, v in point.items():
        ok = ok[ok[f] == v]
    window_h = float(ok["duration_h"].iloc[0] - ok["warmup_h"].iloc[0]) \
        if {"duration_h", "warmup_h"} <= set(ok.columns) else 1.0
    base = _node_waits(out_dir, list(ok[ok["variant"] == variants[0]]["run_id"]), window_h)
    rows: list[list[str]] = []
    for variant in variants[1:]:
        mine = _node_waits(out_dir, list(ok[ok["variant"] == variant]["run_id"]), window_h)
        if base is None or mine is None:
            continue
        change = mine.sub(base, fill_value=0.0)
        try:
            drawn = experiment.variant_layout(variant, point or None)
        except (InputError, FleetSimError):
            continue
        where = f" at {point_text(point)}" if point else ""
        title = (f"{variant} - {variants[0]}{where}: change of AGV waiting per node "
                 "(s per hour; red more, blue less)")
        sec.figures.append(png_figure(f"waits_{variant}", title, cfigs.wait_difference(
               drawn.layout, drawn.baseline, {str(k): float(v) for k, v in change.items()}, title)))
        top = change[change.abs() > 0].abs().sort_values(ascending=False).head(3).index
        if len(top):
            rows.append([variant, f"{float(mine.sum() - base.sum()):+.0f}",
                         ", ".join(f"{n} ({change[n]:+.0f})" for n in top)])
    if rows:
        sec.tables.append(Table(["variant", "AGV waiting, all nodes [s/h] vs baseline",
                                 "largest changes [s/h]"], rows))
        sec.text += [f"{r[0]}: waiting {r[1]} s/h in all; most at {r[2]}" for r in rows]
    sec.paragraphs.append("Seconds per hour AGVs with work to do stood waiting at each node "
                          "(mean over the replications), variant minus baseline.")
    return sec


def _section_statistics(data: Mapping[str, Any]) -> CompareSection:
    c = data["correction"]
    sec = CompareSection(heading="Statistics")
    sec.paragraphs.append(
        f"Common random numbers: replication r runs with the same seed in every variant. "
        f"Looks after {', '.join(str(n) for n in data['looks_planned'])} replications "
        f"(done: {', '.join(str(n) for n in data['looks_done'])}); stopped: "
        f"{data['stopped']}. Correction: {c['name']}: each interval at "
        f"1 - {1 - c['confidence']:.2g} / ({c['comparisons']} x {c['looks']}) = "
        f"{c['level_each_interval']:.4%}, so all intervals hold together with "
        f"{c['confidence']:.0%} confidence whichever look the study stopped at.")
    precision = data.get("precision") or {}
    if precision:
        sec.paragraphs.append("Precision asked (a comparison whose interval is this narrow "
                              "is decided): " + ", ".join(
                                  f"{kpi_label(k)} ± {number_text(v)}"
                                  for k, v in precision.items()))
    for s in data.get("selection") or []:
        sec.paragraphs.append(
            f"Selection by {s['procedure']} on {kpi_label(s['kpi'])} ({s['direction']}), "
            f"indifference zone {number_text(s['indifference_zone'])}{_unit(s['kpi'])}, "
            "probability "
            f"of correct selection {s['probability_correct_selection']:.0%}, first stage "
            f"{s['first_stage']} replications: " + s["statement"])
    sec.text += sec.paragraphs
    return sec


def _section_runs(summary: pd.DataFrame, data: Mapping[str, Any]) -> CompareSection:
    sec = CompareSection(heading="Runs")
    n_ok = int((summary["status"] == "ok").sum()) if "status" in summary.columns else 0
    failed = list(data.get("failed_runs") or [])
    sec.paragraphs.append(
        f"{len(summary)} runs in the folder ({n_ok} finished); {data['runs_made']} made by "
        f"the last `fleet-sim compare`, {data['runs_skipped']} already there"
        + (f"; failed: {', '.join(failed)}" if failed else "") + ". The baseline's runs "
        f"carry the run ids a sweep gives them; a variant's start with v=<variant>__. "
        f"Base scenario: {BASE_VARIANT}.")
    return sec
