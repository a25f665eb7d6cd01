"""What the vehicles' protocols cost on the bundled mixed fleet (experiments/warehouse_mixed.yaml:
6 RSS-AGV-001 carriers, 6 CarriRo AD+, 4 KTM-02 on the warehouse, 8-hour shift): each AGV's
commands timed on its own profile's protocol and link (fleet.command_timing: auto) against
commands that take no time (off), over the same seeds (common random numbers: the same orders
in every variant). Also: the route given whole to every type (no per-hop permissions), and
granted hop by hop to every type with a protocol (CarriRo too).

    .venv/bin/python bench/protocol_cost.py [--seeds 5] [--hours 8]

Prints medians over seeds, the median paired difference against `off` with its range, and
what the commands themselves took: the assign's transit per type (the fleet manager's decision
to the AGV's order_assigned event) and commands sent per delivered order; and the parking
trips cut short per type (an AGV that set off for parking when its drop-off was done, and
turned round at the next node where it could stop for an order that came after it left).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agv_model.fleet_commands import GRANTS_PER_HOP, CommandTiming  # noqa: E402
from fleet_sim.analysis.kpi_sums import run_kpis  # noqa: E402
from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import RunOutput, simulate  # noqa: E402

EXPERIMENT = ROOT / "experiments" / "warehouse_mixed.yaml"
VARIANTS: dict[str, dict[str, Any]] = {
    "off (commands take no time)": {"fleet.command_timing": "off"},
    "auto (each type its own link)": {},
    "auto, every route whole": {"traffic.grants": "whole_route"},
    "auto, every route hop by hop": {"traffic.grants": "per_hop"},
}
TYPES = ("carriro", "ktm02")


def measure(changes: dict[str, Any], seed: int, hours: float) -> dict[str, Any]:
    scenario = load_scenario(EXPERIMENT, {**changes, "seed": seed, "duration_h": hours})
    layout = load_layout_for(scenario, str(EXPERIMENT))
    run = simulate(scenario, layout)
    figures = run_kpis(run)
    delivered = sum(1 for o in run.recorder.orders if o.delivered_s is not None)
    figures["commands_per_order"] = figures["commands_sent"] / max(delivered, 1)
    figures["assign_ms"] = assign_transit_ms(run)
    types = scenario.fleet.agv_types
    figures["cut_short"] = {t: sum(1 for e in run.recorder.events if e.event == "Event_Stop"
                                   and "cut short" in e.detail and types[e.agv] == t)
                            for t in TYPES}
    return figures


def assign_transit_ms(run: RunOutput) -> dict[str, float]:
    """Type -> mean time (ms) from the fleet manager's decision to the AGV having the order."""
    got = {(e.agv, e.detail.split()[1]): e.time_s for e in run.recorder.events
           if e.event == "order_assigned"}
    types = run.scenario.fleet.agv_types
    spans: dict[str, list[float]] = {}
    for order in run.recorder.orders:
        if order.assigned_s is None or order.agv is None:
            continue
        at = got.get((order.agv, str(order.id)))
        if at is not None:
            spans.setdefault(types[order.agv], []).append(1000.0 * (at - order.assigned_s))
    return {t: statistics.mean(v) for t, v in spans.items()}


def by_type(figures: dict[str, Any], name: str, kpi: str) -> float:
    value = figures.get("by_type", {}).get(f"{name}.{kpi}")
    return float(value) if value is not None else float("nan")


COLUMNS: dict[str, Any] = {
    "throughput/h": lambda f: f["throughput_per_hour"],
    "lead mean s": lambda f: f["lead_time_mean_s"],
    "lead p95 s": lambda f: f["lead_time_p95_s"],
    "CarriRo lead s": lambda f: by_type(f, "carriro", "lead_time_mean_s"),
    "KTM-02 lead s": lambda f: by_type(f, "ktm02", "lead_time_mean_s"),
}


def messages() -> None:
    """Each type's messages on its own link (jitter excluded), and how its route is given."""
    scenario = load_scenario(EXPERIMENT)
    print("| type | protocol | assign ms | status (boot report) ms | resume (a hop's "
          "permission) ms | route under auto |")
    print("|---|---|---:|---:|---:|---|")
    for kind in scenario.fleet.vehicles:
        link = kind.command_link
        if link is None or link.protocol is None:
            print(f"| {kind.type} | none | 0 | 0 | 0 | whole |")
            continue
        timing = CommandTiming(link.protocol, link.link)
        ms = [1000.0 * timing.round_trip_s(k) for k in ("assign", "status", "resume")]
        route = "hop by hop" if link.protocol in GRANTS_PER_HOP else "whole"
        print(f"| {kind.type} | {link.protocol} | " + " | ".join(f"{m:.1f}" for m in ms)
              + f" | {route} |")
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--hours", type=float, default=8.0)
    args = parser.parse_args()
    seeds = list(range(1, args.seeds + 1))
    messages()
    runs = {name: [measure(changes, s, args.hours) for s in seeds]
            for name, changes in VARIANTS.items()}
    print(f"experiments/warehouse_mixed.yaml, {args.hours:g} h, seeds {seeds}: medians over "
          "seeds")
    print()
    print("| variant | " + " | ".join(COLUMNS) + " | commands/order | assign ms "
          "CarriRo / KTM-02 | parking trips cut short CarriRo / KTM-02 |")
    print("|---|" + "---:|" * (len(COLUMNS) + 3))
    for name, figures in runs.items():
        cells = [statistics.median(get(f) for f in figures) for get in COLUMNS.values()]
        assign = [statistics.median(f["assign_ms"].get(t, 0.0) for f in figures)
                  for t in TYPES]
        per_order = statistics.median(f["commands_per_order"] for f in figures)
        cut = [statistics.median(f["cut_short"][t] for f in figures) for t in TYPES]
        print(f"| {name} | " + " | ".join(f"{c:.1f}" for c in cells)
              + f" | {per_order:.1f} | {assign[0]:.1f} / {assign[1]:.1f} | "
              f"{cut[0]:.0f} / {cut[1]:.0f} |")
    print()
    print("Paired differences against off (same seed): median [min, max]")
    print()
    print("| variant | " + " | ".join(COLUMNS) + " |")
    print("|---|" + "---:|" * len(COLUMNS))
    base = runs[next(iter(VARIANTS))]
    for name, figures in list(runs.items())[1:]:
        cells = []
        for get in COLUMNS.values():
            diffs = [get(f) - get(b) for f, b in zip(figures, base, strict=True)]
            cells.append(f"{statistics.median(diffs):+.1f} [{min(diffs):+.1f}, "
                         f"{max(diffs):+.1f}]")
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
