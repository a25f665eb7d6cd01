"""What the LDS reading of the AGV ahead changes (`rules.agv_ahead`, issue 33 item 2): the
bundled warehouse shift (experiments/warehouse_shift.yaml) at several fleet sizes, `--seeds`
replications each, under ``lds`` (the default: a queued AGV closes up and is paused by its
LDS, E_101 after 5 minutes) and ``held_back`` (the fleet manager keeps AGVs out of LDS range:
the model before the reading). Prints per fleet size and reading the medians over seeds of
throughput, lead time mean and p95, the share of time Paused, pauses behind AGVs, E_101s,
and the station queue discharge: the time from one AGV's Event_Load_Complete at a pickup
to the next queued AGV's Event_Arrived_Pickup there (the next arrival within 60 s).

    .venv/bin/python bench/agv_ahead.py [--fleets 12 16 20] [--seeds 5] [--hours 8]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.analysis.kpi_sums import run_kpis  # noqa: E402
from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import simulate  # noqa: E402

QUEUED_S = 60.0
"""An arrival at a pickup this soon after the last departure counts as a queue discharge."""


def one(job: tuple[int, int, str, float]) -> dict[str, Any]:
    agvs, seed, reading, hours = job
    path = ROOT / "experiments" / "warehouse_shift.yaml"
    scenario = load_scenario(path, {"fleet.size": agvs, "seed": seed, "duration_h": hours,
                                    "rules.agv_ahead": reading})
    out = simulate(scenario, load_layout_for(scenario, path))
    kpis = run_kpis(out)
    left: dict[str, float] = {}
    gaps: list[float] = []
    for e in out.recorder.events:
        if e.event == "Event_Load_Complete":
            left[e.node] = e.time_s
        elif e.event == "Event_Arrived_Pickup" and e.node in left:
            gap = e.time_s - left.pop(e.node)
            if gap <= QUEUED_S:
                gaps.append(gap)
    return {"agvs": agvs, "reading": reading,
            "throughput": kpis["throughput_per_hour"],
            "lead_mean": kpis["lead_time_mean_s"], "lead_p95": kpis["lead_time_p95_s"],
            "paused_pct": kpis["state_paused_pct"], "pauses": kpis["agv_obstacle_pauses"],
            "e101": (kpis["errors_by_code"] or {}).get("E_101", 0),
            "discharge_s": statistics.median(gaps) if gaps else float("nan")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fleets", type=int, nargs="+", default=[12, 16, 20])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--hours", type=float, default=8.0)
    args = parser.parse_args()
    jobs = [(agvs, 11 + s, reading, args.hours) for agvs in args.fleets
            for reading in ("held_back", "lds") for s in range(args.seeds)]
    with ProcessPoolExecutor(os.cpu_count()) as pool:
        rows = list(pool.map(one, jobs))
    print(f"warehouse shift, {args.hours:g} h, medians of {args.seeds} seeds; "
          f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"{'agvs':>4} {'reading':<9} {'orders/h':>8} {'lead s':>7} {'p95 s':>7} "
          f"{'paused %':>8} {'pauses':>6} {'E_101':>5} {'discharge s':>11}")
    groups: dict[tuple[int, str], list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[row["agvs"], row["reading"]].append(row)
    for (agvs, reading), group in groups.items():
        def med(key: str, group: list[dict[str, Any]] = group) -> float:
            return statistics.median(r[key] for r in group)
        print(f"{agvs:>4} {reading:<9} {med('throughput'):>8.1f} {med('lead_mean'):>7.1f} "
              f"{med('lead_p95'):>7.1f} {med('paused_pct'):>8.2f} {med('pauses'):>6.0f} "
              f"{med('e101'):>5.0f} {med('discharge_s'):>11.2f}")


if __name__ == "__main__":
    main()
