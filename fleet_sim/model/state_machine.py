"""The RSS-AGV-001 vehicle state machine as data: a (state, event) -> transition table.

Every transition of section 4.2 is a row with its trigger event, its condition (a guard over the
vehicle's facts) and its action, as the spec words them. Rows the spec does not list but the fleet
model needs are marked `spec=None` with the reason; the readings of the spec behind them (travel
to a charger and to parking is Moving, the link lost and back, SafeMode's way out, the guards
left out): docs/background/decisions/sim.md.

Firing an event that has no row for the current state raises `InvalidTransition`, which names the
AGV, the state and the event. A row whose guard fails does not fire (`fire` returns False).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from fleet_sim.config.scenario import Rules
from fleet_sim.errors import SimulationError
from fleet_sim.model.states import VehicleState


class Facts(Protocol):
    """What the guards read about a vehicle."""

    @property
    def soc_pct(self) -> float: ...

    @property
    def position_known(self) -> bool: ...

    @property
    def obstacle_near_s(self) -> float: ...

    @property
    def obstacle_clear_s(self) -> float: ...

    @property
    def load_on(self) -> bool: ...

    @property
    def charger_assigned(self) -> bool: ...

    @property
    def error_flags(self) -> bool: ...

    @property
    def rssi_dbm(self) -> float: ...

    @property
    def fms_link(self) -> bool: ...

    @property
    def on_charger(self) -> bool: ...


Guard = Callable[[Facts, Rules], bool]
"""A condition over the vehicle's facts and the scenario's thresholds (RSS-AGV-001 7.1)."""


@dataclass(frozen=True)
class Transition:
    source: VehicleState | None
    """None: from any state (4.2.11 Global -> Error)."""
    event: str
    target: VehicleState
    guard: Guard | None
    condition: str
    action: str
    spec: str | None
    """The section of RSS-AGV-001 this row comes from; None for a row the model adds."""
    why: str = ""


def _soc_above_low(f: Facts, p: Rules) -> bool:
    return f.soc_pct > p.bat_low_pct and f.position_known


T = Transition
S = VehicleState
TRANSITIONS: tuple[Transition, ...] = (
    T(S.BOOTING, "Event_Init_Complete", S.IDLE, None,
      "POST passed in every module", "notify the FMS of start-up; connect Wi-Fi", "4.2.1"),
    T(S.IDLE, "Event_Transport_Order", S.MOVING, _soc_above_low,
      "SOC > 20 % (P_050) and position known", "load the route; energise the drive motors",
      "4.2.2"),
    T(S.MOVING, "Event_Obstacle_Detected", S.PAUSED,
      lambda f, p: f.obstacle_near_s >= p.obstacle_pause_s,
      "LDS < 1.0 m for >= 300 ms", "brake to a stop; warning sound; report to the FMS", "4.2.3"),
    T(S.PAUSED, "Event_Obstacle_Cleared", S.MOVING,
      lambda f, p: f.obstacle_clear_s >= p.obstacle_clear_s,
      "LDS > 1.2 m for >= 2000 ms", "stop the warning sound; drive on", "4.2.4"),
    T(S.MOVING, "Event_Arrived_Pickup", S.LOADING, None,
      "station tag read and stopped within +/-10 mm", "start talking to the transfer unit",
      "4.2.5"),
    T(S.LOADING, "Event_Load_Complete", S.MOVING, lambda f, p: f.load_on,
      "load sensor ON", "set the route to the drop-off", "4.2.6"),
    T(S.MOVING, "Event_Arrived_Dropoff", S.UNLOADING, None,
      "stopped within +/-10 mm", "", "4.2.7"),
    T(S.UNLOADING, "Event_Unload_Complete", S.IDLE, lambda f, p: not f.load_on,
      "load sensor OFF", "go to the waiting position or stay idle here", "4.2.8"),
    T(S.UNLOADING, "Event_Next_Stop", S.MOVING, lambda f, p: not f.load_on,
      "load sensor OFF and the order has another pickup", "set the route to the next pickup",
      None, "multi-stop orders (fleet_sim.config.chains): after a dropoff that is not the "
      "chain's last, drive on to its next pickup without passing through Idle"),
    T(S.IDLE, "Event_Go_Charge", S.MOVING, lambda f, p: f.charger_assigned,
      "a charger is free (FMS)", "drive to the charger", "4.2.9",
      "travel to the charger is recorded as Moving (reading)"),
    T(S.IDLE, "Event_Low_Battery", S.MOVING, lambda f, p: f.charger_assigned,
      "a charger is free (FMS)", "drive to the charger", "4.2.9",
      "travel to the charger is recorded as Moving (reading)"),
    T(S.MOVING, "Event_Arrived_Charger", S.CHARGING, None, "at the charger node",
      "docking sequence", None, "second half of 4.2.9: docking at the charger"),
    T(S.CHARGING, "Event_Charge_Complete", S.IDLE,
      lambda f, p: f.soc_pct > p.charge_done_pct, "SOC > 95 %", "undocking sequence", "4.2.10"),
    T(None, "Event_Critical_Error", S.ERROR, None,
      "any state: sensor break, communication timeout (60 s)...", "stop; wait for an operator",
      "4.2.11"),
    T(S.ERROR, "Event_Switch_Manual", S.MAINTENANCE, None,
      "physical mode switch turned to MANUAL", "release the servo lock", "4.2.12"),
    T(S.MAINTENANCE, "Event_Switch_Auto", S.IDLE, lambda f, p: not f.error_flags,
      "error flags cleared", "estimate the initial position", "4.2.13"),
    T(S.ERROR, "Event_NetLoss_LowBat", S.SAFE_MODE,
      lambda f, p: f.rssi_dbm < p.safe_mode_rssi_dbm and f.soc_pct < p.safe_mode_soc_pct
      and not f.on_charger and not f.fms_link,
      "RSSI < -80 dBm and SOC < 15 % (and, 6.3, no charger and no FMS link)",
      "cut actuator power; save position; emergency beacon", "4.2.14"),
    T(S.SAFE_MODE, "Event_Operator_Rescue", S.MAINTENANCE, None, "an operator reaches the AGV",
      "manual recovery", None, "6.3: only an operator brings an AGV out of SafeMode"),
    T(S.IDLE, "Event_Go_Park", S.MOVING, None, "", "drive to a parking area", None,
      "4.2.8 action 'move to the waiting position', recorded as Moving"),
    T(S.MOVING, "Event_Arrived_Parking", S.IDLE, None, "at the parking area", "", None,
      "end of the trip to the waiting position"),
    T(S.MOVING, "Event_Stop", S.IDLE, None, "the trip to parking was cut short by an order",
      "", None, "the AGV stops where it is to take the order"),
    T(S.MOVING, "Event_Heartbeat_Lost", S.IDLE, None, "FMS heartbeat lost, at the next tag",
      "slow down, drive to the nearest RFID tag, wait and retry", None,
      "Req.Err.011 steps 1-3"),
    T(S.IDLE, "Event_Heartbeat_Restored", S.MOVING, _soc_above_low, "link back, SOC > 20 %",
      "resume the interrupted trip", None, "Req.Err.011: resume after reconnecting"),
    T(S.ERROR, "Event_Watchdog_Reset", S.BOOTING, None, "E_999: CPU exception",
      "the watchdog resets the CPU: POST, then the start-up report (4.2.1)", None,
      "6.1 E_999 'Watchdog Reset', read as a reboot (incidents.cpu_reset: reboot)"),
    T(S.IDLE, "Event_Locate", S.MOVING, None, "position unknown after a reset",
      "creep along the tape to the nearest TYPE_LOC tag (not a transport order: 4.2.2's "
      "guard does not apply)", None,
      "5.3 TYPE_LOC corrects the position; reading: the AGV finds it by itself"),
    T(S.MOVING, "Event_Located", S.IDLE, lambda f, p: f.position_known,
      "a TYPE_LOC tag read (position known)", "wait for orders", None,
      "5.3 TYPE_LOC: the end of the run to find the position"),
)

TABLE: dict[tuple[VehicleState | None, str], Transition] = {
    (t.source, t.event): t for t in TRANSITIONS}
EVENTS = frozenset(t.event for t in TRANSITIONS)


class InvalidTransition(SimulationError):
    """An event fired in a state that has no transition for it."""

    def __init__(self, agv: int, state: VehicleState, event: str) -> None:
        self.agv, self.state, self.event = agv, state, event
        known = sorted(e for (s, e) in TABLE if s in (state, None))
        super().__init__(f"AGV {agv}: event {event} has no transition from state "
                         f"{state.value} ({state.spec_id}); from there: {', '.join(known)}")


def transition_for(agv: int, state: VehicleState, event: str) -> Transition:
    found = TABLE.get((state, event)) or TABLE.get((None, event))
    if found is None:
        raise InvalidTransition(agv, state, event)
    return found
