"""Processes that make incidents happen to AGVs: scripted and random FMS link losses, losses of
the vehicle's internal links, random critical faults (MTBF), scripted faults, scripted segment
blocks and scheduled charging. What an AGV does about each is in fleet_sim.sim.agents.vehicle.

Scheduled charging calls go out only when charging is on and the vehicle has a battery model
(with either off, a call to charge has nothing to do).

Heartbeats are not simulated message by message: a loss is noticed `heartbeat_timeout_s` after it
starts (a loss shorter than that goes unnoticed, like an obstacle seen for less than 300 ms).
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

import numpy as np
import simpy

from fleet_sim.config.scenario import Scenario
from fleet_sim.model.records import Recorder
from fleet_sim.sim.agents.fleet_manager import FleetManager
from fleet_sim.sim.agents.vehicle import Vehicle
from fleet_sim.sim.traffic.control import Traffic

Proc = Generator[simpy.Event, Any, None]


def start_incidents(env: simpy.Environment, scenario: Scenario, vehicles: list[Vehicle],
                    fleet: FleetManager, traffic: Traffic, recorder: Recorder,
                    rngs: list[np.random.Generator]) -> None:
    incidents = scenario.incidents
    for block in incidents.blocks:
        traffic.block(block.from_node, block.to_node, block.at_s, block.at_s + block.duration_s)
    for loss in incidents.link_losses:
        env.process(_link_loss(env, scenario, vehicles[loss.agv], fleet, recorder, loss.at_s,
                               loss.duration_s))
    for fault in incidents.faults:
        env.process(_fault_at(env, vehicles[fault.agv], fault.at_s, fault.code))
    for vehicle, rng in zip(vehicles, rngs, strict=True):
        if incidents.link_loss_rate_per_h > 0:
            env.process(_random_link_losses(env, scenario, vehicle, fleet, recorder, rng))
        if incidents.internal_link_loss_rate_per_h > 0:
            env.process(_random_internal_losses(env, scenario, vehicle, recorder, rng))
        if incidents.mtbf_h > 0:
            env.process(_random_faults(env, scenario, vehicle, rng))
    if scenario.charging.enabled and any(p.battery is not None
                                         for p in scenario.fleet.type_profiles.values()):
        for hour in scenario.charging.schedule_h:
            env.process(_charging_call(env, scenario, vehicles, fleet, hour))


def _link_loss(env: simpy.Environment, scenario: Scenario, vehicle: Vehicle,
               fleet: FleetManager, recorder: Recorder, at_s: float, duration_s: float) -> Proc:
    rules = scenario.rules
    if at_s > env.now:
        yield env.timeout(at_s - env.now)
    if duration_s < rules.heartbeat_timeout_s:
        return  # back before anyone noticed
    yield env.timeout(rules.heartbeat_timeout_s)
    recorder.comm_losses += 1
    vehicle.note("heartbeat_lost", f"FMS link down for {duration_s:.0f} s")
    vehicle.set_link(+1)
    if rules.comm_policy == "timeout_60s" and duration_s >= rules.comm_timeout_s:
        yield env.timeout(rules.comm_timeout_s - rules.heartbeat_timeout_s)
        vehicle.fail("E_301", "FMS link lost for 60 s (4.2.11)")
        yield env.timeout(duration_s - rules.comm_timeout_s)
    else:
        yield env.timeout(duration_s - rules.heartbeat_timeout_s)
    vehicle.set_link(-1)
    vehicle.note("heartbeat_restored")
    fleet.link_restored()


def _random_link_losses(env: simpy.Environment, scenario: Scenario, vehicle: Vehicle,
                        fleet: FleetManager, recorder: Recorder,
                        rng: np.random.Generator) -> Proc:
    incidents = scenario.incidents
    while True:
        yield env.timeout(float(rng.exponential(3600.0 / incidents.link_loss_rate_per_h)))
        duration = incidents.link_loss_duration.sample(rng)
        yield env.process(_link_loss(env, scenario, vehicle, fleet, recorder, env.now, duration))


def _random_internal_losses(env: simpy.Environment, scenario: Scenario, vehicle: Vehicle,
                            recorder: Recorder, rng: np.random.Generator) -> Proc:
    """The vehicle's internal links (sensor bus): 4.2.11's 60 s timeout always applies."""
    incidents = scenario.incidents
    rules = scenario.rules
    while True:
        yield env.timeout(float(rng.exponential(3600.0 / incidents.internal_link_loss_rate_per_h)))
        duration = incidents.internal_link_loss_duration.sample(rng)
        recorder.comm_losses += 1
        vehicle.note("internal_link_lost", f"for {duration:.1f} s")
        if duration >= rules.comm_timeout_s:
            yield env.timeout(rules.comm_timeout_s)
            vehicle.fail("E_301", "internal link lost for 60 s (4.2.11)")
            yield env.timeout(duration - rules.comm_timeout_s)
        else:
            yield env.timeout(duration)


def _random_faults(env: simpy.Environment, scenario: Scenario, vehicle: Vehicle,
                   rng: np.random.Generator) -> Proc:
    while True:
        yield env.timeout(float(rng.exponential(scenario.incidents.mtbf_h * 3600.0)))
        vehicle.fail("E_999", "random critical fault (MTBF)")


def _fault_at(env: simpy.Environment, vehicle: Vehicle, at_s: float, code: str) -> Proc:
    yield env.timeout(max(0.0, at_s - env.now))
    vehicle.fail(code, "scripted")


def _charging_call(env: simpy.Environment, scenario: Scenario, vehicles: list[Vehicle],
                   fleet: FleetManager, hour: float) -> Proc:
    """Every day at `hour`, every AGV goes to charge once it is free (scheduled charging)."""
    first = ((hour - scenario.start_h) % 24.0) * 3600.0
    yield env.timeout(first)
    while True:
        for vehicle in vehicles:
            if vehicle.has_battery:  # a type without a battery model never charges
                fleet.commands.send(vehicle.id, "stop", vehicle.call_to_charge)
        yield env.timeout(24 * 3600.0)

