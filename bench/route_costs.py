"""What do congestion-aware route searches cost, before and after issue 35 made them quicker?
Each case runs the fulfilment centre's shift (experiments/fulfilment_shift.yaml: 2,059 nodes,
congestion priced at 10 s an AGV, reactive traffic unless --policy) at so many AGVs, twice per
repeat, interleaved: `before`, with every costed search done by the plain A* and a call per
segment for its extra cost (`Routes._a_star` with `SegmentCosts.extra_s`, the search as it was
at 1c3dcfa), and `after`, as the engine does it now (`Routes._a_star_costed`). It prints the
medians of --repeats: wall seconds per simulated hour, the seconds a simulated hour spends in
costed searches (each destination's free-flow table, built once on first asking, left out) and
their share of the run, the searches an hour, and whether both runs gave the same events (they
must: the same routes). The machine's load is printed at start and end; these machines are
shared and noisy, so compare figures within one run of this script only.

    .venv/bin/python bench/route_costs.py [--agvs 50 200] [--hours 1] [--repeats 3]
        [--orders-per-agv-hour 5] [--policy reactive]
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import build_simulation  # noqa: E402
from fleet_sim.sim.traffic.routing import NO_EDGES, Routes, SegmentCosts  # noqa: E402

SCENARIO = ROOT / "experiments" / "fulfilment_shift.yaml"


class SearchClock:
    """Wall seconds spent in `Routes.route_costed`, less the free-flow tables built inside it."""

    def __init__(self) -> None:
        self.search_s = 0.0
        self.table_s = 0.0
        self.searches = 0
        self._depth = 0

    @contextmanager
    def installed(self, plain: bool) -> Iterator[None]:
        """Route every costed search through the clock (by the plain A* if `plain`)."""
        costed, table = Routes.route_costed, Routes._table
        clock = self

        def timed_costed(routes: Routes, src: str, dest: str, costs: SegmentCosts,
                         avoid_edges: frozenset[tuple[str, str]] = NO_EDGES
                         ) -> list[str] | None:
            clock.searches += 1
            clock._depth += 1
            start = time.perf_counter()
            try:
                if plain:
                    return routes._a_star(src, dest, frozenset(), avoid_edges, costs.extra_s)
                return costed(routes, src, dest, costs, avoid_edges)
            finally:
                clock.search_s += time.perf_counter() - start
                clock._depth -= 1

        def timed_table(routes: Routes, dest: str) -> tuple[dict[str, float], dict[str, str]]:
            if not clock._depth or dest in routes._to_dest:
                return table(routes, dest)
            start = time.perf_counter()
            try:
                return table(routes, dest)
            finally:
                clock.table_s += time.perf_counter() - start

        Routes.route_costed = timed_costed  # type: ignore[method-assign]
        Routes._table = timed_table  # type: ignore[method-assign]
        try:
            yield
        finally:
            Routes.route_costed = costed  # type: ignore[method-assign]
            Routes._table = table  # type: ignore[method-assign]


def run_case(agvs: int, hours: float, rate: float, policy: str, plain: bool) -> dict[str, Any]:
    """One run: wall seconds of simulating, of costed searches, their number, the events."""
    scenario = load_scenario(SCENARIO, {
        "fleet.size": agvs, "duration_h": hours, "warmup_h": min(0.5, hours / 4),
        "demand.rate_per_hour": rate, "demand.profile": [], "traffic.policy": policy})
    model = build_simulation(scenario, load_layout_for(scenario, str(SCENARIO)), (), False,
                             False, None, 10_000)
    clock = SearchClock()
    with clock.installed(plain):
        start = time.perf_counter()
        model.env.run(until=scenario.duration_s)
        wall_s = time.perf_counter() - start
    events = [(e.time_s, e.agv, e.event, e.node, e.detail) for e in model.recorder.events]
    return {"wall_s": wall_s, "search_s": clock.search_s - clock.table_s,
            "searches": clock.searches,
            "digest": hashlib.sha256(repr(events).encode()).hexdigest()}


def per_hour(runs: list[dict[str, Any]], key: str, hours: float) -> float:
    """The median of `key` over `runs`, per simulated hour."""
    return float(statistics.median(r[key] for r in runs)) / hours


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--agvs", type=int, nargs="+", default=[50, 200])
    parser.add_argument("--hours", type=float, default=1.0, help="simulated hours a run")
    parser.add_argument("--orders-per-agv-hour", type=float, default=5.0,
                        help="demand: this many orders an hour per AGV")
    parser.add_argument("--policy", default="reactive", help="traffic.policy of every run")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    from machine import machine_line  # bench/machine.py, beside this script

    print(machine_line("at start"), flush=True)
    print(f"fulfilment_shift, {args.policy}, {args.hours:g} h a run, "
          f"{args.orders_per_agv_hour:g} orders/h per AGV, medians of {args.repeats}")
    print("| AGVs | searches/h | wall s/h before | after | ratio | search s/h before | after | "
          "ratio | search share before | after | same events |")
    print("|---" * 11 + "|")
    for agvs in args.agvs:
        runs: dict[bool, list[dict[str, Any]]] = {True: [], False: []}
        for _ in range(args.repeats):
            for plain in (True, False):
                runs[plain].append(run_case(agvs, args.hours, args.orders_per_agv_hour * agvs,
                                            args.policy, plain))
        wall_b, wall_a = (per_hour(runs[p], "wall_s", args.hours) for p in (True, False))
        search_b, search_a = (per_hour(runs[p], "search_s", args.hours) for p in (True, False))
        searches = per_hour(runs[False], "searches", args.hours)
        same = len({r["digest"] for r in runs[True] + runs[False]}) == 1
        print(f"| {agvs} | {searches:,.0f} | {wall_b:.2f} | {wall_a:.2f} | "
              f"{wall_b / wall_a:.2f}x | {search_b:.2f} | {search_a:.2f} | "
              f"{search_b / search_a:.2f}x | {search_b / wall_b:.0%} | {search_a / wall_a:.0%} "
              f"| {'yes' if same else 'NO'} |", flush=True)
    print(machine_line("at end"))


if __name__ == "__main__":
    main()
