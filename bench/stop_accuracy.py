"""Study (b): stop accuracy at a station against approach speed and command latency, held
against the +/-10 mm of RSS-AGV-001 4.2.5.

The vehicle (agv_model.dynamics, 10 ms control step) cruises towards a station on a straight
line at 0.2, 0.5 or 1.0 m/s (the TYPE_SPD speeds of 5.3) and brakes at VEL_DEC 0.5 m/s2. Two
ways of stopping it:

* host stop: the host (FMS) sends "stop" the moment the vehicle passes the braking point
  (station - v^2 / 2 VEL_DEC), as a host that drives the vehicle over the link would; the
  command arrives after the link latency and is taken at the vehicle's next control step.
* planned stop: the host sends "stop at the station" well ahead (with the route); the vehicle
  plans its braking on its own odometry, so the latency only delays when the plan is known.

Each cell runs 10 station positions spread over one control step of travel (the command's
arrival falls anywhere within a step) and reports the mean and worst stop error (positive:
past the station). Prints the tables and writes a PNG under --out.

    .venv/bin/python bench/stop_accuracy.py [--out results/agv_model]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agv_model.dynamics import (  # noqa: E402
    Command,
    Drive,
    Start,
    Stop,
    StopAt,
    VehicleParams,
    simulate,
)
from agv_model.track import Track  # noqa: E402

SPEEDS_MPS = (0.2, 0.5, 1.0)
LATENCIES_S = (0.0, 0.010, 0.050, 0.100, 0.250)
TOLERANCE_M = 0.010
"""RSS-AGV-001 4.2.5 (and 4.2.7): stop position within +/-10 mm."""
PHASES = 10
DT_S = 0.01
APPROACH_M = 0.5
"""Cruise this far before the braking point."""
BASE_M = 5.0
"""Station position of the first phase."""


@dataclass(frozen=True)
class Cell:
    speed_mps: float
    latency_s: float
    mode: str
    errors_m: tuple[float, ...]

    @property
    def mean_m(self) -> float:
        return sum(self.errors_m) / len(self.errors_m)

    @property
    def worst_m(self) -> float:
        return max(self.errors_m, key=abs)

    @property
    def passes(self) -> bool:
        return all(abs(e) <= TOLERANCE_M for e in self.errors_m)


def stop_error_m(speed_mps: float, latency_s: float, mode: str, station_m: float,
                 params: VehicleParams) -> float:
    braking_m = speed_mps ** 2 / (2.0 * params.decel_mps2)
    start_m = BASE_M - braking_m - APPROACH_M  # the same start for every station position
    track = Track.straight(station_m + 2.0)
    start = Start(position_m=start_m, speed_mps=speed_mps)
    commands: list[Command] = [Drive(0.0, speed_mps, delay_s=0.0)]
    if mode == "host stop":
        # when the vehicle, cruising from start_m, passes the braking point
        sent_s = (station_m - braking_m - start_m) / speed_mps
        commands.append(Stop(sent_s))
    else:
        commands.append(StopAt(0.0, station_m))
    trace = simulate(track, commands, params, link_delay_s=latency_s, dt_s=DT_S, start=start)
    return trace.final_position_m - station_m


def cell(speed_mps: float, latency_s: float, mode: str, params: VehicleParams) -> Cell:
    errors = tuple(stop_error_m(speed_mps, latency_s, mode,
                                BASE_M + i / PHASES * speed_mps * DT_S, params)
                   for i in range(PHASES))
    return Cell(speed_mps, latency_s, mode, errors)


def largest_passing_latency_s(speed_mps: float, params: VehicleParams) -> float | None:
    """Largest latency (1 ms grid, up to 60 ms) at which every host stop is within tolerance."""
    best = None
    for ms in range(61):
        if cell(speed_mps, ms / 1000.0, "host stop", params).passes:
            best = ms / 1000.0
        else:
            break
    return best


def print_table(cells: list[Cell]) -> None:
    head = (f"{'speed m/s':>9} {'latency ms':>10} {'v x L mm':>9} | {'host stop: mean':>15} "
            f"{'worst mm':>8} {'':>4} | {'planned stop: worst mm':>22} {'':>4}")
    print(head)
    print("-" * len(head))
    by_key = {(c.speed_mps, c.latency_s, c.mode): c for c in cells}
    for v in SPEEDS_MPS:
        for lat in LATENCIES_S:
            host = by_key[(v, lat, "host stop")]
            plan = by_key[(v, lat, "planned stop")]
            print(f"{v:>9.1f} {lat * 1000:>10.0f} {v * lat * 1000:>9.1f} | "
                  f"{host.mean_m * 1000:>15.1f} {host.worst_m * 1000:>+8.1f} "
                  f"{'pass' if host.passes else 'FAIL':>4} | {plan.worst_m * 1000:>+22.2f} "
                  f"{'pass' if plan.passes else 'FAIL':>4}")


def plot(cells: list[Cell], out: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8, 5))
    for v, colour in zip(SPEEDS_MPS, ("tab:green", "tab:blue", "tab:red"), strict=True):
        host = [c for c in cells if c.speed_mps == v and c.mode == "host stop"]
        plan = [c for c in cells if c.speed_mps == v and c.mode == "planned stop"]
        lat_ms = [c.latency_s * 1000 for c in host]
        ax.plot(lat_ms, [c.worst_m * 1000 for c in host], "o-", color=colour,
                label=f"host stop, {v} m/s (worst of {PHASES})")
        ax.fill_between(lat_ms, [min(c.errors_m) * 1000 for c in host],
                        [max(c.errors_m) * 1000 for c in host], color=colour, alpha=0.2)
        ax.plot([c.latency_s * 1000 for c in plan], [c.worst_m * 1000 for c in plan], "x--",
                color=colour, label=f"planned stop, {v} m/s")
    ax.axhspan(-TOLERANCE_M * 1000, TOLERANCE_M * 1000, color="gray", alpha=0.15,
               label="RSS-AGV-001 4.2.5: +/-10 mm")
    ax.set_xscale("symlog", linthresh=10)
    ax.set_yscale("symlog", linthresh=10)
    ax.set_ylim(-12, None)
    ax.set_xlabel("command latency (ms)")
    ax.set_ylabel("stop error (mm, + past the station)")
    ax.set_title("Stop accuracy vs approach speed and command latency (10 ms control step)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    path = out / "stop_accuracy.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "agv_model")
    args = parser.parse_args()
    params = VehicleParams()
    cells = [cell(v, lat, mode, params) for v in SPEEDS_MPS for lat in LATENCIES_S
             for mode in ("host stop", "planned stop")]
    print(f"Stop error at a station (mm, + past it), {PHASES} station positions per cell over "
          f"one {DT_S * 1000:g} ms step; VEL_DEC {params.decel_mps2} m/s2; pass: every run "
          f"within +/-{TOLERANCE_M * 1000:g} mm")
    print_table(cells)
    print("\nLargest latency at which a host stop still passes (1 ms grid):")
    for v in SPEEDS_MPS:
        best = largest_passing_latency_s(v, params)
        text = "none (fails at 0 ms)" if best is None else f"{best * 1000:.0f} ms"
        print(f"  {v} m/s: {text}   (budget 10 mm / v = {TOLERANCE_M / v * 1000:.0f} ms, "
              f"less up to one {DT_S * 1000:g} ms step)")
    path = plot(cells, args.out)
    print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")


if __name__ == "__main__":
    main()
