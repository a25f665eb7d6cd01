"""E_999 (RSS-AGV-001 6.1, CPU exception, watchdog reset) read as a reboot through Booting
(4.2.1), the position unknown (4.2.2's guard) until a TYPE_LOC tag is read (5.3); and the
switch back to an operator and Maintenance (`incidents.cpu_reset: operator`)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
import yaml

from fleet_sim.config.scenario import Rules
from fleet_sim.model.state_machine import transition_for
from fleet_sim.model.states import VehicleState

from .conftest import write_yaml
from .test_incidents import ONE_ORDER, events, run, tiny

FAULT_AT_S = 30.0
"""AGV 0 is on its way to the pickup, between SW and S1 (tiny loop)."""


def reset_run(tmp_path: Path, cpu_reset: str = "reboot", **layout: object):
    return run(tiny(tmp_path, **layout), ONE_ORDER, duration_h=0.5,
               incidents={"faults": [{"agv": 0, "at_s": FAULT_AT_S, "code": "E_999"}],
                          "cpu_reset": cpu_reset})


def states(out, since_s: float) -> list[tuple[str, str, str]]:
    return [(e.event, e.from_state, e.to_state) for e in out.recorder.events
            if e.time_s >= since_s and e.from_state != e.to_state and e.from_state]


def test_e999_reboots_through_booting_and_finds_its_position_at_the_next_tag(
        tmp_path: Path) -> None:
    out = reset_run(tmp_path)
    flow = states(out, FAULT_AT_S)
    assert flow[:5] == [("Event_Critical_Error", "Moving", "Error"),
                        ("Event_Watchdog_Reset", "Error", "Booting"),
                        ("Event_Init_Complete", "Booting", "Idle"),
                        ("Event_Locate", "Idle", "Moving"),
                        ("Event_Located", "Moving", "Idle")]
    booted = events(out, "Event_Init_Complete")[-1]
    assert booted.time_s == pytest.approx(FAULT_AT_S + 5.0)  # POST: the profile's boot_s
    locate, located = events(out, "Event_Locate")[0], events(out, "Event_Located")[0]
    # it stopped between SW and S1: it creeps on to S1, the tag ahead, at 0.3 m/s
    assert located.node == "S1" and located.time_s - locate.time_s > 4.0 / 0.3 * 0.5
    assert not events(out, "Event_Switch_Manual")  # no operator, no Maintenance
    assert out.recorder.errors[0].code == "E_999"
    order = out.recorder.orders[0]
    assert order.delivered_s is not None and order.delivered_s < 200.0


def test_with_type_loc_tags_it_creeps_to_the_nearest_one(tmp_path: Path) -> None:
    out = reset_run(tmp_path, markers={"E1": "location"})
    located = events(out, "Event_Located")[0]
    assert located.node == "E1" and "TYPE_LOC" in located.detail
    locate = events(out, "Event_Locate")[0]
    # S1 -> P -> S3 -> SE -> E1 (16 m and the rest of the hop it was on) at creep speed
    assert located.time_s - locate.time_s > 16.0 / 0.3
    assert out.recorder.orders[0].delivered_s is not None


def test_the_operator_reading_sends_it_to_maintenance(tmp_path: Path) -> None:
    out = reset_run(tmp_path, cpu_reset="operator")
    flow = [event for event, _, _ in states(out, FAULT_AT_S)]
    assert flow[:3] == ["Event_Critical_Error", "Event_Switch_Manual", "Event_Switch_Auto"]
    assert not events(out, "Event_Watchdog_Reset") and not events(out, "Event_Locate")


def test_an_agv_that_does_not_know_where_it_is_may_not_take_an_order() -> None:
    """4.2.2: SOC > 20 % and position known; the second half can now fail."""
    guard = transition_for(0, VehicleState.IDLE, "Event_Transport_Order").guard
    assert guard is not None
    rules = Rules()
    assert guard(SimpleNamespace(soc_pct=80.0, position_known=True), rules)
    assert not guard(SimpleNamespace(soc_pct=80.0, position_known=False), rules)
    located = transition_for(0, VehicleState.MOVING, "Event_Located").guard
    assert located is not None
    assert not located(SimpleNamespace(position_known=False), rules)


def test_a_fault_while_booting_is_recovered_from(tmp_path: Path) -> None:
    """A scripted fault before POST ends (boot_s 5 s) used to crash the run."""
    for reset in ("reboot", "operator"):
        out = run(tiny(tmp_path), ONE_ORDER, duration_h=0.5,
                  incidents={"faults": [{"agv": 0, "at_s": 2.0, "code": "E_999"}],
                             "cpu_reset": reset})
        assert events(out, "Event_Critical_Error")[0].from_state == "Booting"
        assert out.recorder.orders[0].delivered_s is not None, reset


def test_a_fault_while_it_looks_for_its_position_is_an_error_like_any_other(
        tmp_path: Path) -> None:
    """Reset at 30 s, POST to 35 s, then creeping to S1: a transfer fault at 40 s sends it to
    the operator (whose Maintenance re-estimates the position, 4.2.13), not a crashed run."""
    out = run(tiny(tmp_path), ONE_ORDER, duration_h=1.0,
              incidents={"faults": [{"agv": 0, "at_s": FAULT_AT_S, "code": "E_999"},
                                    {"agv": 0, "at_s": 40.0, "code": "E_102"}]})
    second = events(out, "Event_Critical_Error")[1]
    assert second.time_s == 40.0 and second.from_state == "Moving"
    assert events(out, "Event_Locate") and not events(out, "Event_Located")
    assert events(out, "Event_Switch_Auto")
    assert out.recorder.orders[0].delivered_s is not None


def test_stopped_between_tags_it_creeps_on_to_the_tag_ahead_before_it_turns(
        tmp_path: Path) -> None:
    """Reset between SW and S1; the only TYPE_LOC tag, X, is a spur 4 m off SW. It cannot
    turn back on the tape: it creeps on to S1 and round the loop to X (about 52 m at 0.3 m/s),
    never straight from SW to X while it holds S1 (a run with the route from the tag behind
    drove into a corridor it did not hold)."""
    data = yaml.safe_load(tiny(tmp_path).read_text())
    data["nodes"].append({"id": "X", "x": -4, "y": 0, "marker": "location"})
    data["segments"].append({"from": "SW", "to": "X", "direction": "two_way"})
    out = run(write_yaml(tmp_path / "spur.yaml", data), ONE_ORDER, duration_h=0.5,
              incidents={"faults": [{"agv": 0, "at_s": FAULT_AT_S, "code": "E_999"}]})
    locate, located = events(out, "Event_Locate")[0], events(out, "Event_Located")[0]
    assert locate.detail.endswith("to X") and located.node == "X"
    assert located.time_s - locate.time_s > 48.0 / 0.3
    assert out.recorder.orders[0].delivered_s is not None


def test_under_avoiding_traffic_its_plan_goes_on_to_the_tag_ahead_first(
        tmp_path: Path) -> None:
    """The same reset under `traffic.policy: avoiding`: the plan declared for the creep starts
    with the tag ahead it holds (S1), not with the route from the tag behind straight to X (a
    run with that plan read the node after S1 off the wrong route and stopped with a KeyError
    for a segment the layout does not have: warehouse_incidents, seeds 5, 6, 7, 10 and 19 of
    20)."""
    data = yaml.safe_load(tiny(tmp_path).read_text())
    data["nodes"].append({"id": "X", "x": -4, "y": 0, "marker": "location"})
    data["segments"].append({"from": "SW", "to": "X", "direction": "two_way"})
    out = run(write_yaml(tmp_path / "spur.yaml", data), ONE_ORDER, duration_h=0.5,
              traffic={"policy": "avoiding"},
              incidents={"faults": [{"agv": 0, "at_s": FAULT_AT_S, "code": "E_999"}]})
    locate, located = events(out, "Event_Locate")[0], events(out, "Event_Located")[0]
    assert locate.detail.endswith("to X") and located.node == "X"
    assert located.time_s - locate.time_s > 48.0 / 0.3
    assert out.recorder.orders[0].delivered_s is not None
