"""Costed routes (fleet_sim.sim.traffic.routing.Routes.route_costed): the cheapest route on
random congestion states of the bundled layouts, by networkx's Dijkstra on the same costs;
ties go the way the layout lists first; the congestion is read as it is when asked."""

from __future__ import annotations

import itertools
import random
from dataclasses import dataclass, field
from pathlib import Path

import networkx as nx
import pytest

from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.model.kinematics import Motion
from fleet_sim.sim.traffic.routing import NO_EDGES, Routes, SegmentCosts

from .conftest import DATA, LAYOUTS, write_yaml

MOTION = Motion(1.0, 0.5, 0.5, 0.3)


@dataclass
class Crowd:
    """A stand-in node lock: the AGVs on it and those queued for it."""

    users: list[int] = field(default_factory=list)
    put_queue: list[int] = field(default_factory=list)


def random_costs(layout: Layout, rng: random.Random, per_agv_s: float,
                 weak_share: float) -> SegmentCosts:
    """Some nodes held, some with queues; a share of the segments with a cost of their own."""
    locks = {}
    for node in layout.graph.nodes:
        held = rng.random() < 0.3
        locks[node] = Crowd([0] * held, [0] * (rng.randrange(3) if held else 0))
    fixed = {(u, v): rng.choice((5.0, 30.0, 0.7, 12.5)) for u, v in layout.graph.edges
             if rng.random() < weak_share}
    return SegmentCosts(fixed, per_agv_s, locks)


def cheapest_s(layout: Layout, routes: Routes, src: str, dest: str, costs: SegmentCosts,
               avoid_edges: frozenset[tuple[str, str]] = NO_EDGES) -> float:
    """The oracle: the cost of the cheapest route by networkx's Dijkstra, each segment's
    free-flow time plus `SegmentCosts.extra_s`."""
    times = {(u, v): t for u, succ in routes._succ.items() for v, t in succ}

    def weight(u: str, v: str, _: object) -> float | None:
        return None if (u, v) in avoid_edges else times[u, v] + costs.extra_s(u, v)

    return float(nx.shortest_path_length(layout.graph, src, dest, weight=weight))


def route_s(routes: Routes, path: list[str], costs: SegmentCosts) -> float:
    times = {(u, v): t for u, succ in routes._succ.items() for v, t in succ}
    return sum(times[u, v] + costs.extra_s(u, v) for u, v in itertools.pairwise(path))


@pytest.mark.parametrize("name", ["fulfilment_centre", "warehouse_wifi",
                                  "warehouse_same_direction", "distribution_centre"])
def test_a_costed_route_is_the_cheapest(name: str) -> None:
    """Random congestion states (10 s or 0.3 s an AGV, or none; weak-Wi-Fi segments or none)
    and random questions, some around blocked segments: the route found costs what the
    cheapest route costs, by networkx's Dijkstra on the same costs, and keeps off the blocked
    segments. (That it is the same route as before, ties included, the costed runs' digests
    in tests/test_engine.py show.)"""
    layout = load_layout(LAYOUTS / f"{name}.yaml")
    routes = Routes(layout, MOTION)
    rng = random.Random(35)
    nodes = sorted(layout.graph.nodes)
    edges = sorted(layout.graph.edges)
    dests = rng.sample(nodes, 6)
    for k in range(60):
        costs = random_costs(layout, rng, (10.0, 0.3, 0.0)[k % 3], (0.0, 0.05)[k % 2])
        src, dest = rng.choice(nodes), dests[k % len(dests)]
        avoid = frozenset(rng.sample(edges, 8)) if k % 4 == 0 else NO_EDGES
        path = routes.route_costed(src, dest, costs, avoid)
        if path is None:
            with pytest.raises(nx.NetworkXNoPath):
                cheapest_s(layout, routes, src, dest, costs, avoid)
            continue
        assert path[0] == src and path[-1] == dest
        assert not avoid & set(itertools.pairwise(path)), (k, src, dest)
        assert route_s(routes, path, costs) == pytest.approx(
            cheapest_s(layout, routes, src, dest, costs, avoid), abs=1e-9), (k, src, dest)


def test_a_route_is_costed_as_the_locks_stand_when_it_is_asked() -> None:
    """The costs read the locks when the route is searched, not when they were built: an AGV
    arriving on N1 sends the next route round by B0, and its leaving brings it back."""
    ring = load_layout(DATA / "deadlock_ring.yaml")
    crowd = {node: Crowd() for node in ring.graph.nodes}
    costs = SegmentCosts({}, 20.0, crowd)
    routes = Routes(ring, MOTION)
    assert routes.route_costed("N0", "N2", costs) == ["N0", "N1", "N2"]
    crowd["N1"].users.append(1)
    assert routes.route_costed("N0", "N2", costs) == ["N0", "B0", "N2"]
    crowd["N1"].users.clear()
    crowd["N1"].put_queue.append(2)  # queued for it counts the same
    assert routes.route_costed("N0", "N2", costs) == ["N0", "B0", "N2"]
    crowd["N1"].put_queue.clear()
    assert routes.route_costed("N0", "N2", costs) == ["N0", "N1", "N2"]


def square(tmp_path: Path, first: str) -> Layout:
    """A -> B -> D and A -> C -> D, both 20 m; the segment out of A to `first` listed first."""
    other = "C" if first == "B" else "B"
    data = {
        "name": "square",
        "nodes": [{"id": "A", "x": 0, "y": 0, "kind": "station"}, {"id": "B", "x": 10, "y": 0},
                  {"id": "C", "x": 0, "y": 10},
                  {"id": "D", "x": 10, "y": 10, "kind": "station"},
                  {"id": "P", "x": 20, "y": 10, "kind": "parking"}],
        "segments": [{"from": "A", "to": first}, {"from": "A", "to": other},
                     {"from": "B", "to": "D"}, {"from": "C", "to": "D"},
                     {"from": "D", "to": "P"}, {"from": "P", "to": "A", "length_m": 30}],
        "stations": [
            {"id": "PICK", "kind": "pickup", "nodes": ["A"],
             "handling": {"dist": "fixed", "mean_s": 10}},
            {"id": "DROP", "kind": "dropoff", "nodes": ["D"],
             "handling": {"dist": "fixed", "mean_s": 10}}],
        "parking": [{"id": "PARK", "node": "P", "capacity": 1}],
    }
    return load_layout(write_yaml(tmp_path / f"square_{first}.yaml", data))


@pytest.mark.parametrize("first", ["B", "C"])
def test_a_tie_goes_the_way_the_layout_lists_first(tmp_path: Path, first: str) -> None:
    """Two equally cheap ways round a square: the one whose segment the layout lists first
    (as routes always went), unless congestion makes the other cheaper; equally crowded,
    they tie again."""
    routes = Routes(square(tmp_path, first), MOTION)
    crowd = {node: Crowd() for node in "ABCDP"}
    costs = SegmentCosts({}, 10.0, crowd)
    other = "C" if first == "B" else "B"

    def route() -> list[str] | None:
        return routes.route_costed("A", "D", costs)

    assert route() == ["A", first, "D"]
    crowd[first].users.append(1)
    assert route() == ["A", other, "D"]
    crowd[other].put_queue.append(2)
    assert route() == ["A", first, "D"]


@pytest.mark.parametrize("name", ["fulfilment_centre", "warehouse"])
def test_the_free_flow_table_goes_the_way_networkx_paths_go(name: str) -> None:
    """Each destination's table (free-flow seconds to it, and the next hop there), built from
    networkx's predecessors, is what networkx's shortest paths give, equal routes included,
    for the default vehicle and for a vehicle type of its own."""
    layout = load_layout(LAYOUTS / f"{name}.yaml")
    for routes in (Routes(layout, MOTION), Routes(layout, MOTION, "tugger")):
        reverse = routes.graph.reverse(copy=False)
        for dest in sorted(layout.graph.nodes)[::150]:
            dist, paths = nx.single_source_dijkstra(reverse, dest, weight=routes._reverse_weight)
            table = routes._table(dest)
            assert table[0] == dist
            assert table[1] == {n: p[-2] for n, p in paths.items() if len(p) > 1}
