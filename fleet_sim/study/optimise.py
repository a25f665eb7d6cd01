"""`fleet-sim optimise`: the cheapest design (fleet, chargers, policies, layout changes) that
meets every target, with a stated probability of being right.

The file's ``optimise:`` section (fleet_sim.config.decisions) gives the decisions and their
prices; the procedure is fleet_sim.study.cheapest's (F_B checks in order of price). This module
turns the procedure's requests into runs, reads what they measured, and writes optimise.json:

* ``answer``: the design named (its decisions, price, each target's mean and 95 % interval,
  replications) or null, with ``statement``, the answer in a planner's words;
* ``designs``: every design of the space with its price and verdict: meets, fails (with
  ``inferred`` when the assumption decided it), not needed (a cheaper design meets), undecided,
  ruled out (the analytic estimate: fewer AGVs than it keeps busy), refused (does not fit its
  layout), or not examined;
* ``target_costs``: what each target costs: the cheapest design if that target were relaxed
  to each looser bound the file lists (else by its tolerance), from the runs already made;
* ``runs_used`` against ``full_grid_runs``, every design at the replications the answer ended
  with.

What is known before any run is used first: designs whose scenario does not fit the layout
are refused, fleets below the AGVs the analytic estimate keeps busy at the mean demand
(fleet_sim.sim.estimate; travel and handling only, no waiting: a lower bound) are ruled out;
neither counts in the Bonferroni split of the error (they are decided without error).

Runs are the experiment's (fleet_sim.config.decisions.design_run: replication r has the same
seed in every design), through fleet_sim.study.runner: resumable, on the process pool or a
Dask scheduler, shared with `sweep` and `size` where they are the same runs. The warm-up is
the scenario's, or estimated by MSER-5 from pilot runs at the largest fleet first.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from fleet_sim.analysis.feasibility import LEVELS, Constraint, check, error_per_check, fb_h2
from fleet_sim.analysis.stats import mean_ci
from fleet_sim.config.decisions import (
    LAYOUT_PREFIX,
    Design,
    DesignSpace,
    design_layout,
    design_run,
    design_space,
)
from fleet_sim.config.experiment import MAX_RUNS, Experiment, RunSpec, Target, load_trace_for
from fleet_sim.sim.estimate import analytic_estimate
from fleet_sim.study.cheapest import (
    FAILS,
    MEETS,
    OPEN,
    RULED_OUT,
    UNDECIDED,
    CheapestSearch,
    Structure,
)
from fleet_sim.study.optimise_words import answer_statements, guarantee_sentence, money
from fleet_sim.study.pools import DEFAULT_NO_WORKERS_TIMEOUT_S, make_pool
from fleet_sim.study.progress import Progress
from fleet_sim.study.results import tables_written
from fleet_sim.study.runner import check_extras, execute, prepare
from fleet_sim.study.search import RunBudget, RunLimit, drive, run_kpis
from fleet_sim.study.study_folder import folder_lock, write_plan
from fleet_sim.study.warmup import settle_warmup
from userfiles.writing import write_json_atomic

OPTIMISE_FILE = "optimise.json"
ENERGY = "energy_used_kwh"
"""Reported per design (the fleet's energy in the measured window), never part of the price:
the procedures need a price known without simulation."""
REFUSED = "refused"
NOT_EXAMINED = "not examined"


class OptimiseLimit(RunLimit):
    """The search would need more runs than one experiment may have."""


@dataclass
class OptimiseOutcome:
    """What `optimise` found: the document written to optimise.json, and the run counts."""

    out_dir: Path
    document: dict[str, Any]
    runs_made: int = 0
    runs_failed: list[str] = field(default_factory=list)

    @property
    def statement(self) -> str:
        return str(self.document["statement"])


def constraints_of(targets: Sequence[Target], tolerance: dict[str, float]
                   ) -> list[Constraint]:
    """The targets as the check sees them."""
    return [Constraint(t.bound, t.higher_is_better, tolerance[t.kpi]) for t in targets]


def optimise(experiment: Experiment, out_dir: Path, workers: int = 0,
             scheduler: str | None = None, quiet: bool = False,
             stream: IO[str] | None = None, max_runs: int = MAX_RUNS,
             dask_timeout_s: float = DEFAULT_NO_WORKERS_TIMEOUT_S,
             space: DesignSpace | None = None) -> OptimiseOutcome:
    """Search the experiment's design space (`space`, where the caller has it already);
    write optimise.json and the summary tables (holding the results folder). Raises
    OptimiseLimit, after writing them, if the search would need more than `max_runs` runs."""
    space = space if space is not None else design_space(experiment)
    config = space.config
    check_extras(experiment, scheduler)
    targets = list(experiment.spec.targets)
    kpis = [t.kpi for t in targets]
    columns = [*experiment.factor_names, *(k for k in space.config.decisions),
               *(f"{LAYOUT_PREFIX}{g}" for g in space.config.layout_decisions)]
    with folder_lock(out_dir, stream), \
            tables_written(experiment, out_dir, columns, stream, quiet) as plan:
        pool = make_pool(scheduler, workers, dask_timeout_s=dask_timeout_s)
        budget = RunBudget(max_runs, "design search", OPTIMISE_FILE,
                           "Fewer decisions or levels, or a lower optimise.max_replications",
                           OptimiseLimit)
        made: list[RunSpec] = []
        energy: dict[int, dict[int, float]] = {}
        """Per design: replication -> energy_used_kwh (reported, not optimised)."""
        with pool, Progress(stream=stream, quiet=quiet) as progress:
            largest = max((space.count(d) or 0 for d in space.designs), default=0) or None
            experiment = settle_warmup(experiment, out_dir, [{}], largest, pool, progress)
            prepare(experiment, out_dir)
            write_plan(out_dir, "optimise", None)
            refused = {e.design.index: e.reason for e in space.refused}
            ruled_out = {**_ruled_out(experiment, space, refused, progress), **refused}
            candidates = len(space.designs) - len(ruled_out)
            beta = error_per_check(config.confidence, candidates, len(targets))
            h2 = fb_h2(config.min_replications, beta)
            structure = None
            if config.more_agvs_never_worse:
                structure = Structure([space.rest(d) for d in space.designs],
                                      [space.count(d) or 0 for d in space.designs])
            search = CheapestSearch([d.price for d in space.designs],
                                    constraints_of(targets, config.tolerance),
                                    config.min_replications, config.max_replications, h2,
                                    pool.workers, structure, ruled_out)
            progress.note(f"{len(space.designs)} designs: {len(refused)} refused (do not fit "
                          f"their layout), {len(ruled_out) - len(refused)} ruled out by the "
                          f"analytic estimate, {candidates} to examine by price "
                          f"(h^2 {h2:.3g}, beta {beta:.2g} per check)")

            def run_batch(request: list[tuple[int, int]]) -> None:
                runs = [design_run(experiment, space.designs[i], r) for i, r in request]
                budget.take(runs)
                execute(runs, out_dir, quiet=True, pool=pool)
                made.extend(runs)
                for (i, r), spec in zip(request, runs, strict=True):
                    measured = run_kpis(out_dir, spec, [*kpis, ENERGY])
                    if measured is None:  # a run that failed: no value, its targets fail
                        measured = [math.nan] * (len(kpis) + 1)
                    search.record(i, r, measured[:-1])
                    energy.setdefault(i, {})[r] = measured[-1]
                _progress(progress, space, search, len(budget.used), config.currency)

            stopped: str | None = None
            checks: list[dict[str, object]] = []
            try:
                drive(search.run(), run_batch)
                checks = drive(search.check_neighbours(), run_batch)
            except OptimiseLimit as exc:
                stopped = str(exc)
            document = _document(experiment, space, search, h2, beta, len(budget.used),
                                 checks, stopped, energy)
        plan.add(sorted(budget.used))
        write_json_atomic(out_dir / OPTIMISE_FILE, document)
        if stopped is not None:
            raise OptimiseLimit(stopped)
    failed = [s.run_id for s in made if not (out_dir / "runs" / s.run_id / "kpis.json").exists()]
    return OptimiseOutcome(out_dir, document, len({s.run_id for s in made}), sorted(set(failed)))


def _progress(progress: Progress, space: DesignSpace, search: CheapestSearch, runs: int,
              currency: str) -> None:
    decided = sum(st.status != OPEN for st in search.states)
    best = search.incumbent()
    cheapest = "none yet" if best is None else \
        f"{space.designs[best].label()} at {money(space.designs[best].price, currency)}"
    progress.note(f"{decided} of {len(search.states)} designs decided, {runs} runs; cheapest "
                  f"meeting every target so far: {cheapest}")


def _ruled_out(experiment: Experiment, space: DesignSpace, refused: dict[int, str],
               progress: Progress) -> dict[int, str]:
    """Designs with fewer AGVs than the analytic estimate keeps busy at the mean demand (a
    one-type fleet whose size is a decision), per combination of the other decisions."""
    if space.count_decision != "fleet.size":
        return {}
    busy: dict[Any, float] = {}
    out: dict[int, str] = {}
    factors = dict(experiment.points[0]) if experiment.points else {}
    for design in space.designs:
        if design.index in refused:
            continue
        rest = space.rest(design)
        if rest not in busy:
            scenario = experiment.scenario({**factors, **dict(design.settings)})
            layout = design_layout(experiment, scenario, design)
            estimate = analytic_estimate(scenario, layout, space.config.estimate_availability,
                                         load_trace_for(scenario, layout))
            busy[rest] = estimate.agvs
        count = space.count(design) or 0
        if count < busy[rest] - 1e-9:
            out[design.index] = (f"{count} AGV{' is' if count == 1 else 's are'} fewer than "
                                 f"the {busy[rest]:.2f} the analytic estimate keeps busy at "
                                 "the mean demand")
    if busy:
        low, high = min(busy.values()), max(busy.values())
        progress.note(f"analytic estimate: {low:.2f} to {high:.2f} AGVs busy at the mean "
                      f"demand over {len(busy)} combinations of the other decisions")
    return out


# ---- optimise.json -----------------------------------------------------------------------------


def _status(search: CheapestSearch, i: int, refused: set[int]) -> str:
    st = search.states[i]
    if i in refused:
        return REFUSED
    if st.status == OPEN:
        return NOT_EXAMINED
    return st.status


def _target_rows(targets: Sequence[Target], values: np.ndarray) -> list[dict[str, Any]]:
    rows = []
    for k, t in enumerate(targets):
        ci = mean_ci(values[:, k]) if len(values) else None
        rows.append({"kpi": t.kpi, "target": t.describe(), "bound": t.bound,
                     "at_least": t.higher_is_better,
                     "mean": _num(ci.mean) if ci else None,
                     "ci_low": _num(ci.low) if ci else None,
                     "ci_high": _num(ci.high) if ci else None,
                     "n": ci.n if ci else 0,
                     "meets_bound": None if ci is None or math.isnan(ci.mean)
                     else t.met_by(ci.mean)})
    return rows


def _document(experiment: Experiment, space: DesignSpace, search: CheapestSearch, h2: float,
              beta: float, runs_used: int, checks: list[dict[str, object]],
              stopped: str | None, energy: dict[int, dict[int, float]]) -> dict[str, Any]:
    config = space.config
    targets = list(experiment.spec.targets)
    width = len(targets)
    designs: list[dict[str, Any]] = []
    refused = {e.design.index for e in space.refused}
    for design in space.designs:
        st = search.states[design.index]
        values = st.values(width)
        verdict = st.verdict
        designs.append({
            "index": design.index, "label": design.label(), "choices": design.choice_dict(),
            "price": design.price, "verdict": _status(search, design.index, refused),
            "reason": st.reason, "inferred": st.inferred_from is not None,
            "replications": len(values),
            "decided_at": verdict.at if verdict is not None and verdict.decision != UNDECIDED
            else None,
            "check": search.checks.get(design.index),
            "energy_used_kwh": _energy_mean(energy.get(design.index, {}), len(values)),
            "targets": _target_rows(targets, values)})
    answer = search.answer()
    base = experiment.scenario(dict(experiment.points[0]) if experiment.points else None)
    examined = [d for d in designs if d["replications"]]
    reps = designs[answer]["replications"] if answer is not None else config.min_replications
    candidates = [d for d in designs if d["verdict"] not in (REFUSED, RULED_OUT)]
    document: dict[str, Any] = {
        "experiment": experiment.name, "currency": config.currency,
        "horizon_years": config.horizon_years, "confidence": config.confidence,
        "targets": [t.describe() for t in targets],
        "tolerance": dict(config.tolerance),
        "procedure": {"name": "F_B feasibility checks in order of price (Batur and Kim 2010; "
                              "Andradóttir and Kim 2010), Bonferroni over designs (common "
                              "random numbers)",
                      "min_replications": config.min_replications,
                      "max_replications": config.max_replications, "h2": h2, "beta": beta,
                      "designs_counted": len(candidates), "tolerance_levels": LEVELS},
        "assumption": {"more_agvs_never_worse": config.more_agvs_never_worse,
                       "checked": [{**c, "design": designs[int(str(c["design"]))]["label"]}
                                   for c in checks],
                       "held": all(bool(c["agrees"]) for c in checks)},
        "warmup_h": base.warmup_h,
        "window_h": base.duration_h - base.warmup_h,
        "answer": None if answer is None else {
            "design": designs[answer]["label"], "choices": designs[answer]["choices"],
            "words": design_words(space, space.designs[answer]),
            "price": space.designs[answer].price, "replications": reps,
            "energy_used_kwh": designs[answer]["energy_used_kwh"],
            "targets": designs[answer]["targets"]},
        "undecided_cheaper": [d["label"] for d in designs
                              if d["verdict"] == UNDECIDED and
                              (answer is None or search.cheaper(d["index"], answer))],
        "runs_used": runs_used, "design_count": len(designs),
        "designs_examined": len(examined),
        "full_grid_runs": len(candidates) * reps,
        "stopped": stopped,
    }
    if answer is None:
        document["closest"] = closest(designs, targets, config.tolerance)
    document["target_costs"] = target_costs(experiment, space, search, h2)
    document["designs"] = designs
    words = [design_words(space, d) for d in space.designs]
    document["guarantee"] = guarantee_sentence(document)
    document["statement"] = " ".join([*answer_statements(document, words),
                                      document["guarantee"]])
    return document


def _energy_mean(values: dict[int, float], replications: int) -> float | None:
    """Mean energy_used_kwh over the design's first `replications` (None: no value)."""
    xs = [values[r] for r in range(replications) if r in values and not math.isnan(values[r])]
    return float(np.mean(xs)) if xs else None


def design_words(space: DesignSpace, design: Design) -> str:
    """"16 AGVs, opportunity charging, a fifth charger at C05, aisle 3 as it is"."""
    parts = []
    for key, value in design.choices:
        if key.startswith(LAYOUT_PREFIX):
            group = key.removeprefix(LAYOUT_PREFIX)
            option = space.config.layout_decisions[group][value]
            parts.append(option.description or f"{group}: {value}")
        else:
            parts.append(space.config.decisions[key].words(key, value))
    return ", ".join(parts)


def closest(designs: list[dict[str, Any]], targets: Sequence[Target],
            tolerance: dict[str, float]) -> dict[str, Any] | None:
    """The examined design whose worst miss (in tolerances) is smallest, and the target that
    binds there."""
    best: tuple[float, dict[str, Any], str] | None = None
    for d in designs:
        if not d["replications"]:
            continue
        worst, binding = -math.inf, ""
        for row, t in zip(d["targets"], targets, strict=True):
            mean = row["mean"]
            miss = math.inf if mean is None else \
                ((t.bound - mean) if t.higher_is_better else (mean - t.bound)) / tolerance[t.kpi]
            if miss > worst:
                worst, binding = miss, t.kpi
        if best is None or worst < best[0]:
            best = (worst, d, binding)
    if best is None:
        return None
    return {"design": best[1]["label"], "price": best[1]["price"], "binding_target": best[2],
            "misses_by_tolerances": best[0] if math.isfinite(best[0]) else None,
            "targets": best[1]["targets"]}


def target_costs(experiment: Experiment, space: DesignSpace, search: CheapestSearch,
                 h2: float) -> list[dict[str, Any]]:
    """Per target and looser bound: the cheapest design that meets with that target relaxed,
    decided from the replications already made (undecided where they do not suffice)."""
    config = space.config
    targets = list(experiment.spec.targets)
    answer = search.answer()
    out: list[dict[str, Any]] = []
    for k, t in enumerate(targets):
        step = config.tolerance[t.kpi]
        bounds = list(config.relax.get(t.kpi, ())) or \
            [t.bound - step if t.higher_is_better else t.bound + step]
        for bound in bounds:
            found, decided, why = _relaxed_answer(search, space, k, bound, h2)
            row: dict[str, Any] = {"kpi": t.kpi, "target": t.describe(), "relaxed_to": bound,
                                   "decided": decided, "reason": why, "design": None,
                                   "price": None, "saving": None}
            if found is not None:
                row |= {"design": space.designs[found].label(),
                        "price": space.designs[found].price,
                        "saving": None if answer is None
                        else space.designs[answer].price - space.designs[found].price}
            out.append(row)
    return out


def _relaxed_answer(search: CheapestSearch, space: DesignSpace, target: int, bound: float,
                    h2: float) -> tuple[int | None, bool, str]:
    """The cheapest design shown to meet with target `target` at `bound`, walking designs by
    price on the values they have: (design, decided, why not decided)."""
    cons = [Constraint(bound if i == target else c.bound, c.at_least, c.tolerance)
            for i, c in enumerate(search.constraints)]
    width = len(cons)
    fails: dict[int, bool] = {}
    for i in search.order:
        st = search.states[i]
        if st.status == RULED_OUT:
            continue
        values = st.values(width)
        verdict = check(values, cons, search.n0, h2) if len(values) >= search.n0 else None
        if verdict is not None and verdict.decision == MEETS:
            return i, True, ""
        if verdict is not None and verdict.decision == FAILS:
            fails[i] = True
            continue
        if search.structure is not None and _inferred(search, i, fails, cons, h2):
            continue
        label = space.designs[i].label()
        return None, False, (f"{label} has {len(values)} replications, too few to decide it "
                             "against the relaxed target")
    return None, True, "no design meets the relaxed targets"


def _inferred(search: CheapestSearch, i: int, fails: dict[int, bool],
              cons: list[Constraint], h2: float) -> bool:
    """Under the assumption: a design with more AGVs and the same other choices fails the
    relaxed targets on its own replications."""
    assert search.structure is not None
    rest, n = search.structure.rest[i], search.structure.count[i]
    for j, st in enumerate(search.states):
        if search.structure.rest[j] != rest or search.structure.count[j] <= n:
            continue
        values = st.values(len(cons))
        if len(values) >= search.n0 and check(values, cons, search.n0, h2).decision == FAILS:
            return True
    return False


def _num(value: float) -> float | None:
    return None if math.isnan(value) else float(value)
