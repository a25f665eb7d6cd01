"""Gridlock: telling when the fleet has locked solid.

Traffic resolves most wait-for cycles within seconds (fleet_sim.sim.traffic.deadlock); one that
no escape can break (`deadlock_unresolved`: every member boxed in) stays for the rest of the
run, and the AGVs queued behind it stop too. A watcher process looks every tenth of
`traffic.gridlock_after_s` and records the first time either of these has lasted
`gridlock_after_s`:

* **cycle**: a wait-for cycle whose members have all been waiting, unbroken, for that long.
  It locked when the cycle closed: when its last member began the wait it is still in.
* **standstill**: no AGV has finished a hop for that long while orders are open and at least
  one AGV has been waiting for a lock all along (a chain ending at an AGV that never moves
  again, with no cycle). It locked at the later of the last hop's end and the oldest such
  wait's start. A fleet standing still for other reasons (charging, Idle for want of
  admission, down) has no lock waits that long and is not called locked.

A standstill is a traffic gridlock only if traffic explains it: when every chain of those waits
ends at an AGV held by its battery or out of service (charging, waiting for or on its way to a
charger, at or below the charging threshold; Error, Maintenance, SafeMode, but not after an
obstacle timeout, E_101, which a jam itself ends in: fleet_sim.model.stalls), the AGVs behind
stand for the charger queue or the repair, not for traffic, and it is not recorded: the stall
is measured as what it is (the KPIs charging_starvation_h and out_of_service_h), and the
watcher goes on looking. A wait-for cycle is traffic whoever its members are.

What it records: a `gridlock` event (at the moment it is told, on the first AGV named; the
detail says since when, which AGVs and the nodes they stand at) and `Recorder.gridlock`, from
which the KPIs take `gridlock_at_h` and the summary its warning. The watcher only reads: it
draws no random numbers and changes no lock.

The choices where the issues were silent (the threshold, one gridlock per run, what "no AGV
moves" means): docs/background/decisions/sim.md.
"""

from __future__ import annotations

from collections.abc import Generator, Mapping, Sequence
from typing import Any

import simpy

from fleet_sim.model.records import Gridlock, Recorder
from fleet_sim.sim.traffic.control import Traffic
from fleet_sim.sim.traffic.deadlock import chain_heads, find_cycle
from fleet_sim.sim.traffic.locks import Lock

CHECKS_PER_THRESHOLD = 10
"""The watcher looks every `gridlock_after_s / 10`: told at most that late (the time it
records, when the fleet locked, is exact)."""


def watch(env: simpy.Environment, traffic: Traffic, vehicles: Sequence[Any],
          recorder: Recorder, after_s: float) -> Generator[simpy.Event, Any, None]:
    """The watcher process (see the module)."""
    step = after_s / CHECKS_PER_THRESHOLD
    while True:
        yield env.timeout(step)
        found = locked(env.now, traffic, vehicles, recorder, after_s)
        if found is not None:
            recorder.gridlock = found
            first = vehicles[found.agvs[0]]
            state = first.state.value
            recorder.event(env.now, first.id, "gridlock", state, state, first.node,
                           f"since {found.since_s:.1f} s: {found.where()}")
            return


def locked(now_s: float, traffic: Traffic, vehicles: Sequence[Any], recorder: Recorder,
           after_s: float) -> Gridlock | None:
    """The gridlock standing at `now_s` for at least `after_s`, if any (cycle first)."""
    waits = recorder.open_waits
    old = sorted(agv for agv, (since, _) in waits.items() if since <= now_s - after_s)
    if not old:
        return None
    waiting = traffic.waiting
    for agv in old:
        if agv not in waiting:
            continue
        cycle = find_cycle(agv, waiting)
        if cycle is None:
            continue
        since = max(waits[m][0] if m in waits else now_s for m in cycle)
        if now_s - since >= after_s:
            return Gridlock(since, tuple(cycle), tuple(vehicles[m].node for m in cycle),
                            "cycle")
    if recorder.open_orders and now_s - recorder.moved_s >= after_s \
            and not held_up_off_traffic(old, waiting, recorder):
        since = max(recorder.moved_s, min(waits[agv][0] for agv in old))
        return Gridlock(since, tuple(old), tuple(vehicles[m].node for m in old), "standstill")
    return None


def held_up_off_traffic(agvs: Sequence[int], waiting: Mapping[int, Lock],
                        recorder: Recorder) -> bool:
    """Does every chain of lock waits from `agvs` end at an AGV held by its battery or out of
    service (`StallMeter.explains_standstill`)? False if any ends elsewhere, or at a lock
    nobody holds, or runs round a cycle."""
    stalls = recorder.stalls
    if stalls is None:
        return False
    heads = chain_heads(agvs, waiting)
    return heads is not None and all(stalls.explains_standstill(agv) for agv in heads)
