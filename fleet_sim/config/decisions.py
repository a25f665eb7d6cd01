"""Decisions and costs (an experiment file's ``optimise:``): what a planner may choose, what
each choice costs, and the design space `fleet-sim optimise` searches.

Example (docs/how-to/optimise.md)::

    optimise:
      currency: EUR
      horizon_years: 5                      # yearly costs count this many years
      decisions:                            # scenario keys
        fleet.size: {min: 12, max: 20, price_per_unit: 38000, yearly_per_unit: 2500}
        charging.opportunity:
          levels: [{level: false}, {level: true, price: 6000}]
      layout_decisions:                     # groups of layout changes: one option each
        chargers:
          as_they_are: {}
          fifth_at_C05: {price: 14000, changes: [{add_node: ...}, ...]}
      tolerance: {throughput_pct_of_demand: 0.5, lead_time_p95_s: 20}
      confidence: 0.95
      more_agvs_never_worse: false          # the search may skip designs by it

The choices where the issues were silent: docs/background/decisions/config.md.

fleet_sim.config.experiment reads the ``optimise:`` section with the models here and checks it
with `design_space` when the file is loaded; what both need (run ids, seeds, the layout cache)
is fleet_sim.config.runs, and the experiment is known here by type only.
"""

from __future__ import annotations

import dataclasses
import difflib
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any, Final

from pydantic import Field, Strict, field_validator, model_validator

from fleet_sim.config.layout_changes import Change, ChangeSite, LayoutChange, parse_changes
from fleet_sim.config.runs import (
    MAX_RUNS,
    changed_layout_for,
    check_path,
    layout_for,
    level_text,
    run_id,
)
from fleet_sim.config.scenario_fleet import MAX_FLEET_SIZE, VEHICLE_TYPES
from fleet_sim.errors import InputError
from userfiles.checking import Items, NonNegative, Positive, Problem, StrictModel, Text

if TYPE_CHECKING:
    from fleet_sim.config.experiment import Experiment, RunSpec
    from fleet_sim.config.layout import Layout
    from fleet_sim.config.scenario import Scenario

MAX_DESIGNS: Final = 5_000
"""Most designs of one design space: beyond it a search is a grid of days."""
MAX_LEVELS: Final = 200
LAYOUT_PREFIX: Final = "layout:"
"""A layout group's name as a decision (in run ids, the summary and optimise.json)."""


class Level(StrictModel):
    """One level of a decision over a scenario key, and what choosing it costs."""

    level: Any
    description: Text = ""
    """The level in a planner's words ("opportunity charging"), for the answer."""
    price: NonNegative = 0.0
    """One-off price of choosing this level."""
    yearly: NonNegative = 0.0
    """Running cost per year of this level (counted over horizon_years)."""


class ScenarioDecision(StrictModel):
    """A scenario key to choose: a whole-number range with a price per unit, or levels."""

    min: int | None = None
    max: int | None = None
    step: int = Field(default=1, ge=1)
    price_per_unit: NonNegative = 0.0
    """One-off price per unit of the level (per AGV)."""
    yearly_per_unit: NonNegative = 0.0
    """Running cost per unit and year (counted over horizon_years)."""
    levels: Annotated[tuple[Level, ...], Strict(False), Field(max_length=MAX_LEVELS)] = ()

    @model_validator(mode="after")
    def _range_or_levels(self) -> ScenarioDecision:
        ranged = self.min is not None or self.max is not None
        if ranged == bool(self.levels):
            raise Problem("", "both" if ranged else "neither",
                          "either a range (min, max, step, price_per_unit) or levels")
        if ranged:
            if self.min is None or self.max is None:
                raise Problem("max" if self.max is None else "min", None,
                              "both min and max of a range")
            if self.max < self.min:
                raise Problem("max", self.max, f"an integer >= min ({self.min})")
            if (self.max - self.min) // self.step + 1 > MAX_LEVELS:
                raise Problem("max", self.max, f"a range of at most {MAX_LEVELS} levels")
        else:
            if self.price_per_unit or self.yearly_per_unit:
                raise Problem("price_per_unit", self.price_per_unit,
                              "no price per unit with levels (each level has its price)")
            seen = [repr(lv.level) for lv in self.levels]
            if len(set(seen)) != len(seen):
                raise Problem("levels", [lv.level for lv in self.levels], "distinct levels")
        return self

    def values(self) -> list[Any]:
        if self.levels:
            return [lv.level for lv in self.levels]
        assert self.min is not None and self.max is not None
        return list(range(self.min, self.max + 1, self.step))

    def words(self, key: str, value: Any) -> str:
        """The level in the answer's words: its description, else ``key = value``."""
        for lv in self.levels:
            if repr(lv.level) == repr(value) and lv.description:
                return lv.description
        if count_path(key):
            kind = "" if key == "fleet.size" else key.split(".")[2] + " "
            return f"{value} {kind}AGV{'' if value == 1 else 's'}"
        return f"{key} = {level_text(value)}"

    def price(self, value: Any, horizon_years: float) -> float:
        if self.levels:
            level = next(lv for lv in self.levels if repr(lv.level) == repr(value))
            return level.price + level.yearly * horizon_years
        return float(value) * (self.price_per_unit + self.yearly_per_unit * horizon_years)


class LayoutOption(StrictModel):
    """One option of a group of layout changes, and what it costs."""

    description: Text = ""
    price: NonNegative = 0.0
    yearly: NonNegative = 0.0
    changes: Annotated[tuple[LayoutChange, ...], Strict(False), Field(max_length=200)] = ()
    """The layout changes of this option (the kinds of a variant's layout_changes); none: the
    layout as it is."""

    @field_validator("changes", mode="before")
    @classmethod
    def _each_change(cls, value: Any) -> Any:
        return parse_changes(value)


class OptimiseConfig(StrictModel):
    """What `fleet-sim optimise` may choose, what it costs, and the guarantee asked for."""

    decisions: dict[Text, ScenarioDecision] = Field(default_factory=dict)
    """Scenario key (dotted path) -> a range or levels."""
    layout_decisions: dict[Text, dict[Text, LayoutOption]] = Field(default_factory=dict)
    """Group -> option name -> its changes and price; a design picks one option per group."""
    currency: Text = "EUR"
    horizon_years: NonNegative = 0.0
    """Years the running costs (yearly, yearly_per_unit) are counted over; 0: none."""
    tolerance: dict[Text, Positive] = Field(default_factory=dict)
    """Target KPI -> the smallest miss that matters, in the KPI's unit: a design whose mean
    misses a bound by less may be called meeting, and one that beats it by less failing."""
    confidence: float = Field(default=0.95, gt=0.5, lt=1)
    """The probability that the design named meets every target (within its tolerance) and no
    cheaper design meets them all by more than the tolerance."""
    min_replications: int = Field(default=10, ge=2, le=1_000)
    """Replications of a design before its first look (n0 of the procedure)."""
    max_replications: int = Field(default=40, ge=2, le=1_000)
    """Replications a design may grow to; one still undecided there is reported as such."""
    more_agvs_never_worse: bool = False
    """Assume more AGVs (all else the same) never make a target worse: the search then skips
    fleets below one that fails and bisects the fleet (as `fleet-sim size` does); the designs
    next to the answer are run to check it."""
    relax: dict[Text, Items[float]] = Field(default_factory=dict)
    """Target KPI -> looser bounds, for "what a target costs" (default: by its tolerance)."""
    estimate_availability: float = Field(default=1.0, gt=0, le=1)
    """Share of each AGV-hour available for orders, for the analytic lower bound that rules
    out fleets below the AGVs kept busy."""

    @model_validator(mode="after")
    def _something_to_choose(self) -> OptimiseConfig:
        if not self.decisions and not self.layout_decisions:
            raise Problem("decisions", {}, "at least one decision (decisions or "
                                           "layout_decisions)")
        if self.max_replications < self.min_replications:
            raise Problem("max_replications", self.max_replications,
                          f"an integer >= min_replications ({self.min_replications})")
        for group, options in self.layout_decisions.items():
            if len(options) < 2:
                raise Problem(f"layout_decisions.{group}", list(options),
                              "at least two options (one may be the layout as it is: {})")
        return self


# ---- the design space ---------------------------------------------------------------------


@dataclass(frozen=True)
class DecisionSite(ChangeSite):
    """Names a layout option's change in a refusal: ``optimise.layout_decisions.<group>.
    <option>.changes[i]``, however the groups' changes were combined."""

    parts: tuple[tuple[str, str, int], ...] = ()
    """Per combined change: its group, option and index within the option."""

    def element(self, index: int, change: Change) -> str:
        group, option, own = self.parts[index]
        return f"optimise.layout_decisions.{group}.{option}.changes[{own}] ({change.KIND})"


@dataclass(frozen=True)
class Design:
    """One combination of decisions, its price and what its runs change."""

    index: int
    """Position in the enumeration (file order, last decision fastest)."""
    choices: tuple[tuple[str, Any], ...]
    """Decision -> level: scenario keys, then ``layout:<group>`` -> option name."""
    price: float
    settings: tuple[tuple[str, Any], ...]
    """The scenario decisions' values (set like factors in every run of the design)."""
    options: tuple[tuple[str, str], ...]
    """Layout group -> option chosen."""
    changes: tuple[Change, ...]
    site: DecisionSite

    def choice_dict(self) -> dict[str, Any]:
        return dict(self.choices)

    def label(self) -> str:
        """The design in a line: ``fleet.size=16, charging.opportunity=true, chargers=fifth``."""
        return ", ".join(f"{k.removeprefix(LAYOUT_PREFIX)}={level_text(v)}"
                         for k, v in self.choices)

    def layout_label(self) -> str:
        """The layout options that change something, as a run's variant (empty: none)."""
        return ",".join(f"{g}={o}" for (g, o) in self.options_changing())

    def options_changing(self) -> list[tuple[str, str]]:
        return [(g, o) for (g, o) in self.options if o in self.site_options(g)]

    def site_options(self, group: str) -> set[str]:
        return {o for (g, o, _) in self.site.parts if g == group}


@dataclass(frozen=True)
class Excluded:
    """A design left out before any run, and why."""

    design: Design
    reason: str


@dataclass(frozen=True)
class DesignSpace:
    """Every design of an experiment's ``optimise:``, in enumeration order."""

    config: OptimiseConfig
    designs: tuple[Design, ...]
    count_decision: str | None
    """The decision that counts AGVs of one design (fleet.size or a type's count), if one is a
    range; the axis of `more_agvs_never_worse`."""
    refused: tuple[Excluded, ...]
    """Designs whose scenario does not fit their layout (too many AGVs for parking)."""

    def rest(self, design: Design) -> tuple[tuple[str, Any], ...]:
        """The design's choices but the AGV count."""
        return tuple((k, v) for k, v in design.choices if k != self.count_decision)

    def count(self, design: Design) -> int | None:
        if self.count_decision is None:
            return None
        value = design.choice_dict()[self.count_decision]
        return int(value)

    def runs(self, experiment: Experiment, design: Design, replications: Sequence[int]
             ) -> list[RunSpec]:
        """The runs of `design` at `replications`."""
        return [design_run(experiment, design, r) for r in replications]


def count_path(key: str) -> bool:
    """Whether a decision counts AGVs: fleet.size or fleet.vehicles.<type>.count."""
    return key == "fleet.size" or (key.startswith(f"{VEHICLE_TYPES}.") and key.endswith(".count")
                                   and key.count(".") == 3)


def design_run(experiment: Experiment, design: Design, replication: int) -> RunSpec:
    """A design's run: the experiment's run at the design's scenario decisions (and its
    fixed factor levels), with its layout options' changes."""
    factors = {**dict(experiment.points[0] if experiment.points else ()),
               **dict(design.settings)}
    base = experiment.run(factors, replication)
    if not design.changes:
        return base
    named = {**factors, **{f"{LAYOUT_PREFIX}{g}": o for g, o in design.options_changing()}}
    return dataclasses.replace(
        base, run_id=run_id(named, replication),
        factors=tuple(named.items()), variant=design.layout_label(),
        layout_changes=design.changes, experiment_file=str(experiment.file))


def design_space(experiment: Experiment) -> DesignSpace:
    """The experiment's design space, every decision and combination checked; InputError
    naming ``optimise...`` for the first problem."""
    config = experiment.spec.optimise
    file = str(experiment.file)
    if config is None:
        raise InputError(file, "optimise", None, "an optimise section: the decisions a "
                         "planner may take and their costs (docs/how-to/optimise.md)")
    _check_against_experiment(experiment, config)
    groups = [(g, list(options.items())) for g, options in config.layout_decisions.items()]
    _check_layout_options(experiment, config, groups)
    keys = list(config.decisions)
    axes: list[list[tuple[str, Any]]] = [[(k, v) for v in config.decisions[k].values()]
                                         for k in keys]
    axes += [[(f"{LAYOUT_PREFIX}{g}", o) for o, _ in options] for g, options in groups]
    total = math.prod(len(a) for a in axes)
    if total > MAX_DESIGNS:
        raise InputError(file, "optimise", f"{total} designs",
                         f"a design space of at most {MAX_DESIGNS} designs (fewer levels, or "
                         "split the question)")
    if total * config.min_replications > MAX_RUNS:
        raise InputError(file, "optimise", f"{total} designs x {config.min_replications} "
                         "first replications", f"at most {MAX_RUNS} runs in one experiment "
                         "(fewer levels or min_replications)")
    counts = [k for k in keys if count_path(k) and config.decisions[k].levels == ()]
    count_decision = counts[0] if len(counts) == 1 else None
    if config.more_agvs_never_worse and count_decision is None:
        raise InputError(file, "optimise.more_agvs_never_worse", True,
                         "one decision that counts AGVs as a range (fleet.size or "
                         "fleet.vehicles.<type>.count: min, max) for the assumption to be "
                         f"about; this file has {len(counts)}")
    designs: list[Design] = []
    refused: list[Excluded] = []
    options_of = {g: dict(options) for g, options in groups}
    for index, combo in enumerate(itertools.product(*axes)):
        design = _design(index, combo, config, options_of, file)
        designs.append(design)
        problem = _fit_problem(experiment, design)
        if problem is not None:
            refused.append(Excluded(design, problem))
    return DesignSpace(config, tuple(designs), count_decision, tuple(refused))


def _design(index: int, combo: Sequence[tuple[str, Any]], config: OptimiseConfig,
            options_of: Mapping[str, Mapping[str, LayoutOption]], file: str) -> Design:
    price = 0.0
    settings: list[tuple[str, Any]] = []
    options: list[tuple[str, str]] = []
    changes: list[Change] = []
    parts: list[tuple[str, str, int]] = []
    for key, value in combo:
        if key.startswith(LAYOUT_PREFIX):
            group = key.removeprefix(LAYOUT_PREFIX)
            option = options_of[group][value]
            price += option.price + option.yearly * config.horizon_years
            options.append((group, value))
            changes += option.changes
            parts += [(group, value, i) for i in range(len(option.changes))]
        else:
            price += config.decisions[key].price(value, config.horizon_years)
            settings.append((key, value))
    return Design(index, tuple(combo), price, tuple(settings), tuple(options), tuple(changes),
                  DecisionSite(file, "optimise", tuple(parts)))


def _fit_problem(experiment: Experiment, design: Design) -> str | None:
    """Why the design's scenario does not fit its layout, or None."""
    factors = {**dict(experiment.points[0] if experiment.points else ()),
               **dict(design.settings)}
    try:
        scenario = experiment.scenario(factors)
        design_layout(experiment, scenario, design)
    except InputError as exc:
        return f"{exc.element}: {exc.expected} (got {exc.value})"
    return None


def design_layout(experiment: Experiment, scenario: Scenario, design: Design) -> Layout:
    """The layout a design's runs drive on (cached per process), checked against `scenario`."""
    if not design.changes:
        return layout_for(scenario, str(experiment.scenario_file))
    return changed_layout_for(scenario, str(experiment.scenario_file), design.changes,
                              design.site)


def _check_against_experiment(experiment: Experiment, config: OptimiseConfig) -> None:
    """Every scenario decision names a field the scenario has, each level valid alone, none a
    factor, an override, the seed or the layout; every target has a tolerance; the relaxed
    bounds are looser than the targets'."""
    spec = experiment.spec
    file = str(experiment.file)
    at = "optimise.decisions"
    many = [k for k, v in spec.factors.items() if not isinstance(v, list) or len(v) != 1]
    if many:
        raise InputError(file, f"factors.{many[0]}", spec.factors[many[0]],
                         "one level per factor with optimise (decisions say what varies; "
                         "run optimise once per demand level, say)")
    if spec.variants:
        raise InputError(file, "variants", list(spec.variants),
                         "no variants with optimise (layout_decisions choose between layouts)")
    for key, decision in config.decisions.items():
        check_path(file, f"{at}.{key}", key)
        if key == "layout":
            raise InputError(file, f"{at}.layout", key, "a scenario field other than layout "
                             "(layout_decisions choose between layout changes)")
        if key in spec.factors or key in spec.overrides:
            where = "factors" if key in spec.factors else "overrides"
            raise InputError(file, f"{at}.{key}", key, f"a field not also set in {where} (the "
                             "decision sets it)")
        if count_path(key) and decision.min is not None \
                and not 1 <= decision.min <= (decision.max or 0) <= MAX_FLEET_SIZE:
            raise InputError(file, f"{at}.{key}.min", decision.min,
                             f"an AGV count in [1, {MAX_FLEET_SIZE}]")
        for i, value in enumerate(decision.values()):
            try:
                experiment.scenario({**dict(experiment.points[0] if experiment.points
                                            else ()), key: value})
            except InputError as exc:
                element = f"{at}.{key}" + (f".levels[{i}].level" if decision.levels else "")
                hint = "" if "did you mean" in exc.expected else _did_you_mean(experiment, key)
                raise InputError(file, element, value, f"{exc.expected} (scenario field "
                                 f"{exc.element}{hint})") from None
    kpis = [t.kpi for t in spec.targets]
    if not kpis:
        raise InputError(file, "targets", [], "at least one target for `fleet-sim optimise` "
                         "to meet")
    for kpi in config.tolerance:
        if kpi not in kpis:
            close = difflib.get_close_matches(kpi, kpis, n=1)
            raise InputError(file, f"optimise.tolerance.{kpi}", config.tolerance[kpi],
                             "a tolerance for a target's KPI (" + ", ".join(kpis) + ")"
                             + (f"; did you mean {close[0]}?" if close else ""))
    for kpi in kpis:
        if kpi not in config.tolerance:
            raise InputError(file, "optimise.tolerance", dict(config.tolerance),
                             f"a tolerance for every target's KPI, {kpi} included (the "
                             "smallest miss that matters, in the KPI's unit)")
    for kpi, bounds in config.relax.items():
        targets = [t for t in spec.targets if t.kpi == kpi]
        if not targets:
            raise InputError(file, f"optimise.relax.{kpi}", list(bounds),
                             "looser bounds of a target's KPI (" + ", ".join(kpis) + ")")
        target = targets[0]
        for i, bound in enumerate(bounds):
            looser = bound < target.bound if target.higher_is_better else bound > target.bound
            if not looser or not math.isfinite(bound):
                raise InputError(file, f"optimise.relax.{kpi}[{i}]", bound,
                                 f"a bound looser than the target's ({target.describe()})")


def _did_you_mean(experiment: Experiment, key: str) -> str:
    """"; did you mean fleet.size?" for a misspelt decision key, from the base scenario's
    resolved keys."""
    plain = experiment.scenario().model_dump(mode="json", by_alias=True)
    known: list[str] = []

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        else:
            known.append(prefix)

    walk("", plain)
    close = difflib.get_close_matches(key, known, n=1)
    return f"; did you mean {close[0]}?" if close and close[0] != key else ""


def _check_layout_options(experiment: Experiment, config: OptimiseConfig,
                          groups: Sequence[tuple[str, list[tuple[str, LayoutOption]]]]) -> None:
    """Each option alone on the base scenario, then every pair of options of two groups
    together: a conflict names both."""
    file = str(experiment.file)
    scenario = experiment.scenario(dict(experiment.points[0]) if experiment.points else None)

    def site(picks: Sequence[tuple[str, str, LayoutOption]]) -> tuple[tuple[Change, ...],
                                                                       DecisionSite]:
        changes: list[Change] = []
        parts: list[tuple[str, str, int]] = []
        for group, name, option in picks:
            changes += option.changes
            parts += [(group, name, i) for i in range(len(option.changes))]
        return tuple(changes), DecisionSite(file, "optimise", tuple(parts))

    for group, options in groups:
        for name, option in options:
            if option.changes:
                changes, where = site([(group, name, option)])
                changed_layout_for(scenario, str(experiment.scenario_file), changes, where)
    for (g1, options1), (g2, options2) in itertools.combinations(groups, 2):
        for (n1, o1), (n2, o2) in itertools.product(options1, options2):
            if not o1.changes or not o2.changes:
                continue
            changes, where = site([(g1, n1, o1), (g2, n2, o2)])
            try:
                changed_layout_for(scenario, str(experiment.scenario_file), changes, where)
            except InputError as exc:
                raise InputError(file, f"optimise.layout_decisions.{g2}.{n2}", exc.value,
                                 f"changes that do not conflict with those of {g1}.{n1} "
                                 f"(together: {exc.element}: {exc.expected})") from None
