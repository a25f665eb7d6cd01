"""The reservation table (fleet_sim.sim.traffic): locks keyed by client, wait-for cycles and the
deadlock strategy, with stand-in clients rather than whole AGVs."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import simpy
import yaml

from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.errors import SimulationError
from fleet_sim.model.kinematics import Motion
from fleet_sim.model.records import Recorder
from fleet_sim.sim.traffic.control import RouteCosts, Traffic
from fleet_sim.sim.traffic.deadlock import DeadlockVictim, Escape, GentlestEscapeFirst
from fleet_sim.sim.traffic.locks import Claim, CorridorLock, NodeLock
from fleet_sim.sim.traffic.reactive import ReactivePolicy

from .conftest import DATA, write_yaml


@dataclass
class Client:
    """A stand-in AGV: what traffic may know of it, and what it is told."""

    id: int
    node: str
    goal: str | None = None
    next_node: str | None = None
    failing: bool = False
    notes: list[tuple[str, str]] = field(default_factory=list)
    causes: list[DeadlockVictim] = field(default_factory=list)

    def note(self, event: str, detail: str = "") -> None:
        self.notes.append((event, detail))

    def on_deadlock_victim(self, cause: DeadlockVictim) -> None:
        self.causes.append(cause)

    def began_waiting(self, lock: object) -> None:
        pass


def make_traffic(layout: Layout, clients: int = 0, **kwargs: object) -> Traffic:
    """Traffic on `layout`, with stand-in clients 0 .. clients-1 registered."""
    recorder = Recorder(0.0, 3600.0)
    kwargs.setdefault("strategy", ReactivePolicy)
    traffic = Traffic(simpy.Environment(), layout, Motion(1.0, 0.5, 0.5, 0.3), recorder,
                      **kwargs)  # type: ignore[arg-type]
    for i in range(clients):
        traffic.register(Client(i, ""))
    return traffic


@pytest.fixture
def ring() -> Layout:
    return load_layout(DATA / "deadlock_ring.yaml")


def test_lock_keys_name_what_they_lock() -> None:
    assert str(NodeLock("N0")) == "N0" and str(CorridorLock(3)) == "corridor 3"
    assert NodeLock("N0") == NodeLock("N0") and NodeLock("N0") != NodeLock("N1")


def test_request_and_free_keyed_by_client(ring: Layout) -> None:
    traffic = make_traffic(ring, clients=2)
    lock = traffic.node_locks["N0"]
    assert lock.key == NodeLock("N0")
    first = traffic.request(0, lock)
    second = traffic.request(1, lock)
    assert first.triggered and not second.triggered
    assert lock.holder == 0 and dict(traffic.holders()) == {"N0": 0}
    traffic.free(0, first)
    traffic.env.run()  # the lock passes to the one waiting
    assert second.triggered and lock.holder == 1
    traffic.free(1, second)
    assert lock.holder is None and lock.is_free


def test_a_client_cannot_free_what_it_does_not_hold(ring: Layout) -> None:
    traffic = make_traffic(ring, clients=2)
    lock = traffic.node_locks["N1"]
    held = traffic.request(0, lock)
    waiting = traffic.request(1, lock)
    with pytest.raises(SimulationError, match="AGV 1 cannot free N1: it does not hold it"):
        traffic.free(1, held)
    with pytest.raises(SimulationError, match="AGV 1 cannot free N1"):
        traffic.free(1, waiting)  # still waiting: not held
    with pytest.raises(SimulationError, match="AGV 0 cannot withdraw"):
        traffic.withdraw(0, held)  # granted: free it instead
    traffic.withdraw(1, waiting)
    assert lock.holder == 0 and not lock.put_queue


def test_a_corridor_lock_excludes_a_second_client(warehouse_layout: Layout) -> None:
    traffic = make_traffic(warehouse_layout, clients=2)
    corridor = warehouse_layout.corridors[0]
    lock = traffic.corridor_locks[corridor.id]
    entry = sorted(corridor.members)[0]
    first = traffic.request(0, lock, entry=entry)
    second = traffic.request(1, lock, entry=entry)
    assert first.triggered and not second.triggered
    assert traffic.holds_corridor(0, corridor.id) and not traffic.holds_corridor(1, corridor.id)
    assert traffic.corridors_of(0)[corridor.id] == (first, entry)
    traffic.entered_corridor(0, corridor.id)
    assert traffic.corridors_of(0)[corridor.id] == (first, None)
    assert traffic.blocks_others(0) and not traffic.blocks_others(1)
    traffic.free(0, first)
    traffic.env.run()
    assert second.triggered and traffic.holds_corridor(1, corridor.id)
    assert corridor.id not in traffic.corridors_of(0)


def four_in_a_ring(traffic: Traffic) -> list[Client]:
    """AGV i on Ni, bound two nodes ahead, holding Ni and waiting for the next node, which the
    next AGV holds: a wait-for cycle 0 -> 1 -> 2 -> 3 -> 0."""
    clients = [Client(i, f"N{i}", goal=f"N{(i + 2) % 4}", next_node=f"N{(i + 1) % 4}")
               for i in range(4)]
    claims: list[Claim] = []
    for c in clients:
        traffic.register(c)
        claims.append(traffic.request(c.id, traffic.node_locks[c.node]))
    for c in clients:
        assert c.next_node is not None
        lock = traffic.node_locks[c.next_node]
        assert not traffic.request(c.id, lock).triggered
        traffic.start_waiting(c.id, lock)
    assert all(claim.triggered for claim in claims)
    return clients


def test_a_wait_for_cycle_is_found_and_the_caller_takes_the_bypass(ring: Layout) -> None:
    traffic = make_traffic(ring)
    clients = four_in_a_ring(traffic)
    escape = traffic.strategy.resolve_deadlock(clients[0])
    # each AGV's way round the node it waits for is the bypass: N0 -> B0 -> N2, B0 free
    assert escape == Escape("reroute", ("N0", "B0", "N2"))
    assert traffic.recorder.deadlocks == 1
    assert clients[0].notes == [("deadlock_detected", "agvs 0 1 2 3 waiting for N1 N2 N3 N0"),
                                ("deadlock_resolved", "reroute via N0 B0 N2")]
    assert not any(c.causes for c in clients)
    assert traffic.take_escape(0) == escape and traffic.take_escape(0) is None


class LastMember:
    """A strategy that always picks the last member that can move."""

    def choose(self, options: Sequence[tuple[int, Escape | None]]) -> tuple[int, Escape] | None:
        movable = [(i, e) for i, e in options if e is not None]
        return movable[-1] if movable else None


def test_the_victim_chosen_by_the_strategy_gets_a_deadlock_victim_cause(ring: Layout) -> None:
    traffic = make_traffic(ring, victim_choice=LastMember())
    clients = four_in_a_ring(traffic)
    assert traffic.strategy.resolve_deadlock(clients[0]) is None  # someone else moves
    victim = clients[3]
    assert victim.causes == [DeadlockVictim(Escape("reroute", ("N3", "B3", "N1")))]
    assert victim.notes == [("deadlock_resolved", "reroute via N3 B3 N1")]
    # while the victim has not taken its escape, the cycle is not resolved twice
    assert traffic.strategy.resolve_deadlock(clients[1]) is None
    assert victim.causes == [DeadlockVictim(Escape("reroute", ("N3", "B3", "N1")))]
    assert traffic.recorder.deadlocks == 1


def test_a_cycle_with_a_failing_member_is_left_to_the_fault(ring: Layout) -> None:
    traffic = make_traffic(ring)
    clients = four_in_a_ring(traffic)
    clients[2].failing = True
    assert traffic.strategy.resolve_deadlock(clients[0]) is None
    assert traffic.recorder.deadlocks == 0 and not clients[0].notes


def test_no_cycle_without_a_closed_chain(ring: Layout) -> None:
    traffic = make_traffic(ring)
    clients = four_in_a_ring(traffic)
    traffic.stop_waiting(3)  # AGV 3 no longer waits for N0: the chain is open
    assert traffic.strategy.resolve_deadlock(clients[0]) is None
    assert traffic.recorder.deadlocks == 0


def test_the_default_strategy_prefers_the_gentlest_escape() -> None:
    yield_ = Escape("yield", ("A",))
    reroute = Escape("reroute", ("B", "C"))
    backoff = Escape("backoff", ("D", "E"))
    policy = GentlestEscapeFirst()
    assert policy.choose([(0, backoff), (1, None), (2, reroute), (3, yield_)]) == (3, yield_)
    assert policy.choose([(0, backoff), (1, reroute), (2, reroute)]) == (1, reroute)
    assert policy.choose([(0, None), (1, None)]) is None


def test_routes_go_round_what_they_must_avoid(ring: Layout) -> None:
    traffic = make_traffic(ring)
    assert traffic.route("N0", "N2") == ["N0", "N1", "N2"]
    assert traffic.routes.route_avoiding("N0", "N2", {"N1"}) == ["N0", "B0", "N2"]
    assert traffic.routes.route_avoiding("N0", "N2", {"N1", "B0"}) is None
    traffic.block("N0", "N1", 0.0, 100.0)
    assert traffic.blocked_until("N0", "N1", 50.0) == 100.0
    assert traffic.route("N0", "N2") == ["N0", "B0", "N2"]  # reported blocks are avoided


def test_route_costs_go_round_congestion_only_when_asked(ring: Layout) -> None:
    """N0 -> N2: through N1 (16 m), or round by B0 (about 26 m, ~10 s longer)."""
    plain = make_traffic(ring, clients=2)
    plain.request(1, plain.node_locks["N1"])  # an AGV stands on N1
    assert plain.route("N0", "N2") == ["N0", "N1", "N2"]  # default: free-flow routes
    mild = make_traffic(ring, clients=2, costs=RouteCosts(congestion_s=5.0))
    mild.request(1, mild.node_locks["N1"])
    assert mild.route("N0", "N2") == ["N0", "N1", "N2"]  # 5 s less than the detour costs
    costly = make_traffic(ring, clients=3, costs=RouteCosts(congestion_s=20.0))
    assert costly.route("N0", "N2") == ["N0", "N1", "N2"]  # nobody there yet
    held = costly.request(1, costly.node_locks["N1"])
    assert costly.route("N0", "N2") == ["N0", "B0", "N2"]
    costly.free(1, held)
    costly.env.run()
    assert costly.route("N0", "N2") == ["N0", "N1", "N2"]  # gone again


def test_route_costs_keep_off_weak_wifi_when_asked(ring: Layout, tmp_path: Path) -> None:
    data = yaml.safe_load((DATA / "deadlock_ring.yaml").read_text(encoding="utf-8"))
    data["segments"][0]["rssi_dbm"] = -75.0  # N0 -> N1: weak (E_002 below -70 dBm)
    weak = load_layout(write_yaml(tmp_path / "weak.yaml", data))
    assert make_traffic(weak).route("N0", "N2") == ["N0", "N1", "N2"]
    avoiding = make_traffic(weak, costs=RouteCosts(weak_wifi_s=30.0, weak_rssi_dbm=-70.0))
    assert avoiding.route("N0", "N2") == ["N0", "B0", "N2"]
    assert avoiding.route("N1", "N3") == ["N1", "N2", "N3"]  # elsewhere: unchanged


def test_the_detour_cache_is_bounded_and_forgetting_changes_no_result(
        warehouse_layout: Layout, monkeypatch: pytest.MonkeyPatch) -> None:
    """A long run asks ever new detour questions: the cache keeps the most recent ones only,
    and a run that forgets almost everything computes the same routes (same KPIs)."""
    from fleet_sim.analysis.kpi_sums import run_kpis
    from fleet_sim.sim import engine
    from fleet_sim.sim.traffic import routing

    from .conftest import make_scenario

    def run() -> tuple[dict[str, object], int, int]:
        scenario = make_scenario("warehouse.yaml", duration_h=2, warmup_h=0.25, seed=5,
                                 fleet={"size": 40}, demand={"rate_per_hour": 150})
        asked: list[int] = []
        real = routing.Routes.route_avoiding

        def counting(self: routing.Routes, *args: object, **kw: object) -> object:
            found = real(self, *args, **kw)  # type: ignore[arg-type]
            asked.append(len(self._detours))
            return found

        monkeypatch.setattr(routing.Routes, "route_avoiding", counting)
        out = engine.simulate(scenario, warehouse_layout)
        return run_kpis(out), len(asked), max(asked, default=0)

    full, asked_full, largest_full = run()
    monkeypatch.setattr(routing, "DETOUR_CACHE_SIZE", 3)
    small, asked_small, largest_small = run()
    assert asked_full > 100 and largest_full > 3  # the run does ask for many detours
    assert largest_small <= 3
    assert small == full
    assert asked_small == asked_full


def corridor_entry(layout: Layout) -> tuple[int, str, str]:
    """A corridor, a junction outside it and the first node inside, on the way in."""
    for corridor in layout.corridors:
        for a, b in sorted(corridor.segments):
            if a not in corridor.members and b in corridor.members:
                return corridor.id, a, b
    raise AssertionError("no corridor with a member")


def test_a_hop_is_granted_whole_or_not_at_all(warehouse_layout: Layout) -> None:
    """The look-ahead (`try_allocate`) takes the node and the corridor it enters together, or
    nothing: with the corridor held by another AGV, the free node stays free."""
    from fleet_sim.sim.traffic.allocation import Hop

    traffic = make_traffic(warehouse_layout, clients=2)
    cid, junction, inside = corridor_entry(warehouse_layout)
    other = traffic.request(1, traffic.corridor_locks[cid], entry=junction)
    assert traffic.try_allocate(0, Hop(junction, inside)) is None
    assert traffic.node_locks[inside].holder is None and not traffic.corridors_of(0)
    traffic.free(1, other)
    claim = traffic.try_allocate(0, Hop(junction, inside))
    assert claim is not None and traffic.node_locks[inside].holder == 0
    assert traffic.holds_corridor(0, cid) and traffic.corridors_of(0)[cid][1] == junction


def test_a_queued_hop_waits_for_its_corridor_then_takes_its_node(
        warehouse_layout: Layout) -> None:
    """`allocate` queues the AGV for the corridor first (it waits outside), then the node."""
    from fleet_sim.sim.traffic.allocation import Hop

    traffic = make_traffic(warehouse_layout)
    client = Client(0, "")
    traffic.register(client)
    traffic.register(Client(1, ""))
    cid, junction, inside = corridor_entry(warehouse_layout)
    client.node = junction
    other = traffic.request(1, traffic.corridor_locks[cid], entry=junction)
    env = traffic.env
    hop = env.process(traffic.allocate(client, Hop(junction, inside)))
    env.run(until=3)
    assert hop.is_alive and traffic.waiting[0].key == CorridorLock(cid)
    assert traffic.node_locks[inside].holder is None
    traffic.free(1, other)
    env.run(until=4)
    assert not hop.is_alive and isinstance(hop.value, Claim)
    assert traffic.node_locks[inside].holder == 0 and traffic.holds_corridor(0, cid)
    assert 0 not in traffic.waiting


def test_no_import_circle_in_the_simulation_core_type_only_imports_included() -> None:
    """Issue 34: the allocation modules, the plans and the policies see the reservation table
    (`Reservations`), not `Traffic`; nothing Traffic imports imports it back, not even for a
    type (grimp counts `if TYPE_CHECKING:` imports)."""
    import grimp
    import networkx as nx

    graph = grimp.build_graph("fleet_sim")
    core = nx.DiGraph()
    for module in graph.modules:
        if module.startswith("fleet_sim.sim"):
            core.add_edges_from((module, imported)
                                for imported in graph.find_modules_directly_imported_by(module)
                                if imported.startswith("fleet_sim.sim"))
    assert list(nx.simple_cycles(core)) == []


def test_only_traffic_reads_lock_state() -> None:
    """Traffic (fleet_sim.sim.traffic) owns every allocation: no other module of fleet_sim
    reads its locks, their holders or their queues."""
    import ast

    import fleet_sim

    lock_state = {"node_locks", "corridor_locks", "zone_locks", "is_free", "admits",
                  "put_queue", "users", "holder", "blockers", "_nodes", "_corridors", "_zones"}
    root = Path(fleet_sim.__file__).parent
    readers = []
    for path in sorted(root.rglob("*.py")):
        if (root / "sim" / "traffic") in path.parents:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and node.attr in lock_state:
                readers.append(f"{path.relative_to(root)}:{node.lineno} .{node.attr}")
    assert len(list(root.rglob("*.py"))) > 50  # the walk saw the package
    assert readers == []


def test_a_vehicle_holds_its_driver() -> None:
    """The AGV's state machine holds a `Driver` (and is its host); it does not inherit from
    it, so the driver's bookkeeping is not the vehicle's to touch."""
    from fleet_sim.sim.agents.driving import Driver
    from fleet_sim.sim.agents.vehicle import Vehicle

    assert not issubclass(Vehicle, Driver)
    assert "driver" in Vehicle.__init__.__code__.co_names
