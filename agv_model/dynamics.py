"""Time-stepped model of one AGV following a magnetic line (RSS-AGV-001 5.1-5.3, 6.2, 7.1).

Every `dt_s` (default 10 ms, the control cycle) the vehicle reads its line sensor, runs the
steering PID, picks a speed and moves. What it models, and what it assumes (say "assumed"):

* Body: differential drive, seen as a kinematic bicycle whose virtual front wheel sits at the
  line sensor, `sensor_ahead_m` (assumed 0.2 m) ahead of the drive-axle centre. The PID output is
  that wheel's steering angle, so the yaw rate is speed x tan(steer) / sensor_ahead_m. The
  drive-axle centre is the vehicle's reference point: its position, lateral error, RFID reader
  and stop point. It moves in path coordinates (distance along the line, lateral offset, heading
  relative to the line), exact for arcs and straights up to small-angle terms in the sensor's
  look-ahead. On a curve the axle centre runs inside the tape (about sensor_ahead^2 / 2R), so it
  covers the curve's length a little sooner than its wheels' speed says; its odometer (wheel
  distance) runs correspondingly behind the true position until a TYPE_LOC tag corrects it.
* Speed: the drive follows the speed command exactly; the command ramps at VEL_ACC (P_002) up
  and VEL_DEC (P_003) down, never above VEL_MAX (P_001), the cruise speed (from a Drive command
  or a TYPE_SPD tag, 5.3) or TURN_SPEED (P_004, Req.Nav.005) on an arc. Braking for an arc or a
  stop is planned on the odometer so that the vehicle reaches the arc at the turn speed and stops
  on the target; within a step the speed is linear in time and position follows exactly (the
  step that comes to rest ends at decel VEL_DEC, not at the step boundary).
* Commands (Drive, StopAt, Stop) arrive `link_delay_s` after they are sent (per command
  override: `delay_s`) and take effect at the first control step at or after their arrival.
  StopAt plans a stop at a position; Stop brakes now at VEL_DEC. The end of the track is a stop.
* Line loss (Req.Err.010): with every sensor element off the vehicle holds its last steering
  angle for up to `line_loss_limit_m` (0.5 m); if the tape is not found again it goes to Error
  and brakes to a stop.

Deterministic: the same inputs give the same trace. The only noise, RFID read-position jitter
(default 0), comes from `numpy.random.default_rng(seed)`. Plotting is in dynamics_plot.py.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from pydantic import InstanceOf

from agv_model.line_sensor import LineSensor
from agv_model.pid import PidGains, SteeringPid
from agv_model.track import PAUSE_S, SPEED_TAG_MPS, Marker, TagType, Track
from userfiles.checking import NonNegative, Positive, StrictModel

FloatArray = npt.NDArray[np.float64]


class State(StrEnum):
    IDLE = "idle"
    """At rest, not yet told to drive."""
    ACCEL = "accelerating"
    CRUISE = "cruising"
    BRAKE = "braking"
    STOPPED = "stopped"
    """At rest after a stop."""
    PAUSED = "paused"
    """TYPE_CMD 0x20: braking to a stop, then waiting 3 s."""
    LINE_LOST = "line_lost"
    """Req.Err.010: every sensor element off, holding the last steering angle."""
    ERROR = "error"


class VehicleParams(StrictModel):
    """The vehicle's figures (a bad one is an InputError naming it)."""

    max_speed_mps: Positive = 1.0
    """P_001 VEL_MAX 1000 mm/s."""
    accel_mps2: Positive = 0.5
    """P_002 VEL_ACC 500 mm/s2."""
    decel_mps2: Positive = 0.5
    """P_003 VEL_DEC 500 mm/s2."""
    turn_speed_mps: Positive = 0.3
    """P_004 TURN_SPEED 300 mm/s; Req.Nav.005 0.3 m/s on a branch."""
    sensor: InstanceOf[LineSensor] = LineSensor()
    pid: InstanceOf[PidGains] = PidGains()
    sensor_ahead_m: Positive = 0.2
    """Assumed: line sensor 0.2 m ahead of the drive-axle centre."""
    max_steer_rad: Positive = math.radians(60.0)
    """Assumed: steering angle limit of the virtual front wheel."""
    line_loss_limit_m: NonNegative = 0.5
    """Req.Err.010: hold the last steering for at most 50 cm without tape."""
    pause_s: NonNegative = PAUSE_S
    """RSS-AGV-001 5.3: TYPE_CMD 0x20 pauses 3 s."""
    tag_jitter_m: NonNegative = 0.0
    """Assumed 0: standard deviation of where along the track an RFID tag is read."""


@dataclass(frozen=True)
class Drive:
    """Drive (or go on driving) at `speed_mps`."""

    sent_s: float
    speed_mps: float
    delay_s: float | None = None
    """Link delay of this command; None: the run's `link_delay_s`."""


@dataclass(frozen=True)
class StopAt:
    """Stop with the reference point on `position_m` (by the vehicle's odometry)."""

    sent_s: float
    position_m: float
    delay_s: float | None = None


@dataclass(frozen=True)
class Stop:
    """Brake now at VEL_DEC."""

    sent_s: float
    delay_s: float | None = None


Command = Drive | StopAt | Stop


@dataclass(frozen=True)
class Start:
    """Where and how the run starts. A start at speed keeps on at that speed until told."""

    position_m: float = 0.0
    speed_mps: float = 0.0
    lateral_error_m: float = 0.0
    """Offset of the reference point from the line, positive to the left."""
    heading_error_rad: float = 0.0
    """Heading relative to the line, positive to the left."""


@dataclass(frozen=True)
class Event:
    time_s: float
    position_m: float
    what: str


class TraceRecord(NamedTuple):
    time_s: float
    position_m: float
    speed_mps: float
    lateral_error_m: float
    heading_rad: float
    state: State


@dataclass(frozen=True)
class Trace:
    """One sample per step (at the end of it; sample 0 is the start)."""

    dt_s: float
    time_s: FloatArray
    position_m: FloatArray
    """True distance of the reference point along the line."""
    odometer_m: FloatArray
    """Where the vehicle believes it is (wheel odometry, corrected at TYPE_LOC tags)."""
    speed_mps: FloatArray
    lateral_error_m: FloatArray
    """True offset of the reference point from the line, positive to the left."""
    sensor_error_m: FloatArray
    """True offset of the line sensor's centre from the line."""
    heading_rad: FloatArray
    """Heading of the body (0 along the track's first piece)."""
    steer_rad: FloatArray
    state: tuple[State, ...]
    events: tuple[Event, ...]
    stop_time_s: float | None
    """When the vehicle last came to rest, exactly (within its step); None if it never did."""

    def records(self) -> list[TraceRecord]:
        return [TraceRecord(float(t), float(p), float(v), float(y), float(h), s)
                for t, p, v, y, h, s in zip(self.time_s, self.position_m, self.speed_mps,
                                            self.lateral_error_m, self.heading_rad, self.state,
                                            strict=True)]

    @property
    def final_position_m(self) -> float:
        return float(self.position_m[-1])

    def time_at(self, position_m: float) -> float:
        """When the reference point first reached `position_m`, within its step: the step's
        speed is linear in time, so the distance is solved as a quadratic."""
        pos = self.position_m
        reached = np.nonzero(pos >= position_m)[0]
        if reached.size == 0:
            raise ValueError(f"the vehicle never reached {position_m} m "
                             f"(furthest: {float(pos.max())} m)")
        k = int(reached[0])
        if k == 0:
            return float(self.time_s[0])
        p0, p1 = float(pos[k - 1]), float(pos[k])
        v0, v1 = float(self.speed_mps[k - 1]), float(self.speed_mps[k])
        dt = self.dt_s
        if v0 + v1 <= 0.0 or p1 <= p0:
            return float(self.time_s[k])
        # the step's shape in time (speed linear) scaled to its path distance
        fraction = (position_m - p0) / (p1 - p0)
        if v1 == 0.0:  # the step that comes to rest: it stops before the step's end
            duration = 2.0 * (p1 - p0) / v0
            accel = -v0 / duration
            travel = fraction * (p1 - p0)
        else:
            accel = (v1 - v0) / dt
            travel = fraction * (v0 + v1) / 2.0 * dt
        if abs(accel) < 1e-12:
            tau = travel / v0
        else:
            disc = max(v0 * v0 + 2.0 * accel * travel, 0.0)
            tau = (math.sqrt(disc) - v0) / accel
        return float(self.time_s[k - 1]) + tau


def simulate(track: Track, commands: Sequence[Command] = (),
             params: VehicleParams | None = None, *, link_delay_s: float = 0.0,
             dt_s: float = 0.01, start: Start | None = None, seed: int = 0,
             max_time_s: float = 3600.0) -> Trace:
    """Run one vehicle along `track` until it is at rest with nothing left to do (or
    `max_time_s`), and return its trace."""
    return _Run(track, commands, params or VehicleParams(), link_delay_s, dt_s,
                start or Start(), seed, max_time_s).run()


def _braking_speed(odo_m: float, v_mps: float, target_m: float, target_speed_mps: float,
                   decel: float, dt_s: float) -> float:
    """Highest speed at the end of this step from which braking at `decel` still reaches
    `target_m` no faster than `target_speed_mps`. Never below `target_speed_mps`: a step that
    ends past the target only has to arrive there at that speed (and a stop, target speed 0,
    is landed exactly by the step that comes to rest)."""
    c = odo_m + v_mps * dt_s / 2.0 - target_m - target_speed_mps ** 2 / (2.0 * decel)
    disc = (decel * dt_s) ** 2 - 8.0 * decel * c
    if disc < 0.0:
        return target_speed_mps
    return max((-decel * dt_s + math.sqrt(disc)) / 2.0, target_speed_mps)


class _Run:
    def __init__(self, track: Track, commands: Sequence[Command], params: VehicleParams,
                 link_delay_s: float, dt_s: float, start: Start, seed: int,
                 max_time_s: float) -> None:
        if not dt_s > 0:
            raise ValueError(f"dt_s ({dt_s}) must be > 0")
        if link_delay_s < 0:
            raise ValueError(f"link_delay_s ({link_delay_s}) must be >= 0")
        if start.speed_mps < 0 or start.speed_mps > params.max_speed_mps:
            raise ValueError(f"start speed ({start.speed_mps} m/s) must be between 0 and "
                             f"max_speed_mps ({params.max_speed_mps})")
        self.track = track
        self.params = params
        self.dt_s = dt_s
        self.max_time_s = max_time_s
        self.pid = SteeringPid(params.pid)
        pending: list[tuple[float, int, Command]] = []
        for i, cmd in enumerate(commands):
            delay = link_delay_s if cmd.delay_s is None else cmd.delay_s
            if delay < 0:
                raise ValueError(f"command {i} ({cmd}) has a negative delay ({delay} s)")
            if isinstance(cmd, Drive) and not cmd.speed_mps > 0:
                raise ValueError(f"command {i} ({cmd}) needs speed_mps > 0")
            pending.append((cmd.sent_s + delay, i, cmd))
        self.pending = sorted(pending, key=lambda a: (a[0], a[1]))
        rng = np.random.default_rng(seed)
        self.reads: list[tuple[float, Marker]] = []
        for marker in track.markers:
            jitter = float(rng.normal(0.0, params.tag_jitter_m)) if params.tag_jitter_m else 0.0
            self.reads.append((marker.position_m + jitter, marker))
        self.reads.sort(key=lambda r: r[0])
        self.next_read = 0
        while self.next_read < len(self.reads) \
                and self.reads[self.next_read][0] <= start.position_m:
            self.next_read += 1
        # vehicle state
        self.t = 0.0
        self.p = start.position_m
        self.odo = start.position_m
        self.v = start.speed_mps
        self.y = start.lateral_error_m
        self.psi = start.heading_error_rad
        self.steer = 0.0
        self.cruise_mps: float | None = start.speed_mps if start.speed_mps > 0 else None
        self.stop_target_m: float | None = None
        self.lost_at_m: float | None = None
        self.error = False
        self.pausing = False
        self.pause_until_s: float | None = None
        self.moved = start.speed_mps > 0
        self.stop_time_s: float | None = None
        self.events: list[Event] = []
        self.curves = track.curves()

    # ---- helpers ---------------------------------------------------------------------------
    def _event(self, what: str, time_s: float | None = None) -> None:
        self.events.append(Event(self.t if time_s is None else time_s, self.p, what))

    def _brake_now(self) -> None:
        self.stop_target_m = self.odo + self.v ** 2 / (2.0 * self.params.decel_mps2)

    def _apply(self, cmd: Command) -> None:
        if isinstance(cmd, Drive):
            self.cruise_mps = cmd.speed_mps
            self._event(f"command drive {cmd.speed_mps:g} m/s")
        elif isinstance(cmd, StopAt):
            self.stop_target_m = cmd.position_m
            self._event(f"command stop at {cmd.position_m:g} m")
        else:
            self._brake_now()
            self._event("command stop")

    def _read(self, marker: Marker, read_at_m: float) -> None:
        self._event(f"tag {marker.tag.value} {marker.value:#04x} at {marker.position_m:g} m")
        if marker.tag is TagType.SPD:
            if self.cruise_mps is not None:
                self.cruise_mps = SPEED_TAG_MPS[marker.value]
        elif marker.tag is TagType.LOC:
            self.odo = marker.position_m + (self.p - read_at_m)
        elif not self.error:
            self.pausing = True
            self._brake_now()

    def _sensor_error_m(self) -> float:
        d = self.params.sensor_ahead_m
        return self.y + d * math.sin(self.psi) - self.track.bend_m(self.p, d)

    # ---- one control step ------------------------------------------------------------------
    def _steer(self, moving: bool) -> None:
        prm = self.params
        tape = self.track.has_tape(self.p + prm.sensor_ahead_m)
        reading = prm.sensor.read_m(-self._sensor_error_m() if tape else None)
        if reading is None:
            if self.lost_at_m is None:
                self.lost_at_m = self.odo
                self._event("line lost (all sensors off)")
            if not self.error and self.odo - self.lost_at_m > prm.line_loss_limit_m:
                self.error = True
                self._event("error: line not found again (Req.Err.010)")
                self._brake_now()
            return  # keep the last steering angle
        if self.lost_at_m is not None:
            self.lost_at_m = None
            self.pid.reset_derivative()
            self._event("line found")
        if moving:
            steer = self.pid.step(-reading, self.dt_s)
            self.steer = max(-prm.max_steer_rad, min(prm.max_steer_rad, steer))

    def _speed_goal(self) -> float:
        prm = self.params
        dt = self.dt_s
        dec = prm.decel_mps2
        cap = 0.0
        if self.cruise_mps is not None and not self.pausing and self.pause_until_s is None:
            cap = min(self.cruise_mps, prm.max_speed_mps)
        for start_m, end_m in self.curves:
            if start_m <= self.odo < end_m:
                cap = min(cap, prm.turn_speed_mps)
            elif start_m > self.odo:
                cap = min(cap, _braking_speed(self.odo, self.v, start_m, prm.turn_speed_mps,
                                              dec, dt))
        cap = min(cap, _braking_speed(self.odo, self.v, self.track.length_m, 0.0, dec, dt))
        if self.stop_target_m is not None:
            cap = min(cap, _braking_speed(self.odo, self.v, self.stop_target_m, 0.0, dec, dt))
        return cap

    def step(self) -> float:
        """One control step; returns the speed at its end."""
        prm = self.params
        dt = self.dt_s
        while self.pending and self.pending[0][0] <= self.t + 1e-9:
            _, _, cmd = self.pending.pop(0)
            self._apply(cmd)
        if self.pause_until_s is not None and self.t >= self.pause_until_s - 1e-9:
            self.pause_until_s = None
            self._event("pause over")
        goal = self._speed_goal()
        self._steer(moving=self.v > 0.0 or goal > 0.0)
        if self.error:
            goal = 0.0  # brake at VEL_DEC to a stop and stay there
        v0 = self.v
        v1 = min(max(goal, v0 - prm.decel_mps2 * dt, 0.0), v0 + prm.accel_mps2 * dt)
        if v1 == 0.0 and v0 > 0.0:
            ds = v0 * v0 / (2.0 * prm.decel_mps2)  # comes to rest within the step
            self.stop_time_s = self.t + v0 / prm.decel_mps2
        else:
            ds = (v0 + v1) / 2.0 * dt
        if ds > 0.0:
            self.moved = True
            self._move(ds)
        self.v = v1
        self.t += dt
        if v1 == 0.0 and v0 > 0.0:
            self._came_to_rest()
        return v1

    def _move(self, ds: float) -> None:
        d = self.params.sensor_ahead_m
        k = self.track.curvature_at(self.p)
        rate = math.tan(self.steer) / d
        psi_mid = self.psi + 0.5 * ds * (rate - k)
        y_mid = self.y + 0.5 * ds * math.sin(self.psi)
        dp = ds * math.cos(psi_mid) / (1.0 - k * y_mid)
        p_old = self.p
        self.y += ds * math.sin(psi_mid)
        self.psi += ds * rate - k * dp
        self.p += dp
        self.odo += ds
        while self.next_read < len(self.reads) and self.reads[self.next_read][0] <= self.p:
            read_at, marker = self.reads[self.next_read]
            if read_at > p_old:
                self._read(marker, read_at)
            self.next_read += 1

    def _came_to_rest(self) -> None:
        assert self.stop_time_s is not None
        self._event("at rest", self.stop_time_s)
        if self.pausing:
            self.pausing = False
            self.pause_until_s = self.stop_time_s + self.params.pause_s
            self.stop_target_m = None
            return
        if self.stop_target_m is not None and self.odo >= self.stop_target_m - 1e-6:
            self.stop_target_m = None
            self.cruise_mps = None
        elif self.odo >= self.track.length_m - 1e-6:
            self.cruise_mps = None

    def state(self, v_before: float) -> State:
        if self.error:
            return State.ERROR
        if self.lost_at_m is not None:
            return State.LINE_LOST
        if self.pausing or self.pause_until_s is not None:
            return State.PAUSED
        if self.v == 0.0:
            return State.STOPPED if self.moved else State.IDLE
        if self.v > v_before + 1e-12:
            return State.ACCEL
        if self.v < v_before - 1e-12:
            return State.BRAKE
        return State.CRUISE

    def _done(self) -> bool:
        return self.v == 0.0 and not self.pending and self.pause_until_s is None \
            and self._speed_goal() <= 0.0

    # ---- the run ---------------------------------------------------------------------------
    def run(self) -> Trace:
        rows: list[tuple[float, float, float, float, float, float, float, float]] = []
        states: list[State] = []

        def sample(state: State) -> None:
            rows.append((self.t, self.p, self.odo, self.v, self.y, self._sensor_error_m(),
                         self.track.heading_at(self.p) + self.psi, self.steer))
            states.append(state)

        sample(self.state(self.v))
        steps = 0
        limit = math.ceil(self.max_time_s / self.dt_s)
        while steps < limit:
            if self._done():
                break
            v_before = self.v
            self.step()
            steps += 1
            sample(self.state(v_before))
        else:
            self._event("time limit")
        cols = np.array(rows, dtype=np.float64).T
        return Trace(self.dt_s, cols[0], cols[1], cols[2], cols[3], cols[4], cols[5], cols[6],
                     cols[7], tuple(states), tuple(self.events), self.stop_time_s)
