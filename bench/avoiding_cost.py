"""What does the deadlock-avoiding traffic policy cost against the reactive one? Each case runs
the same scenario under both policies (by default every AGV admitted onto the track,
`dispatch.max_active_agvs` = the fleet: the check alone; `--admitted policy`: no limit set,
as a planner gets each policy, the critical fleet under avoiding), interleaved, --repeats
times, and prints the median wall seconds per simulated hour, their ratio, delivered orders
per hour, and what the avoiding policy's safety check did: walks (every AGV on the track
driven to parking, fleet_sim.sim.traffic.avoidance) and the moves they made. `--profile` adds
the functions the first case's avoiding run spent its time in (cProfile, by own time and
by cumulative time).
`--split` adds, from one more avoiding run a case (timers around the check's parts), where its
wall time went: the walks' driving (`Walk.run`) and the rest of the walks (adding every AGV,
the schedule), the fits' walks of one AGV alone and the rest of the fits, and everything else;
and the ratio to reactive that would be left if every walk's and fit's driving cost nothing
(what compiling the walk's loop alone could at best give).
`--components` adds, over each case's walks (one more avoiding run, counted before each walk),
how many AGVs were on the track and how many of them in the claim graph's largest strongly
connected component and in any cycle: the share a walk of the cycles alone could skip.
These machines are noisy: compare figures within one run (the load average is printed).

    .venv/bin/python bench/avoiding_cost.py [--cases fulfilment_centre:200 ...] [--hours 1]
        [--orders-per-agv-hour 5] [--repeats 1] [--profile] [--components]
        [--admitted fleet|policy] [--split]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import statistics
import sys
import time
from pathlib import Path
from typing import Any
from unittest import mock

import networkx as nx

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import build_simulation, collecting_seldom  # noqa: E402
from fleet_sim.sim.traffic.avoidance import Plans  # noqa: E402
from fleet_sim.sim.traffic.walk import Walk, holders_of  # noqa: E402

SCENARIO_OF = {
    "warehouse": "warehouse_shift.yaml",
    "distribution_centre": "dc_shift.yaml",
    "fulfilment_centre": "fulfilment_shift.yaml",
}
DEFAULT_CASES = ["warehouse:40", "distribution_centre:100", "fulfilment_centre:200",
                 "fulfilment_centre:300"]


def run_case(layout: str, agvs: int, hours: float, rate: float, policy: str,
             profile: cProfile.Profile | None = None, admitted: str = "fleet") -> dict[str, Any]:
    """One run: wall seconds of simulating, delivered orders/h and the check's counters.
    `admitted`: "fleet", every AGV on the track (the check alone); "policy", as a planner who
    sets no limit gets it (none under reactive traffic, the critical fleet under avoiding)."""
    path = ROOT / "experiments" / SCENARIO_OF[layout]
    scenario = load_scenario(path, {
        "layout": f"../layouts/{layout}.yaml", "fleet.size": agvs, "duration_h": hours,
        "warmup_h": min(0.5, hours / 4), "demand.rate_per_hour": rate, "demand.profile": [],
        "traffic.policy": policy,
        "dispatch.max_active_agvs": agvs if admitted == "fleet" else None})
    model = build_simulation(scenario, load_layout_for(scenario, str(path)), (), False,
                             False, None, 10_000)
    start = time.perf_counter()
    if profile is not None:
        profile.enable()
    with collecting_seldom():  # as `simulate` runs
        model.env.run(until=scenario.duration_s)
    if profile is not None:
        profile.disable()
    wall_s = time.perf_counter() - start
    delivered = sum(1 for o in model.recorder.orders if o.delivered_s is not None)
    out: dict[str, Any] = {"wall_s": wall_s, "delivered_per_h": delivered / hours,
                           "deadlocks": model.recorder.deadlocks}
    plans = getattr(model.traffic.strategy, "plans", None)
    if isinstance(plans, Plans):
        out.update(walks=plans.walks, walked_moves=plans.walked_moves,
                   refused=plans.refused_grants + plans.refused_plans)
    return out


def split(layout: str, agvs: int, hours: float, rate: float, admitted: str,
          reactive_s: float) -> str:
    """One avoiding run with timers around the walks, the fits and the walks' driving: where
    its wall time went, in seconds a simulated hour."""
    spent = {"walk": 0.0, "walk run": 0.0, "fit": 0.0, "fit run": 0.0}
    inside: list[str] = []

    def timed(original: Any, key: str | None) -> Any:
        """`original` with its wall time added to `key` (None: to the driving of the walk or
        fit it runs in)."""

        def wrapper(*args: Any, **kwargs: Any) -> Any:
            part = key if key is not None else f"{inside[-1]} run" if inside else None
            if key is not None:
                inside.append(key)
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                if part is not None:
                    spent[part] += time.perf_counter() - start
                if key is not None:
                    inside.pop()

        return wrapper

    with mock.patch.object(Plans, "_walk", timed(Plans._walk, "walk")), \
            mock.patch.object(Plans, "_fit", timed(Plans._fit, "fit")), \
            mock.patch.object(Walk, "run", timed(Walk.run, None)):
        total = run_case(layout, agvs, hours, rate, "avoiding", admitted=admitted)["wall_s"]
    per_h = {part: seconds / hours for part, seconds in spent.items()}
    total /= hours
    rest = total - per_h["walk"] - per_h["fit"]
    free = total - per_h["walk run"] - per_h["fit run"]
    return (f"{total:.2f} s/h: walks driving {per_h['walk run']:.2f}, walks' rest "
            f"{per_h['walk'] - per_h['walk run']:.2f}, fits driving {per_h['fit run']:.2f}, "
            f"fits' rest {per_h['fit'] - per_h['fit run']:.2f}, everything else {rest:.2f}; "
            f"with the driving free {free:.2f} s/h, {free / reactive_s:.1f}x reactive")


def components(layout: str, agvs: int, hours: float, rate: float, admitted: str) -> str:
    """One avoiding run, the claim graph's components counted before each walk: medians of
    the AGVs on the track, of the largest component and of those in any cycle."""
    counts: list[tuple[int, int, int]] = []
    walk = Plans._walk

    def counted(plans: Plans, *args: Any) -> Any:
        graph: nx.DiGraph = nx.DiGraph()
        graph.add_nodes_from(x for x in plans.path if any(plans.table.held_locks(x)))
        for x, needs in plans.needs.items():
            graph.add_edges_from((x, y) for lock in needs for y in holders_of(lock) if y != x)
        cycles = [len(c) for c in nx.strongly_connected_components(graph) if len(c) > 1]
        counts.append((graph.number_of_nodes(), max(cycles, default=0), sum(cycles)))
        return walk(plans, *args)

    with mock.patch.object(Plans, "_walk", counted):
        run_case(layout, agvs, hours, rate, "avoiding", admitted=admitted)
    if not counts:
        return "no walks"
    on, largest, cycling = (statistics.median(c[i] for c in counts) for i in range(3))
    return (f"{len(counts)} walks; medians: {on:g} AGVs on the track, {largest:g} in the "
            f"largest component (at most {max(c[1] for c in counts)}), {cycling:g} in cycles")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=DEFAULT_CASES,
                        help="layout:AGVs pairs (layouts: " + ", ".join(SCENARIO_OF) + ")")
    parser.add_argument("--hours", type=float, default=1.0, help="simulated hours a run")
    parser.add_argument("--orders-per-agv-hour", type=float, default=5.0,
                        help="demand: this many orders an hour per AGV")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--profile", action="store_true",
                        help="profile the first case's avoiding run")
    parser.add_argument("--admitted", choices=("fleet", "policy"), default="fleet",
                        help="fleet: every AGV on the track (the check alone); policy: as a "
                        "planner who sets no limit gets it (the critical fleet under avoiding)")
    parser.add_argument("--split", action="store_true",
                        help="time the check's parts in one more avoiding run")
    parser.add_argument("--components", action="store_true",
                        help="count the claim graph's cycles before each walk")
    args = parser.parse_args()
    cases = []
    for case in args.cases:
        layout, _, agvs = case.partition(":")
        if layout not in SCENARIO_OF or not agvs.isdigit() or int(agvs) < 1:
            parser.error(f"--cases: {case!r} is not layout:AGVs with a layout of "
                         f"{', '.join(SCENARIO_OF)} and a whole number of AGVs")
        cases.append((layout, int(agvs)))
    print(f"load average at start: {os.getloadavg()[0]:.2f}; {args.hours:g} h a run, "
          f"{args.orders_per_agv_hour:g} orders/h per AGV, medians of {args.repeats}, "
          f"admitted: {args.admitted}")
    header = ("| case | reactive s/h | avoiding s/h | ratio | delivered/h reactive | "
              "avoiding | walks | moves a walk |")
    print(header)
    print("|---" * 8 + "|")
    for n, (layout, agvs) in enumerate(cases):
        rate = args.orders_per_agv_hour * agvs
        reactive, avoiding = [], []
        for _ in range(args.repeats):
            reactive.append(run_case(layout, agvs, args.hours, rate, "reactive",
                                     admitted=args.admitted))
            avoiding.append(run_case(layout, agvs, args.hours, rate, "avoiding",
                                     admitted=args.admitted))
        r_s, a_s = (statistics.median(r["wall_s"] for r in runs) / args.hours
                    for runs in (reactive, avoiding))
        last = avoiding[-1]
        print(f"| {layout} {agvs} | {r_s:.2f} | {a_s:.2f} | {a_s / r_s:.1f}x | "
              f"{reactive[-1]['delivered_per_h']:.0f} | {last['delivered_per_h']:.0f} | "
              f"{last['walks']} | {last['walked_moves'] / max(1, last['walks']):,.0f} |",
              flush=True)
        if args.profile and n == 0:
            profile = cProfile.Profile()
            run_case(layout, agvs, args.hours, rate, "avoiding", profile, args.admitted)
            for order in ("tottime", "cumulative"):
                text = io.StringIO()
                pstats.Stats(profile, stream=text).sort_stats(order).print_stats(14)
                print("\n".join(text.getvalue().splitlines()[4:]))
        if args.split:
            print(f"  split ({layout} {agvs}): "
                  f"{split(layout, agvs, args.hours, rate, args.admitted, r_s)}", flush=True)
        if args.components:
            found = components(layout, agvs, args.hours, rate, args.admitted)
            print(f"  components ({layout} {agvs}): {found}", flush=True)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
