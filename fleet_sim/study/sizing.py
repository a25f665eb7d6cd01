"""Fleet sizing: the smallest fleet that meets every target with 95 % confidence.

Two answers side by side:

* The analytic estimate (fleet_sim.analysis.estimate): travel and handling per order x demand /
  AGV time; no waiting, no traffic: a lower bound on the fleet, and the search starts there.
* The search: evaluate a fleet size with the experiment's replications; where the 95 % interval
  of a target KPI straddles the bound, add replications (up to ``sizing.max_replications``,
  growing towards the number fleet_sim.analysis.stats estimates would decide it); step away
  from the start
  (1, 2, 4 ... AGVs) until one size meets every target and a smaller one does not, then bisect.
  A size still undecided at the replication limit counts as not shown to meet the targets (the
  recommendation errs towards more AGVs). The search assumes more AGVs never make a target
  worse; the report's grid (from a sweep) shows whether that held.

Every run goes through fleet_sim.study.sweep with the experiment's seeds, so a sizing search over a
folder that already holds a sweep reuses its runs, and an interrupted search resumes.
Other factors of the experiment (say, two demand levels) each get their own search.

The search is held to the run limit of one experiment (MAX_RUNS, fleet_sim.config.experiment),
as a sweep is when its file is read: it counts the distinct runs it uses over all its groups,
reused ones included, and before asking for runs that would take it over the limit it stops
with `SizingLimit`, naming the limit. What was decided so far is kept: sizing.json is written
with every evaluation done (the stopped group says so; groups not reached are left out), the
runs stay in the folder, and the summary tables are refreshed as after any search.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from fleet_sim.analysis.estimate import Estimate, analytic_estimate
from fleet_sim.analysis.kpis import kpi_value
from fleet_sim.analysis.stats import TargetCheck, target_check
from fleet_sim.config.experiment import (
    FLEET,
    MAX_RUNS,
    Experiment,
    RunSpec,
    Target,
    layout_for,
    load_trace_for,
)
from fleet_sim.errors import FleetSimError, InputError
from fleet_sim.study.progress import Progress
from fleet_sim.study.sweep import DaskPool, LocalPool, execute, folder_lock, prepare, tables_written

DEFAULT_MAX_AGVS = 50


# ---- the search ----------------------------------------------------------------------------


class SizingLimit(FleetSimError):
    """The search would need more runs than one experiment may have."""


class RunBudget:
    """The distinct runs a search has used, at most `limit` of them."""

    def __init__(self, limit: int = MAX_RUNS) -> None:
        self.limit = limit
        self.used: set[str] = set()

    def take(self, runs: Sequence[RunSpec]) -> None:
        """Count `runs` in, or raise SizingLimit (counting none of them) if they would take
        the search over the limit."""
        new = {r.run_id for r in runs} - self.used
        if len(self.used) + len(new) > self.limit:
            raise SizingLimit(
                f"the sizing search stopped: it needs more than {self.limit} runs, the limit "
                f"of one experiment (it has used {len(self.used)} and asked for {len(new)} "
                "more); sizing.json keeps what was decided so far. Narrow sizing.min_agvs / "
                "sizing.max_agvs or lower sizing.max_replications")
        self.used |= new



@dataclass
class Evaluation:
    agvs: int
    replications: int
    checks: list[TargetCheck]
    failed_runs: int = 0

    @property
    def verdict(self) -> str:
        decisions = [c.decision for c in self.checks]
        if any(d == "fails" for d in decisions):
            return "fails"
        if decisions and all(d == "meets" for d in decisions):
            return "meets"
        return "undecided"

    def as_dict(self) -> dict[str, Any]:
        return {
            "agvs": self.agvs, "replications": self.replications, "verdict": self.verdict,
            "failed_runs": self.failed_runs,
            "targets": [{"target": c.target.describe(), "kpi": c.target.kpi,
                         "bound": c.target.bound, "at_least": c.target.higher_is_better,
                         "decision": c.decision, "n": c.interval.n,
                         "mean": _num(c.interval.mean), "ci_low": _num(c.interval.low),
                         "ci_high": _num(c.interval.high), "needed": c.needed}
                        for c in self.checks],
        }


@dataclass
class GroupResult:
    fixed: dict[str, Any]
    estimate: Estimate
    evaluations: dict[int, Evaluation] = field(default_factory=dict)
    recommended: int | None = None
    min_agvs: int = 1
    max_agvs: int = DEFAULT_MAX_AGVS
    stopped: str | None = None
    """Why the search stopped before an answer (the run limit), if it did."""

    def statement(self) -> str:
        """The recommendation in a planner's words, with its confidence."""
        where = ", ".join(f"{k} = {v}" for k, v in self.fixed.items())
        head = f"{where}: " if where else ""
        if self.stopped is not None:
            done = ", ".join(f"{n} AGVs {self.evaluations[n].verdict}"
                             for n in sorted(self.evaluations)) or "no fleet evaluated"
            return f"{head}no answer ({done}): {self.stopped}"
        if self.recommended is None:
            tried = self.evaluations.get(self.max_agvs)
            why = _why_not(tried) if tried else ""
            return (f"{head}no fleet of {self.min_agvs} to {self.max_agvs} AGVs meets every "
                    f"target with 95 % confidence{why}")
        ev = self.evaluations[self.recommended]
        parts = [f"{c.target.kpi} {c.interval.mean:.4g} (95 % CI {c.interval.low:.4g} to "
                 f"{c.interval.high:.4g}; target {c.target.describe().split(' ', 1)[1]})"
                 for c in ev.checks]
        text = (f"{head}{self.recommended} AGVs meet every target with 95 % confidence over "
                f"{ev.replications} replications: " + "; ".join(parts) + ".")
        below = self.evaluations.get(self.recommended - 1)
        if below is not None:
            text += f" {below.agvs} AGVs: {below.verdict}{_why_not(below)}."
        elif self.recommended == self.min_agvs:
            text += f" ({self.min_agvs} is the smallest fleet searched.)"
        return text

    def as_dict(self) -> dict[str, Any]:
        return {"fixed": self.fixed, "estimate": self.estimate.as_dict(),
                "recommended": self.recommended, "min_agvs": self.min_agvs,
                "max_agvs": self.max_agvs, "stopped": self.stopped,
                "statement": self.statement(),
                "evaluations": [self.evaluations[n].as_dict() for n in sorted(self.evaluations)]}


def _why_not(ev: Evaluation) -> str:
    bad = [c for c in ev.checks if c.decision != "meets"]
    if not bad:
        return ""
    return " (" + "; ".join(
        f"{c.target.kpi} {c.interval.mean:.4g}, 95 % CI {c.interval.low:.4g} to "
        f"{c.interval.high:.4g}, {c.decision} {c.target.describe().split(' ', 1)[1]}"
        for c in bad) + ")"


def _num(value: float) -> float | None:
    return None if math.isnan(value) else value


class Sizer:
    """Runs the search for one group of fixed factor values."""

    def __init__(self, experiment: Experiment, out_dir: Path, fixed: dict[str, Any],
                 pool: LocalPool | DaskPool, progress: Progress,
                 budget: RunBudget | None = None) -> None:
        self.experiment = experiment
        self.budget = budget if budget is not None else RunBudget()
        self.out_dir = out_dir
        self.fixed = fixed
        self.pool = pool
        self.progress = progress
        self.targets: Sequence[Target] = experiment.spec.targets

    def evaluate(self, agvs: int, result: GroupResult) -> Evaluation:
        spec = self.experiment.spec
        reps = spec.replications
        cap = max(spec.sizing.max_replications, reps)
        while True:
            factors = {**self.fixed, FLEET: agvs}
            runs = [self.experiment.run(factors, r) for r in range(reps)]
            self.budget.take(runs)
            execute(runs, self.out_dir, quiet=True, pool=self.pool)
            values, failed = self._values(runs)
            checks = [target_check(factors, t, values[t.kpi]) for t in self.targets]
            ev = Evaluation(agvs, reps, checks, failed)
            result.evaluations[agvs] = ev  # kept if the run limit stops the search
            if ev.verdict != "undecided" or reps >= cap:
                break
            wanted = [c.needed for c in checks if c.decision == "undecided" and c.needed]
            grow = max(wanted) if wanted else reps + 1
            reps = min(cap, max(reps + 1, min(grow, 2 * reps)))
        note = " (undecided at the replication limit: counted as not meeting)" \
            if ev.verdict == "undecided" else ""
        self.progress.note(f"{_where(self.fixed)}{agvs} AGVs, {ev.replications} "
                           f"replications: {ev.verdict}{note}")
        return ev

    def _values(self, runs: Sequence[Any]) -> tuple[dict[str, np.ndarray], int]:
        values: dict[str, list[float]] = {t.kpi: [] for t in self.targets}
        failed = 0
        for spec in runs:
            kpi_file = self.out_dir / "runs" / spec.run_id / "kpis.json"
            if not kpi_file.exists():
                failed += 1
                continue
            figures = json.loads(kpi_file.read_text(encoding="utf-8"))
            for kpi in values:
                value = kpi_value(figures, kpi)
                values[kpi].append(math.nan if value is None else float(value))
        return {k: np.array(v, dtype=float) for k, v in values.items()}, failed

    def search(self, estimate: Estimate, lo_limit: int, hi_limit: int) -> GroupResult:
        """The search; stopped (result.stopped) where the run budget runs out."""
        result = GroupResult(self.fixed, estimate, min_agvs=lo_limit, max_agvs=hi_limit)
        try:
            self._search(result, estimate, lo_limit, hi_limit)
        except SizingLimit as exc:
            result.stopped = str(exc)
        return result

    def _search(self, result: GroupResult, estimate: Estimate, lo_limit: int,
                hi_limit: int) -> None:
        def meets(n: int) -> bool:
            ev = result.evaluations.get(n) or self.evaluate(n, result)
            return ev.verdict == "meets"

        start = min(max(estimate.minimum, lo_limit), hi_limit)
        lo = lo_limit - 1  # largest size known not to meet (lo_limit - 1: none below)
        hi: int | None = None  # smallest size known to meet
        if meets(start):
            hi, step = start, 1
            while hi - step >= lo_limit:
                probe = hi - step
                if meets(probe):
                    hi, step = probe, step * 2
                else:
                    lo = probe
                    break
        else:
            lo, step = start, 1
            while lo < hi_limit:
                probe = min(lo + step, hi_limit)
                if meets(probe):
                    hi = probe
                    break
                lo, step = probe, step * 2
        if hi is None:
            return
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if meets(mid):
                hi = mid
            else:
                lo = mid
        result.recommended = hi


def groups(experiment: Experiment) -> list[dict[str, Any]]:
    """The combinations of the other factors' values, one sizing search each."""
    others = [f for f in experiment.factor_names if f != FLEET]
    for name in others:
        value = experiment.spec.factors[name]
        if not isinstance(value, list):
            raise InputError(str(experiment.file), f"factors.{name}", value,
                             "a list of levels (`fleet-sim size` searches each combination of "
                             "the other factors' levels; ranges are for sweeps)")
    seen: list[dict[str, Any]] = []
    for point in experiment.points:
        fixed = {k: v for k, v in point if k in others}
        if fixed not in seen:
            seen.append(fixed)
    return seen or [{}]


def size_fleet(experiment: Experiment, out_dir: Path, workers: int = 0,
               scheduler: str | None = None, quiet: bool = False,
               stream: IO[str] | None = None, max_runs: int = MAX_RUNS) -> list[GroupResult]:
    """Search every group; write sizing.json and refresh the summary tables (holding the
    results folder: see fleet_sim.study.sweep.folder_lock). Raises SizingLimit, after writing
    them, if the search would need more than `max_runs` runs."""
    spec = experiment.spec
    if not spec.targets:
        raise InputError(str(experiment.file), "targets", [],
                         "at least one target for `fleet-sim size` to meet")
    levels = [v for v in (spec.factors.get(FLEET) or []) if isinstance(v, int)]
    lo_limit = spec.sizing.min_agvs or (min(levels) if levels else 1)
    hi_limit = spec.sizing.max_agvs or (max(levels) if levels else DEFAULT_MAX_AGVS)
    if hi_limit < lo_limit:
        raise InputError(str(experiment.file), "sizing.max_agvs", hi_limit,
                         f"at least the smallest fleet searched ({lo_limit})")
    with folder_lock(out_dir, stream), tables_written(experiment, out_dir):
        prepare(experiment, out_dir)
        results = []
        n_workers = workers or os.cpu_count() or 1
        pool: LocalPool | DaskPool = DaskPool(scheduler, n_workers) if scheduler \
            else LocalPool(n_workers)
        budget = RunBudget(max_runs)
        stopped: str | None = None
        with pool, Progress(stream=stream, quiet=quiet) as progress:
            for fixed in groups(experiment):
                if stopped is not None:
                    break
                result = _size_group(experiment, out_dir, fixed, lo_limit, hi_limit, pool,
                                     progress, budget)
                results.append(result)
                stopped = result.stopped
        document = {"experiment": experiment.name, "confidence": 0.95,
                    "targets": [t.describe() for t in spec.targets],
                    "runs_used": len(budget.used), "max_runs": max_runs,
                    "stopped": stopped, "groups": [r.as_dict() for r in results]}
        (out_dir / "sizing.json").write_text(json.dumps(document, indent=2, default=str) + "\n",
                                             encoding="utf-8")
        if stopped is not None:
            raise SizingLimit(stopped)
    return results


def _size_group(experiment: Experiment, out_dir: Path, fixed: dict[str, Any], lo_limit: int,
                hi_limit: int, pool: LocalPool | DaskPool, progress: Progress,
                budget: RunBudget) -> GroupResult:
    spec = experiment.spec
    scenario = experiment.scenario(fixed)
    layout = layout_for(scenario, str(experiment.scenario_file))
    trace = load_trace_for(scenario, layout)
    estimate = analytic_estimate(scenario, layout, spec.sizing.agv_availability, trace)
    progress.note(f"{_where(fixed)}analytic estimate {estimate.agvs:.2f} AGVs busy at the mean "
                  f"demand ({estimate.demand_per_hour:.1f} orders/h x {estimate.cycle_s:.1f} s "
                  f"per order); searching {lo_limit} to {hi_limit} AGVs from "
                  f"{min(max(estimate.minimum, lo_limit), hi_limit)}")
    return Sizer(experiment, out_dir, fixed, pool, progress, budget).search(estimate, lo_limit,
                                                                            hi_limit)


def _where(fixed: dict[str, Any]) -> str:
    """The fixed factor values as a message prefix ("demand.rate_per_hour=90: "), or ""."""
    return ", ".join(f"{k}={v}" for k, v in fixed.items()) + ": " if fixed else ""
