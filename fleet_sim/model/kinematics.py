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
    """Moves AGVs instead of the closed form (fleet_sim.sim.sumo.backend.SumoMotion): the driver
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
    bounds = speed_bounds(pieces, v_in, v_end_max, accel, decel)
    total = 0.0
    for i, (length, limit) in enumerate(pieces):
        total += piece_time(length, bounds[i], limit, bounds[i + 1], accel, decel)
    return total, bounds[-1]


def speed_bounds(pieces: Sequence[Piece], v_in: float, v_end_max: float,
                 accel: float, decel: float) -> list[float]:
    """The speed at each boundary between `pieces` (entry first, exit last) of `traverse`."""
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
    return bounds


def distance_at(pieces: Sequence[Piece], v_in: float, v_end: float, accel: float,
                decel: float, t_s: float) -> float:
    """How far into `pieces` a vehicle is `t_s` seconds after entering them at `v_in`, on the
    profile of `traverse(pieces, v_in, v_end, ...)` (`v_end`: the speed traverse returned):
    within each piece it accelerates to the piece's peak, cruises, and brakes to the next
    boundary's speed, exactly as `piece_time` times it. Clamped to [0, total length]; the
    replay draws AGVs with it (and with its JavaScript twin in the replay page)."""
    bounds = speed_bounds(pieces, v_in, v_end, accel, decel)
    done_m = 0.0
    left_s = t_s
    for i, (length, limit) in enumerate(pieces):
        if length <= 0.0:
            continue
        v0, v1 = bounds[i], bounds[i + 1]
        v_peak_sq = (2.0 * accel * decel * length + decel * v0 * v0 + accel * v1 * v1) \
            / (accel + decel)
        v_peak = max(min(limit, math.sqrt(v_peak_sq)), v0, v1)
        t_acc = (v_peak - v0) / accel
        d_acc = (v_peak * v_peak - v0 * v0) / (2.0 * accel)
        d_dec = (v_peak * v_peak - v1 * v1) / (2.0 * decel)
        cruise = max(0.0, length - d_acc - d_dec)
        t_cruise = cruise / v_peak
        t_dec = (v_peak - v1) / decel
        if left_s >= t_acc + t_cruise + t_dec:
            done_m += length
            left_s -= t_acc + t_cruise + t_dec
            continue
        if left_s < t_acc:
            along = v0 * left_s + 0.5 * accel * left_s * left_s
        elif left_s < t_acc + t_cruise:
            along = d_acc + v_peak * (left_s - t_acc)
        else:
            tau = left_s - t_acc - t_cruise
            along = d_acc + cruise + v_peak * tau - 0.5 * decel * tau * tau
        return done_m + min(max(along, 0.0), length)
    return done_m


def stop_entry_speed(pieces: Sequence[Piece], decel: float) -> float:
    """Highest speed at which a vehicle may enter `pieces` and still stop at their end."""
    v = 0.0
    for length, limit in reversed(pieces):
        v = min(limit, math.sqrt(v * v + 2.0 * decel * length))
    return v
