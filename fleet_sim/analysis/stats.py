"""Statistics across replications: means, 95 % confidence intervals, paired differences, and
whether an interval is narrow enough to decide against a target.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy.special import stdtrit

from fleet_sim.analysis.kpis import COUNTS_BY_CODE, OPEN_AGE_OF
from fleet_sim.config.experiment import Target, level_text, point_text

CONFIDENCE = 0.95
NOT_KPIS = {"replication", "seed", "point", "agvs_requested"}
MAX_REPLICATIONS_ADVISED = 10_000


@dataclass(frozen=True)
class Interval:
    n: int
    mean: float
    sd: float
    half_width: float

    @property
    def low(self) -> float:
        return self.mean - self.half_width

    @property
    def high(self) -> float:
        return self.mean + self.half_width


def t_quantile(n: int, confidence: float = CONFIDENCE) -> float:
    """Two-sided Student t quantile for n observations (n - 1 degrees of freedom)."""
    return float(stdtrit(n - 1, 0.5 + confidence / 2))


def mean_ci(values: Sequence[float] | np.ndarray, confidence: float = CONFIDENCE) -> Interval:
    """Mean and half-width of the Student t interval of `values` (NaNs dropped)."""
    x = np.asarray(values, dtype=float)
    x = x[~np.isnan(x)]
    n = len(x)
    if n == 0:
        return Interval(0, math.nan, math.nan, math.nan)
    mean = float(x.mean())
    if n == 1:
        return Interval(1, mean, math.nan, math.nan)
    sd = float(x.std(ddof=1))
    return Interval(n, mean, sd, t_quantile(n, confidence) * sd / math.sqrt(n))


def decide(values: Sequence[float] | np.ndarray, target: Target,
           confidence: float = CONFIDENCE) -> str:
    """'meets', 'fails' or 'undecided': where the interval (95 % unless said) lies against the
    bound."""
    x = np.asarray(values, dtype=float)
    if len(x) == 0:
        return "undecided"
    if np.isnan(x).any():
        return "fails"  # a replication without a value (nothing delivered) cannot meet it
    ci = mean_ci(x, confidence)
    if ci.n < 2:
        return "undecided"
    good_low, good_high = (ci.low, ci.high) if target.higher_is_better else (-ci.high, -ci.low)
    bound = target.bound if target.higher_is_better else -target.bound
    if good_low >= bound:
        return "meets"
    if good_high < bound:
        return "fails"
    return "undecided"


def replications_needed(sd: float, distance: float, n_now: int = 2,
                        confidence: float = CONFIDENCE) -> int | None:
    """Smallest n >= max(2, n_now) whose interval half-width is below `distance`; None if the
    mean sits on the bound (no n decides) or more than MAX_REPLICATIONS_ADVISED would be needed."""
    distance = abs(distance)
    if distance == 0 or math.isnan(distance) or math.isnan(sd):
        return None
    n = max(2, n_now)
    while n <= MAX_REPLICATIONS_ADVISED:
        if t_quantile(n, confidence) * sd / math.sqrt(n) < distance:
            return n
        n += 1
    return None


MSER_BATCH = 5


def mser5_truncation(values: Sequence[float] | np.ndarray) -> int:
    """How many leading observations of `values` to delete as warm-up (a multiple of 5),
    by MSER-5; 0 for a series shorter than two batches."""
    x = np.asarray(values, dtype=float)
    k = len(x) // MSER_BATCH
    if k < 2:
        return 0
    z = x[:k * MSER_BATCH].reshape(k, MSER_BATCH).mean(axis=1)
    scores = [float(((z[d:] - z[d:].mean()) ** 2).sum()) / (k - d) ** 2
              for d in range(k // 2 + 1)]
    return int(np.argmin(scores)) * MSER_BATCH  # argmin: the first of equal minima


def kpi_columns(summary: pd.DataFrame, factor_names: Sequence[str]) -> list[str]:
    """Numeric KPI columns of a sweep summary."""
    skip = set(factor_names) | NOT_KPIS
    return [c for c in summary.columns
            if c not in skip and pd.api.types.is_numeric_dtype(summary[c])
            and not pd.api.types.is_bool_dtype(summary[c])]


def _ok(summary: pd.DataFrame) -> pd.DataFrame:
    if "status" not in summary.columns:
        return summary
    return summary[summary["status"] == "ok"]


def point_stats(summary: pd.DataFrame, factor_names: Sequence[str]) -> pd.DataFrame:
    """Long table: one row per design point and KPI with n, mean, sd and the 95 % interval."""
    ok = _ok(summary)
    columns = [*factor_names, "kpi", "n", "mean", "sd", "half_width", "ci_low", "ci_high"]
    if ok.empty:
        return pd.DataFrame({c: pd.Series(dtype="float64") for c in columns})
    rows: list[dict[str, Any]] = []
    kpis = kpi_columns(ok, factor_names)
    groups = ok.groupby(list(factor_names), sort=True, dropna=False) if factor_names \
        else [((), ok)]
    for key, group in groups:
        values = key if isinstance(key, tuple) else (key,)
        for kpi in kpis:
            ci = mean_ci(group[kpi].to_numpy(dtype=float, na_value=np.nan))
            rows.append({**dict(zip(factor_names, values, strict=True)), "kpi": kpi,
                         "n": ci.n, "mean": ci.mean, "sd": ci.sd, "half_width": ci.half_width,
                         "ci_low": ci.low, "ci_high": ci.high})
    return pd.DataFrame(rows, columns=columns)


@dataclass(frozen=True)
class PointPair:
    """Two design points that differ in one factor: `factor` goes from `from_level` to
    `to_level`, the other factors stay at `fixed`."""

    factor: str
    from_level: Any
    to_level: Any
    fixed: dict[str, Any]

    def point(self, level: Any) -> dict[str, Any]:
        return {**self.fixed, self.factor: level}


def is_number(value: Any) -> bool:
    """A level that is a number (not true/false): its factor's pairs are adjacent levels."""
    return isinstance(value, (int, float, np.integer, np.floating)) \
        and not isinstance(value, (bool, np.bool_))


def one_factor_pairs(summary: pd.DataFrame, factor_names: Sequence[str],
                     factors: Sequence[str] | None = None,
                     listed: Mapping[str, Sequence[Any]] | None = None) -> list[PointPair]:
    """The pairs of design points of `summary` (finished runs) that differ in one factor (each
    of `factors`, default every factor): adjacent levels of a numeric factor, every level
    against the first of any other (the first `listed` for it in the experiment file, else
    the first in the summary), each at every combination of the other factors."""
    ok = _ok(summary)
    pairs: list[PointPair] = []
    for factor in factors if factors is not None else factor_names:
        if factor not in ok.columns:
            continue
        others = [f for f in factor_names if f != factor]
        groups = ok.groupby(others, sort=True, dropna=False) if others else [((), ok)]
        for key, group in groups:
            fixed = dict(zip(others, key if isinstance(key, tuple) else (key,), strict=True))
            levels = list(dict.fromkeys(group[factor].tolist()))
            if len(levels) < 2:
                continue
            if all(is_number(v) for v in levels):
                ordered = sorted(levels)
                steps = list(itertools.pairwise(ordered))
            else:
                order = [level_text(v) for v in (listed or {}).get(factor, [])]
                rank = {k: i for i, k in enumerate(order)}
                ordered = sorted(levels, key=lambda v: rank.get(level_text(v), len(rank)))
                steps = [(ordered[0], other) for other in ordered[1:]]
            pairs += [PointPair(factor, a, b, fixed) for a, b in steps]
    return pairs


def _at(frame: pd.DataFrame, point: Mapping[str, Any]) -> pd.DataFrame:
    mask = np.ones(len(frame), dtype=bool)
    for name, value in point.items():
        column = frame[name]
        if value is None or (isinstance(value, float) and math.isnan(value)):
            mask &= column.isna().to_numpy()
        else:
            mask &= (column == value).fillna(False).to_numpy(dtype=bool)
    return frame[mask]


@dataclass(frozen=True)
class PairDifference:
    """KPI at `to` minus KPI at `from`, replication by replication: the interval of the
    differences, and each point's mean over the same pairs."""

    kpi: str
    from_mean: float
    to_mean: float
    interval: Interval

    @property
    def pairs(self) -> int:
        return self.interval.n

    @property
    def excludes_zero(self) -> bool:
        ci = self.interval
        return ci.n >= 2 and not math.isnan(ci.half_width) and (ci.low > 0 or ci.high < 0)


def pair_difference(summary: pd.DataFrame, from_point: Mapping[str, Any],
                    to_point: Mapping[str, Any], kpi: str,
                    confidence: float = CONFIDENCE) -> PairDifference:
    """`kpi` at design point `to_point` minus at `from_point` (any two points of the summary),
    paired by replication: the replications both ran with a value on both sides."""
    ok = _ok(summary)
    nan = PairDifference(kpi, math.nan, math.nan, Interval(0, math.nan, math.nan, math.nan))
    if kpi not in ok.columns:
        return nan
    left = _at(ok, from_point).drop_duplicates("replication").set_index("replication")[kpi]
    right = _at(ok, to_point).drop_duplicates("replication").set_index("replication")[kpi]
    common = left.index.intersection(right.index).sort_values()
    a = left.loc[common].to_numpy(dtype=float, na_value=np.nan)
    b = right.loc[common].to_numpy(dtype=float, na_value=np.nan)
    keep = ~(np.isnan(a) | np.isnan(b))
    if not keep.any():
        return nan
    return PairDifference(kpi, float(a[keep].mean()), float(b[keep].mean()),
                          mean_ci(b[keep] - a[keep], confidence))


def factor_effect(summary: pd.DataFrame, factor_names: Sequence[str], factor: str,
                  from_level: Any, to_level: Any, kpi: str,
                  confidence: float = CONFIDENCE) -> PairDifference:
    """What moving `factor` from `from_level` to `to_level` does to `kpi`, averaged over the
    levels of the other factors, paired by replication: replication r's difference is the mean
    over the other factors' combinations of (KPI at to_level - KPI at from_level), over the
    replications that ran, with a value, at both levels in every combination that has both.
    With no other factor it is `pair_difference`."""
    ok = _ok(summary)
    nan = PairDifference(kpi, math.nan, math.nan, Interval(0, math.nan, math.nan, math.nan))
    if kpi not in ok.columns or factor not in ok.columns:
        return nan
    others = [f for f in factor_names if f != factor]
    groups = ok.groupby(others, sort=True, dropna=False) if others else [((), ok)]
    sides: list[tuple[pd.Series, pd.Series]] = []
    for _, group in groups:
        at_a = _at(group, {factor: from_level}).drop_duplicates("replication")
        at_b = _at(group, {factor: to_level}).drop_duplicates("replication")
        if len(at_a) and len(at_b):
            sides.append((at_a.set_index("replication")[kpi].astype(float),
                          at_b.set_index("replication")[kpi].astype(float)))
    if not sides:
        return nan
    common = sides[0][0].index
    for one, other in sides:
        common = common.intersection(one.index).intersection(other.index)
    common = common.sort_values()
    left = np.array([x.loc[common].to_numpy(dtype=float, na_value=np.nan) for x, _ in sides])
    right = np.array([y.loc[common].to_numpy(dtype=float, na_value=np.nan) for _, y in sides])
    keep = ~(np.isnan(left).any(axis=0) | np.isnan(right).any(axis=0))
    if not keep.any():
        return nan
    left, right = left[:, keep].mean(axis=0), right[:, keep].mean(axis=0)
    return PairDifference(kpi, float(left.mean()), float(right.mean()),
                          mean_ci(right - left, confidence))


def paired_differences(summary: pd.DataFrame, factor_names: Sequence[str], kpis: Sequence[str],
                       factors: Sequence[str] | None = None,
                       listed: Mapping[str, Sequence[Any]] | None = None,
                       confidence: float = CONFIDENCE) -> pd.DataFrame:
    """Long table: one row per pair of design points differing in one factor
    (`one_factor_pairs`) and KPI, with each point's mean over the pairs and the mean and
    interval of the paired difference (to - from). The other factors' columns hold the levels
    they are fixed at (empty, None or NaN, in the column of the factor that varies)."""
    columns = [*factor_names, "factor", "from_level", "to_level", "kpi", "pairs", "from_mean",
               "to_mean", "mean_diff", "half_width", "ci_low", "ci_high"]
    rows: list[dict[str, Any]] = []
    for pair in one_factor_pairs(summary, factor_names, factors, listed):
        for kpi in kpis:
            diff = pair_difference(summary, pair.point(pair.from_level),
                                   pair.point(pair.to_level), kpi, confidence)
            ci = diff.interval
            rows.append({**{f: pair.fixed.get(f) for f in factor_names}, "factor": pair.factor,
                         "from_level": pair.from_level, "to_level": pair.to_level, "kpi": kpi,
                         "pairs": ci.n, "from_mean": diff.from_mean, "to_mean": diff.to_mean,
                         "mean_diff": ci.mean, "half_width": ci.half_width, "ci_low": ci.low,
                         "ci_high": ci.high})
    return pd.DataFrame(rows, columns=columns)


@dataclass(frozen=True)
class TargetCheck:
    """One design point against one target."""

    point: dict[str, Any]
    target: Target
    decision: str
    interval: Interval
    needed: int | None
    """Replications that would decide an undecided point (None: none would, or decided)."""

    def warning(self) -> str | None:
        if self.decision != "undecided":
            return None
        where = point_text(self.point) or "the scenario"
        ci = self.interval
        if ci.n < 2:
            return (f"{where}: {self.target.describe()} cannot be decided from {ci.n} "
                    "replication: run at least 2")
        text = (f"{where}: the 95 % CI of {self.target.kpi} [{ci.low:.4g}, {ci.high:.4g}] "
                f"straddles the target ({self.target.describe()}) with {ci.n} replications")
        if self.needed is None:
            return text + "; the mean sits on the bound, so more replications will not decide it"
        return text + f"; about {self.needed} replications would narrow it enough to decide"


def check_targets(summary: pd.DataFrame, factor_names: Sequence[str],
                  targets: Sequence[Target]) -> list[TargetCheck]:
    """Every design point against every target."""
    ok = _ok(summary)
    checks: list[TargetCheck] = []
    if ok.empty:
        return checks
    groups = ok.groupby(list(factor_names), sort=True, dropna=False) if factor_names \
        else [((), ok)]
    for key, group in groups:
        point = dict(zip(factor_names, key if isinstance(key, tuple) else (key,), strict=True))
        for target in targets:
            if target.kpi in group:
                values = group[target.kpi].to_numpy(dtype=float, na_value=np.nan)
                age = OPEN_AGE_OF.get(target.kpi)  # a lead time: the open orders' age too
                if age is not None and age in group:
                    values = np.fmax(values, group[age].to_numpy(dtype=float,
                                                                 na_value=np.nan))
            elif target.kpi in COUNTS_BY_CODE:  # no run raised that code: zero times
                values = np.zeros(len(group))
            else:
                values = np.array([np.nan])
            checks.append(target_check(point, target, values))
    return checks


def target_check(point: dict[str, Any], target: Target, values: np.ndarray,
                 confidence: float = CONFIDENCE) -> TargetCheck:
    """The point against the target at `confidence` (decision, interval and replications
    needed all at that level)."""
    decision = decide(values, target, confidence)
    ci = mean_ci(values, confidence)
    needed = None
    if decision == "undecided" and ci.n >= 2:
        needed = replications_needed(ci.sd, ci.mean - target.bound, ci.n + 1, confidence)
    return TargetCheck(point, target, decision, ci, needed)
