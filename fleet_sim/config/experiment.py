"""Experiment files -> a validated design: every run of a study, with its factors and seed.

An experiment file names a base scenario, the factors to vary (any scenario field by its dotted
path, such as ``fleet.size`` or ``demand.rate_per_hour``), a design, the number of replications,
a master seed and the targets a planner must meet. Example::

    name: warehouse_sizing
    scenario: warehouse_shift.yaml          # relative to this file
    overrides: {warmup_h: 0.25}             # set in every run
    factors:
      fleet.size: [6, 8, 10, 12]            # levels (full factorial or Latin hypercube)
      demand.rate_per_hour: {min: 80, max: 120}   # a range (Latin hypercube only)
    design: full_factorial                  # or latin_hypercube, with `samples`
    replications: 4
    master_seed: 2024
    targets:
      - {kpi: throughput_pct_of_demand, at_least: 98}
      - {kpi: lead_time_p95_s, at_most: 600}
    sizing: {min_agvs: 4, max_agvs: 20, stopping: sequential, min_replications: 2,
             max_replications: 12}
    warmup: {method: mser5, pilot_replications: 2}   # or fixed: the scenario's warmup_h

Decisions, where the issue is silent:

* Seeds. Replication r of every design point runs with the seed
  ``SeedSequence(master_seed, spawn_key=(r,))`` (the same child as
  ``SeedSequence(master_seed).spawn(n)[r]``), reduced to a 32-bit integer for the scenario's
  ``seed``. The same replication index gets the same seed at every factor level (common random
  numbers), so comparisons between levels are paired; replications added later (by the sizing
  search) get the seeds they would have had in a larger experiment. ``seed`` may not be a factor.
* Validation builds a real scenario for every design point (so a bad dotted path, a bad level or
  a combination the layout cannot hold, such as more AGVs than parking places, is an error naming
  the experiment file, the factor and the level). The names of the targets' KPIs are checked
  at the study layer, which knows the KPIs; this module runs no simulation.
* Run ids are readable and depend only on the factor values and the replication
  (``fleet.size=8__r03``), so a sweep and a sizing search over the same experiment share their
  runs, and adding levels later does not rename finished runs.
* A Latin hypercube draws `samples` points; a factor given as levels is sampled by stratified
  index over its levels, one given as ``{min, max}`` uniformly within its stratum (rounded for
  ``integer: true``). Its random stream is ``SeedSequence(master_seed, spawn_key=(2**32,))``, apart
  from every replication's.
* A mixed fleet (the base scenario's ``fleet.vehicles``) is varied one type at a time: the
  factor (or override) ``fleet.vehicles.<type>.count`` sets that type's count, the others keep
  theirs; ``fleet.size`` is their sum and cannot be set. `fleet-sim size` varies the type named
  by ``sizing.vary_type`` (required with a mixed fleet, refused with a one-type fleet), whose
  count min_agvs and max_agvs then bound; run ids read ``fleet.vehicles.heavy.count=3__r00``.
  Why one type: "how many heavy tuggers do my eight carriers need beside them" is the
  planner's question; a search over several counts at once has no single smallest answer.
* Variants (``variants:``, docs/how-to/whatif.md): name -> overrides over the experiment's, another
  layout file, layout changes (fleet_sim.config.layout_changes). The baseline is the base
  scenario (named BASE_VARIANT, ``baseline``) unless ``baseline:`` names a variant; the base
  scenario is among the variants compared only as the baseline. Every variant runs at every
  design point, replication r with the base scenario's seed of replication r (common random
  numbers). The base scenario's run ids and spec.json stay exactly what a sweep makes, so a
  comparison shares its runs with sweep and size; a named variant's run ids are prefixed
  ``v=<variant>__`` whatever its role (a run id says what runs, not how it is compared).
  A variant may not override a factor, ``seed`` or ``layout`` (its own `layout` key says
  it); every variant is validated at every design point when the file is loaded, so sweep
  and size refuse a broken variant too, though they run the base scenario only.
* ``layout`` may be a factor or an override, its values layout files relative to the
  experiment file (as a variant's `layout`); run ids and the summary show a level as
  written, the runs' overrides hold the absolute path.
* Battery and charging traps (fleet_sim.config.scenario.setup_warnings) are said once per
  experiment (`experiment_warnings`): each kind of trap once, with the first design point's
  line and how many design points have it, not once per run.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Final, Literal

import numpy as np
from pydantic import Field, Strict, field_validator, model_validator

from fleet_sim.config.decisions import OptimiseConfig, design_space
from fleet_sim.config.layout import Layout
from fleet_sim.config.layout_changes import (
    Change,
    ChangeSite,
    LayoutChange,
    LayoutDiff,
    layout_diff,
    parse_changes,
)
from fleet_sim.config.runs import MAX_REPLICATIONS as MAX_REPLICATIONS
from fleet_sim.config.runs import MAX_RUNS as MAX_RUNS
from fleet_sim.config.runs import VARIANT_PREFIX as VARIANT_PREFIX
from fleet_sim.config.runs import cached_layout as cached_layout
from fleet_sim.config.runs import changed_layout_for as changed_layout_for
from fleet_sim.config.runs import check_path as check_path
from fleet_sim.config.runs import layout_for as layout_for
from fleet_sim.config.runs import level_text as level_text
from fleet_sim.config.runs import point_text as point_text
from fleet_sim.config.runs import replication_seed as replication_seed
from fleet_sim.config.runs import run_id as run_id
from fleet_sim.config.runs import variant_run_id as variant_run_id
from fleet_sim.config.scenario import (
    FOLDER_NAME,
    MAX_FLEET_SIZE,
    Scenario,
    is_folder_name,
    load_scenario,
    setup_warnings,
    type_count_path,
)
from fleet_sim.config.trace import TraceOrder
from fleet_sim.errors import InputError
from userfiles.checking import Items, Positive, Problem, StrictModel, Text, validate
from userfiles.reading import read_yaml

FLEET = "fleet.size"
"""The factor the sizing search varies."""

LHS_STREAM = 2**32


class Range(StrictModel):
    """A continuous (or integer) factor range, for Latin hypercube designs."""

    min: float
    max: float
    integer: bool = False

    @model_validator(mode="after")
    def _ordered(self) -> Range:
        if not self.min < self.max:
            raise Problem("max", self.max, f"a number > min ({self.min})")
        return self


class Target(StrictModel):
    """A KPI bound that every recommended configuration must meet."""

    kpi: Text
    at_least: float | None = None
    at_most: float | None = None

    @model_validator(mode="after")
    def _one_bound(self) -> Target:
        if (self.at_least is None) == (self.at_most is None):
            raise Problem("", {"kpi": self.kpi}, "exactly one of at_least, at_most")
        return self

    @property
    def bound(self) -> float:
        value = self.at_least if self.at_least is not None else self.at_most
        assert value is not None
        return value

    @property
    def higher_is_better(self) -> bool:
        return self.at_least is not None

    def describe(self) -> str:
        return f"{self.kpi} {'>=' if self.higher_is_better else '<='} {self.bound:g}"

    def met_by(self, value: float) -> bool:
        return value >= self.bound if self.higher_is_better else value <= self.bound


class SizingConfig(StrictModel):
    """The fleet-size search of `fleet-sim size`."""

    stopping: Literal["sequential", "fixed"] = "sequential"
    """sequential: each fleet size starts with min_replications and adds replications (as many
    at a time as there are workers) only until every target is decided (its 95 % interval
    clear of the bound: met, or one target failed) or max_replications is reached. fixed:
    every fleet size runs the experiment's `replications`, no more and no fewer."""
    min_replications: int = Field(default=2, ge=2, le=MAX_REPLICATIONS)
    """Replications a fleet size starts with under sequential stopping (a confidence interval
    needs two)."""
    min_agvs: Annotated[int, Field(ge=1, le=MAX_FLEET_SIZE)] | None = None
    """Smallest fleet to consider; default: the lowest fleet.size level, else 1."""
    max_agvs: Annotated[int, Field(ge=1, le=MAX_FLEET_SIZE)] | None = None
    """Largest fleet to consider; default: the highest fleet.size level, else 50."""
    max_replications: int = Field(default=12, ge=2, le=MAX_REPLICATIONS)
    """Replications a close decision may grow to under sequential stopping (a size still
    undecided there counts as not meeting the targets)."""
    vary_type: Text | None = None
    """With a mixed fleet (the base scenario's fleet.vehicles): the vehicle type whose count
    the search varies (the factor fleet.vehicles.<type>.count); the other types keep their
    counts. min_agvs and max_agvs then bound that type's count. Needed with a mixed fleet;
    not given with a one-type fleet (the search varies fleet.size)."""
    agv_availability: float = Field(default=1.0, gt=0, le=1)
    """Share of each AGV-hour available for orders, for the analytic estimate (charging,
    breaks); 1.0 while the runs model no charging."""

    @model_validator(mode="after")
    def _ordered(self) -> SizingConfig:
        if (self.min_agvs is not None and self.max_agvs is not None
                and self.max_agvs < self.min_agvs):
            raise Problem("max_agvs", self.max_agvs, f"an integer >= min_agvs ({self.min_agvs})")
        if self.max_replications < self.min_replications:
            raise Problem("max_replications", self.max_replications,
                          f"an integer >= min_replications ({self.min_replications})")
        return self


class WarmupConfig(StrictModel):
    """How long the warm-up of every run of the experiment is."""

    method: Literal["fixed", "mser5"] = "fixed"
    """fixed: the scenario's warmup_h. mser5: estimated from the data before the runs start
    (fleet_sim.study.warmup): pilot runs without warm-up, MSER-5 on their lead times, the
    longest estimate rounded up to 0.05 h becomes every run's warmup_h."""
    pilot_replications: int = Field(default=2, ge=1, le=MAX_REPLICATIONS)
    """Pilot runs per combination of the other factors' levels (mser5)."""


class Objective(StrictModel):
    """What `fleet-sim compare` selects the best variant by (baseline included)."""

    kpi: Text
    direction: Literal["min", "max"]
    """min: the lowest mean is best (a lead time); max: the highest (a throughput)."""
    indifference_zone: Positive
    """The smallest difference of the KPI's mean worth telling apart, in the KPI's unit:
    variants closer to the best than this count as good as the best."""
    probability_correct_selection: float = Field(default=0.95, gt=0.5, lt=1)
    """The chance of selecting the best when it beats every other by the indifference zone
    (Kim and Nelson's KN procedure, docs/how-to/whatif.md)."""
    among: Items[Text] = ()
    """The variants to select from (at least two; `baseline` names the base scenario);
    default: every variant and the baseline. A variant that is a scenario rather than a
    choice (20 % more demand) is compared but not selected."""


class CompareConfig(StrictModel):
    """How `fleet-sim compare` compares the variants with the baseline (docs/how-to/whatif.md)."""

    kpis: Items[Text] = ()
    """KPIs compared; default: the targets' KPIs, else throughput_per_hour and
    lead_time_p95_s."""
    precision: dict[Text, Positive] = Field(default_factory=dict)
    """KPI -> half-width of the paired difference's interval that is precise enough, in the
    KPI's unit: a comparison whose interval is that narrow is decided (no difference larger
    than its interval detected). A KPI without one is decided only by an interval clear of
    zero (or the replication limit)."""
    min_replications: int = Field(default=5, ge=2, le=MAX_REPLICATIONS)
    """Replications of every variant before the first look."""
    max_replications: int = Field(default=20, ge=2, le=MAX_REPLICATIONS)
    """Replications a comparison may grow to (doubling from min_replications)."""
    confidence: float = Field(default=0.95, gt=0.5, lt=1)
    """Joint confidence of every interval reported, over all comparisons and looks."""
    objective: Objective | None = None

    @model_validator(mode="after")
    def _ordered(self) -> CompareConfig:
        if self.max_replications < self.min_replications:
            raise Problem("max_replications", self.max_replications,
                          f"an integer >= min_replications ({self.min_replications})")
        if len(set(self.kpis)) != len(self.kpis):
            raise Problem("kpis", list(self.kpis), "distinct KPIs")
        if self.kpis:
            for kpi in self.precision:
                if kpi not in self.kpis:
                    raise Problem(f"precision.{kpi}", self.precision[kpi],
                                  "a precision for a compared KPI (one of kpis: "
                                  f"{', '.join(self.kpis)})")
        return self


BASE_VARIANT: Final = "baseline"
"""The name of the base scenario as a variant: the baseline unless the file names another."""
MAX_VARIANTS: Final = 100
"""Most variants of one experiment (a comparison of more is a design, not a what-if)."""
MAX_LAYOUT_CHANGES: Final = 200
"""Most layout changes of one variant: more is another layout file."""


class VariantSpec(StrictModel):
    """One what-if variant: changes over the base scenario (with the experiment's overrides)."""

    description: Text = ""
    overrides: dict[str, Any] = Field(default_factory=dict)
    """Scenario fields (dotted paths) set in this variant's runs, over the experiment's
    overrides; not a factor, not `seed`, not `layout` (use the variant's `layout`)."""
    layout: Text | None = None
    """Another layout file for this variant, relative to the experiment file; not when
    `layout` is a factor."""
    layout_changes: Annotated[tuple[LayoutChange, ...], Strict(False),
                              Field(max_length=MAX_LAYOUT_CHANGES)] = ()
    """Edits of the variant's layout, applied in order: one_way, two_way, close_segment,
    close_node, speed_limit, add_node, add_segment, add_/move_/remove_ charger, station,
    parking, station_handling, parking_capacity (docs/how-to/whatif.md)."""

    @field_validator("layout_changes", mode="before")
    @classmethod
    def _each_change(cls, value: Any) -> Any:
        return parse_changes(value)


class ExperimentSpec(StrictModel):
    """The experiment file as written (before the design is expanded)."""

    scenario: Text
    """Base scenario file, relative to the experiment file."""
    name: Text = "experiment"
    """Names the results folder: letters, digits, '_', '.', '-'."""
    description: Text = ""
    overrides: dict[str, Any] = Field(default_factory=dict)
    """Scenario fields (dotted paths) set in every run."""
    factors: dict[str, Any] = Field(default_factory=dict)
    """Dotted scenario path -> list of levels, or {min, max, integer} (Latin hypercube)."""
    design: Literal["full_factorial", "latin_hypercube"] = "full_factorial"
    samples: int = Field(default=0, ge=0, le=MAX_RUNS)
    """Design points of a Latin hypercube."""
    replications: int = Field(default=3, ge=1, le=MAX_REPLICATIONS)
    master_seed: int = Field(default=1, ge=0)
    targets: Items[Target] = ()
    sizing: SizingConfig = SizingConfig()
    warmup: WarmupConfig = WarmupConfig()
    compare: CompareConfig = CompareConfig()
    variants: Annotated[dict[Text, VariantSpec], Field(max_length=MAX_VARIANTS)] = \
        Field(default_factory=dict)
    """What-if variants by name: each runs at every design point, with the baseline's seeds
    (common random numbers)."""
    baseline: Text | None = None
    """The variant the others are compared with; default: the base scenario (`baseline`)."""
    optimise: OptimiseConfig | None = None
    """What `fleet-sim optimise` may choose and what each choice costs
    (fleet_sim.config.decisions)."""

    @field_validator("name")
    @classmethod
    def _folder_name(cls, name: str) -> str:
        if not is_folder_name(name):
            raise Problem("", name, FOLDER_NAME)
        return name

    @model_validator(mode="after")
    def _warmup_not_set_twice(self) -> ExperimentSpec:
        if self.warmup.method == "mser5" and ("warmup_h" in self.overrides
                                              or "warmup_h" in self.factors
                                              or any("warmup_h" in v.overrides
                                                     for v in self.variants.values())):
            raise Problem("warmup.method", self.warmup.method,
                          "fixed when warmup_h is an override or a factor (mser5 sets it)")
        return self

    @field_validator("variants")
    @classmethod
    def _variant_names(cls, variants: dict[str, VariantSpec]) -> dict[str, VariantSpec]:
        for name in variants:
            if not is_folder_name(name) or len(name) > 40:
                raise Problem(name, name, "a variant name of at most 40 letters, digits, "
                                          "'_', '.', '-' (it names run folders)")
            if name == BASE_VARIANT:
                raise Problem(name, name, f"another name ({BASE_VARIANT} is the base "
                                          "scenario)")
        return variants

    @model_validator(mode="after")
    def _baseline_is_a_variant(self) -> ExperimentSpec:
        if self.baseline is not None and self.baseline != BASE_VARIANT \
                and self.baseline not in self.variants:
            names = ", ".join([BASE_VARIANT, *self.variants])
            raise Problem("baseline", self.baseline, f"the name of a variant ({names}; "
                          f"{BASE_VARIANT}: the base scenario)")
        return self

    @model_validator(mode="after")
    def _samples_fit_design(self) -> ExperimentSpec:
        if self.design == "latin_hypercube" and self.samples < 1:
            raise Problem("samples", self.samples,
                          "an integer >= 1 (design points of the Latin hypercube)")
        if self.design == "full_factorial" and self.samples:
            raise Problem("samples", self.samples,
                          "no samples for a full-factorial design (every level combination "
                          "runs)")
        return self


@dataclass(frozen=True)
class RunSpec:
    """One run: a design point, a replication and its seed. Picklable, sent to workers."""

    run_id: str
    point: int
    factors: tuple[tuple[str, Any], ...]
    replication: int
    seed: int
    scenario_file: str
    overrides: tuple[tuple[str, Any], ...]
    """Every override of the base scenario: the experiment's, the variant's (its layout file
    as `layout`), the factors', the seed."""
    variant: str = ""
    """The named variant the run belongs to; empty for the base scenario (the baseline unless
    the experiment names another)."""
    layout_changes: tuple[Change, ...] = ()
    """The variant's layout changes: the worker gets the run's layout from `run_layout`."""
    experiment_file: str = ""
    """The experiment file, named by a refused layout change (set for a variant's runs)."""

    def factor_dict(self) -> dict[str, Any]:
        return dict(self.factors)

    def override_dict(self) -> dict[str, Any]:
        return dict(self.overrides)

    def as_json(self) -> dict[str, Any]:
        """The run as spec.json records it; a variant's runs add `variant`, `layout_changes`
        and `experiment_file` (the base scenario's keep the keys they always had)."""
        plain = {"run_id": self.run_id, "point": self.point, "factors": self.factor_dict(),
                 "replication": self.replication, "seed": self.seed,
                 "scenario_file": self.scenario_file, "overrides": self.override_dict()}
        if self.variant:
            plain |= {"variant": self.variant,
                      "layout_changes": [c.model_dump(mode="json", by_alias=True)
                                         for c in self.layout_changes],
                      "experiment_file": self.experiment_file}
        return plain


@dataclass(frozen=True)
class VariantLayout:
    """A variant's layout at one design point, its changes applied, against the baseline's
    (for drawing the variant with its changes highlighted)."""

    variant: str
    layout: Layout
    baseline: Layout
    """The baseline's layout at the same design point."""
    diff: LayoutDiff
    """What the variant's layout changes against the baseline's: node ids, (from, to) hops,
    place ids."""


@dataclass(frozen=True)
class Experiment:
    """A loaded, validated experiment: the spec, where it came from, and its design points."""

    spec: ExperimentSpec
    file: Path
    points: tuple[tuple[tuple[str, Any], ...], ...]
    """Design points in run order: each a tuple of (dotted path, value) in factor order."""

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def scenario_file(self) -> Path:
        p = Path(self.spec.scenario)
        return (p if p.is_absolute() else self.file.parent / p).resolve()

    @property
    def factor_names(self) -> list[str]:
        return list(self.spec.factors)

    @property
    def fleet_factor(self) -> str:
        """The factor a sizing search varies, and the fleet axis of reports: fleet.size, or
        a mixed fleet's count of `sizing.vary_type` (fleet.vehicles.<type>.count)."""
        vary = self.spec.sizing.vary_type
        return FLEET if vary is None else type_count_path(vary)

    # ---- variants

    @property
    def baseline_name(self) -> str:
        """The variant the others are compared with: BASE_VARIANT (the base scenario) unless
        the file's `baseline` names one of its variants."""
        return self.spec.baseline or BASE_VARIANT

    @property
    def variant_names(self) -> list[str]:
        """Every variant a comparison runs, the baseline first, the others in file order.
        The base scenario (BASE_VARIANT) is among them only when it is the baseline."""
        return [self.baseline_name, *(v for v in self.spec.variants if v != self.baseline_name)]

    def variant_spec(self, variant: str | None) -> VariantSpec | None:
        """The named variant as written; None for the base scenario (None or BASE_VARIANT)."""
        if variant is None or variant == BASE_VARIANT:
            return None
        if variant not in self.spec.variants:
            raise KeyError(f"no variant {variant!r} in {self.file} "
                           f"(variants: {', '.join(self.variant_names)})")
        return self.spec.variants[variant]

    def change_site(self, variant: str) -> ChangeSite:
        """Names the experiment file and `variant` in a refused layout change."""
        return ChangeSite(str(self.file), variant)

    def file_path(self, name: str) -> str:
        """A file named in the experiment (a layout), as an absolute path: relative to the
        experiment file's folder."""
        p = Path(name)
        return str(p if p.is_absolute() else (self.file.parent / p).resolve())

    def scenario_overrides(self, factors: Mapping[str, Any] | None = None,
                           variant: str | None = None) -> dict[str, Any]:
        """Every override of the base scenario at design point `factors` in `variant`: the
        experiment's, the variant's (its layout as `layout`), the factors'. A `layout` value
        names a file relative to the experiment file; here it is absolute."""
        merged = dict(self.spec.overrides)
        named = self.variant_spec(variant)
        if named is not None:
            merged |= named.overrides
            if named.layout is not None:
                merged["layout"] = named.layout
        merged |= factors or {}
        if isinstance(merged.get("layout"), str):
            merged["layout"] = self.file_path(merged["layout"])
        return merged

    def run(self, factors: Mapping[str, Any], replication: int, point: int = -1,
            variant: str | None = None) -> RunSpec:
        """The run of design point `factors` (any factor values) at `replication`, in
        `variant` (None or BASE_VARIANT: the base scenario). Every variant's replication r has
        the seed of the base scenario's (common random numbers); a named variant's run id is
        the base scenario's prefixed with ``v=<variant>__``."""
        seed = replication_seed(self.spec.master_seed, replication)
        overrides = {**self.scenario_overrides(factors, variant), "seed": seed}
        named = self.variant_spec(variant)
        if named is None:
            return RunSpec(run_id(factors, replication), point, tuple(factors.items()),
                           replication, seed, str(self.scenario_file), tuple(overrides.items()))
        assert variant is not None
        return RunSpec(variant_run_id(variant, factors, replication), point,
                       tuple(factors.items()), replication, seed, str(self.scenario_file),
                       tuple(overrides.items()), variant, tuple(named.layout_changes),
                       str(self.file))

    def runs(self) -> list[RunSpec]:
        """Every run of the design: each point times each replication (the base scenario)."""
        return [self.run(dict(point), r, i) for i, point in enumerate(self.points)
                for r in range(self.spec.replications)]

    def variant_runs(self, variant: str, replications: Iterable[int] | None = None
                     ) -> list[RunSpec]:
        """The runs of `variant` at every design point, for `replications` (default: the
        file's 0 .. replications-1), point by point. The base scenario's are `runs()`."""
        reps = list(range(self.spec.replications) if replications is None else replications)
        design = self.points or ((),)
        return [self.run(dict(point), r, i, variant) for i, point in enumerate(design)
                for r in reps]

    def scenario(self, factors: Mapping[str, Any] | None = None,
                 variant: str | None = None) -> Scenario:
        """The base scenario with the experiment's overrides (the variant's, and `factors`)
        applied."""
        return load_scenario(self.scenario_file, self.scenario_overrides(factors, variant))

    def layout(self, scenario: Scenario, variant: str | None = None) -> Layout:
        """`scenario`'s layout (cached) with `variant`'s layout changes, checked against it."""
        named = self.variant_spec(variant)
        if named is None or not named.layout_changes:
            return layout_for(scenario, str(self.scenario_file))
        assert variant is not None
        return changed_layout_for(scenario, str(self.scenario_file), named.layout_changes,
                                  self.change_site(variant))

    def variant_layout(self, variant: str, factors: Mapping[str, Any] | None = None
                       ) -> VariantLayout:
        """`variant`'s layout at design point `factors` (default: the first) with what it
        changes against the baseline's layout there."""
        if factors is None:
            factors = dict(self.points[0]) if self.points else {}
        layout = self.layout(self.scenario(factors, variant), variant)
        base_name = self.baseline_name
        baseline = self.layout(self.scenario(factors, base_name), base_name)
        return VariantLayout(variant, layout, baseline, layout_diff(baseline, layout))

    def with_overrides(self, extra: Mapping[str, Any]) -> Experiment:
        """The same experiment with `extra` set in every run (an estimated warm-up)."""
        spec = self.spec.model_copy(update={"overrides": {**self.spec.overrides, **extra}})
        return Experiment(spec, self.file, self.points)

    def resolved(self) -> dict[str, Any]:
        """The experiment with every default written out and paths made absolute (the
        scenario, layouts in overrides and variants; a layout factor's levels stay as
        written, as the run ids and the summary show them)."""
        plain = self.spec.model_dump(mode="json", by_alias=True)
        plain["scenario"] = str(self.scenario_file)
        plain["experiment_file"] = str(self.file.resolve())
        if isinstance(plain["overrides"].get("layout"), str):
            plain["overrides"]["layout"] = self.file_path(plain["overrides"]["layout"])
        for variant in plain["variants"].values():
            if variant.get("layout") is not None:
                variant["layout"] = self.file_path(variant["layout"])
        return plain


def load_experiment(path: str | Path, settings: Mapping[str, Any] | None = None,
                    source: str = "--set") -> Experiment:
    """Read and validate an experiment file; every error names the file and the element.

    `settings` (dotted scenario path -> value, from the command line) are overrides added to
    the file's, checked like them; a problem they bring names `source` and the field."""
    path = Path(path)
    file = str(path)
    data = read_yaml(path)
    spec = validate(ExperimentSpec, data, file)
    scenario_file = Path(spec.scenario)
    if not scenario_file.is_absolute():
        scenario_file = path.parent / scenario_file
    if not scenario_file.exists():
        raise InputError(file, "scenario", spec.scenario,
                         f"an existing scenario file (looked for {scenario_file})")
    for key in spec.overrides:
        check_path(file, f"overrides.{key}", key)
    _check_layout_names(file, "overrides.layout", spec.overrides.get("layout", ""))
    if settings:
        spec = _with_settings(spec, settings, source, scenario_file)
    levels: dict[str, list[Any]] = {}
    ranges: dict[str, Range] = {}
    for key, value in spec.factors.items():
        check_path(file, f"factors.{key}", key)
        if key in spec.overrides:
            raise InputError(file, f"factors.{key}", value,
                             "a field not also set in overrides (the factor varies it)")
        if isinstance(value, list):
            if not value:
                raise InputError(file, f"factors.{key}", value, "a list of at least one level")
            if len({repr(v) for v in value}) != len(value):
                raise InputError(file, f"factors.{key}", value, "distinct levels")
            if key == "layout":
                for i, level in enumerate(value):
                    _check_layout_names(file, f"factors.layout[{i}]", level)
            levels[key] = value
        elif isinstance(value, Mapping):
            if spec.design != "latin_hypercube":
                raise InputError(file, f"factors.{key}", value,
                                 "a list of levels ({min, max} ranges need design: "
                                 "latin_hypercube)")
            ranges[key] = validate(Range, value, file, f"factors.{key}")
        else:
            raise InputError(file, f"factors.{key}", value,
                             "a list of levels, or {min, max} for a Latin hypercube")
    n_points = math.prod(len(v) for v in levels.values()) if spec.design == "full_factorial" \
        else spec.samples
    if n_points * spec.replications > MAX_RUNS:
        element = "factors" if spec.design == "full_factorial" else "samples"
        raise InputError(file, element, f"{n_points} design points x {spec.replications} "
                         "replications", f"at most {MAX_RUNS} runs in one experiment")
    compared = len(spec.variants) + (spec.baseline in (None, BASE_VARIANT))
    if spec.variants and max(n_points, 1) * spec.replications * compared > MAX_RUNS:
        raise InputError(file, "variants", f"{compared} variants x {max(n_points, 1)} design "
                         f"points x {spec.replications} replications",
                         f"at most {MAX_RUNS} runs in one experiment")
    if spec.design == "full_factorial":
        points = full_factorial(levels)
    else:
        points = latin_hypercube(levels, ranges, spec.samples, spec.master_seed,
                                 list(spec.factors))
    experiment = Experiment(spec, path, tuple(tuple(p.items()) for p in points))
    _check_scenarios(experiment, levels)
    _check_vary_type(experiment)
    _check_variants(experiment)
    if spec.optimise is not None:
        design_space(experiment)
    return experiment


def _check_layout_names(file: str, element: str, value: Any) -> None:
    if not isinstance(value, str):
        raise InputError(file, element, value, "a layout file (a text: its path, relative to "
                                               "the experiment file)")


def _check_variants(experiment: Experiment) -> None:
    """Every variant's overrides, layout and layout changes, at every design point: a real
    scenario and its changed layout, like the base scenario's (`_check_scenarios`)."""
    spec = experiment.spec
    file = str(experiment.file)
    for name, variant in spec.variants.items():
        at = f"variants.{name}"
        for key, value in variant.overrides.items():
            check_path(file, f"{at}.overrides.{key}", key)
            if key == "layout":
                raise InputError(file, f"{at}.overrides.layout", value,
                                 f"the variant's own layout key ({at}.layout), not an override")
            if key in spec.factors:
                raise InputError(file, f"{at}.overrides.{key}", value,
                                 "a field that is not a factor (the factor varies it)")
        if variant.layout is not None:
            if "layout" in spec.factors:
                raise InputError(file, f"{at}.layout", variant.layout,
                                 "no layout of the variant's own: layout is a factor")
            path = Path(experiment.file_path(variant.layout))
            if not path.is_file():
                raise InputError(file, f"{at}.layout", variant.layout,
                                 f"an existing layout file, relative to the experiment file "
                                 f"(looked for {path})")
        for point in experiment.points or ((),):
            factors = dict(point)
            where = f" at design point ({point_text(factors)})" if factors else ""
            try:
                scenario = experiment.scenario(factors, name)
                experiment.layout(scenario, name)
            except InputError as exc:
                if exc.file == file:  # a refused layout change names the variant already
                    raise
                own = next((k for k in variant.overrides if exc.element == k
                            or exc.element.startswith((f"{k}.", f"{k}["))), None)
                if own is not None:  # the variant's own override is wrong
                    raise InputError(file, f"{at}.overrides.{own}", exc.value,
                                     f"{exc.expected} ({exc.element}{where})") from None
                raise InputError(file, f"{at}{where}", exc.value,
                                 f"{exc.expected} ({exc.element}, in {exc.file})") from None
def _with_settings(spec: ExperimentSpec, settings: Mapping[str, Any], source: str,
                   scenario_file: Path) -> ExperimentSpec:
    """`spec` with `settings` among its overrides, each checked: a dotted path, not seed or
    layout, not a factor, and a valid scenario with the file's overrides (whose own problems
    are left to the checks of the file that follow)."""
    for key, value in settings.items():
        check_path(source, key, key)
        if key in spec.factors:
            raise InputError(source, key, value, f"a field that is not a factor of the "
                             f"experiment (factors.{key} varies it)")
        if key == "warmup_h" and spec.warmup.method == "mser5":
            raise InputError(source, key, value, "no warmup_h with warmup.method: mser5 (it "
                             "estimates the warm-up)")
    try:
        load_scenario(scenario_file, dict(spec.overrides))
    except InputError:
        return spec  # the file's own problem: named by the file's checks
    try:
        load_scenario(scenario_file, {**spec.overrides, **settings})
    except InputError as exc:
        raise InputError(source, exc.element, exc.value, exc.expected) from None
    return spec.model_copy(update={"overrides": {**spec.overrides, **settings}})


def _check_vary_type(experiment: Experiment) -> None:
    """`sizing.vary_type` names a type of the base scenario's mixed fleet (fleet.size cannot
    be a factor of a mixed fleet: the scenario refuses it)."""
    vary = experiment.spec.sizing.vary_type
    if vary is None:
        return
    file = str(experiment.file)
    types = list(experiment.scenario().fleet.type_profiles)
    if not experiment.scenario().fleet.vehicles:
        raise InputError(file, "sizing.vary_type", vary, "no vary_type with a one-type fleet "
                         f"(the base scenario's fleet is {types[0]} only: the search varies "
                         "fleet.size)")
    if vary not in types:
        raise InputError(file, "sizing.vary_type", vary,
                         f"a type of the base scenario's fleet.vehicles ({', '.join(types)})")


def full_factorial(levels: Mapping[str, list[Any]]) -> list[dict[str, Any]]:
    """Every combination of levels, the last factor varying fastest."""
    names = list(levels)
    return [dict(zip(names, combo, strict=True))
            for combo in itertools.product(*(levels[n] for n in names))]


def latin_hypercube(levels: Mapping[str, list[Any]], ranges: Mapping[str, Range], samples: int,
                    master_seed: int, order: list[str]) -> list[dict[str, Any]]:
    """`samples` points; each factor's range (or level list) cut into `samples` strata, each
    stratum used once, strata paired at random across factors."""
    rng = np.random.default_rng(np.random.SeedSequence(master_seed, spawn_key=(LHS_STREAM,)))
    points: list[dict[str, Any]] = [{} for _ in range(samples)]
    for name in order:
        u = (rng.permutation(samples) + rng.random(samples)) / samples
        for i in range(samples):
            if name in ranges:
                r = ranges[name]
                if r.integer:
                    lo, hi = math.ceil(r.min), math.floor(r.max)
                    value: Any = int(min(hi, lo + math.floor(u[i] * (hi - lo + 1))))
                else:
                    value = float(r.min + u[i] * (r.max - r.min))
            else:
                choices = levels[name]
                value = choices[min(len(choices) - 1, int(u[i] * len(choices)))]
            points[i][name] = value
    return points


def run_layout(scenario: Scenario, spec: RunSpec) -> Layout:
    """The layout run `spec` drives on: its scenario's (cached per process), with its
    variant's layout changes applied, checked against the scenario. What a worker calls."""
    if not spec.layout_changes:
        return layout_for(scenario, spec.scenario_file)
    return changed_layout_for(scenario, spec.scenario_file, spec.layout_changes,
                              ChangeSite(spec.experiment_file, spec.variant))


def _check_scenarios(experiment: Experiment, levels: Mapping[str, list[Any]]) -> None:
    """Build a real scenario for each level alone, then for every design point."""
    file = str(experiment.file)
    try:
        base = experiment.scenario()
        layout_for(base, str(experiment.scenario_file))
    except InputError as exc:
        raise InputError(file, "overrides" if experiment.spec.overrides else "scenario",
                         exc.value, f"{exc.expected} (scenario field {exc.element}, "
                         f"in {exc.file})") from None
    for name, values in levels.items():
        for i, value in enumerate(values):
            try:
                scenario = experiment.scenario({name: value})
                if name == "layout":
                    layout_for(scenario, str(experiment.scenario_file))
            except InputError as exc:
                raise InputError(file, f"factors.{name}[{i}]", value,
                                 f"a valid scenario field: {exc.element}: got {exc.value!r}; "
                                 f"expected {exc.expected}") from None
    for point in experiment.points:
        factors = dict(point)
        try:
            scenario = experiment.scenario(factors)
            layout_for(scenario, str(experiment.scenario_file))
        except InputError as exc:
            where = point_text(factors)
            raise InputError(file, f"design point ({where})", exc.value,
                             f"{exc.expected} (scenario field {exc.element})") from None


def experiment_warnings(experiment: Experiment, variant: str | None = None) -> list[str]:
    """The setup warnings of the experiment's design points (in `variant`; None: the base
    scenario), each kind once: the line of the first point that has it, and in how many of
    the points it holds."""
    first: dict[str, str] = {}
    points: dict[str, int] = {}
    design = experiment.points or ((),)
    for point in design:
        scenario = experiment.scenario(dict(point), variant)
        layout = experiment.layout(scenario, variant)
        for warning in setup_warnings(scenario, layout):
            first.setdefault(warning.kind, warning.text)
            points[warning.kind] = points.get(warning.kind, 0) + 1
    return [text + (f" (in {points[kind]} of {len(design)} design points)"
                    if points[kind] < len(design) else "")
            for kind, text in first.items()]


def load_trace_for(scenario: Scenario, layout: Layout) -> list[TraceOrder]:
    """The scenario's order trace, or no orders for Poisson demand."""
    if scenario.demand.kind != "trace":
        return []
    from fleet_sim.config.trace import load_trace

    assert scenario.demand.trace_csv is not None
    return load_trace(scenario.path(scenario.demand.trace_csv), layout)
