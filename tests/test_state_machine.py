"""The RSS-AGV-001 state machine: the table against the spec, and every transition with its guard
and its recorded event."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import pytest

from fleet_sim.config.layout import Layout
from fleet_sim.model.records import EventRecord
from fleet_sim.model.state_machine import TABLE, TRANSITIONS, InvalidTransition
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.agents.vehicle import Vehicle
from fleet_sim.sim.engine import Simulation, build_simulation

from .conftest import make_scenario

S = VehicleState

# Section 4.2 of RSS-AGV-001, written down from the spec: (section, from, event, to).
SPEC_4_2 = [
    ("4.2.1", S.BOOTING, "Event_Init_Complete", S.IDLE),
    ("4.2.2", S.IDLE, "Event_Transport_Order", S.MOVING),
    ("4.2.3", S.MOVING, "Event_Obstacle_Detected", S.PAUSED),
    ("4.2.4", S.PAUSED, "Event_Obstacle_Cleared", S.MOVING),
    ("4.2.5", S.MOVING, "Event_Arrived_Pickup", S.LOADING),
    ("4.2.6", S.LOADING, "Event_Load_Complete", S.MOVING),
    ("4.2.7", S.MOVING, "Event_Arrived_Dropoff", S.UNLOADING),
    ("4.2.8", S.UNLOADING, "Event_Unload_Complete", S.IDLE),
    # 4.2.9 Idle -> Charging: travel to the charger is recorded as Moving (fleet_sim's reading)
    ("4.2.9", S.IDLE, "Event_Go_Charge", S.MOVING),
    ("4.2.9", S.IDLE, "Event_Low_Battery", S.MOVING),
    ("4.2.10", S.CHARGING, "Event_Charge_Complete", S.IDLE),
    ("4.2.11", None, "Event_Critical_Error", S.ERROR),
    ("4.2.12", S.ERROR, "Event_Switch_Manual", S.MAINTENANCE),
    ("4.2.13", S.MAINTENANCE, "Event_Switch_Auto", S.IDLE),
    ("4.2.14", S.ERROR, "Event_NetLoss_LowBat", S.SAFE_MODE),
]


@pytest.mark.parametrize("section,source,event,target", SPEC_4_2)
def test_table_holds_every_transition_of_4_2(section: str, source: VehicleState | None, event: str,
                                             target: VehicleState) -> None:
    row = TABLE[(source, event)]
    assert row.target is target and row.spec == section


def test_rows_not_in_the_spec_say_why() -> None:
    extra = [t for t in TRANSITIONS if t.spec is None]
    assert extra and all(t.why for t in extra)
    spec_rows = {(s, e) for _, s, e, _ in SPEC_4_2}
    assert all((t.source, t.event) not in spec_rows for t in extra)


@dataclass
class Harness:
    model: Simulation
    agv: Vehicle

    def events(self) -> list[EventRecord]:
        return self.model.recorder.events


@pytest.fixture
def harness(tiny_layout: Layout) -> Harness:
    """One AGV on the tiny loop whose process is never started: the test fires events itself."""
    scenario = make_scenario(duration_h=1, warmup_h=0, fleet={"size": 1, "start_nodes": ["S1"]},
                             demand={"rate_per_hour": 0})
    model = build_simulation(scenario, tiny_layout)
    agv = model.vehicles[0]
    return Harness(model, agv)  # its own process is still booting (5 s): time never moves


def satisfy(agv: Vehicle, event: str) -> None:
    """Make the facts such that the guard of `event` passes."""
    agv.battery.set_soc(agv.env.now, 50.0)
    agv._obstacle_near_s = 0.3
    agv._obstacle_clear_s = 2.0
    agv.error_code = None
    agv._position_known = True
    agv.rssi_override = -55.0  # type: ignore[attr-defined]
    agv.links_down, agv.in_dead_spot, agv.docked = 0, False, False
    agv.loaded = event == "Event_Load_Complete"
    if event in ("Event_Go_Charge", "Event_Low_Battery"):
        agv.charger = agv.model_charger  # type: ignore[attr-defined]
    if event == "Event_Charge_Complete":
        agv.battery.set_soc(agv.env.now, 96.0)
    if event == "Event_NetLoss_LowBat":
        agv.battery.set_soc(agv.env.now, 12.0)
        agv.links_down = 1
        agv.in_dead_spot = True
        agv.rssi_override = -90.0  # type: ignore[attr-defined]


def reach(agv: Vehicle, state: VehicleState) -> None:
    """Drive the AGV from Booting to `state` through the table's own transitions."""
    paths: dict[VehicleState, list[str]] = {S.BOOTING: []}
    todo = deque([S.BOOTING])
    while todo:
        here = todo.popleft()
        for t in TRANSITIONS:
            if t.source == here and t.target not in paths:
                paths[t.target] = [*paths[here], t.event]
                todo.append(t.target)
        if here != S.ERROR and S.ERROR not in paths:
            paths[S.ERROR] = ["Event_Critical_Error"]
            todo.append(S.ERROR)
    for event in paths[state]:
        satisfy(agv, event)
        assert agv.fire(event), f"could not fire {event} from {agv.state}"
    assert agv.state is state


# (event, what breaks its guard) for every guarded transition
BREAK_GUARD: dict[str, Callable[[Vehicle], None]] = {
    "Event_Transport_Order": lambda a: a.battery.set_soc(a.env.now, 20.0),
    "Event_Obstacle_Detected": lambda a: setattr(a, "_obstacle_near_s", 0.299),
    "Event_Obstacle_Cleared": lambda a: setattr(a, "_obstacle_clear_s", 1.999),
    "Event_Load_Complete": lambda a: setattr(a, "loaded", False),
    "Event_Unload_Complete": lambda a: setattr(a, "loaded", True),
    "Event_Next_Stop": lambda a: setattr(a, "loaded", True),
    "Event_Go_Charge": lambda a: setattr(a, "charger", None),
    "Event_Low_Battery": lambda a: setattr(a, "charger", None),
    "Event_Charge_Complete": lambda a: a.battery.set_soc(a.env.now, 95.0),
    "Event_Switch_Auto": lambda a: setattr(a, "error_code", "E_999"),
    "Event_NetLoss_LowBat": lambda a: a.battery.set_soc(a.env.now, 15.0),
    "Event_Heartbeat_Restored": lambda a: a.battery.set_soc(a.env.now, 19.0),
    "Event_Located": lambda a: setattr(a, "_position_known", False),
}


@pytest.mark.parametrize("transition", TRANSITIONS, ids=lambda t: f"{t.source}-{t.event}")
def test_each_transition(harness: Harness, transition: object, monkeypatch: pytest.MonkeyPatch,
                         tiny_layout: Layout) -> None:
    from fleet_sim.model.state_machine import Transition
    assert isinstance(transition, Transition)
    agv = harness.agv
    agv.model_charger = tiny_layout.places["PICK"]  # type: ignore[attr-defined]
    monkeypatch.setattr(Vehicle, "rssi_dbm",
                        property(lambda a: getattr(a, "rssi_override", -55.0)))
    source = transition.source or S.LOADING  # a Global row: from any state, here Loading
    reach(agv, source)
    # the guard: when its condition fails, nothing happens but a guard_failed note
    if transition.guard is not None:
        satisfy(agv, transition.event)
        BREAK_GUARD[transition.event](agv)
        before = len(harness.events())
        assert agv.fire(transition.event) is False
        assert agv.state is source
        assert harness.events()[before].event == "guard_failed"
    satisfy(agv, transition.event)
    assert agv.fire(transition.event, "in a test")
    assert agv.state is transition.target
    assert harness.events()[-1] == EventRecord(
        time_s=0.0, agv=0, event=transition.event, from_state=source.value,
        to_state=transition.target.value, node="S1", detail="in a test")


def test_an_event_with_no_transition_names_agv_state_and_event(harness: Harness) -> None:
    with pytest.raises(InvalidTransition, match=r"AGV 0: event Event_Load_Complete has no "
                                                r"transition from state Booting \(ST_001\)"):
        harness.agv.fire("Event_Load_Complete")


def test_safe_mode_needs_every_condition_of_6_3(harness: Harness,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(Vehicle, "rssi_dbm",
                        property(lambda a: getattr(a, "rssi_override", -55.0)))
    agv = harness.agv
    reach(agv, S.ERROR)
    for breaker in (lambda: setattr(agv, "rssi_override", -80.0),  # RSSI not below -80 dBm
                    lambda: setattr(agv, "links_down", 0) or setattr(agv, "in_dead_spot", False),
                    lambda: setattr(agv, "docked", True)):  # on the charger
        satisfy(agv, "Event_NetLoss_LowBat")
        breaker()
        assert agv.fire("Event_NetLoss_LowBat") is False
    satisfy(agv, "Event_NetLoss_LowBat")
    agv.battery.set_soc(agv.env.now, 14.99)
    assert agv.fire("Event_NetLoss_LowBat")
    assert agv.state is S.SAFE_MODE
