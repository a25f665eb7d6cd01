"""A blocked AGV's look times (fleet_sim.sim.traffic.waking.Sleeper): the floats a timer of
`deadlock_check_s` set again at each look gives (each the last plus the period), found without
walking the whole wait at every call, and never the instant it has just looked at."""

from __future__ import annotations

import simpy

from fleet_sim.sim.traffic.waking import SCAN_LOOKS, AlarmClock, Sleeper


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
