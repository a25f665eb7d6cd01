"""What each kind of incident costs on the realistic warehouse: 90 orders/h, 8-hour shift, each
incident type switched on alone against a baseline, over the same seeds (common random numbers:
the same orders in every variant), with a fleet that has slack and one that is short.

    .venv/bin/python bench/incident_costs.py [--seeds 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.analysis.kpi_sums import run_kpis  # noqa: E402
from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import simulate  # noqa: E402

BASE: dict[str, Any] = {"layout": "../layouts/warehouse.yaml", "fleet.size": 12,
                        "demand.rate_per_hour": 90, "demand.profile": [], "duration_h": 8}
VARIANTS: dict[str, dict[str, Any]] = {
    "baseline (charging on)": {},
    "no battery limits": {"fleet.vehicle.battery": False},
    "obstacles 2/km, mean 4 s": {"incidents.obstacle_rate_per_km": 2.0},
    "aisle 5 blocked 15 min": {"incidents.blocks": [
        {"from": "M011", "to": "A05_04", "at_s": 14400, "duration_s": 900}]},
    "link losses 0.3/h/AGV": {"incidents.link_loss_rate_per_h": 0.3},
    "critical faults, MTBF 40 h": {"incidents.mtbf_h": 40.0},
    "transfer failures 0.5 %": {"incidents.transfer_failure_prob": 0.005},
    "line losses 0.2/km": {"incidents.line_loss_per_km": 0.2},
}


def measure(changes: dict[str, Any], seed: int) -> dict[str, Any]:
    path = ROOT / "experiments" / "warehouse_shift.yaml"
    scenario = load_scenario(path, {**BASE, **changes, "seed": seed})
    layout = load_layout_for(scenario, str(path))
    run = simulate(scenario, layout)
    return run_kpis(run)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--agvs", type=int, nargs="+", default=[12, 7],
                        help="fleet sizes: 12 has slack at 90 orders/h, 7 is short of AGVs")
    args = parser.parse_args()
    for agvs in args.agvs:
        table(agvs, list(range(1, args.seeds + 1)))
        print()


def table(agvs: int, seeds: list[int]) -> None:
    every: dict[str, Any] = {}
    for changes in list(VARIANTS.values())[2:]:
        every.update(changes)
    variants = {**VARIANTS, "all of the above": every}
    print(f"{agvs} AGVs, 90 orders/h, 8 h, warehouse.yaml; means over seeds {seeds}")
    print()
    print("| incidents | throughput/h | change | lead time p95 s | availability % | errors |")
    print("|---|---:|---:|---:|---:|---|")
    base = None
    for name, changes in variants.items():
        runs = [measure({**changes, "fleet.size": agvs}, seed) for seed in seeds]
        tput = statistics.mean(r["throughput_per_hour"] for r in runs)
        p95 = statistics.mean(r["lead_time_p95_s"] or 0.0 for r in runs)
        avail = statistics.mean(r["availability_pct"] for r in runs)
        errors: dict[str, int] = {}
        for r in runs:
            for code, n in r["errors_by_code"].items():
                errors[code] = errors.get(code, 0) + n
        base = tput if base is None else base
        change = 100.0 * (tput - base) / base
        print(f"| {name} | {tput:.1f} | {change:+.1f} % | {p95:.0f} | {avail:.1f} | "
              f"{', '.join(f'{c} x{n}' for c, n in sorted(errors.items())) or '-'} |",
              flush=True)


if __name__ == "__main__":
    main()
