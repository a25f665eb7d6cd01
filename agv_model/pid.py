"""The steering PID of RSS-AGV-001 5.1 with the gains of 7.1 (P_007-P_009).

5.1 gives the form (P: error x Kp, I: accumulated error x Ki, D: rate of change of error x Kd)
and 7.1 the gains (1.25, 0.05, 0.80) with no units. The reading used here, assumed and
configurable, is that of a firmware loop: the error is counted in millimetres, the output is a
steering angle in degrees, the integral is the sum of the errors of each control cycle and the
derivative the change of error over one cycle, with a control cycle of 10 ms. So, in SI units,

    steer_rad = rad(1 deg) * (Kp * e_mm + Ki * sum(e_mm) + Kd * (e_mm - e_prev_mm))

which this class computes for any time step as Kp*e + (Ki/cycle) * integral(e dt)
+ (Kd*cycle) * de/dt, so that a different simulation step gives the same controller. With these
units Kp is 71.6 rad of steering per metre of error: the 16-bit sensor's 5 mm steps stay a few
degrees, and a 90 degree branch curve of 1 m (radius 0.64 m) needs about 4 mm of error. Other
readings (error normalised to the sensor half-width, output in radians, continuous-time gains)
are one `PidGains(...)` away; docs/studies/2026-11-agv-model-dynamics.md says why this one was kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class PidGains:
    kp: float = 1.25
    """P_007 YAW_GAIN_P."""
    ki: float = 0.05
    """P_008 YAW_GAIN_I."""
    kd: float = 0.80
    """P_009 YAW_GAIN_D."""
    error_unit_m: float = 0.001
    """Assumed: one unit of error is 1 mm."""
    output_unit_rad: float = math.pi / 180.0
    """Assumed: one unit of output is 1 degree of steering."""
    cycle_s: float = 0.010
    """Assumed: the firmware's control cycle, over which I sums and D differences."""
    integral_limit_rad: float = math.radians(20.0)
    """Assumed anti-windup: the I term alone never asks for more than this much steering."""

    def __post_init__(self) -> None:
        for name in ("error_unit_m", "output_unit_rad", "cycle_s"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} ({getattr(self, name)}) must be > 0")
        if self.integral_limit_rad < 0:
            raise ValueError(f"integral_limit_rad ({self.integral_limit_rad}) must be >= 0")


class SteeringPid:
    """One PID controller; `step` takes the measured error and returns the steering angle."""

    def __init__(self, gains: PidGains) -> None:
        self.gains = gains
        self._integral = 0.0
        """Integral of the error in error units x seconds."""
        self._previous: float | None = None

    def reset_derivative(self) -> None:
        """Forget the previous error, so the next step has no derivative kick (after the line
        was lost and found again)."""
        self._previous = None

    def step(self, error_m: float, dt_s: float) -> float:
        """Steering angle (rad, positive turns left) that reduces a lateral error `error_m`
        (positive: the sensor lies left of the line, so the answer is negative)."""
        g = self.gains
        e = error_m / g.error_unit_m
        self._integral += e * dt_s
        i_term = g.ki / g.cycle_s * self._integral * g.output_unit_rad
        if g.ki > 0 and abs(i_term) > g.integral_limit_rad:
            i_term = math.copysign(g.integral_limit_rad, i_term)
            self._integral = i_term / (g.ki / g.cycle_s * g.output_unit_rad)
        d_term = 0.0
        if self._previous is not None:
            d_term = g.kd * g.cycle_s * (e - self._previous) / dt_s * g.output_unit_rad
        self._previous = e
        return -(g.kp * e * g.output_unit_rad + i_term + d_term)
