"""`fleet-sim compare`: every variant of an experiment against its baseline, with common random
numbers, replications added in batches until every paired difference is decided, and the best
variant selected when the file names an objective. The statistics are
fleet_sim.analysis.paired's; this module decides which runs to make and when to stop.

Results folder (``results/<experiment>`` by default), as a sweep's (fleet_sim.study.sweep)::

    runs/<run id>/         the baseline's runs under the ids a sweep gives them (shared with
                           sweep and size), a variant's under ``v=<variant>__<id>``
    summary.parquet        one row per run, with a `variant` column; stats.parquet per variant
                           and design point; sweep.duckdb (fleet_sim.study.results)
    compare.json           the comparisons (means, paired differences, intervals, verdicts),
                           the correction, the looks, the replications, the selection

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import json
import math
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from fleet_sim.analysis.kpis import (
    is_kpi_name,
    kpi_better,
    kpi_label,
    kpi_names,
    kpi_short,
    kpi_unit,
    kpi_value,
)
from fleet_sim.analysis.paired import (
    Correction,
    KnResult,
    PairedDifference,
    Verdict,
    decided,
    kn_select,
    looks,
    number_text,
    paired_difference,
    signed_text,
    verdict,
)
from fleet_sim.config.experiment import MAX_RUNS, Experiment, RunSpec, point_text
from fleet_sim.errors import InputError
from fleet_sim.study.pools import DEFAULT_NO_WORKERS_TIMEOUT_S, DaskPool, LocalPool, make_pool
from fleet_sim.study.progress import Progress
from fleet_sim.study.results import tables_written
from fleet_sim.study.run_folder import OK
from fleet_sim.study.runner import check_extras, execute, prepare
from fleet_sim.study.study_folder import folder_lock, write_plan
from fleet_sim.study.warmup import largest_fleet, pilot_groups, settle_warmup
from fleet_sim.study.worker import RunFn, execute_run
from userfiles.writing import write_json_atomic

DEFAULT_KPIS = ("throughput_per_hour", "lead_time_p95_s")
COMPARE_FILE = "compare.json"


# ---- the experiment's comparison -------------------------------------------------------------


def compared_kpis(experiment: Experiment) -> list[str]:
    """The KPIs compared: compare.kpis, else the targets' KPIs, else DEFAULT_KPIS."""
    spec = experiment.spec
    if spec.compare.kpis:
        return list(spec.compare.kpis)
    targets = list(dict.fromkeys(t.kpi for t in spec.targets))
    return targets or list(DEFAULT_KPIS)


def check_compare(experiment: Experiment, max_replications: int | None = None) -> None:
    """Refuse, with one line, a comparison that cannot run: no variant but the baseline, an
    unknown KPI, a precision for a KPI not compared, a cap below min_replications (a PCS of
    at most 1/2, no better than a coin between two, is refused by the file's model)."""
    file = str(experiment.file)
    cfg = experiment.spec.compare
    if len(experiment.variant_names) < 2:
        raise InputError(file, "variants", dict(experiment.spec.variants),
                         "at least one variant besides the baseline "
                         f"({experiment.baseline_name}) to compare")
    kpis = compared_kpis(experiment)
    known = sorted(kpi_names())
    for i, kpi in enumerate(kpis):
        if not is_kpi_name(kpi):
            element = f"compare.kpis[{i}]" if cfg.kpis else f"targets ({kpi})"
            raise InputError(file, element, kpi, "a KPI of the catalogue (fleet-sim schema "
                             "experiment; docs): " + ", ".join(known[:12]) + ", ...")
    for kpi, value in cfg.precision.items():
        if kpi not in kpis:
            raise InputError(file, f"compare.precision.{kpi}", value,
                             "a precision for a compared KPI (" + ", ".join(kpis) + ")")
    objective = cfg.objective
    if objective is not None:
        if not is_kpi_name(objective.kpi):
            raise InputError(file, "compare.objective.kpi", objective.kpi,
                             "a KPI of the catalogue, such as lead_time_p95_s")
        names = experiment.variant_names
        for i, name in enumerate(objective.among):
            if name not in names:
                raise InputError(file, f"compare.objective.among[{i}]", name,
                                 "the name of a variant of this file (" + ", ".join(names) + ")")
        if objective.among and len(set(objective.among)) < 2:
            raise InputError(file, "compare.objective.among", list(objective.among),
                             "at least two distinct variants to select from")
    if max_replications is not None and max_replications < cfg.min_replications:
        raise InputError("--max-replications", "max_replications", max_replications,
                         f"an integer >= compare.min_replications ({cfg.min_replications})")
    cap = max_replications if max_replications is not None else cfg.max_replications
    runs = len(experiment.variant_names) * len(design(experiment)) * cap
    if runs > MAX_RUNS:
        raise InputError(file if max_replications is None else "--max-replications",
                         "compare.max_replications" if max_replications is None
                         else "max_replications", cap,
                         f"at most {MAX_RUNS} runs in one comparison ({runs} = "
                         f"{len(experiment.variant_names)} variants x "
                         f"{len(design(experiment))} design points x {cap})")


# ---- results ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Comparison:
    """One variant against the baseline at one design point on one KPI."""

    variant: str
    point: dict[str, Any]
    kpi: str
    diff: PairedDifference
    verdict: Verdict
    precision: float | None

    @property
    def better(self) -> str | None:
        return kpi_better(self.kpi)

    @property
    def unit(self) -> str:
        return kpi_unit(self.kpi)

    def words(self) -> str:
        """The verdict in words: better/worse with the difference, or what was ruled out."""
        return verdict_words(self.kpi, self.diff, self.verdict)

    def as_dict(self) -> dict[str, Any]:
        d = self.diff
        return {"variant": self.variant, "point": self.point, "kpi": self.kpi,
                "unit": self.unit, "better": self.better, "pairs": d.pairs,
                "baseline_mean": _num(d.baseline_mean), "variant_mean": _num(d.variant_mean),
                "difference": _num(d.mean), "ci_low": _num(d.low), "ci_high": _num(d.high),
                "half_width": _num(d.half_width), "level": d.level,
                "precision": self.precision, "verdict": self.verdict, "words": self.words()}


@dataclass(frozen=True)
class Selection:
    """KN's selection of the best variant at one design point."""

    point: dict[str, Any]
    kpi: str
    direction: str
    indifference_zone: float
    pcs: float
    n0: int
    systems: list[str]
    result: KnResult | None
    note: str = ""

    @property
    def selected(self) -> str | None:
        if self.result is None:
            return None
        i = self.result.selected if self.result.selected is not None \
            else self.result.best_at_cap
        return None if i is None else self.systems[i]

    @property
    def done(self) -> bool:
        return self.result is not None and (self.result.selected is not None
                                            or not self.result.guaranteed)

    def statement(self) -> str:
        unit = kpi_unit(self.kpi)
        zone = f"{number_text(self.indifference_zone)} {unit}".strip()
        goal = "lowest" if self.direction == "min" else "highest"
        what = f"the {goal} {kpi_short(self.kpi)}"
        where = f" at {point_text(self.point)}" if self.point else ""
        if self.result is None:
            return f"No selection{where}: {self.note}"
        if self.result.selected is not None:
            same = [self.systems[i] for i in self.result.identical]
            twins = (f" ({', '.join(same)} gave identical results in every replication)"
                     if same else "")
            return (f"Best{where}: {self.selected}{twins}, {what} (KN: correct with probability at "
                    f"least {self.pcs:.0%} when the best beats the others by {zone} or more; "
                    f"decided at {self.result.replications} replications).")
        if not self.result.guaranteed:
            left = ", ".join(self.systems[i] for i in self.result.survivors)
            return (f"No variant stood out{where} by {zone} within the replication limit: "
                    f"{left} remain; {self.selected} has {what} so far (without KN's "
                    "guarantee).")
        return f"Selection{where} still open ({self.result.replications} replications)."

    def as_dict(self) -> dict[str, Any]:
        r = self.result
        return {"point": self.point, "kpi": self.kpi, "direction": self.direction,
                "indifference_zone": self.indifference_zone,
                "probability_correct_selection": self.pcs, "first_stage": self.n0,
                "procedure": "KN (Kim and Nelson 2001)", "systems": self.systems,
                "selected": self.selected,
                "guaranteed": bool(r is not None and r.selected is not None),
                "survivors": [self.systems[i] for i in r.survivors] if r else [],
                "identical": [self.systems[i] for i in r.identical] if r else [],
                "eliminated_at": {self.systems[i]: n for i, n in r.eliminated_at.items()}
                if r else {},
                "replications": r.replications if r else 0,
                "h2": _num(r.h2) if r else None, "note": self.note,
                "statement": self.statement()}


@dataclass
class CompareOutcome:
    out_dir: Path
    experiment: Experiment
    kpis: list[str]
    correction: Correction
    looks_planned: list[int]
    looks_done: list[int] = field(default_factory=list)
    comparisons: list[Comparison] = field(default_factory=list)
    selections: list[Selection] = field(default_factory=list)
    runs_made: int = 0
    runs_skipped: int = 0
    failed: list[str] = field(default_factory=list)
    means: dict[str, dict[str, dict[str, float | None]]] = field(default_factory=dict)
    """Design point text -> variant -> KPI -> mean over the replications run."""

    @property
    def replications(self) -> int:
        return self.looks_done[-1] if self.looks_done else 0

    @property
    def all_decided(self) -> bool:
        return all(decided(c.verdict) for c in self.comparisons)

    def as_dict(self) -> dict[str, Any]:
        exp = self.experiment
        cfg = exp.spec.compare
        return {
            "experiment": exp.name, "baseline": exp.baseline_name,
            "variants": exp.variant_names,
            "descriptions": {v: (exp.variant_spec(v).description  # type: ignore[union-attr]
                                 if exp.variant_spec(v) is not None else "")
                             for v in exp.variant_names},
            "factors": exp.factor_names, "kpis": self.kpis,
            "precision": dict(cfg.precision), "confidence": cfg.confidence,
            "min_replications": cfg.min_replications,
            "max_replications": self.looks_planned[-1],
            "correction": self.correction.as_dict(),
            "looks_planned": self.looks_planned, "looks_done": self.looks_done,
            "replications": self.replications,
            "stopped": "decided" if self.all_decided and all(s.done for s in self.selections)
            else "replication limit",
            "runs_made": self.runs_made, "runs_skipped": self.runs_skipped,
            "failed_runs": self.failed, "means": self.means,
            "comparisons": [c.as_dict() for c in self.comparisons],
            "selection": [s.as_dict() for s in self.selections]}


# ---- words ------------------------------------------------------------------------------------


def interval_text(diff: PairedDifference, unit: str) -> str:
    """``+7 s (-34 to +48 s)``."""
    u = f" {unit}" if unit else ""
    return f"{signed_text(diff.mean)}{u} ({signed_text(diff.low)} to {signed_text(diff.high)}{u})"


def verdict_words(kpi: str, diff: PairedDifference, v: Verdict) -> str:
    unit = kpi_unit(kpi)
    u = f" {unit}" if unit else ""
    if v in ("better", "worse", "higher", "lower"):
        return f"{v}: {interval_text(diff, unit)}"
    if v == "no_difference":
        return f"no difference larger than {number_text(diff.largest_effect)}{u} detected"
    if diff.pairs < 2:
        return f"undecided: {diff.pairs} pair(s) of replications with a value"
    return (f"undecided after {diff.pairs} replications: {interval_text(diff, unit)}; no "
            f"difference larger than {number_text(diff.largest_effect)}{u}")


# ---- running it -------------------------------------------------------------------------------


def design(experiment: Experiment) -> list[dict[str, Any]]:
    return [dict(p) for p in experiment.points] or [{}]


def specs_for(experiment: Experiment, replications: int) -> list[RunSpec]:
    """Every variant's runs (the baseline first) at every design point, replications 0..n-1."""
    out: list[RunSpec] = []
    for variant in experiment.variant_names:
        out += experiment.variant_runs(variant, range(replications))
    return out


def _read_values(experiment: Experiment, runs_dir: Path, n: int, kpis: Sequence[str]
                 ) -> dict[tuple[str, int], dict[str, np.ndarray]]:
    """(variant, point index) -> KPI -> values of replications 0..n-1 (NaN: no value)."""
    out: dict[tuple[str, int], dict[str, np.ndarray]] = {}
    for variant in experiment.variant_names:
        for spec in experiment.variant_runs(variant, range(n)):
            cell = out.setdefault((variant, spec.point if spec.point >= 0 else 0),
                                  {k: np.full(n, np.nan) for k in kpis})
            kpi_file = runs_dir / spec.run_id / "kpis.json"
            if not kpi_file.exists():
                continue
            figures = json.loads(kpi_file.read_text(encoding="utf-8"))
            for kpi in kpis:
                value = kpi_value(figures, kpi)
                if isinstance(value, (int, float)) and not isinstance(value, bool):
                    cell[kpi][spec.replication] = float(value)
    return out


def evaluate(experiment: Experiment, values: Mapping[tuple[str, int], Mapping[str, np.ndarray]],
             kpis: Sequence[str], correction: Correction, final: bool
             ) -> tuple[list[Comparison], list[Selection]]:
    """The comparisons and selections on the values of the replications run so far."""
    cfg = experiment.spec.compare
    base = experiment.baseline_name
    comparisons: list[Comparison] = []
    selections: list[Selection] = []
    for i, point in enumerate(design(experiment)):
        for variant in experiment.variant_names[1:]:
            for kpi in kpis:
                diff = paired_difference(values[(base, i)][kpi], values[(variant, i)][kpi],
                                         correction.level)
                precision = cfg.precision.get(kpi)
                comparisons.append(Comparison(variant, point, kpi, diff,
                                              verdict(diff, kpi_better(kpi), precision),
                                              precision))
        objective = cfg.objective
        if objective is None:
            continue
        systems = selection_systems(experiment)
        sample = np.vstack([values[(v, i)][objective.kpi] for v in systems]) \
            if (base, i) in values and objective.kpi in values[(base, i)] else None
        common = dict(point=point, kpi=objective.kpi, direction=objective.direction,
                      indifference_zone=objective.indifference_zone,
                      pcs=objective.probability_correct_selection,
                      n0=cfg.min_replications, systems=list(systems))
        if sample is None or np.isnan(sample).any():
            selections.append(Selection(**common, result=None,  # type: ignore[arg-type]
                                        note="a run without a value of "
                                             f"{objective.kpi} (failed, or nothing delivered)"))
            continue
        result = kn_select(sample, objective.indifference_zone,
                           objective.probability_correct_selection, cfg.min_replications,
                           maximise=objective.direction == "max", final=final)
        selections.append(Selection(**common, result=result))  # type: ignore[arg-type]
    return comparisons, selections


def selection_systems(experiment: Experiment) -> list[str]:
    """The variants the objective selects from, in the file's order (the baseline first)."""
    objective = experiment.spec.compare.objective
    among = set(objective.among) if objective is not None and objective.among else None
    return [v for v in experiment.variant_names if among is None or v in among]


def _means(experiment: Experiment, values: Mapping[tuple[str, int], Mapping[str, np.ndarray]],
           kpis: Sequence[str]) -> dict[str, dict[str, dict[str, float | None]]]:
    out: dict[str, dict[str, dict[str, float | None]]] = {}
    for i, point in enumerate(design(experiment)):
        key = point_text(point)
        for variant in experiment.variant_names:
            row = out.setdefault(key, {}).setdefault(variant, {})
            for kpi in kpis:
                x = values[(variant, i)][kpi]
                row[kpi] = _num(float(np.nanmean(x))) if (~np.isnan(x)).any() else None
    return out


def compare(experiment: Experiment, out_dir: Path, workers: int = 0,
            scheduler: str | None = None, quiet: bool = False,
            max_replications: int | None = None, run_fn: RunFn = execute_run,
            stream: IO[str] | None = None, pool: LocalPool | DaskPool | None = None,
            dask_timeout_s: float = DEFAULT_NO_WORKERS_TIMEOUT_S) -> CompareOutcome:
    """Run the comparison into `out_dir` (see the module docstring) and write compare.json.
    `pool`: worker processes to reuse (else a pool is started, and closed at the end)."""
    check_compare(experiment, max_replications)
    cfg = experiment.spec.compare
    cap = max_replications if max_replications is not None else cfg.max_replications
    planned = looks(cfg.min_replications, cap)
    kpis = compared_kpis(experiment)
    n_points = len(design(experiment))
    correction = Correction(cfg.confidence,
                            (len(experiment.variant_names) - 1) * n_points * len(kpis),
                            len(planned))
    outcome = CompareOutcome(out_dir, experiment, kpis, correction, planned)
    n_workers = workers or os.cpu_count() or 1
    check_extras(experiment, scheduler)
    with folder_lock(out_dir, stream), \
            tables_written(experiment, out_dir, stream=stream, quiet=quiet) as plan:
        own = pool is None
        if pool is None:
            pool = make_pool(scheduler, n_workers, run_fn, dask_timeout_s)
        try:
            if experiment.spec.warmup.method != "fixed":
                with Progress(stream=stream, quiet=quiet) as progress:
                    experiment = settle_warmup(experiment, out_dir, pilot_groups(experiment),
                                               largest_fleet(experiment), pool, progress)
                outcome.experiment = experiment
            prepare(experiment, out_dir)
            write_plan(out_dir, "compare", None)
            objective_kpi = [cfg.objective.kpi] if cfg.objective else []
            wanted = list(dict.fromkeys([*kpis, *objective_kpi]))
            earlier = 0
            for n in planned:
                specs = specs_for(experiment, n)
                plan.add(spec.run_id for spec in specs)
                if not quiet:
                    print(f"  look {len(outcome.looks_done) + 1} of at most {len(planned)}: "
                          f"{n} replications x {len(experiment.variant_names)} variants x "
                          f"{n_points} design points = {len(specs)} runs",
                          file=stream or sys.stdout)
                done = execute(specs, out_dir, n_workers, scheduler, quiet, run_fn, stream,
                               pool=pool)
                outcome.runs_made += len(done.results)
                # skipped: finished before this invocation (not the runs of its earlier looks)
                outcome.runs_skipped += max(0, done.skipped - earlier)
                earlier = len(specs)
                outcome.failed += [r.run_id for r in done.results if r.status != OK]
                outcome.looks_done.append(n)
                values = _read_values(experiment, out_dir / "runs", n, wanted)
                final = n == planned[-1]
                outcome.comparisons, outcome.selections = evaluate(
                    experiment, values, kpis, correction, final)
                outcome.means = _means(experiment, values, wanted)
                if outcome.all_decided and all(s.done for s in outcome.selections):
                    break
        finally:
            if own:
                pool.close()
        write_compare(outcome)
    return outcome


def write_compare(outcome: CompareOutcome) -> Path:
    path = outcome.out_dir / COMPARE_FILE
    write_json_atomic(path, outcome.as_dict())
    return path


def read_compare(out_dir: Path) -> dict[str, Any] | None:
    path = out_dir / COMPARE_FILE
    if not path.exists():
        return None
    data: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return data


# ---- the printed table ------------------------------------------------------------------------


def table_lines(outcome: CompareOutcome) -> list[str]:
    """Per design point, variant and KPI: baseline mean, variant mean, the paired difference
    with its interval, and the verdict in words; then the selection."""
    level = outcome.correction.level
    lines = [f"paired differences (variant - {outcome.experiment.baseline_name}), each "
             f"interval at {level:.4%} ({outcome.correction.confidence:.0%} jointly over "
             f"{outcome.correction.comparisons} comparisons x {outcome.correction.looks} "
             f"looks, Bonferroni); {outcome.replications} replications per variant"]
    header = ("variant", "KPI", "baseline", "variant", "difference (interval)", "verdict")
    rows: list[tuple[str, ...]] = []
    last_point: str | None = None
    for c in outcome.comparisons:
        where = point_text(c.point)
        if where and where != last_point:
            rows.append((f"[{where}]", "", "", "", "", ""))
            last_point = where
        d = c.diff
        verdict_text = c.words().split(": ")[0] if c.verdict in (
            "better", "worse", "higher", "lower") else c.words()
        rows.append((c.variant, kpi_label(c.kpi), number_text(d.baseline_mean),
                     number_text(d.variant_mean), interval_text(d, ""), verdict_text))
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    for r in [header, *rows]:
        lines.append("  " + "  ".join(cell.ljust(widths[i]) for i, cell in enumerate(r))
                     .rstrip())
    lines += ["  " + s.statement() for s in outcome.selections]
    return lines


def _num(value: float) -> float | None:
    return None if value is None or math.isnan(value) else round(float(value), 6)
