"""How fast is the engine? The realistic warehouse over an 8-hour shift with 10, 25, 50 and 100
AGVs, against a bare SimPy ring (400 nodes, 50 AGVs, node locks, 8 h) run in the same process.

Two regimes: a fleet-sizing sweep (demand fixed at 150 orders/h, about what the layout can
carry; idle AGVs park), and every AGV busy (demand 7.5 orders/h per AGV, the load of the bundled
shift scenario). Prints medians of --repeats runs; these machines are noisy, so compare figures
within one run of this script only.

    .venv/bin/python bench/engine_scaling.py [--repeats 3] [--fleets 10 25 50 100]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import simpy

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import simulate  # noqa: E402

SHIFT_H = 8.0
ORDERS_PER_AGV_HOUR = 7.5
FIXED_ORDERS_PER_HOUR = 150.0


def bare_ring(nodes: int = 400, agvs: int = 50, hours: float = SHIFT_H,
              hop_s: float = 4.0) -> tuple[float, int]:
    """The yardstick: AGVs circle a ring, each holding its node and taking the next one."""
    env = simpy.Environment()
    locks = [simpy.Resource(env, capacity=1) for _ in range(nodes)]

    def agv(start: int) -> simpy.events.ProcessGenerator:
        pos = start
        held = locks[pos].request()
        yield held
        while True:
            nxt = (pos + 1) % nodes
            ahead = locks[nxt].request()
            yield ahead
            yield env.timeout(hop_s)
            locks[pos].release(held)
            pos, held = nxt, ahead

    for i in range(agvs):
        env.process(agv(i * nodes // agvs))
    start = time.perf_counter()
    env.run(until=hours * 3600)
    return time.perf_counter() - start, next(env._eid)


def warehouse(agvs: int, rate_per_hour: float) -> tuple[float, int, float]:
    path = ROOT / "experiments" / "warehouse_shift.yaml"
    scenario = load_scenario(path, {"fleet.size": agvs, "duration_h": SHIFT_H,
                                    "demand.rate_per_hour": rate_per_hour,
                                    "demand.profile": []})
    layout = load_layout_for(scenario, str(path))
    start = time.perf_counter()
    run = simulate(scenario, layout)
    wall = time.perf_counter() - start
    delivered = sum(1 for o in run.recorder.orders if o.delivered_s is not None)
    return wall, run.sim_events, delivered / SHIFT_H


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fleets", type=int, nargs="+", default=[10, 25, 50, 100])
    args = parser.parse_args()

    ring = [bare_ring() for _ in range(args.repeats)]
    ring_wall = statistics.median(w for w, _ in ring)
    ring_events = ring[0][1]
    print(f"bare SimPy ring, 400 nodes, 50 AGVs, {SHIFT_H:.0f} h: "
          f"{ring_wall:.2f} s wall, {SHIFT_H / ring_wall:.1f} sim h/s, "
          f"{ring_events / ring_wall:,.0f} events/s (median of {args.repeats})")
    print()
    for title, rate in (("fleet-sizing sweep: demand fixed at 150 orders/h", None),
                        ("every AGV busy: demand 7.5 orders/h per AGV", ORDERS_PER_AGV_HOUR)):
        print(f"realistic warehouse, {SHIFT_H:.0f} h shift, {title}")
        print()
        table(args.fleets, args.repeats, rate, ring_wall)
        print()


def table(fleets: list[int], repeats: int, per_agv: float | None, ring_wall: float) -> None:
    header = ("AGVs", "wall s", "sim h / wall s", "events/s", "ms per sim h per AGV",
              "x ring", "delivered/h")
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---:" for _ in header) + "|")
    for agvs in fleets:
        rate = FIXED_ORDERS_PER_HOUR if per_agv is None else per_agv * agvs
        runs = [warehouse(agvs, rate) for _ in range(repeats)]
        wall = statistics.median(r[0] for r in runs)
        events = runs[0][1]
        print(f"| {agvs} | {wall:.2f} | {SHIFT_H / wall:.1f} | {events / wall:,.0f} | "
              f"{wall / SHIFT_H / agvs * 1000:.1f} | {wall / ring_wall:.2f} | "
              f"{runs[0][2]:.0f} |", flush=True)


if __name__ == "__main__":
    main()
