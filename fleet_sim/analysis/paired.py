"""Comparing variants with a baseline: paired differences under common random numbers, their
sequential intervals with the error rate held over looks and comparisons, the verdict in words,
and Kim and Nelson's fully sequential selection of the best. Pure functions on numbers (no
runs, no files), so each can be tested on synthetic data.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.special import stdtrit

Better = Literal["higher", "lower"] | None
Verdict = Literal["better", "worse", "higher", "lower", "no_difference", "undecided"]

CORRECTION_NAME = "Bonferroni over comparisons and looks"


def looks(min_replications: int, max_replications: int) -> list[int]:
    """Replication counts at which the data are looked at: min, then doubling, up to max."""
    out = [min_replications]
    while out[-1] < max_replications:
        out.append(min(max_replications, 2 * out[-1]))
    return out


@dataclass(frozen=True)
class Correction:
    """The level of each interval: Bonferroni over `comparisons` and `looks`."""

    confidence: float
    comparisons: int
    looks: int

    @property
    def alpha_each(self) -> float:
        return (1.0 - self.confidence) / (max(1, self.comparisons) * max(1, self.looks))

    @property
    def level(self) -> float:
        """Confidence level of each interval at each look."""
        return 1.0 - self.alpha_each

    def as_dict(self) -> dict[str, float | int | str]:
        return {"name": CORRECTION_NAME, "confidence": self.confidence,
                "comparisons": self.comparisons, "looks": self.looks,
                "level_each_interval": self.level}


@dataclass(frozen=True)
class PairedDifference:
    """Variant minus baseline over the replications both have, with its interval."""

    pairs: int
    baseline_mean: float
    variant_mean: float
    mean: float
    half_width: float
    level: float

    @property
    def low(self) -> float:
        return self.mean - self.half_width

    @property
    def high(self) -> float:
        return self.mean + self.half_width

    @property
    def excludes_zero(self) -> bool:
        return self.pairs >= 2 and not math.isnan(self.half_width) and \
            (self.low > 0 or self.high < 0)

    @property
    def largest_effect(self) -> float:
        """The farthest end of the interval from zero: no larger difference is plausible."""
        return max(abs(self.low), abs(self.high))


def paired_difference(baseline: Sequence[float] | np.ndarray,
                      variant: Sequence[float] | np.ndarray, level: float) -> PairedDifference:
    """The paired difference variant - baseline (replication by replication) and its Student t
    interval at `level`; pairs with a NaN on either side are left out."""
    a = np.asarray(baseline, dtype=float)
    b = np.asarray(variant, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired samples of different lengths ({len(a)} and {len(b)})")
    keep = ~(np.isnan(a) | np.isnan(b))
    a, b = a[keep], b[keep]
    n = len(a)
    if n == 0:
        return PairedDifference(0, math.nan, math.nan, math.nan, math.nan, level)
    d = b - a
    mean = float(d.mean())
    half = math.nan
    if n >= 2:
        sd = float(d.std(ddof=1))
        half = float(stdtrit(n - 1, 0.5 + level / 2)) * sd / math.sqrt(n)
    return PairedDifference(n, float(a.mean()), float(b.mean()), mean, half, level)


def verdict(diff: PairedDifference, better: Better, precision: float | None) -> Verdict:
    """better/worse (higher/lower without a better direction) when the interval excludes zero;
    no_difference when its half-width is at most `precision` (none given: zero, as when every
    pair is equal); else undecided."""
    if diff.excludes_zero:
        up = diff.low > 0
        if better is None:
            return "higher" if up else "lower"
        return "better" if up == (better == "higher") else "worse"
    if diff.pairs >= 2 and not math.isnan(diff.half_width) \
            and diff.half_width <= (precision or 0.0):
        return "no_difference"
    return "undecided"


def decided(v: Verdict) -> bool:
    return v != "undecided"


# ---- selection of the best: KN ---------------------------------------------------------------


def kn_h2(k: int, n0: int, pcs: float) -> float:
    """KN's h^2 = 2 eta (n0 - 1) for k systems, first stage n0 and probability `pcs`."""
    alpha = 1.0 - pcs
    eta = 0.5 * ((2.0 * alpha / (k - 1)) ** (-2.0 / (n0 - 1)) - 1.0)
    return float(2.0 * eta * (n0 - 1))


@dataclass(frozen=True)
class KnResult:
    """The state of KN after screening every replication available."""

    selected: int | None
    """Index of the system selected (the last survivor), None while several survive."""
    survivors: tuple[int, ...]
    eliminated_at: dict[int, int] = field(default_factory=dict)
    """System -> the replication count r at which it left."""
    replications: int = 0
    """r at which the screening stopped (the last survivor found, or the data ran out)."""
    h2: float = math.nan
    guaranteed: bool = True
    """False when the cap stopped KN with several survivors (see `best_at_cap`)."""
    best_at_cap: int | None = None
    identical: tuple[int, ...] = ()
    """Survivors whose results equal the selected system's in every replication: the same
    system under another name (KN alone would never part them)."""


def kn_select(samples: np.ndarray, indifference_zone: float, pcs: float, n0: int,
              maximise: bool = True, final: bool = False) -> KnResult:
    """KN on `samples` (k systems x n replications, common random numbers: column r is
    replication r of every system). `final`: no more replications will come (the cap), so with
    several survivors the best mean among them is named, without KN's guarantee."""
    x = np.asarray(samples, dtype=float)
    if not maximise:
        x = -x
    k, n = x.shape
    if k < 2:
        return KnResult(0 if k else None, tuple(range(k)), {}, n, math.nan)
    if n < n0:
        return KnResult(None, tuple(range(k)), {}, n, math.nan, final, None)
    if np.isnan(x[:, :n]).any():
        raise ValueError("KN needs a value for every system and replication")
    h2 = kn_h2(k, n0, pcs)
    first = x[:, :n0]
    s2 = np.zeros((k, k))
    for i in range(k):
        for m in range(k):
            if i != m:
                s2[i, m] = float(np.var(first[i] - first[m], ddof=1))
    d = indifference_zone
    survivors = list(range(k))
    eliminated: dict[int, int] = {}
    cums = np.cumsum(x, axis=1)
    r = n0
    while True:
        means = cums[:, r - 1] / r
        old = list(survivors)
        survivors = []
        for i in old:
            out = False
            for m in old:
                if m == i:
                    continue
                w = max(0.0, d / (2 * r) * (h2 * s2[i, m] / d ** 2 - r))
                if means[i] < means[m] - w:
                    out = True
                    break
            if out:
                eliminated[i] = r
            else:
                survivors.append(i)
        if len(survivors) == 1:
            return KnResult(survivors[0], (survivors[0],), eliminated, r, h2)
        if all(np.array_equal(x[survivors[0], :r], x[i, :r]) for i in survivors[1:]):
            # the survivors gave identical results in every replication: one system (a
            # variant that changes nothing); the first (the baseline first) stands for them
            return KnResult(survivors[0], tuple(survivors), eliminated, r, h2,
                            identical=tuple(survivors[1:]))
        if r >= n:
            break
        r += 1
    best = max(survivors, key=lambda i: (means[i], -i))
    if final:
        return KnResult(None, tuple(survivors), eliminated, r, h2, False, best)
    return KnResult(None, tuple(survivors), eliminated, r, h2, True, best)


# ---- numbers in words ------------------------------------------------------------------------


def number_text(value: float | None) -> str:
    """A number as a planner reads it: three significant figures, no exponent, thousands
    separated, "n/a" for none (what the comparison's table, sentences and report all say)."""
    if value is None or math.isnan(value):
        return "n/a"
    value = round(float(value), 6)  # as compare.json keeps it: float noise is no digit
    a = abs(value)
    if value.is_integer() and a < 1e6:
        return f"{int(value)}"
    if a >= 100:
        return f"{value:,.0f}"
    if a >= 10:
        return f"{value:.1f}"
    if a >= 1:
        return f"{value:.2f}"
    return f"{value:.3g}"


def signed_text(value: float | None) -> str:
    """`number_text` with its sign: +7, -34."""
    text = number_text(value)
    return text if text.startswith("-") or text == "n/a" else "+" + text
