"""What do congestion-aware route searches cost, before and after a change to them? Each case
runs the fulfilment centre's shift (experiments/fulfilment_shift.yaml: 2,059 nodes, congestion
priced at 10 s an AGV, reactive traffic unless --policy) at so many AGVs on the commit
--before (a git worktree, as bench/equivalence.py makes it) and on this tree, one process per
run, interleaved (before, after, before, ...). It prints the medians of --repeats: wall
seconds per simulated hour, the seconds a simulated hour spends in costed searches
(`Routes.route_costed`, the free-flow tables they build on first asking included) and their
share of the run, the searches an hour, and whether both trees gave the same events (they
must, for a change that is only quicker). The machine's load is printed at start and end;
these machines are shared and noisy, so compare figures within one run of this script only.

    .venv/bin/python bench/route_costs.py --before REV [--agvs 50 200] [--hours 1]
        [--repeats 3] [--orders-per-agv-hour 5] [--policy reactive]
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from equivalence import worktree  # noqa: E402  (bench/equivalence.py, beside this script)
from machine import machine_line  # noqa: E402


def _init(tree: str) -> None:
    sys.path.insert(0, tree)


def run_case(job: tuple[str, int, float, float, str]) -> dict[str, Any]:
    """One run in `tree`: wall seconds of simulating, of costed searches, their number, and a
    digest of the events."""
    tree, agvs, hours, rate, policy = job
    import fleet_sim
    from fleet_sim.config.scenario import load_layout_for, load_scenario
    from fleet_sim.sim.engine import build_simulation
    from fleet_sim.sim.traffic.routing import Routes

    assert str(Path(fleet_sim.__file__).resolve()).startswith(tree), fleet_sim.__file__
    path = Path(tree) / "experiments" / "fulfilment_shift.yaml"
    scenario = load_scenario(path, {
        "fleet.size": agvs, "duration_h": hours, "warmup_h": min(0.5, hours / 4),
        "demand.rate_per_hour": rate, "demand.profile": [], "traffic.policy": policy})
    model = build_simulation(scenario, load_layout_for(scenario, str(path)), (), False,
                             False, None, 10_000)
    costed = Routes.route_costed
    clock = {"search_s": 0.0, "searches": 0}

    def timed(routes: Routes, *args: Any) -> list[str] | None:
        clock["searches"] += 1
        start = time.perf_counter()
        try:
            return costed(routes, *args)
        finally:
            clock["search_s"] += time.perf_counter() - start

    Routes.route_costed = timed  # type: ignore[method-assign]
    start = time.perf_counter()
    model.env.run(until=scenario.duration_s)
    wall_s = time.perf_counter() - start
    events = [(e.time_s, e.agv, e.event, e.node, e.detail) for e in model.recorder.events]
    return {"wall_s": wall_s, **clock,
            "digest": hashlib.sha256(repr(events).encode()).hexdigest()}


def in_tree(tree: Path, job: tuple[int, float, float, str]) -> dict[str, Any]:
    """`run_case` in a fresh process that imports fleet_sim from `tree`."""
    with ProcessPoolExecutor(1, mp_context=get_context("spawn"), initializer=_init,
                             initargs=(str(tree),)) as pool:
        return pool.submit(run_case, (str(tree), *job)).result()


def per_hour(runs: list[dict[str, Any]], key: str, hours: float) -> float:
    """The median of `key` over `runs`, per simulated hour."""
    return float(statistics.median(r[key] for r in runs)) / hours


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", required=True, help="the commit to compare with")
    parser.add_argument("--agvs", type=int, nargs="+", default=[50, 200])
    parser.add_argument("--hours", type=float, default=1.0, help="simulated hours a run")
    parser.add_argument("--orders-per-agv-hour", type=float, default=5.0,
                        help="demand: this many orders an hour per AGV")
    parser.add_argument("--policy", default="reactive", help="traffic.policy of every run")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    trees = {"before": worktree(args.before), "after": ROOT}
    print(machine_line("at start"), flush=True)
    print(f"fulfilment_shift, {args.policy}, {args.hours:g} h a run, "
          f"{args.orders_per_agv_hour:g} orders/h per AGV, medians of {args.repeats}; "
          f"before: {args.before} ({trees['before']}), after: this tree")
    print("| AGVs | searches/h | wall s/h before | after | ratio | search s/h before | after | "
          "ratio | search share before | after | same events |")
    print("|---" * 11 + "|")
    for agvs in args.agvs:
        runs: dict[str, list[dict[str, Any]]] = {"before": [], "after": []}
        job = (agvs, args.hours, args.orders_per_agv_hour * agvs, args.policy)
        for _ in range(args.repeats):
            for name, tree in trees.items():
                runs[name].append(in_tree(tree, job))
        wall_b, wall_a = (per_hour(runs[n], "wall_s", args.hours) for n in trees)
        search_b, search_a = (per_hour(runs[n], "search_s", args.hours) for n in trees)
        searches = per_hour(runs["after"], "searches", args.hours)
        same = len({r["digest"] for r in runs["before"] + runs["after"]}) == 1
        print(f"| {agvs} | {searches:,.0f} | {wall_b:.2f} | {wall_a:.2f} | "
              f"{wall_b / wall_a:.2f}x | {search_b:.2f} | {search_a:.2f} | "
              f"{search_b / search_a:.2f}x | {search_b / wall_b:.0%} | {search_a / wall_a:.0%} "
              f"| {'yes' if same else 'NO'} |", flush=True)
    print(machine_line("at end"))


if __name__ == "__main__":
    main()
