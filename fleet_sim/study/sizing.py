"""Fleet sizing: the smallest fleet that meets every target with 95 % confidence.

Two answers side by side:

* The analytic estimate (fleet_sim.sim.estimate): travel and handling per order x demand /
  AGV time; no waiting, no traffic: a lower bound on the fleet, and the search starts there.
* The search: evaluate a fleet size, step away from the start (1, 2, 4 ... AGVs) until one size
  meets every target and a smaller one does not, then bisect. A size still undecided at the
  replication limit counts as not shown to meet the targets (the recommendation errs towards
  more AGVs). The search assumes more AGVs never make a target worse; the report's grid (from
  a sweep) shows whether that held.

How many replications a fleet size gets (`sizing.stopping`):

* ``sequential`` (default): start with ``sizing.min_replications`` (2) and look again after
  doubling the replications (at least as many more as there are workers, so every core is
  busy; 2, 4, 8, 12 with the defaults) until the size is decided, or at
  ``sizing.max_replications``. It *fails* as soon as one target's 95 % interval lies wholly on
  the bad side of its bound (whatever the others say); it *meets* once every target's interval
  lies on the good side, at 99.5 % confidence at an early look and at the level left over at
  the last one (96.5 % with four looks: 0.05 - 3 x 0.005). Why: stopping at the first interval
  that clears the bound gives a size several chances to be declared good; spending the 5 %
  over the looks (Bonferroni, most of it kept for the last look, as in O'Brien-Fleming
  designs) keeps the chance of calling a size good that is not at most what one 95 % interval
  allows. Failing early errs towards more AGVs, so it keeps the nominal level. From four
  replications on, a hopeless size is given up (futility): one whose mean misses a bound, or
  sits so close to it that, with the spread seen so far, clearing it at the last look's level
  would take more than twice ``max_replications``. A size not shown to meet counts as not
  meeting whether it stops now or at the limit; giving up early can only err towards more
  AGVs. A clear case costs two or four runs instead of a fixed number; the tests check
  the answer against fixed replications.
* ``fixed``: every size runs the experiment's ``replications``; undecided counts as not meeting.

Common random numbers: replication r runs with the same seed at every fleet size
(fleet_sim.config.experiment), and the engine draws orders from streams spawned before any
AGV's, so fleet sizes face the same orders. The recommendation reports the paired difference
of each target's KPI between the recommended size and the one below, replication by
replication, beside the interval the same runs would give unpaired: the pairing cancels the
demand's noise, which both sizes share.

A mixed fleet is sized one type at a time (`sizing.vary_type`, fleet_sim.config.experiment): the
search varies that type's count, the other types keep theirs, and the answer reads "3 heavy
AGVs (beside 8 carrier)". The analytic estimate is then of a fleet of that type alone, and the
search starts from it less the other types' AGVs.

The warm-up is the scenario's, or estimated from pilot runs by MSER-5 (experiment
``warmup.method: mser5``, fleet_sim.study.warmup) before the search starts.

Every run goes through fleet_sim.study.runner with the experiment's seeds, so a sizing search over a
folder that already holds a sweep reuses its runs, and an interrupted search resumes.
Other factors of the experiment (say, two demand levels) each get their own search; the
searches run side by side (`run_searches`): each asks for its next batch of runs, and the
batches asked for at the same step run as one, so two searches of two runs each keep two
workers busy where one after the other would leave one idle half the time. Each search sees
exactly the runs it would see alone: the answer does not depend on the other groups.

The search is held to the run limit of one experiment (MAX_RUNS, fleet_sim.config.experiment),
as a sweep is when its file is read: it counts the distinct runs it uses over all its groups,
reused ones included, and before asking for runs that would take it over the limit it stops
with `SizingLimit`, naming the limit. What was decided so far is kept: sizing.json is written
with every evaluation done (a stopped group says so; the groups searched side by side stop
at the limit too), the runs stay in the folder, and the summary tables are refreshed as after
any search.
"""

from __future__ import annotations

import json
import math
from collections.abc import Generator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from fleet_sim.analysis.stats import (
    CONFIDENCE,
    TargetCheck,
    mean_ci,
    replications_needed,
    target_check,
)
from fleet_sim.config.experiment import (
    MAX_RUNS,
    Experiment,
    RunSpec,
    Target,
    layout_for,
    load_trace_for,
    point_text,
)
from fleet_sim.errors import InputError
from fleet_sim.sim.estimate import Estimate, analytic_estimate
from fleet_sim.study.pools import DEFAULT_NO_WORKERS_TIMEOUT_S, DaskPool, LocalPool, make_pool
from fleet_sim.study.progress import Progress
from fleet_sim.study.results import tables_written
from fleet_sim.study.runner import check_extras, prepare
from fleet_sim.study.search import RunBudget as SearchBudget
from fleet_sim.study.search import RunLimit, ordered_search, run_searches, run_values
from fleet_sim.study.study_folder import folder_lock, write_plan
from fleet_sim.study.warmup import largest_fleet, settle_warmup

DEFAULT_MAX_AGVS = 50
EARLY_ALPHA = 0.005
FUTILE_FROM = 4
"""Sequential stopping may give up on a hopeless size from this many replications on."""
FUTILE_MARGIN = 2
"""... when a decision would need more than this many times max_replications."""
"""Two-sided error spent at each early look of sequential stopping (99.5 % intervals)."""


# ---- the search ----------------------------------------------------------------------------


class SizingLimit(RunLimit):
    """The search would need more runs than one experiment may have."""


class RunBudget(SearchBudget):
    """The distinct runs a sizing search has used, at most `limit` of them."""

    def __init__(self, limit: int = MAX_RUNS) -> None:
        super().__init__(limit, "sizing search", "sizing.json",
                         "Narrow sizing.min_agvs / sizing.max_agvs or lower "
                         "sizing.max_replications", SizingLimit)


@dataclass
class Evaluation:
    agvs: int
    replications: int
    checks: list[TargetCheck]
    failed_runs: int = 0
    values: dict[str, dict[int, float]] = field(default_factory=dict)
    """Per target KPI: replication -> value (runs that finished)."""
    futile: bool = False
    """Stopped undecided with a target's mean on the wrong side of its bound."""
    strict: list[TargetCheck] | None = None
    """The checks at `meets_at`, the level a size must meet at (None: the 95 % checks)."""
    meets_at: float = CONFIDENCE

    @property
    def verdict(self) -> str:
        if any(c.decision == "fails" for c in self.checks):
            return "fails"
        strict = self.checks if self.strict is None else self.strict
        if strict and all(c.decision == "meets" for c in strict):
            return "meets"
        return "undecided"

    def as_dict(self) -> dict[str, Any]:
        return {
            "agvs": self.agvs, "replications": self.replications, "verdict": self.verdict,
            "meets_at_confidence": self.meets_at, "futile": self.futile,
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
    vary_type: str | None = None
    """The vehicle type whose count is searched (a mixed fleet), else None (fleet.size)."""
    beside: dict[str, int] = field(default_factory=dict)
    """With `vary_type`: the other types' counts, fixed during the search."""

    @property
    def unit(self) -> str:
        """What a count of the search counts: "AGVs", or "heavy AGVs" (a mixed fleet)."""
        return "AGVs" if self.vary_type is None else f"{self.vary_type} AGVs"

    def _beside(self) -> str:
        return "" if not self.beside else " (beside " + ", ".join(
            f"{n} {t}" for t, n in self.beside.items()) + ")"

    def statement(self) -> str:
        """The recommendation in a planner's words, with its confidence."""
        where = ", ".join(f"{k} = {v}" for k, v in self.fixed.items())
        head = f"{where}: " if where else ""
        if self.stopped is not None:
            done = ", ".join(f"{n} {self.unit} {self.evaluations[n].verdict}"
                             for n in sorted(self.evaluations)) or "no fleet evaluated"
            return f"{head}no answer ({done}): {self.stopped}"
        if self.recommended is None:
            tried = self.evaluations.get(self.max_agvs)
            why = _why_not(tried) if tried else ""
            return (f"{head}no fleet of {self.min_agvs} to {self.max_agvs} {self.unit}"
                    f"{self._beside()} meets every target with 95 % confidence{why}")
        ev = self.evaluations[self.recommended]
        parts = [f"{c.target.kpi} {c.interval.mean:.4g} (95 % CI {c.interval.low:.4g} to "
                 f"{c.interval.high:.4g}; target {c.target.describe().split(' ', 1)[1]})"
                 for c in ev.checks]
        level = "" if ev.meets_at == CONFIDENCE else \
            f" (each interval clear of its bound at {100 * ev.meets_at:.4g} %: the 5 % spent " \
            "over the looks of sequential stopping)"
        text = (f"{head}{self.recommended} {self.unit}{self._beside()} meet every target with "
                f"95 % confidence over {ev.replications} replications{level}: "
                + "; ".join(parts) + ".")
        below = self.evaluations.get(self.recommended - 1)
        if below is not None:
            text += f" {below.agvs} {self.unit}: {below.verdict}{_why_not(below)}."
            for diff in self.paired():
                text += (f" {diff['kpi']} from {diff['from_agvs']} to {diff['to_agvs']} "
                         f"{self.unit}: "
                         f"{diff['mean_diff']:+.4g} (paired 95 % CI +/- "
                         f"{diff['half_width']:.3g} over {diff['pairs']} common replications;"
                         f" unpaired +/- {diff['unpaired_half_width']:.3g}).")
        elif self.recommended == self.min_agvs:
            text += f" ({self.min_agvs} is the smallest fleet searched.)"
        return text

    def paired(self) -> list[dict[str, Any]]:
        """Per target KPI: the recommended size minus the one below, replication by
        replication (common random numbers), and the unpaired interval of the same runs."""
        if self.recommended is None:
            return []
        top = self.evaluations.get(self.recommended)
        below = self.evaluations.get(self.recommended - 1)
        if top is None or below is None:
            return []
        out = []
        for kpi, upper in top.values.items():
            lower = below.values.get(kpi, {})
            common = sorted(set(upper) & set(lower))
            if len(common) < 2:
                continue
            diff = mean_ci([upper[r] - lower[r] for r in common])
            a, b = mean_ci([upper[r] for r in common]), mean_ci([lower[r] for r in common])
            unpaired = diff.half_width if math.isnan(a.sd) or math.isnan(b.sd) else \
                float(np.hypot(a.half_width, b.half_width))
            out.append({"kpi": kpi, "from_agvs": below.agvs, "to_agvs": top.agvs,
                        "pairs": diff.n, "mean_diff": diff.mean, "half_width": diff.half_width,
                        "unpaired_half_width": unpaired})
        return out

    def runs(self) -> int:
        """Replications run over all the fleet sizes evaluated."""
        return sum(e.replications for e in self.evaluations.values())

    def as_dict(self) -> dict[str, Any]:
        return {"fixed": self.fixed, "estimate": self.estimate.as_dict(),
                **({"vary_type": self.vary_type, "beside": self.beside}
                   if self.vary_type is not None else {}),
                "recommended": self.recommended, "min_agvs": self.min_agvs,
                "max_agvs": self.max_agvs, "stopped": self.stopped,
                "statement": self.statement(),
                "runs": self.runs(), "paired": self.paired(),
                "evaluations": [self.evaluations[n].as_dict() for n in sorted(self.evaluations)]}


def _why_not(ev: Evaluation) -> str:
    bad = [c for c in ev.checks if c.decision != "meets"]
    if not bad:
        return ""
    return " (" + "; ".join(
        f"{c.target.kpi} {c.interval.mean:.4g}, 95 % CI {c.interval.low:.4g} to "
        f"{c.interval.high:.4g}, {c.decision} {c.target.describe().split(' ', 1)[1]}"
        for c in bad) + ")"


def _futile(check: TargetCheck, cap: int, confidence: float) -> bool:
    """No use replicating further for this target: its mean lies on the wrong side of the
    bound, or so close to it that, with the spread seen so far, an interval at `confidence`
    would need more than FUTILE_MARGIN x `cap` replications to clear it."""
    if check.decision != "undecided":
        return False
    ci = check.interval
    if math.isnan(ci.mean) or not check.target.met_by(ci.mean):
        return True
    needed = replications_needed(ci.sd, ci.mean - check.target.bound, ci.n, confidence)
    return needed is None or needed > FUTILE_MARGIN * cap


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
        self.factor = experiment.fleet_factor
        """What the search varies: fleet.size, or a mixed fleet's count of one type."""
        vary = experiment.spec.sizing.vary_type
        self.unit = "AGVs" if vary is None else f"{vary} AGVs"

    def looks(self) -> list[int]:
        """The replication counts at which a fleet size is looked at."""
        spec = self.experiment.spec
        if spec.sizing.stopping == "fixed":
            return [spec.replications]
        n, cap = spec.sizing.min_replications, spec.sizing.max_replications
        out = [n]
        while n < cap:
            n = min(cap, max(n + self.pool.workers, 2 * n))
            out.append(n)
        return out

    def evaluate(self, agvs: int, result: GroupResult) -> Generator[list[RunSpec], None,
                                                                     Evaluation]:
        """Evaluate a fleet size: yields each batch of runs it needs (the caller makes them,
        with other groups' batches), and returns the evaluation."""
        factors = {**self.fixed, self.factor: agvs}
        looks = self.looks()
        alpha = 1.0 - CONFIDENCE
        early = min(EARLY_ALPHA, alpha / (2 * len(looks)))
        for i, reps in enumerate(looks):
            meets_at = 1.0 - (early if i < len(looks) - 1 else alpha - early * (len(looks) - 1))
            runs = [self.experiment.run(factors, r) for r in range(reps)]
            self.budget.take(runs)
            yield runs
            values, failed = run_values(self.out_dir, runs, [t.kpi for t in self.targets])
            arrays = {t.kpi: np.array(list(values[t.kpi].values()), dtype=float)
                      for t in self.targets}
            checks = [target_check(factors, t, arrays[t.kpi]) for t in self.targets]
            strict = [target_check(factors, t, arrays[t.kpi], meets_at) for t in self.targets] \
                if abs(meets_at - CONFIDENCE) > 1e-12 else checks
            ev = Evaluation(agvs, reps, checks, failed, values, strict=strict, meets_at=meets_at)
            if ev.verdict != "undecided":
                break
            last = alpha - early * (len(looks) - 1)
            if i < len(looks) - 1 and reps >= FUTILE_FROM \
                    and any(_futile(c, looks[-1], 1.0 - last) for c in checks):
                ev.futile = True
                break
        result.evaluations[agvs] = ev
        note = ""
        if ev.futile:
            note = " (hopeless: a mean on or near the wrong side of its bound; not meeting)"
        elif ev.verdict == "undecided":
            note = " (undecided at the replication limit: counted as not meeting)"
        self.progress.note(f"{_where(self.fixed)}{agvs} {self.unit}, {ev.replications} "
                           f"replications: {ev.verdict}{note}")
        return ev

    def search(self, estimate: Estimate, lo_limit: int, hi_limit: int,
               beside: dict[str, int] | None = None
               ) -> Generator[list[RunSpec], None, GroupResult]:
        """The search; yields the batches of runs it needs (see `run_searches`); stopped
        (result.stopped) where the run budget runs out. `beside`: a mixed fleet's other
        types and their fixed counts (the search starts from the estimate less them)."""
        result = GroupResult(self.fixed, estimate, min_agvs=lo_limit, max_agvs=hi_limit,
                             vary_type=self.experiment.spec.sizing.vary_type,
                             beside=dict(beside or {}))
        try:
            yield from self._search(result, start_count(estimate, result.beside, lo_limit,
                                                        hi_limit), lo_limit, hi_limit)
        except SizingLimit as exc:
            result.stopped = str(exc)
        return result

    def _search(self, result: GroupResult, start: int, lo_limit: int,
                hi_limit: int) -> Generator[list[RunSpec], None, None]:
        def meets(n: int) -> Generator[list[RunSpec], None, bool]:
            ev = result.evaluations.get(n)
            if ev is None:
                ev = yield from self.evaluate(n, result)
            return ev.verdict == "meets"

        result.recommended = yield from ordered_search(meets, start, lo_limit, hi_limit)


def start_count(estimate: Estimate, beside: dict[str, int], lo_limit: int,
                hi_limit: int) -> int:
    """Where the search starts: the estimate's least whole fleet, less the other types' fixed
    counts of a mixed fleet, within the limits."""
    return min(max(estimate.minimum - sum(beside.values()), lo_limit), hi_limit)


def groups(experiment: Experiment) -> list[dict[str, Any]]:
    """The combinations of the other factors' values, one sizing search each."""
    others = [f for f in experiment.factor_names if f != experiment.fleet_factor]
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
               stream: IO[str] | None = None, max_runs: int = MAX_RUNS,
               dask_timeout_s: float = DEFAULT_NO_WORKERS_TIMEOUT_S) -> list[GroupResult]:
    """Search every group; write sizing.json and refresh the summary tables (holding the
    results folder: see fleet_sim.study.study_folder.folder_lock). Raises SizingLimit, after
    writing them, if the search would need more than `max_runs` runs."""
    spec = experiment.spec
    if not spec.targets:
        raise InputError(str(experiment.file), "targets", [],
                         "at least one target for `fleet-sim size` to meet")
    _check_fleet_varies(experiment)
    check_extras(experiment, scheduler)
    levels = [v for v in (spec.factors.get(experiment.fleet_factor) or [])
              if isinstance(v, int)]
    lo_limit = spec.sizing.min_agvs or (min(levels) if levels else 1)
    hi_limit = spec.sizing.max_agvs or (max(levels) if levels else DEFAULT_MAX_AGVS)
    if hi_limit < lo_limit:
        raise InputError(str(experiment.file), "sizing.max_agvs", hi_limit,
                         f"at least the smallest fleet searched ({lo_limit})")
    with folder_lock(out_dir, stream), \
            tables_written(experiment, out_dir, stream=stream, quiet=quiet) as plan:
        results: list[GroupResult] = []
        pool = make_pool(scheduler, workers, dask_timeout_s=dask_timeout_s)
        budget = RunBudget(max_runs)
        stopped: str | None = None
        with pool, Progress(stream=stream, quiet=quiet) as progress:
            experiment = settle_warmup(experiment, out_dir, groups(experiment),
                                       largest_fleet(experiment) or hi_limit, pool, progress)
            prepare(experiment, out_dir)
            write_plan(out_dir, "size", None)
            results = run_searches(
                [_size_group(experiment, out_dir, fixed, lo_limit, hi_limit, pool, progress,
                             budget) for fixed in groups(experiment)], out_dir, pool)
            stopped = next((r.stopped for r in results if r.stopped is not None), None)
        plan.add(sorted(budget.used))
        document = {"experiment": experiment.name, "confidence": 0.95,
                    "stopping": spec.sizing.stopping,
                    "warmup_h": experiment.scenario().warmup_h,
                    "runs": sum(r.runs() for r in results),
                    "targets": [t.describe() for t in spec.targets],
                    "runs_used": len(budget.used), "max_runs": max_runs,
                    "stopped": stopped, "groups": [r.as_dict() for r in results]}
        (out_dir / "sizing.json").write_text(json.dumps(document, indent=2, default=str) + "\n",
                                             encoding="utf-8")
        if stopped is not None:
            raise SizingLimit(stopped)
    return results


def _check_fleet_varies(experiment: Experiment) -> None:
    """A mixed fleet is sized one type at a time: `sizing.vary_type` must name it."""
    fleet = experiment.scenario().fleet
    if fleet.vehicles and experiment.spec.sizing.vary_type is None:
        types = [t.type for t in fleet.vehicles]
        raise InputError(str(experiment.file), "sizing.vary_type", None,
                         "the vehicle type whose count the search varies, the other types "
                         f"keeping theirs (the base scenario's fleet mixes {', '.join(types)}; "
                         f"for example sizing: {{vary_type: {types[-1]}}})")


def _size_group(experiment: Experiment, out_dir: Path, fixed: dict[str, Any], lo_limit: int,
                hi_limit: int, pool: LocalPool | DaskPool, progress: Progress,
                budget: RunBudget) -> Generator[list[RunSpec], None, GroupResult]:
    spec = experiment.spec
    scenario = experiment.scenario(fixed)
    layout = layout_for(scenario, str(experiment.scenario_file))
    trace = load_trace_for(scenario, layout)
    vary = spec.sizing.vary_type
    beside = {t.type: t.count for t in scenario.fleet.vehicles if t.type != vary}
    vehicle = scenario.fleet.type_profiles[vary] if vary is not None else None
    estimate = analytic_estimate(scenario, layout, spec.sizing.agv_availability, trace,
                                 vehicle)
    unit = "AGVs" if vary is None else f"{vary} AGVs"
    others = "" if not beside else " beside " + ", ".join(f"{n} {t}" for t, n in beside.items())
    progress.note(f"{_where(fixed)}analytic estimate {estimate.agvs:.2f} AGVs busy at the mean "
                  f"demand ({estimate.demand_per_hour:.1f} orders/h x {estimate.cycle_s:.1f} s "
                  f"per order); searching {lo_limit} to {hi_limit} {unit}{others} from "
                  f"{start_count(estimate, beside, lo_limit, hi_limit)}")
    return Sizer(experiment, out_dir, fixed, pool, progress, budget).search(
        estimate, lo_limit, hi_limit, beside)


def _where(fixed: dict[str, Any]) -> str:
    """The fixed factor values as a message prefix ("demand.rate_per_hour=90: "), or ""."""
    return point_text(fixed) + ": " if fixed else ""
