"""An experiment checked against its base scenario: every level, design point and variant
makes a real scenario on its layout, command-line settings are valid overrides, and a mixed
fleet's `sizing.vary_type` names one of its types."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fleet_sim.config.runs import check_path, layout_for, point_text
from fleet_sim.config.scenario import load_scenario
from fleet_sim.errors import InputError

if TYPE_CHECKING:
    from fleet_sim.config.experiment import Experiment
    from fleet_sim.config.experiment_spec import ExperimentSpec


def check_layout_names(file: str, element: str, value: Any) -> None:
    if not isinstance(value, str):
        raise InputError(file, element, value, "a layout file (a text: its path, relative to "
                                               "the experiment file)")


def check_variants(experiment: Experiment) -> None:
    """Every variant's overrides, layout and layout changes, at every design point: a real
    scenario and its changed layout, like the base scenario's (`check_scenarios`)."""
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


def with_settings(spec: ExperimentSpec, settings: Mapping[str, Any], source: str,
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


def check_vary_type(experiment: Experiment) -> None:
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


def check_scenarios(experiment: Experiment, levels: Mapping[str, list[Any]]) -> None:
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
