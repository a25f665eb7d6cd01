"""The commands of the vehicle's motion: `crosscheck` (the closed-form and the SUMO backends
side by side) and `emulate` (a virtual vehicle on a pseudo-terminal).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fleet_sim.cli.arguments import AGVS, HOURS_ARG, SEED, SEED_ARG
from fleet_sim.cli.registry import arg, command
from fleet_sim.config.overrides import Agvs
from fleet_sim.errors import FleetSimError


@command(
    "crosscheck", "run a scenario with the closed-form and the SUMO motion backends and "
    "compare the KPIs (each run in its own process)",
    arg("scenario", type=Path, help="scenario YAML file"),
    arg("--agvs", type=AGVS, nargs="+", metavar="N",
        help="fleet sizes to compare (default: the scenario's); a mixed fleet: TYPE=N[,TYPE=N] "
             "each"),
    HOURS_ARG,
    SEED_ARG)
def _crosscheck(args: argparse.Namespace) -> int:
    """One table per fleet size: KPIs and wall time of each backend, and SUMO's difference."""
    from fleet_sim.config.overrides import flag_overrides, fleet_overrides, load_scenario
    from fleet_sim.config.scenario import load_layout_for
    from fleet_sim.study.crosscheck import crosscheck, table

    # bad input fails here, before any run
    scenario = load_scenario(args.scenario, hours=args.hours, seed=args.seed)
    base = flag_overrides(args.hours, args.seed)
    load_layout_for(scenario, str(args.scenario))
    for size in args.agvs or [None]:
        overrides = base if size is None else {**base, **fleet_overrides(size, scenario)}
        fleet = scenario.fleet
        text = _fleet_text(size) if size is not None else _fleet_text(
            {t.type: t.count for t in fleet.vehicles} if fleet.vehicles else fleet.size)
        print(f"{scenario.name}: {text}, {scenario.duration_h:g} h "
              f"(warm-up {scenario.warmup_h:g} h), seed {scenario.seed}", flush=True)
        print(table(crosscheck(args.scenario, overrides)), flush=True)
        print()
    return 0


@command(
    "emulate", "serve a virtual vehicle on a pseudo-terminal",
    arg("protocol", help="carriro, ktm02, tabo or agv3"),
    arg("--profile", help="vehicle profile (default: the one for the protocol)"),
    arg("--seed", type=SEED, help="seed of the link jitter"))
def _emulate(args: argparse.Namespace) -> int:
    """Print the pty path first, answer until Ctrl-C or SIGTERM, exit 0."""
    from agv_model.emulate import EmulateError, choose_profile, serve

    try:
        return serve(choose_profile(args.protocol, args.profile), seed=args.seed)
    except EmulateError as exc:
        raise FleetSimError(str(exc)) from None


def _fleet_text(agvs: Agvs) -> str:
    if isinstance(agvs, int):
        return f"{agvs} AGVs"
    return " + ".join(f"{n} {name}" for name, n in agvs.items())
