"""How fast is the engine? Three sections, each printing a table; these machines are noisy, so
compare figures within one run of this script only (the load average is printed).

* `ring`: the full model against a bare SimPy ring (400 nodes, 50 AGVs, node locks, 8 h) in the
  same process, interleaved (ring, model, ring, model, ...), medians of --repeats. The model
  runs the 50-AGV 8-hour shift of the warehouse: demand fixed at 150 orders/h (what the layout
  carries); every AGV busy (7.5 orders/h per AGV); and with everything on (the warehouse_wifi
  layout with every incident of experiments/warehouse_incidents.yaml, charging, admission of 20
  AGVs, congestion- and Wi-Fi-aware routes).
* `warehouse`: 8-hour shifts of the warehouse at --fleets AGVs, demand fixed at 150 orders/h
  (a fleet-sizing sweep; idle AGVs park) and every AGV busy.
* `dc`: the 627-node distribution centre at --dc-fleets AGVs with demand that keeps them about
  70 % busy by the analytic estimate (0.7 x AGVs x 3600 / cycle time), without admission and
  with --dc-max-active AGVs admitted: wall time per simulated AGV-hour against the 50-AGV
  figure. The layout carries ~200 orders/h, so beyond ~40 AGVs the demand exceeds it.
* `site`: the 2,059-node fulfilment centre (experiments/fulfilment_shift.yaml, congestion-aware
  routes as the scenario sets them) at --site-fleets
  AGVs for --site-hours, with demand --site-load times what the analytic estimate says the
  fleet can carry (--site-load x AGVs x 3600 / cycle time; nearest-idle dispatch shortens the
  empty legs, so 1.1 keeps every AGV busy until the floor saturates), without admission and
  with --site-max-active AGVs admitted. It prints delivered orders per hour, the busy share
  (agv_utilisation_pct, after the warm-up), SimPy events and wall ms per busy AGV-hour (busy
  AGV-hours: AGVs x simulated hours x busy share) and that cost against the 50-AGV figure.
  The admission table lists only the fleets larger than the limit (the others run as without).

`--policy NAME` runs every model with the override `traffic.policy: NAME` (a traffic policy
the scenario knows); without it, the scenario's. `--set KEY=VALUE` (repeatable) sets any
other scenario field for every model run (`--set rules.agv_ahead=held_back`: the model
before issue 33's reading of the AGV ahead). `--profile REGIME` (a ring regime: "150
orders/h", "every AGV busy", "everything on") profiles one more model run of it after the
sections and prints the functions by own time (cProfile: slower, shares only). The script
lowers its own CPU priority (`--nice`, default 10): the machine is shared.

    .venv/bin/python bench/engine_scaling.py [--sections ring warehouse dc site] [--repeats 3]
        [--profile "every AGV busy"]
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

import simpy
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_sim.analysis.kpi_sums import run_kpis  # noqa: E402
from fleet_sim.config.scenario import load_layout_for, load_scenario  # noqa: E402
from fleet_sim.sim.engine import RunOutput, collecting_seldom, simulate  # noqa: E402
from fleet_sim.sim.estimate import analytic_estimate  # noqa: E402
from userfiles.checking import InputError  # noqa: E402

SHIFT_H = 8.0
ORDERS_PER_AGV_HOUR = 7.5
FIXED_ORDERS_PER_HOUR = 150.0
BUSY_SHARE = 0.7
EXPERIMENTS = ROOT / "experiments"
EVERY_RUN: dict[str, Any] = {}
"""Overrides of every model run (--policy, --set), empty: the scenarios as they are."""


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
    with collecting_seldom():  # the collector as the model's runs have it (`simulate`)
        env.run(until=hours * 3600)
    return time.perf_counter() - start, next(env._eid)


def model_run(scenario_file: str, overrides: dict[str, Any]) -> tuple[float, RunOutput]:
    path = EXPERIMENTS / scenario_file
    scenario = load_scenario(path, {**overrides, **EVERY_RUN})
    layout = load_layout_for(scenario, str(path))
    start = time.perf_counter()
    run = simulate(scenario, layout)
    return time.perf_counter() - start, run


def delivered_per_hour(run: RunOutput) -> float:
    return sum(1 for o in run.recorder.orders if o.delivered_s is not None) \
        / run.scenario.duration_h


SHIFTS: dict[str, tuple[str, dict[str, Any]]] = {
    "150 orders/h": ("warehouse_shift.yaml", {
        "fleet.size": 50, "duration_h": SHIFT_H, "demand.rate_per_hour": FIXED_ORDERS_PER_HOUR,
        "demand.profile": []}),
    "every AGV busy": ("warehouse_shift.yaml", {
        "fleet.size": 50, "duration_h": SHIFT_H,
        "demand.rate_per_hour": ORDERS_PER_AGV_HOUR * 50, "demand.profile": []}),
    "everything on": ("warehouse_incidents.yaml", {
        "fleet.size": 50, "duration_h": SHIFT_H, "demand.rate_per_hour": FIXED_ORDERS_PER_HOUR,
        "dispatch.max_active_agvs": 20, "traffic.congestion_cost_s": 10.0,
        "traffic.weak_wifi_cost_s": 30.0}),
}


def ring_section(repeats: int) -> None:
    print("## 50 AGVs, 8-hour shift, against a bare SimPy ring (400 nodes, 50 AGVs, 8 h), "
          f"interleaved, medians of {repeats}")
    print()
    header = ("warehouse shift", "ring s", "model s", "model / ring", "SimPy events/s",
              "delivered/h")
    print("| " + " | ".join(header) + " |")
    print("|---|" + "|".join("---:" for _ in header[1:]) + "|")
    for title, (scenario_file, overrides) in SHIFTS.items():
        rings: list[float] = []
        models: list[float] = []
        run: RunOutput | None = None
        for _ in range(repeats):
            rings.append(bare_ring()[0])
            wall, run = model_run(scenario_file, overrides)
            models.append(wall)
        assert run is not None
        ring_s, model_s = statistics.median(rings), statistics.median(models)
        print(f"| {title} | {ring_s:.2f} | {model_s:.2f} | {model_s / ring_s:.2f} | "
              f"{run.sim_events / model_s:,.0f} | {delivered_per_hour(run):.0f} |", flush=True)
    print()


def warehouse_section(fleets: list[int], repeats: int) -> None:
    ring_wall = statistics.median(bare_ring()[0] for _ in range(repeats))
    print(f"bare SimPy ring, 400 nodes, 50 AGVs, {SHIFT_H:.0f} h: {ring_wall:.2f} s wall "
          f"(median of {repeats})")
    print()
    for title, per_agv in (("fleet-sizing sweep: demand fixed at 150 orders/h", None),
                           ("every AGV busy: demand 7.5 orders/h per AGV", ORDERS_PER_AGV_HOUR)):
        print(f"## realistic warehouse, {SHIFT_H:.0f} h shift, {title}")
        print()
        header = ("AGVs", "wall s", "sim h / wall s", "events/s", "ms per sim h per AGV",
                  "x ring", "delivered/h")
        print("| " + " | ".join(header) + " |")
        print("|" + "|".join("---:" for _ in header) + "|")
        for agvs in fleets:
            rate = FIXED_ORDERS_PER_HOUR if per_agv is None else per_agv * agvs
            runs = [model_run("warehouse_shift.yaml", {
                "fleet.size": agvs, "duration_h": SHIFT_H, "demand.rate_per_hour": rate,
                "demand.profile": []}) for _ in range(repeats)]
            wall = statistics.median(r[0] for r in runs)
            first = runs[0][1]
            print(f"| {agvs} | {wall:.2f} | {SHIFT_H / wall:.1f} | "
                  f"{first.sim_events / wall:,.0f} | {wall / SHIFT_H / agvs * 1000:.1f} | "
                  f"{wall / ring_wall:.2f} | {delivered_per_hour(first):.0f} |", flush=True)
        print()


def dc_section(fleets: list[int], hours: float, max_active: int, repeats: int) -> None:
    path = EXPERIMENTS / "warehouse_shift.yaml"
    base = {"layout": "../layouts/distribution_centre.yaml", "duration_h": hours,
            "warmup_h": 0.5, "demand.profile": []}
    scenario = load_scenario(path, base)
    estimate = analytic_estimate(scenario, load_layout_for(scenario, str(path)))
    per_agv = BUSY_SHARE * 3600.0 / estimate.cycle_s
    print(f"## distribution centre (627 nodes), {hours:g} h, demand {per_agv:.2f} orders/h "
          f"per AGV ({BUSY_SHARE:.0%} busy by the analytic estimate, {estimate.cycle_s:.0f} s "
          f"per order), medians of {repeats}")
    for rule in (None, max_active):
        print()
        print("without admission" if rule is None
              else f"with admission: at most {rule} AGVs on the track")
        print()
        header = ("AGVs", "demand/h", "wall s", "ms per sim AGV-h", "x 50 AGVs", "events/s",
                  "delivered/h", "busy %", "deadlocks")
        print("| " + " | ".join(header) + " |")
        print("|" + "|".join("---:" for _ in header) + "|")
        at_50: float | None = None
        for agvs in fleets:
            overrides = {**base, "fleet.size": agvs, "demand.rate_per_hour": per_agv * agvs}
            if rule is not None and agvs > rule:
                overrides["dispatch.max_active_agvs"] = rule
            runs = [model_run("warehouse_shift.yaml", overrides) for _ in range(repeats)]
            wall = statistics.median(r[0] for r in runs)
            run = runs[0][1]
            cost = wall / hours / agvs * 1000
            if agvs == 50:
                at_50 = cost
            ratio = f"{cost / at_50:.2f}" if at_50 else ""
            figures = run_kpis(run)
            print(f"| {agvs} | {per_agv * agvs:.0f} | {wall:.1f} | {cost:.1f} | {ratio} | "
                  f"{run.sim_events / wall:,.0f} | {figures['throughput_per_hour']:.0f} | "
                  f"{figures['agv_utilisation_pct']:.0f} | {run.recorder.deadlocks} |",
                  flush=True)
    print()


def site_section(fleets: list[int], hours: float, load: float, max_active: int,
                 repeats: int) -> None:
    scenario_file = "fulfilment_shift.yaml"
    path = EXPERIMENTS / scenario_file
    base: dict[str, Any] = {"duration_h": hours, "warmup_h": 0.5, "demand.profile": []}
    scenario = load_scenario(path, {**base, **EVERY_RUN})
    estimate = analytic_estimate(scenario, load_layout_for(scenario, str(path)))
    per_agv = load * 3600.0 / estimate.cycle_s
    policy = EVERY_RUN.get("traffic.policy", "the scenario's")
    routes = (f"congestion-aware routes ({scenario.traffic.congestion_cost_s:g} s)"
              if scenario.traffic.congestion_cost_s else "shortest routes")
    print(f"## fulfilment centre (2,059 nodes), {hours:g} h, traffic policy {policy}, {routes}, "
          "demand "
          f"{per_agv:.2f} orders/h per AGV ({load:g} x the analytic estimate's "
          f"{3600.0 / estimate.cycle_s:.2f}: {estimate.cycle_s:.0f} s per order), medians of "
          f"{repeats}")
    at_50: float | None = None
    for rule in (None, max_active):
        rows = fleets if rule is None else [agvs for agvs in fleets if agvs > rule]
        if not rows:
            continue
        print()
        print("without admission" if rule is None
              else f"with admission: at most {rule} AGVs on the track (smaller fleets: as "
                   "without; x 50 AGVs: against the 50-AGV figure above)")
        print()
        header = ("AGVs", "demand/h", "delivered/h", "busy %", "wall s", "events per busy AGV-h",
                  "ms per busy AGV-h", "x 50 AGVs", "deadlocks")
        print("| " + " | ".join(header) + " |")
        print("|" + "|".join("---:" for _ in header) + "|")
        for agvs in rows:
            overrides = {**base, "fleet.size": agvs, "demand.rate_per_hour": per_agv * agvs}
            if rule is not None:
                overrides["dispatch.max_active_agvs"] = rule
            runs = [model_run(scenario_file, overrides) for _ in range(repeats)]
            wall = statistics.median(r[0] for r in runs)
            run = runs[0][1]
            figures = run_kpis(run)
            busy = figures["agv_utilisation_pct"] / 100.0
            busy_agv_h = agvs * hours * busy
            cost = wall * 1000 / busy_agv_h
            if agvs == 50 and rule is None:
                at_50 = cost
            ratio = f"{cost / at_50:.2f}" if at_50 else ""
            print(f"| {agvs} | {per_agv * agvs:.0f} | {figures['throughput_per_hour']:.0f} | "
                  f"{busy:.0%} | {wall:.1f} | {run.sim_events / busy_agv_h:,.0f} | {cost:.1f} | "
                  f"{ratio} | {run.recorder.deadlocks} |", flush=True)
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sections", nargs="+", default=["ring", "warehouse", "dc", "site"],
                        choices=["ring", "warehouse", "dc", "site"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fleets", type=int, nargs="+", default=[10, 25, 50, 100])
    parser.add_argument("--dc-fleets", type=int, nargs="+", default=[10, 25, 50, 100, 200, 500])
    parser.add_argument("--dc-hours", type=float, default=4.0)
    parser.add_argument("--dc-max-active", type=int, default=40)
    parser.add_argument("--dc-repeats", type=int, default=1)
    parser.add_argument("--site-fleets", type=int, nargs="+", default=[50, 100, 200, 300, 500])
    parser.add_argument("--site-hours", type=float, default=2.5)
    parser.add_argument("--site-load", type=float, default=1.1)
    parser.add_argument("--site-max-active", type=int, default=300)
    parser.add_argument("--site-repeats", type=int, default=1)
    parser.add_argument("--policy", help="traffic.policy for every model run")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a scenario field for every model run, the value in YAML "
                        "(--set rules.agv_ahead=held_back); repeat for several")
    parser.add_argument("--nice", type=int, default=10, help="added to this process's niceness")
    parser.add_argument("--profile", choices=list(SHIFTS), help="profile one ring regime's run")
    args = parser.parse_args()
    os.nice(args.nice)
    if args.policy:
        EVERY_RUN["traffic.policy"] = args.policy
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep or not key:
            parser.error(f"--set {item!r}: expected KEY=VALUE")
        EVERY_RUN[key] = yaml.safe_load(value)
    try:  # a field or value the scenarios refuse: one line, before any run
        load_scenario(EXPERIMENTS / "warehouse_shift.yaml", EVERY_RUN)
    except InputError as exc:
        parser.error(f"--policy/--set: {exc}")
    if EVERY_RUN:
        print("every model run with " + ", ".join(f"{k}={v}" for k, v in EVERY_RUN.items()))
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    print()
    if "ring" in args.sections:
        ring_section(args.repeats)
    if "warehouse" in args.sections:
        warehouse_section(args.fleets, args.repeats)
    if "dc" in args.sections:
        dc_section(args.dc_fleets, args.dc_hours, args.dc_max_active, args.dc_repeats)
    if "site" in args.sections:
        site_section(args.site_fleets, args.site_hours, args.site_load, args.site_max_active,
                     args.site_repeats)
    if args.profile:
        profile_shift(args.profile)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


def profile_shift(title: str) -> None:
    """One model run of a ring regime under cProfile: the functions by own time."""
    scenario_file, overrides = SHIFTS[title]
    profile = cProfile.Profile()
    profile.enable()
    model_run(scenario_file, overrides)
    profile.disable()
    text = io.StringIO()
    pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(20)
    print(f"## profile: {title}")
    print("\n".join(text.getvalue().splitlines()[2:]))


if __name__ == "__main__":
    main()
