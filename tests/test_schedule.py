"""The avoiding policy's fitted witnesses (fleet_sim.sim.traffic.schedule, issue 35): a changed
plan or a grant out of the witness's order is fitted in among the other AGVs' moves instead of
walking every AGV again. A fit only spares a walk: every state it lets through is shown safe
from scratch (`Plans.proof`), a fit that fails leaves the schedule as it was, and where the
client's moves meet a hold they cannot go round, the fit says whose."""

from __future__ import annotations

from typing import Any

import pytest

from fleet_sim.config.layout import load_layout
from fleet_sim.sim.engine import build_simulation
from fleet_sim.sim.traffic.avoidance import Plans
from fleet_sim.sim.traffic.control import Traffic
from fleet_sim.sim.traffic.schedule import Schedule
from fleet_sim.sim.traffic.walk import INF, holders_of

from .conftest import DATA, make_scenario, scenario_for


@pytest.mark.parametrize("layout_name, base, fleet", [
    ("warehouse_same_direction", "warehouse_same_direction.yaml", 30),
    ("distribution_centre", "dc_shift.yaml", 40),
])
def test_every_fitted_witness_is_shown_safe_and_a_failed_fit_changes_nothing(
        monkeypatch: pytest.MonkeyPatch, layout_name: str, base: str, fleet: int) -> None:
    """Busy runs on a layout with same-direction aisles (AGVs turn round in them only alone)
    and on the distribution centre's single-track corridors: after every grant and every plan
    the state is shown safe from scratch, hundreds of times by a fitted witness, some of them
    with another AGV's moves fitted again; every fit that fails leaves the witness, the
    positions, the holds and the current numbers as they were. Fits are kept on after walks
    that fail (the policy stops fitting at the first), so that they are checked in the dense
    states that follow too."""
    scenario, layout = scenario_for(layout_name, fleet, 0.6, 200, "avoiding", base=base,
                                    **{"dispatch.max_active_agvs": fleet})
    model = build_simulation(scenario, layout, (), False, False, None, 10_000)
    counts = {"checked": 0, "failed fits": 0}
    grant_now, declare, fit, walk = Traffic.grant_now, Plans.declare, Schedule.fit, Plans._walk

    def shown_safe(plans: Plans, what: str) -> None:
        assert plans.proof() is not None, what
        counts["checked"] += 1

    def grant_checked(self: Traffic, client_id: int, needs: Any) -> Any:
        claim = grant_now(self, client_id, needs)
        shown_safe(self.strategy.plans, f"grant to {client_id} at {self.env.now} s")
        return claim

    def declare_checked(self: Plans, client_id: int, path: Any) -> None:
        declare(self, client_id, path)
        shown_safe(self, f"plan of {client_id} at {self.table.env.now} s")

    def state(schedule: Schedule, start: int) -> tuple[Any, ...]:
        """All but the holds a fit may drop for good: of moves given up, or over (let go of
        before the first move not made) and of an AGV that holds the lock no more."""
        start_at = schedule.pos[start] if start < len(schedule.pos) else float("inf")
        live = {lock: sorted(h for h in holds if schedule.current[h[2]][0] == h[3] and (
                    h[1] >= start_at or h[2] in set(holders_of(lock))))
                for lock, holds in schedule.holds.items()}
        return (list(schedule.moves), list(schedule.pos), dict(schedule.current),
                {lock: holds for lock, holds in live.items() if holds})

    def fit_undone(self: Schedule, chains: Any, start: int, *args: Any) -> int | None:
        before = state(self, start)
        stuck = fit(self, chains, start, *args)
        if stuck is not None:
            counts["failed fits"] += 1
            assert state(self, start) == before
        return stuck

    def walk_fitting_on(self: Plans, *args: Any) -> Any:
        stuck = walk(self, *args)
        self._fits = True
        return stuck

    monkeypatch.setattr(Plans, "_walk", walk_fitting_on)
    monkeypatch.setattr(Traffic, "grant_now", grant_checked)
    monkeypatch.setattr(Plans, "declare", declare_checked)
    monkeypatch.setattr(Schedule, "fit", fit_undone)
    model.env.run(until=scenario.duration_s)
    plans = model.traffic.strategy.plans
    assert plans is not None
    assert counts["checked"] > 2_000 and counts["failed fits"] > 10
    assert plans.fits > 100 and plans.refits > 0
    assert model.recorder.deadlocks == 0


def on_the_junction_ring(*paths: list[str]) -> tuple[Any, Plans]:
    """The junction ring with an AGV at the start of each of `paths`, that path its plan."""
    layout = load_layout(DATA / "junction_ring.yaml")
    scenario = make_scenario(str(DATA / "junction_ring.yaml"), duration_h=0.1, warmup_h=0,
                             demand={"rate_per_hour": 0},
                             fleet={"size": len(paths), "start_nodes": [p[0] for p in paths]},
                             dispatch={"park_idle": False}, traffic={"policy": "avoiding"})
    model = build_simulation(scenario, layout)
    plans = model.traffic.strategy.plans
    assert isinstance(plans, Plans)
    for x, path in enumerate(paths):
        plans.declare(x, path)
    return model, plans


def two_bound_through_j() -> tuple[Any, Plans]:
    """An AGV at W and one at S, both bound through J to N and K."""
    return on_the_junction_ring(["W", "J", "N", "K"], ["S", "J", "N", "K"])


def test_a_changed_plan_is_fitted_after_the_hold_it_meets_without_a_walk() -> None:
    """On the junction ring, an AGV at S is bound round through J to N, and one at W bound
    across J to N too; the walk found a witness. The AGV at W then takes another plan, across
    J to E and X. It is fitted in without a walk, each of its moves in the order of its plan,
    and never in J while the other holds J: the fitted witness, replayed from the state, takes
    both off the track."""
    model, plans = two_bound_through_j()
    assert plans._walk(1, None, ()) is None and plans.witness is not None
    walks = plans.walks
    assert plans.may_declare(0, ["W", "J", "E", "X", "K"])
    assert plans.fits == 1 and plans.walks == walks
    plans.declare(0, ["W", "J", "E", "X", "K"])
    assert plans.proof() == "witness"
    witness = plans.witness
    mine = [k for x, plan, k in witness if x == 0 and plan == plans.plan_id[0]]
    assert mine == sorted(mine) == list(range(1, 6))  # every move, in order, to parking
    schedule = plans._schedule
    assert schedule is not None
    j_lock = model.traffic.table.node_locks["J"]
    spans = {x: (t, r) for t, r, x, number in schedule.holds[j_lock]
             if schedule.current[x][0] == number}
    (t0, r0), (t1, r1) = spans[0], spans[1]
    assert r0 <= t1 or r1 < t0  # never both in J


def test_an_agv_fitted_again_holds_what_it_holds_only_until_its_schedule_lets_go() -> None:
    """While the client is fitted, an AGV to be fitted again after it (`Plans._fit`) holds
    what it holds now until its moves in the schedule let go of it, not for ever: the client
    may take it after that (its own fit then shows it lets go in time, or fails); what it
    would take later is left to its own fit."""
    model, plans = two_bound_through_j()
    assert plans._walk(1, None, ()) is None
    schedule = plans._schedule
    assert schedule is not None
    locks = model.traffic.table.node_locks
    w_lock, j_lock = locks["W"], locks["J"]
    assert 0 in holders_of(w_lock)
    (_, let_go, _, _), = [h for h in schedule.holds[w_lock] if h[2] == 0]
    assert let_go < len(schedule.moves)
    current = dict(schedule.current)

    def others(lock: Any, pending: set[int]) -> list[tuple[float, float, int]]:
        return schedule._others(lock, 1, 0, schedule.pos[0], plans.plan_id.get, pending,
                                current)

    assert others(w_lock, {0}) == [(-INF, let_go, 0)]  # held now, until its move lets go
    assert others(w_lock, set()) == [(-INF, let_go, 0)]  # as for an AGV not fitted again
    assert [h for h in others(j_lock, set()) if h[2] == 0]  # it takes J later on
    assert not [h for h in others(j_lock, {0}) if h[2] == 0]  # left to its own fit


def test_a_move_further_on_is_made_first_only_if_no_move_before_it_takes_what_it_takes(
        ) -> None:
    """On the junction ring an AGV at S is bound through J and N to K and one at E through X
    to K; the witness has one of them go first. The other's move onto a node nobody else's
    earlier move takes (X, or N) is made first, and put first in the witness; its move on to
    K, which the first one's moves take before it, is not."""
    paths = {0: ["E", "X", "K"], 1: ["S", "J", "N", "K"]}
    model, plans = on_the_junction_ring(paths[0], paths[1])
    assert plans._walk(0, None, ()) is None and plans.witness is not None
    first = plans.witness[0][0]
    other = 1 - first
    locks = model.traffic.table.node_locks
    onto = paths[other][1]
    assert plans._moves_first(other, [(locks[onto], 0)], onto)
    assert plans.witness[0][0] == other and plans._next == 1  # put first, counted as made
    plans.took(other, onto)
    plans.advance(other, onto)
    then = paths[other][2]
    if then != "K":  # the AGV at S: J, then N, which nobody else takes
        assert plans._moves_first(other, [(locks[then], 0)], then)
        plans.took(other, then)
        plans.advance(other, then)
    assert not plans._moves_first(other, [(locks["K"], 0)], "K")  # the first one's moves
    # onto K come before it


def test_no_fit_after_the_first_walk_that_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the greedy walk refuses, a fitted witness can show safe a state the walk cannot,
    and the fleet then moves only in the witness's order: from the first walk that fails, the
    policy walks every change as before fits (and records no holds)."""
    scenario, layout = scenario_for("warehouse_same_direction", 30, 0.5, 200, "avoiding",
                                    base="warehouse_same_direction.yaml",
                                    **{"dispatch.max_active_agvs": 30})
    model = build_simulation(scenario, layout, (), False, False, None, 10_000)
    plans = model.traffic.strategy.plans
    assert plans is not None
    at_first: dict[str, int] = {}
    walk = Plans._walk

    def watched(self: Plans, *args: Any) -> Any:
        stuck = walk(self, *args)
        if stuck is not None and not at_first:
            at_first.update(fits=self.fits, walks=self.walks)
        return stuck

    monkeypatch.setattr(Plans, "_walk", watched)
    model.env.run(until=scenario.duration_s)
    assert at_first and at_first["fits"] > 0  # it fitted before
    assert plans.fits == at_first["fits"] and plans.walks > at_first["walks"] + 50
    assert plans._schedule is not None and not plans._schedule.holds  # the witness found
    # since has no holds
