"""The same scenario with both motion backends, side by side (`fleet-sim crosscheck`).

Each run happens in a fresh process (multiprocessing, spawn): libsumo allows one simulation per
process, is not thread-safe, and a crash in it ends its process, which must not be this one.
The closed-form run gets its own process too, so the wall times compare like with like.
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

from fleet_sim.errors import FleetSimError
from fleet_sim.sim.sumo import require_backend

MOTIONS = ("closed_form", "sumo")
COLUMNS = (("throughput_per_hour", "throughput /h", "{:.1f}"),
           ("lead_time_mean_s", "lead mean s", "{:.1f}"),
           ("lead_time_p95_s", "lead p95 s", "{:.1f}"),
           ("blocked_time_pct", "blocked %", "{:.2f}"),
           ("distance_km", "distance km", "{:.2f}"),
           ("wall_s", "wall s", "{:.1f}"))


def run_here(scenario_file: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """Run one scenario in this process; its KPIs plus wall time and SimPy event count."""
    from fleet_sim.analysis.kpi_sums import run_kpis
    from fleet_sim.config.scenario import load_layout_for, load_scenario
    from fleet_sim.config.trace import load_trace
    from fleet_sim.sim.engine import simulate

    scenario = load_scenario(scenario_file, overrides)
    layout = load_layout_for(scenario, scenario_file)
    trace = []
    if scenario.demand.kind == "trace":
        assert scenario.demand.trace_csv is not None
        trace = load_trace(scenario.path(scenario.demand.trace_csv), layout)
    run = simulate(scenario, layout, trace)
    figures = run_kpis(run)
    figures["wall_s"] = run.wall_s
    figures["sim_events"] = run.sim_events
    figures["motion"] = scenario.motion
    figures["delivered_s"] = sorted(o.delivered_s for o in run.recorder.orders
                                    if o.delivered_s is not None)
    return figures


def _run_child(scenario_file: str, overrides: dict[str, Any]) -> dict[str, Any]:
    try:
        return run_here(scenario_file, overrides)
    except Exception as exc:  # libsumo's exceptions do not pickle; ours carry extra arguments
        raise FleetSimError(str(exc)) from None


def run_isolated(scenario_file: str | Path, overrides: dict[str, Any]) -> dict[str, Any]:
    """`run_here` in a fresh process (a SUMO crash ends that process, not this one). A
    process that dies raises FleetSimError."""
    context = multiprocessing.get_context("spawn")
    try:
        with ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
            return pool.submit(_run_child, str(scenario_file), dict(overrides)).result()
    except BrokenProcessPool:
        raise FleetSimError(f"the run of {scenario_file} ({overrides}) ended its process "
                            "(a crash in SUMO?)") from None


def crosscheck(scenario_file: str | Path, overrides: dict[str, Any],
               motions: tuple[str, ...] = MOTIONS) -> dict[str, dict[str, Any]]:
    """KPIs of the scenario under each motion backend, each run in its own process."""
    for motion in motions:  # before any run: one line if an extra is missing
        require_backend(motion, f"crosscheck: motion: {motion}")
    out: dict[str, dict[str, Any]] = {}
    for motion in motions:
        start = time.perf_counter()
        out[motion] = run_isolated(scenario_file, {**overrides, "motion": motion})
        out[motion]["process_wall_s"] = time.perf_counter() - start
    return out


def table(results: dict[str, dict[str, Any]]) -> str:
    """The KPIs side by side, with SUMO's difference from the closed form."""
    header = f"{'':22}" + "".join(f"{label:>15}" for _, label, _ in COLUMNS)
    lines = [header]
    for motion, figures in results.items():
        cells = "".join(f"{_fmt(figures.get(key), fmt):>15}" for key, _, fmt in COLUMNS)
        lines.append(f"{motion:22}" + cells)
    if set(MOTIONS) <= set(results):
        base, sumo = results["closed_form"], results["sumo"]
        cells = ""
        for key, _, _ in COLUMNS:
            a, b = base.get(key), sumo.get(key)
            if key == "wall_s" and a and b:
                cells += f"{f'x{b / a:.1f}':>15}"
            elif isinstance(a, float | int) and isinstance(b, float | int) and a:
                cells += f"{f'{100.0 * (b - a) / a:+.1f} %':>15}"
            else:
                cells += f"{'n/a':>15}"
        lines.append(f"{'sumo vs closed_form':22}" + cells)
    return "\n".join(lines)


def _fmt(value: Any, fmt: str) -> str:
    return "n/a" if value is None else fmt.format(value)
