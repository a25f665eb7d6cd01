"""What `fleet-sim size` and `fleet-sim optimise` share: one machinery for searching designs.

* The run budget (`RunBudget`): the distinct runs a search uses, held to the run limit of one
  experiment (MAX_RUNS); asking for more stops the search with `RunLimit`, what was decided
  so far kept.
* Searches side by side (`run_searches`): each search is a generator that yields the batch
  of runs it needs next and returns its result; the batches asked for at the same step run as
  one, so the workers stay busy while each search waits for its own few runs.
* The search along one count (`ordered_search`): from a start, step away (1, 2, 4 ...) until a
  count meets and a smaller one does not, then bisect. It assumes more AGVs never make a target
  worse; `size` searches the fleet with it, `optimise` each combination of the other decisions
  when the experiment file turns that assumption on.
* Reading what runs measured (`run_values`): each target's KPI per replication, from the run
  folders, lead times counting open orders' age (fleet_sim.analysis.kpis.target_value).

Seeds are the experiment's (fleet_sim.config.experiment: replication r has the same seed in
every design, common random numbers), and runs go through fleet_sim.study.runner, so a search
reuses every run a sweep, a sizing search or a comparison already made in the same folder.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Generator, Sequence
from pathlib import Path
from typing import TypeVar

from fleet_sim.analysis.kpis import target_value
from fleet_sim.config.experiment import MAX_RUNS, RunSpec
from fleet_sim.errors import FleetSimError
from fleet_sim.study.pools import DaskPool, LocalPool
from fleet_sim.study.runner import execute

Result = TypeVar("Result")
Search = Generator[list[RunSpec], None, Result]
"""A search: yields the batches of runs it needs, returns its result."""


class RunLimit(FleetSimError):
    """The search would need more runs than one experiment may have."""


class RunBudget:
    """The distinct runs a search has used, at most `limit` of them."""

    def __init__(self, limit: int = MAX_RUNS, study: str = "sizing search",
                 output: str = "sizing.json", advice: str = "",
                 error: type[RunLimit] = RunLimit) -> None:
        self.limit = limit
        self.study = study
        self.output = output
        self.advice = advice
        self.error = error
        """What taking too many raises (the study's own kind of RunLimit)."""
        self.used: set[str] = set()

    def take(self, runs: Sequence[RunSpec]) -> None:
        """Count `runs` in, or raise the budget's RunLimit (counting none of them) if they
        would take the search over the limit."""
        new = {r.run_id for r in runs} - self.used
        if len(self.used) + len(new) > self.limit:
            raise self.error(
                f"the {self.study} stopped: it needs more than {self.limit} runs, the limit "
                f"of one experiment (it has used {len(self.used)} and asked for {len(new)} "
                f"more); {self.output} keeps what was decided so far. {self.advice}".rstrip())
        self.used |= new


Request = TypeVar("Request")


def side_by_side(searches: Sequence[Generator[list[Request], None, Result]]
                 ) -> Generator[list[Request], None, list[Result]]:
    """Several searches as one: each step yields the requests of every search still running,
    joined in the searches' order; once the caller has made them (and resumes this), every
    search that asked looks again. Returns their results in order."""
    results: list[Result | None] = [None] * len(searches)
    wanted: dict[int, list[Request]] = {}

    def advance(i: int) -> None:
        try:
            wanted[i] = next(searches[i])
        except StopIteration as done:
            results[i] = done.value
            wanted.pop(i, None)

    for i in range(len(searches)):
        advance(i)
    while wanted:
        yield [item for i in sorted(wanted) for item in wanted[i]]
        for i in sorted(wanted):
            advance(i)
    return [r for r in results if r is not None]


def drive(search: Generator[list[Request], None, Result],
          run_batch: Callable[[list[Request]], None]) -> Result:
    """Run `search` to its end, handing each batch it asks for to `run_batch`."""
    try:
        batch = next(search)
        while True:
            run_batch(batch)
            batch = search.send(None)
    except StopIteration as done:
        return done.value  # type: ignore[no-any-return]


def run_searches(searches: Sequence[Search[Result]], out_dir: Path,
                 pool: LocalPool | DaskPool) -> list[Result]:
    """Drive searches that ask for runs: each step's batches run as one on `pool`, so the
    workers stay busy while each search waits for its own few runs."""
    def run_batch(batch: list[RunSpec]) -> None:
        execute(batch, out_dir, quiet=True, pool=pool)

    return drive(side_by_side(searches), run_batch)


Ask = TypeVar("Ask")
"""What a search yields while it waits: the runs it needs (size), a design to take further
(optimise)."""


def ordered_search(meets: Callable[[int], Generator[Ask, None, bool]], start: int,
                   lo_limit: int, hi_limit: int) -> Generator[Ask, None, int | None]:
    """The smallest count in lo_limit..hi_limit that meets, assuming a larger count never
    meets less: from `start`, step down (1, 2, 4 ...) while counts meet, or up until one
    does, then bisect between the largest count known not to meet and the smallest known to.
    `meets(n)` is a search of its own: it yields what it needs (runs) and returns whether
    count n meets. None: no count up to hi_limit meets."""
    lo = lo_limit - 1  # largest count known not to meet (lo_limit - 1: none below)
    hi: int | None = None  # smallest count known to meet
    if (yield from meets(start)):
        hi, step = start, 1
        while hi - step >= lo_limit:
            probe = hi - step
            if (yield from meets(probe)):
                hi, step = probe, step * 2
            else:
                lo = probe
                break
    else:
        lo, step = start, 1
        while lo < hi_limit:
            probe = min(lo + step, hi_limit)
            if (yield from meets(probe)):
                hi = probe
                break
            lo, step = probe, step * 2
    if hi is None:
        return None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if (yield from meets(mid)):
            hi = mid
        else:
            lo = mid
    return hi


def run_kpis(out_dir: Path, spec: RunSpec, kpis: Sequence[str]) -> list[float] | None:
    """What one run measured of each KPI (NaN: the run does not report it, such as a p95
    lead time with nothing delivered); None if the run did not finish (no kpis.json)."""
    kpi_file = out_dir / "runs" / spec.run_id / "kpis.json"
    if not kpi_file.exists():
        return None
    figures = json.loads(kpi_file.read_text(encoding="utf-8"))
    out = []
    for kpi in kpis:
        value = target_value(figures, kpi)  # lead times: open orders' age too
        out.append(math.nan if value is None else float(value))
    return out


def run_values(out_dir: Path, runs: Sequence[RunSpec], kpis: Sequence[str]
               ) -> tuple[dict[str, dict[int, float]], int]:
    """Per KPI: replication -> value, over the runs (of one design) that finished; and how
    many runs did not finish."""
    values: dict[str, dict[int, float]] = {kpi: {} for kpi in kpis}
    failed = 0
    for spec in runs:
        measured = run_kpis(out_dir, spec, kpis)
        if measured is None:
            failed += 1
            continue
        for kpi, value in zip(kpis, measured, strict=True):
            values[kpi][spec.replication] = value
    return values, failed
