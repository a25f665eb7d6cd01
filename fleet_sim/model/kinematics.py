"""Closed-form travel times under a trapezoidal speed profile.

A stretch of track is a sequence of pieces, each a (length_m, speed_limit_mps) pair: a segment at
its limit, or a branch curve at the turn speed (Req.Nav.005: 0.3 m/s) followed by the rest of the
segment. The vehicle accelerates at `accel_mps2` up to the limit, cruises, and brakes at
`decel_mps2` where a lower limit or a stop comes. Times are exact for that profile; no time steps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    import simpy

Piece = tuple[float, float]
"""(length_m, speed_limit_mps) of one stretch of uniform speed limit."""


@dataclass(frozen=True)
class Motion:
    """The motion limits of one vehicle type."""

    max_speed_mps: float
    accel_mps2: float
    decel_mps2: float
    turn_speed_mps: float


class MotionBackend(Protocol):
    """Moves AGVs instead of the closed form (fleet_sim.sim.motion.sumo.SumoMotion): the driver
    asks it for each hop and waits for the events it hands back; locks stay with the driver."""

    def hop(self, agv_id: int, prev: str | None, u: str, v: str, after: str | None,
            cap_mps: float | None) -> simpy.Event:
        """Start driving u -> v (on to `after` without stopping, or stop at v if None); the
        event fires with the speed at v when the AGV gets there."""

    def reach(self, agv_id: int, u: str, v: str, share: float) -> simpy.Event:
        """An event that fires when `share` of the current hop u -> v is behind the AGV."""

    def hold(self, agv_id: int, speed_mps: float) -> None:
        """Keep the AGV at or below `speed_mps` (0: brake to a stop) until `release`."""

    def release(self, agv_id: int) -> None:
        """Let the AGV drive its plan again after `hold`."""

    def halt(self, agv_id: int) -> None:
        """A fault: brake to a stop and forget the hop under way."""

    def off_track(self, agv_id: int) -> None:
        """The AGV left the track (parking bay, operator): take it out of the simulation."""

    def close(self) -> None:
        """End the simulation behind the backend."""


def piece_time(length_m: float, v_in: float, v_limit: float, v_out: float,
               accel: float, decel: float) -> float:
    """Time to drive one piece entering at v_in and leaving at v_out (both feasible)."""
    if length_m <= 0.0:
        return 0.0
    v_peak_sq = (2.0 * accel * decel * length_m + decel * v_in * v_in + accel * v_out * v_out) \
        / (accel + decel)
    v_peak = min(v_limit, math.sqrt(v_peak_sq))
    v_peak = max(v_peak, v_in, v_out)
    d_acc = (v_peak * v_peak - v_in * v_in) / (2.0 * accel)
    d_dec = (v_peak * v_peak - v_out * v_out) / (2.0 * decel)
    cruise = max(0.0, length_m - d_acc - d_dec)
    return (v_peak - v_in) / accel + (v_peak - v_out) / decel + cruise / v_peak


def traverse(pieces: Sequence[Piece], v_in: float, v_end_max: float,
             accel: float, decel: float) -> tuple[float, float]:
    """Drive `pieces` from speed `v_in`, ending no faster than `v_end_max`.

    Returns (time_s, v_end). `v_in` must allow braking to every later limit within the pieces,
    which holds when the caller ends each stretch at a speed from `stop_entry_speed` of the next.
    """
    n = len(pieces)
    bounds = [0.0] * (n + 1)
    bounds[0] = v_in
    for i in range(1, n):
        bounds[i] = min(pieces[i - 1][1], pieces[i][1])
    bounds[n] = min(v_end_max, pieces[n - 1][1])
    for i in range(1, n + 1):  # forward: what acceleration can reach
        reach = math.sqrt(bounds[i - 1] ** 2 + 2.0 * accel * pieces[i - 1][0])
        if reach < bounds[i]:
            bounds[i] = reach
    for i in range(n - 1, 0, -1):  # backward: what braking allows
        brake = math.sqrt(bounds[i + 1] ** 2 + 2.0 * decel * pieces[i][0])
        if brake < bounds[i]:
            bounds[i] = brake
    total = 0.0
    for i, (length, limit) in enumerate(pieces):
        total += piece_time(length, bounds[i], limit, bounds[i + 1], accel, decel)
    return total, bounds[n]


def stop_entry_speed(pieces: Sequence[Piece], decel: float) -> float:
    """Highest speed at which a vehicle may enter `pieces` and still stop at their end."""
    v = 0.0
    for length, limit in reversed(pieces):
        v = min(limit, math.sqrt(v * v + 2.0 * decel * length))
    return v
