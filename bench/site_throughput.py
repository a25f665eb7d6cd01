"""Does the fulfilment centre's throughput rise with the fleet? Delivered orders per hour on
layouts/fulfilment_centre.yaml (experiments/fulfilment_shift.yaml) at --fleets AGVs, with demand
--load times what the analytic estimate says the fleet can carry (so every AGV has work and the
floor, not the demand, sets the figure), for the spec's shortest routes and for
congestion-aware routes (`traffic.congestion_cost_s`), without admission. One run per cell
(seed 7), --hours simulated hours after a 0.5 h warm-up; the table also gives the busy share,
the blocked share and deadlocks. `--policy NAME` adds the override `traffic.policy: NAME`.

    .venv/bin/python bench/site_throughput.py [--fleets 50 100 ...] [--hours 4]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.analysis.kpi_sums import run_kpis  # noqa: E402
from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import simulate  # noqa: E402
from fleet_sim.sim.estimate import analytic_estimate  # noqa: E402

SCENARIO = ROOT / "experiments" / "fulfilment_shift.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fleets", type=int, nargs="+",
                        default=[50, 100, 150, 200, 250, 300, 350, 400, 500])
    parser.add_argument("--hours", type=float, default=4.0)
    parser.add_argument("--load", type=float, default=1.1)
    parser.add_argument("--congestion-cost-s", type=float, default=10.0)
    parser.add_argument("--policy", help="traffic.policy for every run")
    parser.add_argument("--nice", type=int, default=10)
    args = parser.parse_args()
    os.nice(args.nice)
    extra: dict[str, Any] = {"traffic.policy": args.policy} if args.policy else {}
    base: dict[str, Any] = {"duration_h": args.hours + 0.5, "warmup_h": 0.5,
                            "demand.profile": [], **extra}
    scenario = load_scenario(SCENARIO, base)
    estimate = analytic_estimate(scenario, load_layout_for(scenario, str(SCENARIO)))
    per_agv = args.load * 3600.0 / estimate.cycle_s
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    print()
    print(f"## fulfilment centre, {args.hours:g} h after 0.5 h warm-up, demand {per_agv:.2f} "
          f"orders/h per AGV ({args.load:g} x the analytic estimate)")
    print()
    header = ("AGVs", "demand/h", "shortest routes: delivered/h", "busy %", "blocked %",
              "deadlocks", f"congestion-aware ({args.congestion_cost_s:g} s): delivered/h",
              "busy %", "blocked %", "deadlocks")
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---:" for _ in header) + "|")
    for agvs in args.fleets:
        cells = [str(agvs), f"{per_agv * agvs:.0f}"]
        for cost in (0.0, args.congestion_cost_s):
            overrides = {**base, "fleet.size": agvs, "demand.rate_per_hour": per_agv * agvs,
                         "traffic.congestion_cost_s": cost}
            run_scenario = load_scenario(SCENARIO, overrides)
            run = simulate(run_scenario, load_layout_for(run_scenario, str(SCENARIO)))
            k = run_kpis(run)
            cells += [f"{k['throughput_per_hour']:.0f}", f"{k['agv_utilisation_pct']:.0f}",
                      f"{k['blocked_time_pct']:.0f}", str(run.recorder.deadlocks)]
        print("| " + " | ".join(cells) + " |", flush=True)
    print()
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
