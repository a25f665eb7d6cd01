"""Feasibility of a design against stochastic constraints: a fully sequential check with a
stated probability of correct decision (docs/background/design-optimisation.md).

The check is Batur and Kim's procedure F_B (ACM TOMACS 20(3), 2010): Andradóttir, Goldsman
and Kim's (2005) one-constraint check on every constraint, the error split over the
constraints and, because the designs share their seeds (common random numbers), over the
designs by Bonferroni, as Healey, Andradóttir and Kim (ACM TOMACS 24(3), 2014) do under
correlated sampling. For a constraint "mean <= q" (an ``at_least`` target is turned round)
with tolerance epsilon, after r replications of a design::

    D(r) = sum_{j <= r} (Y_j - q)
    R(r) = max(0, h^2 S^2 / (2 epsilon) - epsilon r / 2)

where S^2 is the variance of the first n0 replications and h^2 = (n0 - 1)((2 beta)^(-2/(n0-1))
- 1) solves 1/2 (1 + 2 eta)^(-(n0 - 1)/2) = beta (the triangular region of Fabian 1974 as the
papers use it, c = 1). D(r) <= -R(r): the constraint is met; D(r) >= R(r): the design fails;
else one replication more. A design meets once every constraint is met and fails at the first
that fails.

The guarantee: a design whose every mean is on the good side of its bound by at least the
tolerance (desirable) is declared to meet, and one with a mean on the bad side by at least the
tolerance (unacceptable) is declared to fail, each wrong with probability at most beta per
constraint. Designs in between (acceptable) may go either way.

Relaxed tolerances (after the indifference-zone relaxation of Kim, Andradóttir, Kim and Zhou,
arXiv 2509.04514, 2025): a design far from its bound is decided sooner by the same check at a
wider tolerance e_m = epsilon x 4^m with a shifted bound, so that its only possible wrong
answer is still judged at the planner's tolerance: a "fails" at level m uses the bound
q - epsilon + e_m (wrong only if mean <= q - epsilon: a desirable design), a "meets" at level
m the bound q + epsilon - e_m (wrong only if mean >= q + epsilon). For a given mean only one
kind of error is possible, so the levels share beta: each level gets beta / LEVELS.

A replication without a value (nothing delivered: no p95 lead time) fails its constraint.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

LEVELS = 3
"""Tolerance levels epsilon, 4 epsilon, 16 epsilon (the widest decides far designs early)."""
LEVEL_FACTOR = 4.0


def fb_h2(n0: int, beta: float) -> float:
    """h^2 = 2 eta (n0 - 1), where 1/2 (1 + 2 eta)^(-(n0 - 1)/2) = beta."""
    if n0 < 2:
        raise ValueError("the first stage needs at least 2 replications")
    if not 0 < beta < 0.5:
        raise ValueError(f"beta {beta} is not in (0, 0.5)")
    return float((n0 - 1) * ((2.0 * beta) ** (-2.0 / (n0 - 1)) - 1.0))


def error_per_check(confidence: float, designs: int, constraints: int) -> float:
    """beta of each constraint's check at each tolerance level: the error 1 - confidence split
    by Bonferroni over the designs (they share seeds), the constraints and the levels."""
    return (1.0 - confidence) / (max(designs, 1) * max(constraints, 1) * LEVELS)


@dataclass(frozen=True)
class Constraint:
    """A target as the check sees it: the bound, which side is good, the tolerance."""

    bound: float
    at_least: bool
    tolerance: float

    def bad_side(self, values: np.ndarray) -> np.ndarray:
        """Values turned so that the constraint reads mean <= bound."""
        return -values if self.at_least else values

    @property
    def turned_bound(self) -> float:
        return -self.bound if self.at_least else self.bound


@dataclass(frozen=True)
class ConstraintDecision:
    decision: str
    """meets, fails or undecided."""
    at: int
    """Replications at which it was decided (or the replications seen when undecided)."""
    level: int
    """The tolerance level that decided it (0: the planner's tolerance), -1 undecided."""


@dataclass(frozen=True)
class Verdict:
    """One design's check on the replications it has."""

    decision: str
    """meets, fails, or undecided (needs more replications)."""
    at: int
    """Replications at which it was decided: the largest of the constraints' when it meets,
    the first failing constraint's when it fails; the replications seen when undecided."""
    constraints: tuple[ConstraintDecision, ...]


def check(values: np.ndarray, constraints: Sequence[Constraint], n0: int, h2: float) -> Verdict:
    """The fully sequential check of one design on `values` (replications x constraints, in
    replication order; NaN: no value), walked from replication n0 on. With fewer than n0
    replications nothing is decided."""
    x = np.asarray(values, dtype=float)
    n = x.shape[0]
    if n < n0:
        return Verdict("undecided", n, tuple(ConstraintDecision("undecided", n, -1)
                                           for _ in constraints))
    decisions = [_one(x[:, i], c, n0, h2) for i, c in enumerate(constraints)]
    fails = [d for d in decisions if d.decision == "fails"]
    if fails:
        first = min(d.at for d in fails)
        # a constraint that would fail later is not looked at after the design failed
        shown = tuple(d if d.decision != "fails" or d.at == first
                      else ConstraintDecision("undecided", first, -1) for d in decisions)
        shown = tuple(d if d.decision != "meets" or d.at <= first
                      else ConstraintDecision("undecided", first, -1) for d in shown)
        return Verdict("fails", first, shown)
    if all(d.decision == "meets" for d in decisions):
        return Verdict("meets", max(d.at for d in decisions), tuple(decisions))
    return Verdict("undecided", n, tuple(decisions))


def _one(y: np.ndarray, c: Constraint, n0: int, h2: float) -> ConstraintDecision:
    """One constraint's sequential check at every tolerance level; the first decision wins
    (at the same replication, fails before meets: erring towards more money)."""
    n = len(y)
    if np.isnan(y[:n0]).any():
        return ConstraintDecision("fails", n0, 0)
    turned = c.bad_side(y)
    q = c.turned_bound
    eps = c.tolerance
    s2 = float(np.var(turned[:n0], ddof=1))
    cums = np.cumsum(turned)
    for r in range(n0, n + 1):
        if math.isnan(turned[r - 1]):
            return ConstraintDecision("fails", r, 0)
        total = float(cums[r - 1])
        for level in range(LEVELS - 1, -1, -1):  # the widest first: same answer, said sooner
            e = eps * LEVEL_FACTOR ** level
            half = max(0.0, h2 * s2 / (2 * e) - e * r / 2)
            fail_q = q - eps + e
            if total - r * fail_q >= half:
                return ConstraintDecision("fails", r, level)
            meet_q = q + eps - e
            if total - r * meet_q <= -half:
                return ConstraintDecision("meets", r, level)
    return ConstraintDecision("undecided", n, -1)


def largest_replications(s2: float, tolerance: float, h2: float) -> int:
    """Replications after which the planner's tolerance level must decide (R(r) = 0)."""
    if tolerance <= 0:
        return 10**9
    return max(1, math.ceil(h2 * s2 / tolerance ** 2))
