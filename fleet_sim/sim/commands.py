"""The fleet manager's command path to the AGVs, over each vehicle's real protocol and link.

With `fleet.command_profile` set, every command costs what the profile's link takes to carry it
(agv_model.fleet_commands: the protocol's real messages, encoded, timed on the link model):
an order or a charger reaches an AGV one `assign` round trip after the fleet manager decided;
a `resume` follows a restored link; a `stop` carries a scheduled charging call. A command that
misses its reply timeout is sent again (counted in `command_retries`).

With `fleet.status_poll_s` > 0 the fleet manager learns that an AGV has become free only at its
next status poll of that AGV (polls are spread over the period by AGV number), plus the status
reply; events in between wait. 0 means the AGV reports at once.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import Any

import numpy as np
import simpy

from agv_model.fleet_commands import CommandTiming, Kind
from fleet_sim.model.records import Recorder

GOLDEN = 0.6180339887498949
"""Spreads the AGVs' poll phases evenly over the period, whatever the fleet size."""


class CommandPath:
    def __init__(self, env: simpy.Environment, profile: str | None, poll_s: float,
                 rng: np.random.Generator, recorder: Recorder) -> None:
        self.env = env
        self.timing = CommandTiming.for_profile(profile) if profile else None
        self.poll_s = poll_s
        self.rng = rng
        self.recorder = recorder

    @property
    def immediate(self) -> bool:
        """Commands take no time (no `fleet.command_profile`)."""
        return self.timing is None

    def send(self, kind: Kind, then: Callable[[], object]) -> None:
        """Send a command; `then` runs when the AGV has it (at once without a profile)."""
        if self.timing is None:
            then()
            return
        self.env.process(self._send(kind, then))

    def _send(self, kind: Kind, then: Callable[[], object]) -> Generator[simpy.Event, Any, None]:
        yield from self.wait(kind)
        then()

    def wait(self, kind: Kind) -> Generator[simpy.Event, Any, None]:
        """The time one command takes, retries included (for a process to yield from)."""
        if self.timing is None:
            return
        while True:
            attempt = self.timing.attempt(kind, self.rng)
            self.recorder.commands_sent += 1
            yield self.env.timeout(attempt.seconds)
            if not attempt.timed_out:
                return
            self.recorder.command_retries += 1

    def notice_delay_s(self, agv: int) -> float:
        """How long until the fleet manager learns of a change on AGV `agv` (next poll)."""
        if self.poll_s <= 0:
            return 0.0
        phase = (agv * GOLDEN) % 1.0 * self.poll_s
        since = (self.env.now - phase) % self.poll_s
        wait = 0.0 if since == 0 else self.poll_s - since
        reply = self.timing.reply_s("status") if self.timing is not None else 0.0
        return wait + reply
