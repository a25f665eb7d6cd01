"""Order arrivals: Poisson flows with a time-of-day rate profile, or the replay of a trace.

Poisson: orders arrive at `rate_per_hour` times the profile multiplier for the time of day
(a non-homogeneous Poisson process, sampled exactly by thinning); each order picks a flow with
probability proportional to its weight. Handling times are drawn when an order is created, from a
stream of their own, so that runs that differ only in fleet or policy see the same orders with the
same handling times (common random numbers).

Multi-stop orders (fleet_sim.config.chains): a flow or trace row with `stops` makes orders of
that chain; handling times are drawn stop by stop, in chain order, from the same stream. A chain
of two stops is the plain order (exactly as `from`/`to`).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Sequence
from typing import Any

import numpy as np
import simpy

from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import DemandConfig
from fleet_sim.config.trace import TraceOrder
from fleet_sim.model.records import Order


def resolved_flows(demand: DemandConfig, layout: Layout) -> list[tuple[str, str, float]]:
    """(pickup, dropoff, weight) of every flow; all pickup-dropoff pairs when none are given."""
    if demand.flows:
        return [(f.chain[0], f.chain[-1], f.weight) for f in demand.flows]
    return [(p.id, d.id, 1.0) for p in layout.pickups for d in layout.dropoffs]


def resolved_chains(demand: DemandConfig, layout: Layout) -> list[tuple[tuple[str, ...], float]]:
    """(stops, weight) of every flow; all pickup-dropoff pairs when none are given."""
    if demand.flows:
        return [(f.chain, f.weight) for f in demand.flows]
    return [((p.id, d.id), 1.0) for p in layout.pickups for d in layout.dropoffs]


class Demand:
    def __init__(self, env: simpy.Environment, layout: Layout, config: DemandConfig,
                 start_h: float, submit: Callable[[Order], None],
                 arrival_rng: np.random.Generator, handling_rng: np.random.Generator,
                 trace: Sequence[TraceOrder] = ()) -> None:
        self.env = env
        self.layout = layout
        self.config = config
        self.start_h = start_h
        self.submit = submit
        self.arrival_rng = arrival_rng
        self.handling_rng = handling_rng
        self.trace = trace
        self.flows = resolved_chains(config, layout)
        weights = np.array([w for _, w in self.flows], dtype=float)
        self.flow_p = weights / weights.sum()
        self.created = 0

    def start(self) -> None:
        if self.config.kind == "trace":
            self.env.process(self._replay())
        elif self.config.rate_per_hour > 0 and self.config.max_multiplier > 0:
            self.env.process(self._poisson())

    def _new_order(self, pickup: str, dropoff: str, stops: tuple[str, ...] = ()) -> None:
        if len(stops) > 2:
            self._new_chain(stops)
            return
        p_handling = self.layout.places[pickup].handling
        d_handling = self.layout.places[dropoff].handling
        assert p_handling is not None and d_handling is not None
        order = Order(self.created, self.env.now, pickup, dropoff,
                      pickup_handling_s=p_handling.sample(self.handling_rng),
                      dropoff_handling_s=d_handling.sample(self.handling_rng))
        self.created += 1
        self.submit(order)

    def _new_chain(self, stops: tuple[str, ...]) -> None:
        handling = []
        for station in stops:
            spec = self.layout.places[station].handling
            assert spec is not None
            handling.append(spec.sample(self.handling_rng))
        order = Order(self.created, self.env.now, stops[0], stops[-1],
                      pickup_handling_s=handling[0], dropoff_handling_s=handling[-1],
                      stops=stops, stop_handling_s=tuple(handling),
                      stop_nodes=[None] * len(stops))
        self.created += 1
        self.submit(order)

    def _poisson(self) -> Generator[simpy.Event, Any, None]:
        peak_per_s = self.config.rate_per_hour * self.config.max_multiplier / 3600.0
        rng = self.arrival_rng
        while True:
            yield self.env.timeout(float(rng.exponential(1.0 / peak_per_s)))
            hour = (self.start_h + self.env.now / 3600.0) % 24.0
            accept = self.config.multiplier_at(hour) / self.config.max_multiplier
            # Two draws every candidate, accepted or not, keep the stream aligned across runs.
            u, pick = rng.random(), rng.random()
            if u < accept:
                flow = int(np.searchsorted(np.cumsum(self.flow_p), pick, side="right"))
                stops, _ = self.flows[min(flow, len(self.flows) - 1)]
                self._new_order(stops[0], stops[-1], stops)

    def _replay(self) -> Generator[simpy.Event, Any, None]:
        for item in self.trace:
            if item.time_s > self.env.now:
                yield self.env.timeout(item.time_s - self.env.now)
            self._new_order(item.pickup, item.dropoff, item.stops)
