"""`motion: sumo`: AGVs driven by SUMO (libsumo) while the SimPy model keeps everything else.

Dispatching, the state machine, charging, incidents and the node and corridor locks stay in the
SimPy model; only the driving of each hop moves to SUMO, whose Krauss car-following model (with
sigma 0) accelerates, brakes and keeps the gap to the vehicle ahead, vehicle by vehicle.

How the two advance together: a SimPy process steps SUMO in steps of `sumo.step_length_s`, and
after each step fires the events of the hops that ended in it. While no hop is under way it
sleeps, and SUMO is brought up to the SimPy clock before the next command. A hop u -> v tells
SUMO the route (u -> v, and v -> w when the driver already holds w and may pass through v) and
keeps one stop at the end of the last edge the AGV may enter, so that SUMO brakes wherever the
closed form would: at v when the AGV must stop there, else at w (which it must be able to). The
slow branch curve after a left or right turn (Req.Nav.005) is a SUMO waypoint at the turn speed
over the first `turn_length_m` of the edge. A marker or comm-loss speed cap is the vehicle's
maximum speed. A mixed fleet: each AGV is inserted as its type's vType (top speed,
acceleration, deceleration, length, gap), its turn waypoints use its type's turn speed, and a
segment's per-type speed limits are its class's limits in SUMO's network
(fleet_sim.sim.sumo.network.vehicle_classes). Obstacles and line searches hold the
vehicle (brake to the creep speed or to a stop) and let it go again; a fault halts it;
leaving the track removes it; the next hop inserts it again at the node where it comes back.

libsumo runs one simulation per process, is not thread-safe, and a crash in it ends the
process: one `SumoMotion` at a time (a second raises), and the commands that run several SUMO
runs (`fleet-sim crosscheck`, bench/sumo_vs_engine.py) start one process per run. libsumo is
imported here, lazily, so closed-form runs never load it.
"""

from __future__ import annotations

import contextlib
import io
import math
import tempfile
from collections.abc import Generator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import simpy

from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario
from fleet_sim.errors import SimulationError, optional_import
from fleet_sim.sim.sumo import NEEDED_BY, require_backend
from fleet_sim.sim.sumo.network import VehicleClass, edge_id, export, vehicle_classes

STOP_S = 1e9
"""Duration of the stop that holds an AGV at a node until its next hop resumes it."""
AT_STOP_M = 0.2
"""A vehicle standing still this close to the end of its stop edge has arrived."""

Proc = Generator[simpy.Event, Any, None]

_active: SumoMotion | None = None


def load_libsumo() -> ModuleType:
    """Import libsumo (quietly: it prints a pyarrow version note on import)."""
    with contextlib.redirect_stdout(io.StringIO()):
        return optional_import("libsumo", "sumo", NEEDED_BY)


@dataclass
class _Car:
    vid: str
    kind: VehicleClass
    """Its vehicle type: SUMO vType, top speed and turn speed."""
    present: bool = False
    route: list[str] = field(default_factory=list)
    """Edges SUMO knows the vehicle will drive, from the one it is on."""
    stop_edge: str | None = None
    """The edge at whose end the vehicle's stop is."""
    max_speed_mps: float = 0.0
    held: bool = False


@dataclass
class _Watch:
    """What the stepping process looks for after each step."""

    kind: str  # "leave": on to `beyond`; "stop": standing at the end of `edge`; "reach": past
    edge: str  # `pos_m` on `edge`, or on to `beyond`
    pos_m: float
    beyond: str | None
    event: simpy.Event


class SumoMotion:
    """The libsumo simulation behind the AGVs of one run (a MotionBackend)."""

    def __init__(self, env: simpy.Environment, layout: Layout, scenario: Scenario) -> None:
        global _active
        if _active is not None:
            raise SimulationError("a SUMO simulation is already running in this process "
                                  "(libsumo allows one per process)")
        require_backend("sumo")  # before the network is built: one line if SUMO is missing
        self.env = env
        self.layout = layout
        self.step_s = scenario.sumo.step_length_s
        classes = vehicle_classes(scenario.fleet.type_profiles, layout)
        by_name = {c.name: c for c in classes}
        self.kinds = [by_name[name] for name in scenario.fleet.agv_types]
        """Each AGV's vehicle type, in AGV order."""
        self._tmp = tempfile.TemporaryDirectory(prefix="fleet_sim_sumo_")
        network = export(layout, Path(self._tmp.name), tau_s=scenario.sumo.tau_s,
                         classes=classes)
        self.lengths = {edge_id(u, v): float(d["length_m"])
                        for u, v, d in layout.graph.edges(data=True)}
        self.limits = {edge_id(u, v): float(d["speed_limit_mps"])
                       for u, v, d in layout.graph.edges(data=True)}
        self.sumo = load_libsumo()
        self.sumo.start([
            "sumo", "-n", str(network.net_file), "-a", str(network.vtype_file),
            "--step-length", repr(self.step_s), "--step-method.ballistic", "true",
            "--time-to-teleport", "-1", "--collision.action", "warn",
            "--no-step-log", "true", "--no-warnings", "true", "--seed", str(scenario.seed),
        ])
        _active = self
        self.step_index = 0
        """SUMO's clock, in steps."""
        self.steps = 0
        self.cars: dict[int, _Car] = {}
        self.watches: dict[int, list[_Watch]] = {}
        self._routes = 0
        self._wake: simpy.Event | None = None
        self.closed = False
        env.process(self._stepper())

    # ---- the clock --------------------------------------------------------------------------
    def _step_to(self, index: int) -> None:
        if index > self.step_index:
            self.sumo.simulationStep(index * self.step_s)
            self.steps += index - self.step_index
            self.step_index = index

    def _sync(self) -> None:
        """Bring SUMO up to the last step at or before the SimPy clock."""
        self._step_to(math.floor(self.env.now / self.step_s + 1e-6))

    def _stepper(self) -> Proc:
        while True:
            if not self.watches:
                self._wake = self.env.event()
                yield self._wake
                self._wake = None
            index = max(self.step_index, math.floor(self.env.now / self.step_s + 1e-6)) + 1
            yield self.env.timeout(max(0.0, index * self.step_s - self.env.now))
            self._step_to(index)
            self._look()

    def _look(self) -> None:
        vehicle = self.sumo.vehicle
        for agv_id in list(self.watches):
            car = self.cars[agv_id]
            road = vehicle.getRoadID(car.vid)
            left: list[_Watch] = []
            for watch in self.watches[agv_id]:
                if road == "":  # not inserted yet
                    left.append(watch)
                    continue
                if watch.kind == "leave":
                    done = road == watch.beyond
                elif watch.kind == "stop":
                    done = road == watch.edge and not car.held \
                        and vehicle.getSpeed(car.vid) == 0.0 \
                        and vehicle.getLanePosition(car.vid) >= \
                        self.lengths[watch.edge] - AT_STOP_M
                else:
                    done = road == watch.beyond or (
                        road == watch.edge and vehicle.getLanePosition(car.vid) >= watch.pos_m)
                if done:
                    watch.event.succeed(0.0 if watch.kind == "stop"
                                        else float(vehicle.getSpeed(car.vid)))
                else:
                    left.append(watch)
            if left:
                self.watches[agv_id] = left
            else:
                del self.watches[agv_id]

    def _watch(self, agv_id: int, kind: str, edge: str, pos_m: float = 0.0) -> simpy.Event:
        event = self.env.event()
        route = self.cars[agv_id].route
        beyond = route[route.index(edge) + 1] if edge in route[:-1] else None
        self.watches.setdefault(agv_id, []).append(_Watch(kind, edge, pos_m, beyond, event))
        if self._wake is not None and not self._wake.triggered:
            self._wake.succeed()
        return event

    # ---- hops ---------------------------------------------------------------------------------
    def _car(self, agv_id: int) -> _Car:
        car = self.cars.get(agv_id)
        if car is None:
            car = self.cars[agv_id] = _Car(f"agv{agv_id}", self.kinds[agv_id])
        return car

    def hop(self, agv_id: int, prev: str | None, u: str, v: str, after: str | None,
            cap_mps: float | None) -> simpy.Event:
        self._sync()
        vehicle = self.sumo.vehicle
        car = self._car(agv_id)
        edge = edge_id(u, v)
        ahead = [edge] + ([edge_id(v, after)] if after is not None else [])
        last = ahead[-1]
        if not car.present:
            self._routes += 1
            route_id = f"r{self._routes}"
            self.sumo.route.add(route_id, ahead)
            vehicle.add(car.vid, route_id, typeID=car.kind.vtype_id, depart="now",
                        departPos="0", departSpeed="0", departLane="0")
            car.present, car.route, car.stop_edge = True, list(ahead), None
            car.max_speed_mps = car.kind.profile.max_speed_mps
            self._curve(car, prev, u, v)
            if after is not None:
                self._curve(car, u, v, after)
        else:
            road = vehicle.getRoadID(car.vid)
            if road == edge:
                route = ahead
            elif prev is not None and road == edge_id(prev, u):
                route = [road, *ahead]
            else:
                raise SimulationError(f"AGV {agv_id} starts hop {u} -> {v} but SUMO has it on "
                                      f"edge {road!r}")
            if car.stop_edge == road and vehicle.getSpeed(car.vid) == 0.0:
                try:  # standing at its stop: drive on
                    vehicle.resume(car.vid)
                    car.stop_edge = None
                except self.sumo.TraCIException:  # held short of it (an obstacle): drop it
                    self._drop_stop(car)
            if car.stop_edge is not None and car.stop_edge != last:
                self._drop_stop(car)
            new = [e for e in route if e not in car.route]
            if route != car.route[:len(route)] or len(car.route) != len(route):
                vehicle.setRoute(car.vid, route)
            car.route = route
            if edge in new:
                self._curve(car, prev, u, v)
            if after is not None and ahead[-1] in new:
                self._curve(car, u, v, after)
        if car.stop_edge != last:
            vehicle.setStop(car.vid, last, pos=self.lengths[last], laneIndex=0, duration=STOP_S)
            car.stop_edge = last
        speed = car.kind.profile.max_speed_mps if cap_mps is None else cap_mps
        if speed != car.max_speed_mps:
            vehicle.setMaxSpeed(car.vid, speed)
            car.max_speed_mps = speed
        return self._watch(agv_id, "leave" if after is not None else "stop", edge)

    def _curve(self, car: _Car, prev: str | None, u: str, v: str) -> None:
        """A waypoint at the turn speed over the curve at the start of u -> v, if it turns
        (at most the segment's limit for the car's type)."""
        if self.layout.turn(prev, u, v) not in ("left", "right"):
            return
        edge = edge_id(u, v)
        curve = min(self.layout.turn_length_m, self.lengths[edge])
        if curve <= 0:
            return
        vehicle = self.sumo.vehicle
        vehicle.setStop(car.vid, edge, pos=curve, laneIndex=0, duration=0.0, startPos=0.0)
        for index, stop in enumerate(vehicle.getStops(car.vid)):
            if stop.lane == f"{edge}_0" and abs(stop.endPos - curve) < 1e-6 \
                    and stop.duration == 0.0:
                limit = self.layout.speed_limit_mps(u, v, car.kind.name) \
                    if car.kind.vclass is not None else self.limits[edge]
                vehicle.setStopParameter(car.vid, index, "speed",
                                         repr(min(car.kind.profile.turn_speed_mps, limit)))
                return
        raise SimulationError(f"SUMO did not take the turn waypoint on {edge} for {car.vid}")

    def _drop_stop(self, car: _Car) -> None:
        vehicle = self.sumo.vehicle
        lane = f"{car.stop_edge}_0"
        for index, stop in enumerate(vehicle.getStops(car.vid)):
            if stop.lane == lane and stop.duration >= STOP_S - 1:
                vehicle.replaceStop(car.vid, index, "")
                break
        car.stop_edge = None

    def reach(self, agv_id: int, u: str, v: str, share: float) -> simpy.Event:
        edge = edge_id(u, v)
        return self._watch(agv_id, "reach", edge, share * self.lengths[edge])

    # ---- holding, faults, off the track ----------------------------------------------------
    def hold(self, agv_id: int, speed_mps: float) -> None:
        car = self.cars.get(agv_id)
        if car is None or not car.present:
            return
        self._sync()
        self.sumo.vehicle.setSpeed(car.vid, speed_mps)
        car.held = True
        if self._wake is not None and not self._wake.triggered:
            self._wake.succeed()  # keep SUMO in step while it brakes

    def release(self, agv_id: int) -> None:
        car = self.cars.get(agv_id)
        if car is None or not car.present or not car.held:
            return
        self._sync()
        self.sumo.vehicle.setSpeed(car.vid, -1.0)
        car.held = False

    def halt(self, agv_id: int) -> None:
        self.watches.pop(agv_id, None)
        car = self.cars.get(agv_id)
        if car is not None and car.present:
            self._sync()
            self.sumo.vehicle.setSpeed(car.vid, 0.0)
            car.held = True

    def off_track(self, agv_id: int) -> None:
        self.watches.pop(agv_id, None)
        car = self.cars.get(agv_id)
        if car is None or not car.present:
            return
        self._sync()
        with contextlib.suppress(self.sumo.TraCIException):
            self.sumo.vehicle.remove(car.vid)
        self.cars[agv_id] = _Car(car.vid, car.kind)

    def close(self) -> None:
        global _active
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(Exception):
            self.sumo.close()
        if _active is self:
            _active = None
        self._tmp.cleanup()
