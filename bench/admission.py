"""Throughput as the fleet grows, with and without admission (`dispatch.max_active_agvs`), on
every bundled layout: the plateau with the rule, the collapse without it.

Demand is fixed well above what each layout can carry, so throughput shows the fleet's own
capacity. Each run is `--hours` long after a 0.5 h warm-up (throughput counts after it), one
seed per fleet size (the same orders at every size). The limit per layout is the fleet size at
which throughput peaked without the rule in earlier runs of this script (the loop's working
load); `--routing` adds a column with congestion-aware routes (`traffic.congestion_cost_s`) on
top of admission; `--avoiding` columns with the deadlock-avoiding traffic policy
(`traffic.policy: avoiding`, with its own admission limit, the layout's critical fleet, printed
above the table), the gridlocks each policy locked into, and whether the policy's throughput
is within 5 % of the best smaller fleet's (the no-collapse rule of issue 21).

    .venv/bin/python bench/admission.py [--hours 3] [--layouts warehouse ...] [--routing]
        [--avoiding] [--seeds 3] [--fleets 20 40 ...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.analysis.kpi_sums import run_kpis  # noqa: E402
from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import simulate  # noqa: E402

WARMUP_H = 0.5


@dataclass(frozen=True)
class Case:
    layout: str
    fleets: tuple[int, ...]
    rate_per_hour: float
    max_active: int


CASES = (
    Case("tiny_loop", (1, 2, 3, 4), 120.0, 3),
    Case("warehouse", (10, 20, 40, 70, 100, 150), 300.0, 20),
    Case("warehouse_wifi", (10, 20, 40, 70, 100, 150), 300.0, 20),
    Case("distribution_centre", (20, 40, 80, 150, 250), 600.0, 40),
    Case("fulfilment_centre", (50, 100, 200, 300, 500), 3000.0, 300),
)


def run(case: Case, agvs: int, hours: float, overrides: dict[str, Any],
        seeds: int = 1) -> dict[str, Any]:
    """One run per seed (11, 12, ...): mean throughput and wall time, deadlocks summed, the
    first gridlock."""
    path = ROOT / "experiments" / "warehouse_shift.yaml"
    runs = []
    for seed in range(11, 11 + seeds):
        scenario = load_scenario(path, {
            "layout": f"../layouts/{case.layout}.yaml", "fleet.size": agvs,
            "duration_h": WARMUP_H + hours, "warmup_h": WARMUP_H,
            "demand.rate_per_hour": case.rate_per_hour, "demand.profile": [], "seed": seed,
            **overrides})
        layout = load_layout_for(scenario, str(path))
        start = time.perf_counter()
        out = simulate(scenario, layout)
        wall = time.perf_counter() - start
        figures = run_kpis(out)
        runs.append({"throughput": figures["throughput_per_hour"],
                     "deadlocks": out.recorder.deadlocks, "wall": wall,
                     "gridlock": figures["gridlock_at_h"],
                     "limit": None if out.admission is None else out.admission[1].describe()})
    gridlocks = [r["gridlock"] for r in runs if r["gridlock"] is not None]
    return {"throughput": statistics.fmean(r["throughput"] for r in runs),
            "deadlocks": sum(r["deadlocks"] for r in runs),
            "wall": statistics.fmean(r["wall"] for r in runs),
            "gridlock": min(gridlocks) if gridlocks else None, "limit": runs[0]["limit"]}


def gridlock_cell(figures: dict[str, Any]) -> str:
    at_h = figures["gridlock"]
    return "-" if at_h is None else f"at {at_h:.1f} h"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=3.0,
                        help="measured hours after the warm-up (default 3)")
    parser.add_argument("--layouts", nargs="+", default=[c.layout for c in CASES])
    parser.add_argument("--fleets", type=int, nargs="+",
                        help="these fleet sizes instead of each layout's own")
    parser.add_argument("--avoiding", action="store_true",
                        help="also the deadlock-avoiding policy (traffic.policy: avoiding)")
    parser.add_argument("--seeds", type=int, default=1,
                        help="replications per cell, seeds 11, 12, ...: means (default 1)")
    parser.add_argument("--routing", action="store_true",
                        help="also admission + congestion-aware routes (congestion_cost_s 10)")
    args = parser.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.2f} "
          f"({os.cpu_count()} cores); {args.hours:g} h measured after {WARMUP_H} h warm-up; "
          f"means of {args.seeds} seed(s)")
    for case in CASES:
        if case.layout not in args.layouts:
            continue
        print()
        print(f"{case.layout}: demand {case.rate_per_hour:g} orders/h, admission limit "
              f"{case.max_active} AGVs on the track")
        print()
        header = ["AGVs", "no rule: delivered/h", "deadlocks", "gridlock",
                  "with rule: delivered/h", "deadlocks"]
        if args.routing:
            header += ["rule + congestion routes: delivered/h", "deadlocks"]
        if args.avoiding:
            header += ["avoiding: delivered/h", "deadlocks", "gridlock", "within 5 %", "wall s"]
        header += ["wall s (no rule / rule)"]
        print("| " + " | ".join(header) + " |")
        print("|" + "|".join("---:" for _ in header) + "|")
        best = 0.0
        limit = None
        for agvs in args.fleets or case.fleets:
            free = run(case, agvs, args.hours, {}, args.seeds)
            ruled = run(case, agvs, args.hours, {"dispatch.max_active_agvs": case.max_active},
                        args.seeds) \
                if agvs > case.max_active else free  # below the limit the rule never binds
            cells = [f"{agvs}", f"{free['throughput']:.1f}", f"{free['deadlocks']:.0f}",
                     gridlock_cell(free), f"{ruled['throughput']:.1f}",
                     f"{ruled['deadlocks']:.0f}"]
            if args.routing:
                routed = run(case, agvs, args.hours,
                             {"dispatch.max_active_agvs": min(case.max_active, agvs),
                              "traffic.congestion_cost_s": 10.0}, args.seeds)
                cells += [f"{routed['throughput']:.1f}", f"{routed['deadlocks']:.0f}"]
            if args.avoiding:
                safe = run(case, agvs, args.hours, {"traffic.policy": "avoiding"}, args.seeds)
                kept = safe["throughput"] >= 0.95 * best
                best = max(best, safe["throughput"])
                limit = safe["limit"]
                cells += [f"{safe['throughput']:.1f}", f"{safe['deadlocks']:.0f}",
                          gridlock_cell(safe), "yes" if kept else "NO", f"{safe['wall']:.1f}"]
            cells += [f"{free['wall']:.1f} / {ruled['wall']:.1f}"]
            print("| " + " | ".join(cells) + " |", flush=True)
        if limit is not None:
            print(f"\navoiding admits the critical fleet: {limit}")
    print()
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
