"""The engine's environment (fleet_sim.sim.clock.Clock): SimPy's event loop written out, which
must process the same events in the same order and stop, return and fail as SimPy's does."""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

import pytest
import simpy

from fleet_sim.sim.clock import Clock

from .test_locks import _script


@pytest.mark.parametrize("seed", range(10))
def test_same_steps_as_simpy(seed: int) -> None:
    assert _script(seed, True, Clock()) == _script(seed, True, simpy.Environment())
    assert _script(seed, False, Clock()) == _script(seed, False, simpy.Environment())


def _runs(env: simpy.Environment) -> list[Any]:
    """run(until=a time) in steps, run(until=an event) for its value, run() to the end."""
    seen: list[Any] = []

    def ticker() -> Generator[simpy.Event, Any, str]:
        for i in range(5):
            yield env.timeout(1.5)
            seen.append(("tick", env.now, i))
        return "done"

    process = env.process(ticker())
    seen.append(env.run(until=2))
    seen.append(env.now)
    seen.append(env.run(until=process))
    seen.append(env.now)
    env.timeout(3)
    seen.append(env.run())
    seen.append(env.now)
    return seen


def test_runs_stop_and_return_as_simpy() -> None:
    assert _runs(Clock()) == _runs(simpy.Environment())


@pytest.mark.parametrize("make", [Clock, simpy.Environment])
def test_a_failed_event_and_an_unreached_until_raise_as_in_simpy(make: type) -> None:
    env = make()
    env.event().fail(KeyError("lost"))
    with pytest.raises(KeyError):
        env.run()
    env = make()
    with pytest.raises(RuntimeError, match="until"):
        env.run(until=env.event())
    with pytest.raises(ValueError):
        env.run(until=env.now)
