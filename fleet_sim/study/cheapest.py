"""The cheapest feasible design: a fully sequential procedure over designs in order of price.

Pure: it asks for replications of designs and is handed their values; `fleet-sim optimise`
(fleet_sim.study.optimise) turns its requests into runs, the tests into draws from known
distributions. docs/background/design-optimisation.md has the procedure and its guarantee.

Every design's feasibility is the fully sequential check of fleet_sim.analysis.feasibility
(Batur and Kim's F_B), each check at error beta = (1 - confidence) / (designs x targets x
levels), so that with probability at least `confidence` every design checked is judged right
where it is clear of its bounds by the tolerance. Then, as in Andradóttir and Kim's (2010)
procedures for constrained selection with a deterministic primary objective (here the price):
a design costlier than one shown to meet is not needed and never run, and the answer is the
cheapest design shown to meet once every cheaper design is shown to fail. Hence the guarantee:
the design named meets every target within its tolerance, and no cheaper design meets them
all by more than the tolerance.

Two orders of examination, the same answer when their assumption holds:

* by price (default): the cheapest open designs first, as many side by side as there are
  workers; a design gets min_replications, then one more at a time (more when fewer designs
  than workers are open), until decided or at max_replications (undecided).
* ``more_agvs_never_worse``: for each combination of the other decisions, the AGV count is
  searched as `fleet-sim size` searches a fleet (fleet_sim.study.search.ordered_search: step
  up from the smallest count the analytic estimate allows, then bisect); a design that fails
  marks every smaller count of its combination as failing (inferred), and a design costlier
  than one that meets counts as meeting (not needed: look below it). The combinations are
  searched side by side. The designs next to the answer (one AGV more, one fewer) are then
  checked, and optimise.json says whether they agree with the assumption.

A design's verdict depends only on its own replications (seeds shared by every design), not on
the order of examination or the batches: the answer is the same on any number of workers,
and an interrupted search that is run again asks for the same runs.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Hashable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from fleet_sim.analysis.feasibility import Constraint, Verdict, check
from fleet_sim.study.search import drive, ordered_search

Request = list[tuple[int, int]]
"""(design, replication) pairs to run."""

OPEN = "open"
MEETS = "meets"
FAILS = "fails"
UNDECIDED = "undecided"
NOT_NEEDED = "not needed"
RULED_OUT = "ruled out"


@dataclass
class DesignState:
    """What the procedure knows of one design."""

    price: float
    status: str = OPEN
    reason: str = ""
    rows: dict[int, np.ndarray] = field(default_factory=dict)
    """Replication -> its values, one per constraint (NaN: none)."""
    asked: int = 0
    verdict: Verdict | None = None
    inferred_from: int | None = None
    """A design whose failure made this one fail by the assumption."""

    def values(self, width: int) -> np.ndarray:
        """The replications asked for so far, in order (replications x `width` constraints)."""
        rows = [self.rows[r] for r in range(self.asked) if r in self.rows]
        return np.array(rows, dtype=float).reshape(len(rows), width)


@dataclass(frozen=True)
class Structure:
    """The AGV-count axis of the design space, for `more_agvs_never_worse`."""

    rest: Sequence[Hashable]
    """Per design: its other decisions (designs with equal rest differ only in the count)."""
    count: Sequence[int]
    """Per design: its AGV count."""


class CheapestSearch:
    """The procedure on designs with known prices; `run` yields requests, `record` takes the
    values that come back."""

    def __init__(self, prices: Sequence[float], constraints: Sequence[Constraint], n0: int,
                 max_replications: int, h2: float, width: int = 1,
                 structure: Structure | None = None,
                 ruled_out: Mapping[int, str] | None = None) -> None:
        self.states = [DesignState(float(p)) for p in prices]
        for i, reason in (ruled_out or {}).items():
            self.states[i].status = RULED_OUT
            self.states[i].reason = reason
        self.constraints = list(constraints)
        self.n0 = n0
        self.max_replications = max_replications
        self.h2 = h2
        self.width = max(1, width)
        self.structure = structure
        self.order = sorted(range(len(prices)), key=lambda i: (self.states[i].price, i))
        self.rank = {i: k for k, i in enumerate(self.order)}
        self.checks: dict[int, str] = {}
        """Designs run only to check the assumption -> their verdict."""

    # ---- what is known

    def record(self, design: int, replication: int, values: Sequence[float]) -> None:
        self.states[design].rows[replication] = np.asarray(values, dtype=float)

    def incumbent(self) -> int | None:
        """The cheapest design shown to meet."""
        met = [i for i in self.order if self.states[i].status == MEETS]
        return met[0] if met else None

    def answer(self) -> int | None:
        return self.incumbent()

    def cheaper(self, i: int, j: int) -> bool:
        return self.rank[i] < self.rank[j]

    def _decide(self, i: int) -> None:
        st = self.states[i]
        values = st.values(len(self.constraints))
        verdict = check(values, self.constraints, self.n0, self.h2)
        st.verdict = verdict
        if verdict.decision in (MEETS, FAILS):
            st.status = verdict.decision
        elif st.asked >= self.max_replications:
            st.status = UNDECIDED
            st.reason = f"undecided at {self.max_replications} replications"

    def _prune(self) -> None:
        best = self.incumbent()
        if best is None:
            return
        for i in self.order:
            if self.states[i].status == OPEN and self.cheaper(best, i):
                self.states[i].status = NOT_NEEDED
                self.states[i].reason = "a cheaper design meets every target"

    def _next(self, i: int, step: int) -> Request:
        st = self.states[i]
        want = self.n0 if st.asked == 0 else min(self.max_replications, st.asked + step)
        request = [(i, r) for r in range(st.asked, want)]
        st.asked = want
        return request

    # ---- the search

    def run(self) -> Generator[Request, None, int | None]:
        """The search: yields requests (the caller records their values before resuming),
        returns the design named (None: no design shown to meet)."""
        if self.structure is None:
            yield from self._by_price()
        else:
            yield from self._by_count()
        self._prune()  # what the count searches never reached above the answer
        return self.answer()

    def _by_price(self) -> Generator[Request, None, None]:
        """Every design its own search, examined cheapest first."""
        yield from self._schedule([self._until_decided(i) for i in self.order
                                   if self.states[i].status == OPEN])

    def _by_count(self) -> Generator[Request, None, None]:
        """One search along the AGV count per combination of the other decisions."""
        assert self.structure is not None
        groups: dict[Hashable, dict[int, int]] = {}
        for i in self.order:
            rest, n = self.structure.rest[i], self.structure.count[i]
            if self.states[i].status != RULED_OUT:
                groups.setdefault(rest, {})[n] = i
        yield from self._schedule([self._group(members) for members in groups.values()
                                   if members])

    def _schedule(self, searches: Sequence[Generator[int, None, object]]
                  ) -> Generator[Request, None, None]:
        """Searches that each ask for one design at a time to be taken further: at each step,
        the cheapest designs asked for (as many as there are workers) get their next
        replications; a design asked for that a cheaper design's success has made not needed
        is not run, and its search looks again at once. Searches not served wait."""
        wants: dict[int, int] = {}

        def advance(k: int) -> None:
            try:
                wants[k] = next(searches[k])
            except StopIteration:
                wants.pop(k, None)

        for k in range(len(searches)):
            advance(k)
        while wants:
            best = self.incumbent()
            spared = [k for k, i in wants.items() if best is not None and self.cheaper(best, i)]
            if spared:
                for k in spared:
                    st = self.states[wants[k]]
                    if st.status == OPEN:
                        st.status, st.reason = NOT_NEEDED, "a cheaper design meets every target"
                    advance(k)
                continue
            chosen = sorted(wants.items(), key=lambda kv: self.rank[kv[1]])[:self.width]
            designs = list(dict.fromkeys(i for _, i in chosen))
            step = max(1, self.width // len(designs))
            yield [pair for i in designs for pair in self._next(i, step)]
            for i in designs:
                self._decide(i)
            for k, _ in chosen:
                advance(k)

    def _until_decided(self, i: int) -> Generator[int, None, bool]:
        """A design's own search: asks for it until it is decided (or not needed)."""
        while self.states[i].status == OPEN:
            yield i
        return self.states[i].status == MEETS

    def _group(self, members: dict[int, int]) -> Generator[int, None, int | None]:
        """One combination's search along the AGV count."""
        counts = sorted(members)

        def meets(n: int) -> Generator[int, None, bool]:
            i = members.get(n)
            if i is None:  # a count between the levels (a range with a step): not a design
                return False
            st = self.states[i]
            yield from self._until_decided(i)
            if st.status == FAILS:
                for m in counts:
                    j = members[m]
                    if m < n and self.states[j].status == OPEN:
                        self.states[j].status = FAILS
                        self.states[j].inferred_from = i
                        self.states[j].reason = (f"fails by more_agvs_never_worse: {n} AGVs "
                                                 "with the same choices fail")
            return st.status in (MEETS, NOT_NEEDED)

        found = yield from ordered_search(meets, counts[0], counts[0], counts[-1])
        return found

    def check_neighbours(self) -> Generator[Request, None, list[dict[str, object]]]:
        """Under the assumption: run the designs next to the answer (one AGV more, one fewer,
        the same other choices) to a decision, and say whether they agree."""
        answer = self.answer()
        if self.structure is None or answer is None:
            return []
        rest, n = self.structure.rest[answer], self.structure.count[answer]
        by_count = {self.structure.count[i]: i for i in range(len(self.states))
                    if self.structure.rest[i] == rest}
        out: list[dict[str, object]] = []
        for other, expect in ((n - 1, FAILS), (n + 1, MEETS)):
            j = by_count.get(other)
            if j is None or self.states[j].status == RULED_OUT:
                continue
            st = self.states[j]
            if st.status not in (MEETS, FAILS) or st.inferred_from is not None:
                while True:
                    verdict = check(st.values(len(self.constraints)), self.constraints,
                                    self.n0, self.h2)
                    if verdict.decision != UNDECIDED or st.asked >= self.max_replications:
                        break
                    yield self._next(j, self.width if st.asked else 1)
                st.verdict = verdict
                seen = verdict.decision
                self.checks[j] = seen
            else:
                seen = st.status
            out.append({"design": j, "agvs": other, "expected": expect, "seen": seen,
                        "agrees": seen in (expect, UNDECIDED)})
        return out


def simulate(search: CheapestSearch, sample: Callable[[int, int], Sequence[float]]
             ) -> int | None:
    """Run `search` to its end, drawing each requested replication from `sample(design,
    replication)` (the tests' known designs)."""

    def run_batch(request: Request) -> None:
        for i, r in request:
            search.record(i, r, sample(i, r))

    return drive(search.run(), run_batch)
