"""A blocked AGV's look times (fleet_sim.sim.traffic.waking.Sleeper): the floats a timer of
`deadlock_check_s` set again at each look gives (each the last plus the period), found without
walking the whole wait at every call, and never the instant it has just looked at; and what
waking only on change buys: at most 2.5 SimPy events a hop on the 50-AGV warehouse shift."""

from __future__ import annotations

import pytest
import simpy

from fleet_sim.config.scenario import load_layout_for, load_scenario
from fleet_sim.model.records import Recorder
from fleet_sim.sim.engine import simulate
from fleet_sim.sim.traffic.waking import SCAN_LOOKS, AlarmClock, Sleeper

from .conftest import ROOT


def _sleeper(env: simpy.Environment, start_s: float, period_s: float) -> Sleeper:
    def idle() -> simpy.events.ProcessGenerator:
        yield env.timeout(1e12)

    return Sleeper(env.process(idle()), AlarmClock(env), start_s, period_s)


def _looks(start_s: float, period_s: float, n: int) -> list[float]:
    out, at_s = [], start_s
    for _ in range(n):
        at_s = at_s + period_s
        out.append(at_s)
    return out


def test_look_times_are_the_timers_floats_as_the_wait_goes_on() -> None:
    """Asked again and again as time goes on (a wait of 2,000 looks), the next look is the
    first of the summed floats after now, equal to the last bit."""
    env = simpy.Environment(initial_time=3.7)
    sleeper = _sleeper(env, 3.7, 0.1)
    looks = _looks(3.7, 0.1, 2_100)
    for i in range(0, 2_000, 7):
        env.run(until=looks[i] - 0.05)
        assert sleeper.next_look() == looks[i]
        assert sleeper.first_look_waited(looks[i + 50] - 3.7) == looks[i + 50]


def test_the_instant_just_looked_at_is_not_looked_at_again() -> None:
    """At one of its look times, before it has looked, that time is its next look; once it
    has looked (`looked_s`), the one after (a suspect woken with nothing changed set its
    alarm for the instant it had looked at, and spun there for ever)."""
    env = simpy.Environment()
    sleeper = _sleeper(env, 0.0, 10.0)
    env.run(until=30.0)
    assert sleeper.next_look() == 30.0
    sleeper.looked_s = 30.0
    assert sleeper.next_look() == 40.0


def test_a_far_threshold_is_reached_in_steps_of_scan_looks() -> None:
    """A threshold days away (`replan_after_s: 1e9`) gives a look at most SCAN_LOOKS periods
    on (a look time all the same), not a walk through 1e8 look times; from there, the next
    step, until the threshold's own look time."""
    env = simpy.Environment()
    sleeper = _sleeper(env, 0.0, 10.0)
    first = sleeper.first_look_waited(1e9)
    assert first == _looks(0.0, 10.0, SCAN_LOOKS)[-1]
    near = sleeper.first_look_waited(100.0)
    assert near == 100.0
    env.run(until=first)  # the scan counts the look at now: SCAN_LOOKS - 1 looks on
    assert sleeper.first_look_waited(1e9) == _looks(0.0, 10.0, 2 * SCAN_LOOKS - 1)[-1]


def test_the_50_agv_shift_processes_at_most_2_5_simpy_events_a_hop(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 35's target, on bench/sumo_vs_engine.py's scenario (the warehouse shift, 50 AGVs,
    8 hours, 150 orders/h, its demand profile): a blocked AGV and an LDS watch cost events only
    where they may see a change, and an event that would be processed next is processed at
    once. Every event SimPy processes counts, those pushed onto its queue directly too (2.35 a
    hop when written; 5.27 with the blocked AGVs' and the LDS's periodic looks)."""
    processed = [0]
    hops = [0]
    step = simpy.Environment.step
    drove = Recorder.drove

    def counted_step(env: simpy.Environment) -> None:
        processed[0] += 1
        step(env)

    def counted_drove(recorder: Recorder, start_s: float, end_s: float, length_m: float) -> None:
        hops[0] += 1
        drove(recorder, start_s, end_s, length_m)

    monkeypatch.setattr(simpy.Environment, "step", counted_step)
    monkeypatch.setattr(Recorder, "drove", counted_drove)
    path = ROOT / "experiments" / "warehouse_shift.yaml"
    scenario = load_scenario(path, {"fleet.size": 50, "duration_h": 8.0, "warmup_h": 0.5,
                                    "demand.rate_per_hour": 150.0})
    simulate(scenario, load_layout_for(scenario, path))
    assert hops[0] > 60_000  # (68,330 when written)
    assert processed[0] / hops[0] <= 2.5
