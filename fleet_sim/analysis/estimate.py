"""The analytic fleet estimate: how many AGVs the demand keeps busy, with no waiting at all.

The time one order takes an AGV (empty travel to the pickup, loaded travel to the drop-off,
handling at both ends), times the demand, over the AGV time available. Travel times are
free-flow times of the shortest routes under the vehicle's speed profile
(fleet_sim.model.kinematics: start, turns at turn speed, stop), weighted by the order flows; the
empty leg runs from the drop-off of one order to the pickup of an independent next order. No
waiting, no traffic, no charging beyond `availability`: a lower bound on the fleet, which the
sizing search (fleet_sim.study.sizing) starts from and the report sets beside the simulation.

Multi-stop orders (fleet_sim.config.chains): a chain's pickup -> dropoff legs are loaded travel,
its dropoff -> next pickup legs empty travel, and it is handled at every stop; the empty leg
between orders runs from the chain's last stop to the first stop of the next order.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario
from fleet_sim.config.trace import TraceOrder
from fleet_sim.config.vehicle import VehicleProfile
from fleet_sim.model.kinematics import Motion, Piece, traverse
from fleet_sim.sim.demand import resolved_chains
from fleet_sim.sim.traffic.routing import Routes


@dataclass(frozen=True)
class Estimate:
    """Analytic fleet estimate from travel and handling times."""

    empty_travel_s: float
    loaded_travel_s: float
    handling_s: float
    demand_per_hour: float
    """Mean demand over the measured window (after warm-up)."""
    peak_demand_per_hour: float
    agv_availability: float

    @property
    def cycle_s(self) -> float:
        return self.empty_travel_s + self.loaded_travel_s + self.handling_s

    @property
    def capacity_per_agv_per_hour(self) -> float:
        return 3600.0 * self.agv_availability / self.cycle_s

    @property
    def agvs(self) -> float:
        """AGVs kept busy by the mean demand (fractional)."""
        return self.demand_per_hour / self.capacity_per_agv_per_hour

    @property
    def agvs_at_peak(self) -> float:
        return self.peak_demand_per_hour / self.capacity_per_agv_per_hour

    @property
    def minimum(self) -> int:
        """The least whole fleet that can carry the mean demand at all."""
        return max(1, math.ceil(self.agvs - 1e-9))

    def as_dict(self) -> dict[str, float]:
        return {**asdict(self), "cycle_s": self.cycle_s,
                "capacity_per_agv_per_hour": self.capacity_per_agv_per_hour,
                "agvs": self.agvs, "agvs_at_peak": self.agvs_at_peak, "minimum": self.minimum}


def route_time_s(routes: Routes, motion: Motion, src: str, dest: str) -> float:
    """Free-flow time from standstill at `src` to standstill at `dest` by the shortest route."""
    if src == dest:
        return 0.0
    path = routes.route(src, dest)
    pieces: list[Piece] = []
    prev: str | None = None
    for u, v in itertools.pairwise(path):
        pieces.extend(routes.pieces(prev, u, v))
        prev = u
    time_s, _ = traverse(pieces, 0.0, 0.0, motion.accel_mps2, motion.decel_mps2)
    return time_s


def analytic_estimate(scenario: Scenario, layout: Layout, availability: float = 1.0,
                      trace: Sequence[TraceOrder] = (),
                      vehicle: VehicleProfile | None = None) -> Estimate:
    """The estimate for the scenario's demand (or its trace), AGVs available `availability` of
    the time, all of them `vehicle`s (default: the scenario's fleet.vehicle; a sizing search
    over one type of a mixed fleet passes that type's)."""
    profile = vehicle if vehicle is not None else scenario.fleet.vehicle
    motion = Motion(profile.max_speed_mps, profile.accel_mps2, profile.decel_mps2,
                    profile.turn_speed_mps)
    routes = Routes(layout, motion)

    def place_time(a: str, b: str) -> float:
        """Mean over the nodes of two places."""
        times = [route_time_s(routes, motion, u, v)
                 for u in layout.places[a].nodes for v in layout.places[b].nodes]
        return float(np.mean(times))

    if trace:
        pairs: dict[tuple[str, ...], float] = {}
        for item in trace:
            stops = item.stops or (item.pickup, item.dropoff)
            pairs[stops] = pairs.get(stops, 0) + 1
        flows = list(pairs.items())
    else:
        flows = resolved_chains(scenario.demand, layout)
    total = sum(w for _, w in flows)
    p_pick: dict[str, float] = {}
    p_drop: dict[str, float] = {}
    for stops, w in flows:
        p_pick[stops[0]] = p_pick.get(stops[0], 0.0) + w / total
        p_drop[stops[-1]] = p_drop.get(stops[-1], 0.0) + w / total

    def legs(stops: tuple[str, ...], first: int) -> float:
        """Travel over the legs stops[k] -> stops[k + 1], k = first, first + 2, ..."""
        return sum(place_time(stops[k], stops[k + 1]) for k in range(first, len(stops) - 1, 2))

    loaded = sum(w / total * legs(stops, 0) for stops, w in flows)
    empty = sum(pd * pp * place_time(d, p) for d, pd in p_drop.items()
                for p, pp in p_pick.items())
    inner = sum(w / total * legs(stops, 1) for stops, w in flows if len(stops) > 2)
    if inner:
        empty += inner

    def handling(place: str) -> float:
        spec = layout.places[place].handling
        return spec.expected_s if spec is not None else 0.0

    handle = sum(w / total * sum(handling(s) for s in stops) for stops, w in flows)
    mean_rate, peak_rate = demand_rates(scenario, trace)
    return Estimate(empty, loaded, handle, mean_rate, peak_rate, availability)


def demand_rates(scenario: Scenario, trace: Sequence[TraceOrder] = ()) -> tuple[float, float]:
    """(mean, peak hourly) demand over the measured window."""
    start, end = scenario.warmup_s, scenario.duration_s
    if scenario.demand.kind == "trace":
        times = np.array([t.time_s for t in trace], dtype=float)
        inside = times[(times >= start) & (times <= end)]
        window_h = max((end - start) / 3600.0, 1e-9)
        bins = max(1, math.ceil(window_h))
        counts = np.histogram(inside, bins=bins, range=(start, end))[0]
        return len(inside) / window_h, float(counts.max()) / (window_h / bins)
    steps = np.arange(start, end, 60.0) + 30.0  # minute midpoints
    clock_h = (scenario.start_h + steps / 3600.0) % 24.0
    mult = np.array([scenario.demand.multiplier_at(float(h)) for h in clock_h])
    rate = scenario.demand.rate_per_hour
    return rate * float(mult.mean()), rate * float(mult.max())
