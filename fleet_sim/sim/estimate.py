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


Leg = tuple[str, str, float, bool]
"""(from place, to place, share of orders that drive it, loaded)."""


def _flows(scenario: Scenario, layout: Layout,
           trace: Sequence[TraceOrder]) -> list[tuple[tuple[str, ...], float]]:
    """(stops, weight) of the scenario's order flows, or of its trace."""
    if not trace:
        return resolved_chains(scenario.demand, layout)
    pairs: dict[tuple[str, ...], float] = {}
    for item in trace:
        stops = item.stops or (item.pickup, item.dropoff)
        pairs[stops] = pairs.get(stops, 0) + 1
    return list(pairs.items())


def _legs(flows: Sequence[tuple[tuple[str, ...], float]]) -> list[Leg]:
    """Every leg an order drives, weighted by the share of orders that drive it: each chain's
    legs (loaded from a pickup, empty from a drop-off to its next pickup), and the empty leg
    from one order's last stop to an independent next order's first."""
    total = sum(w for _, w in flows)
    p_pick: dict[str, float] = {}
    p_drop: dict[str, float] = {}
    legs: list[Leg] = []
    for stops, w in flows:
        p_pick[stops[0]] = p_pick.get(stops[0], 0.0) + w / total
        p_drop[stops[-1]] = p_drop.get(stops[-1], 0.0) + w / total
        legs += [(stops[k], stops[k + 1], w / total, k % 2 == 0) for k in range(len(stops) - 1)]
    legs += [(d, p, pd * pp, False) for d, pd in p_drop.items() for p, pp in p_pick.items()]
    return legs


def _handling_s(layout: Layout, place: str) -> float:
    spec = layout.places[place].handling
    return spec.expected_s if spec is not None else 0.0


def _motion(profile: VehicleProfile) -> Motion:
    return Motion(profile.max_speed_mps, profile.accel_mps2, profile.decel_mps2,
                  profile.turn_speed_mps)


def analytic_estimate(scenario: Scenario, layout: Layout, availability: float = 1.0,
                      trace: Sequence[TraceOrder] = (),
                      vehicle: VehicleProfile | None = None) -> Estimate:
    """The estimate for the scenario's demand (or its trace), AGVs available `availability` of
    the time, all of them `vehicle`s (default: the scenario's fleet.vehicle; a sizing search
    over one type of a mixed fleet passes that type's)."""
    profile = vehicle if vehicle is not None else scenario.fleet.vehicle
    motion = _motion(profile)
    routes = Routes(layout, motion)

    def place_time(a: str, b: str) -> float:
        """Mean over the nodes of two places."""
        times = [route_time_s(routes, motion, u, v)
                 for u in layout.places[a].nodes for v in layout.places[b].nodes]
        return float(np.mean(times))

    flows = _flows(scenario, layout, trace)
    loaded = empty = 0.0
    for a, b, share, is_loaded in _legs(flows):
        t = share * place_time(a, b)
        if is_loaded:
            loaded += t
        else:
            empty += t
    total = sum(w for _, w in flows)
    handle = sum(w / total * sum(_handling_s(layout, s) for s in stops) for stops, w in flows)
    mean_rate, peak_rate = demand_rates(scenario, trace)
    return Estimate(empty, loaded, handle, mean_rate, peak_rate, availability)


@dataclass(frozen=True)
class Bottleneck:
    """The resource of the track the order flows keep busiest, and the fleet that would keep
    it busy all the time if nobody ever waited (the critical fleet)."""

    resource: str
    """Which one, in the layout's words: `node M011`, `corridor 2`, `zone Z1`."""
    busy_s_per_order: float
    """Seconds it is held per order, on average over the flows (its capacity shared out)."""
    cycle_s: float
    """Free-flow time of one order (the analytic estimate's cycle: travel and handling)."""

    @property
    def orders_per_hour(self) -> float:
        """The most orders per hour the resource lets through (an upper bound)."""
        return 3600.0 / self.busy_s_per_order

    @property
    def critical_fleet(self) -> int:
        """AGVs on the track at which the bottleneck is saturated at free-flow speed: the
        cycle over the bottleneck's busy time per order (at least one)."""
        return max(1, math.ceil(self.cycle_s / self.busy_s_per_order - 1e-6))

    def describe(self) -> str:
        return (f"{self.resource} is held {self.busy_s_per_order:.1f} s per order, an order "
                f"takes {self.cycle_s:.1f} s: {self.critical_fleet} AGVs on the track keep it busy")


def bottleneck(scenario: Scenario, layout: Layout,
               trace: Sequence[TraceOrder] = ()) -> Bottleneck:
    """The busiest exclusive resource of the track under the order flows (operational
    analysis, Denning and Buzen 1978: the bottleneck's demand per job bounds throughput, and
    the cycle over it is the population beyond which only queues grow; Hopp and Spearman's
    critical WIP). Each leg drives its shortest free-flow route, between every pair of nodes of
    its two places, equally likely; node v is held from the start of the hop before the hop
    into it (the driver's look-ahead takes it then; from the leg's start for its first hop)
    until the body has cleared it ((segment + length + gap) / speed after that); a corridor
    (one AGV at a time) and a zone are held from the hop into them until the body has left,
    and a station's node, and the corridor or zone it lies in, for its mean handling time. A
    mutex zone's time is shared out over its capacity; a same-direction aisle counts as one
    AGV at a time (it may carry several AGVs one way: a lower, safe figure). Charging, turns
    and acceleration are left out."""
    profile = scenario.fleet.vehicle
    routes = Routes(layout, _motion(profile))
    clear_m = profile.length_m + profile.min_gap_m
    corridor_of: dict[tuple[str, str], str] = {
        seg: f"corridor {c.id}" for c in layout.corridors for seg in c.segments}
    zones_at: dict[str, list[tuple[str, int]]] = {}
    for zone in layout.traffic_zones:
        if zone.kind == "ban":
            continue
        capacity = zone.capacity if zone.kind == "mutex" and zone.capacity else 1
        for node in zone.nodes:
            zones_at.setdefault(node, []).append((f"zone {zone.id}", capacity))
    busy: dict[str, float] = {}

    def hold(resource: str, seconds: float) -> None:
        busy[resource] = busy.get(resource, 0.0) + seconds

    def drive(path: list[str], weight: float) -> None:
        inside: set[str] = set()
        before_s = 0.0  # the hop before: the driver takes v then (its look-ahead)
        for u, v in itertools.pairwise(path):
            data = routes.edge[u, v]
            speed = data["length_m"] / data["free_time_s"]
            hold(f"node {v}", weight * (before_s + (data["length_m"] + clear_m) / speed))
            before_s = data["free_time_s"]
            now = {(corridor_of[u, v], 1)} if (u, v) in corridor_of else set()
            now.update(zones_at.get(v, ()))
            for resource, capacity in now:
                extra = 0.0 if resource in inside else clear_m
                hold(resource, weight * (data["length_m"] + extra) / speed / capacity)
            inside = {r for r, _ in now}

    flows = _flows(scenario, layout, trace)
    for a, b, share, _ in _legs(flows):
        pairs = [(u, v) for u in layout.places[a].nodes for v in layout.places[b].nodes]
        for u, v in pairs:
            if u != v:
                drive(routes.route(u, v), share / len(pairs))
    total = sum(w for _, w in flows)
    for stops, w in flows:
        for place in stops:
            nodes = layout.places[place].nodes
            seconds = w / total * _handling_s(layout, place) / len(nodes)
            for node in nodes:
                hold(f"node {node}", seconds)
                corridor = layout.corridor_at(node)
                if corridor is not None:
                    hold(f"corridor {corridor.id}", seconds)
                for resource, capacity in zones_at.get(node, ()):
                    hold(resource, seconds / capacity)
    resource = max(busy, key=lambda r: (busy[r], r))
    cycle_s = analytic_estimate(scenario, layout, trace=trace).cycle_s
    return Bottleneck(resource, busy[resource], cycle_s)


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
