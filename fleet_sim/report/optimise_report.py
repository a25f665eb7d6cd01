"""The optimise report: a `fleet-sim optimise` results folder (optimise.json) -> a `Report`
(plain data, as fleet_sim.report.study_report's) that fleet_sim.report.render writes as HTML
and PDF.

The first screen answers in a planner's words: "The cheapest system that meets both targets
(throughput at least 95 % of demand; p95 lead time at most 600 s): 16 AGVs, opportunity
charging, a fifth charger at C05: 742,000 EUR.", what it reaches, then "No cheaper design does:
the same system with 15 AGVs (704,000 EUR) misses p95 lead time 631 s (604 to 658)."; the
guarantee, and the runs used against the full grid. When no design meets: which target binds
and the design that comes closest. Below: price against each target's KPI (every design run,
marked by its verdict), the table of every design, the chosen design's layout with its changes
in red, what each target costs, and how the answer was found.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from fleet_sim.analysis.kpis import kpi_label, kpi_short, target_words
from fleet_sim.analysis.paired import number_text
from fleet_sim.config.decisions import DesignSpace, design_layout, design_space
from fleet_sim.config.experiment import Experiment, load_experiment
from fleet_sim.config.layout_changes import layout_diff
from fleet_sim.errors import FleetSimError, InputError
from fleet_sim.report import figures as figs
from fleet_sim.report import optimise_figures as ofigs
from fleet_sim.report.content import Figure, Report, Section, Table, png_figure
from fleet_sim.report.layout_plot import variant_figure
from fleet_sim.report.sections.compare_section import CompareSection
from fleet_sim.study.optimise import OPTIMISE_FILE, design_words
from fleet_sim.study.optimise_words import (
    and_words,
    answer_index,
    answer_statements,
    by_price,
    guarantee_sentence,
    index_of,
    interval_cell,
    money,
    runs_sentence,
    target_of,
    targets_words,
    verdict_counts,
)

ANSWER_VERDICT = "meets (the answer)"


def is_optimise_folder(out_dir: Path) -> bool:
    return (out_dir / OPTIMISE_FILE).exists()


def read_optimise(out_dir: Path) -> dict[str, Any]:
    """optimise.json of `out_dir`; InputError if it is not there or not readable."""
    path = out_dir / OPTIMISE_FILE
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(str(out_dir), "folder", str(out_dir),
                         f"a results folder of `fleet-sim optimise` (with a readable "
                         f"{OPTIMISE_FILE}: {exc})") from exc
    if not isinstance(document, dict) or "designs" not in document:
        raise InputError(str(path), "designs", None,
                         "the list of every design, as `fleet-sim optimise` writes it")
    return document


# ---- the report -------------------------------------------------------------------------------


def build_optimise_report(out_dir: Path) -> Report:
    """Read an optimise results folder and prepare every section (figures drawn)."""
    document = read_optimise(out_dir)
    experiment, space, problem = _experiment(out_dir, document)
    designs: list[dict[str, Any]] = document["designs"]
    words = [design_words(space, space.designs[i]) if space is not None else str(d["label"])
             for i, d in enumerate(designs)]
    statements = answer_statements(document, words)
    estimates = [guarantee_sentence(document), runs_sentence(document)]
    if document["assumption"].get("more_agvs_never_worse") and \
            not document["assumption"].get("held", True):
        estimates.append("The assumption more_agvs_never_worse did NOT hold on the designs "
                         "next to the answer: see How the answer was found.")
    sections: list[Section] = [
        _section_chart(document),
        _section_designs(document, words),
        _section_layout(document, experiment, space, words, problem),
        _section_target_costs(document, words),
        _section_procedure(document),
    ]
    decisions = list(designs[0]["choices"]) if designs else []
    what, targets = targets_words(document)
    lead = (f"The cheapest of {document['design_count']} designs over "
            f"{and_words([k.removeprefix('layout:') for k in decisions])} that meets {what} "
            f"({targets}); prices in {document['currency']}. Generated "
            f"{time.strftime('%Y-%m-%d %H:%M')} by fleet-sim.")
    return Report(f"Cheapest design: {document.get('experiment', 'experiment')}", lead,
                  statements, estimates, sections, template="optimise.html.j2",
                  answer_title="Answer")


def _experiment(out_dir: Path, document: Mapping[str, Any]
                ) -> tuple[Experiment | None, DesignSpace | None, str]:
    """The experiment read again and its design space, if it still matches optimise.json;
    else why not."""
    resolved_file = out_dir / "experiment.resolved.yaml"
    try:
        resolved = yaml.safe_load(resolved_file.read_text(encoding="utf-8")) or {}
    except (OSError, yaml.YAMLError) as exc:
        return None, None, f"The folder's experiment.resolved.yaml could not be read: {exc}"
    file = resolved.get("experiment_file") if isinstance(resolved, dict) else None
    try:
        experiment = load_experiment(str(file))
        space = design_space(experiment)
    except (InputError, FleetSimError, OSError) as exc:
        return None, None, f"The experiment file {file} could not be read again: {exc}"
    labels = [d.label() for d in space.designs]
    if labels != [d["label"] for d in document["designs"]]:
        return None, None, (f"The experiment file {file} has changed since the search: its "
                            "design space is no longer the one optimise.json describes.")
    return experiment, space, ""


def _section_chart(document: Mapping[str, Any]) -> CompareSection:
    sec = CompareSection(heading="Price against each target")
    designs: list[dict[str, Any]] = document["designs"]
    answer = answer_index(document)
    highlight = "the answer"
    if answer is None and document.get("closest"):
        answer = index_of(document, str(document["closest"]["design"]))
        highlight = "closest"
    run = [d for d in designs if d["replications"]]
    if not run or not designs:
        sec.paragraphs.append("No design was run: there is nothing to draw.")
        return sec
    tolerance: Mapping[str, float] = document.get("tolerance") or {}
    targets = [ofigs.TargetLine(str(r["kpi"]), float(r["bound"]), bool(r["at_least"]),
                                tolerance.get(str(r["kpi"])))
               for r in designs[0]["targets"]]
    points = [ofigs.DesignPoint(float(d["price"]), str(d["verdict"]),
                                [(r["mean"], r["ci_low"], r["ci_high"]) for r in d["targets"]],
                                highlight if int(d["index"]) == answer else "")
              for d in run]
    sec.paragraphs.append(
        f"Every design that was run ({len(run)} of {len(designs)}): its price against each "
        "target's KPI, the mean with its 95 % interval, marked by its verdict. The dashed line "
        "is the target; in the grey band round it (± the tolerance) either verdict may be "
        "right. The answer (else the design that comes closest) is ringed in blue. Designs "
        "never run (not needed, ruled out, refused) are in the table below.")
    sec.figures.append(png_figure("price_against_targets",
                                  "Price against each target's KPI, every design run",
                                  ofigs.price_against_targets(points, targets,
                                                              str(document["currency"]))))
    return sec


def _reason(d: Mapping[str, Any]) -> str:
    if d["reason"]:
        text = str(d["reason"])
    elif d["decided_at"] is not None:
        text = f"decided after {d['decided_at']} replications"
    else:
        text = ""
    if d.get("check"):
        text += ("; " if text else "") + f"run to check the assumption: {d['check']}"
    return text


def _section_designs(document: Mapping[str, Any], words: Sequence[str]) -> CompareSection:
    designs: list[dict[str, Any]] = document["designs"]
    currency = str(document["currency"])
    answer = answer_index(document)
    kpis = [str(r["kpi"]) for r in designs[0]["targets"]] if designs else []
    header = ["design", "decisions", f"price [{currency}]", "verdict", "replications",
              *(f"{kpi_label(k)}: mean (95 % interval)" for k in kpis), "why"]
    rows = [[words[int(d["index"])], str(d["label"]), f"{float(d['price']):,.0f}",
             ANSWER_VERDICT if int(d["index"]) == answer else str(d["verdict"]),
             str(d["replications"]), *(interval_cell(r) for r in d["targets"]), _reason(d)]
            for d in by_price(designs)]
    sec = CompareSection(heading="Every design", tables=[Table(header, rows, "designs")])
    counts = ", ".join(f"{v}: {n}" for v, n in
                       verdict_counts([str(d["verdict"]) for d in by_price(designs)]).items())
    sec.paragraphs.append(
        f"All {len(designs)} designs by price ({counts}). A design costlier than one shown to "
        "meet every target is not needed and never run; a fleet below the AGVs the analytic "
        "estimate keeps busy is ruled out, a design whose AGVs do not fit its layout refused, "
        "both before any run.")
    sec.text += [f"{r[0]} ({r[2]} {currency}): {r[3]}, {r[4]} replications"
                 + "".join(f"; {kpi_short(k)} {c}" for k, c in zip(kpis, r[5:-1], strict=True)
                           if r[4] != "0")
                 + (f"; {r[-1]}" if r[-1] else "") for r in rows]
    return sec


def _section_layout(document: Mapping[str, Any], experiment: Experiment | None,
                    space: DesignSpace | None, words: Sequence[str],
                    problem: str) -> CompareSection:
    sec = CompareSection(heading="The chosen design's layout")
    answer = answer_index(document)
    which = "the answer"
    if answer is None:
        close = document.get("closest")
        answer = index_of(document, str(close["design"])) if close else None
        sec.heading = "The closest design's layout"
        which = "the design that comes closest (no design meets)"
        if answer is None:
            sec.paragraphs.append("No design was run: there is no layout to show.")
            return sec
    if experiment is None or space is None:
        sec.paragraphs.append(problem + " The layout is not drawn; the rest of the report "
                              "stands.")
        sec.text += sec.paragraphs
        return sec
    design = space.designs[answer]
    factors = dict(experiment.points[0]) if experiment.points else {}
    try:
        scenario = experiment.scenario({**factors, **dict(design.settings)})
        changed = design_layout(experiment, scenario, design)
        base = design_layout(experiment, scenario, dataclasses.replace(design, changes=()))
    except (InputError, FleetSimError, OSError) as exc:
        sec.paragraphs.append(f"The layout of {words[answer]} could not be drawn: {exc}")
        sec.text += sec.paragraphs
        return sec
    config = space.config
    chosen = [f"{group}: {option}" + (f" ({config.layout_decisions[group][option].description})"
                                       if config.layout_decisions[group][option].description
                                       else "")
              for group, option in design.options]
    diff = layout_diff(base, changed)
    if not design.changes or diff.empty:
        sec.paragraphs.append(
            f"{words[answer][0].upper() + words[answer][1:]}, {which}, drives on the layout as "
            f"it is ({changed.name})"
            + (f"; layout options chosen: {'; '.join(chosen)}." if chosen else "."))
        png = figs.layout_png(changed)
        caption = f"Layout {changed.name}, as it is"
        sec.figures.append(Figure("layout_answer", caption, png,
                                  figs.image_page(png, caption)))
        sec.text += sec.paragraphs
        return sec
    what = [f"{len(items)} {name}: {', '.join(items)}" for name, items in (
        ("changed or new nodes", diff.changed_nodes), ("removed nodes", diff.removed_nodes),
        ("changed or new places", diff.changed_places), ("removed places", diff.removed_places))
        if items]
    if diff.changed_segments or diff.removed_segments:
        what.append(f"{len(diff.changed_segments)} changed or new hops, "
                    f"{len(diff.removed_segments)} removed")
    sec.paragraphs.append(
        f"{words[answer][0].upper() + words[answer][1:]}, {which}, on layout {changed.name} "
        f"with its layout changes in red; options chosen: {'; '.join(chosen)}. "
        f"Against the layout as it is: {'; '.join(what)}.")
    title = "Layout changes in red (new or changed hops, nodes ringed)"
    sec.figures.append(png_figure("layout_answer", f"{words[answer]}: its layout changes in red "
                                  "(new or changed hops, nodes ringed)",
                                  variant_figure(changed, base, diff, title)))
    sec.text += sec.paragraphs
    return sec


def _section_target_costs(document: Mapping[str, Any], words: Sequence[str]) -> CompareSection:
    sec = CompareSection(heading="What each target costs")
    currency = str(document["currency"])
    rows_in: list[dict[str, Any]] = list(document.get("target_costs") or [])
    answer = answer_index(document)
    if not rows_in:
        sec.paragraphs.append("optimise.json has no target costs.")
        return sec
    designs: list[dict[str, Any]] = document["designs"]
    by_kpi = {str(r["kpi"]): r for r in designs[0]["targets"]} if designs else {}
    rows: list[list[str]] = []
    for r in rows_in:
        target_row = by_kpi.get(str(r["kpi"]))
        target = target_words(target_of(target_row)) if target_row else str(r["target"])
        relaxed = target_words(target_of(target_row, r["relaxed_to"])) if target_row \
            else f"{r['relaxed_to']:g}"
        index = index_of(document, str(r["design"])) if r["design"] is not None else None
        if r["design"] is None:
            design = "undecided" if not r["decided"] else "no design meets"
            price = saving = "-"
            sentence = f"{design}: {r['reason']}" if r["reason"] else design
        else:
            design = words[index] if index is not None else str(r["design"])
            price = money(r["price"], currency)
            if r["saving"] is None:
                saving = "-"
            elif index == answer:
                saving = "none: the same design"
            else:
                saving = money(r["saving"], currency)
            sentence = (f"{design} would do, {price}"
                        + (f", saving {saving}" if r["saving"] and index != answer else
                           " (the same design)" if index == answer else ""))
        rows.append([target, relaxed, design, price, saving,
                     str(r["reason"]) if r["design"] is None else ""])
        sec.text.append(f"{relaxed} (instead of {target}): {sentence}.")
    sec.tables.append(Table(["target", "relaxed to", "cheapest design", "price", "saving",
                             "why not decided"], rows, "target-costs"))
    saving_note = "" if answer is not None else \
        " No design meets the targets as they stand, so there is no saving to count."
    sec.paragraphs.append(
        "The cheapest design if one target were relaxed, each in turn, to each looser bound the "
        "file lists (else by its tolerance), the other targets as they are; decided from the "
        "replications already made, no new runs: where those do not decide it, it says "
        f"undecided and why.{saving_note}")
    return sec


def _section_procedure(document: Mapping[str, Any]) -> CompareSection:
    sec = CompareSection(heading="How the answer was found")
    p = document.get("procedure") or {}
    sec.paragraphs.append(
        f"{p.get('name', 'F_B feasibility checks in order of price')}. Designs are examined "
        f"cheapest first; each starts with {p.get('min_replications', '?')} replications and "
        f"gets more, up to {p.get('max_replications', '?')}, until every target is decided. "
        f"The error is split over the {p.get('designs_counted', '?')} designs that could be "
        f"run and their targets (beta {float(p.get('beta', float('nan'))):.2g} per check, h² "
        f"{float(p.get('h2', float('nan'))):.3g}); refused and ruled-out designs are decided "
        "without error and not counted. Replication r has the same seed in every design "
        "(common random numbers).")
    sec.paragraphs.append(f"Warm-up: {number_text(document.get('warmup_h'))} h of every run "
                          "is left out of its KPIs.")
    assumption = document.get("assumption") or {}
    if assumption.get("more_agvs_never_worse"):
        checked = assumption.get("checked") or []
        seen = "; ".join(f"{c['design']}: expected {c['expected']}, seen {c['seen']}"
                         for c in checked) or "no design next to the answer to check"
        held = "held" if assumption.get("held") else "did NOT hold"
        sec.paragraphs.append(
            "Assumed: more AGVs, all else the same, never make a target worse (a fleet below "
            f"one that fails fails too). Checked on the designs next to the answer: {seen}. "
            f"The assumption {held}.")
    else:
        sec.paragraphs.append("No assumption about the fleet size: every design cheaper than "
                              "the answer was decided on its own replications (or before any "
                              "run).")
    sec.paragraphs.append(runs_sentence(document)
                          + (f" The search stopped: {document['stopped']}"
                             if document.get("stopped") else ""))
    sec.text += sec.paragraphs
    return sec
