"""Time distributions: which parameters each takes, their means, and the numbers they draw."""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
import pytest

from fleet_sim.config.distributions import (
    DISTRIBUTIONS,
    ExponentialTime,
    FixedTime,
    TimeDistribution,
    TriangularTime,
)
from userfiles.checking import InputError, StrictModel, validate


class Station(StrictModel):
    handling: TimeDistribution = FixedTime(mean_s=20.0)


def load(handling: Any) -> Any:
    return validate(Station, {"handling": handling}, "layout.yaml", "stations[0]").handling


TAKES = {
    "fixed": {"mean_s": 20},
    "uniform": {"low_s": 10, "high_s": 30},
    "triangular": {"low_s": 10, "mode_s": 15, "high_s": 35},
    "normal": {"mean_s": 20, "sd_s": 5},
    "lognormal": {"mean_s": 20, "sd_s": 5},
    "exponential": {"mean_s": 20},
}
"""Every distribution's parameters, and a mean of 20 s each (worked by hand)."""


@pytest.mark.parametrize("dist", list(TAKES))
def test_each_distribution_takes_exactly_its_parameters(dist: str) -> None:
    loaded = load({"dist": dist, **TAKES[dist]})
    assert type(loaded) is DISTRIBUTIONS[dist]
    assert loaded.expected_s == 20.0
    foreign = next(p for p in ("sd_s", "mode_s", "low_s") if p not in TAKES[dist])
    with pytest.raises(InputError) as info:
        load({"dist": dist, **TAKES[dist], foreign: 1})
    assert info.value.element == f"stations[0].handling.{foreign}"
    assert re.match(rf"no such key for dist '{dist}'(: did you mean '\w+'\?)? \(known keys: "
                    "dist, ", info.value.expected), info.value.expected
    for missing in TAKES[dist]:
        with pytest.raises(InputError) as info:
            load({"dist": dist, **{k: v for k, v in TAKES[dist].items() if k != missing}})
        assert info.value.element == f"stations[0].handling.{missing}"
        assert info.value.expected == f"a value for required key {missing!r}"


def test_dist_left_out_means_fixed() -> None:
    assert load({"mean_s": 7}) == FixedTime(mean_s=7.0)


@pytest.mark.parametrize(("handling", "element", "value", "expected"), [
    ({"dist": "gamma", "mean_s": 3}, "dist", "gamma",
     "one of 'fixed', 'uniform', 'triangular', 'normal', 'lognormal', 'exponential'"),
    ({"dist": "uniform", "low_s": 30, "high_s": 10}, "high_s", 10.0, "a time >= low_s (30.0)"),
    ({"dist": "triangular", "low_s": 10, "mode_s": 40, "high_s": 35}, "mode_s", 40.0,
     "low_s <= mode_s <= high_s with low_s < high_s (low_s=10.0, high_s=35.0)"),
    ({"dist": "triangular", "low_s": 10, "mode_s": 10, "high_s": 10}, "mode_s", 10.0,
     "low_s <= mode_s <= high_s with low_s < high_s (low_s=10.0, high_s=10.0)"),
    ({"dist": "lognormal", "mean_s": 0, "sd_s": 1}, "mean_s", 0, "a number > 0"),
    ({"dist": "exponential", "mean_s": -1}, "mean_s", -1, "a number >= 0"),
    ({"dist": "normal", "mean_s": 5, "sd_s": math.inf}, "sd_s", math.inf, "a finite number"),
    ({"dist": "fixed", "mean_s": "20 s"}, "mean_s", "20 s", "a number"),
    (20, "", 20, "a mapping such as {dist: fixed, mean_s: 20}"),
])
def test_bad_distributions_name_the_element(handling: Any, element: str, value: object,
                                            expected: str) -> None:
    with pytest.raises(InputError) as info:
        load(handling)
    where = "stations[0].handling" + (f".{element}" if element else "")
    assert (info.value.element, info.value.value, info.value.expected) == (where, value, expected)


@pytest.mark.parametrize(("handling", "mean_s", "sd_s"), [
    ({"dist": "uniform", "low_s": 10, "high_s": 30}, 20.0, 20 / math.sqrt(12)),
    ({"dist": "triangular", "low_s": 10, "mode_s": 15, "high_s": 35}, 20.0,
     math.sqrt((100 + 225 + 1225 - 150 - 350 - 525) / 18)),
    ({"dist": "normal", "mean_s": 20, "sd_s": 5}, 20.0, 5.0),
    ({"dist": "lognormal", "mean_s": 20, "sd_s": 5}, 20.0, 5.0),
    ({"dist": "exponential", "mean_s": 20}, 20.0, 20.0),
])
def test_sample_means_and_spreads_match_hand_values(handling: dict[str, Any], mean_s: float,
                                                    sd_s: float) -> None:
    distribution = load(handling)
    rng = np.random.default_rng(11)
    draws = np.array([distribution.sample(rng) for _ in range(40_000)])
    assert draws.mean() == pytest.approx(mean_s, abs=4 * sd_s / math.sqrt(len(draws)))
    assert draws.std() == pytest.approx(sd_s, rel=0.03)
    assert draws.min() >= 0


def test_normal_is_cut_at_zero() -> None:
    distribution = load({"dist": "normal", "mean_s": 1, "sd_s": 10})
    rng = np.random.default_rng(3)
    draws = [distribution.sample(rng) for _ in range(1000)]
    assert min(draws) == 0.0 and sum(d == 0.0 for d in draws) > 400  # about 46 % below zero


def test_draws_are_the_generators_own_numbers() -> None:
    """One draw per sample, the same numpy call as always: same seed, same run."""
    fixed = FixedTime(mean_s=4.0)
    rng = np.random.default_rng(5)
    assert fixed.sample(rng) == 4.0
    assert rng.random() == np.random.default_rng(5).random()  # a fixed time draws nothing
    pairs: list[tuple[Any, Any]] = [
        (TriangularTime(dist="triangular", low_s=60, mode_s=180, high_s=600),
         lambda g: g.triangular(60.0, 180.0, 600.0)),
        (ExponentialTime(dist="exponential", mean_s=30.0), lambda g: g.exponential(30.0)),
        (load({"dist": "uniform", "low_s": 1, "high_s": 2}), lambda g: g.uniform(1.0, 2.0)),
        (load({"dist": "normal", "mean_s": 9, "sd_s": 2}), lambda g: max(0.0, g.normal(9.0, 2.0))),
        (load({"dist": "lognormal", "mean_s": 20, "sd_s": 5}),
         lambda g: g.lognormal(math.log(20) - math.log1p(1 / 16) / 2,
                               math.sqrt(math.log1p(1 / 16)))),
    ]
    for distribution, numpy_call in pairs:
        ours, theirs = np.random.default_rng(8), np.random.default_rng(8)
        assert [distribution.sample(ours) for _ in range(5)] == \
            [float(numpy_call(theirs)) for _ in range(5)]
