"""How fast is the closed-form engine against SUMO? The realistic warehouse (warehouse_shift)
with 50 AGVs over an 8-hour shift, with each motion backend (each run in its own process, as
libsumo requires), and the speed ratio; then SUMO alone, as the yardstick a SUMO user would
reach for: the same number of vehicles on the exported network, each with a route of random
trips between stations (no fleet model, no stops), stepped through the shift at 1 s and 0.1 s.

Demand defaults to 150 orders/h (about what the layout can carry, as in bench/engine_scaling.py).
These machines are noisy: compare figures within one run of this script only. `--events` also
prints what the closed form's SimPy events are spent on, per hop (one more run, counted, after
the timed ones: counting slows it), every event SimPy processes counted, those the engine pushes
onto the queue itself (the alarm clock's timers, LDS looks at exact times) in a row of their own.

    .venv/bin/python bench/sumo_vs_engine.py [--agvs 50] [--hours 8] [--rate 150] [--events]
"""

from __future__ import annotations

import argparse
import itertools
import multiprocessing
import sys
import tempfile
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.study.crosscheck import crosscheck  # noqa: E402

SCENARIO = ROOT / "experiments" / "warehouse_shift.yaml"


def sumo_alone(agvs: int, hours: float, step_s: float, seed: int = 1) -> dict[str, float]:
    """Wall time of plain SUMO: `agvs` vehicles on random station-to-station routes."""
    import networkx as nx
    import numpy as np

    from fleet_sim.config.layout import load_layout
    from fleet_sim.sim.sumo.backend import load_libsumo
    from fleet_sim.sim.sumo.network import VTYPE_ID, edge_id, export

    layout = load_layout(ROOT / "layouts" / "warehouse.yaml")
    rng = np.random.default_rng(seed)
    stations = [n for p in layout.pickups + layout.dropoffs for n in p.nodes]
    starts = [p.nodes[0] for p in layout.parking]
    with tempfile.TemporaryDirectory() as tmp:
        network = export(layout, Path(tmp))
        sumo = load_libsumo()
        sumo.start(["sumo", "-n", str(network.net_file), "-a", str(network.vtype_file),
                    "--step-length", repr(step_s), "--step-method.ballistic", "true",
                    "--time-to-teleport", "-1", "--collision.action", "none",
                    "--no-step-log", "true", "--no-warnings", "true"])
        setup = time.perf_counter()
        trip_m = 0.0
        for i in range(agvs):
            node = starts[i % len(starts)]
            edges: list[str] = []
            length = 0.0
            while length < hours * 3600.0 * 1.2:  # more route than a shift can use
                goal = str(stations[int(rng.integers(len(stations)))])
                if goal == node:
                    continue
                path = nx.shortest_path(layout.graph, node, goal, weight="free_time_s")
                for a, b in itertools.pairwise(path):
                    edges.append(edge_id(a, b))
                    length += layout.graph.edges[a, b]["length_m"]
                node = goal
            trip_m += length
            sumo.route.add(f"r{i}", edges)
            sumo.vehicle.add(f"v{i}", f"r{i}", typeID=VTYPE_ID, depart=repr(i * 5.0),
                             departPos="0", departSpeed="0")
        setup_s = time.perf_counter() - setup
        start = time.perf_counter()
        sumo.simulationStep(hours * 3600.0)
        wall = time.perf_counter() - start
        driven = sum(sumo.vehicle.getDistance(v) for v in sumo.vehicle.getIDList())
        sumo.close()
    return {"wall_s": wall, "setup_s": setup_s, "distance_km": driven / 1000.0,
            "steps": hours * 3600.0 / step_s}


EVENT_KINDS = {  # (SimPy event class, the function that scheduled it) -> what it is for
    ("Timeout", "move"): "a drive along a hop ends",
    ("Released", "__init__"): "a lock let go (offered to the first waiting)",
    ("FirstOf", "_check"): "a blocked AGV resumes (its claim, or its look)",
    ("Timeout", "wait"): "a blocked AGV's look (every deadlock_check_s)",
    ("Claim", "grant"): "a queued claim granted",
    ("Timeout", "_look_in"): "an LDS look at the AGV ahead (a queue's pause, 300 ms)",
    ("Timeout", "_look"): "an LDS look once the AGV ahead's hop ends",
    ("Nudge", "__init__"): "a blocked AGV woken to look again (the alarm clock)",
    ("Relay", "_pass"): "a blocked AGV resumed by its grant",
    ("(pushed directly)", "the alarm clock or an LDS look"):
        "pushed onto the queue directly: the alarm clock's timers, LDS looks woken",
}


def events_per_hop(scenario: Path, overrides: dict[str, Any]) -> None:
    """Run the closed form once more, counting every SimPy event by what scheduled it."""
    import simpy

    from fleet_sim.config.scenario import load_layout_for, load_scenario
    from fleet_sim.sim.engine import simulate
    from fleet_sim.sim.traffic.control import Traffic

    counts: Counter[tuple[str, str]] = Counter()
    hops = steps = 0
    schedule, hopped, step = simpy.Environment.schedule, Traffic.hopped, simpy.Environment.step

    def counted_schedule(env: simpy.Environment, event: Any, *args: Any, **kwargs: Any) -> None:
        caller = sys._getframe(1)
        while caller.f_back is not None and "simpy" in caller.f_code.co_filename:
            caller = caller.f_back  # the first caller outside SimPy
        counts[type(event).__name__, caller.f_code.co_name] += 1
        schedule(env, event, *args, **kwargs)

    def counted_hop(traffic: Traffic, *args: Any) -> None:
        nonlocal hops
        hops += 1
        hopped(traffic, *args)

    def counted_step(env: simpy.Environment) -> None:
        nonlocal steps
        steps += 1
        step(env)

    run_scenario = load_scenario(scenario, {**overrides, "motion": "closed_form"})
    layout = load_layout_for(run_scenario, scenario)
    simpy.Environment.schedule = counted_schedule  # type: ignore[method-assign]
    Traffic.hopped = counted_hop  # type: ignore[method-assign]
    simpy.Environment.step = counted_step  # type: ignore[method-assign]
    try:
        run = simulate(run_scenario, layout)
    finally:
        simpy.Environment.schedule = schedule  # type: ignore[method-assign]
        Traffic.hopped = hopped  # type: ignore[method-assign]
        simpy.Environment.step = step  # type: ignore[method-assign]
    left = len(run.vehicles[0].env._queue)  # scheduled or pushed, never processed
    counts["(pushed directly)", "the alarm clock or an LDS look"] = \
        steps + left - sum(counts.values())
    total = sum(counts.values())
    per_hop = 1.0 / max(hops, 1)
    print(f"  closed form's SimPy events: {total:,} for {hops:,} hops, "
          f"{total * per_hop:.2f} per hop")
    others = 0
    for (kind, where), n in counts.most_common():
        label = EVENT_KINDS.get((kind, where))
        if label is None:
            others += n
            continue
        print(f"    {n * per_hop:5.2f} per hop  {n:9,}  {label} ({kind} from {where})")
    print(f"    {others * per_hop:5.2f} per hop  {others:9,}  everything else (orders, "
          "handling, charging, incidents, ...)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agvs", type=int, default=50)
    parser.add_argument("--hours", type=float, default=8.0)
    parser.add_argument("--rate", type=float, default=150.0, help="orders per hour")
    parser.add_argument("--events", action="store_true",
                        help="also print what the closed form's SimPy events are spent on")
    args = parser.parse_args()
    overrides = {"fleet.size": args.agvs, "duration_h": args.hours,
                 "warmup_h": min(0.5, args.hours / 4), "demand.rate_per_hour": args.rate}
    print(f"warehouse_shift, {args.agvs} AGVs, {args.hours:g} h, {args.rate:g} orders/h")
    results = crosscheck(SCENARIO, overrides)
    for motion, figures in results.items():
        print(f"  {motion:12} wall {figures['wall_s']:7.1f} s  "
              f"(process incl. start-up {figures['process_wall_s']:6.1f} s)  "
              f"throughput {figures['throughput_per_hour']:.1f}/h  "
              f"distance {figures['distance_km']:.1f} km")
    ratio = results["sumo"]["wall_s"] / results["closed_form"]["wall_s"]
    print(f"  speed ratio: closed form is x{ratio:.1f} faster than motion: sumo")
    context = multiprocessing.get_context("spawn")
    for step_s in (1.0, 0.1):
        with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
            alone = pool.submit(sumo_alone, args.agvs, args.hours, step_s).result()
        print(f"  SUMO alone, step {step_s:g} s: wall {alone['wall_s']:7.1f} s "
              f"({alone['steps']:,.0f} steps, {alone['distance_km']:.1f} km driven; "
              f"routes set up in {alone['setup_s']:.1f} s)")
    if args.events:
        events_per_hop(SCENARIO, overrides)


if __name__ == "__main__":
    from machine import machine_line  # bench/machine.py, beside this script

    print(machine_line("at start"), flush=True)
    main()
    print(machine_line("at end"))
