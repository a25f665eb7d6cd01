"""What a traffic policy is (`traffic.policy`): how a hop is granted, how an AGV comes back onto
the track, and what the policy keeps as AGVs move. One module per policy
(fleet_sim.sim.traffic.reactive, fleet_sim.sim.traffic.avoiding), looked up by name in
fleet_sim.sim.traffic.policies.POLICIES, as dispatch policies are; `Traffic` never asks which
one it has.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Any, Protocol

import simpy

from fleet_sim.sim.traffic.allocation import Hop
from fleet_sim.sim.traffic.deadlock import Escape
from fleet_sim.sim.traffic.locks import Claim
from fleet_sim.sim.traffic.table import TrafficClient


class TrafficPolicy(Protocol):
    """One way of granting hops (openTCS: the Scheduler's allocation strategy)."""

    name: str
    """The `traffic.policy` value that selects it."""

    def allocate(self, client: TrafficClient,
                 hop: Hop) -> Generator[simpy.Event, Any, Claim | None]:
        """Wait for the whole hop; its node's claim, or None: the client gave up waiting."""
        ...

    def try_allocate(self, client_id: int, hop: Hop) -> Claim | None:
        """The whole hop now, or nothing (the look-ahead)."""
        ...

    def reenter(self, client: TrafficClient,
                access: str) -> Generator[simpy.Event, Any, Claim | None]:
        """Back onto the track at `access`; None: the wait was broken."""
        ...

    def placed(self, client_id: int, node: str) -> None:
        """The client was put on `node` at the start."""

    def hopped(self, client_id: int, node: str) -> None:
        """The client reached `node`."""

    def left(self, client_id: int) -> None:
        """The client left the track."""

    def granted(self, client_id: int, node: str) -> None:
        """The client was granted a hop to `node`."""

    def take_escape(self, client_id: int) -> Escape | None:
        """The escape chosen for the client, if any (it is then the client's to take)."""
        ...

    def escape_for(self, client: TrafficClient) -> Escape | None:
        """A way out for a blocked client (another route, a circle, a step back)."""
        ...
