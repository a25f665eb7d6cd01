"""Duration distributions that users write in layout and scenario files (handling times...).

Each distribution validates its own parameters when loaded and samples from the numpy Generator
it is handed; nothing here keeps random state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from fleet_sim.errors import InputError

DistName = Literal["fixed", "uniform", "triangular", "normal", "lognormal", "exponential"]

_NEEDS: dict[str, tuple[str, ...]] = {
    "fixed": ("mean_s",),
    "uniform": ("low_s", "high_s"),
    "triangular": ("low_s", "mode_s", "high_s"),
    "normal": ("mean_s", "sd_s"),
    "lognormal": ("mean_s", "sd_s"),
    "exponential": ("mean_s",),
}


@dataclass(frozen=True)
class Duration:
    """A random duration in seconds. `normal` is truncated at zero; `lognormal` takes the mean and
    standard deviation of the duration itself (not of its logarithm)."""

    dist: DistName = "fixed"
    mean_s: float | None = None
    sd_s: float | None = None
    low_s: float | None = None
    mode_s: float | None = None
    high_s: float | None = None

    def check(self, file: str, element: str) -> None:
        for name in ("mean_s", "sd_s", "low_s", "mode_s", "high_s"):
            value = getattr(self, name)
            needed = name in _NEEDS[self.dist]
            if needed and value is None:
                raise InputError(file, f"{element}.{name}", None,
                                 f"a number of seconds (distribution {self.dist!r} needs "
                                 f"{', '.join(_NEEDS[self.dist])})")
            if not needed and value is not None:
                raise InputError(file, f"{element}.{name}", value,
                                 f"no {name} for distribution {self.dist!r} (it takes "
                                 f"{', '.join(_NEEDS[self.dist])})")
            if value is not None and value < 0:
                raise InputError(file, f"{element}.{name}", value, "a duration >= 0 s")
        if self.dist == "uniform" and self.low_s is not None and self.high_s is not None \
                and self.low_s > self.high_s:
            raise InputError(file, f"{element}.high_s", self.high_s, f">= low_s ({self.low_s})")
        if self.dist == "triangular":
            assert self.low_s is not None and self.mode_s is not None and self.high_s is not None
            if not self.low_s <= self.mode_s <= self.high_s or self.low_s == self.high_s:
                raise InputError(file, f"{element}.mode_s", self.mode_s,
                                 f"low_s <= mode_s <= high_s with low_s < high_s "
                                 f"(low_s={self.low_s}, high_s={self.high_s})")
        if self.dist == "lognormal" and (self.mean_s or 0.0) <= 0:
            raise InputError(file, f"{element}.mean_s", self.mean_s, "a mean > 0 for lognormal")

    @property
    def expected_s(self) -> float:
        """The mean of the distribution (for analytic estimates)."""
        if self.dist in ("uniform",):
            assert self.low_s is not None and self.high_s is not None
            return (self.low_s + self.high_s) / 2
        if self.dist == "triangular":
            assert self.low_s is not None and self.mode_s is not None and self.high_s is not None
            return (self.low_s + self.mode_s + self.high_s) / 3
        assert self.mean_s is not None
        return self.mean_s

    def sample(self, rng: np.random.Generator) -> float:
        d = self.dist
        if d == "fixed":
            assert self.mean_s is not None
            return self.mean_s
        if d == "uniform":
            assert self.low_s is not None and self.high_s is not None
            return float(rng.uniform(self.low_s, self.high_s))
        if d == "triangular":
            assert self.low_s is not None and self.mode_s is not None and self.high_s is not None
            return float(rng.triangular(self.low_s, self.mode_s, self.high_s))
        if d == "normal":
            assert self.mean_s is not None and self.sd_s is not None
            return max(0.0, float(rng.normal(self.mean_s, self.sd_s)))
        if d == "lognormal":
            assert self.mean_s is not None and self.sd_s is not None
            sigma2 = math.log1p((self.sd_s / self.mean_s) ** 2)
            mu = math.log(self.mean_s) - sigma2 / 2
            return float(rng.lognormal(mu, math.sqrt(sigma2)))
        assert self.mean_s is not None
        return float(rng.exponential(self.mean_s))
