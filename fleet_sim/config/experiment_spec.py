"""The experiment file as written, before its design is expanded: the base scenario, overrides,
factors, design, replications and seed, targets, and the settings of `fleet-sim size`,
`compare` and `optimise`, with the what-if variants."""

from __future__ import annotations

from typing import Annotated, Any, Final, Literal

from pydantic import Field, Strict, field_validator, model_validator

from fleet_sim.config.decisions import OptimiseConfig
from fleet_sim.config.layout_changes import LayoutChange, parse_changes
from fleet_sim.config.runs import MAX_REPLICATIONS, MAX_RUNS
from fleet_sim.config.scenario import FOLDER_NAME, is_folder_name
from fleet_sim.config.scenario_fleet import MAX_FLEET_SIZE
from userfiles.checking import Items, Positive, Problem, StrictModel, Text


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

