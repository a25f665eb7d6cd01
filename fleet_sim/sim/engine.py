"""Builds the SimPy model of a scenario, runs it, and hands back the run's records.

Random streams come from one `numpy.random.SeedSequence(seed)`, spawned in a fixed order
(arrivals, handling times, traffic back-off per AGV, incidents per AGV, command link jitter), so
the same scenario and seed give the same run, and runs that differ only in fleet size still
share their order streams.

Vehicle types: a mixed fleet (`fleet.vehicles`), a layout that opens segments or stations to
some types only (`allowed_types`), or one that gives a type of the fleet a speed limit of its
own on some segment (`speed_limit_mps_by_type`), gives each type its own routes and motion in
`Traffic` and tells the fleet manager each AGV's type. A one-type fleet on a layout without
either has one set of routes and no types, and the same random streams.

What a run records stays in its `Recorder` (in memory) unless `simulate` is handed a
`RecordSink`: then the recorder streams its rows to the sink as the run goes and closes it when
the run has reached its end (fleet_sim.model.records). A run that raises leaves the sink open:
its owner decides what a half-written sink becomes. At the end, before the sink is closed, the
recorder closes the spells still open (lock and charger waits: `Recorder.end_of_run`). A
watcher process (fleet_sim.sim.gridlock) tells when the fleet locks solid; a `StallMeter`
(fleet_sim.model.stalls) on the recorder keeps the spells of charging starvation and of a fleet
out of service.

Admission `auto` (dispatch.max_active_agvs, the default under `traffic.policy: avoiding`) is
resolved here, once per run, to the layout's critical fleet (`admission_limit`).
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import simpy

from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import Scenario
from fleet_sim.config.trace import TraceOrder
from fleet_sim.model.kinematics import Motion, MotionBackend
from fleet_sim.model.records import BATCH_ROWS, Recorder, RecordSink
from fleet_sim.model.stalls import StallMeter
from fleet_sim.sim.agents.fleet_manager import FleetManager
from fleet_sim.sim.agents.vehicle import Vehicle
from fleet_sim.sim.agents.vehicle_base import SegmentFacts
from fleet_sim.sim.commands import CommandPath
from fleet_sim.sim.demand import Demand
from fleet_sim.sim.estimate import Bottleneck, bottleneck
from fleet_sim.sim.gridlock import watch
from fleet_sim.sim.incidents import start_incidents
from fleet_sim.sim.traffic.control import RouteCosts, Traffic
from fleet_sim.sim.traffic.policies import POLICIES

ProgressCallback = Callable[[float, float], None]
"""Called with (simulated seconds so far, simulated seconds in all) during a run."""

PROGRESS_STEPS = 20
RUN_GC_THRESHOLDS = (100_000, 50, 100)
"""Python's cyclic garbage collector during a run (`collecting_seldom`): a young collection
after 100,000 new container objects, not 700 (and older ones 5 to 10 times less often)."""


@dataclass
class Simulation:
    """One simulation built and ready to run: its SimPy environment and the parts in it."""

    env: simpy.Environment
    traffic: Traffic
    fleet: FleetManager
    vehicles: list[Vehicle]
    demand: Demand
    recorder: Recorder
    motion_backend: MotionBackend | None = None
    admission: tuple[int, Bottleneck] | None = None
    """Admission `auto`: the limit in force and the bottleneck it was derived from."""

    def close(self) -> None:
        """Release what the run holds outside Python (the SUMO simulation, if any)."""
        if self.motion_backend is not None:
            self.motion_backend.close()


@dataclass
class RunOutput:
    scenario: Scenario
    layout: Layout
    recorder: Recorder
    vehicles: list[Vehicle]
    sim_events: int
    wall_s: float
    admission: tuple[int, Bottleneck] | None = None
    """Admission `auto`: the limit in force and the bottleneck it was derived from."""


def build_simulation(scenario: Scenario, layout: Layout, trace: Sequence[TraceOrder] = (),
                     record_occupancy: bool = False, record_moves: bool = False,
                     sink: RecordSink | None = None,
                     batch_rows: int = BATCH_ROWS) -> Simulation:
    env = simpy.Environment()
    profile = scenario.fleet.vehicle
    motion = Motion(profile.max_speed_mps, profile.accel_mps2, profile.decel_mps2,
                    profile.turn_speed_mps)
    recorder = Recorder(scenario.warmup_s, scenario.duration_s, record_occupancy=record_occupancy,
                        record_moves=record_moves, sink=sink, batch_rows=batch_rows)
    costs = RouteCosts(scenario.traffic.congestion_cost_s, scenario.traffic.weak_wifi_cost_s,
                       scenario.rules.weak_rssi_dbm)
    traffic = Traffic(env, layout, motion, recorder, costs=costs, config=scenario.traffic,
                      strategy=POLICIES[scenario.traffic.policy])
    recorder.zone_wait_s = {z: 0.0 for z in traffic.zone_ids}
    recorder.stalls = StallMeter(scenario.fleet.size, stall_threshold_pct(scenario))
    if scenario.motion == "sumo":  # imported here: closed-form runs never load libsumo
        from fleet_sim.sim.sumo.backend import SumoMotion

        traffic.motion_backend = SumoMotion(env, layout, scenario)
    arrivals, handling, backoff, incident, link = np.random.SeedSequence(scenario.seed).spawn(5)
    commands = CommandPath.for_scenario(env, scenario, np.random.default_rng(link), recorder)
    limit, neck = admission_limit(scenario, layout, trace)
    dispatch = scenario.dispatch if limit == scenario.dispatch.max_active_agvs \
        else scenario.dispatch.model_copy(update={"max_active_agvs": limit})
    fleet = FleetManager(env, layout, traffic, dispatch, recorder, commands)
    vehicle_seeds = backoff.spawn(scenario.fleet.size)
    incident_seeds = incident.spawn(2 * scenario.fleet.size)
    profiles = scenario.fleet.agv_profiles
    if scenario.fleet.vehicles or layout.restricts_types \
            or layout.speed_limited_types & set(scenario.fleet.agv_types):
        _set_types(scenario, traffic, fleet)
    segment_facts: dict[tuple[str, str], SegmentFacts] = {}  # the same for every AGV
    vehicles = [
        Vehicle(i, env, traffic, fleet, recorder, scenario,
                np.random.default_rng(vehicle_seeds[i]),
                np.random.default_rng(incident_seeds[2 * i]), profiles[i], segment_facts)
        for i in range(scenario.fleet.size)
    ]
    _place(vehicles, scenario, layout, fleet)
    start_incidents(env, scenario, vehicles, fleet, traffic, recorder,
                    [np.random.default_rng(incident_seeds[2 * i + 1])
                     for i in range(scenario.fleet.size)])
    demand = Demand(env, layout, scenario.demand, scenario.start_h, fleet.submit,
                    np.random.default_rng(arrivals), np.random.default_rng(handling), trace)
    for v in vehicles:
        v.start()
    demand.start()
    env.process(watch(env, traffic, vehicles, recorder, scenario.traffic.gridlock_after_s))
    return Simulation(env, traffic, fleet, vehicles, demand, recorder, traffic.motion_backend,
                 None if neck is None or limit is None else (limit, neck))


def admission_limit(scenario: Scenario, layout: Layout, trace: Sequence[TraceOrder] = ()
                    ) -> tuple[int | None, Bottleneck | None]:
    """The most AGVs admitted onto the track (None: no limit) and, for `auto`, the bottleneck
    it is derived from: the critical fleet, and never fewer than the fleet when the AGVs start
    on the track (fleet.start_nodes: every one holds an admission from the start)."""
    cap = scenario.dispatch.max_active_agvs
    if cap is None and scenario.traffic.policy == "avoiding":
        cap = "auto"
    if cap != "auto":
        return cap, None
    neck = bottleneck(scenario, layout, trace)
    limit = neck.critical_fleet
    if scenario.fleet.start_nodes:
        limit = max(limit, scenario.fleet.size)
    return limit, neck


def stall_threshold_pct(scenario: Scenario) -> float:
    """The SOC at or below which an AGV counts as held by its battery (fleet_sim.model.stalls):
    the threshold it goes to charge at, or P_050 with charging off."""
    rules, charging = scenario.rules, scenario.charging
    return max(charging.threshold_pct, rules.bat_low_pct) if charging.enabled \
        else rules.bat_low_pct


def _set_types(scenario: Scenario, traffic: Traffic, fleet: FleetManager) -> None:
    """Each type's routes and motion in traffic, each AGV's type in traffic and dispatch."""
    for name, p in scenario.fleet.type_profiles.items():
        traffic.add_vehicle_type(name, Motion(p.max_speed_mps, p.accel_mps2, p.decel_mps2,
                                              p.turn_speed_mps))
    agv_types = dict(enumerate(scenario.fleet.agv_types))
    for agv, name in agv_types.items():
        traffic.assign_type(agv, name)
    fleet.set_types(agv_types)


def _place(vehicles: list[Vehicle], scenario: Scenario, layout: Layout,
           fleet: FleetManager) -> None:
    if scenario.fleet.start_nodes:
        for vehicle, node in zip(vehicles, scenario.fleet.start_nodes, strict=False):
            vehicle.place_at(node)
            fleet.on_track_at_start(vehicle)
        return
    slots = [p for p in layout.parking for _ in range(p.capacity)]
    for vehicle, place in zip(vehicles, slots, strict=False):
        vehicle.place_in_parking(place)
        fleet.parking_free[place.id] -= 1


@contextmanager
def collecting_seldom() -> Iterator[None]:
    """Run with Python's cyclic garbage collector seldom at work. The garbage earlier runs
    left is collected first (frozen with the rest, a sweep's worker kept every run's garbage
    and grew to 12 GB); then what exists when the run starts (the layout, routes, the model
    just built) is frozen out of the collections, and the collector works only after
    `RUN_GC_THRESHOLDS` new objects. A run makes short-lived objects by the million (the
    avoiding policy's walks most of all), few of them in reference cycles, so collections
    mostly scan live objects for nothing: 10 to 18 % of a run of 200 AGVs on the fulfilment
    centre under the avoiding policy (docs/background/engine.md). Results do not depend on
    it. The collector's thresholds are restored, and the frozen objects thawed, at the end."""
    thresholds = gc.get_threshold()
    gc.collect()  # what earlier runs left is garbage, not to be frozen (and kept) with the rest
    gc.freeze()
    gc.set_threshold(*RUN_GC_THRESHOLDS)
    try:
        yield
    finally:
        gc.set_threshold(*thresholds)
        gc.unfreeze()


def simulate(scenario: Scenario, layout: Layout, trace: Sequence[TraceOrder] = (),
             progress: ProgressCallback | None = None, record_occupancy: bool = False,
             record_moves: bool = False, sink: RecordSink | None = None,
             batch_rows: int = BATCH_ROWS) -> RunOutput:
    """Run the scenario to its end and return what it recorded: everything in memory, or,
    with a `sink`, streamed to it in batches of `batch_rows` rows of a kind (the sink is
    closed at the end; the recorder keeps the running totals). `record_moves`: also every
    drive, lock wait and placement of every AGV (the replay's data; it changes nothing else)."""
    wall_start = time.perf_counter()
    model = build_simulation(scenario, layout, trace, record_occupancy, record_moves, sink,
                        batch_rows)
    end = scenario.duration_s
    try:
        with collecting_seldom():
            for step in range(1, PROGRESS_STEPS + 1):
                model.env.run(until=end * step / PROGRESS_STEPS)
                if progress is not None:
                    progress(model.env.now, end)
        if record_moves:  # what is under way at the end, as far as it got; then nothing more
            for vehicle in model.vehicles:
                vehicle.end_of_run()
            model.recorder.record_moves = False
    finally:
        model.close()
    model.recorder.end_of_run()
    model.recorder.finish()
    sim_events = next(model.env._eid)  # SimPy's count of scheduled events
    return RunOutput(scenario, layout, model.recorder, model.vehicles, sim_events,
                     time.perf_counter() - wall_start, model.admission)
