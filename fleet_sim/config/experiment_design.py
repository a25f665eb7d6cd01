"""An experiment's factors -> its design points: each factor's levels (or range), every
combination of them (full factorial) or a Latin hypercube sample."""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from fleet_sim.config.experiment_checks import check_layout_names
from fleet_sim.config.experiment_spec import ExperimentSpec, Range
from fleet_sim.config.runs import check_path
from fleet_sim.errors import InputError
from userfiles.checking import validate

LHS_STREAM = 2**32
"""The Latin hypercube's random stream, apart from every replication's."""


def factor_levels(spec: ExperimentSpec, file: str
                  ) -> tuple[dict[str, list[Any]], dict[str, Range]]:
    """Each factor's levels (a list) or range ({min, max}, Latin hypercube only), checked."""
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
                    check_layout_names(file, f"factors.layout[{i}]", level)
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
    return levels, ranges


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
