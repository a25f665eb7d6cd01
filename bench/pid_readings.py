"""Why the steering PID reads P_007-P_009 as millimetres in, degrees out, per 10 ms cycle.

RSS-AGV-001 gives the gains (1.25, 0.05, 0.80) without units. This runs the dynamics model with
three readings of them and prints, for a 20 mm start offset on a straight at 0.2/0.5/1.0 m/s,
the worst lateral error after 2 m, and whether a 90 degree branch curve of 1 m (0.3 m/s) is
followed without losing the line (Req.Err.010).

    .venv/bin/python bench/pid_readings.py
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agv_model.dynamics import Drive, Start, State, VehicleParams, simulate  # noqa: E402
from agv_model.pid import PidGains  # noqa: E402
from agv_model.track import Track  # noqa: E402

READINGS: dict[str, PidGains] = {
    "mm -> deg, per 10 ms cycle (default)": PidGains(),
    "half-width (80 mm) -> rad, per second": PidGains(error_unit_m=0.08, output_unit_rad=1.0,
                                                      cycle_s=1.0,
                                                      integral_limit_rad=math.radians(20)),
    "m -> rad, per second": PidGains(error_unit_m=1.0, output_unit_rad=1.0, cycle_s=1.0,
                                     integral_limit_rad=math.radians(20)),
}


def straight_worst_mm(gains: PidGains, speed_mps: float) -> str:
    trace = simulate(Track.straight(6.0), [Drive(0.0, speed_mps)], VehicleParams(pid=gains),
                     start=Start(speed_mps=speed_mps, lateral_error_m=0.02))
    if State.LINE_LOST in trace.state:
        return "line lost"
    after = np.abs(trace.lateral_error_m[trace.position_m >= 2.0])
    return f"{float(after.max()) * 1000:.1f} mm"


def branch(gains: PidGains) -> str:
    trace = simulate(Track.branch(4.0, 4.0), [Drive(0.0, 1.0)], VehicleParams(pid=gains))
    if State.LINE_LOST in trace.state:
        return "line lost"
    return f"followed, sensor within {float(np.abs(trace.sensor_error_m).max()) * 1000:.1f} mm"


def main() -> None:
    print(f"{'reading':<40} {'0.2 m/s':>10} {'0.5 m/s':>10} {'1.0 m/s':>10}   branch curve")
    for name, gains in READINGS.items():
        cols = [straight_worst_mm(gains, v) for v in (0.2, 0.5, 1.0)]
        print(f"{name:<40} {cols[0]:>10} {cols[1]:>10} {cols[2]:>10}   {branch(gains)}")


if __name__ == "__main__":
    main()
