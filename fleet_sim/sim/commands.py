"""The fleet manager's command path to the AGVs, over each vehicle's real protocol and link.

Each AGV is reached over its own link (`AgvLink`, one per AGV, built from the scenario by
`CommandPath.for_scenario`): with `fleet.command_timing: auto` (the default) an AGV of a type
whose profile has a protocol (`fleet.vehicles[].profile`: carriro-ad-plus, ktm-02, tabo, agv-3)
is timed on that profile's protocol and link, so a mixed fleet of CarriRo AD+ and KTM-02 AGVs
talks to each over its own; `fleet.command_profile` (one-type fleets) times every AGV on one
profile's. Other AGVs (no profile, the generic rss-agv-001 profile, `command_timing: off`)
take no time: their commands act at once and nothing below happens for them.

A timed command costs what the link takes to carry it (agv_model.fleet_commands: the
protocol's real messages, encoded, timed on the link model): an order or a charger reaches an
AGV one `assign` round trip after the fleet manager decided; a `resume` follows a restored
link; a `stop` carries a scheduled charging call. A command that misses its reply timeout is
sent again (counted in `command_retries`). Every message counts in `commands_sent`.

The boot report is one `status` round trip, and a route granted hop by hop costs a permission
message per hop (`traffic.grants`), waited for only if it has not come when the AGV gets there:
the readings of the documents behind these are in docs/background/decisions/sim.md.

With `fleet.status_poll_s` > 0 the fleet manager learns that an AGV has become free only at its
next status poll of that AGV (polls are spread over the period by AGV number), plus the status
reply on its link; events in between wait. 0 means the AGV reports at once.
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import simpy

from agv_model.fleet_commands import GRANTS_PER_HOP, PERMISSION, CommandTiming, Kind
from fleet_sim.config.scenario import CommandLink, Scenario
from fleet_sim.errors import SimulationError
from fleet_sim.model.records import Recorder

GOLDEN = 0.6180339887498949
"""Spreads the AGVs' poll phases evenly over the period, whatever the fleet size."""


@dataclass(frozen=True)
class AgvLink:
    """How the fleet manager reaches one AGV."""

    timing: CommandTiming | None = None
    """Its protocol's commands on its link; None: commands take no time."""
    per_hop: bool = False
    """Its route is granted hop by hop: each hop's permission is a message (timed only)."""


INSTANT = AgvLink()
"""An AGV whose commands take no time."""


class CommandPath:
    def __init__(self, env: simpy.Environment, links: Sequence[AgvLink] | AgvLink,
                 poll_s: float, rng: np.random.Generator, recorder: Recorder) -> None:
        """`links`: one per AGV, by AGV number, or one for every AGV."""
        self.env = env
        self.links: Sequence[AgvLink] | None = None if isinstance(links, AgvLink) else links
        self.link_all = links if isinstance(links, AgvLink) else INSTANT
        self.poll_s = poll_s
        self.rng = rng
        self.recorder = recorder
        self._free_s: dict[int, float] = {}
        """AGV id -> when its link has carried the last permission sent to it."""

    @classmethod
    def for_scenario(cls, env: simpy.Environment, scenario: Scenario,
                     rng: np.random.Generator, recorder: Recorder) -> CommandPath:
        """Each AGV's link as the scenario says (`fleet.agv_command_links`, `traffic.grants`);
        every AGV instant when none is timed."""
        wanted = scenario.fleet.agv_command_links
        grants = scenario.traffic.grants
        made: dict[CommandLink, AgvLink] = {}
        for link in wanted:
            if link is not None and link not in made:
                per_hop = grants == "per_hop" or (grants == "auto"
                                                  and link.protocol in GRANTS_PER_HOP)
                made[link] = AgvLink(CommandTiming(link.protocol, link.link), per_hop)
        if not made:
            return cls(env, INSTANT, scenario.fleet.status_poll_s, rng, recorder)
        return cls(env, [INSTANT if link is None else made[link] for link in wanted],
                   scenario.fleet.status_poll_s, rng, recorder)

    @classmethod
    def for_profile(cls, env: simpy.Environment, profile: str | None, poll_s: float,
                    rng: np.random.Generator, recorder: Recorder,
                    per_hop: bool = False) -> CommandPath:
        """Every AGV on bundled profile `profile`'s link (None: commands take no time)."""
        link = INSTANT if profile is None \
            else AgvLink(CommandTiming.for_profile(profile), per_hop)
        return cls(env, link, poll_s, rng, recorder)

    def link_of(self, agv: int) -> AgvLink:
        return self.link_all if self.links is None else self.links[agv]

    def immediate(self, agv: int) -> bool:
        """Commands to AGV `agv` take no time."""
        return self.link_of(agv).timing is None

    def send(self, agv: int, kind: Kind, then: Callable[[], object]) -> None:
        """Send AGV `agv` a command; `then` runs when the AGV has it (at once if instant)."""
        timing = self.link_of(agv).timing
        if timing is None:
            then()
            return
        self.env.process(self._send(timing, kind, then))

    def _send(self, timing: CommandTiming, kind: Kind,
              then: Callable[[], object]) -> Generator[simpy.Event, Any, None]:
        yield from self._wait(timing, kind)
        then()

    def wait(self, agv: int, kind: Kind) -> Generator[simpy.Event, Any, None]:
        """The time one command to AGV `agv` takes, retries included (for a process to yield
        from)."""
        timing = self.link_of(agv).timing
        if timing is None:
            return
        yield from self._wait(timing, kind)

    def _wait(self, timing: CommandTiming, kind: Kind) -> Generator[simpy.Event, Any, None]:
        while True:
            attempt = timing.attempt(kind, self.rng)
            self.recorder.commands_sent += 1
            yield self.env.timeout(attempt.seconds)
            if not attempt.timed_out:
                return
            self.recorder.command_retries += 1

    def permission(self, agv: int) -> Callable[[], float] | None:
        """AGV `agv`'s route granted hop by hop with timed commands: a function that sends
        one hop's permission now and says when the AGV has it (sim time). None: traffic's
        grant is the permission."""
        link = self.link_of(agv)
        timing = link.timing
        if timing is None or not link.per_hop:
            return None
        if timing.timed_out(PERMISSION):
            raise SimulationError(
                f"AGV {agv}: every {PERMISSION} message misses its reply timeout on the "
                f"{timing.protocol} link, so no route permission would ever reach it "
                f"(reply_timeout_s {timing.settings.reply_timeout_s:g} s)")
        return lambda: self._permit(agv, timing)

    def _permit(self, agv: int, timing: CommandTiming) -> float:
        start_s = max(self.env.now, self._free_s.get(agv, 0.0))
        seconds = 0.0
        while True:
            attempt = timing.attempt(PERMISSION, self.rng)
            self.recorder.commands_sent += 1
            seconds += attempt.seconds
            if not attempt.timed_out:
                break
            self.recorder.command_retries += 1
        done_s = start_s + seconds
        self._free_s[agv] = done_s
        return done_s

    def notice_delay_s(self, agv: int) -> float:
        """How long until the fleet manager learns of a change on AGV `agv` (next poll)."""
        if self.poll_s <= 0:
            return 0.0
        phase = (agv * GOLDEN) % 1.0 * self.poll_s
        since = (self.env.now - phase) % self.poll_s
        wait = 0.0 if since == 0 else self.poll_s - since
        timing = self.link_of(agv).timing
        reply = timing.reply_s("status") if timing is not None else 0.0
        return wait + reply

