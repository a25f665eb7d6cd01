"""Distributions of times that users write in layout and scenario files (handling times, repair
times, obstacle durations...): ``{dist: triangular, low_s: 10, mode_s: 15, high_s: 25}``.

`TimeDistribution` is a union tagged by ``dist``: one small model per distribution, each taking
exactly its own parameters (an unknown or missing one is an input error naming the element) and
knowing its mean (`expected_s`) and how to draw from the numpy Generator it is handed; nothing
here keeps random state. The choices where the issues were silent (a missing ``dist``,
truncation, lognormal's parameters): docs/background/decisions/config.md.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Discriminator, Field, Tag, model_validator

from userfiles.checking import Problem, StrictModel

Seconds = Annotated[float, Field(ge=0)]
"""A time parameter: a finite number of seconds >= 0."""


class FixedTime(StrictModel):
    """Always the same time."""

    dist: Literal["fixed"] = "fixed"
    mean_s: Seconds

    @property
    def expected_s(self) -> float:
        return self.mean_s

    def sample(self, rng: np.random.Generator) -> float:
        return self.mean_s


class UniformTime(StrictModel):
    """Any time between low_s and high_s, equally likely."""

    dist: Literal["uniform"]
    low_s: Seconds
    high_s: Seconds

    @model_validator(mode="after")
    def _ordered(self) -> UniformTime:
        if self.low_s > self.high_s:
            raise Problem("high_s", self.high_s, f"a time >= low_s ({self.low_s})")
        return self

    @property
    def expected_s(self) -> float:
        return (self.low_s + self.high_s) / 2

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.low_s, self.high_s))


class TriangularTime(StrictModel):
    """Between low_s and high_s, most often near mode_s."""

    dist: Literal["triangular"]
    low_s: Seconds
    mode_s: Seconds
    high_s: Seconds

    @model_validator(mode="after")
    def _ordered(self) -> TriangularTime:
        if not self.low_s <= self.mode_s <= self.high_s or self.low_s == self.high_s:
            raise Problem("mode_s", self.mode_s,
                          f"low_s <= mode_s <= high_s with low_s < high_s "
                          f"(low_s={self.low_s}, high_s={self.high_s})")
        return self

    @property
    def expected_s(self) -> float:
        return (self.low_s + self.mode_s + self.high_s) / 3

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.triangular(self.low_s, self.mode_s, self.high_s))


class NormalTime(StrictModel):
    """Normal with mean mean_s and standard deviation sd_s, cut at 0 (a draw below 0 is 0)."""

    dist: Literal["normal"]
    mean_s: Seconds
    sd_s: Seconds

    @property
    def expected_s(self) -> float:
        """The mean before the cut at zero (the cut matters only when sd_s is near mean_s)."""
        return self.mean_s

    def sample(self, rng: np.random.Generator) -> float:
        return max(0.0, float(rng.normal(self.mean_s, self.sd_s)))


class LognormalTime(StrictModel):
    """Lognormal whose time (not its logarithm) has mean mean_s and standard deviation sd_s."""

    dist: Literal["lognormal"]
    mean_s: Annotated[float, Field(gt=0)]
    sd_s: Seconds

    @property
    def expected_s(self) -> float:
        return self.mean_s

    def sample(self, rng: np.random.Generator) -> float:
        sigma2 = math.log1p((self.sd_s / self.mean_s) ** 2)
        mu = math.log(self.mean_s) - sigma2 / 2
        return float(rng.lognormal(mu, math.sqrt(sigma2)))


class ExponentialTime(StrictModel):
    """Exponential with mean mean_s (memoryless: arrivals, obstacle durations)."""

    dist: Literal["exponential"]
    mean_s: Seconds

    @property
    def expected_s(self) -> float:
        return self.mean_s

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.exponential(self.mean_s))


def _dist_of(value: Any) -> str | None:
    """The tag of a distribution as written (``fixed`` when ``dist`` is left out)."""
    if isinstance(value, dict):
        tag = value.get("dist", "fixed")
        return tag if isinstance(tag, str) else repr(tag)
    return getattr(value, "dist", None)


TimeDistribution = Annotated[
    Annotated[FixedTime, Tag("fixed")]
    | Annotated[UniformTime, Tag("uniform")]
    | Annotated[TriangularTime, Tag("triangular")]
    | Annotated[NormalTime, Tag("normal")]
    | Annotated[LognormalTime, Tag("lognormal")]
    | Annotated[ExponentialTime, Tag("exponential")],
    Discriminator(_dist_of),
]
"""A random time in seconds, one of the distributions above, chosen by ``dist``."""

DISTRIBUTIONS: dict[str, type[StrictModel]] = {
    "fixed": FixedTime, "uniform": UniformTime, "triangular": TriangularTime,
    "normal": NormalTime, "lognormal": LognormalTime, "exponential": ExponentialTime,
}
