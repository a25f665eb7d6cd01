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

Replication r of every design point runs with the same seed (common random numbers), so
comparisons between levels and variants are paired. The choices where the issues were silent:
docs/background/decisions/config.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fleet_sim.config.decisions import design_space
from fleet_sim.config.experiment_checks import (
    check_layout_names,
    check_scenarios,
    check_variants,
    check_vary_type,
    with_settings,
)
from fleet_sim.config.experiment_design import factor_levels, full_factorial, latin_hypercube
from fleet_sim.config.experiment_spec import BASE_VARIANT as BASE_VARIANT
from fleet_sim.config.experiment_spec import ExperimentSpec as ExperimentSpec
from fleet_sim.config.experiment_spec import Target as Target
from fleet_sim.config.experiment_spec import VariantSpec
from fleet_sim.config.layout import Layout
from fleet_sim.config.layout_changes import Change, ChangeSite, LayoutDiff, layout_diff
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
from fleet_sim.config.scenario import Scenario, load_scenario, setup_warnings, type_count_path
from fleet_sim.config.trace import TraceOrder
from fleet_sim.errors import InputError
from userfiles.checking import validate
from userfiles.reading import read_yaml

FLEET = "fleet.size"
"""The factor the sizing search varies."""


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
        and `experiment_file` (the base scenario's runs have none of them)."""
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
    check_layout_names(file, "overrides.layout", spec.overrides.get("layout", ""))
    if settings:
        spec = with_settings(spec, settings, source, scenario_file)
    levels, ranges = factor_levels(spec, file)
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
    check_scenarios(experiment, levels)
    check_vary_type(experiment)
    check_variants(experiment)
    if spec.optimise is not None:
        design_space(experiment)
    return experiment



def run_layout(scenario: Scenario, spec: RunSpec) -> Layout:
    """The layout run `spec` drives on: its scenario's (cached per process), with its
    variant's layout changes applied, checked against the scenario. What a worker calls."""
    if not spec.layout_changes:
        return layout_for(scenario, spec.scenario_file)
    return changed_layout_for(scenario, spec.scenario_file, spec.layout_changes,
                              ChangeSite(spec.experiment_file, spec.variant))



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
