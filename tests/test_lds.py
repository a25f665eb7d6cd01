"""Another AGV as an obstacle to the LDS (RSS-AGV-001 4.2.3, 4.2.4, E_101; P_005, P_006):
the default reading (`rules.agv_ahead: lds`) and the switch to a fleet manager that holds AGVs
back (`held_back`). See fleet_sim.sim.agents.lds."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import simpy
import yaml

from fleet_sim.config.layout import load_layout
from fleet_sim.config.scenario import Rules
from fleet_sim.config.trace import TraceOrder
from fleet_sim.sim.agents.driving import Driver
from fleet_sim.sim.agents.lds import AgvAhead
from fleet_sim.sim.engine import RunOutput, simulate
from fleet_sim.sim.traffic.waking import AlarmClock

from .conftest import LAYOUTS, make_scenario, write_yaml

TWO_ORDERS = [TraceOrder(20.0, "PICK", "DROP"), TraceOrder(21.0, "PICK", "DROP")]
"""Two AGVs for the pickup: the second queues behind the first while it loads."""


def queue_run(tmp_path: Path, handling_s: float, monkeypatch: pytest.MonkeyPatch | None = None,
              **rules: Any) -> tuple[RunOutput, list[tuple[int, float]]]:
    """Two AGVs, two orders at the pickup P (tiny loop), loading `handling_s` each. Returns the
    run and (AGV, time) of every time traffic made an AGV wait on a drive."""
    data = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text())
    data["stations"][0]["handling"] = {"dist": "fixed", "mean_s": handling_s}
    layout_file = write_yaml(tmp_path / "tiny.yaml", data)
    waits: list[tuple[int, float]] = []
    if monkeypatch is not None:
        began = Driver.began_waiting

        def seen(self: Driver, lock: Any) -> None:
            if self.next_node is not None:
                waits.append((self.id, self.env.now))
            began(self, lock)

        monkeypatch.setattr(Driver, "began_waiting", seen)
    scenario = make_scenario(str(layout_file), warmup_h=0.0, duration_h=0.5,
                             fleet={"size": 2}, rules=rules,
                             demand={"kind": "trace", "trace_csv": "unused.csv"})
    return simulate(scenario, load_layout(layout_file), TWO_ORDERS), waits


def named(out: RunOutput, event: str, agv: int | None = None) -> list[Any]:
    return [e for e in out.recorder.events
            if e.event == event and (agv is None or e.agv == agv)]


def test_a_queue_behind_a_standing_agv_pauses_300_ms_after_it_stopped(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out, waits = queue_run(tmp_path, 200.0, monkeypatch)
    paused = named(out, "Event_Obstacle_Detected", 1)
    assert len(paused) == 1 and paused[0].from_state == "Moving"
    assert paused[0].to_state == "Paused" and paused[0].node == "S1"
    began = [t for agv, t in waits if agv == 1 and t < paused[0].time_s]
    assert paused[0].time_s == pytest.approx(began[-1] + 0.3, abs=1e-9)  # stopped at S1
    assert out.recorder.agv_obstacle_pauses == 1 and out.recorder.obstacle_pauses == 0
    assert "AGV 0 0.50 m ahead" in paused[0].detail
    # it stays paused while AGV 0 loads, and moves on only after AGV 0 left P
    cleared = named(out, "Event_Obstacle_Cleared", 1)
    loaded = named(out, "Event_Load_Complete", 0)[0].time_s
    assert len(cleared) == 1 and cleared[0].time_s > loaded + 2.0
    assert not named(out, "Event_Critical_Error")
    assert all(o.delivered_s is not None for o in out.recorder.orders)


def test_e101_after_five_minutes_paused_behind_an_agv_and_not_before(tmp_path: Path) -> None:
    long, _ = queue_run(tmp_path, 400.0)
    paused = named(long, "Event_Obstacle_Detected", 1)[0].time_s
    errors = named(long, "Event_Critical_Error", 1)
    assert errors[0].detail.startswith("E_101")
    assert errors[0].time_s == pytest.approx(paused + 300.0, abs=1e-9)
    assert errors[0].from_state == "Paused"
    # paused for less than 5 minutes (AGV 0 loads for 280 s): no E_101
    short, _ = queue_run(tmp_path, 280.0)
    assert not named(short, "Event_Critical_Error")
    assert len(named(short, "Event_Obstacle_Cleared", 1)) == 1


def test_held_back_agvs_never_see_the_one_ahead(tmp_path: Path) -> None:
    held, _ = queue_run(tmp_path, 400.0, agv_ahead="held_back")
    assert not named(held, "Event_Obstacle_Detected")
    assert not named(held, "Event_Critical_Error")
    assert held.recorder.agv_obstacle_pauses == 0
    assert all(o.delivered_s is not None for o in held.recorder.orders)


def test_no_pause_when_the_minimum_gap_is_outside_the_stop_distance(tmp_path: Path) -> None:
    """P_006 against 4.2.3: closed up to a gap of 1.0 m or more, the LDS does not stop it."""
    out, _ = queue_run(tmp_path, 400.0, lds_stop_m=0.5)  # gap 0.5 m is not under 0.5 m
    assert not named(out, "Event_Obstacle_Detected")
    assert not named(out, "Event_Critical_Error")


class Ahead:
    """The AGV ahead, as the LDS sees it: standing, or set off at `departed_s`."""

    def __init__(self, departed_s: float, accel_mps2: float) -> None:
        self.standing = True
        self.departed_s = departed_s
        self.accel_mps2 = accel_mps2
        self.hop_ends_s: float | None = None
        self.halted: list[Callable[[], None]] = []

    def when_halted(self, tell: Callable[[], None]) -> None:
        self.halted.append(tell)


class Behind:
    def __init__(self) -> None:
        self.log: list[tuple[str, float]] = []
        self.env: simpy.Environment | None = None

    def pause_for_agv(self, ahead: int, gap_m: float) -> bool:
        assert self.env is not None
        self.log.append(("paused", self.env.now))
        return True

    def resume_after_agv(self, paused_s: float) -> None:
        assert self.env is not None
        self.log.append(("cleared", self.env.now))

    def fail(self, code: str, detail: str = "") -> bool:
        assert self.env is not None
        self.log.append((code, self.env.now))
        return True


@pytest.mark.parametrize("granted_s", [1.0, 10.0])
def test_it_moves_on_once_the_way_is_clear_beyond_1_2_m_for_2000_ms(granted_s: float) -> None:
    """4.2.4: the AGV ahead sets off at 50 s from 0.5 m (P_006); at 0.5 m/s^2 the gap passes
    1.2 m after sqrt(2 x 0.7 / 0.5) s; 2000 ms later the AGV behind moves on, or when traffic
    grants the node, whichever is later."""
    env = simpy.Environment()
    behind = Behind()
    behind.env = env
    watch = AgvAhead(env, Rules(), 0.5, behind, AlarmClock(env))
    ahead = Ahead(0.0, 0.5)

    def drive() -> Any:
        yield env.timeout(40.0)
        watch.began_waiting(lambda: (0, ahead, True), True)
        yield env.timeout(10.0)  # it set off at 50 s
        ahead.standing, ahead.departed_s = False, env.now
        yield env.timeout(granted_s)  # traffic grants the node
        yield from watch.wait_over()

    env.process(drive())
    env.run()
    clear_at = 50.0 + math.sqrt(2 * 0.7 / 0.5) + 2.0
    assert behind.log == [("paused", pytest.approx(40.3)),
                          ("cleared", pytest.approx(max(clear_at, 50.0 + granted_s)))]


def test_a_fault_while_paused_after_the_grant_lets_go_of_the_node(tmp_path: Path) -> None:
    """AGV 0 breaks down loading at P; AGV 1 waits paused behind it. The operator takes AGV 0
    off at 160 s: AGV 1 is granted P and stays paused until the way has been clear for 2 s;
    a fault at 161 s, in that pause, must let go of P (before, the grant leaked and AGV 0,
    back on the track at P after its repair, waited for it for ever)."""
    data = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text())
    data["stations"][0]["handling"] = {"dist": "fixed", "mean_s": 100.0}
    layout_file = write_yaml(tmp_path / "tiny.yaml", data)
    faults = [{"agv": 0, "at_s": 60.0, "code": "E_102"}, {"agv": 1, "at_s": 161.0,
                                                         "code": "E_102"}]
    scenario = make_scenario(str(layout_file), warmup_h=0.0, duration_h=1.0,
                             fleet={"size": 2},
                             demand={"kind": "trace", "trace_csv": "unused.csv"},
                             incidents={"faults": faults,
                                        "operator_response": {"dist": "fixed", "mean_s": 100},
                                        "repair": {"dist": "fixed", "mean_s": 100}})
    out = simulate(scenario, load_layout(layout_file), TWO_ORDERS)
    failed = named(out, "Event_Critical_Error", 1)[0]
    assert failed.from_state == "Paused" and failed.time_s == 161.0
    assert all(o.delivered_s is not None for o in out.recorder.orders)


def _behind_a_driving_agv(hop_ends_s: float) -> tuple[simpy.Environment, Any, AgvAhead, Any]:
    """An AGV's watch on the AGV ahead, 0.5 m on, which drives a hop that ends at
    `hop_ends_s`: (env, the AGV behind, its watch, the AGV ahead)."""
    env = simpy.Environment()
    behind = Behind()
    behind.env = env
    watch = AgvAhead(env, Rules(), 0.5, behind, AlarmClock(env))
    ahead = Ahead(0.0, 0.5)
    ahead.standing, ahead.hop_ends_s = False, hop_ends_s
    return env, behind, watch, ahead


@pytest.mark.parametrize("drives_on", [False, True])
def test_behind_a_driving_agv_the_pause_begins_at_the_first_look_after_its_hop(
        drives_on: bool) -> None:
    """The AGV ahead drives a hop that ends at 45.6 s and stops there: the AGV behind, waiting
    since 40 s and looking every second from 40.3 s, is paused at its first look after the
    hop's end, 46.3 s; had the AGV ahead driven on, it is not paused."""
    env, behind, watch, ahead = _behind_a_driving_agv(45.6)

    def hop() -> Any:
        yield env.timeout(45.6)
        ahead.standing = not drives_on
        ahead.hop_ends_s = 50.0 if drives_on else None

    def wait() -> Any:
        yield env.timeout(40.0)
        watch.began_waiting(lambda: (0, ahead, True), True)
        yield env.timeout(9.0)
        watch.waiting = False

    env.process(hop())
    env.process(wait())
    env.run(until=60.0)
    assert behind.log == ([] if drives_on else [("paused", pytest.approx(46.3))])


def test_behind_an_agv_a_fault_halts_on_its_hop_the_pause_begins_at_the_next_look() -> None:
    """The AGV ahead drives a hop planned to end at 50 s; a fault halts it at 44 s. The AGV
    behind, looking every second from 40.3 s, is paused at 44.3 s, its first look after the
    halt (not at the hop's planned end)."""
    env, behind, watch, ahead = _behind_a_driving_agv(50.0)

    def fault() -> Any:
        yield env.timeout(44.0)
        ahead.standing, ahead.hop_ends_s = True, None
        for tell in ahead.halted:
            tell()

    def wait() -> Any:
        yield env.timeout(40.0)
        watch.began_waiting(lambda: (0, ahead, True), True)

    env.process(fault())
    env.process(wait())
    env.run(until=60.0)
    assert behind.log == [("paused", pytest.approx(44.3))]


def test_waiting_for_a_corridor_it_does_not_look_and_looks_on_its_grid_once_it_waits_for_a_node(
        ) -> None:
    """The AGV waits from 40 s for a corridor (a look would see nobody: it makes none), then,
    the corridor granted at 43.5 s, for the node the AGV ahead stands on: it is paused at
    44.3 s, the look a watch looking every second from 40.3 s would have made first after
    43.5 s, to the last bit of those looks' times (each the last plus a second)."""
    env = simpy.Environment()
    behind = Behind()
    behind.env = env
    watch = AgvAhead(env, Rules(), 0.5, behind, AlarmClock(env))
    ahead = Ahead(0.0, 0.5)
    looks: list[float] = []
    node_wait = [False]

    def find() -> Any:
        looks.append(env.now)
        return (0, ahead, True) if node_wait[0] else None

    def wait() -> Any:
        yield env.timeout(40.0)
        watch.began_waiting(find, False)
        yield env.timeout(3.5)
        node_wait[0] = True
        watch.began_waiting(find, True)

    env.process(wait())
    env.run(until=60.0)
    grid_s = 40.0 + 0.3
    for _ in range(4):
        grid_s += 1.0
    assert looks == [grid_s]
    assert behind.log == [("paused", grid_s)]
