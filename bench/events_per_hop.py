"""What the SimPy events of a run are spent on, per hop: the three 50-AGV warehouse shifts of
bench/engine_scaling.py's ring comparison, and the bare SimPy ring beside them.

Every event the environment schedules is counted by its kind (Timeout, Claim, Released,
FirstOf...) and by the fleet_sim function that made it (the first caller outside SimPy and the
engine's lean SimPy parts in fleet_sim/sim/traffic/locks.py:
`move` is a hop's drive, `wait` a blocked AGV's periodic look for a deadlock or another way,
`free` the Released event of a lock given back, `grant` a claim granted to an AGV that waited
for it, `_handle` the load and unload sub-states...). Events per hop and wall microseconds per
hop are printed beside the bare ring's (3 events per hop: request, timeout, release), with the
load average: compare figures within one run only. Events the engine pushes onto SimPy's queue
itself, not through `schedule` (the alarm clock's timers, fleet_sim.sim.traffic.waking, and an
LDS look at a time to the last bit, fleet_sim.sim.agents.lds), are counted where SimPy processes
them (`step`), in the total and in a row of their own. `--lds` adds what the LDS watch's
looks found (fleet_sim.sim.agents.lds.AgvAhead._look): the AGV ahead standing (a pause), driving,
nobody (waiting for a corridor, a zone or a free node), or a wait already over.

    .venv/bin/python bench/events_per_hop.py [--hours 2] [--lds]
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import time
from pathlib import Path
from typing import Any

import simpy
from simpy.core import Environment

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from engine_scaling import SHIFTS, bare_ring, model_run  # noqa: E402

from fleet_sim.model import records  # noqa: E402
from fleet_sim.sim.agents.lds import AgvAhead  # noqa: E402

LEAN_PARTS: dict[str, set[str] | None] = {
    "fleet_sim/sim/traffic/locks.py": {"__init__", "_check", "release"}}
"""The engine's own SimPy parts (file -> functions, None: all): their callers are counted,
as SimPy's are (`grant`, in locks.py, is counted itself)."""


def _simpy_part(code: Any) -> bool:
    name: str = code.co_filename
    if "simpy" in name:
        return True
    for path, functions in LEAN_PARTS.items():
        if name.endswith(path):
            return functions is None or code.co_name in functions
    return False

COUNTS: collections.Counter[tuple[str, str]] = collections.Counter()
HOPS = [0]
STEPS = [0]
"""Events processed (`Environment.step`), those pushed onto the queue directly among them."""


def _counting_schedule(original: Any) -> Any:
    def schedule(self: Environment, event: simpy.Event, priority: int = 1,
                 delay: float = 0) -> None:
        frame = sys._getframe(1)
        while frame is not None and _simpy_part(frame.f_code):
            frame = frame.f_back
        COUNTS[(type(event).__name__, frame.f_code.co_name if frame else "?")] += 1
        original(self, event, priority, delay)
    return schedule


def _counting_step(original: Any) -> Any:
    def step(self: Environment) -> None:
        STEPS[0] += 1
        original(self)
    return step


LOOKS: collections.Counter[str] = collections.Counter()


def _counting_look(original: Any) -> Any:
    def look(self: AgvAhead, find: Any, wait_no: int) -> None:
        if not self.waiting or self._wait_no != wait_no or self.paused_since is not None:
            LOOKS["the wait already over"] += 1
        else:
            found = find()
            if found is None:
                LOOKS["nobody (a corridor, a zone or a free node)"] += 1
            elif found[2] and found[1].standing:
                LOOKS["the AGV ahead standing (a pause)"] += 1
            elif not found[1].standing:
                LOOKS["the AGV ahead driving"] += 1
            else:
                LOOKS["the AGV ahead standing elsewhere"] += 1
        original(self, find, wait_no)
    return look


def _counting_drove(original: Any) -> Any:
    def drove(self: records.Recorder, start_s: float, end_s: float, length_m: float) -> None:
        HOPS[0] += 1
        original(self, start_s, end_s, length_m)
    return drove


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=2.0)
    parser.add_argument("--lds", action="store_true", help="what the LDS watch's looks found")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} "
          f"{os.getloadavg()[2]:.2f}; {args.hours:g} simulated hours each")
    wall, _ = bare_ring(hours=args.hours)
    ring_hops = 50 * args.hours * 3600 / 4.0
    print(f"bare ring: 3.00 events/hop, {wall / ring_hops * 1e6:.1f} us/hop")
    Environment.schedule = _counting_schedule(Environment.schedule)  # type: ignore[method-assign]
    Environment.step = _counting_step(Environment.step)  # type: ignore[method-assign]
    records.Recorder.drove = _counting_drove(records.Recorder.drove)  # type: ignore[method-assign]
    if args.lds:
        AgvAhead._look = _counting_look(AgvAhead._look)  # type: ignore[method-assign]
    for title, (scenario_file, overrides) in SHIFTS.items():
        COUNTS.clear()
        LOOKS.clear()
        HOPS[0] = STEPS[0] = 0
        start = time.perf_counter()
        _, run = model_run(scenario_file, {**overrides, "duration_h": args.hours})
        wall = time.perf_counter() - start
        hops = HOPS[0]
        scheduled = sum(COUNTS.values())
        left = len(run.vehicles[0].env._queue)  # scheduled or pushed, never processed
        COUNTS[("(pushed directly)", "alarm clock, LDS")] = STEPS[0] + left - scheduled
        total = sum(COUNTS.values())
        print()
        print(f"## {title}: {hops:,} hops, {total / hops:.2f} events/hop, "
              f"{wall / hops * 1e6:.0f} us/hop (wall {wall:.2f} s, load "
              f"{os.getloadavg()[0]:.2f})")
        print()
        print("| event | made by | per hop | share |")
        print("|---|---|---:|---:|")
        for (kind, by), n in COUNTS.most_common():
            if n / hops >= 0.01:
                print(f"| {kind} | {by} | {n / hops:.2f} | {n / total:.0%} |")
        if args.lds:
            looks = sum(LOOKS.values())
            print()
            print(f"LDS looks: {looks:,} ({looks / hops:.2f} a hop): " + ", ".join(
                f"{found} {n / max(looks, 1):.0%}" for found, n in LOOKS.most_common()))


if __name__ == "__main__":
    main()
